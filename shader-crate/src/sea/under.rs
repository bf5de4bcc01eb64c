//! The eye under water (issue 26; Iwasaki, Dobashi and Nishita 2002's
//! setting, with the sea paper's water, `../shared/papers/004_*`).
//!
//! An eye at depth `z_e` (m, `SeaParams::camera_depth`) looks along unit
//! `d`. Its view ray stays in the water until it meets, first, an object
//! (the G-buffer's distance), the surface (`d_y > 0`: `t = z_e / d_y`, the
//! mean level), the bottom (`d_y < 0`) or nothing (open water). Along it,
//! with `c` the extinction (1/m), the depth is `z(t) = z_e - t d_y` and
//! the pixel's radiance (W/(m^2 sr)) is
//!
//! `L = int_0^l J(z(t), -d) e^(-c t) dt + e^(-c l) L_end`
//!
//! - `J` of order 1 is `beta(theta) E_w e^(-c z/mu_s)` (the sea's eq. 2 and
//!   its flat-surface sun beam), integrated in closed form
//!   (`order1_segment`: eq. 5 along any segment);
//! - `J` of order 2 is the scattering maps' source (eq. 6 and 8), whose
//!   texels cover every direction toward an eye under water (`map_zenith`:
//!   the whole sphere rather than the upward half), read between the
//!   sampling planes and integrated along the ray (`order2_segment`);
//! - `L_end` at the surface, seen from below at a normal `n` (the wave
//!   slopes' mean under the sample's footprint): the sky and the sun seen
//!   through Snell's window, `(1 - R) n_w^2 L_air` along the refracted ray
//!   (radiance gains `n_w^2` entering the denser medium), plus the water
//!   below reflected, `R L_up`, where `R` is Fresnel's from the water side
//!   (1 past the critical angle: total internal reflection) and `L_up` the
//!   light arriving at the surface from below along the reflected ray's
//!   reverse: exactly what the sea passes compute for an eye above water
//!   (orders 1 and 2 and the bottom toward the surface);
//! - `L_end` at the bottom: the refracted sun reflected by the Lambertian
//!   bottom, `E_w e^(-c z_b/mu_s) cos(gamma) albedo/pi` (eq. 9 without the
//!   way up);
//! - at an object, its own layer times `e^(-c l)` (the `sea.water`
//!   pass's transmittance layer).
//!
//! The sun inside the water is the flat surface's refracted beam, as
//! everywhere in the sea passes (the paper's section 3), except where
//! the waves' focusing of it is built (`caustics`): on a flat bottom (its
//! caustic map) and, with shafts, along the view ray in order 1
//! (`order1_shafts`) and on the objects (`water_transmittance`). Order 2
//! and the light the surface reflects down keep the flat beam.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use super::caustics;
use super::surface;
use super::{
    bottom_depth, bottom_hit, exp_linear3, layer_at, layer_params, map_coords, march_to_bottom, phi3, plane_depth,
    MapCoords, SeaParams, DEEP, WAVES_NORMAL_MAP,
};
use crate::camera::{camera_ray, in_image};
use crate::geometry::{occluded, Geometry};
use crate::glam::{Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::optics::{reflect, reflectance, refract};
use crate::phase::henyey_greenstein;
use crate::types::{CommonParams, GBufferTexel, NO_OBJECT};
use core::f32::consts::{FRAC_1_PI, PI};

/// Where an underwater view ray ends (`UnderView::end`).
pub const END_NONE: u32 = 0;
pub const END_OPEN: u32 = 1;
pub const END_BOTTOM: u32 = 2;
pub const END_OBJECT: u32 = 3;
pub const END_SURFACE: u32 = 4;

/// The most steps of `order2_segment`'s integral along the view ray.
pub const ORDER2_STEPS: u32 = 24;

/// Optical length (in the clearest channel's extinction) past which
/// `order2_segment` stops: the rest adds under `e^-12` of the source's.
pub const ORDER2_REACH: f32 = 12.0;

/// What an underwater eye's view ray meets.
#[derive(Copy, Clone, Debug, Default)]
pub struct UnderView {
    /// `END_*`.
    pub end: u32,
    /// The eye and the ray's unit direction.
    pub origin: Vec3,
    pub dir: Vec3,
    /// Distance to the end, m (`DEEP` in open water).
    pub length: f32,
    /// At the surface: the upward unit direction of travel of the light
    /// that the surface reflects toward the eye (the reflected view ray
    /// reversed), and the reflectance `R` from the water side.
    pub up: Vec3,
    pub reflectance: f32,
}

impl UnderView {
    /// Where the ray ends.
    pub fn end_point(&self) -> Vec3 {
        self.origin + self.dir * self.length.min(1e7)
    }

    /// The unit normal the surface reflected the view ray at (`d - r` is
    /// along it for a mirror).
    pub fn surface_normal(&self) -> Vec3 {
        let n = self.dir + self.up;
        if n.length_squared() < 1e-12 {
            return Vec3::Y;
        }
        n.normalize()
    }

    /// The form `sea.surface` keeps per sample: at the surface
    /// `(up, R)` (`up.y > 0`), elsewhere `(end, -1, 0, length)` (length 0
    /// in open water, where it is `DEEP`), and zero for no sample.
    pub fn encode(&self) -> Vec4 {
        if self.end == END_SURFACE {
            return self.up.extend(self.reflectance);
        }
        if self.end == END_NONE {
            return Vec4::ZERO;
        }
        // Open water keeps no length (`DEEP` would set the scale the
        // backends' values are compared at).
        let length = if self.end == END_OPEN { 0.0 } else { self.length };
        Vec4::new(self.end as f32, -1.0, 0.0, length)
    }
}

/// `UnderView::encode` read back for pixel `index`'s current sample.
pub fn decode(index: u32, common: &CommonParams, p: &SeaParams, v: Vec4) -> UnderView {
    let (origin, dir) = camera_ray(common, index % common.width, index / common.width);
    let mut out = UnderView { origin, dir, ..Default::default() };
    if v.y > 0.0 {
        out.end = END_SURFACE;
        out.length = p.camera_depth.max(0.0) / dir.y.max(1e-12);
        out.up = v.xyz();
        out.reflectance = v.w;
    } else if v.y < 0.0 {
        out.end = v.x as u32;
        out.length = if out.end == END_OPEN { DEEP } else { v.w };
    }
    out
}

/// The view ray of pixel `index`'s current sample from an eye under water
/// (see the module's text): what it meets first and how far; at the
/// surface the normal is the mean of the wave slopes under the sample's
/// footprint (`surface::footprint_slopes`; up for a flat sea). A varying
/// bottom is found by `march_to_bottom` on the way down (a ray going up
/// meets only the surface or objects).
pub fn under_ray(
    index: u32,
    common: &CommonParams,
    p: &SeaParams,
    waves: &[Vec4],
    grid: &[f32],
    texel: &GBufferTexel,
) -> UnderView {
    let (x, y) = (index % common.width, index / common.width);
    let mut out = UnderView::default();
    if !in_image(common, x, y) {
        return out;
    }
    let (origin, dir) = camera_ray(common, x, y);
    let z_e = p.camera_depth.max(0.0);
    out.origin = origin;
    out.dir = dir;
    out.end = END_OPEN;
    out.length = DEEP;
    if texel.object != NO_OBJECT {
        out.end = END_OBJECT;
        out.length = texel.normal_distance.w;
    }
    if dir.y > 0.0 {
        let t = z_e / dir.y;
        if t < out.length {
            out.end = END_SURFACE;
            out.length = t;
        }
    } else if dir.y < 0.0 {
        let t = bottom_distance(p, grid, origin, dir, out.length);
        if t >= 0.0 && t < out.length {
            out.end = END_BOTTOM;
            out.length = t;
        }
    }
    if out.end == END_SURFACE {
        let point = origin + dir * out.length;
        let mut normal = Vec3::Y;
        if p.waves == WAVES_NORMAL_MAP {
            let (a, b) = if p.wave_filter != 0 {
                surface::footprint(common, x, y, dir, out.length, 2.0 * p.wave_size)
            } else {
                (Vec2::ZERO, Vec2::ZERO)
            };
            let slopes = surface::footprint_slopes(p, waves, point.x, point.z, a, b);
            normal = surface::slope_normal(slopes.mean());
            if normal.dot(dir) < 1e-4 {
                // A facet turned away from the ray is met edge-on: the mean surface.
                normal = Vec3::Y;
            }
        }
        out.reflectance = reflectance(dir.dot(normal), p.extinction.w);
        let up = -reflect(dir, normal);
        out.up = if up.y < 1e-4 { Vec3::new(up.x, 1e-4, up.z).normalize() } else { up };
    }
    out
}

/// How far the downward ray from `origin` along `dir` (`dir.y < 0`) goes
/// before it meets the bottom, m, within `limit`; -1 where it does not.
pub fn bottom_distance(p: &SeaParams, grid: &[f32], origin: Vec3, dir: Vec3, limit: f32) -> f32 {
    let z_e = p.camera_depth.max(0.0);
    let down = -dir.y;
    if p.bottom_nx < 2 {
        if p.depth >= DEEP {
            return -1.0;
        }
        return (p.depth - z_e).max(0.0) / down;
    }
    let c_min = p.extinction.x.min(p.extinction.y).min(p.extinction.z);
    // Past 40 optical depths of the clearest channel the bottom adds nothing in f32.
    let reach = if c_min > 0.0 { 40.0 / c_min } else { 1e6 };
    let t_max = ((p.bottom_grid.w - z_e).max(0.0) / down).min(limit).min(reach);
    march_to_bottom(p, grid, origin.x, origin.z, z_e, -dir, t_max, 2048)
}

/// Eq. 5 along a segment: the sun's single scattering gathered toward an
/// eye at depth `z_e` (m) along its view ray `dir` over `length` m, with
/// extinction `c` (1/m), W/(m^2 sr):
/// `beta(theta) E_w int_0^l e^(-a(t)) dt`, `a(t) = c z(t)/mu_s + c t`
/// linear in `t`, so the integral is `l e^(-min(a_0, a_l)) phi(|a_l - a_0|)`
/// (no exponential grows, whichever way the ray goes).
pub fn order1_segment(p: &SeaParams, dir: Vec3, z_e: f32, length: f32, c: Vec3) -> Vec3 {
    let mu_s = p.sun_in_water.w;
    let beta = p.scattering.xyz() * henyey_greenstein(-p.sun_in_water.xyz().dot(dir), p.scattering.w);
    let a0 = c * (z_e / mu_s);
    let a1 = a0 + c * ((1.0 - dir.y / mu_s) * length);
    beta * p.beam_irradiance.xyz() * (length * (-a0.min(a1)).exp() * phi3((a1 - a0).abs()))
}

/// The most taps `shafts_over` takes along one step.
pub const SHAFT_TAPS: u32 = 4;

/// Optical length (in the clearest channel's order-1 extinction) that
/// `order1_shafts` steps through; the rest, under `e^-8` of the first
/// step's weight, is the flat beam's closed form.
pub const SHAFT_REACH: f32 = 8.0;

/// Order 1 with the waves' caustic light shafts (issue 26; Iwasaki,
/// Dobashi and Nishita 2002's virtual planes): eq. 5's integrand along the
/// view ray times the caustic ratio `C(x)` of the refracted sun's
/// irradiance to the flat beam's (`caustics::shaft_at`, W/m^2 over W/m^2),
///
/// `int_0^l beta(theta) E_w e^(-a(t)) C(x(t)) dt`, `a(t) = c z(t)/mu_s + c t`,
///
/// over `K = shaft_steps` intervals graded from the eye (`t_k = T (k/K)^2`,
/// `T` the length or `SHAFT_REACH` optical lengths, whichever is
/// shorter): each interval's exact integral of the exponential (energy
/// conserving whatever its length, as `order1_segment`) times `C` at its
/// middle, averaged over how far the interval moves across the shafts
/// (`caustics::shaft_drift`); past `T` the flat beam's. With `C = 1` it is
/// `order1_segment` over the whole ray; without shafts or objects it is
/// that. Objects shade each interval by a shadow ray from its middle
/// (`sun_visibility`): their shadows in the water's light, with the shafts
/// or in the flat beam (`C = 1`).
pub fn order1_shafts(p: &SeaParams, sunlit: &Sunlit, origin: Vec3, dir: Vec3, z_e: f32, length: f32, c: Vec3) -> Vec3 {
    if p.shaft_planes == 0 && sunlit.geometry.is_empty() {
        return order1_segment(p, dir, z_e, length, c);
    }
    let mu_s = p.sun_in_water.w;
    let beta = p.scattering.xyz() * henyey_greenstein(-p.sun_in_water.xyz().dot(dir), p.scattering.w);
    let source = beta * p.beam_irradiance.xyz();
    let c_min = c.x.min(c.y).min(c.z);
    let reach = if c_min > 0.0 { SHAFT_REACH / c_min } else { 1e6 };
    let end = length.min(reach);
    let drift = caustics::shaft_drift(p, dir);
    // a(t) = a0 + kappa t, never negative along the ray in the water.
    let a0 = c * (z_e / mu_s);
    let kappa = c * (1.0 - dir.y / mu_s);
    let mut e_a = (-a0).exp();
    let mut sum = Vec3::ZERO;
    let mut t_a = 0.0;
    let mut k = 1;
    let steps = p.shaft_steps.max(1);
    while k <= steps {
        let u = k as f32 / steps as f32;
        let t_b = end * u * u;
        let dt = t_b - t_a;
        let e_b = (-(a0 + kappa * t_b)).exp();
        let delta = (kappa * dt).abs();
        let piece = Vec3::new(
            interval(dt, e_a.x, e_b.x, delta.x),
            interval(dt, e_a.y, e_b.y, delta.y),
            interval(dt, e_a.z, e_b.z, delta.z),
        );
        let shade = sun_visibility(p, &sunlit.geometry, origin + dir * (t_a + 0.5 * dt));
        let focus = if p.shaft_planes > 0 {
            shafts_over(p, sunlit.shafts, origin + dir * t_a, dir * dt, dt * drift)
        } else {
            Vec3::ONE
        };
        sum += piece * focus * shade;
        t_a = t_b;
        e_a = e_b;
        k += 1;
    }
    sum *= source;
    if length > end {
        let z_a = (z_e - end * dir.y).max(0.0);
        sum += order1_segment(p, dir, z_a, length - end, c) * (-c * end).exp();
    }
    sum
}

/// Whether `order1_shafts` is sampled every `shaft_stride` pixels and
/// interpolated between (`shaft_sample`, `order1_upsampled`): under water,
/// where it does more than the closed form (shafts or objects' shadows).
pub fn shafts_sampled(p: &SeaParams, geometry: &Geometry) -> bool {
    p.underwater != 0 && p.shaft_stride > 1 && !(p.shaft_planes == 0 && geometry.is_empty())
}

/// Relative difference of two samples' lengths (`shaft_sample`'s w) within
/// which one stands for the other: the ratio is a weighted mean over the
/// ray, and rays 10 % apart in length past an object's edge or the
/// surface's horizon are left to be gathered whole.
pub const SHAFT_SAMPLE_LENGTH_TOLERANCE: f32 = 0.1;

/// How far along the view ray `order1_shafts` looks before the flat tail
/// (m): the ray's length up to `SHAFT_REACH` optical lengths.
fn shaft_reach_length(p: &SeaParams, length: f32) -> f32 {
    let c = p.order1_extinction.xyz();
    let c_min = c.x.min(c.y).min(c.z);
    let reach = if c_min > 0.0 { SHAFT_REACH / c_min } else { 1e6 };
    length.min(reach)
}

/// Whether the sun reaches two points of the view ray, at 0.5 and 0.94 of
/// the length `order1_shafts` gathers over (`shaft_reach_length`): the
/// objects' shadows a pixel's ray crosses, told cheaply. Where it looks
/// along the sun's beam past an object (a raft against the sun), its
/// whole ray is in the shadow and its neighbours' are not, though all end
/// at the surface alike: the two visibilities tell them apart. (1, 1)
/// without objects, at no cost.
pub fn shade_signature(p: &SeaParams, geometry: &Geometry, origin: Vec3, dir: Vec3, length: f32) -> Vec2 {
    let l = shaft_reach_length(p, length);
    Vec2::new(
        sun_visibility(p, geometry, origin + dir * (0.5 * l)),
        sun_visibility(p, geometry, origin + dir * (0.94 * l)),
    )
}

/// No sample (`shaft_sample`'s first value's w).
const NO_SAMPLE: Vec4 = Vec4::new(0.0, 0.0, 0.0, -1.0);

/// The per-pixel values of `sea.shaft_samples`: at every `shaft_stride`-th
/// pixel each way (`x` and `y` multiples of it), first the ratio of the
/// view ray's order 1 with the shafts and the objects' shadows
/// (`order1_shafts`) to the flat beam's closed form (`order1_segment`),
/// rgb (dimensionless), and w the length it was gathered over (m, up to
/// `SHAFT_REACH` optical lengths); second its `shade_signature` (xy).
/// Elsewhere, and where the ray sees no water, w = -1.
pub fn shaft_sample(index: u32, common: &CommonParams, p: &SeaParams, surface: Vec4, sunlit: &Sunlit) -> (Vec4, Vec4) {
    let s = p.shaft_stride.max(1);
    let (x, y) = (index % common.width, index / common.width);
    if x % s != 0 || y % s != 0 {
        return (NO_SAMPLE, Vec4::ZERO);
    }
    let v = decode(index, common, p, surface);
    if v.end == END_NONE {
        return (NO_SAMPLE, Vec4::ZERO);
    }
    let c1 = p.order1_extinction.xyz();
    let full = order1_shafts(p, sunlit, v.origin, v.dir, p.camera_depth, v.length, c1);
    let flat = order1_segment(p, v.dir, p.camera_depth, v.length, c1);
    let signature = shade_signature(p, &sunlit.geometry, v.origin, v.dir, v.length);
    (ratio(full, flat).extend(shaft_reach_length(p, v.length)), signature.extend(0.0).extend(0.0))
}

/// `full / flat` per channel, 1 where the flat beam sends nothing.
fn ratio(full: Vec3, flat: Vec3) -> Vec3 {
    Vec3::new(ratio1(full.x, flat.x), ratio1(full.y, flat.y), ratio1(full.z, flat.z))
}

fn ratio1(a: f32, b: f32) -> f32 {
    if b > 1e-30 {
        a / b
    } else {
        1.0
    }
}

/// Order 1 along the view ray of `v` (pixel `index`'s sample) from
/// `sea.shaft_samples`' ratios: the flat beam's closed form
/// (`order1_segment`) times the ratio bilinear between the four samples
/// around the pixel (`samples`, this band's, two values a pixel), when
/// all four it weighs were gathered over lengths within
/// `SHAFT_SAMPLE_LENGTH_TOLERANCE` of its own and share its
/// `shade_signature`; otherwise (an object's silhouette, its shadow's
/// edge seen along the beam, the surface's horizon, the image's or the
/// band's last rows and columns) `order1_shafts` itself. W/(m^2 sr), rgb.
pub fn order1_upsampled(
    p: &SeaParams,
    common: &CommonParams,
    index: u32,
    samples: &[Vec4],
    sunlit: &Sunlit,
    v: &UnderView,
) -> Vec3 {
    let c1 = p.order1_extinction.xyz();
    let s = p.shaft_stride.max(1);
    let (x, y) = (index % common.width, index / common.width);
    let (x0, y0) = (x - x % s, y - y % s);
    let (fx, fy) = ((x - x0) as f32 / s as f32, (y - y0) as f32 / s as f32);
    let own = shaft_reach_length(p, v.length);
    let signature = shade_signature(p, &sunlit.geometry, v.origin, v.dir, v.length);
    let mut sum = Vec3::ZERO;
    let mut all = true;
    let mut corner = 0;
    while corner < 4 {
        let (dx, dy) = (corner & 1, corner >> 1);
        let w = if dx == 1 { fx } else { 1.0 - fx } * if dy == 1 { fy } else { 1.0 - fy };
        if w > 0.0 {
            let (cx, cy) = (x0 + dx * s, y0 + dy * s);
            let at = cy * common.width + cx;
            let inside = cx < common.width && at >= common.band_start && at - common.band_start < common.band_pixels;
            let (sample, shade) = if inside {
                let k = 2 * (at - common.band_start) as usize;
                (samples[k], samples[k + 1])
            } else {
                (NO_SAMPLE, Vec4::ZERO)
            };
            let alike = sample.w >= 0.0
                && (sample.w - own).abs() <= SHAFT_SAMPLE_LENGTH_TOLERANCE * own
                && shade.x == signature.x
                && shade.y == signature.y;
            if !alike {
                all = false;
            }
            sum += sample.xyz() * w;
        }
        corner += 1;
    }
    if all {
        return order1_segment(p, v.dir, p.camera_depth, v.length, c1) * sum;
    }
    order1_shafts(p, sunlit, v.origin, v.dir, p.camera_depth, v.length, c1)
}

/// What lights the water with shafts: the shaft maps and the objects that
/// shade the sun (`order1_shafts`).
pub struct Sunlit<'a> {
    pub shafts: &'a [Vec4],
    pub geometry: Geometry<'a>,
}

