//! Sea colour: light reflected at the surface, single and second-order
//! scattering in the water, and the bottom's reflection, after Iwasaki,
//! Dobashi and Nishita (`../shared/papers/004_*`, eq. 1-9).
//!
//! Radiometry is the standard one, and differs from the paper's printed
//! equations in three stated ways:
//! - the sun's irradiance `E` (W/m^2) is normal to its rays; the refracted
//!   beam in the water carries `E_w = T_i E cos(theta_ii) / cos(theta_io)`
//!   normal to itself (the horizontal irradiance `E cos(theta_ii)`, times the
//!   Fresnel transmittance, spread over the refracted beam's cross-section).
//!   Eq. 5 and 7 write `L_sun T` for `E_w cos(theta_io)`;
//! - radiance leaving the water is `T_o L_w / n^2` (the `n^2` law); the
//!   paper's eq. 5 and 9 have no `1/n^2`;
//! - the bottom is Lambertian with BRDF `albedo / pi` (eq. 9 prints `K_d cos`
//!   without the `1/pi`).
//!
//! Inside the water the surface is flat for the sun (the paper's
//! assumption, section 3), and depths are measured down from it. With `c`
//! the extinction, `b` the scattering coefficient (1/m) and `p` the
//! Henyey-Greenstein phase function (1/sr), `beta = b p` (eq. 2):
//! - order 1 toward the surface along an upward direction with cosine `mu_v`
//!   over a bottom at depth `d` (eq. 5 with `c`, in closed form):
//!   `L1 = beta(a) E_w (d / mu_v) phi(c d (1/mu_s + 1/mu_v))`, `phi(x) = (1 - e^-x)/x`;
//!   eq. 5 as printed puts `c (1 - omega_0 c_f)` in place of `c` (`order1_extinction`);
//! - order 2 (eq. 6-8): horizontal sampling planes; at each, the order-1
//!   radiance arriving from every direction (eq. 7, `order1_path`) times the
//!   volume scattering function, summed over `n_d` directions, is the
//!   scattering map (`scattering_map_texel`); the per-pixel kernel
//!   accumulates the maps over the planes with the attenuation to the
//!   surface (`order2_pixel`).
//!
//! Deviations from the paper's discretisation, for accuracy at a given
//! cost, measured by the bench:
//! - the `n_d` directions are three sets of `n_d / 3`: one distributed like
//!   the phase function around the refracted sun (where the order-1 radiance
//!   peaks), one around the view direction (where the volume scattering
//!   function peaks) and one uniform, its cells split at the horizontal
//!   (where the order-1 radiance near the surface jumps), combined with the
//!   power heuristic (the uniform set alone at the horizontal);
//! - the planes are placed per channel (a scattering map is rgb) down to the
//!   bottom or to `DEEP_OPTICAL_DEPTH`, graded toward the surface (and the
//!   bottom), and the source between planes is taken as a line times the
//!   known exponential attenuation, integrated exactly.
//!
//! Over a varying bottom the maps are built for `layers` flat bottoms and
//! read at the depth under each pixel's view ray; `table.rs` corrects
//! that with the paper's depth table (5.4).
//!
//! A scattering map texel stands for a direction toward the eye rather than
//! a point on the plane: in a flat, uniform, horizontally infinite sea the
//! order-2 radiance at a depth depends on the point only through that
//! direction, so one map serves every camera.

pub mod air;
pub mod caustics;
pub mod glass;
pub mod surface;
pub mod table;
pub mod under;

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::camera::{camera_ray, in_image, sample_offset};
use crate::geometry::{trace_nearest, Geometry, Hit, NO_HIT};
use crate::glam::{UVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::optics::{reflectance, refract};
use crate::phase::henyey_greenstein;
use crate::sky::{sky_radiance, sun_disk, SkyParams};
use crate::types::{CommonParams, GBufferTexel, GpuLight, GpuMaterial, NO_OBJECT};
use crate::volumes::{light_transmittance, LightGrid};
use core::f32::consts::{FRAC_1_PI, FRAC_PI_2, PI};
use spirv_std::spirv;

/// The sea passes' parameter block.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct SeaParams {
    /// Unit direction toward the sun (y up); w: `cos(theta_ii)`.
    pub sun_direction: Vec4,
    /// Direction of travel of the refracted sunlight in the water (unit,
    /// downward); w: `mu_s = cos(theta_io)`.
    pub sun_in_water: Vec4,
    /// Irradiance normal to the refracted beam just below the surface,
    /// `E_w`, W/m^2 per channel; w: the Fresnel transmittance `T_i`.
    pub beam_irradiance: Vec4,
    /// Scattering coefficient `b`, 1/m per channel; w: Henyey-Greenstein `g`.
    pub scattering: Vec4,
    /// Extinction `c = a + b`, 1/m per channel; w: the index of refraction `n`.
    pub extinction: Vec4,
    /// The extinction order 1 uses: `c` (exact) or eq. 5's `c (1 - omega_0 c_f)`.
    pub order1_extinction: Vec4,
    /// Lambertian albedo of the bottom.
    pub bottom_albedo: Vec4,
    /// Depth of the lowest sampling plane per channel, m.
    pub plane_depth: Vec4,
    /// A varying bottom's depth grid: x, z of its first sample's position
    /// (m), the spacing (m), and w: the deepest depth (m), met beyond it.
    pub bottom_grid: Vec4,
    /// The slope covariance `(xx, zz, xz)` of the waves shorter than the
    /// normal map's texels (`surface`): added under every footprint.
    pub roughness: Vec4,
    /// Height of the surface (scene y), m.
    pub level: f32,
    /// Depth of the flat bottom below the surface, m (`DEEP` for no bottom).
    pub depth: f32,
    /// Sampling planes `n_z` (at least 2).
    pub planes: u32,
    /// Directions per set: `polar` x `azimuths` (`n_d` = twice their product).
    pub polar: u32,
    pub azimuths: u32,
    /// Scattering maps: `map_width` azimuths (0..pi from the sun's) by
    /// `map_height` zenith angles (0..pi/2) of the direction toward the eye.
    pub map_width: u32,
    pub map_height: u32,
    /// `WAVES_FLAT` or `WAVES_NORMAL_MAP`.
    pub waves: u32,
    /// Normal map: `wave_resolution`^2 texels over `wave_size` m, tiled.
    pub wave_resolution: u32,
    pub wave_size: f32,
    /// A varying bottom: `bottom_nx x bottom_nz` depth samples (0: a flat
    /// bottom at `depth`).
    pub bottom_nx: u32,
    pub bottom_nz: u32,
    /// Bottom depths the order-2 maps are built for (1 for a flat bottom),
    /// geometric from `shallow` to `bottom_grid.w`.
    pub layers: u32,
    pub shallow: f32,
    /// Over a varying bottom, section 5.4's depth table and the order-2
    /// correction it feeds (`sea_table`): `table_width x table_height`
    /// samples across the image (0: none, the water under each pixel taken
    /// as flat).
    pub table_width: u32,
    pub table_height: u32,
    /// The sun's light (its index in the lights, plus one) when clouds
    /// shade the sea through its transmittance volume (`CloudShadow`); 0:
    /// no volumes.
    pub sun_light: u32,
    /// 1: the wave slopes are filtered over each sample's footprint
    /// (`surface::footprint`); 0: read at the sample's point.
    pub wave_filter: u32,
    /// The eye's depth below the level, m, when it is under water
    /// (`underwater` 1: `under`); 0 above.
    pub camera_depth: f32,
    pub underwater: u32,
    /// 1: the waves' caustic map is built for the flat bottom (`caustics`).
    pub caustics: u32,
    /// Caustic light shafts (`caustics`, `under::order1_shafts`): the
    /// waves' caustic on `shaft_planes` horizontal planes from the surface
    /// down to `shaft_depth` (m), on the wave pyramid's level
    /// `shaft_level` (maps of `wave_resolution >> shaft_level` texels a
    /// side); 0 planes: none.
    pub shaft_planes: u32,
    pub shaft_depth: f32,
    pub shaft_level: u32,
    /// Intervals of `under::order1_shafts` along each view ray.
    pub shaft_steps: u32,
    /// 1 when second-order scattering is on (the accumulated map is
    /// built): `glass::sea_along` reads order 2 only then.
    pub second_order: u32,
    /// `under::order1_shafts` is gathered every `shaft_stride` pixels each
    /// way (`sea.shaft_samples`) and interpolated between (1: every pixel).
    pub shaft_stride: u32,
    pub pad3: u32,
}

#[cfg(not(target_arch = "spirv"))]
// SAFETY: `repr(C)`, ten `Vec4`s and twenty-eight 4-byte scalars (272
// bytes, a multiple of the `Vec4`s' 16-byte alignment: no padding, which
// `bytes_of` would read uninitialised; the assertion below holds it); any
// bits are valid.
unsafe impl bytemuck::Zeroable for SeaParams {}
#[cfg(not(target_arch = "spirv"))]
unsafe impl bytemuck::Pod for SeaParams {}
#[cfg(not(target_arch = "spirv"))]
const _: () = assert!(core::mem::size_of::<SeaParams>() == 160 + 28 * 4);

pub const WAVES_FLAT: u32 = 0;
pub const WAVES_NORMAL_MAP: u32 = 1;

/// A depth standing for "no bottom", m: every attenuation over it is 0 in f32.
pub const DEEP: f32 = 1e20;

/// Optical depth of the lowest sampling plane in deep water: the order-2
/// integrand has fallen by at least `e^-12` there (it decays at least as
/// `e^-tau (1/mu_s + 1/mu_v)`); the rest is extrapolated.
pub const DEEP_OPTICAL_DEPTH: f32 = 6.0;

pub use crate::light::phi;

fn phi3(v: Vec3) -> Vec3 {
    Vec3::new(phi(v.x), phi(v.y), phi(v.z))
}

/// The forward scattering fraction of Henyey-Greenstein with parameter `g`:
/// the phase function's integral over the forward hemisphere (the paper's
/// `c_f`, section 5.1, taken as a fraction: with `beta`'s `b` in it,
/// `omega_0 c_f` would not be dimensionless).
pub fn forward_fraction(g: f32) -> f32 {
    if g.abs() < 1e-3 {
        // (1 + g)/(2g) - (1 - g^2)/(2g sqrt(1 + g^2)) to second order.
        return 0.5 + 0.75 * g;
    }
    (1.0 + g) / (2.0 * g) - (1.0 - g * g) / (2.0 * g * (1.0 + g * g).sqrt())
}

