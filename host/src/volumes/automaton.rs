//! The cloud automaton (kernels: `shader-crate/src/volumes/automaton.rs`):
//! a `[[volume]]`'s `automaton = { ... }` settings, the per-cell
//! probabilities from its ellipsoids, and two passes: the steps
//! (`cloud_automaton`, dispatched once per step) and the continuous
//! density's weights (`cloud_automaton.smooth`). The volume's density grid
//! is the automaton's lattice; `volume_density` fills it from the weights.

use anyhow::{bail, Result};
use glam::{UVec4, Vec3};
use indicatif::ProgressBar;
use serde::Deserialize;
use slicelight_shaders::types::CommonParams;
use slicelight_shaders::volumes::automaton::{automaton_cell, smooth_cell, AutomatonParams};

use crate::cpu::for_each_invocation;
use crate::passes::*;
use crate::scene::{invalid, validate, SceneData};

/// `automaton = { ... }` in a `[[volume]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Cells along x, y (up), z over the volume's box.
    pub cells: [u32; 3],
    /// Steps run per frame (from a clear sky) at the scene's time 0.
    pub steps: u32,
    /// Steps per second of scene time (an animation's clouds evolve:
    /// `steps + round(steps_per_second * t)` at time `t`); default 0.
    pub steps_per_second: Option<f32>,
    #[serde(default)]
    pub seed: u32,
    /// Half-width (cells) of the smoothing cube; default 1 (3x3x3).
    pub smoothing: Option<u32>,
    /// Cells per step along x and z; default none.
    pub wind: Option<[f32; 2]>,
    /// Metaball radius in cells (of the largest cell edge); default 1.5.
    pub ball_radius: Option<f32>,
    /// Cloud extinction probability per step outside every ellipsoid;
    /// default 0.1.
    pub extinction: Option<f32>,
    /// Where clouds form: ellipsoids whose probabilities fall from their
    /// centre to their surface.
    pub ellipsoids: Vec<Ellipsoid>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ellipsoid {
    /// Centre and semi-axes along x, y, z, metres.
    pub center: [f32; 3],
    pub radii: [f32; 3],
    /// Per step at the centre: vapour supply `p_hum`, activation `p_act`,
    /// cloud extinction `p_ext`.
    pub humidity: f32,
    pub activation: f32,
    pub extinction: f32,
}

/// Most cells an automaton may have (64 MiB of state and weights).
pub const MAX_CELLS: u64 = 1 << 24;
/// Most steps a frame may run.
pub const MAX_STEPS: u32 = 100_000;

/// The automaton's state for a scene (`automaton.cells == 0`: none).
#[derive(Debug, Clone, Default)]
pub struct Setup {
    pub params: AutomatonParams,
    /// Per cell, `(p_hum, p_act, p_ext, 0)` times 2^32.
    pub probability: Vec<UVec4>,
    pub steps: u32,
    /// The weights per cell after `steps`, run on the CPU once, for the
    /// references (`weights`).
    pub cached_weights: std::sync::OnceLock<Vec<f32>>,
}

impl Setup {
    /// The continuous density's weights after the steps (the CPU path's,
    /// bit for bit the kernels' state), computed once.
    pub fn weights(&self) -> &[f32] {
        self.cached_weights.get_or_init(|| {
            let state = run(self, &ProgressBar::hidden());
            (0..self.params.cells).map(|i| smooth_cell(i, &self.params, &state)).collect()
        })
    }

    /// The largest density the metaballs can sum to anywhere: every
    /// lattice point within a radius at full weight, normalised.
    pub fn density_bound(&self) -> f64 {
        let p = &self.params;
        let span = |r: u32| (2 * r + 2) as f64;
        span(p.reach_x) * span(p.reach_y) * span(p.reach_z) * p.norm as f64
    }

