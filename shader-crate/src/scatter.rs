//! Scatter accumulation: many invocations adding into shared bins, with a
//! result that does not depend on the order of the additions, so that the
//! GPU (atomics on a storage buffer) and the CPU backend (real `AtomicU32`s
//! under rayon) agree bit for bit.
//!
//! # Format
//! A bin is a 64-bit unsigned fixed-point number kept in two 32-bit words
//! `[low, high]`: value = `(high * 2^32 + low) / scale`. A contribution `x`
//! (non-negative) becomes the integer `trunc(x * scale)` (one f32 multiply,
//! correctly rounded on both backends, then truncation toward zero), which
//! is added to `low` with an atomic add; when that add wraps, the carry goes
//! into `high`. Integer addition is associative, so the bin's final value
//! is the exact sum of the quantised contributions in any order.
//!
//! # Range and resolution
//! Resolution is `1 / scale` per contribution (each is truncated, so a sum of
//! `n` contributions is low by at most `n / scale`). The range is
//! `SATURATED_HIGH * 2^32 / scale` = `2^63 / scale`: with `scale = 2^24`,
//! sums up to 5.5e11 at a resolution of 6e-8.
//!
//! # Overflow
//! `high` is updated with a saturating compare-and-swap: a bin whose sum would
//! pass `2^63` fixed-point units stays at `high = SATURATED_HIGH`, which
//! `decode` reports as saturated, never wraps. A single contribution too large
//! to convert (`x * scale >= 2^62`) saturates its bin at once. Contributions
//! that are negative or NaN are not added; they are counted in word 0 of the
//! buffer (`REJECTED_WORD`) so the host can report them.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// Word 0 of an accumulation buffer counts rejected (negative or NaN)
/// contributions; bin `b` occupies words `1 + 2b` (low) and `2 + 2b` (high).
pub const REJECTED_WORD: u32 = 0;
/// `high` of a saturated bin: `2^31`, i.e. the bin holds at least `2^63 / scale`.
pub const SATURATED_HIGH: u32 = 1 << 31;

/// Words of a buffer holding `bins` bins.
pub const fn words_for(bins: u32) -> u32 {
    1 + 2 * bins
}

/// 32-bit words that many invocations update atomically.
pub trait AtomicWords {
    /// Adds `value` to word `index` (wrapping) and returns the previous value.
    fn fetch_add(&mut self, index: u32, value: u32) -> u32;
    /// Stores `new` at word `index` if it holds `expected`; returns what it held.
    fn compare_exchange(&mut self, index: u32, expected: u32, new: u32) -> u32;
}

#[cfg(target_arch = "spirv")]
impl AtomicWords for [u32] {
    fn fetch_add(&mut self, index: u32, value: u32) -> u32 {
        use spirv_std::memory::{Scope, Semantics};
        // SAFETY: a storage-buffer word. Queue-family scope (every invocation
        // of the dispatch; device scope would need VulkanMemoryModelDeviceScope),
        // no ordering needed
        // (the sums are read only after the dispatch ends).
        unsafe {
            spirv_std::arch::atomic_i_add::<u32, { Scope::QueueFamily as u32 }, { Semantics::NONE.bits() }>(
                &mut self[index as usize],
                value,
            )
        }
    }

    fn compare_exchange(&mut self, index: u32, expected: u32, new: u32) -> u32 {
        use spirv_std::memory::{Scope, Semantics};
        // SAFETY: as for `fetch_add`.
        unsafe {
            spirv_std::arch::atomic_compare_exchange::<
                u32,
                { Scope::QueueFamily as u32 },
                { Semantics::NONE.bits() },
                { Semantics::NONE.bits() },
            >(&mut self[index as usize], new, expected)
        }
    }
}

/// The CPU backend's words: real atomics, shared by every rayon thread.
#[cfg(not(target_arch = "spirv"))]
#[derive(Copy, Clone)]
pub struct CpuAtomics<'a>(pub &'a [core::sync::atomic::AtomicU32]);

#[cfg(not(target_arch = "spirv"))]
impl AtomicWords for CpuAtomics<'_> {
    fn fetch_add(&mut self, index: u32, value: u32) -> u32 {
        self.0[index as usize].fetch_add(value, core::sync::atomic::Ordering::Relaxed)
    }

    fn compare_exchange(&mut self, index: u32, expected: u32, new: u32) -> u32 {
        match self.0[index as usize].compare_exchange(
            expected,
            new,
            core::sync::atomic::Ordering::Relaxed,
            core::sync::atomic::Ordering::Relaxed,
        ) {
            Ok(v) | Err(v) => v,
        }
    }
}

