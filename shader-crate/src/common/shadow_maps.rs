//! The shadow-map pass: for every light, the depth of the nearest surface
//! along each texel's ray (the shadow test `H` of eq. 2 of the 2002 paper
//! reads it).

use crate::geometry::{trace_nearest, Geometry};
use crate::glam::UVec3;
use crate::light::{shadow_texel_ray, SHADOW_FAR};
use crate::types::{CommonParams, GpuBvhNode, GpuLight, GpuSphere, GpuTriangle, LIGHT_SPOT};
use spirv_std::spirv;

/// Shadow-map texel kernel: the distance from the light (spot, metres along the
/// texel's ray) or from its entry plane (directional) to the nearest surface,
/// or `SHADOW_FAR`. `index` runs over the texels of all lights in order.
pub fn shadow_map_texel(index: u32, params: &CommonParams, lights: &[GpuLight], geometry: &Geometry) -> f32 {
    let mut l = 0;
    while l < params.light_count as usize {
        let (offset, res) = (lights[l].shadow_offset, lights[l].shadow_resolution);
        if index >= offset && index < offset + res * res {
            return light_texel(&lights[l], index - offset, geometry);
        }
        l += 1;
    }
    SHADOW_FAR
}

/// Texel `texel` of `light`'s shadow map (see `shadow_map_texel`). The light
/// is read where it lies, not copied: on the CPU, a copy of the 144-byte
/// struct per texel cost as much as tracing the texel's ray.
fn light_texel(light: &GpuLight, texel: u32, geometry: &Geometry) -> f32 {
    if light.kind == LIGHT_SPOT && outside_the_cone(light, texel) {
        return SHADOW_FAR;
    }
    let (origin, dir) = shadow_texel_ray(light, texel);
    trace_nearest(origin, dir, 0.0, SHADOW_FAR, geometry).distance.min(SHADOW_FAR)
}

/// Whether a spot's shadow-map texel lies wholly outside its cone (the
/// corners of the square map, 21 % of it): the shadow test runs only where
/// the light shines (`light::emitted_visible`), inside the cone, whose
/// points map into the disc `|2 uv - 1| <= 1`; a texel whose nearest point
/// is beyond it (by 1e-3, for rounding) is never read and is not traced.
pub fn outside_the_cone(light: &GpuLight, texel: u32) -> bool {
    let res = light.shadow_resolution;
    let (a, b) = (nearest_to_axis(texel % res, res), nearest_to_axis(texel / res, res));
    a * a + b * b > 1.002
}

/// The coordinate in [-1, 1] nearest 0 of texel column (or row) `i` of `res`.
fn nearest_to_axis(i: u32, res: u32) -> f32 {
    let (lo, hi) = (2.0 * i as f32 / res as f32 - 1.0, 2.0 * (i + 1) as f32 / res as f32 - 1.0);
    if lo > 0.0 {
        lo
    } else if hi < 0.0 {
        hi
    } else {
        0.0
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::glam::{Vec3, Vec4};
    use crate::light::{cone_terms, light_uv};

    #[test]
    fn every_texel_a_point_in_the_cone_reads_is_traced() {
        // Points inside cones of 5 to 85 degrees, up to the rim, at several
        // resolutions: the texel each reads is never one `outside_the_cone`
        // skips; and the skipped share is about 1 - pi/4 at 512^2.
        let mut next = crate::test_uniforms(7);
        for (deg, res) in [(5.0f32, 64u32), (30.0, 512), (60.0, 129), (85.0, 1024)] {
            let (tan_cutoff, cos2_cutoff, sin2_cutoff) = cone_terms(deg.to_radians());
            let light = GpuLight {
                axis_x: Vec4::X,
                axis_y: Vec4::Y,
                axis_z: Vec4::Z,
                cutoff: deg.to_radians(),
                tan_cutoff,
                cos2_cutoff,
                sin2_cutoff,
                shadow_resolution: res,
                ..Default::default()
            };
            for _ in 0..20_000 {
                let (r, phi) = ((1.0 - next() * next()).sqrt(), core::f32::consts::TAU * next());
                let z = 0.1 + 10.0 * next();
                let local = Vec3::new(r * phi.cos() * z * tan_cutoff, r * phi.sin() * z * tan_cutoff, z);
                let (u, v) = light_uv(&light, local);
                let (i, j) = (((u * res as f32) as u32).min(res - 1), ((v * res as f32) as u32).min(res - 1));
                assert!(!outside_the_cone(&light, j * res + i), "{deg} deg, {res}: {local} reads a skipped texel");
            }
            if res == 512 {
                let skipped = (0..res * res).filter(|&t| outside_the_cone(&light, t)).count() as f32;
                let share = skipped / (res * res) as f32;
                assert!((share - (1.0 - core::f32::consts::FRAC_PI_4)).abs() < 0.01, "{share}");
            }
        }
    }
}
