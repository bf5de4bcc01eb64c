//! The sand automaton: Werner's slab model of dunes (Werner 1995, "Eolian
//! dunes: computer simulations and attractor interpretation", Geology 23)
//! with Nishimori and Ouchi's height-dependent saltation length and surface
//! creep (Nishimori and Ouchi 1993, "Formation of ripple patterns and dunes
//! by wind-blown sand", PRL 71; the survey's [16], section 5.1).
//!
//! Heights are whole slabs (`u32`), so every rule moves whole slabs and the
//! total is conserved exactly. The wind blows along `+x` of the lattice
//! (the host turns the lattice to the scene's wind); both axes wrap around.
//! A step is a sequence of synchronous phases, each a pure function of the
//! previous phase's lattice (so both backends compute the same bits):
//!
//! 1. **saltation, source**: a sand cell outside the wind shadow gives a slab
//!    with probability `erode`; the slab jumps `L = L0 + b h` cells downwind
//!    (Nishimori-Ouchi's `L = L0 + b tau h`, the wind's `tau` in `L0` and
//!    `b`), and lands there with probability `deposit_sand` on sand,
//!    `deposit_bare` on bare ground, always in a wind shadow, else jumps
//!    again, at most `hops` times (Werner's rule, bounded so that the
//!    gather below has a fixed window). A cell is in the wind shadow if
//!    the line falling at the shadow angle (Werner: 15 degrees) from some
//!    upwind cell's top passes above it: `(h(x - d) - h(x)) > d tan(15) dx
//!    / slab` for some `d` up to `shadow_reach` cells (fixed point, 1/256
//!    slab).
//! 2. **saltation, gather**: each cell loses the slab it gave and gains the
//!    slabs whose jump ends on it (it looks `hops * max_jump` cells upwind).
//! 3. **avalanches, then creep**: in rounds of two colours (a checkerboard),
//!    each cell of the round's colour whose steepest 4-neighbour lies more
//!    than `threshold` slabs below moves one slab to it. Avalanches use the
//!    angle of repose (`repose` slabs, about 33 degrees) and always move;
//!    creep (Nishimori-Ouchi's relaxation toward the neighbours) uses one
//!    slab and moves with probability `creep`. Senders and receivers are of
//!    different colours, so a round is a gather without conflicts; with
//!    `repose >= 2` every avalanche move lowers the sum of squared heights,
//!    so rounds repeated until nothing moves (`settled`) end. A round is
//!    two phases: the senders *choose* (each writes the direction it sends
//!    to, or 0), then every cell *applies* (a sender loses its slab, a
//!    receiver gains one per neighbour whose choice points at it). One
//!    phase would do, but then each receiver recomputes its four
//!    neighbours' choices (20 reads) where it now reads four numbers.
//!
//! Random numbers: the counter-based hash of (cell, step, seed, stream)
//! (`crate::random`); probabilities are thresholds on its 32 bits.

use crate::glam::{UVec2, UVec3};
use crate::random::{keyed, random, stream_key};
use spirv_std::spirv;

/// The automaton's parameter block (the host fills it from the scene's
/// `dunes = { ... }` or `ripples = { ... }`).
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct SandParams {
    /// Cells along the wind (x) and across it (z), and both; each axis even
    /// or 1 (the checkerboard wraps around).
    pub nx: u32,
    pub nz: u32,
    pub cells: u32,
    pub seed: u32,
    /// Phases per step: 2 + 4 (avalanche_rounds + creep_rounds) (a round
    /// is two colours, each a choose and an apply phase).
    pub phases: u32,
    pub avalanche_rounds: u32,
    pub creep_rounds: u32,
    /// The random start: `mean_sand` slabs per cell, give or take one.
    pub mean_sand: u32,
    /// 1: the start adds the host's slabs per cell (`start`: piles of sand
    /// the scene places), 0: the random bed alone.
    pub given_start: u32,
    /// Saltation length `L0` (1/256 cells) and its growth `b` per slab of
    /// the source's height (1/256 cells per slab); at most `max_jump` cells.
    pub jump: u32,
    pub jump_growth: u32,
    pub max_jump: u32,
    /// Jumps a slab may make before it lands wherever it is.
    pub hops: u32,
    /// Cells the gather looks upwind: `hops * max_jump`.
    pub window: u32,
    /// Probabilities as thresholds on 32 random bits (`p * 2^32`).
    pub erode: u32,
    pub deposit_sand: u32,
    pub deposit_bare: u32,
    pub creep: u32,
    /// The largest height difference (slabs) between 4-neighbours at rest:
    /// `floor(tan(repose) dx / slab)`.
    pub repose: u32,
    /// The wind shadow's fall per cell (1/256 slab): `tan(15) dx / slab`
    /// (`shadow_reach * shadow_drop` below 2^32).
    pub shadow_drop: u32,
    /// Cells behind a crest its shadow may reach.
    pub shadow_reach: u32,
    /// No cell is higher than this (slabs) when the step's saltation phase
    /// reads the lattice, or `u32::MAX` (no bound): the wind-shadow scan
    /// stops where its line falls below the bound, since no top upwind can
    /// rise above it there (the same answer, fewer reads; the CPU run
    /// bounds each step by its highest cell, the GPU self-check runs
    /// unbounded, and the equivalence test holds the two to the bit).
    pub height_bound: u32,
}

