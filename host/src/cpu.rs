//! The CPU backend: the same per-invocation kernel functions as the SPIR-V
//! entry points, called for every invocation id in parallel with rayon.

use glam::Vec4;
use indicatif::{ParallelProgressIterator, ProgressBar};
use rayon::prelude::*;
use slicelight_shaders::{light, shafts, surface};

use crate::scene::SceneData;

/// `shadow_map_kernel` on the CPU: every light's shadow map, concatenated.
pub fn shadow_maps(data: &SceneData, progress: &ProgressBar) -> Vec<f32> {
    let p = &data.params;
    (0..p.shadow_texel_count)
        .into_par_iter()
        .progress_with(progress.clone())
        .map(|i| light::shadow_map_texel(i, p, &data.lights, &data.spheres, &data.triangles))
        .collect()
}

/// `surface_kernel` on the CPU: rgb = attenuated surface radiance, w = hit distance.
pub fn surface(data: &SceneData, shadow: &[f32], progress: &ProgressBar) -> Vec<Vec4> {
    let p = &data.params;
    (0..data.pixel_count())
        .into_par_iter()
        .progress_with(progress.clone())
        .map(|i| surface::surface_pixel(i, p, &data.lights, &data.spheres, &data.triangles, &data.light_map, shadow))
        .collect()
}

/// `shafts_kernel` on the CPU: adds in-scattered light to the surface image
/// in place; `w` becomes the number of `H I_l` samples evaluated.
pub fn shafts(data: &SceneData, shadow: &[f32], image: &mut [Vec4], progress: &ProgressBar) {
    let p = &data.params;
    image.par_iter_mut().enumerate().progress_with(progress.clone()).for_each(|(i, px)| {
        let s = shafts::shafts_pixel(i as u32, p, &data.lights, &data.light_map, shadow, &data.tables, px.w);
        *px = shafts::add_to_surface(*px, s);
    });
}
