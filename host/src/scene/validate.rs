//! Field checks: each failure names the field and what was expected.

use anyhow::{anyhow, Result};
use glam::{Vec3, Vec4};

/// The least default shadow-map resolution where the maps serve the shafts
/// alone (surfaces shadowed by shadow rays, the default); the default there
/// is the smallest resolution whose texels are no wider than a pixel where
/// the view sees the light (`common::shadow_maps::shafts_resolution`), up to
/// `SURFACE_SHADOW_MAP_RESOLUTION`.
pub const SHAFTS_MIN_SHADOW_MAP_RESOLUTION: u32 = 128;

/// The default shadow-map resolution where the maps also shadow the
/// surfaces seen (`[surface] shadows = "shadow-map"` or `--surface-shadows
/// shadow-map`), where each texel's step shows on a shadow's outline. Measured on the Fig. 7 stage at 720x480
/// (surface term against shadow rays): 512 costs 0.05 % RMS of the 8-bit
/// range, a quarter of the time of 1024.
pub const SURFACE_SHADOW_MAP_RESOLUTION: u32 = 512;

/// One validation failure: the field's path and what was expected.
pub fn invalid(field: &str, expected: &str, got: impl std::fmt::Debug) -> anyhow::Error {
    anyhow!("{field}: expected {expected}, got {got:?}")
}

/// A positive number up to `MAX_COORDINATE` (lengths, scales).
pub fn positive(field: &str, v: f32) -> Result<f32> {
    if !(v.is_finite() && v > 0.0 && v <= MAX_COORDINATE) {
        return Err(invalid(field, "a positive number up to 1e7", v));
    }
    Ok(v)
}

/// The largest coordinate or vector component a scene may give (m, or the
/// field's unit): 10 000 km, past any scene's extent (the planet's radius
/// is the sky's own field), and small enough that squares and sums of
/// coordinates stay far inside f32's range (3.4e38) in every kernel.
pub const MAX_COORDINATE: f32 = 1e7;

/// The largest light intensity (W/sr), irradiance (W/m^2) or coefficient
/// (1/m) a scene may give: 1e12, a thousand times a stadium floodlight's
/// intensity, so that intensity times coefficient times path length
/// (1e12 * 1e4 /m * 1e7 m) stays inside f32's range.
pub const MAX_MAGNITUDE: f32 = 1e12;

pub fn finite3(field: &str, v: [f32; 3]) -> Result<Vec3> {
    if v.iter().all(|x| x.is_finite() && x.abs() <= MAX_COORDINATE) {
        Ok(Vec3::from(v))
    } else {
        Err(invalid(field, "three finite numbers within +-1e7 (MAX_COORDINATE)", v))
    }
}

pub fn unit3(field: &str, v: [f32; 3]) -> Result<Vec3> {
    let v3 = finite3(field, v)?;
    let len = v3.length();
    if !len.is_finite() || len <= 1e-12 {
        return Err(invalid(field, "a non-zero direction", v));
    }
    Ok(v3 / len)
}

pub fn non_negative3(field: &str, v: [f32; 3]) -> Result<Vec3> {
    if v.iter().all(|x| x.is_finite() && *x >= 0.0 && *x <= MAX_MAGNITUDE) {
        Ok(Vec3::from(v))
    } else {
        Err(invalid(field, "three non-negative numbers up to 1e12 (MAX_MAGNITUDE)", v))
    }
}

pub fn albedo(field: &str, v: [f32; 3]) -> Result<Vec4> {
    if v.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)) {
        Ok(Vec3::from(v).extend(0.0))
    } else {
        Err(invalid(field, "three numbers in [0, 1]", v))
    }
}

/// A light's `shadow_map_resolution`, checked; `None` if the file gives none.
pub fn shadow_resolution(field: &str, r: Option<u32>) -> Result<Option<u32>> {
    match r {
        None => Ok(None),
        Some(r) if (1..=8192).contains(&r) => Ok(Some(r)),
        Some(r) => Err(invalid(field, "a resolution in 1..=8192", r)),
    }
}
