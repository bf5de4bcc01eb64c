//! The volumes' Monte Carlo reference for all scattering orders, in f64:
//! random walks through the metaballs' analytic field by delta tracking
//! (Woodcock tracking) against a piecewise-constant majorant, each real
//! collision lit by next-event estimation with the transmittance toward the
//! light from ratio tracking. Unbiased for the scene's model of light: the
//! lights' direct light scattered any number of times by the volumes, the
//! homogeneous medium only attenuating (as in the slice renderer), surfaces
//! occluding the lights but reflecting nothing into the volumes.
//!
//! Order 1 is left to the single-scattering quadrature
//! (`reference::volume_ray`), which has no variance; this module adds
//! orders 2 and up: a walk's first collision is where light is scattered
//! toward the camera last, and the next-event estimate at its k-th
//! collision is order k.
//!
//! Chromatic media are tracked with one majorant (the largest channel's)
//! and per-channel weights: a tentative collision is real with probability
//! `mean(sigma_t) / mu`, and the weights `sigma_s / (mu P_real)` and
//! `(mu - sigma_t) / (mu (1 - P_real))` keep every channel unbiased (Kutz et
//! al. 2017's spectral tracking, with the mean as the pick).

use glam::DVec3;

use super::reference::{density, phase as volume_phase};
use crate::reference::{box_span, d3, emitted, falloff, nearest, sees_light, toward_light, unit_from_hash};
use crate::scene::SceneData;
use slicelight_shaders::volumes::PHASE_DOUBLE_HENYEY_GREENSTEIN;

/// Collisions after which a walk stops (its weight has long been rouletted
/// away in any medium with albedo below 0.9999; a cap against a lossless
/// medium trapping a walk forever).
const MAX_COLLISIONS: u32 = 1 << 16;

/// Sub-cells of the majorant grid per metaball bin, along each axis.
const SPLIT: u32 = 4;

/// A volume's majorant grid: its bins split `SPLIT` ways, or one cell for
/// a grid from a file (which has no bins).
fn majorant_cells(v: &slicelight_shaders::volumes::GpuVolume) -> (u32, u32, u32) {
    if v.is_file_grid() {
        (1, 1, 1)
    } else {
        (v.bins_x * SPLIT, v.bins_y * SPLIT, v.bins_z * SPLIT)
    }
}

/// Per volume, a grid of upper bounds of the density, each bin of the
/// metaballs split `SPLIT` times along each axis: in a sub-cell, the sum
/// over the balls the bin lists of `q f(a)` at the ball's nearest distance
/// `a` (over its radius) to the sub-cell (Wyvill's field falls with
/// distance, so each term is the ball's largest value there). Tight where
/// the cells are small against the balls: the majorant is what sets the
/// cost of delta tracking (one density evaluation per tentative collision).
pub struct Majorants {
    cells: Vec<Vec<f64>>,
}

impl Majorants {
    pub fn new(data: &SceneData) -> Self {
        use rayon::prelude::*;
        let s = &data.volumes;
        let cells = s
            .volumes
            .iter()
            .enumerate()
            .map(|(index, v)| {
                let (lo, hi) = (d3(v.min), d3(v.max));
                let automaton = s.params.automaton_volume == index as u32 + 1;
                let file = s.file_grid(v);
                let grid = file.is_some();
                // A grid's trilinear values lie within its largest.
                let bound = match file {
                    Some(values) => values.iter().fold(0.0f32, |a, b| a.max(*b)) as f64,
                    None => s.automaton.density_bound(),
                } * d3(v.sigma_t).max_element();
                let (nx, ny, nz) = majorant_cells(v);
                let cell = (hi - lo) / DVec3::new(nx as f64, ny as f64, nz as f64);
                (0..nx * ny * nz)
                    .into_par_iter()
                    .map(|c| {
                        if automaton || grid {
                            return bound;
                        }
                        let i = DVec3::new((c % nx) as f64, ((c / nx) % ny) as f64, (c / (nx * ny)) as f64);
                        let (a, b) = (lo + i * cell, lo + (i + 1.0) * cell);
                        let bin =
                            (c / (nx * ny) / SPLIT * v.bins_y + (c / nx) % ny / SPLIT) * v.bins_x + c % nx / SPLIT;
                        let at = (v.bin_offset + bin) as usize;
                        (s.bins[at]..s.bins[at + 1])
                            .map(|k| {
                                let ball = &s.balls[s.bins[k as usize] as usize];
                                let (centre, r) = (d3(ball.center_radius), ball.center_radius.w as f64);
                                let nearest = centre.clamp(a, b);
                                ball.q.x as f64 * super::reference::field((nearest - centre).length_squared() / (r * r))
                            })
                            .sum::<f64>()
                            * d3(v.sigma_t).max_element()
                    })
                    .collect()
            })
            .collect();
        Self { cells }
    }

