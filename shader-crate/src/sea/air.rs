//! The scene's objects in the air over the sea, seen from the water's
//! surface: through Snell's window by an eye under the water, and mirrored
//! by the surface to an eye above it. Where the ray leaving the surface
//! meets an object, the object's light in air takes the place of the sky
//! and the sun's disk along it, lit as the surface and skylight passes
//! light what an eye sees directly. Glass there shows what lies beyond
//! it and what it mirrors (`GlassInAir`, its own pass: `sea.glass_air`).

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use super::glass::{sea_along, SeaInputs};
use super::under::Sunlit;
use super::{reflection_pixel, CloudShadow, SeaParams};
use crate::common::surface::{channel_part, direct_radiance, glass_entry, reflectances, view_channels, LightInputs};
use crate::geometry::{occluded, trace_nearest, Geometry, Hit, NO_HIT};
use crate::glam::UVec3;
use crate::glam::{Vec3, Vec4, Vec4Swizzles};
use crate::glass::{is_glass, surface_epsilon, trace_through, Glass, PATH_OUT};
use crate::sky::light::{irradiance_lookup, sky_visibility};
use crate::sky::{sky_radiance, sun_disk, SkyParams};
use crate::types::{CommonParams, GBufferTexel, GlassTriangle, GlassVertex, GpuLight, GpuMaterial, NO_OBJECT};
use crate::types::{GpuBvhNode, GpuSphere, GpuTriangle};
use crate::volumes::LightGrid;
use core::f32::consts::FRAC_1_PI;
use spirv_std::spirv;

/// `Objects::seen`: the ray meets nothing (the sky shows).
pub const NOTHING: u32 = 0;
/// `Objects::seen`: the ray meets an opaque object.
pub const OBJECT: u32 = 1;
/// `Objects::seen`: the ray meets glass.
pub const GLASS: u32 = 2;

/// What a ray leaving the water's surface into the air sees of the scene's
/// objects.
pub trait Objects {
    /// What the ray from `point` along unit `dir` meets (`NOTHING`,
    /// `OBJECT` or `GLASS`) and its light toward `point` (rgb,
    /// W/(m^2 sr)); `(NOTHING, 0)` where it meets nothing (the sky shows
    /// there, as without objects).
    fn seen(&self, point: Vec3, dir: Vec3) -> (u32, Vec3);
    /// Whether the sky (and the sun's disk) shows along rays that meet
    /// nothing: false for a layer that adds one kind of object's light to
    /// another's picture (`GlassInAir`).
    fn sky(&self) -> bool {
        true
    }
    /// 1 where nothing stands between `point` and the sun (unit `to_sun`),
    /// else 0: the sun's glint on the waves there.
    fn sun_seen(&self, point: Vec3, to_sun: Vec3) -> f32;
    /// Whether there is anything to see (else `seen` is always false).
    fn any(&self) -> bool;
    /// Whether a ray from `apex` within the cone about unit `axis` whose
    /// half-angle has the cosine `cos_half` may meet an object (false: none
    /// does).
    fn in_cone(&self, apex: Vec3, axis: Vec3, cos_half: f32) -> bool;
    /// The cosine of the angle one pixel spans: rays closer than that
    /// need not be traced apart.
    fn cos_pixel(&self) -> f32;
}

/// No objects: what the surface shows is the sky's (the sea seen through
/// glass, whose kernel reads no lights).
pub struct NoObjects;

impl Objects for NoObjects {
    fn seen(&self, _point: Vec3, _dir: Vec3) -> (u32, Vec3) {
        (NOTHING, Vec3::ZERO)
    }
    fn sun_seen(&self, _point: Vec3, _to_sun: Vec3) -> f32 {
        1.0
    }
    fn any(&self) -> bool {
        false
    }
    fn in_cone(&self, _apex: Vec3, _axis: Vec3, _cos_half: f32) -> bool {
        false
    }
    fn cos_pixel(&self) -> f32 {
        1.0
    }
}

/// The scene's objects and what lights them: its geometry and materials,
/// its lights and what their terms read, the sky's tables (its irradiance
/// table read where the sky lights surfaces).
#[derive(Copy, Clone)]
pub struct Above<'a> {
    pub common: &'a CommonParams,
    pub geometry: Geometry<'a>,
    pub materials: &'a [GpuMaterial],
    pub lights: &'a [GpuLight],
    pub inputs: LightInputs<'a>,
    pub sky: &'a SkyParams,
    pub transmittance: &'a [Vec4],
    pub sky_view: &'a [Vec4],
    pub irradiance: &'a [Vec4],
}