/// Whether the sun reaches `point` in the water (1) or an object is in the
/// way (0): a shadow ray up the refracted beam to the surface, and on
/// toward the sun in the air (an object above the surface shades the water
/// too). 1 without objects, at no cost. (A point's own shadow: the shafts
/// paper's shadow test, here per sample rather than from a shadow map.)
pub fn sun_visibility(p: &SeaParams, geometry: &Geometry, point: Vec3) -> f32 {
    if geometry.is_empty() {
        return 1.0;
    }
    let up = -p.sun_in_water.xyz();
    let t_s = (p.level - point.y).max(0.0) / up.y.max(1e-6);
    let eps = 1e-5 * point.abs().max_element().max(1.0);
    if t_s > eps && occluded(point, up, eps, t_s, geometry) {
        return 0.0;
    }
    let sun = p.sun_direction.xyz();
    if sun.y > 0.0 && occluded(point + up * t_s, sun, eps, 1e7, geometry) {
        return 0.0;
    }
    1.0
}

/// The caustic (`caustics::shaft_at`) averaged along the step from
/// `start` by `step` (m), which moves `width` m across the shafts: up to
/// `SHAFT_TAPS` taps along it, each read over its share of the width (a
/// box mip is square, the step a line: taps keep the shafts the line
/// crosses rather than blurring them away).
fn shafts_over(p: &SeaParams, shafts: &[Vec4], start: Vec3, step: Vec3, width: f32) -> Vec3 {
    let texel = p.wave_size / caustics::shaft_resolution(p) as f32;
    let taps = ((width / (2.0 * texel)).ceil() as u32).clamp(1, SHAFT_TAPS);
    let mut sum = Vec3::ZERO;
    let mut i = 0;
    while i < taps {
        let at = start + step * ((i as f32 + 0.5) / taps as f32);
        sum += caustics::shaft_at(p, shafts, at, width / taps as f32);
        i += 1;
    }
    sum / taps as f32
}

