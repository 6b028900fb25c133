//! What to sample ([`SampleOptions`], from the configuration and the
//! command line) and what comes out ([`SampledVariant`]).

use crate::config::{BendExemplars, Config};
use crate::learn::schedule::{FinalStep, Sampler};
use crate::level::Level;
use crate::level::resize::Extent;
use crate::level::warp::Bend;

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
    /// attempts are left (`sample.attempts.reject_copies`).
    pub reject_copies: bool,
    /// Whether holes through a sheet are closed level by level, where the
    /// exemplar is one (`sample.filters.mend_sheets`).
    pub mend_sheets: bool,
    /// Whether every level loses its specks (`sample.filters.remove_specks`).
    pub remove_specks: bool,
    /// A pass whose level-0 candidates are none new enough is instead the
    /// exemplar bent by up to this many level-0 voxels (`sample.proposers.bend_voxels`;
    /// 0: never). Not written when 0, so the stamps of variants sampled
    /// before it existed still match.
    #[serde(skip_serializing_if = "is_zero")]
    pub bend_voxels: f64,
    /// Which exemplars are bent (`sample.proposers.bend_exemplars`). Not written when
    /// `figures`, the default.
    #[serde(default, skip_serializing_if = "BendExemplars::is_figures")]
    pub bend_exemplars: BendExemplars,
    /// A pass whose level-0 candidates are none new enough, where the
    /// exemplar is not bent, starts instead from a level-0 box resized along
    /// the exemplar's longer horizontal axis by up to this factor (`sample.proposers.resize_max`,
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
            level0_candidates: config.sample.level0.candidates,
            level0_min_structure: config.sample.level0.min_structure,
            level0_pick: config.sample.level0.pick,
            level0_sampler: config.sample.level0.sampler.or(config.sample.sampler),
            attempts: config.sample.attempts.count,
            reject_copies: config.sample.attempts.reject_copies,
            mend_sheets: config.sample.filters.mend_sheets,
            remove_specks: config.sample.filters.remove_specks,
            bend_voxels: config.sample.proposers.bend_voxels,
            bend_exemplars: config.sample.proposers.bend_exemplars,
            resize_max: config.sample.proposers.resize_max,
        }
    }
}

pub(super) fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// One sampled variant: the pruned level of each stage produced, coarsest
/// first, the bend its start was bent by, where it started from the
/// exemplar bent (`sample.proposers.bend_voxels`), and its extent, where its box was
/// resized.
#[derive(Clone, Debug)]
pub struct SampledVariant {
    pub levels: Vec<Level>,
    pub bend: Option<Bend>,
    /// The extent of its level-0 box against the exemplar's, where it is not
    /// the exemplar's (`--extent`, or a resized pass).
    pub extent: Option<Extent>,
}

/// Told of every level of a variant as it is made (the variant's index, the
/// level), coarsest first: the studio shows each level as it finishes.
/// Levels an attempt makes and the choice among attempts passes over are not
/// told; the kept attempt's are, once it is kept.
pub type LevelSink<'a> = &'a (dyn Fn(usize, &Level) + Sync);