#[cfg(not(target_arch = "spirv"))]
mod pod {
    // SAFETY: `repr(C)` of 4-byte scalars, 88 bytes, no padding.
    unsafe impl bytemuck::Zeroable for super::SandParams {}
    unsafe impl bytemuck::Pod for super::SandParams {}
}

/// The hash's streams (one per decision, so that no two share bits).
const STREAM_START: u32 = 100;
const STREAM_ERODE: u32 = 101;
/// `STREAM_DEPOSIT + hop`.
const STREAM_DEPOSIT: u32 = 110;
/// `STREAM_RELAX + relax phase`.
const STREAM_RELAX: u32 = 200;

/// The hash keys of a step's random streams (`stream_key`), looked up
/// where a decision asks for one: computed there on the GPU (`StepKeys`),
/// made once per row by the CPU's row passes (`SaltationKeys`, `OneKey`).
/// The same numbers either way (`random(cell, step, seed, stream)` is
/// `keyed(cell, stream_key(step, seed, stream))`), three hashes fewer
/// each from a table.
pub trait Keys {
    fn key(&self, stream: u32) -> u32;
}

/// The keys of step `step` computed where they are asked for.
pub struct StepKeys {
    pub step: u32,
    pub seed: u32,
}

impl Keys for StepKeys {
    #[inline(always)]
    fn key(&self, stream: u32) -> u32 {
        stream_key(self.step, self.seed, stream)
    }
}

/// The saltation's keys for one step, made once: the erosion's and one
/// deposit's per hop (`hops` is at most 8; the host checks it).
#[cfg(not(target_arch = "spirv"))]
pub struct SaltationKeys {
    erode: u32,
    deposit: [u32; 8],
}

#[cfg(not(target_arch = "spirv"))]
impl SaltationKeys {
    pub fn new(step: u32, seed: u32) -> Self {
        let mut deposit = [0; 8];
        for (hop, key) in deposit.iter_mut().enumerate() {
            *key = stream_key(step, seed, STREAM_DEPOSIT + hop as u32);
        }
        Self { erode: stream_key(step, seed, STREAM_ERODE), deposit }
    }
}

#[cfg(not(target_arch = "spirv"))]
impl Keys for SaltationKeys {
    #[inline(always)]
    fn key(&self, stream: u32) -> u32 {
        if stream == STREAM_ERODE {
            self.erode
        } else {
            self.deposit[(stream - STREAM_DEPOSIT) as usize]
        }
    }
}

/// The key of the one stream a relaxation uses, made once.
#[cfg(not(target_arch = "spirv"))]
pub struct OneKey(pub u32);

#[cfg(not(target_arch = "spirv"))]
impl Keys for OneKey {
    #[inline(always)]
    fn key(&self, _stream: u32) -> u32 {
        self.0
    }
}

/// A relaxation's kind: moves a slab down a drop of more than `threshold`
/// slabs, with probability `probability / 2^32` (`u32::MAX`: always).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Relax {
    pub colour: u32,
    pub threshold: u32,
    pub probability: u32,
    pub stream: u32,
}

/// The avalanche rule of colour `colour` (rounds until nothing moves use it).
pub fn avalanche(p: &SandParams, colour: u32) -> Relax {
    Relax { colour, threshold: p.repose, probability: u32::MAX, stream: STREAM_RELAX }
}

/// `v` wrapped into `0..n` (the offsets here are a few lattices at most:
/// adding or subtracting beats an integer division).
fn wrap(v: i32, n: u32) -> u32 {
    let n = n as i32;
    let mut r = v;
    while r < 0 {
        r += n;
    }
    while r >= n {
        r -= n;
    }
    r as u32
}

/// The index of cell `(x, z)` (wrapped around).
fn at(p: &SandParams, x: i32, z: i32) -> usize {
    (wrap(z, p.nz) * p.nx + wrap(x, p.nx)) as usize
}

/// The cell at step 0: a nearly flat bed, `mean_sand` slabs give or take
/// one (uniform over the three), or bare (`mean_sand` 0), plus the given
/// start's slabs (`start[index]`, where `given_start` is 1: the scene's
/// piles, laid out by the host).
pub fn start_height(index: u32, p: &SandParams, start: &[u32]) -> u32 {
    let given = if p.given_start != 0 { start[index as usize] } else { 0 };
    if p.mean_sand == 0 {
        return given;
    }
    given + p.mean_sand + random(index, 0, p.seed, STREAM_START) % 3 - 1
}

/// Whether cell `(x, z)` lies in the wind shadow of a crest upwind: some
/// `h(x - d) - h(x) > d drop / 256` (slabs; for whole slabs that is `>
/// floor(d drop / 256)`, so no product of a height overflows). The scan
/// walks the row upwind by index (wrapping at its start): this is the
/// automaton's hottest loop on the CPU.
fn shadowed(p: &SandParams, state: &[UVec2], x: i32, z: i32) -> bool {
    let row = wrap(z, p.nz) * p.nx;
    let mut xi = wrap(x, p.nx);
    let h = state[(row + xi) as usize].x;
    let mut fall = 0;
    let mut d = 1;
    while d <= p.shadow_reach {
        xi = if xi == 0 { p.nx - 1 } else { xi - 1 };
        fall += p.shadow_drop;
        // No top upwind is above the bound, which the line now clears
        // (`h < 2^31`, `fall >> 8 < 2^24`: the sum does not wrap).
        if h + (fall >> 8) >= p.height_bound {
            return false;
        }
        let up = state[(row + xi) as usize].x;
        if up > h && up - h > fall >> 8 {
            return true;
        }
        d += 1;
    }
    false
}

