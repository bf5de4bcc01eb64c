//! The sea's references, in f64, sharing none of the method's shortcuts
//! (no sampling planes, no direction sets, no maps):
//! - `SeaReference::order1`, `order2`: deterministic quadrature of the
//!   radiative transfer's first two orders in a flat, uniform water slab,
//!   adaptive Gauss-Kronrod over depth and over the sphere of directions
//!   (split where the phase functions peak and where the order-1 radiance
//!   changes form at the horizontal);
//! - `SeaReference::monte_carlo`: backward path tracing in the same slab with
//!   next-event estimation toward the refracted sun, recording orders 1, 2
//!   and all orders (the bottom absorbs scattered light, as in the method;
//!   its direct reflection is `bottom`).
//!
//! The two must agree before either judges the maps. Radiances are below the
//! surface along an upward direction of travel `view`, W/(m^2 sr); the
//! surface's `T_o / n^2` is the caller's.

use glam::{DVec3, Vec4Swizzles};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use slicelight_shaders::sea::SeaParams;
use std::f64::consts::PI;

use crate::sky::reference::integrate;

fn d3(v: glam::Vec3) -> DVec3 {
    v.as_dvec3()
}

/// A varying bottom for the references: its depth (m) at horizontal
/// `(x, z)`, the march step that resolves it (m), and its deepest depth.
pub struct HeightField<'a> {
    pub depth: &'a (dyn Fn(f64, f64) -> f64 + Sync),
    pub step: f64,
    pub deepest: f64,
}

impl<'a> HeightField<'a> {
    /// A sea's varying bottom (`p.bottom_grid`), its depth given by
    /// `depth` (`grid_depth`), marched half a grid spacing at a time.
    pub fn of_sea(p: &SeaParams, depth: &'a (dyn Fn(f64, f64) -> f64 + Sync)) -> HeightField<'a> {
        HeightField { depth, step: 0.5 * p.bottom_grid.z as f64, deepest: p.bottom_grid.w as f64 }
    }
}

/// The depth (m) of a sea's varying bottom `grid` at horizontal `(x, z)`:
/// the scene's own bilinear height field (`sea::bottom_depth`), in f64.
pub fn grid_depth<'a>(p: &'a SeaParams, grid: &'a [f32]) -> impl Fn(f64, f64) -> f64 + Sync + 'a {
    move |x, z| slicelight_shaders::sea::bottom_depth(p, grid, x as f32, z as f32) as f64
}

/// The water and its sunlight, in f64.
#[derive(Debug, Clone)]
pub struct SeaReference {
    pub b: DVec3,
    pub c: DVec3,
    pub g: f64,
    pub depth: f64,
    /// Direction of travel of the refracted sun (unit, downward).
    pub sun: DVec3,
    pub mu_s: f64,
    /// Irradiance normal to the refracted beam, W/m^2.
    pub beam: DVec3,
    pub albedo: DVec3,
    /// Relative tolerance of the adaptive quadratures.
    pub tolerance: f64,
}

/// Results of a Monte Carlo run: means and standard errors per order.
#[derive(Debug, Clone, Copy, Default)]
pub struct MonteCarlo {
    pub order1: DVec3,
    pub order2: DVec3,
    pub all: DVec3,
    pub order1_error: DVec3,
    pub order2_error: DVec3,
    pub all_error: DVec3,
}

impl SeaReference {
    pub fn new(p: &SeaParams, tolerance: f64) -> SeaReference {
        let sun = d3(p.sun_in_water.xyz()).normalize();
        SeaReference {
            b: d3(p.scattering.xyz()),
            c: d3(p.extinction.xyz()),
            g: p.scattering.w as f64,
            depth: p.depth as f64,
            sun,
            mu_s: -sun.y,
            beam: d3(p.beam_irradiance.xyz()),
            albedo: d3(p.bottom_albedo.xyz()),
            tolerance,
        }
    }

    /// Henyey-Greenstein, 1/sr.
    pub fn hg(&self, cos: f64) -> f64 {
        let g = self.g;
        (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * cos).powf(1.5))
    }

    /// How deep anything can matter: 60 optical depths of the clearest
    /// channel (`e^-60` of the surface's light), or the bottom.
    fn reach(&self) -> f64 {
        let c = self.c.min_element();
        if c > 0.0 {
            (60.0 / c).min(self.depth)
        } else {
            self.depth.min(1e9)
        }
    }

    /// Order-1 radiance at depth `z` travelling along unit `dir`, by the
    /// closed-form integral along the ray (eq. 7 written out afresh), over
    /// the flat bottom.
    pub fn l1(&self, z: f64, dir: DVec3) -> DVec3 {
        self.l1_below(z, dir, self.depth - z)
    }

