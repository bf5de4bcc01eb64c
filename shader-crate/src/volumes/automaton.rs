//! The cloud automaton of Dobashi, Kaneda, Yamashita, Okita and Nishita,
//! "A simple, efficient method for realistic animation of clouds" (SIGGRAPH
//! 2000, section 4; the survey's section 3.2), after Nagel and Raschke's
//! cellular automaton: three bits per cell, vapour `hum`, phase-transition
//! activation `act` and cloud `cld`, grown by
//!
//! - `hum' = hum & !act`, `cld' = cld | act`, `act' = !act & hum & f_act`
//!   (Dobashi 2000 eqs. 1-3), `f_act` the OR of `act` over eleven
//!   neighbours: one and two cells either way along x and z, one either way
//!   and two below along y (up), as clouds grow upward (eq. 4);
//! - extinction, `cld' = cld & !(rnd < p_ext)`, and supply,
//!   `hum' = hum | (rnd < p_hum)`, `act' = act | (rnd < p_act)` (eqs. 5-7),
//!   the probabilities per cell (from the scene's ellipsoids, on the host);
//! - wind: the whole lattice shifted along x and z by the wind's whole cells
//!   each step (cells shifted in from outside are clear).
//!
//! Random numbers are a counter-based hash of (cell, step, seed, stream),
//! integers only, so both backends produce the same bits. Probabilities are
//! thresholds on the hash's 32 bits (`p * 2^32`).
//!
//! The continuous density (section 4.3): `smooth_cell`, the mean of `cld`
//! over a cube of `2 s + 1` cells a side; the volume's density is then the
//! field of metaballs at the cell centres with those weights
//! (`lattice_density`).

use crate::glam::{UVec3, UVec4, Vec3, Vec4Swizzles};
use crate::random::random;
use crate::volumes::{field, GpuVolume};
use spirv_std::spirv;

/// The cell's bits.
pub const HUM: u32 = 1;
pub const ACT: u32 = 2;
pub const CLD: u32 = 4;

/// The automaton's parameter block.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct AutomatonParams {
    /// Cells along x, y (up), z, and all of them.
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    pub cells: u32,
    pub seed: u32,
    /// Half-width `s` (cells) of the smoothing cube.
    pub smoothing: u32,
    /// Wind, 1/256 cells per step along x and z (fixed point, so that the
    /// shift at each step is the same integer on both backends).
    pub wind_x: i32,
    pub wind_z: i32,
    /// The volume the automaton fills (its index).
    pub volume: u32,
    /// Metaball radius (m) and the inverse of the sum of the field over the
    /// lattice offsets within it, so that a uniform weight `q` gives density
    /// `q`; the lattice offsets reached, per axis.
    pub radius: f32,
    pub norm: f32,
    pub reach_x: u32,
    pub reach_y: u32,
    pub reach_z: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

#[cfg(not(target_arch = "spirv"))]
mod pod {
    // SAFETY: `repr(C)` of 4-byte scalars, 64 bytes, no padding.
    unsafe impl bytemuck::Zeroable for super::AutomatonParams {}
    unsafe impl bytemuck::Pod for super::AutomatonParams {}
}

/// The wind's whole-cell shift at `step` for `v` (1/256 cells per step):
/// `floor(v (step + 1) / 256) - floor(v step / 256)`.
pub fn wind_shift(v: i32, step: u32) -> i32 {
    let a = v * (step as i32 + 1);
    let b = v * step as i32;
    (a >> 8) - (b >> 8)
}

/// Cell `(i, j, k)`'s bits in `state` (before the step's wind shift is
/// applied by the caller), 0 outside the lattice.
fn bits(p: &AutomatonParams, state: &[u32], i: i32, j: i32, k: i32) -> u32 {
    if i < 0 || j < 0 || k < 0 || i >= p.nx as i32 || j >= p.ny as i32 || k >= p.nz as i32 {
        return 0;
    }
    state[((k as u32 * p.ny + j as u32) * p.nx + i as u32) as usize]
}

