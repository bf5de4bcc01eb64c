//! The lit-surface pass: surfaces lit directly by every light (cone, light map,
//! shadow map), seen through the medium. This is the first term of eq. 1 of the
//! 2002 shafts-of-light paper, `I_o exp(-rho kappa T)`, with `rho kappa = sigma_t`.
//! It also writes the G-buffer that later passes read.

use crate::camera::{camera_ray, in_image};
use crate::caustics::{caustic_light, pack_rgb, CausticsParams};
use crate::desert::ripples::{rippled, RippleRecord, Ripples};
use crate::geometry::{occluded, trace_nearest, Geometry, Hit, NO_HIT};
use crate::glam::{UVec3, Vec3, Vec4, Vec4Swizzles};
use crate::glass::{dispersive, is_glass, shading_normal, surface_epsilon, trace_through, Glass, GlassPath, PATH_OUT};
use crate::light::{emitted, emitted_visible, light_local, transmittance};
use crate::optics::{reflect, reflectance};
use crate::types::{
    CommonParams, GBufferTexel, GlassTriangle, GlassVertex, GpuBvhNode, GpuLight, GpuMaterial, GpuSphere, GpuTriangle,
    LIGHT_DIRECTIONAL, NO_OBJECT, SHADOWS_MAP,
};
use crate::volumes::{light_transmittance, LightGrid};
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
        caustic: [0; 2],
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
///
/// Each light's irradiance is also multiplied by its transmittance through
/// the volumes (`exp(-tau)`, `volumes::light_optical_depth` from the
/// light's transmittance volume): the clouds' shadows.
pub fn direct_radiance(
    params: &CommonParams,
    lights: &[GpuLight],
    geometry: &Geometry,
    inputs: &LightInputs,
    p: Vec3,
    normal: Vec3,
    albedo: Vec4,
) -> Vec4 {
    let (light_map, shadow) = (inputs.light_map, inputs.shadow);
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
            let clouds = volume_transmittance(inputs, &light, l, p);
            if params.surface_shadows == SHADOWS_MAP && light.shadow_resolution > 0 {
                let lit = emitted_visible(&light, light_map, shadow, local, cos_incidence);
                irradiance += lit * clouds * transmittance(params.sigma_t, distance) * (cos_incidence * falloff);
            } else {
                let color = emitted(&light, light_map, local);
                if color.x > 0.0 || color.y > 0.0 || color.z > 0.0 {
                    let visible = shadow_ray_visibility(geometry, p, normal, to_light, distance);
                    irradiance +=
                        color * clouds * transmittance(params.sigma_t, distance) * (visible * cos_incidence * falloff);
                }
            }
        }
        l += 1;
    }
    let radiance = albedo * irradiance * FRAC_1_PI;
    Vec4::new(radiance.x, radiance.y, radiance.z, 0.0)
}

/// What the lights' terms read besides the lights: their light maps and
/// shadow maps, and the volumes' transmittance volumes (one `LightGrid` per
/// light and their optical depths; empty in a scene without volumes).
#[derive(Copy, Clone)]
pub struct LightInputs<'a> {
    pub light_map: &'a [Vec4],
    pub shadow: &'a [f32],
    pub grids: &'a [LightGrid],
    pub depths: &'a [Vec4],
}

/// Light `l`'s transmittance (rgb) through the volumes to `p`
/// (`volumes::light_transmittance`).
pub fn volume_transmittance(inputs: &LightInputs, light: &GpuLight, l: usize, p: Vec3) -> Vec4 {
    light_transmittance(inputs.grids, inputs.depths, light, l, p)
}

/// 1 if the segment from the surface point `p` (unit `normal`, facing the
/// light) toward the light is free of geometry, else 0. The ray starts at
/// `p` itself and counts hits from `1e-5` of `p`'s magnitude (at least 1 m)
/// on, divided by the cosine of incidence (where f32 rounding of `p` could
/// meet its own surface again), to a hair short of the light (or of a
/// directional light's entry plane). An origin moved off the surface along
/// the normal instead would move every shadow's outline by that much: 57 µm
/// in Fig. 6, where the sphere's outline passes 3 µm from a pixel centre.
///
/// The light's distance takes no part in where hits start: a sun's entry
/// plane lies at the scene's bounds, 400 km off in a scene with a ground
/// to the horizon, and `1e-5` of that skipped the first 4 m / cos of every
/// shadow ray: no object shadowed the ground it stood on (`desert_garden`,
/// 4.1 % RMS against the reference, 0.56 % without).
pub fn shadow_ray_visibility(geometry: &Geometry, p: Vec3, normal: Vec3, to_light: Vec3, distance: f32) -> f32 {
    let scale = p.abs().max_element().max(1.0);
    let t_min = 1e-5 * scale / normal.dot(to_light).max(1e-3);
    if occluded(p, to_light, t_min, distance * (1.0 - 1e-5), geometry) {
        0.0
    } else {
        1.0
    }
}

