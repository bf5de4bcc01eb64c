//! The wave surface as one sub-pixel sample sees it: the distribution of
//! the slopes under the sample's footprint, and the light it reflects.
//!
//! A pixel near the horizon covers hundreds of waves; one wave normal per
//! sample there is a random pick among them, and the sun's reflection in it
//! sparkles. Following Bruneton, Neyret and Holzschuch ("Real-time
//! Realistic Ocean Lighting using Seamless Transitions from Geometry to
//! BRDF", 2010) the surface under a footprint is described by its slopes'
//! mean and covariance instead: the waves the footprint does not resolve
//! become roughness. The map's slope moments are kept as a pyramid
//! (`E[s]`, `E[s s^T]` averaged 2x2 per level: LEAN mapping, Olano and
//! Baker 2010), which averages linearly, so a footprint's moments are the
//! mean of a few trilinear lookups along its long axis.
//!
//! Slopes are `s = (dh/dx, dh/dz)` (dimensionless; the normal is
//! `normalize(-s_x, 1, -s_z)`). The covariance adds the waves shorter than
//! the map's texels (`SeaParams::roughness`: Cox and Munk's measured slope
//! variance minus the map's own), so the sun's glitter has its real width
//! at every distance.
//!
//! The pyramid: level `l` has `(n >> l)^2` texels of two `Vec4`s,
//! `(E[s_x], E[s_z], E[s_x^2], E[s_z^2])` and `(E[s_x s_z], 0, 0, 0)`;
//! level 0 holds the map's point values, level `log2 n` one texel.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use super::{SeaParams, WAVES_NORMAL_MAP};
use crate::camera::{ray_direction, sample_offset};
use crate::glam::{Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::optics::reflectance;
use crate::sky::{transmittance_to_space, SkyParams};
use crate::types::CommonParams;
use core::f32::consts::PI;

/// `Vec4`s per pyramid texel.
pub const TEXEL_VEC4S: u32 = 2;

/// The most lookups along a footprint's long axis; a longer footprint is
/// read at a coarser level (wider across than it is).
pub const MAX_TAPS: u32 = 16;

/// The slopes under a footprint: mean `(s_x, s_z)` and covariance
/// `(xx, zz, xz)`, dimensionless. (Kept in `Vec4`s: a struct nested in
/// another must have the size SPIR-V's layout gives it, a multiple of 16
/// with a vector of three.)
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Slopes {
    m: Vec4,
    c: Vec4,
}

impl Slopes {
    pub fn new(mean: Vec2, cov: Vec3) -> Slopes {
        Slopes { m: mean.extend(0.0).extend(0.0), c: cov.extend(0.0) }
    }
    pub fn mean(&self) -> Vec2 {
        self.m.xy()
    }
    pub fn cov(&self) -> Vec3 {
        self.c.xyz()
    }
}

/// The first texel of pyramid level `level` of an `n x n` map (`n` a power
/// of two up to 4096): `sum_{l < level} (n >> l)^2 = 4 (n^2 - (n >> level)^2) / 3`.
pub fn level_offset(n: u32, level: u32) -> u32 {
    let m = n >> level;
    4 * (n * n - m * m) / 3
}

/// The pyramid's coarsest level (`log2 n`).
pub fn top_level(n: u32) -> u32 {
    31 - n.leading_zeros()
}

/// The unit normal of a surface of slopes `s`.
pub fn slope_normal(s: Vec2) -> Vec3 {
    Vec3::new(-s.x, 1.0, -s.y).normalize()
}

/// The wave map's slope `(s_x, s_z)` at its grid point `(i, j)` (level 0,
/// tiled: indices wrap).
pub fn grid_slope(p: &SeaParams, waves: &[Vec4], i: u32, j: u32) -> Vec2 {
    let n = p.wave_resolution;
    texel(p, waves, 0, i % n, j % n).0.xy()
}

/// The mean slope of level `level`'s texel `(i, j)` (tiled): the waves
/// averaged over `2^level` base texels each way.
pub fn level_slope(p: &SeaParams, waves: &[Vec4], level: u32, i: u32, j: u32) -> Vec2 {
    let m = p.wave_resolution >> level;
    texel(p, waves, level, i % m, j % m).0.xy()
}

/// Texel `(i, j)` of level `level`: its two `Vec4`s.
fn texel(p: &SeaParams, waves: &[Vec4], level: u32, i: u32, j: u32) -> (Vec4, Vec4) {
    let m = p.wave_resolution >> level;
    let at = ((level_offset(p.wave_resolution, level) + j * m + i) * TEXEL_VEC4S) as usize;
    (waves[at], waves[at + 1])
}

/// Level `level`'s moments at the horizontal point `(x, z)` (m), bilinear
/// between its texel centres, the tile repeating: `(E[s], E[s_x^2], E[s_z^2])`
/// in the first `Vec4`, `E[s_x s_z]` in the second's x.
fn level_moments(p: &SeaParams, waves: &[Vec4], level: u32, x: f32, z: f32) -> (Vec4, Vec4) {
    let n = p.wave_resolution;
    let m = n >> level;
    let scale = (1u32 << level) as f32;
    // Level 0's texel `i` sits at `i` base texels; level `l`'s texel `j`
    // averages base texels `j 2^l .. (j + 1) 2^l - 1`, centred at `j 2^l + (2^l - 1) / 2`.
    let wrap = |v: f32| {
        let f = (v / p.wave_size) * n as f32;
        let f = (f - (scale - 1.0) * 0.5) / scale;
        f - (f / m as f32).floor() * m as f32
    };
    let (fx, fz) = (wrap(x), wrap(z));
    let (x0, z0) = ((fx as u32).min(m - 1), (fz as u32).min(m - 1));
    let (ax, az) = (fx - x0 as f32, fz - z0 as f32);
    let (x1, z1) = ((x0 + 1) % m, (z0 + 1) % m);
    let (a0, a1) = texel(p, waves, level, x0, z0);
    let (b0, b1) = texel(p, waves, level, x1, z0);
    let (c0, c1) = texel(p, waves, level, x0, z1);
    let (d0, d1) = texel(p, waves, level, x1, z1);
    let first = (a0 * (1.0 - ax) + b0 * ax) * (1.0 - az) + (c0 * (1.0 - ax) + d0 * ax) * az;
    let second = (a1 * (1.0 - ax) + b1 * ax) * (1.0 - az) + (c1 * (1.0 - ax) + d1 * ax) * az;
    (first, second)
}

/// The slopes at the point `(x, z)` (bilinear in the map's point values)
/// and their rates of change along x and along z (1/m).
fn point_slopes(p: &SeaParams, waves: &[Vec4], x: f32, z: f32) -> (Vec2, Vec2, Vec2) {
    let n = p.wave_resolution;
    let texel_m = p.wave_size / n as f32;
    let f = |v: f32| {
        let u = v / p.wave_size;
        (u - u.floor()) * n as f32
    };
    let (fx, fz) = (f(x), f(z));
    let (x0, z0) = ((fx as u32).min(n - 1), (fz as u32).min(n - 1));
    let (ax, az) = (fx - x0 as f32, fz - z0 as f32);
    let (x1, z1) = ((x0 + 1) % n, (z0 + 1) % n);
    let a = texel(p, waves, 0, x0, z0).0.xy();
    let b = texel(p, waves, 0, x1, z0).0.xy();
    let c = texel(p, waves, 0, x0, z1).0.xy();
    let d = texel(p, waves, 0, x1, z1).0.xy();
    let mean = (a * (1.0 - ax) + b * ax) * (1.0 - az) + (c * (1.0 - ax) + d * ax) * az;
    let along_x = ((b - a) * (1.0 - az) + (d - c) * az) / texel_m;
    let along_z = ((c - a) * (1.0 - ax) + (d - b) * ax) / texel_m;
    (mean, along_x, along_z)
}

/// The surface's unit normal at the point `(x, z)`: up for a flat sea,
/// else from the map's slopes, bilinear, tiled (no footprint, no roughness).
pub fn point_normal(p: &SeaParams, waves: &[Vec4], x: f32, z: f32) -> Vec3 {
    if p.waves != WAVES_NORMAL_MAP {
        return Vec3::Y;
    }
    slope_normal(point_slopes(p, waves, x, z).0)
}

/// The current sub-pixel sample's footprint on the mean surface: the two
/// edges (x, z in m) of the image of its cell (a pixel divided by
/// `sqrt(samples_per_pixel)` each way), for the ray `dir` meeting the level
/// plane `t` metres from the eye. From ray differentials: a change `dd` of
/// the direction moves the hit by `t (dd - dir dd_y / dir_y)`. Each edge is
/// at most `limit` long (past a whole tile the statistics no longer change).
pub fn footprint(common: &CommonParams, x: u32, y: u32, dir: Vec3, t: f32, limit: f32) -> (Vec2, Vec2) {
    let offset = sample_offset(common.sample_index, common.samples_per_pixel);
    let cell = 1.0 / (common.samples_per_pixel.max(1) as f32).sqrt();
    let edge = |step: Vec2| {
        let dd = ray_direction(common, x, y, offset + step * 0.5) - ray_direction(common, x, y, offset - step * 0.5);
        let moved = (dd - dir * (dd.y / dir.y)) * t;
        let v = Vec2::new(moved.x, moved.z);
        let length = v.length();
        if length > limit {
            v * (limit / length)
        } else {
            v
        }
    };
    (edge(Vec2::new(cell, 0.0)), edge(Vec2::new(0.0, cell)))
}

/// Level 0 in point mode: the moments of the map's bilinear slopes over a
/// box of edges `a`, `b` (m) centred on `(x, z)`: the centre's slope and,
/// from its gradient `G`, the spread `(G a)(G a)^T / 12 + (G b)(G b)^T / 12`
/// (a box's variance along an edge of length 1 is 1/12). Laid out as a
/// pyramid texel (`level_moments`).
fn point_moments(p: &SeaParams, waves: &[Vec4], x: f32, z: f32, a: Vec2, b: Vec2) -> (Vec4, f32) {
    let (mean, gx, gz) = point_slopes(p, waves, x, z);
    let (da, db) = (gx * a.x + gz * a.y, gx * b.x + gz * b.y);
    let spread = Vec3::new(da.x * da.x + db.x * db.x, da.y * da.y + db.y * db.y, da.x * da.y + db.x * db.y) / 12.0;
    let first = Vec4::new(mean.x, mean.y, mean.x * mean.x + spread.x, mean.y * mean.y + spread.y);
    (first, mean.x * mean.y + spread.z)
}

/// The slopes under a footprint of edges `a` and `b` (m) centred on
/// `(x, z)`, with the unresolved waves' roughness added.
///
/// The footprint is read as up to `MAX_TAPS` boxes along its long edge,
/// each as wide as the footprint across, and their moments averaged:
/// `cov = E[s s^T] - E[s] E[s]^T`. A box is read at the pyramid level
/// whose bilinear tent has the variance of the box (`2^l = w / sqrt 2`
/// texels for a box `w` texels wide), trilinear; at level 0 by the map's
/// bilinear slopes and their gradient over the box (`point_moments`)
/// rather than by interpolated moments, whose spread between texel centres
/// is the interpolation's, not the surface's.
pub fn footprint_slopes(p: &SeaParams, waves: &[Vec4], x: f32, z: f32, a: Vec2, b: Vec2) -> Slopes {
    let texel_m = p.wave_size / p.wave_resolution as f32;
    let (la, lb) = (a.length() / texel_m, b.length() / texel_m);
    let (major, minor, long, short) = if la >= lb { (a, b, la, lb) } else { (b, a, lb, la) };
    let top = top_level(p.wave_resolution);
    let width = short.max(long / MAX_TAPS as f32);
    let lod = (width.max(1e-6).log2() - 0.5).clamp(0.0, top as f32);
    let taps = ((long / width.max(1.0)).ceil() as u32).clamp(1, MAX_TAPS);
    let l0 = (lod as u32).min(top);
    let l1 = (l0 + 1).min(top);
    let f = lod - l0 as f32;
    let step = major / taps as f32;
    let mut first = Vec4::ZERO;
    let mut cross = 0.0;
    let mut i = 0;
    while i < taps {
        let along = major * ((i as f32 + 0.5) / taps as f32 - 0.5);
        let (px, pz) = (x + along.x, z + along.y);
        let (a0, a1) = if l0 == 0 {
            point_moments(p, waves, px, pz, step, minor)
        } else {
            let (m, c) = level_moments(p, waves, l0, px, pz);
            (m, c.x)
        };
        first += a0 * (1.0 - f);
        cross += a1 * (1.0 - f);
        if f > 0.0 {
            let (b0, b1) = level_moments(p, waves, l1, px, pz);
            first += b0 * f;
            cross += b1.x * f;
        }
        i += 1;
    }
    let (first, cross) = (first / taps as f32, cross / taps as f32);
    let mean = first.xy();
    let cov =
        Vec3::new((first.z - mean.x * mean.x).max(0.0), (first.w - mean.y * mean.y).max(0.0), cross - mean.x * mean.y);
    Slopes::new(mean, cov + p.roughness.xyz())
}

/// The standard normal's upper tail `Q(z) = P(Z > z)`, from erfc
/// (Abramowitz and Stegun 7.1.26, absolute error under 1.5e-7, relative
/// accuracy kept in the far tail by the `exp(-x^2)` factor).
pub fn normal_upper_tail(z: f32) -> f32 {
    let x = z.abs() * core::f32::consts::FRAC_1_SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t * (0.254_829_6 + t * (-0.284_496_74 + t * (1.421_413_8 + t * (-1.453_152_1 + t * 1.061_405_4))));
    let half_erfc = 0.5 * poly * (-x * x).exp();
    if z >= 0.0 {
        half_erfc
    } else {
        1.0 - half_erfc
    }
}

/// Nodes of the slope rule along the view (`SLOPE_NODES` = this + 1).
pub const ALONG_NODES: u32 = 8;

/// How far along the view the rule reaches, in standard deviations (the
/// mass beyond is 3e-5 and the weights are renormalised to the rest).
const ALONG_REACH: f32 = 4.0;

/// Node `i` (0..8) of 8-point Gauss-Legendre on (-1, 1): position and weight.
fn gauss_legendre8(i: u32) -> (f32, f32) {
    let (x, w) = if i < 2 {
        (0.960_289_86, 0.101_228_54)
    } else if i < 4 {
        (0.796_666_5, 0.222_381_03)
    } else if i < 6 {
        (0.525_532_4, 0.313_706_64)
    } else {
        (0.183_434_64, 0.362_683_78)
    };
    (if i & 1 == 0 { -x } else { x }, w)
}

/// The standard normal density.
fn standard_normal(z: f32) -> f32 {
    (-0.5 * z * z).exp() * 0.398_942_3
}

/// One facet of a `SlopeRule`: its unit normal, its weight, and the cosine
/// Fresnel's law takes (`cos_i`, see `SlopeRule`).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Facet {
    pub normal: Vec3,
    pub weight: f32,
    pub cos_i: f32,
}

