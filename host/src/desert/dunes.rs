//! The sand automaton's host side (kernels: `shader-crate/src/desert/sand.rs`):
//! a `[[terrain]]`'s `dunes = { ... }` settings, their validation and
//! conversion to the kernel's integer parameters, the CPU run at scene
//! load, the settling to the angle of repose, and the self-check pass that
//! runs the same steps on the backend (`--pass desert.dunes`).

use anyhow::{bail, Result};
use glam::UVec2;
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::Deserialize;
use slicelight_shaders::desert::sand::{
    avalanche, relax_rows, relax_rule, saltation_row, sand_cell, Relax, SandParams,
};
use slicelight_shaders::types::CommonParams;

use crate::cpu::for_each_invocation;
use crate::passes::*;
use crate::scene::{invalid, SceneData};

/// `dunes = { ... }` in a `[[terrain]]`: the automaton run at load.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Cells along x and z over the terrain's rectangle (each even or 1).
    pub cells: [u32; 2],
    /// Steps run from the start (at time 0).
    pub steps: u32,
    /// Steps more per second of the scene's time (`steps + round(rate t)`
    /// at time `t`: the dunes migrate in an animation); default 0.
    pub steps_per_second: Option<f32>,
    #[serde(default)]
    pub seed: u32,
    /// Mean depth of loose sand at the start (m); default 1, or 0 with `piles`.
    pub sand: Option<f32>,
    /// Piles of sand on the bed at the start: `[x, z, radius, height]`
    /// (m, the scene's x and z): cones, wrapped around the field's edges.
    pub piles: Option<Vec<[f32; 4]>>,
    /// A slab's height (m); default a tenth of a cell's width.
    pub slab: Option<f32>,
    /// Wind speed (m/s, 10 m above the sand); default 10.
    pub wind_speed: Option<f32>,
    /// Where the wind blows to: "+x", "-x", "+z" or "-z"; default "+x".
    pub wind_direction: Option<String>,
    /// Below this wind speed (m/s) no grain moves (Bagnold's threshold); default 4.
    pub threshold_speed: Option<f32>,
    /// Probability per step that an exposed sand cell gives a slab, at
    /// winds far above the threshold; default 0.5.
    pub erosion: Option<f32>,
    /// Saltation length at 10 m/s (cells), in proportion to the wind; default 5.
    pub jump: Option<f32>,
    /// Growth of the saltation length with the source's height (cells per
    /// metre; Nishimori-Ouchi's `b tau`); default 0.
    pub jump_growth: Option<f32>,
    /// Jumps a slab may make before it lands; default 3.
    pub hops: Option<u32>,
    /// Probability a slab lands on sand and on bare ground; default [0.6, 0.4] (Werner).
    pub deposit: Option<[f32; 2]>,
    /// Angle of repose (degrees); default 33.
    pub repose_deg: Option<f32>,
    /// Angle of the wind shadow behind a crest (degrees); default 15 (Werner).
    pub shadow_deg: Option<f32>,
    /// Probability per creep round that a cell moves a slab to a lower
    /// neighbour (two or more slabs below); default 0.1.
    pub creep: Option<f32>,
    /// Avalanche and creep rounds per step; default 2 and 1.
    pub avalanche_rounds: Option<u32>,
    pub creep_rounds: Option<u32>,
}

/// Most cells a dune field may have.
pub const MAX_CELLS: u64 = 1 << 24;
/// Most steps.
pub const MAX_STEPS: u32 = 1_000_000;
/// Most piles at the start (each is laid over the cells around it at load).
const MAX_PILES: usize = 4096;
/// Most cells the piles may cover in all (the work of laying them).
const MAX_PILE_WORK: u64 = 1 << 28;
/// Most dispatches (steps times phases) a self-check may run on the GPU.
const MAX_DISPATCHES: u64 = u32::MAX as u64;
/// Wind speed (m/s) at which `jump` is the saltation length.
const REFERENCE_WIND: f32 = 10.0;
/// The longest jump (cells) and the shadow's farthest reach (cells).
const MAX_JUMP: u32 = 32;
const MAX_SHADOW_REACH: u32 = 64;

/// Which way the wind blows over the terrain; the automaton's lattice has
/// the wind along its `+x`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Wind {
    #[default]
    PlusX,
    MinusX,
    PlusZ,
    MinusZ,
}

/// The automaton of one terrain.
#[derive(Debug, Clone, Default)]
pub struct Setup {
    pub params: SandParams,
    pub steps: u32,
    pub wind: Wind,
    /// The terrain's cells along x and z.
    pub cells: [u32; 2],
    /// A slab's height (m).
    pub slab: f32,
    /// The given start's slabs per lattice cell (the piles), or empty.
    pub start: Start,
}

/// Slabs per lattice cell laid on the bed at the start. Its `Debug` (part
/// of the key the formed fields are kept and cached by) is its length and
/// a hash of its contents, not every cell.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct Start(pub Vec<u32>);

impl std::fmt::Debug for Start {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let hash = crate::output::stable_hash(bytemuck::cast_slice(&self.0));
        write!(f, "Start({} cells, {hash:016x})", self.0.len())
    }
}

impl Setup {
    /// Dispatches of the kernel: the start, then every phase of every step.
    pub fn dispatches(&self) -> u32 {
        1 + self.steps * self.params.phases
    }