/// The cosine to the axis of a Henyey-Greenstein-distributed direction at
/// cumulative probability `xi` in [0, 1] (from -1 at 0 to 1 at 1).
pub fn hg_inverse_cdf(xi: f32, g: f32) -> f32 {
    if g.abs() < 1e-3 {
        return 2.0 * xi - 1.0;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

/// Two unit vectors completing unit `n` to an orthonormal basis (Duff et
/// al. 2017, continuous except across `n.z = 0`'s sign).
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vec3::new(b, sign + n.y * n.y * a, -n.y))
}

/// Direction `j` of a set of `polar x azimuths` directions distributed like
/// the phase function around `axis`: midpoints in the cumulative
/// probability and in the azimuth, so that each carries `1/(polar azimuths)`
/// of the phase function's weight.
pub fn set_direction(axis: Vec3, j: u32, polar: u32, azimuths: u32, g: f32) -> Vec3 {
    let cos_t = hg_inverse_cdf(((j / azimuths) as f32 + 0.5) / polar as f32, g);
    around(axis, cos_t, j % azimuths, azimuths)
}

/// Direction `j` of the uniform set: as `set_direction` with `g = 0` about
/// the vertical (written apart so that no constant `g = 0` reaches
/// `hg_inverse_cdf`'s division by `2g`, which the SPIR-V optimiser folds
/// into a NaN literal the Vulkan front end rejects).
pub fn uniform_direction(j: u32, polar: u32, azimuths: u32) -> Vec3 {
    let cos_t = 2.0 * (((j / azimuths) as f32 + 0.5) / polar as f32) - 1.0;
    around(Vec3::Y, cos_t, j % azimuths, azimuths)
}

/// The direction at cosine `cos_t` to unit `axis` and azimuth cell `i` of `azimuths`.
fn around(axis: Vec3, cos_t: f32, i: u32, azimuths: u32) -> Vec3 {
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let psi = 2.0 * PI * (i as f32 + 0.5) / azimuths as f32;
    let (t, u) = basis(axis);
    (axis * cos_t + (t * psi.cos() + u * psi.sin()) * sin_t).normalize()
}

/// Eq. 7 without the volume scattering function and the beam: the order-1
/// radiance at depths `z` (m, per channel) travelling along a direction of
/// vertical cosine `mu` (> 0 upward), per unit `beta E_w`: a length, m
/// (times `beta`, 1/(m sr), and `E_w`, W/m^2, it is W/(m^2 sr)).
///
/// Upward light was scattered below, between `z` and the bottom `d`:
/// `e^(-c z/mu_s) (d - z)/mu phi(c (d - z)(1/mu_s + 1/mu))`; downward light
/// above, between the surface and `z`: `(z/|mu|) (e^-a - e^-b)/(b - a)`,
/// `a = c z/mu_s`, `b = c z/|mu|`, written as `e^-min(a,b) phi(|b - a|)`: eq.
/// 7's removable singularity at `|mu| = mu_s` (`1 - sec(theta_io) cos(theta) = 0`)
/// is `phi(0) = 1`, and no exponential grows.
pub fn order1_path(z: Vec3, mu: f32, p: &SeaParams) -> Vec3 {
    order1_path_over(z, mu, (Vec3::splat(p.depth) - z).max(Vec3::ZERO), p)
}

/// `order1_path` where upward light was scattered over `below` (m,
/// vertically, per channel) under `z`: to wherever the bottom lies along
/// the way it came (section 5.4's `Q_P P_k`).
pub fn order1_path_over(z: Vec3, mu: f32, below: Vec3, p: &SeaParams) -> Vec3 {
    let c = p.extinction.xyz();
    let mu_s = p.sun_in_water.w;
    if mu > 0.0 {
        let mu = mu.max(1e-6);
        let length = below * (1.0 / mu_s + 1.0 / mu);
        (-c * z / mu_s).exp() * below / mu * phi3(c * length)
    } else {
        let m = (-mu).max(1e-6);
        let a = c * z / mu_s;
        let b = c * z / m;
        (-a.min(b)).exp() * z / m * phi3((b - a).abs())
    }
}

/// Eq. 5 (closed-form order 1) toward the surface along a unit upward
/// direction of travel `view` in the water (W/(m^2 sr), below the surface)
/// over a flat bottom at depth `depth`, with extinction `c` (the exact
/// `p.extinction` or eq. 5's `p.order1_extinction`).
pub fn order1_radiance(p: &SeaParams, view: Vec3, depth: f32, c: Vec3) -> Vec3 {
    let mu_s = p.sun_in_water.w;
    let mu_v = view.y.max(1e-6);
    let beta = p.scattering.xyz() * henyey_greenstein(p.sun_in_water.xyz().dot(view), p.scattering.w);
    let length = depth * (1.0 / mu_s + 1.0 / mu_v);
    beta * p.beam_irradiance.xyz() * (depth / mu_v) * phi3(c * length)
}

/// Eq. 9 in the standard form: the refracted sunlight reflected by a
/// Lambertian bottom at depth `depth` with cosine `cos_gamma` to its normal,
/// seen along the upward `view` (W/(m^2 sr), below the surface):
/// `E_w e^(-c d/mu_s) cos(gamma) (albedo/pi) e^(-c d/mu_v)`.
pub fn bottom_radiance(p: &SeaParams, view: Vec3, depth: f32, cos_gamma: f32) -> Vec3 {
    let mu_v = view.y.max(1e-6);
    under::bottom_leaving(p, depth, cos_gamma) * (-p.extinction.xyz() * (depth / mu_v)).exp()
}

/// Depth of sampling plane `k` per channel, m, from the surface down to
/// `plane_depth`: graded as `u^2` toward the surface in deep water (where
/// near-horizontal light builds up over a thin layer), as `(1 - cos(pi u))/2`
/// toward both ends where the planes reach the bottom (where the light from
/// below fades over another), `u = k/(n_z - 1)`.
pub fn plane_depth(p: &SeaParams, k: u32) -> Vec3 {
    let u = k as f32 / (p.planes - 1) as f32;
    let z = p.plane_depth.xyz();
    Vec3::new(z.x * grade(u, z.x, p.depth), z.y * grade(u, z.y, p.depth), z.z * grade(u, z.z, p.depth))
}

/// `plane_depth`'s grading of `u` for planes reaching `reach` over a bottom at `depth`.
fn grade(u: f32, reach: f32, depth: f32) -> f32 {
    if reach >= depth * 0.999_999 {
        0.5 - 0.5 * (PI * u).cos()
    } else {
        u * u
    }
}

/// The bottom depth of order-2 layer `j`, m: the flat bottom's, or for a
/// varying bottom geometric from `shallow` to the deepest.
pub fn layer_depth(p: &SeaParams, j: u32) -> f32 {
    if p.layers <= 1 {
        return p.depth;
    }
    let t = j as f32 / (p.layers - 1) as f32;
    p.shallow * (p.bottom_grid.w / p.shallow).powf(t)
}

/// `p` with the bottom of layer `j` (and the planes that reach it).
pub fn layer_params(p: &SeaParams, j: u32) -> SeaParams {
    if p.layers <= 1 {
        return *p;
    }
    let depth = layer_depth(p, j);
    SeaParams { depth, plane_depth: plane_reach(p.extinction.xyz(), depth).extend(0.0), ..*p }
}

/// How deep the sampling planes reach per channel over a bottom at `depth`
/// (m) in water of extinction `c` (1/m): to the bottom, or to
/// `DEEP_OPTICAL_DEPTH` where that comes first.
pub fn plane_reach(c: Vec3, depth: f32) -> Vec3 {
    (Vec3::splat(DEEP_OPTICAL_DEPTH) / c).min(Vec3::splat(depth))
}

/// Directions per set: `polar x azimuths` (`n_d` is three sets).
pub fn set_size(p: &SeaParams) -> u32 {
    p.polar * p.azimuths
}

/// Direction `m` of the map-held sets: the first `set_size` around the
/// refracted sun, the next `set_size` uniform over the sphere about the
/// vertical (`polar` even: no cell straddles the horizontal, where the
/// order-1 radiance near the surface jumps).
pub fn held_direction(p: &SeaParams, m: u32) -> Vec3 {
    let n = set_size(p);
    if m < n {
        set_direction(p.sun_in_water.xyz(), m, p.polar, p.azimuths, p.scattering.w)
    } else {
        uniform_direction(m - n, p.polar, p.azimuths)
    }
}

/// Length of one layer's block of the radiance map buffer (the buffer holds
/// `layers` of them): the order-1 radiance for every
/// plane and held direction (`planes x 2N`), then the held directions
/// themselves (`2N`, w: `p_s`), then the view set's directions in the
/// view's frame (`N`: x, y across, z along the view), so that the
/// scattering maps kernel reads rather than recomputes them per texel.
pub fn radiance_map_len(p: &SeaParams) -> u32 {
    (2 * p.planes + 3) * set_size(p)
}

/// Radiance map kernel (eq. 7): element `index` of the buffer laid out as
/// `radiance_map_len` says; the radiance part is the order-1 radiance (rgb,
/// W/(m^2 sr)) arriving at plane `k` travelling along held direction `m`.
pub fn radiance_map_texel(index: u32, p: &SeaParams) -> Vec4 {
    let len = radiance_map_len(p);
    let q = layer_params(p, index / len);
    layer_radiance_map_texel(index % len, &q)
}

/// `radiance_map_texel` within one layer's block.
fn layer_radiance_map_texel(index: u32, p: &SeaParams) -> Vec4 {
    let n = set_size(p);
    let sun = p.sun_in_water.xyz();
    let g = p.scattering.w;
    let held = p.planes * 2 * n;
    if index >= held + 2 * n {
        // The view set's pattern, in the frame (t, u, view) of `basis`.
        return set_direction(Vec3::Z, index - held - 2 * n, p.polar, p.azimuths, g).extend(0.0);
    }
    if index >= held {
        let dir = held_direction(p, index - held);
        return dir.extend(henyey_greenstein(sun.dot(dir), g));
    }
    let (k, m) = (index / (2 * n), index % (2 * n));
    let dir = held_direction(p, m);
    let beta = p.scattering.xyz() * henyey_greenstein(sun.dot(dir), g);
    (beta * p.beam_irradiance.xyz() * order1_path(plane_depth(p, k), dir.y, p)).extend(0.0)
}

/// The largest zenith angle of the direction toward the eye that the
/// scattering maps hold: just above the horizontal for an eye above the
/// water (light reaches it travelling up); just short of the nadir for an
/// eye under it (light reaches it from every direction, `under`).
pub fn map_zenith(p: &SeaParams) -> f32 {
    if p.underwater != 0 {
        PI - 1e-3
    } else {
        FRAC_PI_2 - 1e-3
    }
}

