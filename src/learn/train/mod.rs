//! @brief Training one level of the hierarchy (docs/method.md section 4): the level's
//! upsampler U_l first (levels >= 1), then its diffusion model M_l.
//!
//! Data (all built once from the exemplar's levels, on `device`):
//! - level 0: the DENSE box over the active voxels, with the flooded target of
//!   [`flood_blur`]; a step sees `level0_batch` copies of the whole box, each with its
//!   own t ~ U[0, 1];
//! - levels >= 1: the subdivided coarse ground truth; children active in the fine
//!   ground truth get their true features (mask +1), the others keep X_up's features
//!   with mask -1 ([`flooded_target`]). The upsampler learns the whole grid (MSE to
//!   that target); the diffusion model learns random `crop`^3 crops centred on random
//!   active fine voxels, `upper_batch` per step, t ~ U[0, upper_t_max].
//!
//! The forward process is x_t = alpha(t) x0 + sigma(t) eps ([`Schedule`], the
//! released code's; the paper's mixing of x0 with U_l(coarse) is not used). The
//! loss is the MSE between M_l(x_t, t) and x0 over all voxels and channels.
//!
//! Reproducibility: every step reseeds libtorch's generator and its own crop/time
//! generator from (seed, level, phase, step), so a run is a pure function of the
//! configuration, and a resumed run sees exactly the data the uninterrupted one
//! would; Adam's moments are checkpointed with the weights ([`optim::Adam`]), so a
//! training stopped and resumed ends exactly where an uninterrupted one ends.
//!
//! Files in `out_dir` (all written atomically: temporary name, then rename):
//! `level_K_diffusion.safetensors`, `level_K_diffusion_ema.safetensors` (the
//! exponential moving average sampling uses), `level_K_upsampler.safetensors` (K >= 1),
//! `level_K_diffusion_adam.safetensors` and `level_K_upsampler_adam.safetensors`
//! (the optimiser's moments), `level_K_state.json` ([`TrainState`]), `level_K_loss.png`. Checkpoints are written
//! every `checkpoint_minutes`, on interruption and at the end; the state file is
//! written after the weights, so it never claims more steps than were saved.

use std::cell::{Cell, RefCell};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use glam::IVec3;
use tch::{Device, Kind, Tensor};

use crate::config::{Config, TrainConfig};
use crate::util::rng::Rng;
use crate::learn::schedule::Schedule;
use crate::error::{Error, Result};
use crate::util::fs::write_file;
use crate::level::{Channel, Level};
use crate::learn::nn::{mse, new_diffusion, new_upsampler, DiffusionNet, LevelNet, Upsampler};
use crate::learn::sparse::{flood_blur, upsample_trilinear, SparseTensor};

pub mod optim;

pub use crate::learn::checkpoint::{
    diffusion_checkpoint, diffusion_ema_checkpoint, loss_plot_path, optimiser_checkpoint, read_state, state_path,
    thread_grant_path, upsampler_checkpoint, TrainState,
};
use crate::util::seed::{derive_seed, Stream};

use optim::{lr_at, Adam, Ema};

/// Digest of what a level's training depends on, minus the iteration counts and the
/// checkpoint interval: a run may be resumed with more iterations.
pub fn resume_digest(config: &Config) -> String {
    let mut c = config.clone();
    c.train.level0_iterations = 0;
    c.train.upper_iterations = 0;
    c.train.upsampler_iterations = 0;
    c.train.checkpoint_minutes = 0.0;
    c.stage_digest(crate::config::Stage::Train)
}

/// The outcome of [`train_level`].
#[derive(Clone, Debug, PartialEq)]
pub struct TrainReport {
    pub level: usize,
    /// Steps done in total (including those of earlier sessions when resumed).
    pub upsampler_steps: usize,
    pub diffusion_steps: usize,
    /// Steps done in this call.
    pub upsampler_steps_now: usize,
    pub diffusion_steps_now: usize,
    /// Mean loss of the first and last 10% of all steps (NaN when none).
    pub diffusion_loss_start: f64,
    pub diffusion_loss_end: f64,
    pub upsampler_loss_start: f64,
    pub upsampler_loss_end: f64,
    /// Speed in this call, iterations per second (0 when none).
    pub upsampler_it_per_s: f64,
    pub diffusion_it_per_s: f64,
    pub seconds: f64,
    /// Whether every iteration the configuration asks for is done.
    pub finished: bool,
    pub interrupted: bool,
    /// Voxels of one training item (the box at level 0, the subdivided grid above).
    pub grid_voxels: usize,
    /// The cores the level had at its end (its process's libtorch threads,
    /// or more where the cores of levels that finished were granted to it).
    pub cores: i32,
}

