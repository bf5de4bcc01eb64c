//! Shafts of light: single scattering from every light along each view ray,
//! with shadows (eq. 2-3 of the 2002 shafts-of-light paper), integrated by
//! slice accumulation over sample planes parallel to the screen (eq. 5) with
//! sub-sample planes averaging `H I_l` over each plane interval (eq. 7-9).
//!
//! Beyond the paper:
//! - each view ray is clipped to each light's volume (the cone, or the
//!   window's prism) analytically, and the planes' intervals to that range
//!   and to the visible surface, so no sample is spent where no light is;
//! - the `1/s^2` of eq. 3 is integrated exactly over each interval (it is the
//!   one factor that varies fast near a light), the rest sampled once per
//!   interval, as the paper samples `g` once per plane;
//! - the plane lattice can be offset per pixel by an ordered (Bayer) dither,
//!   which turns banding into a fine, regular pattern.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::camera::{camera_ray, pinhole_direction, pixel_ndc};
use crate::common::surface::LightInputs;
use crate::glam::{UVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::light::{emitted_visible, emitted_visible4, light_local, transmittance, Lanes};
use crate::phase;
use crate::types::{
    CommonParams, GBufferTexel, GpuLight, LIGHT_DIRECTIONAL, LIGHT_POINT, LIGHT_SPOT, PROJECTION_FISHEYE,
};
use crate::volumes::{light_transmittance, LightGrid};
use core::f32::consts::PI;
use spirv_std::spirv;

/// The shafts pass's parameter block.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct ShaftsParams {
    /// Number of sample planes `n` (eq. 5).
    pub plane_count: u32,
    /// Sub-sample planes per plane interval `m` (eq. 9).
    pub subplane_count: u32,
    /// `MODE_EXACT` or `MODE_TABLES`.
    pub mode: u32,
    /// 1 to offset the plane lattice per pixel by an ordered dither.
    pub jitter: u32,
    /// Depth range (along the view direction, metres) the planes span.
    pub depth_near: f32,
    pub depth_far: f32,
    /// Nodes of the phase table `F(alpha)` over [0, pi].
    pub phase_table_size: u32,
    /// Nodes of the attenuation table `h(s, t)` along `s` and `t`.
    pub h_table_s: u32,
    pub h_table_t: u32,
    /// The `h` table covers `[0, h_s_max] x [0, h_t_max]` metres.
    pub h_s_max: f32,
    pub h_t_max: f32,
    /// 1 to integrate the `1/s^2` of eq. 3 exactly over each interval.
    pub analytic_inverse_square: u32,
    /// 1 to round each interval's contribution to 8 bits of the frame
    /// buffer, as the 2002 paper's blending hardware did.
    pub quantize_8bit: u32,
    /// Radiance that maps to 1.0 in the frame buffer is `1 / quantize_scale`
    /// (the PNG exposure).
    pub quantize_scale: f32,
    pub _pad: [u32; 2],
}

#[cfg(not(target_arch = "spirv"))]
// SAFETY: `repr(C)`, sixteen 4-byte scalars, no padding; any bits are valid.
unsafe impl bytemuck::Zeroable for ShaftsParams {}
#[cfg(not(target_arch = "spirv"))]
unsafe impl bytemuck::Pod for ShaftsParams {}

/// A point light is treated as a ball of this radius (metres) in the `1/s^2`
/// factor, so that a view ray through the light gives a large but finite
/// radiance instead of an infinite one. The reference uses the same bound.
pub const LIGHT_RADIUS: f32 = 1e-3;

/// `ShaftsParams::mode`: evaluate the phase and attenuation functions.
pub const MODE_EXACT: u32 = 0;
/// The paper's tables: `F(alpha)` (1D) and `h(s, t)` (2D).
pub const MODE_TABLES: u32 = 1;

/// The interval `[t_lo, t_hi]` of a view ray `o + t d` (d unit) inside a
/// spotlight's cone, intersected with `[t_min, t_max]`; empty if `lo >= hi`.
///
/// Inside the cone of half-angle `theta` means `z >= 0` and
/// `g(t) = cos^2(theta) (x^2 + y^2) - sin^2(theta) z^2 <= 0` in the light's
/// frame; written with `cos^2` and `sin^2` the coefficients stay accurate for
/// angles near 0 and near 90 degrees. `g <= 0` is the double cone, and a
/// line meets each nappe (convex for `theta < 90` degrees) in one interval:
/// - `a > 0` (the line steeper than the cone's sides): `g <= 0` between the
///   roots, a segment inside one nappe, the forward one if `z >= 0` at its
///   middle;
/// - `a < 0` (shallower): `g <= 0` outside the roots, one half-line per nappe;
///   the forward one is the half-line toward which `z` grows (`v.z` is not 0,
///   since `a < 0` needs `v.z^2 > 0`);
/// - `a = 0` (parallel to a side): `g` linear, one half-line, kept if `z >= 0`
///   at a point of it.
///
/// The roots come from the cancellation-free form `q = -(b + sign(b) root)/2`.
pub fn clip_to_cone(light: &GpuLight, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> (f32, f32) {
    let q = light_local(light, o);
    let v = Vec3::new(d.dot(light.axis_x.xyz()), d.dot(light.axis_y.xyz()), d.dot(light.axis_z.xyz()));
    let (c2, s2) = (light.cos2_cutoff, light.sin2_cutoff);
    let a = c2 * (v.x * v.x + v.y * v.y) - s2 * v.z * v.z;
    let b = 2.0 * (c2 * (q.x * v.x + q.y * v.y) - s2 * q.z * v.z);
    let c = c2 * (q.x * q.x + q.y * q.y) - s2 * q.z * q.z;
    let empty = (t_max, t_min);
    let (lo, hi) = if a.abs() > 1e-12 * (b.abs() + c.abs()) {
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            // No real root: `g` has `a`'s sign everywhere. `a < 0` would put
            // the whole line inside the double cone, which only rounding
            // can do (a line through the apex): keep the forward half.
            if a > 0.0 {
                return empty;
            }
            forward_half_line(q.z, v.z)
        } else {
            let root = disc.sqrt();
            let qq = -0.5 * (b + if b >= 0.0 { root } else { -root });
            let (x0, x1) = if qq != 0.0 { (qq / a, c / qq) } else { (0.0, 0.0) };
            let (r0, r1) = (x0.min(x1), x0.max(x1));
            if a > 0.0 {
                if q.z + 0.5 * (r0 + r1) * v.z < 0.0 {
                    return empty;
                }
                (r0, r1)
            } else if v.z > 0.0 {
                (r1, f32::MAX)
            } else {
                (-f32::MAX, r0)
            }
        }
    } else if b != 0.0 {
        // `g = b t + c <= 0` on one side of its root.
        let root = -c / b;
        let (g_lo, g_hi) = if b > 0.0 { (-f32::MAX, root) } else { (root, f32::MAX) };
        let (z_lo, z_hi) = forward_half_line(q.z, v.z);
        (g_lo.max(z_lo), g_hi.min(z_hi))
    } else {
        // `g` constant: the line is on the cone's side or outside it.
        if c > 0.0 {
            return empty;
        }
        forward_half_line(q.z, v.z)
    };
    (lo.max(t_min), hi.min(t_max))
}