/// `int e^(-a) dt` over an interval `dt` long at whose ends `e^(-a)` is
/// `e_a` and `e_b`, `a` linear and changing by `delta` (>= 0) across it:
/// `dt max(e_a, e_b) (1 - e^-delta)/delta` (a series below 1e-2, where the
/// difference would lose digits).
fn interval(dt: f32, e_a: f32, e_b: f32, delta: f32) -> f32 {
    let hi = e_a.max(e_b);
    if delta < 1e-2 {
        dt * hi * (1.0 - delta * (0.5 - delta * (1.0 / 6.0 - delta / 24.0)))
    } else {
        dt * (hi - e_a.min(e_b)) / delta
    }
}

/// One channel of a `Vec3`.
fn channel(v: Vec3, i: u32) -> f32 {
    if i == 0 {
        v.x
    } else if i == 1 {
        v.y
    } else {
        v.z
    }
}

/// The plane `k` whose slab holds depth `z` in channel `i` (the inverse
/// of `plane_depth`'s grading; the last slab below the last plane).
fn slab_of(q: &SeaParams, i: u32, z: f32) -> u32 {
    let reach = channel(q.plane_depth.xyz(), i);
    let s = (z / reach.max(1e-20)).clamp(0.0, 1.0);
    let u = if reach >= q.depth * 0.999_999 { (1.0 - 2.0 * s).clamp(-1.0, 1.0).acos() / PI } else { s.sqrt() };
    ((u * (q.planes - 1) as f32) as u32).min(q.planes - 2)
}

