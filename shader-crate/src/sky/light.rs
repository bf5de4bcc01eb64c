//! Skylight on surfaces: the sky's radiance (the in-scattered light of the
//! sky passes, without the sun's disk, which lights the scene as a
//! directional light) integrated over the hemisphere above a diffuse
//! surface,
//!
//! `E(n) = int L_sky(w) max(0, n . w) dw` (W/m^2), reflected as
//! `L = rho / pi E(n) V` (W/(m^2 sr)),
//!
//! the rendering equation's diffuse term with the sky as the only source.
//! `E` depends on the normal only (the observer's sky is the same over the
//! scene), so a table over normals holds it (`irradiance_texel`); the sky
//! is symmetric about the sun's vertical plane, so the table covers normal
//! azimuths from the sun's to its opposite. `V` is the share of the sky a
//! point sees past the scene's geometry: the radiance-weighted share of
//! `light_rays` cosine-distributed rays that escape (`sky_light_pixel`).

use super::{sky_radiance, SkyParams};
use crate::camera::{camera_ray, in_image};
use crate::geometry::{occluded, Geometry};
use crate::glam::{Vec3, Vec4, Vec4Swizzles};
use crate::types::{CommonParams, GBufferTexel, GpuMaterial, MATERIAL_DIFFUSE, NO_OBJECT};
use core::f32::consts::{FRAC_1_PI, PI, TAU};
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// The irradiance table: normal azimuths (from the sun's, 0..pi) by normal
/// zenith angles (0..pi), both uniform, the end values on the grid.
pub const IRRADIANCE_WIDTH: u32 = 16;
pub const IRRADIANCE_HEIGHT: u32 = 32;
/// The quadrature over the sphere of sky directions: azimuths by cosines of
/// the zenith angle, each uniform (so every cell has the same solid angle,
/// `4 pi / (AZIMUTHS ZENITHS)`), midpoints.
pub const SPHERE_AZIMUTHS: u32 = 64;
pub const SPHERE_ZENITHS: u32 = 48;

/// The horizontal unit vector toward the sun's azimuth (`+x` with the sun
/// at the zenith) and the one a quarter turn from it about `+y`.
fn sun_frame(p: &SkyParams) -> (Vec3, Vec3) {
    let s = p.sun_direction.xyz();
    let h = Vec3::new(s.x, 0.0, s.z);
    let a = if h.length_squared() > 1e-12 { h.normalize() } else { Vec3::X };
    (a, Vec3::new(-a.z, 0.0, a.x))
}

/// The unit normal of irradiance texel `index`.
pub fn irradiance_normal(p: &SkyParams, index: u32) -> Vec3 {
    let (col, row) = (index % IRRADIANCE_WIDTH, index / IRRADIANCE_WIDTH);
    let phi = PI * col as f32 / (IRRADIANCE_WIDTH - 1) as f32;
    let theta = PI * row as f32 / (IRRADIANCE_HEIGHT - 1) as f32;
    let (a, b) = sun_frame(p);
    (a * phi.cos() + b * phi.sin()) * theta.sin() + Vec3::Y * theta.cos()
}

/// Irradiance table kernel: `E(n)` (rgb, W/m^2) for texel `index`'s normal,
/// by the midpoint rule over `SPHERE_AZIMUTHS x SPHERE_ZENITHS` equal
/// solid angles, the sky's radiance from the sky-view table (or integrated,
/// as the sky pass takes it).
pub fn irradiance_texel(index: u32, p: &SkyParams, transmittance: &[Vec4], sky_view: &[Vec4]) -> Vec4 {
    let n = irradiance_normal(p, index);
    let mut sum = Vec3::ZERO;
    let mut j = 0;
    while j < SPHERE_ZENITHS {
        let mu = -1.0 + 2.0 * (j as f32 + 0.5) / SPHERE_ZENITHS as f32;
        let ring = (1.0 - mu * mu).max(0.0).sqrt();
        let mut i = 0;
        while i < SPHERE_AZIMUTHS {
            let phi = TAU * (i as f32 + 0.5) / SPHERE_AZIMUTHS as f32;
            let w = Vec3::new(ring * phi.cos(), mu, ring * phi.sin());
            let c = n.dot(w);
            if c > 0.0 {
                sum += sky_radiance(p, transmittance, sky_view, w) * c;
            }
            i += 1;
        }
        j += 1;
    }
    (sum * (4.0 * PI / (SPHERE_AZIMUTHS * SPHERE_ZENITHS) as f32)).extend(0.0)
}