    /// `l1` where light travelling upward was scattered over `span` (m,
    /// vertically) below `z`: between `z` and wherever the bottom is along
    /// the way it came.
    pub fn l1_below(&self, z: f64, dir: DVec3, span: f64) -> DVec3 {
        let beta = self.b * self.hg(self.sun.dot(dir));
        let mu = dir.y;
        let per_channel = |c: f64| -> f64 {
            if mu > 0.0 {
                // Scattered between z and the bottom, travelling up.
                let k = c * (1.0 / self.mu_s + 1.0 / mu);
                let span = span.max(0.0);
                let integral = if k * span < 1e-8 { span } else { -(-k * span).exp_m1() / k };
                (-c * z / self.mu_s).exp() * integral / mu
            } else {
                // Scattered between the surface and z, travelling down:
                // (z/m) (e^-a - e^-b)/(b - a), a = c z/mu_s, b = c z/m.
                let m = -mu;
                let (a, b) = (c * z / self.mu_s, c * z / m);
                let x = (b - a).abs();
                let phi = if x < 1e-12 { 1.0 } else { -(-x).exp_m1() / x };
                (z / m) * (-a.min(b)).exp() * phi
            }
        };
        beta * self.beam * DVec3::new(per_channel(self.c.x), per_channel(self.c.y), per_channel(self.c.z))
    }

