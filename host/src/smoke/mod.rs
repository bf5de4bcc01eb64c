//! Smoke (the survey's section 4; kernels in `shader-crate/src/smoke/`):
//! a `[[volume]]`'s `smoke = { ... }` settings, the fluid simulated to the
//! scene's time, and the puffs it carries, which become the volume's
//! metaballs (or its density grid, `render = "density"`), so the volumes'
//! renderer, shadows and shafts draw them unchanged.

pub mod bench;
pub mod cache;
pub mod fluid;
pub mod gpu;
pub mod reference;

use anyhow::{bail, Result};
use glam::{UVec3, Vec3};
use serde::Deserialize;
use slicelight_shaders::geometry::{trace_nearest, NO_HIT};
use slicelight_shaders::smoke::*;
use std::sync::Mutex;

pub use fluid::{Advection, Fluid, Puff, PuffRules, SourceCells, StepStats};

use crate::passes::{Family, Pass};
use crate::scene::{invalid, validate, SceneData};

static PASSES: &[&dyn Pass] = &[];

/// The family, as `passes::FAMILIES` registers it: no pass of its own (the
/// fluid runs on the CPU at load, see `docs/smoke.md`), a bench sweep.
pub static FAMILY: Family =
    Family { name: "smoke", passes: PASSES, kernels: gpu::KERNELS, bench: Some(&bench::SmokeSweep) };

/// `smoke = { ... }` in a `[[volume]]`: the fluid fills the volume's box.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Cells along x, y (up), z; the cells must be cubes (the box's edges
    /// in the same ratio).
    pub cells: [u32; 3],
    /// Simulated seconds at the scene's time 0 (a still shows this instant;
    /// an animation's frame `f` shows `seconds + f / fps`).
    #[serde(default)]
    pub seconds: f32,
    /// Time step, s (default 1/30).
    pub dt: Option<f32>,
    #[serde(default)]
    pub seed: u32,
    /// Which faces of the box are walls: `"floor"` (the default: the
    /// bottom only, the rest open to the outside air), `"closed"` (all six),
    /// `"open"` (none).
    #[serde(default)]
    pub walls: Walls,
    /// The outside air's velocity, m/s (at the open faces; default still).
    #[serde(default)]
    pub wind: [f32; 3],
    /// Ambient temperature (K, default 293.15) and gravity (m/s^2, 9.81).
    pub ambient_k: Option<f32>,
    pub gravity: Option<f32>,
    /// Eq. 4's kinematic viscosity `nu` and eddy viscosity `nu_t` (m^2/s;
    /// defaults: air's 1.5e-5 and 0).
    pub viscosity: Option<f32>,
    #[serde(default)]
    pub eddy_viscosity: f32,
    /// Eq. 5's heat diffusivity `alpha` and eddy diffusivity `alpha_t`
    /// (m^2/s; defaults: air's 2.2e-5 and 0).
    pub diffusivity: Option<f32>,
    #[serde(default)]
    pub eddy_diffusivity: f32,
    /// The random components: acceleration amplitude per face and step
    /// (m/s^2) and temperature amplitude per cell and step (K).
    #[serde(default)]
    pub turbulence: f32,
    #[serde(default)]
    pub temperature_noise: f32,
    #[serde(default)]
    pub advection: Advection,
    /// The projection stops when `max |div u| h / max |u|` is below this
    /// (default 1e-6), or after `max_iterations` (default 100).
    pub tolerance: Option<f32>,
    pub max_iterations: Option<u32>,
    /// Whether the scene's objects are solid cells (default true).
    pub obstacles: Option<bool>,
    /// `"puffs"` (the paper's metaballs, the default) or `"density"` (the
    /// grid's own smoke density field).
    #[serde(default)]
    pub render: Render,
    /// Puff radius growth, m/s (default 0.05), and the e-folding time of
    /// their density, s (default 10).
    pub puff_growth: Option<f32>,
    pub puff_lifetime: Option<f32>,
    /// Where smoke comes from (`[[volume.smoke.source]]`).
    #[serde(default)]
    pub source: Vec<Source>,
}

#[derive(Debug, Clone, Copy, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Walls {
    #[default]
    Floor,
    Closed,
    Open,
}

