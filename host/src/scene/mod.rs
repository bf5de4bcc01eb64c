//! Scene files (TOML): parsing, validation with errors that name the file and
//! the field, and conversion to the buffers the kernels read.
//!
//! The format is documented in `scenes/README.md`; `schema` is its serde
//! form, `validate` the field checks, `geometry` and `lights` the conversions.

use anyhow::{anyhow, bail, Context, Result};
use glam::{Vec3, Vec4};
use slicelight_shaders::geometry::Geometry;
use slicelight_shaders::types::{
    CommonParams, GlassTriangle, GlassVertex, GpuBvhNode, GpuLight, GpuMaterial, GpuSphere, GpuTriangle, PHASE_DOBASHI,
    PHASE_HENYEY_GREENSTEIN, PHASE_ISOTROPIC, PHASE_RAYLEIGH, PROJECTION_FISHEYE, PROJECTION_PINHOLE,
};
use std::path::Path;

pub mod geometry;
pub mod keyframes;
pub mod lights;
pub mod schema;
pub mod validate;

pub use crate::shafts::{Settings as Shafts, ShaftMode};
pub use lights::srgb_to_linear;
pub use schema::*;
use validate::{finite3, non_negative3, unit3};
pub use validate::{invalid, SHAFTS_MIN_SHADOW_MAP_RESOLUTION, SURFACE_SHADOW_MAP_RESOLUTION};

/// Most sub-pixel samples per pixel a scene or `--spp` may ask for.
pub const MAX_SAMPLES_PER_PIXEL: u32 = 4096;

/// A scene ready for the kernels: every buffer they read, plus what the host
/// needs to write the image.
#[derive(Debug, Clone)]
pub struct SceneData {
    pub common: CommonParams,
    pub lights: Vec<GpuLight>,
    /// The line lights as defined; each is a row of `lights` for the kernels.
    pub line_lights: Vec<lights::LineSource>,
    pub spheres: Vec<GpuSphere>,
    /// Triangles in BVH order.
    pub triangles: Vec<GpuTriangle>,
    pub bvh_nodes: Vec<GpuBvhNode>,
    /// One per object.
    pub materials: Vec<GpuMaterial>,
    /// The glass meshes (vertices with smooth normals, indexed triangles).
    pub glass_vertices: Vec<GlassVertex>,
    pub glass_triangles: Vec<GlassTriangle>,
    /// Per object, what its shape is made from, not where it stands (the
    /// cache key of a glass object's table; `geometry::Objects::shape_keys`).
    pub shape_keys: Vec<u128>,
    pub light_map: Vec<Vec4>,
    /// Per light, the shadow-map resolution its file gives (`None`: the
    /// default, see `lay_out_shadow_maps`).
    pub shadow_resolutions: Vec<Option<u32>>,
    /// Axis-aligned bounds of the geometry, if there is any.
    pub bounds: Option<(Vec3, Vec3)>,
    pub exposure: f32,
    /// The shafts pass's settings, parameter block and tables.
    pub shafts: crate::shafts::Setup,
    /// The sky passes' parameter block (`enabled` false without `[sky]`).
    pub sky: crate::sky::Setup,
    /// The sea passes' parameter block and wave slope pyramid (`enabled` false without `[sea]`).
    pub sea: crate::sea::Setup,
    /// The caustics passes' parameter block (`enabled` false without glass and light on it).
    pub caustics: crate::caustics::Setup,
    /// The volumes' parameter block, records and metaballs (`enabled` false without `[[volume]]`).
    pub volumes: crate::volumes::Setup,
    /// The terrains' height fields and the dunes' automaton (empty without `[[terrain]]`).
    pub desert: crate::desert::Setup,
    /// Passes a scene never needs that were asked for by name (self-checks).
    pub requested_passes: Vec<String>,
    /// Passes turned off by name (the viewer's toggles): skipped where no
    /// other running pass reads what they write (`render::plans`).
    pub disabled_passes: Vec<String>,
    /// The instant shown, s (`[time] seconds`): simulations run to it.
    pub time: f64,
    /// The parsed file and the folder its paths are relative to: what
    /// `reconfigure` edits and validates again.
    pub source: std::sync::Arc<Source>,
}