/// The unit direction of travel (toward the eye) that scattering map
/// texel `(col, row)` stands for: azimuth `pi col/(w-1)` from the refracted
/// sun's, zenith angle `map_zenith row/(h-1)` (the last row just above the
/// horizontal, or under water just short of straight down).
pub fn map_direction(p: &SeaParams, col: u32, row: u32) -> Vec3 {
    let azimuth = PI * col as f32 / (p.map_width - 1) as f32;
    let zenith = map_zenith(p) * row as f32 / (p.map_height - 1) as f32;
    let (t, u) = sun_azimuth_frame(p);
    let horizontal = t * azimuth.cos() + u * azimuth.sin();
    (horizontal * zenith.sin() + Vec3::Y * zenith.cos()).normalize()
}

/// Horizontal unit vectors: toward the sun's azimuth (the way the refracted
/// sun travels, horizontally) and across it; any pair for a sun at the zenith.
pub fn sun_azimuth_frame(p: &SeaParams) -> (Vec3, Vec3) {
    let s = p.sun_in_water.xyz();
    let h = Vec3::new(s.x, 0.0, s.z);
    let t = if h.length_squared() > 1e-12 { h.normalize() } else { Vec3::X };
    (t, Vec3::new(-t.z, 0.0, t.x))
}

/// Scattering map kernel (eq. 6 and 8): texel `index` = plane `k` x map
/// texel, the order-2 source `int beta(a') L1(z_k, w') dw'` (rgb,
/// W/(m^3 sr)) toward the texel's direction (`scattering_source`).
pub fn scattering_map_texel(index: u32, p: &SeaParams, radiance_map: &[Vec4]) -> Vec4 {
    let texels = p.map_width * p.map_height;
    let per_layer = p.planes * texels;
    let j = index / per_layer;
    let q = layer_params(p, j);
    let (k, t) = ((index % per_layer) / texels, index % texels);
    let view = map_direction(&q, t % q.map_width, t / q.map_width);
    scattering_source(&q, k, view, radiance_map, (j * radiance_map_len(p)) as usize).extend(0.0)
}

/// Width (in the vertical cosine) of the band about the horizontal that
/// the sun's and the view's sets leave to the uniform set.
pub const HORIZON_BAND: f32 = 0.2;

