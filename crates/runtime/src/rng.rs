//! Seeded randomness per module.
//!
//! A module's RNG depends only on the host seed and the module's name, not on the order modules
//! were added or on what other modules draw: replaying one module alone reproduces its draws.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// FNV-1a: a stable hash (std's hasher may change between releases, which would change runs).
pub fn stable_hash(text: &str) -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in text.as_bytes() {
        hash ^= u64::from(*byte);
        hash = hash.wrapping_mul(0x0100_0000_01b3);
    }
    hash
}

/// The RNG handed to module `name` under host seed `seed`.
pub fn module_rng(seed: u64, name: &str) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stable_hash(name));
    rng
}

/// A separate stream for the lockstep host's processing-time model, so a module drawing more
/// or fewer random numbers does not change its own timing.
pub(crate) fn timing_rng(seed: u64, name: &str) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7469_6d69_6e67_0000);
    rng.set_stream(stable_hash(name));
    rng
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn streams_differ_by_name_and_seed_and_repeat() {
        let a = module_rng(1, "a").next_u64();
        assert_eq!(a, module_rng(1, "a").next_u64());
        assert_ne!(a, module_rng(1, "b").next_u64());
        assert_ne!(a, module_rng(2, "a").next_u64());
    }
}