/// A scene as its file gave it (see `SceneData::reconfigure`).
pub struct Source {
    /// The file's settings at this instant, every edit applied.
    pub file: SceneFile,
    pub base: std::path::PathBuf,
    /// With `[[keyframe]]`s: the file's TOML without them, and the
    /// keyframes (`keyframes::take`), from which `at_time` builds an instant.
    pub animated: Option<(toml::Table, Keyframes)>,
    /// The edits made since the file was read (command-line overrides,
    /// `reconfigure`), in order: an animated scene applies them again to
    /// every instant `at_time` builds from its keyframes.
    pub edits: Vec<Edit>,
}

/// A change to a scene file's settings (`SceneData::reconfigure`).
pub type Edit = std::sync::Arc<dyn Fn(&mut SceneFile) + Send + Sync>;

impl std::fmt::Debug for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Source")
            .field("file", &self.file)
            .field("base", &self.base)
            .field("animated", &self.animated)
            .field("edits", &self.edits.len())
            .finish()
    }
}

pub use keyframes::Keyframes;

impl SceneData {
    /// The scene with its file's settings edited by `edit`, built and
    /// validated again from the start, exactly as `load` does: the one way
    /// settings change after a scene is read (the command line's overrides,
    /// the benches' sweeps, the viewer, tests), so that every setting tried
    /// passes the checks and limits a scene file's does. Errors name the
    /// field. An animated scene stays animated: `at_time` applies the edit
    /// again at every instant.
    pub fn reconfigure(&self, edit: impl Fn(&mut SceneFile) + Send + Sync + 'static) -> Result<SceneData> {
        let edit: Edit = std::sync::Arc::new(edit);
        let mut edits = self.source.edits.clone();
        edits.push(edit.clone());
        match &self.source.animated {
            Some((raw, keys)) => from_table(raw, keys, &self.source.base, Some(self.time), &edits),
            None => {
                let mut file = self.source.file.clone();
                edit(&mut file);
                let mut data = build(&file, &self.source.base)?;
                std::sync::Arc::get_mut(&mut data.source).expect("just built").edits = edits;
                Ok(data)
            }
        }
    }

    /// The scene at time `t` (s): its `[time] seconds` set to `t` and, with
    /// `[[keyframe]]`s, every animated field at its value then.
    pub fn at_time(&self, t: f64) -> Result<SceneData> {
        match &self.source.animated {
            None => self.reconfigure(move |f| f.time.seconds = t),
            Some((raw, keys)) => from_table(raw, keys, &self.source.base, Some(t), &self.source.edits),
        }
    }

    /// `at_time(t)` and then `reconfigure(edit)` in one build (the viewer's
    /// view of an instant): the keyframes at `t`, the scene's edits, then
    /// `edit`, which the result keeps as `reconfigure` does.
    pub fn at_time_edited(&self, t: f64, edit: impl Fn(&mut SceneFile) + Send + Sync + 'static) -> Result<SceneData> {
        match &self.source.animated {
            None => self.reconfigure(move |f| {
                f.time.seconds = t;
                edit(f);
            }),
            Some((raw, keys)) => {
                let mut edits = self.source.edits.clone();
                edits.push(std::sync::Arc::new(edit));
                from_table(raw, keys, &self.source.base, Some(t), &edits)
            }
        }
    }

