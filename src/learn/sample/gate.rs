//! The level-0 gate: of the level-0 shapes drawn for a pass, which is kept.
//! A candidate passes when its structure score against the exemplar's
//! level 0 reaches `level0_min_structure` and it lost no part; the `novel`
//! pick keeps the first new enough, else the least like the exemplar; in a
//! resized box, the first like enough to the exemplar at that extent, else
//! the likest.

use crate::judge::{Flag, Structure, Thresholds, Verdict};
use crate::level::Level;
use crate::util::seed::{derive_seed, Stream};

/// A passing level-0 candidate whose 1-voxel-tolerant F-score against the
/// exemplar's level 0 is below this ends the novel pick's draws: new enough.
/// Measured on the demo and the tower (16^3): candidates the finer levels
/// turned into near copies scored 0.990-1.000, those that became towers of
/// their own 0.94-0.981; stopping there saves most of the draws (each a
/// full reverse process at level 0).
pub const NEW_ENOUGH_LEVEL0_FSCORE: f64 = 0.985;

/// In a resized box, a passing level-0 candidate whose F-score against the
/// exemplar's level 0 at that extent reaches this ends the draws: like
/// enough, the exemplar at that size. Otherwise all the candidates are drawn
/// ([`super::proposers::RESIZED_CANDIDATES`]) and the likest kept. The box's
/// size is what is new there; a start that differs from the exemplar at its
/// extent has lost a part the finer levels do not grow back. Measured at
/// 16^3 (`examples/level0_at_extent.rs`, docs/lab/single-buildings.md): the
/// first passing starts the Han house and the Mauryan hall kept when they
/// lost the rear hall and the front vault read 0.957 and 0.984; the starts
/// of whole longer buildings 0.978-1.000 (the temple's ten 1.000).
pub const LIKE_ENOUGH_AT_EXTENT_FSCORE: f64 = 0.995;

/// Why the level-0 pick kept the candidate it kept.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Kept {
    /// `first`: the first that passed.
    First,
    /// `novel`: the first that passed with an F-score below
    /// [`NEW_ENOUGH_LEVEL0_FSCORE`] against the exemplar's level 0.
    NewEnough { fscore: f64, change: f64 },
    /// `novel`: none new enough; of those that passed, the least like the
    /// exemplar (lowest F-score, then the largest changed region).
    LeastLike { fscore: f64, change: f64 },
    /// In a resized box: the first that passed with an F-score of
    /// [`LIKE_ENOUGH_AT_EXTENT_FSCORE`] or more against the exemplar at
    /// the box's extent.
    LikeEnough { fscore: f64, change: f64 },
    /// In a resized box, none like enough: of those that passed, the likest
    /// (highest F-score, then the smallest changed region).
    Likest { fscore: f64, change: f64 },
    /// None passed: the best scoring.
    BestScoring { score: f64, fscore: f64 },
}

/// How the pick chooses among the candidates that pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Policy {
    /// The first (`sample.level0.pick = "first"`).
    First,
    /// The first new enough, else the least like the exemplar
    /// (`"novel"`).
    Novel,
    /// In a resized box: the first like enough to the exemplar at the box's
    /// extent, else the likest.
    Likest,
}

/// What an offered candidate means for the pick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Offer {
    /// Hold it as the fallback: it is the best scoring so far.
    pub(super) best: bool,
    /// Hold it as the pick: the first that passed (`first`), or the least
    /// like the exemplar of those passing so far (`novel`).
    pub(super) picked: bool,
    /// Draw no more candidates.
    pub(super) stop: bool,
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
pub(super) struct Level0Pick {
    pub(super) policy: Policy,
    pub(super) min_structure: f64,
    /// (score, k, F-score against the exemplar) of the best scoring.
    pub(super) best: Option<(f64, usize, f64)>,
    /// ((F-score, change), k) of the one that passed that the policy ranks
    /// first so far: the least like the exemplar (`Novel`), the likest
    /// (`Likest`).
    pub(super) ranked: Option<((f64, f64), usize)>,
    /// The `first` pick's candidate, once one passed.
    pub(super) first: Option<usize>,
}

