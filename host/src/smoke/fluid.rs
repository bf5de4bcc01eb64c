//! The fluid solver's driver (kernels: `shader-crate/src/smoke/`): the
//! staggered grid's arrays, one step as the sequence of per-element
//! functions, the pressure projection's preconditioned conjugate gradients
//! with their dot products, and the puffs moved through the field.

use glam::{UVec3, Vec3};
use indicatif::ProgressBar;
use slicelight_shaders::random::random;
use slicelight_shaders::smoke::*;

use crate::cpu::{for_each_invocation, for_each_invocation2};
use rayon::prelude::*;

/// Red-black Gauss-Seidel sweeps before and after the coarse correction.
pub(crate) const SMOOTHING_SWEEPS: u32 = 2;

/// The sums of `partial`s, in order, in f64: `(sum a b, max |a|, sum a, count)`.
pub fn sum_partials(partials: &[glam::Vec4]) -> [f64; 4] {
    partials.iter().fold([0.0, 0.0, 0.0, 0.0], |s, q| {
        [s[0] + q.x as f64, s[1].max(q.y as f64), s[2] + q.z as f64, s[3] + q.w as f64]
    })
}

/// `sum_partials` of `a` and `b` (the last two over `fluid`'s cells where
/// given): the same groups and order as the GPU's `fluid_partials`.
pub fn reduce(a: &[f32], b: &[f32], fluid: Option<&[u32]>) -> [f64; 4] {
    let count = a.len() as u32;
    let mut partials = vec![glam::Vec4::ZERO; partial_groups(count) as usize];
    let (flags, use_fluid) = match fluid {
        Some(f) => (f, true),
        None => (&[][..], false),
    };
    for_each_invocation(&mut partials, 0, &ProgressBar::hidden(), |g, out| {
        *out = partial(a, b, flags, use_fluid, count, g)
    });
    sum_partials(&partials)
}

/// One multigrid level: its cells, which are fluid, and its work arrays.
#[derive(Debug, Clone)]
struct Level {
    n: UVec3,
    fluid: Vec<u32>,
    /// Per cell, its stencil (`stencil`).
    stencils: Vec<u32>,
    x: Vec<f32>,
    b: Vec<f32>,
    scratch: Vec<f32>,
}

impl Level {
    fn new(n: UVec3, walls: u32, fluid: Vec<u32>) -> Level {
        let cells = fluid.len();
        let mut stencils = vec![0u32; cells];
        for_each_invocation(&mut stencils, 0, &ProgressBar::hidden(), |i, s| *s = stencil(n, walls, &fluid, i));
        Level { n, fluid, stencils, x: vec![0.0; cells], b: vec![0.0; cells], scratch: vec![0.0; cells] }
    }
}

/// The pressure Poisson equation's solver: conjugate gradients with a
/// multigrid V-cycle as the preconditioner (MGPCG, as McAdams, Sifakis and
/// Teran 2010; here with piecewise-constant transfers).
#[derive(Debug, Clone)]
pub struct Poisson {
    levels: Vec<Level>,
    /// No open face and so no fixed pressure: `A` is singular (constants),
    /// and the right side and the search directions are kept mean-free.
    singular: bool,
}

/// What one projection did.
#[derive(Debug, Clone, Copy, Default)]
pub struct Solve {
    pub iterations: u32,
    /// `max |r| / (h max |u|)` when it stopped: the divergence left,
    /// `max |div u| h / max |u|`.
    pub relative_divergence: f64,
    pub converged: bool,
}

/// One colour of red-black Gauss-Seidel in place, rows of cells in
/// parallel: a colour's cells read only the other colour's, which this
/// half-sweep does not write, so the values are those of the sweep into a
/// second array that a device runs (`fluid_gauss_seidel`), bit for bit,
/// without writing (or copying) the other colour's half of the cells.
fn gs_sweep(level: &mut Level, colour: u32) {
    let Level { n, stencils, x, b, .. } = level;
    let n = *n;
    let cells = crate::cpu::as_atomics(bytemuck::cast_slice_mut::<f32, u32>(x));
    let row = n.x as usize;
    (0..(n.y * n.z) as usize).into_par_iter().with_min_len(64).for_each(|r| {
        for i in r * row..(r + 1) * row {
            if ((stencils[i] & STENCIL_COLOUR) != 0) as u32 == colour {
                let v = gauss_seidel(n, stencils, b, cells, i as u32, colour);
                cells[i].store(v.to_bits(), std::sync::atomic::Ordering::Relaxed);
            }
        }
    });
}