    /// The spotlights whose light reaches nothing (`spotlight[k]`): no
    /// scattering medium for their shafts, and none of 1 024 rays spread
    /// over the cone (Fibonacci directions, uniform in solid angle) meets
    /// a surface or a volume's box. Such a light adds nothing to the image
    /// (pointed away from the scene, or inside a closed object); the render
    /// warns rather than leave it silently black.
    pub fn spotlights_reaching_nothing(&self) -> Vec<String> {
        use slicelight_shaders::geometry::{ray_hits_box, trace_nearest, NO_HIT};
        if self.common.sigma_s.truncate().max_element() > 0.0 {
            return Vec::new();
        }
        let geometry = self.geometry();
        let boxes: Vec<(Vec3, Vec3)> =
            self.volumes.volumes.iter().map(|v| (v.min.truncate(), v.max.truncate())).collect();
        let mut out = Vec::new();
        for (k, s) in self.source.file.spotlight.iter().enumerate() {
            let (apex, axis) = (Vec3::from(s.position), Vec3::from(s.direction).normalize_or_zero());
            let cos_cut = s.cutoff_deg.to_radians().cos();
            let (a, b) = axis.any_orthonormal_pair();
            let rays = 1024;
            let reaches = (0..rays).any(|i| {
                // Directions uniform in solid angle over the cone.
                let cos = 1.0 - (1.0 - cos_cut) * (i as f32 + 0.5) / rays as f32;
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let phi = i as f32 * 2.399_963;
                let dir = (axis * cos + (a * phi.cos() + b * phi.sin()) * sin).normalize();
                let inv = dir.recip();
                trace_nearest(apex, dir, 1e-4, f32::MAX, &geometry).distance != NO_HIT
                    || boxes.iter().any(|(lo, hi)| ray_hits_box(apex, inv, *lo, *hi, 0.0, f32::MAX))
            });
            if !reaches {
                out.push(format!("spotlight[{k}]"));
            }
        }
        out
    }

    /// Spotlights and point lights inside a glass object
    /// (`point_light[k] is inside object[j]`): slicelight carries light
    /// through glass only from outside it (the caustics method sweeps
    /// illumination volumes from lights outside the object, and surfaces'
    /// shadow rays stop at glass), so such a light adds nothing and the
    /// render warns instead of leaving it silently black. Inside means: rays
    /// in three generic directions each cross the object's closed mesh an
    /// odd number of times (two of three, so a ray grazing an edge does not
    /// decide it).
    pub fn lights_inside_glass(&self) -> Vec<String> {
        use slicelight_shaders::geometry::{ray_triangle, NO_HIT};
        if self.glass_triangles.is_empty() {
            return Vec::new();
        }
        let file = &self.source.file;
        let lights = file
            .spotlight
            .iter()
            .enumerate()
            .map(|(k, l)| (format!("spotlight[{k}]"), l.position))
            .chain(file.point_light.iter().enumerate().map(|(k, l)| (format!("point_light[{k}]"), l.position)));
        let directions =
            [Vec3::new(0.5773, 0.6124, 0.5403), Vec3::new(-0.7, 0.1414, 0.6928), Vec3::new(0.2236, -0.8660, -0.4472)];
        let objects = self.glass_triangles.iter().map(|t| t.object).max().map_or(0, |m| m as usize + 1);
        let mut out = Vec::new();
        for (name, position) in lights {
            let origin = Vec3::from(position);
            let mut inside_votes = vec![0u32; objects];
            for dir in directions.map(|d| d.normalize()) {
                let mut crossings = vec![0u32; objects];
                for t in &self.glass_triangles {
                    let [a, b, c] = t.vertices.map(|i| self.glass_vertices[i as usize].position.truncate());
                    if ray_triangle(origin, dir, a, b, c, 0.0) != NO_HIT {
                        crossings[t.object as usize] += 1;
                    }
                }
                for (v, c) in inside_votes.iter_mut().zip(crossings) {
                    *v += c % 2;
                }
            }
            if let Some(j) = inside_votes.iter().position(|v| *v >= 2) {
                out.push(format!("{name} is inside object[{j}]"));
            }
        }
        out
    }