    /// The density at `x` in f64 (the references'): the metaballs at the
    /// lattice's cell centres of the box `[lo, hi]`, weighted by `weights`,
    /// Wyvill's field evaluated exactly, normalised as the kernel does.
    pub fn density_f64(&self, lo: glam::DVec3, hi: glam::DVec3, x: glam::DVec3) -> f64 {
        use glam::DVec3;
        let p = &self.params;
        let n = DVec3::new(p.nx as f64, p.ny as f64, p.nz as f64);
        let size = (hi - lo) / n;
        let r = p.radius as f64;
        let weights = self.weights();
        let first = ((x - lo - DVec3::splat(r)) / size - 0.5).ceil().max(DVec3::ZERO);
        let last = ((x - lo + DVec3::splat(r)) / size - 0.5).floor().min(n - 1.0);
        let mut sum = 0.0;
        for k in first.z as i64..=last.z as i64 {
            for j in first.y as i64..=last.y as i64 {
                for i in first.x as i64..=last.x as i64 {
                    let q = weights[((k as u32 * p.ny + j as u32) * p.nx + i as u32) as usize] as f64;
                    if q > 0.0 {
                        let c = lo + (DVec3::new(i as f64, j as f64, k as f64) + 0.5) * size;
                        sum += q * super::reference::field((x - c).length_squared() / (r * r));
                    }
                }
            }
        }
        sum * p.norm as f64
    }
}

/// A probability as a threshold on 32 random bits.
fn threshold(p: f32) -> u32 {
    (p as f64 * 4294967296.0).clamp(0.0, u32::MAX as f64) as u32
}

fn probability(field: &str, p: f32) -> Result<f32> {
    if !(0.0..=1.0).contains(&p) {
        bail!(invalid(field, "a probability in [0, 1]", p));
    }
    Ok(p)
}

/// Validates `s` for the volume `index` with box `[lo, hi]` at the scene's
/// `time` (s) and builds the automaton's parameters and probabilities.
pub fn configure_at(field: &str, index: usize, s: &Settings, lo: Vec3, hi: Vec3, time: f64) -> Result<Setup> {
    let rate = s.steps_per_second.unwrap_or(0.0);
    if !(rate.is_finite() && (0.0..=1000.0).contains(&rate)) {
        bail!(invalid(&format!("{field}.automaton.steps_per_second"), "a rate in [0, 1000] steps per second", rate));
    }
    // The count asked for is checked before the clock adds to it (a
    // clamp here once turned `steps = 2^31` into 100 000 silent steps).
    if !(1..=MAX_STEPS).contains(&s.steps) {
        bail!(invalid(&format!("{field}.automaton.steps"), &format!("a step count in 1..={MAX_STEPS}"), s.steps));
    }
    let total = s.steps as f64 + (rate as f64 * time).round();
    if total > MAX_STEPS as f64 {
        bail!(invalid(
            &format!("{field}.automaton.steps_per_second"),
            &format!("at most {MAX_STEPS} steps in all at t = {time} s (steps + steps_per_second x t)"),
            total
        ));
    }
    let mut s = s.clone();
    s.steps = total as u32;
    configure(field, index, &s, lo, hi)
}

