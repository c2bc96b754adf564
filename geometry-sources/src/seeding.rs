//! Deterministic parallel random generation.
//!
//! `sample(n, seed)` must return the same batch on any number of threads. Work is therefore split into
//! fixed-size chunks, and chunk `c` draws from its own ChaCha8 stream `c` of a generator seeded from
//! `(seed, salt)`; rayon only decides *which thread* runs a chunk, never what the chunk draws.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Items generated per chunk (and per RNG stream).
pub(crate) const CHUNK: usize = 1024;

/// The generator of chunk `chunk` for `(seed, salt)`. Different `salt`s give unrelated streams, so
/// one sampling call can have several independent random phases.
pub(crate) fn chunk_rng(seed: u64, salt: u64, chunk: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ salt.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.set_stream(chunk);
    rng
}

/// Generates `n` items in parallel: chunk `c` covers items `c * CHUNK ..` and calls
/// `f(rng, count)` which must return exactly `count` items. The result is independent of the thread
/// count.
pub(crate) fn par_generate<T, F>(n: usize, seed: u64, salt: u64, f: F) -> Vec<T>
where
    T: Send,
    F: Fn(&mut ChaCha8Rng, usize) -> Vec<T> + Sync,
{
    let chunks = n.div_ceil(CHUNK);
    let parts: Vec<Vec<T>> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let count = CHUNK.min(n - c * CHUNK);
            f(&mut chunk_rng(seed, salt, c as u64), count)
        })
        .collect();
    parts.into_iter().flatten().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn same_result_on_one_and_many_threads() {
        let gen_ = || par_generate(5000, 7, 1, |rng, k| (0..k).map(|_| rng.random::<u32>()).collect());
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(gen_);
        let many = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap().install(gen_);
        assert_eq!(one.len(), 5000);
        assert_eq!(one, many);
        let other_seed = par_generate(5000, 8, 1, |rng, k| (0..k).map(|_| rng.random::<u32>()).collect());
        assert_ne!(one, other_seed);
    }
}
