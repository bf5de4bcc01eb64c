//! Lights: spotlight cones, light maps (projective textures), shadow maps, and
//! the light that reaches a point of the medium or of a surface.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::glam::{Vec3, Vec4, Vec4Swizzles};
use crate::types::{GpuLight, LIGHT_DIRECTIONAL, LIGHT_POINT};
use core::ops::{Add, Div, Mul, Sub};

/// Arithmetic on one value (`f32`) or on four at once (`Vec4`, SIMD on the
/// CPU), lane by lane. A spot's hard edge, the projective coordinates and
/// the shadow tests are written once over `Lanes`: `emitted_visible` runs
/// them for one point, the shafts for four sub-plane samples at once
/// (`emitted_visible4`), with the same operations in the same order.
pub trait Lanes: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> {
    fn splat(v: f32) -> Self;
    /// The square root.
    fn root(self) -> Self;
    /// The larger of the two.
    fn larger(self, other: Self) -> Self;
    /// 1 where `a > b`, 0 elsewhere (and where either is NaN).
    fn above(a: Self, b: Self) -> Self;
}

impl Lanes for f32 {
    fn splat(v: f32) -> Self {
        v
    }
    fn root(self) -> Self {
        self.sqrt()
    }
    fn larger(self, other: Self) -> Self {
        self.max(other)
    }
    fn above(a: Self, b: Self) -> Self {
        if a > b {
            1.0
        } else {
            0.0
        }
    }
}

impl Lanes for Vec4 {
    fn splat(v: f32) -> Self {
        Vec4::splat(v)
    }
    fn root(self) -> Self {
        self.sqrt()
    }
    fn larger(self, other: Self) -> Self {
        self.max(other)
    }
    fn above(a: Self, b: Self) -> Self {
        Vec4::select(a.cmpgt(b), Vec4::ONE, Vec4::ZERO)
    }
}

/// Stored in a shadow-map texel whose ray hits nothing.
pub const SHADOW_FAR: f32 = f32::MAX;

/// Beer-Lambert transmittance `exp(-sigma_t d)` per channel (the `exp(-rho kappa s)`
/// factors of eq. 1 and eq. 3 of the 2002 paper); `sigma_t` in 1/m, `distance` in m.
/// A grey medium (the same `sigma_t` in every channel) takes one exponential.
pub fn transmittance(sigma_t: Vec4, distance: f32) -> Vec4 {
    let r = (-sigma_t.x * distance).exp();
    if sigma_t.y == sigma_t.x && sigma_t.z == sigma_t.x {
        return Vec4::new(r, r, r, 1.0);
    }
    Vec4::new(r, (-sigma_t.y * distance).exp(), (-sigma_t.z * distance).exp(), 1.0)
}

/// `(1 - e^-x) / x`, 1 at 0, without cancellation for small `|x|`: the
/// mean transmittance over an interval of optical depth `x`.
pub fn phi(x: f32) -> f32 {
    if x.abs() < 1e-3 {
        1.0 - x * (0.5 - x / 6.0)
    } else {
        (1.0 - (-x).exp()) / x
    }
}

/// `phi(x)` given `r = e^(-x)` (the same bits: `phi` takes the same `exp`
/// where it takes one), for a march that carries `r` already.
pub fn phi_given(x: f32, r: f32) -> f32 {
    if x.abs() < 1e-3 {
        phi(x)
    } else {
        (1.0 - r) / x
    }
}

/// `p` in the light's frame: `(x along axis_x, y along axis_y, z along axis_z)`,
/// metres, relative to the light's position (spot) or entry-plane centre
/// (directional).
pub fn light_local(light: &GpuLight, p: Vec3) -> Vec3 {
    let d = p - light.position.xyz();
    Vec3::new(d.dot(light.axis_x.xyz()), d.dot(light.axis_y.xyz()), d.dot(light.axis_z.xyz()))
}

/// The spotlight cone's angular profile at `local` (a point in the light's
/// frame): 1 inside the beam angle, 0 outside the cutoff, linear in the angle
/// between them. The hard-edge test is done on tangents (`r <= z tan(cutoff)`),
/// which keeps its accuracy for cutoffs near 0 where `cos(cutoff)` rounds to 1.
pub fn cone_falloff(light: &GpuLight, local: Vec3) -> f32 {
    let (inside, r) = spot_edge(local.x, local.y, local.z, light.tan_cutoff);
    if inside == 0.0 {
        return 0.0;
    }
    if light.beam >= light.cutoff {
        return 1.0;
    }
    soft_edge(light, r, local.z)
}

