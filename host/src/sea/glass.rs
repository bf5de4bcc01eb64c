//! `sea.glass`: the sea through and reflected in glass, for an eye above
//! the water (kernel: `shader-crate/src/sea/glass.rs`). Without it a glass
//! object over the sea is dark wherever its view leads down to the water:
//! the sea passes draw only pixels whose view ray meets the water directly,
//! and `sky.glass` only the rays that leave for the sky.

use glam::Vec4;
use indicatif::ProgressBar;
use slicelight_shaders::sea::glass::{sea_in_glass_pixel, SeaInputs};
use slicelight_shaders::sea::under::Sunlit;
use slicelight_shaders::sea::CloudShadow;
use slicelight_shaders::types::{CommonParams, GBufferTexel};

use super::{skip_without_sea, SEA_ACCUMULATED_MAP, SEA_BOTTOM_GRID, SEA_CAUSTICS, SEA_PARAMS, SEA_SHAFTS, SEA_WAVES};
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
        let glass =
            slicelight_shaders::glass::Glass { vertices: &scene.glass_vertices, triangles: &scene.glass_triangles };
        frame.write_all::<Vec4>(&SEA_GLASS_RADIANCE, n, |frame, out| {
            let lit = crate::common::light_inputs(scene, frame);
            let inputs = SeaInputs {
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
            };
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