    /// How far below the point at horizontal `at` and depth `z` (m,
    /// vertically) the bottom lies along the way light travelling along
    /// upward unit `dir` came: the first crossing of the bilinear height
    /// field, marched `field.step` horizontally at a time and bisected to
    /// 1e-9 of the step. Where the light has crossed 60 optical depths of the
    /// clearest channel first, that far (the rest cannot be told from no
    /// bottom in f64).
    pub fn below(&self, field: &HeightField, at: (f64, f64), z: f64, dir: DVec3) -> f64 {
        let mu = dir.y.max(1e-12);
        let gap = |t: f64| z + mu * t - (field.depth)(at.0 - dir.x * t, at.1 - dir.z * t);
        if gap(0.0) >= 0.0 {
            return 0.0;
        }
        let t_far = ((field.deepest - z) / mu).min(60.0 / self.c.min_element().max(1e-12));
        let horizontal = (dir.x * dir.x + dir.z * dir.z).sqrt();
        let dt = if horizontal > 1e-12 { (field.step / horizontal).min(t_far) } else { t_far };
        let mut t0 = 0.0;
        loop {
            let t1 = (t0 + dt).min(t_far);
            if gap(t1) >= 0.0 {
                let (mut lo, mut hi) = (t0, t1);
                while hi - lo > 1e-9 * dt {
                    let mid = 0.5 * (lo + hi);
                    if gap(mid) >= 0.0 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                return mu * 0.5 * (lo + hi);
            }
            if t1 >= t_far {
                return mu * t_far;
            }
            t0 = t1;
        }
    }

    /// Order 1 toward the surface along upward `view`: the integral over
    /// depth of the sun's single scattering, attenuated on the way up.
    pub fn order1(&self, view: DVec3) -> DVec3 {
        let mu_v = view.y;
        let beta = self.b * self.hg(self.sun.dot(view));
        let f = |z: f64| {
            let c = self.c;
            beta * self.beam
                * DVec3::new(
                    (-c.x * z * (1.0 / self.mu_s + 1.0 / mu_v)).exp(),
                    (-c.y * z * (1.0 / self.mu_s + 1.0 / mu_v)).exp(),
                    (-c.z * z * (1.0 / self.mu_s + 1.0 / mu_v)).exp(),
                )
                / mu_v
        };
        self.over_depth(&f)
    }

    /// `int_0^depth f(z) dz` in pieces graded toward the surface.
    fn over_depth(&self, f: &dyn Fn(f64) -> DVec3) -> DVec3 {
        self.over_depth_to(f, self.depth)
    }

    /// `int_0^end f(z) dz` in pieces graded toward the surface (cut where
    /// 60 optical depths of the clearest channel are reached).
    fn over_depth_to(&self, f: &dyn Fn(f64) -> DVec3, end: f64) -> DVec3 {
        graded(f, self.reach().min(end), self.tolerance)
    }

    /// The order-2 source at depth `z` toward `view`: `int b p(w . view) L1(z, w) dw`,
    /// over the vertical cosine (cut at the horizontal and where the sun
    /// and the view lie) and the azimuth (cut at theirs).
    pub fn source2(&self, z: f64, view: DVec3) -> DVec3 {
        self.source2_with(view, &|w| self.l1(z, w))
    }

    /// `source2` with the order-1 radiance along each direction `l1(w)`.
    fn source2_with(&self, view: DVec3, l1: &dyn Fn(DVec3) -> DVec3) -> DVec3 {
        let azimuth = |d: DVec3| d.z.atan2(d.x).rem_euclid(2.0 * PI);
        let mut mu_cuts = vec![-1.0, -self.mu_s, 0.0, view.y, 1.0];
        mu_cuts.sort_by(f64::total_cmp);
        mu_cuts.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
        let mut phi_cuts = vec![0.0, azimuth(self.sun), azimuth(view), 2.0 * PI];
        phi_cuts.sort_by(f64::total_cmp);
        phi_cuts.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
        let inner = |mu: f64| -> DVec3 {
            let s = (1.0 - mu * mu).max(0.0).sqrt();
            let f = |phi: f64| {
                let w = DVec3::new(s * phi.cos(), mu, s * phi.sin());
                self.b * self.hg(w.dot(view)) * l1(w)
            };
            phi_cuts.windows(2).map(|p| integrate(&f, p[0], p[1], self.tolerance, 0.0, 20)).sum()
        };
        mu_cuts.windows(2).map(|m| integrate(&inner, m[0], m[1], self.tolerance, 0.0, 20)).sum()
    }

    /// Order 2 toward the surface along upward `view`.
    pub fn order2(&self, view: DVec3) -> DVec3 {
        let mu_v = view.y;
        let c = self.c;
        let f = |z: f64| {
            let att = DVec3::new((-c.x * z / mu_v).exp(), (-c.y * z / mu_v).exp(), (-c.z * z / mu_v).exp());
            self.source2(z, view) * att / mu_v
        };
        self.over_depth(&f)
    }

    /// Order 2 toward the surface along upward `view` from the surface at
    /// horizontal `start`, over the height field `field`: the view ray ends
    /// where it meets the bottom, and the order-1 radiance travelling up at
    /// every point along it was scattered between that point and the bottom
    /// along the way it came (`below`); no sampling planes, no depth table.
    /// The sun's light is not shadowed by the bottom (as in the method).
    pub fn order2_over(&self, field: &HeightField, start: (f64, f64), view: DVec3) -> DVec3 {
        let mu_v = view.y;
        let c = self.c;
        let end = self.below(field, start, 0.0, view);
        let f = |z: f64| {
            let t = z / mu_v;
            let at = (start.0 - view.x * t, start.1 - view.z * t);
            let l1 = |w: DVec3| {
                let span = if w.y > 0.0 { self.below(field, at, z, w) } else { 0.0 };
                self.l1_below(z, w, span)
            };
            let att = DVec3::new((-c.x * z / mu_v).exp(), (-c.y * z / mu_v).exp(), (-c.z * z / mu_v).exp());
            self.source2_with(view, &l1) * att / mu_v
        };
        self.over_depth_to(&f, end)
    }

    /// Order 1 gathered toward an eye at depth `z_e` (m) along its view ray
    /// `d` (unit, any way) over `length` m (`f64::INFINITY` in open
    /// water): `int b p(sun . -d) E_w e^(-c z(t)/mu_s) e^(-c t) dt`,
    /// `z(t) = z_e - t d_y`, by quadrature (not the method's closed form).
    pub fn order1_segment(&self, z_e: f64, d: DVec3, length: f64) -> DVec3 {
        let beta = self.b * self.hg(-self.sun.dot(d));
        let f = |t: f64| {
            let z = (z_e - t * d.y).max(0.0);
            let c = self.c;
            beta * self.beam
                * DVec3::new(
                    (-c.x * (z / self.mu_s + t)).exp(),
                    (-c.y * (z / self.mu_s + t)).exp(),
                    (-c.z * (z / self.mu_s + t)).exp(),
                )
        };
        self.along(&f, length)
    }

    /// Order 1 gathered toward an eye at `o` (scene coordinates, the
    /// surface at height `level`) along `d` over `length` m with the
    /// waves' focusing `focus(x)` (the ratio of the sun's irradiance at `x`
    /// to the flat beam's): `int b p(sun . -d) E_w e^(-c z/mu_s) focus e^(-c t) dt`
    /// by the midpoint rule in steps of about `step` m (at most 10^6),
    /// out to 60 optical lengths of the clearest channel.
    pub fn order1_focused(
        &self,
        o: DVec3,
        level: f64,
        d: DVec3,
        length: f64,
        step: f64,
        focus: &dyn Fn(DVec3) -> DVec3,
    ) -> DVec3 {
        let beta = self.b * self.hg(-self.sun.dot(d));
        let c = self.c;
        let reach = if c.min_element() > 0.0 { length.min(60.0 / c.min_element()) } else { length.min(1e6) };
        let count = ((reach / step).ceil() as usize).clamp(1, 1_000_000);
        let h = reach / count as f64;
        let mut sum = DVec3::ZERO;
        for i in 0..count {
            let t = (i as f64 + 0.5) * h;
            let x = o + d * t;
            let z = (level - x.y).max(0.0);
            let e = DVec3::new(
                (-c.x * (z / self.mu_s + t)).exp(),
                (-c.y * (z / self.mu_s + t)).exp(),
                (-c.z * (z / self.mu_s + t)).exp(),
            );
            sum += e * focus(x);
        }
        beta * self.beam * sum * h
    }

    /// Order 2 gathered toward an eye at depth `z_e` along `d` over
    /// `length` m: `int J2(z(t), -d) e^(-c t) dt` with `J2` the order-2
    /// source by quadrature over the sphere (`source2`), no planes, no maps.
    pub fn order2_segment(&self, z_e: f64, d: DVec3, length: f64) -> DVec3 {
        let f = |t: f64| {
            let z = (z_e - t * d.y).max(0.0);
            let c = self.c;
            self.source2(z, -d) * DVec3::new((-c.x * t).exp(), (-c.y * t).exp(), (-c.z * t).exp())
        };
        self.along(&f, length)
    }

    /// `int_0^length f(t) dt` in pieces graded from the eye (cut at 60
    /// optical lengths of the clearest channel).
    fn along(&self, f: &dyn Fn(f64) -> DVec3, length: f64) -> DVec3 {
        let c = self.c.min_element();
        let reach = if c > 0.0 { length.min(60.0 / c) } else { length.min(1e9) };
        graded(f, reach, self.tolerance)
    }

    /// The Lambertian bottom at depth `depth` lit by the refracted sun,
    /// seen from right above it (eq. 9 without the way up), with cosine
    /// `cos_gamma` between its normal and the beam.
    pub fn bottom_leaving(&self, depth: f64, cos_gamma: f64) -> DVec3 {
        let c = self.c;
        let att = DVec3::new(
            (-c.x * depth / self.mu_s).exp(),
            (-c.y * depth / self.mu_s).exp(),
            (-c.z * depth / self.mu_s).exp(),
        );
        self.beam * att * cos_gamma.max(0.0) * self.albedo / PI
    }

    /// The bottom's reflection of the direct sun along `view` (eq. 9 with `1/pi`), closed form.
    pub fn bottom(&self, view: DVec3) -> DVec3 {
        if self.depth >= slicelight_shaders::sea::DEEP as f64 {
            return DVec3::ZERO;
        }
        let path = self.depth * (1.0 / self.mu_s + 1.0 / view.y);
        let att = DVec3::new((-self.c.x * path).exp(), (-self.c.y * path).exp(), (-self.c.z * path).exp());
        self.beam * att * self.mu_s * self.albedo / PI
    }

    /// Samples a direction of travel distributed like the phase function around `axis`.
    fn sample_hg(&self, axis: DVec3, rng: &mut impl Rng) -> DVec3 {
        let g = self.g;
        let xi: f64 = rng.random();
        let cos = if g.abs() < 1e-6 {
            2.0 * xi - 1.0
        } else {
            let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi);
            ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
        };
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * PI * rng.random::<f64>();
        let t = if axis.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
        let u = axis.cross(t).normalize();
        let v = axis.cross(u);
        (axis * cos + (u * phi.cos() + v * phi.sin()) * sin).normalize()
    }