/// One level's training: what to train, where, and how.
pub struct TrainJob<'a> {
    /// The exemplar's levels, coarsest first.
    pub levels: &'a [Level],
    /// The level to train.
    pub level: usize,
    pub config: &'a Config,
    pub device: Device,
    /// The models folder (checkpoints, state, loss plot).
    pub out_dir: &'a Path,
    /// Continue from the checkpoints and state found in `out_dir` (their
    /// configuration must match up to iteration counts); else start afresh.
    pub resume: bool,
    /// Progress bars on stderr.
    pub progress: bool,
    /// Once set (e.g. by a Ctrl-C handler), training stops cleanly after the
    /// current step: checkpoint, state and plot written.
    pub interrupt: Option<&'a AtomicBool>,
}

impl<'a> TrainJob<'a> {
    /// Level `level` of `levels` into `out_dir`, afresh, quietly, not interruptible.
    pub fn new(levels: &'a [Level], level: usize, config: &'a Config, device: Device, out_dir: &'a Path) -> Self {
        TrainJob { levels, level, config, device, out_dir, resume: false, progress: false, interrupt: None }
    }
}

/// The state to start from: the one recorded in `out_dir` when resuming (it
/// must be for this level and configuration), else a fresh one.
fn starting_state(job: &TrainJob, digest: &str) -> Result<TrainState> {
    let level = job.level;
    let mut state = TrainState {
        level,
        config_digest: digest.to_string(),
        full_config_digest: job.config.digest(),
        note: "Adam's moments are checkpointed beside the weights (level_K_*_adam.safetensors)".into(),
        parameterisation: crate::learn::schedule::TRAINING_PARAMETERISATION.into(),
        ..Default::default()
    };
    let sp = state_path(job.out_dir, level);
    if job.resume && sp.exists() {
        let text = std::fs::read_to_string(&sp).map_err(|e| Error::file(&sp, e.to_string()))?;
        let old: TrainState =
            serde_json::from_str(&text).map_err(|e| Error::file(&sp, format!("bad training state: {e}")))?;
        if old.level != level || old.config_digest != digest {
            return Err(Error::file(
                &sp,
                format!(
                    "was written for level {} with configuration {}, not level {level} with {digest}: \
                     train without resume to start afresh",
                    old.level, old.config_digest
                ),
            ));
        }
        // The state is written after every file of a checkpoint: a file newer
        // than it is from a checkpoint cut off midway (a full disk, a kill
        // between two files), and its weights are not those of the steps the
        // state records. Resuming from them would not reproduce the
        // uninterrupted training, so the level starts afresh.
        let state_time = std::fs::metadata(&sp).and_then(|m| m.modified()).ok();
        let torn = [
            upsampler_checkpoint(job.out_dir, level),
            diffusion_checkpoint(job.out_dir, level),
            diffusion_ema_checkpoint(job.out_dir, level),
            optimiser_checkpoint(job.out_dir, level, "upsampler"),
            optimiser_checkpoint(job.out_dir, level, "diffusion"),
        ]
        .into_iter()
        .find(|p| std::fs::metadata(p).and_then(|m| m.modified()).ok().zip(state_time).is_some_and(|(f, s)| f > s));
        if let Some(newer) = torn {
            log::warn!(
                "level {level}: {} is newer than the training state (a checkpoint cut off midway): training restarts from step 0",
                newer.display()
            );
            return Ok(state);
        }
        state.upsampler_steps = old.upsampler_steps;
        state.diffusion_steps = old.diffusion_steps;
        state.upsampler_loss = old.upsampler_loss;
        state.diffusion_loss = old.diffusion_loss;
        state.seconds = old.seconds;
        state.upsampler_loss.truncate(state.upsampler_steps);
        state.diffusion_loss.truncate(state.diffusion_steps);
        log::info!("level {level}: resuming at upsampler step {}, diffusion step {}", old.upsampler_steps, old.diffusion_steps);
    } else if job.resume {
        log::info!("level {level}: nothing to resume in {}, starting afresh", job.out_dir.display());
    }
    Ok(state)
}

/// The learning rate of each step a level's state records, per phase
/// (upsampler, diffusion), for its loss plot; None where the schedule is
/// constant (nothing to draw).
pub fn learning_rates(state: &TrainState, config: &Config) -> (Option<Vec<f64>>, Option<Vec<f64>>) {
    let tc = &config.train;
    let schedule = tc.lr_warmup_steps > 0 || tc.lr_final_ratio != 1.0;
    let diff_total = if state.level == 0 { tc.level0_iterations } else { tc.upper_iterations };
    let lrs = |n: usize, total: usize, base: f64| schedule.then(|| (0..n).map(|s| lr_at(s, total, base, tc.lr_warmup_steps, tc.lr_final_ratio)).collect::<Vec<f64>>());
    (lrs(state.upsampler_loss.len(), tc.upsampler_iterations, tc.upsampler_lr), lrs(state.diffusion_loss.len(), diff_total, tc.lr))
}

