//! One variant: its passes (a start from a proposer, the gate, the level
//! filters, the reverse process level by level), the choice among them, and
//! the kept pass carried on to the finest level. Composes every other file
//! of [`super`]; none of them imports it.

use std::sync::Arc;

use tch::{Kind, Tensor};

use crate::learn::schedule::{Sampler, Schedule};
use crate::judge::{Against, Flag, Structure, Thresholds, Verdict};
use crate::error::Result;
use crate::learn::grid::SparseGrid;
use crate::level::repair::LevelRepair;
use crate::level::{Level, FEATURE_CHANNELS};
use crate::learn::sparse::SparseTensor;
use crate::level::resize::Extent;
use crate::level::warp::Bend;
use crate::util::seed::{derive_seed, Stream};

use super::attempts::{attempt_seed, keep_attempt, AttemptRank, BOX_COPIES_BEFORE_RESIZE, BOX_MISSES_BEFORE_RESIZE};
use super::gate::{candidate_seed, level0_gate, Kept, Level0Pick, Policy};
use super::models::Models;
use super::options::{LevelSink, SampleOptions, SampledVariant};
use super::proposers::{could_bend, AtExtent, Bending, Start, RESIZED_CANDIDATES, RESIZE_TRIES};
use super::{filters, reverse};

/// Everything one variant's coarse-to-fine pass needs.
#[derive(Clone, Copy)]
pub(super) struct OneVariant<'a> {
    pub(super) models: &'a Models,
    /// The exemplar's levels (a bent start bends them).
    pub(super) exemplar_levels: &'a [Level],
    pub(super) frame: crate::level::Frame,
    pub(super) last: usize,
    pub(super) sampler: Sampler,
    pub(super) schedule: Schedule,
    pub(super) seed: u64,
    /// The exemplar at the pass's extent: the level-0 box, and what the
    /// level-0 candidates and the attempts are judged against.
    pub(super) at: &'a AtExtent,
    /// The exemplar's own structure level, where `at` is resized: the
    /// out-of-style patches are judged against it.
    pub(super) style: Option<(&'a Level, &'a Structure)>,
    /// Per level, what it gets once made ([`crate::level::repair::repairs`];
    /// empty: nothing).
    pub(super) repairs: &'a [LevelRepair],
    /// Whether a pass with nothing new at level 0 is the exemplar bent.
    pub(super) bending: Bending,
    /// Set once the exemplar's box offered this variant nothing whole and
    /// new: level-0 candidates none new enough, a whole near copy, or passes
    /// that were copies or broken. Its later attempts start resized at once.
    pub(super) nothing_new_in_box: &'a std::cell::Cell<bool>,
    /// Whether a resized pass of this variant was whole: if none was, its
    /// last attempt takes the exemplar's box (a whole copy before a broken
    /// shape).
    pub(super) resized_whole: &'a std::cell::Cell<bool>,
    /// Attempts of this variant in the exemplar's box that were whole near
    /// copies, and that were not whole and new (copies or broken): at
    /// [`BOX_COPIES_BEFORE_RESIZE`] or [`BOX_MISSES_BEFORE_RESIZE`] its later
    /// attempts resize.
    pub(super) box_misses: &'a std::cell::Cell<(usize, usize)>,
    /// This variant's resized passes, and how many were whole at the
    /// structure level: after [`RESIZE_TRIES`] with none whole its later
    /// attempts are not resized. Per variant, like every choice of a
    /// variant: what one variant's passes found never steers another's (a
    /// shard of variants writes what one run writes).
    pub(super) resized_passes: &'a std::cell::Cell<(usize, usize)>,
    /// Whether a pass whose level-0 candidates are none new enough is
    /// resized (`resize_max`, not bent, the novel pick in the exemplar's box).
    pub(super) resizing: bool,
    /// Who is told of each level of the variant as it is made, with the
    /// variant's index.
    pub(super) told: Option<(usize, LevelSink<'a>)>,
}

/// One coarse-to-fine pass: its levels, the last one's pruned tensor, and
/// how it started where not from the network in the sampling's box: bent,
/// or resized (with the exemplar at that extent, which judges it).
pub(super) struct Pass {
    pub(super) levels: Vec<Level>,
    pub(super) cur: SparseTensor,
    pub(super) bend: Option<Bend>,
    pub(super) resized: Option<AtExtent>,
}

