//! The scene's objects in the air over the sea, seen from the water's
//! surface: through Snell's window by an eye under the water, and mirrored
//! by the surface to an eye above it. Where the ray leaving the surface
//! meets an object, the object's light in air takes the place of the sky
//! and the sun's disk along it, lit as the surface and skylight passes
//! light what an eye sees directly.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::common::surface::{direct_radiance, LightInputs};
use crate::geometry::{occluded, trace_nearest, Geometry, NO_HIT};
use crate::glam::{Vec3, Vec4, Vec4Swizzles};
use crate::glass::{is_glass, surface_epsilon};
use crate::sky::light::{irradiance_lookup, sky_visibility};
use crate::sky::SkyParams;
use crate::types::{CommonParams, GpuLight, GpuMaterial};
use core::f32::consts::FRAC_1_PI;

/// What a ray leaving the water's surface into the air sees of the scene's
/// objects.
pub trait Objects {
    /// The object the ray from `point` along unit `dir` meets and its
    /// light toward `point` (rgb, W/(m^2 sr)); `(false, 0)` where it meets
    /// nothing or glass (the sky shows there, as without objects).
    fn seen(&self, point: Vec3, dir: Vec3) -> (bool, Vec3);
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
    fn seen(&self, _point: Vec3, _dir: Vec3) -> (bool, Vec3) {
        (false, Vec3::ZERO)
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
    fn seen(&self, point: Vec3, dir: Vec3) -> (bool, Vec3) {
        if self.geometry.is_empty() {
            return (false, Vec3::ZERO);
        }
        let hit = trace_nearest(point, dir, surface_epsilon(point), NO_HIT, &self.geometry);
        if hit.distance == NO_HIT || is_glass(self.materials, &hit) {
            return (false, Vec3::ZERO);
        }
        let q = point + dir * hit.distance;
        let normal = if hit.normal.dot(dir) > 0.0 { -hit.normal } else { hit.normal };
        let albedo = self.materials[hit.material as usize].albedo;
        let inputs = &self.inputs;
        let mut light = direct_radiance(self.common, self.lights, &self.geometry, inputs, q, normal, albedo).xyz();
        if self.sky.lights_surfaces != 0 {
            let seen = sky_visibility(self.sky, self.transmittance, self.sky_view, &self.geometry, q, normal);
            light += albedo.xyz() * FRAC_1_PI * irradiance_lookup(self.sky, self.irradiance, normal) * seen;
        }
        (true, light * crate::light::transmittance(self.common.sigma_t, hit.distance).xyz())
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