/// The sun's and the view's share of the directions near the horizontal:
/// 0 at it, 1 beyond `HORIZON_BAND`, smooth (`3t^2 - 2t^3`).
pub fn horizon_window(mu: f32) -> f32 {
    let t = (mu.abs() / HORIZON_BAND).min(1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The order-2 source at plane `k` toward unit `view` (see
/// `scattering_map_texel`): three sets of `N` directions, distributed like
/// `p_s` (around the sun), `p_u = 1/(4 pi)` (uniform, its cells split at the
/// horizontal) and `p_v` (around the view), combined by multiple importance
/// weights `w_i = q_i^2 / (q_s^2 + q_v^2 + q_u^2)`, `q_s = h p_s`, `q_v = h p_v`,
/// `q_u = p_u`, with `h = horizon_window(mu)`: the power heuristic away from
/// the horizontal (each set keeps the peak it was drawn for, and leaks less
/// of the other's than the balance heuristic), the uniform set alone at it,
/// where the order-1 radiance near the surface (and the bottom) jumps and
/// only the uniform set's cells do not straddle the jump.
pub fn scattering_source(p: &SeaParams, k: u32, view: Vec3, radiance_map: &[Vec4], base: usize) -> Vec3 {
    let n = set_size(p);
    let g = p.scattering.w;
    let sun = p.sun_in_water.xyz();
    let b = p.scattering.xyz();
    let z = plane_depth(p, k);
    let held = base + (p.planes * 2 * n) as usize;
    let mut sum = Vec3::ZERO;
    let mut m = 0;
    while m < 2 * n {
        // The sun's and the uniform set: L1 from the radiance map.
        let d = radiance_map[held + m as usize];
        let (ps, pv, h) = (d.w, henyey_greenstein(d.xyz().dot(view), g), horizon_window(d.y));
        let weight = set_weight(ps, pv, h, if m < n { SET_SUN } else { SET_UNIFORM });
        sum += radiance_map[base + (k * 2 * n + m) as usize].xyz() * (pv * weight);
        m += 1;
    }
    let (t, u) = basis(view);
    let beam = b * p.beam_irradiance.xyz();
    m = 0;
    while m < n {
        // The view's set: L1 by eq. 7.
        let local = radiance_map[held + (2 * n + m) as usize];
        let dir = t * local.x + u * local.y + view * local.z;
        let (ps, pv, h) = (henyey_greenstein(sun.dot(dir), g), henyey_greenstein(local.z, g), horizon_window(dir.y));
        let weight = set_weight(ps, pv, h, SET_VIEW);
        sum += beam * order1_path(z, dir.y, p) * (ps * pv * weight);
        m += 1;
    }
    b * sum / n as f32
}

/// The three direction sets of `scattering_source`.
pub const SET_SUN: u32 = 0;
pub const SET_UNIFORM: u32 = 1;
pub const SET_VIEW: u32 = 2;

/// `scattering_source`'s multiple importance weight of a direction from
/// `set`, divided by that set's density: with `q_s = h p_s`, `q_v = h p_v`
/// (`p_s`, `p_v` the phase function toward the direction from the sun and
/// the view, `h` the horizon window) and `q_u = 1/(4 pi)`, the power
/// heuristic's `q_i^2 / (p_i sum q_j^2)`.
pub fn set_weight(ps: f32, pv: f32, h: f32, set: u32) -> f32 {
    let uniform = 0.25 * FRAC_1_PI;
    let (a_s, a_v) = (h * ps, h * pv);
    let own = if set == SET_SUN {
        h * a_s
    } else if set == SET_UNIFORM {
        uniform
    } else {
        h * a_v
    };
    own / (a_s * a_s + a_v * a_v + uniform * uniform)
}

/// Where unit `view` (upward, or any way under water) falls in a scattering map: the lower-left texel
/// and the bilinear weights, the same for every plane.
#[derive(Copy, Clone)]
pub struct MapCoords {
    pub col: u32,
    pub row: u32,
    pub ax: f32,
    pub ay: f32,
}

pub fn map_coords(p: &SeaParams, view: Vec3) -> MapCoords {
    let (t, u) = sun_azimuth_frame(p);
    let (x, y) = (view.dot(t), view.dot(u).abs());
    let azimuth = if x * x + y * y > 1e-24 { y.atan2(x) } else { 0.0 };
    let zenith = view.y.clamp(-1.0, 1.0).acos();
    let fx = (azimuth / PI).clamp(0.0, 1.0) * (p.map_width - 1) as f32;
    let fy = (zenith / map_zenith(p)).clamp(0.0, 1.0) * (p.map_height - 1) as f32;
    let (col, row) = ((fx as u32).min(p.map_width - 2), (fy as u32).min(p.map_height - 2));
    MapCoords { col, row, ax: fx - col as f32, ay: fy - row as f32 }
}

/// Bilinear lookup of scattering map `k` at `at`.
pub fn scattering_map_lookup(p: &SeaParams, maps: &[Vec4], k: u32, at: MapCoords) -> Vec3 {
    let w = p.map_width;
    let base = (k * w * p.map_height + at.row * w + at.col) as usize;
    let (a, b) = (maps[base].xyz(), maps[base + 1].xyz());
    let (c, d) = (maps[base + w as usize].xyz(), maps[base + w as usize + 1].xyz());
    (a * (1.0 - at.ax) + b * at.ax) * (1.0 - at.ay) + (c * (1.0 - at.ax) + d * at.ax) * at.ay
}

/// `int_0^1 t e^(-x t) dt = (1 - (1 + x) e^-x) / x^2`, without cancellation for small `x`.
pub fn psi1(x: f32) -> f32 {
    if x.abs() < 1e-2 {
        0.5 - x * (1.0 / 3.0 - x / 8.0)
    } else {
        (1.0 - (1.0 + x) * (-x).exp()) / (x * x)
    }
}

/// `int` over an interval of `length` of `h(z) = s(z) e^(-kappa z)` with
/// `s` linear, from the ends' values `h_a`, `h_b`: exact for that form.
/// Where the exponential alone falls by more than `e^-40` across the
/// interval, its start dominates: `h_a int e^(-kappa t) dt`.
fn exp_linear(length: f32, h_a: f32, h_b: f32, kappa: f32) -> f32 {
    let x = kappa * length;
    if x > 40.0 {
        return h_a * length * phi(x);
    }
    let s_b = h_b * x.exp();
    length * (h_a * phi(x) + (s_b - h_a) * psi1(x))
}

/// `exp_linear` per channel.
pub fn exp_linear3(length: Vec3, h_a: Vec3, h_b: Vec3, kappa: Vec3) -> Vec3 {
    Vec3::new(
        exp_linear(length.x, h_a.x, h_b.x, kappa.x),
        exp_linear(length.y, h_a.y, h_b.y, kappa.y),
        exp_linear(length.z, h_a.z, h_b.z, kappa.z),
    )
}

/// Blocks of `map_width x map_height` texels in the accumulated map: one
/// per layer, and for an eye under the water over a flat bottom one more
/// (`under::eye_block`).
pub fn accumulated_blocks(p: &SeaParams) -> u32 {
    p.layers + under::eye_block(p) as u32
}

/// Accumulated map kernel: texel `index`, the scattering maps accumulated
/// over the planes (`order2_radiance` at the texel's own direction, so no
/// interpolation), the order-2 radiance below the surface toward the eye.
/// Per pixel one lookup of this map replaces the per-plane accumulation.
pub fn accumulated_map_texel(index: u32, p: &SeaParams, maps: &[Vec4]) -> Vec4 {
    let texels = p.map_width * p.map_height;
    let (j, t) = (index / texels, index % texels);
    if j == p.layers {
        // The eye's block (`under::eye_block`): order 2 gathered along
        // the whole view ray toward the texel's direction.
        let view = map_direction(p, t % p.map_width, t / p.map_width);
        return under::order2_segment(p, maps, -view, p.camera_depth, under::full_length(p, -view), p.depth)
            .extend(0.0);
    }
    let q = layer_params(p, j);
    let view = map_direction(&q, t % q.map_width, t / q.map_width);
    accumulate_planes(&q, view, maps, j * q.planes * texels + t, texels).extend(0.0)
}

/// The order-2 radiance below the surface along unit upward `view`
/// (W/(m^2 sr)): the order-2 sources of the planes toward `view`
/// (`sources[first + k stride]` for plane `k`: the scattering maps)
/// accumulated with the attenuation map (eq. 8's sum times
/// `G = e^(-c z/mu_v)`, over the path element `dz/mu_v`):
/// `int J(z) e^(-c z/mu_v) dz/mu_v` with `J(z) = s(z) e^(-c z/mu_s)` and `s`
/// taken as linear between planes (the exponential `e^(-kappa z)`,
/// `kappa = c (1/mu_s + 1/mu_v)`, integrated exactly), constant below the
/// last plane down to the bottom.
pub fn accumulate_planes(p: &SeaParams, view: Vec3, sources: &[Vec4], first: u32, stride: u32) -> Vec3 {
    let c = p.extinction.xyz();
    let mu_s = p.sun_in_water.w;
    let mu_v = view.y.max(1e-6);
    let kappa = c * (1.0 / mu_s + 1.0 / mu_v);
    let mut z_a = plane_depth(p, 0);
    let mut h_a = plane_integrand(sources[first as usize].xyz(), z_a, c, mu_v);
    let mut sum = Vec3::ZERO;
    let mut k = 1;
    while k < p.planes {
        let z_b = plane_depth(p, k);
        let h_b = plane_integrand(sources[(first + k * stride) as usize].xyz(), z_b, c, mu_v);
        sum += exp_linear3(z_b - z_a, h_a, h_b, kappa);
        z_a = z_b;
        h_a = h_b;
        k += 1;
    }
    // Below the last plane, down to the bottom: s constant.
    let rest = (Vec3::splat(p.depth) - z_a).max(Vec3::ZERO);
    sum + h_a * rest * phi3(kappa * rest)
}

/// The order-2 integrand at a plane: its source attenuated to the surface, per unit path.
fn plane_integrand(source: Vec3, z: Vec3, c: Vec3, mu_v: f32) -> Vec3 {
    source.max(Vec3::ZERO) * (-c * z / mu_v).exp() / mu_v
}

/// What a pixel's view ray sees of the sea.
#[derive(Copy, Clone, Debug, Default)]
pub struct SeaView {
    /// Whether the ray meets the sea (before any object).
    pub hit: bool,
    /// Fresnel reflectance at the surface (waves: its mean over the slopes).
    pub reflectance: f32,
    /// Reflected direction at the (mean) normal (unit, toward the sky).
    pub reflected: Vec3,
    /// Direction of travel from the water toward the eye, after refraction
    /// (unit, upward; the reverse of the refracted view ray).
    pub view: Vec3,
    /// `T_o / n^2`: the factor from radiance below the surface to radiance above.
    pub transmission: f32,
    /// Where the view ray meets the surface.
    pub point: Vec3,
    /// The view ray's direction (unit, downward).
    pub dir: Vec3,
    /// Waves: the slopes under the sample's footprint (`surface`) and the
    /// rule that integrates over them (`surface::SlopeRule`).
    pub slopes: surface::Slopes,
    pub rule: surface::SlopeRule,
}

/// Depth of a varying bottom at horizontal `(x, z)`, m: bilinear in the
/// grid, clamped at its edges.
pub fn bottom_depth(p: &SeaParams, grid: &[f32], x: f32, z: f32) -> f32 {
    let g = p.bottom_grid;
    let (nx, nz) = (p.bottom_nx, p.bottom_nz);
    let fx = ((x - g.x) / g.z).clamp(0.0, (nx - 1) as f32);
    let fz = ((z - g.y) / g.z).clamp(0.0, (nz - 1) as f32);
    let (i, j) = ((fx as u32).min(nx - 2), (fz as u32).min(nz - 2));
    let (ax, az) = (fx - i as f32, fz - j as f32);
    let (r0, r1) = ((j * nx + i) as usize, ((j + 1) * nx + i) as usize);
    (grid[r0] * (1.0 - ax) + grid[r0 + 1] * ax) * (1.0 - az) + (grid[r1] * (1.0 - ax) + grid[r1 + 1] * ax) * az
}

/// The bottom's upward unit normal at `(x, z)`, from central differences a
/// grid spacing apart (depth grows downward: the normal leans toward it).
pub fn bottom_normal(p: &SeaParams, grid: &[f32], x: f32, z: f32) -> Vec3 {
    let h = p.bottom_grid.z;
    let dx = (bottom_depth(p, grid, x + h, z) - bottom_depth(p, grid, x - h, z)) / (2.0 * h);
    let dz = (bottom_depth(p, grid, x, z + h) - bottom_depth(p, grid, x, z - h)) / (2.0 * h);
    Vec3::new(dx, 1.0, dz).normalize()
}

/// Where the refracted view ray from the surface at `(x, z)`, travelling
/// against upward `view`, meets the bottom: its depth (m) and the cosine of
/// eq. 9's `gamma`. A flat bottom in closed form; a varying one by
/// `march_to_bottom` (at most 2048 steps); past the deepest depth, the
/// deepest.
pub fn bottom_hit(p: &SeaParams, grid: &[f32], x: f32, z: f32, view: Vec3) -> (f32, f32) {
    let mu_s = p.sun_in_water.w;
    if p.bottom_nx < 2 {
        return (p.depth, mu_s);
    }
    let deep = p.bottom_grid.w;
    let mu = view.y.max(1e-4);
    let t = march_to_bottom(p, grid, x, z, 0.0, view, deep / mu, 2048);
    if t < 0.0 {
        return (deep, mu_s);
    }
    let (qx, qz) = (x - view.x * t, z - view.z * t);
    let up = -p.sun_in_water.xyz();
    (t * view.y.max(1e-4), bottom_normal(p, grid, qx, qz).dot(up).max(0.0))
}

/// The distance `t` (m) along the ray from horizontal `(x, z)` at depth
/// `z0` travelling against upward unit `dir` (so going down) to the first
/// crossing of the varying bottom, within `t_max`: marched half a grid
/// spacing at a time (at most `steps`; fewer, longer ones where the ray is
/// steep) and a secant between the last two; -1 where it stays above.
#[allow(clippy::too_many_arguments)]
pub fn march_to_bottom(p: &SeaParams, grid: &[f32], x: f32, z: f32, z0: f32, dir: Vec3, t_max: f32, steps: u32) -> f32 {
    let mu = dir.y.max(1e-4);
    let (hx, hz) = (-dir.x, -dir.z);
    let horizontal = (hx * hx + hz * hz).sqrt().max(1e-6);
    let dt = (0.5 * p.bottom_grid.z / horizontal).min(t_max).max(t_max / steps as f32);
    let mut t_prev = 0.0;
    let mut f_prev = z0 - bottom_depth(p, grid, x, z);
    if f_prev >= 0.0 {
        return 0.0;
    }
    let mut t = dt;
    while t <= t_max + 0.5 * dt {
        let (px, pz) = (x + hx * t, z + hz * t);
        let f = z0 + t * mu - bottom_depth(p, grid, px, pz);
        if f >= 0.0 {
            return t_prev + dt * (-f_prev / (f - f_prev).max(1e-20));
        }
        t_prev = t;
        f_prev = f;
        t += dt;
    }
    -1.0
}

/// The order-2 layers bracketing bottom depth `depth`: the lower index and
/// the weight of the next (linear in the log of the depth).
pub fn layer_at(p: &SeaParams, depth: f32) -> (u32, f32) {
    if p.layers <= 1 {
        return (0, 0.0);
    }
    let top = (p.layers - 1) as f32;
    let t = ((depth.max(p.shallow) / p.shallow).ln() / (p.bottom_grid.w / p.shallow).ln() * top).clamp(0.0, top);
    let j = (t as u32).min(p.layers - 2);
    (j, t - j as f32)
}

/// The normal of the surface at horizontal position `(x, z)`: up for a flat
/// sea, else the wave map's slopes, bilinear, tiled (`surface::point_normal`).
pub fn surface_normal(p: &SeaParams, waves: &[Vec4], x: f32, z: f32) -> Vec3 {
    surface::point_normal(p, waves, x, z)
}

/// Where pixel `index`'s current sub-pixel sample meets the sea (`texel`:
/// the pixel's G-buffer texel; objects hide the sea), and over waves the
/// slope rule there (`surface`); the reflectance, the refracted view and
/// the transmission are left to `sea_view`.
pub fn sea_hit(index: u32, common: &CommonParams, p: &SeaParams, waves: &[Vec4], texel: &GBufferTexel) -> SeaView {
    let x = index % common.width;
    let y = index / common.width;
    if !in_image(common, x, y) {
        return SeaView::default();
    }
    let (origin, dir) = camera_ray(common, x, y);
    if dir.y >= 0.0 || origin.y <= p.level {
        return SeaView::default();
    }
    let t = (p.level - origin.y) / dir.y;
    // An object the straight view ray meets before the water hides it; one
    // it meets under the water is seen through the surface (`sea.water`
    // takes its light in air out, `object_under` finds it).
    if texel.object != NO_OBJECT && texel.normal_distance.w <= t {
        return SeaView::default();
    }
    let (a, b) = if p.waves == WAVES_NORMAL_MAP && p.wave_filter != 0 {
        surface::footprint(common, x, y, dir, t, 2.0 * p.wave_size)
    } else {
        (Vec2::ZERO, Vec2::ZERO)
    };
    sea_hit_along(p, waves, origin, dir, a, b)
}

/// Where the ray `origin + t dir` (from above the water, `dir` unit and
/// downward) meets the sea, and over waves the slope rule there for a
/// footprint with axes `a`, `b` (m; zero: the map's slope at the point, with
/// the unresolved waves' roughness); `hit` false if it does not go down
/// from above the water.
pub fn sea_hit_along(p: &SeaParams, waves: &[Vec4], origin: Vec3, dir: Vec3, a: Vec2, b: Vec2) -> SeaView {
    let mut out = SeaView::default();
    if dir.y >= 0.0 || origin.y <= p.level {
        return out;
    }
    let t = (p.level - origin.y) / dir.y;
    out.hit = true;
    out.point = origin + dir * t;
    out.dir = dir;
    if p.waves == WAVES_NORMAL_MAP {
        out.slopes = surface::footprint_slopes(p, waves, out.point.x, out.point.z, a, b);
        out.rule = surface::SlopeRule::new(&out.slopes, dir);
    }
    out
}

/// The sea as pixel `index`'s current sub-pixel sample sees it (`sea_hit`).
///
/// A flat sea has one normal. Waves are read as the slope distribution
/// under the sample's footprint (`surface`): the reflectance (so the
/// transmission `(1 - R) / n^2`) is averaged over the slope rule's facets,
/// and the light below is taken along the view refracted at their mean
/// normal, each weighted by what it transmits (`1 - R`).
pub fn sea_view(index: u32, common: &CommonParams, p: &SeaParams, waves: &[Vec4], texel: &GBufferTexel) -> SeaView {
    refracted(p, sea_hit(index, common, p, waves, texel))
}

/// `sea_view` of a hit (`sea_hit`, `sea_hit_along`): its reflectance,
/// reflected ray, the view refracted into the water and the transmission.
pub fn refracted(p: &SeaParams, hit: SeaView) -> SeaView {
    let mut out = hit;
    if !out.hit {
        return out;
    }
    let (dir, n) = (out.dir, p.extinction.w);
    let mut normal = Vec3::Y;
    let mut r = 0.0;
    if p.waves == WAVES_NORMAL_MAP {
        let mut mean = Vec3::ZERO;
        let mut through = Vec3::ZERO;
        let mut k = 0;
        while k < surface::SLOPE_NODES {
            let facet = out.rule.node(k);
            let rk = reflectance(facet.cos_i, 1.0 / n);
            r += facet.weight * rk;
            mean += facet.normal * facet.weight;
            through += facet.normal * (facet.weight * (1.0 - rk));
            k += 1;
        }
        normal = mean.normalize();
        // Refracted at the facets' normal weighted by what each transmits
        // (averaging the nine refracted directions instead moved no pixel
        // of sea_open's horizon band by a measurable amount, at 8 more refractions).
        let refracting = if through.y > 0.0 { through.normalize() } else { normal };
        out.view = view_in_water(dir, refracting, n);
    } else {
        r = reflectance(-dir.y, 1.0 / n);
        out.view = view_in_water(dir, normal, n);
    }
    out.reflectance = r;
    out.reflected = reflected_skyward(dir, normal);
    out.transmission = (1.0 - r) / (n * n);
    out
}

/// The view ray `dir` reflected at a surface of unit `normal`, turned up
/// where a steep facet would send it below the horizon (it leaves the
/// wave toward the sky).
pub fn reflected_skyward(dir: Vec3, normal: Vec3) -> Vec3 {
    let r = dir - normal * (2.0 * dir.dot(normal));
    Vec3::new(r.x, r.y.abs(), r.z).normalize()
}

/// Per-pixel kernel, `sea.surface`: what the terms below the surface need
/// of it, computed once: the direction light leaves the water toward the
/// eye (xyz) and the transmission `(1 - R)/n^2` (w); zero where the sample
/// does not see the sea. For an eye under water, where its view ray ends
/// (`under::UnderView::encode`; `grid` the bottom's depths).
pub fn surface_pixel(
    index: u32,
    common: &CommonParams,
    p: &SeaParams,
    waves: &[Vec4],
    grid: &[f32],
    texel: &GBufferTexel,
) -> Vec4 {
    if p.underwater != 0 {
        return under::under_ray(index, common, p, waves, grid, texel).encode();
    }
    let v = sea_view(index, common, p, waves, texel);
    if !v.hit {
        return Vec4::ZERO;
    }
    v.view.extend(v.transmission)
}

/// The sea as the terms below the surface see it: `surface_pixel`'s value
/// for the sample, with the point where its view ray meets the surface.
pub fn seen_from(index: u32, common: &CommonParams, p: &SeaParams, surface: Vec4) -> SeaView {
    let mut out = SeaView::default();
    if surface.y <= 0.0 {
        return out;
    }
    let (origin, dir) = camera_ray(common, index % common.width, index / common.width);
    out.hit = true;
    out.point = origin + dir * ((p.level - origin.y) / dir.y);
    out.dir = dir;
    out.view = surface.xyz();
    out.transmission = surface.w;
    out
}

/// The direction light leaves the water toward an eye looking along `dir`
/// at a surface of normal `normal` and index `n` (the refracted view ray
/// reversed), kept at least 1e-4 above the horizontal.
pub fn view_in_water(dir: Vec3, normal: Vec3, n: f32) -> Vec3 {
    let (refracted, _) = refract(dir, normal, 1.0 / n);
    let view = -refracted;
    if view.y < 1e-4 {
        return Vec3::new(view.x, 1e-4, view.z).normalize();
    }
    view
}

/// Per-pixel kernel, `sea.reflection`: the sky and the sun reflected at the
/// surface, `R (L_sky + L_sun)` along the reflected ray. For an eye under
/// water, what lies beyond Snell's window, `e^(-c l) (1 - R) n^2 L_air`
/// along the ray refracted out (`under::through_window`; `surface`: the
/// sample's `sea.surface` value): an object above the water where that ray
/// meets one (`objects`: `air::Above`), else the sky and the sun. With
/// `air::GlassInAir` (kernel `sea.glass_air`), what glass over the water
/// shows along the same rays, and nothing else. `w`: how many of the rays
/// met glass.
///
/// One call of `reflection_seen` for all three views (under the water, a
/// flat sea, waves): a kernel inlines each call of `Objects::seen`, and
/// the glass's tracing is large.
#[allow(clippy::too_many_arguments)]
pub fn reflection_pixel<O: air::Objects>(
    index: u32,
    common: &CommonParams,
    p: &SeaParams,
    waves: &[Vec4],
    sky: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    texel: &GBufferTexel,
    surface: Vec4,
    clouds: &CloudShadow,
    objects: &O,
) -> Vec4 {
    let (v, rough, scale) = if p.underwater != 0 {
        // Through the window: one ray, weighted by the transmission out.
        let u = under::decode(index, common, p, surface);
        let mut v = SeaView::default();
        if u.end == under::END_SURFACE {
            let (out, factor) = under::through_window(p, &u);
            if factor > 0.0 {
                v.hit = true;
                v.point = u.end_point();
                v.reflected = out;
                v.reflectance = factor;
            }
        }
        (v, false, under::attenuation(p, &u))
    } else if p.waves != WAVES_NORMAL_MAP {
        // A flat sea reads the reflectance and reflected ray (`sea_view`).
        (sea_view(index, common, p, waves, texel), false, Vec3::ONE)
    } else {
        // Waves read the slope rule alone (`sea_hit`).
        (sea_hit(index, common, p, waves, texel), true, Vec3::ONE)
    };
    if !v.hit {
        return Vec4::ZERO;
    }
    let seen = reflection_seen(p, sky, transmittance, sky_view, &v, clouds, objects, rough);
    (seen.xyz() * scale).extend(seen.w)
}

/// The sky and the sun reflected at the surface where `v` meets it (rgb;
/// `w` the number of rays traced that met glass):
/// without `rough`, one ray `v.reflected` weighted by `v.reflectance` (a
/// flat sea's mirror, or the ray out through Snell's window); with it,
/// every facet of `v`'s slope rule and the sun's glint. Where a ray meets
/// one of `objects` (`air::Objects`), the object's light in air takes the
/// sky's place along it; the glint needs the sun seen from the point.
///
/// Every ray is traced at one place (`Objects::seen` is called once in
/// the code): each node of the rule has one ray, or where objects may be
/// near it three across the view and, where those lie within a pixel's
/// angle of each other, the middle one traced for all three.
#[allow(clippy::too_many_arguments)]
pub fn reflection_seen<O: air::Objects>(
    p: &SeaParams,
    sky: &SkyParams,
    transmittance: &[Vec4],
    sky_view: &[Vec4],
    v: &SeaView,
    clouds: &CloudShadow,
    objects: &O,
    rough: bool,
) -> Vec4 {
    let n = p.extinction.w;
    // The sun's light through the volumes' shadow at the point
    // (`CloudShadow`).
    let shade = clouds.at(p, v.point);
    // Over waves, rays are traced only where the cone around the reflected
    // rays may meet an object (most of the sea's pixels mirror only the
    // sky, as without objects).
    let trace = objects.any() && (!rough || reflections_near_objects(v, objects));
    let nodes = if rough { surface::SLOPE_NODES } else { 1 };
    let mut light = Vec3::ZERO;
    let mut glass = 0.0;
    let mut k = 0;
    while k < nodes {
        // Waves: the sky (and, by the turned-away share, the sun's disk)
        // reflected by each facet of the slope rule (`surface::SlopeRule`).
        // Nodes of weight 1e-3 or less take the sky: the rule's tails (at
        // most 0.9 % of the weight in all, nine nodes).
        let (normal, weight, traced) = if rough {
            let facet = v.rule.node(k);
            (facet.normal, facet.weight * reflectance(facet.cos_i, 1.0 / n), trace && facet.weight > 1e-3)
        } else {
            (Vec3::Y, v.reflectance, trace)
        };
        // Objects: each facing node at three slopes across the view
        // (`SlopeRule::across`), each reflected ray traced (a mirrored
        // object, unlike the sky, is not smooth across: with the node's mean
        // slope alone a post's reflection under 7 m/s waves was 2.9 % RMS
        // (8-bit) off the f64 rule, 1.3 % with the three). The last node
        // (the turned-away share) keeps one ray, and the sun's disk.
        let across = rough && trace && k + 1 < surface::SLOPE_NODES;
        let sun = !rough || k + 1 == surface::SLOPE_NODES;
        let narrow = across && {
            let (low, high) = (surface::ACROSS_NODES[0].0, surface::ACROSS_NODES[2].0);
            let (r_low, r_high) =
                (reflected_skyward(v.dir, v.rule.across(k, low)), reflected_skyward(v.dir, v.rule.across(k, high)));
            r_low.dot(r_high) >= objects.cos_pixel()
        };
        // Slot 0: the node's one ray, or (across) the middle ray, traced for
        // the three where they are narrow; slots 1-3: the three across.
        let slots = if across { 4 } else { 1 };
        let mut node_light = Vec3::ZERO;
        let mut middle = (air::NOTHING, Vec3::ZERO);
        let mut j = 0;
        while j < slots {
            let (dir, w, run) = if !across {
                let dir = if rough { reflected_skyward(v.dir, normal) } else { v.reflected };
                (dir, 1.0, traced)
            } else if j == 0 {
                (reflected_skyward(v.dir, v.rule.across(k, 0.0)), 0.0, traced && narrow)
            } else {
                let (z, w) = surface::ACROSS_NODES[j - 1];
                (reflected_skyward(v.dir, v.rule.across(k, z)), w, traced && !narrow)
            };
            let found = if run { objects.seen(v.point, dir) } else { (air::NOTHING, Vec3::ZERO) };
            if found.0 == air::GLASS {
                glass += 1.0;
            }
            if j == 0 {
                middle = found;
            }
            let (kind, object) = if narrow { middle } else { found };
            let seen = kind != air::NOTHING;
            if w > 0.0 {
                let ray_light = if seen {
                    object
                } else if objects.sky() {
                    let sky_light = sky_radiance(sky, transmittance, sky_view, dir);
                    if sun {
                        sky_light + sun_disk(sky, transmittance, dir) * shade
                    } else {
                        sky_light
                    }
                } else {
                    Vec3::ZERO
                };
                node_light += w * ray_light;
            }
            j += 1;
        }
        light += node_light * weight;
        k += 1;
    }
    if rough {
        // The sun's glint in closed form.
        let glint = surface::sun_glint(sky, transmittance, &v.rule, &v.slopes, n);
        light += glint * shade * objects.sun_seen(v.point, sky.sun_direction.xyz());
    }
    light.extend(glass)
}

/// Whether the cone around the rays that the waves at `v` reflect toward
/// the sky (every node's three across, and the mean normal's) may meet one
/// of `objects`.
fn reflections_near_objects<O: air::Objects>(v: &SeaView, objects: &O) -> bool {
    let mut axis = reflected_skyward(v.dir, Vec3::Y);
    let mut k = 0;
    while k < surface::ALONG_NODES {
        let mut j = 0;
        while j < 3 {
            axis += reflected_skyward(v.dir, v.rule.across(k, surface::ACROSS_NODES[j].0));
            j += 1;
        }
        k += 1;
    }
    let axis = axis.normalize();
    let mut cos_half = axis.dot(reflected_skyward(v.dir, Vec3::Y));
    k = 0;
    while k < surface::ALONG_NODES {
        let mut j = 0;
        while j < 3 {
            let r = reflected_skyward(v.dir, v.rule.across(k, surface::ACROSS_NODES[j].0));
            cos_half = cos_half.min(axis.dot(r));
            j += 1;
        }
        k += 1;
    }
    objects.in_cone(v.point, axis, cos_half)
}

/// The volumes' shadow on the water: the sun's transmittance through them
/// to a point of the surface (`volumes::light_transmittance`), which
/// multiplies the sunlight below the surface there (orders 1 and 2 and the
/// bottom; locally, as if the shadow were wide against the light's depth in
/// the water) and the sun reflected there (its disk and glint). The
/// reflected sky is not shaded (nor are the clouds themselves reflected).
pub struct CloudShadow<'a> {
    pub lights: &'a [GpuLight],
    pub grids: &'a [LightGrid],
    pub depths: &'a [Vec4],
}

impl CloudShadow<'_> {
    /// The transmittance (rgb) at the surface point `point`: 1 without
    /// volumes.
    pub fn at(&self, p: &SeaParams, point: Vec3) -> Vec3 {
        if p.sun_light == 0 {
            return Vec3::ONE;
        }
        let l = (p.sun_light - 1) as usize;
        light_ref!(light = self.lights, l);
        light_transmittance(self.grids, self.depths, light, l, point).xyz()
    }
}

/// Per-pixel kernel, `sea.order1`: single scattering down to where the
/// view ray meets the bottom (section 5.4: eq. 5 with `z_Q` for `z_d`), above
/// the surface. Under water, eq. 5 along the view ray
/// (`under::order1_segment`) and, where the ray meets the surface, the
/// single scattering the surface reflects toward the eye, attenuated.
#[allow(clippy::too_many_arguments)]
pub fn order1_pixel(
    index: u32,
    common: &CommonParams,
    p: &SeaParams,
    surface: Vec4,
    bottom: &[f32],
    samples: &[Vec4],
    sunlit: &under::Sunlit,
    clouds: &CloudShadow,
) -> Vec4 {
    let c1 = p.order1_extinction.xyz();
    if p.underwater != 0 {
        let v = under::decode(index, common, p, surface);
        if v.end == under::END_NONE {
            return Vec4::ZERO;
        }
        let above = Vec3::new(v.origin.x, p.level, v.origin.z);
        let along = if under::shafts_sampled(p, &sunlit.geometry) {
            under::order1_upsampled(p, common, index, samples, sunlit, &v)
        } else {
            under::order1_shafts(p, sunlit, v.origin, v.dir, p.camera_depth, v.length, c1)
        };
        let mut light = along * clouds.at(p, above);
        if v.end == under::END_SURFACE {
            // The water below, mirrored: down to the bottom or to an object
            // in the water the reflected ray meets first (`order1_seen`).
            let up = order1_seen(p, &mirrored(&v), bottom, sunlit, clouds);
            light += up * v.reflectance * under::attenuation(p, &v);
        }
        return light.extend(0.0);
    }
    let v = seen_from(index, common, p, surface);
    if !v.hit {
        return Vec4::ZERO;
    }
    order1_seen(p, &v, bottom, sunlit, clouds).extend(0.0)
}

/// What an eye under the water sees mirrored where its view ray `v` meets
/// the surface from below (`under::END_SURFACE`): the light arriving at
/// that point from below along `v.up`, as an eye above the water is sent
/// it (`order1_seen`, `bottom_seen`: the bottom, or an object in the water
/// the reflected ray meets first), with `transmission` 1 (the caller takes
/// `R` and the attenuation to the eye).
pub fn mirrored(v: &under::UnderView) -> SeaView {
    SeaView { hit: true, view: v.up, transmission: 1.0, point: v.end_point(), dir: -v.up, ..Default::default() }
}

/// Order 1 (eq. 5 to the bottom, or to an object under the surface) seen
/// through the surface where `v` (from `refracted`) meets it, rgb.
pub fn order1_seen(p: &SeaParams, v: &SeaView, bottom: &[f32], sunlit: &under::Sunlit, clouds: &CloudShadow) -> Vec3 {
    let c1 = p.order1_extinction.xyz();
    let (mut depth, _) = bottom_hit(p, bottom, v.point.x, v.point.z, v.view);
    // The water in front of an object under the surface, not behind it.
    let object = object_under(v, depth, &sunlit.geometry);
    if object.distance != NO_HIT {
        depth = object.distance * v.view.y.max(1e-4);
    }
    let shade = clouds.at(p, v.point);
    order1_radiance(p, v.view, depth, c1) * v.transmission * shade
}

/// What the refracted view ray of an eye above the water meets under the
/// surface before the bottom `depth` m down (issue 26: a pier's posts, a
/// hull; `NO_HIT` where nothing): the nearest object along `-v.view` from
/// where the view ray meets the surface.
pub fn object_under(v: &SeaView, depth: f32, geometry: &Geometry) -> Hit {
    let length = depth.min(1e6) / v.view.y.max(1e-4);
    let eps = 1e-5 * v.point.abs().max_element().max(1.0);
    trace_nearest(v.point, -v.view, eps, length, geometry)
}

/// An object under the water seen from above (`object_under`'s `hit`),
/// below the surface, W/(m^2 sr): eq. 9's Lambertian reflection of the
/// refracted sun (`lambert_leaving`) at the point's depth, with the
/// object's albedo and its normal turned toward the eye, shaded by what
/// stands between it and the sun (`under::sun_visibility`), attenuated
/// along the `hit.distance` m of water up to the surface, and focused by
/// the waves as the water at its depth is (`caustics::shaft_at` on the
/// shaft planes, which are built for an eye above the water when objects
/// reach below the surface; 1 without them).
pub fn object_radiance(
    p: &SeaParams,
    v: &SeaView,
    hit: &Hit,
    sunlit: &under::Sunlit,
    materials: &[GpuMaterial],
) -> Vec3 {
    let point = v.point - v.view * hit.distance;
    let depth = (p.level - point.y).max(0.0);
    let normal = if hit.normal.dot(v.view) < 0.0 { -hit.normal } else { hit.normal };
    let cos_gamma = normal.dot(-p.sun_in_water.xyz());
    let albedo = materials[hit.material as usize].albedo.xyz();
    let eps = 1e-4 * point.abs().max_element().max(1.0);
    let shade = under::sun_visibility(p, &sunlit.geometry, point + normal * eps);
    let focus = caustics::shaft_at(p, sunlit.shafts, point, 0.0);
    under::lambert_leaving(p, depth, cos_gamma, albedo) * focus * shade * (-p.extinction.xyz() * hit.distance).exp()
}

/// The weight of layer `j + 1` for a bottom at `depth` between layers `j`
/// and `j + 1`, per channel: linear in `1 - e^(-2 c d)`, the share of a
/// slab's light that a bottom at `d` leaves (the order-2 radiance saturates
/// with depth much like it); where the two layers' shares are within 1e-6
/// (both deep in that channel) the log-depth weight `w`.
fn saturation_weight(p: &SeaParams, depth: f32, j: u32, w: f32) -> Vec3 {
    let c = p.extinction.xyz() * 2.0;
    let s = |d: f32| Vec3::ONE - (-c * d).exp();
    let (a, b, x) = (s(layer_depth(p, j)), s(layer_depth(p, j + 1)), s(depth));
    let span = b - a;
    let weight = |x: f32, a: f32, span: f32| if span > 1e-6 { ((x - a) / span).clamp(0.0, 1.0) } else { w };
    Vec3::new(weight(x.x, a.x, span.x), weight(x.y, a.y, span.y), weight(x.z, a.z, span.z))
}

/// The cubic through `(xs[i], ys[i])` at `x`, or `fallback` where two nodes
/// lie within 1e-5 of each other (a channel saturated over those layers).
fn lagrange4(x: f32, xs: [f32; 4], ys: [f32; 4], fallback: f32) -> f32 {
    let [x0, x1, x2, x3] = xs;
    let (d01, d02, d03, d12, d13, d23) = (x0 - x1, x0 - x2, x0 - x3, x1 - x2, x1 - x3, x2 - x3);
    let smallest = d01.abs().min(d02.abs()).min(d03.abs()).min(d12.abs()).min(d13.abs()).min(d23.abs());
    if smallest < 1e-5 {
        return fallback;
    }
    let l0 = (x - x1) * (x - x2) * (x - x3) / (d01 * d02 * d03);
    let l1 = (x - x0) * (x - x2) * (x - x3) / (-d01 * d12 * d13);
    let l2 = (x - x0) * (x - x1) * (x - x3) / (-d02 * -d12 * d23);
    let l3 = (x - x0) * (x - x1) * (x - x2) / (-d03 * -d13 * -d23);
    l0 * ys[0] + l1 * ys[1] + l2 * ys[2] + l3 * ys[3]
}

/// The order-2 radiance arriving at the surface from below along upward
/// `view` (the accumulated map; over a varying bottom between the layers
/// whose bottoms bracket `depth`, the bottom's depth along the view ray:
/// linear, or a cubic in each channel's saturation where four layers
/// surround it).
pub fn accumulated_toward(p: &SeaParams, accumulated: &[Vec4], depth: f32, view: Vec3) -> Vec3 {
    let at = map_coords(p, view);
    let mut value = scattering_map_lookup(p, accumulated, 0, at);
    if p.layers > 1 {
        let (j, w) = layer_at(p, depth);
        let (a, b) = (scattering_map_lookup(p, accumulated, j, at), scattering_map_lookup(p, accumulated, j + 1, at));
        let linear = saturation_weight(p, depth, j, w);
        value = a * (Vec3::ONE - linear) + b * linear;
        if j >= 1 && j + 2 < p.layers {
            // Four layers around the depth: a cubic in each channel's saturation.
            let (before, after) =
                (scattering_map_lookup(p, accumulated, j - 1, at), scattering_map_lookup(p, accumulated, j + 2, at));
            let c = p.extinction.xyz() * 2.0;
            let x = Vec3::ONE - (-c * depth).exp();
            let node = |k: u32| Vec3::ONE - (-c * layer_depth(p, k)).exp();
            let cubic = Vec3::new(
                lagrange4(
                    x.x,
                    [node(j - 1).x, node(j).x, node(j + 1).x, node(j + 2).x],
                    [before.x, a.x, b.x, after.x],
                    value.x,
                ),
                lagrange4(
                    x.y,
                    [node(j - 1).y, node(j).y, node(j + 1).y, node(j + 2).y],
                    [before.y, a.y, b.y, after.y],
                    value.y,
                ),
                lagrange4(
                    x.z,
                    [node(j - 1).z, node(j).z, node(j + 1).z, node(j + 2).z],
                    [before.z, a.z, b.z, after.z],
                    value.z,
                ),
            );
            value = cubic.max(Vec3::ZERO);
        }
    }
    value
}

/// Per-pixel kernel, `sea.order2`: second-order scattering, the
/// accumulated map looked up toward the eye (between the two layers whose
/// bottoms bracket the depth under the pixel, for a varying bottom), above
/// the surface. Under water, the scattering maps' source gathered along
/// the view ray (`under::order2_segment`) and, where it meets the surface,
/// the order-2 light the surface reflects toward the eye, attenuated.
#[allow(clippy::too_many_arguments)]
pub fn order2_pixel(
    index: u32,
    common: &CommonParams,
    p: &SeaParams,
    surface: Vec4,
    bottom: &[f32],
    maps: &[Vec4],
    accumulated: &[Vec4],
    correction: &[Vec4],
    clouds: &CloudShadow,
) -> Vec4 {
    if p.underwater != 0 {
        let v = under::decode(index, common, p, surface);
        if v.end == under::END_NONE {
            return Vec4::ZERO;
        }
        let above = Vec3::new(v.origin.x, p.level, v.origin.z);
        let gathered = if under::eye_block(p) && v.end != under::END_OBJECT {
            // The whole ray: the eye's block of the accumulated map.
            scattering_map_lookup(p, accumulated, p.layers, map_coords(p, -v.dir))
        } else {
            let under_eye = under::depth_under(p, bottom, v.origin);
            under::order2_segment(p, maps, v.dir, p.camera_depth, v.length, under_eye)
        };
        let mut light = gathered * clouds.at(p, above);
        if v.end == under::END_SURFACE {
            let (depth, _) = under::reflected_bottom(p, bottom, &v);
            let up = accumulated_toward(p, accumulated, depth, v.up) * clouds.at(p, v.end_point());
            light += up * v.reflectance * under::attenuation(p, &v);
        }
        return light.extend(0.0);
    }
    let v = seen_from(index, common, p, surface);
    if !v.hit {
        return Vec4::ZERO;
    }
    let (depth, _) = bottom_hit(p, bottom, v.point.x, v.point.z, v.view);
    let mut value = accumulated_toward(p, accumulated, depth, v.view);
    if p.layers > 1 && p.table_width > 0 {
        // Section 5.4: the depth table's correction for the bottom along
        // every sampling ray rather than flat under the view ray.
        let offset = sample_offset(common.sample_index, common.samples_per_pixel);
        let position = Vec2::new((index % common.width) as f32, (index / common.width) as f32) + offset;
        value = (value + crate::sea::table::correction_at(p, common, correction, position)).max(Vec3::ZERO);
    }
    (value * v.transmission * clouds.at(p, v.point)).extend(0.0)
}

/// Per-pixel kernel, `sea.bottom`: the bottom's reflection of the refracted
/// sunlight (eq. 9 with `1/pi`) where the view ray meets it, above the
/// surface, or an object's where the ray meets one first
/// (`object_radiance`). Under water, where the view ray meets the bottom
/// (`under::bottom_leaving`) or its reflection in the surface, attenuated.
#[allow(clippy::too_many_arguments)]
pub fn bottom_pixel(
    index: u32,
    common: &CommonParams,
    p: &SeaParams,
    surface: Vec4,
    bottom: &[f32],
    caustic: &[u32],
    sunlit: &under::Sunlit,
    materials: &[GpuMaterial],
    clouds: &CloudShadow,
) -> Vec4 {
    let geometry = &sunlit.geometry;
    if p.underwater != 0 {
        let v = under::decode(index, common, p, surface);
        let light = if v.end == under::END_BOTTOM {
            let (depth, cos_gamma) = under::bottom_at(p, bottom, &v);
            let q = v.end_point();
            under::bottom_leaving(p, depth, cos_gamma)
                * bottom_focus(p, caustic, sunlit.shafts, q)
                * under::sun_visibility(p, geometry, q)
        } else if v.end == under::END_SURFACE {
            // The bottom mirrored, or an object in the water the reflected
            // ray meets before it (`bottom_seen`, with the cloud shadow at
            // the surface point).
            let seen = bottom_seen(p, &mirrored(&v), bottom, caustic, sunlit, materials, clouds);
            return (seen * v.reflectance * under::attenuation(p, &v)).extend(0.0);
        } else {
            return Vec4::ZERO;
        };
        let point = v.end_point();
        let above = Vec3::new(point.x, p.level, point.z);
        return (light * under::attenuation(p, &v) * clouds.at(p, above)).extend(0.0);
    }
    let v = seen_from(index, common, p, surface);
    if !v.hit {
        return Vec4::ZERO;
    }
    bottom_seen(p, &v, bottom, caustic, sunlit, materials, clouds).extend(0.0)
}

/// The bottom (eq. 9 with the waves' caustic) or an object under the
/// surface, seen through the surface where `v` (from `refracted`) meets
/// it, rgb.
pub fn bottom_seen(
    p: &SeaParams,
    v: &SeaView,
    bottom: &[f32],
    caustic: &[u32],
    sunlit: &under::Sunlit,
    materials: &[GpuMaterial],
    clouds: &CloudShadow,
) -> Vec3 {
    let geometry = &sunlit.geometry;
    let (depth, cos_gamma) = bottom_hit(p, bottom, v.point.x, v.point.z, v.view);
    let object = object_under(v, depth, geometry);
    let light = if object.distance != NO_HIT {
        object_radiance(p, v, &object, sunlit, materials)
    } else if depth >= DEEP {
        Vec3::ZERO
    } else {
        // Where the view ray meets the bottom: the waves' caustic there.
        let q = v.point - v.view * (depth / v.view.y);
        let focus = bottom_focus(p, caustic, sunlit.shafts, q) * under::sun_visibility(p, geometry, q);
        bottom_radiance(p, v.view, depth, cos_gamma) * focus
    };
    light * v.transmission * clouds.at(p, v.point)
}

/// The waves' focusing of the sun at the bottom point `q` (scene
/// coordinates, m): the bottom's caustic map over a flat bottom
/// (`caustics::caustic_at`; 1 with `caustics = false`), over a varying
/// bottom the shaft planes' caustic at the point's depth
/// (`caustics::shaft_at`; 1 without planes).
pub fn bottom_focus(p: &SeaParams, caustic: &[u32], shafts: &[Vec4], q: Vec3) -> Vec3 {
    if p.bottom_nx >= 2 {
        caustics::shaft_at(p, shafts, q, 0.0)
    } else {
        caustics::caustic_at(p, caustic, q.x, q.z)
    }
}

#[spirv(compute(threads(64)))]
pub fn radiance_map_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 21)] map: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < p.layers * radiance_map_len(p) {
        map[index as usize] = radiance_map_texel(index, p);
    }
}