    /// The terrain's cell `(i, k)` (x, z) in the lattice (wind along its x).
    pub fn lattice_index(&self, i: u32, k: u32) -> usize {
        let [nx, nz] = self.cells;
        let (x, z) = match self.wind {
            Wind::PlusX => (i, k),
            Wind::MinusX => (nx - 1 - i, k),
            Wind::PlusZ => (k, i),
            Wind::MinusZ => (nz - 1 - k, i),
        };
        (z * self.params.nx + x) as usize
    }

    /// Heights (m) over the terrain's cells (x fastest) from the lattice's slabs.
    pub fn metres(&self, slabs: &[u32]) -> Vec<f32> {
        let [nx, nz] = self.cells;
        let mut out = Vec::with_capacity((nx * nz) as usize);
        for k in 0..nz {
            for i in 0..nx {
                out.push(slabs[self.lattice_index(i, k)] as f32 * self.slab);
            }
        }
        out
    }
}

fn probability(field: &str, p: f32) -> Result<u32> {
    if !(0.0..=1.0).contains(&p) {
        bail!(invalid(field, "a probability in [0, 1]", p));
    }
    Ok((p as f64 * 4294967296.0).min(u32::MAX as f64) as u32)
}

fn positive(field: &str, v: f32) -> Result<f32> {
    if !(v.is_finite() && v > 0.0) {
        bail!(invalid(field, "a positive number", v));
    }
    Ok(v)
}