/// The scattering maps' source (eq. 6 and 8, W/(m^3 sr)) at depth `z`
/// toward the direction `at` stands for, for layer `q` whose planes start
/// at map `first`: per channel, between the planes bracketing `z`, as
/// `accumulate_planes` takes it (`s = J e^(c z/mu_s)` linear in depth;
/// constant below the last plane).
fn source_at(q: &SeaParams, maps: &[Vec4], first: u32, at: MapCoords, z: f32) -> Vec3 {
    let c = q.extinction.xyz();
    let mu_s = q.sun_in_water.w;
    let mut out = Vec3::ZERO;
    let mut cached = u32::MAX;
    let (mut ja, mut jb) = (Vec3::ZERO, Vec3::ZERO);
    let mut i = 0;
    while i < 3 {
        let k = slab_of(q, i, z);
        if k != cached {
            ja = super::scattering_map_lookup(q, maps, first + k, at);
            jb = super::scattering_map_lookup(q, maps, first + k + 1, at);
            cached = k;
        }
        let (za, zb) = (channel(plane_depth(q, k), i), channel(plane_depth(q, k + 1), i));
        let ci = channel(c, i);
        let value = if z >= zb {
            channel(jb, i) * (-ci * (z - zb) / mu_s).exp()
        } else {
            let w = ((z - za) / (zb - za).max(1e-20)).clamp(0.0, 1.0);
            channel(ja, i) * (-ci * (z - za) / mu_s).exp() * (1.0 - w)
                + channel(jb, i) * (ci * (zb - z) / mu_s).exp() * w
        };
        if i == 0 {
            out.x = value;
        } else if i == 1 {
            out.y = value;
        } else {
            out.z = value;
        }
        i += 1;
    }
    out.max(Vec3::ZERO)
}

