//! Sky colour: single scattering of sunlight by air molecules (Rayleigh) and
//! aerosols (Mie) in an atmosphere whose density falls off exponentially
//! with height, section 2 of the 2002 Nishita-Dobashi survey
//! (`../shared/papers/002_*`, eq. 1-2).
//!
//! Eq. 1 writes the sky as `I_s K F(a) / lambda^4 int rho(s) exp(-t(s') - t(s)) ds`
//! with `F = 3/4 (1 + cos^2 a)`. That `F` integrates to `4 pi` over the sphere, and
//! `4 pi K / lambda^4` (eq. 2) is the scattering coefficient at sea level. This
//! module uses the equivalent standard form
//!
//! `L(v) = E_sun int beta_s(h) P(a) T_sun(p) T_view(p) ds`   (W / (m^2 sr))
//!
//! with `E_sun` the solar irradiance normal to its rays at the top of the
//! atmosphere (W/m^2), `beta_s` the scattering coefficient (1/m) and `P` a
//! phase function normalised to 1 over the sphere (1/sr); using eq. 1's `F`
//! as a normalised phase function would make the sky `4 pi` times too bright.
//!
//! The method:
//! - the optical depth from every height to the top of the atmosphere,
//!   along every direction that does not meet the ground, is a table built
//!   by a kernel (`transmittance_texel`, eq. 2 by quadrature) and looked up
//!   for the sun's path from each sample (`sun_transmittance`), the paper's
//!   look-up table;
//! - the view ray's integral is a quadrature (`inscatter`), split where the
//!   ray passes its lowest point and where it enters and leaves the Earth's
//!   shadow (so that no interval holds the jump of `T_sun` to 0), with
//!   samples graded toward the low, dense end of each piece;
//! - optionally (`use_sky_view`) the sky's radiance over view directions is
//!   itself a table (`sky_view_texel`), with rows graded toward the
//!   horizon, looked up per pixel.
//!
//! Heights are kept as altitudes above the ground, never as differences of
//! radii near 6.4e6 m, so that f32 does not misjudge a ray that grazes the
//! horizon (see `hits_ground`).

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::camera::{camera_ray, in_image};
use crate::glam::{UVec3, Vec3, Vec4, Vec4Swizzles};
use crate::phase;
use crate::types::{CommonParams, GBufferTexel, NO_OBJECT};
use core::f32::consts::{FRAC_1_PI, FRAC_PI_2, PI};
use spirv_std::spirv;

pub mod aerial;
pub mod glass;
pub mod light;

/// The sky passes' parameter block.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct SkyParams {
    /// Unit direction toward the sun (scene frame, y up); w: cosine of the
    /// sun disk's angular radius.
    pub sun_direction: Vec4,
    /// Solar irradiance normal to the sun's rays at the top of the
    /// atmosphere, W/m^2 per channel; w: the disk's solid angle, sr.
    pub sun_irradiance: Vec4,
    /// Rayleigh scattering coefficient at the ground, 1/m per channel;
    /// w: its scale height, m.
    pub rayleigh: Vec4,
    /// Mie aerosols at the ground: x scattering, y extinction (1/m),
    /// z scale height (m), w the phase function's `g`.
    pub mie: Vec4,
    /// Ozone absorption coefficient at the layer's peak, 1/m per channel.
    pub ozone: Vec4,
    /// Lambertian albedo of the ground seen below the horizon.
    pub ground_albedo: Vec4,
    /// Radius of the ground sphere, m.
    pub ground_radius: f32,
    /// Height of the top of the atmosphere above the ground, m.
    pub atmosphere_height: f32,
    /// The observer's (camera's) altitude, m.
    pub observer_altitude: f32,
    /// Ozone density: a tent of half-width `ozone_half_width` around
    /// `ozone_center` (m above the ground).
    pub ozone_center: f32,
    pub ozone_half_width: f32,
    /// `MIE_HENYEY_GREENSTEIN` or `MIE_CORNETTE_SHANKS`.
    pub mie_phase: u32,
    /// Quadrature samples along each view ray (split among its pieces).
    pub view_samples: u32,
    /// Quadrature samples along each ray of the transmittance table.
    pub table_samples: u32,
    /// Transmittance table: `transmittance_width` directions by
    /// `transmittance_height` heights.
    pub transmittance_width: u32,
    pub transmittance_height: u32,
    /// Sky-view table: azimuths (from the sun's, 0..pi) by elevations (an
    /// even number of rows: the lower half below the horizon).
    pub sky_view_width: u32,
    pub sky_view_height: u32,
    /// 1 to look the sky up in the sky-view table, 0 to integrate per pixel.
    pub use_sky_view: u32,
    /// `horizon_elevation` of these parameters, radians (set by the host
    /// with that function, so that the per-pixel kernel need not recompute it).
    pub horizon: f32,
    /// `SEA_BELOW` when a sea covers every downward view, `SEA_AROUND` when
    /// the eye is under its surface (the sea passes draw those views).
    pub sea: u32,
    /// Rays per pixel that find how much of the sky a surface sees (the
    /// skylight's shadow, `light::sky_light_pixel`; 0: unshadowed).
    pub light_rays: u32,
    /// 1 when the sky lights the scene's surfaces (the irradiance table is
    /// built): `sky.glass` then adds the skylight on the surfaces seen
    /// through glass, which the skylight pass (one G-buffer texel, the
    /// glass's) does not reach.
    pub lights_surfaces: u32,
    /// Pixels between the pixels that trace the visibility rays
    /// (`light::visibility_pixel`; 1: every pixel traces its own).
    pub light_spacing: u32,
    /// Padding to a whole number of `Vec4`s.
    pub pad: [u32; 2],
}