/// The opaque surface a view ray finally lands on, directly or through glass.
#[derive(Copy, Clone, Debug)]
pub struct Receiver {
    /// False if the ray meets no opaque surface (or is lost in glass).
    pub found: bool,
    /// The point, metres, and its unit normal turned toward the arriving ray.
    pub point: Vec3,
    pub normal: Vec3,
    pub material: u32,
    /// Transmittance per channel along the way (w = 0): the medium's, and
    /// through glass the Fresnel transmittances and Beer's law.
    pub weight: Vec4,
}

/// Where the view ray `origin + t dir`, whose first hit is `hit`, ends: the
/// hit itself if it is opaque; through glass (section 5.3 of the caustics
/// paper, traced exactly here rather than looked up in the table), the
/// first opaque surface after the glass, in channel `channel` (a dispersive
/// glass sends each channel its own way). Total internal reflection inside
/// glass is followed; the surface mirrored in the glass is `reflected_receiver`'s.
#[allow(clippy::too_many_arguments)]
pub fn receiver(
    params: &CommonParams,
    geometry: &Geometry,
    glass: &Glass,
    materials: &[GpuMaterial],
    origin: Vec3,
    dir: Vec3,
    hit: &Hit,
    channel: u32,
) -> Receiver {
    if hit.distance == NO_HIT {
        return Receiver { found: false, point: origin, normal: Vec3::Y, material: NO_OBJECT, weight: Vec4::ZERO };
    }
    if !is_glass(materials, hit) {
        return opaque_receiver(params, origin, dir, hit);
    }
    let p = origin + dir * hit.distance;
    let n = shading_normal(geometry, glass, hit, p);
    let path = trace_through(geometry, glass, materials, p, n, hit.material, dir, channel, NO_OBJECT, true);
    receiver_after(params, hit.distance, &path)
}

/// The opaque surface at the end of `path`, the way through glass of a
/// view ray whose first hit (the glass) is `hit_distance` m from the eye:
/// not found if the path is lost or leaves for the sky.
pub fn receiver_after(params: &CommonParams, hit_distance: f32, path: &GlassPath) -> Receiver {
    let next = path.next;
    if path.status != PATH_OUT || next.distance == NO_HIT {
        return Receiver {
            found: false,
            point: path.position,
            normal: Vec3::Y,
            material: NO_OBJECT,
            weight: Vec4::ZERO,
        };
    }
    Receiver {
        found: true,
        point: path.position + path.direction * next.distance,
        normal: if next.normal.dot(path.direction) > 0.0 { -next.normal } else { next.normal },
        material: next.material,
        weight: path.transmittance() * transmittance(params.sigma_t, hit_distance + next.distance),
    }
}

/// Where a view ray `origin + t dir` meets glass first (`hit`): the point,
/// the shading normal there (`glass::shading_normal`), the normal turned
/// against the ray, the cosine of incidence and the mirror direction.
pub struct GlassEntry {
    pub point: Vec3,
    pub normal: Vec3,
    pub facing: Vec3,
    pub cos_i: f32,
    pub mirror: Vec3,
}

/// The interface a view ray meets at its first hit `hit` (glass).
pub fn glass_entry(geometry: &Geometry, glass: &Glass, origin: Vec3, dir: Vec3, hit: &Hit) -> GlassEntry {
    let point = origin + dir * hit.distance;
    let normal = shading_normal(geometry, glass, hit, point);
    let facing = if normal.dot(dir) > 0.0 { -normal } else { normal };
    let cos_i = (-facing.dot(dir)).clamp(0.0, 1.0);
    GlassEntry { point, normal, facing, cos_i, mirror: reflect(dir, facing) }
}

