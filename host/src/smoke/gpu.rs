//! The fluid's step on the GPU: the sequence of `fluid.rs`, each stage one
//! dispatch of a kernel (`shader-crate/src/smoke/kernels.rs`) whose
//! per-element function the CPU backend calls too. The conjugate
//! gradients' scalars are computed on the host, in f64, from the kernels'
//! partial sums (`partial`, the same groups and order as the CPU's), so the
//! two backends take the same decisions from the same numbers.

use anyhow::Result;
use glam::{UVec3, Vec3, Vec4};
use slicelight_shaders::smoke::*;
use std::time::Instant;

use super::fluid::{elements, sum_partials, Advection, Fluid, Solve, StepStats, SMOOTHING_SWEEPS};
use crate::gpu::{Batch, GpuContext, Kernel};

// The kernels' bindings (`shader-crate/src/smoke/kernels.rs`).
const P: u32 = 100;
const A: u32 = 101;
const B: u32 = 102;
const C: u32 = 103;
const D: u32 = 104;
const E: u32 = 105;
const F: u32 = 106;
const U: u32 = 107;
const V: u32 = 108;
const W: u32 = 109;
const FLAGS: u32 = 110;
const POINTS: u32 = 111;
const OUT: u32 = 112;
const OUT2: u32 = 113;
const POINTS_OUT: u32 = 114;
const PARTIALS: u32 = 115;
const INDICES: u32 = 116;
const VALUES: u32 = 117;

macro_rules! kernels {
    ($($id:ident = $name:literal reads [$($r:ident),*] writes [$($w:ident),*];)*) => {
        $(static $id: Kernel = Kernel { name: $name, reads: &[$($r),*], writes: &[$($w),*] };)*
        /// The fluid's kernels, registered with the smoke family.
        pub static KERNELS: &[&Kernel] = &[$(&$id),*];
    };
}

kernels! {
    DEPARTURE = "smoke::kernels::fluid_departure" reads [P, U, V, W] writes [POINTS_OUT];
    TRACE = "smoke::kernels::fluid_trace" reads [P, U, V, W, POINTS] writes [POINTS_OUT];
    SAMPLE = "smoke::kernels::fluid_sample" reads [P, A, POINTS] writes [OUT];
    ADVECT = "smoke::kernels::fluid_advect" reads [P, A, U, V, W] writes [OUT];
    MACCORMACK = "smoke::kernels::fluid_maccormack" reads [P, A, B, C, POINTS] writes [OUT];
    ADVECT_CENTRES = "smoke::kernels::fluid_advect_centres" reads [P, A, B, U, V, W] writes [OUT, OUT2];
    SAMPLE_CENTRES = "smoke::kernels::fluid_sample_centres" reads [P, A, B, POINTS] writes [OUT, OUT2];
    MACCORMACK_CENTRES = "smoke::kernels::fluid_maccormack_centres" reads [P, A, B, C, D, E, F, POINTS] writes [OUT, OUT2];
    FORCE = "smoke::kernels::fluid_force" reads [P, A] writes [OUT];
    DIFFUSE = "smoke::kernels::fluid_diffuse" reads [P, A, B, FLAGS] writes [OUT];
    EDDY = "smoke::kernels::fluid_eddy" reads [P] writes [OUT];
    HOLD = "smoke::kernels::fluid_hold" reads [P, INDICES, VALUES] writes [OUT];
    SOLIDS = "smoke::kernels::fluid_solids" reads [P, FLAGS] writes [OUT, OUT2];
    DIVERGENCE = "smoke::kernels::fluid_divergence" reads [P, U, V, W, FLAGS] writes [OUT];
    APPLY = "smoke::kernels::fluid_apply" reads [P, A, FLAGS] writes [OUT];
    RESIDUAL = "smoke::kernels::fluid_residual" reads [P, A, B, FLAGS] writes [OUT];
    GAUSS_SEIDEL = "smoke::kernels::fluid_gauss_seidel" reads [P, A, B, FLAGS] writes [OUT];
    COARSE_SOLVE = "smoke::kernels::fluid_coarse_solve" reads [P, A, FLAGS] writes [OUT];
    RESTRICT = "smoke::kernels::fluid_restrict" reads [P, A] writes [OUT];
    PROLONG = "smoke::kernels::fluid_prolong" reads [P, A, B, FLAGS] writes [OUT];
    PROJECT = "smoke::kernels::fluid_project" reads [P, A, FLAGS] writes [OUT];
    CG_UPDATE = "smoke::kernels::fluid_cg_update" reads [P, A, B] writes [OUT, OUT2];
    CG_DIRECTION = "smoke::kernels::fluid_cg_direction" reads [P, A] writes [OUT];
    LESS_MEAN = "smoke::kernels::fluid_less_mean" reads [P, FLAGS] writes [OUT];
    PARTIALS_KERNEL = "smoke::kernels::fluid_partials" reads [P, A, B, FLAGS] writes [PARTIALS];
}

