//! The sea passes (kernels: `shader-crate/src/sea/`): the radiance map
//! and the scattering maps (order 2, once per frame), and the four
//! per-pixel terms, each its own layer: `sea.reflection`, `sea.order1`,
//! `sea.order2`, `sea.bottom`; their settings (the scene's `[sea]`), and the
//! automatic choice of `n_z` and `n_d` by the paper's 1/255 rule (6.1).
//! Over a varying bottom, `table.rs` adds the depth table (5.4).

pub mod bench;
pub mod bench_under;
pub mod bench_waves;
pub mod glass;
pub mod reference;
pub mod table;
pub mod waves;

use anyhow::{bail, ensure, Result};
use glam::{Vec3, Vec4};
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::Deserialize;
use slicelight_shaders::glass::Glass;
use slicelight_shaders::optics;
use slicelight_shaders::sea::air::{Above, GlassInAir};
use slicelight_shaders::sea::caustics::{
    caustic_points, caustic_ray, caustic_triangle, caustic_triangles, shaft_map_len, shaft_mip_texel,
};
use slicelight_shaders::sea::under::Sunlit;
use slicelight_shaders::sea::{
    accumulate_planes, accumulated_map_texel, bottom_pixel, forward_fraction, layer_params, map_coords, order1_pixel,
    order2_pixel, plane_reach, radiance_map_len, radiance_map_texel, reflection_pixel, scattering_map_lookup,
    scattering_map_texel, scattering_source, set_size, sun_azimuth_frame, CloudShadow, SeaParams, DEEP, WAVES_FLAT,
    WAVES_NORMAL_MAP,
};
use slicelight_shaders::types::{CommonParams, GBufferTexel};

use crate::passes::*;
use crate::scene::validate::positive;
use crate::sea::table::SEA_BOTTOM_CORRECTION;
use crate::sky::{SKY_PARAMS, SKY_TRANSMITTANCE, SKY_VIEW};

/// The family's passes, in the order they run (see `passes::FAMILIES`).
pub static PASSES: &[&dyn Pass] = &[
    &SeaRadianceMap,
    &SeaScatteringMaps,
    &SeaAccumulatedMap,
    &SeaCausticRays,
    &SeaCaustics,
    &SeaShafts,
    &table::SeaTableSamples,
    &table::SeaDepthTable,
    &table::SeaBottomCorrection,
    &SeaSurface,
    &SeaWater,
    &SeaReflection,
    &SeaShaftSamples,
    &SeaOrder1,
    &SeaOrder2,
    &SeaBottom,
    &glass::SeaGlass,
    &glass::SeaGlassAir,
];

/// The family, as `passes::FAMILIES` registers it.
pub static FAMILY: Family = Family { name: "sea", passes: PASSES, kernels: &[], bench: Some(&bench::SeaSweep) };
use crate::cpu::for_each_invocation;
use crate::scene::{invalid, validate, SceneData};

pub static SEA_PARAMS: Resource =
    Resource { binding: 19, name: "sea parameters", kind: ResourceKind::Scene(|s| bytemuck::bytes_of(&s.sea.params)) };
/// The waves' slope-moment pyramid (`slicelight_shaders::sea::surface`; two
/// zero `Vec4`s for a flat sea).
pub static SEA_WAVES: Resource =
    Resource { binding: 20, name: "wave slopes", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.sea.waves)) };
/// Order-1 radiance (rgb) per plane and direction of the sun's set (eq. 7).
pub static SEA_RADIANCE_MAP: Resource =
    Resource { binding: 21, name: "sea radiance map", kind: ResourceKind::Frame(|s| s.sea.radiance_map_texels() * 16) };
/// Order-2 source (rgb) per plane and direction toward the eye (eq. 8).
pub static SEA_SCATTERING_MAPS: Resource = Resource {
    binding: 22,
    name: "sea scattering maps",
    kind: ResourceKind::Frame(|s| s.sea.scattering_map_texels() * 16),
};
/// Order-2 radiance below the surface (rgb) per direction toward the eye:
/// the scattering maps accumulated over the planes.
pub static SEA_ACCUMULATED_MAP: Resource = Resource {
    binding: 27,
    name: "sea accumulated map",
    kind: ResourceKind::Frame(|s| s.sea.accumulated_map_texels() * 16),
};
/// The waves' caustic map on a flat bottom (`slicelight_shaders::sea::caustics`):
/// fixed-point words, rgb per texel of the wave tile.
pub static SEA_CAUSTICS: Resource =
    Resource { binding: 77, name: "sea caustics", kind: ResourceKind::Frame(|s| s.sea.caustic_words() * 4) };
/// The sun refracted at every grid point of the caustic maps' meshes
/// (`sea.caustic_rays`): two `Vec4`s a point, where it lands and its flux.
pub static SEA_CAUSTIC_RAYS: Resource =
    Resource { binding: 89, name: "sea caustic rays", kind: ResourceKind::Frame(|s| s.sea.caustic_ray_bytes()) };
/// The shaft planes' caustics and their mips (`sea.shafts`), rgb per texel.
pub static SEA_SHAFTS: Resource =
    Resource { binding: 78, name: "sea shaft maps", kind: ResourceKind::Frame(|s| s.sea.shaft_texels() * 16) };
/// A varying bottom's depth grid (one 0 for a flat bottom).
pub static SEA_BOTTOM_GRID: Resource = Resource {
    binding: 28,
    name: "sea bottom depths",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.sea.bottom)),
};
/// What the terms below the surface need of it, per pixel (`sea.surface`):
/// the direction light leaves the water toward the eye (xyz) and the
/// transmission `(1 - R)/n^2` (w); zero where the sea is not seen.
pub static SEA_SURFACE: Resource =
    Resource { binding: 68, name: "sea surface", kind: ResourceKind::PerPixel { blank: no_radiance } };
pub static SEA_REFLECTION: Resource =
    Resource { binding: 23, name: "sea reflection", kind: ResourceKind::PerPixel { blank: no_radiance } };
/// `sea.shaft_samples`, two `Vec4`s a pixel: the shafts' ratio to the flat
/// beam (rgb) and the length gathered over (w), and the shade signature
/// (xy), at every `shaft_stride`-th pixel; w = -1 elsewhere
/// (`slicelight_shaders::sea::under::shaft_sample`).
pub static SEA_SHAFT_SAMPLES: Resource =
    Resource { binding: 88, name: "sea shaft samples", kind: ResourceKind::PerPixel { blank: no_shaft_sample } };
fn no_shaft_sample() -> Vec<u8> {
    bytemuck::cast_slice(&[Vec4::new(0.0, 0.0, 0.0, -1.0), Vec4::ZERO]).to_vec()
}
pub static SEA_ORDER1: Resource =
    Resource { binding: 24, name: "sea order 1", kind: ResourceKind::PerPixel { blank: no_radiance } };
pub static SEA_ORDER2: Resource =
    Resource { binding: 25, name: "sea order 2", kind: ResourceKind::PerPixel { blank: no_radiance } };
pub static SEA_BOTTOM: Resource =
    Resource { binding: 26, name: "sea bottom", kind: ResourceKind::PerPixel { blank: no_radiance } };

/// The scene's `[sea]` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Height of the surface (scene y), m.
    #[serde(default)]
    pub level_m: f32,
    /// Depth of a flat bottom below the surface, m; none: no bottom (or `bottom`).
    pub depth_m: Option<f32>,
    /// A varying bottom (instead of `depth_m`).
    pub bottom: Option<Bottom>,
    /// Bottom depths the order-2 maps are built for over a varying bottom.
    #[serde(default = "depth_layers")]
    pub depth_layers: u32,
    /// Over a varying bottom, the depth table's samples across the image
    /// (section 5.4; rows by the image's aspect); 0: none, the water under
    /// each pixel taken as flat.
    #[serde(default = "depth_table")]
    pub depth_table: u32,
    /// Lambertian albedo of the bottom.
    #[serde(default = "sand")]
    pub bottom_albedo: [f32; 3],
    /// Absorption coefficient `a`, 1/m per channel.
    pub absorption: Option<[f32; 3]>,
    /// Scattering coefficient `b`, 1/m per channel.
    pub scattering: Option<[f32; 3]>,
    /// A preset water for `absorption` and `scattering` (either given
    /// alongside overrides the preset's).
    pub water: Option<Water>,
    /// Henyey-Greenstein `g` of the water's volume scattering function.
    #[serde(default = "petzold_g")]
    pub g: f32,
    /// Index of refraction of the water.
    #[serde(default = "water_ior")]
    pub ior: f32,
    /// Single scattering: the exact order-1 integral or eq. 5 as printed.
    #[serde(default)]
    pub single: Single,
    /// Whether to compute second-order scattering (the scattering maps).
    #[serde(default = "yes")]
    pub second_order: bool,
    /// Whether the waves focus the sunlight on a flat bottom (`caustics`).
    #[serde(default = "yes")]
    pub caustics: bool,
    /// Whether the waves' focusing is traced into the water on the shaft
    /// planes: for an eye under the water, its light shafts and the caustic
    /// on objects and a varying bottom; for an eye above it, the caustic on
    /// objects under the surface and on a varying bottom.
    #[serde(default = "yes")]
    pub shafts: bool,
    /// Horizontal planes the shafts' caustic is built on, surface to
    /// `shaft_depth_m`.
    #[serde(default = "shaft_planes")]
    pub shaft_planes: u32,
    /// Depth of the deepest shaft plane, m; none: the bottom's depth or
    /// 20 m, whichever is less (below it the caustic's mean).
    pub shaft_depth_m: Option<f32>,
    /// Intervals along each view ray the shafts are gathered over.
    #[serde(default = "shaft_steps")]
    pub shaft_steps: u32,
    /// Under the water, the shafts (and objects' shadows in the water) are
    /// gathered along every `shaft_stride`-th pixel's ray each way and
    /// interpolated between rays alike in length; 1: every pixel.
    #[serde(default = "shaft_stride")]
    pub shaft_stride: u32,
    /// Sampling planes `n_z`; none: chosen by the 1/255 rule.
    pub planes: Option<u32>,
    /// Sampling directions `n_d` (three sets of `k^2`, `k` even: 12, 48, 108,
    /// 192, 300, ...); none: the 1/255 rule.
    pub directions: Option<u32>,
    /// Scattering map size: azimuths x zenith angles of the direction toward the eye.
    #[serde(default = "map_size")]
    pub scattering_map: [u32; 2],
    #[serde(default)]
    pub waves: Waves,
}