/// Validates `s` (the field `field`) for a terrain over `min .. min + size`
/// (m, x and z) at the scene's time `time` (s) and builds the kernel's
/// parameters and the start.
pub fn configure(field: &str, s: &Settings, min: [f32; 2], size: [f32; 2], time: f64) -> Result<Setup> {
    let f = |name: &str| format!("{field}.dunes.{name}");
    let [cx, cz] = s.cells;
    let even_or_one = |n: u32| n == 1 || (n.is_multiple_of(2) && (2..=8192).contains(&n));
    if !(even_or_one(cx) && even_or_one(cz)) {
        bail!(invalid(
            &f("cells"),
            "two cell counts, each 1 or even, at most 8192 (the avalanche's checkerboard wraps around)",
            s.cells
        ));
    }
    let cells = cx as u64 * cz as u64;
    if cells > MAX_CELLS {
        bail!(invalid(&f("cells"), &format!("at most {MAX_CELLS} cells"), s.cells));
    }
    if !(1..=MAX_STEPS).contains(&s.steps) {
        bail!(invalid(&f("steps"), &format!("a step count in 1..={MAX_STEPS}"), s.steps));
    }
    let rate = s.steps_per_second.unwrap_or(0.0);
    if !(rate.is_finite() && (0.0..=1000.0).contains(&rate)) {
        bail!(invalid(&f("steps_per_second"), "a rate in [0, 1000] steps per second", rate));
    }
    let more = (rate as f64 * time.max(0.0)).round();
    if s.steps as f64 + more > MAX_STEPS as f64 {
        bail!(invalid(
            &f("steps_per_second"),
            &format!("at most {MAX_STEPS} steps in all at t = {time} s (steps + steps_per_second x t)"),
            rate
        ));
    }
    let steps = s.steps + more as u32;
    let dx = size[0] / cx as f32;
    if (size[1] / cz as f32 - dx).abs() > 1e-3 * dx {
        bail!(invalid(
            &f("cells"),
            &format!("square cells: the terrain's size {size:?} over the same cell width along x and z"),
            s.cells
        ));
    }
    let slab = positive(&f("slab"), s.slab.unwrap_or(dx / 10.0))?;
    let sand = s.sand.unwrap_or(if s.piles.is_some() { 0.0 } else { 1.0 });
    if !(sand.is_finite() && sand >= 0.0) {
        bail!(invalid(&f("sand"), "a depth of at least 0 m", sand));
    }
    let mean_sand = (sand / slab).round() as u64;
    // Every cell's height stays below 2^31 slabs (the kernels' differences
    // of heights are 32-bit signed).
    if (2 * mean_sand + 1) * cells >= 1 << 31 {
        bail!(invalid(&f("sand"), "less sand: at most 2^31 slabs in all (raise slab or lower sand)", sand));
    }
    let piles = piles(&f("piles"), s.piles.as_deref().unwrap_or(&[]), min, size, s.cells, slab)?;
    let pile_slabs: u64 = piles.iter().map(|&v| v as u64).sum();
    if (2 * mean_sand + 1) * cells + pile_slabs >= 1 << 31 {
        bail!(invalid(
            &f("piles"),
            "less sand: at most 2^31 slabs in all with the bed (lower or narrow the piles)",
            pile_slabs
        ));
    }
    let wind = match s.wind_direction.as_deref().unwrap_or("+x") {
        "+x" => Wind::PlusX,
        "-x" => Wind::MinusX,
        "+z" => Wind::PlusZ,
        "-z" => Wind::MinusZ,
        other => bail!(invalid(&f("wind_direction"), "one of \"+x\", \"-x\", \"+z\", \"-z\"", other)),
    };
    let (nx, nz) = match wind {
        Wind::PlusX | Wind::MinusX => (cx, cz),
        Wind::PlusZ | Wind::MinusZ => (cz, cx),
    };
    let u = s.wind_speed.unwrap_or(10.0);
    if !(u.is_finite() && (0.0..=200.0).contains(&u)) {
        bail!(invalid(&f("wind_speed"), "a speed in [0, 200] m/s", u));
    }
    let ut = s.threshold_speed.unwrap_or(4.0);
    if !(ut.is_finite() && ut >= 0.0) {
        bail!(invalid(&f("threshold_speed"), "a speed of at least 0 m/s", ut));
    }
    // The share of exposed cells that give sand grows from 0 at the
    // threshold toward `erosion` (the excess shear stress, 1 - (u_t/u)^2).
    let excess = if u > ut { 1.0 - (ut / u).powi(2) } else { 0.0 };
    let erosion = s.erosion.unwrap_or(0.5);
    let erode = probability(&f("erosion"), erosion)?;
    let erode = (erode as f64 * excess as f64) as u32;
    let jump = s.jump.unwrap_or(5.0);
    if !(jump.is_finite() && (0.0..=MAX_JUMP as f32).contains(&jump)) {
        bail!(invalid(&f("jump"), &format!("a length in [0, {MAX_JUMP}] cells"), jump));
    }
    let growth = s.jump_growth.unwrap_or(0.0);
    // The kernel's growth is fixed-point cells per slab, at most 256: the
    // bound scales with the slab (fine ripple lattices have thin slabs).
    if !(growth.is_finite() && growth >= 0.0 && growth * slab <= 256.0) {
        bail!(invalid(
            &f("jump_growth"),
            &format!("cells per metre in [0, {}] (256 cells per slab of {slab} m)", 256.0 / slab),
            growth
        ));
    }
    let hops = s.hops.unwrap_or(3);
    if !(1..=8).contains(&hops) {
        bail!(invalid(&f("hops"), "1 to 8 jumps", hops));
    }
    let [ps, pb] = s.deposit.unwrap_or([0.6, 0.4]);
    let repose = s.repose_deg.unwrap_or(33.0);
    if !(repose.is_finite() && (5.0..=60.0).contains(&repose)) {
        bail!(invalid(&f("repose_deg"), "an angle in [5, 60] degrees", repose));
    }
    let repose_slabs = (repose.to_radians().tan() * dx / slab).floor();
    if repose_slabs < 2.0 {
        bail!(invalid(
            &f("slab"),
            &format!(
                "a slab thin enough that the angle of repose spans 2 slabs per cell: at most {} m",
                repose.to_radians().tan() * dx / 2.0
            ),
            slab
        ));
    }
    let shadow = s.shadow_deg.unwrap_or(15.0);
    if !(shadow.is_finite() && (1.0..=repose).contains(&shadow)) {
        bail!(invalid(&f("shadow_deg"), &format!("an angle in [1, repose_deg = {repose}] degrees"), shadow));
    }
    // Below 2^25, so that the shadow's fall over its reach (64 cells) fits 32 bits.
    let shadow_drop = (shadow.to_radians().tan() * dx / slab * 256.0).round().min((1 << 25) as f32);
    let rounds = |name: &str, v: Option<u32>, default: u32| -> Result<u32> {
        let r = v.unwrap_or(default);
        if r > 64 {
            bail!(invalid(&f(name), "0 to 64 rounds per step", r));
        }
        Ok(r)
    };
    let avalanche_rounds = rounds("avalanche_rounds", s.avalanche_rounds, 2)?;
    let creep_rounds = rounds("creep_rounds", s.creep_rounds, 1)?;
    let phases = 2 + 4 * (avalanche_rounds + creep_rounds);
    if 1 + steps as u64 * phases as u64 > MAX_DISPATCHES {
        bail!(invalid(&f("steps"), "fewer steps times rounds (the dispatch counter is 32 bits)", steps));
    }
    // The saltation length in cells, proportional to the wind (1/256 cells).
    let scale = u / REFERENCE_WIND;
    let jump_fixed = (jump * scale * 256.0).round().min((MAX_JUMP * 256) as f32) as u32;
    let growth_fixed = (growth * slab * scale * 256.0).round().min(65536.0) as u32;
    let max_jump = if growth_fixed == 0 { (jump_fixed >> 8).clamp(1, MAX_JUMP) } else { MAX_JUMP };
    let params = SandParams {
        nx,
        nz,
        cells: cells as u32,
        seed: s.seed,
        phases,
        avalanche_rounds,
        creep_rounds,
        mean_sand: mean_sand as u32,
        given_start: !piles.is_empty() as u32,
        jump: jump_fixed,
        jump_growth: growth_fixed,
        max_jump,
        hops,
        window: hops * max_jump,
        erode,
        deposit_sand: probability(&f("deposit[0]"), ps)?,
        deposit_bare: probability(&f("deposit[1]"), pb)?,
        creep: probability(&f("creep"), s.creep.unwrap_or(0.1))?,
        repose: repose_slabs as u32,
        shadow_drop: shadow_drop.max(1.0) as u32,
        shadow_reach: MAX_SHADOW_REACH.min(nx.saturating_sub(1)),
        height_bound: u32::MAX,
    };
    let mut setup = Setup { params, steps, wind, cells: s.cells, slab, start: Start::default() };
    if !piles.is_empty() {
        // The piles were laid over the terrain's cells (x fastest); the
        // kernel reads them in the lattice's order (the wind along its x).
        let mut start = vec![0; cells as usize];
        for k in 0..s.cells[1] {
            for i in 0..s.cells[0] {
                start[setup.lattice_index(i, k)] = piles[(k * s.cells[0] + i) as usize];
            }
        }
        setup.start = Start(start);
    }
    Ok(setup)
}

