//! `[model]` and `[train]`: the networks' sizes and how they are trained.

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    pub channels: i64,
    pub upsampler_channels: i64,
    pub level0_layers: usize,
    pub level0_first_kernel: usize,
    pub level0_head_layers: usize,
    pub upper_layers: usize,
    pub upper_first_kernel: usize,
    pub upper_head_layers: usize,
    pub dropout: f64,
    pub upsampler_dropout: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    pub level0_iterations: usize,
    pub level0_batch: usize,
    pub upper_iterations: usize,
    pub upper_batch: usize,
    /// Crop edge in voxels for levels >= 1.
    pub crop: i32,
    pub upsampler_iterations: usize,
    pub lr: f64,
    pub upsampler_lr: f64,
    pub grad_clip: f64,
    /// Levels >= 1 use t in [0, upper_t_max].
    pub upper_t_max: f64,
    /// The forward process: only the released code's, x_t = alpha x0 + sigma
    /// eps (docs/configuration.md). Kept as a recorded setting so that the
    /// digests of existing runs stay valid.
    #[serde(default)]
    pub mixing: Mixing,
    /// Learning-rate schedule of every phase: linear warm-up over this many
    /// steps, then cosine decay to `lr_final_ratio` times the rate at the
    /// phase's last step (0 and 1.0: a constant rate, the paper's).
    #[serde(default)]
    pub lr_warmup_steps: usize,
    #[serde(default = "one_f64")]
    pub lr_final_ratio: f64,
    /// Exponential moving average of the diffusion weights, used for
    /// sampling: per step, ema = decay * ema + (1 - decay) * weights
    /// (0: none, sampling uses the last weights).
    #[serde(default)]
    pub ema_decay: f64,
    /// Mixed precision: the diffusion model's convolutions multiply in bf16
    /// during training (weights, optimiser and activations stay f32). Off:
    /// not written, so the digests of existing runs stay valid.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub bf16: bool,
    pub checkpoint_minutes: f64,
    pub seed: u64,
}

/// What the diffusion model is trained to undo. The paper's mixing of x0
/// with the upsampled coarse level ("paper") was trained but never sampled,
/// and is gone; a configuration that asks for it is refused.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mixing {
    /// x_t = alpha(t) x0 + sigma(t) eps, as the released code.
    #[default]
    Code,
}

/// A serde default of 1 (ratios that are neutral at 1).
fn one_f64() -> f64 {
    1.0
}