#[spirv(compute(threads(64)))]
pub fn scattering_maps_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 21)] radiance_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 22)] maps: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < p.layers * p.planes * p.map_width * p.map_height {
        maps[index as usize] = scattering_map_texel(index, p, radiance_map);
    }
}

#[spirv(compute(threads(64)))]
pub fn accumulated_map_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 22)] maps: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 27)] accumulated: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < accumulated_blocks(p) * p.map_width * p.map_height {
        accumulated[index as usize] = accumulated_map_texel(index, p, maps);
    }
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn surface_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 20)] waves: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 28)] bottom: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 68)] surface: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        surface[index as usize] =
            surface_pixel(common.band_start + index, common, &params[0], waves, bottom, &gbuffer[index as usize]);
    }
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn reflection_kernel(
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
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[crate::types::GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[crate::types::GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[crate::types::GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] shadow: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 62)] irradiance: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 23)] radiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let clouds = CloudShadow { lights, grids, depths };
        let above = air::Above {
            common,
            geometry: crate::scene_geometry(common, spheres, triangles, nodes),
            materials,
            lights,
            inputs: crate::common::surface::LightInputs { light_map, shadow, grids, depths },
            sky: &sky[0],
            transmittance,
            sky_view,
            irradiance,
        };
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
            &above,
        );
    }
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn order1_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 68)] surface: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 28)] bottom: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 78)] shafts: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[crate::types::GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[crate::types::GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[crate::types::GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 88)] samples: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 24)] radiance: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let clouds = CloudShadow { lights, grids, depths };
        let sunlit = under::Sunlit { shafts, geometry: crate::scene_geometry(common, spheres, triangles, nodes) };
        radiance[index as usize] = order1_pixel(
            common.band_start + index,
            common,
            &params[0],
            surface[index as usize],
            bottom,
            samples,
            &sunlit,
            &clouds,
        );
    }
}