impl OneVariant<'_> {
    /// Level 0 from the noise of `seed` in this pass's box, pruned.
    fn level0(&self, resolution0: u32, seed: u64, opts: &SampleOptions) -> Result<SparseTensor> {
        reverse::level0(self.models, &self.schedule, resolution0, self.at.box0, seed, opts)
    }

    /// `level` (and its pruned tensor) through the level filters.
    fn repaired(&self, pruned: SparseTensor, level: Level) -> Result<(SparseTensor, Level)> {
        filters::repaired(self.repairs, self.models.device, self.frame, pruned, level)
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
    /// at once are the variant's later attempts. A resized box keeps, of
    /// the candidates that pass against the exemplar at its extent, the first
    /// like enough to it ([`super::gate::LIKE_ENOUGH_AT_EXTENT_FSCORE`]),
    /// else the likest: the size is what is new, and a start unlike the
    /// exemplar at that size has lost a part.
    fn chosen_level0(&self, seed: u64, resolution0: u32, opts: &SampleOptions) -> Result<Start> {
        if self.resizes() && self.nothing_new_in_box.get() {
            if let Some(extent) = self.drawn_extent(seed, opts) {
                return Ok(Start::Resized(extent));
            }
        }
        let (ex_level, ex_structure) = (&self.at.level0, &self.at.structure0);
        let params = Thresholds::default();
        let resized = !self.at.extent.is_same();
        let candidates = if resized { opts.level0_candidates.clamp(1, RESIZED_CANDIDATES) } else { opts.level0_candidates.max(1) };
        let mut pick = if resized { Level0Pick::with_policy(Policy::Likest, opts.level0_min_structure) } else { Level0Pick::new(opts.level0_pick, opts.level0_min_structure) };
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
            log::debug!("level 0 candidate {k}: structure {score:.3}, F {:.3}, change {:.3}{}", likeness.0, likeness.1, if part_lost { ", a part lost" } else { "" });
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
        if matches!(why, Kept::LeastLike { .. } | Kept::BestScoring { .. }) {
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
                self.nothing_new_in_box.set(true);
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
            Kept::LikeEnough { fscore, change } | Kept::Likest { fscore, change } => {
                let how = if matches!(why, Kept::LikeEnough { .. }) { "like enough" } else { "the likest of all" };
                log::info!("level 0: candidate {k} of {candidates} kept, {how} (F {fscore:.3}, change {change:.3} against the exemplar's level 0 at extent {})", self.at.extent);
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

    /// Whether a pass with nothing new at level 0 is resized: resizing is on
    /// and this variant's resized passes have not failed [`RESIZE_TRIES`]
    /// times with none whole.
    fn resizes(&self) -> bool {
        let (passes, whole) = self.resized_passes.get();
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
            let last_in_box = a + 1 == attempts && a > 0 && self.nothing_new_in_box.get() && !self.resized_whole.get();
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
            // floor), or passes there that are copies or broken: the
            // networks offer nothing whole and new in that box, and later
            // attempts resize.
            if p.resized.is_none() && p.bend.is_none() && !(rank.whole && rank.new) && self.resizes() && !self.nothing_new_in_box.get() {
                let (copies, misses) = self.box_misses.get();
                let (copies, misses) = (copies + (rank.whole as usize), misses + 1);
                self.box_misses.set((copies, misses));
                if copies == BOX_COPIES_BEFORE_RESIZE {
                    log::info!("whole near copies in the exemplar's box ({BOX_COPIES_BEFORE_RESIZE}): the later attempts resize");
                    self.nothing_new_in_box.set(true);
                } else if misses == BOX_MISSES_BEFORE_RESIZE {
                    log::info!("{BOX_MISSES_BEFORE_RESIZE} passes in the exemplar's box, none whole and new: the later attempts resize");
                    self.nothing_new_in_box.set(true);
                }
            }
            if p.resized.is_some() {
                self.resized_whole.set(self.resized_whole.get() || rank.whole);
                let (passes, whole) = self.resized_passes.get();
                let record = (passes + 1, whole + rank.whole as usize);
                self.resized_passes.set(record);
                if record.0 == RESIZE_TRIES && record.1 == 0 {
                    log::warn!("{RESIZE_TRIES} resized passes of this variant, none whole: its later attempts stay in the exemplar's box");
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
                        "; for a figure with nothing repeated in it (a statue, an animal), --set sample.proposers.bend_voxels=2 poses it anew"
                    }
                    Bending::NotAFigure if opts.resize_max == 0.0 => {
                        "; the networks copy what appears once in the exemplar: --set sample.proposers.resize_max=1.5 draws longer boxes instead (a longer house), or try --extent"
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
    /// The variant: one coarse-to-fine pass from its seed, or with
    /// `attempts` > 1 (and no level to continue from), passes from new
    /// level-0 noise (attempt seeds) until one is whole at the structure
    /// level ([`Verdict`] flags); else the best (whole first, then
    /// not a near copy, then by score). Attempts stop at the structure
    /// level; only the kept one goes on to the finer levels (continuing
    /// from a level reproduces the pass that made it, so the variant is the
    /// same as if every attempt had gone to the end; a bent pass goes on
    /// bent).
    pub(super) fn run(&self, resolution0: u32, opts: &SampleOptions, from: Option<&Level>) -> Result<SampledVariant> {
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
            let pruned = reverse::upper_level(self.models, &self.schedule, l, &cur, seed, opts, self.sampler)?;
            let level = pruned.to_level(l, self.frame)?;
            let (pruned, level) = self.repaired(pruned, level)?;
            self.tell(&level);
            cur = pruned;
            out.push(level);
        }
        Ok(cur)
    }
}