#[cfg(not(target_arch = "spirv"))]
// SAFETY: `repr(C)`, six `Vec4`s and twenty 4-byte scalars, no padding; any bits are valid.
unsafe impl bytemuck::Zeroable for SkyParams {}
#[cfg(not(target_arch = "spirv"))]
unsafe impl bytemuck::Pod for SkyParams {}

pub const MIE_HENYEY_GREENSTEIN: u32 = 0;
pub const MIE_CORNETTE_SHANKS: u32 = 1;

/// The Cornette-Shanks phase function, 1/sr: Henyey-Greenstein with a
/// Rayleigh-like `1 + cos^2` factor, normalised,
/// `3 (1 - g^2) (1 + cos^2) / (8 pi (2 + g^2) (1 + g^2 - 2 g cos)^(3/2))`.
pub fn cornette_shanks(cos_theta: f32, g: f32) -> f32 {
    let one_minus_g = 1.0 - g;
    let denom = (one_minus_g * one_minus_g + 2.0 * g * (1.0 - cos_theta)).max(1e-30);
    3.0 * (1.0 - g * g) * (1.0 + cos_theta * cos_theta) / (8.0 * PI * (2.0 + g * g) * denom * denom.sqrt())
}

/// The aerosols' phase function at scattering cosine `nu`, 1/sr.
pub fn mie_phase(p: &SkyParams, nu: f32) -> f32 {
    if p.mie_phase == MIE_CORNETTE_SHANKS {
        cornette_shanks(nu, p.mie.w)
    } else {
        phase::henyey_greenstein(nu, p.mie.w)
    }
}

/// Ozone's relative density at altitude `h`: 1 at the layer's centre,
/// falling linearly to 0 at `ozone_half_width` from it.
fn ozone_density(p: &SkyParams, h: f32) -> f32 {
    if p.ozone_half_width <= 0.0 {
        return 0.0;
    }
    (1.0 - (h - p.ozone_center).abs() / p.ozone_half_width).max(0.0)
}

/// Extinction coefficient at altitude `h` (m), 1/m per channel (eq. 2's
/// integrand, `4 pi K / lambda^4 rho(h)` for the molecules, plus aerosols and ozone).
pub fn extinction(p: &SkyParams, h: f32) -> Vec3 {
    let h = h.max(0.0);
    let rayleigh = p.rayleigh.xyz() * (-h / p.rayleigh.w).exp();
    let mie = p.mie.y * (-h / p.mie.z).exp();
    rayleigh + Vec3::splat(mie) + p.ozone.xyz() * ozone_density(p, h)
}

/// Scattering coefficients at altitude `h`: Rayleigh per channel and Mie, 1/m.
pub fn scattering(p: &SkyParams, h: f32) -> (Vec3, f32) {
    let h = h.max(0.0);
    (p.rayleigh.xyz() * (-h / p.rayleigh.w).exp(), p.mie.x * (-h / p.mie.z).exp())
}

/// `r^2 - R^2` for a point at altitude `h` (`R` the ground radius), m^2,
/// without the cancellation of subtracting two squares near 4e13.
fn excess_sq(p: &SkyParams, h: f32) -> f32 {
    h * (2.0 * p.ground_radius + h)
}

/// Whether the ray from altitude `h` with zenith cosine `mu` meets the
/// ground, and at what distance (m). `mu r` against `sqrt(r^2 - R^2)` is
/// compared without forming `r^2 - R^2` from radii, so that rays that graze
/// the horizon are judged right in f32; at `h = 0` every ray with `mu < 0`
/// meets the ground at once and `mu = 0` does not.
pub fn hits_ground(p: &SkyParams, h: f32, mu: f32) -> (bool, f32) {
    if mu >= 0.0 {
        return (false, 0.0);
    }
    let r = p.ground_radius + h;
    let c = excess_sq(p, h.max(0.0));
    let disc = r * r * mu * mu - c;
    if disc < 0.0 {
        return (false, 0.0);
    }
    // The nearer root of t^2 + 2 r mu t + c = 0 as c / (far root): no cancellation.
    (true, c / (-r * mu + disc.sqrt()))
}

/// The distances along the ray from altitude `h` (zenith cosine `mu`) at
/// which it enters and leaves the atmosphere's top sphere; `enter >= leave`
/// if it never enters. From inside, `enter` is 0.
pub fn atmosphere_span(p: &SkyParams, h: f32, mu: f32) -> (f32, f32) {
    let r = p.ground_radius + h;
    let top = p.atmosphere_height;
    // r^2 - r_top^2, factored.
    let c = (h - top) * (2.0 * p.ground_radius + h + top);
    let disc = r * r * mu * mu - c;
    if disc < 0.0 {
        return (1.0, 0.0);
    }
    let far = -r * mu + disc.sqrt();
    if c <= 0.0 {
        return (0.0, far.max(0.0));
    }
    if mu >= 0.0 {
        return (1.0, 0.0);
    }
    (c / far, far)
}

/// Altitude (m) of the point at distance `t` along the ray from altitude `h`
/// with zenith cosine `mu`: `r_t - R` as `(r_t^2 - R^2) / (r_t + R)`.
pub fn altitude_along(p: &SkyParams, h: f32, mu: f32, t: f32) -> f32 {
    let r = p.ground_radius + h;
    let excess = (excess_sq(p, h) + t * (2.0 * r * mu + t)).max(0.0);
    let r_t = (p.ground_radius * p.ground_radius + excess).sqrt();
    excess / (r_t + p.ground_radius)
}

