//! slicelight's kernels.
//!
//! Every pass has a module here holding its pure per-invocation function
//! (`common::shadow_maps::shadow_map_texel`, `common::surface::surface_pixel`,
//! `shafts::shafts_pixel`, ...) and a thin `#[spirv(compute)]` entry point that
//! reads the invocation id, calls it and stores the result. The host's CPU
//! backend calls the same functions for every invocation id. There is one
//! copy of the math.
//!
//! Every entry point uses descriptor set 0; binding numbers belong to
//! resources, not to kernels, and the host lists each resource with its
//! binding once (`host/src/passes`). A host test reads the bindings each
//! entry point of the compiled SPIR-V declares and fails if they differ from
//! the host's.
#![cfg_attr(target_arch = "spirv", no_std)]

/// `light_ref!(light = lights, l)`: binds `light` to `&lights[l]` the way
/// each backend reads it fastest. A GPU keeps a copy of the light in
/// registers; on the CPU the copy is a 144-byte memcpy per pixel and light
/// that stalls the loads after it, so the light is read in place there
/// (measured: Fig. 6 shafts 39 -> 36 ms on the CPU, 103 -> 154 ms on
/// lavapipe reading in place).
macro_rules! light_ref {
    ($name:ident = $lights:expr, $l:expr) => {
        #[cfg(target_arch = "spirv")]
        let copy = $lights[$l];
        #[cfg(target_arch = "spirv")]
        let $name = &copy;
        #[cfg(not(target_arch = "spirv"))]
        let $name = &$lights[$l];
    };
}

// Shared math: the camera, ray-geometry intersection, the glass meshes,
// lights, optics (Fresnel, Snell), phase functions, the scattering
// integrals, and the structs the host uploads.
pub mod camera;
pub mod geometry;
pub mod glass;
pub mod light;
pub mod optics;
pub mod phase;
pub mod random;
pub mod scatter;
pub mod types;

// The families, each a folder named as its host folder (`host/src/<family>`).
pub mod caustics;
pub mod common;
pub mod desert;
pub mod sea;
pub mod shafts;
pub mod sky;
pub mod smoke;
pub mod volumes;

pub use spirv_std::glam;

use crate::glam::UVec3;
use geometry::Geometry;
use types::{CommonParams, GpuBvhNode, GpuSphere, GpuTriangle};

/// Threads per workgroup of every kernel; the host sizes its dispatches by it.
pub const WORKGROUP_SIZE: u32 = 64;

/// The flat invocation index of a 2D dispatch of 1D workgroups (the host
/// splits dispatches wider than the per-dimension limit into rows).
pub fn flat_index(id: UVec3, groups: UVec3) -> u32 {
    id.x + id.y * groups.x * WORKGROUP_SIZE
}

/// The scene's geometry buffers, with their counts from the common block.
pub fn scene_geometry<'a>(
    params: &CommonParams,
    spheres: &'a [GpuSphere],
    triangles: &'a [GpuTriangle],
    nodes: &'a [GpuBvhNode],
) -> Geometry<'a> {
    Geometry { spheres, sphere_count: params.sphere_count, triangles, nodes, node_count: params.bvh_node_count }
}

/// The unit tests' uniform numbers in [0, 1): a 32-bit linear congruential
/// generator (Numerical Recipes' constants), top 24 bits of each state.
#[cfg(test)]
pub(crate) fn test_uniforms(seed: u32) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32
    }
}