/// The piles `[x, z, radius, height]` (field `field`) as slabs over the
/// terrain's cells (x fastest; empty without piles): each a cone of sand,
/// `height (1 - d / radius)` at a cell centre `d` metres from the pile's
/// centre (the nearest of its copies around the wrapping field), rounded
/// to whole slabs of `slab` m; overlapping piles add.
fn piles(
    field: &str,
    piles: &[[f32; 4]],
    min: [f32; 2],
    size: [f32; 2],
    cells: [u32; 2],
    slab: f32,
) -> Result<Vec<u32>> {
    if piles.is_empty() {
        return Ok(Vec::new());
    }
    if piles.len() > MAX_PILES {
        bail!(invalid(field, &format!("at most {MAX_PILES} piles"), piles.len()));
    }
    let dx = size[0] / cells[0] as f32;
    let mut out = vec![0u32; (cells[0] * cells[1]) as usize];
    let mut work = 0u64;
    for (n, &[x, z, radius, height]) in piles.iter().enumerate() {
        let inside = |v: f32, a: usize| v.is_finite() && v >= min[a] && v <= min[a] + size[a];
        if !(inside(x, 0) && inside(z, 1)) {
            bail!(invalid(
                &format!("{field}[{n}]"),
                &format!("a centre [x, z] on the terrain ({:?} to {:?})", min, [min[0] + size[0], min[1] + size[1]]),
                [x, z]
            ));
        }
        let widest = 0.5 * size[0].min(size[1]);
        if !(radius.is_finite() && radius >= 0.5 * dx && radius <= widest) {
            bail!(invalid(
                &format!("{field}[{n}]"),
                &format!("a radius (third number) from half a cell ({} m) to half the terrain ({widest} m)", 0.5 * dx),
                radius
            ));
        }
        if !(height.is_finite() && height >= 0.0 && height / slab < (1u64 << 31) as f32) {
            bail!(invalid(
                &format!("{field}[{n}]"),
                "a height (fourth number) of at least 0 m, under 2^31 slabs",
                height
            ));
        }
        // Cells within the radius, each once (a pile wider than the field
        // covers all of it along that axis).
        let reach = (radius / dx).ceil() as i64 + 1;
        let span = |centre: f32, n: u32| -> Vec<u32> {
            let c = centre.floor() as i64;
            if 2 * reach + 1 >= n as i64 {
                (0..n).collect()
            } else {
                (c - reach..=c + reach).map(|v| v.rem_euclid(n as i64) as u32).collect()
            }
        };
        let (is, ks) = (span((x - min[0]) / dx, cells[0]), span((z - min[1]) / dx, cells[1]));
        work += (is.len() * ks.len()) as u64;
        if work > MAX_PILE_WORK {
            bail!(invalid(
                field,
                &format!("piles covering at most {MAX_PILE_WORK} cells in all (fewer or narrower)"),
                n + 1
            ));
        }
        let wrapped = |d: f32, span: f32| d - span * (d / span).round();
        for &k in &ks {
            for &i in &is {
                let ddx = wrapped(min[0] + (i as f32 + 0.5) * dx - x, size[0]);
                let ddz = wrapped(min[1] + (k as f32 + 0.5) * dx - z, size[1]);
                let h = height * (1.0 - (ddx * ddx + ddz * ddz).sqrt() / radius);
                if h > 0.0 {
                    let cell = &mut out[(k * cells[0] + i) as usize];
                    *cell = cell.saturating_add((h / slab).round() as u32);
                }
            }
        }
    }
    Ok(out)
}

/// Runs dispatches `first..first + count` of the kernel on the CPU from
/// `state` (the lattice after dispatch `first - 1`; `start`: the given
/// start's slabs, read by dispatch 0 where `p.given_start` is 1), the same
/// function per cell as on the GPU. Each step's saltation phase is given
/// the lattice's highest cell as `height_bound` (its wind-shadow scans stop
/// below it; the same decisions as unbounded, `sand.rs`); its saltation
/// runs row by row as one pass (`saltation_row`), each relaxation band by
/// band as one pass (`relax_rows`), and where a run starts or ends between
/// two such phases, they run as the GPU's dispatches, the gather looking
/// upwind only as far as the step's longest jump (test
/// `bounded_steps_give_the_unbounded_lattice`).
pub fn run_dispatches(
    p: &SandParams,
    start: &[u32],
    mut state: Vec<UVec2>,
    first: u32,
    count: u32,
    progress: &ProgressBar,
) -> Vec<UVec2> {
    let mut next = vec![UVec2::ZERO; p.cells as usize];
    let quiet = ProgressBar::hidden();
    let phases = p.phases.max(1);
    let mut q = *p;
    let mut k = first;
    while k < first + count {
        let phase = k.checked_sub(1).map(|c| c % phases);
        if phase == Some(0) {
            q.height_bound = p.height_bound.min(state.iter().map(|c| c.x).max().unwrap_or(0));
        }
        // A step's saltation (phases 0 and 1) row by row in one pass, where
        // both are asked for: each row's sources scattered to where they
        // land (`saltation_row`, the same counts as the gather).
        // A relaxation's choose and apply phases likewise, by bands of rows
        // (`relax_rows`: the choices wait in a ring of three rows).
        let fused = phase.filter(|f| f % 2 == 0 && k + 1 < first + count);
        if let Some(phase) = fused {
            let step = (k - 1) / phases;
            if phase == 0 {
                next.par_chunks_mut(p.nx as usize)
                    .enumerate()
                    .for_each(|(z, row)| saltation_row(z as u32, step, &q, &state, row));
            } else {
                relax_pass(&q, step, relax_rule(&q, phase), &state, &mut next);
            }
        } else {
            // The gather (phase 1) looks upwind only as far as the step's
            // longest jump (`y`, phase 0's offsets): the same counts, since
            // no slab lands farther, in fewer reads.
            if phase == Some(1) {
                q.window = p.window.min(state.par_iter().map(|c| c.y).max().unwrap_or(0));
            }
            for_each_invocation(&mut next, 0, &quiet, |i, out| *out = sand_cell(i, k, &q, start, &state));
        }
        std::mem::swap(&mut state, &mut next);
        let done = if fused.is_some() { 2 } else { 1 };
        for d in k..k + done {
            if (d + 1 - first).is_multiple_of(phases) {
                progress.inc(1);
            }
        }
        k += done;
    }
    state
}