impl Walls {
    pub fn bits(self) -> u32 {
        match self {
            Walls::Floor => WALL_Y_LO,
            Walls::Closed => 63,
            Walls::Open => 0,
        }
    }
}

#[derive(Debug, Clone, Copy, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Render {
    #[default]
    Puffs,
    Density,
}

/// A smoke source: a sphere held at a temperature, a smoke density and a
/// velocity, emitting puffs.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Source {
    /// Centre (m) and radius (m).
    pub position: [f32; 3],
    pub radius: f32,
    /// Puffs per second.
    pub rate: f32,
    /// The gas's temperature, K.
    pub temperature: f32,
    /// The gas's velocity, m/s (default still).
    #[serde(default)]
    pub velocity: [f32; 3],
    /// A puff's radius at emission (m, default the source's) and its
    /// density at the centre (default 1).
    pub puff_radius: Option<f32>,
    pub puff_density: Option<f32>,
}

/// Most cells a fluid may have: its arrays (velocity, temperature, smoke,
/// pressure, the solver's vectors and levels, about 80 bytes a cell) then
/// fit in 1.3 GiB.
pub const MAX_CELLS: u64 = 1 << 24;
/// Most steps a scene may ask to simulate.
pub const MAX_STEPS: u64 = 1_000_000;
/// Bytes per cell the fluid and its solver hold (for the error that names
/// the memory a grid needs).
pub const BYTES_PER_CELL: u64 = 80;

/// A validated fluid, not yet simulated: what `Fluid::new` needs and the
/// step count a time gives.
#[derive(Debug, Clone)]
pub struct Config {
    pub params: FluidParams,
    pub origin: Vec3,
    pub advection: Advection,
    pub rules: PuffRules,
    pub sources: Vec<Source>,
    pub seconds: f32,
    pub render: Render,
    pub tolerance: f64,
    pub max_iterations: u32,
    pub obstacles: bool,
}

impl Config {
    /// Steps to reach `seconds` (rounded to the nearest).
    pub fn steps_to(&self, seconds: f64) -> u64 {
        (seconds / self.params.dt as f64).round().max(0.0) as u64
    }

    /// A fluid at rest with this configuration, its solid cells given.
    pub fn start(&self, fluid_cells: Vec<u32>) -> Fluid {
        let mut f = Fluid::new(self.params, self.origin, fluid_cells, self.advection);
        f.tolerance = self.tolerance;
        f.max_iterations = self.max_iterations;
        f.rules = self.rules.clone();
        f.owed = vec![0.0; self.rules.sources.len()];
        f.sources = self.sources.iter().map(|s| source_cells(&self.params, self.origin, s)).collect();
        f
    }
}

/// The cells and faces inside a source's sphere.
fn source_cells(p: &FluidParams, origin: Vec3, s: &Source) -> SourceCells {
    let c = (Vec3::from(s.position) - origin) / p.h;
    let r = s.radius / p.h;
    let inside = |kind: u32| -> Vec<u32> {
        let e = extent(p, kind);
        (0..e.x * e.y * e.z).filter(|&f| (position(kind, coords(e, f)) - c).length() <= r).collect()
    };
    SourceCells {
        cells: inside(KIND_TEMPERATURE),
        faces: [inside(KIND_U), inside(KIND_V), inside(KIND_W)],
        temperature: s.temperature,
        density: s.puff_density.unwrap_or(1.0),
        velocity: Vec3::from(s.velocity),
    }
}

/// Jacobi iterations for backward-Euler diffusion with weight `lambda`:
/// enough that the iteration's contraction `6 lambda / (1 + 6 lambda)`
/// shrinks the error 1000-fold, at most 50 (0 without diffusion).
fn diffusion_iterations(lambda: f32) -> u32 {
    if lambda <= 0.0 {
        return 0;
    }
    let rate = 6.0 * lambda as f64 / (1.0 + 6.0 * lambda as f64);
    ((1e-3f64).ln() / rate.ln()).ceil().clamp(1.0, 50.0) as u32
}

fn non_negative(field: &str, v: f32) -> Result<f32> {
    if !(v.is_finite() && v >= 0.0) {
        bail!(invalid(field, "a non-negative number", v));
    }
    Ok(v)
}