    /// One channel's backward random walk from the surface at horizontal
    /// `start` along `-view`: each vertex adds the sun's next-event estimate
    /// to its order. `bottom(x, z)` is the bottom's depth (m) under each
    /// vertex; a path whose vertex falls below it ends there (the bottom
    /// absorbs scattered light; the segment is not searched for a crossing,
    /// so features thinner than a free path can be stepped over).
    fn walk(
        &self,
        channel: usize,
        view: DVec3,
        start: (f64, f64),
        bottom: &(dyn Fn(f64, f64) -> f64 + Sync),
        rng: &mut impl Rng,
        max_orders: u32,
    ) -> (f64, f64, f64) {
        let (b, c) = (self.b[channel], self.c[channel]);
        if b <= 0.0 {
            return (0.0, 0.0, 0.0);
        }
        let beam = self.beam[channel];
        let mut depth = 0.0f64;
        let (mut x, mut z) = start;
        let mut d = -view;
        let mut weight = 1.0f64;
        let (mut o1, mut o2, mut all) = (0.0, 0.0, 0.0);
        for order in 1..=max_orders {
            let t = -(1.0 - rng.random::<f64>()).ln() / c;
            depth -= t * d.y;
            x += t * d.x;
            z += t * d.z;
            if depth <= 0.0 || depth >= self.depth.min(bottom(x, z)) {
                break;
            }
            weight *= b / c;
            let estimate = weight * self.hg(self.sun.dot(-d)) * beam * (-c * depth / self.mu_s).exp();
            all += estimate;
            match order {
                1 => o1 = estimate,
                2 => o2 = estimate,
                _ => {}
            }
            if weight < 1e-4 {
                // Russian roulette.
                if rng.random::<f64>() < 0.5 {
                    break;
                }
                weight *= 2.0;
            }
            d = -self.sample_hg(-d, rng);
        }
        (o1, o2, all)
    }

    /// Monte Carlo estimates of orders 1, 2 and all along upward `view`,
    /// `paths` walks per channel (at most `max_orders` scatterings each), seeded.
    pub fn monte_carlo(&self, view: DVec3, paths: u64, seed: u64, max_orders: u32) -> MonteCarlo {
        self.monte_carlo_over(view, (0.0, 0.0), &|_, _| f64::INFINITY, paths, seed, max_orders)
    }

