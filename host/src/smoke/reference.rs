//! The fluid's closed-form references: the Taylor-Green vortex's viscous
//! decay (the advection's numerical viscosity against the given one) and
//! the added-mass start of a buoyant sphere. The tests and the bench sweep
//! measure against them.

use glam::{UVec3, Vec3};
use slicelight_shaders::smoke::{coords, position, KIND_TEMPERATURE, KIND_U, KIND_V};

use super::{configure, Advection, Settings};

fn settings(body: &str) -> Settings {
    toml::from_str(body).expect("a valid smoke table")
}

/// What a Taylor-Green run measured.
#[derive(Debug, Clone, Copy)]
pub struct TaylorGreen {
    /// The effective viscosity from the energy's decay, m^2/s.
    pub viscosity: f64,
    /// The median wall time of a step, s.
    pub seconds_per_step: f64,
    /// The worst relative divergence after a projection.
    pub divergence: f64,
}

/// A 2D Taylor-Green vortex (`u = sin x cos y`, `v = -cos x sin y`, m/s)
/// on `[0, pi]^2` with free-slip walls (an exact solution there: the walls
/// are its symmetry lines) on `n x n x 1` cells, viscosity `nu`, CFL 0.25,
/// for `seconds`: its effective viscosity from `E = E0 exp(-4 nu t)`.
pub fn taylor_green(n: u32, nu: f32, advection: Advection, seconds: f32) -> TaylorGreen {
    let pi = std::f32::consts::PI;
    let dt = 0.25 * pi / n as f32;
    let scheme = match advection {
        Advection::SemiLagrangian => "semi-lagrangian",
        Advection::Maccormack => "maccormack",
    };
    let body = format!(
        "cells = [{n}, {n}, 1]\nwalls = \"closed\"\ngravity = 0.0\nviscosity = {nu}\ndt = {dt}\nadvection = \"{scheme}\"\ntolerance = 1e-7"
    );
    let c = configure("taylor-green", &settings(&body), Vec3::ZERO, Vec3::new(pi, pi, pi / n as f32))
        .expect("a valid Taylor-Green setup");
    let mut f = c.start(vec![1; (n * n) as usize]);
    f.set_velocity(|kind, x| match kind {
        KIND_U => x.x.sin() * x.y.cos(),
        KIND_V => -x.x.cos() * x.y.sin(),
        _ => 0.0,
    });
    f.project();
    let e0 = f.kinetic_energy();
    let steps = (seconds / dt).round().max(1.0) as u32;
    let mut times = Vec::with_capacity(steps as usize);
    let mut divergence = 0.0f64;
    for _ in 0..steps {
        let t = std::time::Instant::now();
        f.step();
        times.push(t.elapsed().as_secs_f64());
        divergence = divergence.max(f.last.divergence);
    }
    let viscosity = -(f.kinetic_energy() / e0).ln() / (4.0 * (steps as f64 * dt as f64));
    TaylorGreen { viscosity, seconds_per_step: crate::bench::median(times), divergence }
}

/// A buoyant sphere's first acceleration (m/s^2) at its centre, measured on
/// `n^3` cells (radius `n / 8` cells, `dt` 1 ms, closed walls 4 radii
/// away), and the potential-flow value `2 g' / 3` (added mass of a sphere,
/// `C_m = 1/2`) for a temperature excess of 10 %.
pub fn buoyant_sphere(n: u32) -> (f64, f64) {
    let size = 0.1 * n as f32;
    let body = format!("cells = [{n}, {n}, {n}]\nwalls = \"closed\"\ndt = 0.001\nviscosity = 0.0\ndiffusivity = 0.0");
    let c = configure("sphere", &settings(&body), Vec3::ZERO, Vec3::splat(size)).expect("a valid setup");
    let mut f = c.start(vec![1; (n * n * n) as usize]);
    let (centre, radius) = (Vec3::splat(0.5 * size), size / 8.0);
    let hot = 1.1 * f.params.ambient;
    for i in 0..f.params.cells {
        if (position(KIND_TEMPERATURE, coords(UVec3::splat(n), i)) * f.params.h - centre).length() < radius {
            f.temperature[i as usize] = hot;
        }
    }
    f.step();
    let rise = slicelight_shaders::smoke::sample(&f.params, KIND_V, &f.v, centre / f.params.h) / f.params.dt;
    (rise as f64, 2.0 * f.params.gravity as f64 * 0.1 / 3.0)
}