/// A spot's profile between its beam and cutoff angles at a point `r` from
/// its axis, `z` along it: linear in the angle.
fn soft_edge(light: &GpuLight, r: f32, z: f32) -> f32 {
    let angle = angle_from_axis(r, z);
    ((light.cutoff - angle) / (light.cutoff - light.beam)).clamp(0.0, 1.0)
}

/// `atan(r / z)` for `r >= 0`, `z > 0`, radians, to within a few f32 ulps
/// on every backend. Vulkan lets `atan2` be off by 4096 ulps (6e-5 rad at
/// 0.25 rad): across a 3-degree soft edge that moved the light by 1e-3 of
/// itself between lavapipe and the CPU. Reduced to `[0, tan(pi/12)]`
/// (`atan t = pi/2 - atan(1/t)`, `atan t = pi/6 + atan((t sqrt 3 - 1) /
/// (t + sqrt 3))`), then the Taylor series to `x^11` (remainder under
/// `x^13 / 13 < 3e-9`).
pub fn angle_from_axis(r: f32, z: f32) -> f32 {
    const SQRT_3: f32 = 1.732_050_8;
    const TAN_PI_12: f32 = 0.267_949_2;
    let flip = r > z;
    let t = if flip { z / r } else { r / z };
    let reduce = t > TAN_PI_12;
    let x = if reduce { (t * SQRT_3 - 1.0) / (t + SQRT_3) } else { t };
    let x2 = x * x;
    let series = x * (1.0 - x2 * (1.0 / 3.0 - x2 * (0.2 - x2 * (1.0 / 7.0 - x2 * (1.0 / 9.0 - x2 / 11.0)))));
    let a = if reduce { core::f32::consts::FRAC_PI_6 + series } else { series };
    if flip {
        core::f32::consts::FRAC_PI_2 - a
    } else {
        a
    }
}

/// `atan2(y, x)` in `(-pi, pi]`, radians, to within a few f32 ulps on
/// every backend (`angle_from_axis` in each quadrant; 0 at the origin).
pub fn atan2_accurate(y: f32, x: f32) -> f32 {
    if x == 0.0 && y == 0.0 {
        return 0.0;
    }
    let a = angle_from_axis(y.abs(), x.abs());
    let a = if x < 0.0 { core::f32::consts::PI - a } else { a };
    if y < 0.0 {
        -a
    } else {
        a
    }
}

/// A spot's hard edge at the point `(x, y, z)` of its frame: 1 inside the
/// cone (`z > 0`, `r <= z tan(cutoff)`), else 0; and `r`, the distance from
/// the axis.
pub fn spot_edge<L: Lanes>(x: L, y: L, z: L, tan_cutoff: f32) -> (L, L) {
    let r = (x * x + y * y).root();
    let inside = L::above(z, L::splat(0.0)) * (L::splat(1.0) - L::above(r, z * L::splat(tan_cutoff)));
    (inside, r)
}

/// A spot's projective coordinates (`light_uv`) of the point `(x, y, z)`.
pub fn spot_uv<L: Lanes>(x: L, y: L, z: L, tan_cutoff: f32) -> (L, L) {
    let s = L::splat(0.5) / (z * L::splat(tan_cutoff));
    (L::splat(0.5) + x * s, L::splat(0.5) + y * s)
}

/// The spot's shadow test at the point `(x, y, z)` of its frame, given the
/// depth `stored` its texel holds (`SHADOW_FAR` outside the map): 1 if lit.
/// `texel_slope` is the texel's angular size `2 tan(cutoff) / res` times
/// `shadow_slope` (see `shadow_visibility`).
pub fn spot_lit<L: Lanes>(x: L, y: L, z: L, stored: L, texel_slope: f32) -> L {
    // The distance to the light is |local| (the frame is orthonormal), and
    // a texel's footprint there `d 2 tan(cutoff) / (res cos^2)`, widened
    // off-axis by `1/cos^2 = d^2 / z^2` (at most 1e3). The test
    // `d - bias > stored` multiplied through by `z^2` (the larger of `z^2`
    // and `1e-3 d^2`, positive) needs no division: it runs for every sample
    // of every shaft.
    let d2 = x * x + y * y + z * z;
    let d = d2.root();
    let z2 = (z * z).larger(L::splat(1e-3) * d2);
    let shadowed = L::above((d * L::splat(1.0 - 1e-4) - stored) * z2, L::splat(texel_slope) * d * d2);
    L::splat(1.0) - shadowed
}