impl Level0Pick {
    pub(super) fn new(pick: crate::config::Level0Pick, min_structure: f64) -> Self {
        let policy = match pick {
            crate::config::Level0Pick::First => Policy::First,
            crate::config::Level0Pick::Novel => Policy::Novel,
        };
        Self::with_policy(policy, min_structure)
    }

    pub(super) fn with_policy(policy: Policy, min_structure: f64) -> Self {
        Level0Pick { policy, min_structure, best: None, ranked: None, first: None }
    }

    pub(super) fn passes(&self, score: f64, part_lost: bool) -> bool {
        score >= self.min_structure && (self.min_structure <= 0.0 || !part_lost)
    }

    /// Candidate `k` with its structure score, whether it lost a part
    /// (`shrunken` or `thin_part_lost`) and its `likeness` (F-score and
    /// largest changed region against the exemplar's level 0).
    pub(super) fn offer(&mut self, k: usize, score: f64, part_lost: bool, likeness: (f64, f64)) -> Offer {
        let pass = self.passes(score, part_lost);
        let mut offer = Offer { best: false, picked: false, stop: false };
        if self.best.is_none_or(|(b, _, _)| score > b) {
            self.best = Some((score, k, likeness.0));
            offer.best = true;
        }
        if !pass {
            return offer;
        }
        match self.policy {
            Policy::First => {
                self.first = Some(k);
                offer.picked = true;
                offer.stop = true;
            }
            Policy::Novel | Policy::Likest => {
                let likest = self.policy == Policy::Likest;
                // Lower ranks first: the least like the exemplar (a lower
                // F-score, then a larger change), or the likest (a higher
                // F-score, then a smaller change).
                let key = |(f, c): (f64, f64)| if likest { (-f, c) } else { (f, -c) };
                if self.ranked.is_none_or(|(r, _)| key(likeness) < key(r)) {
                    self.ranked = Some((likeness, k));
                    offer.picked = true;
                }
                offer.stop = if likest { likeness.0 >= LIKE_ENOUGH_AT_EXTENT_FSCORE } else { likeness.0 < NEW_ENOUGH_LEVEL0_FSCORE };
            }
        }
        offer
    }

    /// The candidate kept, and why (None before any offer).
    pub(super) fn kept(&self) -> Option<(usize, Kept)> {
        if let Some(k) = self.first {
            return Some((k, Kept::First));
        }
        if let Some(((fscore, change), k)) = self.ranked {
            let why = match self.policy {
                Policy::Likest if fscore >= LIKE_ENOUGH_AT_EXTENT_FSCORE => Kept::LikeEnough { fscore, change },
                Policy::Likest => Kept::Likest { fscore, change },
                _ if fscore < NEW_ENOUGH_LEVEL0_FSCORE => Kept::NewEnough { fscore, change },
                _ => Kept::LeastLike { fscore, change },
            };
            return Some((k, why));
        }
        self.best.map(|(score, k, fscore)| (k, Kept::BestScoring { score, fscore }))
    }
}

/// A level-0 candidate's figures for [`Level0Pick`], against the exemplar's
/// level 0: its structure score, whether it lost a part (`shrunken` or
/// `thin_part_lost`), and its likeness (F-score, largest changed region). An
/// empty candidate scores 0, has lost everything and is like nothing.
pub(super) fn level0_gate(level: &Level, ex_level: &Level, ex_structure: &Structure, params: &Thresholds) -> (f64, bool, (f64, f64)) {
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

/// The seed of level-0 candidate `k` of a variant (candidate 0 is the
/// variant's own seed: without rejection, nothing changes).
pub(super) fn candidate_seed(seed: u64, k: usize) -> u64 {
    if k == 0 {
        seed
    } else {
        derive_seed(seed, k as u64, Stream::Level0Candidate, 0)
    }
}
