//! Sampling variants coarse to fine (docs/method.md section 5), as a
//! pipeline one variant at a time:
//!
//! | stage | file | what |
//! |---|---|---|
//! | the paper's reverse process | `reverse.rs` | level 0 from noise in the box; each finer level from the upsampled level below, noised to `upper_t_max` and denoised |
//! | proposers | `proposers.rs` | where a pass starts: a level-0 shape drawn by the network, the exemplar bent (figures), or a resized box (the networks only copy) |
//! | the gate | `gate.rs` | which of the level-0 candidates is kept: structure score, no part lost, the least like the exemplar |
//! | level filters | `filters.rs` | specks removed and sheets mended on every level made (`level::repair`) |
//! | the choice among attempts | `attempts.rs` | coarse-to-fine passes until one is whole and new at the structure level, judged by `judge::Verdict` |
//! | one variant | `variant.rs` | the pass, the descent to the finest level, who is told of each level |
//! | networks, options | `models.rs`, `options.rs` | the checkpoints read; what to sample |
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



use crate::learn::schedule::Schedule;
use crate::judge::Structure;
use crate::error::{Error, Result};
use crate::level::Level;
use crate::level::resize::Extent;
use crate::util::seed::{derive_seed, Stream};

mod attempts;
mod filters;
mod gate;
mod models;
mod options;
mod proposers;
mod reverse;
pub mod settings;
mod variant;
#[cfg(test)]
mod tests;

pub use attempts::{keep_attempt, AttemptRank, BOX_COPIES_BEFORE_RESIZE, BOX_MISSES_BEFORE_RESIZE};
pub use gate::NEW_ENOUGH_LEVEL0_FSCORE;
pub use models::{load_models, untrained_models, Models};
pub use options::{LevelSink, SampleOptions, SampledVariant};
use proposers::{could_bend, AtExtent, Bending};
use variant::OneVariant;
pub use proposers::{RESIZED_CANDIDATES, RESIZE_TRIES};


pub use crate::level::resize::{level0_box, MAX_LEVEL0_BOX_CUBES};


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
    let nothing_new_in_box = std::cell::Cell::new(false);
    let resized_whole = std::cell::Cell::new(false);
    let box_misses = std::cell::Cell::new((0, 0));
    let resized_passes = std::cell::Cell::new((0, 0));
    let repairs = crate::level::repair::repairs(exemplar_levels, &sheet_axes, opts.remove_specks, opts.mend_sheets);
    // The proposers start a pass in the exemplar's box: with a box asked for
    // (`--extent`) or a level to continue from, they are off, and said so.
    if (opts.bend_voxels > 0.0 || opts.resize_max > 0.0) && (opts.extent != [1.0; 3] || continuing) {
        let why = if continuing { "continuing from a level" } else { "in the box --extent asks for" };
        // Said once per process: the pipeline samples one variant per call.
        static SAID: std::sync::Once = std::sync::Once::new();
        SAID.call_once(|| log::info!("sample: no bent or resized starts {why}: every variant is the networks' own"));
    }
    let bending = Bending::of(opts, exemplar_levels, from.is_some());
    let resizing = opts.resize_max > 0.0 && could_bend(opts) && !continuing && !matches!(bending, Bending::Bends(_));
    tch::no_grad(|| {
        (opts.first..opts.first + opts.n)
            .map(|i| {
                nothing_new_in_box.set(false);
                resized_whole.set(false);
                box_misses.set((0, 0));
                resized_passes.set((0, 0));
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
                    nothing_new_in_box: &nothing_new_in_box,
                    resized_whole: &resized_whole,
                    box_misses: &box_misses,
                    resized_passes: &resized_passes,
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
