//! Counter-based random numbers: the 32 random bits of `(cell, step,
//! seed, stream)` from an integer hash, the same on every backend, so
//! that the simulations (the cloud automaton, the sand automaton, the
//! smoke's puffs) agree bit for bit between the GPU and the CPU.

/// A 32-bit integer hash (Wellons' "lowbias32"): every output bit depends
/// on every input bit; integer operations only.
pub fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// The random 32 bits of `(cell, step, seed, stream)`.
pub fn random(cell: u32, step: u32, seed: u32, stream: u32) -> u32 {
    keyed(cell, stream_key(step, seed, stream))
}

/// The part of `random` that does not depend on the cell: a loop over
/// cells computes it once (`keyed`), three hashes fewer per number.
pub fn stream_key(step: u32, seed: u32, stream: u32) -> u32 {
    hash(step ^ hash(seed ^ hash(stream)))
}

/// `random(cell, step, seed, stream)` from its `stream_key(step, seed, stream)`.
pub fn keyed(cell: u32, key: u32) -> u32 {
    hash(cell ^ key)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_bits_are_balanced() {
        // Each of the 32 output bits is set in half of 2^16 consecutive
        // counters, within 4 standard deviations (128 * 4).
        for bit in 0..32 {
            let ones = (0..1u32 << 16).filter(|&x| random(x, 7, 1, 0) >> bit & 1 == 1).count() as i64;
            assert!((ones - (1 << 15)).abs() < 512, "bit {bit}: {ones}");
        }
    }
}
