//! Scene files (TOML): parsing, validation with errors that name the file and
//! the field, and conversion to the buffers the kernels read.
//!
//! The format is documented in `scenes/README.md`.

use anyhow::{anyhow, bail, Context, Result};
use glam::{Vec3, Vec4};
use serde::Deserialize;
use slicelight_shaders::types::{
    FrameParams, GpuLight, GpuSphere, GpuTriangle, GpuTriangleGroup, LIGHT_DIRECTIONAL, LIGHT_SPOT, PHASE_DOBASHI,
    PHASE_HENYEY_GREENSTEIN, PHASE_ISOTROPIC, PHASE_RAYLEIGH,
};
use std::path::{Path, PathBuf};

/// Measured on the Fig. 7 stage at 720x480 (surface term against shadow rays):
/// 512 costs 0.05 % RMS of the 8-bit range, a quarter of the time of 1024.
pub const DEFAULT_SHADOW_MAP_RESOLUTION: u32 = 512;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub camera: Camera,
    #[serde(default)]
    pub medium: Medium,
    #[serde(default)]
    pub spotlight: Vec<Spotlight>,
    #[serde(default)]
    pub directional_light: Vec<DirectionalLight>,
    #[serde(default)]
    pub object: Vec<Object>,
    #[serde(default)]
    pub shafts: Shafts,
}

/// Settings of the shafts-of-light pass (in-scattering by slice accumulation).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Shafts {
    /// Sample planes `n` (eq. 5).
    pub planes: u32,
    /// Sub-sample planes per plane interval `m` (eq. 9).
    pub subplanes: u32,
    /// `exact` evaluates the phase and attenuation functions; `tables` looks
    /// them up in the paper's 1D `F` and 2D `h` tables.
    pub mode: ShaftMode,
    /// Offset the plane lattice per pixel by a 4x4 ordered dither.
    pub jitter: bool,
    /// Integrate the `1/s^2` of eq. 3 exactly over each interval.
    pub analytic_inverse_square: bool,
    /// Nodes of the phase table over [0, 180] degrees.
    pub phase_table_size: u32,
    /// Nodes of the attenuation table `h(s, t)` along `s` and `t`.
    pub h_table_size: [u32; 2],
    /// Round the tables and each plane's contribution to 8 bits, as the
    /// 2002 paper's hardware did (for reproducing its Fig. 4 trade-off).
    pub quantize_8bit: bool,
}