    /// As `monte_carlo`, from the surface at horizontal `start` over a bottom
    /// of depth `bottom(x, z)` (the sun's light is not shadowed by it).
    pub fn monte_carlo_over(
        &self,
        view: DVec3,
        start: (f64, f64),
        bottom: &(dyn Fn(f64, f64) -> f64 + Sync),
        paths: u64,
        seed: u64,
        max_orders: u32,
    ) -> MonteCarlo {
        const CHUNK: u64 = 16_384;
        let mut out = MonteCarlo::default();
        for ch in 0..3 {
            let chunks = paths.div_ceil(CHUNK);
            let sums: [f64; 6] = (0..chunks)
                .into_par_iter()
                .map(|k| {
                    let mut rng =
                        rand::rngs::StdRng::seed_from_u64(seed ^ ((k * 3 + ch as u64 + 1) * 0x9E3779B97F4A7C15));
                    let mut s = [0.0; 6];
                    for _ in 0..CHUNK.min(paths - k * CHUNK) {
                        let (a, b, c) = self.walk(ch, view, start, bottom, &mut rng, max_orders);
                        s[0] += a;
                        s[1] += a * a;
                        s[2] += b;
                        s[3] += b * b;
                        s[4] += c;
                        s[5] += c * c;
                    }
                    s
                })
                .reduce(|| [0.0; 6], |x, y| std::array::from_fn(|i| x[i] + y[i]));
            let n = paths as f64;
            let stat = |s: f64, s2: f64| {
                let mean = s / n;
                (mean, ((s2 / n - mean * mean).max(0.0) / n).sqrt())
            };
            (out.order1[ch], out.order1_error[ch]) = stat(sums[0], sums[1]);
            (out.order2[ch], out.order2_error[ch]) = stat(sums[2], sums[3]);
            (out.all[ch], out.all_error[ch]) = stat(sums[4], sums[5]);
        }
        out
    }
}

/// `int_0^reach f(x) dx` by adaptive quadrature in pieces growing fourfold
/// from `reach / 4096` (the integrands fall off exponentially from 0).
fn graded(f: &dyn Fn(f64) -> DVec3, reach: f64, tolerance: f64) -> DVec3 {
    if reach <= 0.0 {
        return DVec3::ZERO;
    }
    let mut cuts = vec![0.0];
    let mut x = reach / 4096.0;
    while x < reach {
        cuts.push(x);
        x *= 4.0;
    }
    cuts.push(reach);
    cuts.windows(2).map(|w| integrate(f, w[0], w[1], tolerance, 0.0, 24)).sum()
}

/// Nodes and weights of `n`-point Gauss-Legendre on (-1, 1), by Newton's
/// iteration on the Legendre polynomial (to 1e-15).
pub fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            loop {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    (p0, p1) = (p1, p2);
                }
                let (p, dp) = if n == 0 { (1.0, 0.0) } else { (p1, n as f64 * (x * p1 - p0) / (x * x - 1.0)) };
                let step = p / dp;
                x -= step;
                if step.abs() < 1e-15 {
                    return (x, 2.0 / ((1.0 - x * x) * dp * dp));
                }
            }
        })
        .collect()
}

