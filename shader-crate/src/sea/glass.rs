//! The sea seen in glass: where a view ray's first hit is glass and the
//! eye is above the water, the sea along the rays that leave the glass
//! downward and meet nothing more (the sea passes draw only pixels whose
//! view ray meets the water directly; `sky.glass` adds the sky where the
//! rays leave upward).
//!
//! Per channel (each its own path through dispersive glass), in
//! W/(m^2 sr):
//! - **through**: the view ray refracted into the glass and out
//!   (`glass::trace_through`), weighted by the Fresnel transmittances and
//!   Beer's law, times the sea along the ray that leaves: `T L_sea`;
//! - **reflected** at the first interface where the reflected ray goes
//!   down to the water: `R(cos_i) L_sea(reflect(d))`.
//!
//! `L_sea` is what the sea passes give an eye whose view ray is that ray
//! (`sea_along`): the sky and the sun reflected at the surface, and below
//! it orders 1 and 2 and the bottom (or an object under the water) times
//! the transmission; the slopes are the wave map's at the point with the
//! unresolved waves' roughness (no pixel footprint: the glass has bent the
//! ray), and order 2 without the depth table's per-pixel correction.

use super::{accumulated_toward, bottom_hit, reflection_seen, refracted, sea_hit_along, CloudShadow, SeaParams};
use super::{bottom_seen, order1_seen, under};
use crate::camera::{camera_ray, in_image};
use crate::common::surface::{channel_part, glass_entry, reflectances, view_channels};
use crate::geometry::{trace_nearest, NO_HIT};
use crate::glam::{UVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::glass::{is_glass, surface_epsilon, trace_through, Glass, PATH_OUT};
use crate::sky::SkyParams;
use crate::types::{CommonParams, GBufferTexel, GlassTriangle, GlassVertex, GpuBvhNode, GpuLight, GpuMaterial};
use crate::types::{GpuSphere, GpuTriangle, MATERIAL_GLASS, NO_OBJECT};
use crate::volumes::LightGrid;
use spirv_std::spirv;

/// What the sea along a ray reads: its parameters and tables, the sky it
/// reflects, the volumes' shadow on it, the bottom's caustic, the
/// scene's geometry (objects under the water and their shadows) and
/// materials.
pub struct SeaInputs<'a> {
    pub p: &'a SeaParams,
    pub waves: &'a [Vec4],
    pub bottom: &'a [f32],
    pub accumulated: &'a [Vec4],
    pub caustic: &'a [u32],
    pub sky: &'a SkyParams,
    pub transmittance: &'a [Vec4],
    pub sky_view: &'a [Vec4],
    pub clouds: CloudShadow<'a>,
    pub sunlit: under::Sunlit<'a>,
    pub materials: &'a [GpuMaterial],
}

/// The sea an eye above the water sees along the ray `from + t dir` (rgb,
/// W/(m^2 sr)) if the ray goes down to the water and meets nothing on the
/// way; else 0.
pub fn sea_along(s: &SeaInputs, from: Vec3, dir: Vec3) -> Vec3 {
    let p = s.p;
    if dir.y >= 0.0 || from.y <= p.level {
        return Vec3::ZERO;
    }
    let eps = surface_epsilon(from);
    let t_water = (p.level - from.y) / dir.y;
    if trace_nearest(from, dir, eps, t_water, &s.sunlit.geometry).distance != NO_HIT {
        return Vec3::ZERO;
    }
    let v = refracted(p, sea_hit_along(p, s.waves, from, dir, Vec2::ZERO, Vec2::ZERO));
    if !v.hit {
        return Vec3::ZERO;
    }
    let rough = p.waves == super::WAVES_NORMAL_MAP;
    let reflected =
        reflection_seen(p, s.sky, s.transmittance, s.sky_view, &v, &s.clouds, &super::air::NoObjects, rough).xyz();
    let first = order1_seen(p, &v, s.bottom, &s.sunlit, &s.clouds);
    let mut second = Vec3::ZERO;
    if p.second_order != 0 {
        let (depth, _) = bottom_hit(p, s.bottom, v.point.x, v.point.z, v.view);
        second = accumulated_toward(p, s.accumulated, depth, v.view) * v.transmission * s.clouds.at(p, v.point);
    }
    let floor = bottom_seen(p, &v, s.bottom, s.caustic, &s.sunlit, s.materials, &s.clouds);
    reflected + first + second + floor
}

/// Per-pixel kernel of `sea.glass` at pixel `index`'s current sub-pixel
/// sample (`texel`: its G-buffer texel): the sea through and reflected in
/// the glass the view ray meets first (rgb, w = 0), else 0.
pub fn sea_in_glass_pixel(
    index: u32,
    common: &CommonParams,
    s: &SeaInputs,
    texel: &GBufferTexel,
    glass: &Glass,
) -> Vec4 {
    let x = index % common.width;
    let y = index / common.width;
    if texel.material == NO_OBJECT || !in_image(common, x, y) || s.p.underwater != 0 {
        return Vec4::ZERO;
    }
    let materials = s.materials;
    if materials[texel.material as usize].kind != MATERIAL_GLASS {
        return Vec4::ZERO;
    }
    let geometry = &s.sunlit.geometry;
    let (origin, dir) = camera_ray(common, x, y);
    let hit = trace_nearest(origin, dir, 0.0, NO_HIT, geometry);
    if !is_glass(materials, &hit) {
        return Vec4::ZERO;
    }
    let entry = glass_entry(geometry, glass, origin, dir, &hit);
    let (point, n) = (entry.point, entry.normal);
    // The reflected ray is the same in every channel: followed once.
    let fresnel = reflectances(materials[hit.material as usize].ior, entry.cos_i);
    let mut out = sea_along(s, point, entry.mirror).extend(0.0) * fresnel;
    let channels = view_channels(materials, &hit);
    let mut c = 0;
    while c < channels {
        let path = trace_through(geometry, glass, materials, point, n, hit.material, dir, c, NO_OBJECT, true);
        if path.status == PATH_OUT && path.next.distance == NO_HIT {
            let through = sea_along(s, path.position, path.direction).extend(0.0) * path.transmittance();
            out += channel_part(through, c, channels);
        }
        c += 1;
    }
    Vec4::new(out.x, out.y, out.z, 0.0)
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn sea_glass_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] sky: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] sky_view: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 20)] waves: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 27)] accumulated: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 28)] bottom: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 29)] glass_vertices: &[GlassVertex],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 30)] glass_triangles: &[GlassTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 77)] caustic: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 78)] shafts: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 85)] radiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let inputs = SeaInputs {
            p: &params[0],
            waves,
            bottom,
            accumulated,
            caustic,
            sky: &sky[0],
            transmittance,
            sky_view,
            clouds: CloudShadow { lights, grids, depths },
            sunlit: under::Sunlit { shafts, geometry: crate::scene_geometry(common, spheres, triangles, nodes) },
            materials,
        };
        let glass = Glass { vertices: glass_vertices, triangles: glass_triangles };
        radiance[index as usize] =
            sea_in_glass_pixel(common.band_start + index, common, &inputs, &gbuffer[index as usize], &glass);
    }
}