impl Objects for Above<'_> {
    /// Every light (`direct_radiance`: cone, light map, shadows, the
    /// volumes' shadows, the `[medium]` on the way), and under a sky that
    /// lights surfaces the sky's light `rho/pi E(n) V` (the irradiance
    /// table, `sky_visibility`'s rays from the point itself). The
    /// `[medium]` attenuates the way from the surface to the object; the
    /// air adds no aerial perspective there (metres, not kilometres).
    fn seen(&self, point: Vec3, dir: Vec3) -> (u32, Vec3) {
        if self.geometry.is_empty() {
            return (NOTHING, Vec3::ZERO);
        }
        let hit = trace_nearest(point, dir, surface_epsilon(point), NO_HIT, &self.geometry);
        if hit.distance == NO_HIT {
            return (NOTHING, Vec3::ZERO);
        }
        if is_glass(self.materials, &hit) {
            // Its light is `sea.glass_air`'s layer (`GlassInAir`).
            return (GLASS, Vec3::ZERO);
        }
        let light = self.lit(point + dir * hit.distance, dir, &hit);
        (OBJECT, light * crate::light::transmittance(self.common.sigma_t, hit.distance).xyz())
    }

    fn sun_seen(&self, point: Vec3, to_sun: Vec3) -> f32 {
        if self.geometry.is_empty() || to_sun.y <= 0.0 {
            return 1.0;
        }
        if occluded(point, to_sun, surface_epsilon(point), 1e30, &self.geometry) {
            0.0
        } else {
            1.0
        }
    }

    fn any(&self) -> bool {
        !self.geometry.is_empty()
    }

    fn cos_pixel(&self) -> f32 {
        let angle = 2.0 * self.common.camera_up.xyz().length() / self.common.height.max(1) as f32;
        angle.cos()
    }

    /// Against the spheres around the BVH's root box and around each
    /// sphere.
    fn in_cone(&self, apex: Vec3, axis: Vec3, cos_half: f32) -> bool {
        let half = cos_half.clamp(-1.0, 1.0).acos();
        let g = &self.geometry;
        if g.node_count > 0 {
            let (lo, hi) = (g.nodes[0].bounds_min.xyz(), g.nodes[0].bounds_max.xyz());
            if ball_in_cone(apex, axis, half, (lo + hi) * 0.5, (hi - lo).length() * 0.5) {
                return true;
            }
        }
        let mut i = 0;
        while i < g.sphere_count as usize {
            let s = g.spheres[i].center_radius;
            if ball_in_cone(apex, axis, half, s.xyz(), s.w) {
                return true;
            }
            i += 1;
        }
        false
    }
}

impl Above<'_> {
    /// The light the opaque surface `hit` sends back along the ray `dir`
    /// that meets it at `q` (rgb, W/(m^2 sr)): every light's and the sky's.
    fn lit(&self, q: Vec3, dir: Vec3, hit: &Hit) -> Vec3 {
        let normal = if hit.normal.dot(dir) > 0.0 { -hit.normal } else { hit.normal };
        let albedo = self.materials[hit.material as usize].albedo;
        let inputs = &self.inputs;
        let mut light = direct_radiance(self.common, self.lights, &self.geometry, inputs, q, normal, albedo).xyz();
        if self.sky.lights_surfaces != 0 {
            let seen = sky_visibility(self.sky, self.transmittance, self.sky_view, &self.geometry, q, normal);
            light += albedo.xyz() * FRAC_1_PI * irradiance_lookup(self.sky, self.irradiance, normal) * seen;
        }
        light
    }
}

/// Glass in the air over the sea, as the layer `sea.glass_air` adds to
/// `sea.reflection`'s picture: along the same rays (`Above` says which it
/// traces and sees nothing where one meets glass), what the glass shows;
/// nothing else (no sky, no other object, no glint).
pub struct GlassInAir<'a> {
    pub above: Above<'a>,
    pub glass: Glass<'a>,
    /// The sea as an eye above the water sees it along a ray
    /// (`glass::sea_along`): what a ray that leaves the glass downward
    /// sees, where the eye is above the water. (Under the water such a ray
    /// is not followed: the sea passes' tables there are the diver's.)
    pub sea: SeaInputs<'a>,
    /// Whether the rays leaving the glass see the sun's disk: where one ray
    /// a pixel leaves the surface (a flat sea, Snell's window) it draws the
    /// sun's image in the glass; the waves' slope rule traces a few rays a
    /// facet, too few to find a disk half a degree wide (each that did would
    /// be a lone pixel hundreds of times too bright), so there the sun's
    /// light through the glass and off the waves is left out.
    pub sun: bool,
}

