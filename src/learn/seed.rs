//! Seeds derived from the run's one seed: every random choice of training and
//! sampling draws from its own stream, keyed by what it is for, so a run is a
//! pure function of its configuration, a resumed run sees the data the
//! uninterrupted one would, and any shard of variants reproduces one run.

use crate::util::rng::Rng;

/// What a derived seed is for. The numbers are part of every recorded result:
/// never renumber them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u64)]
pub enum Stream {
    /// libtorch's generator before the networks are initialised.
    Init = 0,
    /// One upsampler training step.
    UpsamplerStep = 1,
    /// One diffusion training step (crop centres, times, noise).
    DiffusionStep = 2,
    /// The seed of one variant.
    Variant = 7,
    /// The noise of one sampling step of one variant.
    SamplingStep = 8,
    /// The random draws of detail transfer (one variant, one level).
    Transfer = 9,
    /// The noise of one level-0 candidate of a variant (after the first).
    Level0Candidate = 10,
    /// The noise eps of one diffusion training step.
    TrainingNoise = 11,
    /// The seed of one more coarse-to-fine attempt of a variant.
    StructureAttempt = 12,
}

/// SplitMix64 of the tuple (seed, index, stream, step): `index` is the level
/// or the variant. Non-negative as i64 (libtorch's `manual_seed` takes i64).
pub fn derive_seed(seed: u64, index: u64, stream: Stream, step: u64) -> u64 {
    let mut r = Rng::new(seed ^ 0x5348_4150_4553_4846);
    let mut h = r.next_u64();
    for v in [index, stream as u64, step] {
        h = Rng::new(h ^ v.wrapping_mul(0x9E37_79B9_7F4A_7C15)).next_u64();
    }
    h >> 1
}

/// Standard normal noise of `rows` x `cols` from SplitMix64 and Box-Muller on
/// the CPU, from `seed` alone: independent of libtorch's global generator, of
/// the threads and of the device, so the same seed gives the same noise
/// wherever it is drawn.
pub fn standard_normal(rows: usize, cols: usize, seed: u64, device: tch::Device) -> tch::Tensor {
    let mut rng = Rng::new(seed);
    let n = rows * cols;
    let mut v = Vec::with_capacity(n + 1);
    while v.len() < n {
        // Box-Muller: two normals from two uniforms in (0, 1].
        let u1 = 1.0 - rng.uniform();
        let u2 = rng.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let a = std::f64::consts::TAU * u2;
        v.push((r * a.cos()) as f32);
        v.push((r * a.sin()) as f32);
    }
    v.truncate(n);
    tch::Tensor::from_slice(&v).view([rows as i64, cols as i64]).to_device(device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_differ_and_repeat() {
        let a = derive_seed(7, 1, Stream::DiffusionStep, 3);
        assert_eq!(a, derive_seed(7, 1, Stream::DiffusionStep, 3));
        assert_ne!(a, derive_seed(7, 1, Stream::UpsamplerStep, 3));
        assert_ne!(a, derive_seed(7, 2, Stream::DiffusionStep, 3));
        assert_ne!(a, derive_seed(7, 1, Stream::DiffusionStep, 4));
        assert_ne!(a, derive_seed(8, 1, Stream::DiffusionStep, 3));
        assert!((a as i64) >= 0);
    }
}
