//! Splatting (Dobashi, Kaneda, Yamashita, Okita and Nishita, "A Simple,
//! Efficient Method for Realistic Animation of Clouds", SIGGRAPH 2000; the
//! 2002 survey's section 3.3): a metaball volume drawn as one billboard
//! per metaball instead of by slices.
//!
//! The paper's billboard texture holds, across a metaball of unit radius
//! and weight, the attenuation ratio and the cumulative density along the
//! line through each texel. Here that texture is exact: Wyvill's field is a
//! polynomial in `r^2 = s + z^2` (`s` the line's squared distance from the
//! centre over `R^2`), so its integral along any part of a line is a
//! polynomial in `z` (`line_integral`), and each billboard is evaluated
//! where a ray meets it, clipped to the volume's box, the surface behind
//! and the camera (`chord`).
//!
//! Three kernels, each a pure per-invocation function and a thin entry point:
//! - `splat_ball` (step 1, per metaball): the light reaching its centre
//!   (each light's optical depth from the centre toward the light, summed
//!   over all metaballs' chords: what the paper reads from the frame buffer
//!   after multiplying in the billboards nearer the sun; a directional
//!   light's balls found through its `LightBins`), turned into the
//!   billboard's colour (the scattering albedo, the phase function toward
//!   the eye, the octaves of multiple scattering); and its rank in the
//!   front-to-back order (the count of metaballs nearer the eye), written
//!   to `order[rank]`: a sort as one scatter;
//! - `splat_tile` (per screen tile of `TILE` x `TILE` pixels): the
//!   metaballs whose spheres meet the tile's cone of view rays, in order;
//! - `splat_pixel` (step 2, per pixel): the tile's billboards front to back
//!   (the paper blends back to front; front to back is the same sum),
//!   `L += T alpha c`, `T *= 1 - alpha`, with `alpha = 1 - exp(-sigma_t tau)`
//!   and `tau` the chord's optical depth. For one metaball lit uniformly
//!   this is exact (`c = albedo p E`: the source over the extinction is the
//!   same all along the chord); the method's error is the light taken at
//!   the centre and the order taken by centre.
//!
//! Units: lengths in metres, `sigma_*` in 1/m per unit density, radiance
//! in W/(m^2 sr).

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use super::{light_at, scattered_light, volume_phase, FogShare, GpuMetaball, GpuVolume, VolumesParams};
use crate::camera::{camera_ray, ray_direction};
use crate::geometry::box_span;
use crate::glam::{UVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::light::light_local;
use crate::types::{CommonParams, GBufferTexel, GpuLight, LIGHT_DIRECTIONAL};
use spirv_std::spirv;

/// Pixels a side of a splatting tile.
pub const TILE: u32 = 16;

/// One metaball's billboard for step 2 (`splat_ball`).
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct SplatBall {
    /// rgb: the radiance an opaque billboard would send toward the eye
    /// (W/(m^2 sr)): the scattering albedo times the phase-weighted light
    /// at the centre; w: the centre's distance from the eye (m).
    pub color: Vec4,
    /// rgb: the same at the points half a radius from the centre toward
    /// the key light (`toward`) and away from it (`away`), along `axis`
    /// (`seen_color` reads the light between them).
    pub toward: Vec4,
    pub away: Vec4,
    /// rgb: the part of `color`, `toward` and `away` that is single
    /// scattering (the light's direct beam scattered once, `e^-tau p E`):
    /// it follows the ball's own optical depth toward the light, where the
    /// rest (multiple scattering) varies slowly.
    pub direct: Vec4,
    pub direct_toward: Vec4,
    pub direct_away: Vec4,
    /// xyz: the unit direction toward the key light (the one that brings
    /// the centre the most light; zero if none does).
    pub axis: Vec4,
    /// xyz: the billboard's unit vectors across the eye's view of the
    /// centre (its texture's x and y, `billboard_frame`).
    pub across_x: Vec4,
    pub across_y: Vec4,
    /// Its place in the front-to-back order.
    pub rank: u32,
    /// The volume it belongs to.
    pub volume: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// A directional light's bins of metaballs: a grid over the plane across
/// its rays (its frame's x and y, `light_local`), each cell listing the
/// balls whose spheres' shadows on that plane meet the cell, so the balls
/// a light ray crosses are the ones listed in the cell its ray lies in.
/// `nx = 0`: none (a spot's rays are not parallel; its balls are all walked).
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct LightBins {
    /// x, y: the grid's corner in the light's frame (m).
    pub lo: Vec4,
    /// A cell's side (m).
    pub cell: f32,
    pub nx: u32,
    pub ny: u32,
    /// Where the light's `nx * ny + 1` cell starts lie in the list buffer
    /// (absolute indices into it, the balls' indices after them).
    pub offset: u32,
}

#[cfg(not(target_arch = "spirv"))]
mod pod {
    // SAFETY: `repr(C)`, nine `Vec4`s and four 4-byte scalars (160 bytes, no padding).
    unsafe impl bytemuck::Zeroable for super::SplatBall {}
    unsafe impl bytemuck::Pod for super::SplatBall {}
    unsafe impl bytemuck::Zeroable for super::LightBins {}
    unsafe impl bytemuck::Pod for super::LightBins {}
}

/// The balls light `light`'s ray through `p` may cross: `(start, end,
/// listed)`, entries `start..end` of `lists` (`listed`) or balls
/// `start..end` (the light has no bins).
fn balls_on_ray(
    params: &VolumesParams,
    bins: &LightBins,
    lists: &[u32],
    light: &GpuLight,
    p: Vec3,
) -> (u32, u32, bool) {
    if bins.nx == 0 {
        return (0, params.ball_count, false);
    }
    let local = light_local(light, p);
    let fx = ((local.x - bins.lo.x) / bins.cell).floor();
    let fy = ((local.y - bins.lo.y) / bins.cell).floor();
    if !(fx >= 0.0 && fy >= 0.0 && fx < bins.nx as f32 && fy < bins.ny as f32) {
        return (0, 0, true);
    }
    let cell = bins.offset + fy as u32 * bins.nx + fx as u32;
    (lists[cell as usize], lists[cell as usize + 1], true)
}

/// `int_0^z f(sqrt(s + x^2)) dx` (dimensionless): the antiderivative of
/// Wyvill's field (the survey's eq. 1's `f`, `field`) along a line at
/// squared distance `s` from the centre of a unit metaball, `z` along the
/// line from its point nearest the centre (`s + z^2 <= 1`: inside the
/// ball). Term by term from `r^2 = s + x^2`:
/// `z - 22/9 (s z + z^3/3) + 17/9 (s^2 z + 2 s z^3/3 + z^5/5)
///  - 4/9 (s^3 z + s^2 z^3 + 3 s z^5/5 + z^7/7)`.
pub fn line_integral(z: f32, s: f32) -> f32 {
    let z2 = z * z;
    let r2 = s + z2 * (1.0 / 3.0);
    let r4 = s * s + z2 * (2.0 / 3.0 * s + z2 * 0.2);
    let r6 = s * s * s + z2 * (s * s + z2 * (0.6 * s + z2 * (1.0 / 7.0)));
    z * (1.0 - 22.0 / 9.0 * r2 + 17.0 / 9.0 * r4 - 4.0 / 9.0 * r6)
}

/// The metaball's density integrated along the line `o + t u` (`u` unit)
/// over `t` in `[t0, t1]` (m: density times metres): `q R` times the
/// difference of `line_integral` across the chord's part in that range.
pub fn chord(ball: &GpuMetaball, o: Vec3, u: Vec3, t0: f32, t1: f32) -> f32 {
    let r = ball.center_radius.w;
    let v = ball.center_radius.xyz() - o;
    let tc = v.dot(u);
    let d2 = (v.length_squared() - tc * tc).max(0.0);
    let r2 = r * r;
    if d2 >= r2 {
        return 0.0;
    }
    let h = (r2 - d2).sqrt();
    let a = (tc - h).max(t0);
    let b = (tc + h).min(t1);
    if b <= a {
        return 0.0;
    }
    let s = d2 / r2;
    let inv_r = 1.0 / r;
    let z0 = ((a - tc) * inv_r).clamp(-1.0, 1.0);
    let z1 = ((b - tc) * inv_r).clamp(-1.0, 1.0);
    ball.q.x * r * (line_integral(z1, s) - line_integral(z0, s)).max(0.0)
}

/// Wyvill's field (the survey's eq. 1's `f`) at squared radius `r2` (radii^2).
fn field_at(r2: f32) -> f32 {
    if r2 >= 1.0 {
        return 0.0;
    }
    1.0 - r2 * (22.0 / 9.0 - r2 * (17.0 / 9.0 - r2 * (4.0 / 9.0)))
}

/// Where along a chord of a metaball (at squared distance `s` from its
/// centre, radii^2, from `z0` to `z1` radii along it) whose optical depth
/// is `tau` the eye gets the share `q` of the light the chord sends it: the
/// emission `sigma_t rho(z) e^(-tau(z))` integrates to `1 - e^(-tau)`, so
/// the point is where the optical depth from the chord's start reaches
/// `quantile_share(tau, q) tau`. The density's integral is
/// `line_integral`; Newton's method on it, kept inside its bracket by
/// bisection (8 steps: the unit test's 1e-4 of the share at optical depths
/// to 60; 6 were not enough there).
pub fn emission_quantile(s: f32, z0: f32, z1: f32, tau: f32, q: f32) -> f32 {
    let base = line_integral(z0, s);
    let whole = line_integral(z1, s) - base;
    let share = quantile_share(tau, q);
    let target = share * whole;
    let (mut lo, mut hi) = (z0, z1);
    let mut z = z0 + share * (z1 - z0);
    let mut k = 0;
    while k < 8 {
        let g = line_integral(z, s) - base - target;
        if g > 0.0 {
            hi = z;
        } else {
            lo = z;
        }
        let slope = field_at(s + z * z);
        let next = if slope > 0.0 { z - g / slope } else { lo - 1.0 };
        // Newton's step where it stays in the bracket (at its ends too: a
        // converged step lands on the end it just set), else bisection.
        z = if next >= lo && next <= hi { next } else { 0.5 * (lo + hi) };
        k += 1;
    }
    z
}

/// The share of a chord's optical depth `tau` before the point that sends
/// the eye the share `q` of its light: `-ln(1 - q (1 - e^-tau)) / tau`
/// (`q` when thin); below `tau = 0.05` by the series of `1 - e^-tau` and of
/// `-ln(1 - u)` (f32's `1 - e^-tau` there has lost digits; the series'
/// first terms left out are below 1e-7 of the value).
fn quantile_share(tau: f32, q: f32) -> f32 {
    if tau > 0.05 {
        return -(1.0 - q * (1.0 - (-tau).exp())).ln() / tau;
    }
    // u = q (1 - e^-tau) / tau, then -ln(1 - u tau) / tau.
    let u = q * (1.0 - tau * (0.5 - tau * (1.0 / 6.0 - tau * (1.0 / 24.0))));
    let ut = u * tau;
    u * (1.0 + ut * (0.5 + ut * (1.0 / 3.0 + ut * 0.25)))
}

/// Step 1's samples of a ball's light (`SplatBall`) as `seen_color` reads
/// them, taken apart once per texel: the direct beam's logarithms per
/// channel (`ln 0` as `LOG_ZERO`) at the centre and the two side samples,
/// and the rest of the light (multiple scattering) at each.
struct Samples {
    direct: [Vec3; 3],
    log: [Vec3; 3],
    rest: [Vec3; 3],
    rest_log: [Vec3; 3],
}

/// The logarithm taken for 0 (`e^-69` is 1e-30).
const LOG_ZERO: f32 = -69.0;

fn log_or_zero(v: Vec3) -> Vec3 {
    let l = |x: f32| if x > 1e-30 { x.ln() } else { LOG_ZERO };
    Vec3::new(l(v.x), l(v.y), l(v.z))
}

fn samples(splat: &SplatBall) -> Samples {
    let direct = [splat.direct.xyz(), splat.direct_toward.xyz(), splat.direct_away.xyz()];
    let all = [splat.color.xyz(), splat.toward.xyz(), splat.away.xyz()];
    let rest = [
        (all[0] - direct[0]).max(Vec3::ZERO),
        (all[1] - direct[1]).max(Vec3::ZERO),
        (all[2] - direct[2]).max(Vec3::ZERO),
    ];
    Samples {
        direct,
        log: [log_or_zero(direct[0]), log_or_zero(direct[1]), log_or_zero(direct[2])],
        rest,
        rest_log: [log_or_zero(rest[0]), log_or_zero(rest[1]), log_or_zero(rest[2])],
    }
}

/// The billboard's colour (rgb) at `point` of the ball (`billboard_texel`
/// takes the points where a chord sends the eye its light:
/// `emission_quantile`), from step 1's samples along the key light's axis
/// (`samples`), read at the point's projection on the axis:
/// - the direct beam's logarithm is linear in the ball's own optical depth
///   along the axis (exactly, for the ball's own share), so the position `a`
///   (radii) is measured by `line_integral(a, 0)` against its value at the
///   samples' half radius, and past them the same law carries on to the
///   ball's edge; off the axis, where the ball's own path toward the light
///   is shorter, times `e^-(sigma_t q R (own_off - own_on))`; linear where
///   a sample is 0;
/// - the rest (multiple scattering, which varies slowly): by the same law
///   between the samples (nearer the measured error than linear: 4.58
///   against 4.74 % RMS on the cumulus against Monte Carlo), held past them.
fn seen_color(sm: &Samples, splat: &SplatBall, ball: &GpuMetaball, vol: &GpuVolume, point: Vec3) -> Vec3 {
    let rel = (point - ball.center_radius.xyz()) / ball.center_radius.w;
    let a = rel.dot(splat.axis.xyz()).clamp(-1.0, 1.0);
    let w = line_integral(a, 0.0) / line_integral(0.5, 0.0);
    let k = if w >= 0.0 { 1 } else { 2 };
    let w = w.abs();
    let b2 = (rel.length_squared() - a * a).clamp(0.0, 1.0);
    let exit = (1.0 - b2).max(0.0).sqrt();
    let own_off = (line_integral(exit, b2) - line_integral(a.min(exit), b2)).max(0.0);
    let own_on = line_integral(1.0, 0.0) - line_integral(a, 0.0);
    let delta = vol.sigma_t.xyz() * (ball.q.x * ball.center_radius.w * (own_off - own_on));
    let direct = Vec3::new(
        direct_at(sm.direct[0].x, sm.direct[k].x, sm.log[0].x, sm.log[k].x, w, delta.x),
        direct_at(sm.direct[0].y, sm.direct[k].y, sm.log[0].y, sm.log[k].y, w, delta.y),
        direct_at(sm.direct[0].z, sm.direct[k].z, sm.log[0].z, sm.log[k].z, w, delta.z),
    );
    let w = w.min(1.0);
    let rest = Vec3::new(
        direct_at(sm.rest[0].x, sm.rest[k].x, sm.rest_log[0].x, sm.rest_log[k].x, w, 0.0),
        direct_at(sm.rest[0].y, sm.rest[k].y, sm.rest_log[0].y, sm.rest_log[k].y, w, 0.0),
        direct_at(sm.rest[0].z, sm.rest[k].z, sm.rest_log[0].z, sm.rest_log[k].z, w, 0.0),
    );
    direct + rest
}

/// One channel of the light in `seen_color`: `c0 (c1 / c0)^w
/// e^-delta` from the logarithms `l0`, `l1` when both samples are
/// positive, else `(c0 + (c1 - c0) w) e^-delta` (at least 0, and 0 without
/// `0 * inf` where that is 0); the exponent at most 80 (`e^-delta` at
/// optical depths of 10^4 overflows).
fn direct_at(c0: f32, c1: f32, l0: f32, l1: f32, w: f32, delta: f32) -> f32 {
    if c0 > 0.0 && c1 > 0.0 {
        return (l0 + w * (l1 - l0) - delta).min(80.0).exp();
    }
    let v = c0 + (c1 - c0) * w;
    if v > 0.0 {
        v * (-delta.max(-80.0)).exp()
    } else {
        0.0
    }
}

/// Texels a side of a billboard's texture (`billboard_texel`).
pub const BILLBOARD_SIDE: u32 = 4;
/// Texels of a billboard's texture.
pub const BILLBOARD_TEXELS: u32 = BILLBOARD_SIDE * BILLBOARD_SIDE;
/// The parts of equal light a texel's chord is split into (`billboard_texel`).
const SPLIT: u32 = 2;
/// How far out (in radii squared) a texel's chord is taken at most: the
/// texels past the ball's rim (the corners of the square) hold the colour
/// just inside it, for the bilinear lookup at the rim.
const RIM: f32 = 0.98;

/// The frame a metaball's billboard faces: the unit direction from the eye
/// to its centre and two unit vectors across it (a function of that
/// direction alone, the same in both steps).
fn billboard_frame(common: &CommonParams, c: Vec3) -> (Vec3, Vec3, Vec3) {
    let to = c - common.camera_position.xyz();
    let view = if to.length_squared() > 0.0 { to.normalize() } else { common.camera_forward.xyz() };
    let e1 = crate::caustics::frame_tangent(view);
    (view, e1, view.cross(e1))
}

/// Texel `k` of the billboards' textures (ball `k / BILLBOARD_TEXELS`):
/// the colour (rgb, W/(m^2 sr); w 0) of the ball's light
/// along the chord, parallel to the eye's view of the centre, through the
/// texel's centre (`(i + 1/2) / BILLBOARD_SIDE` across the ball's square
/// of side `2R`): the mean of `seen_color` at the two points that split
/// the light the chord sends the eye into quarters, halves and quarters
/// (`emission_quantile` at 1/4 and 3/4): a two-point rule for the
/// emission-weighted light along the chord. This is the paper's billboard
/// texture with the light in it; the pixel reads it bilinearly
/// (`billboard_color`), where solving for the points per pixel cost seven
/// times the blend.
pub fn billboard_texel(
    k: u32,
    common: &CommonParams,
    volumes: &[GpuVolume],
    balls: &[GpuMetaball],
    splats: &[SplatBall],
) -> Vec4 {
    let j = (k / BILLBOARD_TEXELS) as usize;
    let t = k % BILLBOARD_TEXELS;
    let ball = &balls[j];
    let splat = &splats[j];
    let vol = &volumes[volume_of(ball)];
    let c = ball.center_radius.xyz();
    let r = ball.center_radius.w;
    let (view, e1, e2) = billboard_frame(common, c);
    let side = BILLBOARD_SIDE as f32;
    let mut off = Vec2::new(
        ((t % BILLBOARD_SIDE) as f32 + 0.5) / side * 2.0 - 1.0,
        ((t / BILLBOARD_SIDE) as f32 + 0.5) / side * 2.0 - 1.0,
    );
    let out = off.length_squared();
    if out > RIM {
        off *= (RIM / out).sqrt();
    }
    let s = off.length_squared();
    let h = (1.0 - s).sqrt();
    let sigma = (vol.sigma_t.x + vol.sigma_t.y + vol.sigma_t.z) / 3.0;
    let tau = sigma * ball.q.x * r * (line_integral(h, s) - line_integral(-h, s)).max(0.0);
    let across = c + (e1 * off.x + e2 * off.y) * r;
    let sm = samples(splat);
    let mut color = Vec3::ZERO;
    let mut i = 0;
    while i < SPLIT {
        let z = emission_quantile(s, -h, h, tau, (i as f32 + 0.5) / SPLIT as f32);
        color += seen_color(&sm, splat, ball, vol, across + view * (z * r));
        i += 1;
    }
    (color / SPLIT as f32).extend(0.0)
}

/// Ball `j`'s colour where the ray `o + t d` passes it (rgb): its texture
/// (`billboard_texel`) read bilinearly between texel centres at the ray's
/// nearest point to the centre, in the billboard's frame, clamped to the
/// texture.
fn billboard_color(textures: &[Vec4], ball: &GpuMetaball, splat: &SplatBall, j: u32, o: Vec3, d: Vec3) -> Vec3 {
    let v = ball.center_radius.xyz() - o;
    let across = d * v.dot(d) - v;
    let side = BILLBOARD_SIDE as f32;
    let to_texels = 0.5 * side / ball.center_radius.w;
    let x = (across.dot(splat.across_x.xyz()) * to_texels + 0.5 * side - 0.5).clamp(0.0, side - 1.0);
    let y = (across.dot(splat.across_y.xyz()) * to_texels + 0.5 * side - 0.5).clamp(0.0, side - 1.0);
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(BILLBOARD_SIDE - 1), (y0 + 1).min(BILLBOARD_SIDE - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let base = (j * BILLBOARD_TEXELS) as usize;
    let (r0, r1) = (base + (y0 * BILLBOARD_SIDE) as usize, base + (y1 * BILLBOARD_SIDE) as usize);
    let top = textures[r0 + x0 as usize] * (1.0 - fx) + textures[r0 + x1 as usize] * fx;
    let bottom = textures[r1 + x0 as usize] * (1.0 - fx) + textures[r1 + x1 as usize] * fx;
    (top * (1.0 - fy) + bottom * fy).xyz()
}

/// The ball's volume (stored in `q.y`, `configure`).
fn volume_of(ball: &GpuMetaball) -> usize {
    ball.q.y as usize
}

/// `chord` within the part of `[t0, t1]` inside the ball's volume's box.
fn boxed_chord(ball: &GpuMetaball, v: &GpuVolume, o: Vec3, u: Vec3, t0: f32, t1: f32) -> f32 {
    let (near, far) = box_span(o, Vec3::ONE / u, v.min.xyz(), v.max.xyz(), t0, t1);
    if near < far {
        chord(ball, o, u, near, far)
    } else {
        0.0
    }
}

/// The optical depth (rgb) along `p + t u`, summed over the chords of the
/// metaballs the ray may cross (`balls_on_ray`: `start..end`, through
/// `lists` if `listed`; in the balls' order either way, so the sums are
/// the same bits as over every ball): over `t` in `[0, t_max]` (from `p` to
/// the light) and over `(-inf, t_max]` (the light's whole ray through the
/// volumes, for multiple scattering, `scattered_light`).
#[allow(clippy::too_many_arguments)]
fn optical_depths(
    volumes: &[GpuVolume],
    balls: &[GpuMetaball],
    lists: &[u32],
    (start, end, listed): (u32, u32, bool),
    p: Vec3,
    u: Vec3,
    t_max: f32,
) -> (Vec4, Vec4) {
    let mut tau = Vec4::ZERO;
    let mut through = Vec4::ZERO;
    let mut k = start;
    while k < end {
        let i = if listed { lists[k as usize] } else { k } as usize;
        k += 1;
        let ball = &balls[i];
        let v = &volumes[volume_of(ball)];
        let whole = boxed_chord(ball, v, p, u, -f32::MAX, t_max);
        if whole > 0.0 {
            through += v.sigma_t * whole;
            tau += v.sigma_t * boxed_chord(ball, v, p, u, 0.0, t_max);
        }
    }
    (tau, through)
}

/// The light of every light reaching `p` (a point of metaball `ball`, in
/// volume `vol`), attenuated by all metaballs' chords toward that light and
/// scattered toward the eye along `view` per unit scattering coefficient
/// (`scattered_light`, W/(m^2 sr)); its single-scattering part (the
/// direct beam scattered once: `e^-tau p E`, the first octave); and the
/// unit direction toward the light that brings the most (zero if none does).
fn ball_light(inp: &Step1, vol: &GpuVolume, p: Vec3, view: Vec3) -> (Vec4, Vec4, Vec3) {
    let (common, params, lists) = (inp.common, inp.params, inp.lists);
    let mut light = Vec4::ZERO;
    let mut direct = Vec4::ZERO;
    let mut key = Vec3::ZERO;
    let mut strongest = 0.0;
    let mut l = 0;
    while l < common.light_count as usize {
        light_ref!(source = inp.lights, l);
        let (e, travel) = light_at(common, source, inp.light_map, inp.shadow, p);
        if e.x > 0.0 || e.y > 0.0 || e.z > 0.0 {
            let t_max = if source.kind == LIGHT_DIRECTIONAL { f32::MAX } else { (source.position.xyz() - p).length() };
            let on_ray = balls_on_ray(params, &inp.bins[l], lists, source, p);
            let (tau, through) = optical_depths(inp.volumes, inp.balls, lists, on_ray, p, -travel, t_max);
            let cos_theta = -travel.dot(view);
            light += scattered_light(params, vol, e, tau, through, cos_theta);
            let beam = Vec4::new((-tau.x).exp(), (-tau.y).exp(), (-tau.z).exp(), 0.0);
            direct += e * beam * volume_phase(vol, cos_theta, 1.0);
            let strength = e.x + e.y + e.z;
            if strength > strongest {
                strongest = strength;
                key = -travel;
            }
        }
        l += 1;
    }
    (light, direct, key)
}

/// Step 1 for metaball `j`: its billboard's colours (the light reaching
/// its centre from every light, `ball_light`, times its volume's albedo;
/// and the same half a radius toward and away from the key light, so that
/// step 2 can take the light where the eye sees the ball rather than at
/// its centre: `seen_color`), its distance from the eye, and its rank: the
/// number of metaballs whose centres are nearer the eye (equal distances by
/// index), so that ranks are a permutation of `0..ball_count` on every
/// backend.
pub fn splat_ball(j: u32, inp: &Step1) -> SplatBall {
    let mut s = splat_light(j, inp);
    s.rank = splat_rank(j, inp.common, inp.params, inp.balls);
    s
}

/// What step 1 reads: the frame's parameters, the volumes and their
/// metaballs, the lights (with the spots' light maps and shadow maps) and
/// the directional lights' bins of metaballs (`LightBins`, `lists`).
pub struct Step1<'a> {
    pub common: &'a CommonParams,
    pub params: &'a VolumesParams,
    pub volumes: &'a [GpuVolume],
    pub balls: &'a [GpuMetaball],
    pub lights: &'a [GpuLight],
    pub light_map: &'a [Vec4],
    pub shadow: &'a [f32],
    pub bins: &'a [LightBins],
    pub lists: &'a [u32],
}

/// The squared distance of ball `j`'s centre from the eye, m^2: the key
/// of the front-to-back order.
pub fn splat_key(common: &CommonParams, balls: &[GpuMetaball], j: u32) -> f32 {
    (balls[j as usize].center_radius.xyz() - common.camera_position.xyz()).length_squared()
}

/// Ball `j`'s rank front to back: the balls whose keys (`splat_key`) are
/// smaller, or equal with a smaller index. (The CPU backend gets the same
/// numbers by sorting the keys with their indices, in `n log n` where
/// this is `n^2`.)
pub fn splat_rank(j: u32, common: &CommonParams, params: &VolumesParams, balls: &[GpuMetaball]) -> u32 {
    let key = splat_key(common, balls, j);
    let mut rank = 0u32;
    let mut i = 0;
    while i < params.ball_count {
        let other = splat_key(common, balls, i);
        rank += (other < key) as u32 + ((other == key) & (i < j)) as u32;
        i += 1;
    }
    rank
}

/// Step 1 without the rank (`splat_ball`): the billboard's colours, frame
/// and distance; `rank` 0.
pub fn splat_light(j: u32, inp: &Step1) -> SplatBall {
    let (common, balls) = (inp.common, inp.balls);
    let ball = &balls[j as usize];
    let c = ball.center_radius.xyz();
    let eye = common.camera_position.xyz();
    let key = splat_key(common, balls, j);
    let vi = volume_of(ball);
    let vol = &inp.volumes[vi];
    let distance = key.sqrt();
    let view = if distance > 0.0 { (c - eye) / distance } else { common.camera_forward.xyz() };
    let (_, e1, e2) = billboard_frame(common, c);
    let (centre, direct, axis) = ball_light(inp, vol, c, view);
    let (mut toward, mut away) = ((centre, direct, axis), (centre, direct, axis));
    if axis.length_squared() > 0.0 {
        let half = axis * (0.5 * ball.center_radius.w);
        toward = ball_light(inp, vol, c + half, view);
        away = ball_light(inp, vol, c - half, view);
    }
    let albedo = Vec4::new(
        ratio(vol.sigma_s.x, vol.sigma_t.x),
        ratio(vol.sigma_s.y, vol.sigma_t.y),
        ratio(vol.sigma_s.z, vol.sigma_t.z),
        0.0,
    );
    SplatBall {
        color: (centre * albedo).xyz().extend(distance),
        toward: toward.0 * albedo,
        away: away.0 * albedo,
        direct: direct * albedo,
        direct_toward: toward.1 * albedo,
        direct_away: away.1 * albedo,
        axis: axis.extend(0.0),
        across_x: e1.extend(0.0),
        across_y: e2.extend(0.0),
        rank: 0,
        volume: vi as u32,
        _pad0: 0,
        _pad1: 0,
    }
}

/// `s / t`, 0 where `t` is 0 (a volume's scattering albedo).
fn ratio(s: f32, t: f32) -> f32 {
    if t > 0.0 {
        s / t
    } else {
        0.0
    }
}

/// Tiles across the image (the tile of pixel `(x, y)` is
/// `(y / TILE) * tiles_across + x / TILE`).
pub fn tiles_across(common: &CommonParams) -> u32 {
    common.width.div_ceil(TILE)
}

/// The cone of view rays through tile `(tx, ty)`: its middle direction and
/// the cosine of its half-angle (over the tile's corners and edge
/// midpoints, the directions of the outermost sample positions).
fn tile_cone(common: &CommonParams, tx: u32, ty: u32) -> (Vec3, f32) {
    let x0 = tx * TILE;
    let y0 = ty * TILE;
    let w = TILE.min(common.width - x0) as f32;
    let h = TILE.min(common.height - y0) as f32;
    let middle = ray_direction(common, x0, y0, Vec2::new(0.5 * w, 0.5 * h));
    let mut cos_half = 1.0f32;
    let mut k = 0;
    while k < 9 {
        if k != 4 {
            let offset = Vec2::new((k % 3) as f32 * 0.5 * w, (k / 3) as f32 * 0.5 * h);
            cos_half = cos_half.min(middle.dot(ray_direction(common, x0, y0, offset)));
        }
        k += 1;
    }
    (middle, cos_half)
}

/// Whether a ball (centre `c`, radius `r`) meets the cone `(axis, cos,
/// sin)` (its half-angle's cosine and sine) from the eye: the angle to its
/// centre is within the cone's half-angle plus the ball's angular radius
/// `b` (`sin b = r / distance`), `cos(angle) >= cos(half + b)`, or the eye
/// is within the ball.
fn ball_in_cone(eye: Vec3, c: Vec3, r: f32, axis: Vec3, cos_half: f32, sin_half: f32) -> bool {
    let w = c - eye;
    let d2 = w.length_squared();
    if d2 <= r * r {
        return true;
    }
    let sin_b2 = r * r / d2;
    let cos_b = (1.0 - sin_b2).sqrt();
    let sin_b = sin_b2.sqrt();
    // cos(half + b), and half + b past pi: every direction.
    let cos_sum = cos_half * cos_b - sin_half * sin_b;
    let past_pi = sin_half * cos_b + cos_half * sin_b < 0.0;
    past_pi || w.dot(axis) >= cos_sum * d2.sqrt()
}

/// Tile `tile`'s list: `out[base]` the count of balls (in front-to-back
/// order, `order`) whose spheres meet the tile's cone of rays, the balls'
/// indices after it; a tile that meets more than `tile_capacity` balls
/// stores `tile_capacity + 1` and no list, and its pixels walk `order`
/// whole.
pub fn splat_tile(
    tile: u32,
    common: &CommonParams,
    params: &VolumesParams,
    balls: &[GpuMetaball],
    order: &[u32],
    out: &mut [u32],
    base: usize,
) {
    let (tx, ty) = (tile % tiles_across(common), tile / tiles_across(common));
    if ty * TILE >= common.height {
        // Past the image (the buffer holds the tiles of the size the scene
        // was configured at).
        out[base] = 0;
        return;
    }
    let (axis, cos_cone) = tile_cone(common, tx, ty);
    // A thousandth of a radian more for the edge midpoints' bound.
    let half = cos_cone.clamp(-1.0, 1.0).acos() + 1e-3;
    let (sin_half, cos_half) = (half.sin(), half.cos());
    let eye = common.camera_position.xyz();
    let mut count = 0u32;
    let mut k = 0;
    while k < params.ball_count as usize {
        let index = order[k];
        let ball = &balls[index as usize];
        if ball_in_cone(eye, ball.center_radius.xyz(), ball.center_radius.w, axis, cos_half, sin_half) {
            if count == params.tile_capacity {
                count += 1;
                break;
            }
            out[base + 1 + count as usize] = index;
            count += 1;
        }
        k += 1;
    }
    out[base] = count;
}

/// Step 2 for pixel `index`: the volumes' radiance toward the camera (rgb,
/// W/(m^2 sr)) and the view transmittance (rgb; w: the share of the fog's
/// light along the ray the balls let through, as `volumes_pixel` gives
/// it), the billboards of the pixel's tile blended front to back up to
/// `surface_distance`.
#[allow(clippy::too_many_arguments)]
pub fn splat_pixel(
    index: u32,
    common: &CommonParams,
    params: &VolumesParams,
    volumes: &[GpuVolume],
    balls: &[GpuMetaball],
    splats: &[SplatBall],
    textures: &[Vec4],
    order: &[u32],
    tiles: &[u32],
    surface_distance: f32,
) -> (Vec4, Vec4) {
    let x = index % common.width;
    let y = index / common.width;
    let (o, d) = camera_ray(common, x, y);
    let tile = (y / TILE) * tiles_across(common) + x / TILE;
    let base = (tile * (params.tile_capacity + 1)) as usize;
    let listed = tiles[base];
    let count = if listed > params.tile_capacity { params.ball_count } else { listed };
    let fog_scatters = common.sigma_s.x > 0.0 || common.sigma_s.y > 0.0 || common.sigma_s.z > 0.0;
    let mut fog = FogShare::new(common, 0.0);
    let mut radiance = Vec4::ZERO;
    let mut view = Vec4::ONE;
    let mut end = 0.0f32;
    let mut k = 0;
    while k < count {
        let j = if listed > params.tile_capacity { order[k as usize] } else { tiles[base + 1 + k as usize] };
        k += 1;
        let ball = &balls[j as usize];
        let splat = &splats[j as usize];
        let v = &volumes[splat.volume as usize];
        let depth = boxed_chord(ball, v, o, d, 0.0, surface_distance);
        if depth <= 0.0 {
            continue;
        }
        let tau = v.sigma_t * depth;
        let step = Vec4::new((-tau.x).exp(), (-tau.y).exp(), (-tau.z).exp(), 0.0);
        let alpha = Vec4::ONE - step;
        let t = splat.color.w;
        // The light where the eye sees the ball, from its texture.
        let color = billboard_color(textures, ball, splat, j, o, d);
        radiance += view * alpha * color.extend(0.0) * crate::light::transmittance(common.sigma_t, t);
        if fog_scatters {
            // The billboard as a layer at its centre's distance: the fog
            // before it seen through what is in front.
            let layer = t.min(surface_distance).max(end);
            fog.interval(end, layer - end, (view.x + view.y + view.z) / 3.0, 0.0);
            end = layer;
        }
        view = (view.xyz() * step.xyz()).extend(1.0);
        if view.x < 1e-6 && view.y < 1e-6 && view.z < 1e-6 {
            break;
        }
    }
    view.w = if fog_scatters { fog.share(end, (view.x + view.y + view.z) / 3.0, surface_distance) } else { 1.0 };
    (radiance, view)
}

/// The step-1 kernel's entry point (`splat_ball`; writes the ball's
/// billboard and scatters its index to its rank).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn splat_ball_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] shadow: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 40)] params: &[VolumesParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 41)] volumes: &[GpuVolume],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 42)] balls: &[GpuMetaball],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 74)] bins: &[LightBins],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 75)] lists: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 69)] splats: &mut [SplatBall],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 70)] order: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let params = &params[0];
    if index < params.ball_count {
        let inp = Step1 { common: &common[0], params, volumes, balls, lights, light_map, shadow, bins, lists };
        let s = splat_ball(index, &inp);
        order[s.rank as usize] = index;
        splats[index as usize] = s;
    }
}

/// The texture kernel's entry point (`billboard_texel`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn splat_texture_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 40)] params: &[VolumesParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 41)] volumes: &[GpuVolume],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 42)] balls: &[GpuMetaball],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 69)] splats: &[SplatBall],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 84)] textures: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    if index < params[0].ball_count * BILLBOARD_TEXELS {
        textures[index as usize] = billboard_texel(index, &common[0], volumes, balls, splats);
    }
}