/// Validates `s` for a volume with box `[lo, hi]`.
pub fn configure(field: &str, s: &Settings, lo: Vec3, hi: Vec3) -> Result<Config> {
    let f = |name: &str| format!("{field}.smoke.{name}");
    if !s.cells.iter().all(|n| (1..=4096).contains(n)) {
        bail!(invalid(&f("cells"), "three cell counts in 1..=4096", s.cells));
    }
    let cells = s.cells.iter().map(|&n| n as u64).product::<u64>();
    if cells > MAX_CELLS {
        bail!(invalid(
            &f("cells"),
            &format!(
                "at most {MAX_CELLS} cells ({} cells would need {:.1} GiB at {BYTES_PER_CELL} bytes a cell)",
                cells,
                (cells * BYTES_PER_CELL) as f64 / (1u64 << 30) as f64
            ),
            s.cells
        ));
    }
    let size = hi - lo;
    let n = UVec3::from(s.cells).as_vec3();
    let edges = size / n;
    let h = edges.x;
    if (edges - Vec3::splat(h)).abs().max_element() > 1e-3 * h {
        bail!(invalid(
            &f("cells"),
            &format!("cubic cells (the box's {size:?} m in the ratio of the cell counts)"),
            s.cells
        ));
    }
    let dt = s.dt.unwrap_or(1.0 / 30.0);
    if !(dt.is_finite() && dt > 0.0 && dt <= 10.0) {
        bail!(invalid(&f("dt"), "a time step in (0, 10] seconds", dt));
    }
    let seconds = non_negative(&f("seconds"), s.seconds)?;
    if (seconds as f64 / dt as f64) > MAX_STEPS as f64 {
        bail!(invalid(&f("seconds"), &format!("at most {MAX_STEPS} steps of dt"), seconds));
    }
    let wind = validate::finite3(&f("wind"), s.wind)?;
    let ambient = s.ambient_k.unwrap_or(293.15);
    if !(ambient.is_finite() && ambient > 0.0) {
        bail!(invalid(&f("ambient_k"), "a positive temperature in kelvin", ambient));
    }
    let gravity = non_negative(&f("gravity"), s.gravity.unwrap_or(9.81))?;
    let nu = non_negative(&f("viscosity"), s.viscosity.unwrap_or(1.5e-5))?;
    let nu_t = non_negative(&f("eddy_viscosity"), s.eddy_viscosity)?;
    let alpha = non_negative(&f("diffusivity"), s.diffusivity.unwrap_or(2.2e-5))?;
    let alpha_t = non_negative(&f("eddy_diffusivity"), s.eddy_diffusivity)?;
    let turbulence = non_negative(&f("turbulence"), s.turbulence)?;
    let noise = non_negative(&f("temperature_noise"), s.temperature_noise)?;
    let tolerance = s.tolerance.unwrap_or(1e-6);
    if !(tolerance > 0.0 && tolerance < 1.0) {
        bail!(invalid(&f("tolerance"), "a relative divergence in (0, 1)", tolerance));
    }
    let max_iterations = s.max_iterations.unwrap_or(100);
    if !(1..=10_000).contains(&max_iterations) {
        bail!(invalid(&f("max_iterations"), "an iteration count in 1..=10000", max_iterations));
    }
    let growth = non_negative(&f("puff_growth"), s.puff_growth.unwrap_or(0.05))?;
    let lifetime = s.puff_lifetime.unwrap_or(10.0);
    if !(lifetime.is_finite() && lifetime > 0.0) {
        bail!(invalid(&f("puff_lifetime"), "a positive time in seconds", lifetime));
    }
    let mut puff_sources = Vec::new();
    for (i, src) in s.source.iter().enumerate() {
        let g = |name: &str| format!("{field}.smoke.source[{i}].{name}");
        let c = validate::finite3(&g("position"), src.position)?;
        if c.cmplt(lo).any() || c.cmpgt(hi).any() {
            bail!(invalid(&g("position"), "a centre inside the volume's box", src.position));
        }
        let r = validate::positive(&g("radius"), src.radius)?;
        let rate = non_negative(&g("rate"), src.rate)?;
        if rate > 1000.0 {
            bail!(invalid(&g("rate"), "at most 1000 puffs per second", rate));
        }
        if !(src.temperature.is_finite() && src.temperature >= 0.0 && src.temperature <= 1e5) {
            bail!(invalid(&g("temperature"), "a temperature in [0, 1e5] K", src.temperature));
        }
        validate::finite3(&g("velocity"), src.velocity)?;
        let pr = validate::positive(&g("puff_radius"), src.puff_radius.unwrap_or(r))?;
        let pq = non_negative(&g("puff_density"), src.puff_density.unwrap_or(1.0))?;
        puff_sources.push((c, r, rate, pr, pq));
    }
    let lambda = |k: f32| (k as f64 * dt as f64 / (h as f64 * h as f64)) as f32;
    let params = FluidParams {
        nx: s.cells[0],
        ny: s.cells[1],
        nz: s.cells[2],
        cells: cells as u32,
        h,
        dt,
        step: 0,
        seed: s.seed,
        walls: s.walls.bits(),
        gravity,
        ambient,
        turbulence,
        wind_x: wind.x,
        wind_y: wind.y,
        wind_z: wind.z,
        temperature_noise: noise,
        eddy_diffusivity: alpha_t,
        viscous_weight: lambda(nu + nu_t),
        thermal_weight: lambda(alpha),
        viscous_iterations: diffusion_iterations(lambda(nu + nu_t)),
        thermal_iterations: diffusion_iterations(lambda(alpha)),
        _pad: 0,
    };
    Ok(Config {
        params,
        origin: lo,
        advection: s.advection,
        rules: PuffRules { sources: puff_sources, growth, lifetime },
        sources: s.source.clone(),
        seconds,
        render: s.render,
        tolerance: tolerance as f64,
        max_iterations,
        obstacles: s.obstacles.unwrap_or(true),
    })
}