/// Trains one level: the upsampler (levels >= 1), then the diffusion model.
pub fn train_level(job: &TrainJob) -> Result<TrainReport> {
    let TrainJob { levels, level, config, device, out_dir, progress, interrupt, .. } = *job;
    if level >= levels.len() {
        return Err(Error::Invalid(format!("level {level} asked for, the exemplar has {} levels", levels.len())));
    }
    for (i, l) in levels.iter().enumerate() {
        if l.is_empty() {
            return Err(Error::Invalid(format!("exemplar level {i} has no voxels")));
        }
    }
    if !out_dir.is_dir() {
        return Err(Error::file(out_dir, "output folder does not exist"));
    }
    let t0 = Instant::now();
    let tc = &config.train;
    let bf16 = tc.bf16 && crate::learn::sparse::bf16_is_native(device);
    log::info!("level {level}: {}", crate::learn::sparse::compute_path(device, tc.bf16));
    let _bf16 = crate::learn::sparse::bf16_compute_scope(bf16);
    let digest = resume_digest(config);

    let mut state = starting_state(job, &digest)?;
    let seconds_before = state.seconds;

    // ------------------------------------------------------------ models
    tch::manual_seed(derive_seed(tc.seed, level as u64, Stream::Init, u64::MAX) as i64);
    let mut diffusion = new_diffusion(&config.model, level, device)?;
    let mut upsampler = if level > 0 { Some(new_upsampler(&config.model, device)?) } else { None };
    if state.diffusion_steps > 0 {
        diffusion.load(&diffusion_checkpoint(out_dir, level))?;
    }
    if let Some(u) = upsampler.as_mut() {
        if state.upsampler_steps > 0 {
            u.load(&upsampler_checkpoint(out_dir, level))?;
        }
    }

    // The optimisers, with the moments of an earlier session where there are
    // some (AdamW for the upsampler, Adam for the diffusion model).
    let resume_moments = |opt: &mut Adam, network: &str, steps: usize| -> Result<()> {
        let path = optimiser_checkpoint(out_dir, level, network);
        if steps == 0 {
            Ok(())
        } else if path.exists() {
            opt.load(&path)
        } else {
            log::warn!("level {level}: no {network} optimiser state in {} (trained by an older version): its moments restart", out_dir.display());
            Ok(())
        }
    };
    let up_opt = match upsampler.as_ref() {
        Some(u) => {
            let mut o = Adam::new(&u.vs, true);
            resume_moments(&mut o, "upsampler", state.upsampler_steps)?;
            Some(RefCell::new(o))
        }
        None => None,
    };
    let diff_opt = {
        let mut o = Adam::new(&diffusion.vs, false);
        resume_moments(&mut o, "diffusion", state.diffusion_steps)?;
        RefCell::new(o)
    };

    // The weights' moving average, continued from an earlier session's.
    let ema_path = diffusion_ema_checkpoint(out_dir, level);
    let ema = RefCell::new(if tc.ema_decay > 0.0 {
        let saved = (state.diffusion_steps > 0 && ema_path.exists()).then_some(ema_path.as_path());
        Some(Ema::new(&diffusion.vs, tc.ema_decay, saved)?)
    } else {
        None
    });
    let lr = |step: usize, total: usize, base: f64| lr_at(step, total, base, tc.lr_warmup_steps, tc.lr_final_ratio);

    let mut ckpt = Checkpointer {
        out_dir: out_dir.to_path_buf(),
        level,
        every_s: tc.checkpoint_minutes * 60.0,
        last: Instant::now(),
        session_start: t0,
        seconds_before,
    };
    let grant = ThreadGrant::new(out_dir, level, device);
    // On the CPU every libtorch operation of the level runs on one thread
    // (see `diffusion_step`); the level's cores are used by running a
    // step's two parts side by side. Set once for the whole level: turning
    // libtorch's threads down and up at every step left OpenMP's idle
    // workers spinning on the core the second part needed.
    let _one_thread = (device == Device::Cpu).then(crate::learn::OneThread::new);
    let mut interrupted = false;
    // A stop signal (util::interrupt) ends training like the job's own flag:
    // after the current step, with a checkpoint.
    let stop = || interrupt.map(|f| f.load(Ordering::Relaxed)).unwrap_or(false) || crate::util::interrupt::requested().is_some();
    let (mut up_now, mut up_rate) = (0usize, 0.0);

    let diff_total = if level == 0 { tc.level0_iterations } else { tc.upper_iterations };
    let (mut diff_now, mut diff_rate) = (0usize, 0.0);

    let data = TrainingData::new(levels, level, device)?;
    let grid_voxels = data.target.len();
    let mut make_batch = data.diffusion_batches(tc)?;
    let diffusion_phase = if level == 0 { "level 0 diffusion" } else { "diffusion" };
    // The level's progress: the upsampler's steps cost about a quarter of a
    // diffusion step's (whole grid, no noise levels; pipeline::children::training_cost).
    let upsampler_cost = if data.coarse.is_some() { 0.25 * tc.upsampler_iterations as f64 } else { 0.0 };
    let split = upsampler_cost / (upsampler_cost + diff_total as f64).max(1.0);
    if let Some(coarse) = &data.coarse {
        // -------------------------------------------------------- levels >= 1
        let target = &data.target;
        let u: &LevelNet<Upsampler> = upsampler.as_ref().expect("upsampler exists above level 0");
        // upsampler: whole grid
        {
            let opt = up_opt.as_ref().expect("an upsampler has an optimiser");
            let net = &u.net;
            let phase = Phase { name: "upsampler", total: tc.upsampler_iterations, progress, share: (0.0, split) };
            let target_f = target.feats.shallow_clone();
            let base = state.clone();
            let r = phase.run(&mut state.upsampler_steps, &mut state.upsampler_loss, &stop, |step| {
                tch::manual_seed(derive_seed(tc.seed, level as u64, Stream::UpsamplerStep, step as u64) as i64);
                let _one = (coarse.device() == Device::Cpu).then(crate::learn::OneThread::new);
                let pred = net.forward_t(coarse, true)?;
                let loss = mse(&pred.feats, &target_f);
                let mut opt = opt.borrow_mut();
                opt.zero_grad();
                loss.backward();
                opt.clip_grad_norm(tc.grad_clip);
                opt.step(lr(step, tc.upsampler_iterations, tc.upsampler_lr));
                Ok(loss.double_value(&[]))
            }, |s| {
                grant.poll();
                ckpt.maybe(&base, false, s, Some((u, opt)), None).map(|_| ())
            })?;
            up_now = r.0;
            up_rate = r.1;
            interrupted |= r.2;
        }
        if up_now > 0 || interrupted {
            ckpt.save(&state, up_opt.as_ref().map(|o| (u, o)), None)?;
        }
    }

    // ------------------------------------------------------------ diffusion
    if !interrupted {
        let net = &diffusion.net;
        let phase = Phase { name: diffusion_phase, total: diff_total, progress, share: (split, 1.0) };
        let base = state.clone();
        let d_ref = &diffusion;
        let r = phase.run(&mut state.diffusion_steps, &mut state.diffusion_loss, &stop, |step| {
            let mut rng = Rng::new(derive_seed(tc.seed, level as u64, Stream::DiffusionStep, step as u64));
            tch::manual_seed(rng.next_u64() as i64);
            let (x0, t_rows) = make_batch(&mut rng)?;
            let t_rows = Tensor::from_slice(&t_rows).to_device(device);
            let noise_seed = derive_seed(tc.seed, level as u64, Stream::TrainingNoise, step as u64);
            let dropout_seed = derive_seed(tc.seed, level as u64, Stream::TrainingDropout, step as u64);
            let side_by_side = grant.cores() >= 2;
            let seeds = StepSeeds { noise: noise_seed, dropout: dropout_seed };
            let loss = diffusion_step(net, &mut diff_opt.borrow_mut(), lr(step, diff_total, tc.lr), &x0, &t_rows, tc.grad_clip, seeds, side_by_side)?;
            if let Some(e) = ema.borrow_mut().as_mut() {
                e.update();
            }
            Ok(loss)
        }, |s| {
            grant.poll();
            ckpt.maybe(&base, true, s, None, Some((d_ref, &diff_opt, &ema))).map(|_| ())
        })?;
        diff_now = r.0;
        diff_rate = r.1;
        interrupted |= r.2;
    }

    // ------------------------------------------------------------ final save
    state.finished = state.diffusion_steps >= diff_total
        && (level == 0 || state.upsampler_steps >= tc.upsampler_iterations);
    state.seconds = seconds_before + t0.elapsed().as_secs_f64();
    ckpt.save(&state, upsampler.as_ref().zip(up_opt.as_ref()), Some((&diffusion, &diff_opt, &ema)))?;

    let (ds, de) = start_end(&state.diffusion_loss);
    let (us, ue) = start_end(&state.upsampler_loss);
    Ok(TrainReport {
        level,
        upsampler_steps: state.upsampler_steps,
        diffusion_steps: state.diffusion_steps,
        upsampler_steps_now: up_now,
        diffusion_steps_now: diff_now,
        diffusion_loss_start: ds,
        diffusion_loss_end: de,
        upsampler_loss_start: us,
        upsampler_loss_end: ue,
        upsampler_it_per_s: up_rate,
        diffusion_it_per_s: diff_rate,
        seconds: t0.elapsed().as_secs_f64(),
        finished: state.finished,
        interrupted,
        grid_voxels,
        cores: grant.cores(),
    })
}