/// The depth a light's shadow-map texel holds at projective coordinates
/// `(u, v)`, or `SHADOW_FAR` outside the map (outside the cone or the
/// window, already dark) or without one.
// Plain comparisons rather than `Range::contains` in a kernel.
#[allow(clippy::manual_range_contains)]
pub fn stored_depth(light: &GpuLight, shadow: &[f32], u: f32, v: f32) -> f32 {
    let res = light.shadow_resolution;
    // Written so that NaN coordinates fall outside.
    if res == 0 || !(u >= 0.0 && u < 1.0 && v >= 0.0 && v < 1.0) {
        return SHADOW_FAR;
    }
    // SAFETY: `u` and `v` are in [0, 1) (checked above, so not NaN) and
    // `res` at most 8192: the products are finite and fit a `u32`. Rust's
    // saturating `as` adds four compares and moves per conversion, 6 % of
    // the shafts pass on the CPU, for a case that cannot occur here.
    let i = unsafe { (u * res as f32).to_int_unchecked::<u32>() }.min(res - 1);
    let j = unsafe { (v * res as f32).to_int_unchecked::<u32>() }.min(res - 1);
    shadow[(light.shadow_offset + j * res + i) as usize]
}

/// A directional light's projective coordinates (`light_uv`) of the point
/// `(x, y)` of its frame.
pub fn directional_uv<L: Lanes>(x: L, y: L, half_extent_x: f32, half_extent_y: f32) -> (L, L) {
    (
        L::splat(0.5) + L::splat(0.5) * x / L::splat(half_extent_x),
        L::splat(0.5) + L::splat(0.5) * y / L::splat(half_extent_y),
    )
}

/// A directional light's shadow test at depth `z` (from its entry plane),
/// given the depth `stored` its texel holds: 1 if lit. `bias` is the texel's
/// footprint times `shadow_slope` (see `shadow_visibility`).
pub fn directional_lit<L: Lanes>(z: L, stored: L, bias: f32) -> L {
    L::splat(1.0) - L::above(z - (L::splat(bias) + L::splat(1e-4) * z), stored)
}

/// `emitted_visible(light, light_map, shadow, p, 1.0)` summed over four
/// points `p` of the medium given lane by lane (`x`, `y`, `z` in the light's
/// frame), lane `k` counted `used[k]` (1 or 0) times; a spot or a directional
/// light. The cone's hard edge, the projective coordinates and the shadow
/// test run on the four lanes at once; a soft edge, a window's bounds, the
/// shadow-map and light-map reads lane by lane.
pub fn emitted_visible4(
    light: &GpuLight,
    light_map: &[Vec4],
    shadow: &[f32],
    x: Vec4,
    y: Vec4,
    z: Vec4,
    used: Vec4,
) -> Vec4 {
    let spot = light.kind != LIGHT_DIRECTIONAL;
    let mut weight;
    let (u, v);
    if spot {
        let (inside, r) = spot_edge(x, y, z, light.tan_cutoff);
        weight = inside * used;
        if light.beam < light.cutoff {
            weight *= Vec4::new(
                soft_lane(light, weight.x, r.x, z.x),
                soft_lane(light, weight.y, r.y, z.y),
                soft_lane(light, weight.z, r.z, z.z),
                soft_lane(light, weight.w, r.w, z.w),
            );
        }
        (u, v) = spot_uv(x, y, z, light.tan_cutoff);
    } else {
        // Past the entry plane (`z >= 0`).
        weight = (Vec4::ONE - Vec4::above(Vec4::ZERO, z)) * used;
        (u, v) = directional_uv(x, y, light.half_extent_x, light.half_extent_y);
        if light.bounded != 0 {
            weight *= Vec4::new(in_window(u.x, v.x), in_window(u.y, v.y), in_window(u.z, v.z), in_window(u.w, v.w));
        }
    }
    let res = light.shadow_resolution;
    if res > 0 {
        let stored = Vec4::new(
            stored_depth(light, shadow, u.x, v.x),
            stored_depth(light, shadow, u.y, v.y),
            stored_depth(light, shadow, u.z, v.z),
            stored_depth(light, shadow, u.w, v.w),
        );
        // Points of the medium: `shadow_slope(1.0)` is 1.
        weight *= if spot {
            spot_lit(x, y, z, stored, 2.0 * light.tan_cutoff / res as f32)
        } else {
            directional_lit(z, stored, 2.0 * light.half_extent_x.max(light.half_extent_y) / res as f32)
        };
    }
    if light.light_map_width == 0 {
        return light.power * weight.element_sum();
    }
    mapped_lane(light, light_map, weight.x, u.x, v.x)
        + mapped_lane(light, light_map, weight.y, u.y, v.y)
        + mapped_lane(light, light_map, weight.z, u.z, v.z)
        + mapped_lane(light, light_map, weight.w, u.w, v.w)
}

