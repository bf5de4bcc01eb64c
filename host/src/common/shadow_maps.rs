//! The shadow-map pass (kernel: `shader-crate/src/common/shadow_maps.rs`).

use anyhow::{ensure, Result};
use indicatif::ProgressBar;
use slicelight_shaders::camera::pinhole_direction;
use slicelight_shaders::common::shadow_maps::shadow_map_texel;
use slicelight_shaders::geometry::{trace_nearest, Geometry, NO_HIT};
use slicelight_shaders::glam::{Vec2, Vec3, Vec4Swizzles};
use slicelight_shaders::light::light_local;
use slicelight_shaders::shafts::{clip_to_beam, clip_to_cone};
use slicelight_shaders::types::{CommonParams, GpuLight, LIGHT_DIRECTIONAL, PROJECTION_PINHOLE};

use crate::cpu::for_each_invocation;
use crate::passes::{
    count_differences, read_by_a_running_pass, Dispatch, Frame, Pass, Plan, Resource, BVH_NODES, COMMON, LIGHTS,
    SHADOW_MAPS, SPHERES, TRIANGLES,
};
use crate::scene::SceneData;

pub struct ShadowMaps;

impl Pass for ShadowMaps {
    fn name(&self) -> &'static str {
        "shadow_maps"
    }
    fn kernel(&self) -> &'static str {
        "common::shadow_maps::shadow_map_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, LIGHTS, SPHERES, TRIANGLES, BVH_NODES]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SHADOW_MAPS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }

    fn plan(&self, scene: &SceneData) -> Plan {
        let texels = scene.common.shadow_texel_count;
        let lights = scene.lights.len();
        if lights == 0 {
            Plan::skip("no lights")
        } else if !scene.has_geometry() {
            Plan::skip("no geometry to cast shadows")
        } else if !read_by_a_running_pass(scene, &SHADOW_MAPS) {
            // (Surfaces read the maps only with `SHADOWS_MAP`: `unused_reads`.)
            Plan::skip("surfaces use shadow rays and no running pass reads the maps")
        } else {
            let sizes: Vec<String> = scene
                .lights
                .iter()
                .filter(|l| l.shadow_resolution > 0)
                .map(|l| format!("{0}x{0}", l.shadow_resolution))
                .collect();
            Plan::run(format!("{lights} light(s), {texels} shadow-map texels ({})", sizes.join(", ")), texels as u64)
        }
    }

    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let geometry = scene.geometry();
        frame.write_all::<f32>(&SHADOW_MAPS, common.shadow_texel_count as usize, |_, out| {
            for_each_invocation(out, 0, progress, |i, v| *v = shadow_map_texel(i, common, &scene.lights, &geometry));
        });
    }

    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        let (g, c) = (gpu.get::<f32>(&SHADOW_MAPS), cpu.get::<f32>(&SHADOW_MAPS));
        // A depth is one ray-surface intersection in f32. The GPU may fuse
        // multiply-adds and round sqrt differently, so depths agree to a few ulps
        // of the operands (1e-5 relative leaves a 10x margin over the worst seen).
        // A texel whose ray grazes a silhouette can hit on one backend and miss on
        // the other: such flips are allowed on at most 1e-4 of the texels.
        let (outliers, worst) = count_differences(g, c, |c| 1e-5 * c.abs().max(1.0));
        let allowed = c.len() / 10_000 + 1;
        ensure!(outliers <= allowed, "{outliers} of {} shadow texels differ (allowed {allowed})", c.len());
        Ok(format!("{} texels, {outliers} silhouette flips, worst other difference {worst:e} m", c.len()))
    }
}

/// View rays per image side that `shafts_resolution` follows.
const FOOTPRINT_RAYS: u32 = 24;
/// Points per ray, evenly spaced over the stretch inside the light's volume.
const FOOTPRINT_POINTS: u32 = 16;