/// The flooded target of a level >= 1 on the coarse ground truth's subdivision:
/// children active in the fine ground truth (`fine`, mask > 0) get their true
/// features with mask +1; every other child keeps X_up's features with mask -1.
pub fn flooded_target(coarse: &SparseTensor, fine: &SparseTensor) -> Result<SparseTensor> {
    tch::no_grad(|| {
        let x_up = upsample_trilinear(coarse)?;
        let feats = x_up.feats.detach().copy();
        let _ = feats.narrow(1, Channel::Mask.start() as i64, 1).fill_(-1.0);
        let rows = x_up.grid.lookup(&fine.grid);
        let mask: Vec<f32> = Vec::try_from(
            fine.feats.narrow(1, Channel::Mask.start() as i64, 1).to_device(Device::Cpu).to_kind(Kind::Float).view([-1]),
        )?;
        let (mut dst, mut src) = (Vec::new(), Vec::new());
        let mut orphans = 0usize;
        for (i, &r) in rows.iter().enumerate() {
            if r < 0 {
                orphans += 1;
            } else if mask[i] > 0.0 {
                dst.push(r);
                src.push(i as i64);
            }
        }
        if orphans > 0 {
            log::warn!("{orphans} fine voxels have no active parent in the coarse level; they are ignored");
        }
        let dev = feats.device();
        let true_feats = fine.feats.index_select(0, &Tensor::from_slice(&src).to_device(dev)).copy();
        let _ = true_feats.narrow(1, Channel::Mask.start() as i64, 1).fill_(1.0);
        let feats = feats.index_copy(0, &Tensor::from_slice(&dst).to_device(dev), &true_feats);
        x_up.with_feats(feats).map_err(Error::from)
    })
}