/// Words one CPU thread owns alone: plain adds, no atomics. Each thread
/// adds into its own words and `merge` sums them after: the bins' integer
/// sums do not depend on how the contributions were split or ordered, so
/// the merged words are the bits `CpuAtomics` (and the GPU) give.
#[cfg(not(target_arch = "spirv"))]
pub struct CpuWords<'a>(pub &'a mut [u32]);

#[cfg(not(target_arch = "spirv"))]
impl AtomicWords for CpuWords<'_> {
    fn fetch_add(&mut self, index: u32, value: u32) -> u32 {
        let w = &mut self.0[index as usize];
        let old = *w;
        *w = old.wrapping_add(value);
        old
    }

    fn compare_exchange(&mut self, index: u32, expected: u32, new: u32) -> u32 {
        let w = &mut self.0[index as usize];
        let old = *w;
        if old == expected {
            *w = new;
        }
        old
    }
}

/// Adds the words `from` (a buffer of the same layout, filled by the
/// scatter primitive) into `into`: the rejected counts, and each bin's
/// 64-bit sum with the carry out of `low` and `high` saturating at
/// `SATURATED_HIGH`. `low` wraps as the atomic adds wrap it, and a
/// saturated `high` stays so: the result is the words that every
/// contribution of both added into one buffer would hold, bit for bit.
#[cfg(not(target_arch = "spirv"))]
pub fn merge(into: &mut [u32], from: &[u32]) {
    assert_eq!(into.len(), from.len(), "merging buffers of different sizes");
    if into.is_empty() {
        return;
    }
    into[0] = into[0].wrapping_add(from[0]);
    merge_bins(&mut into[1..], &from[1..]);
}

/// `merge` of whole bins (`[low, high]` pairs, no rejected count).
#[cfg(not(target_arch = "spirv"))]
pub fn merge_bins(into: &mut [u32], from: &[u32]) {
    for (a, b) in into.as_chunks_mut::<2>().0.iter_mut().zip(from.as_chunks::<2>().0) {
        if b[0] == 0 && b[1] == 0 {
            continue;
        }
        let low = a[0] as u64 + b[0] as u64;
        a[0] = low as u32;
        let high = a[1] as u64 + b[1] as u64 + (low >> 32);
        a[1] = high.min(SATURATED_HIGH as u64) as u32;
    }
}

/// `high + add`, stopping at `SATURATED_HIGH`, with a compare-and-swap loop
/// (carries are rare next to the adds on `low`, so the loop rarely repeats).
fn add_high<A: AtomicWords + ?Sized>(words: &mut A, index: u32, add: u32) {
    let mut expected = 0;
    loop {
        let new = if expected >= SATURATED_HIGH || add >= SATURATED_HIGH - expected {
            SATURATED_HIGH
        } else {
            expected + add
        };
        let seen = words.compare_exchange(index, expected, new);
        if seen == expected {
            return;
        }
        expected = seen;
    }
}

/// Adds `x` (any unit; non-negative) to bin `bin`, in fixed point with
/// `scale` units per unit of `x` (see the module docs).
pub fn scatter_add<A: AtomicWords + ?Sized>(words: &mut A, bin: u32, x: f32, scale: f32) {
    if x.is_nan() || x < 0.0 {
        words.fetch_add(REJECTED_WORD, 1);
        return;
    }
    let v = x * scale;
    let low_word = 1 + 2 * bin;
    let high_word = low_word + 1;
    // 2^62: beyond it the high part alone could reach SATURATED_HIGH.
    if v >= 4.611_686e18 {
        add_high(words, high_word, SATURATED_HIGH);
        return;
    }
    let (high, low) = if v < 4_294_967_296.0 {
        (0, v as u32)
    } else {
        // v >= 2^32 has an ulp of at least 2^9, so both parts are exact.
        let h = (v * (1.0 / 4_294_967_296.0)).floor();
        (h as u32, (v - h * 4_294_967_296.0) as u32)
    };
    let mut carry = 0;
    if low != 0 {
        let old = words.fetch_add(low_word, low);
        if old > u32::MAX - low {
            carry = 1;
        }
    }
    if high + carry != 0 {
        add_high(words, high_word, high + carry);
    }
}

