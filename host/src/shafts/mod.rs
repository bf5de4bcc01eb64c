//! The shafts-of-light pass (kernel: `shader-crate/src/shafts/`):
//! in-scattering by slice accumulation over sample planes, its settings
//! (the scene's `[shafts]` table) and its tables.

pub mod bench;

use anyhow::{bail, ensure, Result};
use glam::{Vec3, Vec4};
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::Deserialize;
use slicelight_shaders::shafts::{
    shafts_pixel, table_entry, tile_count, tile_lights, uses_paper_modes, ShaftsParams, MODE_EXACT, MODE_TABLES,
};
use slicelight_shaders::types::{CommonParams, GBufferTexel, GpuLight, LIGHT_DIRECTIONAL};

use crate::passes::*;

/// The family's passes, in the order they run (see `passes::FAMILIES`).
pub static PASSES: &[&dyn Pass] = &[&ShaftsTiles, &Shafts];

/// The family, as `passes::FAMILIES` registers it.
pub static FAMILY: Family = Family { name: "shafts", passes: PASSES, kernels: &[], bench: Some(&bench::ShaftsSweep) };
use crate::cpu::for_each_invocation;
use crate::scene::{invalid, SceneData};

pub static SHAFTS_PARAMS: Resource = Resource {
    binding: 10,
    name: "shafts parameters",
    kind: ResourceKind::Scene(|s| bytemuck::bytes_of(&s.shafts.params)),
};
/// The phase table `F` then the attenuation table `h` (empty in exact mode).
pub static SHAFT_TABLES: Resource = Resource {
    binding: 11,
    name: "shaft tables",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.shafts.tables)),
};
/// Per tile of `TILE x TILE` pixels, the lights whose volume its pixels may
/// see (`tile_lights`).
pub static SHAFT_TILES: Resource =
    Resource { binding: 39, name: "shaft tiles", kind: ResourceKind::Frame(|s| tile_count(&s.common) as u64 * 4) };