fn depth_layers() -> u32 {
    12
}
fn shaft_planes() -> u32 {
    12
}
fn shaft_steps() -> u32 {
    SHAFT_STEPS
}
fn shaft_stride() -> u32 {
    SHAFT_STRIDE
}
/// The default stride of the shafts' samples under the water (docs/sea.md,
/// "Caustic light shafts": the bench's time against error).
pub const SHAFT_STRIDE: u32 = 4;
/// The default intervals of the shafts along a view ray (docs/sea.md,
/// "Caustic light shafts": the bench's time against error).
pub const SHAFT_STEPS: u32 = 16;
/// The deepest default shaft plane, m.
pub const SHAFT_DEPTH: f32 = 20.0;
fn depth_table() -> u32 {
    32
}
/// The depth table's rows for `columns` samples across the image: by the
/// image's aspect, at least 2 (0 without a table).
pub fn table_rows(columns: u32, common: &CommonParams) -> u32 {
    if columns == 0 {
        return 0;
    }
    ((columns as f32 * common.height as f32 / common.width as f32).round() as u32).max(2)
}
/// The largest depth table a scene may ask for (one buffer, f32 entries).
pub const MAX_TABLE_BYTES: u64 = 1 << 30;
fn sand() -> [f32; 3] {
    [0.6, 0.55, 0.4]
}
fn petzold_g() -> f32 {
    0.924
}
fn water_ior() -> f32 {
    1.333
}
fn yes() -> bool {
    true
}
fn map_size() -> [u32; 2] {
    [32, 32]
}

/// The preset waters of scenes/README.md ("Water presets"): absorption
/// and scattering at 650, 550, 450 nm, 1/m.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Water {
    ClearOcean,
    Tropical,
    Coastal,
}

