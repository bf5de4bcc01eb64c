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

/// Sky directions on the quadrature's sphere.
pub const SPHERE_DIRECTIONS: u32 = SPHERE_AZIMUTHS * SPHERE_ZENITHS;

/// The cosine of the zenith angle of the quadrature's ring `j` (midpoints).
fn sphere_mu(j: u32) -> f32 {
    -1.0 + 2.0 * (j as f32 + 0.5) / SPHERE_ZENITHS as f32
}

/// The unit direction of the quadrature's cell `k` (ring `k /
/// SPHERE_AZIMUTHS`, azimuth `k % SPHERE_AZIMUTHS`, each at its midpoint).
pub fn sphere_direction(k: u32) -> Vec3 {
    let mu = sphere_mu(k / SPHERE_AZIMUTHS);
    let ring = (1.0 - mu * mu).max(0.0).sqrt();
    let phi = TAU * ((k % SPHERE_AZIMUTHS) as f32 + 0.5) / SPHERE_AZIMUTHS as f32;
    Vec3::new(ring * phi.cos(), mu, ring * phi.sin())
}

/// Sphere table kernel: the sky's radiance (rgb, W/(m^2 sr)) toward the
/// quadrature's direction `index` (`sphere_direction`), from the sky-view
/// table (or integrated, as the sky pass takes it). Looked up once here,
/// not once per irradiance texel: the table's lookups (through asin and
/// acos) were most of the irradiance pass.
pub fn sphere_texel(index: u32, p: &SkyParams, transmittance: &[Vec4], sky_view: &[Vec4]) -> Vec4 {
    sky_radiance(p, transmittance, sky_view, sphere_direction(index)).extend(0.0)
}

/// Irradiance table kernel: `E(n)` (rgb, W/m^2) for texel `index`'s normal,
/// by the midpoint rule over `SPHERE_AZIMUTHS x SPHERE_ZENITHS` equal
/// solid angles `4 pi / (AZIMUTHS ZENITHS)` of the sky's radiance `sphere`
/// (`sphere_texel`). A ring's directions are stepped by a rotation of the
/// azimuth (two sines a ring, not two a direction; the rotation's rounding
/// after 64 steps is ~1e-6 of a direction).
pub fn irradiance_texel(index: u32, p: &SkyParams, sphere: &[Vec4]) -> Vec4 {
    let n = irradiance_normal(p, index);
    let step = TAU / SPHERE_AZIMUTHS as f32;
    let (step_sin, step_cos) = (step.sin(), step.cos());
    let mut sum = Vec3::ZERO;
    let mut j = 0;
    while j < SPHERE_ZENITHS {
        let mu = sphere_mu(j);
        let ring = (1.0 - mu * mu).max(0.0).sqrt();
        // n . w = n.y mu + ring (n.x cos(phi) + n.z sin(phi)).
        let (mut c, mut s) = ((0.5 * step).cos(), (0.5 * step).sin());
        let mut i = 0;
        while i < SPHERE_AZIMUTHS {
            let cosine = n.y * mu + ring * (n.x * c + n.z * s);
            if cosine > 0.0 {
                sum += sphere[(j * SPHERE_AZIMUTHS + i) as usize].xyz() * cosine;
            }
            let next_c = c * step_cos - s * step_sin;
            s = s * step_cos + c * step_sin;
            c = next_c;
            i += 1;
        }
        j += 1;
    }
    (sum * (4.0 * PI / SPHERE_DIRECTIONS as f32)).extend(0.0)
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

/// The sky tables the skylight reads: the parameters, the transmittance
/// and sky-view tables and the irradiance table.
pub struct SkyTables<'a> {
    pub p: &'a SkyParams,
    pub transmittance: &'a [Vec4],
    pub sky_view: &'a [Vec4],
    pub irradiance: &'a [Vec4],
}

/// `V` at `point` (unit `normal`): the share of the hemisphere's sky light
/// that arrives, the radiance-weighted share of `light_rays` visibility
/// rays (`visibility_direction`) that escape the scene's geometry, rgb in
/// [0, 1]; 1 with no rays.
pub fn sky_visibility(
    p: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    geometry: &Geometry,
    point: Vec3,
    n: Vec3,
) -> Vec3 {
    if p.light_rays == 0 {
        return Vec3::ONE;
    }
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
    Vec3::new(
        if all.x > 0.0 { free.x / all.x } else { 1.0 },
        if all.y > 0.0 { free.y / all.y } else { 1.0 },
        if all.z > 0.0 { free.z / all.z } else { 1.0 },
    )
}

/// The sky's light reflected by a diffuse surface of `albedo` at `point`
/// (unit `normal`, turned toward the viewer), rgb W/(m^2 sr):
/// `rho / pi E(n) V` (`sky_visibility`).
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
    albedo * FRAC_1_PI * e * sky_visibility(p, transmittance, sky_view, geometry, point, n)
}

/// Whether pixel `(x, y)` traces the visibility rays: both coordinates
/// multiples of `light_spacing` (every pixel with a spacing of 1).
pub fn traces_visibility(p: &SkyParams, x: u32, y: u32) -> bool {
    let s = p.light_spacing.max(1);
    x.is_multiple_of(s) && y.is_multiple_of(s)
}

/// The point pixel `(x, y)`'s G-buffer `texel` sees, and the diffuse
/// material there; not found where it sees no surface, or one that is not
/// diffuse (glass, whose view `sky.glass` lights), or lies outside the image.
fn diffuse_seen(
    common: &CommonParams,
    materials: &[GpuMaterial],
    x: u32,
    y: u32,
    texel: &GBufferTexel,
) -> (bool, Vec3) {
    if texel.object == NO_OBJECT
        || !in_image(common, x, y)
        || materials[texel.material as usize].kind != MATERIAL_DIFFUSE
    {
        return (false, Vec3::ZERO);
    }
    let (origin, dir) = camera_ray(common, x, y);
    (true, origin + dir * texel.normal_distance.w)
}