/// Per cell, 1 if fluid, 0 if its centre is inside one of the scene's
/// objects: a point is inside where at least four of the six rays along
/// the axes cross the surfaces an odd number of times (closed meshes and
/// spheres give six; a lone open quad, one).
pub fn voxelise(scene: &SceneData, p: &FluidParams, origin: Vec3) -> Vec<u32> {
    let geometry = scene.geometry();
    let e = p.dims();
    let mut out = vec![1u32; p.cells as usize];
    if scene.spheres.is_empty() && scene.triangles.is_empty() {
        return out;
    }
    let dirs = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
    crate::cpu::for_each_invocation(&mut out, 0, &indicatif::ProgressBar::hidden(), |i, o| {
        let x = origin + position(KIND_TEMPERATURE, coords(e, i)) * p.h;
        let odd = dirs
            .iter()
            .filter(|&&d| {
                let mut crossings = 0;
                let mut t = 0.0;
                for _ in 0..64 {
                    let hit = trace_nearest(x, d, t, f32::MAX, &geometry);
                    if hit.distance == NO_HIT {
                        break;
                    }
                    crossings += 1;
                    t = hit.distance + 1e-4 * (1.0 + hit.distance);
                }
                crossings % 2 == 1
            })
            .count();
        *o = (odd < 4) as u32;
    });
    out
}

/// Simulations kept between the frames of an animation (and the renders
/// of one process), by configuration: a later time continues from the
/// state kept instead of starting again. The steps are the same either way
/// (deterministic), so the state at a step does not depend on the path.
static KEPT: Mutex<Vec<(String, Fluid)>> = Mutex::new(Vec::new());

/// The device fluids step on, opened on first use (or why there is none).
static DEVICE: std::sync::OnceLock<std::result::Result<crate::gpu::GpuContext, String>> = std::sync::OnceLock::new();

/// The device `simulate` steps on, if any, by `render::simulation_backend`:
/// `gpu` a device (an error without one), `cpu` none, `auto` a device
/// unless it is itself a CPU device.
pub fn stepping_device() -> Result<Option<&'static crate::gpu::GpuContext>> {
    use crate::render::BackendChoice;
    let choice = crate::render::simulation_backend();
    if choice == BackendChoice::Cpu {
        return Ok(None);
    }
    let device = DEVICE.get_or_init(|| crate::gpu::GpuContext::new().map_err(|e| format!("{e:#}")));
    match (device.as_ref(), choice) {
        // `auto` on a device that is itself the CPU (lavapipe): the CPU
        // steps faster (smoke_chimney's 160 steps: 7 s against 23 s on the
        // 2-core development machine), so the fluid stays there.
        (Ok(d), BackendChoice::Auto) if d.runs_on_the_cpu() => Ok(None),
        (Ok(d), _) => Ok(Some(d)),
        (Err(e), BackendChoice::Gpu) => bail!("stepping the fluid on the GPU: {e}"),
        (Err(_), _) => Ok(None),
    }
}