impl Water {
    pub fn coefficients(self) -> ([f32; 3], [f32; 3]) {
        match self {
            Water::ClearOcean => ([0.343, 0.0585, 0.0180], [0.0369, 0.0489, 0.0620]),
            Water::Tropical => ([0.345, 0.0620, 0.0300], [0.0950, 0.1130, 0.1400]),
            Water::Coastal => ([0.380, 0.120, 0.280], [0.390, 0.460, 0.560]),
        }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Single {
    /// The order-1 integral with the extinction `c`.
    #[default]
    Exact,
    /// Eq. 5 as printed: `c (1 - omega_0 c_f)` in place of `c`.
    PaperEq5,
}

/// `bottom = { kind = ... }` of `[sea]`: a height field.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Bottom {
    /// A sloping shore: the depth grows by `slope` metres per metre along
    /// `direction_deg` (from +x toward +z) from the shoreline, which passes
    /// `offset_m` from the origin, between `shallow_m` and `deep_m`; sampled
    /// on a `resolution`^2 grid over `extent_m` around `center_m`.
    Shore {
        slope: f32,
        shallow_m: f32,
        deep_m: f32,
        #[serde(default)]
        direction_deg: f32,
        #[serde(default)]
        offset_m: f32,
        #[serde(default = "shore_extent")]
        extent_m: f32,
        #[serde(default)]
        center_m: [f32; 2],
        #[serde(default = "shore_grid")]
        resolution: u32,
    },
    /// A grey image over `size_m` (x by z) centred on `center_m`: white is
    /// `shallow_m` deep, black `deep_m`; path relative to the scene file.
    Image {
        path: std::path::PathBuf,
        size_m: [f32; 2],
        #[serde(default)]
        center_m: [f32; 2],
        shallow_m: f32,
        deep_m: f32,
    },
}

fn shore_extent() -> f32 {
    400.0
}
fn shore_grid() -> u32 {
    512
}

/// A bottom's depth grid: the samples (row by row in z), the first
/// sample's (x, z), the spacing, the grid's size, and the depth range.
struct Grid {
    depths: Vec<f32>,
    origin: [f32; 2],
    spacing: f32,
    size: [u32; 2],
    shallow: f32,
    deep: f32,
}

fn depth_range(shallow: f32, deep: f32) -> Result<(f32, f32)> {
    if !(shallow.is_finite() && shallow >= 0.01) {
        bail!(invalid("sea.bottom.shallow_m", "a depth of at least 0.01 m", shallow));
    }
    if !(deep.is_finite() && deep > shallow && deep <= 1e6) {
        bail!(invalid("sea.bottom.deep_m", "a depth above shallow_m, at most 1e6 m", deep));
    }
    Ok((shallow, deep))
}

impl Bottom {
    fn grid(&self, base: &std::path::Path) -> Result<Grid> {
        match self {
            Bottom::Shore { slope, shallow_m, deep_m, direction_deg, offset_m, extent_m, center_m, resolution } => {
                let (shallow, deep) = depth_range(*shallow_m, *deep_m)?;
                if !(slope.is_finite() && *slope > 0.0) {
                    bail!(invalid("sea.bottom.slope", "a positive slope (m of depth per m)", slope));
                }
                if !(extent_m.is_finite() && *extent_m > 0.0 && *extent_m <= 1e6) {
                    bail!(invalid("sea.bottom.extent_m", "a size in (0, 1e6] m", extent_m));
                }
                if !(2..=4096).contains(resolution) {
                    bail!(invalid("sea.bottom.resolution", "a grid size in 2..=4096", resolution));
                }
                let n = *resolution;
                let spacing = extent_m / (n - 1) as f32;
                let origin = [center_m[0] - 0.5 * extent_m, center_m[1] - 0.5 * extent_m];
                let (dx, dz) = (direction_deg.to_radians().cos(), direction_deg.to_radians().sin());
                let depths = (0..n * n)
                    .map(|i| {
                        let (x, z) = (origin[0] + (i % n) as f32 * spacing, origin[1] + (i / n) as f32 * spacing);
                        (shallow + slope * (x * dx + z * dz - offset_m)).clamp(shallow, deep)
                    })
                    .collect();
                Ok(Grid { depths, origin, spacing, size: [n, n], shallow, deep })
            }
            Bottom::Image { path, size_m, center_m, shallow_m, deep_m } => {
                let (shallow, deep) = depth_range(*shallow_m, *deep_m)?;
                let file = base.join(path);
                crate::output::regular_file("sea.bottom.path", &file, crate::output::MAX_IMAGE_BYTES)?;
                let img = image::open(&file)
                    .map_err(|e| anyhow::anyhow!("sea.bottom.path: cannot read '{}': {e}", file.display()))?
                    .to_luma32f();
                let (w, h) = img.dimensions();
                if w < 2 || h < 2 {
                    bail!(invalid("sea.bottom.path", "an image of at least 2x2 pixels", (w, h)));
                }
                if !(size_m.iter().all(|v| v.is_finite() && *v > 0.0)) {
                    bail!(invalid("sea.bottom.size_m", "two positive sizes in m", size_m));
                }
                // Square cells: the image's x spacing.
                let spacing = size_m[0] / (w - 1) as f32;
                let origin = [center_m[0] - 0.5 * size_m[0], center_m[1] - 0.5 * (h - 1) as f32 * spacing];
                let depths = img.pixels().map(|p| deep - p[0].clamp(0.0, 1.0) * (deep - shallow)).collect();
                Ok(Grid { depths, origin, spacing, size: [w, h], shallow, deep })
            }
        }
    }
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Waves {
    #[default]
    Flat,
    /// A statistical wave spectrum on an FFT grid (Tessendorf).
    Spectrum(crate::sea::waves::Spectrum),
}

/// The sea's state for one scene.
#[derive(Debug, Clone, Default)]
pub struct Setup {
    pub enabled: bool,
    pub params: SeaParams,
    /// The waves' slope-moment pyramid (`slicelight_shaders::sea::surface`).
    pub waves: Vec<Vec4>,
    /// A varying bottom's depth grid (one 0 for a flat bottom).
    pub bottom: Vec<f32>,
    pub second_order: bool,
    pub single: Single,
    /// How `n_z` and `n_d` were chosen, for the plan.
    pub sampling: String,
}

impl Setup {
    pub fn radiance_map_texels(&self) -> u64 {
        if self.enabled && self.second_order {
            self.params.layers as u64 * radiance_map_len(&self.params) as u64
        } else {
            0
        }
    }
    pub fn accumulated_map_texels(&self) -> u64 {
        if self.enabled && self.second_order {
            slicelight_shaders::sea::accumulated_blocks(&self.params) as u64
                * self.params.map_width as u64
                * self.params.map_height as u64
        } else {
            0
        }
    }
    /// Texels of the shaft maps (0 without shafts).
    pub fn shaft_texels(&self) -> u64 {
        if self.enabled {
            shaft_map_len(&self.params) as u64
        } else {
            0
        }
    }
    /// Bytes of the refracted rays the caustic maps are drawn from (0
    /// without a map).
    pub fn caustic_ray_bytes(&self) -> u64 {
        if self.enabled && caustic_triangles(&self.params) > 0 {
            caustic_points(&self.params) as u64 * 32
        } else {
            0
        }
    }
    /// Words of the waves' caustic maps (0 without one).
    pub fn caustic_words(&self) -> u64 {
        if self.enabled && caustic_triangles(&self.params) > 0 {
            slicelight_shaders::scatter::words_for(slicelight_shaders::sea::caustics::caustic_bins(&self.params)) as u64
        } else {
            0
        }
    }
    pub fn scattering_map_texels(&self) -> u64 {
        if self.enabled && self.second_order {
            self.params.layers as u64
                * self.params.planes as u64
                * self.params.map_width as u64
                * self.params.map_height as u64
        } else {
            0
        }
    }
}

/// The threshold of the 1/255 rule (section 6.1): successive counts whose
/// order-2 radiance differs by less than this fraction of its peak.
pub const EPSILON: f32 = 1.0 / 255.0;

/// Upward directions in the water (toward the eye) that the 1/255 rule
/// checks: the nadir view, and 20 and 45 degrees toward and away from the
/// sun (the refracted view cone reaches 48.6 degrees).
pub fn rule_views(p: &SeaParams) -> Vec<Vec3> {
    let (t, _) = sun_azimuth_frame(p);
    let mut views = vec![Vec3::Y];
    for zenith in [20f32, 45.0] {
        let z = zenith.to_radians();
        views.push((t * z.sin() + Vec3::Y * z.cos()).normalize());
        views.push((-t * z.sin() + Vec3::Y * z.cos()).normalize());
    }
    views
}

/// The order-2 radiance below the surface toward `views`, with the radiance
/// map and the sources computed directly (no scattering-map interpolation):
/// what the 1/255 rule compares.
pub fn order2_at(p: &SeaParams, views: &[Vec3]) -> Vec<Vec3> {
    let p = &SeaParams { layers: 1, ..*p };
    let map: Vec<Vec4> = (0..radiance_map_len(p)).map(|i| radiance_map_texel(i, p)).collect();
    views
        .iter()
        .map(|&v| {
            let sources: Vec<Vec4> = (0..p.planes).map(|k| scattering_source(p, k, v, &map, 0).extend(0.0)).collect();
            accumulate_planes(p, v, &sources, 0, 1)
        })
        .collect()
}

/// The order-2 radiance below the surface toward `views` as the passes
/// compute it (radiance map, scattering maps, accumulated map, lookup), on
/// the CPU: what the accuracy tests and the bench measure.
pub fn order2_by_maps(p: &SeaParams, views: &[Vec3]) -> Vec<Vec3> {
    let p = &SeaParams { layers: 1, ..*p };
    let radiance: Vec<Vec4> = (0..radiance_map_len(p)).into_par_iter().map(|i| radiance_map_texel(i, p)).collect();
    let texels = p.map_width * p.map_height;
    let maps: Vec<Vec4> =
        (0..p.planes * texels).into_par_iter().map(|i| scattering_map_texel(i, p, &radiance)).collect();
    let accumulated: Vec<Vec4> = (0..texels).into_par_iter().map(|i| accumulated_map_texel(i, p, &maps)).collect();
    views.iter().map(|&v| scattering_map_lookup(p, &accumulated, 0, map_coords(p, v))).collect()
}

/// The largest difference between two sets of radiances, per channel over
/// that channel's peak (so that a dim channel, the red of clear water, is
/// held to the same relative accuracy as the bright ones).
pub fn max_difference(a: &[Vec3], b: &[Vec3]) -> f32 {
    let peak = b.iter().chain(a).fold(Vec3::ZERO, |m, v| m.max(*v));
    let worst = a.iter().zip(b).fold(Vec3::ZERO, |m, (x, y)| m.max((*x - *y).abs()));
    let relative = Vec3::select(peak.cmpgt(Vec3::ZERO), worst / peak.max(Vec3::splat(1e-30)), Vec3::ZERO);
    relative.max_element()
}

/// The 1/255 rule for `n_z` (section 6.1): the smallest count whose
/// order-2 radiance differs from that with twice the planes by less than
/// `EPSILON` of its peak, per channel. The paper compares `n` with `n + 1`;
/// with planes graded and the source integrated against its exponential,
/// the error falls as `n^-2` and the step from `n` to `n + 1` is about
/// `2/n` of the error, so that comparison would stop at an error of `n/2`
/// times the threshold; the step to `2n` is 3/4 of the error, so this rule
/// bounds the error itself. Returns the count and the differences on the
/// way (the paper's Fig. 7, with `n + 1` in the bench).
pub fn choose_planes(p: &SeaParams) -> (u32, Vec<(u32, f32)>) {
    let views = rule_views(p);
    let at = |n: u32| order2_at(&SeaParams { planes: n, ..*p }, &views);
    let mut curve = Vec::new();
    for n in 2..=64 {
        let d = max_difference(&at(n), &at(2 * n));
        curve.push((n, d));
        if d < EPSILON {
            return (n, curve);
        }
    }
    (64, curve)
}

/// The 1/255 rule for `n_d = 3 k^2`, `k` even (the paper's Fig. 8), as
/// `choose_planes`, comparing `k` with `2k`, with `p.planes` planes.
pub fn choose_directions(p: &SeaParams) -> (u32, Vec<(u32, f32)>) {
    let views = rule_views(p);
    let at = |k: u32| order2_at(&SeaParams { polar: k, azimuths: k, ..*p }, &views);
    let mut curve = Vec::new();
    for k in (2..=32).step_by(2) {
        let d = max_difference(&at(k), &at(2 * k));
        curve.push((3 * k * k, d));
        if d < EPSILON {
            return (k, curve);
        }
    }
    (32, curve)
}

/// Validates `[sea]` against the sky's sun and the camera's height, and
/// returns the sea's setup at the scene's `time` (s: the waves' phases);
/// the error names the field under `sea.`. `lowest`: the lowest height
/// (m) the scene's objects reach, if it has any (objects under the water
/// take the waves' caustic from the shaft planes).
pub fn configure(
    s: &Settings,
    sky: &crate::sky::Setup,
    common: &CommonParams,
    base: &std::path::Path,
    time: f64,
    lowest: Option<f32>,
) -> Result<Setup> {
    let camera_y = common.camera_position.y;
    if !sky.enabled {
        bail!(invalid("sea", "a scene with a [sky] (the sea's sun and the sky it reflects)", "no [sky]"));
    }
    let most = crate::scene::validate::MAX_COORDINATE;
    if !(s.level_m.is_finite() && s.level_m.abs() <= most) {
        bail!(invalid("sea.level_m", &format!("a height in m within +-{most:e}"), s.level_m));
    }
    // An eye at the level or below it is under water (`under`).
    let camera_depth = (s.level_m - camera_y).max(0.0);
    let underwater = camera_y <= s.level_m;
    let (grid, depth) = bottom_of(s, base, underwater.then_some(camera_depth))?;
    let albedo = validate::albedo("sea.bottom_albedo", s.bottom_albedo)?;
    let (a, b, n) = water_of(s)?;
    let (size, polar) = sampling_of(s)?;
    let WaveMap {
        kind: waves_kind,
        slopes: waves,
        resolution: wave_resolution,
        size: wave_size,
        roughness,
        filter: wave_filter,
    } = wave_map(&s.waves, time)?;

    let RefractedSun { sun, cos_ii, in_water, cos_io, beam, t_i } = refracted_sun(sky, n);
    let c = a + b;
    let albedo0 = Vec3::select(c.cmpgt(Vec3::ZERO), b / c.max(Vec3::splat(1e-30)), Vec3::ZERO);
    let order1_c = match s.single {
        Single::Exact => c,
        Single::PaperEq5 => c * (Vec3::ONE - albedo0 * forward_fraction(s.g)),
    };
    let plane_depth = plane_reach(c, depth);
    let mut params = SeaParams {
        sun_direction: sun.extend(cos_ii),
        sun_in_water: in_water.extend(cos_io),
        beam_irradiance: beam.extend(t_i),
        scattering: b.extend(s.g),
        extinction: c.extend(n),
        order1_extinction: order1_c.extend(0.0),
        bottom_albedo: albedo,
        plane_depth: plane_depth.extend(0.0),
        level: s.level_m,
        depth,
        planes: s.planes.unwrap_or(16),
        polar: polar.unwrap_or(8),
        azimuths: polar.unwrap_or(8),
        map_width: size[0],
        // Under water the maps hold every direction toward the eye, not
        // only upward ones: twice the rows, at the same spacing.
        map_height: if underwater { 2 * size[1] - 1 } else { size[1] },
        waves: waves_kind,
        wave_resolution,
        wave_size,
        bottom_grid: match &grid {
            Some(g) => Vec4::new(g.origin[0], g.origin[1], g.spacing, g.deep),
            None => Vec4::ZERO,
        },
        bottom_nx: grid.as_ref().map_or(0, |g| g.size[0]),
        bottom_nz: grid.as_ref().map_or(0, |g| g.size[1]),
        layers: if grid.is_some() { s.depth_layers } else { 1 },
        shallow: grid.as_ref().map_or(0.0, |g| g.shallow),
        // The depth table corrects views from above the water.
        table_width: if grid.is_some() && s.second_order && !underwater { s.depth_table } else { 0 },
        table_height: if grid.is_some() && s.second_order && !underwater {
            table_rows(s.depth_table, common)
        } else {
            0
        },
        roughness,
        sun_light: 0,
        wave_filter,
        camera_depth,
        underwater: underwater as u32,
        caustics: 0,
        shaft_planes: 0,
        shaft_depth: 0.0,
        shaft_level: 0,
        shaft_steps: 0,
        second_order: (s.second_order) as u32,
        shaft_stride: 1,
        pad3: 0,
    };
    if underwater {
        check_eye_above_bottom(&params, grid.as_ref(), common)?;
    }
    // The waves' caustic: over a flat bottom that exists.
    params.caustics = (s.caustics && waves_kind == WAVES_NORMAL_MAP && grid.is_none() && depth < DEEP) as u32;
    shafts_of(s, &mut params, lowest.is_some_and(|y| y < s.level_m))?;
    let sampling = if s.second_order { choose_sampling(&mut params, s.planes, polar) } else { Vec::new() };
    check_table_size(&params, s.depth_table)?;
    Ok(Setup {
        enabled: true,
        params,
        waves,
        bottom: grid.map_or(vec![0.0], |g| g.depths),
        second_order: s.second_order,
        single: s.single,
        sampling: sampling.join(", "),
    })
}

/// `[sea]`'s caustic light shafts: `shaft_planes` planes from the surface
/// to `shaft_depth_m` (default: the bottom's depth, at most
/// `SHAFT_DEPTH`), on the wave pyramid's level whose side is at most
/// `MAX_SHAFT_RESOLUTION` texels, holding the waves' caustic at their
/// depths. Built under waves for an eye under the water (its shafts, and
/// the caustic on objects and a varying bottom there) and for an eye above
/// it where objects reach under the surface (`objects_below`) or the
/// bottom varies (the caustic on them; the flat bottom has its own map).
fn shafts_of(s: &Settings, params: &mut SeaParams, objects_below: bool) -> Result<()> {
    if !(2..=64).contains(&s.shaft_planes) {
        bail!(invalid("sea.shaft_planes", "a count of planes in 2..=64", s.shaft_planes));
    }
    if !(2..=64).contains(&s.shaft_steps) {
        bail!(invalid("sea.shaft_steps", "a count of intervals in 2..=64", s.shaft_steps));
    }
    if let Some(d) = s.shaft_depth_m {
        if !(d.is_finite() && d > 0.0 && d <= 1e4) {
            bail!(invalid("sea.shaft_depth_m", "a depth in m in (0, 1e4]", d));
        }
    }
    if !(1..=8).contains(&s.shaft_stride) {
        bail!(invalid("sea.shaft_stride", "a stride in pixels in 1..=8", s.shaft_stride));
    }
    // The intervals also carry the objects' shadows without shafts.
    params.shaft_steps = s.shaft_steps;
    params.shaft_stride = s.shaft_stride;
    let needed = params.underwater != 0 || objects_below || params.bottom_nx >= 2;
    if !(s.shafts && needed && params.waves == WAVES_NORMAL_MAP) {
        return Ok(());
    }
    let max = slicelight_shaders::sea::caustics::MAX_SHAFT_RESOLUTION;
    let n = params.wave_resolution;
    params.shaft_level = if n > max { (n / max).trailing_zeros() } else { 0 };
    params.shaft_planes = s.shaft_planes;
    let bottom = if params.bottom_nx >= 2 { params.bottom_grid.w } else { params.depth };
    params.shaft_depth = s.shaft_depth_m.unwrap_or(bottom.min(SHAFT_DEPTH));
    Ok(())
}

/// `[sea]`'s bottom: a varying one's grid, if any, and the flat depth (m;
/// a grid's deepest, or `DEEP` for none). `eye_depth`: how far under the
/// water the camera is, if it is, which a flat bottom must lie below.
fn bottom_of(s: &Settings, base: &std::path::Path, eye_depth: Option<f32>) -> Result<(Option<Grid>, f32)> {
    if s.depth_m.is_some() && s.bottom.is_some() {
        bail!(invalid("sea.bottom", "either depth_m or bottom, not both", "both"));
    }
    if s.depth_table == 1 || s.depth_table > 512 {
        bail!(invalid("sea.depth_table", "0 (no depth table) or 2..=512 samples across the image", s.depth_table));
    }
    if !(2..=64).contains(&s.depth_layers) {
        bail!(invalid("sea.depth_layers", "a layer count in 2..=64", s.depth_layers));
    }
    let grid = s.bottom.as_ref().map(|b| b.grid(base)).transpose()?;
    let depth = match s.depth_m {
        None if grid.is_some() => grid.as_ref().map_or(DEEP, |g| g.deep),
        None => DEEP,
        Some(d) => {
            if !(d.is_finite() && d > 0.0 && d <= 1e6) {
                bail!(invalid("sea.depth_m", "a depth in (0, 1e6] m (leave it out for no bottom)", d));
            }
            if let Some(camera_depth) = eye_depth.filter(|&e| d <= e) {
                bail!(invalid(
                    "sea.depth_m",
                    &format!("a bottom below the camera, which is {camera_depth} m under the water"),
                    d
                ));
            }
            d
        }
    };
    Ok((grid, depth))
}

/// `[sea]`'s water: absorption and scattering (1/m, per channel, a preset's
/// unless given) and the index of refraction, validated (and `g`).
fn water_of(s: &Settings) -> Result<(Vec3, Vec3, f32)> {
    let preset = s.water.map(Water::coefficients);
    let (Some(absorption), Some(scattering)) =
        (s.absorption.or(preset.map(|p| p.0)), s.scattering.or(preset.map(|p| p.1)))
    else {
        bail!(invalid(
            "sea.absorption",
            "absorption and scattering, or a preset water = \"clear-ocean\" | \"tropical\" | \"coastal\"",
            "missing"
        ));
    };
    let a = validate::non_negative3("sea.absorption", absorption)?;
    let b = validate::non_negative3("sea.scattering", scattering)?;
    if !(s.g > -1.0 && s.g < 1.0) {
        bail!(invalid("sea.g", "a number in (-1, 1)", s.g));
    }
    let n = positive("sea.ior", s.ior)?;
    if !(1.0..=3.0).contains(&n) {
        bail!(invalid("sea.ior", "an index of refraction in [1, 3]", s.ior));
    }
    Ok((a, b, n))
}

/// `[sea]`'s order-2 sampling as given: the scattering maps' size and
/// `k` of the directions (`n_d = 3 k^2`), if given (`planes` checked).
fn sampling_of(s: &Settings) -> Result<([u32; 2], Option<u32>)> {
    let size = s.scattering_map;
    if !size.iter().all(|v| (2..=1024).contains(v)) {
        bail!(invalid("sea.scattering_map", "two sizes in 2..=1024", size));
    }
    if let Some(planes) = s.planes {
        if !(2..=256).contains(&planes) {
            bail!(invalid("sea.planes", "a plane count in 2..=256", planes));
        }
    }
    Ok((size, polar_of(s.directions)?))
}

/// The surface's slopes as the kernels read them (`surface`).
struct WaveMap {
    kind: u32,
    slopes: Vec<Vec4>,
    resolution: u32,
    size: f32,
    roughness: Vec4,
    filter: u32,
}

/// `[sea].waves` at the scene's `time` (s): flat, or a spectrum's slope
/// pyramid with the unresolved waves' roughness.
fn wave_map(w: &Waves, time: f64) -> Result<WaveMap> {
    Ok(match w {
        Waves::Flat => WaveMap {
            kind: WAVES_FLAT,
            slopes: vec![Vec4::ZERO; 2],
            resolution: 1,
            size: 1.0,
            roughness: Vec4::ZERO,
            filter: 0,
        },
        Waves::Spectrum(spectrum) => {
            let normals = spectrum.normal_map(time)?;
            WaveMap {
                kind: WAVES_NORMAL_MAP,
                slopes: waves::slope_pyramid(&normals, spectrum.resolution as usize),
                resolution: spectrum.resolution,
                size: spectrum.size_m,
                roughness: spectrum.unresolved_roughness(&normals),
                filter: spectrum.filter as u32,
            }
        }
    })
}

/// A varying bottom must lie below an eye under the water.
fn check_eye_above_bottom(p: &SeaParams, grid: Option<&Grid>, common: &CommonParams) -> Result<()> {
    let Some(g) = grid else {
        return Ok(());
    };
    let (x, z) = (common.camera_position.x, common.camera_position.z);
    let under = slicelight_shaders::sea::bottom_depth(p, &g.depths, x, z);
    if under <= p.camera_depth {
        bail!(invalid(
            "sea.bottom",
            &format!("a bottom below the camera, which is {} m under the water", p.camera_depth),
            format!("{under} m deep under the camera")
        ));
    }
    Ok(())
}

/// The sun refracted at the mean (flat) surface, eq. 5's and 7's beam:
/// its direction above the water and cosine `cos_ii`, its direction in the
/// water and cosine `cos_io` (Snell), the irradiance normal to the
/// refracted beam `E_w = T_i E cos(theta_ii) / cos(theta_io)` (W/m^2) and
/// the Fresnel transmittance `T_i`.
struct RefractedSun {
    sun: Vec3,
    cos_ii: f32,
    in_water: Vec3,
    cos_io: f32,
    beam: Vec3,
    t_i: f32,
}

fn refracted_sun(sky: &crate::sky::Setup, n: f32) -> RefractedSun {
    let sun = sky.params.sun_direction.truncate();
    let (irradiance, cos_ii) = match sky.sun_at_observer() {
        Some((e, _)) => (e, sun.y.max(0.0)),
        None => (Vec3::ZERO, sun.y.max(1e-3)),
    };
    let t_i = optics::transmittance(cos_ii, 1.0 / n);
    let (cos_io, _) = optics::transmitted_cosine(cos_ii, 1.0 / n);
    let sin_io = (1.0 - cos_io * cos_io).max(0.0).sqrt();
    let horizontal = Vec3::new(sun.x, 0.0, sun.z);
    let horizontal = if horizontal.length_squared() > 1e-12 { horizontal.normalize() } else { Vec3::X };
    let in_water = (-horizontal * sin_io - Vec3::Y * cos_io).normalize();
    let beam = irradiance * (t_i * cos_ii / cos_io);
    RefractedSun { sun, cos_ii, in_water, cos_io, beam, t_i }
}

/// `sea.directions` as `k` (`n_d = 3 k^2`, `k` even), if given.
fn polar_of(directions: Option<u32>) -> Result<Option<u32>> {
    let Some(d) = directions else { return Ok(None) };
    let k = ((d / 3) as f32).sqrt().round() as u32;
    if !(12..=12288).contains(&d) || 3 * k * k != d || !k.is_multiple_of(2) {
        bail!(invalid("sea.directions", "three times an even square in 12..=12288 (12, 48, 108, 192, 300, ...)", d));
    }
    Ok(Some(k))
}

/// Chooses `n_d` (unless `polar` is given) and `n_z` (unless `planes` is)
/// by the paper's 1/255 rule (6.1); returns what it chose, for the plan.
fn choose_sampling(params: &mut SeaParams, planes: Option<u32>, polar: Option<u32>) -> Vec<String> {
    /// The last choice: its inputs (the parameter block's bytes and the
    /// counts given), the block it left, its notes. The rule takes about
    /// 20 ms and depends on nothing else, and the viewer builds the scene
    /// again for every move of the camera.
    type Choice = (Vec<u8>, SeaParams, Vec<String>);
    static LAST: std::sync::Mutex<Option<Choice>> = std::sync::Mutex::new(None);
    let mut key = bytemuck::bytes_of(params).to_vec();
    key.extend(planes.unwrap_or(u32::MAX).to_le_bytes());
    key.extend(polar.unwrap_or(u32::MAX).to_le_bytes());
    if let Some((k, after, notes)) = LAST.lock().ok().as_deref().and_then(|l| l.clone()) {
        if k == key {
            *params = after;
            return notes;
        }
    }
    let notes = choose_sampling_now(params, planes, polar);
    if let Ok(mut last) = LAST.lock() {
        *last = Some((key, *params, notes.clone()));
    }
    notes
}

fn choose_sampling_now(params: &mut SeaParams, planes: Option<u32>, polar: Option<u32>) -> Vec<String> {
    let mut sampling = Vec::new();
    let chosen = std::time::Instant::now();
    // Over a varying bottom the rule runs for the deepest bottom and
    // for the middle layer's (geometric mean), and keeps the larger count.
    let rule_at: Vec<SeaParams> = if params.layers > 1 {
        vec![layer_params(params, params.layers - 1), layer_params(params, params.layers / 2)]
    } else {
        vec![*params]
    };
    if polar.is_none() {
        let (mut k, mut tried) = (2, 0);
        for q in &rule_at {
            let (kq, curve) = choose_directions(&SeaParams { layers: 1, ..*q });
            (k, tried) = (k.max(kq), tried + curve.len());
        }
        params.polar = k;
        params.azimuths = k;
        sampling.push(format!("n_d = {} by the 1/255 rule ({tried} counts tried)", 3 * k * k));
    }
    if planes.is_none() {
        let (mut n, mut tried) = (2, 0);
        for q in &rule_at {
            let q = SeaParams { layers: 1, polar: params.polar, azimuths: params.azimuths, ..*q };
            let (nq, curve) = choose_planes(&q);
            (n, tried) = (n.max(nq), tried + curve.len());
        }
        params.planes = n;
        sampling.push(format!("n_z = {n} by the 1/255 rule ({tried} counts tried)"));
    }
    if planes.is_none() || polar.is_none() {
        sampling.push(format!("chosen in {:.0} ms", 1e3 * chosen.elapsed().as_secs_f64()));
    }
    sampling
}

/// The depth table within its memory limit.
fn check_table_size(params: &SeaParams, depth_table: u32) -> Result<()> {
    // The depth table holds a distance per sample, level and direction.
    let table_bytes =
        4 * params.table_width as u64 * params.table_height as u64 * params.planes as u64 * 3 * set_size(params) as u64;
    if table_bytes > MAX_TABLE_BYTES {
        bail!(invalid(
            "sea.depth_table",
            &format!(
                "a depth table within {} MiB ({} planes x {} directions per sample)",
                MAX_TABLE_BYTES >> 20,
                params.planes,
                3 * set_size(params)
            ),
            depth_table
        ));
    }
    Ok(())
}

pub(super) fn skip_without_sea(scene: &SceneData) -> Option<Plan> {
    (!scene.sea.enabled).then(|| Plan::skip("no [sea]"))
}

pub(super) fn skip_without_order2(scene: &SceneData) -> Option<Plan> {
    skip_without_sea(scene).or_else(|| (!scene.sea.second_order).then(|| Plan::skip("second_order = false")))
}

pub struct SeaRadianceMap;

impl Pass for SeaRadianceMap {
    fn name(&self) -> &'static str {
        "sea.radiance_map"
    }
    fn kernel(&self) -> &'static str {
        "sea::radiance_map_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SEA_PARAMS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_RADIANCE_MAP]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_order2(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        Plan::run(
            format!(
                "order-1 radiance (eq. 7) on {} planes from {} directions (around the refracted sun, uniform)",
                p.planes,
                2 * set_size(p)
            ),
            scene.sea.radiance_map_texels(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        frame.write::<Vec4>(&SEA_RADIANCE_MAP, scene.sea.radiance_map_texels() as usize, |_, out| {
            for_each_invocation(out, 0, progress, |i, v| *v = radiance_map_texel(i, p));
        });
    }
    fn compare(&self, scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // The buffer is the order-1 radiance, then the held directions (w:
        // the phase function toward the sun), then the view set's pattern
        // (`radiance_map_len`). Directions come from sin, cos and sqrt,
        // which Vulkan allows to 2^-11 absolute: 1e-3 per component. The
        // phase function g ~ 0.9 changes by up to ~20 per radian of
        // direction on its peak's flank (`d ln p/d theta = 3 g sin/(1 + g^2 - 2 g cos)`):
        // 2 % of its value, and the radiance that carries it 2 % of its own.
        let p = &scene.sea.params;
        let (g, c) = (gpu.get::<Vec4>(&SEA_RADIANCE_MAP), cpu.get::<Vec4>(&SEA_RADIANCE_MAP));
        ensure!(g.len() == c.len(), "radiance maps of {} and {} values", g.len(), c.len());
        let (len, held) = (radiance_map_len(p) as usize, (p.planes * 2 * set_size(p)) as usize);
        let part = |v: &[Vec4], directions: bool| -> Vec<Vec4> {
            v.chunks(len).flat_map(|b| if directions { &b[held..] } else { &b[..held] }).copied().collect()
        };
        let (gr, cr) = (part(g, false), part(c, false));
        let radiance = compare_rgb("radiance map", &gr, &cr, 1e-3, cr.len() * 3 / 100 + 1)?;
        let flat = |v: &[Vec4]| v.iter().flat_map(|d| d.to_array()).collect::<Vec<f32>>();
        let (gd, cd) = (flat(&part(g, true)), flat(&part(c, true)));
        let (outliers, worst) = count_differences(&gd, &cd, |v| 1e-3 + 2e-2 * v.abs());
        ensure!(outliers == 0, "radiance map directions: {outliers} of {} values differ", cd.len());
        Ok(format!("{radiance}; directions and phase values: worst difference {worst:e}"))
    }
}

pub struct SeaScatteringMaps;

impl Pass for SeaScatteringMaps {
    fn name(&self) -> &'static str {
        "sea.scattering_maps"
    }
    fn kernel(&self) -> &'static str {
        "sea::scattering_maps_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SEA_PARAMS, SEA_RADIANCE_MAP]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_SCATTERING_MAPS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_order2(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        let mut how = if scene.sea.sampling.is_empty() { String::new() } else { format!(" ({})", scene.sea.sampling) };
        if p.layers > 1 {
            how += &format!(", for {} bottom depths from {} to {} m", p.layers, p.shallow, p.depth);
        }
        Plan::run(
            format!(
                "second-order scattering maps (eq. 6, 8), {} planes of {}x{}, {} directions{how}",
                p.planes,
                p.map_width,
                p.map_height,
                3 * set_size(p)
            ),
            scene.sea.scattering_map_texels(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        frame.write::<Vec4>(&SEA_SCATTERING_MAPS, scene.sea.scattering_map_texels() as usize, |frame, out| {
            let map = frame.get::<Vec4>(&SEA_RADIANCE_MAP);
            for_each_invocation(out, 0, progress, |i, v| *v = scattering_map_texel(i, p, map));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Sums of 2 n_d products of f32 phase functions and exps (each ~1e-6
        // relative); the directions go through sin and cos, which Vulkan
        // allows to 2^-11 absolute, moving a direction by up to ~5e-4 rad
        // where the phase function (g ~ 0.9) changes by a few per cent per
        // 0.01 rad: 1e-3 of the peak.
        compare_rgb("scattering maps", gpu.get(&SEA_SCATTERING_MAPS), cpu.get(&SEA_SCATTERING_MAPS), 1e-3, 0)
    }
}

/// The per-pixel sea passes' comparison: the view ray's refraction and
/// the map lookup go through sqrt, acos and atan2 (Vulkan: 4096 ulps for
/// the inverses), and a pixel on the horizon or a wave facet's edge may
/// flip; 1e-3 of the peak, 1e-3 of the values.
fn compare_layer(what: &str, r: &Resource, gpu: &Frame, cpu: &Frame) -> Result<String> {
    let c = cpu.get::<Vec4>(r);
    compare_rgb(what, gpu.get(r), c, 1e-3, c.len() * 3 / 1000 + 1)
}

pub struct SeaAccumulatedMap;

impl Pass for SeaAccumulatedMap {
    fn name(&self) -> &'static str {
        "sea.accumulated_map"
    }
    fn kernel(&self) -> &'static str {
        "sea::accumulated_map_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SEA_PARAMS, SEA_SCATTERING_MAPS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_ACCUMULATED_MAP]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_order2(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        let eye = if slicelight_shaders::sea::under::eye_block(p) {
            ", and order 2 along the eye's view ray toward each direction"
        } else {
            ""
        };
        Plan::run(
            format!("the scattering maps accumulated over {} planes with the attenuation map (eq. 8){eye}", p.planes),
            scene.sea.accumulated_map_texels(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        frame.write::<Vec4>(&SEA_ACCUMULATED_MAP, scene.sea.accumulated_map_texels() as usize, |frame, out| {
            let maps = frame.get::<Vec4>(&SEA_SCATTERING_MAPS);
            for_each_invocation(out, 0, progress, |i, v| *v = accumulated_map_texel(i, p, maps));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Sums over the planes of the maps (compared at 1e-3) times exps
        // and logs: the maps' tolerance.
        compare_rgb("accumulated map", gpu.get(&SEA_ACCUMULATED_MAP), cpu.get(&SEA_ACCUMULATED_MAP), 1e-3, 0)
    }
}

/// Why the waves' caustic maps are not drawn, if they are not.
fn skip_without_caustics(scene: &SceneData) -> Option<Plan> {
    if let Some(skip) = skip_without_sea(scene) {
        return Some(skip);
    }
    let p = &scene.sea.params;
    if p.caustics == 0 && p.shaft_planes == 0 {
        let why = if p.waves != WAVES_NORMAL_MAP {
            "a flat sea (no waves to focus the light)"
        } else if p.depth >= DEEP {
            "no bottom"
        } else if p.layers > 1 {
            "a varying bottom (the caustic map is for a flat one)"
        } else {
            "caustics = false"
        };
        return Some(Plan::skip(why));
    }
    None
}

/// `sea.caustic_rays`: the sun refracted once at every grid point of the
/// caustic maps' meshes (`slicelight_shaders::sea::caustics::caustic_ray`),
/// which the six triangles around a point share.
pub struct SeaCausticRays;

impl Pass for SeaCausticRays {
    fn name(&self) -> &'static str {
        "sea.caustic_rays"
    }
    fn kernel(&self) -> &'static str {
        "sea::wave_caustic_rays_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SEA_PARAMS, SEA_WAVES]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_CAUSTIC_RAYS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_caustics(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        Plan::run(
            format!("the sun refracted at the {} grid points of the caustic maps' meshes", caustic_points(p)),
            caustic_points(p) as u64,
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        frame.write_all::<[Vec4; 2]>(&SEA_CAUSTIC_RAYS, caustic_points(p) as usize, |_, out| {
            for_each_invocation(out, 0, progress, |i, v| {
                let (offset, flux) = caustic_ray(i, p, &scene.sea.waves);
                *v = [offset, flux];
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // A refraction (sqrt) and three exps: Vulkan's precision, some ulps.
        let (g, c) = (gpu.get::<Vec4>(&SEA_CAUSTIC_RAYS), cpu.get::<Vec4>(&SEA_CAUSTIC_RAYS));
        compare_values(
            "sea caustic rays",
            &g.iter().flat_map(|v| v.to_array()).collect::<Vec<f32>>(),
            &c.iter().flat_map(|v| v.to_array()).collect::<Vec<f32>>(),
            1e-5,
            0,
        )
    }
}

/// `sea.caustics`: the waves' caustic map on a flat bottom and on the
/// shaft planes (`slicelight_shaders::sea::caustics`), rebuilt with the
/// waves.
pub struct SeaCaustics;

impl Pass for SeaCaustics {
    fn name(&self) -> &'static str {
        "sea.caustics"
    }
    fn kernel(&self) -> &'static str {
        "sea::wave_caustics_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SEA_PARAMS, SEA_CAUSTIC_RAYS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_CAUSTICS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_caustics(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        let n = p.wave_resolution;
        let mut what = Vec::new();
        if p.caustics != 0 {
            what.push(format!("{} triangles onto the bottom at {} m ({n}x{n} map)", 2 * n * n, p.depth));
        }
        if p.shaft_planes != 0 {
            let m = slicelight_shaders::sea::caustics::shaft_resolution(p);
            what.push(format!(
                "{} triangles onto each of {} shaft planes down to {} m ({m}x{m} maps)",
                2 * m * m,
                p.shaft_planes,
                p.shaft_depth
            ));
        }
        Plan::run(format!("the waves refract the sun: {}", what.join("; ")), caustic_triangles(p) as u64)
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        let mut words = Buffer::zeroed::<u32>(scene.sea.caustic_words() as usize);
        {
            let rays = frame.get::<Vec4>(&SEA_CAUSTIC_RAYS);
            /// `caustic_triangle`, as the CPU's scatter driver calls it.
            struct Triangles<'a>(&'a SeaParams, &'a [Vec4]);
            impl crate::cpu::ScatterKernel for Triangles<'_> {
                fn run<A: slicelight_shaders::scatter::AtomicWords + ?Sized>(&self, i: u32, words: &mut A) {
                    caustic_triangle(i, self.0, self.1, words);
                }
            }
            let kernel = Triangles(p, rays);
            crate::cpu::scatter_each_index(words.as_mut_slice::<u32>(), caustic_triangles(p), progress, &kernel);
        }
        frame.insert(&SEA_CAUSTICS, words);
    }
    fn compare(&self, scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Refraction and exp on the device (sqrt, exp: Vulkan's precision)
        // move a corner by ~1e-6 texels: a sub-sample on a cross-section's
        // edge may flip, moving a quarter texel's share between
        // neighbours. 1e-3 of the peak, 1 % of the texels.
        let p = &scene.sea.params;
        let ratios = |f: &Frame| -> Vec<f32> {
            let words = f.get::<u32>(&SEA_CAUSTICS);
            let bins = slicelight_shaders::sea::caustics::caustic_bins(p);
            (0..bins).map(|b| slicelight_shaders::sea::caustics::read(words, b)).collect()
        };
        let (g, c) = (ratios(gpu), ratios(cpu));
        let (rg, rc) = (gpu.get::<u32>(&SEA_CAUSTICS)[0], cpu.get::<u32>(&SEA_CAUSTICS)[0]);
        ensure!(rg == rc, "sea caustics: {rg} cross-sections rejected on the device, {rc} on the CPU");
        let line = compare_values("sea caustics", &g, &c, 1e-3, c.len() / 100 + 1)?;
        Ok(format!("{line}; {rc} cross-sections rejected"))
    }
}

/// `sea.shafts`: the shaft planes' caustics as rgb ratios with their mips
/// (`caustics::shaft_mip_texel`), read along the view rays by order 1.
pub struct SeaShafts;

impl Pass for SeaShafts {
    fn name(&self) -> &'static str {
        "sea.shafts"
    }
    fn kernel(&self) -> &'static str {
        "sea::shaft_maps_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SEA_PARAMS, SEA_CAUSTICS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_SHAFTS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        if p.shaft_planes == 0 {
            let asked = scene.source.file.sea.as_ref().is_some_and(|s| s.shafts);
            let why = if p.waves != WAVES_NORMAL_MAP {
                "a flat sea (no waves to focus the light)"
            } else if !asked {
                "shafts = false"
            } else {
                "the eye is above the water, and no object or varying bottom lies under it"
            };
            return Plan::skip(why);
        }
        let m = slicelight_shaders::sea::caustics::shaft_resolution(p);
        Plan::run(format!("{} shaft planes' {m}x{m} caustics and their mips", p.shaft_planes), shaft_map_len(p) as u64)
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        let mut maps = Buffer::zeroed::<Vec4>(shaft_map_len(p) as usize);
        {
            let words = frame.get::<u32>(&SEA_CAUSTICS);
            for_each_invocation(maps.as_mut_slice::<Vec4>(), 0, progress, |i, v| {
                *v = shaft_mip_texel(i, p, words);
            });
        }
        frame.insert(&SEA_SHAFTS, maps);
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Averages of the caustic words, which agree to 1e-3 of the peak
        // on 1 % of the bins (`sea.caustics`); the mips average those.
        let c = cpu.get::<Vec4>(&SEA_SHAFTS);
        compare_rgb("sea shaft maps", gpu.get(&SEA_SHAFTS), c, 1e-3, c.len() * 3 / 100 + 1)
    }
}

pub struct SeaSurface;

impl Pass for SeaSurface {
    fn name(&self) -> &'static str {
        "sea.surface"
    }
    fn kernel(&self) -> &'static str {
        "sea::surface_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, GBUFFER, SEA_PARAMS, SEA_WAVES, SEA_BOTTOM_GRID]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_SURFACE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        if p.underwater != 0 {
            return Plan::run(
                format!(
                    "the eye is {} m under the water: where each view ray ends (surface, bottom, objects), Fresnel from below",
                    p.camera_depth
                ),
                0,
            );
        }
        if p.waves != slicelight_shaders::sea::WAVES_NORMAL_MAP {
            return Plan::run("the flat surface: Fresnel and Snell per pixel", 0);
        }
        let how = if p.wave_filter != 0 {
            "the wave slopes under each sample's footprint"
        } else {
            "the wave slopes at each sample's point"
        };
        Plan::run(format!("{how}: mean Fresnel transmission and refracted view"), 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        let blank = slicelight_shaders::common::surface::no_surface();
        frame.write_all::<Vec4>(&SEA_SURFACE, common.band_pixels as usize, |frame, out| {
            let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                let texel = gbuffer.get((i - common.band_start) as usize).unwrap_or(&blank);
                *v = slicelight_shaders::sea::surface_pixel(i, common, p, &scene.sea.waves, &scene.sea.bottom, texel);
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Unit directions (or, under the water, where the ray ends): the
        // terms' 1e-3. In w, transmissions and reflectances near 1, or under
        // the water lengths in metres (up to km along level rays): each to
        // 1e-3 of itself (at least of 1).
        let c = cpu.get::<Vec4>(&SEA_SURFACE);
        let g = gpu.get::<Vec4>(&SEA_SURFACE);
        let xyz = |v: &[Vec4]| v.iter().flat_map(|p| p.truncate().to_array()).collect::<Vec<f32>>();
        let w = |v: &[Vec4]| v.iter().map(|p| p.w).collect::<Vec<f32>>();
        let line = compare_values("sea surface", &xyz(g), &xyz(c), 1e-3, c.len() * 3 / 1000 + 1)?;
        let (outliers, worst) = count_differences(&w(g), &w(c), |v| 1e-3 * v.abs().max(1.0));
        ensure!(outliers <= c.len() / 1000 + 1, "sea surface: {outliers} of {} w values differ", c.len());
        Ok(format!("{line}; w: {outliers} outliers, worst difference {worst:e}"))
    }
}

/// The water between an eye under it and the objects it sees.
pub static SEA_WATER: Resource = Resource {
    binding: 76,
    name: "sea water transmittance",
    kind: ResourceKind::PerPixel { blank: || bytemuck::bytes_of(&Vec4::ONE).to_vec() },
};

/// `sea.water`: for an eye under water, what the water does to the light
/// of the objects it sees (`under::water_transmittance`), which the
/// framework applies to the layers before it (the objects' light); the
/// later sea passes attenuate their own. For an eye above the water, the
/// objects' light in air taken out where the water hides them (`water_pixel`).
pub struct SeaWater;

impl Pass for SeaWater {
    fn name(&self) -> &'static str {
        "sea.water"
    }
    fn kernel(&self) -> &'static str {
        "sea::water_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, GBUFFER, SEA_PARAMS, SEA_SURFACE, SEA_SHAFTS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_WATER]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn transmittance_layer(&self) -> Option<&'static Resource> {
        Some(&SEA_WATER)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        if !scene.has_geometry() {
            return Plan::skip("no objects");
        }
        if scene.sea.params.underwater == 0 {
            return Plan::run(
                "objects below the water level: their light in air out where the view ray meets the water first (sea.bottom sees them)",
                0,
            );
        }
        Plan::run("the water between the eye and the objects, and above them (the sunlight on them)", 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        let blank = slicelight_shaders::common::surface::no_surface();
        frame.write_all::<Vec4>(&SEA_WATER, common.band_pixels as usize, |frame, out| {
            let surface = frame.get::<Vec4>(&SEA_SURFACE);
            let shafts = frame.get::<Vec4>(&SEA_SHAFTS);
            let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                let k = (i - common.band_start) as usize;
                let seen = surface.get(k).copied().unwrap_or(Vec4::ZERO);
                let texel = gbuffer.get(k).unwrap_or(&blank);
                *v = slicelight_shaders::sea::water_pixel(i, common, p, seen, shafts, texel);
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // exp of a distance from the G-buffer: 1e-3 like the other terms.
        compare_layer("sea water", &SEA_WATER, gpu, cpu)
    }
}

pub struct SeaReflection;

impl Pass for SeaReflection {
    fn name(&self) -> &'static str {
        "sea.reflection"
    }
    fn kernel(&self) -> &'static str {
        "sea::reflection_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            GBUFFER,
            SKY_PARAMS,
            SKY_TRANSMITTANCE,
            SKY_VIEW,
            SEA_PARAMS,
            SEA_WAVES,
            LIGHTS,
            crate::volumes::LIGHT_GRIDS,
            crate::volumes::OPTICAL_DEPTHS,
            SEA_SURFACE,
            SPHERES,
            TRIANGLES,
            BVH_NODES,
            MATERIALS,
            LIGHT_MAPS,
            SHADOW_MAPS,
            crate::sky::SKY_IRRADIANCE
        ]
    }
    fn unused_reads(&self, scene: &SceneData) -> &'static [&'static Resource] {
        // Objects mirrored by the surface or seen through Snell's window,
        // lit as the surface pass lights them.
        let maps = scene.common.surface_shadows == slicelight_shaders::types::SHADOWS_MAP;
        if scene.has_geometry() && maps {
            &[]
        } else {
            resources![SHADOW_MAPS]
        }
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_REFLECTION]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SEA_REFLECTION)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        if scene.sea.params.underwater != 0 {
            let objects = if scene.has_geometry() { ", or the objects above the water seen through it" } else { "" };
            return Plan::run(
                format!("the sky and the sun through Snell's window (Fresnel from below){objects}, attenuated"),
                0,
            );
        }
        let objects = if scene.has_geometry() { ", and the objects over it" } else { "" };
        Plan::run(
            format!(
                "the sky and the sun reflected at the surface (Fresnel){objects}, the sun through the volumes' shadow"
            ),
            0,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        run_air(scene, common, frame, progress, &SEA_REFLECTION, false);
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // The reflected sky also carries the sky pass's 2e-3 (see its compare).
        let c = cpu.get::<Vec4>(&SEA_REFLECTION);
        compare_rgb("sea reflection", gpu.get(&SEA_REFLECTION), c, 2e-3, c.len() * 3 / 1000 + 1)
    }
}

