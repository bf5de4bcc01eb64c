//! The volumes' reference, in f64: the metaballs' analytic field (no
//! density grid), the view ray marched with jittered stratified samples, and
//! each sample's optical depth toward each light by a nested march through
//! the field (no transmittance volume), a shadow ray against the geometry
//! (no shadow map), the lights evaluated from their definition. It shares
//! the scene and the pixel positions with the slice renderer and none of
//! its grids, so the difference between the two is the method's error.
//! Single scattering here; `montecarlo` adds the higher orders.

use glam::DVec3;

use crate::reference::{box_span, d3, emitted, falloff, phase_f64, sees_light, toward_light, unit_from_hash};
use crate::scene::SceneData;
use slicelight_shaders::types::PHASE_HENYEY_GREENSTEIN;
use slicelight_shaders::volumes::{GpuVolume, PHASE_DOUBLE_HENYEY_GREENSTEIN};

/// Wyvill's field function in f64 (`volumes::field`).
pub(super) fn field(a2: f64) -> f64 {
    if a2 >= 1.0 {
        return 0.0;
    }
    1.0 + a2 * (-22.0 / 9.0 + a2 * (17.0 / 9.0 - a2 * (4.0 / 9.0)))
}

/// Volume `v`'s density at `p`: every ball's field summed (the bins only
/// skip balls that cannot reach `p`), 0 outside its box.
pub fn density(data: &SceneData, v: &GpuVolume, p: DVec3) -> f64 {
    let (lo, hi) = (d3(v.min), d3(v.max));
    if p.cmplt(lo).any() || p.cmpgt(hi).any() {
        return 0.0;
    }
    let s = &data.volumes;
    if s.params.automaton_volume > 0 && std::ptr::eq(v, &s.volumes[s.params.automaton_volume as usize - 1]) {
        return s.automaton.density_f64(lo, hi, p);
    }
    if let Some(values) = s.file_grid(v) {
        return super::grid::density_f64(values, [v.nx, v.ny, v.nz], lo, hi, p);
    }
    let f = (p - lo) / (hi - lo);
    let bin = |f: f64, n: u32| ((f * n as f64) as i64).clamp(0, n as i64 - 1) as u32;
    let b = v.bin_offset + (bin(f.z, v.bins_z) * v.bins_y + bin(f.y, v.bins_y)) * v.bins_x + bin(f.x, v.bins_x);
    let (start, end) = (s.bins[b as usize], s.bins[b as usize + 1]);
    (start..end)
        .map(|i| {
            let ball = &s.balls[s.bins[i as usize] as usize];
            let r = ball.center_radius.w as f64;
            ball.q.x as f64 * field((p - d3(ball.center_radius)).length_squared() / (r * r))
        })
        .sum()
}

/// A volume's phase function from its closed form, 1/sr.
pub(super) fn phase(v: &GpuVolume, cos: f64) -> f64 {
    if v.phase_kind == PHASE_DOUBLE_HENYEY_GREENSTEIN {
        let w = v.weight as f64;
        w * phase_f64(PHASE_HENYEY_GREENSTEIN, v.g1 as f64, cos)
            + (1.0 - w) * phase_f64(PHASE_HENYEY_GREENSTEIN, v.g2 as f64, cos)
    } else {
        phase_f64(v.phase_kind, v.g1 as f64, cos)
    }
}

/// Extinction (rgb, 1/m) of all volumes at `p`.
fn extinction(data: &SceneData, p: DVec3) -> DVec3 {
    data.volumes.volumes.iter().map(|v| d3(v.sigma_t) * density(data, v, p)).sum()
}

/// The span `[near, far]` of the ray `o + t d` (t >= 0) inside any volume's box.
fn span(data: &SceneData, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let mut range: Option<(f64, f64)> = None;
    let inv = 1.0 / d;
    for v in &data.volumes.volumes {
        let (near, far) = box_span(o, inv, d3(v.min), d3(v.max), 0.0, f64::INFINITY);
        if near < far {
            range = Some(range.map_or((near, far), |(n, f)| (n.min(near), f.max(far))));
        }
    }
    range
}

/// Hash of (ray, stratum, round) to [0, 1): the jitter of the stratified samples.
fn jitter(ray: u64, k: u64, round: u64) -> f64 {
    unit_from_hash(ray.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ k.wrapping_mul(0xD1B5_4A32_D192_ED03) ^ round)
}