/// The saltation length (cells) from a cell `h` slabs high.
pub fn jump_length(p: &SandParams, h: u32) -> u32 {
    // Heights above 4096 slabs jump as 4096 (keeps the product in 32 bits).
    let h = if h < 4096 { h } else { 4096 };
    let l = (p.jump + p.jump_growth * h) >> 8;
    if l < 1 {
        1
    } else if l > p.max_jump {
        p.max_jump
    } else {
        l
    }
}

/// Phase 1: cell `index`'s slab (if it gives one) and where it lands, as
/// the offset downwind (0: none). The wind shadow is looked up only where a
/// decision needs it (a scan of up to `shadow_reach` cells).
fn saltation_offset(index: u32, step: u32, p: &SandParams, state: &[UVec2]) -> u32 {
    let keys = StepKeys { step, seed: p.seed };
    saltation_offset_at(index % p.nx, index / p.nx, &keys, &Scan, p, state)
}

/// How a caller answers `shadowed` for cells of the row it works on: by
/// the scan where it is asked on the GPU (`Scan`), from the row's mask
/// made at once on the CPU (`ShadowRow`).
pub trait Shade {
    fn shadowed(&self, p: &SandParams, state: &[UVec2], x: i32, z: i32) -> bool;
}

/// `shadowed` itself.
pub struct Scan;

impl Shade for Scan {
    #[inline(always)]
    fn shadowed(&self, p: &SandParams, state: &[UVec2], x: i32, z: i32) -> bool {
        shadowed(p, state, x, z)
    }
}

/// `saltation_offset` of cell `(x, z)` with the step's random streams
/// `keys` and the wind shadow from `shade` (for a caller that walks rows:
/// no division, keys and shadows made once a row).
#[inline(always)]
fn saltation_offset_at<K: Keys, S: Shade>(x: u32, z: u32, keys: &K, shade: &S, p: &SandParams, state: &[UVec2]) -> u32 {
    let index = z * p.nx + x;
    if !erodes(index, state[index as usize].x, keys, p) {
        return 0;
    }
    jump_from(x, z, keys, shade, p, state)
}

/// Whether a cell `own` slabs high draws a slab to erode (`erode / 2^32`);
/// both tests made, no branch (a row's loop compacts the sources with it).
#[inline(always)]
fn erodes<K: Keys>(index: u32, own: u32, keys: &K, p: &SandParams) -> bool {
    (own != 0) & (keyed(index, keys.key(STREAM_ERODE)) < p.erode)
}

/// The offset downwind where the slab of an eroding cell `(x, z)` lands
/// (0: none, the cell is in the wind shadow or the jump goes around the
/// lattice onto itself).
#[inline(always)]
fn jump_from<K: Keys, S: Shade>(x: u32, z: u32, keys: &K, shade: &S, p: &SandParams, state: &[UVec2]) -> u32 {
    let index = z * p.nx + x;
    let (x, z) = (x as i32, z as i32);
    if shade.shadowed(p, state, x, z) {
        return 0;
    }
    let l = jump_length(p, state[index as usize].x);
    let mut d = 0;
    let mut hop = 0;
    loop {
        d += l;
        hop += 1;
        if hop >= p.hops {
            break;
        }
        let t = x + d as i32;
        let target = state[at(p, t, z)].x;
        let chance = if target > 0 { p.deposit_sand } else { p.deposit_bare };
        if keyed(index, keys.key(STREAM_DEPOSIT + hop)) < chance || shade.shadowed(p, state, t, z) {
            break;
        }
    }
    // A jump around the whole lattice back onto itself moves nothing
    // (`wrap`: no division).
    if wrap(d as i32, p.nx) == 0 {
        0
    } else {
        d
    }
}

/// The wind shadow of every cell of one row (`mask[x]`: `shadowed(p,
/// state, x, z)`), made at once: `O(nx)` where the scans cost up to
/// `shadow_reach` reads a cell.
///
/// `shadowed`'s test on whole slabs, `up - h > floor(d drop / 256)`, is
/// `256 up - d drop > 256 h` (for an integer `n`, `n > floor(f)` if and
/// only if `n > f`). With `g(i) = 256 h(i) + i drop` at the row's positions
/// `i` (unwrapped: the `shadow_reach` cells before the row's start are its
/// last ones), cell `x` is shadowed where the largest `g` over the window
/// `x - reach ..= x - 1` exceeds `g(x)`. The windows' maxima come from
/// prefix and suffix maxima over blocks of `reach` positions (van Herk,
/// Gil and Werman): a window spans at most two blocks, the suffix of the
/// first and the prefix of the second. `i64`: `256 h` needs 40 bits.
///
/// Where the scans are short (`Scans`: the row's mean height is less than
/// 2 cells' fall below the step's bound, as on ripples, whose shadow falls
/// 13 slabs a cell, or on a fresh bed), the row keeps them: there the mask
/// cost 12 % more a ripple step (1024^2), and on forming dunes it saves
/// 12 % (512^2). Test `a_row_of_shadows_is_the_scans`.
#[cfg(not(target_arch = "spirv"))]
pub enum ShadowRow {
    Scans,
    Mask(Vec<bool>),
}