impl<'a> GlassInAir<'a> {
    /// The glass among `above`'s objects, seen over the sea `sea`.
    pub fn new(above: Above<'a>, glass: Glass<'a>, sea: SeaInputs<'a>) -> Self {
        let p = sea.p;
        GlassInAir { above, glass, sea, sun: p.underwater != 0 || p.waves != super::WAVES_NORMAL_MAP }
    }
}

impl Objects for GlassInAir<'_> {
    fn seen(&self, point: Vec3, dir: Vec3) -> (u32, Vec3) {
        let a = &self.above;
        if a.geometry.is_empty() {
            return (NOTHING, Vec3::ZERO);
        }
        let hit = trace_nearest(point, dir, surface_epsilon(point), NO_HIT, &a.geometry);
        if hit.distance == NO_HIT {
            return (NOTHING, Vec3::ZERO);
        }
        if !is_glass(a.materials, &hit) {
            // Its light is `sea.reflection`'s.
            return (OBJECT, Vec3::ZERO);
        }
        (GLASS, self.through_glass(point, dir, &hit))
    }
    fn sky(&self) -> bool {
        false
    }
    fn sun_seen(&self, _point: Vec3, _to_sun: Vec3) -> f32 {
        0.0
    }
    fn any(&self) -> bool {
        self.above.any()
    }
    fn in_cone(&self, apex: Vec3, axis: Vec3, cos_half: f32) -> bool {
        self.above.in_cone(apex, axis, cos_half)
    }
    fn cos_pixel(&self) -> f32 {
        self.above.cos_pixel()
    }
}

impl GlassInAir<'_> {
    /// Glass met at `hit` by the ray from `point` along `dir`, as glass
    /// seen directly shows it (the lit-surface pass and `sky.glass`): what
    /// the ray mirrored at the first interface sees, times the Fresnel
    /// reflectance per channel, and per channel (each its own path through
    /// dispersive glass) what the ray refracted through the glass sees where
    /// it leaves, times the path's Fresnel transmittances and Beer's law
    /// (`trace_through`). Each of those rays sees the opaque surface it
    /// meets, lit, through the `[medium]` (from `point`), or the sky and
    /// the sun's disk, or the sea below (these two not attenuated, as the
    /// sky seen directly is not); a second glass shows nothing (not
    /// followed). Rgb,
    /// W/(m^2 sr). One call of `beyond` for all the rays (see
    /// `reflection_pixel`).
    pub fn through_glass(&self, point: Vec3, dir: Vec3, hit: &Hit) -> Vec3 {
        let a = &self.above;
        let (geometry, glass, materials) = (&a.geometry, &self.glass, a.materials);
        let entry = glass_entry(geometry, glass, point, dir, hit);
        let fresnel = reflectances(materials[hit.material as usize].ior, entry.cos_i);
        let channels = view_channels(materials, hit);
        let (mut surfaces, mut skies) = (Vec4::ZERO, Vec4::ZERO);
        // Rays 0 .. channels: through the glass, one per channel; ray
        // `channels`: mirrored at the first interface.
        let mut c = 0;
        while c <= channels {
            let (from, to, weight, out) = if c < channels {
                let path = trace_through(
                    geometry,
                    glass,
                    materials,
                    entry.point,
                    entry.normal,
                    hit.material,
                    dir,
                    c,
                    NO_OBJECT,
                    true,
                );
                (path.position, path.direction, path.transmittance(), path.status == PATH_OUT)
            } else {
                (entry.point, entry.mirror, fresnel, true)
            };
            if out {
                let (surface, sky) = self.beyond(from, to);
                if c < channels {
                    surfaces += channel_part(surface * weight, c, channels);
                    skies += channel_part(sky * weight, c, channels);
                } else {
                    surfaces += surface * weight;
                    skies += sky * weight;
                }
            }
            c += 1;
        }
        (surfaces * crate::light::transmittance(a.common.sigma_t, hit.distance) + skies).xyz()
    }

    /// What a ray that left the glass at `from` along `dir` sees, as
    /// `(surface, sky)`: the opaque surface it meets, lit, through the
    /// `[medium]` on the way; going up, the sky and the sun's disk
    /// (`sun`); going down, the sea (`sea`).
    /// Another glass, or the water below: nothing.
    fn beyond(&self, from: Vec3, dir: Vec3) -> (Vec4, Vec4) {
        let a = &self.above;
        let hit = trace_nearest(from, dir, surface_epsilon(from), NO_HIT, &a.geometry);
        if hit.distance != NO_HIT {
            if is_glass(a.materials, &hit) {
                return (Vec4::ZERO, Vec4::ZERO);
            }
            let light = a.lit(from + dir * hit.distance, dir, &hit);
            let light = light * crate::light::transmittance(a.common.sigma_t, hit.distance).xyz();
            return (light.extend(0.0), Vec4::ZERO);
        }
        if dir.y <= 0.0 {
            // Down to the water (not attenuated by the `[medium]`, as the
            // sea seen through glass directly, `sea.glass`).
            if self.sea.p.underwater != 0 {
                return (Vec4::ZERO, Vec4::ZERO);
            }
            return (Vec4::ZERO, sea_along(&self.sea, from, dir).extend(0.0));
        }
        let mut sky = sky_radiance(a.sky, a.transmittance, a.sky_view, dir);
        if self.sun {
            sky += sun_disk(a.sky, a.transmittance, dir);
        }
        (Vec4::ZERO, sky.extend(0.0))
    }
}