/// One diffusion training batch: the noised items' clean features and the
/// time of every row. Drawn from the step's own generator.
pub type BatchMaker = Box<dyn FnMut(&mut Rng) -> Result<(SparseTensor, Vec<f32>)>>;

/// What one level trains on, built once from the exemplar's levels.
pub struct TrainingData {
    /// The upsampler's input, the coarse level (None at level 0).
    pub coarse: Option<SparseTensor>,
    /// Level 0: the flooded box ([`flood_blur`]); above: the flooded
    /// subdivision of the coarse level ([`flooded_target`]).
    pub target: SparseTensor,
    /// Levels >= 1: the active fine voxels that crops are centred on.
    centres: Vec<IVec3>,
}

impl TrainingData {
    pub fn new(levels: &[Level], level: usize, device: Device) -> Result<Self> {
        let fine = SparseTensor::from_level(&levels[level], device)?;
        if level == 0 {
            return Ok(TrainingData { coarse: None, target: flood_blur(&fine)?, centres: Vec::new() });
        }
        let coarse = SparseTensor::from_level(&levels[level - 1], device)?;
        let target = flooded_target(&coarse, &fine)?;
        let l = &levels[level];
        let centres: Vec<IVec3> = l.coords.iter().zip(&l.mask).filter(|(_, &m)| m > 0.0).map(|(c, _)| *c).collect();
        if centres.is_empty() {
            return Err(Error::Invalid(format!("exemplar level {level} has no active voxel")));
        }
        Ok(TrainingData { coarse: Some(coarse), target, centres })
    }

    /// The diffusion batches of this level: level 0 the whole flooded box
    /// `level0_batch` times, each copy at its own time in [0, 1]; above,
    /// `upper_batch` crops of `crop`^3 around random active fine voxels, each at
    /// its own time in [0, upper_t_max].
    pub fn diffusion_batches(&self, tc: &TrainConfig) -> Result<BatchMaker> {
        let target = self.target.clone();
        if self.coarse.is_none() {
            let (n, batch) = (target.len(), tc.level0_batch);
            let x0 = SparseTensor::batch(&vec![&target; batch])?;
            return Ok(Box::new(move |rng| {
                let t_items: Vec<f32> = (0..batch).map(|_| rng.uniform() as f32).collect();
                Ok((x0.clone(), t_items.iter().flat_map(|&t| std::iter::repeat(t).take(n)).collect()))
            }));
        }
        let centres = self.centres.clone();
        let (crop, batch, t_max) = (tc.crop, tc.upper_batch, tc.upper_t_max);
        Ok(Box::new(move |rng| {
            let mut crops = Vec::with_capacity(batch);
            let mut t_rows = Vec::new();
            for _ in 0..batch {
                let c = centres[rng.below(centres.len())];
                let t = (rng.uniform() * t_max) as f32;
                let item = target.crop(c, 0, crop)?;
                t_rows.extend(std::iter::repeat(t).take(item.len()));
                crops.push(item);
            }
            Ok((SparseTensor::batch(&crops.iter().collect::<Vec<_>>())?, t_rows))
        }))
    }
}

/// The seeds of one training step: its noise eps and its dropout masks.
#[derive(Clone, Copy, Debug)]
pub struct StepSeeds {
    pub noise: u64,
    pub dropout: u64,
}