/// The fluid of `config` simulated to `seconds` (its steps rounded), from
/// the latest state at or before it that this process keeps or the disk
/// cache holds (`cache`), if any; the state reached is kept and, if any
/// step was taken, written to the cache. `progress` counts steps.
pub fn simulate(
    config: &Config,
    fluid_cells: Vec<u32>,
    seconds: f64,
    progress: &indicatif::ProgressBar,
) -> Result<Fluid> {
    let device = stepping_device()?;
    // Everything a step's result depends on: the backend (the two agree to
    // rounding, not bit for bit), the parameters, the sources, the puffs'
    // rules, the solver's stop, and the solid cells (hashed: millions of
    // flags need not be formatted).
    let key = format!(
        "{}{:?}{:?}{:?}{:?}{:?}{:?}{:?}{:016x}",
        if device.is_some() { "gpu" } else { "cpu" },
        config.params,
        config.origin,
        config.advection,
        config.sources,
        config.rules,
        config.tolerance,
        config.max_iterations,
        crate::output::stable_hash(bytemuck::cast_slice(&fluid_cells))
    );
    let hash = cache::key_hash(&key);
    let steps = config.steps_to(seconds);
    let mut start = None;
    if let Ok(mut kept) = KEPT.lock() {
        if let Some(k) = kept.iter().position(|(key_k, f)| *key_k == key && f.params.step as u64 <= steps) {
            start = Some(kept.swap_remove(k).1);
        }
    }
    let dir = crate::output::cache_directory();
    let kept_step = start.as_ref().map(|f: &Fluid| f.params.step as u64);
    if let Some(dir) = &dir {
        if let Some(f) = cache::load(dir, hash, steps, config, &fluid_cells) {
            if kept_step.is_none_or(|k| (f.params.step as u64) > k) {
                crate::output::note(&format!("smoke: continuing from the state cached at step {}", f.params.step));
                start = Some(f);
            }
        }
    }
    let mut fluid = start.unwrap_or_else(|| config.start(fluid_cells));
    let first = fluid.params.step as u64;
    progress.set_length(steps);
    progress.set_position(first);
    if (fluid.params.step as u64) < steps {
        let mut stepper = gpu::Stepper::new(device, &fluid)?;
        while (fluid.params.step as u64) < steps {
            stepper.step(&mut fluid)?;
            progress.inc(1);
        }
        stepper.finish(&mut fluid)?;
    }
    progress.finish_and_clear();
    if let (Some(dir), true) = (&dir, steps > first) {
        // A cache that cannot be written costs time later, not correctness.
        let _ = cache::save(dir, hash, &fluid);
    }
    if let Ok(mut kept) = KEPT.lock() {
        kept.retain(|(k, _)| *k != key);
        kept.push((key, fluid.clone()));
        if kept.len() > 2 {
            kept.remove(0);
        }
    }
    Ok(fluid)
}

/// The puffs as metaballs `[x, y, z, radius, q]` inside the box.
pub fn metaballs(fluid: &Fluid, lo: Vec3, hi: Vec3) -> Vec<[f32; 5]> {
    fluid
        .puffs
        .iter()
        .filter(|puff| puff.position.cmpge(lo).all() && puff.position.cmple(hi).all())
        .map(|puff| {
            let (r, q) = fluid.rules.shape(puff);
            [puff.position.x, puff.position.y, puff.position.z, r, q]
        })
        .collect()
}

/// A progress bar of the simulation's steps on a terminal's stderr
/// (hidden elsewhere: tests, pipes, CI logs).
pub fn progress_bar(field: &str) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(0);
    if let Ok(style) = indicatif::ProgressStyle::with_template(&format!(
        "{field} smoke: step {{pos}}/{{len}} {{wide_bar}} {{elapsed}} (eta {{eta}})"
    )) {
        bar.set_style(style);
    }
    bar
}