/// One relaxation of the whole lattice on the CPU, its choose and apply
/// phases at once (`relax_rows`): `next` gets `state` after it. Bands of
/// rows as tasks: 32 tasks or more (both cores busy to the end), and at
/// least 8 rows, since each band chooses two rows more than it applies.
fn relax_pass(p: &SandParams, step: u32, rule: Relax, state: &[UVec2], next: &mut [UVec2]) {
    let band = (p.nz / 32).max(8);
    next.par_chunks_mut((band * p.nx) as usize)
        .enumerate()
        .for_each(|(b, rows)| relax_rows(b as u32 * band, step, p, state, rule, rows));
}

/// The automaton's lattice after all its steps (before settling): what the
/// self-check pass computes.
pub fn run(setup: &Setup, progress: &ProgressBar) -> Vec<UVec2> {
    let start =
        run_dispatches(&setup.params, &setup.start.0, vec![UVec2::ZERO; setup.params.cells as usize], 0, 1, progress);
    run_dispatches(&setup.params, &setup.start.0, start, 1, setup.steps * setup.params.phases, progress)
}

/// The field the automaton `setup` forms: its slabs after all steps (what
/// the self-check compares) and its heights (m, the terrain's cells) after
/// settling to the angle of repose.
///
/// The automaton is deterministic, and a scene is built again from its
/// file for every view the viewer shows and every frame of an animation:
/// the last `FORMED_KEPT` fields are kept in memory by their settings, so
/// those rebuilds take no seconds of sand; a field of the same settings
/// and more steps (the next frame of an animation, `steps_per_second`)
/// continues from the kept one with the most steps short of it, which
/// gives the same bits as a run from the start (test
/// `a_kept_field_continues_to_more_steps`). Across processes (the next
/// render of the same scene) the field is read from the cache folder
/// (`output::cache_directory`) where an earlier run wrote it.
pub fn formed(setup: &Setup, progress: &ProgressBar) -> Result<(Vec<u32>, Vec<f32>)> {
    formed_in(setup, progress, crate::output::cache_directory().as_deref())
}

/// `formed` with the cache folder `dir` (none: no cache on disk).
fn formed_in(setup: &Setup, progress: &ProgressBar, dir: Option<&std::path::Path>) -> Result<(Vec<u32>, Vec<f32>)> {
    let key = format!("{setup:?}");
    let family = family(setup);
    let kept = || FORMED.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(f) = kept().iter().find(|f| f.key == key) {
        progress.inc(setup.dispatches() as u64);
        return Ok((f.slabs.clone(), f.heights.clone()));
    }
    let cells = setup.params.cells as usize;
    let file = dir.map(|dir| field_path(dir, &key));
    let (slabs, heights) = match file.as_deref().and_then(|f| read_field(f, &key, cells)) {
        Some(field) => {
            progress.inc(setup.dispatches() as u64);
            field
        }
        None => {
            let slabs: Vec<u32> = match earlier_field(setup, &family) {
                // After a whole step every cell's `y` is 0 (the last
                // phase clears it): the lattice is the slabs alone.
                Some((steps, slabs)) => {
                    let p = &setup.params;
                    progress.inc(1 + (steps * p.phases) as u64);
                    let state = slabs.iter().map(|&h| UVec2::new(h, 0)).collect();
                    let rest = (setup.steps - steps) * p.phases;
                    run_dispatches(p, &setup.start.0, state, 1 + steps * p.phases, rest, progress)
                }
                None => run(setup, progress),
            }
            .iter()
            .map(|c| c.x)
            .collect();
            let (settled, _) = settle(&setup.params, &slabs, 1 << 20)?;
            let heights = setup.metres(&settled);
            if let Some(f) = &file {
                // A cache that cannot be written costs the next run its
                // seconds, nothing else.
                if let Err(e) = write_field(f, &key, &slabs, &heights) {
                    crate::output::note(&format!("desert: the formed field was not cached: {e:#}"));
                }
            }
            (slabs, heights)
        }
    };
    let mut fields = kept();
    if fields.len() >= FORMED_KEPT {
        fields.remove(0);
    }
    fields.push(Formed { key, family, steps: setup.steps, slabs: slabs.clone(), heights: heights.clone() });
    Ok((slabs, heights))
}

/// `setup`'s settings but its steps: the fields that one continues.
fn family(setup: &Setup) -> String {
    format!("{:?}", Setup { steps: 0, ..setup.clone() })
}

/// The kept field of `setup`'s `family` (`family(setup)`) with the most
/// steps short of its own: those steps and the slabs.
fn earlier_field(setup: &Setup, family: &str) -> Option<(u32, Vec<u32>)> {
    let kept = FORMED.lock().unwrap_or_else(|e| e.into_inner());
    kept.iter()
        .filter(|f| f.family == family && f.steps < setup.steps)
        .max_by_key(|f| f.steps)
        .map(|f| (f.steps, f.slabs.clone()))
}

