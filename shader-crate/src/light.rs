//! Lights: spotlight cones, light maps (projective textures), shadow maps, and
//! the light that reaches a point of the medium or of a surface.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::glam::{Vec3, Vec4, Vec4Swizzles};
use crate::types::{GpuLight, LIGHT_DIRECTIONAL, LIGHT_POINT};

/// Stored in a shadow-map texel whose ray hits nothing.
pub const SHADOW_FAR: f32 = f32::MAX;

/// Beer-Lambert transmittance `exp(-sigma_t d)` per channel (the `exp(-rho kappa s)`
/// factors of eq. 1 and eq. 3 of the 2002 paper); `sigma_t` in 1/m, `distance` in m.
pub fn transmittance(sigma_t: Vec4, distance: f32) -> Vec4 {
    Vec4::new((-sigma_t.x * distance).exp(), (-sigma_t.y * distance).exp(), (-sigma_t.z * distance).exp(), 1.0)
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
    if local.z <= 0.0 {
        return 0.0;
    }
    let r = (local.x * local.x + local.y * local.y).sqrt();
    if r > local.z * light.tan_cutoff {
        return 0.0;
    }
    if light.beam >= light.cutoff {
        return 1.0;
    }
    let angle = r.atan2(local.z);
    ((light.cutoff - angle) / (light.cutoff - light.beam)).clamp(0.0, 1.0)
}

/// Bilinear lookup in a light map stored row by row (row 0 at `v = 0`), with
/// texel centres at `(i + 0.5) / width`, clamped to the edge texels.
pub fn sample_light_map(texels: &[Vec4], offset: u32, width: u32, height: u32, u: f32, v: f32) -> Vec4 {
    let fx = (u * width as f32 - 0.5).clamp(0.0, (width - 1) as f32);
    let fy = (v * height as f32 - 0.5).clamp(0.0, (height - 1) as f32);
    // fx, fy >= 0: truncation is the floor (and needs no libm call).
    let x0 = fx as u32;
    let y0 = fy as u32;
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
        (0.5 + 0.5 * local.x / light.half_extent_x, 0.5 + 0.5 * local.y / light.half_extent_y)
    } else {
        let s = 0.5 / (local.z * light.tan_cutoff);
        (0.5 + local.x * s, 0.5 + local.y * s)
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
    let res = light.shadow_resolution;
    if u < 0.0 || u >= 1.0 || v < 0.0 || v >= 1.0 {
        // Outside the shadow map: outside the cone or the window, already dark.
        return 1.0;
    }
    let i = ((u * res as f32) as u32).min(res - 1);
    let j = ((v * res as f32) as u32).min(res - 1);
    let stored = shadow[(light.shadow_offset + j * res + i) as usize];
    // `shadow_bias` is `footprint * slope + 1e-4 distance`.
    let slope = shadow_slope(cos_incidence);
    if light.kind == LIGHT_DIRECTIONAL {
        let footprint = 2.0 * light.half_extent_x.max(light.half_extent_y) / res as f32;
        return if local.z - (footprint * slope + 1e-4 * local.z) > stored { 0.0 } else { 1.0 };
    }
    // A spot: the distance to the light is |local| (the frame is
    // orthonormal), and a texel's footprint there `d 2 tan(cutoff) / (res
    // cos^2)`, widened off-axis by `1/cos^2 = d^2 / z^2` (at most 1e3).
    // The test `d - bias > stored` multiplied through by `z^2` (the larger
    // of `z^2` and `1e-3 d^2`, positive) needs no division: it runs for
    // every sample of every shaft.
    let d2 = local.length_squared();
    let d = d2.sqrt();
    let z2 = (local.z * local.z).max(1e-3 * d2);
    let texel = 2.0 * light.tan_cutoff / res as f32;
    if (d * (1.0 - 1e-4) - stored) * z2 > texel * slope * d * d2 {
        0.0
    } else {
        1.0
    }
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
        let mut state = 12345u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
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
}