impl Default for Shafts {
    fn default() -> Self {
        Shafts {
            planes: 30,
            subplanes: 6,
            mode: ShaftMode::Exact,
            jitter: true,
            analytic_inverse_square: true,
            phase_table_size: 256,
            h_table_size: [256, 256],
            quantize_8bit: false,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ShaftMode {
    Exact,
    Tables,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    pub position: [f32; 3],
    pub look_at: [f32; 3],
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    pub vfov_deg: f32,
    pub resolution: [u32; 2],
    #[serde(default = "one")]
    pub exposure: f32,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Medium {
    /// 1/m per channel.
    pub sigma_s: [f32; 3],
    /// 1/m per channel.
    pub sigma_t: [f32; 3],
    #[serde(default)]
    pub phase: Phase,
}

impl Default for Medium {
    fn default() -> Self {
        Medium { sigma_s: [0.0; 3], sigma_t: [0.0; 3], phase: Phase::Isotropic }
    }
}

#[derive(Debug, Default, Deserialize, Clone, Copy)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Phase {
    #[default]
    Isotropic,
    HenyeyGreenstein { g: f32 },
    Rayleigh,
    /// `1 + 9 cos^16(a/2)` of the 2002 paper, normalised.
    Dobashi2002,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spotlight {
    pub position: [f32; 3],
    pub direction: [f32; 3],
    pub up: Option<[f32; 3]>,
    pub cutoff_deg: f32,
    pub beam_deg: Option<f32>,
    /// W/sr per channel.
    pub intensity: [f32; 3],
    pub light_map: Option<PathBuf>,
    pub shadow_map_resolution: Option<u32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DirectionalLight {
    pub direction: [f32; 3],
    pub up: Option<[f32; 3]>,
    /// W/m^2 per channel, on a surface facing the light.
    pub irradiance: [f32; 3],
    pub origin: Option<[f32; 3]>,
    pub light_map: Option<PathBuf>,
    /// Width and height of the window the light map covers, metres.
    pub size: Option<[f32; 2]>,
    pub shadow_map_resolution: Option<u32>,
}

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Object {
    Sphere(SphereObject),
    Box(BoxObject),
    Quad(QuadObject),
    Mesh(MeshObject),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereObject {
    pub center: [f32; 3],
    pub radius: f32,
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxObject {
    pub min: [f32; 3],
    pub max: [f32; 3],
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
}

/// The rectangle `center +- u/2 +- v/2`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuadObject {
    pub center: [f32; 3],
    pub u: [f32; 3],
    pub v: [f32; 3],
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshObject {
    pub file: PathBuf,
    #[serde(default = "one")]
    pub scale: f32,
    #[serde(default)]
    pub translate: [f32; 3],
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}
fn one() -> f32 {
    1.0
}
fn default_albedo() -> [f32; 3] {
    [0.8; 3]
}

/// A scene ready for the kernels: every buffer they read, plus what the host
/// needs to write the image.
#[derive(Debug, Clone)]
pub struct SceneData {
    pub params: FrameParams,
    pub lights: Vec<GpuLight>,
    pub spheres: Vec<GpuSphere>,
    pub triangles: Vec<GpuTriangle>,
    /// One group of consecutive triangles per object, with its bounds.
    pub groups: Vec<GpuTriangleGroup>,
    pub light_map: Vec<Vec4>,
    /// The shafts pass's tables (`F` then `h`), empty in exact mode.
    pub tables: Vec<Vec4>,
    pub exposure: f32,
    /// The settings the shafts pass was configured with.
    pub shafts: Shafts,
}

impl SceneData {
    pub fn width(&self) -> u32 {
        self.params.width
    }
    pub fn height(&self) -> u32 {
        self.params.height
    }
    pub fn pixel_count(&self) -> u32 {
        self.params.width * self.params.height
    }
    pub fn has_geometry(&self) -> bool {
        !self.spheres.is_empty() || !self.triangles.is_empty()
    }
    /// Whether the medium scatters light at all (in any channel).
    pub fn scatters(&self) -> bool {
        self.params.sigma_s.truncate().max_element() > 0.0
    }

    /// Applies shaft settings: validates them, sets the plane depth range, the
    /// table ranges and the lights' `in_view` flags, and fills the tables.
    /// The error names the field within `[shafts]`.
    pub fn configure_shafts(&mut self, s: Shafts) -> Result<()> {
        if !(1..=100_000).contains(&s.planes) {
            bail!(invalid("planes", "a plane count in 1..=100000", s.planes));
        }
        if !(1..=1024).contains(&s.subplanes) {
            bail!(invalid("subplanes", "a sub-plane count in 1..=1024", s.subplanes));
        }
        if !(2..=65536).contains(&s.phase_table_size) {
            bail!(invalid("phase_table_size", "a table size in 2..=65536", s.phase_table_size));
        }
        if !s.h_table_size.iter().all(|n| (2..=4096).contains(n)) {
            bail!(invalid("h_table_size", "two table sizes in 2..=4096", s.h_table_size));
        }
        let p = &mut self.params;
        p.plane_count = s.planes;
        p.subplane_count = s.subplanes;
        p.shaft_mode = match s.mode {
            ShaftMode::Exact => slicelight_shaders::shafts::MODE_EXACT,
            ShaftMode::Tables => slicelight_shaders::shafts::MODE_TABLES,
        };
        p.jitter = s.jitter as u32;
        p.analytic_inverse_square = s.analytic_inverse_square as u32;
        let camera = p.camera_position.truncate();
        let forward = p.camera_forward.truncate();
        // Depth range of the planes: everything that can scatter light toward
        // the camera lies within the bounds of the geometry and the lights.
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        if let Some((a, b)) = bounds(&self.spheres, &self.triangles) {
            lo = a;
            hi = b;
        }
        for l in &self.lights {
            lo = lo.min(l.position.truncate());
            hi = hi.max(l.position.truncate());
        }
        let corners: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new([lo.x, hi.x][i & 1], [lo.y, hi.y][(i >> 1) & 1], [lo.z, hi.z][(i >> 2) & 1]))
            .collect();
        let depths = corners.iter().map(|c| (*c - camera).dot(forward));
        let near = depths.clone().fold(f32::INFINITY, f32::min).max(0.0);
        let far = depths.fold(f32::NEG_INFINITY, f32::max).max(near + 1e-3);
        p.depth_near = near;
        p.depth_far = far;
        // The h table spans every light-to-point and eye-to-point distance
        // in the bounds; the widest view ray (through an image corner) is
        // the longest for a given depth.
        let corner_cos = forward.dot((p.camera_forward + p.camera_right + p.camera_up).truncate().normalize());
        p.h_t_max = far / corner_cos.max(1e-3);
        p.h_s_max = self
            .lights
            .iter()
            .flat_map(|l| corners.iter().map(move |c| (*c - l.position.truncate()).length()))
            .fold(1e-3, f32::max);
        p.phase_table_size = s.phase_table_size;
        p.h_table_s = s.h_table_size[0];
        p.h_table_t = s.h_table_size[1];
        p.quantize_8bit = s.quantize_8bit as u32;
        p.quantize_scale = self.exposure;
        let params = *p;
        for l in &mut self.lights {
            l.in_view = light_in_view(&params, l) as u32;
        }
        self.tables = if s.mode == ShaftMode::Tables {
            let n = params.phase_table_size + params.h_table_s * params.h_table_t;
            let mut t: Vec<Vec4> = (0..n).map(|k| slicelight_shaders::shafts::table_entry(&params, k)).collect();
            if s.quantize_8bit {
                // 8-bit textures: each table scaled to its own maximum.
                let (f, h) = t.split_at_mut(params.phase_table_size as usize);
                quantize_table(f);
                quantize_table(h);
            }
            t
        } else {
            Vec::new()
        };
        self.shafts = s;
        Ok(())
    }

    /// Turns shadow maps off (every light then sees every point), for scenes
    /// with nothing to cast a shadow.
    pub fn without_shadow_maps(&mut self) {
        for l in &mut self.lights {
            l.shadow_resolution = 0;
            l.shadow_offset = 0;
        }
        self.params.shadow_texel_count = 0;
    }
}

/// Reads, validates and converts a scene file. Relative paths inside it are
/// taken relative to the file's folder.
pub fn load(path: &Path) -> Result<SceneData> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read the scene file", path.display()))?;
    let file: SceneFile = toml::from_str(&text).map_err(|e| anyhow!("{}: {}", path.display(), e))?;
    let base = path.parent().unwrap_or(Path::new("."));
    build(&file, base).map_err(|e| anyhow!("{}: {}", path.display(), e))
}

/// One validation failure: the field's path and what was expected.
fn invalid(field: &str, expected: &str, got: impl std::fmt::Debug) -> anyhow::Error {
    anyhow!("{field}: expected {expected}, got {got:?}")
}

fn finite3(field: &str, v: [f32; 3]) -> Result<Vec3> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(Vec3::from(v))
    } else {
        Err(invalid(field, "three finite numbers", v))
    }
}

fn unit3(field: &str, v: [f32; 3]) -> Result<Vec3> {
    let v3 = finite3(field, v)?;
    let len = v3.length();
    if !(len > 1e-12) || !len.is_finite() {
        return Err(invalid(field, "a non-zero direction", v));
    }
    Ok(v3 / len)
}

fn non_negative3(field: &str, v: [f32; 3]) -> Result<Vec3> {
    if v.iter().all(|x| x.is_finite() && *x >= 0.0) {
        Ok(Vec3::from(v))
    } else {
        Err(invalid(field, "three finite non-negative numbers", v))
    }
}

fn albedo(field: &str, v: [f32; 3]) -> Result<Vec4> {
    if v.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)) {
        Ok(Vec3::from(v).extend(0.0))
    } else {
        Err(invalid(field, "three numbers in [0, 1]", v))
    }
}

fn shadow_resolution(field: &str, r: Option<u32>) -> Result<u32> {
    match r {
        None => Ok(DEFAULT_SHADOW_MAP_RESOLUTION),
        Some(r) if (1..=8192).contains(&r) => Ok(r),
        Some(r) => Err(invalid(field, "a resolution in 1..=8192", r)),
    }
}

/// An orthonormal light frame: `z` along the light, `x` to its right, `y`
/// down, seen from behind the light with `up` up (so a light map's first row
/// lands at the top, like a slide projector's). Without an `up`, it is +y, or
/// -z for a light that points straight up or down.
fn light_frame(field: &str, z: Vec3, up: Option<[f32; 3]>) -> Result<(Vec3, Vec3)> {
    let up = match up {
        Some(up) => unit3(&format!("{field}.up"), up)?,
        None if z.y.abs() > 0.999 => Vec3::NEG_Z,
        None => Vec3::Y,
    };
    let x = z.cross(up);
    if x.length() < 1e-4 {
        return Err(invalid(&format!("{field}.up"), "an up vector not parallel to the direction", up));
    }
    let x = x.normalize();
    Ok((x, z.cross(x)))
}

/// Decodes an image into linear-light texels (sRGB transfer undone).
fn load_light_map(field: &str, base: &Path, file: &Path) -> Result<(u32, u32, Vec<Vec4>)> {
    let path = base.join(file);
    let img = image::open(&path).map_err(|e| anyhow!("{field}: cannot read light map '{}': {e}", path.display()))?;
    let img = img.to_rgb32f();
    let texels = img
        .pixels()
        .map(|p| Vec4::new(srgb_to_linear(p[0]), srgb_to_linear(p[1]), srgb_to_linear(p[2]), 1.0))
        .collect();
    Ok((img.width(), img.height(), texels))
}

pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn push_quad(tris: &mut Vec<GpuTriangle>, a: Vec3, b: Vec3, c: Vec3, d: Vec3, albedo: Vec4) {
    tris.push(GpuTriangle { v0: a.extend(1.0), v1: b.extend(1.0), v2: c.extend(1.0), albedo });
    tris.push(GpuTriangle { v0: a.extend(1.0), v1: c.extend(1.0), v2: d.extend(1.0), albedo });
}

fn load_mesh(field: &str, base: &Path, m: &MeshObject, albedo: Vec4, tris: &mut Vec<GpuTriangle>) -> Result<()> {
    let path = base.join(&m.file);
    let (models, _) = tobj::load_obj(&path, &tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() })
        .map_err(|e| anyhow!("{field}.file: cannot read mesh '{}': {e}", path.display()))?;
    let translate = finite3(&format!("{field}.translate"), m.translate)?;
    if !(m.scale.is_finite() && m.scale > 0.0) {
        return Err(invalid(&format!("{field}.scale"), "a positive number", m.scale));
    }
    let before = tris.len();
    for model in models {
        let p = &model.mesh.positions;
        let vertex = |i: u32| Vec3::new(p[3 * i as usize], p[3 * i as usize + 1], p[3 * i as usize + 2]) * m.scale + translate;
        for f in model.mesh.indices.chunks_exact(3) {
            tris.push(GpuTriangle {
                v0: vertex(f[0]).extend(1.0),
                v1: vertex(f[1]).extend(1.0),
                v2: vertex(f[2]).extend(1.0),
                albedo,
            });
        }
    }
    if tris.len() == before {
        return Err(anyhow!("{field}.file: mesh '{}' has no triangles", path.display()));
    }
    Ok(())
}