/// The slopes under a footprint as a quadrature rule for an eye looking
/// along `dir`. Each point of the footprint counts by its horizontal area
/// (as a sample that meets the mean surface there and reads its slope
/// would: averaging such samples converges to this), and a facet turned
/// away from the eye is seen edge-on, as the mean surface (normal up).
///
/// Whether a facet faces the eye, and most of its Fresnel reflectance,
/// depend only on its slope along the view's horizontal direction, so the
/// rule runs in that frame: 8-point Gauss-Legendre with the normal density
/// over the facing part of that axis, `z` from the facets' horizon `z*` (or
/// -4) to 4 standard deviations (the jump at `z*` is an end of the rule,
/// not inside it; a Gauss-Hermite rule across it, or Gauss-Legendre in
/// probability, which starves the tails, were 2 % off at 60 degrees), and
/// one last node, up, carrying the turned-away share. Across, each node
/// takes the conditional mean slope, and the conditional variance `l22^2`
/// enters the normal's length in Fresnel's cosine, `cos_i = v . N /
/// sqrt(1 + |s|^2 + l22^2)` (the across slope's effect on `cos_i` is of
/// second order): within 0.25 % of Monte Carlo where a 3-node rule across
/// took three times the work.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct SlopeRule {
    /// The view ray's direction (unit, downward); w: the factor that made
    /// the facing nodes' weights sum to `facing`.
    dir_scale: Vec4,
    /// Unit horizontal axes along (xy) and across (zw) the view.
    axes: Vec4,
    /// The mean slope along and across (xy), and the rule's range of `z`
    /// along, in standard deviations (zw).
    mean_range: Vec4,
    /// The Cholesky factor of the covariance in that frame (`l11`, `l21`,
    /// `l22`); w: the share of facets facing the eye, `P(N . v > 0)` with
    /// `N = (-s_x, 1, -s_z)`, `v = -dir`. (All `Vec4`s: see `Slopes`.)
    factor_facing: Vec4,
    /// The facing nodes' weights (nodes 0-3, 4-7), summing to `facing`.
    weights_low: Vec4,
    weights_high: Vec4,
}

