//! The shadow-map pass (kernel: `shader-crate/src/shadow_map.rs`).

use anyhow::{ensure, Result};
use indicatif::ProgressBar;
use slicelight_shaders::shadow_map::shadow_map_texel;
use slicelight_shaders::types::CommonParams;

use super::{
    count_differences, Dispatch, Frame, Pass, Plan, Resource, BVH_NODES, COMMON, LIGHTS, SHADOW_MAPS, SPHERES,
    TRIANGLES,
};
use crate::cpu::for_each_invocation;
use crate::scene::SceneData;

pub struct ShadowMaps;

impl Pass for ShadowMaps {
    fn name(&self) -> &'static str {
        "shadow_maps"
    }
    fn kernel(&self) -> &'static str {
        "shadow_map::shadow_map_kernel"
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
        } else if scene.common.surface_shadows != slicelight_shaders::types::SHADOWS_MAP
            && !super::shafts::Shafts.plan(scene).runs
        {
            Plan::skip("surfaces use shadow rays and no shafts are rendered")
        } else {
            Plan::run(format!("{lights} light(s), {texels} shadow-map texels"), texels as u64)
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