    /// The majorant (1/m, the largest channel's) on the ray from `p` along
    /// `d` and how far (m) it holds: the sum over the volumes whose box holds
    /// `p` of `max(sigma_t) * bound` of the bin holding it, up to the nearest
    /// bin face or box entry ahead. `None`: no volume lies ahead.
    fn at(&self, data: &SceneData, p: DVec3, d: DVec3) -> Option<(f64, f64)> {
        let inv = 1.0 / d;
        let mut mu = 0.0;
        let mut run = f64::INFINITY;
        let mut ahead = false;
        for (v, bounds) in data.volumes.volumes.iter().zip(&self.cells) {
            let (lo, hi) = (d3(v.min), d3(v.max));
            let (near, far) = box_span(p, inv, lo, hi, 0.0, f64::INFINITY);
            if near > far || far <= 0.0 {
                continue;
            }
            ahead = true;
            if near > 0.0 {
                run = run.min(near);
                continue;
            }
            let (nx, ny, nz) = majorant_cells(v);
            let n = DVec3::new(nx as f64, ny as f64, nz as f64);
            let cell = (hi - lo) / n;
            // The sub-cell the ray is in just past `p` (a point on a face
            // belongs to the cell it enters).
            let q = p + d * (1e-9 * cell.min_element());
            let i = ((q - lo) / cell).floor().clamp(DVec3::ZERO, n - 1.0);
            let c = ((i.z * n.y + i.y) * n.x + i.x) as usize;
            let cell_lo = lo + i * cell;
            let (_, exit) = box_span(p, inv, cell_lo, cell_lo + cell, 0.0, f64::INFINITY);
            run = run.min(exit.max(1e-9 * cell.min_element()));
            mu += bounds[c];
        }
        ahead.then_some((mu, run))
    }
}

/// A walk's random numbers: SplitMix64 over a counter seeded by the ray.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        unit_from_hash(self.0)
    }
}

/// The medium at a point: extinction and scattering (rgb, 1/m) of all
/// volumes, and each volume's scattering (rgb, 1/m) for the phase mixture.
struct Point {
    sigma_t: DVec3,
    sigma_s: DVec3,
    parts: Vec<DVec3>,
}

fn medium(data: &SceneData, p: DVec3) -> Point {
    let mut point = Point { sigma_t: DVec3::ZERO, sigma_s: DVec3::ZERO, parts: Vec::new() };
    for v in &data.volumes.volumes {
        let rho = density(data, v, p);
        point.sigma_t += d3(v.sigma_t) * rho;
        let s = d3(v.sigma_s) * rho;
        point.sigma_s += s;
        point.parts.push(s);
    }
    point
}

/// The phase mixture at a point (rgb, 1/sr): each volume's phase function
/// weighted by its share of the scattering, per channel.
fn phase_mix(data: &SceneData, point: &Point, cos: f64) -> DVec3 {
    let mut sum = DVec3::ZERO;
    for (v, s) in data.volumes.volumes.iter().zip(&point.parts) {
        sum += *s * volume_phase(v, cos);
    }
    sum / point.sigma_s.max(DVec3::splat(1e-300))
}