/// In-scattered radiance per pixel (rgb); w = the `H I_l` samples evaluated.
pub static SHAFTS_RADIANCE: Resource =
    Resource { binding: 12, name: "shafts radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };

/// Settings of the shafts-of-light pass (the scene's `[shafts]` table).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Settings {
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

impl Default for Settings {
    fn default() -> Self {
        Settings {
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

/// The pass's state for one scene: its settings, parameter block and tables.
#[derive(Debug, Clone, Default)]
pub struct Setup {
    pub settings: Settings,
    pub params: ShaftsParams,
    pub tables: Vec<Vec4>,
}

/// Applies shaft settings to a scene: validates them, sets the plane depth
/// range, the table ranges and the lights' `in_view` flags, and fills the
/// tables. The error names the field within `[shafts]`.
pub fn configure(scene: &mut SceneData, s: Settings) -> Result<()> {
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
    let common = scene.common;
    let camera = common.camera_position.truncate();
    let forward = common.camera_forward.truncate();
    // Depth range of the planes: everything that can scatter light toward
    // the camera lies within the bounds of the geometry and the lights.
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    if let Some((a, b)) = scene.bounds {
        lo = a;
        hi = b;
    }
    for l in &scene.lights {
        lo = lo.min(l.position.truncate());
        hi = hi.max(l.position.truncate());
    }
    let corners: Vec<Vec3> = (0..8)
        .map(|i| Vec3::new([lo.x, hi.x][i & 1], [lo.y, hi.y][(i >> 1) & 1], [lo.z, hi.z][(i >> 2) & 1]))
        .collect();
    let depths = corners.iter().map(|c| (*c - camera).dot(forward));
    let near = depths.clone().fold(f32::INFINITY, f32::min).max(0.0);
    let far = depths.fold(f32::NEG_INFINITY, f32::max).max(near + 1e-3);
    // The h table spans every light-to-point and eye-to-point distance in
    // the bounds; the widest view ray (through an image corner) is the
    // longest for a given depth.
    let corner_cos =
        forward.dot((common.camera_forward + common.camera_right + common.camera_up).truncate().normalize());
    let h_s_max = scene
        .lights
        .iter()
        .flat_map(|l| corners.iter().map(move |c| (*c - l.position.truncate()).length()))
        .fold(1e-3, f32::max);
    let params = ShaftsParams {
        plane_count: s.planes,
        subplane_count: s.subplanes,
        mode: match s.mode {
            ShaftMode::Exact => MODE_EXACT,
            ShaftMode::Tables => MODE_TABLES,
        },
        jitter: s.jitter as u32,
        depth_near: near,
        depth_far: far,
        phase_table_size: s.phase_table_size,
        h_table_s: s.h_table_size[0],
        h_table_t: s.h_table_size[1],
        h_s_max,
        h_t_max: far / corner_cos.max(1e-3),
        analytic_inverse_square: s.analytic_inverse_square as u32,
        quantize_8bit: s.quantize_8bit as u32,
        quantize_scale: scene.exposure,
        _pad: [0; 2],
    };
    for l in &mut scene.lights {
        l.in_view = light_in_view(&common, &params, l) as u32;
    }
    let tables = if s.mode == ShaftMode::Tables {
        let n = params.phase_table_size + params.h_table_s * params.h_table_t;
        let mut t: Vec<Vec4> = (0..n).map(|k| table_entry(&common, &params, k)).collect();
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
    scene.shafts = Setup { settings: s, params, tables };
    Ok(())
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
fn light_in_view(p: &CommonParams, shafts: &ShaftsParams, l: &GpuLight) -> bool {
    if l.kind == LIGHT_DIRECTIONAL {
        return true;
    }
    let camera = p.camera_position.truncate();
    let (f, r, u) = (p.camera_forward.truncate(), p.camera_right.truncate(), p.camera_up.truncate());
    let apex = l.position.truncate();
    let axis = l.axis_z.truncate();
    // Every point the planes sample lies in the frustum up to depth_far, the
    // convex hull of the camera and the four far corners.
    let far_corners = [f + r + u, f + r - u, f - r + u, f - r - u].map(|c| camera + c * shafts.depth_far);
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

/// Why a scene has no shafts (the reason the plan gives), or `None`.
fn why_no_shafts(scene: &SceneData) -> Option<String> {
    if !scene.scatters() {
        Some("the medium does not scatter (sigma_s = 0)".into())
    } else if scene.lights.iter().all(|l| l.in_view == 0) {
        Some(format!("no light's volume is in view ({} light(s))", scene.lights.len()))
    } else {
        None
    }
}

/// The shafts' light culling per tile of pixels (kernel `tile_lights`), run
/// wherever the shafts run.
pub struct ShaftsTiles;

impl Pass for ShaftsTiles {
    fn name(&self) -> &'static str {
        "shafts.tiles"
    }
    fn kernel(&self) -> &'static str {
        "shafts::shafts_tiles_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, LIGHTS, SHAFTS_PARAMS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SHAFT_TILES]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        match why_no_shafts(scene) {
            Some(why) => Plan::skip(why),
            None => Plan::run(
                format!("lights each {0}x{0}-pixel tile may see", slicelight_shaders::shafts::TILE),
                tile_count(&scene.common) as u64,
            ),
        }
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        frame.write_all::<u32>(&SHAFT_TILES, tile_count(common) as usize, |_, out| {
            for_each_invocation(out, 0, progress, |i, v| {
                *v = tile_lights(i, common, &scene.shafts.params, &scene.lights)
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // One clipping of a ray per tile and light, with the tolerances of
        // `clip_to_cone`: a light whose moved cone the centre ray grazes may
        // be kept on one backend only (either keeps the culling
        // conservative); at most 1e-3 of the tiles may differ.
        let (g, c) = (gpu.get::<u32>(&SHAFT_TILES), cpu.get::<u32>(&SHAFT_TILES));
        let (differ, _) = crate::passes::differing_records("shaft tiles", g, c, 1)?;
        let allowed = c.len() / 1000 + 1;
        ensure!(differ <= allowed, "{differ} of {} tiles differ (allowed {allowed})", c.len());
        let culled = c.iter().filter(|m| **m == 0).count();
        Ok(format!("{} tiles, {culled} with no light, {differ} differ", c.len()))
    }
}

pub struct Shafts;

impl Pass for Shafts {
    fn name(&self) -> &'static str {
        "shafts"
    }
    fn kernel(&self) -> &'static str {
        "shafts::shafts_kernel"
    }
    fn variants(&self) -> &'static [&'static str] {
        &["shafts::shafts_exact_kernel"]
    }
    fn kernel_for(&self, scene: &SceneData) -> &'static str {
        if uses_paper_modes(&scene.shafts.params) {
            self.kernel()
        } else {
            self.variants()[0]
        }
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            LIGHTS,
            LIGHT_MAPS,
            SHADOW_MAPS,
            GBUFFER,
            SHAFTS_PARAMS,
            SHAFT_TABLES,
            SHAFT_TILES,
            crate::volumes::LIGHT_GRIDS,
            crate::volumes::OPTICAL_DEPTHS
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SHAFTS_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn spans_the_view_ray(&self) -> bool {
        true
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SHAFTS_RADIANCE)
    }

    fn plan(&self, scene: &SceneData) -> Plan {
        let lights = scene.lights.len();
        let visible = scene.lights.iter().filter(|l| l.in_view != 0).count();
        let s = &scene.shafts.settings;
        match why_no_shafts(scene) {
            Some(why) => Plan::skip(why),
            None => Plan::run(
                format!(
                    "{visible} of {lights} light(s) in view, {} planes x {} sub-planes, {:?} mode",
                    s.planes, s.subplanes, s.mode
                ),
                0,
            ),
        }
    }

    /// `shaft_samples`: the `H I_l` samples evaluated (the layer's w, summed
    /// over pixels and sub-pixel samples); `shaft_samples_naive`: the
    /// `pixels x samples x planes x sub-planes x lights` of slicing every
    /// plane for every light without clipping or culling.
    fn counters(&self, scene: &SceneData, frame: &Frame) -> Vec<(&'static str, u64)> {
        // Whole counts per pixel (exact in f32 below 2^24), summed as
        // integers across threads: a serial f64 sum over Fig. 6's pixels
        // took 0.65 ms of its frame.
        let evaluated: u64 = frame.get::<Vec4>(&SHAFTS_RADIANCE).par_iter().map(|p| p.w as u64).sum();
        let s = &scene.shafts.settings;
        let naive = scene.pixel_count() as u64
            * scene.samples_per_pixel() as u64
            * s.planes as u64
            * s.subplanes as u64
            * scene.lights.len() as u64;
        vec![("shaft_samples", evaluated), ("shaft_samples_naive", naive)]
    }

    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let s = &scene.shafts;
        frame.write_all::<Vec4>(&SHAFTS_RADIANCE, common.band_pixels as usize, |frame, out| {
            let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
            // The CPU runs the variant the GPU would (`kernel_for`), with
            // its samples in SIMD packets.
            let pixel =
                if uses_paper_modes(&s.params) { shafts_pixel::<true, true> } else { shafts_pixel::<false, true> };
            let tiles = frame.get::<u32>(&SHAFT_TILES);
            let inputs = crate::common::light_inputs(scene, frame);
            for_each_invocation(out, common.band_start, progress, |i, px| {
                let distance = gbuffer[(i - common.band_start) as usize].normal_distance.w;
                *px = pixel(i, common, &s.params, &scene.lights, &inputs, &s.tables, tiles, distance);
            });
        });
    }

    fn compare(&self, scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        let (g, c) = (gpu.get::<Vec4>(&SHAFTS_RADIANCE), cpu.get::<Vec4>(&SHAFTS_RADIANCE));
        let rgb = |img: &[Vec4]| img.iter().flat_map(|p| p.truncate().to_array()).collect::<Vec<f32>>();
        let (gr, cr) = (rgb(g), rgb(c));
        let peak = cr.iter().fold(0.0f32, |m, v| m.max(*v));
        // In-scattered radiance is a sum over up to planes x sub-planes x
        // lights terms, each a product of ~20 f32 factors, on a device that
        // may fuse multiply-adds: measured on lavapipe, the worst difference
        // in exact mode was 9.9e-5 of this layer's peak (fog_spot) when the
        // bounds were set and is 2.77e-4 since (measured at 0264878 and
        // after; one pixel of 90 samples, 1.1e-3 of its own value; the
        // interval weights near a light go through `atan` and `sin_cos`,
        // which Vulkan lets a device compute to 4096 ulps, 2.4e-4). Tables
        // mode adds an acos ahead of the table interpolation: measured
        // 9.4e-5. Bounds: 3e-4 exact, 5e-4 tables.
        // A sub-plane sample can flip where its shadow test or cone test
        // sits on a threshold (a plane boundary rounded differently moves
        // it), and a value past the bound counts as such a flip: at most
        // 1e-3 of the values may.
        let bound = if scene.shafts.settings.mode == ShaftMode::Tables { 5e-4 } else { 3e-4 };
        let (outliers, worst) = count_differences(&gr, &cr, |v| bound * peak.max(v.abs()));
        let allowed = cr.len() / 1000 + 1;
        ensure!(
            outliers <= allowed,
            "{outliers} of {} values differ by more than {bound:e} of the peak (allowed {allowed})",
            cr.len()
        );
        // The sample counts (w) are integers; a flipped clip bound may move one
        // interval's sub-planes in or out of a pixel's count.
        let counts_differ = g.iter().zip(c).filter(|(a, b)| a.w != b.w).count();
        ensure!(counts_differ <= allowed, "{counts_differ} sample counts differ (allowed {allowed})");
        Ok(format!(
            "{:?} mode: {} pixels, {outliers} flipped values, worst other difference {:.2e} of the peak {peak:e}, {counts_differ} sample counts differ",
            scene.shafts.settings.mode,
            c.len(),
            worst / peak.max(1e-30)
        ))
    }
}