/// The wave surface's reflection at one point, in f64 and by its own
/// rules: the slopes a Gaussian of mean `mean` (the map's slope there) and
/// covariance `cov` (`xx, zz, xz`: the unresolved waves' roughness), a
/// facet turned away from the eye taken as the mean surface (the method's
/// convention, `slicelight_shaders::sea::surface::SlopeRule`), the eye
/// looking along `d`, water of index `n`.
///
/// The sky (`sky`, without the sun's disk) is summed over a dense product
/// rule: 24-point Gauss-Legendre with the normal density along the view's
/// horizontal direction from the facets' horizon (or -6) to 6 standard
/// deviations, times 6-point Gauss-Hermite across, the full 2D normal at
/// every node (no conditional means). The sun is integrated over its disk
/// (8 rings x 16 sectors of equal solid angle): each direction of the disk
/// is mirrored by the facet whose normal is the half vector, of density
/// `p(s_h)` per unit slope, `1/(4 (v.h) h_y^3)` per unit of solid angle.
/// `sun_shade` multiplies the sun's light (the volumes' shadow at the
/// point, and 0 where an object hides the sun from it). Where `objects`
/// gives an object's light along a reflected direction, that light takes
/// the sky's place there (the scene's objects mirrored). Returns the
/// reflected radiance and the mean reflectance.
#[allow(clippy::too_many_arguments)]
pub fn rough_reflection(
    sky: &crate::sky::reference::SkyReference,
    sun: &slicelight_shaders::sky::SkyParams,
    d: DVec3,
    mean: glam::DVec2,
    cov: DVec3,
    n: f64,
    sun_shade: DVec3,
    objects: &dyn Fn(DVec3) -> Option<DVec3>,
) -> (DVec3, f64) {
    use glam::DVec2;
    use slicelight_shaders::optics::reflectance;
    let fresnel = |cos: f64| reflectance(cos, 1.0 / n);
    let horizontal = DVec2::new(d.x, d.z);
    let length = horizontal.length();
    let along = if length > 1e-12 { horizontal / length } else { DVec2::X };
    let across = DVec2::new(-along.y, along.x);
    let var = |a: DVec2, b: DVec2| a.x * b.x * cov.x + a.y * b.y * cov.y + (a.x * b.y + a.y * b.x) * cov.z;
    let l11 = var(along, along).max(0.0).sqrt();
    let l21 = if l11 > 0.0 { var(along, across) / l11 } else { 0.0 };
    let l22 = (var(across, across) - l21 * l21).max(0.0).sqrt();
    let m = DVec2::new(mean.dot(along), mean.dot(across));
    let z_star = if length > 1e-12 && l11 > 0.0 { ((d.y / length - m.x) / l11).clamp(-6.0, 6.0) } else { -6.0 };
    let phi = |z: f64| (-0.5 * z * z).exp() / (2.0 * PI).sqrt();
    // The facing share, from the same rule (its weights' sum over (z*, 6)).
    let along_nodes: Vec<(f64, f64)> = gauss_legendre(24)
        .into_iter()
        .map(|(x, w)| {
            let z = z_star + (6.0 - z_star) * 0.5 * (1.0 + x);
            (z, w * 0.5 * (6.0 - z_star) * phi(z))
        })
        .collect();
    let facing: f64 = along_nodes.iter().map(|n| n.1).sum();
    let hermite = [
        (-3.324_257_433_6, 0.002_555_784_95),
        (-1.889_175_877_8, 0.088_615_746),
        (-0.616_706_590_2, 0.408_828_469_5),
        (0.616_706_590_2, 0.408_828_469_5),
        (1.889_175_877_8, 0.088_615_746),
        (3.324_257_433_6, 0.002_555_784_95),
    ];
    let normal_of = |s: DVec2| DVec3::new(-s.x, 1.0, -s.y).normalize();
    let mut light = DVec3::ZERO;
    let mut r_mean = 0.0;
    // The turned-away share, seen edge-on as the mean surface.
    let mut facet = |normal: DVec3, w: f64| {
        let cos = -d.dot(normal);
        let reflected = d + normal * (2.0 * cos);
        let reflected = DVec3::new(reflected.x, reflected.y.abs(), reflected.z).normalize();
        let r = fresnel(cos);
        light += objects(reflected).unwrap_or_else(|| sky.sky_without_sun(reflected)) * (w * r);
        r_mean += w * r;
    };
    facet(DVec3::Y, 1.0 - facing.min(1.0));
    for &(z1, w1) in &along_nodes {
        for &(z2, w2) in &hermite {
            let frame = m + DVec2::new(l11 * z1, l21 * z1 + l22 * z2);
            let slope = along * frame.x + across * frame.y;
            let normal = normal_of(slope);
            facet(if normal.dot(d) >= 0.0 { DVec3::Y } else { normal }, w1 * w2);
        }
    }
    // The sun's disk, mirrored by the facets of the half vector.
    let to_sun = sun.sun_direction.xyz().as_dvec3().normalize();
    let cos_radius = sun.sun_direction.w as f64;
    if to_sun.y > 0.0 && cos_radius < 1.0 {
        let det = cov.x * cov.y - cov.z * cov.z;
        let (t, u) = {
            let t = if to_sun.y.abs() < 0.9 { DVec3::Y.cross(to_sun) } else { DVec3::X.cross(to_sun) }.normalize();
            (t, to_sun.cross(t))
        };
        let irradiance = sun.sun_irradiance.truncate().as_dvec3() * sky.sun_at_observer() * sun_shade;
        let (rings, sectors) = (8, 16);
        let cell = 2.0 * PI * (1.0 - cos_radius) / (rings * sectors) as f64;
        for i in 0..rings {
            // Equal solid angles: cos theta uniform between 1 and cos_radius.
            let cos_t = 1.0 - (1.0 - cos_radius) * (i as f64 + 0.5) / rings as f64;
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            for j in 0..sectors {
                let a = 2.0 * PI * (j as f64 + 0.5) / sectors as f64;
                let w = (to_sun * cos_t + (t * a.cos() + u * a.sin()) * sin_t).normalize();
                let h = w - d;
                if h.y <= 0.0 || det <= 0.0 {
                    continue;
                }
                let h = h.normalize();
                let vh = -d.dot(h);
                let s_h = DVec2::new(-h.x / h.y, -h.z / h.y) - mean;
                let q = (cov.y * s_h.x * s_h.x - 2.0 * cov.z * s_h.x * s_h.y + cov.x * s_h.y * s_h.y) / det;
                let density = (-0.5 * q).exp() / (2.0 * PI * det.sqrt());
                let radiance = irradiance / (2.0 * PI * (1.0 - cos_radius));
                light += radiance * (cell * fresnel(vh) * density / (4.0 * vh * h.y.powi(3)));
            }
        }
    }
    (light, r_mean)
}

/// The waves' caustic on a flat bottom by photon tracing, in f64, for the
/// reference: sharing none of `sea.caustics`' mesh or rasteriser. Photons
/// leave a stratified grid of `PHOTONS_PER_TEXEL` per wave-map texel over
/// the tile; each takes the wave slope at its point (bilinear between grid
/// points, as the renderer reads the surface), is refracted (Snell) with
/// Fresnel's transmittance, attenuated on its slanted way down relative to
/// the flat beam, and binned where it meets the bottom on the wave map's
/// texels (centres at integer texel widths). A texel's value is the ratio
/// of the bottom's irradiance there to the flat sea's, per channel.
pub struct CausticReference {
    n: usize,
    size: f64,
    ratio: Vec<DVec3>,
}