    /// Whether light `i` is one of a line light's points (the references
    /// light the line itself instead).
    pub fn is_line_point(&self, i: usize) -> bool {
        self.line_lights.iter().any(|l| l.lights.contains(&i))
    }

    pub fn width(&self) -> u32 {
        self.common.width
    }
    pub fn height(&self) -> u32 {
        self.common.height
    }
    pub fn pixel_count(&self) -> u32 {
        self.common.width * self.common.height
    }
    pub fn samples_per_pixel(&self) -> u32 {
        self.common.samples_per_pixel
    }
    pub fn has_geometry(&self) -> bool {
        !self.spheres.is_empty() || !self.triangles.is_empty()
    }
    /// Whether any object is glass (`surface::surface_pixel`'s `GLASS`).
    pub fn has_glass(&self) -> bool {
        self.materials.iter().any(|m| m.kind == slicelight_shaders::types::MATERIAL_GLASS)
    }
    /// Whether the medium scatters light at all (in any channel).
    pub fn scatters(&self) -> bool {
        self.common.sigma_s.truncate().max_element() > 0.0
    }

    /// The geometry as the kernels see it.
    pub fn geometry(&self) -> Geometry<'_> {
        slicelight_shaders::scene_geometry(&self.common, &self.spheres, &self.triangles, &self.bvh_nodes)
    }

    /// Applies shaft settings (see `shafts::configure`).
    fn configure_shafts(&mut self, s: Shafts) -> Result<()> {
        crate::shafts::configure(self, s)
    }

    /// The scene as sub-pixel sample `k` of its `samples_per_pixel` is
    /// dispatched (`sample_index`: which sub-pixel position the camera's
    /// rays go through; the renderer sets it per sample): for checks of
    /// one sample's passes.
    pub fn at_sample(&self, k: u32) -> Result<SceneData> {
        let n = self.common.samples_per_pixel;
        if k >= n {
            bail!(invalid("sample", &format!("a sample index below samples_per_pixel = {n}"), k));
        }
        let mut d = self.clone();
        d.common.sample_index = k;
        Ok(d)
    }

    /// Gives each spot and directional light its shadow map, one after the
    /// other in one buffer: the resolution its file gives, else, where the
    /// maps serve only the shafts, the smallest whose texels are no wider
    /// than a pixel where the view sees the light's volume (at least
    /// `SHAFTS_MIN_SHADOW_MAP_RESOLUTION`, at most
    /// `SURFACE_SHADOW_MAP_RESOLUTION`: `shadow_maps::shafts_resolution`),
    /// and `SURFACE_SHADOW_MAP_RESOLUTION` where they also shadow surfaces.
    /// A scene without geometry has no maps (every light sees every point).
    pub fn lay_out_shadow_maps(&mut self) -> Result<()> {
        let geometry = self.has_geometry();
        let surfaces = self.common.surface_shadows == slicelight_shaders::types::SHADOWS_MAP;
        // Where the view rays that see no surface leave the scene's bounds.
        let t_far = self.bounds.map_or(0.0, |(lo, hi)| {
            let eye = self.common.camera_position.truncate();
            (eye - (lo + hi) * 0.5).length() + (hi - lo).length() * 0.5
        });
        // The view rays the footprint rule follows, traced once for every light
        // that needs them.
        let mut rays = None;
        let mut resolutions = Vec::with_capacity(self.lights.len());
        for (light, given) in self.lights.iter().zip(&self.shadow_resolutions) {
            resolutions.push(match given {
                _ if !geometry || light.kind == slicelight_shaders::types::LIGHT_POINT => 0,
                Some(r) => *r,
                None if surfaces => SURFACE_SHADOW_MAP_RESOLUTION,
                None => crate::common::shadow_maps::shafts_resolution(
                    &self.common,
                    light,
                    rays.get_or_insert_with(|| {
                        crate::common::shadow_maps::footprint_rays(&self.common, &self.geometry(), t_far)
                    }),
                    SHAFTS_MIN_SHADOW_MAP_RESOLUTION,
                    SURFACE_SHADOW_MAP_RESOLUTION,
                ),
            });
        }
        // Checked before any light changes, so a failed layout leaves the scene as it was.
        let texels: u64 = resolutions.iter().map(|&r| r as u64 * r as u64).sum();
        let count = u32::try_from(texels).map_err(|_| {
            invalid(
                "shadow_map_resolution",
                "fewer shadow-map texels in all lights' maps together (at most 2^32 - 1)",
                texels,
            )
        })?;
        let mut offset = 0u32;
        for (light, res) in self.lights.iter_mut().zip(resolutions) {
            light.shadow_resolution = res;
            light.shadow_offset = if res > 0 { offset } else { 0 };
            offset += res * res;
        }
        self.common.shadow_texel_count = count;
        Ok(())
    }
}