impl Poisson {
    pub fn new(n: UVec3, walls: u32, fluid: Vec<u32>) -> Poisson {
        let singular = walls == 63;
        let mut levels = vec![Level::new(n, walls, fluid)];
        loop {
            let fine = levels.last().expect("one level");
            if fine.n.max_element() <= 4 || levels.len() >= 12 {
                break;
            }
            let coarse = coarser(fine.n);
            let count = (coarse.x * coarse.y * coarse.z) as usize;
            let mut flags = vec![0u32; count];
            let fine_n = fine.n;
            for_each_invocation(&mut flags, 0, &ProgressBar::hidden(), |i, f| {
                *f = coarse_fluid(fine_n, &fine.fluid, i)
            });
            levels.push(Level::new(coarse, walls, flags));
        }
        Poisson { levels, singular }
    }

    fn fluid(&self) -> &[u32] {
        &self.levels[0].fluid
    }

    /// Each level's cells, fluid flags and stencils (the GPU's copy of them).
    pub fn levels(&self) -> Vec<(UVec3, &[u32], &[u32])> {
        self.levels.iter().map(|l| (l.n, &l.fluid[..], &l.stencils[..])).collect()
    }

    /// Removes the mean over the fluid cells (the singular case's null space).
    fn remove_mean(&self, v: &mut [f32]) {
        if !self.singular {
            return;
        }
        let fluid = self.fluid();
        let [_, _, sum, count] = reduce(v, v, Some(fluid));
        if count <= 0.0 {
            return;
        }
        let mean = (sum / count) as f32;
        for (x, f) in v.iter_mut().zip(fluid) {
            *x = less_mean(*x, *f, mean);
        }
    }

    /// The V-cycle from level `l`: `levels[l].x` approximates
    /// `A^-1 levels[l].b`, starting from 0; symmetric (the post-smoothing
    /// sweeps the colours in the reverse order), as conjugate gradients need.
    fn v_cycle(&mut self, l: usize) {
        self.levels[l].x.fill(0.0);
        if l + 1 == self.levels.len() {
            let Level { n, stencils, x, b, .. } = &mut self.levels[l];
            coarse_solve(*n, stencils, b, x);
            return;
        }
        for _ in 0..SMOOTHING_SWEEPS {
            gs_sweep(&mut self.levels[l], 0);
            gs_sweep(&mut self.levels[l], 1);
        }
        {
            let Level { n, stencils, x, b, scratch, .. } = &mut self.levels[l];
            let n = *n;
            for_each_invocation(scratch, 0, &ProgressBar::hidden(), |i, r| {
                *r = b[i as usize] - apply_poisson(n, stencils, x, i)
            });
        }
        let (fine, coarse) = self.levels.split_at_mut(l + 1);
        let (fine, coarse) = (&fine[l], &mut coarse[0]);
        let fine_n = fine.n;
        for_each_invocation(&mut coarse.b, 0, &ProgressBar::hidden(), |i, b| *b = restrict(fine_n, &fine.scratch, i));
        self.v_cycle(l + 1);
        let (fine, coarse) = self.levels.split_at_mut(l + 1);
        let (fine, coarse) = (&mut fine[l], &coarse[0]);
        let Level { n, fluid, x, scratch, .. } = fine;
        let n = *n;
        for_each_invocation(scratch, 0, &ProgressBar::hidden(), |i, out| *out = prolong(n, fluid, x, &coarse.x, i));
        std::mem::swap(x, scratch);
        for _ in 0..SMOOTHING_SWEEPS {
            gs_sweep(&mut self.levels[l], 1);
            gs_sweep(&mut self.levels[l], 0);
        }
    }