/// Photons per wave-map texel (each way: the square root).
pub const PHOTONS_PER_TEXEL_SIDE: usize = 8;

impl CausticReference {
    /// The caustic for the sea `p` with wave slopes `waves`, or `None`
    /// where the renderer builds none (`SeaParams::caustics` 0).
    pub fn new(p: &SeaParams, waves: &[glam::Vec4]) -> Option<CausticReference> {
        if p.caustics == 0 {
            return None;
        }
        let mut maps = photon_maps(p, waves, &[p.depth as f64], PHOTONS_PER_TEXEL_SIDE);
        Some(CausticReference { n: p.wave_resolution as usize, size: p.wave_size as f64, ratio: maps.remove(0) })
    }

    /// The ratio at the bottom point `(x, z)` (m), bilinear between texel
    /// centres, tiled (the same reconstruction as the renderer's map).
    pub fn at(&self, x: f64, z: f64) -> DVec3 {
        bilinear(&self.ratio, self.n, self.size, x, z)
    }
}

/// `map` (`n`^2 texels over a tile `size` m wide, centres at integer
/// texel widths) at the horizontal point `(x, z)`, bilinear, tiled.
fn bilinear(map: &[DVec3], n: usize, size: f64, x: f64, z: f64) -> DVec3 {
    let wrap = |v: f64| (v / size).rem_euclid(1.0) * n as f64;
    let (fx, fz) = (wrap(x), wrap(z));
    let (x0, z0) = (fx.floor() as usize % n, fz.floor() as usize % n);
    let (ax, az) = (fx - fx.floor(), fz - fz.floor());
    let (x1, z1) = ((x0 + 1) % n, (z0 + 1) % n);
    let r = |i: usize, j: usize| map[j * n + i];
    (r(x0, z0) * (1.0 - ax) + r(x1, z0) * ax) * (1.0 - az) + (r(x0, z1) * (1.0 - ax) + r(x1, z1) * ax) * az
}

/// The waves' caustic at each of `depths` (m) by photon tracing in f64:
/// `side`^2 photons per wave-map texel from a stratified grid over the
/// tile, each taking the wave slope at its point (bilinear between the
/// full-resolution grid's points, as the renderer reads the surface),
/// refracted (Snell) with Fresnel's transmittance, attenuated on its
/// slanted way down relative to the flat beam, and binned where its
/// straight path crosses each depth, on the wave map's texels. Each map
/// holds the ratio of the irradiance there to the flat sea's, per channel.
pub fn photon_maps(p: &SeaParams, waves: &[glam::Vec4], depths: &[f64], side: usize) -> Vec<Vec<DVec3>> {
    let n = p.wave_resolution as usize;
    let size = p.wave_size as f64;
    let texel = size / n as f64;
    let slope = |i: usize, j: usize| {
        slicelight_shaders::sea::surface::grid_slope(p, waves, (i % n) as u32, (j % n) as u32).as_dvec2()
    };
    let sun = p.sun_direction.xyz().as_dvec3().normalize();
    let n_w = p.extinction.w as f64;
    let eta = 1.0 / n_w;
    let flat = sun.y * slicelight_shaders::optics::transmittance(sun.y, eta);
    let mu_s = {
        let (cos_t, _) = slicelight_shaders::optics::transmitted_cosine(sun.y, eta);
        cos_t
    };
    let c = p.extinction.xyz().as_dvec3();
    let rows = n * side;
    let empty = || vec![vec![DVec3::ZERO; n * n]; depths.len()];
    let maps = (0..rows)
        .into_par_iter()
        .fold(empty, |mut h, row| {
            for col in 0..rows {
                // Texel coordinates of the photon on the surface.
                let (u, v) = ((col as f64 + 0.5) / side as f64, (row as f64 + 0.5) / side as f64);
                let (i0, j0) = (u.floor() as usize, v.floor() as usize);
                let (ax, az) = (u - i0 as f64, v - j0 as f64);
                let s = (slope(i0, j0) * (1.0 - ax) + slope(i0 + 1, j0) * ax) * (1.0 - az)
                    + (slope(i0, j0 + 1) * (1.0 - ax) + slope(i0 + 1, j0 + 1) * ax) * az;
                let normal = DVec3::new(-s.x, 1.0, -s.y).normalize();
                let cos_i = sun.dot(normal);
                if cos_i <= 0.0 {
                    continue;
                }
                let (cos_t, _) = slicelight_shaders::optics::transmitted_cosine(cos_i, eta);
                let r = (-sun * eta + normal * (eta * cos_i - cos_t)).normalize();
                let down = -r.y;
                let weight = cos_i / normal.y * slicelight_shaders::optics::transmittance(cos_i, eta) / flat;
                for (map, &depth) in h.iter_mut().zip(depths) {
                    let att = (-c * (depth * (1.0 / down - 1.0 / mu_s))).exp();
                    let (lu, lv) = (u + r.x * depth / down / texel, v + r.z * depth / down / texel);
                    let (bi, bj) = ((lu + 0.5).floor() as i64, (lv + 0.5).floor() as i64);
                    let (bi, bj) = (bi.rem_euclid(n as i64) as usize, bj.rem_euclid(n as i64) as usize);
                    map[bj * n + bi] += att * weight;
                }
            }
            h
        })
        .reduce(empty, |mut a, b| {
            for (x, y) in a.iter_mut().zip(&b) {
                for (u, v) in x.iter_mut().zip(y) {
                    *u += *v;
                }
            }
            a
        });
    // Each photon carries 1/side^2 of a texel's area.
    let per_photon = 1.0 / (side * side) as f64;
    maps.into_iter().map(|m| m.into_iter().map(|v| v * per_photon).collect()).collect()
}

