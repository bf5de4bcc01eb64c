//! The lit-surface pass: surfaces lit directly by every light (cone, light map,
//! shadow map), seen through the medium. This is the first term of eq. 1 of the
//! 2002 shafts-of-light paper, `I_o exp(-rho kappa T)`, with `rho kappa = sigma_t`.
//! It also writes the G-buffer that later passes read.

use crate::camera::{camera_ray, in_image};
use crate::geometry::{occluded, trace_nearest, Geometry, NO_HIT};
use crate::glam::{UVec3, Vec3, Vec4, Vec4Swizzles};
use crate::light::{emitted, light_local, shadow_visibility, transmittance};
use crate::types::{
    CommonParams, GBufferTexel, GpuBvhNode, GpuLight, GpuMaterial, GpuSphere, GpuTriangle, LIGHT_DIRECTIONAL,
    NO_OBJECT, SHADOWS_MAP,
};
use core::f32::consts::FRAC_1_PI;
use spirv_std::spirv;

/// The G-buffer's distance at a pixel whose view ray hits nothing.
pub const MISS_DISTANCE: f32 = f32::MAX;

/// The G-buffer texel of a pixel that sees no surface.
pub fn no_surface() -> GBufferTexel {
    GBufferTexel {
        normal_distance: Vec4::new(0.0, 0.0, 0.0, MISS_DISTANCE),
        object: NO_OBJECT,
        material: NO_OBJECT,
        _pad: [0; 2],
    }
}

/// Radiance leaving a diffuse surface point `p` with unit normal `normal`
/// (facing the viewer) and albedo `albedo`, W/(m^2 sr) per channel:
/// `albedo / pi * sum_lights E`, where a spotlight gives the irradiance
/// `E = I_l H cos(theta) exp(-sigma_t s) / s^2` (the `I_o` of eq. 1) and a
/// directional light `E = E_l H cos(theta) exp(-sigma_t z)`, `z` the distance
/// travelled from its entry plane.
///
/// The shadow test `H` is an exact shadow ray through the BVH
/// (`SHADOWS_RAYS`, the default) or the light's shadow map (`SHADOWS_MAP`,
/// the 2002 paper's method, which misjudges pixels on shadow outlines).
#[allow(clippy::too_many_arguments)]
pub fn direct_radiance(
    params: &CommonParams,
    lights: &[GpuLight],
    geometry: &Geometry,
    light_map: &[Vec4],
    shadow: &[f32],
    p: Vec3,
    normal: Vec3,
    albedo: Vec4,
) -> Vec4 {
    let mut irradiance = Vec4::ZERO;
    let mut l = 0;
    while l < params.light_count as usize {
        let light = lights[l];
        let local = light_local(&light, p);
        let (to_light, distance, falloff) = if light.kind == LIGHT_DIRECTIONAL {
            (-light.axis_z.xyz(), local.z, 1.0)
        } else {
            let d = light.position.xyz() - p;
            let s = d.length();
            (d / s, s, 1.0 / (s * s))
        };
        let cos_incidence = normal.dot(to_light);
        if cos_incidence > 0.0 {
            let color = emitted(&light, light_map, local);
            if color.x > 0.0 || color.y > 0.0 || color.z > 0.0 {
                let visible = if params.surface_shadows == SHADOWS_MAP {
                    shadow_visibility(&light, shadow, local, cos_incidence)
                } else {
                    shadow_ray_visibility(geometry, p, normal, to_light, distance)
                };
                irradiance += color * transmittance(params.sigma_t, distance) * (visible * cos_incidence * falloff);
            }
        }
        l += 1;
    }
    let radiance = albedo * irradiance * FRAC_1_PI;
    Vec4::new(radiance.x, radiance.y, radiance.z, 0.0)
}

/// 1 if the segment from the surface point `p` (unit `normal`, facing the
/// light) toward the light is free of geometry, else 0. It starts a hair off
/// the surface along the normal and stops a hair short of the light (or of
/// a directional light's entry plane), both relative to the scene's scale
/// at `p` and to the distance, so the surface does not shadow itself in f32.
pub fn shadow_ray_visibility(geometry: &Geometry, p: Vec3, normal: Vec3, to_light: Vec3, distance: f32) -> f32 {
    let scale = p.abs().max_element().max(distance).max(1.0);
    let origin = p + normal * (1e-5 * scale);
    if occluded(origin, to_light, 1e-5 * scale, distance * (1.0 - 1e-5), geometry) {
        0.0
    } else {
        1.0
    }
}

/// Per-pixel kernel of the lit-surface pass, at the current sub-pixel
/// sample. Returns the attenuated surface radiance `I_o exp(-sigma_t T)`
/// (eq. 1, first term) in rgb, W/(m^2 sr) (w = 0), and the pixel's G-buffer
/// texel: normal toward the viewer, distance `T` (metres), object, material.
pub fn surface_pixel(
    index: u32,
    params: &CommonParams,
    lights: &[GpuLight],
    geometry: &Geometry,
    materials: &[GpuMaterial],
    light_map: &[Vec4],
    shadow: &[f32],
) -> (Vec4, GBufferTexel) {
    let x = index % params.width;
    let y = index / params.width;
    if !in_image(params, x, y) {
        return (Vec4::ZERO, no_surface());
    }
    let (origin, dir) = camera_ray(params, x, y);
    let hit = trace_nearest(origin, dir, 0.0, NO_HIT, geometry);
    if hit.distance == NO_HIT {
        return (Vec4::ZERO, no_surface());
    }
    let p = origin + dir * hit.distance;
    let normal = if hit.normal.dot(dir) > 0.0 { -hit.normal } else { hit.normal };
    let albedo = materials[hit.material as usize].albedo;
    let radiance = direct_radiance(params, lights, geometry, light_map, shadow, p, normal, albedo)
        * transmittance(params.sigma_t, hit.distance);
    let texel = GBufferTexel {
        normal_distance: normal.extend(hit.distance),
        object: hit.object,
        material: hit.material,
        _pad: [0; 2],
    };
    (Vec4::new(radiance.x, radiance.y, radiance.z, 0.0), texel)
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn surface_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] shadow: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &mut [GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 9)] radiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let params = &common[0];
    if index < params.band_pixels {
        let geometry = crate::scene_geometry(params, spheres, triangles, nodes);
        let (color, texel) =
            surface_pixel(params.band_start + index, params, lights, &geometry, materials, light_map, shadow);
        radiance[index as usize] = color;
        gbuffer[index as usize] = texel;
    }
}