/// `reflection_pixel` at every pixel into `out`, with the scene's objects
/// over the sea (`air::Above`: `sea.reflection`), or with `glass` what
/// the glass among them shows (`air::GlassInAir`: `sea.glass_air`).
pub(crate) fn run_air(
    scene: &SceneData,
    common: &CommonParams,
    frame: &mut Frame,
    progress: &ProgressBar,
    out: &Resource,
    glass: bool,
) {
    let (p, sky) = (&scene.sea.params, &scene.sky.params);
    let blank = slicelight_shaders::common::surface::no_surface();
    frame.write_all::<Vec4>(out, common.band_pixels as usize, |frame, values| {
        let transmittance = frame.get::<Vec4>(&SKY_TRANSMITTANCE);
        let sky_view = frame.get::<Vec4>(&SKY_VIEW);
        let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
        let surface = frame.get::<Vec4>(&SEA_SURFACE);
        let lit = crate::common::light_inputs(scene, frame);
        let clouds = CloudShadow { lights: &scene.lights, grids: lit.grids, depths: lit.depths };
        let above = Above {
            common,
            geometry: scene.geometry(),
            materials: &scene.materials,
            lights: &scene.lights,
            inputs: lit,
            sky,
            transmittance,
            sky_view,
            irradiance: frame.get::<Vec4>(&crate::sky::SKY_IRRADIANCE),
        };
        // The glass layer's objects, and where `sea.reflection`'s rays met
        // glass (the only pixels it draws).
        let in_air = glass.then(|| {
            let meshes = Glass { vertices: &scene.glass_vertices, triangles: &scene.glass_triangles };
            (GlassInAir::new(above, meshes, glass::sea_inputs(scene, frame)), frame.get::<Vec4>(&SEA_REFLECTION))
        });
        for_each_invocation(values, common.band_start, progress, |i, v| {
            let k = (i - common.band_start) as usize;
            let texel = gbuffer.get(k).unwrap_or(&blank);
            let seen = surface.get(k).copied().unwrap_or(Vec4::ZERO);
            let waves = &scene.sea.waves;
            *v = match &in_air {
                Some((_, mirror)) if mirror.get(k).is_none_or(|m| m.w == 0.0) => Vec4::ZERO,
                Some((in_air, _)) => {
                    reflection_pixel(i, common, p, waves, sky, transmittance, sky_view, texel, seen, &clouds, in_air)
                }
                None => {
                    reflection_pixel(i, common, p, waves, sky, transmittance, sky_view, texel, seen, &clouds, &above)
                }
            };
        });
    });
}

