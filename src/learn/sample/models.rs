//! The networks sampling runs: each level's diffusion network and
//! upsampler, read from a training folder (or untrained, for the ladder).

use std::path::Path;

use tch::Device;

use crate::config::Config;
use crate::learn::schedule::TRAINING_PARAMETERISATION;
use crate::error::{Error, Result};
use crate::learn::nn::{new_diffusion, new_upsampler, DiffusionNet, LevelNet, Upsampler};
use crate::learn::checkpoint::{diffusion_checkpoint, diffusion_ema_checkpoint, upsampler_checkpoint};

/// The trained networks of every level, read from a training folder.
pub struct Models {
    pub config: Config,
    pub device: Device,
    /// Diffusion model of each level, coarsest first.
    pub diffusion: Vec<LevelNet<DiffusionNet>>,
    /// Upsampler of each level (`None` at level 0). With one level loaded,
    /// level 1's where it is trained: the level-0 choice uses it
    /// ([`AtExtent::thin_ratio`]).
    pub upsamplers: Vec<Option<LevelNet<Upsampler>>>,
}

impl Models {
    pub fn levels(&self) -> usize {
        self.diffusion.len()
    }
}

/// Loads the checkpoints of levels `0..levels` from `dir` (written by
/// `crate::learn::train::train_level` with the same model configuration).
pub fn load_models(dir: &Path, config: &Config, levels: usize, device: Device) -> Result<Models> {
    if levels == 0 {
        return Err(Error::Invalid("no levels to load".into()));
    }
    let mut diffusion = Vec::with_capacity(levels);
    let mut upsamplers = Vec::with_capacity(levels);
    for l in 0..levels {
        check_parameterisation(dir, l)?;
        let mut d = new_diffusion(&config.model, l, device)?;
        // The weights' moving average where training kept one.
        let p = if config.train.ema_decay > 0.0 { diffusion_ema_checkpoint(dir, l) } else { diffusion_checkpoint(dir, l) };
        if !p.exists() {
            return Err(Error::file(&p, format!("no diffusion checkpoint for level {l}: train it first")));
        }
        d.load(&p)?;
        diffusion.push(d);
        if l == 0 {
            upsamplers.push(None);
        } else {
            let mut u = new_upsampler(&config.model, device)?;
            let p = upsampler_checkpoint(dir, l);
            if !p.exists() {
                return Err(Error::file(&p, format!("no upsampler checkpoint for level {l}: train it first")));
            }
            u.load(&p)?;
            upsamplers.push(Some(u));
        }
    }
    // Sampling that stops at level 0 still counts thin parts a level finer,
    // so a variant's level 0 does not depend on where its pass stops
    // (`--stop-level 0`, then `--from`); where level 1 is not trained yet,
    // the count is off.
    let p = upsampler_checkpoint(dir, 1);
    if levels == 1 && p.exists() {
        let mut u = new_upsampler(&config.model, device)?;
        u.load(&p)?;
        upsamplers.push(Some(u));
    }
    Ok(Models { config: config.clone(), device, diffusion, upsamplers })
}

/// Refuses a level whose recorded training parameterisation is not this
/// program's (weights trained to predict something else, or under another
/// schedule or noise, would sample garbage without a word).
pub(super) fn check_parameterisation(dir: &Path, level: usize) -> Result<()> {
    let path = crate::learn::checkpoint::state_path(dir, level);
    let Some(state) = crate::learn::checkpoint::read_state(dir, level) else {
        return Err(Error::file(&path, format!("no training state for level {level}: train it first")));
    };
    if state.parameterisation != TRAINING_PARAMETERISATION {
        let was = if state.parameterisation.is_empty() { "an earlier parameterisation (not recorded)" } else { state.parameterisation.as_str() };
        return Err(Error::file(
            &path,
            format!("level {level} was trained under {was}, this program samples \"{TRAINING_PARAMETERISATION}\": train it again"),
        ));
    }
    Ok(())
}

/// Freshly initialised networks for levels `0..levels` (libtorch's generator
/// seeded with `seed` first, so the same seed gives the same networks): the
/// floor of the degradation ladder, what the method makes of noise.
pub fn untrained_models(config: &Config, levels: usize, device: Device, seed: u64) -> Result<Models> {
    if levels == 0 {
        return Err(Error::Invalid("no levels to build".into()));
    }
    tch::manual_seed(seed as i64);
    let mut diffusion = Vec::with_capacity(levels);
    let mut upsamplers = Vec::with_capacity(levels);
    for l in 0..levels {
        diffusion.push(new_diffusion(&config.model, l, device)?);
        upsamplers.push(if l == 0 { None } else { Some(new_upsampler(&config.model, device)?) });
    }
    Ok(Models { config: config.clone(), device, diffusion, upsamplers })
}
