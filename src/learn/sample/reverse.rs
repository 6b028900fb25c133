//! The paper's reverse process (docs/method.md section 5), alone: level 0
//! from noise in a box; each finer level from the level below, upsampled by
//! its network, noised to `upper_t_max` and denoised. Every clean estimate
//! is clamped per channel to what the features can be before the sampler
//! steps with it; the last step's rule is [`FinalStep`]. The noise of each
//! step comes from the variant's seed, the level and the step alone
//! ([`gaussian`]).

use std::sync::Arc;

use glam::IVec3;
use tch::{Device, Tensor};

use super::models::Models;
use super::options::SampleOptions;
use crate::error::{Error, Result};
use crate::learn::grid::SparseGrid;
use crate::learn::schedule::{reverse_step, reverse_times, FinalStep, Sampler, Schedule};
use crate::learn::sparse::{clamp_to_feature_ranges, SparseTensor};
use crate::level::FEATURE_CHANNELS;
use crate::util::seed::{derive_seed, Stream};

/// Standard normal noise of `rows` x 10 from SplitMix64 and Box-Muller on the
/// CPU, seeded by (variant seed, level, step): independent of libtorch's
/// global generator, of the batch and of the device, so a variant's noise is
/// the same wherever and with whatever else it is sampled.
pub(super) fn gaussian(rows: usize, seed: u64, level: usize, step: usize, device: Device) -> Tensor {
    crate::learn::noise::standard_normal(rows, FEATURE_CHANNELS, derive_seed(seed, level as u64, Stream::SamplingStep, step as u64), device)
}

/// Level 0: the dense box `box0` (lowest voxel, size, in voxels of
/// `resolution0`) filled with N(0, 1) from `seed`, denoised from t = 1 in
/// `level0_steps` steps of `level0_sampler`, pruned (mask > 0 kept).
pub(super) fn level0(models: &Models, schedule: &Schedule, resolution0: u32, box0: (IVec3, IVec3), seed: u64, opts: &SampleOptions) -> Result<SparseTensor> {
    let (lo, size) = box0;
    let bx = SparseGrid::full_box(resolution0, lo, size)?;
    let noise = gaussian(bx.len(), seed, 0, 0, models.device);
    let x = SparseTensor::new(Arc::new(bx), noise)?;
    Ok(reverse(models, schedule, 0, x, 1.0, opts.level0_steps, seed, opts.final_step, opts.level0_sampler)?.prune_by_mask()?)
}

/// Level `l` >= 1 from the pruned level below, `cur`: U_l(cur) (X_up plus
/// the learned correction, on the subdivided grid), noised to
/// `upper_t_max`, denoised from there in `upper_steps` steps, pruned.
pub(super) fn upper_level(models: &Models, schedule: &Schedule, l: usize, cur: &SparseTensor, seed: u64, opts: &SampleOptions, sampler: Sampler) -> Result<SparseTensor> {
    let up = models.upsamplers[l].as_ref().ok_or_else(|| Error::Invalid(format!("level {l} has no upsampler")))?;
    let u = up.net.forward_t(cur, false)?;
    let eps = gaussian(u.len(), seed, l, 0, models.device);
    let x = u.with_feats(schedule.add_noise(&u.feats, opts.upper_t_max, &eps))?;
    Ok(reverse(models, schedule, l, x, opts.upper_t_max, opts.upper_steps, seed, opts.final_step, sampler)?.prune_by_mask()?)
}

/// The reverse process of level `l` from `t_max` to 0 in `steps` steps,
/// its noise from `seed`; every clean estimate clamped per channel.
#[allow(clippy::too_many_arguments)]
fn reverse(
    models: &Models,
    schedule: &Schedule,
    l: usize,
    mut x: SparseTensor,
    t_max: f64,
    steps: usize,
    seed: u64,
    final_step: FinalStep,
    sampler: Sampler,
) -> Result<SparseTensor> {
    let net = &models.diffusion[l].net;
    let times = reverse_times(t_max, steps);
    for (k, w) in times.windows(2).enumerate() {
        // A stop signal ends sampling between steps (the variant is
        // sampled again, identically, by the next run).
        crate::util::interrupt::check()?;
        let x0_hat = clamp_to_feature_ranges(&net.forward_at(&x, w[0], false)?.feats);
        let noise = gaussian(x.len(), seed, l, k + 1, models.device);
        let next = reverse_step(sampler, final_step, schedule, &x.feats, &x0_hat, w[0], w[1], &noise);
        x = x.with_feats(next)?;
    }
    Ok(x)
}