/// A per-pixel sea term whose kernel reads `sea.surface`'s value for the
/// pixel, the sea's parameters, and optionally the accumulated map and the depth
/// table's correction (empty where their passes did not run); `T` a pixel
/// in `out` (a `Vec4`, or `sea.shaft_samples`' two).
fn run_term<T: bytemuck::Pod + Send>(
    scene: &SceneData,
    common: &CommonParams,
    frame: &mut Frame,
    progress: &ProgressBar,
    out: &Resource,
    term: impl Fn(u32, Vec4, &TermInputs) -> T + Sync,
) {
    frame.write_all::<T>(out, common.band_pixels as usize, |frame, values| {
        let lit = crate::common::light_inputs(scene, frame);
        let inputs = TermInputs {
            maps: frame.get::<Vec4>(&SEA_SCATTERING_MAPS),
            accumulated: frame.get::<Vec4>(&SEA_ACCUMULATED_MAP),
            correction: frame.get::<Vec4>(&SEA_BOTTOM_CORRECTION),
            caustic: frame.get::<u32>(&SEA_CAUSTICS),
            samples: frame.get::<Vec4>(&SEA_SHAFT_SAMPLES),
            // The shaft maps (empty where `sea.shafts` did not run) and the
            // objects that shade the sun, once per band.
            sunlit: Sunlit { shafts: frame.get::<Vec4>(&SEA_SHAFTS), geometry: scene.geometry() },
            // The clouds' shadow where the volumes' transmittance volumes ran.
            clouds: CloudShadow { lights: &scene.lights, grids: lit.grids, depths: lit.depths },
        };
        let surface = frame.get::<Vec4>(&SEA_SURFACE);
        for_each_invocation(values, common.band_start, progress, |i, v| {
            let seen = surface.get((i - common.band_start) as usize).copied().unwrap_or(Vec4::ZERO);
            *v = term(i, seen, &inputs);
        });
    });
}