/// Node `k` of `n` of the graded quadrature over `[t0, t1]`: `t = t0 + L u^2`
/// (or `t1 - L u^2` when the dense end is `t1`) at the midpoints `u` of `n`
/// equal steps, so that samples crowd toward the end where the air is
/// densest. Returns the distance and its weight `dt`.
pub fn graded_node(t0: f32, t1: f32, dense_at_start: bool, k: u32, n: u32) -> (f32, f32) {
    let u = (k as f32 + 0.5) / n as f32;
    let len = t1 - t0;
    let weight = 2.0 * u * len / n as f32;
    if dense_at_start {
        (t0 + len * u * u, weight)
    } else {
        (t1 - len * u * u, weight)
    }
}

/// Optical depth (eq. 2) from altitude `h` along zenith cosine `mu` to the
/// top of the atmosphere, by the graded quadrature with `n` samples per
/// piece (the ray is split at its lowest point). The ray must not meet the
/// ground. Per channel, dimensionless.
pub fn optical_depth_to_top(p: &SkyParams, h: f32, mu: f32, n: u32) -> Vec3 {
    let (_, end) = atmosphere_span(p, h, mu);
    let r = p.ground_radius + h;
    let lowest = (-r * mu).clamp(0.0, end);
    let mut tau = Vec3::ZERO;
    let mut piece = 0;
    while piece < 2 {
        let (t0, t1, dense_at_start) = if piece == 0 { (0.0, lowest, false) } else { (lowest, end, true) };
        if t1 > t0 {
            let mut k = 0;
            while k < n {
                let (t, w) = graded_node(t0, t1, dense_at_start, k, n);
                tau += extinction(p, altitude_along(p, h, mu, t)) * w;
                k += 1;
            }
        }
        piece += 1;
    }
    tau
}

/// The transmittance table's coordinates (each in [0, 1]) of the ray from
/// altitude `h` with zenith cosine `mu` (Bruneton's mapping: the distance to
/// the top between its least and greatest values over the directions that
/// miss the ground, and the horizon distance `rho = sqrt(r^2 - R^2)`).
pub fn transmittance_coords(p: &SkyParams, h: f32, mu: f32) -> (f32, f32) {
    let top = p.atmosphere_height;
    let big_h = excess_sq(p, top).sqrt();
    let h = h.clamp(0.0, top);
    let rho = excess_sq(p, h).sqrt();
    let (_, d) = atmosphere_span(p, h, mu);
    let d_min = top - h;
    let d_max = rho + big_h;
    (((d - d_min) / (d_max - d_min)).clamp(0.0, 1.0), (rho / big_h).clamp(0.0, 1.0))
}

/// The ray of table coordinates `(x_mu, x_r)`: altitude (m) and zenith cosine.
pub fn transmittance_ray(p: &SkyParams, x_mu: f32, x_r: f32) -> (f32, f32) {
    let big_r = p.ground_radius;
    let top = p.atmosphere_height;
    let big_h = excess_sq(p, top).sqrt();
    let rho = big_h * x_r;
    let h = rho * rho / ((rho * rho + big_r * big_r).sqrt() + big_r);
    let r = big_r + h;
    let d_min = top - h;
    let d_max = rho + big_h;
    let d = d_min + x_mu * (d_max - d_min);
    if d <= 0.0 {
        return (h, 1.0);
    }
    // mu from r_top^2 = r^2 + 2 r mu d + d^2, with r_top^2 - r^2 factored.
    let mu = ((top - h) * (2.0 * big_r + top + h) - d * d) / (2.0 * r * d);
    (h, mu.clamp(-1.0, 1.0))
}

/// Transmittance-table kernel: the optical depth (rgb, w = 0) of texel
/// `index` (row-major, `transmittance_width` directions per row of heights).
pub fn transmittance_texel(index: u32, p: &SkyParams) -> Vec4 {
    let w = p.transmittance_width;
    let x_mu = (index % w) as f32 / (w - 1) as f32;
    let x_r = (index / w) as f32 / (p.transmittance_height - 1) as f32;
    let (h, mu) = transmittance_ray(p, x_mu, x_r);
    optical_depth_to_top(p, h, mu, p.table_samples).extend(0.0)
}

/// Bilinear lookup of a row-major table of `w x h` nodes at `(x, y)` in
/// [0, 1]^2 (nodes at both ends), rows `row0 ..` of it.
fn bilinear(table: &[Vec4], w: u32, row0: u32, rows: u32, x: f32, y: f32) -> Vec4 {
    let fx = x.clamp(0.0, 1.0) * (w - 1) as f32;
    let fy = y.clamp(0.0, 1.0) * (rows - 1) as f32;
    let x0 = (fx as u32).min(w - 2);
    let y0 = (fy as u32).min(rows.max(2) - 2);
    let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
    let i00 = ((row0 + y0) * w + x0) as usize;
    let i01 = i00 + w as usize;
    let top = table[i00] * (1.0 - tx) + table[i00 + 1] * tx;
    let bottom = table[i01] * (1.0 - tx) + table[i01 + 1] * tx;
    top * (1.0 - ty) + bottom * ty
}