#[cfg(not(target_arch = "spirv"))]
impl ShadowRow {
    pub fn new(p: &SandParams, state: &[UVec2], z: u32) -> Self {
        let (nx, reach) = (p.nx as usize, p.shadow_reach as usize);
        let row = &state[z as usize * nx..][..nx];
        let mean = row.iter().map(|c| c.x as u64).sum::<u64>() / nx as u64;
        if reach == 0 || (p.height_bound as u64).saturating_sub(mean) * 256 < 2 * p.shadow_drop as u64 {
            return Self::Scans;
        }
        Self::mask(p, row)
    }

    /// The mask of `row` (a row of `p`'s lattice), whatever the scans' length.
    fn mask(p: &SandParams, row: &[UVec2]) -> Self {
        let (nx, reach) = (p.nx as usize, p.shadow_reach as usize);
        if reach == 0 {
            return Self::Mask(vec![false; nx]);
        }
        // The reach is below the row's length (the host's bound; a longer
        // one would wrap onto the cell itself): position j is cell
        // (j - reach) mod nx.
        let reach = reach.min(nx.saturating_sub(1)).max(1);
        let len = nx + reach;
        let drop = p.shadow_drop as i64;
        let g: Vec<i64> =
            row[nx - reach..].iter().chain(row).enumerate().map(|(j, c)| 256 * c.x as i64 + j as i64 * drop).collect();
        let mut suffix = g.clone();
        for block in (0..len).step_by(reach) {
            for j in (block..(block + reach).min(len) - 1).rev() {
                suffix[j] = suffix[j].max(suffix[j + 1]);
            }
        }
        // The prefix maxima as the windows' last position `x + reach - 1`
        // moves right, starting again at each block's first position.
        let mut prefix = g[..reach - 1].iter().fold(i64::MIN, |m, &v| m.max(v));
        let mut in_block = reach - 1;
        let mut mask = Vec::with_capacity(nx);
        for x in 0..nx {
            let last = g[x + reach - 1];
            prefix = if in_block == 0 { last } else { prefix.max(last) };
            in_block = if in_block + 1 == reach { 0 } else { in_block + 1 };
            mask.push(suffix[x].max(prefix) > g[x + reach]);
        }
        Self::Mask(mask)
    }
}

#[cfg(not(target_arch = "spirv"))]
impl Shade for ShadowRow {
    #[inline(always)]
    fn shadowed(&self, p: &SandParams, state: &[UVec2], x: i32, z: i32) -> bool {
        match self {
            Self::Scans => shadowed(p, state, x, z),
            Self::Mask(mask) => mask[wrap(x, p.nx) as usize],
        }
    }
}

/// Phase 2: the height after the saltation (`state`'s `y`: phase 1's offset).
fn gathered(index: u32, p: &SandParams, state: &[UVec2]) -> u32 {
    let (mut xi, row) = (index % p.nx, index - index % p.nx);
    let mut h = state[index as usize].x;
    if state[index as usize].y != 0 {
        h -= 1;
    }
    let mut d = 1;
    while d <= p.window {
        xi = if xi == 0 { p.nx - 1 } else { xi - 1 };
        if state[(row + xi) as usize].y == d {
            h += 1;
        }
        d += 1;
    }
    h
}

/// Phases 1 and 2 for row `z` at once, for the CPU, which runs a row as one
/// task (the GPU runs the two phases as dispatches): `row` gets the row's
/// cells after the saltation of step `step` from `state`. Each source's
/// slab is taken from it and added where its jump ends, the same counts as
/// `gathered` sums (integer adds commute), without its scan of `window`
/// cells per cell (test `the_row_scatter_is_the_gather`).
#[cfg(not(target_arch = "spirv"))]
pub fn saltation_row(z: u32, step: u32, p: &SandParams, state: &[UVec2], row: &mut [UVec2]) {
    let first = (z * p.nx) as usize;
    for (c, s) in row.iter_mut().zip(&state[first..first + p.nx as usize]) {
        *c = UVec2::new(s.x, 0);
    }
    let keys = SaltationKeys::new(step, p.seed);
    let shade = ShadowRow::new(p, state, z);
    // The sources first, a block of the row at a time, by a loop with no
    // branch (whether a cell erodes is a coin toss, which a branch
    // mispredicts), then each source's jump.
    const BLOCK: u32 = 256;
    let mut sources = [0u32; BLOCK as usize];
    for x0 in (0..p.nx).step_by(BLOCK as usize) {
        let mut n = 0;
        for x in x0..(x0 + BLOCK).min(p.nx) {
            sources[n] = x;
            let index = z * p.nx + x;
            n += erodes(index, state[index as usize].x, &keys, p) as usize;
        }
        for &x in &sources[..n] {
            let d = jump_from(x, z, &keys, &shade, p, state);
            if d != 0 {
                // A source holds a slab (`own > 0`): no wrap below zero.
                row[x as usize].x -= 1;
                row[wrap((x + d) as i32, p.nx) as usize].x += 1;
            }
        }
    }
}

/// The 4-neighbours of `(x, z)` (wrapped around), in the order +x, -x,
/// +z, -z (directions 1 to 4).
fn neighbours(p: &SandParams, x: u32, z: u32) -> [u32; 4] {
    let row = z * p.nx;
    let xp = if x + 1 == p.nx { 0 } else { x + 1 };
    let xm = if x == 0 { p.nx - 1 } else { x - 1 };
    let zp = if z + 1 == p.nz { 0 } else { z + 1 };
    let zm = if z == 0 { p.nz - 1 } else { z - 1 };
    [row + xp, row + xm, zp * p.nx + x, zm * p.nx + x]
}

