//! slicelight's kernels.
//!
//! Every kernel is a pure per-invocation function (`shadow_map_texel`,
//! `surface_pixel`, ...) that the host's CPU backend calls for every invocation
//! id, and that a thin `#[spirv(compute)]` entry point below calls on the GPU.
//! There is one copy of the math.
//!
//! All entry points share one binding layout (descriptor set 0), so the host
//! binds the same buffers to every kernel:
//!
//! | binding | contents | type |
//! |---|---|---|
//! | 0 | frame parameters (one element) | `FrameParams` |
//! | 1 | lights | `GpuLight` |
//! | 2 | spheres | `GpuSphere` |
//! | 3 | triangles | `GpuTriangle` |
//! | 4 | light-map texels of all lights | `Vec4` |
//! | 5 | shadow-map depths of all lights | `f32` |
//! | 6 | output image, or a band of its rows (rgb radiance, w = hit distance) | `Vec4` |
//! | 7 | shaft tables: phase `F`, then attenuation `h` | `Vec4` |
//! | 8 | triangle groups (bounding boxes of the objects' triangle runs) | `GpuTriangleGroup` |
#![cfg_attr(target_arch = "spirv", no_std)]

pub mod geometry;
pub mod light;
pub mod phase;
pub mod shafts;
pub mod surface;
pub mod types;

pub use spirv_std::glam;

use crate::glam::{UVec3, Vec4};
use spirv_std::spirv;
use types::{FrameParams, GpuLight, GpuSphere, GpuTriangle, GpuTriangleGroup};

/// Threads per workgroup of every kernel; the host sizes its dispatches by it.
pub const WORKGROUP_SIZE: u32 = 64;

/// The flat invocation index of a 2D dispatch of 1D workgroups (the host
/// splits dispatches wider than the per-dimension limit into rows).
fn flat_index(id: UVec3, groups: UVec3) -> u32 {
    id.x + id.y * groups.x * WORKGROUP_SIZE
}

#[spirv(compute(threads(64)))]
pub fn shadow_map_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] params: &[FrameParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] shadow: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] triangle_groups: &[GpuTriangleGroup],
) {
    let index = flat_index(id, groups);
    let params = &params[0];
    if index < params.shadow_texel_count {
        shadow[index as usize] = light::shadow_map_texel(index, params, lights, spheres, triangles, triangle_groups);
    }
}

#[spirv(compute(threads(64)))]
pub fn surface_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] params: &[FrameParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] shadow: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] output: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] triangle_groups: &[GpuTriangleGroup],
) {
    let index = flat_index(id, groups);
    let params = &params[0];
    if index < params.band_pixels {
        output[index as usize] = surface::surface_pixel(
            params.band_start + index,
            params,
            lights,
            spheres,
            triangles,
            triangle_groups,
            light_map,
            shadow,
        );
    }
}

#[spirv(compute(threads(64)))]
pub fn shafts_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] params: &[FrameParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] shadow: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] output: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] tables: &[Vec4],
) {
    let index = flat_index(id, groups);
    let params = &params[0];
    if index < params.band_pixels {
        let surface = output[index as usize];
        let pixel = params.band_start + index;
        let shafts = shafts::shafts_pixel(pixel, params, lights, light_map, shadow, tables, surface.w);
        output[index as usize] = shafts::add_to_surface(surface, shafts);
    }
}
