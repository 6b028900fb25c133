//! @brief Sampling variants coarse to fine (docs/method.md section 5).
//!
//! 1. Level 0: the dense box of the exemplar's level 0, resized per axis by
//!    `extent` around its centre (the anisotropic control), filled with N(0, 1);
//!    the reverse process from t = 1 with `level0_steps` steps of
//!    `level0_sampler`; prune (mask > 0 kept, mask set to 1). With
//!    `level0_candidates` > 1, level-0 shapes are drawn, each from its own
//!    noise; of those whose structure against the exemplar's level 0
//!    ([`crate::judge`]) scores at least `level0_min_structure`,
//!    and that lost no part (cut short, or a thin part gone: counted at 16^3
//!    and again at 32^3 after the level-1 upsampler alone),
//!    the first is kept, or with `level0_pick = novel` the least like the
//!    exemplar's level 0 (else the best scoring): no variant starts from a
//!    tiny blob or three pieces, nor, where the network learned its exemplar
//!    by heart, from the exemplar again.
//!    With `attempts` > 1, the whole coarse-to-fine pass is repeated from
//!    new level-0 noise until the variant is whole at the structure level
//!    (64^3): the faults that level 0 cannot show yet (a
//!    wall that breaks at 32^3) are caught where they appear; with
//!    `reject_copies`, until it is whole and not a near copy of the exemplar
//!    there (a whole copy is kept before a broken shape). With `bend_voxels`
//!    > 0 (and the novel pick of more than one candidate, in the exemplar's
//!    box), a pass whose level-0 candidates are none new enough is instead
//!    the exemplar bent at random, every level ([`crate::level::warp`]),
//!    judged against the exemplar except for the inside seen and the
//!    out-of-style patches, which are judged against the exemplar bent the
//!    same way ([`Verdict::against_bend`]); the variant's bend is
//!    returned with its levels. Continuing from a level of a bent variant
//!    (`from`) runs the networks: a continuation is not bent.
//! 2. Level l >= 1: U_l of the previous pruned level (X_up plus the learned
//!    correction, on the subdivided grid), noised to t = `upper_t_max`, the reverse
//!    process from there with `upper_steps` steps; prune.
//! 3. Every stage's pruned grid is returned as a [`Level`] in the exemplar's frame,
//!    so a caller can stop, edit a level and continue from it.
//!
//! Every clean estimate the network makes is clamped per channel to what the
//! features can be ([`clamp_to_feature_ranges`]) before the sampler steps
//! with it; the last step's rule is [`FinalStep`].
//!
//! Each variant is sampled alone, from its own seed ([`variant_seed`] of the run's
//! seed and its index) and its own noise (drawn on the CPU from that seed, the
//! level and the step, not from libtorch's global generator). So variant i is the
//! same whichever shard computes it (`sample --first K -n N` on another machine
//! writes exactly what one `sample -n` writes, for the same libtorch thread count
//! and device), and continuing from an unedited level reproduces the finer levels
//! of the uninterrupted run. Batching variants would save little on a CPU (the
//! matrix products are as efficient for one variant's rows as for ten) and would
//! tie each variant's floating-point results to its batch.

use std::path::Path;
use std::sync::Arc;

use glam::IVec3;
use tch::{Device, Kind, Tensor};

use crate::config::{BendExemplars, Config};
use crate::learn::schedule::{reverse_step, reverse_times, FinalStep, Sampler, Schedule, TRAINING_PARAMETERISATION};
use crate::judge::{thin_count, Against, Flag, Structure, Thresholds, Verdict};
use crate::error::{Error, Result};
use crate::learn::grid::SparseGrid;
use crate::level::repair::LevelRepair;
use crate::level::{Level, FEATURE_CHANNELS};
use crate::learn::nn::{new_diffusion, new_upsampler, DiffusionNet, LevelNet, Upsampler};
use crate::learn::sparse::{clamp_to_feature_ranges, SparseTensor};
use crate::learn::checkpoint::{diffusion_checkpoint, diffusion_ema_checkpoint, upsampler_checkpoint};
use crate::judge::figure::FigureReading;
use crate::judge::THRESHOLDS;
use crate::level::resize::Extent;
use crate::level::warp::Bend;
use crate::util::seed::{derive_seed, Stream};

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
    /// Resized passes these networks made, and how many were whole at the
    /// structure level: after [`RESIZE_TRIES`] with none whole, they cannot
    /// fill a longer box and later variants are not resized.
    pub resized_passes: std::sync::Mutex<(usize, usize)>,
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
    Ok(Models { config: config.clone(), device, diffusion, upsamplers, resized_passes: Default::default() })
}

/// Refuses a level whose recorded training parameterisation is not this
/// program's (weights trained to predict something else, or under another
/// schedule or noise, would sample garbage without a word).
fn check_parameterisation(dir: &Path, level: usize) -> Result<()> {
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
    Ok(Models { config: config.clone(), device, diffusion, upsamplers, resized_passes: Default::default() })
}

/// What to sample.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SampleOptions {
    /// Index of the first variant (a shard of a larger set: `--first K`).
    pub first: usize,
    /// Number of variants.
    pub n: usize,
    /// The run's seed; variant i uses [`variant_seed`]`(seed, i)`.
    pub seed: u64,
    /// Per-axis scale of the level-0 box (1, 1, 1 = the exemplar's extent).
    pub extent: [f32; 3],
    /// Last level to produce (inclusive); `None` = the finest trained level.
    pub stop_level: Option<usize>,
    pub sampler: Sampler,
    pub level0_steps: usize,
    pub upper_steps: usize,
    /// Upper levels start from U_l(...) noised to this time.
    pub upper_t_max: f64,
    /// The last reverse step's rule.
    pub final_step: FinalStep,
    /// Level-0 shapes drawn per variant at most, and the structure score one
    /// must reach to be kept (see the module documentation).
    pub level0_candidates: usize,
    pub level0_min_structure: f64,
    /// Which passing candidate is kept ([`crate::config::Level0Pick`]).
    pub level0_pick: crate::config::Level0Pick,
    /// The reverse process at level 0.
    pub level0_sampler: Sampler,
    /// Coarse-to-fine passes per variant at most, until one is whole at the
    /// structure level (1: one pass, no check).
    pub attempts: usize,
    /// Whether a whole pass that is a near copy is passed over while
    /// attempts are left (`sample.reject_copies`).
    pub reject_copies: bool,
    /// Whether holes through a sheet are closed level by level, where the
    /// exemplar is one (`sample.mend_sheets`).
    pub mend_sheets: bool,
    /// Whether every level loses its specks (`sample.remove_specks`).
    pub remove_specks: bool,
    /// A pass whose level-0 candidates are none new enough is instead the
    /// exemplar bent by up to this many level-0 voxels (`sample.bend_voxels`;
    /// 0: never). Not written when 0, so the stamps of variants sampled
    /// before it existed still match.
    #[serde(skip_serializing_if = "is_zero")]
    pub bend_voxels: f64,
    /// Which exemplars are bent (`sample.bend_exemplars`). Not written when
    /// `figures`, the default.
    #[serde(default, skip_serializing_if = "BendExemplars::is_figures")]
    pub bend_exemplars: BendExemplars,
    /// A pass whose level-0 candidates are none new enough, where the
    /// exemplar is not bent, starts instead from a level-0 box resized along
    /// the exemplar's longer horizontal axis by up to this factor (`sample.resize_max`,
    /// [`crate::level::resize::Extent::drawn`]; 0: never). Not written when 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub resize_max: f64,
}

