//! The CPU backend's driver: the same per-invocation kernel functions as the
//! SPIR-V entry points, called for every invocation id in parallel with rayon.

use indicatif::ProgressBar;
use rayon::prelude::*;
use slicelight_shaders::scatter::{merge_bins, CpuWords};

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

/// Invocations per turn of `scatter_each_index`: its threads take turns
/// through the range, so that a run of expensive invocations is shared.
const SCATTER_CHUNK: u32 = 256;

/// Runs `kernel(index, words)` for `count` invocations in parallel, each
/// adding into `words` with the scatter primitive, without atomics: every
/// rayon thread adds into words of its own (the first thread into `words`
/// itself, the others into zeroed copies, whose pages are only touched
/// where they are reached), and the copies are then merged into `words`
/// (`scatter::merge`). The integer sums do not depend on the split or the
/// order, so `words` ends with the bits that atomics give (and the GPU's).
pub fn scatter_each_index(
    words: &mut [u32],
    count: u32,
    progress: &ProgressBar,
    kernel: impl Fn(u32, &mut CpuWords) + Sync,
) {
    let turns = count.div_ceil(SCATTER_CHUNK);
    let threads = rayon::current_num_threads().clamp(1, turns.max(1) as usize);
    let mut copies: Vec<Vec<u32>> = (1..threads).map(|_| vec![0u32; words.len()]).collect();
    let mut all: Vec<&mut [u32]> = std::iter::once(&mut *words).chain(copies.iter_mut().map(|c| &mut c[..])).collect();
    all.par_iter_mut().enumerate().for_each(|(thread, own)| {
        let mut own = CpuWords(own);
        let mut turn = thread as u32;
        while turn < turns {
            let start = turn * SCATTER_CHUNK;
            let end = (start + SCATTER_CHUNK).min(count);
            for i in start..end {
                kernel(i, &mut own);
            }
            progress.inc((end - start) as u64);
            turn += threads as u32;
        }
    });
    for copy in &copies {
        if words.is_empty() {
            break;
        }
        words[0] = words[0].wrapping_add(copy[0]);
        // Whole bins per task (an even number of words after the first).
        words[1..].par_chunks_mut(2 * CHUNK).zip(copy[1..].par_chunks(2 * CHUNK)).for_each(|(a, b)| merge_bins(a, b));
    }
}

/// `words` seen as atomics, for kernels that accumulate with the scatter
/// primitive (`scatter::CpuAtomics`): no copy in or out.
pub fn as_atomics(words: &mut [u32]) -> &[std::sync::atomic::AtomicU32] {
    // SAFETY: `AtomicU32` has the size, alignment and bit validity of `u32`,
    // and the exclusive borrow of `words` lasts as long as this view.
    unsafe { &*(words as *mut [u32] as *const [std::sync::atomic::AtomicU32]) }
}
