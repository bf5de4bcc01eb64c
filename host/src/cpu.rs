//! The CPU backend's driver: the same per-invocation kernel functions as the
//! SPIR-V entry points, called for every invocation id in parallel with rayon.

use indicatif::ProgressBar;
use rayon::prelude::*;

/// Invocations per rayon task; the progress bar advances once per chunk, so
/// that counting progress costs nothing next to the kernels.
const CHUNK: usize = 4096;

/// Runs `kernel(index, &mut value)` for every element of `out` in parallel,
/// `index` counting from `first`.
pub fn for_each_invocation<T: Send>(
    out: &mut [T],
    first: u32,
    progress: &ProgressBar,
    kernel: impl Fn(u32, &mut T) + Sync,
) {
    out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, chunk)| {
        let start = first as usize + c * CHUNK;
        for (k, value) in chunk.iter_mut().enumerate() {
            kernel((start + k) as u32, value);
        }
        progress.inc(chunk.len() as u64);
    });
}

/// Runs `kernel(index)` for `count` invocations in parallel (kernels that
/// scatter into shared atomics rather than write one value each).
pub fn for_each_index(count: u32, progress: &ProgressBar, kernel: impl Fn(u32) + Sync) {
    (0..count.div_ceil(CHUNK as u32)).into_par_iter().for_each(|c| {
        let start = c * CHUNK as u32;
        let end = (start + CHUNK as u32).min(count);
        for i in start..end {
            kernel(i);
        }
        progress.inc((end - start) as u64);
    });
}

/// As `for_each_invocation`, for a kernel with two outputs per invocation.
pub fn for_each_invocation2<T: Send, U: Send>(
    a: &mut [T],
    b: &mut [U],
    first: u32,
    progress: &ProgressBar,
    kernel: impl Fn(u32, &mut T, &mut U) + Sync,
) {
    a.par_chunks_mut(CHUNK).zip(b.par_chunks_mut(CHUNK)).enumerate().for_each(|(c, (ca, cb))| {
        let start = first as usize + c * CHUNK;
        for (k, (va, vb)) in ca.iter_mut().zip(cb.iter_mut()).enumerate() {
            kernel((start + k) as u32, va, vb);
        }
        progress.inc(ca.len() as u64);
    });
}

/// `words` seen as atomics, for kernels that accumulate with the scatter
/// primitive (`scatter::CpuAtomics`): no copy in or out.
pub fn as_atomics(words: &mut [u32]) -> &[std::sync::atomic::AtomicU32] {
    // SAFETY: `AtomicU32` has the size, alignment and bit validity of `u32`,
    // and the exclusive borrow of `words` lasts as long as this view.
    unsafe { &*(words as *mut [u32] as *const [std::sync::atomic::AtomicU32]) }
}
