//! The lit-surface pass (kernel: `shader-crate/src/common/surface.rs`): surfaces
//! seen through the medium, and the G-buffer.

use anyhow::{ensure, Result};
use glam::Vec4;
use indicatif::ProgressBar;
use slicelight_shaders::common::surface::surface_pixel;
use slicelight_shaders::types::{CommonParams, GBufferTexel};

use crate::caustics;
use crate::cpu::for_each_invocation2;
use crate::passes::*;
use crate::scene::SceneData;
use crate::volumes;

/// Attenuated surface radiance per pixel (rgb; w = 0).
pub static SURFACE_RADIANCE: Resource =
    Resource { binding: 9, name: "surface radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };

/// Settings of the surface pass (the scene's `[surface]` table).
#[derive(Debug, Clone, Copy, Default, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Settings {
    /// How directly seen surfaces test their visibility of each light.
    pub shadows: SurfaceShadows,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum SurfaceShadows {
    /// An exact shadow ray per pixel and light, through the BVH.
    #[default]
    Rays,
    /// The lights' shadow maps (the 2002 paper's method).
    ShadowMap,
}

impl SurfaceShadows {
    pub fn code(self) -> u32 {
        match self {
            SurfaceShadows::Rays => slicelight_shaders::types::SHADOWS_RAYS,
            SurfaceShadows::ShadowMap => slicelight_shaders::types::SHADOWS_MAP,
        }
    }
}

pub struct Surface;

impl Pass for Surface {
    fn name(&self) -> &'static str {
        "surface"
    }
    fn kernel(&self) -> &'static str {
        "common::surface::surface_kernel"
    }
    fn variants(&self) -> &'static [&'static str] {
        &["common::surface::surface_opaque_kernel"]
    }
    fn kernel_for(&self, scene: &SceneData) -> &'static str {
        if scene.has_glass() {
            self.kernel()
        } else {
            self.variants()[0]
        }
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            LIGHTS,
            SPHERES,
            TRIANGLES,
            BVH_NODES,
            MATERIALS,
            LIGHT_MAPS,
            SHADOW_MAPS,
            GLASS_VERTICES,
            GLASS_TRIANGLES,
            caustics::CAUSTICS_PARAMS,
            caustics::CAUSTICS_MAPS,
            volumes::LIGHT_GRIDS,
            volumes::OPTICAL_DEPTHS,
            crate::desert::RIPPLE_RECORDS,
            crate::desert::RIPPLE_NORMALS
        ]
    }
    fn unused_reads(&self, scene: &SceneData) -> &'static [&'static Resource] {
        if scene.common.surface_shadows == slicelight_shaders::types::SHADOWS_MAP {
            &[]
        } else {
            resources![SHADOW_MAPS]
        }
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![GBUFFER, SURFACE_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SURFACE_RADIANCE)
    }

    fn plan(&self, scene: &SceneData) -> Plan {
        if scene.has_geometry() {
            let shadows = if scene.common.surface_shadows == slicelight_shaders::types::SHADOWS_MAP {
                "shadow maps"
            } else {
                "shadow rays"
            };
            Plan::run(format!("surfaces seen through the medium (eq. 1, first term), {shadows}, G-buffer"), 0)
        } else {
            Plan::skip("no geometry")
        }
    }

    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let n = common.band_pixels as usize;
        // Every pixel of both is assigned below.
        let mut radiance = Buffer::overwritten::<Vec4>(n);
        let mut gbuffer = Buffer::overwritten::<GBufferTexel>(n);
        let geometry = scene.geometry();
        let glass =
            slicelight_shaders::glass::Glass { vertices: &scene.glass_vertices, triangles: &scene.glass_triangles };
        // The caustic light at each receiver goes into the G-buffer when
        // this frame has caustics maps (`caustics::caustic_light`).
        let caustic_maps = frame.get::<u32>(&caustics::CAUSTICS_MAPS);
        let no_caustics = slicelight_shaders::caustics::CausticsParams::default();
        let caustics = if caustic_maps.is_empty() { &no_caustics } else { &scene.caustics.params };
        let inputs = super::light_inputs(scene, frame);
        let ripples = scene.desert.ripples();
        // The CPU runs the variant the GPU would (`kernel_for`).
        let pixel = if scene.has_glass() { surface_pixel::<true> } else { surface_pixel::<false> };
        for_each_invocation2(
            radiance.as_mut_slice::<Vec4>(),
            gbuffer.as_mut_slice::<GBufferTexel>(),
            common.band_start,
            progress,
            |i, color, texel| {
                (*color, *texel) = pixel(
                    i,
                    common,
                    &scene.lights,
                    &geometry,
                    &glass,
                    &scene.materials,
                    &inputs,
                    caustics,
                    caustic_maps,
                    &ripples,
                );
            },
        );
        frame.insert(&SURFACE_RADIANCE, radiance);
        frame.insert(&GBUFFER, gbuffer);
    }

    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        let rgb = |f: &Frame| f.get::<Vec4>(&SURFACE_RADIANCE).iter().flat_map(|p| p.to_array()).collect::<Vec<f32>>();
        let (g, c) = (rgb(gpu), rgb(cpu));
        let peak = c.iter().fold(0.0f32, |m, v| m.max(*v));
        // Radiance is a product of about 20 f32 factors (exp, sqrt, dot
        // products): 1e-5 of the image's peak is ~100 ulps of the largest
        // value. A pixel can flip where its ray grazes a silhouette or its
        // shadow test sits on the bias threshold: at most 1e-3 of the values may.
        let (outliers, worst) = count_differences(&g, &c, |v| 1e-5 * peak.max(v.abs()));
        let allowed = c.len() / 1000 + 1;
        ensure!(outliers <= allowed, "radiance: {outliers} of {} values differ (allowed {allowed})", c.len());
        // The G-buffer: distances like the shadow depths (1e-5 relative),
        // normals to 1e-5, ids exactly, except at silhouette flips.
        let (gg, cg) = (gpu.get::<GBufferTexel>(&GBUFFER), cpu.get::<GBufferTexel>(&GBUFFER));
        ensure!(gg.len() == cg.len(), "G-buffers of {} and {} texels", gg.len(), cg.len());
        let flips = gg
            .iter()
            .zip(cg)
            .filter(|(a, b)| {
                let d = a.normal_distance - b.normal_distance;
                a.object != b.object
                    || a.material != b.material
                    || d.truncate().abs().max_element() > 1e-5
                    || d.w.abs() > 1e-5 * b.normal_distance.w.abs().max(1.0)
            })
            .count();
        let allowed_texels = cg.len() / 1000 + 1;
        ensure!(flips <= allowed_texels, "G-buffer: {flips} of {} texels differ (allowed {allowed_texels})", cg.len());
        Ok(format!(
            "{} pixels, {outliers} flipped radiance values, worst other difference {worst:e} (peak {peak:e}); {flips} G-buffer texels differ",
            cg.len()
        ))
    }
}