/// Reads, validates and converts a scene file. Relative paths inside it are
/// taken relative to the file's folder.
pub fn load(path: &Path) -> Result<SceneData> {
    load_edited(path, None)
}

/// `load` with `edit` applied to the file's settings before the scene is
/// built (the command line's overrides): one build, validated as the file
/// is, and kept by an animated scene for every instant.
pub fn load_edited(path: &Path, edit: Option<Edit>) -> Result<SceneData> {
    crate::output::regular_file("the scene file", path, crate::output::MAX_SCENE_BYTES)
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let text =
        std::fs::read_to_string(path).with_context(|| format!("{}: cannot read the scene file", path.display()))?;
    from_text_edited(&text, path, edit)
}

/// A scene from a scene file's text; `path` names it in errors and its
/// folder is where the file's paths start.
pub fn from_text(text: &str, path: &Path) -> Result<SceneData> {
    from_text_edited(text, path, None)
}

fn from_text_edited(text: &str, path: &Path, edit: Option<Edit>) -> Result<SceneData> {
    let base = path.parent().unwrap_or(Path::new("."));
    let mut raw: toml::Table = text.parse().map_err(|e| anyhow!("{}: {}", path.display(), e))?;
    let keys = keyframes::take(&mut raw).map_err(|e| anyhow!("{}: {}", path.display(), e))?;
    let edits: Vec<Edit> = edit.into_iter().collect();
    if !keys.is_empty() {
        return from_table(&raw, &keys, base, None, &edits).map_err(|e| anyhow!("{}: {}", path.display(), e));
    }
    // Without keyframes, read from the text: serde's errors then give lines.
    let mut file: SceneFile = toml::from_str(text).map_err(|e| anyhow!("{}: {}", path.display(), e))?;
    edits.iter().for_each(|e| e(&mut file));
    let mut data = build(&file, base).map_err(|e| anyhow!("{}: {}", path.display(), e))?;
    std::sync::Arc::get_mut(&mut data.source).expect("just built").edits = edits;
    Ok(data)
}

/// The scene of an animated file (`raw` without its keyframes `keys`) at
/// `time` (s; default the file's `[time] seconds`), `edits` applied to the
/// settings of that instant.
fn from_table(
    raw: &toml::Table,
    keys: &Keyframes,
    base: &Path,
    time: Option<f64>,
    edits: &[Edit],
) -> Result<SceneData> {
    let mut table = raw.clone();
    if let Some(t) = time {
        let clock = table.entry("time").or_insert_with(|| toml::Value::Table(toml::Table::new()));
        let toml::Value::Table(clock) = clock else { bail!("time: expected a table") };
        clock.insert("seconds".into(), toml::Value::Float(t));
    }
    let t = match table.get("time").and_then(|c| c.get("seconds")) {
        Some(toml::Value::Float(f)) => *f,
        Some(toml::Value::Integer(n)) => *n as f64,
        Some(other) => bail!(invalid("time.seconds", "a time in seconds", other)),
        None => 0.0,
    };
    keyframes::apply(&mut table, keys, t)?;
    let mut file: SceneFile = toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| anyhow!("{e}"))?;
    edits.iter().for_each(|e| e(&mut file));
    let mut data = build(&file, base)?;
    data.source = std::sync::Arc::new(Source {
        file,
        base: base.to_path_buf(),
        animated: Some((raw.clone(), keys.clone())),
        edits: edits.to_vec(),
    });
    Ok(data)
}