/// A view ray of the footprint rule: origin, unit direction, and where it
/// ends (metres): at the first surface, or at `t_far`.
pub type FootprintRay = (Vec3, Vec3, f32);

/// The `FOOTPRINT_RAYS^2` view rays `shafts_resolution` follows, evenly
/// spread over a pinhole camera's image, each to the first surface it meets
/// (or to `t_far`, metres, where the scene's bounds end). They do not
/// depend on the light, so a scene traces them once for all its lights.
pub fn footprint_rays(common: &CommonParams, geometry: &Geometry, t_far: f32) -> Vec<FootprintRay> {
    if common.projection != PROJECTION_PINHOLE {
        return Vec::new();
    }
    let o = common.camera_position.xyz();
    let cell = |i: u32| 2.0 * (i as f32 + 0.5) / FOOTPRINT_RAYS as f32 - 1.0;
    (0..FOOTPRINT_RAYS * FOOTPRINT_RAYS)
        .map(|k| {
            let (i, j) = (k % FOOTPRINT_RAYS, k / FOOTPRINT_RAYS);
            let d = pinhole_direction(common, Vec2::new(cell(i), -cell(j)));
            (o, d, trace_nearest(o, d, 0.0, NO_HIT, geometry).distance.min(t_far))
        })
        .collect()
}

/// The default resolution of `light`'s shadow map where it serves only the
/// shafts: the smallest multiple of 32 from `min` to `max` whose texels are no
/// wider than a pixel wherever the view sees the light's volume. A texel of a
/// spot's perspective map spans `2 z tan(cutoff) / N` metres at depth `z`
/// along the light's axis, a directional light's orthographic one `2 h / N`
/// (`h` the larger half-extent); a pixel spans `d 2 tan(vfov / 2) / height`
/// at depth `d` along the camera's axis. The ratio is taken at
/// `FOOTPRINT_POINTS` points along each of the view rays `rays`
/// (`footprint_rays`), clipped to the light's volume (`clip_to_cone`,
/// `clip_to_beam`: the shafts' own clipping), and its largest value decides.
/// Shadow edges in the medium are seen through the shafts' integral along
/// each ray, which averages a map's steps; finer texels than a pixel change
/// no image measurably (docs/shafts.md). A fisheye camera (no shafts)
/// gets `max`.
pub fn shafts_resolution(common: &CommonParams, light: &GpuLight, rays: &[FootprintRay], min: u32, max: u32) -> u32 {
    if common.projection != PROJECTION_PINHOLE {
        return max;
    }
    let pixel_per_depth = 2.0 * common.camera_up.xyz().length() / common.height as f32;
    let texel_span = |local_z: f32| {
        if light.kind == LIGHT_DIRECTIONAL {
            2.0 * light.half_extent_x.max(light.half_extent_y)
        } else {
            2.0 * local_z.max(0.0) * light.tan_cutoff
        }
    };
    let forward = common.camera_forward.xyz();
    let mut needed = 0.0f32;
    for &(o, d, t_max) in rays {
        let (lo, hi) = if light.kind == LIGHT_DIRECTIONAL {
            clip_to_beam(light, o, d, 0.0, t_max)
        } else {
            clip_to_cone(light, o, d, 0.0, t_max)
        };
        if hi <= lo {
            continue;
        }
        for k in 0..FOOTPRINT_POINTS {
            let t = lo + (hi - lo) * k as f32 / (FOOTPRINT_POINTS - 1) as f32;
            let p = o + d * t;
            let pixel = (p - o).dot(forward) * pixel_per_depth;
            let texels = texel_span(light_local(light, p).z) / pixel;
            // A point at the eye (a camera inside the volume) needs every texel.
            needed = needed.max(if texels.is_finite() { texels } else { f32::MAX });
        }
    }
    ((needed.min(max as f32).ceil() as u32).next_multiple_of(32)).clamp(min, max)
}
