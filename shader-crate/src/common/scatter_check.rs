//! The scatter self-check pass: a kernel whose sums are known in closed form,
//! run under heavy contention (a few bins, millions of invocations), to check
//! the scatter accumulation of `scatter.rs` on a device.
//!
//! Invocation `i` adds `((i mod 7) + 1) / 4` to bin `i mod bins`. With `bins`
//! coprime to 7 and `invocations` a multiple of `7 bins`, every bin sees each
//! residue mod 7 equally often, so every bin sums to exactly
//! `invocations / bins` (the mean contribution is `(1 + ... + 7) / 28 = 1`).
//!
//! Each invocation adds the same value again to bin `bins + (i mod bins)`
//! with `overflow_scale`, chosen by the host so that those bins pass the
//! fixed-point range: they must come out saturated, never wrapped.

#[cfg(target_arch = "spirv")]
use crate::glam::UVec3;
use crate::scatter::{scatter_add, AtomicWords};
#[cfg(target_arch = "spirv")]
use spirv_std::spirv;

#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct ScatterCheckParams {
    pub invocations: u32,
    pub bins: u32,
    /// Fixed-point units per unit (see `scatter.rs`) of the first `bins` bins.
    pub scale: f32,
    /// The same, for the `bins` bins that must saturate.
    pub overflow_scale: f32,
}

#[cfg(not(target_arch = "spirv"))]
// SAFETY: `repr(C)`, four 4-byte scalars, no padding; any bits are valid.
unsafe impl bytemuck::Zeroable for ScatterCheckParams {}
#[cfg(not(target_arch = "spirv"))]
unsafe impl bytemuck::Pod for ScatterCheckParams {}

/// What invocation `index` adds, and to which bin.
pub fn contribution(index: u32, bins: u32) -> (u32, f32) {
    (index % bins, ((index % 7) + 1) as f32 * 0.25)
}

pub fn scatter_check_invocation<A: AtomicWords + ?Sized>(index: u32, params: &ScatterCheckParams, words: &mut A) {
    let (bin, x) = contribution(index, params.bins);
    scatter_add(words, bin, x, params.scale);
    scatter_add(words, params.bins + bin, x, params.overflow_scale);
}

/// GPU only: on the host the words are `AtomicU32`s (`scatter::CpuAtomics`),
/// never a plain `[u32]`, so this adapter is not compiled there.
#[cfg(target_arch = "spirv")]
#[spirv(compute(threads(64)))]
pub fn scatter_check_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 13)] params: &[ScatterCheckParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 14)] words: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let params = &params[0];
    if index < params.invocations {
        scatter_check_invocation(index, params, words);
    }
}