/// `int_0^l J2(z(t), -dir) e^(-c t) dt` for layer `q` (maps from `first`):
/// equal steps out to `length` or `ORDER2_REACH` optical lengths, two more
/// than the sampling planes' slabs the ray crosses (one for a level ray; at
/// most `ORDER2_STEPS`), each integrated exactly for a source linear
/// between its ends times the exponential `e^(-c t (1 - dir_y/mu_s))` that
/// the sun's beam and the way back give it (`exp_linear3`).
fn order2_layer(q: &SeaParams, maps: &[Vec4], first: u32, dir: Vec3, z_e: f32, length: f32) -> Vec3 {
    let c = q.extinction.xyz();
    let mu_s = q.sun_in_water.w;
    let c_min = c.x.min(c.y).min(c.z);
    let reach = if c_min > 0.0 { ORDER2_REACH / c_min } else { 1e6 };
    let end = length.min(reach);
    if end <= 0.0 {
        return Vec3::ZERO;
    }
    let at = map_coords(q, -dir);
    let kappa = c * (1.0 - dir.y / mu_s);
    // A step per slab the ray crosses (one for a level ray, whose source
    // does not change along it), at least 2 where it crosses any.
    let (z_a, z_b) = (z_e, (z_e - end * dir.y).max(0.0));
    let mut crossed = 0;
    let mut i = 0;
    while i < 3 {
        let (ka, kb) = (slab_of(q, i, z_a), slab_of(q, i, z_b));
        crossed = crossed.max(ka.abs_diff(kb));
        i += 1;
    }
    let steps = if (z_a - z_b).abs() < 1e-6 { 1 } else { (crossed + 2).min(ORDER2_STEPS) };
    let step = end / steps as f32;
    let mut h_a = source_at(q, maps, first, at, z_e);
    let mut sum = Vec3::ZERO;
    let mut k = 1;
    while k <= steps {
        let t = step * k as f32;
        let h_b = source_at(q, maps, first, at, (z_e - t * dir.y).max(0.0)) * (-c * t).exp();
        sum += exp_linear3(Vec3::splat(step), h_a, h_b, kappa);
        h_a = h_b;
        k += 1;
    }
    sum
}

