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
    /// The bend of one attempt of a variant that starts from the exemplar
    /// bent (`level::warp`).
    Bend = 13,
    /// The extent of one pass of a variant that starts from a resized box
    /// (`level::resize`).
    Resize = 14,
    /// The dropout masks of one part of one diffusion training step
    /// (`step` is the step; `index` the level, the part in the top bits).
    TrainingDropout = 15,
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
