//! Aerial perspective: the air between the eye and a surface. The sky's
//! single scattering (the survey's eq. 1, as the sky pass integrates it to
//! the top of the atmosphere) integrated along the view ray only up to the
//! surface: the sun's light the air scatters toward the eye,
//!
//! `L_air = E_sun int_0^t (beta_R(h) P_R + beta_M(h) P_M) T_sun(s) T_view(0, s) ds`,
//!
//! and the air's transmittance `T_view(0, t)`, which dims the surface's light.

use super::{altitude_along, atmosphere_span, extinction, mie_phase, scattered_sunlight, SkyParams};
use crate::camera::{camera_ray, in_image};
use crate::glam::{Vec3, Vec4, Vec4Swizzles};
use crate::phase;
use crate::types::{CommonParams, GBufferTexel, NO_OBJECT};
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// Metres of view ray per quadrature sample (the midpoint rule; at least 1
/// sample, at most 4 `view_samples`): the air changes over its scale
/// heights (1.2 and 8 km), so 250 m keeps the rule's error far below the
/// 0.5 % asked.
pub const AERIAL_STEP: f32 = 250.0;
/// The smallest |cosine| a step's length is figured with: level rays take
/// steps of `AERIAL_STEP / AERIAL_FLATTEST`.
pub const AERIAL_FLATTEST: f32 = 0.25;

/// The air's light along unit view direction `dir` from the observer to
/// distance `t` (m; rgb, W/(m^2 sr)) and its transmittance over that
/// distance (rgb).
pub fn aerial_segment(p: &SkyParams, table: &[Vec4], dir: Vec3, t: f32) -> (Vec3, Vec3) {
    let h = p.observer_altitude;
    let mu = dir.y.clamp(-1.0, 1.0);
    let (enter, leave) = atmosphere_span(p, h, mu);
    let (t0, t1) = (enter.max(0.0), t.min(leave));
    if t1 <= t0 {
        return (Vec3::ZERO, Vec3::ONE);
    }
    // Each step climbs or falls at most `AERIAL_STEP`, and is at most
    // `AERIAL_STEP / AERIAL_FLATTEST` long (nearly level rays).
    let rise = if mu.abs() > AERIAL_FLATTEST { mu.abs() } else { AERIAL_FLATTEST };
    let mut n = ((t1 - t0) * rise / AERIAL_STEP).ceil() as u32;
    if n < 1 {
        n = 1;
    }
    if n > 4 * p.view_samples.max(1) {
        n = 4 * p.view_samples.max(1);
    }
    let ds = (t1 - t0) / n as f32;
    let sun_dir = p.sun_direction.xyz();
    let mu_s = sun_dir.y;
    let nu = dir.dot(sun_dir).clamp(-1.0, 1.0);
    let r = p.ground_radius + h;
    let phase_r = phase::rayleigh(nu);
    let phase_m = mie_phase(p, nu);
    let mut tau = Vec3::ZERO;
    let mut sum = Vec3::ZERO;
    let mut k = 0;
    while k < n {
        let s = t0 + (k as f32 + 0.5) * ds;
        let h_s = altitude_along(p, h, mu, s);
        let sigma = extinction(p, h_s);
        let view = (-(tau + sigma * (0.5 * ds))).exp();
        sum += scattered_sunlight(p, table, r, mu_s, nu, s, h_s, phase_r, phase_m) * view * ds;
        tau += sigma * ds;
        k += 1;
    }
    (sum * p.sun_irradiance.xyz(), (-tau).exp())
}

/// Per-pixel aerial perspective kernel: the air's light in front of the
/// surface pixel `index` sees (rgb, W/(m^2 sr)) and the air's
/// transmittance to it (rgb; w 1: the fog's own light, gathered near the
/// eye, is not dimmed by it), or nothing and a transmittance of 1 where the
/// pixel sees no surface (the sky pass has the air to the sky).
pub fn aerial_pixel(
    index: u32,
    common: &CommonParams,
    p: &SkyParams,
    transmittance: &[Vec4],
    texel: &GBufferTexel,
) -> (Vec4, Vec4) {
    let (x, y) = (index % common.width, index / common.width);
    if texel.object == NO_OBJECT || !in_image(common, x, y) {
        return (Vec4::ZERO, Vec4::ONE);
    }
    let (_, dir) = camera_ray(common, x, y);
    let (light, through) = aerial_segment(p, transmittance, dir, texel.normal_distance.w);
    (light.extend(0.0), through.extend(1.0))
}