/// One step of cell `index` (x fastest, then y, then z): the cell's bits at
/// `step + 1` from the lattice `state` at `step`; `probability` holds the
/// cell's thresholds `(p_hum, p_act, p_ext)` times 2^32.
pub fn automaton_cell(index: u32, step: u32, p: &AutomatonParams, state: &[u32], probability: &[UVec4]) -> u32 {
    let (i, j, k) = ((index % p.nx) as i32, ((index / p.nx) % p.ny) as i32, (index / (p.nx * p.ny)) as i32);
    // Wind: this cell takes what was upwind of it.
    let (si, sk) = (i - wind_shift(p.wind_x, step), k - wind_shift(p.wind_z, step));
    let own = bits(p, state, si, j, sk);
    let f_act = bits(p, state, si + 1, j, sk)
        | bits(p, state, si - 1, j, sk)
        | bits(p, state, si + 2, j, sk)
        | bits(p, state, si - 2, j, sk)
        | bits(p, state, si, j, sk + 1)
        | bits(p, state, si, j, sk - 1)
        | bits(p, state, si, j, sk + 2)
        | bits(p, state, si, j, sk - 2)
        | bits(p, state, si, j + 1, sk)
        | bits(p, state, si, j - 1, sk)
        | bits(p, state, si, j - 2, sk);
    // Bits as 0/1 integers (no booleans stored: both backends, one logic).
    let (hum, act, cld) = (own & 1, (own >> 1) & 1, (own >> 2) & 1);
    let not_act = act ^ 1;
    // Growth (eqs. 1-3).
    let mut next_hum = hum & not_act;
    let mut next_cld = cld | act;
    let mut next_act = not_act & hum & ((f_act >> 1) & 1);
    // Extinction and supply (eqs. 5-7).
    let t = probability[index as usize];
    if next_cld == 1 && random(index, step, p.seed, 0) < t.z {
        next_cld = 0;
    }
    if random(index, step, p.seed, 1) < t.x {
        next_hum = 1;
    }
    if random(index, step, p.seed, 2) < t.y {
        next_act = 1;
    }
    (next_hum * HUM) | (next_act * ACT) | (next_cld * CLD)
}

/// The continuous density's weight at cell `index`: the share of cells with
/// `cld` in the cube of `2 s + 1` cells a side around it (cells outside the
/// lattice count as clear), in [0, 1].
pub fn smooth_cell(index: u32, p: &AutomatonParams, state: &[u32]) -> f32 {
    let (i, j, k) = ((index % p.nx) as i32, ((index / p.nx) % p.ny) as i32, (index / (p.nx * p.ny)) as i32);
    let s = p.smoothing as i32;
    let mut count = 0u32;
    let mut dk = -s;
    while dk <= s {
        let mut dj = -s;
        while dj <= s {
            let mut di = -s;
            while di <= s {
                count += (bits(p, state, i + di, j + dj, k + dk) >> 2) & 1;
                di += 1;
            }
            dj += 1;
        }
        dk += 1;
    }
    let side = (2 * p.smoothing + 1) as f32;
    count as f32 / (side * side * side)
}

/// The density at `x` of the automaton's volume `v`: metaballs of radius
/// `p.radius` at the cell centres weighted by `smooth` (Wyvill's field,
/// `field`), normalised by `p.norm`; `(i, j, k)` is the cell holding `x`.
pub fn lattice_density(v: &GpuVolume, p: &AutomatonParams, smooth: &[f32], x: Vec3, cell: UVec3) -> f32 {
    let size = (v.max.xyz() - v.min.xyz()) / Vec3::new(p.nx as f32, p.ny as f32, p.nz as f32);
    let r2 = p.radius * p.radius;
    let mut sum = 0.0;
    let (rx, ry, rz) = (p.reach_x as i32, p.reach_y as i32, p.reach_z as i32);
    let mut dk = -rz;
    while dk <= rz {
        let k = cell.z as i32 + dk;
        let mut dj = -ry;
        while dj <= ry {
            let j = cell.y as i32 + dj;
            let mut di = -rx;
            while di <= rx {
                let i = cell.x as i32 + di;
                if i >= 0 && j >= 0 && k >= 0 && i < p.nx as i32 && j < p.ny as i32 && k < p.nz as i32 {
                    let q = smooth[((k as u32 * p.ny + j as u32) * p.nx + i as u32) as usize];
                    if q > 0.0 {
                        let c = v.min.xyz() + (Vec3::new(i as f32, j as f32, k as f32) + Vec3::splat(0.5)) * size;
                        sum += q * field((x - c).length_squared() / r2);
                    }
                }
                di += 1;
            }
            dj += 1;
        }
        dk += 1;
    }
    sum * p.norm
}

/// The automaton step's entry point: every cell, `state` at step
/// `counter[0]` to `next`; invocation 0 advances the counter into
/// `counter_next` (the host copies `next` and `counter_next` back between
/// steps: `Pass::carry`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn automaton_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 49)] params: &[AutomatonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 50)] probability: &[UVec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 51)] state: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 52)] next: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 53)] counter: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 54)] counter_next: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index >= p.cells {
        return;
    }
    let step = counter[0];
    next[index as usize] = automaton_cell(index, step, p, state, probability);
    if index == 0 {
        counter_next[0] = step + 1;
    }
}

/// The smoothing's entry point (`smooth_cell`), over the final state.
#[spirv(compute(threads(64)))]
pub fn smooth_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 49)] params: &[AutomatonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 52)] state: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 55)] smooth: &mut [f32],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index >= p.cells {
        return;
    }
    smooth[index as usize] = smooth_cell(index, p, state);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wind_shifts_add_up_to_the_wind() {
        for v in [-700, -256, -1, 0, 1, 100, 256, 300, 2048] {
            let total: i32 = (0..1000).map(|s| wind_shift(v, s)).sum();
            assert_eq!(total, (v * 1000) >> 8, "v {v}");
        }
    }
}
