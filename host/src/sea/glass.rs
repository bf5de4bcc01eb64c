//! `sea.glass`: the sea through and reflected in glass, for an eye above
//! the water (kernel: `shader-crate/src/sea/glass.rs`). Without it a glass
//! object over the sea is dark wherever its view leads down to the water:
//! the sea passes draw only pixels whose view ray meets the water directly,
//! and `sky.glass` only the rays that leave for the sky.
//!
//! `sea.glass_air`: glass in the air over the sea seen from the water's
//! surface (kernel: `shader-crate/src/sea/air.rs`, `GlassInAir`), mirrored
//! by the waves and through Snell's window: the layer that takes the
//! glass's place in `sea.reflection`'s picture, where that pass sees
//! nothing.

use glam::Vec4;
use indicatif::ProgressBar;
use slicelight_shaders::glass::Glass;
use slicelight_shaders::sea::glass::{sea_in_glass_pixel, SeaInputs};
use slicelight_shaders::sea::under::Sunlit;
use slicelight_shaders::sea::CloudShadow;
use slicelight_shaders::types::{CommonParams, GBufferTexel};

use super::{
    run_air, skip_without_sea, SEA_ACCUMULATED_MAP, SEA_BOTTOM_GRID, SEA_CAUSTICS, SEA_PARAMS, SEA_SHAFTS, SEA_SURFACE,
    SEA_WAVES,
};
use crate::cpu::for_each_invocation;
use crate::passes::*;
use crate::scene::SceneData;
use crate::sky::{SKY_PARAMS, SKY_TRANSMITTANCE, SKY_VIEW};

/// The sea seen in glass, per pixel (rgb).
pub static SEA_GLASS_RADIANCE: Resource =
    Resource { binding: 85, name: "sea in glass radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };

pub struct SeaGlass;

impl Pass for SeaGlass {
    fn name(&self) -> &'static str {
        "sea.glass"
    }
    fn kernel(&self) -> &'static str {
        "sea::glass::sea_glass_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            LIGHTS,
            SPHERES,
            TRIANGLES,
            BVH_NODES,
            MATERIALS,
            GBUFFER,
            SKY_PARAMS,
            SKY_TRANSMITTANCE,
            SKY_VIEW,
            SEA_PARAMS,
            SEA_WAVES,
            SEA_ACCUMULATED_MAP,
            SEA_BOTTOM_GRID,
            GLASS_VERTICES,
            GLASS_TRIANGLES,
            crate::volumes::LIGHT_GRIDS,
            crate::volumes::OPTICAL_DEPTHS,
            SEA_CAUSTICS,
            SEA_SHAFTS
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_GLASS_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SEA_GLASS_RADIANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        if !scene.has_glass() {
            return Plan::skip("no glass");
        }
        if scene.sea.params.underwater != 0 {
            return Plan::skip("the eye is under the water");
        }
        Plan::run("the sea through and reflected in glass (Fresnel, Beer's law per channel; the sea passes' terms along each ray)", 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let n = common.band_pixels as usize;
        let blank = slicelight_shaders::common::surface::no_surface();
        let glass = Glass { vertices: &scene.glass_vertices, triangles: &scene.glass_triangles };
        frame.write_all::<Vec4>(&SEA_GLASS_RADIANCE, n, |frame, out| {
            let inputs = sea_inputs(scene, frame);
            let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                let texel = gbuffer.get((i - common.band_start) as usize).unwrap_or(&blank);
                *v = sea_in_glass_pixel(i, common, &inputs, texel, &glass);
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> anyhow::Result<String> {
        // The sea terms' tolerance (`compare_layer`: 1e-3 of the peak, a
        // value in a thousand further), here after paths through glass
        // whose edges may flip a pixel's path.
        let c = cpu.get::<Vec4>(&SEA_GLASS_RADIANCE);
        compare_rgb("sea in glass", gpu.get(&SEA_GLASS_RADIANCE), c, 1e-3, c.len() * 3 / 1000 + 1)
    }
}

/// What the sea seen along a ray reads (`sea_along`), from the scene and
/// the frame's maps.
pub(crate) fn sea_inputs<'a>(scene: &'a SceneData, frame: &'a Frame) -> SeaInputs<'a> {
    let lit = crate::common::light_inputs(scene, frame);
    SeaInputs {
        p: &scene.sea.params,
        waves: &scene.sea.waves,
        bottom: &scene.sea.bottom,
        accumulated: frame.get::<Vec4>(&SEA_ACCUMULATED_MAP),
        caustic: frame.get::<u32>(&SEA_CAUSTICS),
        sky: &scene.sky.params,
        transmittance: frame.get::<Vec4>(&SKY_TRANSMITTANCE),
        sky_view: frame.get::<Vec4>(&SKY_VIEW),
        clouds: CloudShadow { lights: &scene.lights, grids: lit.grids, depths: lit.depths },
        sunlit: Sunlit { shafts: frame.get::<Vec4>(&SEA_SHAFTS), geometry: scene.geometry() },
        materials: &scene.materials,
    }
}

/// What glass over the sea shows along `sea.reflection`'s rays, per pixel
/// (rgb).
pub static SEA_GLASS_AIR_RADIANCE: Resource =
    Resource { binding: 120, name: "glass over the sea radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };

pub struct SeaGlassAir;

impl Pass for SeaGlassAir {
    fn name(&self) -> &'static str {
        "sea.glass_air"
    }
    fn kernel(&self) -> &'static str {
        "sea::air::glass_air_kernel"
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
            crate::sky::SKY_IRRADIANCE,
            GLASS_VERTICES,
            GLASS_TRIANGLES,
            SEA_ACCUMULATED_MAP,
            SEA_BOTTOM_GRID,
            SEA_CAUSTICS,
            SEA_SHAFTS,
            super::SEA_REFLECTION
        ]
    }
    fn unused_reads(&self, scene: &SceneData) -> &'static [&'static Resource] {
        // The surfaces beyond the glass, lit as `sea.reflection` lights
        // them; the sea below it, for an eye above the water.
        let maps = scene.common.surface_shadows == slicelight_shaders::types::SHADOWS_MAP;
        match (maps, scene.sea.params.underwater != 0) {
            (true, false) => &[],
            (false, false) => resources![SHADOW_MAPS],
            (true, true) => resources![SEA_ACCUMULATED_MAP, SEA_CAUSTICS, SEA_SHAFTS],
            (false, true) => resources![SHADOW_MAPS, SEA_ACCUMULATED_MAP, SEA_CAUSTICS, SEA_SHAFTS],
        }
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_GLASS_AIR_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SEA_GLASS_AIR_RADIANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sea(scene) {
            return skip;
        }
        if !scene.has_glass() {
            return Plan::skip("no glass");
        }
        let how = if scene.sea.params.underwater != 0 { "seen through Snell's window" } else { "mirrored by the sea" };
        Plan::run(
            format!(
                "glass over the water {how}: what lies beyond it and what it mirrors (Fresnel, Beer's law per channel)"
            ),
            0,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        run_air(scene, common, frame, progress, &SEA_GLASS_AIR_RADIANCE, true);
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> anyhow::Result<String> {
        // As `sea.reflection` (the sky's 2e-3), here after paths through
        // glass whose edges may flip a ray's path.
        let c = cpu.get::<Vec4>(&SEA_GLASS_AIR_RADIANCE);
        compare_rgb("glass over the sea", gpu.get(&SEA_GLASS_AIR_RADIANCE), c, 2e-3, c.len() * 3 / 1000 + 1)
    }
}