/// The Fresnel reflectance for unpolarised light (`optics::reflectance`,
/// from air into index `ior` per channel) at cosine `cos_i`, rgb (w = 0).
pub fn reflectances(ior: Vec4, cos_i: f32) -> Vec4 {
    let r = |n: f32| reflectance(cos_i, 1.0 / n);
    Vec4::new(r(ior.x), r(ior.y), r(ior.z), 0.0)
}

/// The opaque surface seen in glass by reflection: the view ray
/// `origin + t dir` whose first hit `hit` is glass, mirrored at that
/// interface (`glass_entry`) and traced to the next surface. Its weight is
/// the Fresnel reflectance per channel (`reflectances`) times the medium's
/// transmittance over both legs, as `receiver_after` weights a path through
/// the glass. Not found where the first hit is not glass or the mirrored
/// ray meets nothing or glass again (one reflection, not followed into a
/// second glass); `material` is then the second hit's, or `NO_OBJECT`.
#[allow(clippy::too_many_arguments)]
pub fn reflected_receiver(
    params: &CommonParams,
    geometry: &Geometry,
    materials: &[GpuMaterial],
    entry: &GlassEntry,
    hit: &Hit,
) -> Receiver {
    let next = trace_nearest(entry.point, entry.mirror, surface_epsilon(entry.point), NO_HIT, geometry);
    let mut r = Receiver { found: false, point: entry.point, normal: Vec3::Y, material: NO_OBJECT, weight: Vec4::ZERO };
    if next.distance == NO_HIT {
        return r;
    }
    r.material = next.material;
    if is_glass(materials, &next) {
        return r;
    }
    r.found = true;
    r.point = entry.point + entry.mirror * next.distance;
    r.normal = if next.normal.dot(entry.mirror) > 0.0 { -next.normal } else { next.normal };
    let fresnel = reflectances(materials[hit.material as usize].ior, entry.cos_i);
    r.weight = fresnel * transmittance(params.sigma_t, hit.distance + next.distance);
    r
}

/// `receiver` of a view ray whose first hit `hit` (a hit) is opaque: the
/// hit itself.
pub fn opaque_receiver(params: &CommonParams, origin: Vec3, dir: Vec3, hit: &Hit) -> Receiver {
    Receiver {
        found: true,
        point: origin + dir * hit.distance,
        normal: if hit.normal.dot(dir) > 0.0 { -hit.normal } else { hit.normal },
        material: hit.material,
        weight: transmittance(params.sigma_t, hit.distance),
    }
}

/// Channels traced separately for a view ray whose first hit is `hit`: 3
/// through dispersive glass, else 1 (every channel takes the same path).
pub fn view_channels(materials: &[GpuMaterial], hit: &Hit) -> u32 {
    if is_glass(materials, hit) && dispersive(&materials[hit.material as usize]) {
        3
    } else {
        1
    }
}

/// `v` with only channel `c` kept when `channels` is 3 (all of it when 1).
pub fn channel_part(v: Vec4, c: u32, channels: u32) -> Vec4 {
    if channels == 1 {
        v
    } else if c == 0 {
        Vec4::new(v.x, 0.0, 0.0, 0.0)
    } else if c == 1 {
        Vec4::new(0.0, v.y, 0.0, 0.0)
    } else {
        Vec4::new(0.0, 0.0, v.z, 0.0)
    }
}