    /// `M^-1 r`: one V-cycle.
    fn precondition(&mut self, r: &[f32]) -> Vec<f32> {
        self.levels[0].b.copy_from_slice(r);
        self.v_cycle(0);
        let mut z = self.levels[0].x.clone();
        self.remove_mean(&mut z);
        z
    }

    fn apply(&self, x: &[f32], out: &mut [f32]) {
        let (n, stencils) = (self.levels[0].n, &self.levels[0].stencils);
        for_each_invocation(out, 0, &ProgressBar::hidden(), |i, o| *o = apply_poisson(n, stencils, x, i));
    }

    /// Solves `A phi = b` from the guess in `phi`, until `max |r| <= stop`
    /// or `max_iterations`; `scale` converts `max |r|` to the reported
    /// relative divergence.
    pub fn solve(&mut self, b: &[f32], phi: &mut [f32], stop: f64, scale: f64, max_iterations: u32) -> Solve {
        let cells = b.len();
        let mut b = b.to_vec();
        self.remove_mean(&mut b);
        let mut ap = vec![0.0f32; cells];
        self.apply(phi, &mut ap);
        let mut r: Vec<f32> = b.iter().zip(&ap).map(|(b, a)| b - a).collect();
        self.remove_mean(&mut r);
        let max_abs = |v: &[f32]| reduce(v, v, None)[1];
        let dot = |a: &[f32], b: &[f32]| reduce(a, b, None)[0];
        let mut residual = max_abs(&r);
        if residual <= stop {
            return Solve { iterations: 0, relative_divergence: residual * scale, converged: true };
        }
        let mut z = self.precondition(&r);
        let mut p = z.clone();
        let mut rz = dot(&r, &z);
        for k in 1..=max_iterations {
            self.apply(&p, &mut ap);
            let pap = dot(&p, &ap);
            if pap <= 0.0 || !pap.is_finite() {
                return Solve { iterations: k, relative_divergence: residual * scale, converged: false };
            }
            let alpha = (rz / pap) as f32;
            for i in 0..cells {
                (phi[i], r[i]) = cg_update(phi[i], r[i], p[i], ap[i], alpha);
            }
            residual = max_abs(&r);
            if residual <= stop {
                return Solve { iterations: k, relative_divergence: residual * scale, converged: true };
            }
            z = self.precondition(&r);
            let rz_next = dot(&r, &z);
            let beta = (rz_next / rz) as f32;
            rz = rz_next;
            for i in 0..cells {
                p[i] = cg_direction(z[i], p[i], beta);
            }
        }
        Solve { iterations: max_iterations, relative_divergence: residual * scale, converged: false }
    }
}

/// How the quantities are advected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Advection {
    /// Stam's semi-Lagrangian step.
    SemiLagrangian,
    /// MacCormack's correction of it (second order where the field is smooth).
    #[default]
    Maccormack,
}

/// A source's cells and what it holds them at.
#[derive(Debug, Clone)]
pub struct SourceCells {
    /// Cells (flat) whose centres are inside the source's sphere.
    pub cells: Vec<u32>,
    /// Faces per velocity component inside the sphere.
    pub faces: [Vec<u32>; 3],
    pub temperature: f32,
    pub density: f32,
    pub velocity: Vec3,
}

/// A puff: a metaball carried by the flow (world metres), grown and faded
/// with its age.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Puff {
    pub position: Vec3,
    pub age: f32,
    /// Radius (m) and density at emission.
    pub radius: f32,
    pub density: f32,
}

/// How puffs are emitted, grown and faded.
#[derive(Debug, Clone)]
pub struct PuffRules {
    /// Per source: position (m), jitter radius (m), puffs per second, the
    /// puff's radius and density at emission.
    pub sources: Vec<(Vec3, f32, f32, f32, f32)>,
    /// Radius growth (m/s) and the e-folding time of the density (s).
    pub growth: f32,
    pub lifetime: f32,
}

impl PuffRules {
    /// A puff's radius and density at its age: the radius grows linearly,
    /// the density falls as the cube of the radius (the puff's smoke is
    /// conserved as it spreads) times `exp(-age / lifetime)` (it thins out).
    pub fn shape(&self, puff: &Puff) -> (f32, f32) {
        let r = puff.radius + self.growth * puff.age;
        let spread = (puff.radius / r).powi(3);
        (r, puff.density * spread * (-puff.age / self.lifetime).exp())
    }
}