/// `soft_edge` for a lane inside the cone (`inside` non-zero), else 0.
fn soft_lane(light: &GpuLight, inside: f32, r: f32, z: f32) -> f32 {
    if inside == 0.0 {
        0.0
    } else {
        soft_edge(light, r, z)
    }
}

/// 1 inside a window's rectangle in projective coordinates, else 0.
fn in_window(u: f32, v: f32) -> f32 {
    if u < 0.0 || u > 1.0 || v < 0.0 || v > 1.0 {
        0.0
    } else {
        1.0
    }
}

/// `power * weight` times the light map at `(u, v)`; 0 (no read) where
/// `weight` is 0.
fn mapped_lane(light: &GpuLight, light_map: &[Vec4], weight: f32, u: f32, v: f32) -> Vec4 {
    if weight == 0.0 {
        return Vec4::ZERO;
    }
    let map = sample_light_map(light_map, light.light_map_offset, light.light_map_width, light.light_map_height, u, v);
    light.power * weight * map
}

/// Bilinear lookup in a light map stored row by row (row 0 at `v = 0`), with
/// texel centres at `(i + 0.5) / width`, clamped to the edge texels.
pub fn sample_light_map(texels: &[Vec4], offset: u32, width: u32, height: u32, u: f32, v: f32) -> Vec4 {
    // `max` then `min` rather than `clamp`: a NaN coordinate becomes 0
    // (`f32::max` returns the number), so both are finite, in [0, size - 1].
    let fx = (u * width as f32 - 0.5).max(0.0).min((width - 1) as f32);
    let fy = (v * height as f32 - 0.5).max(0.0).min((height - 1) as f32);
    // fx, fy >= 0: truncation is the floor (and needs no libm call).
    // SAFETY: finite and in [0, size - 1] (above), so they fit a `u32`.
    let x0 = unsafe { fx.to_int_unchecked::<u32>() };
    let y0 = unsafe { fy.to_int_unchecked::<u32>() };
    let tx = fx - x0 as f32;
    let ty = fy - y0 as f32;
    let x1 = (x0 + 1).min(width - 1);
    let y1 = (y0 + 1).min(height - 1);
    let row0 = offset + y0 * width;
    let row1 = offset + y1 * width;
    let top = texels[(row0 + x0) as usize] * (1.0 - tx) + texels[(row0 + x1) as usize] * tx;
    let bottom = texels[(row1 + x0) as usize] * (1.0 - tx) + texels[(row1 + x1) as usize] * tx;
    top * (1.0 - ty) + bottom * ty
}

/// A spotlight's cone terms from its half-angle `cutoff` (radians):
/// `tan(cutoff)`, `cos^2(cutoff)` and `sin^2(cutoff)` (`GpuLight`'s
/// `tan_cutoff`, `cos2_cutoff`, `sin2_cutoff`).
pub fn cone_terms(cutoff: f32) -> (f32, f32, f32) {
    let (sin, cos) = cutoff.sin_cos();
    (cutoff.tan(), cos * cos, sin * sin)
}

/// Light-map / shadow-map coordinates `(u, v)` in [0, 1] of a point given in
/// the light's frame. Spot: `uv = 0.5 + 0.5 (x, y) / (z tan(cutoff))`;
/// directional: `uv = 0.5 + 0.5 (x / half_extent_x, y / half_extent_y)`.
pub fn light_uv(light: &GpuLight, local: Vec3) -> (f32, f32) {
    if light.kind == LIGHT_DIRECTIONAL {
        directional_uv(local.x, local.y, light.half_extent_x, light.half_extent_y)
    } else {
        spot_uv(local.x, local.y, local.z, light.tan_cutoff)
    }
}