/// One optimiser step of the diffusion model on `x0` (per-row times `t_rows`):
/// noise (drawn from `noise_seed` alone, not from libtorch's global
/// generator), forward, MSE to x0, backward, clipped step; returns the loss.
///
/// On the CPU the batch's items are cut into two parts (where it has two or
/// more), each with its own forward and backward pass and its own dropout
/// masks (drawn from `dropout_seed` and the part); the parts' gradients
/// are added, part 0's first, and the step is taken once. With
/// `side_by_side` (a level that has two cores: it trains alone, or was
/// granted the cores of levels that finished) the parts run on two threads
/// at once, each on one libtorch thread; else one after the other. Either
/// way every operation sees the same rows in the same order, so the
/// weights are the same bits whatever the thread count. A CUDA device
/// takes the whole batch at once, its dropout from libtorch's generator.
#[allow(clippy::too_many_arguments)]
pub fn diffusion_step(
    net: &DiffusionNet,
    opt: &mut Adam,
    lr: f64,
    x0: &SparseTensor,
    t_rows: &Tensor,
    clip: f64,
    seeds: StepSeeds,
    side_by_side: bool,
) -> Result<f64> {
    let StepSeeds { noise: noise_seed, dropout: dropout_seed } = seeds;
    let size = x0.feats.size();
    let eps = crate::learn::noise::standard_normal(size[0] as usize, size[1] as usize, noise_seed, x0.feats.device())
        .to_kind(x0.feats.kind());
    let x_t = x0.with_feats(Schedule::default().add_noise_rows(&x0.feats, t_rows, &eps))?;
    // On the CPU each part runs on one libtorch thread, whatever the
    // process has: elementwise sin, cos and exp (the time embedding, SiLU)
    // and their gradients split their rows by thread, and on an AVX-512
    // machine the rows at a split's ragged end came out in other bits, so
    // weights depended on the thread count (and a run on its granted cores,
    // `thread_grant_path`, differed from its resumed or staged twin). The
    // cores are used by running the parts side by side instead.
    let cpu = x0.feats.device() == Device::Cpu;
    let one = cpu.then(crate::learn::OneThread::new);
    let parts = step_parts(&x_t, x0, t_rows, cpu)?;
    // Each part's loss is its share of the whole batch's mean square error.
    let elements = (size[0] * size[1]).max(1) as f64;
    let weights = opt.weights();
    let bf16 = crate::learn::sparse::bf16_compute();
    let part_grads = |i: usize, (x_t, t, target): &StepPart| -> Result<(Vec<Tensor>, f64)> {
        let _bf16 = crate::learn::sparse::bf16_compute_scope(bf16);
        let _dropout = cpu.then(|| crate::learn::sparse::dropout_stream_scope(Rng::new(dropout_seed ^ (i as u64 + 1)).next_u64()));
        let pred = net.forward_t(x_t, t, true)?;
        let loss = (&pred.feats - target).square().sum(Kind::Float) / elements;
        let grads = Tensor::run_backward(&[&loss], &weights, false, false);
        Ok((grads, loss.double_value(&[])))
    };
    let results: Vec<Result<(Vec<Tensor>, f64)>> = if side_by_side && parts.len() == 2 {
        let shared = SharedAcrossThreads(&part_grads);
        let second = SharedAcrossThreads(&parts[1]);
        std::thread::scope(|s| {
            let other = s.spawn(move || {
                let (f, part) = (shared, second);
                // OpenMP's thread count is per thread: a new thread starts
                // with as many as the machine has cores.
                tch::set_num_threads(1);
                (f.0)(1, part.0)
            });
            let first = part_grads(0, &parts[0]);
            let second = other.join().unwrap_or_else(|p| std::panic::resume_unwind(p));
            vec![first, second]
        })
    } else {
        parts.iter().enumerate().map(|(i, p)| part_grads(i, p)).collect()
    };
    let mut grads: Option<Vec<Tensor>> = None;
    let mut loss = 0.0;
    for r in results {
        let (g, l) = r?;
        loss += l;
        grads = Some(match grads {
            None => g,
            Some(sum) => tch::no_grad(|| sum.iter().zip(&g).map(|(a, b)| add_defined(a, b)).collect()),
        });
    }
    let grads: Vec<Tensor> = grads
        .unwrap_or_default()
        .into_iter()
        .zip(&weights)
        .map(|(g, w)| if g.defined() { g } else { tch::no_grad(|| w.zeros_like()) })
        .collect();
    opt.step_with(&grads, clip, lr);
    drop(one);
    Ok(loss)
}

/// One part of a training step's batch: the noised items, their times per
/// row, their clean features.
type StepPart = (SparseTensor, Tensor, Tensor);

/// The batch `x_t` (and its clean features `x0`, times `t_rows`) cut into
/// two parts of whole items ([`SparseGrid::halves`]: the first holds the
/// first half, rounded up) where `split`; one part where not, or where the
/// batch has a single item.
fn step_parts(x_t: &SparseTensor, x0: &SparseTensor, t_rows: &Tensor, split: bool) -> Result<Vec<StepPart>> {
    let Some(halves) = x_t.grid.halves().filter(|_| split) else {
        return Ok(vec![(x_t.clone(), t_rows.shallow_clone(), x0.feats.shallow_clone())]);
    };
    let (n, split) = (x_t.len() as i64, halves.split_row as i64);
    [(&halves.first, 0, split), (&halves.second, split, n - split)]
        .into_iter()
        .map(|(grid, start, rows)| {
            let part = SparseTensor::new(grid.clone(), x_t.feats.narrow(0, start, rows))?;
            Ok((part, t_rows.narrow(0, start, rows), x0.feats.narrow(0, start, rows)))
        })
        .collect()
}