impl SlopeRule {
    pub fn dir(&self) -> Vec3 {
        self.dir_scale.xyz()
    }
    pub fn facing(&self) -> f32 {
        self.factor_facing.w
    }
}

/// Nodes of the slope rule (`SlopeRule`): facing ones and the turned-away share.
pub const SLOPE_NODES: u32 = ALONG_NODES + 1;

impl SlopeRule {
    /// The rule for the slopes `s` seen along `dir`.
    pub fn new(s: &Slopes, dir: Vec3) -> SlopeRule {
        let horizontal = Vec2::new(dir.x, dir.z);
        let length = horizontal.length();
        let along = if length > 1e-6 { horizontal / length } else { Vec2::X };
        let across = Vec2::new(-along.y, along.x);
        let cov = s.cov();
        let var = |a: Vec2, b: Vec2| a.x * b.x * cov.x + a.y * b.y * cov.y + (a.x * b.y + a.y * b.x) * cov.z;
        let l11 = var(along, along).max(0.0).sqrt();
        let l21 = if l11 > 0.0 { var(along, across) / l11 } else { 0.0 };
        let l22 = (var(across, across) - l21 * l21).max(0.0).sqrt();
        let mean = Vec2::new(s.mean().dot(along), s.mean().dot(across));
        // Facing: N . v = -dir_y + s_along |dir_xz| > 0.
        let facing = if length <= 1e-6 {
            1.0
        } else if l11 > 0.0 {
            normal_upper_tail((dir.y / length - mean.x) / l11)
        } else if mean.x * length > dir.y {
            1.0
        } else {
            0.0
        };
        let z_star = if length > 1e-6 && l11 > 0.0 { (dir.y / length - mean.x) / l11 } else { -ALONG_REACH };
        let range = Vec2::new(z_star.clamp(-ALONG_REACH, ALONG_REACH), ALONG_REACH);
        let weight = |i: u32| {
            let (x, w) = gauss_legendre8(i);
            w * standard_normal(range.x + (range.y - range.x) * 0.5 * (1.0 + x))
        };
        let low = Vec4::new(weight(0), weight(1), weight(2), weight(3));
        let high = Vec4::new(weight(4), weight(5), weight(6), weight(7));
        let mass = low.element_sum() + high.element_sum();
        let scale = if mass > 0.0 { facing / mass } else { 0.0 };
        SlopeRule {
            dir_scale: dir.extend(scale),
            axes: Vec4::new(along.x, along.y, across.x, across.y),
            mean_range: Vec4::new(mean.x, mean.y, range.x, range.y),
            factor_facing: Vec4::new(l11, l21, l22, facing),
            weights_low: low * scale,
            weights_high: high * scale,
        }
    }

