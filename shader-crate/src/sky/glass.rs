//! The sky seen in glass: where a view ray's first hit is glass, the sky
//! and the sun's disk along the rays that leave the glass and meet nothing
//! more (the sky pass draws the sky only where no surface is seen, and the
//! surface pass follows the view through glass only to an opaque surface).
//!
//! Two parts, per channel (each channel on its own path through dispersive
//! glass), in W/(m^2 sr):
//! - **through**: the view ray refracted into the glass and out (every
//!   interface, total internal reflection inside followed:
//!   `glass::trace_through`), weighted by the Fresnel transmittances and
//!   Beer's law, `T L_sky(d_out)`;
//! - **reflected** at the first interface: `R(cos_i) L_sky(reflect(d))`,
//!   the Fresnel reflectance for unpolarised light (`optics::reflectance`,
//!   the same law as the transmittance, `R = 1 - T`).
//!
//! - **skylight behind**: where the path through the glass ends on a
//!   diffuse surface and the sky lights the scene (`lights_surfaces`), the
//!   sky's light on that surface (`light::sky_light_at`, its normal's
//!   irradiance and visibility rays from the point), times the path's
//!   transmittance and the medium's along its legs in the open, as the
//!   surface pass weights the sun's light there (`receiver_after`). The
//!   skylight pass reads one G-buffer texel, the glass's, and cannot.
//!
//! - **skylight mirrored**: where the reflected ray meets a diffuse surface
//!   (`common::surface::reflected_receiver`; the surface pass lights it
//!   with the lights), the sky's light on it times the reflectance.
//!
//! A ray that is lost in the glass, or (with a sea below the eye) goes
//! down toward the water adds nothing here (`sea.glass` draws the sea). Like
//! the sky seen directly, the sky through glass is not attenuated by a
//! `[medium]`.

use crate::camera::{camera_ray, in_image};
use crate::common::surface::{
    channel_part, glass_entry, receiver_after, reflectances, reflected_receiver, view_channels,
};
use crate::geometry::{trace_nearest, Geometry, NO_HIT};
use crate::glam::{UVec3, Vec3, Vec4, Vec4Swizzles};
use crate::glass::{is_glass, surface_epsilon, trace_through, Glass, PATH_OUT};
use crate::sky::light::sky_light_at;
use crate::sky::{sky_radiance, sun_disk, SkyParams, SEA_AROUND, SEA_BELOW};
use crate::types::{CommonParams, GBufferTexel, GlassTriangle, GlassVertex, GpuBvhNode, GpuMaterial, GpuSphere};
use crate::types::{GpuTriangle, MATERIAL_DIFFUSE, NO_OBJECT};
use spirv_std::spirv;

/// The sky and the sun's disk along unit `dir` from a point `from` of the
/// scene, if nothing is in the way and the sky is what lies that way (not
/// the sea), rgb W/(m^2 sr); else 0.
fn open_sky(
    p: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    geometry: &Geometry,
    from: Vec3,
    dir: Vec3,
) -> Vec3 {
    if p.sea == SEA_AROUND || (p.sea == SEA_BELOW && dir.y < 0.0) {
        return Vec3::ZERO;
    }
    let eps = surface_epsilon(from);
    if trace_nearest(from, dir, eps, NO_HIT, geometry).distance != NO_HIT {
        return Vec3::ZERO;
    }
    sky_along(p, transmittance, sky_view, dir)
}

/// `open_sky` along a ray already known to meet nothing.
fn sky_along(p: &SkyParams, transmittance: &[Vec4], sky_view: &[Vec4], dir: Vec3) -> Vec3 {
    if p.sea == SEA_AROUND || (p.sea == SEA_BELOW && dir.y < 0.0) {
        return Vec3::ZERO;
    }
    sky_radiance(p, transmittance, sky_view, dir) + sun_disk(p, transmittance, dir)
}

/// Per-pixel kernel of `sky.glass` at pixel `index`'s current sub-pixel
/// sample (`texel`: its G-buffer texel): the sky through and reflected in
/// the glass the view ray meets first (rgb, w = 0), else 0.
#[allow(clippy::too_many_arguments)]
pub fn sky_in_glass_pixel(
    index: u32,
    common: &CommonParams,
    p: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    irradiance: &[Vec4],
    texel: &GBufferTexel,
    geometry: &Geometry,
    glass: &Glass,
    materials: &[GpuMaterial],
) -> Vec4 {
    let x = index % common.width;
    let y = index / common.width;
    if texel.material == NO_OBJECT || !in_image(common, x, y) {
        return Vec4::ZERO;
    }
    if materials[texel.material as usize].kind != crate::types::MATERIAL_GLASS {
        return Vec4::ZERO;
    }
    let (origin, dir) = camera_ray(common, x, y);
    let hit = trace_nearest(origin, dir, 0.0, NO_HIT, geometry);
    if !is_glass(materials, &hit) {
        return Vec4::ZERO;
    }
    let entry = glass_entry(geometry, glass, origin, dir, &hit);
    let (point, n) = (entry.point, entry.normal);
    // The reflected ray is the same in every channel: traced once, to the
    // sky or to a surface the sky lights.
    let mirror = reflected_receiver(common, geometry, materials, &entry, &hit);
    let fresnel = reflectances(materials[hit.material as usize].ior, entry.cos_i);
    let mut out = Vec4::ZERO;
    if mirror.material == NO_OBJECT {
        out = sky_along(p, transmittance, sky_view, entry.mirror).extend(0.0) * fresnel;
    } else if mirror.found && p.lights_surfaces != 0 && materials[mirror.material as usize].kind == MATERIAL_DIFFUSE {
        let albedo = materials[mirror.material as usize].albedo.xyz();
        let light = sky_light_at(p, transmittance, sky_view, irradiance, geometry, mirror.point, mirror.normal, albedo);
        out = light.extend(0.0) * mirror.weight;
    }
    let channels = view_channels(materials, &hit);
    let mut c = 0;
    while c < channels {
        let path = trace_through(geometry, glass, materials, point, n, hit.material, dir, c, NO_OBJECT, true);
        let mut through = Vec4::ZERO;
        if path.status == PATH_OUT && path.next.distance == NO_HIT {
            let sky = open_sky(p, transmittance, sky_view, geometry, path.position, path.direction);
            through = sky.extend(0.0) * path.transmittance();
        } else if p.lights_surfaces != 0 {
            let r = receiver_after(common, hit.distance, &path);
            if r.found && materials[r.material as usize].kind == MATERIAL_DIFFUSE {
                let albedo = materials[r.material as usize].albedo.xyz();
                let light = sky_light_at(p, transmittance, sky_view, irradiance, geometry, r.point, r.normal, albedo);
                through = light.extend(0.0) * r.weight;
            }
        }
        out += channel_part(through, c, channels);
        c += 1;
    }
    Vec4::new(out.x, out.y, out.z, 0.0)
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn sky_glass_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] sky_view: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 62)] irradiance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 29)] glass_vertices: &[GlassVertex],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 30)] glass_triangles: &[GlassTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 83)] radiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let geometry = crate::scene_geometry(common, spheres, triangles, nodes);
        let glass = Glass { vertices: glass_vertices, triangles: glass_triangles };
        radiance[index as usize] = sky_in_glass_pixel(
            common.band_start + index,
            common,
            &params[0],
            transmittance,
            sky_view,
            irradiance,
            &gbuffer[index as usize],
            &geometry,
            &glass,
            materials,
        );
    }
}