/// Validates `s` for the volume `index` with box `[lo, hi]` and builds the
/// automaton's parameters and probabilities.
pub fn configure(field: &str, index: usize, s: &Settings, lo: Vec3, hi: Vec3) -> Result<Setup> {
    let f = |name: &str| format!("{field}.automaton.{name}");
    if !s.cells.iter().all(|n| (1..=4096).contains(n)) {
        bail!(invalid(&f("cells"), "three cell counts in 1..=4096", s.cells));
    }
    let cells = s.cells.iter().map(|&n| n as u64).product::<u64>();
    if cells > MAX_CELLS {
        bail!(invalid(&f("cells"), &format!("at most {MAX_CELLS} cells"), s.cells));
    }
    if !(1..=MAX_STEPS).contains(&s.steps) {
        bail!(invalid(&f("steps"), &format!("a step count in 1..={MAX_STEPS}"), s.steps));
    }
    let smoothing = s.smoothing.unwrap_or(1);
    if smoothing > 8 {
        bail!(invalid(&f("smoothing"), "a half-width in 0..=8 cells", smoothing));
    }
    let wind = s.wind.unwrap_or([0.0, 0.0]);
    if !wind.iter().all(|w| w.is_finite() && w.abs() <= 8.0) {
        bail!(invalid(&f("wind"), "cells per step within [-8, 8]", wind));
    }
    let ball = s.ball_radius.unwrap_or(1.5);
    if !(0.5..=4.0).contains(&ball) {
        bail!(invalid(&f("ball_radius"), "a radius in [0.5, 4] cells", ball));
    }
    let outside = probability(&f("extinction"), s.extinction.unwrap_or(0.1))?;
    let mut shapes = Vec::with_capacity(s.ellipsoids.len());
    for (i, e) in s.ellipsoids.iter().enumerate() {
        let name = |x: &str| format!("{field}.automaton.ellipsoids[{i}].{x}");
        let c = validate::finite3(&name("center"), e.center)?;
        let r = validate::finite3(&name("radii"), e.radii)?;
        if !r.cmpgt(Vec3::ZERO).all() {
            bail!(invalid(&name("radii"), "three positive semi-axes", e.radii));
        }
        let p = [
            probability(&name("humidity"), e.humidity)?,
            probability(&name("activation"), e.activation)?,
            probability(&name("extinction"), e.extinction)?,
        ];
        shapes.push((c, r, p));
    }
    let [nx, ny, nz] = s.cells;
    let n = Vec3::new(nx as f32, ny as f32, nz as f32);
    let size = (hi - lo) / n;
    // Per cell: the ellipsoid reaching it most (weight 1 - d^2 at
    // normalised distance d < 1), its probabilities times that weight, the
    // extinction blended toward the outside value.
    let probability = (0..cells as u32)
        .map(|c| {
            let i = Vec3::new((c % nx) as f32, ((c / nx) % ny) as f32, (c / (nx * ny)) as f32);
            let x = lo + (i + 0.5) * size;
            let (w, p) = shapes
                .iter()
                .map(|(centre, r, p)| (1.0 - ((x - *centre) / *r).length_squared(), p))
                .fold((0.0f32, &[0.0f32; 3]), |best, e| if e.0 > best.0 { e } else { best });
            UVec4::new(threshold(p[0] * w), threshold(p[1] * w), threshold(p[2] * w + outside * (1.0 - w)), 0)
        })
        .collect();
    // The metaballs' radius (m), the offsets it reaches per axis, and the
    // field's sum over them (a uniform weight then gives that density).
    let radius = ball * size.max_element();
    let reach = (Vec3::splat(radius) / size).floor();
    let mut sum = 0.0f64;
    for dk in -(reach.z as i32)..=reach.z as i32 {
        for dj in -(reach.y as i32)..=reach.y as i32 {
            for di in -(reach.x as i32)..=reach.x as i32 {
                let d = Vec3::new(di as f32, dj as f32, dk as f32) * size;
                sum += slicelight_shaders::volumes::field(d.length_squared() / (radius * radius)) as f64;
            }
        }
    }
    let params = AutomatonParams {
        nx,
        ny,
        nz,
        cells: cells as u32,
        seed: s.seed,
        smoothing,
        wind_x: (wind[0] * 256.0).round() as i32,
        wind_z: (wind[1] * 256.0).round() as i32,
        volume: index as u32,
        radius,
        norm: (1.0 / sum) as f32,
        reach_x: reach.x as u32,
        reach_y: reach.y as u32,
        reach_z: reach.z as u32,
        _pad0: 0,
        _pad1: 0,
    };
    Ok(Setup { params, probability, steps: s.steps, cached_weights: Default::default() })
}

/// Runs the automaton's steps on the CPU (the same function per cell as
/// the kernel), from a clear lattice; returns the final state.
pub fn run(setup: &Setup, progress: &ProgressBar) -> Vec<u32> {
    let p = &setup.params;
    let mut state = vec![0u32; p.cells as usize];
    let mut next = vec![0u32; p.cells as usize];
    let quiet = ProgressBar::hidden();
    for step in 0..setup.steps {
        for_each_invocation(&mut next, 0, &quiet, |i, out| {
            *out = automaton_cell(i, step, p, &state, &setup.probability)
        });
        std::mem::swap(&mut state, &mut next);
        progress.inc(p.cells as u64);
    }
    state
}

fn skip_without_automaton(scene: &SceneData) -> Option<Plan> {
    (scene.volumes.automaton.params.cells == 0).then(|| Plan::skip("no automaton"))
}

pub static AUTOMATON_PARAMS: Resource = Resource {
    binding: 49,
    name: "automaton parameters",
    kind: ResourceKind::Scene(|s| bytemuck::bytes_of(&s.volumes.automaton.params)),
};
pub static AUTOMATON_PROBABILITY: Resource = Resource {
    binding: 50,
    name: "automaton probabilities",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.volumes.automaton.probability)),
};
/// The lattice a step reads (the GPU copies the step's output over it).
pub static AUTOMATON_STATE: Resource = Resource {
    binding: 51,
    name: "automaton state",
    kind: ResourceKind::Frame(|s| s.volumes.automaton.params.cells as u64 * 4),
};
/// The lattice a step writes: after the last, the final state.
pub static AUTOMATON_NEXT: Resource = Resource {
    binding: 52,
    name: "automaton next state",
    kind: ResourceKind::Frame(|s| s.volumes.automaton.params.cells as u64 * 4),
};
pub static AUTOMATON_STEP: Resource =
    Resource { binding: 53, name: "automaton step", kind: ResourceKind::Frame(|_| 4) };