    /// Node `k` (`0..SLOPE_NODES`; the weights sum to 1).
    pub fn node(&self, k: u32) -> Facet {
        let dir = self.dir();
        let facing = self.facing();
        let edge_on = Facet { normal: Vec3::Y, weight: 1.0 - facing, cos_i: -dir.y };
        if k + 1 == SLOPE_NODES {
            return edge_on;
        }
        if facing <= 0.0 {
            return Facet { weight: 0.0, ..edge_on };
        }
        let (x, _) = gauss_legendre8(k);
        let (lo, hi) = (self.mean_range.z, self.mean_range.w);
        let z = lo + (hi - lo) * 0.5 * (1.0 + x);
        let weights = if k < 4 { self.weights_low } else { self.weights_high };
        // A chain of selects: indexing a vector by a variable makes SPIR-V pointers.
        let weight = match k & 3 {
            0 => weights.x,
            1 => weights.y,
            2 => weights.z,
            _ => weights.w,
        };
        let (l11, l21, l22) = (self.factor_facing.x, self.factor_facing.y, self.factor_facing.z);
        let frame = self.mean_range.xy() + Vec2::new(l11 * z, l21 * z);
        let slope = self.axes.xy() * frame.x + self.axes.zw() * frame.y;
        let n = Vec3::new(-slope.x, 1.0, -slope.y);
        let cos_i = -n.dot(dir) / (n.length_squared() + l22 * l22).sqrt();
        if cos_i <= 0.0 {
            // Rounding at the facets' horizon: seen edge-on.
            return Facet { weight, ..edge_on };
        }
        Facet { normal: n.normalize(), weight, cos_i }
    }
}