/// What the per-pixel terms read besides the sample's `sea.surface` value.
struct TermInputs<'a> {
    maps: &'a [Vec4],
    accumulated: &'a [Vec4],
    correction: &'a [Vec4],
    caustic: &'a [u32],
    samples: &'a [Vec4],
    sunlit: Sunlit<'a>,
    clouds: CloudShadow<'a>,
}

pub struct SeaShaftSamples;

impl Pass for SeaShaftSamples {
    fn name(&self) -> &'static str {
        "sea.shaft_samples"
    }
    fn kernel(&self) -> &'static str {
        "sea::shaft_samples_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            SEA_PARAMS,
            SEA_SURFACE,
            SEA_SHAFTS,
            crate::passes::SPHERES,
            crate::passes::TRIANGLES,
            crate::passes::BVH_NODES
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_SHAFT_SAMPLES]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        if p.underwater == 0 {
            return Plan::skip("the eye is above the water");
        }
        if p.scattering.truncate().max_element() <= 0.0 {
            return Plan::skip("the water does not scatter (scattering = 0)");
        }
        if !slicelight_shaders::sea::under::shafts_sampled(p, &scene.geometry()) {
            let why = if p.shaft_stride <= 1 {
                "shaft_stride = 1: gathered at every pixel"
            } else {
                "no shafts and no objects: the flat beam's closed form at every pixel"
            };
            return Plan::skip(why);
        }
        let s = p.shaft_stride;
        let what = if p.shaft_planes > 0 { "the shafts" } else { "the objects' shadows in the water" };
        Plan::run(format!("{what} gathered every {s} pixels each way, interpolated between rays alike in length"), 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        run_term(scene, common, frame, progress, &SEA_SHAFT_SAMPLES, |i, t, x| {
            let (ratio, shade) = slicelight_shaders::sea::under::shaft_sample(i, common, p, t, &x.sunlit);
            [ratio, shade]
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        compare_layer("sea shaft samples", &SEA_SHAFT_SAMPLES, gpu, cpu)
    }
}

pub struct SeaOrder1;

impl Pass for SeaOrder1 {
    fn name(&self) -> &'static str {
        "sea.order1"
    }
    fn kernel(&self) -> &'static str {
        "sea::order1_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            SEA_PARAMS,
            SEA_SURFACE,
            SEA_BOTTOM_GRID,
            SEA_SHAFTS,
            SEA_SHAFT_SAMPLES,
            crate::passes::SPHERES,
            crate::passes::TRIANGLES,
            crate::passes::BVH_NODES,
            LIGHTS,
            crate::volumes::LIGHT_GRIDS,
            crate::volumes::OPTICAL_DEPTHS
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_ORDER1]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SEA_ORDER1)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        if scene.sea.params.scattering.truncate().max_element() <= 0.0 {
            return Plan::skip("the water does not scatter (scattering = 0)");
        }
        let how = match scene.sea.single {
            Single::Exact => "the exact order-1 integral (eq. 5 with c)",
            Single::PaperEq5 => "eq. 5 as printed, c (1 - omega_0 c_f)",
        };
        Plan::run(format!("single scattering, {how}"), 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let (p, bottom) = (&scene.sea.params, &scene.sea.bottom[..]);
        run_term(scene, common, frame, progress, &SEA_ORDER1, |i, t, x| {
            order1_pixel(i, common, p, t, bottom, x.samples, &x.sunlit, &x.clouds)
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        compare_layer("sea order 1", &SEA_ORDER1, gpu, cpu)
    }
}

pub struct SeaOrder2;

impl Pass for SeaOrder2 {
    fn name(&self) -> &'static str {
        "sea.order2"
    }
    fn kernel(&self) -> &'static str {
        "sea::order2_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            SEA_PARAMS,
            SEA_SURFACE,
            SEA_SCATTERING_MAPS,
            SEA_ACCUMULATED_MAP,
            SEA_BOTTOM_GRID,
            SEA_BOTTOM_CORRECTION,
            LIGHTS,
            crate::volumes::LIGHT_GRIDS,
            crate::volumes::OPTICAL_DEPTHS
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_ORDER2]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SEA_ORDER2)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_order2(scene) {
            return skip;
        }
        if scene.sea.params.scattering.truncate().max_element() <= 0.0 {
            return Plan::skip("the water does not scatter (scattering = 0)");
        }
        if scene.sea.params.table_width > 0 {
            return Plan::run(
                "second-order scattering, looked up in the accumulated map, with the depth table's correction",
                0,
            );
        }
        let p = &scene.sea.params;
        if p.underwater != 0 {
            let along = if slicelight_shaders::sea::under::eye_block(p) {
                "second-order scattering along the view ray from the accumulated map's eye block (per pixel where an object ends it)"
            } else {
                "second-order scattering: the maps' source gathered along each view ray"
            };
            return Plan::run(format!("{along}, and the surface's reflection of the water below"), 0);
        }
        Plan::run("second-order scattering, looked up in the accumulated map", 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let (p, bottom) = (&scene.sea.params, &scene.sea.bottom[..]);
        run_term(scene, common, frame, progress, &SEA_ORDER2, |i, t, x| {
            order2_pixel(i, common, p, t, bottom, x.maps, x.accumulated, x.correction, &x.clouds)
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        compare_layer("sea order 2", &SEA_ORDER2, gpu, cpu)
    }
}

pub struct SeaBottom;

impl Pass for SeaBottom {
    fn name(&self) -> &'static str {
        "sea.bottom"
    }
    fn kernel(&self) -> &'static str {
        "sea::bottom_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            SEA_PARAMS,
            SEA_SURFACE,
            SEA_BOTTOM_GRID,
            SEA_CAUSTICS,
            SEA_SHAFTS,
            crate::passes::SPHERES,
            crate::passes::TRIANGLES,
            crate::passes::BVH_NODES,
            crate::passes::MATERIALS,
            LIGHTS,
            crate::volumes::LIGHT_GRIDS,
            crate::volumes::OPTICAL_DEPTHS
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_BOTTOM]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SEA_BOTTOM)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        let objects = !scene.geometry().is_empty();
        if p.depth >= DEEP {
            if p.underwater == 0 && objects {
                return Plan::run(
                    "no bottom: the objects the refracted view rays meet under the water (eq. 9 with 1/pi)",
                    0,
                );
            }
            return Plan::skip("no bottom (neither depth_m nor bottom given)");
        }
        if p.layers > 1 {
            return Plan::run(
                format!(
                    "a varying bottom from {} to {} m (eq. 9 with 1/pi; the view ray marched to it)",
                    p.shallow, p.depth
                ),
                0,
            );
        }
        // The brightest the bottom can be seen: straight down, sun overhead.
        let brightest = (-p.extinction.truncate() * 2.0 * p.depth).exp() * p.bottom_albedo.truncate();
        if brightest.max_element() <= 0.0 && !objects {
            return Plan::skip("the bottom is black or lies below all light (e^(-2 c d) = 0 in f32)");
        }
        let focus = if p.caustics != 0 { ", the waves' caustic on it" } else { "" };
        Plan::run(format!("the bottom at {} m (eq. 9 with 1/pi){focus}", p.depth), 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let (p, bottom) = (&scene.sea.params, &scene.sea.bottom[..]);
        run_term(scene, common, frame, progress, &SEA_BOTTOM, |i, t, x| {
            bottom_pixel(i, common, p, t, bottom, x.caustic, &x.sunlit, &scene.materials, &x.clouds)
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        compare_layer("sea bottom", &SEA_BOTTOM, gpu, cpu)
    }
}