/// One step's measurements.
#[derive(Debug, Clone, Copy, Default)]
pub struct StepStats {
    pub solve: Solve,
    /// Seconds in advection, in forces and diffusion, in the projection.
    pub advect_seconds: f64,
    pub forces_seconds: f64,
    pub project_seconds: f64,
    /// `max |div u| h / max |u|` measured on the projected field.
    pub divergence: f64,
    pub max_speed: f64,
}

/// The fluid's state on the staggered grid.
#[derive(Debug, Clone)]
pub struct Fluid {
    pub params: FluidParams,
    /// Box's lower corner (m).
    pub origin: Vec3,
    pub advection: Advection,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub w: Vec<f32>,
    pub temperature: Vec<f32>,
    pub smoke: Vec<f32>,
    /// `phi = p dt / rho` (m^2/s) of the last projection (the next one's guess).
    pub phi: Vec<f32>,
    pub fluid: Vec<u32>,
    pub sources: Vec<SourceCells>,
    pub puffs: Vec<Puff>,
    pub rules: PuffRules,
    /// Puffs owed by each source (the fraction carried to the next step).
    pub owed: Vec<f32>,
    /// Puffs emitted so far (each one's jitter is hashed from its number).
    pub emitted: u32,
    poisson: Poisson,
    pub tolerance: f64,
    pub max_iterations: u32,
    pub last: StepStats,
}

/// The elements of the array holding `kind` (faces: one more along its axis).
pub(crate) fn elements(p: &FluidParams, kind: u32) -> u32 {
    let e = extent(p, kind);
    e.x * e.y * e.z
}

impl Fluid {
    /// A fluid at rest at the ambient temperature, with the outside wind
    /// on every face (then projected, so the first step starts divergence-free).
    pub fn new(params: FluidParams, origin: Vec3, fluid: Vec<u32>, advection: Advection) -> Fluid {
        let p = params;
        let wind = [p.wind_x, p.wind_y, p.wind_z];
        let cells = p.cells as usize;
        let poisson = Poisson::new(p.dims(), p.walls, fluid.clone());
        let mut f = Fluid {
            params: p,
            origin,
            advection,
            u: vec![0.0; elements(&p, KIND_U) as usize],
            v: vec![0.0; elements(&p, KIND_V) as usize],
            w: vec![0.0; elements(&p, KIND_W) as usize],
            temperature: vec![p.ambient; cells],
            smoke: vec![0.0; cells],
            phi: vec![0.0; cells],
            fluid,
            sources: Vec::new(),
            puffs: Vec::new(),
            rules: PuffRules { sources: Vec::new(), growth: 0.0, lifetime: f32::INFINITY },
            owed: Vec::new(),
            emitted: 0,
            poisson,
            tolerance: 1e-6,
            max_iterations: 200,
            last: StepStats::default(),
        };
        if wind != [0.0; 3] {
            f.set_velocity(|kind, _| wind[kind as usize]);
            f.last = f.project();
        }
        f
    }

    /// Sets each velocity component from `f(kind, x)` (x in metres from
    /// the box's corner) at its faces, keeping closed faces (walls,
    /// solids) at 0.
    pub fn set_velocity(&mut self, mut f: impl FnMut(u32, Vec3) -> f32) {
        let p = self.params;
        for (q, kind) in [(&mut self.u, KIND_U), (&mut self.v, KIND_V), (&mut self.w, KIND_W)] {
            let e = extent(&p, kind);
            for (i, x) in q.iter_mut().enumerate() {
                let open = face_open(&p, kind, i as u32, &self.fluid);
                *x = if open != 0 { f(kind, position(kind, coords(e, i as u32)) * p.h) } else { 0.0 };
            }
        }
    }

