//! The CPU backend: the same per-invocation kernel functions as the SPIR-V
//! entry points, called for every invocation id in parallel with rayon.

use glam::Vec4;
use indicatif::ProgressBar;
use rayon::prelude::*;
use slicelight_shaders::{light, shafts, surface};

use crate::scene::SceneData;

/// Invocations per rayon task; the progress bar advances once per chunk, so
/// that counting progress costs nothing next to the kernels.
const CHUNK: usize = 4096;

/// Runs `kernel(index, &mut value)` for every element of `out` in parallel.
fn for_each_invocation<T: Send>(out: &mut [T], progress: &ProgressBar, kernel: impl Fn(u32, &mut T) + Sync) {
    out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, chunk)| {
        let first = c * CHUNK;
        for (k, value) in chunk.iter_mut().enumerate() {
            kernel((first + k) as u32, value);
        }
        progress.inc(chunk.len() as u64);
    });
}

/// `shadow_map_kernel` on the CPU: every light's shadow map, concatenated.
pub fn shadow_maps(data: &SceneData, progress: &ProgressBar) -> Vec<f32> {
    let p = &data.params;
    let mut out = vec![0.0; p.shadow_texel_count as usize];
    for_each_invocation(&mut out, progress, |i, v| {
        *v = light::shadow_map_texel(i, p, &data.lights, &data.spheres, &data.triangles, &data.groups)
    });
    out
}

/// `surface_kernel` on the CPU: rgb = attenuated surface radiance, w = hit distance.
pub fn surface(data: &SceneData, shadow: &[f32], progress: &ProgressBar) -> Vec<Vec4> {
    let p = &data.params;
    let mut out = vec![Vec4::ZERO; data.pixel_count() as usize];
    for_each_invocation(&mut out, progress, |i, v| {
        *v = surface::surface_pixel(i, p, &data.lights, &data.spheres, &data.triangles, &data.groups, &data.light_map, shadow)
    });
    out
}

/// `shafts_kernel` on the CPU: adds in-scattered light to the surface image
/// in place; `w` becomes the number of `H I_l` samples evaluated.
pub fn shafts(data: &SceneData, shadow: &[f32], image: &mut [Vec4], progress: &ProgressBar) {
    let p = &data.params;
    for_each_invocation(image, progress, |i, px| {
        let s = shafts::shafts_pixel(i, p, &data.lights, &data.light_map, shadow, &data.tables, px.w);
        *px = shafts::add_to_surface(*px, s);
    });
}