impl SampleOptions {
    /// The configuration's sampler and step counts, extent 1.
    pub fn from_config(config: &Config, n: usize, seed: u64) -> Self {
        SampleOptions {
            first: 0,
            n,
            seed,
            extent: [1.0; 3],
            stop_level: None,
            sampler: config.sample.sampler,
            level0_steps: config.sample.level0_steps,
            upper_steps: config.sample.upper_steps,
            upper_t_max: config.train.upper_t_max,
            final_step: config.sample.final_step,
            level0_candidates: config.sample.level0_candidates,
            level0_min_structure: config.sample.level0_min_structure,
            level0_pick: config.sample.level0_pick,
            level0_sampler: config.sample.level0_sampler.or(config.sample.sampler),
            attempts: config.sample.attempts,
            reject_copies: config.sample.reject_copies,
            mend_sheets: config.sample.mend_sheets,
            remove_specks: config.sample.remove_specks,
            bend_voxels: config.sample.bend_voxels,
            bend_exemplars: config.sample.bend_exemplars,
            resize_max: config.sample.resize_max,
        }
    }
}

pub use crate::level::resize::{level0_box, MAX_LEVEL0_BOX_CUBES};

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// One sampled variant: the pruned level of each stage produced, coarsest
/// first, the bend its start was bent by, where it started from the
/// exemplar bent (`sample.bend_voxels`), and its extent, where its box was
/// resized.
#[derive(Clone, Debug)]
pub struct SampledVariant {
    pub levels: Vec<Level>,
    pub bend: Option<Bend>,
    /// The extent of its level-0 box against the exemplar's, where it is not
    /// the exemplar's (`--extent`, or a resized pass).
    pub extent: Option<Extent>,
}

/// Samples `opts.n` variants. `exemplar_levels` gives the level-0 box and the frame.
/// With `from` (a level of index k, e.g. an edited level file), the levels k+1 ..
/// are produced from it for every variant; otherwise levels 0 ...
pub fn sample(
    models: &Models,
    exemplar_levels: &[Level],
    opts: &SampleOptions,
    from: Option<Level>,
) -> Result<Vec<SampledVariant>> {
    sample_observed(models, exemplar_levels, opts, from, None)
}

/// Told of every level of a variant as it is made (the variant's index, the
/// level), coarsest first: the studio shows each level as it finishes.
/// Levels an attempt makes and the choice among attempts passes over are not
/// told; the kept attempt's are, once it is kept.
pub type LevelSink<'a> = &'a (dyn Fn(usize, &Level) + Sync);

/// [`sample`], telling `sink` of every level as it is made.
pub fn sample_observed(
    models: &Models,
    exemplar_levels: &[Level],
    opts: &SampleOptions,
    from: Option<Level>,
    sink: Option<LevelSink>,
) -> Result<Vec<SampledVariant>> {
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
    if let Some(level) = &from {
        let k = level.index;
        if k >= last {
            return Err(Error::Invalid(format!("continuing from level {k}: nothing finer to do (last level {last})")));
        }
        if let Some(ex) = exemplar_levels.get(k) {
            if ex.resolution != level.resolution {
                return Err(Error::Invalid(format!(
                    "level {k} to continue from has resolution {}, the exemplar's level {k} has {}",
                    level.resolution, ex.resolution
                )));
            }
        }
    }
    let sheet_axes = crate::judge::sheet::sheet_axes(exemplar_levels);
    let continuing = from.is_some();
    let at_extent = AtExtent::of(exemplar_levels, Extent { extent: opts.extent }, sheet_axes[0], continuing)?;
    // Out-of-style patches are the exemplar's own at any extent.
    let style = if continuing || at_extent.extent.is_same() {
        None
    } else {
        crate::judge::structure_level(exemplar_levels).map(|l| (l, Structure::of(l)))
    };
    let copies_only = std::cell::Cell::new(false);
    let resized_whole = std::cell::Cell::new(false);
    let box_copies = std::cell::Cell::new(0);
    let repairs = crate::level::repair::repairs(exemplar_levels, &sheet_axes, opts.remove_specks, opts.mend_sheets);
    let bending = Bending::of(opts, exemplar_levels, from.is_some());
    let resizing = opts.resize_max > 0.0 && could_bend(opts) && !continuing && !matches!(bending, Bending::Bends(_));
    tch::no_grad(|| {
        (opts.first..opts.first + opts.n)
            .map(|i| {
                copies_only.set(false);
                resized_whole.set(false);
                box_copies.set(0);
                let job = OneVariant {
                    models,
                    exemplar_levels,
                    frame,
                    last,
                    sampler: opts.sampler,
                    schedule: Schedule::default(),
                    seed: variant_seed(opts.seed, i),
                    at: &at_extent,
                    style: style.as_ref().map(|(l, s)| (*l, s)),
                    repairs: &repairs,
                    bending,
                    copies_only: &copies_only,
                    resized_whole: &resized_whole,
                    box_copies: &box_copies,
                    resizing,
                    told: sink.map(|f| (i, f)),
                };
                job.run(exemplar0.resolution, opts, from.as_ref())
            })
            .collect()
    })
}

/// The seed of variant `index` of a run with seed `run_seed`: variants are
/// sampled one at a time from their own seeds, so any shard of indices
/// (`--first K -n N`) reproduces exactly what one `sample -n` writes.
pub fn variant_seed(run_seed: u64, index: usize) -> u64 {
    derive_seed(run_seed, index as u64, Stream::Variant, 0)
}

/// Standard normal noise of `rows` x 10 from SplitMix64 and Box-Muller on the
/// CPU, seeded by (variant seed, level, step): independent of libtorch's
/// global generator, of the batch and of the device, so a variant's noise is
/// the same wherever and with whatever else it is sampled.
fn gaussian(rows: usize, seed: u64, level: usize, step: usize, device: Device) -> Tensor {
    crate::learn::noise::standard_normal(rows, FEATURE_CHANNELS, derive_seed(seed, level as u64, Stream::SamplingStep, step as u64), device)
}

/// Everything one variant's coarse-to-fine pass needs.
#[derive(Clone, Copy)]
struct OneVariant<'a> {
    models: &'a Models,
    /// The exemplar's levels (a bent start bends them).
    exemplar_levels: &'a [Level],
    frame: crate::level::Frame,
    last: usize,
    sampler: Sampler,
    schedule: Schedule,
    seed: u64,
    /// The exemplar at the pass's extent: the level-0 box, and what the
    /// level-0 candidates and the attempts are judged against.
    at: &'a AtExtent,
    /// The exemplar's own structure level, where `at` is resized: the
    /// out-of-style patches are judged against it.
    style: Option<(&'a Level, &'a Structure)>,
    /// Per level, what it gets once made ([`crate::level::repair::repairs`];
    /// empty: nothing).
    repairs: &'a [LevelRepair],
    /// Whether a pass with nothing new at level 0 is the exemplar bent.
    bending: Bending,
    /// Set once a pass of this variant found its level-0 candidates none new
    /// enough and resized: its later attempts start resized at once.
    copies_only: &'a std::cell::Cell<bool>,
    /// Whether a resized pass of this variant was whole: if none was, its
    /// last attempt takes the exemplar's box (a whole copy before a broken
    /// shape).
    resized_whole: &'a std::cell::Cell<bool>,
    /// Attempts of this variant in the exemplar's box that were whole near
    /// copies: at [`BOX_COPIES_BEFORE_RESIZE`] its later attempts resize.
    box_copies: &'a std::cell::Cell<usize>,
    /// Whether a pass whose level-0 candidates are none new enough is
    /// resized (`resize_max`, not bent, the novel pick in the exemplar's box).
    resizing: bool,
    /// Who is told of each level of the variant as it is made, with the
    /// variant's index.
    told: Option<(usize, LevelSink<'a>)>,
}