type Buf = wgpu::Buffer;

/// One multigrid level's arrays on the device.
struct Level {
    n: UVec3,
    cells: u32,
    fluid: Buf,
    stencils: Buf,
    x: Buf,
    b: Buf,
    scratch: Buf,
}

/// Values a step holds fixed (the sources), for one array.
struct Hold {
    indices: Buf,
    values: Buf,
    count: u32,
}

/// A fluid's arrays on the device (`new` uploads a `Fluid`'s state,
/// `download` reads it back; `step` advances both).
pub struct GpuFluid<'a> {
    ctx: &'a GpuContext,
    /// The velocity, temperature and smoke (`KINDS`' order), and where a
    /// step's advection writes them.
    q: [Buf; 5],
    next: [Buf; 5],
    phi: Buf,
    /// Departure points and four work arrays, each as long as the longest array.
    from: Buf,
    work: [Buf; 4],
    levels: Vec<Level>,
    singular: bool,
    r: Buf,
    z: Buf,
    p: Buf,
    ap: Buf,
    rhs: Buf,
    partials: Buf,
    /// Per array (u, v, w, temperature, smoke), the source values held.
    holds: [Option<Hold>; 5],
    /// The puffs' positions and their traces (grown as puffs are emitted).
    points: Buf,
    points_out: Buf,
}

const KINDS: [u32; 5] = [KIND_U, KIND_V, KIND_W, KIND_TEMPERATURE, KIND_SMOKE];

fn f32s(v: &[f32]) -> &[u8] {
    bytemuck::cast_slice(v)
}

