//! The shadow-map pass: for every light, the depth of the nearest surface
//! along each texel's ray (the shadow test `H` of eq. 2 of the 2002 paper
//! reads it).

use crate::geometry::{trace_nearest, Geometry};
use crate::glam::UVec3;
use crate::light::{shadow_texel_ray, SHADOW_FAR};
use crate::types::{CommonParams, GpuBvhNode, GpuLight, GpuSphere, GpuTriangle};
use spirv_std::spirv;

/// Shadow-map texel kernel: the distance from the light (spot, metres along the
/// texel's ray) or from its entry plane (directional) to the nearest surface,
/// or `SHADOW_FAR`. `index` runs over the texels of all lights in order.
pub fn shadow_map_texel(index: u32, params: &CommonParams, lights: &[GpuLight], geometry: &Geometry) -> f32 {
    let mut l = 0;
    while l < params.light_count as usize {
        let light = lights[l];
        let count = light.shadow_resolution * light.shadow_resolution;
        if index >= light.shadow_offset && index < light.shadow_offset + count {
            let (origin, dir) = shadow_texel_ray(&light, index - light.shadow_offset);
            let hit = trace_nearest(origin, dir, 0.0, SHADOW_FAR, geometry);
            return hit.distance.min(SHADOW_FAR);
        }
        l += 1;
    }
    SHADOW_FAR
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn shadow_map_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] shadow: &mut [f32],
) {
    let index = crate::flat_index(id, groups);
    let params = &common[0];
    if index < params.shadow_texel_count {
        let geometry = crate::scene_geometry(params, spheres, triangles, nodes);
        shadow[index as usize] = shadow_map_texel(index, params, lights, &geometry);
    }
}