/// Whether sampling bends a pass whose level-0 candidates are none new
/// enough (`sample.bend_voxels`, `sample.bend_exemplars`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Bending {
    /// No bends asked for, or none possible (not the novel pick of several
    /// candidates over the exemplar's box, or continuing from a level).
    Never,
    /// Bends asked for `figures`, and the exemplar is none.
    NotAFigure,
    /// The exemplar bent by up to this many level-0 voxels.
    Bends(f64),
}

impl Bending {
    fn of(opts: &SampleOptions, exemplar_levels: &[Level], continuing: bool) -> Bending {
        if opts.bend_voxels == 0.0 || !could_bend(opts) || continuing {
            return Bending::Never;
        }
        if opts.bend_exemplars == BendExemplars::All {
            return Bending::Bends(opts.bend_voxels);
        }
        let reading = FigureReading::of_exemplar(exemplar_levels);
        let (bending, why) = match reading {
            None => (Bending::NotAFigure, format!("the exemplar has no level of {}^3 to 64^3 to read whether it is a figure: it is not bent", THRESHOLDS.min_reading_resolution)),
            Some(r) => {
                let figures = format!(
                    "normal spread {:.2}, a figure's at least {}; upright share {:.2}, a figure's at most {}",
                    r.normal_spread, THRESHOLDS.min_normal_spread, r.upright_share, THRESHOLDS.max_upright_share
                );
                if r.is_figure() {
                    (Bending::Bends(opts.bend_voxels), format!("the exemplar is a figure ({figures}): a pass with nothing new at level 0 is the exemplar bent"))
                } else {
                    (Bending::NotAFigure, format!("the exemplar has flat faces or upright walls ({figures}): it is not bent"))
                }
            }
        };
        // Said once per process: the pipeline samples one variant per call.
        static SAID: std::sync::Once = std::sync::Once::new();
        SAID.call_once(|| log::info!("{why}"));
        bending
    }
}

/// The exemplar as sampling judges a pass at one extent
/// ([`crate::level::resize`]): its level-0 box; its level 0 and structure
/// (the level-0 gate); its level 1's thin parts (the level-0 candidates'
/// thin parts are counted a level finer, see [`AtExtent::thin_ratio`]); its
/// structure level and structure (the attempts). The exemplar's own at its
/// own extent, else stretched to the extent.
struct AtExtent {
    extent: Extent,
    box0: (IVec3, IVec3),
    level0: Level,
    structure0: Structure,
    /// Level 1 and its thin-part voxel count, where it has thin parts
    /// enough to lose ([`Thresholds::min_exemplar_thin_share`]).
    thin1: Option<(Level, usize)>,
    reference: Option<(Level, Structure)>,
}

impl AtExtent {
    /// `sheet_axis0`: whether level 0 is a sheet (the `holed` term of the
    /// level-0 gate) is the structure level's decision, not 16^3's own. A
    /// continuation from a level has no level-0 gate nor attempts: level 1
    /// and the structure level are not measured then (a tenth of a second
    /// of the studio's regeneration).
    fn of(levels: &[Level], extent: Extent, sheet_axis0: Option<usize>, continuing: bool) -> Result<AtExtent> {
        let level0 = levels.first().ok_or_else(|| Error::Invalid("no exemplar levels".into()))?;
        let box0 = level0_box(level0, extent.extent)?;
        let level0 = extent.of(levels, 0)?;
        let mut structure0 = Structure::of(&level0);
        structure0.sheet_axis = sheet_axis0;
        if continuing {
            return Ok(AtExtent { extent, box0, level0, structure0, thin1: None, reference: None });
        }
        // Also when sampling stops at level 0 (see `Models::upsamplers`).
        let thin1 = match levels.get(1) {
            Some(_) => {
                let level = extent.of(levels, 1)?;
                let thin = thin_count(&level);
                let surface = level.mask.iter().filter(|&&m| m > 0.0).count();
                let enough = thin > 0 && thin as f64 >= Thresholds::default().min_exemplar_thin_share * surface as f64;
                enough.then_some((level, thin))
            }
            None => None,
        };
        let reference = match crate::judge::structure_level(levels) {
            Some(l) => {
                let level = extent.of(levels, l.index)?;
                let structure = Structure::of(&level);
                Some((level, structure))
            }
            None => None,
        };
        Ok(AtExtent { extent, box0, level0, structure0, thin1, reference })
    }

    /// The thin-part check of a level-0 candidate one level finer: its
    /// thin-part voxels taken to level 1 over the exemplar's. At 16^3 a
    /// bunny's body is itself "thin" (3 voxels deep; 83 of its 299 voxels),
    /// so an ear gone is 10% of the thin voxels, as much as a ruined wall
    /// top of the demo tower, and the rim of the hole it leaves adds thin
    /// voxels back (thin ratio 0.81-0.96 with the ear gone). At 32^3 the
    /// body is not thin and the ear is: ratio 0.58-0.72 with the ear gone,
    /// 0.9 with it, 0.83 or more for the demo's and the tower's ruins. The
    /// candidate is taken there by the level-1 upsampler alone (no
    /// diffusion steps: a fraction of a second).
    fn thin_ratio(&self, level1: &Level) -> Option<f64> {
        let (ex, thin) = self.thin1.as_ref()?;
        debug_assert_eq!(level1.resolution, ex.resolution);
        Some(thin_count(level1) as f64 / *thin as f64)
    }

    /// The exemplar's structure level at this extent and its structure.
    fn reference(&self) -> Option<(&Level, &Structure)> {
        self.reference.as_ref().map(|(l, s)| (l, s))
    }
}

/// How one coarse-to-fine attempt came out at the structure level.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttemptRank {
    /// No broken structure flag.
    pub whole: bool,
    /// Not a near copy of the exemplar.
    pub new: bool,
    /// [`Verdict::score`].
    pub score: f64,
}

impl AttemptRank {
    /// Whether the attempt ends the search: whole, and with
    /// `reject_copies` also new.
    pub fn accepted(&self, reject_copies: bool) -> bool {
        self.whole && (self.new || !reject_copies)
    }

    /// Fallback order: whole first, then new, then by score (a whole copy
    /// before a broken new shape: a copy is still a shape a user can use).
    fn key(&self) -> (bool, bool, f64) {
        (self.whole, self.new, self.score)
    }
}

/// Runs `attempt(0)`, `attempt(1)`, ... until one is
/// [`AttemptRank::accepted`] or `attempts` have run; returns the index, rank
/// and payload of the accepted one, else of the best by the fallback order
/// (the first of equals). Whole is the criterion; with `reject_copies`,
/// whole and not a near copy. (Before the seen-through flag, rejecting
/// copies on the ruined tower traded them for towers split open at 64^3
/// that the flags called whole, docs/lab/whole-shapes.md "Whole shapes"; that flag
/// now sees those.)
pub fn keep_attempt<T>(
    attempts: usize,
    reject_copies: bool,
    mut attempt: impl FnMut(usize) -> Result<(AttemptRank, T)>,
) -> Result<(usize, AttemptRank, T)> {
    let mut best: Option<(usize, AttemptRank, T)> = None;
    for a in 0..attempts.max(1) {
        let (rank, payload) = attempt(a)?;
        if rank.accepted(reject_copies) {
            return Ok((a, rank, payload));
        }
        if best.as_ref().is_none_or(|(_, b, _)| rank.key().partial_cmp(&b.key()) == Some(std::cmp::Ordering::Greater)) {
            best = Some((a, rank, payload));
        }
    }
    Ok(best.expect("at least one attempt"))
}

/// The seed of attempt `a` of a variant (attempt 0 is the variant's own seed).
fn attempt_seed(seed: u64, a: usize) -> u64 {
    if a == 0 {
        seed
    } else {
        derive_seed(seed, a as u64, Stream::StructureAttempt, 0)
    }
}