/// `a + b` where both are defined, else the defined one.
fn add_defined(a: &Tensor, b: &Tensor) -> Tensor {
    match (a.defined(), b.defined()) {
        (true, true) => a + b,
        (true, false) => a.shallow_clone(),
        _ => b.shallow_clone(),
    }
}

/// A reference handed to the second thread of a training step.
struct SharedAcrossThreads<'a, T: ?Sized>(&'a T);

// SAFETY: `diffusion_step` hands one part of its batch and its part closure
// to a scoped thread that it joins before it returns. The part's tensors
// are only read there; the closure reads the network's weights (libtorch
// allows concurrent reads of a tensor, and creates a leaf's gradient
// accumulator under a lock) and builds its own graph, whose gradients it
// returns without accumulating them into the weights (`run_backward`).
unsafe impl<T: ?Sized> Send for SharedAcrossThreads<'_, T> {}

/// The libtorch threads the parent process grants this level's training
/// ([`thread_grant_path`]): when the other levels' processes have ended, the
/// last one left takes their cores (level 0 of the `cpu` profile trains
/// alone for its last third or so). Read at most once a second; the weights
/// do not depend on it (every step of the level is thread-count invariant:
/// the level-0 target's blur runs on one thread, see `flood_blur`).
struct ThreadGrant {
    path: Option<PathBuf>,
    level: usize,
    checked: Cell<Instant>,
    /// The level's cores: the process's libtorch threads at the start, then
    /// the last grant read.
    cores: Cell<i32>,
}

impl ThreadGrant {
    fn new(out_dir: &Path, level: usize, device: Device) -> Self {
        let path = (device == Device::Cpu).then(|| thread_grant_path(out_dir, level));
        // The first poll at the first step.
        let long_ago = Instant::now().checked_sub(Duration::from_secs(2)).unwrap_or_else(Instant::now);
        ThreadGrant { path, level, checked: Cell::new(long_ago), cores: Cell::new(tch::get_num_threads().max(1)) }
    }

    fn cores(&self) -> i32 {
        self.cores.get()
    }

    fn poll(&self) {
        let Some(path) = &self.path else { return };
        if self.checked.get().elapsed() < Duration::from_secs(1) {
            return;
        }
        self.checked.set(Instant::now());
        let Ok(text) = std::fs::read_to_string(path) else { return };
        match text.trim().parse::<i32>() {
            Ok(n) if n > 0 && n != self.cores.get() => {
                log::info!("level {}: {n} cores from now on (granted: the cores of levels that finished)", self.level);
                self.cores.set(n);
            }
            _ => {}
        }
    }
}

/// A training loop with its progress bar.
struct Phase {
    name: &'static str,
    total: usize,
    progress: bool,
    /// Its part of the level's training, for `--progress alf` (util::progress).
    share: (f64, f64),
}

impl Phase {
    /// Runs steps `*steps .. total`; returns (steps run, it/s, interrupted).
    fn run(
        &self,
        steps: &mut usize,
        losses: &mut Vec<f32>,
        stop: &dyn Fn() -> bool,
        mut step: impl FnMut(usize) -> Result<f64>,
        mut after: impl FnMut(&StepInfo) -> Result<()>,
    ) -> Result<(usize, f64, bool)> {
        let start = *steps;
        if start >= self.total {
            return Ok((0, 0.0, false));
        }
        let bar = if self.progress {
            let b = indicatif::ProgressBar::new(self.total as u64);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} {per_sec} ETA {eta}",
                )
                .expect("valid template"),
            );
            b.set_position(start as u64);
            b.reset_eta();
            b
        } else {
            indicatif::ProgressBar::hidden()
        };
        let t0 = Instant::now();
        let mut interrupted = false;
        let _span = crate::util::progress::span(self.share.0, self.share.1);
        while *steps < self.total {
            let loss = step(*steps)?;
            if !loss.is_finite() {
                return Err(Error::Invalid(format!("{}: loss became {loss} at step {}", self.name, *steps)));
            }
            losses.push(loss as f32);
            *steps += 1;
            log::debug!("{} step {} loss {loss:.6}", self.name, *steps);
            if *steps % (self.total / 10).max(1) == 0 {
                log::info!("{} step {}/{} loss {loss:.5}", self.name, *steps, self.total);
            }
            bar.set_message(format!("{} loss {loss:.4}", self.name));
            bar.inc(1);
            crate::util::progress::report_parts(*steps, self.total);
            after(&StepInfo { steps: *steps, losses })?;
            if stop() {
                interrupted = true;
                break;
            }
        }
        bar.finish_and_clear();
        let n = *steps - start;
        let dt = t0.elapsed().as_secs_f64();
        Ok((n, if dt > 0.0 { n as f64 / dt } else { 0.0 }, interrupted))
    }
}