/// The optical depth through the volumes from `p` along `dir` (unit) for
/// `distance` metres, by `samples` jittered strata (clipped to the boxes).
fn optical_depth(data: &SceneData, p: DVec3, dir: DVec3, distance: f64, samples: u32, seed: u64) -> DVec3 {
    let Some((near, far)) = span(data, p, dir) else {
        return DVec3::ZERO;
    };
    let far = far.min(distance);
    if far <= near {
        return DVec3::ZERO;
    }
    let dt = (far - near) / samples as f64;
    (0..samples)
        .map(|k| extinction(data, p + dir * (near + (k as f64 + jitter(seed, k as u64, 7)) * dt)))
        .sum::<DVec3>()
        * dt
}

/// The transmittance (rgb) through the volumes from `p` toward a light
/// along `dir` (unit) for `distance` metres: 1 without volumes, else
/// `exp(-tau)` with `tau` by 256 jittered strata (the references' shadows
/// of the volumes on surfaces and the sea).
pub fn transmittance_toward(data: &SceneData, p: DVec3, dir: DVec3, distance: f64) -> DVec3 {
    transmittance_strata(data, p, dir, distance, 256)
}

/// `transmittance_toward` with `strata` strata (the fog's samples take 32
/// each: they are many, and their jitter differs from sample to sample).
pub fn transmittance_strata(data: &SceneData, p: DVec3, dir: DVec3, distance: f64, strata: u32) -> DVec3 {
    if !data.volumes.enabled {
        return DVec3::ONE;
    }
    let seed = p.x.to_bits() ^ p.y.to_bits().rotate_left(21) ^ p.z.to_bits().rotate_left(42);
    (-optical_depth(data, p, dir, distance, strata, seed)).exp()
}

/// The volumes' radiance toward the camera along the ray `o + t d` up to
/// `t_surface` (rgb, W/(m^2 sr)), and the view transmittance through them:
/// `samples` jittered strata over the ray's span inside the boxes, each
/// contributing `T S (1 - exp(-sigma dt)) / sigma` (constant over its
/// stratum; exact in the limit), the light's optical depth at each by
/// `samples / 4` (at least 16) strata toward the light. `ray` seeds the jitter.
pub fn volume_ray(data: &SceneData, o: DVec3, d: DVec3, t_surface: f64, samples: u32, ray: u64) -> (DVec3, DVec3) {
    let Some((near, far)) = span(data, o, d) else {
        return (DVec3::ZERO, DVec3::ONE);
    };
    let far = far.min(t_surface);
    if far <= near {
        return (DVec3::ZERO, DVec3::ONE);
    }
    let fog_t = d3(data.common.sigma_t);
    let light_samples = (samples / 4).max(16);
    let dt = (far - near) / samples as f64;
    let mut radiance = DVec3::ZERO;
    let mut view = DVec3::ONE;
    for k in 0..samples {
        let t = near + (k as f64 + jitter(ray, k as u64, samples as u64)) * dt;
        let p = o + d * t;
        let densities: Vec<f64> = data.volumes.volumes.iter().map(|v| density(data, v, p)).collect();
        let sigma: DVec3 = data.volumes.volumes.iter().zip(&densities).map(|(v, rho)| d3(v.sigma_t) * *rho).sum();
        if sigma == DVec3::ZERO {
            continue;
        }
        let mut source = DVec3::ZERO;
        for (l, light) in data.lights.iter().enumerate() {
            let (local, to_light, distance) = toward_light(light, p);
            let e = emitted(data, light, local);
            if e == DVec3::ZERO || !sees_light(data, p, to_light, distance) {
                continue;
            }
            let falloff = falloff(light, distance);
            let seed = ray.wrapping_mul(1_000_003).wrapping_add(k as u64 * 64 + l as u64);
            let tau = optical_depth(data, p, to_light, distance, light_samples, seed);
            let arriving = e * falloff * (-fog_t * distance.max(0.0)).exp() * (-tau).exp();
            // Incident travel direction -to_light against the scattered one, -d.
            let cos = to_light.dot(d);
            for (v, rho) in data.volumes.volumes.iter().zip(&densities) {
                source += arriving * d3(v.sigma_s) * (*rho * phase(v, cos));
            }
        }
        let step = (-sigma * dt).exp();
        let weight = DVec3::new(
            if sigma.x > 0.0 { (1.0 - step.x) / sigma.x } else { dt },
            if sigma.y > 0.0 { (1.0 - step.y) / sigma.y } else { dt },
            if sigma.z > 0.0 { (1.0 - step.z) / sigma.z } else { dt },
        );
        radiance += view * source * weight * (-fog_t * t).exp();
        view *= step;
    }
    (radiance, view)
}