/// Second-order scattering gathered toward an eye at depth `z_e` along
/// `dir` over `length` m (`order2_layer`); over a varying bottom, between
/// the two layers whose bottoms bracket the depth under the eye `bottom`.
pub fn order2_segment(p: &SeaParams, maps: &[Vec4], dir: Vec3, z_e: f32, length: f32, bottom: f32) -> Vec3 {
    if p.layers <= 1 {
        return order2_layer(p, maps, 0, dir, z_e, length);
    }
    let (j, w) = layer_at(p, bottom);
    let (qa, qb) = (layer_params(p, j), layer_params(p, j + 1));
    let a = order2_layer(&qa, maps, j * p.planes, dir, z_e, length);
    let b = order2_layer(&qb, maps, (j + 1) * p.planes, dir, z_e, length);
    a * (1.0 - w) + b * w
}

/// Whether the accumulated map holds the eye's block: for an eye under
/// the water over a flat bottom, every view ray that meets no object runs
/// its whole length (`full_length`), which depends on its direction only,
/// so order 2 gathered along it (`order2_segment`) is kept per map
/// direction and looked up per pixel (bilinear between directions)
/// instead of integrated per pixel.
pub fn eye_block(p: &SeaParams) -> bool {
    p.underwater != 0 && p.layers <= 1
}