/// The tile kernel's entry point (`splat_tile`).
#[spirv(compute(threads(64)))]
pub fn splat_tile_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 40)] params: &[VolumesParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 42)] balls: &[GpuMetaball],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 70)] order: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 71)] tiles: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let params = &params[0];
    if index < params.tiles_x * params.tiles_y {
        let base = (index * (params.tile_capacity + 1)) as usize;
        splat_tile(index, &common[0], params, balls, order, tiles, base);
    }
}

/// The per-pixel kernel's entry point (`splat_pixel`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn splat_pixel_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 40)] params: &[VolumesParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 41)] volumes: &[GpuVolume],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 42)] balls: &[GpuMetaball],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 69)] splats: &[SplatBall],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 84)] textures: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 70)] order: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 71)] tiles: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 72)] radiance: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 73)] transmittance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let distance = gbuffer[index as usize].normal_distance.w;
        let (l, t) = splat_pixel(
            common.band_start + index,
            common,
            &params[0],
            volumes,
            balls,
            splats,
            textures,
            order,
            tiles,
            distance,
        );
        radiance[index as usize] = l;
        transmittance[index as usize] = t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The integral of `field` along a line by the midpoint rule in f64.
    fn numeric(s: f64, z0: f64, z1: f64) -> f64 {
        let n = 200_000;
        let h = (z1 - z0) / n as f64;
        (0..n)
            .map(|i| {
                let z = z0 + (i as f64 + 0.5) * h;
                let a2 = s + z * z;
                if a2 >= 1.0 {
                    0.0
                } else {
                    (1.0 + a2 * (-22.0 / 9.0 + a2 * (17.0 / 9.0 - a2 * 4.0 / 9.0))) * h
                }
            })
            .sum()
    }

    #[test]
    fn the_line_integral_is_the_fields_integral() {
        // Through the centre, the whole chord: 2 (1 - 22/27 + 17/45 - 4/63).
        let whole = line_integral(1.0, 0.0) - line_integral(-1.0, 0.0);
        let exact = 2.0 * (1.0 - 22.0 / 27.0 + 17.0 / 45.0 - 4.0 / 63.0);
        assert!((whole as f64 - exact).abs() < 1e-6, "{whole} against {exact}");
        // Off centre and over parts of chords, against the midpoint rule:
        // within 2e-6 (f32 sums of terms of order 1).
        for &s in &[0.0f32, 0.1, 0.5, 0.9, 0.999] {
            let h = (1.0 - s).sqrt();
            for &(a, b) in &[(-h, h), (-h, 0.0), (-0.3 * h, 0.7 * h), (0.2 * h, h)] {
                let got = (line_integral(b, s) - line_integral(a, s)) as f64;
                let want = numeric(s as f64, a as f64, b as f64);
                assert!((got - want).abs() < 2e-6, "s {s} [{a}, {b}]: {got} against {want}");
            }
        }
    }

    #[test]
    fn chords_clip_to_their_range() {
        let ball = GpuMetaball { center_radius: Vec4::new(0.0, 0.0, 10.0, 2.0), q: Vec4::new(0.5, 0.0, 0.0, 0.0) };
        let o = Vec3::ZERO;
        let u = Vec3::Z;
        let whole = chord(&ball, o, u, 0.0, f32::MAX);
        let exact = 0.5 * 2.0 * 2.0 * (1.0 - 22.0 / 27.0 + 17.0 / 45.0 - 4.0 / 63.0) as f32;
        assert!((whole - exact).abs() < 1e-5 * exact, "{whole} against {exact}");
        // Half of it before the centre, none past the ball or behind the origin.
        assert!((chord(&ball, o, u, 0.0, 10.0) - 0.5 * exact).abs() < 1e-5 * exact);
        assert_eq!(chord(&ball, o, u, 12.5, 20.0), 0.0);
        assert_eq!(chord(&ball, o, -u, 0.0, f32::MAX), 0.0);
        // A line that misses the sphere.
        assert_eq!(chord(&ball, Vec3::new(2.5, 0.0, 0.0), u, 0.0, f32::MAX), 0.0);
    }

    #[test]
    fn emission_quantiles_split_the_light_as_asked() {
        // The light a chord sends the eye up to its quantile point is the
        // share `q` of the whole, `1 - e^(-tau(z)) = q (1 - e^(-tau))`,
        // against the field's integral by the midpoint rule in f64: within
        // 1e-4 of the share (Newton's 8 steps converge far below; f32
        // polynomials near the chord's ends leave ~1e-5), more on grazing
        // chords (below). A ball of unit weight: `tau = sigma * chord`.
        for &s in &[0.0f32, 0.16, 0.64, 0.9801] {
            let h = (1.0 - s).sqrt();
            for &(z0, z1) in &[(-h, h), (-h, 0.25 * h), (-0.5 * h, 0.5 * h)] {
                let whole = numeric(s as f64, z0 as f64, z1 as f64);
                for &sigma in &[1e-3f32, 0.3, 3.0, 30.0] {
                    let tau = sigma * whole as f32;
                    for &q in &[0.25f32, 0.5, 0.75] {
                        let z = emission_quantile(s, z0, z1, tau, q);
                        let depth = sigma as f64 * numeric(s as f64, z0 as f64, z as f64);
                        let share = (1.0 - (-depth).exp()) / (1.0 - (-(tau as f64)).exp());
                        // On a grazing chord the field's integral is tiny
                        // (2.7e-5 at 0.99 radii) against the polynomial's
                        // terms, each rounded to f32 (1e-8 at |z| ~ 0.15).
                        let bound = 1e-4 + 1.5e-8 / whole;
                        assert!(
                            (share - q as f64).abs() < bound,
                            "s {s}, [{z0}, {z1}], tau {tau}, q {q}: z {z}, share {share}"
                        );
                    }
                }
            }
        }
    }
}