/// Transmittance of the sun's light to a point at altitude `h` whose zenith
/// cosine toward the sun is `mu_s`: 0 in the Earth's shadow, else `exp(-tau)`
/// with `tau` from the table. Per channel.
pub fn sun_transmittance(p: &SkyParams, table: &[Vec4], h: f32, mu_s: f32) -> Vec3 {
    let h = h.clamp(0.0, p.atmosphere_height);
    if hits_ground(p, h, mu_s).0 {
        return Vec3::ZERO;
    }
    let (x_mu, x_r) = transmittance_coords(p, h, mu_s);
    let tau = bilinear(table, p.transmittance_width, 0, p.transmittance_height, x_mu, x_r);
    (-tau.xyz()).exp()
}

/// Transmittance from the observer to space along zenith cosine `mu` (the
/// sun's disk seen through the air): 0 if the ray meets the ground, 1 if it
/// misses the atmosphere, else from the table at the observer (or where the
/// ray enters the atmosphere from above).
pub fn transmittance_to_space(p: &SkyParams, table: &[Vec4], mu: f32) -> Vec3 {
    let h = p.observer_altitude;
    if hits_ground(p, h, mu).0 {
        return Vec3::ZERO;
    }
    if h <= p.atmosphere_height {
        return sun_transmittance(p, table, h, mu);
    }
    let (enter, leave) = atmosphere_span(p, h, mu);
    if enter >= leave {
        return Vec3::ONE;
    }
    let r = p.ground_radius + h;
    let r_top = p.ground_radius + p.atmosphere_height;
    sun_transmittance(p, table, p.atmosphere_height, ((r * mu + enter) / r_top).clamp(-1.0, 1.0))
}