/// Henyey-Greenstein's cosine for a uniform `u` (its inverse CDF).
fn sample_hg(g: f64, u: f64) -> f64 {
    if g.abs() < 1e-4 {
        return 1.0 - 2.0 * u;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

/// A unit vector at angle `acos(cos)` from `d`, about it at `2 pi u`.
fn rotate(d: DVec3, cos: f64, u: f64) -> DVec3 {
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let (a, b) = d.any_orthonormal_pair();
    let phi = std::f64::consts::TAU * u;
    (d * cos + (a * phi.cos() + b * phi.sin()) * sin).normalize()
}

/// A new direction from the phase mixture (volumes picked by their mean
/// scattering, each by its own lobes) and the per-channel weight
/// `phase_mix / pdf` (1 for one volume).
fn scatter(data: &SceneData, point: &Point, d: DVec3, rng: &mut Rng) -> (DVec3, DVec3) {
    let total: f64 = point.parts.iter().map(|s| s.element_sum()).sum();
    let mut pick = rng.next() * total;
    let mut chosen = 0;
    for (i, s) in point.parts.iter().enumerate() {
        chosen = i;
        pick -= s.element_sum();
        if pick < 0.0 {
            break;
        }
    }
    let v = &data.volumes.volumes[chosen];
    let g = if v.phase_kind == PHASE_DOUBLE_HENYEY_GREENSTEIN {
        if rng.next() < v.weight as f64 {
            v.g1 as f64
        } else {
            v.g2 as f64
        }
    } else if v.phase_kind == slicelight_shaders::types::PHASE_HENYEY_GREENSTEIN {
        v.g1 as f64
    } else {
        0.0
    };
    let cos = sample_hg(g, rng.next());
    let next = rotate(d, cos, rng.next());
    let cos = next.dot(d);
    // The Henyey-Greenstein kinds are sampled from their own lobes (the
    // pdf is the phase function); the other kinds isotropically.
    let pdf: f64 = data
        .volumes
        .volumes
        .iter()
        .zip(&point.parts)
        .map(|(v, s)| {
            let hg = v.phase_kind == PHASE_DOUBLE_HENYEY_GREENSTEIN
                || v.phase_kind == slicelight_shaders::types::PHASE_HENYEY_GREENSTEIN;
            let density = if hg { volume_phase(v, cos) } else { 0.25 * std::f64::consts::FRAC_1_PI };
            s.element_sum() / total * density
        })
        .sum();
    (next, phase_mix(data, point, cos) / pdf.max(1e-300))
}

/// Transmittance (rgb) through the volumes from `p` along `d` for
/// `distance` metres, by ratio tracking against the majorants, with
/// Russian roulette once it falls below 0.05 (unbiased).
fn ratio_tracking(data: &SceneData, m: &Majorants, p: DVec3, d: DVec3, distance: f64, rng: &mut Rng) -> DVec3 {
    let mut t = DVec3::ONE;
    let mut s = 0.0;
    while s < distance {
        let Some((mu, run)) = m.at(data, p + d * s, d) else {
            break;
        };
        let end = (s + run).min(distance);
        if mu <= 0.0 {
            s = end;
            continue;
        }
        let step = -(1.0 - rng.next()).ln() / mu;
        if s + step >= end {
            s = end;
            continue;
        }
        s += step;
        t *= (1.0 - medium(data, p + d * s).sigma_t / mu).max(DVec3::ZERO);
        let largest = t.max_element();
        if largest < 0.05 {
            if rng.next() < 0.5 {
                return DVec3::ZERO;
            }
            t *= 2.0;
        }
    }
    t
}

/// Light from every light arriving at `p` (rgb, W/m^2 per unit solid angle
/// of the phase function) scattered toward `-d` (the walk's direction `d`
/// reversed), through surfaces (shadow rays), the homogeneous medium and
/// the volumes (ratio tracking).
fn next_event(data: &SceneData, m: &Majorants, point: &Point, p: DVec3, d: DVec3, rng: &mut Rng) -> DVec3 {
    let fog_t = d3(data.common.sigma_t);
    let mut sum = DVec3::ZERO;
    for light in &data.lights {
        let (local, to_light, distance) = toward_light(light, p);
        let e = emitted(data, light, local);
        if e == DVec3::ZERO || !sees_light(data, p, to_light, distance) {
            continue;
        }
        let through = ratio_tracking(data, m, p, to_light, distance, rng);
        if through == DVec3::ZERO {
            continue;
        }
        // Incident travel -to_light against the scattered travel -d.
        let arriving = e * falloff(light, distance) * (-fog_t * distance.max(0.0)).exp() * through;
        sum += arriving * phase_mix(data, point, to_light.dot(d));
    }
    sum
}

/// One random walk's estimate of the radiance (rgb, W/(m^2 sr)) scattered
/// toward the camera along the ray `o + t d` (t below `t_surface`) by the
/// volumes, the orders `lowest..=highest` of it; `seed` picks its random
/// numbers. The reference takes orders 2 and up; order 1 alone is the
/// quadrature's, which tests the walk.
pub fn walk(
    data: &SceneData,
    m: &Majorants,
    o: DVec3,
    d: DVec3,
    t_surface: f64,
    (lowest, highest): (u32, u32),
    seed: u64,
) -> DVec3 {
    let fog_t = d3(data.common.sigma_t);
    let mut sum = DVec3::ZERO;
    let mut rng = Rng(seed.wrapping_mul(0xD1B5_4A32_D192_ED03));
    let (mut p, mut d, mut limit) = (o, d, t_surface);
    let mut beta = DVec3::ONE;
    let mut collisions = 0u32;
    'walk: while collisions < MAX_COLLISIONS.min(highest) {
        // Free flight from `p` along `d` to the next real collision.
        let mut s = 0.0;
        let point = loop {
            if s >= limit {
                break 'walk;
            }
            let Some((mu, run)) = m.at(data, p + d * s, d) else {
                break 'walk;
            };
            let end = (s + run).min(limit);
            let step = if mu > 0.0 { -(1.0 - rng.next()).ln() / mu } else { f64::INFINITY };
            if s + step >= end {
                s = end;
                continue;
            }
            s += step;
            let point = medium(data, p + d * s);
            let real = point.sigma_t.element_sum() / (3.0 * mu);
            if rng.next() < real {
                beta *= point.sigma_s / (mu * real);
                break point;
            }
            beta *= (DVec3::splat(mu) - point.sigma_t) / (mu * (1.0 - real));
        };
        beta *= (-fog_t * s).exp();
        p += d * s;
        collisions += 1;
        if collisions >= lowest {
            sum += beta * next_event(data, m, &point, p, d, &mut rng);
        }
        let (next, weight) = scatter(data, &point, d, &mut rng);
        beta *= weight;
        d = next;
        limit = nearest(data, p, d, 1e-7 * (1.0 + p.length()), f64::INFINITY).map_or(f64::INFINITY, |hit| hit.t);
        // Russian roulette on the weight.
        let largest = beta.max_element();
        if largest < 0.1 {
            if rng.next() >= largest * 10.0 {
                break;
            }
            beta /= largest * 10.0;
        }
    }
    sum
}

/// Most random walks per ray `converged` takes.
pub const MAX_WALKS: u32 = 65536;

/// Orders 2 and up along each ray `(o, d, t_surface)`: random walks in
/// rounds (16, then doubling the total), until the standard error of the
/// mean, RMS over the rays, falls below `tolerance` times the peak of
/// `base + mean` (`base`: the rest of each ray's value), or `MAX_WALKS`
/// walks a ray. Returns the means and the walks per ray.
pub fn converged(data: &SceneData, rays: &[(DVec3, DVec3, f64)], base: &[DVec3], tolerance: f64) -> (Vec<DVec3>, u32) {
    use rayon::prelude::*;
    let m = Majorants::new(data);
    let mut sums = vec![(DVec3::ZERO, DVec3::ZERO); rays.len()];
    let mut walks = 0u32;
    let mut round = 16u32;
    loop {
        sums.par_iter_mut().zip(rays).enumerate().for_each(|(r, (sum, &(o, d, t)))| {
            for k in walks..walks + round {
                let x = walk(data, &m, o, d, t, (2, u32::MAX), (r as u64) << 32 | k as u64);
                sum.0 += x;
                sum.1 += x * x;
            }
        });
        walks += round;
        let n = walks as f64;
        let means: Vec<DVec3> = sums.iter().map(|s| s.0 / n).collect();
        let variance: f64 = sums
            .iter()
            .zip(&means)
            .map(|(s, mean)| ((s.1 / n - *mean * *mean).max(DVec3::ZERO) / n).element_sum() / 3.0)
            .sum::<f64>()
            / rays.len().max(1) as f64;
        let peak = means.iter().zip(base).map(|(m, b)| (*m + *b).max_element()).fold(0.0, f64::max);
        if variance.sqrt() <= tolerance * peak || walks >= MAX_WALKS {
            return (means, walks);
        }
        round = walks;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn henyey_greenstein_sampling_has_mean_cosine_g() {
        // The mean cosine of HG(g) is g; 10^5 stratified samples hold it to
        // ~1e-5 (the integrand is smooth in u).
        for g in [-0.7, -0.3, 0.0, 0.5, 0.85] {
            let n = 100_000;
            let mean: f64 = (0..n).map(|i| sample_hg(g, (i as f64 + 0.5) / n as f64)).sum::<f64>() / n as f64;
            assert!((mean - g).abs() < 1e-3, "g {g}: mean cosine {mean}");
        }
    }
}