/// Whether some ray from `apex` within `half` radians of unit `axis`
/// meets the ball of centre `c` and radius `r` (with a margin of 1e-3 rad
/// and 0.1 % of the radius for rounding).
fn ball_in_cone(apex: Vec3, axis: Vec3, half: f32, c: Vec3, r: f32) -> bool {
    let d = c - apex;
    let dist = d.length();
    let r = r * 1.001 + 1e-6;
    if dist <= r {
        return true;
    }
    let limit = half + (r / dist).asin() + 1e-3;
    limit >= core::f32::consts::PI || axis.dot(d) >= dist * limit.cos()
}

/// Per-pixel kernel, `sea.glass_air`: what glass in the air over the sea
/// shows along the rays `sea.reflection` traces from the surface
/// (`reflection_pixel` with `GlassInAir`): mirrored by the waves to an eye
/// above the water, and through Snell's window to an eye under it; only at
/// pixels where `sea.reflection` counted rays that met glass (its `w`;
/// elsewhere 0). Its own kernel, so that scenes without glass do not
/// build the glass's tracing into their reflection pass.
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn glass_air_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] sky: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] sky_view: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 20)] waves: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 68)] surface: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] shadow: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 62)] irradiance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 29)] glass_vertices: &[GlassVertex],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 30)] glass_triangles: &[GlassTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 27)] accumulated: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 28)] bottom: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 77)] caustic: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 78)] shafts: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 23)] mirror: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 120)] radiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    // Only where `sea.reflection`'s rays met glass (its `w`).
    if index < common.band_pixels && mirror[index as usize].w == 0.0 {
        radiance[index as usize] = Vec4::ZERO;
    } else if index < common.band_pixels {
        let clouds = CloudShadow { lights, grids, depths };
        let objects = GlassInAir::new(
            Above {
                common,
                geometry: crate::scene_geometry(common, spheres, triangles, nodes),
                materials,
                lights,
                inputs: LightInputs { light_map, shadow, grids, depths },
                sky: &sky[0],
                transmittance,
                sky_view,
                irradiance,
            },
            Glass { vertices: glass_vertices, triangles: glass_triangles },
            SeaInputs {
                p: &params[0],
                waves,
                bottom,
                accumulated,
                caustic,
                sky: &sky[0],
                transmittance,
                sky_view,
                clouds: CloudShadow { lights, grids, depths },
                sunlit: Sunlit { shafts, geometry: crate::scene_geometry(common, spheres, triangles, nodes) },
                materials,
            },
        );
        radiance[index as usize] = reflection_pixel(
            common.band_start + index,
            common,
            &params[0],
            waves,
            &sky[0],
            transmittance,
            sky_view,
            &gbuffer[index as usize],
            surface[index as usize],
            &clouds,
            &objects,
        );
    }
}