    /// The velocity's arrays.
    pub fn velocity(&self) -> Velocity<'_> {
        Velocity { u: &self.u, v: &self.v, w: &self.w }
    }

    /// World metres to grid cells.
    pub fn to_cells(&self, x: Vec3) -> Vec3 {
        (x - self.origin) / self.params.h
    }

    /// Advects `q` (of `kind`) by the current velocity.
    fn advected(&self, kind: u32, q: &[f32]) -> Vec<f32> {
        let p = &self.params;
        let vel = self.velocity();
        let mut forward = vec![0.0; q.len()];
        if self.advection == Advection::SemiLagrangian {
            for_each_invocation(&mut forward, 0, &ProgressBar::hidden(), |i, o| *o = advect(p, kind, i, q, vel, 1.0));
            return forward;
        }
        // MacCormack: the forward step's departure points are kept for the
        // limiter (one trace fewer per element than tracing again); the
        // forward step samples there, as `advect` does.
        let mut from = vec![glam::Vec3::ZERO; q.len()];
        for_each_invocation(&mut from, 0, &ProgressBar::hidden(), |i, o| *o = departure(p, kind, i, vel));
        for_each_invocation(&mut forward, 0, &ProgressBar::hidden(), |i, o| *o = sample(p, kind, q, from[i as usize]));
        let mut back = vec![0.0; q.len()];
        for_each_invocation(&mut back, 0, &ProgressBar::hidden(), |i, o| *o = advect(p, kind, i, &forward, vel, -1.0));
        let mut out = vec![0.0; q.len()];
        for_each_invocation(&mut out, 0, &ProgressBar::hidden(), |i, o| {
            *o = maccormack_from(p, kind, i, q, &forward, &back, from[i as usize])
        });
        out
    }

    /// Temperature and smoke advected by the current velocity (one back-trace per cell).
    fn advected_centres(&self) -> (Vec<f32>, Vec<f32>) {
        let p = &self.params;
        let vel = self.velocity();
        let cells = p.cells as usize;
        let pass = |t: &[f32], s: &[f32], direction: f32| {
            let (mut a, mut b) = (vec![0.0; cells], vec![0.0; cells]);
            for_each_invocation2(&mut a, &mut b, 0, &ProgressBar::hidden(), |i, x, y| {
                (*x, *y) = advect_centres(p, i, t, s, vel, direction)
            });
            (a, b)
        };
        if self.advection == Advection::SemiLagrangian {
            return pass(&self.temperature, &self.smoke, 1.0);
        }
        // MacCormack, the departure points kept for the limiter.
        let mut from = vec![glam::Vec3::ZERO; cells];
        for_each_invocation(&mut from, 0, &ProgressBar::hidden(), |i, o| *o = departure(p, KIND_TEMPERATURE, i, vel));
        let (mut t_forward, mut s_forward) = (vec![0.0; cells], vec![0.0; cells]);
        for_each_invocation2(&mut t_forward, &mut s_forward, 0, &ProgressBar::hidden(), |i, x, y| {
            let b = from[i as usize];
            (*x, *y) = (sample(p, KIND_TEMPERATURE, &self.temperature, b), sample(p, KIND_SMOKE, &self.smoke, b))
        });
        let (t_back, s_back) = pass(&t_forward, &s_forward, -1.0);
        let t = Stages { q: &self.temperature, forward: &t_forward, back: &t_back };
        let s = Stages { q: &self.smoke, forward: &s_forward, back: &s_back };
        let (mut a, mut b) = (vec![0.0; cells], vec![0.0; cells]);
        for_each_invocation2(&mut a, &mut b, 0, &ProgressBar::hidden(), |i, x, y| {
            (*x, *y) = maccormack_centres_from(p, i, t, s, from[i as usize])
        });
        (a, b)
    }

    /// Backward-Euler diffusion of `q` with weight `kappa dt / h^2`.
    fn diffused(&self, kind: u32, b: Vec<f32>, weight: f32, iterations: u32) -> Vec<f32> {
        let (p, fluid) = (&self.params, &self.fluid);
        let mut x = b.clone();
        let mut next = vec![0.0; b.len()];
        for _ in 0..iterations {
            for_each_invocation(&mut next, 0, &ProgressBar::hidden(), |i, o| {
                *o = diffuse(p, kind, i, &b, &x, weight, fluid)
            });
            std::mem::swap(&mut x, &mut next);
        }
        x
    }

    /// Makes the velocity divergence-free (the pressure term of eq. 4).
    pub fn project(&mut self) -> StepStats {
        let p = self.params;
        let cells = p.cells as usize;
        let mut rhs = vec![0.0f32; cells];
        let (vel, fluid) = (self.velocity(), &self.fluid);
        // A phi = -h D (D = div u h, m/s); the residual r leaves D = -r / h.
        for_each_invocation(&mut rhs, 0, &ProgressBar::hidden(), |i, b| *b = -p.h * divergence(&p, i, vel, fluid));
        let speed = self.max_speed().max(1e-30);
        let stop = self.tolerance * p.h as f64 * speed;
        let solve = self.poisson.solve(&rhs, &mut self.phi, stop, 1.0 / (p.h as f64 * speed), self.max_iterations);
        let phi = &self.phi;
        for (q, kind) in [(&mut self.u, KIND_U), (&mut self.v, KIND_V), (&mut self.w, KIND_W)] {
            // In place: each face reads only its own value and phi.
            for_each_invocation(q, 0, &ProgressBar::hidden(), |i, o| *o = project_face(&p, kind, i, *o, phi, fluid));
        }
        StepStats {
            solve,
            divergence: self.max_divergence() / self.max_speed().max(1e-30),
            max_speed: self.max_speed(),
            ..Default::default()
        }
    }

    /// `max |div u| h` over the fluid cells (m/s).
    pub fn max_divergence(&self) -> f64 {
        let p = self.params;
        let mut d = vec![0.0f32; p.cells as usize];
        for_each_invocation(&mut d, 0, &ProgressBar::hidden(), |i, o| {
            *o = divergence(&p, i, self.velocity(), &self.fluid)
        });
        d.iter().fold(0.0f64, |m, x| m.max(x.abs() as f64))
    }

    /// The largest face velocity (m/s).
    pub fn max_speed(&self) -> f64 {
        [&self.u, &self.v, &self.w].iter().flat_map(|q| q.iter()).fold(0.0f64, |m, x| m.max(x.abs() as f64))
    }

    /// One step of `dt`: advection, sources, forces, diffusion, projection,
    /// then the puffs.
    pub fn step(&mut self) {
        let clock = std::time::Instant::now();
        let kinds = [KIND_U, KIND_V, KIND_W];
        let advected: Vec<Vec<f32>> =
            kinds.iter().zip([&self.u, &self.v, &self.w]).map(|(&k, q)| self.advected(k, q)).collect();
        let [u, v, w]: [Vec<f32>; 3] = advected.try_into().expect("three components");
        let (t, s) = self.advected_centres();
        let p = self.params;
        let advect_seconds = clock.elapsed().as_secs_f64();
        // Forces (buoyancy from the advected temperature), in place: each
        // face reads only its own value.
        let mut fields = [u, v, w];
        for (kind, q) in fields.iter_mut().enumerate() {
            let temperature = &t;
            for_each_invocation(q, 0, &ProgressBar::hidden(), |i, o| {
                *o = force_face(&p, kind as u32, i, *o, temperature)
            });
        }
        let [u, v, w] = fields;
        self.u = self.diffused(KIND_U, u, p.viscous_weight, p.viscous_iterations);
        self.v = self.diffused(KIND_V, v, p.viscous_weight, p.viscous_iterations);
        self.w = self.diffused(KIND_W, w, p.viscous_weight, p.viscous_iterations);
        let mut t = t;
        if p.temperature_noise != 0.0 && p.eddy_diffusivity != 0.0 {
            for (i, x) in t.iter_mut().enumerate() {
                *x += temperature_eddy(&p, i as u32);
            }
        }
        self.temperature = self.diffused(KIND_TEMPERATURE, t, p.thermal_weight, p.thermal_iterations);
        self.smoke = s;
        self.apply_sources();
        for i in 0..p.cells as usize {
            if self.fluid[i] == 0 {
                self.temperature[i] = p.ambient;
                self.smoke[i] = 0.0;
            }
        }
        let forces_seconds = clock.elapsed().as_secs_f64() - advect_seconds;
        self.last = self.project();
        self.last.advect_seconds = advect_seconds;
        self.last.forces_seconds = forces_seconds;
        self.last.project_seconds = clock.elapsed().as_secs_f64() - advect_seconds - forces_seconds;
        let p = self.params;
        let vel = Velocity { u: &self.u, v: &self.v, w: &self.w };
        let traced = self.puffs.iter().map(|puff| trace(&p, vel, self.to_cells(puff.position), -1.0)).collect();
        self.finish_step(traced);
    }

    /// The multigrid levels of the pressure solver (cells, fluid flags, stencils).
    pub fn solver_levels(&self) -> Vec<(UVec3, &[u32], &[u32])> {
        self.poisson.levels()
    }

    /// Whether the pressure equation is singular (a closed box).
    pub fn solver_singular(&self) -> bool {
        self.poisson.singular
    }

    /// What the sources hold fixed each step, per array (u, v, w,
    /// temperature, smoke): `(element, value)`, each element once, the
    /// last source's value where sources overlap. Both backends hold these
    /// (`apply_sources`, the GPU's `fluid_hold`).
    pub fn held_values(&self) -> [Vec<(u32, f32)>; 5] {
        let mut maps: [std::collections::BTreeMap<u32, f32>; 5] = Default::default();
        for s in &self.sources {
            for &c in &s.cells {
                if self.fluid[c as usize] != 0 {
                    maps[3].insert(c, s.temperature);
                    maps[4].insert(c, s.density);
                }
            }
            for (k, (faces, speed)) in s.faces.iter().zip(s.velocity.to_array()).enumerate() {
                for &f in faces {
                    maps[k].insert(f, speed);
                }
            }
        }
        maps.map(|m| m.into_iter().collect())
    }

    /// Ends a step: the puffs moved to `traced` (cells, one per puff, the
    /// projected field's RK2 trace), aged, thinned and emitted; the step counted.
    pub fn finish_step(&mut self, traced: Vec<Vec3>) {
        self.move_puffs(traced);
        self.params.step += 1;
    }

    /// Holds each source's cells at its temperature and density and its
    /// faces at its velocity.
    fn apply_sources(&mut self) {
        let held = self.held_values();
        let arrays = [&mut self.u, &mut self.v, &mut self.w, &mut self.temperature, &mut self.smoke];
        for (q, list) in arrays.into_iter().zip(held) {
            for (i, value) in list {
                q[i as usize] = value;
            }
        }
    }

    /// Moves the puffs to `traced` (their RK2 trace `dt` on through the
    /// projected field), ages them, drops those that left the box or
    /// faded, and emits new ones.
    fn move_puffs(&mut self, traced: Vec<Vec3>) {
        let p = self.params;
        let n = p.dims().as_vec3();
        let origin = self.origin;
        let rules = &self.rules;
        let mut traced = traced.into_iter();
        self.puffs.retain_mut(|puff| {
            let next = traced.next().expect("one traced position per puff");
            puff.position = origin + next * p.h;
            puff.age += p.dt;
            let inside = next.cmpge(Vec3::ZERO).all() && next.cmple(n).all();
            inside && rules.shape(puff).1 > 1e-4 * puff.density
        });
        for (k, &(centre, jitter, rate, radius, density)) in self.rules.sources.iter().enumerate() {
            self.owed[k] += rate * p.dt;
            while self.owed[k] >= 1.0 {
                self.owed[k] -= 1.0;
                let e = self.emitted;
                let offset = Vec3::new(
                    uniform(e, p.seed, 0) * 2.0 - 1.0,
                    uniform(e, p.seed, 1) * 2.0 - 1.0,
                    uniform(e, p.seed, 2) * 2.0 - 1.0,
                ) * jitter;
                self.puffs.push(Puff { position: centre + offset, age: 0.0, radius, density });
                self.emitted += 1;
            }
        }
    }

    /// Total smoke (density times cell volume, m^3).
    pub fn total_smoke(&self) -> f64 {
        let v = (self.params.h as f64).powi(3);
        self.smoke.iter().map(|&s| s as f64).sum::<f64>() * v
    }

    /// Kinetic energy per unit density (m^5/s^2): half the sum of the
    /// squared face velocities times the cell volume.
    pub fn kinetic_energy(&self) -> f64 {
        let v = (self.params.h as f64).powi(3);
        0.5 * v * [&self.u, &self.v, &self.w].iter().flat_map(|q| q.iter()).map(|&x| x as f64 * x as f64).sum::<f64>()
    }
}