/// Gauss-Hermite's 3-point rule for the standard normal: the nodes `0`
/// and `+-sqrt(3)` and their weights (2/3, 1/6 each).
pub const ACROSS_NODES: [(f32, f32); 3] = [(-1.732_050_8, 1.0 / 6.0), (0.0, 2.0 / 3.0), (1.732_050_8, 1.0 / 6.0)];

impl SlopeRule {
    /// The unit normal of facing node `k` (`0..ALONG_NODES`) with its slope
    /// across the view moved `z` conditional standard deviations (`l22`)
    /// from the conditional mean the node takes (a mirrored object, unlike
    /// the sky, is not smooth across: `sea::reflection_seen` follows each
    /// node at the three `ACROSS_NODES`). Up where no facet faces the eye.
    pub fn across(&self, k: u32, z: f32) -> Vec3 {
        if self.facing() <= 0.0 {
            return Vec3::Y;
        }
        let (x, _) = gauss_legendre8(k);
        let (lo, hi) = (self.mean_range.z, self.mean_range.w);
        let along = lo + (hi - lo) * 0.5 * (1.0 + x);
        let (l11, l21, l22) = (self.factor_facing.x, self.factor_facing.y, self.factor_facing.z);
        let frame = self.mean_range.xy() + Vec2::new(l11 * along, l21 * along + l22 * z);
        let slope = self.axes.xy() * frame.x + self.axes.zw() * frame.y;
        Vec3::new(-slope.x, 1.0, -slope.y).normalize()
    }
}