/// The group of `triangles[first..]` with its bounding box, padded by 1e-4
/// of its extent (plus 1e-6 of its distance from the origin) so that a flat
/// quad's box has a thickness f32 rounding cannot slip through.
fn triangle_group(triangles: &[GpuTriangle], first: usize) -> GpuTriangleGroup {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for t in &triangles[first..] {
        for v in [t.v0, t.v1, t.v2] {
            lo = lo.min(v.truncate());
            hi = hi.max(v.truncate());
        }
    }
    let pad = (hi - lo).max_element() * 1e-4 + 1e-6 * (1.0 + lo.abs().max(hi.abs()).max_element());
    GpuTriangleGroup {
        bounds_min: (lo - Vec3::splat(pad)).extend(0.0),
        bounds_max: (hi + Vec3::splat(pad)).extend(0.0),
        first_triangle: first as u32,
        triangle_count: (triangles.len() - first) as u32,
        _pad: [0; 2],
    }
}

/// Axis-aligned bounds of all geometry (spheres and triangles).
fn bounds(spheres: &[GpuSphere], tris: &[GpuTriangle]) -> Option<(Vec3, Vec3)> {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for s in spheres {
        let c = s.center_radius.truncate();
        lo = lo.min(c - s.center_radius.w);
        hi = hi.max(c + s.center_radius.w);
    }
    for t in tris {
        for v in [t.v0, t.v1, t.v2] {
            lo = lo.min(v.truncate());
            hi = hi.max(v.truncate());
        }
    }
    (lo.x <= hi.x).then_some((lo, hi))
}