/// The direction (1 to 4: +x, -x, +z, -z) to the lowest of the
/// 4-neighbours' heights `n` (that order) if it lies more than
/// `threshold` slabs below `h`, the first in that order on ties; else 0.
#[inline(always)]
fn steepest(h: u32, n: [u32; 4], threshold: u32) -> u32 {
    let h = h as i32;
    let mut best = 0;
    let mut drop = threshold as i32;
    let mut dir = 0;
    while dir < 4 {
        let d = h - n[dir] as i32;
        if d > drop {
            best = dir as u32 + 1;
            drop = d;
        }
        dir += 1;
    }
    best
}

/// The direction cell `index` sends to under `rule` once its steepest
/// neighbour is `best`: `best`, unless the rule moves with a probability
/// and the cell's random number (`keys`: the step's) says no.
#[inline(always)]
fn sends<K: Keys>(index: u32, best: u32, rule: Relax, keys: &K) -> u32 {
    if rule.probability == u32::MAX {
        return best;
    }
    // The draw made whether or not there is a drop, and the answer
    // selected: on creep whether a cell has a drop is a coin toss, which a
    // CPU's branch mispredicted.
    let stays = keyed(index, keys.key(rule.stream)) >= rule.probability;
    if stays {
        0
    } else {
        best
    }
}

/// The direction cell `(x, z)` sends a slab to under `rule` (0: none): its
/// steepest 4-neighbour if the drop exceeds the threshold (the first in
/// the order +x, -x, +z, -z on ties).
#[inline(always)]
fn relax_choice(p: &SandParams, state: &[UVec2], x: u32, z: u32, step: u32, rule: Relax) -> u32 {
    if (x + z) & 1 != rule.colour {
        return 0;
    }
    let index = z * p.nx + x;
    let best = steepest(state[index as usize].x, neighbour_heights(p, state, x, z), rule.threshold);
    sends(index, best, rule, &StepKeys { step, seed: p.seed })
}

/// The heights of the 4-neighbours of `(x, z)` (`neighbours`' order).
#[inline(always)]
fn neighbour_heights(p: &SandParams, state: &[UVec2], x: u32, z: u32) -> [u32; 4] {
    let n = neighbours(p, x, z);
    [state[n[0] as usize].x, state[n[1] as usize].x, state[n[2] as usize].x, state[n[3] as usize].x]
}

/// Phase 3a, a round's choice: cell `index` with `y` the direction it
/// sends a slab to this round (0: none, or not of the round's colour).
pub fn relax_choose(index: u32, step: u32, p: &SandParams, state: &[UVec2], rule: Relax) -> UVec2 {
    let (x, z) = (index % p.nx, index / p.nx);
    UVec2::new(state[index as usize].x, relax_choice(p, state, x, z, step, rule))
}

/// Phase 3b, a round's moves: cell `index`'s height after the round whose
/// choices `state`'s `y` holds (`relax_choose`), and `y` cleared.
pub fn relax_apply(index: u32, p: &SandParams, state: &[UVec2]) -> UVec2 {
    relax_apply_at(index % p.nx, index / p.nx, p, state)
}

/// `relax_apply` of cell `(x, z)` (for a caller that walks rows).
#[inline(always)]
fn relax_apply_at(x: u32, z: u32, p: &SandParams, state: &[UVec2]) -> UVec2 {
    let n = neighbours(p, x, z);
    let chosen = [state[n[0] as usize].y, state[n[1] as usize].y, state[n[2] as usize].y, state[n[3] as usize].y];
    received(state[(z * p.nx + x) as usize], chosen)
}

/// A cell `own` (`y`: its choice) after a round whose 4-neighbours (+x,
/// -x, +z, -z) chose the directions `chosen`: a sender loses its slab (its
/// neighbours are of the other colour), any other cell gains one from each
/// neighbour whose choice points at it, the opposite direction (on a
/// 2-cell axis, both sides are one cell: counted once, from the side its
/// choice names; on a 1-cell axis the neighbour is this cell, which chose
/// nothing). Both sums are formed and one taken (no branch in a row loop).
#[inline(always)]
fn received(own: UVec2, chosen: [u32; 4]) -> UVec2 {
    let gained = (chosen[0] == 2) as u32 + (chosen[1] == 1) as u32 + (chosen[2] == 4) as u32 + (chosen[3] == 3) as u32;
    let h = if own.y != 0 { own.x - 1 } else { own.x + gained };
    UVec2::new(h, 0)
}

/// Cell `index` after the automaton's dispatch `counter`: dispatch 0 lays
/// the start (`start_height`), dispatch `1 + s phases + k` is phase `k` of
/// step `s`. `x` of each cell is its height (slabs), `y` what a phase
/// hands the next.
// Inlined into the CPU's loop over cells, the phase's choice (a division
// of the dispatch counter) leaves the loop: 14 % off a step (2026-12-06).
#[inline(always)]
pub fn sand_cell(index: u32, counter: u32, p: &SandParams, start: &[u32], state: &[UVec2]) -> UVec2 {
    if counter == 0 {
        return UVec2::new(start_height(index, p, start), 0);
    }
    let step = (counter - 1) / p.phases;
    let phase = (counter - 1) % p.phases;
    let own = state[index as usize];
    match phase {
        0 => UVec2::new(own.x, saltation_offset(index, step, p, state)),
        1 => UVec2::new(gathered(index, p, state), 0),
        _ if phase % 2 == 1 => relax_apply(index, p, state),
        _ => relax_choose(index, step, p, state, relax_rule(p, phase)),
    }
}

