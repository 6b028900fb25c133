//! The choice among attempts: a variant's coarse-to-fine passes, each
//! judged at the structure level (`judge::Verdict`), run until one is whole
//! (and, with `reject_copies`, not a near copy); else the best by a fixed
//! order (whole, then new, then score).

use crate::error::Result;
use crate::util::seed::{derive_seed, Stream};

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
    pub(super) fn key(&self) -> (bool, bool, f64) {
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
pub(super) fn attempt_seed(seed: u64, a: usize) -> u64 {
    if a == 0 {
        seed
    } else {
        derive_seed(seed, a as u64, Stream::StructureAttempt, 0)
    }
}

/// Whole near copies in the exemplar's box after which a variant's later
/// attempts are resized (with `resize_max`). One: on a Han house whose
/// networks copy, a variant's resized passes were broken more often than
/// not, so every attempt left for them counts (its copies 3 -> 2 of 10, one
/// more longer house); on the demo three variants whose second attempt was
/// a tower of its own became wider towers instead (still 10 of 10 whole and
/// new); the ruined tower, which draws no copy, is unchanged bit for bit
/// (docs/lab/single-buildings.md, "A Han house, and resizing after one copy").
pub const BOX_COPIES_BEFORE_RESIZE: usize = 1;

/// Passes in the exemplar's box that were not whole and new (copies or
/// broken) after which a variant's later attempts are resized (with
/// `resize_max`). A single building whose networks, trained with its normals
/// facing out, break it in its own box (a Han house: 8 of 10 variants broken
/// in all six attempts, their level 0s not quite the exemplar's, so never
/// resized) gets longer boxes after two; a ruin whose networks make new
/// shapes in its box seldom misses twice.
pub const BOX_MISSES_BEFORE_RESIZE: usize = 2;