/// The cached fields' format: bump when what `formed` returns for the same
/// settings changes other than through the kernels' sources (whose digest
/// is in the file's name, as is this file's own text).
const FIELD_VERSION: u32 = 1;
const FIELD_MAGIC: &[u8; 8] = b"SLDUNES1";
/// Fields kept in the cache folder (the newest; each 8 bytes a cell).
const FIELDS_ON_DISK: usize = 8;

/// Where the field of settings `key` is cached in `dir`.
fn field_path(dir: &std::path::Path, key: &str) -> std::path::PathBuf {
    let source = crate::output::stable_hash(include_str!("dunes.rs").as_bytes());
    dir.join(format!("dunes-{:016x}.field", crate::output::cache_key(FIELD_VERSION, &format!("{source:x}|{key}"))))
}

/// A field `write_field` wrote for `key` and `cells` cells, or nothing
/// (no file, another key, or anything but a whole field: then it is
/// computed again).
fn read_field(path: &std::path::Path, key: &str, cells: usize) -> Option<(Vec<u32>, Vec<f32>)> {
    crate::output::regular_file("dunes cache", path, crate::output::MAX_DATA_BYTES).ok()?;
    let bytes = std::fs::read(path).ok()?;
    let head = FIELD_MAGIC.len() + 8 + key.len();
    if bytes.len() != head + 8 * cells
        || &bytes[..8] != FIELD_MAGIC
        || bytes[8..16] != (key.len() as u64).to_le_bytes()
        || &bytes[16..head] != key.as_bytes()
    {
        return None;
    }
    let (slabs, heights) = bytes[head..].split_at(4 * cells);
    let slabs = slabs.as_chunks::<4>().0.iter().map(|c| u32::from_le_bytes(*c)).collect();
    let heights = heights.as_chunks::<4>().0.iter().map(|c| f32::from_le_bytes(*c)).collect();
    Some((slabs, heights))
}

/// Writes the field of `key` to `path` whole or not at all, and removes all
/// but the newest `FIELDS_ON_DISK` fields beside it.
fn write_field(path: &std::path::Path, key: &str, slabs: &[u32], heights: &[f32]) -> Result<()> {
    let dir = path.parent().expect("a file in the cache folder");
    std::fs::create_dir_all(dir)?;
    let mut out = Vec::with_capacity(16 + key.len() + 8 * slabs.len());
    out.extend_from_slice(FIELD_MAGIC);
    out.extend_from_slice(&(key.len() as u64).to_le_bytes());
    out.extend_from_slice(key.as_bytes());
    out.extend(slabs.iter().flat_map(|h| h.to_le_bytes()));
    out.extend(heights.iter().flat_map(|h| h.to_le_bytes()));
    crate::output::write_atomically(path, &out)?;
    let mut fields: Vec<(std::time::SystemTime, std::path::PathBuf)> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("dunes-"))
        .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
        .collect();
    fields.sort();
    for (_, old) in fields.iter().take(fields.len().saturating_sub(FIELDS_ON_DISK)) {
        let _ = std::fs::remove_file(old);
    }
    Ok(())
}

/// Fields `formed` keeps: a scene's dunes and ripples, and one edit's.
const FORMED_KEPT: usize = 4;

/// A kept field: its settings (`Setup`'s `Debug`), the same without the
/// steps, its steps, slabs and heights.
struct Formed {
    key: String,
    family: String,
    steps: u32,
    slabs: Vec<u32>,
    heights: Vec<f32>,
}
static FORMED: std::sync::Mutex<Vec<Formed>> = std::sync::Mutex::new(Vec::new());

/// Avalanche rounds (both colours) on `slabs` until nothing moves; returns
/// the heights and the rounds it took. Each move lowers the sum of squared
/// heights (`sand.rs`), so this ends; `limit` rounds bound it all the same.
pub fn settle(p: &SandParams, slabs: &[u32], limit: u32) -> Result<(Vec<u32>, u32)> {
    let mut state: Vec<UVec2> = slabs.iter().map(|&h| UVec2::new(h, 0)).collect();
    let mut next = state.clone();
    for round in 0..limit {
        let mut moved = false;
        for colour in 0..2 {
            // Every `y` is 0 between relaxations: a change is a slab moved.
            relax_pass(p, 0, avalanche(p, colour), &state, &mut next);
            moved |= next != state;
            std::mem::swap(&mut state, &mut next);
        }
        if !moved {
            return Ok((state.iter().map(|c| c.x).collect(), round));
        }
    }
    bail!("dunes: the sand did not settle to the angle of repose in {limit} avalanche rounds")
}

pub static SAND_PARAMS: Resource = Resource {
    binding: 57,
    name: "sand parameters",
    kind: ResourceKind::Scene(|s| bytemuck::bytes_of(s.desert.dunes.as_ref().map_or(&NO_PARAMS, |d| &d.params))),
};
static NO_PARAMS: SandParams = SandParams {
    nx: 0,
    nz: 0,
    cells: 0,
    seed: 0,
    phases: 1,
    avalanche_rounds: 0,
    creep_rounds: 0,
    mean_sand: 0,
    given_start: 0,
    jump: 0,
    jump_growth: 0,
    max_jump: 0,
    hops: 0,
    window: 0,
    erode: 0,
    deposit_sand: 0,
    deposit_bare: 0,
    creep: 0,
    repose: 0,
    shadow_drop: 0,
    shadow_reach: 0,
    height_bound: 0,
};
fn lattice_bytes(s: &SceneData) -> u64 {
    s.desert.dunes.as_ref().map_or(0, |d| d.params.cells as u64 * 8)
}
/// The lattice a dispatch reads (the GPU copies the dispatch's output over it).
pub static SAND_STATE: Resource =
    Resource { binding: 58, name: "sand lattice", kind: ResourceKind::Frame(lattice_bytes) };