/// The rule of a step's relaxation whose choose phase is `phase` (even, at
/// least 2): relaxation `r = (phase - 2) / 2` is round `r / 2`'s colour
/// `r % 2`, avalanches for the first `avalanche_rounds` rounds, then creep.
pub fn relax_rule(p: &SandParams, phase: u32) -> Relax {
    let r = (phase - 2) / 2;
    if r / 2 < p.avalanche_rounds {
        avalanche(p, r % 2)
    } else {
        Relax { colour: r % 2, threshold: 1, probability: p.creep, stream: STREAM_RELAX + r }
    }
}

/// A relaxation's two phases (choose, then apply) for rows `z0..z0 + n` at
/// once, for the CPU, which runs a band of rows as one task (`out`: the
/// band's `n` rows after the relaxation of `state`, whose rows wrap around).
/// The choices of rows `z - 1`, `z` and `z + 1` wait in a ring of three
/// rows, at slot `(z + 1) mod 3`. One pass over the lattice where the GPU
/// makes two, the same rules (`steepest`, `sends`, `received`) on the same
/// neighbours, found in the row slices inside a row and by `neighbours` at
/// its two ends; the choice only at cells of the round's colour; the
/// rule's random stream keyed once; rows too flat to send skipped, rows
/// with no choice in or beside them copied (test
/// `a_band_relaxes_as_the_two_phases`).
#[cfg(not(target_arch = "spirv"))]
pub fn relax_rows(z0: u32, step: u32, p: &SandParams, state: &[UVec2], rule: Relax, out: &mut [UVec2]) {
    let nx = p.nx as usize;
    let keys = OneKey(stream_key(step, p.seed, rule.stream));
    let mut ring = vec![UVec2::ZERO; 3 * nx];
    // Whether a slot's row sends anything (an avalanche moves few slabs:
    // most rows see no move in the three rows around them).
    let mut sending = [false; 3];
    let row_of = |z: u32| &state[z as usize * nx..][..nx];
    // The lowest and highest cell of rows `z0 - 2 ..= z0 + n + 1`: where a
    // row's highest lies no more than the threshold above the lowest of
    // it and its two neighbour rows, none of its cells sends (avalanches
    // on ripples: most rows). Not for creep, whose threshold of one slab
    // next to no row clears.
    let extent: Vec<(u32, u32)> = if rule.probability == u32::MAX {
        (0..(out.len() / nx) as i32 + 4)
            .map(|r| {
                let row = row_of(wrap(z0 as i32 + r - 2, p.nz));
                row.iter().fold((u32::MAX, 0), |(lo, hi), c| (lo.min(c.x), hi.max(c.x)))
            })
            .collect()
    } else {
        Vec::new()
    };
    // Row `z0 + z` (z from -1) chosen into its slot.
    let choose = |ring: &mut [UVec2], sending: &mut [bool; 3], z: i32| {
        let gz = wrap(z0 as i32 + z, p.nz);
        let slot = &mut ring[((z + 1) % 3) as usize * nx..][..nx];
        let mut any = 0;
        let (row, up, down) = (row_of(gz), row_of(wrap(gz as i32 + 1, p.nz)), row_of(wrap(gz as i32 - 1, p.nz)));
        for (c, s) in slot.iter_mut().zip(row) {
            *c = UVec2::new(s.x, 0);
        }
        let r = (z + 2) as usize;
        let flat = || {
            let lowest = extent[r - 1].0.min(extent[r].0).min(extent[r + 1].0);
            extent[r].1 <= lowest.saturating_add(rule.threshold)
        };
        if !extent.is_empty() && flat() {
            sending[((z + 1) % 3) as usize] = false;
            return;
        }
        let first = ((rule.colour + gz) & 1) as usize;
        for x in (first..nx).step_by(2) {
            let index = gz * p.nx + x as u32;
            let heights = if x == 0 || x + 1 == nx {
                neighbour_heights(p, state, x as u32, gz)
            } else {
                [row[x + 1].x, row[x - 1].x, up[x].x, down[x].x]
            };
            slot[x].y = sends(index, steepest(row[x].x, heights, rule.threshold), rule, &keys);
            any |= slot[x].y;
        }
        sending[((z + 1) % 3) as usize] = any != 0;
    };
    choose(&mut ring, &mut sending, -1);
    choose(&mut ring, &mut sending, 0);
    for (z, out_row) in out.chunks_mut(nx).enumerate() {
        choose(&mut ring, &mut sending, z as i32 + 1);
        let slot = |k: usize| &ring[(z + k) % 3 * nx..][..nx];
        let (down, mid, up) = (slot(0), slot(1), slot(2));
        if sending == [false; 3] {
            // No choice to apply: each cell as it is (`received` of nothing).
            out_row.copy_from_slice(mid);
            continue;
        }
        // The row's two ends wrap; inside, each cell's row neighbours are
        // the window of three around it.
        let at = |x: usize, xp: usize, xm: usize| received(mid[x], [mid[xp].y, mid[xm].y, up[x].y, down[x].y]);
        if nx < 3 {
            for (x, c) in out_row.iter_mut().enumerate() {
                *c = at(x, (x + 1) % nx, (x + nx - 1) % nx);
            }
            continue;
        }
        out_row[0] = at(0, 1, nx - 1);
        out_row[nx - 1] = at(nx - 1, 0, nx - 2);
        let inside = out_row[1..nx - 1].iter_mut().zip(mid.windows(3)).zip(up[1..].iter().zip(&down[1..]));
        for ((c, w), (u, d)) in inside {
            *c = received(w[1], [w[2].y, w[0].y, u.y, d.y]);
        }
    }
}