/// The part of the ray (from altitude `h`, zenith cosine `mu`) inside the
/// Earth's shadow, whose points see the sun (direction with zenith cosine
/// `mu_s` at the observer, cosine `nu` to the ray) behind the ground: the
/// cylinder of radius `R` along the sun's direction, on the far side of the
/// planet. Empty when `lo >= hi`.
pub fn earth_shadow(p: &SkyParams, h: f32, mu: f32, mu_s: f32, nu: f32) -> (f32, f32) {
    let r = p.ground_radius + h;
    // Distance from the sun's axis through the centre, squared, along the
    // ray: a t^2 + 2 b t + c with c = r^2 (1 - mu_s^2) - R^2, factored.
    let a = 1.0 - nu * nu;
    let b = r * (mu - mu_s * nu);
    let c = excess_sq(p, h) - r * r * mu_s * mu_s;
    let (mut lo, mut hi) = if a < 1e-7 {
        if c < 0.0 {
            (-f32::MAX, f32::MAX)
        } else {
            (1.0, 0.0)
        }
    } else {
        let disc = b * b - a * c;
        if disc < 0.0 {
            return (1.0, 0.0);
        }
        let s = disc.sqrt();
        // Roots as (-b -+ s) / a, the one of cancelling signs as c / (-b +- s).
        let q = if b > 0.0 { -b - s } else { -b + s };
        let (r0, r1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
        (r0.min(r1), r0.max(r1))
    };
    // Behind the planet: (centre-relative point) . sun < 0, i.e. r mu_s + t nu < 0.
    if nu > 0.0 {
        hi = hi.min(-r * mu_s / nu);
    } else if nu < 0.0 {
        lo = lo.max(-r * mu_s / nu);
    } else if mu_s >= 0.0 {
        return (1.0, 0.0);
    }
    (lo, hi)
}

/// Three numbers in increasing order.
fn sort3(a: f32, b: f32, c: f32) -> (f32, f32, f32) {
    let (lo, hi) = (a.min(b), a.max(b));
    let (mid, hi) = (hi.min(c), hi.max(c));
    (lo.min(mid), lo.max(mid), hi)
}

/// Single-scattered radiance along the view ray from the observer with
/// zenith cosine `mu`, to a sun with zenith cosine `mu_s` at cosine `nu`
/// from the ray (eq. 1 in standard form, see the module docs), plus the
/// ground's reflection of the direct sun where the ray meets it (Lambertian,
/// `albedo / pi`), W/(m^2 sr) per channel; and the ray's transmittance.
///
/// The ray inside the atmosphere is split at its lowest point and where it
/// enters and leaves the Earth's shadow; each piece gets `view_samples /
/// pieces` graded samples (dense at its low end). The optical depth to each
/// sample accumulates along the ray (the shadowed pieces count for it too);
/// the in-scattering counts on the lit pieces only.
pub fn inscatter(p: &SkyParams, table: &[Vec4], mu: f32, mu_s: f32, nu: f32) -> (Vec3, Vec3) {
    let h = p.observer_altitude;
    let r = p.ground_radius + h;
    let (enter, mut leave) = atmosphere_span(p, h, mu);
    if enter >= leave {
        return (Vec3::ZERO, Vec3::ONE);
    }
    let (ground, t_ground) = hits_ground(p, h, mu);
    if ground {
        leave = leave.min(t_ground);
    }
    let (shadow_lo, shadow_hi) = earth_shadow(p, h, mu, mu_s, nu);
    let (c0, c1, c2) = sort3(
        (-r * mu).clamp(enter, leave),
        shadow_lo.clamp(enter, leave),
        shadow_hi.max(shadow_lo).clamp(enter, leave),
    );
    let bounds = [enter, c0, c1, c2, leave];
    let mut pieces = 0;
    let mut i = 0;
    while i < 4 {
        if bounds[i + 1] > bounds[i] {
            pieces += 1;
        }
        i += 1;
    }
    let n = p.view_samples.div_ceil(pieces.max(1)).max(1);
    let phase_r = phase::rayleigh(nu);
    let phase_m = mie_phase(p, nu);
    let lowest = -r * mu;
    let mut tau = Vec3::ZERO;
    let mut sum = Vec3::ZERO;
    i = 0;
    while i < 4 {
        let (t0, t1) = (bounds[i], bounds[i + 1]);
        if t1 > t0 {
            let mid = 0.5 * (t0 + t1);
            let lit = !(mid > shadow_lo && mid < shadow_hi);
            let dense_at_start = mid >= lowest;
            let mut k = 0;
            while k < n {
                let kk = if dense_at_start { k } else { n - 1 - k };
                let (t, w) = graded_node(t0, t1, dense_at_start, kk, n);
                let h_t = altitude_along(p, h, mu, t);
                let sigma = extinction(p, h_t);
                if lit {
                    let view = (-(tau + sigma * (0.5 * w))).exp();
                    sum += scattered_sunlight(p, table, r, mu_s, nu, t, h_t, phase_r, phase_m) * view * w;
                }
                tau += sigma * w;
                k += 1;
            }
        }
        i += 1;
    }
    let transmittance = (-tau).exp();
    let mut radiance = sum * p.sun_irradiance.xyz();
    if ground {
        // The ground point's zenith cosine toward the sun.
        let mu_s_g = ((r * mu_s + t_ground * nu) / p.ground_radius).clamp(-1.0, 1.0);
        if mu_s_g > 0.0 {
            let sun = sun_transmittance(p, table, 0.0, mu_s_g);
            radiance += p.ground_albedo.xyz() * FRAC_1_PI * p.sun_irradiance.xyz() * sun * (mu_s_g * transmittance);
        }
    }
    (radiance, transmittance)
}

/// The sunlight scattered toward the eye per metre at distance `t` along
/// a view ray from radius `r` (altitude `h_t` there), per unit solar
/// irradiance, before the view's transmittance:
/// `(beta_R P_R + beta_M P_M) T_sun`, the integrand of eq. 1 that
/// `inscatter` (to the top of the atmosphere) and the aerial perspective
/// (to a surface) share.
#[allow(clippy::too_many_arguments)]
pub fn scattered_sunlight(
    p: &SkyParams,
    table: &[Vec4],
    r: f32,
    mu_s: f32,
    nu: f32,
    t: f32,
    h_t: f32,
    phase_r: f32,
    phase_m: f32,
) -> Vec3 {
    let r_t = p.ground_radius + h_t;
    let mu_s_t = ((r * mu_s + t * nu) / r_t).clamp(-1.0, 1.0);
    let sun = sun_transmittance(p, table, h_t, mu_s_t);
    let (beta_r, beta_m) = scattering(p, h_t);
    (beta_r * phase_r + Vec3::splat(beta_m * phase_m)) * sun
}

/// The sun's disk along unit view direction `dir`: the sun's radiance
/// `E_sun / Omega_sun` (a uniform disk) seen through the air, 0 outside the
/// disk or where the ground hides it.
pub fn sun_disk(p: &SkyParams, table: &[Vec4], dir: Vec3) -> Vec3 {
    if dir.dot(p.sun_direction.xyz()) < p.sun_direction.w {
        return Vec3::ZERO;
    }
    p.sun_irradiance.xyz() / p.sun_irradiance.w * transmittance_to_space(p, table, dir.y)
}

/// The elevation (radians) of the observer's horizon: rays below it meet the ground.
pub fn horizon_elevation(p: &SkyParams) -> f32 {
    let h = p.observer_altitude;
    -(excess_sq(p, h).sqrt() / (p.ground_radius + h)).clamp(0.0, 1.0).asin()
}

/// Rays this close to the horizon (radians) are taken on its side that the
/// table row stands for, so that no row straddles the ground's edge.
const HORIZON_GAP: f32 = 1e-5;

/// The view direction of sky-view texel `index`: (zenith cosine, cosine to
/// the sun). Columns run over the azimuth from the sun's (0) to its
/// opposite (pi); the upper half of the rows over elevations from the
/// horizon up to the zenith, the lower half from the horizon down to the
/// nadir, each `x^2`-graded so that rows crowd toward the horizon.
pub fn sky_view_direction(p: &SkyParams, index: u32) -> (f32, f32) {
    let w = p.sky_view_width;
    let half = p.sky_view_height / 2;
    let (col, row) = (index % w, index / w);
    let azimuth = PI * col as f32 / (w - 1) as f32;
    let horizon = p.horizon;
    let elevation = if row >= half {
        let x = (row - half) as f32 / (half - 1) as f32;
        horizon + HORIZON_GAP + (FRAC_PI_2 - horizon - HORIZON_GAP) * x * x
    } else {
        let x = (half - 1 - row) as f32 / (half - 1) as f32;
        horizon - HORIZON_GAP - (FRAC_PI_2 + horizon - HORIZON_GAP) * x * x
    };
    let mu_s = p.sun_direction.y;
    let sun_horizontal = (1.0 - mu_s * mu_s).max(0.0).sqrt();
    let (mu, cos_el) = (elevation.sin(), elevation.cos());
    (mu, cos_el * azimuth.cos() * sun_horizontal + mu * mu_s)
}

/// Sky-view table kernel: in-scattered plus ground radiance (rgb; no sun
/// disk) of texel `index`.
pub fn sky_view_texel(index: u32, p: &SkyParams, table: &[Vec4]) -> Vec4 {
    let (mu, nu) = sky_view_direction(p, index);
    inscatter(p, table, mu, p.sun_direction.y, nu).0.extend(0.0)
}

/// Looks the sky's radiance along unit `dir` up in the sky-view table,
/// interpolating only within the half (sky or ground) that the ray is in.
pub fn sky_view_lookup(p: &SkyParams, sky_view: &[Vec4], dir: Vec3) -> Vec3 {
    let sun = p.sun_direction.xyz();
    let lengths_sq = (dir.x * dir.x + dir.z * dir.z) * (sun.x * sun.x + sun.z * sun.z);
    let cos_azimuth =
        if lengths_sq > 1e-24 { ((dir.x * sun.x + dir.z * sun.z) / lengths_sq.sqrt()).clamp(-1.0, 1.0) } else { 1.0 };
    let x = cos_azimuth.acos() / PI;
    let mu = dir.y.clamp(-1.0, 1.0);
    let elevation = mu.asin();
    let horizon = p.horizon;
    let half = p.sky_view_height / 2;
    let w = p.sky_view_width;
    let value = if hits_ground(p, p.observer_altitude, mu).0 {
        let y = ((horizon - HORIZON_GAP - elevation) / (FRAC_PI_2 + horizon - HORIZON_GAP)).max(0.0).sqrt();
        bilinear(sky_view, w, 0, half, x, 1.0 - y)
    } else {
        let y = ((elevation - horizon - HORIZON_GAP) / (FRAC_PI_2 - horizon - HORIZON_GAP)).max(0.0).sqrt();
        bilinear(sky_view, w, half, half, x, y)
    };
    value.xyz()
}

/// `SkyParams::sea`: no sea; a sea below the eye; the eye under the water.
pub const SEA_NONE: u32 = 0;
pub const SEA_BELOW: u32 = 1;
pub const SEA_AROUND: u32 = 2;

/// Per-pixel sky kernel: the sky's radiance (rgb, W/(m^2 sr); w = 0) at
/// pixel `index`'s current sub-pixel sample, where the view ray meets no
/// scene surface (`texel` is the pixel's G-buffer texel): the in-scattered
/// light and the ground (from the sky-view table or integrated per pixel)
/// plus the sun's disk.
pub fn sky_pixel(
    index: u32,
    common: &CommonParams,
    p: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    texel: &GBufferTexel,
) -> Vec4 {
    let x = index % common.width;
    let y = index / common.width;
    if texel.object != NO_OBJECT || !in_image(common, x, y) {
        return Vec4::ZERO;
    }
    let (_, dir) = camera_ray(common, x, y);
    if p.sea == SEA_AROUND || (p.sea == SEA_BELOW && dir.y < 0.0) {
        return Vec4::ZERO;
    }
    (sky_radiance(p, transmittance, sky_view, dir) + sun_disk(p, transmittance, dir)).extend(0.0)
}

/// The sky's radiance along unit `dir` without the sun's disk: from the
/// sky-view table, or integrated (`use_sky_view` 0).
pub fn sky_radiance(p: &SkyParams, transmittance: &[Vec4], sky_view: &[Vec4], dir: Vec3) -> Vec3 {
    if p.use_sky_view != 0 {
        sky_view_lookup(p, sky_view, dir)
    } else {
        inscatter(p, transmittance, dir.y, p.sun_direction.y, dir.dot(p.sun_direction.xyz())).0
    }
}

#[spirv(compute(threads(64)))]
pub fn transmittance_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] table: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < p.transmittance_width * p.transmittance_height {
        table[index as usize] = transmittance_texel(index, p);
    }
}