/// The lattice a dispatch writes: after the last, the final state.
pub static SAND_NEXT: Resource =
    Resource { binding: 59, name: "sand next lattice", kind: ResourceKind::Frame(lattice_bytes) };
pub static SAND_COUNTER: Resource = Resource { binding: 60, name: "sand dispatch", kind: ResourceKind::Frame(|_| 4) };
pub static SAND_NEXT_COUNTER: Resource =
    Resource { binding: 61, name: "sand next dispatch", kind: ResourceKind::Frame(|_| 4) };
/// The given start's slabs per lattice cell (one zero word without piles:
/// the kernel reads it only where `given_start` is 1).
pub static SAND_START: Resource = Resource {
    binding: 118,
    name: "sand start",
    kind: ResourceKind::Scene(|s| match s.desert.dunes.as_ref().filter(|d| !d.start.0.is_empty()) {
        Some(d) => bytemuck::cast_slice(&d.start.0),
        None => &[0; 4],
    }),
};

/// The dunes' automaton run on the backend: a self-check (the terrain is
/// built on the CPU at load, since the BVH needs its heights), requested by
/// name; its result must equal the load's bit for bit.
pub struct Dunes;

impl Pass for Dunes {
    fn name(&self) -> &'static str {
        "desert.dunes"
    }
    fn kernel(&self) -> &'static str {
        "desert::sand::sand_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SAND_PARAMS, SAND_STATE, SAND_COUNTER, SAND_START]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SAND_NEXT, SAND_NEXT_COUNTER]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn repeats(&self, scene: &SceneData) -> u32 {
        scene.desert.dunes.as_ref().map_or(1, |d| d.dispatches())
    }
    fn carry(&self) -> &'static [(&'static Resource, &'static Resource)] {
        static CARRY: [(&Resource, &Resource); 2] = [(&SAND_NEXT, &SAND_STATE), (&SAND_NEXT_COUNTER, &SAND_COUNTER)];
        &CARRY
    }
    fn keeps(&self) -> &'static [&'static Resource] {
        resources![SAND_NEXT]
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        let Some(d) = &scene.desert.dunes else {
            return Plan::skip("no dunes");
        };
        if !scene.requested_passes.iter().any(|p| p == self.name()) {
            return Plan::skip(
                "a self-check (the dunes are built on the CPU at load); run it with --pass desert.dunes",
            );
        }
        let p = &d.params;
        Plan::run(
            format!(
                "requested: {} steps of {}x{} cells ({} dispatches), against the load's",
                d.steps,
                p.nx,
                p.nz,
                d.dispatches()
            ),
            p.cells as u64,
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let d = scene.desert.dunes.as_ref().expect("planned only with dunes");
        let state = run(d, progress);
        frame.insert(&SAND_NEXT, Buffer::from_bytes(bytemuck::cast_slice(&state)));
        frame.insert(&SAND_NEXT_COUNTER, Buffer::from_bytes(bytemuck::bytes_of(&d.dispatches())));
    }
    fn report(&self, scene: &SceneData, frame: &Frame) -> Result<Option<String>> {
        let Some(d) = &scene.desert.dunes else { return Ok(None) };
        let Some(loaded) = &scene.desert.dune_slabs else { return Ok(None) };
        let got: Vec<u32> = frame.get::<UVec2>(&SAND_NEXT).iter().map(|c| c.x).collect();
        let differ = got.iter().zip(loaded).filter(|(a, b)| a != b).count();
        if differ > 0 || got.len() != loaded.len() {
            bail!("desert.dunes: {differ} of {} cells differ from the heights built at load", loaded.len());
        }
        Ok(Some(format!("all {} cells equal the load's after {} steps", got.len(), d.steps)))
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Integer rules and a counter-based hash: the same bits, or a bug.
        let (a, b) = (gpu.get::<UVec2>(&SAND_NEXT), cpu.get::<UVec2>(&SAND_NEXT));
        let (differ, _) = crate::passes::differing_records("sand cells", a, b, 1)?;
        let k = (gpu.get::<u32>(&SAND_NEXT_COUNTER)[0], cpu.get::<u32>(&SAND_NEXT_COUNTER)[0]);
        if differ > 0 || k.0 != k.1 {
            bail!("{differ} of {} cells differ; dispatches {} and {}", a.len(), k.0, k.1);
        }
        let slabs: u64 = a.iter().map(|c| c.x as u64).sum();
        Ok(format!("all {} cells identical after {} dispatches ({slabs} slabs)", a.len(), k.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(seed: u32) -> Setup {
        let settings: Settings = toml::from_str(&format!("cells = [16, 8]\nsteps = 30\nseed = {seed}")).unwrap();
        configure("terrain[0]", &settings, [0.0, 0.0], [16.0, 8.0], 0.0).unwrap()
    }

    fn forget(key: &str) {
        FORMED.lock().unwrap().retain(|f| f.key != key);
    }

    /// A field is written once, read back whole by the next process (here:
    /// after the memory's copy is forgotten), and anything but a whole field
    /// of the same settings is computed again.
    #[test]
    fn formed_fields_are_cached_on_disk_and_read_back_only_whole() {
        let dir = tempfile::tempdir().unwrap();
        let hidden = ProgressBar::hidden();
        let setup = small(4242);
        let key = format!("{setup:?}");
        forget(&key);
        let computed = formed_in(&setup, &hidden, Some(dir.path())).unwrap();
        let path = field_path(dir.path(), &key);
        assert!(path.is_file(), "no cached field at {}", path.display());
        assert_eq!(read_field(&path, &key, computed.0.len()), Some(computed.clone()));
        // Another key, another size, a truncated file: not read.
        assert_eq!(read_field(&path, &format!("{key} "), computed.0.len()), None);
        assert_eq!(read_field(&path, &key, computed.0.len() + 1), None);
        let whole = std::fs::read(&path).unwrap();
        std::fs::write(&path, &whole[..whole.len() - 1]).unwrap();
        assert_eq!(read_field(&path, &key, computed.0.len()), None);
        forget(&key);
        assert_eq!(formed_in(&setup, &hidden, Some(dir.path())).unwrap(), computed, "computed again");
        assert_eq!(std::fs::read(&path).unwrap(), whole, "written again, whole");
        // A field in the cache is what a later build takes: marked heights
        // come back as they were written.
        let mut marked = computed.clone();
        marked.1[0] = -1234.5;
        write_field(&path, &key, &marked.0, &marked.1).unwrap();
        forget(&key);
        assert_eq!(formed_in(&setup, &hidden, Some(dir.path())).unwrap(), marked);
        forget(&key);
    }

    /// The CPU run scatters each row's saltation (or bounds the gather by
    /// the step's longest jump) and bounds the shadow scans by the highest
    /// cell: the same lattice, bit for bit,
    /// as every dispatch run unbounded, on ripples' settings (jumps that
    /// grow with the height, a window of 32 cells).
    #[test]
    fn bounded_steps_give_the_unbounded_lattice() {
        let settings: Settings = toml::from_str(
            "cells = [64, 16]\nsteps = 40\nsand = 0.2\nslab = 0.02\njump = 1.0\njump_growth = 50.0\nhops = 1\ncreep = 0.3",
        )
        .unwrap();
        let setup = configure("t", &settings, [0.0, 0.0], [64.0, 16.0], 0.0).unwrap();
        assert_eq!(setup.params.window, MAX_JUMP);
        let bounded = run(&setup, &ProgressBar::hidden());
        let p = &setup.params;
        let mut free = vec![UVec2::ZERO; p.cells as usize];
        for k in 0..setup.dispatches() {
            free = (0..p.cells).map(|i| sand_cell(i, k, p, &[], &free)).collect();
        }
        assert_eq!(bounded, free);
        let longest = (0..p.cells).map(|i| sand_cell(i, 1, p, &[], &free).y).max().unwrap();
        assert!(longest > 1 && longest < p.window, "a bound that bounds: {longest} of {}", p.window);
        // Runs cut between a step's two saltation phases (the row pass
        // does not apply; the gather with its bounded window does).
        let hidden = ProgressBar::hidden();
        let cut = 1 + 5 * p.phases + 1;
        let part = run_dispatches(p, &[], vec![UVec2::ZERO; p.cells as usize], 0, cut, &hidden);
        assert_eq!(run_dispatches(p, &[], part, cut, setup.dispatches() - cut, &hidden), free);
    }

    /// An animation's frames: the field at a later time continues from the
    /// one kept at an earlier time, and equals a run from the start.
    #[test]
    fn a_kept_field_continues_to_more_steps() {
        let hidden = ProgressBar::hidden();
        let settings: Settings =
            toml::from_str("cells = [16, 8]\nsteps = 20\nseed = 4243\nsteps_per_second = 10.0").unwrap();
        let at = |t: f64| configure("terrain[0]", &settings, [0.0, 0.0], [16.0, 8.0], t).unwrap();
        let (early, late) = (at(1.0), at(2.5));
        assert_eq!((early.steps, late.steps), (30, 45));
        for s in [&early, &late] {
            forget(&format!("{s:?}"));
        }
        formed_in(&early, &hidden, None).unwrap();
        assert_eq!(
            earlier_field(&late, &family(&late)).map(|f| f.0),
            Some(30),
            "the later field continues the earlier"
        );
        let continued = formed_in(&late, &hidden, None).unwrap();
        forget(&format!("{late:?}"));
        forget(&format!("{early:?}"));
        let fresh = formed_in(&late, &hidden, None).unwrap();
        assert_eq!(continued, fresh);
        assert_ne!(formed_in(&early, &hidden, None).unwrap().0, fresh.0, "the sand moved in 15 steps");
        forget(&format!("{late:?}"));
        forget(&format!("{early:?}"));
    }

    #[test]
    fn the_cache_keeps_the_newest_fields() {
        let dir = tempfile::tempdir().unwrap();
        for k in 0..FIELDS_ON_DISK + 3 {
            let key = format!("field {k}");
            write_field(&field_path(dir.path(), &key), &key, &[k as u32], &[k as f32]).unwrap();
            // Distinct modification times, so that "newest" is defined.
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        let left = std::fs::read_dir(dir.path()).unwrap().count();
        assert_eq!(left, FIELDS_ON_DISK);
        let last = format!("field {}", FIELDS_ON_DISK + 2);
        assert!(read_field(&field_path(dir.path(), &last), &last, 1).is_some(), "the newest was removed");
    }
}