/// Validates a parsed scene and converts it to kernel buffers.
pub fn build(file: &SceneFile, base: &Path) -> Result<SceneData> {
    // Camera.
    let cam = &file.camera;
    let [w, h] = cam.resolution;
    if w == 0 || h == 0 {
        bail!(invalid("camera.resolution", "two positive pixel counts", cam.resolution));
    }
    if (w as u64) * (h as u64) > u32::MAX as u64 / 4 {
        bail!(invalid("camera.resolution", "at most 2^30 pixels", cam.resolution));
    }
    if !(cam.vfov_deg > 0.0 && cam.vfov_deg < 180.0) {
        bail!(invalid("camera.vfov_deg", "an angle in (0, 180) degrees", cam.vfov_deg));
    }
    if !(cam.exposure.is_finite() && cam.exposure > 0.0) {
        bail!(invalid("camera.exposure", "a positive number", cam.exposure));
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
    let tan_half = (cam.vfov_deg.to_radians() * 0.5).tan();
    let aspect = w as f32 / h as f32;

    // Medium.
    let m = &file.medium;
    let sigma_s = non_negative3("medium.sigma_s", m.sigma_s)?;
    let sigma_t = non_negative3("medium.sigma_t", m.sigma_t)?;
    if sigma_s.cmpgt(sigma_t).any() {
        bail!(invalid("medium.sigma_s", "no channel above medium.sigma_t (scattering is part of extinction)", m.sigma_s));
    }
    let (phase_kind, phase_g) = match m.phase {
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

    // Objects.
    let mut spheres = Vec::new();
    let mut triangles = Vec::new();
    let mut groups = Vec::new();
    for (i, obj) in file.object.iter().enumerate() {
        let field = format!("object[{i}]");
        let first = triangles.len();
        match obj {
            Object::Sphere(s) => {
                let c = finite3(&format!("{field}.center"), s.center)?;
                if !(s.radius.is_finite() && s.radius > 0.0) {
                    bail!(invalid(&format!("{field}.radius"), "a positive number of metres", s.radius));
                }
                let albedo = albedo(&format!("{field}.albedo"), s.albedo)?;
                spheres.push(GpuSphere { center_radius: c.extend(s.radius), albedo });
            }
            Object::Box(b) => {
                let lo = finite3(&format!("{field}.min"), b.min)?;
                let hi = finite3(&format!("{field}.max"), b.max)?;
                if lo.cmpge(hi).any() {
                    bail!(invalid(&format!("{field}.max"), "every coordinate above min's", b.max));
                }
                let a = albedo(&format!("{field}.albedo"), b.albedo)?;
                let c = |x: bool, y: bool, z: bool| {
                    Vec3::new(if x { hi.x } else { lo.x }, if y { hi.y } else { lo.y }, if z { hi.z } else { lo.z })
                };
                let (f, t) = (false, true);
                push_quad(&mut triangles, c(f, f, f), c(t, f, f), c(t, t, f), c(f, t, f), a);
                push_quad(&mut triangles, c(f, f, t), c(t, f, t), c(t, t, t), c(f, t, t), a);
                push_quad(&mut triangles, c(f, f, f), c(f, t, f), c(f, t, t), c(f, f, t), a);
                push_quad(&mut triangles, c(t, f, f), c(t, t, f), c(t, t, t), c(t, f, t), a);
                push_quad(&mut triangles, c(f, f, f), c(t, f, f), c(t, f, t), c(f, f, t), a);
                push_quad(&mut triangles, c(f, t, f), c(t, t, f), c(t, t, t), c(f, t, t), a);
            }
            Object::Quad(q) => {
                let c = finite3(&format!("{field}.center"), q.center)?;
                let u = finite3(&format!("{field}.u"), q.u)?;
                let v = finite3(&format!("{field}.v"), q.v)?;
                if u.cross(v).length() < 1e-12 {
                    bail!(invalid(&format!("{field}.v"), "an edge not parallel to u and both non-zero", q.v));
                }
                let a = albedo(&format!("{field}.albedo"), q.albedo)?;
                let (hu, hv) = (u * 0.5, v * 0.5);
                push_quad(&mut triangles, c - hu - hv, c + hu - hv, c + hu + hv, c - hu + hv, a);
            }
            Object::Mesh(mesh) => {
                let a = albedo(&format!("{field}.albedo"), mesh.albedo)?;
                load_mesh(&field, base, mesh, a, &mut triangles)?;
            }
        }
        if triangles.len() > first {
            groups.push(triangle_group(&triangles, first));
        }
    }
    let scene_bounds = bounds(&spheres, &triangles);

    // Lights.
    let mut lights = Vec::new();
    let mut light_map = Vec::new();
    let mut shadow_texels = 0u32;
    for (i, s) in file.spotlight.iter().enumerate() {
        let field = format!("spotlight[{i}]");
        let pos = finite3(&format!("{field}.position"), s.position)?;
        let z = unit3(&format!("{field}.direction"), s.direction)?;
        let (x, y) = light_frame(&field, z, s.up)?;
        if !(s.cutoff_deg > 0.0 && s.cutoff_deg < 90.0) {
            bail!(invalid(&format!("{field}.cutoff_deg"), "an angle in (0, 90) degrees", s.cutoff_deg));
        }
        let beam = s.beam_deg.unwrap_or(s.cutoff_deg);
        if !(beam > 0.0 && beam <= s.cutoff_deg) {
            bail!(invalid(&format!("{field}.beam_deg"), "an angle in (0, cutoff_deg] degrees", beam));
        }
        let power = non_negative3(&format!("{field}.intensity"), s.intensity)?;
        let res = shadow_resolution(&format!("{field}.shadow_map_resolution"), s.shadow_map_resolution)?;
        let mut light = GpuLight {
            position: pos.extend(1.0),
            axis_x: x.extend(0.0),
            axis_y: y.extend(0.0),
            axis_z: z.extend(0.0),
            power: power.extend(0.0),
            kind: LIGHT_SPOT,
            cutoff: s.cutoff_deg.to_radians(),
            beam: beam.to_radians(),
            tan_cutoff: s.cutoff_deg.to_radians().tan(),
            shadow_offset: shadow_texels,
            shadow_resolution: res,
            ..Default::default()
        };
        if let Some(file) = &s.light_map {
            let (mw, mh, texels) = load_light_map(&format!("{field}.light_map"), base, file)?;
            light.light_map_offset = light_map.len() as u32;
            light.light_map_width = mw;
            light.light_map_height = mh;
            light_map.extend(texels);
        }
        shadow_texels = shadow_texels
            .checked_add(res * res)
            .ok_or_else(|| invalid(&format!("{field}.shadow_map_resolution"), "fewer shadow-map texels in all", res))?;
        lights.push(light);
    }
    for (i, d) in file.directional_light.iter().enumerate() {
        let field = format!("directional_light[{i}]");
        let z = unit3(&format!("{field}.direction"), d.direction)?;
        let (x, y) = light_frame(&field, z, d.up)?;
        let power = non_negative3(&format!("{field}.irradiance"), d.irradiance)?;
        let res = shadow_resolution(&format!("{field}.shadow_map_resolution"), d.shadow_map_resolution)?;
        // Without an explicit entry plane, the light enters the medium where
        // it first meets the scene's bounding sphere.
        let (center, radius) = match scene_bounds {
            Some((lo, hi)) => ((lo + hi) * 0.5, ((hi - lo) * 0.5).length().max(1e-3)),
            None => (Vec3::ZERO, 1.0),
        };
        let origin = match d.origin {
            Some(o) => finite3(&format!("{field}.origin"), o)?,
            None => center - z * radius,
        };
        let mut light = GpuLight {
            position: origin.extend(1.0),
            axis_x: x.extend(0.0),
            axis_y: y.extend(0.0),
            axis_z: z.extend(0.0),
            power: power.extend(0.0),
            kind: LIGHT_DIRECTIONAL,
            half_extent_x: radius,
            half_extent_y: radius,
            shadow_offset: shadow_texels,
            shadow_resolution: res,
            ..Default::default()
        };
        if let Some(size) = d.size {
            if !(size.iter().all(|s| s.is_finite() && *s > 0.0)) {
                bail!(invalid(&format!("{field}.size"), "two positive sizes in metres", size));
            }
            light.half_extent_x = size[0] * 0.5;
            light.half_extent_y = size[1] * 0.5;
            light.bounded = 1;
        }
        if let Some(file) = &d.light_map {
            if d.size.is_none() {
                bail!(invalid(&format!("{field}.size"), "the window's [width, height] in metres when a light_map is given", "nothing"));
            }
            let (mw, mh, texels) = load_light_map(&format!("{field}.light_map"), base, file)?;
            light.light_map_offset = light_map.len() as u32;
            light.light_map_width = mw;
            light.light_map_height = mh;
            light_map.extend(texels);
        }
        shadow_texels = shadow_texels
            .checked_add(res * res)
            .ok_or_else(|| invalid(&format!("{field}.shadow_map_resolution"), "fewer shadow-map texels in all", res))?;
        lights.push(light);
    }

    let params = FrameParams {
        camera_position: position.extend(1.0),
        camera_forward: forward.extend(0.0),
        camera_right: (right * tan_half * aspect).extend(0.0),
        camera_up: (true_up * tan_half).extend(0.0),
        sigma_t: sigma_t.extend(0.0),
        sigma_s: sigma_s.extend(0.0),
        width: w,
        height: h,
        light_count: lights.len() as u32,
        sphere_count: spheres.len() as u32,
        triangle_count: triangles.len() as u32,
        group_count: groups.len() as u32,
        shadow_texel_count: shadow_texels,
        phase_kind,
        phase_g,
        band_start: 0,
        band_pixels: w * h,
        // Filled in by `configure_shafts`.
        ..Default::default()
    };
    let mut data = SceneData {
        params,
        lights,
        spheres,
        triangles,
        groups,
        light_map,
        tables: Vec::new(),
        exposure: cam.exposure,
        shafts: file.shafts,
    };
    if !data.has_geometry() {
        data.without_shadow_maps();
    }
    data.configure_shafts(file.shafts).map_err(|e| anyhow!("shafts.{e}"))?;
    Ok(data)
}

/// Rounds a table to 256 levels of its own largest entry (per channel).
fn quantize_table(t: &mut [Vec4]) {
    let max = t.iter().fold(Vec4::ZERO, |m, v| m.max(*v)).max(Vec4::splat(1e-30));
    for v in t {
        *v = ((*v / max) * 255.0).round() / 255.0 * max;
    }
}

/// Whether a light's volume can be seen: the part of a spotlight's cone
/// within reach of the view frustum (cut at the far end of the plane range) is
/// bounded by a sphere, which is tested against the frustum's four side planes.
/// Conservative: a light that is out of view may be kept, a light in view is
/// never dropped. Directional lights are always kept.
fn light_in_view(p: &FrameParams, l: &GpuLight) -> bool {
    if l.kind == LIGHT_DIRECTIONAL {
        return true;
    }
    let camera = p.camera_position.truncate();
    let (f, r, u) = (p.camera_forward.truncate(), p.camera_right.truncate(), p.camera_up.truncate());
    let apex = l.position.truncate();
    let axis = l.axis_z.truncate();
    // Every point the planes sample lies in the frustum up to depth_far, the
    // convex hull of the camera and the four far corners.
    let far_corners = [f + r + u, f + r - u, f - r + u, f - r - u].map(|c| camera + c * p.depth_far);
    let reach = far_corners.iter().map(|c| (*c - apex).length()).fold((camera - apex).length(), f32::max);
    // A ball around the spherical sector {angle <= cutoff, |x - apex| <= reach}.
    let k = 0.5 * reach;
    let (sin, cos) = l.cutoff.sin_cos();
    let rim = ((reach * cos - k).powi(2) + (reach * sin).powi(2)).sqrt();
    let radius = k.max(rim).max(reach - k);
    let center = apex + axis * k;
    // Side planes through the camera, normals turned to point inward, and
    // the plane through the camera facing forward (nothing behind the eye
    // is seen).
    let sides = [(f - r).cross(u), (f + r).cross(u), (f - u).cross(r), (f + u).cross(r)];
    let in_front = (center - camera).dot(f.normalize()) >= -radius;
    in_front
        && sides.iter().all(|n| {
            let n = n.normalize();
            let n = if n.dot(f) < 0.0 { -n } else { n };
            (center - camera).dot(n) >= -radius
        })
}