/// A bin's value from its two words: `(sum / scale, saturated)`.
#[cfg(not(target_arch = "spirv"))]
pub fn decode(low: u32, high: u32, scale: f32) -> (f64, bool) {
    if high >= SATURATED_HIGH {
        return ((SATURATED_HIGH as f64) * 4_294_967_296.0 / scale as f64, true);
    }
    (((high as u64) << 32 | low as u64) as f64 / scale as f64, false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::sync::atomic::AtomicU32;

    fn words(bins: u32) -> Vec<AtomicU32> {
        (0..words_for(bins)).map(|_| AtomicU32::new(0)).collect()
    }

    #[test]
    fn carries_reach_the_high_word() {
        let w = words(1);
        let mut a = CpuAtomics(&w);
        // 3 x (2^31 + 5) units: two carries out of the low word.
        for _ in 0..3 {
            scatter_add(&mut a, 0, 2_147_483_653.0, 1.0);
        }
        let (v, sat) = decode(
            w[1].load(core::sync::atomic::Ordering::Relaxed),
            w[2].load(core::sync::atomic::Ordering::Relaxed),
            1.0,
        );
        // 2^31 + 5 is not an f32: it rounds to 2^31 + 0 (ulp 256).
        assert_eq!(v, 3.0 * 2_147_483_648.0);
        assert!(!sat);
    }

    #[test]
    fn large_single_contributions_split_exactly() {
        let w = words(1);
        let mut a = CpuAtomics(&w);
        let x = 1.5e15f32;
        scatter_add(&mut a, 0, x, 1.0);
        let (v, _) = decode(
            w[1].load(core::sync::atomic::Ordering::Relaxed),
            w[2].load(core::sync::atomic::Ordering::Relaxed),
            1.0,
        );
        assert_eq!(v, x as f64);
    }

    #[test]
    fn overflow_saturates_and_rejects_are_counted() {
        let w = words(2);
        let mut a = CpuAtomics(&w);
        for _ in 0..5 {
            scatter_add(&mut a, 0, 3.0e18, 1.0);
        }
        scatter_add(&mut a, 1, 1e30, 1.0);
        scatter_add(&mut a, 1, -1.0, 1.0);
        scatter_add(&mut a, 1, f32::NAN, 1.0);
        let load = |i: usize| w[i].load(core::sync::atomic::Ordering::Relaxed);
        assert!(decode(load(1), load(2), 1.0).1, "bin 0 should saturate, not wrap");
        assert!(decode(load(3), load(4), 1.0).1);
        assert_eq!(load(0), 2);
    }

    /// Contributions split among four threads' own words and merged give
    /// the words of one atomic buffer that took them all, bit for bit:
    /// small values, values that carry out of `low`, values past 2^32
    /// units, bins driven to saturation, rejected values. Without the carry
    /// or the saturation in `merge_bins` it fails.
    #[test]
    fn merged_thread_words_are_the_atomic_words() {
        let bins = 8u32;
        let atomic = words(bins);
        let mut parts = vec![vec![0u32; words_for(bins) as usize]; 4];
        // A counter-based hash (splitmix64) picks each contribution.
        let hash = |i: u64| {
            let mut z = i.wrapping_add(0x9e37_79b9_7f4a_7c15);
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        };
        for i in 0..4000u64 {
            let h = hash(i);
            let bin = (h % bins as u64) as u32;
            let x = match (h >> 8) % 6 {
                0 => ((h >> 16) % 1000) as f32 * 0.37,
                1 => 3.9e9 + ((h >> 16) % 1000) as f32 * 1e6,
                2 => 7.5e12,
                // Bin 7 only: enough to pass 2^63 units.
                3 if bin == 7 => 4.0e18,
                4 => -1.0,
                _ => ((h >> 16) % 100_000) as f32,
            };
            scatter_add(&mut CpuAtomics(&atomic), bin, x, 1.0);
            scatter_add(&mut CpuWords(&mut parts[(i % 4) as usize]), bin, x, 1.0);
        }
        let mut merged = vec![0u32; words_for(bins) as usize];
        for part in &parts {
            merge(&mut merged, part);
        }
        let atomic: Vec<u32> = atomic.iter().map(|w| w.load(core::sync::atomic::Ordering::Relaxed)).collect();
        assert_eq!(merged, atomic);
        // The cases were reached: a saturated bin, a bin past 2^32 units, rejects.
        assert!(decode(atomic[15], atomic[16], 1.0).1);
        assert!((1..bins as usize).any(|b| atomic[2 * b] != 0 && atomic[2 * b] < SATURATED_HIGH));
        assert!(atomic[0] > 0);
    }
}
