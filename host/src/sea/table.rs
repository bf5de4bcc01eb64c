//! Order 2 over a varying bottom with the paper's depth table (section 5.4;
//! kernels: `shader-crate/src/sea/table.rs`, which explains the method):
//! the table's sampling points, the depth table, and the order-2 correction
//! the per-pixel `sea.order2` adds. They run only over a varying bottom
//! with second-order scattering and `depth_table` > 0.

use anyhow::Result;
use glam::Vec4;
use indicatif::ProgressBar;
use slicelight_shaders::sea::table::{
    bottom_correction_texel, depth_table_texel, table_directions, table_sample_texel, table_samples,
};
use slicelight_shaders::types::CommonParams;

use super::{skip_without_order2, SEA_BOTTOM_GRID, SEA_PARAMS};
use crate::cpu::for_each_invocation;
use crate::passes::*;
use crate::scene::SceneData;

fn samples(s: &SceneData) -> u64 {
    table_samples(&s.sea.params) as u64
}
fn entries(s: &SceneData) -> u64 {
    samples(s) * s.sea.params.planes as u64 * table_directions(&s.sea.params) as u64
}

/// Per table sample: where its view ray meets the surface (w: the bottom's
/// depth under it), and its upward view in the water (w: 1 on the sea).
pub static SEA_TABLE_SAMPLES: Resource =
    Resource { binding: 36, name: "sea table samples", kind: ResourceKind::Frame(|s| samples(s) * 2 * 16) };
/// Per sample, level and direction: the distance down to the bottom (m).
pub static SEA_DEPTH_TABLE: Resource =
    Resource { binding: 37, name: "sea depth table", kind: ResourceKind::Frame(|s| entries(s) * 4) };
/// Per sample: the order-2 correction (rgb, W/(m^2 sr), signed).
pub static SEA_BOTTOM_CORRECTION: Resource =
    Resource { binding: 38, name: "sea bottom correction", kind: ResourceKind::Frame(|s| samples(s) * 16) };

fn skip_without_table(scene: &SceneData) -> Option<Plan> {
    skip_without_order2(scene).or_else(|| {
        let p = &scene.sea.params;
        if p.layers <= 1 {
            Some(Plan::skip("a flat bottom (no depth table needed)"))
        } else if p.table_width == 0 {
            Some(Plan::skip("depth_table = 0 (the water under each pixel taken as flat)"))
        } else {
            None
        }
    })
}

pub struct SeaTableSamples;

impl Pass for SeaTableSamples {
    fn name(&self) -> &'static str {
        "sea.table_samples"
    }
    fn kernel(&self) -> &'static str {
        "sea::table::table_samples_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, SEA_PARAMS, SEA_BOTTOM_GRID]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_TABLE_SAMPLES]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_table(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        Plan::run(
            format!(
                "the depth table's sampling points: {}x{} view rays across the image",
                p.table_width, p.table_height
            ),
            2 * samples(scene),
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let (p, grid) = (&scene.sea.params, &scene.sea.bottom[..]);
        frame.write::<Vec4>(&SEA_TABLE_SAMPLES, 2 * samples(scene) as usize, |_, out| {
            for_each_invocation(out, 0, progress, |i, v| *v = table_sample_texel(i, common, p, grid));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Points on the surface and unit directions through normalize and
        // sqrt, and each view ray's march to the bottom (a crossing found
        // within a step either way where the ray grazes a slope): 1e-3 of
        // the largest coordinate, 1 % of the samples.
        let c = cpu.get::<Vec4>(&SEA_TABLE_SAMPLES);
        compare_values("table samples", as_f32(gpu.get(&SEA_TABLE_SAMPLES)), as_f32(c), 1e-3, c.len() * 4 / 100 + 1)
    }
}

fn as_f32(v: &[Vec4]) -> &[f32] {
    bytemuck::cast_slice(v)
}

pub struct SeaDepthTable;

impl Pass for SeaDepthTable {
    fn name(&self) -> &'static str {
        "sea.depth_table"
    }
    fn kernel(&self) -> &'static str {
        "sea::table::depth_table_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SEA_PARAMS, SEA_BOTTOM_GRID, SEA_TABLE_SAMPLES]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_DEPTH_TABLE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_table(scene) {
            return skip;
        }
        let p = &scene.sea.params;
        Plan::run(
            format!(
                "depth table (section 5.4): the bottom along {} directions from {} levels of {} sampling points",
                table_directions(p),
                p.planes,
                samples(scene)
            ),
            entries(scene),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let (p, grid) = (&scene.sea.params, &scene.sea.bottom[..]);
        frame.write::<f32>(&SEA_DEPTH_TABLE, entries(scene) as usize, |frame, out| {
            let samples = frame.get::<Vec4>(&SEA_TABLE_SAMPLES);
            for_each_invocation(out, 0, progress, |i, v| *v = depth_table_texel(i, p, grid, samples));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Marches through the bilinear height field: a ray that grazes the
        // bottom within f32 rounding of a step's end can find the crossing
        // a step later on one device; the directions go through sin and
        // cos (Vulkan: 2^-11 absolute). 1e-3 of the largest distance, 1 %
        // of the entries.
        let c = cpu.get::<f32>(&SEA_DEPTH_TABLE);
        compare_values("depth table", gpu.get(&SEA_DEPTH_TABLE), c, 1e-3, c.len() / 100 + 1)
    }
}

pub struct SeaBottomCorrection;

impl Pass for SeaBottomCorrection {
    fn name(&self) -> &'static str {
        "sea.bottom_correction"
    }
    fn kernel(&self) -> &'static str {
        "sea::table::bottom_correction_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SEA_PARAMS, SEA_TABLE_SAMPLES, SEA_DEPTH_TABLE]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SEA_BOTTOM_CORRECTION]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_table(scene) {
            return skip;
        }
        Plan::run(
            "order 2 with the depth table's bottom minus with a flat one under each sample's view ray (eq. 6-8)",
            samples(scene),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sea.params;
        frame.write::<Vec4>(&SEA_BOTTOM_CORRECTION, samples(scene) as usize, |frame, out| {
            let (samples, table) = (frame.get::<Vec4>(&SEA_TABLE_SAMPLES), frame.get::<f32>(&SEA_DEPTH_TABLE));
            for_each_invocation(out, 0, progress, |i, v| *v = bottom_correction_texel(i, p, samples, table));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Signed sums over the levels of differences of two order-1
        // radiances per direction, weighted by phase functions (g ~ 0.9)
        // of directions that go through sin and cos (2^-11 absolute): the
        // scattering maps' 1e-3, here of the correction's own peak, which
        // is a few per cent of the order-2 radiance; 1 % of the samples.
        let c = cpu.get::<Vec4>(&SEA_BOTTOM_CORRECTION);
        compare_rgb("bottom correction", gpu.get(&SEA_BOTTOM_CORRECTION), c, 1e-2, c.len() * 3 / 100 + 1)
    }
}