/// Skylight visibility kernel (the first of the skylight's two passes):
/// at a pixel that traces (`traces_visibility`) and sees a diffuse
/// surface, `V` there (`sky_visibility`; rgb, w = 1); elsewhere 0 (w = 0:
/// no value).
#[allow(clippy::too_many_arguments)]
pub fn visibility_pixel(
    index: u32,
    common: &CommonParams,
    p: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    geometry: &Geometry,
    materials: &[GpuMaterial],
    texel: &GBufferTexel,
) -> Vec4 {
    let (x, y) = (index % common.width, index / common.width);
    if !traces_visibility(p, x, y) {
        return Vec4::ZERO;
    }
    let (found, point) = diffuse_seen(common, materials, x, y, texel);
    if !found {
        return Vec4::ZERO;
    }
    let n = texel.normal_distance.xyz();
    sky_visibility(p, transmittance, sky_view, geometry, point, n).extend(1.0)
}

/// Normals of a pixel and a tracing pixel whose `V` it takes agree to
/// this cosine (18 degrees): `V` turns with the normal's hemisphere.
const SAME_NORMAL: f32 = 0.95;
/// A tracing pixel's point lies within this share of the pixel's distance
/// of the pixel's tangent plane: the same surface, not one in front of or
/// behind it.
const SAME_PLANE: f32 = 0.02;

/// `V` at pixel `(x, y)` (its G-buffer `texel`, the `point` it sees) from
/// the tracing pixels around it, `light_spacing` apart: the bilinear
/// weights of the up to four around it, each kept only where that pixel
/// sees the same object, with the normal within `SAME_NORMAL` and its point
/// within `SAME_PLANE` of the pixel's tangent plane (a joint bilateral
/// upsampling). rgb times the weights kept, and their sum in w (0: none kept).
#[allow(clippy::too_many_arguments)]
fn nearby_visibility(
    common: &CommonParams,
    p: &SkyParams,
    gbuffer: &[GBufferTexel],
    visibility: &[Vec4],
    x: u32,
    y: u32,
    texel: &GBufferTexel,
    point: Vec3,
) -> Vec4 {
    let s = p.light_spacing.max(1);
    let n = texel.normal_distance.xyz();
    let (x0, y0) = (x - x % s, y - y % s);
    let (fx, fy) = ((x % s) as f32 / s as f32, (y % s) as f32 / s as f32);
    let mut sum = Vec4::ZERO;
    let mut corner = 0;
    while corner < 4 {
        let (i, j) = (corner % 2, corner / 2);
        let w = (if i == 0 { 1.0 - fx } else { fx }) * (if j == 0 { 1.0 - fy } else { fy });
        let (xs, ys) = (x0 + i * s, y0 + j * s);
        let k = ys * common.width + xs;
        corner += 1;
        if w <= 0.0 || xs >= common.width || k < common.band_start || k - common.band_start >= common.band_pixels {
            continue;
        }
        let b = (k - common.band_start) as usize;
        let v = visibility[b];
        let other = &gbuffer[b];
        if v.w == 0.0 || other.object != texel.object || other.normal_distance.xyz().dot(n) < SAME_NORMAL {
            continue;
        }
        let (origin, dir) = camera_ray(common, xs, ys);
        let q = origin + dir * other.normal_distance.w;
        if (q - point).dot(n).abs() > SAME_PLANE * texel.normal_distance.w {
            continue;
        }
        sum += Vec4::new(v.x * w, v.y * w, v.z * w, w);
    }
    sum
}

/// Per-pixel skylight kernel (the second pass): the sky's light reflected
/// toward the eye by the diffuse surface pixel `index` sees (rgb,
/// W/(m^2 sr); w = 0), `rho / pi E(n) V` times `exp(-sigma_t t)` (the
/// medium between eye and surface as the surface pass takes it), 0 where
/// the pixel sees no surface or glass (`sky.glass` lights what is seen
/// through glass). `V` is the tracing pixels' around it where they see the
/// same surface (`nearby_visibility`), else its own rays' (a pixel
/// `light_spacing` apart from none that matches traces them itself); with
/// `light_rays` 0, 1 (unshadowed). `gbuffer` and `visibility` hold the band.
#[allow(clippy::too_many_arguments)]
pub fn sky_light_pixel(
    index: u32,
    common: &CommonParams,
    sky: &SkyTables,
    geometry: &Geometry,
    materials: &[GpuMaterial],
    gbuffer: &[GBufferTexel],
    visibility: &[Vec4],
) -> Vec4 {
    let (x, y) = (index % common.width, index / common.width);
    let texel = &gbuffer[(index - common.band_start) as usize];
    let (found, point) = diffuse_seen(common, materials, x, y, texel);
    if !found {
        return Vec4::ZERO;
    }
    let p = sky.p;
    let n = texel.normal_distance.xyz();
    let mut seen = Vec3::ONE;
    if p.light_rays > 0 {
        // With a spacing of 1, the pixel's own.
        let near = nearby_visibility(common, p, gbuffer, visibility, x, y, texel, point);
        seen = if near.w > 0.0 {
            near.xyz() / near.w
        } else {
            sky_visibility(p, sky.transmittance, sky.sky_view, geometry, point, n)
        };
    }
    let albedo = materials[texel.material as usize].albedo.xyz();
    let light = albedo * FRAC_1_PI * irradiance_lookup(p, sky.irradiance, n) * seen;
    let medium = (-common.sigma_t.xyz() * texel.normal_distance.w).exp();
    (light * medium).extend(0.0)
}