/// What the light emits toward `local` before any attenuation or shadowing:
/// radiant intensity in W/sr (spot: `I_l` of eq. 2, cone profile times light
/// map) or irradiance in W/m^2 (directional: light map over the window).
pub fn emitted(light: &GpuLight, light_map: &[Vec4], local: Vec3) -> Vec4 {
    // The projective coordinates cost a division: only for a window or a map.
    let uv = if needs_uv(light) { light_uv(light, local) } else { (0.0, 0.0) };
    emitted_at(light, light_map, local, uv)
}

/// Whether `emitted` reads the light's projective coordinates (a window or
/// a light map).
fn needs_uv(light: &GpuLight) -> bool {
    light.kind != LIGHT_POINT && (light.bounded != 0 || light.light_map_width > 0)
}

/// `emitted(light, light_map, local) * shadow_visibility(light, shadow,
/// local, cos_incidence)`, the light's projective coordinates computed once
/// for both (the shafts' and the surfaces' inner loops).
pub fn emitted_visible(light: &GpuLight, light_map: &[Vec4], shadow: &[f32], local: Vec3, cos_incidence: f32) -> Vec4 {
    let mapped = light.kind != LIGHT_POINT && light.shadow_resolution > 0;
    let uv = if mapped || needs_uv(light) { light_uv(light, local) } else { (0.0, 0.0) };
    let e = emitted_at(light, light_map, local, uv);
    if (e.x > 0.0 || e.y > 0.0 || e.z > 0.0) && mapped {
        e * shadow_visibility_at(light, shadow, local, cos_incidence, uv)
    } else {
        e
    }
}

/// `emitted`, given the light's projective coordinates `uv` (`light_uv`;
/// read only where `needs_uv`).
fn emitted_at(light: &GpuLight, light_map: &[Vec4], local: Vec3, uv: (f32, f32)) -> Vec4 {
    if light.kind == LIGHT_POINT {
        return light.power;
    }
    let mut strength = 1.0;
    if light.kind == LIGHT_DIRECTIONAL {
        if local.z < 0.0 {
            return Vec4::ZERO;
        }
    } else {
        strength = cone_falloff(light, local);
        if strength <= 0.0 {
            return Vec4::ZERO;
        }
    }
    let mut color = light.power * strength;
    if needs_uv(light) {
        let (u, v) = uv;
        if light.kind == LIGHT_DIRECTIONAL && light.bounded != 0 && (u < 0.0 || u > 1.0 || v < 0.0 || v > 1.0) {
            return Vec4::ZERO;
        }
        if light.light_map_width > 0 {
            color *= sample_light_map(
                light_map,
                light.light_map_offset,
                light.light_map_width,
                light.light_map_height,
                u,
                v,
            );
        }
    }
    color
}

/// World-space ray of shadow-map texel `texel` (row-major, `res x res`) of a
/// light: origin and unit direction. Spot: from the light through the texel
/// centre on the `z = 1` plane of the frustum that covers the cone.
/// Directional: from the texel centre on the entry plane along the light.
#[inline]
pub fn shadow_texel_ray(light: &GpuLight, texel: u32) -> (Vec3, Vec3) {
    let res = light.shadow_resolution;
    let i = texel % res;
    let j = texel / res;
    let a = 2.0 * (i as f32 + 0.5) / res as f32 - 1.0;
    let b = 2.0 * (j as f32 + 0.5) / res as f32 - 1.0;
    let (x, y, z) = (light.axis_x.xyz(), light.axis_y.xyz(), light.axis_z.xyz());
    if light.kind == LIGHT_DIRECTIONAL {
        let origin = light.position.xyz() + x * (a * light.half_extent_x) + y * (b * light.half_extent_y);
        (origin, z)
    } else {
        let dir = (z + x * (a * light.tan_cutoff) + y * (b * light.tan_cutoff)).normalize();
        (light.position.xyz(), dir)
    }
}

/// Depth tolerance of the shadow test, metres. A shadow-map texel stores the
/// depth along its centre ray; a point anywhere in the texel's footprint
/// (`footprint` metres wide) on a surface tilted by `theta` to the light can
/// differ from it by up to `footprint * tan(theta)`. The bias is one footprint
/// plus that slope term (capped at 10 footprints, i.e. grazing at 84 deg), plus
/// 1e-4 of the distance for f32 rounding of the depths themselves.
/// (`shadow_visibility` applies it in a form without divisions.)
pub fn shadow_bias(footprint: f32, cos_incidence: f32, distance: f32) -> f32 {
    // A point in the medium (or a surface facing the light): no slope.
    footprint * shadow_slope(cos_incidence) + 1e-4 * distance
}

