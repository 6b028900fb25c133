//! @brief Sampling variants coarse to fine (METHOD.md section 5).
//!
//! 1. Level 0: the dense box of the exemplar's level 0, resized per axis by
//!    `extent` around its centre (the anisotropic control), n copies batched, filled
//!    with N(0, 1); the reverse process from t = 1 with `level0_steps` steps; prune
//!    (mask > 0 kept, mask set to 1).
//! 2. Level l >= 1: U_l of the previous pruned level (X_up plus the learned
//!    correction, on the subdivided grid), noised to t = `upper_t_max`, the reverse
//!    process from there with `upper_steps` steps; prune.
//! 3. Every stage's pruned grid is returned, split per variant, as a [`Level`] in the
//!    exemplar's frame, so a caller can stop, edit a level and continue from it.
//!
//! All variants run as one batch (items never mix: the grid keeps them apart).
//! Each stage reseeds libtorch's generator from (seed, stage), so the same seed on the
//! same device gives the same variants, and continuing from an unedited level
//! reproduces the finer levels of the uninterrupted run.

use std::path::Path;
use std::sync::Arc;

use glam::IVec3;
use tch::{Device, Kind, Tensor};

use crate::config::Config;
use crate::diffusion::{noise_to, reverse_times, sampler, Sampler};
use crate::error::{Error, Result};
use crate::grid::SparseGrid;
use crate::level::{Level, FEATURE_CHANNELS};
use crate::nn::{new_diffusion, new_upsampler, sparse_err, DiffusionNet, LevelNet, Upsampler};
use crate::sparse_conv::SparseTensor;
use crate::train::{diffusion_checkpoint, mix_seed, upsampler_checkpoint};

/// The trained networks of every level, read from a training folder.
pub struct Models {
    pub config: Config,
    pub device: Device,
    /// Diffusion model of each level, coarsest first.
    pub diffusion: Vec<LevelNet<DiffusionNet>>,
    /// Upsampler of each level (`None` at level 0).
    pub upsamplers: Vec<Option<LevelNet<Upsampler>>>,
}

impl Models {
    pub fn levels(&self) -> usize {
        self.diffusion.len()
    }
}