#[spirv(compute(threads(64)))]
pub fn sky_view_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] sky_view: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < p.sky_view_width * p.sky_view_height {
        sky_view[index as usize] = sky_view_texel(index, p, transmittance);
    }
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn sky_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] sky_view: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 18)] radiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        radiance[index as usize] =
            sky_pixel(common.band_start + index, common, &params[0], transmittance, sky_view, &gbuffer[index as usize]);
    }
}

/// The sky's radiance toward the irradiance quadrature's directions
/// (`light::sphere_texel`).
#[spirv(compute(threads(64)))]
pub fn sphere_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] sky_view: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 87)] sphere: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    if index < light::SPHERE_DIRECTIONS {
        sphere[index as usize] = light::sphere_texel(index, &params[0], transmittance, sky_view);
    }
}

/// The skylight's irradiance table over normals (`light::irradiance_texel`).
#[spirv(compute(threads(64)))]
pub fn irradiance_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 87)] sphere: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 62)] irradiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    if index < light::IRRADIANCE_WIDTH * light::IRRADIANCE_HEIGHT {
        irradiance[index as usize] = light::irradiance_texel(index, &params[0], sphere);
    }
}

/// The per-pixel skylight (`light::sky_light_pixel`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn sky_light_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[crate::types::GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[crate::types::GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[crate::types::GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[crate::types::GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] sky_view: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 62)] irradiance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 86)] visibility: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 63)] radiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let geometry = crate::scene_geometry(common, spheres, triangles, nodes);
        let sky = light::SkyTables { p: &params[0], transmittance, sky_view, irradiance };
        radiance[index as usize] =
            light::sky_light_pixel(common.band_start + index, common, &sky, &geometry, materials, gbuffer, visibility);
    }
}

/// The skylight's visibility at the pixels that trace it
/// (`light::visibility_pixel`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn sky_visibility_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[crate::types::GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[crate::types::GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[crate::types::GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[crate::types::GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] sky_view: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 86)] visibility: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let geometry = crate::scene_geometry(common, spheres, triangles, nodes);
        visibility[index as usize] = light::visibility_pixel(
            common.band_start + index,
            common,
            &params[0],
            transmittance,
            sky_view,
            &geometry,
            materials,
            &gbuffer[index as usize],
        );
    }
}