/// The seed of level-0 candidate `k` of a variant (candidate 0 is the
/// variant's own seed: without rejection, nothing changes).
fn candidate_seed(seed: u64, k: usize) -> u64 {
    if k == 0 {
        seed
    } else {
        derive_seed(seed, k as u64, Stream::Level0Candidate, 0)
    }
}

/// Whether sampling with `opts` could bend a pass, given `bend_voxels`: the
/// novel pick of more than one level-0 candidate, in the exemplar's box.
fn could_bend(opts: &SampleOptions) -> bool {
    opts.level0_pick == crate::config::Level0Pick::Novel && opts.level0_candidates > 1 && opts.extent == [1.0; 3]
}

/// Attempts of a variant in the exemplar's box that may be whole near copies
/// before its later attempts are resized (with `resize_max`): one copy may
/// be the seed's bad luck, as on the demo, whose next attempt is a tower of
/// its own; two say the networks copy.
pub const BOX_COPIES_BEFORE_RESIZE: usize = 2;

/// Resized passes that may all fail (none whole at the structure level)
/// before sampling stops resizing for the networks that made them: a
/// church's networks, trained on one nave and one steeple, broke every
/// longer box, where a house's and a temple's filled most.
pub const RESIZE_TRIES: usize = 6;

/// Level-0 candidates drawn at most in a resized box (the first that passes
/// is kept): on the house and the temple one of the first 12 passed every
/// time one did.
pub const RESIZED_CANDIDATES: usize = 12;

/// How a pass starts: a level-0 shape drawn by the network (its pruned
/// tensor and level), the exemplar bent, or a box resized.
enum Start {
    Drawn(SparseTensor, Level),
    Bent(Bend),
    /// The networks offer only copies: the pass starts again in a resized box.
    Resized(Extent),
}

/// One coarse-to-fine pass: its levels, the last one's pruned tensor, and
/// how it started where not from the network in the sampling's box: bent,
/// or resized (with the exemplar at that extent, which judges it).
struct Pass {
    levels: Vec<Level>,
    cur: SparseTensor,
    bend: Option<Bend>,
    resized: Option<AtExtent>,
}

/// A passing level-0 candidate whose 1-voxel-tolerant F-score against the
/// exemplar's level 0 is below this ends the novel pick's draws: new enough.
/// Measured on the demo and the tower (16^3): candidates the finer levels
/// turned into near copies scored 0.990-1.000, those that became towers of
/// their own 0.94-0.981; stopping there saves most of the draws (each a
/// full reverse process at level 0).
pub const NEW_ENOUGH_LEVEL0_FSCORE: f64 = 0.985;

/// Why the level-0 pick kept the candidate it kept.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kept {
    /// `first`: the first that passed.
    First,
    /// `novel`: the first that passed with an F-score below
    /// [`NEW_ENOUGH_LEVEL0_FSCORE`] against the exemplar's level 0.
    NewEnough { fscore: f64, change: f64 },
    /// `novel`: none new enough; of those that passed, the least like the
    /// exemplar (lowest F-score, then the largest changed region).
    LeastLike { fscore: f64, change: f64 },
    /// None passed: the best scoring.
    BestScoring { score: f64, fscore: f64 },
}

/// What an offered candidate means for the pick.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Offer {
    /// Hold it as the fallback: it is the best scoring so far.
    best: bool,
    /// Hold it as the pick: the first that passed (`first`), or the least
    /// like the exemplar of those passing so far (`novel`).
    picked: bool,
    /// Draw no more candidates.
    stop: bool,
}

/// The level-0 pick as a policy over the candidates' figures, drawn one at a
/// time: a candidate passes when its structure score reaches the minimum
/// and, with the gate on (a minimum above 0), it has lost no part: it is not
/// cut short along an axis (`shrunken`: at 16^3 a bunny without its ear
/// tips, 13 of 16 voxels, scores 0.81 and is "new" to the F-score; the finer
/// levels shred the stubs) and keeps the exemplar's thin parts
/// (`thin_part_lost` at 16^3, and its thin voxels counted again one level
/// finer, [`AtExtent::thin_ratio`]: a bunny whose back ear is gone inside the box is
/// "new" too, F 0.97, and no finer level regrows the ear; docs/lab/new-shapes.md,
/// "New shapes" and "Thin parts at level 0").
struct Level0Pick {
    novel: bool,
    min_structure: f64,
    /// (score, k, F-score against the exemplar) of the best scoring.
    best: Option<(f64, usize, f64)>,
    /// ((F-score, -change), k) of the least like the exemplar that passed.
    newest: Option<((f64, f64), usize)>,
    /// The `first` pick's candidate, once one passed.
    first: Option<usize>,
}

impl Level0Pick {
    fn new(pick: crate::config::Level0Pick, min_structure: f64) -> Self {
        Level0Pick { novel: pick == crate::config::Level0Pick::Novel, min_structure, best: None, newest: None, first: None }
    }

    fn passes(&self, score: f64, part_lost: bool) -> bool {
        score >= self.min_structure && (self.min_structure <= 0.0 || !part_lost)
    }

    /// Candidate `k` with its structure score, whether it lost a part
    /// (`shrunken` or `thin_part_lost`) and its `likeness` (F-score and
    /// largest changed region against the exemplar's level 0).
    fn offer(&mut self, k: usize, score: f64, part_lost: bool, likeness: (f64, f64)) -> Offer {
        let pass = self.passes(score, part_lost);
        let mut offer = Offer { best: false, picked: false, stop: false };
        if self.best.is_none_or(|(b, _, _)| score > b) {
            self.best = Some((score, k, likeness.0));
            offer.best = true;
        }
        if pass && self.novel {
            let (fscore, change) = likeness;
            // Lower is less like the exemplar.
            let key = (fscore, -change);
            if self.newest.is_none_or(|(n, _)| key < n) {
                self.newest = Some((key, k));
                offer.picked = true;
            }
            offer.stop = fscore < NEW_ENOUGH_LEVEL0_FSCORE;
        } else if pass {
            self.first = Some(k);
            offer.picked = true;
            offer.stop = true;
        }
        offer
    }

    /// The candidate kept, and why (None before any offer).
    fn kept(&self) -> Option<(usize, Kept)> {
        if let Some(k) = self.first {
            return Some((k, Kept::First));
        }
        if let Some(((fscore, change), k)) = self.newest {
            let change = -change;
            return Some((k, if fscore < NEW_ENOUGH_LEVEL0_FSCORE { Kept::NewEnough { fscore, change } } else { Kept::LeastLike { fscore, change } }));
        }
        self.best.map(|(score, k, fscore)| (k, Kept::BestScoring { score, fscore }))
    }
}

/// A level-0 candidate's figures for [`Level0Pick`], against the exemplar's
/// level 0: its structure score, whether it lost a part (`shrunken` or
/// `thin_part_lost`), and its likeness (F-score, largest changed region). An
/// empty candidate scores 0, has lost everything and is like nothing.
fn level0_gate(level: &Level, ex_level: &Level, ex_structure: &Structure, params: &Thresholds) -> (f64, bool, (f64, f64)) {
    if level.is_empty() {
        return (0.0, true, (0.0, 0.0));
    }
    let s = Verdict::new(level, &Structure::of(level), ex_level, ex_structure, params);
    if log::log_enabled!(log::Level::Trace) {
        let m = crate::judge::Matching::of(level, ex_level);
        log::trace!("level 0 candidate: F {:.3}, change {:.3}, precision {:.3}, recall {:.3}", m.fscore(), m.largest_change(), m.precision(), m.recall());
    }
    let part_lost = s.flags.iter().any(|f| matches!(f, Flag::Shrunken | Flag::ThinPartLost));
    (s.score, part_lost, (s.copy_fscore, s.largest_change))
}