/// `sea.shaft_samples`: the shafts' ratio and the shade signature at
/// every `shaft_stride`-th pixel (`under::shaft_sample`), two values a pixel.
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn shaft_samples_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 68)] surface: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 78)] shafts: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[crate::types::GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[crate::types::GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[crate::types::GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 88)] samples: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let sunlit = under::Sunlit { shafts, geometry: crate::scene_geometry(common, spheres, triangles, nodes) };
        let (ratio, shade) =
            under::shaft_sample(common.band_start + index, common, &params[0], surface[index as usize], &sunlit);
        samples[2 * index as usize] = ratio;
        samples[2 * index as usize + 1] = shade;
    }
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn order2_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 68)] surface: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 22)] maps: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 27)] accumulated: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 28)] bottom: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 38)] correction: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 25)] radiance: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let clouds = CloudShadow { lights, grids, depths };
        radiance[index as usize] = order2_pixel(
            common.band_start + index,
            common,
            &params[0],
            surface[index as usize],
            bottom,
            maps,
            accumulated,
            correction,
            &clouds,
        );
    }
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn bottom_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 68)] surface: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 28)] bottom: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 77)] caustic: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 78)] shafts: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[crate::types::GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[crate::types::GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[crate::types::GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 26)] radiance: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let clouds = CloudShadow { lights, grids, depths };
        let (i, p) = (index as usize, &params[0]);
        let sunlit = under::Sunlit { shafts, geometry: crate::scene_geometry(common, spheres, triangles, nodes) };
        radiance[i] = bottom_pixel(
            common.band_start + index,
            common,
            p,
            surface[i],
            bottom,
            caustic,
            &sunlit,
            materials,
            &clouds,
        );
    }
}