/// Loads the checkpoints of levels `0..levels` from `dir` (written by
/// [`crate::train::train_level`] with the same model configuration).
pub fn load_models(dir: &Path, config: &Config, levels: usize, device: Device) -> Result<Models> {
    if levels == 0 {
        return Err(Error::Invalid("no levels to load".into()));
    }
    let mut diffusion = Vec::with_capacity(levels);
    let mut upsamplers = Vec::with_capacity(levels);
    for l in 0..levels {
        let mut d = new_diffusion(&config.model, l, device)?;
        let p = diffusion_checkpoint(dir, l);
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
    Ok(Models { config: config.clone(), device, diffusion, upsamplers })
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

/// What to sample.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleOptions {
    /// Number of variants.
    pub n: usize,
    pub seed: u64,
    /// Per-axis scale of the level-0 box (1, 1, 1 = the exemplar's extent).
    pub extent: [f32; 3],
    /// Last level to produce (inclusive); `None` = the finest trained level.
    pub stop_level: Option<usize>,
    /// "ddpm" or "ddim".
    pub sampler: String,
    pub level0_steps: usize,
    pub upper_steps: usize,
    /// Upper levels start from U_l(...) noised to this time.
    pub upper_t_max: f64,
}

impl SampleOptions {
    /// The configuration's sampler and step counts, extent 1.
    pub fn from_config(config: &Config, n: usize, seed: u64) -> Self {
        SampleOptions {
            n,
            seed,
            extent: [1.0; 3],
            stop_level: None,
            sampler: config.sample.sampler.clone(),
            level0_steps: config.sample.level0_steps,
            upper_steps: config.sample.upper_steps,
            upper_t_max: config.train.upper_t_max,
        }
    }
}

/// The level-0 box of the exemplar resized by `extent` around its centre:
/// `(min, size)` in voxels.
pub fn level0_box(level0: &Level, extent: [f32; 3]) -> Result<(IVec3, IVec3)> {
    if level0.is_empty() {
        return Err(Error::Invalid("the exemplar's level 0 has no voxels".into()));
    }
    if extent.iter().any(|e| !(e.is_finite() && *e > 0.0)) {
        return Err(Error::Invalid(format!("extent {extent:?} must be positive")));
    }
    let lo = level0.coords.iter().fold(IVec3::MAX, |a, &c| a.min(c));
    let hi = level0.coords.iter().fold(IVec3::MIN, |a, &c| a.max(c));
    let size = hi - lo + IVec3::ONE;
    let new_size = IVec3::from_array(
        [0, 1, 2].map(|a| ((size[a] as f32 * extent[a]).round() as i32).max(1)),
    );
    // keep the centre: shift by half the change (floor division keeps it exact for even changes)
    let new_lo = lo + IVec3::from_array([0, 1, 2].map(|a| (size[a] - new_size[a]).div_euclid(2)));
    Ok((new_lo, new_size))
}

/// Samples `opts.n` variants. `exemplar_levels` gives the level-0 box and the frame.
/// With `from` (a level of index k, e.g. an edited level file), the levels k+1 ..
/// are produced from it for every variant; otherwise levels 0 ... Returns, per
/// variant, the pruned level of each stage produced, coarsest first.
pub fn sample(
    models: &Models,
    exemplar_levels: &[Level],
    opts: &SampleOptions,
    from: Option<Level>,
) -> Result<Vec<Vec<Level>>> {
    if opts.n == 0 {
        return Ok(Vec::new());
    }
    let exemplar0 = exemplar_levels.first().ok_or_else(|| Error::Invalid("no exemplar levels".into()))?;
    let frame = exemplar0.frame;
    let last = opts.stop_level.unwrap_or(models.levels() - 1);
    if last >= models.levels() {
        return Err(Error::Invalid(format!(
            "stop level {last} asked for, only levels 0..{} are trained",
            models.levels() - 1
        )));
    }
    let sampler =
        sampler(&opts.sampler).ok_or_else(|| Error::Invalid(format!("unknown sampler '{}'", opts.sampler)))?;
    let dev = models.device;
    let mut out: Vec<Vec<Level>> = vec![Vec::new(); opts.n];

    tch::no_grad(|| -> Result<()> {
        let (mut cur, first) = match from {
            None => {
                tch::manual_seed(mix_seed(opts.seed, 0, 3, 0) as i64);
                let (lo, size) = level0_box(exemplar0, opts.extent)?;
                let bx = SparseGrid::full_box(exemplar0.resolution, lo, size).map_err(|e| Error::Invalid(e.to_string()))?;
                let grids: Vec<&SparseGrid> = (0..opts.n).map(|_| &bx).collect();
                let grid = Arc::new(SparseGrid::batch(&grids).map_err(|e| Error::Invalid(e.to_string()))?);
                let noise = Tensor::randn([grid.len() as i64, FEATURE_CHANNELS as i64], (Kind::Float, dev));
                let x = SparseTensor::new(grid, noise).map_err(sparse_err)?;
                let x = reverse(&models.diffusion[0].net, x, 1.0, opts.level0_steps, sampler.as_ref())?;
                let pruned = x.prune_by_mask().map_err(sparse_err)?;
                push_levels(&mut out, &pruned, 0, frame)?;
                (pruned, 1)
            }
            Some(level) => {
                let k = level.index;
                if k >= last {
                    return Err(Error::Invalid(format!(
                        "continuing from level {k}: nothing finer to do (last level {last})"
                    )));
                }
                if let Some(ex) = exemplar_levels.get(k) {
                    if ex.resolution != level.resolution {
                        return Err(Error::Invalid(format!(
                            "level {k} to continue from has resolution {}, the exemplar's level {k} has {}",
                            level.resolution, ex.resolution
                        )));
                    }
                }
                let one = SparseTensor::from_level(&level, dev).map_err(sparse_err)?.prune_by_mask().map_err(sparse_err)?;
                let items: Vec<&SparseTensor> = (0..opts.n).map(|_| &one).collect();
                (SparseTensor::batch(&items).map_err(sparse_err)?, k + 1)
            }
        };
        for l in first..=last {
            tch::manual_seed(mix_seed(opts.seed, l as u64, 3, 0) as i64);
            if cur.is_empty() {
                let empty = SparseTensor::new(
                    Arc::new(SparseGrid::empty(cur.grid.resolution() * 2)),
                    Tensor::zeros([0, FEATURE_CHANNELS as i64], (Kind::Float, dev)),
                )
                .map_err(sparse_err)?;
                for v in out.iter_mut() {
                    v.push(empty.to_level(l, frame).map_err(sparse_err)?);
                }
                cur = empty;
                continue;
            }
            let up = models.upsamplers[l]
                .as_ref()
                .ok_or_else(|| Error::Invalid(format!("level {l} has no upsampler")))?;
            let u = up.net.forward_t(&cur, false)?;
            let eps = u.feats.randn_like();
            let x = u.with_feats(noise_to(&u.feats, opts.upper_t_max, &eps)).map_err(sparse_err)?;
            let x = reverse(&models.diffusion[l].net, x, opts.upper_t_max, opts.upper_steps, sampler.as_ref())?;
            cur = x.prune_by_mask().map_err(sparse_err)?;
            push_levels(&mut out, &cur, l, frame)?;
        }
        Ok(())
    })?;
    Ok(out)
}

/// The reverse process from `t_max` to 0 in `steps` steps.
fn reverse(
    net: &DiffusionNet,
    mut x: SparseTensor,
    t_max: f64,
    steps: usize,
    sampler: &dyn Sampler,
) -> Result<SparseTensor> {
    let times = reverse_times(t_max, steps);
    for w in times.windows(2) {
        let x0_hat = net.forward_at(&x, w[0], false)?;
        let noise = x.feats.randn_like();
        let next = sampler.step(&x.feats, &x0_hat.feats, w[0], w[1], &noise);
        x = x.with_feats(next).map_err(sparse_err)?;
    }
    Ok(x)
}

fn push_levels(out: &mut [Vec<Level>], x: &SparseTensor, index: usize, frame: crate::level::Frame) -> Result<()> {
    let items = x.split();
    if items.len() != out.len() {
        return Err(Error::Invalid(format!("{} variants expected, {} in the batch", out.len(), items.len())));
    }
    for (v, item) in out.iter_mut().zip(items) {
        v.push(item.to_level(index, frame).map_err(sparse_err)?);
    }
    Ok(())
}