/// Where `z = qz + t vz >= 0`: `(lo, hi)` in `t`, empty if nowhere.
fn forward_half_line(qz: f32, vz: f32) -> (f32, f32) {
    if vz > 0.0 {
        (-qz / vz, f32::MAX)
    } else if vz < 0.0 {
        (-f32::MAX, -qz / vz)
    } else if qz >= 0.0 {
        (-f32::MAX, f32::MAX)
    } else {
        (f32::MAX, -f32::MAX)
    }
}

/// Pixels on a side of the square tiles of the shafts' light culling.
pub const TILE: u32 = 8;

/// Tiles across the image (a partial tile at the right edge included).
pub fn tiles_across(common: &CommonParams) -> u32 {
    common.width.div_ceil(TILE)
}

/// Tiles in the image.
pub fn tile_count(common: &CommonParams) -> u32 {
    tiles_across(common) * common.height.div_ceil(TILE)
}

/// The lights whose volume a pixel of tile `index` (row by row) may see,
/// as a bit mask (bit `l` for light `l < 32`; lights from 32 on are always
/// kept): the shafts' per-pixel loop skips the others, and a pixel of a
/// tile with none skips the pass (Fig. 6's cone covers a third of its
/// image). Conservative, never dropping a light a pixel's ray meets:
///
/// every view ray of the tile is within the angle `rho` of the ray through
/// the tile's centre (`rho` the largest angle to its corners: the angle to
/// the centre ray is quasi-convex over the image plane), so up to the
/// distance `t_max` the tile's rays stay within `delta = 2 t_max sin(rho/2)`
/// of that centre ray; and every point within `delta` of a spot's cone lies
/// in the same cone with its apex moved back along the axis by
/// `delta / sin(cutoff)`. So a tile whose centre ray misses the moved cone
/// (`clip_to_cone`, between the planes' nearest and farthest distances)
/// has no pixel whose ray meets the light's. A directional light's volume
/// is widened likewise (its window by `delta` on every side, its entry
/// plane moved back by `delta`). Point lights are kept, and a fisheye keeps
/// every light.
pub fn tile_lights(index: u32, common: &CommonParams, params: &ShaftsParams, lights: &[GpuLight]) -> u32 {
    let count = common.light_count.min(32);
    let every = if count == 32 { u32::MAX } else { (1u32 << count) - 1 };
    if common.projection == PROJECTION_FISHEYE {
        return every;
    }
    let across = tiles_across(common);
    let (x0, y0) = ((index % across) * TILE, (index / across) * TILE);
    let (x1, y1) = ((x0 + TILE).min(common.width), (y0 + TILE).min(common.height));
    let forward = common.camera_forward.xyz();
    let centre =
        pinhole_direction(common, pixel_ndc(common, x0, y0, Vec2::new(0.5 * (x1 - x0) as f32, 0.5 * (y1 - y0) as f32)));
    // The smallest cosine to a corner: of the angle to the centre ray, and
    // of the view angle (`t = depth / cos`).
    let mut cos_rho = 1.0f32;
    let mut cos_view = centre.dot(forward);
    let mut k = 0;
    while k < 4 {
        let (cx, cy) = (if k % 2 == 0 { x0 } else { x1 }, if k < 2 { y0 } else { y1 });
        let corner = pinhole_direction(common, pixel_ndc(common, cx, cy, Vec2::ZERO));
        cos_rho = cos_rho.min(corner.dot(centre));
        cos_view = cos_view.min(corner.dot(forward));
        k += 1;
    }
    let t_max = params.depth_far / cos_view.max(1e-6);
    // 2 sin(rho / 2) = sqrt(2 - 2 cos rho); widened by 1 % and a micrometre
    // per metre of reach for rounding.
    let delta = ((2.0 - 2.0 * cos_rho).max(0.0).sqrt() * 1.01 + 1e-6) * t_max;
    let origin = common.camera_position.xyz();
    let mut mask = 0u32;
    let mut l = 0;
    while l < count as usize {
        let light = &lights[l];
        let sin_cutoff = light.sin2_cutoff.sqrt();
        let keep = if light.in_view == 0 {
            false
        } else if light.kind == LIGHT_DIRECTIONAL {
            // Points within `delta` of the lit volume lie past the entry
            // plane moved back by `delta`, inside the window widened by it.
            let mut widened = *light;
            widened.position = (light.position.xyz() - light.axis_z.xyz() * delta).extend(1.0);
            widened.half_extent_x += delta;
            widened.half_extent_y += delta;
            let (lo, hi) = clip_to_beam(&widened, origin, centre, params.depth_near, t_max);
            lo <= hi
        } else if light.kind != LIGHT_SPOT || sin_cutoff < 1e-6 {
            true
        } else {
            let mut moved = *light;
            moved.position = (light.position.xyz() - light.axis_z.xyz() * (delta / sin_cutoff)).extend(1.0);
            let (lo, hi) = clip_to_cone(&moved, origin, centre, params.depth_near, t_max);
            lo <= hi
        };
        if keep {
            mask |= 1 << l;
        }
        l += 1;
    }
    mask
}