pub static AUTOMATON_NEXT_STEP: Resource =
    Resource { binding: 54, name: "automaton next step", kind: ResourceKind::Frame(|_| 4) };
/// The continuous density's weight per cell.
pub static AUTOMATON_WEIGHTS: Resource = Resource {
    binding: 55,
    name: "automaton weights",
    kind: ResourceKind::Frame(|s| s.volumes.automaton.params.cells as u64 * 4),
};

pub struct Steps;

impl Pass for Steps {
    fn name(&self) -> &'static str {
        "cloud_automaton"
    }
    fn kernel(&self) -> &'static str {
        "volumes::automaton::automaton_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![AUTOMATON_PARAMS, AUTOMATON_PROBABILITY, AUTOMATON_STATE, AUTOMATON_STEP]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![AUTOMATON_NEXT, AUTOMATON_NEXT_STEP]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn repeats(&self, scene: &SceneData) -> u32 {
        scene.volumes.automaton.steps
    }
    fn carry(&self) -> &'static [(&'static Resource, &'static Resource)] {
        static CARRY: [(&Resource, &Resource); 2] =
            [(&AUTOMATON_NEXT, &AUTOMATON_STATE), (&AUTOMATON_NEXT_STEP, &AUTOMATON_STEP)];
        &CARRY
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_automaton(scene) {
            return skip;
        }
        let a = &scene.volumes.automaton;
        let p = &a.params;
        Plan::run(format!("{} steps of {}x{}x{} cells (seed {})", a.steps, p.nx, p.ny, p.nz, p.seed), p.cells as u64)
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let a = &scene.volumes.automaton;
        let state = run(a, progress);
        frame.insert(&AUTOMATON_NEXT, Buffer::from_bytes(bytemuck::cast_slice(&state)));
        frame.insert(&AUTOMATON_NEXT_STEP, Buffer::from_bytes(bytemuck::bytes_of(&a.steps)));
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Integer rules and a counter-based hash: the same bits, or a bug.
        let (a, b) = (gpu.get::<u32>(&AUTOMATON_NEXT), cpu.get::<u32>(&AUTOMATON_NEXT));
        let (differ, _) = crate::passes::differing_records("automaton cells", a, b, 1)?;
        let step = (gpu.get::<u32>(&AUTOMATON_NEXT_STEP)[0], cpu.get::<u32>(&AUTOMATON_NEXT_STEP)[0]);
        if differ > 0 || step.0 != step.1 {
            bail!("{differ} of {} cells differ; steps {} and {}", a.len(), step.0, step.1);
        }
        let clouds = a.iter().filter(|&&c| c & slicelight_shaders::volumes::automaton::CLD != 0).count();
        Ok(format!("all {} cells identical after {} steps ({clouds} cloudy)", a.len(), step.0))
    }
}

pub struct Smooth;

impl Pass for Smooth {
    fn name(&self) -> &'static str {
        "cloud_automaton.smooth"
    }
    fn kernel(&self) -> &'static str {
        "volumes::automaton::smooth_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![AUTOMATON_PARAMS, AUTOMATON_NEXT]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![AUTOMATON_WEIGHTS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_automaton(scene) {
            return skip;
        }
        let p = &scene.volumes.automaton.params;
        let side = 2 * p.smoothing + 1;
        Plan::run(format!("cloud share over {side}x{side}x{side} cells"), p.cells as u64)
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.volumes.automaton.params;
        frame.write_all::<f32>(&AUTOMATON_WEIGHTS, p.cells as usize, |f, out| {
            let state = f.get::<u32>(&AUTOMATON_NEXT);
            for_each_invocation(out, 0, progress, |i, w| *w = smooth_cell(i, p, state));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // A count over a product of small integers: exact in f32 on both,
        // up to the division's rounding (2.5 ulp allowed on Vulkan).
        compare_values("weights", gpu.get(&AUTOMATON_WEIGHTS), cpu.get(&AUTOMATON_WEIGHTS), 1e-6, 0)
    }
}