/// Per-pixel kernel of the lit-surface pass, at the current sub-pixel
/// sample. Returns the attenuated surface radiance `I_o exp(-sigma_t T)`
/// (eq. 1, first term) in rgb, W/(m^2 sr) (w = 0), and the pixel's G-buffer
/// texel: normal toward the viewer, distance `T` (metres), object, material.
/// A pixel that sees glass gets the opaque surface behind it (`receiver`)
/// and the one mirrored in it (`reflected_receiver`); its G-buffer texel is
/// the glass's.
///
/// `GLASS` false compiles the function for a scene without glass (every
/// surface opaque, no caustics maps): the same result without the glass
/// code, which a GPU would otherwise carry through every pixel (on
/// llvmpipe, Fig. 6's surface pass takes 97 ms without it, 287 ms with it,
/// though no pixel takes it).
#[allow(clippy::too_many_arguments)]
pub fn surface_pixel<const GLASS: bool>(
    index: u32,
    params: &CommonParams,
    lights: &[GpuLight],
    geometry: &Geometry,
    glass: &Glass,
    materials: &[GpuMaterial],
    inputs: &LightInputs,
    caustics: &CausticsParams,
    caustic_maps: &[u32],
    ripples: &Ripples,
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
    let mut normal = if hit.normal.dot(dir) > 0.0 { -hit.normal } else { hit.normal };
    // A terrain's ripples tilt the shading normal of what the eye sees
    // directly (the survey's 5.2).
    let bump = materials[hit.material as usize].ripples;
    if bump != 0 && hit.primitive != NO_OBJECT {
        let triangle = &geometry.triangles[hit.primitive as usize];
        normal = rippled(
            params,
            ripples.records,
            ripples.normals,
            bump,
            triangle,
            origin,
            origin + dir * hit.distance,
            normal,
        );
    }
    let mut radiance = Vec4::ZERO;
    let mut caustic = Vec4::ZERO;
    if GLASS {
        let channels = view_channels(materials, &hit);
        let mut c = 0;
        while c < channels {
            let mut r = receiver(params, geometry, glass, materials, origin, dir, &hit, c);
            if bump != 0 && !is_glass(materials, &hit) {
                r.normal = normal;
            }
            if r.found {
                let albedo = materials[r.material as usize].albedo;
                let l = direct_radiance(params, lights, geometry, inputs, r.point, r.normal, albedo) * r.weight;
                radiance += channel_part(l, c, channels);
                // The caustic light at the same receiver, for the caustics
                // layer (the view through glass is traced once, here).
                caustic += channel_part(caustic_light(caustic_maps, caustics, materials, &r), c, channels);
            }
            c += 1;
        }
        // The opaque surface mirrored in the glass, lit the same way.
        if is_glass(materials, &hit) {
            let entry = glass_entry(geometry, glass, origin, dir, &hit);
            let r = reflected_receiver(params, geometry, materials, &entry, &hit);
            if r.found {
                let albedo = materials[r.material as usize].albedo;
                radiance += direct_radiance(params, lights, geometry, inputs, r.point, r.normal, albedo) * r.weight;
                caustic += caustic_light(caustic_maps, caustics, materials, &r);
            }
        }
    } else {
        let mut r = opaque_receiver(params, origin, dir, &hit);
        r.normal = normal;
        let albedo = materials[r.material as usize].albedo;
        radiance = direct_radiance(params, lights, geometry, inputs, r.point, r.normal, albedo) * r.weight;
    }
    let texel = GBufferTexel {
        normal_distance: normal.extend(hit.distance),
        object: hit.object,
        material: hit.material,
        caustic: pack_rgb(caustic.truncate()),
    };
    (Vec4::new(radiance.x, radiance.y, radiance.z, 0.0), texel)
}