/// The per-pixel aerial perspective (`aerial::aerial_pixel`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn aerial_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] params: &[SkyParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] transmittance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 64)] radiance: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 65)] through: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let (l, t) = aerial::aerial_pixel(
            common.band_start + index,
            common,
            &params[0],
            transmittance,
            &gbuffer[index as usize],
        );
        radiance[index as usize] = l;
        through[index as usize] = t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Earth's atmosphere with Rayleigh scattering only (the defaults).
    fn rayleigh_only() -> SkyParams {
        with_horizon(SkyParams {
            sun_direction: Vec4::new(0.0, 1.0, 0.0, 0.2666f32.to_radians().cos()),
            sun_irradiance: Vec4::new(1.0, 1.0, 1.0, 2.0 * PI * (1.0 - 0.2666f32.to_radians().cos())),
            rayleigh: Vec4::new(5.802e-6, 13.558e-6, 33.1e-6, 8000.0),
            mie: Vec4::new(0.0, 0.0, 1200.0, 0.8),
            ground_radius: 6_360_000.0,
            atmosphere_height: 60_000.0,
            view_samples: 64,
            table_samples: 64,
            transmittance_width: 256,
            transmittance_height: 64,
            sky_view_width: 64,
            sky_view_height: 64,
            ..Default::default()
        })
    }

    fn with_horizon(p: SkyParams) -> SkyParams {
        SkyParams { horizon: horizon_elevation(&p), ..p }
    }

    fn with_aerosols_and_ozone() -> SkyParams {
        SkyParams {
            mie: Vec4::new(3.996e-6, 4.4e-6, 1200.0, 0.8),
            ozone: Vec4::new(0.650e-6, 1.881e-6, 0.085e-6, 0.0),
            ozone_center: 25_000.0,
            ozone_half_width: 15_000.0,
            ..rayleigh_only()
        }
    }

    fn table(p: &SkyParams) -> Vec<Vec4> {
        (0..p.transmittance_width * p.transmittance_height).map(|i| transmittance_texel(i, p)).collect()
    }

    /// `int_0^top beta exp(-h / H) dh` in f64.
    fn zenith_depth(beta: f32, scale: f32, top: f32) -> f64 {
        beta as f64 * scale as f64 * (1.0 - (-(top as f64) / scale as f64).exp())
    }

    #[test]
    fn zenith_optical_depth_matches_the_closed_form() {
        let p = rayleigh_only();
        let tau = optical_depth_to_top(&p, 0.0, 1.0, p.table_samples);
        for (c, beta) in p.rayleigh.xyz().to_array().into_iter().enumerate() {
            let exact = zenith_depth(beta, 8000.0, 60_000.0);
            // The graded midpoint rule's error is O(1/n^2) on a smooth
            // integrand; 64 samples leave about 1e-4 (f32 sums add ~1e-6).
            let rel = (tau[c] as f64 - exact).abs() / exact;
            assert!(rel < 2e-4, "channel {c}: {} vs {exact} ({rel:e})", tau[c]);
        }
        // The table holds the same depth at its zenith texel of height 0.
        let t = table(&p);
        let looked_up = sun_transmittance(&p, &t, 0.0, 1.0);
        let exact = (-zenith_depth(p.rayleigh.z, 8000.0, 60_000.0)).exp();
        assert!((looked_up.z as f64 - exact).abs() < 1e-4 * exact, "{looked_up} vs {exact}");
    }

    /// Looking at the zenith with the sun there, every sample sees the sun
    /// straight above it, so `T_sun T_view` is the whole column's
    /// transmittance and the integral is closed: `E P(1) tau_s exp(-tau)`.
    #[test]
    fn zenith_sky_under_a_zenith_sun_matches_the_closed_form() {
        for p in [rayleigh_only(), with_aerosols_and_ozone()] {
            let t = table(&p);
            let (radiance, transmittance) = inscatter(&p, &t, 1.0, 1.0, 1.0);
            let mut total = [0.0f64; 3];
            let ozone_column = p.ozone_half_width as f64; // the tent's integral
            for c in 0..3 {
                let rayleigh = zenith_depth(p.rayleigh[c], 8000.0, 60_000.0);
                let mie_s = zenith_depth(p.mie.x, 1200.0, 60_000.0);
                let mie_t = zenith_depth(p.mie.y, 1200.0, 60_000.0);
                let tau = rayleigh + mie_t + p.ozone[c] as f64 * ozone_column;
                total[c] = tau;
                let exact =
                    ((phase::rayleigh(1.0) as f64) * rayleigh + mie_phase(&p, 1.0) as f64 * mie_s) * (-tau).exp();
                // Quadrature of the view ray (64 graded samples) and the
                // table's interpolation: 1e-3 relative.
                let rel = (radiance[c] as f64 - exact).abs() / exact;
                assert!(rel < 1e-3, "channel {c}: {} vs {exact} ({rel:e})", radiance[c]);
                let rel_t = (transmittance[c] as f64 - (-tau).exp()).abs() / (-tau).exp();
                assert!(rel_t < 1e-3, "channel {c} transmittance ({rel_t:e})");
            }
            assert!(total[2] > total[0]);
        }
    }

    #[test]
    fn grazing_rays_are_judged_on_the_right_side_of_the_horizon() {
        let p = rayleigh_only();
        // At the ground, level rays miss it and any downward ray meets it at once.
        assert!(!hits_ground(&p, 0.0, 0.0).0);
        assert_eq!(hits_ground(&p, 0.0, -1e-7), (true, 0.0));
        // From 10 km, just above and below the horizon.
        for h in [10.0f32, 10_000.0, 100_000.0] {
            let horizon = horizon_elevation(&p);
            let p = SkyParams { observer_altitude: h, ..p };
            let horizon_h = horizon_elevation(&p);
            assert!(horizon_h < horizon || h < 1.0);
            let above = (horizon_h + 2e-4).sin();
            let below = (horizon_h - 2e-4).sin();
            assert!(!hits_ground(&p, h, above).0, "{h}: above");
            let (hit, t) = hits_ground(&p, h, below);
            assert!(hit && t > 0.0 && t.is_finite(), "{h}: below {t}");
        }
    }

    #[test]
    fn table_coordinates_invert() {
        let p = with_aerosols_and_ozone();
        for h in [0.0f32, 100.0, 3000.0, 30_000.0, 59_000.0] {
            let horizon = -(excess_sq(&p, h).sqrt() / (p.ground_radius + h));
            for k in 0..=20 {
                let mu = horizon + (1.0 - horizon) * k as f32 / 20.0;
                let (x_mu, x_r) = transmittance_coords(&p, h, mu);
                let (h2, mu2) = transmittance_ray(&p, x_mu, x_r);
                assert!((h2 - h).abs() < 0.05 + 1e-5 * h, "{h} {mu}: {h2}");
                assert!((mu2 - mu).abs() < 2e-3, "{h} {mu}: {mu2}");
            }
        }
    }

    /// Points the shadow interval covers see the sun behind the ground;
    /// points outside it do not.
    #[test]
    fn earth_shadow_interval_is_where_the_sun_is_below_the_horizon() {
        let p = rayleigh_only();
        for sun_deg in [-10.0f32, -6.0, -2.0, -0.01, 3.0] {
            let s = sun_deg.to_radians();
            let sun = Vec3::new(s.cos(), s.sin(), 0.0);
            for h in [0.0f32, 2000.0] {
                let p = SkyParams { observer_altitude: h, ..p };
                for az in 0..12 {
                    for el in [-2.0f32, 0.0, 1.0, 5.0, 30.0, 89.0] {
                        let (a, e) = ((az as f32 * 30.0).to_radians(), el.to_radians());
                        let d = Vec3::new(e.cos() * a.cos(), e.sin(), e.cos() * a.sin());
                        let (lo, hi) = earth_shadow(&p, h, d.y, sun.y, d.dot(sun));
                        let (_, end) = atmosphere_span(&p, h, d.y);
                        let (ground, tg) = hits_ground(&p, h, d.y);
                        let end = if ground { tg } else { end };
                        let r = p.ground_radius + h;
                        let mut misjudged = 0;
                        for k in 0..200 {
                            let t = end * (k as f32 + 0.5) / 200.0;
                            let h_t = altitude_along(&p, h, d.y, t);
                            let mu_s = (r * sun.y + t * d.dot(sun)) / (p.ground_radius + h_t);
                            let dark = hits_ground(&p, h_t, mu_s).0;
                            let inside = t > lo && t < hi;
                            // Within 50 m of a boundary f32 may disagree.
                            let near_edge = (t - lo).abs() < 50.0 || (t - hi).abs() < 50.0;
                            if dark != inside && !near_edge {
                                misjudged += 1;
                            }
                        }
                        assert_eq!(misjudged, 0, "sun {sun_deg}, h {h}, az {az}, el {el}: [{lo}, {hi}] of {end}");
                    }
                }
            }
        }
    }

    /// Stress: the sun from the zenith to 10 degrees below the horizon, views
    /// at and just below the horizon, the observer at 0 m, 10 km and 100 km,
    /// Rayleigh scattering times 0 and times 100: no NaN, no Inf, nothing negative.
    #[test]
    fn radiance_is_finite_and_non_negative_at_the_edges() {
        for scale in [0.0f32, 1.0, 100.0] {
            for h in [0.0f32, 10_000.0, 100_000.0] {
                let base = with_aerosols_and_ozone();
                let p = with_horizon(SkyParams {
                    rayleigh: (base.rayleigh.xyz() * scale).extend(8000.0),
                    observer_altitude: h,
                    ground_albedo: Vec4::splat(0.3),
                    ..base
                });
                let t = table(&p);
                assert!(t.iter().all(|v| v.is_finite() && v.cmpge(Vec4::ZERO).all()));
                let horizon = horizon_elevation(&p);
                for sun_deg in [90.0f32, 45.0, 0.0, -0.01, -6.0, -10.0] {
                    let s = sun_deg.to_radians();
                    let sun = Vec3::new(s.cos(), s.sin(), 0.0);
                    let p = SkyParams { sun_direction: sun.extend(p.sun_direction.w), ..p };
                    let views = [90.0f32, 10.0, 0.0, -0.001, -5.0, -90.0].map(|d| d.to_radians()).into_iter().chain([
                        horizon,
                        horizon + 1e-6,
                        horizon - 1e-6,
                    ]);
                    for e in views {
                        for a in [0.0f32, 1.0, PI] {
                            let d = Vec3::new(e.cos() * a.cos(), e.sin(), e.cos() * a.sin());
                            let (l, tr) = inscatter(&p, &t, d.y, sun.y, d.dot(sun));
                            let disk = sun_disk(&p, &t, d);
                            for v in [l, tr, disk] {
                                assert!(
                                    v.is_finite() && v.cmpge(Vec3::ZERO).all(),
                                    "{scale} {h} {sun_deg} {e} {a}: {v}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}