/// The camera's part of the common block.
fn camera(cam: &Camera) -> Result<CommonParams> {
    let [w, h] = cam.resolution;
    if w == 0 || h == 0 {
        bail!(invalid("camera.resolution", "two positive pixel counts", cam.resolution));
    }
    if (w as u64) * (h as u64) > u32::MAX as u64 / 4 {
        bail!(invalid("camera.resolution", "at most 2^30 pixels", cam.resolution));
    }
    let fisheye = cam.projection == Projection::Fisheye;
    let vfov = match (cam.vfov_deg, fisheye) {
        // A thousandth of a degree is a 1000 mm lens's field on 17 um:
        // narrower views lose the pixel positions to f32 rounding.
        (Some(v), false) if (1e-3..180.0).contains(&v) => v,
        (Some(v), false) => bail!(invalid("camera.vfov_deg", "an angle in [0.001, 180) degrees", v)),
        (None, false) => {
            bail!("camera.vfov_deg: missing; a pinhole camera needs its vertical field of view in degrees")
        }
        (Some(v), true) => bail!(invalid(
            "camera.vfov_deg",
            "no field of view for a fisheye (it sees the 180-degree hemisphere around look_at)",
            v
        )),
        (None, true) => 180.0,
    };
    if !(cam.exposure.is_finite() && cam.exposure > 0.0) {
        bail!(invalid("camera.exposure", "a positive number", cam.exposure));
    }
    if !(1..=MAX_SAMPLES_PER_PIXEL).contains(&cam.samples_per_pixel) {
        bail!(invalid(
            "camera.samples_per_pixel",
            &format!("a sample count in 1..={MAX_SAMPLES_PER_PIXEL}"),
            cam.samples_per_pixel
        ));
    }
    let position = finite3("camera.position", cam.position)?;
    let look_at = finite3("camera.look_at", cam.look_at)?;
    let forward = unit3("camera.look_at", (look_at - position).into())
        .map_err(|_| invalid("camera.look_at", "a point different from camera.position", cam.look_at))?;
    let up = unit3("camera.up", cam.up)?;
    let right = forward.cross(up);
    if right.length() < 1e-4 {
        bail!(invalid("camera.up", "an up vector not parallel to the view direction", cam.up));
    }
    let right = right.normalize();
    let true_up = right.cross(forward);
    // A fisheye's axes are unit vectors (see `camera::camera_ray`).
    let (scale_x, scale_y) = if fisheye {
        (1.0, 1.0)
    } else {
        let tan_half = (vfov.to_radians() * 0.5).tan();
        (tan_half * w as f32 / h as f32, tan_half)
    };
    Ok(CommonParams {
        camera_position: position.extend(1.0),
        camera_forward: forward.extend(0.0),
        camera_right: (right * scale_x).extend(0.0),
        camera_up: (true_up * scale_y).extend(0.0),
        projection: if fisheye { PROJECTION_FISHEYE } else { PROJECTION_PINHOLE },
        width: w,
        height: h,
        band_start: 0,
        band_pixels: w * h,
        samples_per_pixel: cam.samples_per_pixel,
        ..Default::default()
    })
}