/// `E(n)` for unit normal `n`, bilinear in the irradiance table.
pub fn irradiance_lookup(p: &SkyParams, table: &[Vec4], n: Vec3) -> Vec3 {
    let (a, b) = sun_frame(p);
    let theta = n.y.clamp(-1.0, 1.0).acos();
    let phi = n.dot(b).abs().atan2(n.dot(a));
    let x = (phi / PI * (IRRADIANCE_WIDTH - 1) as f32).clamp(0.0, (IRRADIANCE_WIDTH - 1) as f32);
    let y = (theta / PI * (IRRADIANCE_HEIGHT - 1) as f32).clamp(0.0, (IRRADIANCE_HEIGHT - 1) as f32);
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(IRRADIANCE_WIDTH - 1), (y0 + 1).min(IRRADIANCE_HEIGHT - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let w = IRRADIANCE_WIDTH;
    let top = table[(y0 * w + x0) as usize].xyz() * (1.0 - fx) + table[(y0 * w + x1) as usize].xyz() * fx;
    let bottom = table[(y1 * w + x0) as usize].xyz() * (1.0 - fx) + table[(y1 * w + x1) as usize].xyz() * fx;
    top * (1.0 - fy) + bottom * fy
}

/// Visibility ray `k` of `count` around unit normal `n`: cosine-distributed
/// (stratified in the cosine squared, the azimuths by the golden angle), in
/// a frame fixed by `n` alone, so that neighbouring pixels on a surface
/// trace the same directions.
pub fn visibility_direction(n: Vec3, k: u32, count: u32) -> Vec3 {
    let t = crate::caustics::frame_tangent(n);
    let b = n.cross(t);
    let u = (k as f32 + 0.5) / count as f32;
    let r = u.sqrt();
    let phi = 2.399_963_2 * k as f32;
    let local = t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u).max(0.0).sqrt();
    local.normalize()
}

/// The sky's light reflected by a diffuse surface of `albedo` at `point`
/// (unit `normal`, turned toward the viewer), rgb W/(m^2 sr):
/// `rho / pi E(n) V`, `V` the radiance-weighted share of `light_rays`
/// visibility rays that escape the scene's geometry (1 with none).
#[allow(clippy::too_many_arguments)]
pub fn sky_light_at(
    p: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    irradiance: &[Vec4],
    geometry: &Geometry,
    point: Vec3,
    n: Vec3,
    albedo: Vec3,
) -> Vec3 {
    let e = irradiance_lookup(p, irradiance, n);
    let mut seen = Vec3::ONE;
    if p.light_rays > 0 {
        // The share of the hemisphere's sky light that arrives: rays that
        // escape, weighted by the sky's radiance their way.
        let scale = point.abs().max_element().max(1.0);
        let mut all = Vec3::ZERO;
        let mut free = Vec3::ZERO;
        let mut k = 0;
        while k < p.light_rays {
            let w = visibility_direction(n, k, p.light_rays);
            let l = sky_radiance(p, transmittance, sky_view, w);
            all += l;
            let t_min = 1e-5 * scale / n.dot(w).max(1e-3);
            // Out to 10^30 m (short of `NO_HIT`): the sky is beyond everything.
            if !occluded(point, w, t_min, 1e30, geometry) {
                free += l;
            }
            k += 1;
        }
        seen = Vec3::new(
            if all.x > 0.0 { free.x / all.x } else { 1.0 },
            if all.y > 0.0 { free.y / all.y } else { 1.0 },
            if all.z > 0.0 { free.z / all.z } else { 1.0 },
        );
    }
    albedo * FRAC_1_PI * e * seen
}

/// Per-pixel skylight kernel: the sky's light reflected toward the eye by
/// the diffuse surface pixel `index` sees (rgb, W/(m^2 sr); w = 0),
/// `sky_light_at` times `exp(-sigma_t t)` (the medium between eye and
/// surface as the surface pass takes it), 0 where the pixel sees no surface
/// or glass (`sky.glass` lights what is seen through glass). With
/// `light_rays` 0, `V` is 1 (unshadowed).
#[allow(clippy::too_many_arguments)]
pub fn sky_light_pixel(
    index: u32,
    common: &CommonParams,
    p: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    irradiance: &[Vec4],
    geometry: &Geometry,
    materials: &[GpuMaterial],
    texel: &GBufferTexel,
) -> Vec4 {
    let (x, y) = (index % common.width, index / common.width);
    if texel.object == NO_OBJECT || !in_image(common, x, y) {
        return Vec4::ZERO;
    }
    let material = &materials[texel.material as usize];
    if material.kind != MATERIAL_DIFFUSE {
        return Vec4::ZERO;
    }
    let (origin, dir) = camera_ray(common, x, y);
    let t = texel.normal_distance.w;
    let point = origin + dir * t;
    let n = texel.normal_distance.xyz();
    let light = sky_light_at(p, transmittance, sky_view, irradiance, geometry, point, n, material.albedo.xyz());
    let medium = (-common.sigma_t.xyz() * t).exp();
    (light * medium).extend(0.0)
}