/// A uniform number in [0, 1) for puff `e` and axis `axis`.
fn uniform(e: u32, seed: u32, axis: u32) -> f32 {
    (random(e, 0, seed, 0x9f0 + axis) >> 8) as f32 / 16_777_216.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One colour of Gauss-Seidel into a second array, as a device sweeps
    /// the finer levels (`fluid_gauss_seidel`): the reference of the
    /// in-place sweeps.
    fn ping_pong_sweep(level: &mut Level, colour: u32) {
        let Level { n, stencils, x, b, scratch, .. } = level;
        let n = *n;
        for_each_invocation(scratch, 0, &ProgressBar::hidden(), |i, out| {
            *out = gauss_seidel(n, stencils, b, x.as_slice(), i, colour)
        });
        std::mem::swap(x, scratch);
    }

    /// A level of `n` cells with `walls`, every `solid_every`-th cell solid
    /// and a right-hand side of mixed signs.
    fn test_level(n: UVec3, walls: u32, solid_every: u32) -> Level {
        let cells = (n.x * n.y * n.z) as usize;
        let fluid: Vec<u32> = (0..cells as u32).map(|i| (i % solid_every != solid_every / 2) as u32).collect();
        let mut level = Level::new(n, walls, fluid);
        level.b = (0..cells).map(|i| ((i * 37 % 11) as f32 - 5.0) * 0.3).collect();
        level
    }

    /// The CPU's sweeps in place (`gs_sweep`: rows in parallel, each colour
    /// reading the other while it is not written) give the same bits as the
    /// sweeps into a second array, over a V-cycle's worth of half-sweeps on
    /// grids with solid cells, walls and open faces, one a single cell
    /// thick. Updating the other colour too (a data race of the kind the
    /// colours rule out) makes it fail.
    #[test]
    fn the_in_place_sweeps_equal_the_ping_pong_sweeps() {
        for (n, walls) in [(UVec3::new(33, 17, 20), 63), (UVec3::new(16, 1, 9), 5), (UVec3::new(24, 30, 7), 0)] {
            let mut level = test_level(n, walls, 13);
            let mut reference = level.clone();
            for colour in [0, 1, 0, 1, 1, 0, 1, 0] {
                gs_sweep(&mut level, colour);
                ping_pong_sweep(&mut reference, colour);
            }
            assert_eq!(level.x, reference.x, "{n}");
            assert!(level.x.iter().any(|v| *v != 0.0));
        }
    }

    /// The coarse solve in place (`coarse_solve`, as the CPU runs it; and
    /// split among lanes visited in reverse, as a workgroup may interleave
    /// them) gives the same bits as the half-sweeps into a second array.
    #[test]
    fn the_in_place_coarse_solve_equals_the_ping_pong_sweeps() {
        for (n, walls) in [(UVec3::new(4, 4, 4), 63), (UVec3::new(3, 2, 4), 5), (UVec3::new(4, 1, 3), 0)] {
            let cells = (n.x * n.y * n.z) as usize;
            let mut level = test_level(n, walls, 7);
            for _ in 0..COARSE_SWEEPS {
                ping_pong_sweep(&mut level, 0);
                ping_pong_sweep(&mut level, 1);
            }
            for _ in 0..COARSE_SWEEPS {
                ping_pong_sweep(&mut level, 1);
                ping_pong_sweep(&mut level, 0);
            }
            let mut x = vec![0.0; cells];
            coarse_solve(n, &level.stencils, &level.b, &mut x);
            assert_eq!(x, level.x, "{n}");
            let mut split = vec![0.0; cells];
            for k in 0..COARSE_HALF_SWEEPS {
                for lane in (0..7).rev() {
                    gauss_seidel_in_place(n, &level.stencils, &level.b, &mut split, lane, 7, coarse_colour(k));
                }
            }
            assert_eq!(split, level.x, "{n}, 7 lanes");
            assert!(level.x.iter().any(|v| *v != 0.0));
        }
    }
}
