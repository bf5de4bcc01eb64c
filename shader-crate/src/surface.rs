//! The lit-surface pass: surfaces lit directly by every light (cone, light map,
//! shadow map), seen through the medium. This is the first term of eq. 1 of the
//! 2002 shafts-of-light paper, `I_o exp(-rho kappa T)`, with `rho kappa = sigma_t`.

use crate::geometry::{trace_nearest, NO_HIT};
use crate::light::{emitted, light_local, shadow_visibility, transmittance};
use crate::types::{FrameParams, GpuLight, GpuSphere, GpuTriangle, GpuTriangleGroup, LIGHT_DIRECTIONAL};
use core::f32::consts::FRAC_1_PI;
use crate::glam::{Vec3, Vec4, Vec4Swizzles};

/// Stored in the `w` channel of a pixel whose view ray hits nothing.
pub const MISS_DISTANCE: f32 = f32::MAX;

/// Unit view ray through the centre of pixel `(x, y)` (row 0 at the top):
/// origin and direction.
pub fn camera_ray(params: &FrameParams, x: u32, y: u32) -> (Vec3, Vec3) {
    let ndc_x = 2.0 * (x as f32 + 0.5) / params.width as f32 - 1.0;
    let ndc_y = 1.0 - 2.0 * (y as f32 + 0.5) / params.height as f32;
    let dir = params.camera_forward.xyz() + params.camera_right.xyz() * ndc_x + params.camera_up.xyz() * ndc_y;
    (params.camera_position.xyz(), dir.normalize())
}

/// Radiance leaving a diffuse surface point `p` with unit normal `normal`
/// (facing the viewer) and albedo `albedo`, W/(m^2 sr) per channel:
/// `albedo / pi * sum_lights E`, where a spotlight gives the irradiance
/// `E = I_l H cos(theta) exp(-sigma_t s) / s^2` (the `I_o` of eq. 1) and a
/// directional light `E = E_l H cos(theta) exp(-sigma_t z)`, `z` the distance
/// travelled from its entry plane.
pub fn direct_radiance(
    params: &FrameParams,
    lights: &[GpuLight],
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
                let visible = shadow_visibility(&light, shadow, local, cos_incidence);
                irradiance += color * transmittance(params.sigma_t, distance) * (visible * cos_incidence * falloff);
            }
        }
        l += 1;
    }
    let radiance = albedo * irradiance * FRAC_1_PI;
    Vec4::new(radiance.x, radiance.y, radiance.z, 0.0)
}

/// Per-pixel kernel of the lit-surface pass. Returns the attenuated surface
/// radiance `I_o exp(-sigma_t T)` (eq. 1, first term) in rgb, W/(m^2 sr), and
/// the distance `T` to the surface in `w` (metres; `MISS_DISTANCE` if none),
/// which later passes use to end their integrals.
pub fn surface_pixel(
    index: u32,
    params: &FrameParams,
    lights: &[GpuLight],
    spheres: &[GpuSphere],
    triangles: &[GpuTriangle],
    groups: &[GpuTriangleGroup],
    light_map: &[Vec4],
    shadow: &[f32],
) -> Vec4 {
    let x = index % params.width;
    let y = index / params.width;
    let (origin, dir) = camera_ray(params, x, y);
    let hit = trace_nearest(
        origin,
        dir,
        0.0,
        NO_HIT,
        spheres,
        params.sphere_count,
        triangles,
        groups,
        params.group_count,
    );
    if hit.distance == NO_HIT {
        return Vec4::new(0.0, 0.0, 0.0, MISS_DISTANCE);
    }
    let p = origin + dir * hit.distance;
    let normal = if hit.normal.dot(dir) > 0.0 { -hit.normal } else { hit.normal };
    let radiance = direct_radiance(params, lights, light_map, shadow, p, normal, hit.albedo)
        * transmittance(params.sigma_t, hit.distance);
    Vec4::new(radiance.x, radiance.y, radiance.z, hit.distance)
}