/// How far the eye's view ray along `dir` runs over a flat bottom with no
/// object in the way: to the surface, the bottom, or (`DEEP`) on.
pub fn full_length(p: &SeaParams, dir: Vec3) -> f32 {
    let z_e = p.camera_depth.max(0.0);
    if dir.y > 0.0 {
        z_e / dir.y
    } else if dir.y < 0.0 && p.depth < DEEP {
        (p.depth - z_e).max(0.0) / -dir.y
    } else {
        DEEP
    }
}

/// The bottom's depth under the horizontal point of `at` (m).
pub fn depth_under(p: &SeaParams, grid: &[f32], at: Vec3) -> f32 {
    if p.bottom_nx < 2 {
        return p.depth;
    }
    bottom_depth(p, grid, at.x, at.z)
}

/// Eq. 9 at the bottom itself: the refracted sunlight a Lambertian bottom
/// at depth `depth` (m) with cosine `cos_gamma` to the sun's beam sends
/// back, `E_w e^(-c d/mu_s) cos(gamma) albedo/pi`, W/(m^2 sr).
pub fn bottom_leaving(p: &SeaParams, depth: f32, cos_gamma: f32) -> Vec3 {
    lambert_leaving(p, depth, cos_gamma, p.bottom_albedo.xyz())
}