/// Sets the medium's part of the common block.
fn medium(m: &Medium, common: &mut CommonParams) -> Result<()> {
    let sigma_s = non_negative3("medium.sigma_s", m.sigma_s)?;
    let sigma_t = non_negative3("medium.sigma_t", m.sigma_t)?;
    if sigma_s.cmpgt(sigma_t).any() {
        bail!(invalid(
            "medium.sigma_s",
            "no channel above medium.sigma_t (scattering is part of extinction)",
            m.sigma_s
        ));
    }
    (common.phase_kind, common.phase_g) = match m.phase {
        Phase::Isotropic => (PHASE_ISOTROPIC, 0.0),
        Phase::Rayleigh => (PHASE_RAYLEIGH, 0.0),
        Phase::Dobashi2002 => (PHASE_DOBASHI, 0.0),
        Phase::HenyeyGreenstein { g } => {
            if !(g > -1.0 && g < 1.0) {
                bail!(invalid("medium.phase.g", "a number in (-1, 1)", g));
            }
            (PHASE_HENYEY_GREENSTEIN, g)
        }
    };
    common.sigma_s = sigma_s.extend(0.0);
    common.sigma_t = sigma_t.extend(0.0);
    Ok(())
}

/// Validates a parsed scene and converts it to kernel buffers.
pub fn build(file: &SceneFile, base: &Path) -> Result<SceneData> {
    let time = file.time.seconds;
    if !(time.is_finite() && (0.0..=1e7).contains(&time)) {
        bail!(invalid("time.seconds", "a time in [0, 1e7] seconds", time));
    }
    let mut common = camera(&file.camera)?;
    common.surface_shadows = file.surface.shadows.code();
    medium(&file.medium, &mut common)?;
    if common.projection == PROJECTION_FISHEYE && common.sigma_s.truncate().max_element() > 0.0 {
        bail!(invalid(
            "camera.projection",
            "a pinhole camera in a scattering medium (the shafts pass's sample planes are parallel to a pinhole's image plane)",
            "fisheye"
        ));
    }
    if common.projection == PROJECTION_FISHEYE && !file.volume.is_empty() {
        bail!(invalid(
            "camera.projection",
            "a pinhole camera with [[volume]] (the volumes' sample planes are parallel to a pinhole's image plane)",
            "fisheye"
        ));
    }
    let mut objects = geometry::build(&file.object, base)?;
    let desert = crate::desert::configure(&file.terrain, base, time, &indicatif::ProgressBar::hidden())?;
    for (k, (t, f)) in file.terrain.iter().zip(&desert.fields).enumerate() {
        let ripples = desert.ripple_of_terrain[k];
        let (sand, bare) = crate::desert::sand_and_bare(t, crate::desert::mesh(t, f));
        geometry::push_diffuse(&mut objects, &sand, Vec3::from(t.albedo).extend(0.0), ripples);
        if let Some((ground, albedo)) = bare {
            geometry::push_diffuse(&mut objects, &ground, Vec3::from(albedo).extend(0.0), 0);
        }
        let skirt = crate::desert::skirt(t, f);
        if !skirt.indices.is_empty() {
            geometry::push_diffuse(&mut objects, &skirt, Vec3::from(t.albedo).extend(0.0), 0);
        }
    }
    let bounds = geometry::bounds(&objects.spheres, &objects.triangles);
    // The lights cover the geometry and the volumes' boxes (a directional
    // light enters the scene where its bounding sphere begins).
    let light_bounds = file.volume.iter().fold(bounds, |b, v| {
        let (lo, hi) = (Vec3::from(v.min), Vec3::from(v.max));
        Some(b.map_or((lo.min(hi), lo.max(hi)), |(a, c)| (a.min(lo).min(hi), c.max(hi).max(lo))))
    });
    let mut sky = match &file.sky {
        Some(s) => crate::sky::configure(s)?,
        None => Default::default(),
    };
    let sea = match &file.sea {
        Some(s) => {
            if common.projection == PROJECTION_FISHEYE {
                bail!(invalid("camera.projection", "a pinhole camera over a sea", "fisheye"));
            }
            crate::sea::configure(s, &sky, &common, base, time, bounds.map(|(lo, _)| lo.y))?
        }
        None => Default::default(),
    };
    // The sea covers every downward view (and every view from under the
    // water); the sky pass leaves it to the sea passes.
    sky.params.sea = match (sea.enabled, sea.params.underwater != 0) {
        (false, _) => slicelight_shaders::sky::SEA_NONE,
        (true, false) => slicelight_shaders::sky::SEA_BELOW,
        (true, true) => slicelight_shaders::sky::SEA_AROUND,
    };
    // The sun lights the scene's surfaces as a directional light of its
    // colour after the air it crosses to the observer.
    let mut directionals: Vec<DirectionalLight> = Vec::new();
    let sun_lights = file.sky.as_ref().is_some_and(|s| s.light_scene) && light_bounds.is_some();
    let sun_added = sky.sun_at_observer().is_some() && sun_lights;
    if let Some((irradiance, toward)) = sky.sun_at_observer().filter(|_| sun_lights) {
        directionals.push(DirectionalLight {
            direction: (-toward).into(),
            up: None,
            irradiance: irradiance.into(),
            origin: None,
            light_map: None,
            size: None,
            shadow_map_resolution: None,
        });
    }
    let point_lights = !file.point_light.is_empty() || !file.line_light.is_empty();
    if point_lights && common.sigma_s.truncate().max_element() > 0.0 {
        bail!(invalid(
            if file.point_light.is_empty() { "line_light" } else { "point_light" },
            "a clear medium (sigma_s = 0): the shafts pass's shadow maps cover spotlight cones and directional beams only",
            "a light in a scattering medium"
        ));
    }
    let lights = lights::build(
        &file.spotlight,
        &[&file.directional_light[..], &directionals].concat(),
        &file.point_light,
        &file.line_light,
        base,
        light_bounds,
    )?;
    let bvh = crate::bvh::Bvh::build(objects.triangles);
    common.light_count = lights.lights.len() as u32;
    common.sphere_count = objects.spheres.len() as u32;
    common.triangle_count = bvh.triangles.len() as u32;
    common.bvh_node_count = bvh.nodes.len() as u32;
    let mut data = SceneData {
        common,
        lights: lights.lights,
        line_lights: lights.lines,
        spheres: objects.spheres,
        triangles: bvh.triangles,
        bvh_nodes: bvh.nodes,
        materials: objects.materials,
        glass_vertices: objects.glass_vertices,
        glass_triangles: objects.glass_triangles,
        shape_keys: objects.shape_keys,
        light_map: lights.light_map,
        shadow_resolutions: lights.shadow_resolutions,
        bounds,
        exposure: file.camera.exposure,
        shafts: Default::default(),
        sky,
        sea,
        caustics: Default::default(),
        volumes: Default::default(),
        desert,
        requested_passes: Vec::new(),
        disabled_passes: Vec::new(),
        time,
        source: std::sync::Arc::new(Source {
            file: file.clone(),
            base: base.to_path_buf(),
            animated: None,
            edits: Vec::new(),
        }),
    };
    data.lay_out_shadow_maps()?;
    data.configure_shafts(file.shafts).map_err(|e| anyhow!("shafts.{e}"))?;
    data.caustics = crate::caustics::configure(&file.caustics, &data).map_err(|e| anyhow!("caustics.{e}"))?;
    data.volumes = crate::volumes::configure(&file.volume, &file.volumes, &data, base)?;
    // Clouds shade the sea through the sun's transmittance volume: the sun
    // is the last light (`lights::build` adds the directional lights last,
    // the sky's sun after the file's).
    if data.sea.enabled && data.volumes.enabled && sun_added {
        data.sea.params.sun_light = data.lights.len() as u32;
    }
    Ok(data)
}