/// The interval of a view ray inside a directional light's lit volume: past
/// its entry plane (`z >= 0`) and, for a window, inside the window's prism
/// `|x| <= half_extent_x`, `|y| <= half_extent_y`; intersected with
/// `[t_min, t_max]`.
pub fn clip_to_beam(light: &GpuLight, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> (f32, f32) {
    let q = light_local(light, o);
    let v = Vec3::new(d.dot(light.axis_x.xyz()), d.dot(light.axis_y.xyz()), d.dot(light.axis_z.xyz()));
    let (mut lo, mut hi) = slab(q.z, v.z, 0.0, f32::MAX, t_min, t_max);
    if light.bounded != 0 {
        let (lx, hx) = slab(q.x, v.x, -light.half_extent_x, light.half_extent_x, lo, hi);
        let (ly, hy) = slab(q.y, v.y, -light.half_extent_y, light.half_extent_y, lx, hx);
        lo = ly;
        hi = hy;
    }
    (lo, hi)
}

/// `[t_min, t_max]` intersected with `{t : lo <= q + t v <= hi}`.
#[allow(clippy::manual_swap)]
fn slab(q: f32, v: f32, lo: f32, hi: f32, t_min: f32, t_max: f32) -> (f32, f32) {
    if v.abs() < 1e-30 {
        if q >= lo && q <= hi {
            return (t_min, t_max);
        }
        return (t_max, t_min);
    }
    let inv = 1.0 / v;
    let mut ta = (lo - q) * inv;
    let mut tb = (hi - q) * inv;
    if ta > tb {
        let t = ta;
        ta = tb;
        tb = t;
    }
    (ta.max(t_min), tb.min(t_max))
}

/// `integral_a^b dt / s(t)^2` along the ray, exactly, where
/// `s(t)^2 = h^2 + (t - t_c)^2` is the squared distance to a point at
/// distance `h` from the ray, closest at `t_c`; `h` is raised to
/// `LIGHT_RADIUS` (see there). Unit 1/m.
///
/// `atan(x_b) - atan(x_a)` is taken as one `atan` of the difference formula
/// where the two are close, so short intervals far from the light keep
/// their digits.
pub fn inverse_square_integral(a: f32, b: f32, t_c: f32, h: f32) -> f32 {
    let h = h.max(LIGHT_RADIUS);
    let xa = (a - t_c) / h;
    let xb = (b - t_c) / h;
    let den = 1.0 + xa * xb;
    let angle = if den > 0.0 { ((xb - xa) / den).atan() } else { xb.atan() - xa.atan() };
    angle / h
}

/// 4x4 Bayer matrix entry for pixel `(x, y)`, in (0, 1): the plane offset of
/// the ordered dither.
/// The entry is the bit-reversed interleaving of `x ^ y` and `y`, which
/// spreads consecutive ranks as far apart in the 4x4 tile as possible.
pub fn bayer4(x: u32, y: u32) -> f32 {
    let v = x ^ y;
    let rank = ((v & 1) << 3) | ((y & 1) << 2) | (((v >> 1) & 1) << 1) | ((y >> 1) & 1);
    (rank as f32 + 0.5) / 16.0
}

/// Phase table lookup: `F(alpha)` on `size` nodes over `alpha` in `[0, pi]`,
/// linear between nodes (the 2002 paper's 1D texture).
pub fn phase_from_table(tables: &[Vec4], size: u32, cos_alpha: f32) -> f32 {
    let alpha = cos_alpha.clamp(-1.0, 1.0).acos();
    let f = (alpha / PI * (size - 1) as f32).clamp(0.0, (size - 1) as f32);
    let i = (f.floor() as u32).min(size - 2);
    let w = f - i as f32;
    tables[i as usize].x * (1.0 - w) + tables[(i + 1) as usize].x * w
}

/// Attenuation table lookup: `h(s, t)` per channel on an `ns x nt` grid over
/// `[0, s_max] x [0, t_max]` (nodes at the cell ends), bilinear, clamped to the
/// table's edge outside it (eq. 6 of the 2002 paper). `offset` is where the
/// table starts in `tables`.
#[allow(clippy::too_many_arguments)]
pub fn attenuation_from_table(
    tables: &[Vec4],
    offset: u32,
    ns: u32,
    nt: u32,
    s_max: f32,
    t_max: f32,
    s: f32,
    t: f32,
) -> Vec4 {
    let fs = (s / s_max * (ns - 1) as f32).clamp(0.0, (ns - 1) as f32);
    let ft = (t / t_max * (nt - 1) as f32).clamp(0.0, (nt - 1) as f32);
    let i = (fs.floor() as u32).min(ns - 2);
    let j = (ft.floor() as u32).min(nt - 2);
    let (ws, wt) = (fs - i as f32, ft - j as f32);
    let at = offset + j * ns + i;
    let a = tables[at as usize] * (1.0 - ws) + tables[(at + 1) as usize] * ws;
    let b = tables[(at + ns) as usize] * (1.0 - ws) + tables[(at + ns + 1) as usize] * ws;
    a * (1.0 - wt) + b * wt
}

/// The smooth part of the attenuation that the `h` table holds, per channel:
/// `sigma_s exp(-sigma_t (s + t))`, times `1/max(s, LIGHT_RADIUS)^2` unless
/// the `1/s^2` is integrated analytically. Unit 1/m (or 1/m^3 with `1/s^2`).
pub fn attenuation(params: &CommonParams, s: f32, t: f32, with_inverse_square: bool) -> Vec4 {
    let mut h = params.sigma_s * transmittance(params.sigma_t, s + t);
    if with_inverse_square {
        let r = s.max(LIGHT_RADIUS);
        h /= r * r;
    }
    Vec4::new(h.x, h.y, h.z, 0.0)
}

/// Table entry `k` of the shaft tables: the phase table's `phase_table_size`
/// nodes first (`F` in `x`), then the `h` table row by row. The host fills the
/// tables with this function on the CPU, so the values are the very ones the
/// exact mode computes at the nodes.
pub fn table_entry(common: &CommonParams, params: &ShaftsParams, k: u32) -> Vec4 {
    let nf = params.phase_table_size;
    if k < nf {
        let alpha = PI * k as f32 / (nf - 1) as f32;
        let f = phase::evaluate(common.phase_kind, alpha.cos(), common.phase_g);
        return Vec4::new(f, f, f, 0.0);
    }
    let k = k - nf;
    let (i, j) = (k % params.h_table_s, k / params.h_table_s);
    let s = params.h_s_max * i as f32 / (params.h_table_s - 1) as f32;
    let t = params.h_t_max * j as f32 / (params.h_table_t - 1) as f32;
    attenuation(common, s, t, params.analytic_inverse_square == 0)
}

/// Most phase nodes one plane interval gets (an interval through a
/// spotlight's apex, with a sharply peaked phase function).
pub const MAX_ANGLE_NODES: u32 = 64;

/// The rest of eq. 3 for a spotlight over one plane interval `[a, b]` of a
/// view ray, per channel, 1/(m sr): `integral_a^b sigma_s p(alpha)
/// exp(-sigma_t (s + t)) / s^2 dt`, where the ray passes the light at
/// distance `h` (metres), closest at `t_c`.
///
/// With `t = t_c + h tan(theta)`, `dt / s^2 = dtheta / h` and
/// `cos(alpha) = -sin(theta)`: the `1/s^2` weight is uniform in `theta`, and
/// the phase angle is a function of `theta` alone. So the smooth factor is
/// averaged over `theta` by the composite midpoint rule, with nodes no
/// further apart than a quarter of the phase function's angular width
/// (`phase::angular_scale`), and multiplied by the exact integral of
/// `1/s^2` (`inverse_square_integral`). Far from the light an interval spans
/// a small angle (estimated as `h (b - a) / s_mid^2`, less than one node
/// spacing) and gets one node at its middle; an interval past the apex may
/// span almost `pi` and gets up to `MAX_ANGLE_NODES`. Sampling the phase at the
/// interval's middle in `t` instead puts it where the `1/s^2` weight is not,
/// which made pixels near a light's apex 15 % too bright with a
/// forward-peaked phase function.
///
/// Without `analytic_inverse_square` (the paper's own form), everything is
/// sampled at the interval's middle, `1/s^2` included.
///
/// `PAPER` as in `shafts_pixel`.
#[allow(clippy::too_many_arguments)]
pub fn spot_interval_weight<const PAPER: bool>(
    common: &CommonParams,
    params: &ShaftsParams,
    tables: &[Vec4],
    a: f32,
    b: f32,
    t_c: f32,
    h: f32,
) -> Vec4 {
    let h = h.max(LIGHT_RADIUS);
    let smooth = |t: f32, s: f32, cos_alpha: f32, with_inverse_square: bool| -> Vec4 {
        if PAPER && params.mode == MODE_TABLES {
            let f = phase_from_table(tables, params.phase_table_size, cos_alpha);
            let h_st = attenuation_from_table(
                tables,
                params.phase_table_size,
                params.h_table_s,
                params.h_table_t,
                params.h_s_max,
                params.h_t_max,
                s,
                t,
            );
            h_st * f
        } else {
            attenuation(common, s, t, with_inverse_square)
                * phase::evaluate(common.phase_kind, cos_alpha, common.phase_g)
        }
    };
    let t_mid = 0.5 * (a + b);
    let s_mid = (h * h + (t_mid - t_c) * (t_mid - t_c)).sqrt();
    if PAPER && params.analytic_inverse_square == 0 {
        return smooth(t_mid, s_mid, (t_c - t_mid) / s_mid, true) * (b - a);
    }
    // Most intervals span a small angle (`dtheta = h dt / s^2`): one node,
    // which may as well sit at the middle in t (no atan needed).
    let step = 0.25 * phase::angular_scale(common.phase_kind, common.phase_g);
    if (b - a) * h < step * s_mid * s_mid {
        return smooth(t_mid, s_mid, (t_c - t_mid) / s_mid, false) * inverse_square_integral(a, b, t_c, h);
    }
    let theta_a = ((a - t_c) / h).atan();
    let theta_b = ((b - t_c) / h).atan();
    let n = (((theta_b - theta_a) / step).ceil() as u32).clamp(1, MAX_ANGLE_NODES);
    let d_theta = (theta_b - theta_a) / n as f32;
    let mut sum = Vec4::ZERO;
    let mut i = 0;
    while i < n {
        let theta = theta_a + (i as f32 + 0.5) * d_theta;
        let (sin, cos) = theta.sin_cos();
        // |theta| < pi/2, so cos > 0; s >= h >= LIGHT_RADIUS.
        let s = h / cos;
        let t = t_c + s * sin;
        sum += smooth(t, s, -sin, false);
        i += 1;
    }
    sum * (inverse_square_integral(a, b, t_c, h) / n as f32)
}

/// In-scattered radiance along the view ray of one pixel, W/(m^2 sr) per
/// channel, in `xyz`; `w` holds the number of `H I_l` samples evaluated.
/// `surface_distance` is the distance to the visible surface (from the
/// G-buffer), where the integral ends.
///
/// For each light and each plane interval `[a, b]` (clipped as described in
/// the module docs), eq. 7: `I_s += J_i g_i`, with `J_i` the mean of `H I_l`
/// over `m` sub-planes in the interval (eq. 9) and `g_i` the rest of eq. 3
/// integrated over the interval:
/// `sigma_s p(alpha) exp(-sigma_t (s + t)) * integral_a^b dt / s^2` at the
/// interval's middle (spotlights), `sigma_s p(alpha) exp(-sigma_t (z + t)) (b - a)`
/// (directional lights, `z` the distance travelled from the entry plane).
///
/// `PAPER` false compiles the function without the 2002 paper's own
/// shortcuts (`MODE_TABLES`, `quantize_8bit`, `1/s^2` sampled instead of
/// integrated), for parameters that ask for none of them (`uses_paper_modes`
/// false): the same result with less code, which llvmpipe (eight pixels in
/// lock-step) runs measurably faster though the branches it leaves out were
/// never taken. `PAPER` true computes every mode.
///
/// `PACKED` evaluates the sub-plane samples four at a time
/// (`light::emitted_visible4`, SIMD on the CPU: the CPU backend's choice),
/// else one by one (`light::emitted_visible`: the GPU's, where a `Vec4`
/// costs four lanes' work and six samples would fill eight); both run the
/// same lane-generic cone, projection and shadow-test functions.
#[allow(clippy::too_many_arguments)]
pub fn shafts_pixel<const PAPER: bool, const PACKED: bool>(
    index: u32,
    common: &CommonParams,
    params: &ShaftsParams,
    lights: &[GpuLight],
    inputs: &LightInputs,
    tables: &[Vec4],
    tiles: &[u32],
    surface_distance: f32,
) -> Vec4 {
    let (light_map, shadow) = (inputs.light_map, inputs.shadow);
    let x = index % common.width;
    let y = index / common.width;
    let lit = tiles[((y / TILE) * tiles_across(common) + x / TILE) as usize];
    if lit == 0 && common.light_count <= 32 {
        return Vec4::ZERO;
    }
    let (o, d) = camera_ray(common, x, y);
    let cos_view = d.dot(common.camera_forward.xyz());
    let planes = params.plane_count;
    let sub = params.subplane_count;
    let dz = (params.depth_far - params.depth_near) / planes as f32;
    let offset = if params.jitter != 0 { bayer4(x, y) - 0.5 } else { 0.0 };
    let t_near = params.depth_near / cos_view;
    let t_far = (params.depth_far / cos_view).min(surface_distance);
    let mut radiance = Vec4::ZERO;
    let mut samples = 0u32;
    let mut l = 0;
    while l < common.light_count as usize {
        light_ref!(light = lights, l);
        let directional = light.kind == LIGHT_DIRECTIONAL;
        let packed = PACKED && light.kind != LIGHT_POINT;
        let culled = l < 32 && lit & (1 << l) == 0;
        let (lo, hi) = if light.in_view == 0 || culled {
            (t_far, t_near)
        } else if directional {
            clip_to_beam(light, o, d, t_near, t_far)
        } else {
            clip_to_cone(light, o, d, t_near, t_far)
        };
        if lo < hi {
            // The ray in the light's frame: local(t) = q + v t.
            let q = light_local(light, o);
            let v = Vec3::new(d.dot(light.axis_x.xyz()), d.dot(light.axis_y.xyz()), d.dot(light.axis_z.xyz()));
            // Closest approach of the ray to a spotlight, for the exact 1/s^2.
            let to_light = light.position.xyz() - o;
            let t_c = to_light.dot(d);
            let h = (to_light - d * t_c).length();
            // Plane intervals [z_k, z_k + dz] in depth, shifted by the dither.
            let k0 = ((lo * cos_view - params.depth_near) / dz - offset).floor().max(-1.0) as i32;
            let k1 = ((hi * cos_view - params.depth_near) / dz - offset).ceil().min(planes as f32 + 1.0) as i32;
            let mut k = k0;
            while k < k1 {
                let z0 = params.depth_near + (k as f32 + offset) * dz;
                let a = (z0 / cos_view).max(lo);
                let b = ((z0 + dz) / cos_view).min(hi);
                if b > a {
                    // Eq. 9: J = mean of H I_l over the sub-planes (four at
                    // a time if `PACKED`, but for a point light).
                    let mut j_sum = Vec4::ZERO;
                    let mut j = 0;
                    while j < sub {
                        if packed {
                            let lane = Vec4::new(j as f32, (j + 1) as f32, (j + 2) as f32, (j + 3) as f32);
                            let u = sub_plane(a, b, lane, sub);
                            let (x, y, z) =
                                (Vec4::splat(q.x) + v.x * u, Vec4::splat(q.y) + v.y * u, Vec4::splat(q.z) + v.z * u);
                            let used = Vec4::select(lane.cmplt(Vec4::splat(sub as f32)), Vec4::ONE, Vec4::ZERO);
                            j_sum += emitted_visible4(light, light_map, shadow, x, y, z, used);
                            j += 4;
                        } else {
                            let local = q + v * sub_plane(a, b, j as f32, sub);
                            j_sum += emitted_visible(light, light_map, shadow, local, 1.0);
                            j += 1;
                        }
                    }
                    // The volumes' shadow (clouds over the haze: shafts
                    // beneath them), once per interval at its middle.
                    let clouds = light_transmittance(inputs.grids, inputs.depths, light, l, o + d * (0.5 * (a + b)));
                    let j_mean = j_sum * clouds / sub as f32;
                    samples += sub;
                    let g = if directional {
                        // g at the interval's middle: nothing in it varies
                        // fast along the ray.
                        let t_mid = 0.5 * (a + b);
                        let z = (q + v * t_mid).z;
                        let cos_alpha = -light.axis_z.xyz().dot(d);
                        let f = phase::evaluate(common.phase_kind, cos_alpha, common.phase_g);
                        attenuation(common, z, t_mid, false) * (f * (b - a))
                    } else {
                        spot_interval_weight::<PAPER>(common, params, tables, a, b, t_c, h)
                    };
                    let contribution = j_mean * g;
                    radiance += if PAPER && params.quantize_8bit != 0 {
                        quantize_8bit(contribution, params.quantize_scale)
                    } else {
                        contribution
                    };
                }
                k += 1;
            }
        }
        l += 1;
    }
    Vec4::new(radiance.x, radiance.y, radiance.z, samples as f32)
}

/// Where sub-plane `j` (eq. 9: the middles of `sub` equal parts) lies in the
/// plane interval `[a, b]` of a view ray, metres along it; for one `j` or,
/// lane by lane, four.
pub fn sub_plane<L: Lanes>(a: f32, b: f32, j: L, sub: u32) -> L {
    L::splat(a) + L::splat(b - a) * (j + L::splat(0.5)) / L::splat(sub as f32)
}

/// Whether `params` ask for any of the 2002 paper's own shortcuts (see
/// `shafts_pixel`'s `PAPER`).
pub fn uses_paper_modes(params: &ShaftsParams) -> bool {
    params.mode == MODE_TABLES || params.quantize_8bit != 0 || params.analytic_inverse_square == 0
}

/// Rounds a radiance to the nearest of 256 frame-buffer levels, where level
/// 255 is radiance `1 / scale` (the 2002 paper blended 8-bit planes).
pub fn quantize_8bit(v: Vec4, scale: f32) -> Vec4 {
    let q = |c: f32| (c * scale * 255.0 + 0.5).floor().clamp(0.0, 255.0) / (255.0 * scale);
    Vec4::new(q(v.x), q(v.y), q(v.z), v.w)
}

/// The shafts pass's entry points: `$name` runs `shafts_pixel::<$paper, false>`.
macro_rules! shafts_entry_point {
    ($(#[$doc:meta])* $name:ident, $paper:literal) => {
        $(#[$doc])*
        #[allow(clippy::too_many_arguments)]
        #[spirv(compute(threads(64)))]
        pub fn $name(
            #[spirv(global_invocation_id)] id: UVec3,
            #[spirv(num_workgroups)] groups: UVec3,
            #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] light_map: &[Vec4],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] shadow: &[f32],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 10)] params: &[ShaftsParams],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 11)] tables: &[Vec4],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 12)] radiance: &mut [Vec4],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 39)] tiles: &[u32],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
            #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
        ) {
            let index = crate::flat_index(id, groups);
            let common = &common[0];
            if index < common.band_pixels {
                let distance = gbuffer[index as usize].normal_distance.w;
                radiance[index as usize] = shafts_pixel::<$paper, false>(
                    common.band_start + index,
                    common,
                    &params[0],
                    lights,
                    &LightInputs { light_map, shadow, grids, depths },
                    tables,
                    tiles,
                    distance,
                );
            }
        }
    };
}

shafts_entry_point!(
    /// The shafts pass's entry point for every mode (`uses_paper_modes` true).
    shafts_kernel,
    true
);
shafts_entry_point!(
    /// The shafts pass's entry point for parameters without the paper's own
    /// shortcuts (`uses_paper_modes` false).
    shafts_exact_kernel,
    false
);

/// The shafts' light-culling entry point: one invocation per tile
/// (`tile_lights`).
#[spirv(compute(threads(64)))]
pub fn shafts_tiles_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 10)] params: &[ShaftsParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 39)] tiles: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < tile_count(common) {
        tiles[index as usize] = tile_lights(index, common, &params[0], lights);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (64-bit LCG) for test rays.
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f32 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((self.0 >> 40) as f32) / (1u64 << 24) as f32
        }
        fn signed(&mut self) -> f32 {
            2.0 * self.next() - 1.0
        }
    }

    fn spot(cutoff_deg: f32) -> GpuLight {
        let c = cutoff_deg.to_radians();
        let (tan_cutoff, cos2_cutoff, sin2_cutoff) = crate::light::cone_terms(c);
        GpuLight {
            position: Vec4::new(0.3, 2.0, -1.0, 1.0),
            axis_x: Vec4::X,
            axis_y: Vec4::NEG_Z,
            axis_z: Vec4::NEG_Y,
            cutoff: c,
            beam: c,
            tan_cutoff,
            cos2_cutoff,
            sin2_cutoff,
            ..Default::default()
        }
    }

    /// Inside the cone, decided in f64 from the angle to the axis.
    fn inside(light: &GpuLight, p: Vec3) -> bool {
        let v = (p - light.position.xyz()).as_dvec3();
        let axis = light.axis_z.xyz().as_dvec3();
        let along = v.dot(axis);
        along > 0.0 && (v - axis * along).length().atan2(along) <= light.cutoff as f64
    }

    /// How far `p` is from the cone's side (the nearest of its generating
    /// lines, or the apex), metres, in f64.
    fn off_the_side(light: &GpuLight, p: Vec3) -> f64 {
        let v = (p - light.position.xyz()).as_dvec3();
        let axis = light.axis_z.xyz().as_dvec3();
        let along = v.dot(axis);
        let angle = ((v - axis * along).length().atan2(along) - light.cutoff as f64).abs();
        v.length() * angle.min(core::f64::consts::FRAC_PI_2).sin()
    }

    #[test]
    fn cone_clipping_matches_brute_force_membership() {
        let mut rng = Lcg(7);
        for cutoff in [0.5f32, 10.0, 30.0, 60.0, 85.0, 89.9] {
            let light = spot(cutoff);
            for _ in 0..1000 {
                let o = Vec3::new(rng.signed() * 4.0, rng.signed() * 4.0, rng.signed() * 4.0);
                // Aim near the light often, so that narrow cones get hit.
                let target = light.position.xyz() + Vec3::new(rng.signed(), -3.0 * rng.next(), rng.signed()) * 0.5;
                let d = match rng.next() {
                    // Aimed near the light.
                    x if x < 0.5 => (target - o).normalize(),
                    // Any direction (lines through both nappes, or none).
                    x if x < 0.8 => Vec3::new(rng.signed(), rng.signed(), rng.signed()).normalize(),
                    // Parallel to one of the cone's sides (`a = 0`).
                    _ => {
                        let phi = rng.next() * core::f32::consts::TAU;
                        let c = cutoff.to_radians();
                        let side = light.axis_z.xyz() * c.cos()
                            + (light.axis_x.xyz() * phi.cos() + light.axis_y.xyz() * phi.sin()) * c.sin();
                        if rng.next() < 0.5 {
                            side
                        } else {
                            -side
                        }
                    }
                };
                let (lo, hi) = clip_to_cone(&light, o, d, 0.0, 20.0);
                // Every sample strictly inside [lo, hi] (away from the ends
                // by f32 rounding of the roots) is in the cone, and every
                // sample outside is not, but for points within 4e-4 of the
                // origin's distance to the apex from the cone's side: `g`'s
                // terms are that large at the origin, and near a nearly flat
                // cone's apex `g` changes slowly along the ray (at 89.9
                // degrees the worst point seen is 1.7e-4 of it, 1 mm of
                // 5.7 m, off the side; the sorted-breakpoints version of this
                // function before it had the same worst point).
                let eps = 1e-3;
                for k in 0..400 {
                    let t = 20.0 * (k as f32 + 0.5) / 400.0;
                    let p = o + d * t;
                    let ratio = off_the_side(&light, p) / (o - light.position.xyz()).length() as f64;
                    let grazing = ratio < 4e-4;
                    if lo < hi && t > lo + eps && t < hi - eps && !grazing {
                        assert!(inside(&light, p), "cutoff {cutoff}: t={t} in [{lo},{hi}] but outside");
                    }
                    if (lo >= hi || t < lo - eps || t > hi + eps) && !grazing {
                        assert!(!inside(&light, p), "cutoff {cutoff}: t={t} outside [{lo},{hi}] but inside");
                    }
                }
            }
        }
    }

    #[test]
    fn tile_culling_keeps_every_light_a_pixel_of_the_tile_sees() {
        // Three spots and a window's directional light per case.
        let mut next = crate::test_uniforms(99);
        let (mut pairs, mut culled, mut windows_culled) = (0u32, 0u32, 0u32);
        for case in 0..80u32 {
            let eye = Vec3::new(12.0 * next() - 6.0, 0.5 + 3.5 * next(), 4.0 + 6.0 * next());
            let target = Vec3::new(2.0 * next() - 1.0, 3.0 * next(), 2.0 * next() - 1.0);
            let forward = (target - eye).normalize();
            let right = forward.cross(Vec3::Y).normalize();
            let up = right.cross(forward);
            let (width, height) = (40 + case, 30 + case / 2);
            let tan_half = (0.2 + 0.6 * next()).tan();
            let common = CommonParams {
                camera_position: eye.extend(1.0),
                camera_forward: forward.extend(0.0),
                camera_right: (right * tan_half * width as f32 / height as f32).extend(0.0),
                camera_up: (up * tan_half).extend(0.0),
                width,
                height,
                light_count: 3,
                samples_per_pixel: 1,
                ..Default::default()
            };
            let lights: [GpuLight; 3] = core::array::from_fn(|_| {
                let mut light = spot(3.0 + 60.0 * next());
                let z = Vec3::new(2.0 * next() - 1.0, -1.0, 2.0 * next() - 1.0).normalize();
                let x = z.cross(Vec3::Z).normalize();
                light.position = Vec3::new(6.0 * next() - 3.0, 2.0 + 4.0 * next(), 6.0 * next() - 3.0).extend(1.0);
                (light.axis_x, light.axis_y, light.axis_z) = (x.extend(0.0), z.cross(x).extend(0.0), z.extend(0.0));
                light.kind = LIGHT_SPOT;
                light.in_view = 1;
                light
            });
            // And a directional light through a window.
            let z = Vec3::new(0.6 * next() - 0.3, -1.0, 0.6 * next() - 0.3).normalize();
            let x = z.cross(Vec3::Z).normalize();
            let window = GpuLight {
                kind: LIGHT_DIRECTIONAL,
                position: Vec3::new(4.0 * next() - 2.0, 5.0, 4.0 * next() - 2.0).extend(1.0),
                axis_x: x.extend(0.0),
                axis_y: z.cross(x).extend(0.0),
                axis_z: z.extend(0.0),
                half_extent_x: 0.2 + next(),
                half_extent_y: 0.2 + next(),
                bounded: 1,
                in_view: 1,
                ..Default::default()
            };
            let lights = [lights[0], lights[1], lights[2], window];
            let common = CommonParams { light_count: 4, ..common };
            let params =
                ShaftsParams { depth_near: 0.1 + next(), depth_far: 5.0 + 15.0 * next(), ..Default::default() };
            for tile in 0..tile_count(&common) {
                let mask = tile_lights(tile, &common, &params, &lights);
                let (tx, ty) = (tile % tiles_across(&common), tile / tiles_across(&common));
                for (l, light) in lights.iter().enumerate() {
                    let kept = mask & (1 << l) != 0;
                    pairs += 1;
                    culled += (!kept) as u32;
                    windows_culled += (!kept && light.kind == LIGHT_DIRECTIONAL) as u32;
                    if kept {
                        continue;
                    }
                    // A culled light: no ray through any pixel of the tile
                    // (corners, middle) meets its cone between the planes.
                    for y in ty * TILE..((ty + 1) * TILE).min(height) {
                        for x in tx * TILE..((tx + 1) * TILE).min(width) {
                            for offset in [
                                Vec2::ZERO,
                                Vec2::splat(0.5),
                                Vec2::new(0.999, 0.0),
                                Vec2::new(0.0, 0.999),
                                Vec2::splat(0.999),
                            ] {
                                let d = pinhole_direction(&common, pixel_ndc(&common, x, y, offset));
                                let cos = d.dot(forward);
                                let clip = if light.kind == LIGHT_DIRECTIONAL { clip_to_beam } else { clip_to_cone };
                                let (lo, hi) = clip(light, eye, d, params.depth_near / cos, params.depth_far / cos);
                                assert!(lo >= hi, "case {case}: pixel ({x}, {y}) sees light {l} in [{lo}, {hi}], culled in tile {tile}");
                            }
                        }
                    }
                }
            }
        }
        // The culling does cull: many (tile, light) pairs here see nothing.
        assert!(culled > pairs / 3, "{culled} of {pairs} culled");
        assert!(windows_culled > pairs / 16, "{windows_culled} of {pairs} culled for the windows");
    }

    #[test]
    fn ray_along_the_axis_and_from_the_apex() {
        let light = spot(20.0);
        let o = light.position.xyz();
        let (lo, hi) = clip_to_cone(&light, o, Vec3::NEG_Y, 0.0, 10.0);
        assert_eq!((lo, hi), (0.0, 10.0));
        // Pointing away from the cone.
        let (lo, hi) = clip_to_cone(&light, o, Vec3::Y, 0.0, 10.0);
        assert!(lo >= hi);
    }

    #[test]
    fn inverse_square_integral_matches_quadrature() {
        let cases = [
            (0.0f32, 1.0f32, 0.5f32, 0.2f32),
            (0.0, 10.0, 3.0, 1e-3),
            (5.0, 5.01, 0.0, 2.0),
            (100.0, 101.0, 0.0, 0.1),
            (0.0, 2.0, 1.0, 1e-6),
        ];
        for (a, b, tc, h) in cases {
            let hh = (h as f64).max(LIGHT_RADIUS as f64);
            // The antiderivative in f64 is exact; compare f32 to it.
            let exact = (((b - tc) as f64 / hh).atan() - ((a - tc) as f64 / hh).atan()) / hh;
            let got = inverse_square_integral(a, b, tc, h) as f64;
            assert!((got - exact).abs() <= 1e-5 * exact.abs() + 1e-12, "{a} {b} {tc} {h}: {got} vs {exact}");
        }
    }

    #[test]
    fn bayer_offsets_are_the_sixteen_levels() {
        let mut seen = [false; 16];
        for y in 0..4 {
            for x in 0..4 {
                seen[(bayer4(x, y) * 16.0) as usize] = true;
            }
        }
        assert!(seen.iter().all(|s| *s));
    }

    #[test]
    fn tables_are_exact_at_nodes_and_clamped_outside() {
        let common = CommonParams {
            sigma_s: Vec4::new(0.1, 0.2, 0.3, 0.0),
            sigma_t: Vec4::new(0.2, 0.3, 0.4, 0.0),
            phase_kind: crate::types::PHASE_HENYEY_GREENSTEIN,
            phase_g: 0.7,
            ..Default::default()
        };
        let params = ShaftsParams {
            phase_table_size: 64,
            h_table_s: 16,
            h_table_t: 8,
            h_s_max: 15.0,
            h_t_max: 7.0,
            analytic_inverse_square: 1,
            ..Default::default()
        };
        let n = params.phase_table_size + params.h_table_s * params.h_table_t;
        let tables: Vec<Vec4> = (0..n).map(|k| table_entry(&common, &params, k)).collect();
        let alpha = PI * 5.0 / 63.0;
        let f = phase_from_table(&tables, 64, alpha.cos());
        let exact = phase::henyey_greenstein(alpha.cos(), 0.7);
        assert!((f - exact).abs() < 1e-4 * exact);
        let h = attenuation_from_table(&tables, 64, 16, 8, 15.0, 7.0, 3.0, 2.0);
        let e = attenuation(&common, 3.0, 2.0, false);
        assert!((h - e).abs().max_element() < 1e-6);
        // Outside the table: the edge value, finite.
        let far = attenuation_from_table(&tables, 64, 16, 8, 15.0, 7.0, 1e5, -3.0);
        assert_eq!(far, attenuation_from_table(&tables, 64, 16, 8, 15.0, 7.0, 15.0, 0.0));
        assert!(far.is_finite());
    }
}