/// The waves' caustic map (`caustics`): two invocations per wave-grid cell.
/// GPU only: on the host the words are `AtomicU32`s (`scatter::CpuAtomics`).
#[cfg(target_arch = "spirv")]
#[spirv(compute(threads(64)))]
pub fn wave_caustics_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 89)] rays: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 77)] words: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < caustics::caustic_triangles(p) {
        caustics::caustic_triangle(index, p, rays, words);
    }
}

/// The sun refracted once at every grid point of the caustic maps' meshes
/// (`caustics::caustic_ray`), two values a point.
#[spirv(compute(threads(64)))]
pub fn wave_caustic_rays_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 20)] waves: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 89)] rays: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < caustics::caustic_points(p) {
        let (offset, flux) = caustics::caustic_ray(index, p, waves);
        rays[2 * index as usize] = offset;
        rays[2 * index as usize + 1] = flux;
    }
}

/// The shaft planes' maps and their mips from the caustic words
/// (`caustics::shaft_mip_texel`).
#[spirv(compute(threads(64)))]
pub fn shaft_maps_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 77)] words: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 78)] shafts: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < caustics::shaft_map_len(p) {
        shafts[index as usize] = caustics::shaft_mip_texel(index, p, words);
    }
}

/// Per-pixel kernel, `sea.water`: for an eye under water, what the water
/// does to the light of the object the sample sees (`under::water_transmittance`).
/// For an eye above it, 0 where the straight view ray meets the water
/// before the object it reaches (that object's light in air is not what
/// the eye sees: `sea.bottom` and `sea.order1` follow the refracted ray),
/// else 1.
pub fn water_pixel(
    index: u32,
    common: &CommonParams,
    p: &SeaParams,
    surface: Vec4,
    shafts: &[Vec4],
    texel: &GBufferTexel,
) -> Vec4 {
    if p.underwater == 0 {
        // (`surface.y > 0`: the sample sees the sea, as `seen_from` reads it.)
        let under_the_sea = texel.object != NO_OBJECT && surface.y > 0.0;
        return if under_the_sea { Vec4::ZERO } else { Vec4::ONE };
    }
    under::water_transmittance(p, shafts, &under::decode(index, common, p, surface), texel.object != NO_OBJECT)
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn water_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 68)] surface: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 78)] shafts: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 76)] water: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let i = index as usize;
        water[i] = water_pixel(common.band_start + index, common, &params[0], surface[i], shafts, &gbuffer[i]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Clear ocean water (blue-green), a low sun, 40 m deep.
    fn water(g: f32, depth: f32) -> SeaParams {
        let sun = Vec3::new(0.5, -0.8, 0.2).normalize();
        let c = Vec3::new(0.45, 0.07, 0.03);
        SeaParams {
            sun_direction: Vec4::new(0.0, 1.0, 0.0, 1.0),
            sun_in_water: sun.extend(-sun.y),
            beam_irradiance: Vec4::new(1.0, 1.0, 1.0, 1.0),
            scattering: Vec4::new(0.003, 0.004, 0.006, g),
            extinction: c.extend(1.333),
            order1_extinction: c.extend(0.0),
            bottom_albedo: Vec4::splat(0.5),
            plane_depth: plane_reach(c, depth).extend(0.0),
            depth,
            planes: 12,
            polar: 8,
            azimuths: 8,
            map_width: 32,
            map_height: 32,
            layers: 1,
            ..Default::default()
        }
    }

    /// The order-1 path factor by a midpoint sum along the ray (f64).
    fn path_by_sum(p: &SeaParams, z: f64, mu: f64, channel: usize) -> f64 {
        let c = p.extinction.to_array()[channel] as f64;
        let mu_s = p.sun_in_water.w as f64;
        let (from, to) = if mu > 0.0 { (z, (p.depth as f64).min(z + 400.0 / c)) } else { (0.0, z) };
        let n = 200_000;
        let h = (to - from) / n as f64;
        (0..n)
            .map(|i| {
                let zp = from + (i as f64 + 0.5) * h;
                (-c * zp / mu_s).exp() * (-c * (zp - z).abs() / mu.abs()).exp() * h / mu.abs()
            })
            .sum()
    }

    #[test]
    fn order1_path_matches_a_sum_along_the_ray_on_both_sides_of_the_singularity() {
        let p = water(0.9, 40.0);
        let mu_s = p.sun_in_water.w;
        for &mu in &[0.9f32, 0.3, 0.01, -0.05, -mu_s + 1e-4, -mu_s, -mu_s - 1e-4, -0.99] {
            for &z in &[0.0f32, 0.5, 7.0, 39.0] {
                let k = order1_path(Vec3::splat(z), mu, &p);
                for ch in 0..3 {
                    let want = path_by_sum(&p, z as f64, mu as f64, ch);
                    let got = k.to_array()[ch] as f64;
                    assert!((got - want).abs() <= 2e-4 * want.abs() + 1e-9, "mu {mu} z {z} ch {ch}: {got} vs {want}");
                }
            }
        }
    }

    #[test]
    fn forward_fraction_is_the_phase_functions_forward_half() {
        for &g in &[-0.5f32, 0.0, 1e-4, 0.3, 0.9, 0.99] {
            // Midpoints in f64 (the peak at g = 0.99 is 5e-5 wide in 1 - mu).
            let (n, g64) = (2_000_000, g as f64);
            let sum: f64 = (0..n)
                .map(|i| {
                    let mu = (i as f64 + 0.5) / n as f64;
                    let hg = (1.0 - g64 * g64) / (2.0 * (1.0 + g64 * g64 - 2.0 * g64 * mu).powf(1.5));
                    hg / n as f64
                })
                .sum();
            assert!((forward_fraction(g) as f64 - sum).abs() < 2e-4, "g {g}: {} vs {sum}", forward_fraction(g));
        }
    }

    #[test]
    fn a_direction_set_is_distributed_like_the_phase_function() {
        // The mean cosine to the axis of Henyey-Greenstein is g.
        for &g in &[0.0f32, 0.5, 0.9] {
            let axis = Vec3::new(0.3, -0.9, 0.1).normalize();
            let (polar, azimuths) = (64, 8);
            let mean: f32 =
                (0..polar * azimuths).map(|j| set_direction(axis, j, polar, azimuths, g).dot(axis)).sum::<f32>()
                    / (polar * azimuths) as f32;
            assert!((mean - g).abs() < 2e-3, "g {g}: mean cosine {mean}");
        }
    }

    #[test]
    fn isotropic_order2_source_is_b_times_the_mean_order1_radiance() {
        // With g = 0 both sets are uniform; compare with a fine product grid.
        let mut p = water(0.0, DEEP);
        p.polar = 32;
        p.azimuths = 32;
        let view = Vec3::new(0.2, 0.9, -0.1).normalize();
        let map: Vec<Vec4> = (0..radiance_map_len(&p)).map(|i| radiance_map_texel(i, &p)).collect();
        let k = 3;
        let got = scattering_source(&p, k, view, &map, 0);
        let z = plane_depth(&p, k);
        let (nm, nphi) = (4000, 4);
        let mut want = Vec3::ZERO;
        for i in 0..nm {
            let mu = -1.0 + 2.0 * (i as f32 + 0.5) / nm as f32;
            let _ = nphi;
            let radiance = p.scattering.xyz() * (0.25 * FRAC_1_PI) * order1_path(z, mu, &p);
            want += radiance * p.scattering.xyz() * (0.25 * FRAC_1_PI) * (4.0 * PI / nm as f32);
        }
        for ch in 0..3 {
            let (g, w) = (got.to_array()[ch], want.to_array()[ch]);
            assert!((g - w).abs() < 2e-3 * w, "channel {ch}: {g} vs {w}");
        }
    }

    #[test]
    fn order2_accumulation_is_exact_where_the_source_falls_with_the_sun() {
        // A source e^(-c z/mu_s) has a constant shape s: the accumulation is
        // exact, int e^(-c z (1/mu_s + 1/mu_v)) dz/mu_v = 1/(mu_v kappa).
        let mut p = water(0.0, DEEP);
        p.map_width = 2;
        p.map_height = 2;
        p.planes = 5;
        let c = p.extinction.xyz();
        let mu_s = p.sun_in_water.w;
        let sources: Vec<Vec4> = (0..p.planes).map(|k| (-c * plane_depth(&p, k) / mu_s).exp().extend(0.0)).collect();
        let view = Vec3::new(0.3, 0.8, 0.0).normalize();
        let got = accumulate_planes(&p, view, &sources, 0, 1);
        let want = Vec3::ONE / (view.y * c * (1.0 / mu_s + 1.0 / view.y));
        for ch in 0..3 {
            let (g, w) = (got.to_array()[ch], want.to_array()[ch]);
            assert!((g - w).abs() < 1e-5 * w, "channel {ch}: {g} vs {w}");
        }
    }

    #[test]
    fn nothing_is_negative_or_non_finite_at_the_edges() {
        for &g in &[0.0f32, 0.999, -0.5] {
            for &depth in &[0.01f32, 10_000.0, DEEP] {
                let mut p = water(g, depth);
                p.planes = 4;
                p.polar = 4;
                p.azimuths = 4;
                p.map_width = 4;
                p.map_height = 4;
                for sun in [Vec3::NEG_Y, Vec3::new(0.999, -0.0447, 0.0).normalize()] {
                    p.sun_in_water = sun.extend(-sun.y);
                    let map: Vec<Vec4> = (0..radiance_map_len(&p)).map(|i| radiance_map_texel(i, &p)).collect();
                    let maps: Vec<Vec4> = (0..p.planes * 16).map(|i| scattering_map_texel(i, &p, &map)).collect();
                    let accumulated: Vec<Vec4> = (0..16).map(|i| accumulated_map_texel(i, &p, &maps)).collect();
                    for view in [Vec3::Y, Vec3::new(0.999, 1e-4, 0.0).normalize(), Vec3::new(-0.7, 0.7, 0.1)] {
                        let view = view.normalize();
                        for v in [
                            order1_radiance(&p, view, p.depth, p.extinction.xyz()),
                            scattering_map_lookup(&p, &accumulated, 0, map_coords(&p, view)),
                            bottom_radiance(&p, view, p.depth, sun.y.abs()),
                        ] {
                            assert!(v.is_finite() && v.min_element() >= 0.0, "g {g} depth {depth}: {v}");
                        }
                    }
                }
            }
        }
    }
}