impl<'a> GpuFluid<'a> {
    /// Uploads `f`'s state and its solver's levels.
    pub fn new(ctx: &'a GpuContext, f: &Fluid) -> Result<GpuFluid<'a>> {
        let p = &f.params;
        let cells = p.cells;
        let longest = KINDS.iter().map(|k| elements(p, *k)).max().unwrap_or(1);
        let fields = [&f.u, &f.v, &f.w, &f.temperature, &f.smoke];
        let mut q = Vec::new();
        let mut next = Vec::new();
        for (k, field) in fields.iter().enumerate() {
            q.push(ctx.array(&format!("fluid field {k}"), f32s(field))?);
            next.push(ctx.zeroed("fluid field, advected", field.len() as u64 * 4)?);
        }
        let zeroed = |label: &str, n: u32| ctx.zeroed(label, n as u64 * 4);
        let levels = f
            .solver_levels()
            .into_iter()
            .map(|(n, fluid, stencils)| {
                let c = n.x * n.y * n.z;
                Ok(Level {
                    n,
                    cells: c,
                    fluid: ctx.array("multigrid fluid cells", bytemuck::cast_slice(fluid))?,
                    stencils: ctx.array("multigrid stencils", bytemuck::cast_slice(stencils))?,
                    x: zeroed("multigrid x", c)?,
                    b: zeroed("multigrid b", c)?,
                    scratch: zeroed("multigrid scratch", c)?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let mut holds: [Option<Hold>; 5] = Default::default();
        for (k, list) in f.held_values().into_iter().enumerate() {
            if list.is_empty() {
                continue;
            }
            let (indices, values): (Vec<u32>, Vec<f32>) = list.into_iter().unzip();
            holds[k] = Some(Hold {
                indices: ctx.array("source cells", bytemuck::cast_slice(&indices))?,
                values: ctx.array("source values", f32s(&values))?,
                count: indices.len() as u32,
            });
        }
        let groups = 4 * partial_groups(longest);
        Ok(GpuFluid {
            ctx,
            q: q.try_into().map_err(|_| anyhow::anyhow!("five fields"))?,
            next: next.try_into().map_err(|_| anyhow::anyhow!("five fields"))?,
            phi: ctx.array("fluid phi", f32s(&f.phi))?,
            from: ctx.zeroed("departure points", longest as u64 * 16)?,
            work: [
                zeroed("fluid work 0", longest)?,
                zeroed("fluid work 1", longest)?,
                zeroed("fluid work 2", longest)?,
                zeroed("fluid work 3", longest)?,
            ],
            levels,
            singular: f.solver_singular(),
            r: zeroed("cg r", cells)?,
            z: zeroed("cg z", cells)?,
            p: zeroed("cg p", cells)?,
            ap: zeroed("cg Ap", cells)?,
            rhs: zeroed("cg b", cells)?,
            partials: ctx.zeroed("partial sums", groups as u64 * 16)?,
            holds,
            points: ctx.zeroed("puffs", 16)?,
            points_out: ctx.zeroed("puffs traced", 16)?,
        })
    }

    /// The fluid cells' flags (the finest multigrid level's).
    fn fluid(&self) -> &Buf {
        &self.levels[0].fluid
    }

    /// A dispatch over the cells of multigrid level `l`.
    fn on_level(&self, p: &FluidParams, l: usize) -> FluidDispatch {
        let lv = &self.levels[l];
        FluidDispatch { nx: lv.n.x, ny: lv.n.y, nz: lv.n.z, ..at(p, 0, lv.cells) }
    }

    /// Reads the fields back into `f`.
    pub fn download(&self, f: &mut Fluid) -> Result<()> {
        for (k, field) in [&mut f.u, &mut f.v, &mut f.w, &mut f.temperature, &mut f.smoke].into_iter().enumerate() {
            let bytes = self.ctx.download(&self.q[k], field.len() as u64 * 4)?;
            field.copy_from_slice(bytemuck::cast_slice(&bytes));
        }
        let bytes = self.ctx.download(&self.phi, f.phi.len() as u64 * 4)?;
        f.phi.copy_from_slice(bytemuck::cast_slice(&bytes));
        Ok(())
    }

    /// One step of `dt` as `Fluid::step` takes it; `f`'s puffs, step and
    /// measurements follow (its fields stay as they were until `download`).
    pub fn step(&mut self, f: &mut Fluid) -> Result<()> {
        let clock = Instant::now();
        let p = f.params;
        let mut batch = self.ctx.batch();
        for k in 0..3 {
            self.advect(&mut batch, &p, f.advection, k);
        }
        self.advect_centres(&mut batch, &p, f.advection);
        batch.submit()?;
        let advect_seconds = clock.elapsed().as_secs_f64();

        let mut batch = self.ctx.batch();
        for (k, &kind) in KINDS[..3].iter().enumerate() {
            let count = elements(&p, kind);
            batch.dispatch(&FORCE, P, &at(&p, kind, count), &[(A, &self.next[3]), (OUT, &self.next[k])], count);
        }
        for k in 0..3 {
            self.diffuse(&mut batch, &p, k, p.viscous_weight, p.viscous_iterations);
        }
        if p.temperature_noise != 0.0 && p.eddy_diffusivity != 0.0 {
            batch.dispatch(&EDDY, P, &at(&p, KIND_TEMPERATURE, p.cells), &[(OUT, &self.next[3])], p.cells);
        }
        self.diffuse(&mut batch, &p, 3, p.thermal_weight, p.thermal_iterations);
        batch.copy(&self.next[4], &self.q[4], p.cells as u64 * 4);
        // The sources: temperature and smoke, then the velocity's faces.
        for k in [3, 4, 0, 1, 2] {
            if let Some(h) = &self.holds[k] {
                batch.dispatch(
                    &HOLD,
                    P,
                    &at(&p, KINDS[k], h.count),
                    &[(INDICES, &h.indices), (VALUES, &h.values), (OUT, &self.q[k])],
                    h.count,
                );
            }
        }
        batch.dispatch(
            &SOLIDS,
            P,
            &at(&p, KIND_TEMPERATURE, p.cells),
            &[(FLAGS, self.fluid()), (OUT, &self.q[3]), (OUT2, &self.q[4])],
            p.cells,
        );
        batch.submit()?;
        let forces_seconds = clock.elapsed().as_secs_f64() - advect_seconds;

        let mut stats = self.project(f)?;
        stats.advect_seconds = advect_seconds;
        stats.forces_seconds = forces_seconds;
        stats.project_seconds = clock.elapsed().as_secs_f64() - advect_seconds - forces_seconds;
        f.last = stats;
        let traced = self.trace_puffs(f)?;
        f.finish_step(traced);
        Ok(())
    }

    /// The velocity's bindings and `extra`.
    fn with_velocity<'b>(&'b self, extra: &[(u32, &'b Buf)]) -> Vec<(u32, &'b Buf)> {
        [(U, &self.q[0]), (V, &self.q[1]), (W, &self.q[2])].into_iter().chain(extra.iter().copied()).collect()
    }

    /// Component `k`'s advection into `next[k]` (MacCormack or semi-Lagrangian).
    fn advect(&self, batch: &mut Batch, p: &FluidParams, advection: Advection, k: usize) {
        let kind = KINDS[k];
        let count = elements(p, kind);
        let d = at(p, kind, count);
        if advection == Advection::SemiLagrangian {
            batch.dispatch(&ADVECT, P, &d, &self.with_velocity(&[(A, &self.q[k]), (OUT, &self.next[k])]), count);
            return;
        }
        let [forward, back, ..] = &self.work;
        batch.dispatch(&DEPARTURE, P, &d, &self.with_velocity(&[(POINTS_OUT, &self.from)]), count);
        batch.dispatch(&SAMPLE, P, &d, &[(A, &self.q[k]), (POINTS, &self.from), (OUT, forward)], count);
        let reverse = FluidDispatch { direction: -1.0, ..d };
        batch.dispatch(&ADVECT, P, &reverse, &self.with_velocity(&[(A, forward), (OUT, back)]), count);
        batch.dispatch(
            &MACCORMACK,
            P,
            &d,
            &[(A, &self.q[k]), (B, forward), (C, back), (POINTS, &self.from), (OUT, &self.next[k])],
            count,
        );
    }

    /// Temperature and smoke, which share their back-trace, into `next[3]` and `next[4]`.
    fn advect_centres(&self, batch: &mut Batch, p: &FluidParams, advection: Advection) {
        let count = p.cells;
        let d = at(p, KIND_TEMPERATURE, count);
        let (t, s) = (&self.q[3], &self.q[4]);
        let outs = [(OUT, &self.next[3]), (OUT2, &self.next[4])];
        if advection == Advection::SemiLagrangian {
            batch.dispatch(&ADVECT_CENTRES, P, &d, &self.with_velocity(&[(A, t), (B, s), outs[0], outs[1]]), count);
            return;
        }
        let [tf, sf, tb, sb] = &self.work;
        batch.dispatch(&DEPARTURE, P, &d, &self.with_velocity(&[(POINTS_OUT, &self.from)]), count);
        batch.dispatch(&SAMPLE_CENTRES, P, &d, &[(A, t), (B, s), (POINTS, &self.from), (OUT, tf), (OUT2, sf)], count);
        let reverse = FluidDispatch { direction: -1.0, ..d };
        batch.dispatch(
            &ADVECT_CENTRES,
            P,
            &reverse,
            &self.with_velocity(&[(A, tf), (B, sf), (OUT, tb), (OUT2, sb)]),
            count,
        );
        batch.dispatch(
            &MACCORMACK_CENTRES,
            P,
            &d,
            &[(A, t), (B, s), (C, tf), (D, sf), (E, tb), (F, sb), (POINTS, &self.from), outs[0], outs[1]],
            count,
        );
    }

    /// Backward-Euler diffusion of `next[k]` by `iterations` Jacobi
    /// iterations, into `q[k]` (as `Fluid::diffused`: `x` starts at `b`).
    fn diffuse(&self, batch: &mut Batch, p: &FluidParams, k: usize, weight: f32, iterations: u32) {
        let kind = KINDS[k];
        let count = elements(p, kind);
        let bytes = count as u64 * 4;
        let (mut x, mut next) = (&self.q[k], &self.work[0]);
        batch.copy(&self.next[k], x, bytes);
        let d = FluidDispatch { scalar: weight, ..at(p, kind, count) };
        for _ in 0..iterations {
            batch.dispatch(&DIFFUSE, P, &d, &[(A, &self.next[k]), (B, x), (FLAGS, self.fluid()), (OUT, next)], count);
            std::mem::swap(&mut x, &mut next);
        }
        if !std::ptr::eq(x, &self.q[k]) {
            batch.copy(x, &self.q[k], bytes);
        }
    }

    /// Partial sums of `(a, b)` over `count` elements into the partials
    /// from `offset` on; returns the offset after them.
    fn partials(&self, batch: &mut Batch, a: &Buf, b: &Buf, count: u32, fluid: bool, offset: u32) -> u32 {
        // The kernel reads only the count, the flags' switch and the offset.
        let d = FluidDispatch { colour: fluid as u32, nx: offset, count, ..Default::default() };
        let groups = partial_groups(count);
        batch.dispatch(
            &PARTIALS_KERNEL,
            P,
            &d,
            &[(A, a), (B, b), (FLAGS, self.fluid()), (PARTIALS, &self.partials)],
            groups,
        );
        offset + groups
    }

    /// Submits `batch` and sums the partials of each range in `ranges`.
    fn reduce(&self, batch: Batch, ranges: &[std::ops::Range<u32>]) -> Result<Vec<[f64; 4]>> {
        let end = ranges.iter().map(|r| r.end).max().unwrap_or(0);
        let bytes = batch.submit_reading(&self.partials, end as u64 * 16)?;
        let all: &[Vec4] = bytemuck::cast_slice(&bytes);
        Ok(ranges.iter().map(|r| sum_partials(&all[r.start as usize..r.end as usize])).collect())
    }

    /// `reduce` of the partials `0..end`.
    fn reduce_one(&self, batch: Batch, end: u32) -> Result<[f64; 4]> {
        Ok(self.reduce(batch, std::slice::from_ref(&(0..end)))?[0])
    }

    /// The largest face velocity (m/s), recorded after what `batch` holds,
    /// and the largest `|a|` of the partials `before` that `batch` wrote.
    fn max_speed(&self, mut batch: Batch, p: &FluidParams, before: std::ops::Range<u32>) -> Result<(f64, f64)> {
        let mut ranges = vec![before.clone()];
        let mut offset = before.end;
        for (k, &kind) in KINDS[..3].iter().enumerate() {
            let count = elements(p, kind);
            let end = self.partials(&mut batch, &self.q[k], &self.q[k], count, false, offset);
            ranges.push(offset..end);
            offset = end;
        }
        let sums = self.reduce(batch, &ranges)?;
        Ok((sums[0][1], sums[1..].iter().fold(0.0f64, |m, s| m.max(s[1]))))
    }

    /// `Fluid::project` on the device.
    fn project(&mut self, f: &Fluid) -> Result<StepStats> {
        let p = f.params;
        let mut batch = self.ctx.batch();
        let d = FluidDispatch { scalar: -p.h, ..at(&p, KIND_TEMPERATURE, p.cells) };
        batch.dispatch(&DIVERGENCE, P, &d, &self.with_velocity(&[(FLAGS, self.fluid()), (OUT, &self.rhs)]), p.cells);
        let speed = self.max_speed(batch, &p, 0..0)?.1.max(1e-30);
        let stop = f.tolerance * p.h as f64 * speed;
        let solve = self.solve(&p, stop, 1.0 / (p.h as f64 * speed), f.max_iterations)?;
        let mut batch = self.ctx.batch();
        for (k, &kind) in KINDS[..3].iter().enumerate() {
            let count = elements(&p, kind);
            batch.dispatch(
                &PROJECT,
                P,
                &at(&p, kind, count),
                &[(A, &self.phi), (FLAGS, self.fluid()), (OUT, &self.q[k])],
                count,
            );
        }
        let d = FluidDispatch { scalar: 1.0, ..at(&p, KIND_TEMPERATURE, p.cells) };
        batch.dispatch(
            &DIVERGENCE,
            P,
            &d,
            &self.with_velocity(&[(FLAGS, self.fluid()), (OUT, &self.work[0])]),
            p.cells,
        );
        let end = self.partials(&mut batch, &self.work[0], &self.work[0], p.cells, false, 0);
        let (divergence, max_speed) = self.max_speed(batch, &p, 0..end)?;
        Ok(StepStats { solve, divergence: divergence / max_speed.max(1e-30), max_speed, ..Default::default() })
    }

    /// Removes the mean over the fluid cells from `v` (the singular case:
    /// `batch` runs, the mean is read, and the returned batch subtracts
    /// it); otherwise `batch` unchanged.
    fn remove_mean(&self, batch: Batch<'a>, p: &FluidParams, v: &Buf) -> Result<Batch<'a>> {
        if !self.singular {
            return Ok(batch);
        }
        let mut batch = batch;
        let end = self.partials(&mut batch, v, v, p.cells, true, 0);
        let s = self.reduce_one(batch, end)?;
        let mut next = self.ctx.batch();
        if s[3] > 0.0 {
            let d = FluidDispatch { scalar: (s[2] / s[3]) as f32, ..at(p, 0, p.cells) };
            next.dispatch(&LESS_MEAN, P, &d, &[(FLAGS, self.fluid()), (OUT, v)], p.cells);
        }
        Ok(next)
    }

    /// `Poisson::solve` on the device: `phi` from `rhs`. Two readbacks an
    /// iteration: `p . Ap` for `alpha`, then `max |r|` and `r . z` together
    /// (the preconditioner runs before the stop is known, one V-cycle more
    /// on the last iteration than the CPU, whose results it does not change).
    fn solve(&self, p: &FluidParams, stop: f64, scale: f64, max_iterations: u32) -> Result<Solve> {
        let cells = p.cells;
        let l0 = &self.levels[0];
        let d = at(p, 0, cells);
        let level = self.on_level(p, 0);
        let mut batch = self.remove_mean(self.ctx.batch(), p, &self.rhs)?;
        batch.dispatch(
            &RESIDUAL,
            P,
            &level,
            &[(A, &self.rhs), (B, &self.phi), (FLAGS, &l0.stencils), (OUT, &self.r)],
            cells,
        );
        let batch = self.remove_mean(batch, p, &self.r)?;
        let mut batch = self.precondition(batch, p)?;
        let end = self.partials(&mut batch, &self.r, &self.z, cells, false, 0);
        let [mut rz, mut residual, ..] = self.reduce_one(batch, end)?;
        if residual <= stop {
            return Ok(Solve { iterations: 0, relative_divergence: residual * scale, converged: true });
        }
        let mut batch = self.ctx.batch();
        batch.copy(&self.z, &self.p, cells as u64 * 4);
        for k in 1..=max_iterations {
            batch.dispatch(&APPLY, P, &level, &[(A, &self.p), (FLAGS, &l0.stencils), (OUT, &self.ap)], cells);
            let end = self.partials(&mut batch, &self.p, &self.ap, cells, false, 0);
            let pap = self.reduce_one(batch, end)?[0];
            if pap <= 0.0 || !pap.is_finite() {
                return Ok(Solve { iterations: k, relative_divergence: residual * scale, converged: false });
            }
            let alpha = (rz / pap) as f32;
            let mut update = self.ctx.batch();
            update.dispatch(
                &CG_UPDATE,
                P,
                &FluidDispatch { scalar: alpha, ..d },
                &[(A, &self.p), (B, &self.ap), (OUT, &self.phi), (OUT2, &self.r)],
                cells,
            );
            let mut update = self.precondition(update, p)?;
            let end = self.partials(&mut update, &self.r, &self.z, cells, false, 0);
            let [rz_next, r_max, ..] = self.reduce_one(update, end)?;
            residual = r_max;
            if residual <= stop {
                return Ok(Solve { iterations: k, relative_divergence: residual * scale, converged: true });
            }
            let beta = (rz_next / rz) as f32;
            rz = rz_next;
            batch = self.ctx.batch();
            batch.dispatch(
                &CG_DIRECTION,
                P,
                &FluidDispatch { scalar: beta, ..d },
                &[(A, &self.z), (OUT, &self.p)],
                cells,
            );
        }
        Ok(Solve { iterations: max_iterations, relative_divergence: residual * scale, converged: false })
    }

    /// Appends `z = M^-1 r` (one V-cycle, then the mean removed) to `batch`.
    fn precondition(&self, batch: Batch<'a>, p: &FluidParams) -> Result<Batch<'a>> {
        let mut batch = batch;
        let bytes = p.cells as u64 * 4;
        batch.copy(&self.r, &self.levels[0].b, bytes);
        self.v_cycle(&mut batch, p, 0);
        batch.copy(&self.levels[0].x, &self.z, bytes);
        self.remove_mean(batch, p, &self.z)
    }

    /// Two Gauss-Seidel sweeps on level `l`, colour `first` then the
    /// other: `x` into `scratch` and back (each sweep writes every cell,
    /// the other colour's unchanged, so no copy is needed between them).
    /// (Sweeping in place, as the coarse solve does, was slower on
    /// lavapipe at 64^3: see docs/smoke.md.)
    fn sweep_pair(&self, batch: &mut Batch, p: &FluidParams, l: usize, first: u32) {
        let lv = &self.levels[l];
        let d = self.on_level(p, l);
        for (colour, from, to) in [(first, &lv.x, &lv.scratch), (1 - first, &lv.scratch, &lv.x)] {
            batch.dispatch(
                &GAUSS_SEIDEL,
                P,
                &FluidDispatch { colour, ..d },
                &[(A, &lv.b), (B, from), (FLAGS, &lv.stencils), (OUT, to)],
                lv.cells,
            );
        }
    }

    /// `Poisson::v_cycle` from level `l`.
    fn v_cycle(&self, batch: &mut Batch, p: &FluidParams, l: usize) {
        let lv = &self.levels[l];
        batch.clear(&lv.x);
        if l + 1 == self.levels.len() {
            // The whole coarse solve in one workgroup (`fluid_coarse_solve`).
            let d = self.on_level(p, l);
            let lanes = slicelight_shaders::smoke::COARSE_LANES;
            batch.dispatch(&COARSE_SOLVE, P, &d, &[(A, &lv.b), (FLAGS, &lv.stencils), (OUT, &lv.x)], lanes);
            return;
        }
        for _ in 0..SMOOTHING_SWEEPS {
            self.sweep_pair(batch, p, l, 0);
        }
        let fine = self.on_level(p, l);
        batch.dispatch(
            &RESIDUAL,
            P,
            &fine,
            &[(A, &lv.b), (B, &lv.x), (FLAGS, &lv.stencils), (OUT, &lv.scratch)],
            lv.cells,
        );
        let coarse = &self.levels[l + 1];
        let restrict = FluidDispatch { count: coarse.cells, ..fine };
        batch.dispatch(&RESTRICT, P, &restrict, &[(A, &lv.scratch), (OUT, &coarse.b)], coarse.cells);
        self.v_cycle(batch, p, l + 1);
        batch.dispatch(
            &PROLONG,
            P,
            &fine,
            &[(A, &lv.x), (B, &coarse.x), (FLAGS, &lv.fluid), (OUT, &lv.scratch)],
            lv.cells,
        );
        batch.copy(&lv.scratch, &lv.x, lv.cells as u64 * 4);
        for _ in 0..SMOOTHING_SWEEPS {
            self.sweep_pair(batch, p, l, 1);
        }
    }

    /// The puffs' positions `dt` on (cells), traced through the projected field.
    fn trace_puffs(&mut self, f: &Fluid) -> Result<Vec<Vec3>> {
        let points: Vec<Vec4> = f.puffs.iter().map(|puff| f.to_cells(puff.position).extend(0.0)).collect();
        if points.is_empty() {
            return Ok(Vec::new());
        }
        let bytes = points.len() as u64 * 16;
        if bytes > self.points.size() {
            let capacity = bytes.next_power_of_two();
            self.points = self.ctx.zeroed("puffs", capacity)?;
            self.points_out = self.ctx.zeroed("puffs traced", capacity)?;
        }
        self.ctx.upload(&self.points, bytemuck::cast_slice(&points));
        let n = points.len() as u32;
        let d = FluidDispatch { direction: -1.0, ..at(&f.params, 0, n) };
        let mut batch = self.ctx.batch();
        let bound = self.with_velocity(&[(POINTS, &self.points), (POINTS_OUT, &self.points_out)]);
        batch.dispatch(&TRACE, P, &d, &bound, n);
        let traced = batch.submit_reading(&self.points_out, bytes)?;
        Ok(bytemuck::cast_slice::<u8, Vec4>(&traced).iter().map(|x| x.truncate()).collect())
    }
}

/// Steps a `Fluid` on the CPU, or with its kernels on a device (its
/// fields read back by `finish`).
pub enum Stepper<'a> {
    Cpu,
    Device(Box<GpuFluid<'a>>),
}

impl<'a> Stepper<'a> {
    /// On `device` if given (uploading `f`), else on the CPU.
    pub fn new(device: Option<&'a GpuContext>, f: &Fluid) -> Result<Stepper<'a>> {
        Ok(match device {
            Some(ctx) => Stepper::Device(Box::new(GpuFluid::new(ctx, f)?)),
            None => Stepper::Cpu,
        })
    }

    /// One step of `f`.
    pub fn step(&mut self, f: &mut Fluid) -> Result<()> {
        match self {
            Stepper::Device(d) => d.step(f),
            Stepper::Cpu => {
                f.step();
                Ok(())
            }
        }
    }

    /// Brings `f`'s fields up to date (a device's read back).
    pub fn finish(&self, f: &mut Fluid) -> Result<()> {
        match self {
            Stepper::Device(d) => d.download(f),
            Stepper::Cpu => Ok(()),
        }
    }
}

/// A dispatch of `count` invocations on quantity `kind`.
fn at(p: &FluidParams, kind: u32, count: u32) -> FluidDispatch {
    FluidDispatch { fluid: *p, kind, count, direction: 1.0, nx: p.nx, ny: p.ny, nz: p.nz, ..Default::default() }
}
