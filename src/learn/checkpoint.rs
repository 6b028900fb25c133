//! What training leaves in a models folder, named once for training, sampling
//! and the pipeline: the weights of each level's networks (safetensors), its
//! training state and its loss plot.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Checkpoint of level `level`'s diffusion model in `dir`.
pub fn diffusion_checkpoint(dir: &Path, level: usize) -> PathBuf {
    dir.join(format!("level_{level}_diffusion.safetensors"))
}
/// The moving average of level `level`'s diffusion weights in `dir` (what
/// sampling uses when `train.ema_decay` > 0).
pub fn diffusion_ema_checkpoint(dir: &Path, level: usize) -> PathBuf {
    dir.join(format!("level_{level}_diffusion_ema.safetensors"))
}
/// Checkpoint of level `level`'s upsampler in `dir` (levels >= 1).
pub fn upsampler_checkpoint(dir: &Path, level: usize) -> PathBuf {
    dir.join(format!("level_{level}_upsampler.safetensors"))
}
/// Adam's moments for a phase of level `level`'s training in `dir`
/// (`network`: "diffusion" or "upsampler"), so a resumed training continues
/// exactly.
pub fn optimiser_checkpoint(dir: &Path, level: usize, network: &str) -> PathBuf {
    dir.join(format!("level_{level}_{network}_adam.safetensors"))
}
/// Training state of level `level` in `dir`.
pub fn state_path(dir: &Path, level: usize) -> PathBuf {
    dir.join(format!("level_{level}_state.json"))
}
/// Libtorch threads granted to level `level`'s training process in `dir` (a
/// number in a text file), written by the process that started it when the
/// other levels' processes have ended and their cores are free; read while
/// the level trains, removed when it ends.
pub fn thread_grant_path(dir: &Path, level: usize) -> PathBuf {
    dir.join(format!("level_{level}_threads.txt"))
}
/// Loss plot of level `level` in `dir`.
pub fn loss_plot_path(dir: &Path, level: usize) -> PathBuf {
    dir.join(format!("level_{level}_loss.png"))
}

/// What `level_K_state.json` holds.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct TrainState {
    pub level: usize,
    /// [`crate::learn::train::resume_digest`] of the configuration that trained it.
    pub config_digest: String,
    /// Full digest of that configuration (for the record).
    pub full_config_digest: String,
    pub upsampler_steps: usize,
    pub diffusion_steps: usize,
    /// Loss of every step, in order.
    pub upsampler_loss: Vec<f32>,
    pub diffusion_loss: Vec<f32>,
    /// Training time so far (all sessions), seconds.
    pub seconds: f64,
    pub finished: bool,
    pub note: String,
    /// [`crate::learn::schedule::TRAINING_PARAMETERISATION`] of the program
    /// that trained it (empty: before it was recorded); sampling refuses
    /// weights trained under another.
    #[serde(default)]
    pub parameterisation: String,
}

/// The training state recorded for `level` in `dir`, if one is there and reads.
pub fn read_state(dir: &Path, level: usize) -> Option<TrainState> {
    serde_json::from_str(&std::fs::read_to_string(state_path(dir, level)).ok()?).ok()
}