/// The waves' focusing through the water for the shafts' reference: the
/// photon-traced caustic (`photon_maps`) on the full-resolution wave grid
/// at `SHAFT_REFERENCE_REFINE` times the renderer's shaft planes (from the
/// surface to its deepest plane), read at a point between the two maps
/// around its depth along the refracted sun, as light travels (`at`).
pub struct ShaftReference {
    n: usize,
    size: f64,
    spacing: f64,
    along: (f64, f64),
    maps: Vec<Vec<DVec3>>,
}

/// The reference's planes per interval of the renderer's shaft planes.
pub const SHAFT_REFERENCE_REFINE: usize = 4;

impl ShaftReference {
    /// The reference for the sea `p` (`None` without shafts), with
    /// `side`^2 photons per wave texel.
    pub fn new(p: &SeaParams, waves: &[glam::Vec4], side: usize) -> Option<ShaftReference> {
        if p.shaft_planes == 0 {
            return None;
        }
        let count = (p.shaft_planes as usize - 1) * SHAFT_REFERENCE_REFINE + 1;
        let spacing = p.shaft_depth as f64 / (count - 1) as f64;
        let depths: Vec<f64> = (0..count).map(|k| k as f64 * spacing).collect();
        let s = p.sun_in_water.xyz().as_dvec3();
        Some(ShaftReference {
            n: p.wave_resolution as usize,
            size: p.wave_size as f64,
            spacing,
            along: (s.x / -s.y, s.z / -s.y),
            maps: photon_maps(p, waves, &depths, side),
        })
    }

    /// The ratio at the horizontal point `(x, z)` and depth `depth` (m):
    /// each map around the depth read where the refracted sun's line
    /// through the point crosses it, linear between them; below the
    /// deepest, that map's mean.
    pub fn at(&self, x: f64, depth: f64, z: f64) -> DVec3 {
        let last = self.maps.len() - 1;
        let u = (depth / self.spacing).max(0.0);
        if u > last as f64 {
            let m = &self.maps[last];
            return m.iter().sum::<DVec3>() / m.len() as f64;
        }
        let k = (u.floor() as usize).min(last - 1);
        let w = u - k as f64;
        let read = |k: usize| {
            let dz = k as f64 * self.spacing - depth;
            bilinear(&self.maps[k], self.n, self.size, x + self.along.0 * dz, z + self.along.1 * dz)
        };
        read(k) * (1.0 - w) + read(k + 1) * w
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Vec3, Vec4};

    pub(crate) fn clear_ocean(depth: f32) -> SeaParams {
        let sun = Vec3::new(0.4, -0.85, 0.1).normalize();
        let c = Vec3::new(0.3799, 0.1074, 0.08);
        SeaParams {
            sun_in_water: sun.extend(-sun.y),
            beam_irradiance: Vec4::new(1.0, 1.0, 1.0, 1.0),
            scattering: Vec4::new(0.0369, 0.0489, 0.0620, 0.924),
            extinction: c.extend(1.333),
            order1_extinction: c.extend(0.0),
            bottom_albedo: Vec4::splat(0.5),
            depth,
            ..Default::default()
        }
    }

    #[test]
    fn quadrature_and_monte_carlo_agree() {
        let r = SeaReference::new(&clear_ocean(slicelight_shaders::sea::DEEP), 1e-6);
        let view = DVec3::new(0.3, 0.9, -0.2).normalize();
        let t = std::time::Instant::now();
        let (o1, o2) = (r.order1(view), r.order2(view));
        let tq = t.elapsed();
        let t = std::time::Instant::now();
        let mc = r.monte_carlo(view, 400_000, 1, 10_000);
        println!("quadrature {tq:?}: o1 {o1} o2 {o2}; MC {:?}: {mc:?}", t.elapsed());
        // Four standard errors of the Monte Carlo estimate (seeded, so the
        // outcome is fixed), plus 1e-4 of the value for the quadrature's
        // 1e-6 tolerance with room for the path tracer's floating-point sums.
        for ch in 0..3 {
            assert!(
                (o1[ch] - mc.order1[ch]).abs() <= 4.0 * mc.order1_error[ch] + 1e-4 * o1[ch],
                "order 1, channel {ch}"
            );
            assert!(
                (o2[ch] - mc.order2[ch]).abs() <= 4.0 * mc.order2_error[ch] + 1e-4 * o2[ch],
                "order 2, channel {ch}"
            );
        }
    }
}