/// The shadow test `H` of eq. 2 (2002 paper): 1 if the point at `local` in
/// the light's frame sees the light according to the light's shadow map, 0
/// otherwise. `cos_incidence` is the cosine between the surface normal
/// and the direction to the light (1 for points in the medium).
pub fn shadow_visibility(light: &GpuLight, shadow: &[f32], local: Vec3, cos_incidence: f32) -> f32 {
    if light.shadow_resolution == 0 {
        return 1.0;
    }
    shadow_visibility_at(light, shadow, local, cos_incidence, light_uv(light, local))
}

/// `shadow_visibility` of a light with a shadow map, given its projective
/// coordinates `(u, v)` at `local`.
fn shadow_visibility_at(light: &GpuLight, shadow: &[f32], local: Vec3, cos_incidence: f32, (u, v): (f32, f32)) -> f32 {
    let stored = stored_depth(light, shadow, u, v);
    // `shadow_bias` is `footprint * slope + 1e-4 distance`.
    let slope = shadow_slope(cos_incidence);
    let res = light.shadow_resolution;
    if light.kind == LIGHT_DIRECTIONAL {
        let footprint = 2.0 * light.half_extent_x.max(light.half_extent_y) / res as f32;
        return directional_lit(local.z, stored, footprint * slope);
    }
    let texel = 2.0 * light.tan_cutoff / res as f32;
    spot_lit(local.x, local.y, local.z, stored, texel * slope)
}