/// The surface pass's entry points: `$name` runs `surface_pixel::<$glass>`.
macro_rules! surface_entry_point {
    ($(#[$doc:meta])* $name:ident, $glass:literal) => {
        $(#[$doc])*
        #[allow(clippy::too_many_arguments)]
        #[spirv(compute(threads(64)))]
        pub fn $name(
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
            #[spirv(storage_buffer, descriptor_set = 0, binding = 29)] glass_vertices: &[GlassVertex],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 30)] glass_triangles: &[GlassTriangle],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 31)] caustics: &[CausticsParams],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 34)] caustic_maps: &[u32],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 66)] ripple_records: &[RippleRecord],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 67)] ripple_normals: &[Vec4],
        ) {
            let index = crate::flat_index(id, groups);
            let params = &common[0];
            if index < params.band_pixels {
                let geometry = crate::scene_geometry(params, spheres, triangles, nodes);
                let glass = Glass { vertices: glass_vertices, triangles: glass_triangles };
                let (color, texel) = surface_pixel::<$glass>(
                    params.band_start + index,
                    params,
                    lights,
                    &geometry,
                    &glass,
                    materials,
                    &LightInputs { light_map, shadow, grids, depths },
                    &caustics[0],
                    caustic_maps,
                    &Ripples { records: ripple_records, normals: ripple_normals },
                );
                radiance[index as usize] = color;
                gbuffer[index as usize] = texel;
            }
        }
    };
}

surface_entry_point!(
    /// The surface pass's entry point for a scene with glass.
    surface_kernel,
    true
);
surface_entry_point!(
    /// The surface pass's entry point for a scene without glass.
    surface_opaque_kernel,
    false
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shadow_outlines_lie_where_the_geometry_puts_them() {
        // Fig. 6's light and sphere; floor points whose segment to the light
        // passes the sphere's surface within 2e-5 of its radius (11 µm),
        // inside or outside: the shadow ray must decide as the exact
        // geometry does (an origin moved 57 µm off the floor moved the
        // outline past such points).
        let (light, center, radius) = (Vec3::new(0.0, 5.5, 0.0), Vec3::new(0.0, 3.4, 0.0), 0.55f32);
        let spheres = [GpuSphere { center_radius: center.extend(radius), ..Default::default() }];
        let geometry = Geometry { spheres: &spheres, sphere_count: 1, triangles: &[], nodes: &[], node_count: 0 };
        // The outline on the floor is a circle of radius R around the axis:
        // sin(half-angle) = radius / |light - center|.
        let (lc, h) = ((light - center).length() as f64, light.y as f64);
        let half = (radius as f64 / lc).asin();
        let outline = h * half.tan();
        let mut checked = 0;
        for k in 0..64 {
            let phi = k as f64 * 0.0981;
            for (margin, lit) in [(1.0 + 2e-5, true), (1.0 - 2e-5, false)] {
                let r = outline * margin;
                let p = Vec3::new((r * phi.cos()) as f32, 0.0, (r * phi.sin()) as f32);
                // Where the f32 point really is, the exact distance from the
                // segment to the centre decides (f64).
                let (pd, ld, cd) = (p.as_dvec3(), light.as_dvec3(), center.as_dvec3());
                let dir = (ld - pd).normalize();
                let w = cd - pd;
                let gap = (w - dir * w.dot(dir)).length() - radius as f64;
                if gap.abs() < 2e-6 {
                    continue;
                }
                assert_eq!(gap > 0.0, lit, "the point's f32 rounding crossed the outline");
                let to_light = light - p;
                let distance = to_light.length();
                let seen = shadow_ray_visibility(&geometry, p, Vec3::Y, to_light / distance, distance);
                assert_eq!(seen, if lit { 1.0 } else { 0.0 }, "{p}: {gap:e} m from the sphere");
                checked += 1;
            }
        }
        assert!(checked > 120, "{checked}");
    }

    #[test]
    fn a_far_sun_still_casts_near_shadows() {
        // A sun whose entry plane is 400 km off (the bounds of a scene with
        // a ground to the horizon), a ground triangle as wide at y = 0 and
        // a 2 cm ball 10 cm above it: the point under the ball, toward the
        // sun, is in its shadow; points on the wide ground beside it see
        // the sun (the ground does not shadow itself). With hits counted
        // from 1e-5 of the entry plane's distance (4 m), the ball was
        // skipped.
        let far = 4.0e5f32;
        let to_sun = Vec3::new(0.3, 1.0, 0.2).normalize();
        let ball = to_sun * 0.1;
        let spheres = [GpuSphere { center_radius: ball.extend(0.02), ..Default::default() }];
        let triangles = [GpuTriangle {
            v0: Vec4::new(-far, 0.0, -far, 1.0),
            v1: Vec4::new(far, 0.0, -far, 1.0),
            v2: Vec4::new(0.0, 0.0, far, 1.0),
            ..Default::default()
        }];
        let nodes = [GpuBvhNode {
            bounds_min: Vec4::new(-far, -1.0, -far, 0.0),
            bounds_max: Vec4::new(far, 1.0, far, 0.0),
            first: 0,
            count: 1,
            skip: 1,
            right: 0,
        }];
        let geometry =
            Geometry { spheres: &spheres, sphere_count: 1, triangles: &triangles, nodes: &nodes, node_count: 1 };
        assert_eq!(shadow_ray_visibility(&geometry, Vec3::ZERO, Vec3::Y, to_sun, far), 0.0);
        for p in [Vec3::new(0.5, 0.0, 0.0), Vec3::new(-3.0, 0.0, 7.0), Vec3::new(1000.0, 0.0, -2000.0)] {
            assert_eq!(shadow_ray_visibility(&geometry, p, Vec3::Y, to_sun, far), 1.0, "{p}");
        }
    }
}
