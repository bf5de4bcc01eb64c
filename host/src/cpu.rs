//! The CPU backend's driver: the same per-invocation kernel functions as the
//! SPIR-V entry points, called for every invocation id in parallel with rayon.

use indicatif::ProgressBar;
use rayon::prelude::*;
use slicelight_shaders::scatter::{merge_bins, AtomicWords, CpuAtomics, CpuWords};

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

/// A kernel that adds into words with the scatter primitive
/// (`scatter::scatter_add`), for `scatter_each_index`: invocation `index`
/// through whichever words the driver hands it.
pub trait ScatterKernel: Sync {
    fn run<A: AtomicWords + ?Sized>(&self, index: u32, words: &mut A);
}

/// Most memory `scatter_each_index` gives the threads' copies, all together.
const MAX_COPY_BYTES: usize = 256 << 20;

/// Runs `kernel` for `count` invocations in parallel, each adding into
/// `words` with the scatter primitive, without atomics: every rayon thread
/// adds into words of its own (the first thread into `words` itself, the
/// others into zeroed copies, whose pages are only touched where they are
/// reached), and the copies are then merged into `words` (`scatter::merge`,
/// here by runs of bins in parallel). The integer sums do not depend on the
/// split or the order, so `words` ends with the bits that atomics give (and
/// the GPU's). Where the copies would take more than `MAX_COPY_BYTES`
/// (large maps, many threads), all threads add into `words` through
/// atomics instead (`CpuAtomics`): the same bits.
pub fn scatter_each_index(words: &mut [u32], count: u32, progress: &ProgressBar, kernel: &impl ScatterKernel) {
    scatter_within(words, count, progress, MAX_COPY_BYTES, kernel)
}

/// `scatter_each_index` with copies of at most `max_copy_bytes` in all.
fn scatter_within(
    words: &mut [u32],
    count: u32,
    progress: &ProgressBar,
    max_copy_bytes: usize,
    kernel: &impl ScatterKernel,
) {
    let turns = count.div_ceil(SCATTER_CHUNK);
    let threads = rayon::current_num_threads().clamp(1, turns.max(1) as usize);
    if (threads - 1).saturating_mul(words.len() * 4) > max_copy_bytes {
        let atomics = as_atomics(words);
        for_each_index(count, progress, |i| kernel.run(i, &mut CpuAtomics(atomics)));
        return;
    }
    let mut copies: Vec<Vec<u32>> = (1..threads).map(|_| vec![0u32; words.len()]).collect();
    let mut all: Vec<&mut [u32]> = std::iter::once(&mut *words).chain(copies.iter_mut().map(|c| &mut c[..])).collect();
    all.par_iter_mut().enumerate().for_each(|(thread, own)| {
        let mut own = CpuWords(own);
        let mut turn = thread as u32;
        while turn < turns {
            let start = turn * SCATTER_CHUNK;
            let end = (start + SCATTER_CHUNK).min(count);
            for i in start..end {
                kernel.run(i, &mut own);
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

#[cfg(test)]
mod tests {
    use super::*;
    use slicelight_shaders::scatter::{scatter_add, words_for};

    /// The scatter driver gives the bits of one thread adding through
    /// atomics, with the threads' copies merged and with the atomics it
    /// falls back to: 100 000 invocations of a toy kernel adding values
    /// that carry out of the low words into 37 bins, rejected ones among
    /// them. Leaving a copy unmerged makes it fail.
    #[test]
    fn the_scatter_driver_gives_the_atomics_bits() {
        struct Toy;
        impl ScatterKernel for Toy {
            fn run<A: AtomicWords + ?Sized>(&self, i: u32, words: &mut A) {
                let x = if i.is_multiple_of(97) { -1.0 } else { (i % 1013) as f32 * 1.37e6 };
                scatter_add(words, (i * 7919) % 37, x, 1.0);
            }
        }
        let count = 100_000;
        let mut serial = vec![0u32; words_for(37) as usize];
        {
            let atomics = as_atomics(&mut serial);
            for i in 0..count {
                Toy.run(i, &mut CpuAtomics(atomics));
            }
        }
        for max_copy_bytes in [0, usize::MAX] {
            let mut words = vec![0u32; words_for(37) as usize];
            scatter_within(&mut words, count, &ProgressBar::hidden(), max_copy_bytes, &Toy);
            assert_eq!(words, serial, "copies up to {max_copy_bytes} bytes");
        }
        assert!(serial[0] > 0 && serial.iter().skip(2).step_by(2).any(|&high| high > 0));
    }
}