struct StepInfo<'a> {
    steps: usize,
    losses: &'a [f32],
}

/// The diffusion model's checkpoint: weights, optimiser, moving average.
type DiffusionParts<'a> = (&'a LevelNet<DiffusionNet>, &'a RefCell<Adam>, &'a RefCell<Option<Ema>>);

/// Writes checkpoints at an interval and on demand.
struct Checkpointer {
    out_dir: PathBuf,
    level: usize,
    every_s: f64,
    last: Instant,
    session_start: Instant,
    seconds_before: f64,
}

impl Checkpointer {
    /// Periodic checkpoint (every `checkpoint_minutes`) during a phase: `base` is the
    /// state before the phase, `info` the phase's progress. Whether it wrote one.
    fn maybe(
        &mut self,
        base: &TrainState,
        diffusion_phase: bool,
        info: &StepInfo,
        u: Option<(&LevelNet<Upsampler>, &RefCell<Adam>)>,
        d: Option<DiffusionParts>,
    ) -> Result<bool> {
        if self.last.elapsed().as_secs_f64() < self.every_s {
            return Ok(false);
        }
        let mut st = base.clone();
        if diffusion_phase {
            st.diffusion_steps = info.steps;
            st.diffusion_loss = info.losses.to_vec();
        } else {
            st.upsampler_steps = info.steps;
            st.upsampler_loss = info.losses.to_vec();
        }
        log::debug!("level {}: checkpoint", self.level);
        self.save(&st, u, d)?;
        Ok(true)
    }

    /// Weights, then their optimiser's moments, then the state (last: it
    /// never claims more steps than the files beside it hold).
    fn save(
        &mut self,
        state: &TrainState,
        u: Option<(&LevelNet<Upsampler>, &RefCell<Adam>)>,
        d: Option<DiffusionParts>,
    ) -> Result<()> {
        if let Some((u, opt)) = u {
            u.save(&upsampler_checkpoint(&self.out_dir, self.level))?;
            opt.borrow().save(&optimiser_checkpoint(&self.out_dir, self.level, "upsampler"))?;
        }
        if let Some((d, opt, ema)) = d {
            d.save(&diffusion_checkpoint(&self.out_dir, self.level))?;
            opt.borrow().save(&optimiser_checkpoint(&self.out_dir, self.level, "diffusion"))?;
            if let Some(e) = ema.borrow().as_ref() {
                e.save(&diffusion_ema_checkpoint(&self.out_dir, self.level))?;
            }
        }
        let mut st = state.clone();
        st.seconds = self.seconds_before + self.session_start.elapsed().as_secs_f64();
        let path = state_path(&self.out_dir, self.level);
        let text = serde_json::to_string(&st).map_err(|e| Error::file(&path, e.to_string()))?;
        write_file(&path, &text)?;
        self.last = Instant::now();
        Ok(())
    }
}

fn start_end(v: &[f32]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let k = (v.len() / 10).max(1);
    let mean = |s: &[f32]| s.iter().map(|&x| x as f64).sum::<f64>() / s.len() as f64;
    (mean(&v[..k]), mean(&v[v.len() - k..]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resume_digest_ignores_iterations_only() {
        let a = Config::load("cpu", &[]).unwrap();
        let b = Config::load("cpu", &["train.upper_iterations=9".into(), "train.checkpoint_minutes=7".into()]).unwrap();
        let c = Config::load("cpu", &["train.lr=0.5".into()]).unwrap();
        assert_eq!(resume_digest(&a), resume_digest(&b));
        assert_ne!(resume_digest(&a), resume_digest(&c));
    }

    #[test]
    fn flooded_target_marks_fine_voxels() {
        let levels = crate::testing::synthetic::sphere_levels(&[8, 16], glam::DVec3::ZERO, 0.5);
        let c = SparseTensor::from_level(&levels[0], Device::Cpu).unwrap();
        let f = SparseTensor::from_level(&levels[1], Device::Cpu).unwrap();
        let t = flooded_target(&c, &f).unwrap();
        assert_eq!(t.len(), 8 * c.len());
        let mask: Vec<f32> = Vec::try_from(t.channel(Channel::Mask).view([-1])).unwrap();
        let active = mask.iter().filter(|&&m| m == 1.0).count();
        assert_eq!(active, f.len());
        assert_eq!(mask.iter().filter(|&&m| m == -1.0).count(), t.len() - f.len());
        // true features where active
        let rows = t.grid.lookup(&f.grid);
        let r0 = rows[3];
        let got = t.feats.get(r0);
        assert!((got - f.feats.get(3)).abs().max().double_value(&[]) < 1e-6);
    }
}