/// The density of the Gaussian of `s` at the slope `at` (per unit slope area).
pub fn slope_density(s: &Slopes, at: Vec2) -> f32 {
    let c = s.cov();
    let det = c.x * c.y - c.z * c.z;
    if det <= 0.0 {
        return 0.0;
    }
    let d = at - s.mean();
    let q = (c.y * d.x * d.x - 2.0 * c.z * d.x * d.y + c.x * d.y * d.y) / det;
    (-0.5 * q).exp() / (2.0 * PI * det.sqrt())
}

/// The sun reflected toward the eye of `rule` by its surface (radiance,
/// W/(m^2 sr) per channel): the facets whose normal is the half vector `h`
/// of the eye and the sun reflect it (they face the eye), so
/// `L = E_sun R(v.h) p(s_h) / (4 (v.h) h_y^3)`:
/// `E_sun` the sun's irradiance normal to its rays at the sea, `p` the
/// slopes' density (by horizontal area), `1/(4 (v.h))` and `1/h_y^3` the
/// Jacobians from the reflected direction to `h` and from `h` to its slope.
/// The sun's disk (radius `alpha`) adds its own spread, `(alpha/2)^2/4` per
/// axis in `h`, `/h_y^4` in slope. (The turned-away facets, taken as the
/// mean surface, reflect the sun only toward its mirror direction: left
/// out.)
pub fn sun_glint(sky: &SkyParams, table: &[Vec4], rule: &SlopeRule, s: &Slopes, n: f32) -> Vec3 {
    let l = sky.sun_direction.xyz();
    let v = -rule.dir();
    let sum = v + l;
    if sum.y <= 0.0 || l.y <= 0.0 {
        return Vec3::ZERO;
    }
    let h = sum.normalize();
    let vh = v.dot(h);
    if vh <= 0.0 {
        return Vec3::ZERO;
    }
    // alpha^2 = 2 (1 - cos alpha) for the sun's small disk (to 1e-6 of it).
    let alpha2 = 2.0 * (1.0 - sky.sun_direction.w.clamp(-1.0, 1.0));
    let hy2 = h.y * h.y;
    let disk = alpha2 / 16.0 / (hy2 * hy2);
    let spread = Slopes::new(s.mean(), s.cov() + Vec3::new(disk, disk, 0.0));
    let density = slope_density(&spread, Vec2::new(-h.x / h.y, -h.z / h.y));
    let e = sky.sun_irradiance.xyz() * transmittance_to_space(sky, table, l.y);
    e * (reflectance(vh, 1.0 / n) * density / (4.0 * vh * hy2 * h.y))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic standard normal pair from two counters (Box-Muller).
    fn normals(i: u32) -> (f32, f32) {
        let u = |k: u32| {
            let mut x = k.wrapping_mul(0x9E37_79B9) ^ 0x85EB_CA6B;
            x ^= x >> 16;
            x = x.wrapping_mul(0x7FEB_352D);
            x ^= x >> 15;
            x = x.wrapping_mul(0x846C_A68B);
            x ^= x >> 16;
            (x as f64 + 0.5) / 4_294_967_296.0
        };
        let (a, b) = (u(2 * i), u(2 * i + 1));
        let r = (-2.0 * a.ln()).sqrt();
        ((r * (2.0 * core::f64::consts::PI * b).cos()) as f32, (r * (2.0 * core::f64::consts::PI * b).sin()) as f32)
    }

    fn sample(s: &Slopes, i: u32) -> Vec2 {
        let (z0, z1) = normals(i);
        let c = s.cov();
        let l11 = c.x.sqrt();
        let l21 = c.z / l11;
        let l22 = (c.y - l21 * l21).sqrt();
        s.mean() + Vec2::new(l11 * z0, l21 * z0 + l22 * z1)
    }

    #[test]
    fn pyramid_offsets_are_the_sums_of_the_levels() {
        for n in [1u32, 2, 4, 256, 4096] {
            let mut sum = 0;
            for level in 0..=top_level(n) {
                assert_eq!(level_offset(n, level), sum, "n {n} level {level}");
                sum += (n >> level) * (n >> level);
            }
        }
    }

    /// The normal an eye looking along `dir` sees for slope `s`: turned
    /// away, the mean surface's.
    fn seen(s: Vec2, dir: Vec3) -> Vec3 {
        let n = slope_normal(s);
        if n.dot(dir) >= 0.0 {
            Vec3::Y
        } else {
            n
        }
    }

    #[test]
    fn the_normal_tail_matches_tabulated_values() {
        // Q(z) to the approximation's stated 1.5e-7 (tables to 9 digits).
        for (z, q) in
            [(0.0f32, 0.5f32), (1.0, 0.158_655_25), (2.0, 0.022_750_13), (-1.5, 0.933_192_8), (3.0, 0.001_349_9)]
        {
            assert!((normal_upper_tail(z) - q).abs() < 2e-7, "Q({z}) = {} vs {q}", normal_upper_tail(z));
        }
    }

    #[test]
    fn the_slope_rule_matches_monte_carlo_on_fresnel_at_grazing_views() {
        // The mean Fresnel reflectance is the most curved thing the rule
        // integrates (R runs from 0.02 to 1 within a few degrees of grazing,
        // and jumps where facets turn away from the eye). Against 1 000 000
        // Gaussian samples (standard error under 0.2 % of R): the 9-node
        // rule within 1 % (a study in f64 put it within 0.22 % of 300 000
        // samples on these cases, the noise's size), slopes up to the
        // roughest a sea reaches (Cox-Munk at 20 m/s: 0.1 per axis).
        let n = 1.333;
        for (view_deg, var) in
            [(0.0f32, 0.02f32), (60.0, 0.02), (80.0, 0.02), (85.0, 0.05), (88.0, 0.1), (89.5, 0.01), (80.0, 1e-4)]
        {
            let t = view_deg.to_radians();
            let dir = Vec3::new(t.sin() * 0.8, -t.cos(), t.sin() * 0.6);
            let s = Slopes::new(Vec2::new(0.01, -0.02), Vec3::new(var, 0.7 * var, 0.2 * var));
            let count = 1_000_000;
            let mut sum = 0.0f64;
            for i in 0..count {
                sum += reflectance(-dir.dot(seen(sample(&s, i), dir)), 1.0 / n) as f64;
            }
            let mc = sum / count as f64;
            let rule = SlopeRule::new(&s, dir);
            let r =
                (0..SLOPE_NODES).map(|k| rule.node(k)).map(|f| f.weight * reflectance(f.cos_i, 1.0 / n)).sum::<f32>();
            let r = r as f64;
            assert!((r / mc - 1.0).abs() < 0.01, "view {view_deg} var {var}: rule {r} vs MC {mc}");
        }
    }

    #[test]
    fn the_glint_is_the_mean_of_the_reflected_sun_disk() {
        // Independent of the glint's Jacobians: the reflected direction of
        // each of 4 million Gaussian slopes is tested against a 3-degree sun
        // disk of radiance E / Omega; the mean of R L is the glint. The
        // sun's own spread is a small share of the slopes' (0.0017 of
        // 0.01-0.03), and the sampled hits number ~10^4 (1 % noise): 5 %.
        let mut sky = SkyParams::default();
        let alpha = 3.0f32.to_radians();
        let sun = Vec3::new(0.0, 0.5, -1.0).normalize();
        sky.sun_direction = sun.extend(alpha.cos());
        let omega = 2.0 * PI * (1.0 - alpha.cos());
        sky.sun_irradiance = Vec4::new(1.0, 1.0, 1.0, omega);
        sky.observer_altitude = 1.0;
        sky.atmosphere_height = 0.0;
        let n = 1.333;
        for (dir, var) in [
            (Vec3::new(0.0, -0.5, -1.0), 0.01f32),
            (Vec3::new(0.1, -0.4, -1.0), 0.02),
            (Vec3::new(0.0, -0.2, -1.0), 0.03),
        ] {
            let dir = dir.normalize();
            let s = Slopes::new(Vec2::ZERO, Vec3::new(var, var * 0.8, 0.0));
            let table = [Vec4::ONE; 4];
            let e = transmittance_to_space(&sky, &table, sun.y);
            let glint = sun_glint(&sky, &table, &SlopeRule::new(&s, dir), &s, n).x / e.x;
            let count = 4_000_000;
            let mut sum = 0.0f64;
            for i in 0..count {
                let normal = seen(sample(&s, i), dir);
                let cos_i = -dir.dot(normal);
                let reflected = dir + normal * (2.0 * cos_i);
                if reflected.normalize().dot(sun) >= alpha.cos() {
                    sum += (reflectance(cos_i, 1.0 / n) / omega) as f64;
                }
            }
            let mc = sum / count as f64;
            assert!((glint as f64 / mc - 1.0).abs() < 0.05, "dir {dir} var {var}: glint {glint} vs MC {mc}");
        }
    }

    #[test]
    fn slopes_of_a_flat_map_are_flat_at_every_footprint() {
        let n = 8;
        let p = SeaParams {
            waves: WAVES_NORMAL_MAP,
            wave_resolution: n,
            wave_size: 8.0,
            roughness: Vec4::new(1e-3, 2e-3, 0.0, 0.0),
            ..SeaParams::default()
        };
        let waves = vec![Vec4::ZERO; (level_offset(n, top_level(n) + 1) * TEXEL_VEC4S) as usize];
        for a in [Vec2::ZERO, Vec2::new(0.3, 0.1), Vec2::new(40.0, 0.0), Vec2::new(1e4, 3.0)] {
            let s = footprint_slopes(&p, &waves, 1.3, -7.2, a, Vec2::new(0.0, 0.2));
            assert_eq!(s, Slopes::new(Vec2::ZERO, Vec3::new(1e-3, 2e-3, 0.0)), "{a}");
        }
    }
}