/// The automaton's entry point: every cell, `state` after dispatch
/// `counter[0] - 1` to `next`; invocation 0 advances the counter (the host
/// copies `next` and `counter_next` back between dispatches: `Pass::carry`).
// One binding a buffer: the lattices, the dispatch counters, the start.
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn sand_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 57)] params: &[SandParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 58)] state: &[UVec2],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 59)] next: &mut [UVec2],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 60)] counter: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 61)] counter_next: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 118)] start: &[u32],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index >= p.cells {
        return;
    }
    let k = counter[0];
    next[index as usize] = sand_cell(index, k, p, start, state);
    if index == 0 {
        counter_next[0] = k + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(nx: u32, nz: u32) -> SandParams {
        let f = |p: f64| (p * 4294967296.0) as u32;
        SandParams {
            nx,
            nz,
            cells: nx * nz,
            seed: 3,
            phases: 2 + 4 * 3,
            avalanche_rounds: 2,
            creep_rounds: 1,
            mean_sand: 4,
            given_start: 0,
            jump: 3 * 256,
            jump_growth: 0,
            max_jump: 3,
            hops: 3,
            window: 9,
            erode: f(0.5),
            deposit_sand: f(0.6),
            deposit_bare: f(0.4),
            creep: f(0.3),
            repose: 3,
            shadow_drop: 256,
            shadow_reach: 8,
            height_bound: u32::MAX,
        }
    }

    fn run(p: &SandParams, dispatches: u32) -> Vec<UVec2> {
        let mut state = vec![UVec2::ZERO; p.cells as usize];
        for k in 0..dispatches {
            state = (0..p.cells).map(|i| sand_cell(i, k, p, &[], &state)).collect();
        }
        state
    }

    #[test]
    fn every_phase_conserves_the_sand() {
        for (nx, nz) in [(16, 8), (2, 2), (1, 6), (6, 1), (2, 4)] {
            let p = params(nx, nz);
            let mut state = run(&p, 1);
            let total: u32 = state.iter().map(|c| c.x).sum();
            for k in 1..200 {
                state = (0..p.cells).map(|i| sand_cell(i, k, &p, &[], &state)).collect();
                assert_eq!(state.iter().map(|c| c.x).sum::<u32>(), total, "{nx}x{nz}, dispatch {k}");
            }
        }
    }

    #[test]
    fn the_height_bound_changes_no_decision() {
        // Steps bounded by their highest cell against unbounded ones, on a
        // field tall enough that shadows form (a 0.4-slab fall per cell).
        let mut p = params(32, 8);
        p.mean_sand = 20;
        p.shadow_drop = 100;
        p.shadow_reach = 31;
        let mut free = run(&p, 1);
        let mut bounded = free.clone();
        for k in 1..1 + 40 * p.phases {
            let mut q = p;
            q.height_bound = bounded.iter().map(|c| c.x).max().unwrap_or(0);
            free = (0..p.cells).map(|i| sand_cell(i, k, &p, &[], &free)).collect();
            bounded = (0..p.cells).map(|i| sand_cell(i, k, &q, &[], &bounded)).collect();
            assert_eq!(free, bounded, "dispatch {k}");
        }
        // A bound that does stop scans: a crest 10 slabs above the rest.
        let mut state = vec![UVec2::new(20, 0); 32];
        state[4].x = 30;
        let mut q = params(32, 1);
        q.shadow_drop = 256;
        q.shadow_reach = 31;
        for x in 0..32 {
            let tight = SandParams { height_bound: 30, ..q };
            assert_eq!(shadowed(&tight, &state, x, 0), shadowed(&q, &state, x, 0), "cell {x}");
        }
        assert!(shadowed(&q, &state, 13, 0) && !shadowed(&q, &state, 14, 0));
    }

    #[test]
    fn a_given_start_adds_its_slabs_to_the_bed() {
        let mut p = params(4, 2);
        let start = [0, 7, 0, 0, 3, 0, 0, 1];
        let bed: Vec<u32> = (0..8).map(|i| start_height(i, &p, &start)).collect();
        assert!(bed.iter().all(|&h| (3..=5).contains(&h)), "{bed:?}");
        p.given_start = 1;
        for i in 0..8 {
            assert_eq!(start_height(i, &p, &start), bed[i as usize] + start[i as usize]);
            assert_eq!(sand_cell(i, 0, &p, &start, &[]).x, bed[i as usize] + start[i as usize]);
        }
        p.mean_sand = 0;
        assert_eq!((0..8).map(|i| start_height(i, &p, &start)).collect::<Vec<_>>(), start);
    }

    #[test]
    fn a_slab_jumps_downwind_and_lands() {
        // One tall cell on bare ground, no shadow, certain erosion and deposit.
        let mut p = params(16, 1);
        p.erode = u32::MAX;
        p.deposit_bare = u32::MAX;
        p.deposit_sand = u32::MAX;
        p.shadow_reach = 0;
        let mut state = vec![UVec2::ZERO; 16];
        state[2].x = 1;
        assert_eq!(saltation_offset(2, 0, &p, &state), 3);
        state[2].y = 3;
        assert_eq!(gathered(5, &p, &state), 1);
        assert_eq!(gathered(2, &p, &state), 0);
    }

    #[test]
    fn the_row_scatter_is_the_gather() {
        // Rows of 16 and 6 cells (jumps of up to 9 cells wrap around the
        // short one more than once), and of 600 (the row's sources are
        // found in blocks of 256 cells: two whole and one part), a tall
        // bed so that shadows form too.
        for (nx, nz) in [(16, 8), (6, 4), (1, 6), (600, 4)] {
            let mut p = params(nx, nz);
            p.mean_sand = 12;
            p.shadow_drop = 128;
            let mut state = run(&p, 1);
            for step in 0..30 {
                let k = 1 + step * p.phases;
                let offsets: Vec<UVec2> = (0..p.cells).map(|i| sand_cell(i, k, &p, &[], &state)).collect();
                let gather: Vec<UVec2> = (0..p.cells).map(|i| sand_cell(i, k + 1, &p, &[], &offsets)).collect();
                // (On a 1-cell row every jump comes back to its source.)
                assert!(nx == 1 || offsets.iter().any(|c| c.y != 0), "{nx}x{nz}: no slab moved, step {step}");
                let mut scatter = vec![UVec2::ZERO; p.cells as usize];
                for (z, row) in scatter.chunks_mut(nx as usize).enumerate() {
                    saltation_row(z as u32, step, &p, &state, row);
                }
                assert_eq!(scatter, gather, "{nx}x{nz}, step {step}");
                state = (k + 2..k + p.phases)
                    .fold(gather, |s, k| (0..p.cells).map(|i| sand_cell(i, k, &p, &[], &s)).collect());
            }
        }
    }

    #[test]
    fn a_band_relaxes_as_the_two_phases() {
        // Bands of 1, 2 and 3 rows (one shorter at the end) on lattices
        // whose axes are 1, 2 or more cells, a steep bed so that every
        // rule moves slabs; each relaxation of a step against its choose
        // and apply dispatches.
        for (nx, nz) in [(16, 8), (6, 4), (2, 2), (1, 6), (6, 1), (2, 4), (4, 5)] {
            let mut p = params(nx, nz);
            p.mean_sand = 12;
            p.repose = 2;
            let mut state: Vec<UVec2> = (0..p.cells).map(|i| UVec2::new(random(i, 9, 9, 9) % 13, 0)).collect();
            let mut moved = 0;
            for step in 0..4 {
                for phase in (2..p.phases).step_by(2) {
                    let k = 1 + step * p.phases + phase;
                    let chosen: Vec<UVec2> = (0..p.cells).map(|i| sand_cell(i, k, &p, &[], &state)).collect();
                    let applied: Vec<UVec2> = (0..p.cells).map(|i| sand_cell(i, k + 1, &p, &[], &chosen)).collect();
                    for band in 1..=3 {
                        let mut out = vec![UVec2::MAX; p.cells as usize];
                        for (b, rows) in out.chunks_mut((band * nx) as usize).enumerate() {
                            relax_rows(b as u32 * band, step, &p, &state, relax_rule(&p, phase), rows);
                        }
                        assert_eq!(out, applied, "{nx}x{nz}, step {step}, phase {phase}, bands of {band}");
                    }
                    moved += chosen.iter().filter(|c| c.y != 0).count();
                    state = applied;
                }
            }
            assert!(moved > 0, "{nx}x{nz}: nothing moved");
        }
    }

    #[test]
    fn a_row_of_shadows_is_the_scans() {
        // Rows shorter and longer than the reach (which then wraps onto
        // the row's start), falls of whole and fractional slabs per cell,
        // beds from flat to rough; every cell of every row against the scan.
        let mut shadowed_cells = 0;
        for (nx, nz) in [(1, 3), (2, 2), (6, 4), (16, 3), (64, 2), (100, 2)] {
            for reach in [0, 1, 5, 8, 31, 64] {
                for drop in [1, 100, 256, 300, 700, 2048] {
                    for spread in [1, 4, 13, 60] {
                        let mut p = params(nx, nz);
                        p.shadow_reach = reach;
                        p.shadow_drop = drop;
                        let state: Vec<UVec2> =
                            (0..p.cells).map(|i| UVec2::new(random(i, drop, reach, spread) % spread, 0)).collect();
                        for z in 0..nz {
                            let row = &state[(z * nx) as usize..][..nx as usize];
                            let ShadowRow::Mask(mask) = ShadowRow::mask(&p, row) else { panic!("no mask") };
                            for x in 0..nx as i32 {
                                let scan = shadowed(&p, &state, x, z as i32);
                                assert_eq!(mask[x as usize], scan, "{nx}x{nz}, reach {reach}, drop {drop}, x {x}");
                                shadowed_cells += scan as u32;
                            }
                        }
                    }
                }
            }
        }
        // The comparison saw both answers.
        assert!(shadowed_cells > 1000, "{shadowed_cells}");
    }

    #[test]
    fn a_crest_shadows_the_cells_behind_it() {
        let p = params(16, 1);
        let mut state = vec![UVec2::ZERO; 16];
        state[4].x = 5;
        // 1 slab per cell: the shadow falls 5 slabs over 5 cells (strictly above).
        assert!(shadowed(&p, &state, 5, 0));
        assert!(shadowed(&p, &state, 8, 0));
        assert!(!shadowed(&p, &state, 9, 0));
        assert!(!shadowed(&p, &state, 3, 0));
    }
}