/// Eq. 9's reflection of the refracted sun by a Lambertian surface of
/// `albedo` at `depth` m whose normal makes `cos_gamma` with the way to
/// the sun, W/(m^2 sr): `E_w e^(-c d/mu_s) cos(gamma) albedo/pi` (the
/// bottom's, an object's under the water).
pub fn lambert_leaving(p: &SeaParams, depth: f32, cos_gamma: f32, albedo: Vec3) -> Vec3 {
    let c = p.extinction.xyz();
    p.beam_irradiance.xyz() * (-c * (depth / p.sun_in_water.w)).exp() * cos_gamma.max(0.0) * albedo * FRAC_1_PI
}

/// Where the bottom the view ray meets lies and how it faces the sun: its
/// depth (m) and the cosine of eq. 9's `gamma`.
pub fn bottom_at(p: &SeaParams, grid: &[f32], v: &UnderView) -> (f32, f32) {
    let mu_s = p.sun_in_water.w;
    if p.bottom_nx < 2 {
        return (p.depth, mu_s);
    }
    let q = v.end_point();
    let up = -p.sun_in_water.xyz();
    (bottom_depth(p, grid, q.x, q.z), super::bottom_normal(p, grid, q.x, q.z).dot(up).max(0.0))
}

/// What the surface reflects toward the eye from below travels up along
/// `v.up` from depth 0 at the end point: the depth of the bottom along the
/// way it came and the cosine there (`bottom_hit`).
pub fn reflected_bottom(p: &SeaParams, grid: &[f32], v: &UnderView) -> (f32, f32) {
    let q = v.end_point();
    bottom_hit(p, grid, q.x, q.z, v.up)
}

/// `e^(-c l)` over the view ray, per channel.
pub fn attenuation(p: &SeaParams, v: &UnderView) -> Vec3 {
    (-p.extinction.xyz() * v.length.min(1e7)).exp()
}

/// The sky and the sun through the surface seen from below (Snell's
/// window): the direction the view ray leaves the water along, and
/// `(1 - R) n_w^2`, which is 0 past the critical angle (total internal
/// reflection). (A pair rather than an `Option`, which the SPIR-V does not
/// carry.)
pub fn through_window(p: &SeaParams, v: &UnderView) -> (Vec3, f32) {
    let n = p.extinction.w;
    let normal = v.surface_normal();
    let (out, transmitted) = refract(v.dir, -normal, n);
    if !transmitted || v.reflectance >= 1.0 {
        return (Vec3::Y, 0.0);
    }
    // A steep facet may send the ray out below the horizon: it leaves the wave toward the sky.
    let out = Vec3::new(out.x, out.y.abs(), out.z).normalize();
    (out, (1.0 - v.reflectance) * n * n)
}

/// The factor `sea.water` applies to the objects' own light (rgb; w:
/// its channels' mean, for layers gathered along the view ray): where the
/// view ray meets an object under water, the water's transmittance to it,
/// `e^(-c l)`, times what the water does to the sunlight that lights it,
/// `(E_w / E) e^(-c z_o/mu_s)` at the object's depth `z_o` (the refracted
/// beam's irradiance over the sun's, `T_i cos(theta_ii)/cos(theta_io)`,
/// and its attenuation on the way down, times the waves' caustic there
/// where shafts are built: `caustics::shaft_at`; applied to the object's whole
/// shading, whose light under water is mostly that beam's); 0 where the
/// object lies beyond the surface or the bottom (`object_seen` and the ray
/// ends first); 1 elsewhere.
pub fn water_transmittance(p: &SeaParams, shafts: &[Vec4], v: &UnderView, object_seen: bool) -> Vec4 {
    if v.end != END_OBJECT {
        return if object_seen { Vec4::ZERO } else { Vec4::ONE };
    }
    let z_o = p.level - v.end_point().y;
    let mut t = attenuation(p, v);
    if z_o > 0.0 {
        let beam = p.beam_irradiance.w * p.sun_direction.w / p.sun_in_water.w;
        t *= (-p.extinction.xyz() * (z_o / p.sun_in_water.w)).exp() * beam;
        // The waves' focusing at the object (1 without shafts).
        t *= caustics::shaft_at(p, shafts, v.end_point(), 0.0);
    }
    t.extend((t.x + t.y + t.z) / 3.0)
}