/// `shadow_bias`'s factor on the footprint: 1, plus `tan(theta)` (at most
/// 10) on a surface tilted by `theta` to the light.
fn shadow_slope(cos_incidence: f32) -> f32 {
    if cos_incidence >= 1.0 {
        return 1.0;
    }
    let c = cos_incidence.abs().clamp(1e-3, 1.0);
    1.0 + ((1.0 - c * c).sqrt() / c).min(10.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angle_from_axis_matches_atan2_to_a_few_ulps() {
        // Ratios r / z from 1e-6 to 1e6, and the reduction's switch points.
        let mut worst = 0.0f64;
        for k in 0..=24_000 {
            let t = 10f64.powf(-6.0 + k as f64 * 12.0 / 24_000.0);
            for (r, z) in [(t as f32, 1.0f32), (1.0, (1.0 / t) as f32), (0.267_949_2, 1.0), (1.0, 1.0)] {
                let exact = (r as f64).atan2(z as f64);
                let e = (angle_from_axis(r, z) as f64 - exact).abs() / exact.max(1e-30);
                worst = worst.max(e);
            }
        }
        assert_eq!(angle_from_axis(0.0, 1.0), 0.0);
        assert!(worst < 5e-7, "worst relative error {worst:e}");
    }

    /// `atan2_accurate` against f64 `atan2` around the whole circle (every
    /// quadrant, the axes, and radii from 1e-6 to 1e6): within 4e-7 rad
    /// absolute (a few f32 ulps of pi), the signs of zero as f32's `atan2`
    /// gives them except `(-0, x < 0)` (`pi`, never `-pi`: the range is
    /// `(-pi, pi]`), and 0 at the origin.
    #[test]
    fn atan2_accurate_matches_atan2_around_the_circle() {
        let mut worst = 0.0f64;
        for k in 0..36_000 {
            let angle = -std::f64::consts::PI + (k as f64 + 0.5) * std::f64::consts::TAU / 36_000.0;
            for radius in [1e-6f64, 1.0, 1e6] {
                let (y, x) = ((radius * angle.sin()) as f32, (radius * angle.cos()) as f32);
                let exact = (y as f64).atan2(x as f64);
                worst = worst.max((atan2_accurate(y, x) as f64 - exact).abs());
            }
        }
        assert!(worst < 4e-7, "worst absolute error {worst:e} rad");
        assert_eq!(atan2_accurate(0.0, 0.0), 0.0);
        assert_eq!(atan2_accurate(0.0, 1.0), 0.0);
        assert_eq!(atan2_accurate(1.0, 0.0), core::f32::consts::FRAC_PI_2);
        assert_eq!(atan2_accurate(-1.0, 0.0), -core::f32::consts::FRAC_PI_2);
        assert_eq!(atan2_accurate(0.0, -1.0), core::f32::consts::PI);
        assert_eq!(atan2_accurate(-0.0, -1.0), core::f32::consts::PI);
    }

    fn spot(cutoff_deg: f32, beam_deg: f32) -> GpuLight {
        GpuLight {
            position: Vec4::ZERO,
            axis_x: Vec4::X,
            axis_y: Vec4::Y,
            axis_z: Vec4::Z,
            power: Vec4::ONE,
            cutoff: cutoff_deg.to_radians(),
            beam: beam_deg.to_radians(),
            tan_cutoff: cone_terms(cutoff_deg.to_radians()).0,
            cos2_cutoff: cone_terms(cutoff_deg.to_radians()).1,
            sin2_cutoff: cone_terms(cutoff_deg.to_radians()).2,
            ..Default::default()
        }
    }

    #[test]
    fn cone_profile_is_hard_or_linear_in_angle() {
        let hard = spot(30.0, 30.0);
        let at = |deg: f32| Vec3::new(deg.to_radians().tan(), 0.0, 1.0);
        assert_eq!(cone_falloff(&hard, at(29.9)), 1.0);
        assert_eq!(cone_falloff(&hard, at(30.1)), 0.0);
        assert_eq!(cone_falloff(&hard, Vec3::new(0.0, 0.0, -1.0)), 0.0);
        let soft = spot(30.0, 20.0);
        assert_eq!(cone_falloff(&soft, at(10.0)), 1.0);
        assert!((cone_falloff(&soft, at(25.0)) - 0.5).abs() < 1e-5);
        // A 0.01 degree cone still has an inside: cos(cutoff) would round to 1.
        let narrow = spot(0.01, 0.01);
        assert_eq!(cone_falloff(&narrow, at(0.005)), 1.0);
        assert_eq!(cone_falloff(&narrow, at(0.02)), 0.0);
    }

    #[test]
    fn light_map_is_bilinear_between_texel_centres() {
        // 2x1 map: black, white. Texel centres at u = 0.25 and 0.75.
        let texels = [Vec4::ZERO, Vec4::ONE];
        assert_eq!(sample_light_map(&texels, 0, 2, 1, 0.25, 0.5), Vec4::ZERO);
        assert_eq!(sample_light_map(&texels, 0, 2, 1, 0.5, 0.5), Vec4::splat(0.5));
        assert_eq!(sample_light_map(&texels, 0, 2, 1, 0.0, 0.5), Vec4::ZERO);
        assert_eq!(sample_light_map(&texels, 0, 2, 1, 1.0, 0.5), Vec4::ONE);
        // Far outside [0,1]: clamped, never out of bounds.
        assert_eq!(sample_light_map(&texels, 0, 2, 1, -7.0, 99.0), Vec4::ZERO);
    }

    #[test]
    fn shadow_texel_rays_cover_the_cone() {
        let mut light = spot(45.0, 45.0);
        light.shadow_resolution = 2;
        // Texel (0,0) looks toward -x, -y at half the cone's tangent.
        let (o, d) = shadow_texel_ray(&light, 0);
        assert_eq!(o, Vec3::ZERO);
        let expected = Vec3::new(-0.5, -0.5, 1.0).normalize();
        assert!((d - expected).length() < 1e-6);
    }

    #[test]
    fn the_division_free_shadow_test_is_distance_minus_bias() {
        // `shadow_visibility` tests `(d - 1e-4 d - stored) z^2 > texel
        // slope d^3`; it must agree with `d - shadow_bias(footprint) >
        // stored` (footprint `d texel / cos^2`) wherever the two sides are
        // not within f32 rounding (1e-5 of d) of each other. Stored depths
        // are drawn around the threshold, so both outcomes occur.
        let mut light = spot(35.0, 35.0);
        light.shadow_resolution = 64;
        let res = light.shadow_resolution;
        let texel = 2.0 * light.tan_cutoff / res as f32;
        let mut next = crate::test_uniforms(12345);
        let (mut checked, mut shadowed) = (0, 0);
        for _ in 0..20_000 {
            let z = 0.05 + 20.0 * next();
            let local =
                Vec3::new((2.0 * next() - 1.0) * z * light.tan_cutoff, (2.0 * next() - 1.0) * z * light.tan_cutoff, z);
            let cos_incidence = if next() < 0.5 { 1.0 } else { next() };
            let d = local.length();
            let footprint = d * texel / (local.z * local.z / (d * d)).max(1e-3);
            let threshold = d - shadow_bias(footprint, cos_incidence, d);
            let stored = threshold * (1.0 + 0.02 * (2.0 * next() - 1.0));
            if (threshold - stored).abs() < 1e-5 * d {
                continue;
            }
            let mut map = vec![0.0f32; (res * res) as usize];
            let (u, v) = light_uv(&light, local);
            let (i, j) = (((u * res as f32) as u32).min(res - 1), ((v * res as f32) as u32).min(res - 1));
            map[(j * res + i) as usize] = stored;
            let want = if threshold > stored { 0.0 } else { 1.0 };
            assert_eq!(shadow_visibility(&light, &map, local, cos_incidence), want, "{local} {cos_incidence} {stored}");
            checked += 1;
            shadowed += (want == 0.0) as u32;
        }
        assert!(checked > 19_000 && shadowed > 5_000 && shadowed < checked - 5_000, "{checked} {shadowed}");
    }

    #[test]
    fn bias_grows_toward_grazing_and_stays_finite() {
        let b0 = shadow_bias(0.01, 1.0, 10.0);
        assert!((b0 - (0.01 + 1e-3)).abs() < 1e-7);
        let grazing = shadow_bias(0.01, 0.0, 10.0);
        assert!((grazing - (0.11 + 1e-3)).abs() < 1e-6);
    }

    #[test]
    fn four_points_at_once_match_one_at_a_time() {
        // Spots with a hard and a soft edge, with and without a light map,
        // and a window, each with a shadow map of random depths: the four-lane
        // evaluation equals the sum of the one-point one, lane by lane (to
        // rounding: the light map's factors are multiplied in another order),
        // unused lanes counting nothing.
        let mut next = crate::test_uniforms(5);
        let res = 64u32;
        let shadow: Vec<f32> = (0..res * res).map(|_| 1.0 + 8.0 * next()).collect();
        let light_map: Vec<Vec4> = (0..16).map(|_| Vec4::new(next(), next(), next(), 0.0)).collect();
        let mut lights = Vec::new();
        for (beam, mapped) in [(30.0f32, false), (20.0, false), (30.0, true), (12.0, true)] {
            let mut l = spot(30.0, beam);
            l.power = Vec4::new(3.0, 2.0, 1.0, 0.0);
            l.shadow_resolution = res;
            if mapped {
                (l.light_map_width, l.light_map_height) = (4, 4);
            }
            lights.push(l);
        }
        lights.push(GpuLight {
            kind: LIGHT_DIRECTIONAL,
            axis_x: Vec4::X,
            axis_y: Vec4::Y,
            axis_z: Vec4::Z,
            power: Vec4::new(1.0, 2.0, 3.0, 0.0),
            half_extent_x: 2.0,
            half_extent_y: 1.0,
            bounded: 1,
            shadow_resolution: res,
            light_map_width: 4,
            light_map_height: 4,
            ..Default::default()
        });
        let mut lit_lanes = 0;
        for light in &lights {
            for _ in 0..5_000 {
                let mut p = [Vec3::ZERO; 4];
                for q in &mut p {
                    let z = 9.0 * next() - 0.5;
                    *q = Vec3::new(
                        (2.4 * next() - 1.2) * z.abs() * 0.6 + next() - 0.5,
                        (2.4 * next() - 1.2) * z.abs() * 0.6,
                        z,
                    );
                }
                let used = Vec4::new(1.0, 1.0, 1.0, if next() < 0.5 { 1.0 } else { 0.0 });
                let lanes = |f: fn(Vec3) -> f32| Vec4::new(f(p[0]), f(p[1]), f(p[2]), f(p[3]));
                let (x, y, z) = (lanes(|q| q.x), lanes(|q| q.y), lanes(|q| q.z));
                let four = emitted_visible4(light, &light_map, &shadow, x, y, z, used);
                let mut one = Vec4::ZERO;
                for (k, q) in p.iter().enumerate() {
                    let e = emitted_visible(light, &light_map, &shadow, *q, 1.0);
                    if used[k] > 0.0 {
                        one += e;
                        lit_lanes += (e.max_element() > 0.0) as u32;
                    }
                }
                assert!((four - one).abs().max_element() <= 1e-6 * one.abs().max_element(), "{four} vs {one} at {p:?}");
            }
        }
        // The points light some lanes and leave others dark.
        assert!(lit_lanes > 20_000 && lit_lanes < 90_000, "{lit_lanes}");
    }
}