impl OneVariant<'_> {
    /// Level 0 from the noise of `seed`, pruned.
    fn level0(&self, resolution0: u32, seed: u64, opts: &SampleOptions) -> Result<SparseTensor> {
        let (lo, size) = self.at.box0;
        let bx = SparseGrid::full_box(resolution0, lo, size)?;
        let noise = gaussian(bx.len(), seed, 0, 0, self.models.device);
        let x = SparseTensor::new(Arc::new(bx), noise)?;
        Ok(self.reverse(0, x, 1.0, opts.level0_steps, seed, opts.final_step, opts.level0_sampler)?.prune_by_mask()?)
    }

    /// Level 0 of this variant: of up to `level0_candidates` shapes, drawn
    /// one at a time, the one [`Level0Pick`] keeps: the first that passes
    /// (its structure score reaches `level0_min_structure` and it lost no
    /// part, at 16^3 or, for thin parts, at 32^3) with pick `first`; with `novel` the first that passes and
    /// is new enough ([`NEW_ENOUGH_LEVEL0_FSCORE`]), else of all that pass
    /// the least like the exemplar's level 0 (the lowest 1-voxel-tolerant
    /// F-score, then the largest changed region); when none passes, the
    /// best scoring.
    ///
    /// Where none is new enough and the exemplar is not bent, with
    /// `resize_max`, the pass is resized instead ([`Start::Resized`]), and so
    /// at once are the variant's later attempts. A resized box keeps the
    /// first candidate that passes against the exemplar at its extent: the
    /// size is what is new.
    fn chosen_level0(&self, seed: u64, resolution0: u32, opts: &SampleOptions) -> Result<Start> {
        if self.resizes() && self.copies_only.get() {
            if let Some(extent) = self.drawn_extent(seed, opts) {
                return Ok(Start::Resized(extent));
            }
        }
        let (ex_level, ex_structure) = (&self.at.level0, &self.at.structure0);
        let params = Thresholds::default();
        let resized = !self.at.extent.is_same();
        let candidates = if resized { opts.level0_candidates.clamp(1, RESIZED_CANDIDATES) } else { opts.level0_candidates.max(1) };
        let policy = if resized { crate::config::Level0Pick::First } else { opts.level0_pick };
        let mut pick = Level0Pick::new(policy, opts.level0_min_structure);
        // The candidates the pick may still keep: the best scoring (the
        // fallback) and its pick so far.
        let mut best: Option<(SparseTensor, Level)> = None;
        let mut picked: Option<(SparseTensor, Level)> = None;
        for k in 0..candidates {
            let x = self.level0(resolution0, candidate_seed(seed, k), opts)?;
            let level = x.to_level(0, self.frame)?;
            if candidates == 1 {
                return Ok(Start::Drawn(x, level));
            }
            let (score, mut part_lost, likeness) = level0_gate(&level, ex_level, ex_structure, &params);
            // In a resized box the thin parts are the stretched exemplar's,
            // which a network's longer shape need not repeat voxel for voxel.
            if !part_lost && pick.passes(score, false) && params.min_thin_ratio > 0.0 && self.at.extent.is_same() {
                if let Some(ratio) = self.thin_ratio_at_level1(&x)? {
                    log::debug!("level 0 candidate {k}: thin ratio {ratio:.3} one level finer");
                    part_lost = ratio < params.min_thin_ratio;
                }
            }
            let offer = pick.offer(k, score, part_lost, likeness);
            log::debug!("level 0 candidate {k}: structure {score:.3}{}", if part_lost { ", a part lost" } else { "" });
            if offer.picked {
                picked = Some((x.with_feats(x.feats.shallow_clone())?, level.clone()));
            }
            if offer.best {
                best = Some((x, level));
            }
            if offer.stop {
                break;
            }
        }
        let (k, why) = pick.kept().expect("at least one candidate");
        if !matches!(why, Kept::First | Kept::NewEnough { .. }) {
            if let Bending::Bends(voxels) = self.bending {
                let bend = Bend { seed: derive_seed(seed, 0, Stream::Bend, 0), voxels: voxels as f32 };
                log::info!("level 0: none of {candidates} candidates new enough: the exemplar bent instead (seed {})", bend.seed);
                return Ok(Start::Bent(bend));
            }
            // Resized only where the networks draw the exemplar itself (the
            // tower's least-like starts, F 0.985-0.995, became towers of
            // their own at the finer levels; a single house's read 1.000).
            let copy_fscore = match why {
                Kept::LeastLike { fscore, .. } | Kept::BestScoring { fscore, .. } => Some(fscore).filter(|&f| f >= params.coarse_copy_fscore),
                _ => None,
            };
            if let Some((fscore, extent)) = copy_fscore.filter(|_| self.resizes()).and_then(|f| Some((f, self.drawn_extent(seed, opts)?))) {
                self.copies_only.set(true);
                log::info!(
                    "level 0: none of {candidates} candidates new enough (the networks draw the exemplar: F {fscore:.3} at best): resized to extent {extent} instead"
                );
                return Ok(Start::Resized(extent));
            }
        }
        match why {
            Kept::First if k > 0 => log::info!("level 0: candidate {k} kept, {k} rejected"),
            Kept::First => {}
            Kept::NewEnough { fscore, change } | Kept::LeastLike { fscore, change } => {
                let how = if matches!(why, Kept::NewEnough { .. }) { "new enough" } else { "the least like the exemplar of all" };
                log::info!("level 0: candidate {k} of {candidates} kept, {how} (F {fscore:.3}, change {change:.3} against the exemplar's level 0)");
            }
            Kept::BestScoring { score, .. } => log::warn!(
                "level 0: none of {candidates} candidates passed (structure {:.2}, not cut short): the best ({score:.3}) is kept",
                opts.level0_min_structure
            ),
        }
        let kept = if matches!(why, Kept::BestScoring { .. }) { best } else { picked };
        let (x, level) = kept.expect("the kept candidate is held");
        Ok(Start::Drawn(x, level))
    }

    /// The thin-part voxels of level-0 candidate `x` taken to level 1 by the
    /// upsampler alone, over the exemplar's level 1 ([`AtExtent::thin_ratio`]); None
    /// where the exemplar has no thin parts to lose there.
    fn thin_ratio_at_level1(&self, x: &SparseTensor) -> Result<Option<f64>> {
        let (Some(_), Some(Some(up))) = (&self.at.thin1, self.models.upsamplers.get(1)) else {
            return Ok(None);
        };
        if x.is_empty() {
            return Ok(Some(0.0));
        }
        let level1 = up.net.forward_t(x, false)?.prune_by_mask()?.to_level(1, self.frame)?;
        Ok(self.at.thin_ratio(&level1))
    }

    /// The variant: one coarse-to-fine pass from its seed, or with
    /// `attempts` > 1 (and no level to continue from), passes from new
    /// level-0 noise (attempt seeds) until one is whole at the structure
    /// level ([`Verdict`] flags); else the best (whole first, then
    /// not a near copy, then by score). Attempts stop at the structure
    /// level; only the kept one goes on to the finer levels (continuing
    /// from a level reproduces the pass that made it, so the variant is the
    /// same as if every attempt had gone to the end; a bent pass goes on
    /// bent).
    fn run(&self, resolution0: u32, opts: &SampleOptions, from: Option<&Level>) -> Result<SampledVariant> {
        let attempts = if from.is_some() { 1 } else { opts.attempts.max(1) };
        let reference = self.at.reference().filter(|(l, _)| l.index <= self.last);
        let Some((ex_level, _)) = reference.filter(|_| attempts > 1) else {
            let p = self.pass(self.seed, resolution0, opts, from, self.last)?;
            let extent = self.extent_of(&p);
            return Ok(SampledVariant { levels: p.levels, bend: p.bend, extent });
        };
        let p = self.kept_attempt(resolution0, opts, ex_level.index, attempts)?;
        let extent = self.extent_of(&p);
        let Pass { mut levels, cur, bend, .. } = p;
        levels.iter().for_each(|l| self.tell(l));
        let next = levels.len();
        match &bend {
            // A bent pass stays the exemplar bent up to the variant's last level.
            Some(b) => {
                self.bent_levels(b, next, self.last, &mut levels)?;
            }
            None => {
                self.descend(cur, next, self.last, opts, &mut levels)?;
            }
        }
        Ok(SampledVariant { levels, bend, extent })
    }

    /// The extent a pass's variant records: the resized pass's, else the
    /// sampling's own where it is not the exemplar's.
    fn extent_of(&self, p: &Pass) -> Option<Extent> {
        p.resized.as_ref().map(|r| r.extent).or((!self.at.extent.is_same()).then_some(self.at.extent))
    }

    /// Whether a pass with nothing new at level 0 is resized: resizing is on
    /// and these networks have not failed [`RESIZE_TRIES`] times with no
    /// whole resized pass.
    fn resizes(&self) -> bool {
        let (passes, whole) = *self.models.resized_passes.lock().unwrap_or_else(|e| e.into_inner());
        self.resizing && (whole > 0 || passes < RESIZE_TRIES)
    }

    /// A resized pass's extent from the pass's level-0 seed, where
    /// `resize_max` allows one ([`Extent::drawn`]).
    fn drawn_extent(&self, seed: u64, opts: &SampleOptions) -> Option<Extent> {
        Extent::drawn(&self.exemplar_levels[0], opts.resize_max, seed)
    }

    /// The structure scores of `level` (at the structure level) of pass `p`:
    /// a bent pass against its own pose; a resized one, or any pass of a
    /// resized sampling, against the exemplar at its extent, its style
    /// against the exemplar's own patches; else against the exemplar.
    fn judged(&self, p: &Pass, level: &Level) -> Option<Verdict> {
        let own = self.style.or(self.at.reference())?;
        let at = p.resized.as_ref().unwrap_or(self.at).reference()?;
        // A bent pass's level is the exemplar's bent (and repaired): its own pose.
        let structure;
        let against = match (&p.bend, p.resized.is_some() || self.style.is_some()) {
            (Some(_), _) => {
                structure = Structure::of(level);
                Against::Bent(level, &structure)
            }
            (None, true) => Against::AtExtent(at.0, at.1),
            // In the exemplar's box, a level 0 that is the exemplar's makes a near copy.
            (None, false) => Against::Exemplar { level0: Some((&p.levels[0], &self.at.level0)) },
        };
        Some(Verdict::judged(level, own, against, None, &Thresholds::default()))
    }

    /// The pass [`keep_attempt`] keeps of `attempts`, its levels up to the
    /// structure level (`structure_index`), with its pruned tensor of that
    /// level, for the finer levels.
    fn kept_attempt(&self, resolution0: u32, opts: &SampleOptions, structure_index: usize, attempts: usize) -> Result<Pass> {
        // Attempts are not told of their levels: the kept one's are told
        // once it is kept.
        let quiet = OneVariant { told: None, ..*self };
        let (a, rank, kept) = keep_attempt(attempts, opts.reject_copies, |a| {
            // The last attempt of a variant none of whose resized passes was
            // whole takes the exemplar's box.
            let last_in_box = a + 1 == attempts && a > 0 && self.copies_only.get() && !self.resized_whole.get();
            let p = if last_in_box {
                OneVariant { resizing: false, ..quiet }.pass(attempt_seed(self.seed, a), resolution0, opts, None, structure_index)?
            } else {
                quiet.pass(attempt_seed(self.seed, a), resolution0, opts, None, structure_index)?
            };
            let level = &p.levels[structure_index];
            let mut rank = match self.judged(&p, level).filter(|_| !level.is_empty()) {
                None => AttemptRank { whole: false, new: false, score: 0.0 },
                Some(s) => {
                    let how = match (&p.bend, &p.resized) {
                        (Some(_), _) => " (bent)".to_string(),
                        (None, Some(r)) => format!(" (extent {})", r.extent),
                        _ => String::new(),
                    };
                    log::debug!("attempt {a}{how}: structure {:.3} {:?}", s.score, s.flags);
                    AttemptRank { whole: s.whole(), new: !s.flags.contains(&Flag::NearCopy), score: s.score }
                }
            };
            // Whole copies in the exemplar's box, though level 0 looked new
            // enough (a house whose copies differ in a hidden courtyard
            // floor): the networks copy, and later attempts resize.
            if p.resized.is_none() && p.bend.is_none() && rank.whole && !rank.new && self.resizes() {
                self.box_copies.set(self.box_copies.get() + 1);
                if self.box_copies.get() == BOX_COPIES_BEFORE_RESIZE {
                    log::info!("{BOX_COPIES_BEFORE_RESIZE} attempts in the exemplar's box were whole near copies: the later ones resize");
                    self.copies_only.set(true);
                }
            }
            if p.resized.is_some() {
                self.resized_whole.set(self.resized_whole.get() || rank.whole);
                let mut record = self.models.resized_passes.lock().unwrap_or_else(|e| e.into_inner());
                *record = (record.0 + 1, record.1 + rank.whole as usize);
                if record.0 == RESIZE_TRIES && record.1 == 0 {
                    log::warn!("{RESIZE_TRIES} resized passes, none whole: these networks cannot fill a longer box; variants stay in the exemplar's box");
                }
            }
            // Once resizing has failed, the networks offer nothing new in any
            // box: a whole copy ends the search (more attempts would draw
            // more copies, minutes each); eval still calls it a near copy.
            if self.resizing && !self.resizes() && p.resized.is_none() && rank.whole {
                rank.new = true;
            }
            Ok((rank, p))
        })?;
        let res = self.exemplar_levels[structure_index].resolution;
        match (rank.accepted(opts.reject_copies), rank.whole) {
            (true, _) if a > 0 => log::info!("variant kept at attempt {a} (structure {:.3} at {res}^3)", rank.score),
            (true, _) => {}
            (false, true) => log::warn!(
                "every attempt of {attempts} whole at {res}^3 was a near copy of the exemplar: the best kept (structure {:.3}){}",
                rank.score,
                // Where the networks only copy, bends and resizes are what give a new shape.
                match self.bending {
                    Bending::Never if opts.bend_voxels == 0.0 && could_bend(opts) => {
                        "; for a figure with nothing repeated in it (a statue, an animal), --set sample.bend_voxels=2 poses it anew"
                    }
                    Bending::NotAFigure if opts.resize_max == 0.0 => {
                        "; the networks copy what appears once in the exemplar: --set sample.resize_max=1.5 draws longer boxes instead (a longer house), or try --extent"
                    }
                    _ => "",
                }
            ),
            (false, false) => {
                log::warn!("no attempt of {attempts} was whole at {res}^3: the best kept (structure {:.3})", rank.score)
            }
        }
        Ok(kept)
    }

    /// One coarse-to-fine pass up to level `last` (at most the variant's
    /// last), with the last level's pruned tensor: level 0 from
    /// `level0_seed` (or `from`, continued), the finer levels from the
    /// variant's own seed (so continuing from an unedited level reproduces
    /// the finer levels of the pass that made it, whichever attempt that was).
    fn pass(&self, level0_seed: u64, resolution0: u32, opts: &SampleOptions, from: Option<&Level>, last: usize) -> Result<Pass> {
        let mut out = Vec::new();
        let mut bend = None;
        let (cur, first) = match from {
            None => match self.chosen_level0(level0_seed, resolution0, opts)? {
                Start::Drawn(pruned, level) => {
                    let (pruned, level) = self.repaired(pruned, level)?;
                    self.tell(&level);
                    out.push(level);
                    (pruned, 1)
                }
                Start::Bent(b) => {
                    let cur = self.bent_levels(&b, 0, last, &mut out)?.expect("level 0 at least");
                    bend = Some(b);
                    (cur, out.len())
                }
                Start::Resized(extent) => {
                    let at = AtExtent::of(self.exemplar_levels, extent, self.at.structure0.sheet_axis, false)?;
                    let resized = OneVariant { at: &at, style: self.style.or(self.at.reference()), resizing: false, ..*self };
                    let p = resized.pass(level0_seed, resolution0, opts, None, last)?;
                    return Ok(Pass { resized: Some(at), ..p });
                }
            },
            Some(level) => {
                let one = SparseTensor::from_level(level, self.models.device)?.prune_by_mask()?;
                (one, level.index + 1)
            }
        };
        let cur = self.descend(cur, first, last, opts, &mut out)?;
        Ok(Pass { levels: out, cur, bend, resized: None })
    }

    /// Tells the sink, where there is one, of a level of the variant.
    fn tell(&self, level: &Level) {
        if let Some((i, sink)) = self.told {
            sink(i, level);
        }
    }

    /// Levels `first..=last` (at most the variant's last) of the exemplar
    /// bent by `bend`, appended to `out` (every level a network would make:
    /// no network runs on a bent pass); each through the tensor, so its rows
    /// are in the grid's order. The last one's pruned tensor; None when
    /// there is no level to make.
    fn bent_levels(&self, bend: &Bend, first: usize, last: usize, out: &mut Vec<Level>) -> Result<Option<SparseTensor>> {
        let mut cur = None;
        for l in first..=last.min(self.last) {
            let bent = bend.bent(self.exemplar_levels, l);
            let pruned = SparseTensor::from_level(&bent, self.models.device)?.prune_by_mask()?;
            let level = pruned.to_level(l, self.frame)?;
            let (pruned, level) = self.repaired(pruned, level)?;
            self.tell(&level);
            out.push(level);
            cur = Some(pruned);
        }
        Ok(cur)
    }

    /// Levels `first..=last` (at most the variant's last) from the pruned
    /// level below them, `cur`, appended to `out`; the last one's pruned
    /// tensor.
    fn descend(&self, mut cur: SparseTensor, first: usize, last: usize, opts: &SampleOptions, out: &mut Vec<Level>) -> Result<SparseTensor> {
        let (seed, dev) = (self.seed, self.models.device);
        for l in first..=last.min(self.last) {
            if cur.is_empty() {
                let empty = SparseTensor::new(
                    Arc::new(SparseGrid::empty(cur.grid.resolution() * 2)),
                    Tensor::zeros([0, FEATURE_CHANNELS as i64], (Kind::Float, dev)),
                )?;
                let level = empty.to_level(l, self.frame)?;
                self.tell(&level);
                out.push(level);
                cur = empty;
                continue;
            }
            let up = self.models.upsamplers[l]
                .as_ref()
                .ok_or_else(|| Error::Invalid(format!("level {l} has no upsampler")))?;
            let u = up.net.forward_t(&cur, false)?;
            let eps = gaussian(u.len(), seed, l, 0, dev);
            let x = u.with_feats(self.schedule.add_noise(&u.feats, opts.upper_t_max, &eps))?;
            let x = self.reverse(l, x, opts.upper_t_max, opts.upper_steps, seed, opts.final_step, self.sampler)?;
            let pruned = x.prune_by_mask()?;
            let level = pruned.to_level(l, self.frame)?;
            let (pruned, level) = self.repaired(pruned, level)?;
            self.tell(&level);
            cur = pruned;
            out.push(level);
        }
        Ok(cur)
    }

    /// `level` (and its pruned tensor `pruned`) repaired as the exemplar's
    /// level of its index says (specks removed, a sheet mended); else as it is.
    fn repaired(&self, pruned: SparseTensor, level: Level) -> Result<(SparseTensor, Level)> {
        let Some(repair) = self.repairs.get(level.index) else { return Ok((pruned, level)) };
        let Some(r) = repair.apply(&level) else { return Ok((pruned, level)) };
        log::debug!("level {}: {} speck voxels removed, {} voxels mend the sheet", level.index, r.removed(level.len()), r.added);
        // Back through the tensor, so the level's rows are in the grid's order as ever.
        let pruned = SparseTensor::from_level(&r.level, self.models.device)?.prune_by_mask()?;
        let level = pruned.to_level(level.index, self.frame)?;
        Ok((pruned, level))
    }

    /// The reverse process of level `l` from `t_max` to 0 in `steps` steps,
    /// its noise from `seed`; every clean estimate clamped per channel.
    #[allow(clippy::too_many_arguments)]
    fn reverse(
        &self,
        l: usize,
        mut x: SparseTensor,
        t_max: f64,
        steps: usize,
        seed: u64,
        final_step: FinalStep,
        sampler: Sampler,
    ) -> Result<SparseTensor> {
        let net = &self.models.diffusion[l].net;
        let times = reverse_times(t_max, steps);
        for (k, w) in times.windows(2).enumerate() {
            // A stop signal ends sampling between steps (the variant is
            // sampled again, identically, by the next run).
            crate::util::interrupt::check()?;
            let x0_hat = clamp_to_feature_ranges(&net.forward_at(&x, w[0], false)?.feats);
            let noise = gaussian(x.len(), seed, l, k + 1, self.models.device);
            let next = reverse_step(sampler, final_step, &self.schedule, &x.feats, &x0_hat, w[0], w[1], &noise);
            x = x.with_feats(next)?;
        }
        Ok(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Level0Pick as Pick;

    /// Runs [`keep_attempt`] over fixed outcomes (whole, new, score); the
    /// attempts run and the one kept.
    fn run_attempts(reject_copies: bool, outcomes: &[(bool, bool, f64)]) -> (usize, usize) {
        let mut ran = 0;
        let (kept, _, payload) = keep_attempt(outcomes.len(), reject_copies, |a| {
            ran += 1;
            let (whole, new, score) = outcomes[a];
            Ok((AttemptRank { whole, new, score }, a))
        })
        .unwrap();
        assert_eq!(kept, payload);
        (ran, kept)
    }

    #[test]
    fn a_whole_copy_is_passed_over_for_a_whole_new_shape_but_kept_before_a_broken_one() {
        let copy_then_new = [(true, false, 0.99), (false, true, 0.9), (true, true, 0.8), (true, true, 0.95)];
        // Without the rejection the first whole pass ends the search, copy or not.
        assert_eq!(run_attempts(false, &copy_then_new), (1, 0));
        // With it the copy and the broken pass are passed over; the first
        // whole new one is kept even though a later one scores higher.
        assert_eq!(run_attempts(true, &copy_then_new), (3, 2));
        // No whole new pass: the whole copy is kept before broken new shapes
        // of higher score, and every attempt was tried.
        assert_eq!(run_attempts(true, &[(false, true, 0.97), (true, false, 0.6), (false, true, 0.99)]), (3, 1));
        // Nothing whole: the best score of the broken (new before copy).
        assert_eq!(run_attempts(true, &[(false, false, 0.9), (false, true, 0.5), (false, true, 0.7)]), (3, 2));
    }

    /// Offers (score, part lost, F-score, change) in turn until the pick
    /// stops; the candidates drawn and what was kept.
    fn run_pick(pick: Pick, min: f64, candidates: &[(f64, bool, f64, f64)]) -> (usize, Option<(usize, Kept)>) {
        let mut p = Level0Pick::new(pick, min);
        let mut drawn = 0;
        for (k, &(score, part_lost, f, change)) in candidates.iter().enumerate() {
            drawn += 1;
            if p.offer(k, score, part_lost, (f, change)).stop {
                break;
            }
        }
        (drawn, p.kept())
    }

    #[test]
    fn the_first_pick_keeps_the_first_that_passes_not_the_best_scoring() {
        // Candidate 0 scores highest but is cut short: with the gate on it
        // does not pass; candidate 2 is the first that does.
        let c = [(0.95, true, 0.97, 0.03), (0.5, false, 0.99, 0.0), (0.85, false, 0.99, 0.0), (0.9, false, 0.9, 0.1)];
        assert_eq!(run_pick(Pick::First, 0.8, &c), (3, Some((2, Kept::First))));
        // The gate off (minimum 0): the first candidate passes, cut short or not.
        assert_eq!(run_pick(Pick::First, 0.0, &c), (1, Some((0, Kept::First))));
    }

    #[test]
    fn the_novel_pick_stops_at_the_first_new_enough_and_never_keeps_a_shape_cut_short() {
        // 0: cut short and very new (a bunny without its ear tips); 1: a
        // copy; 2: new enough; 3: never drawn.
        let c = [(0.81, true, 0.96, 0.05), (0.99, false, 1.0, 0.0), (0.9, false, 0.98, 0.03), (0.9, false, 0.9, 0.2)];
        assert_eq!(run_pick(Pick::Novel, 0.8, &c), (3, Some((2, Kept::NewEnough { fscore: 0.98, change: 0.03 }))));
        // None new enough: the least like the exemplar of those that pass
        // (the lower F-score; on a tie, the larger change).
        let c = [(0.81, true, 0.9, 0.1), (0.9, false, 0.99, 0.01), (0.9, false, 0.988, 0.01), (0.9, false, 0.988, 0.02)];
        assert_eq!(run_pick(Pick::Novel, 0.8, &c), (4, Some((3, Kept::LeastLike { fscore: 0.988, change: 0.02 }))));
    }

    /// A bunny at `res`^3 made of spheres: a body (radius 0.5) with two ears
    /// up from its top side by side, rods of spheres (radius 0.12, 0.9 long,
    /// 0.6 apart); the same with one ear; the body alone.
    fn bunny_of_spheres(res: u32) -> (Level, Level, Level) {
        use crate::testing::synthetic::sphere_union;
        use glam::Vec3;
        let body = (Vec3::new(0.0, -0.45, 0.0), 0.5);
        let ear = |x: f32| (0..10).map(move |k| (Vec3::new(x, -0.05 + 0.1 * k as f32, 0.0), 0.12));
        (
            sphere_union(res, &std::iter::once(body).chain(ear(-0.3)).chain(ear(0.3)).collect::<Vec<_>>()),
            sphere_union(res, &std::iter::once(body).chain(ear(-0.3)).collect::<Vec<_>>()),
            sphere_union(res, &[body]),
        )
    }

    #[test]
    fn at_16_cubed_an_ear_lost_inside_the_box_is_a_part_lost_not_a_new_shape() {
        // At 16^3 (a voxel is 0.125) the ears are 2 voxels across, 4.8
        // apart. Losing one ear leaves the box as it was (the other ear keeps
        // its height).
        let (exemplar, one_ear, _) = bunny_of_spheres(16);
        let e = Structure::of(&exemplar);
        let p = Thresholds::default();
        assert_eq!(level0_gate(&exemplar, &exemplar, &e, &p), (1.0, false, (1.0, 0.0)));
        let (score, part_lost, (fscore, _)) = level0_gate(&one_ear, &exemplar, &e, &p);
        let m = crate::judge::Matching::of(&one_ear, &exemplar);
        assert_eq!(fscore, m.fscore());
        // What the pick saw before: a passing score and "new enough".
        let sc = Verdict::new(&one_ear, &Structure::of(&one_ear), &exemplar, &e, &p);
        assert!(score >= 0.8 && m.fscore() < NEW_ENOUGH_LEVEL0_FSCORE, "score {score}, F {}: {sc:?}", m.fscore());
        assert!(!sc.flags.contains(&crate::judge::Flag::Shrunken), "{sc:?}");
        assert!(part_lost, "the ear is lost: thin voxels {} of {}: {sc:?}", Structure::of(&one_ear).thin, e.thin);
        assert!(!Level0Pick::new(Pick::Novel, 0.8).passes(score, part_lost));
        assert_eq!(level0_gate(&Level::default(), &exemplar, &e, &p), (0.0, true, (0.0, 0.0)));
    }

    #[test]
    fn one_level_finer_an_ear_lost_is_a_thin_part_lost_and_a_ball_has_none_to_lose() {
        // At 32^3 (a voxel is 0.0625) the ears (4 voxels across) are thin,
        // the body is not.
        let (exemplar, one_ear, ball) = bunny_of_spheres(32);
        let (exemplar0, _, ball0) = bunny_of_spheres(16);
        let p = Thresholds::default();
        let levels = [exemplar0.clone(), exemplar.clone()];
        let at = AtExtent::of(&levels, Extent::SAME, None, false).unwrap();
        assert!(at.thin1.is_some(), "the ears are thin parts");
        assert_eq!(at.thin_ratio(&exemplar), Some(1.0));
        let r = at.thin_ratio(&one_ear).unwrap();
        assert!(r < p.min_thin_ratio, "one ear of two lost: thin ratio {r}");
        // A ball has no thin part to lose: no check.
        assert!(AtExtent::of(&[ball0, ball], Extent::SAME, None, false).unwrap().thin1.is_none());
        assert!(AtExtent::of(&levels[..1], Extent::SAME, None, false).unwrap().thin1.is_none(), "no level 1, no check");
    }

    #[test]
    fn when_nothing_passes_the_best_scoring_is_kept() {
        let c = [(0.5, false, 0.9, 0.1), (0.95, true, 0.9, 0.1), (0.7, false, 0.9, 0.1)];
        for pick in [Pick::First, Pick::Novel] {
            assert_eq!(run_pick(pick, 0.8, &c), (3, Some((1, Kept::BestScoring { score: 0.95, fscore: 0.9 }))), "{pick:?}");
        }
        assert_eq!(Level0Pick::new(Pick::Novel, 0.8).kept(), None);
    }

    #[test]
    fn a_resized_shape_is_judged_against_the_exemplar_at_its_extent() {
        let (exemplar0, _, _) = bunny_of_spheres(16);
        let (mut exemplar, _, _) = bunny_of_spheres(32);
        exemplar.index = 1;
        let levels = [exemplar0, exemplar.clone()];
        let extent = Extent { extent: [1.5, 1.0, 1.0] };
        let at = AtExtent::of(&levels, extent, None, false).unwrap();
        let (ref_level, ref_structure) = at.reference().expect("a structure level");
        assert_eq!(ref_level.index, 1);
        let p = Thresholds::default();
        let e = Structure::of(&exemplar);
        // The exemplar as long as the box: whole at its extent, and not the
        // exemplar's size.
        let long = extent.of(&levels, 1).unwrap();
        let judged = Verdict::at_extent(&long, &Structure::of(&long), (ref_level, ref_structure), (&exemplar, &e), &p);
        assert!(judged.whole() && judged.extent_ratio > 0.99 && (judged.mass_ratio - 1.0).abs() < 0.01, "{judged:?}");
        let plain = Verdict::new(&long, &Structure::of(&long), &exemplar, &e, &p);
        assert!(plain.score < 0.8, "against the exemplar's own box the size is off: {plain:?}");
        // The exemplar's own size in the longer box is cut short.
        let short = Verdict::at_extent(&exemplar, &e, (ref_level, ref_structure), (&exemplar, &e), &p);
        assert!(short.flags.contains(&Flag::Shrunken), "{short:?}");
    }
}
