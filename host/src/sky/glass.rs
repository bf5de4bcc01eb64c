//! `sky.glass`: the sky through and reflected in glass under a `[sky]`,
//! and the sky's light on the surfaces seen through glass (kernel:
//! `shader-crate/src/sky/glass.rs`). Without it a glass object
//! under the sky is black wherever its view leads to the sky: the sky pass
//! draws only pixels that see no surface, and the surface pass follows the
//! view through glass only to an opaque surface.

use glam::Vec4;
use indicatif::ProgressBar;
use slicelight_shaders::sky::glass::sky_in_glass_pixel;
use slicelight_shaders::types::{CommonParams, GBufferTexel};

use super::{skip_without_sky, SKY_IRRADIANCE, SKY_PARAMS, SKY_TRANSMITTANCE, SKY_VIEW};
use crate::cpu::for_each_invocation;
use crate::passes::*;
use crate::scene::SceneData;

/// The sky seen in glass, per pixel (rgb).
pub static SKY_GLASS_RADIANCE: Resource =
    Resource { binding: 83, name: "sky in glass radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };

pub struct SkyGlass;

impl Pass for SkyGlass {
    fn name(&self) -> &'static str {
        "sky.glass"
    }
    fn kernel(&self) -> &'static str {
        "sky::glass::sky_glass_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            SPHERES,
            TRIANGLES,
            BVH_NODES,
            MATERIALS,
            GBUFFER,
            SKY_PARAMS,
            SKY_TRANSMITTANCE,
            SKY_VIEW,
            SKY_IRRADIANCE,
            GLASS_VERTICES,
            GLASS_TRIANGLES
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SKY_GLASS_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SKY_GLASS_RADIANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky(scene) {
            return skip;
        }
        if !scene.has_glass() {
            return Plan::skip("no glass");
        }
        let behind = if scene.sky.light { ", the skylight on surfaces seen through it" } else { "" };
        Plan::run(
            format!("the sky and the sun through and reflected in glass (Fresnel, Beer's law per channel){behind}"),
            0,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let n = common.band_pixels as usize;
        let p = &scene.sky.params;
        let blank = slicelight_shaders::common::surface::no_surface();
        let geometry = scene.geometry();
        let glass =
            slicelight_shaders::glass::Glass { vertices: &scene.glass_vertices, triangles: &scene.glass_triangles };
        frame.write_all::<Vec4>(&SKY_GLASS_RADIANCE, n, |frame, out| {
            let transmittance = frame.get::<Vec4>(&SKY_TRANSMITTANCE);
            let sky_view = frame.get::<Vec4>(&SKY_VIEW);
            // Read only when the sky lights the scene (`lights_surfaces`),
            // when `sky_irradiance` has filled it.
            let irradiance = frame.get::<Vec4>(&SKY_IRRADIANCE);
            let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                let texel = gbuffer.get((i - common.band_start) as usize).unwrap_or(&blank);
                *v = sky_in_glass_pixel(
                    i,
                    common,
                    p,
                    transmittance,
                    sky_view,
                    irradiance,
                    texel,
                    &geometry,
                    &glass,
                    &scene.materials,
                );
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> anyhow::Result<String> {
        // The sky pass's tolerance: directions go through sin, cos and
        // their inverses (2e-3 of the peak), and a pixel whose path grazes
        // a glass edge, the sun's disk or the horizon may flip (1e-3 of the
        // values).
        let cpu_values = cpu.get::<Vec4>(&SKY_GLASS_RADIANCE);
        compare_rgb("sky in glass", gpu.get(&SKY_GLASS_RADIANCE), cpu_values, 2e-3, cpu_values.len() * 3 / 1000 + 1)
    }
}
