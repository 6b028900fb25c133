//! Copies: how much of a shape is the exemplar's surface again. Two levels'
//! surface voxels are matched both ways with a 1-voxel tolerance
//! ([`Matching`]): the F-score, the largest place that changed, and whether
//! every change is a part of the exemplar moved (`near_copy`).

use std::collections::HashSet;

use glam::IVec3;

use super::thresholds::THRESHOLDS;
use crate::grid::components::{component_labels, components, NEIGHBOURS_26};
use crate::level::Level;

/// The largest place where shape `a` differs from `b` (same resolution): the
/// voxels of either with no voxel of the other within 1 voxel (Chebyshev),
/// grouped into 26-connected regions, the largest region's size as a share of
/// `b`'s voxels (0 for the same surface; 0 when `b` is empty). A copy with its
/// surface jittered differs in many small places; a tower with a ruin of its
/// own differs in one large one.
pub fn largest_change(a: &Level, b: &Level) -> f64 {
    Matching::of(a, b).largest_change()
}

/// F-score of two levels' surface voxels (same resolution) where a voxel
/// counts as matched when the other set has a voxel within 1 voxel
/// (Chebyshev): 1 for the same surface, low for a shape that is elsewhere.
pub fn tolerant_fscore(a: &Level, b: &Level) -> f64 {
    Matching::of(a, b).fscore()
}

impl Matching {
    /// [`largest_change`] of the two.
    pub fn largest_change(&self) -> f64 {
        let m = self;
        if m.b_voxels == 0 {
            return 0.0;
        }
        // A voxel of `a` and one of `b` share a coordinate only if both matched,
        // so the unmatched voxels hold no duplicates.
        let changed: Vec<IVec3> = m.a_unmatched.iter().chain(&m.b_unmatched).copied().collect();
        components(&changed).first().map_or(0.0, |&c| c as f64 / m.b_voxels as f64)
    }

    /// The voxels of `b`'s largest region that `a` lacks (none of `a`'s
    /// within 1 voxel), and the voxels `a` has where `b` has none: an ear
    /// gone with nothing in its place is (9, 0) on the bunny at 16^3.
    pub fn gone_and_added(&self) -> (usize, usize) {
        (components(&self.b_unmatched).first().copied().unwrap_or(0), self.a_unmatched.len())
    }

    /// Share of `a`'s voxels with one of `b` within 1 voxel (0 when either
    /// is empty): below 1 where `a` has something `b` does not.
    pub fn precision(&self) -> f64 {
        if self.a_voxels == 0 || self.b_voxels == 0 {
            return 0.0;
        }
        1.0 - self.a_unmatched.len() as f64 / self.a_voxels as f64
    }

    /// Share of `b`'s voxels with one of `a` within 1 voxel (0 when either
    /// is empty): below 1 where `a` lacks something of `b`.
    pub fn recall(&self) -> f64 {
        if self.a_voxels == 0 || self.b_voxels == 0 {
            return 0.0;
        }
        1.0 - self.b_unmatched.len() as f64 / self.b_voxels as f64
    }

    /// [`tolerant_fscore`] of the two.
    pub fn fscore(&self) -> f64 {
        let (precision, recall) = (self.precision(), self.recall());
        if precision + recall == 0.0 {
            0.0
        } else {
            2.0 * precision * recall / (precision + recall)
        }
    }
}

impl Matching {
    /// Whether every difference of `a` from `b` is a part of `b` moved: each
    /// region (26-connected) of `b`'s voxels that `a` lacks and each region
    /// of voxels `a` adds, of at least `min_share` of `b`'s voxels, pairs
    /// with a region of the other kind that is its shape translated (its
    /// voxels, moved by the difference of the two centroids, within 1 voxel
    /// of the other's for `THRESHOLDS.moved_overlap` of them both ways, and sizes
    /// within a third of each other); smaller regions are a surface's
    /// jitter. False where nothing large changed (that is
    /// [`largest_change`]'s case) or something is left unpaired: a part
    /// added, lost or made anew.
    pub fn moved_parts_only(&self, min_share: f64) -> bool {
        let min = (min_share * self.b_voxels as f64).max(1.0);
        let regions = |set: &[IVec3]| -> Vec<Vec<IVec3>> {
            let (labels, sizes) = component_labels(set);
            let mut out: Vec<Vec<IVec3>> = sizes.iter().map(|&n| Vec::with_capacity(n)).collect();
            for (c, l) in set.iter().zip(labels) {
                out[l].push(*c);
            }
            out.retain(|r| r.len() as f64 >= min);
            out
        };
        let (gone, added) = (regions(&self.b_unmatched), regions(&self.a_unmatched));
        if gone.is_empty() || gone.len() != added.len() {
            return false;
        }
        let mut free = vec![true; gone.len()];
        added.iter().all(|a| {
            let found = (0..gone.len()).find(|&g| free[g] && translated_alike(&gone[g], a));
            found.map(|g| free[g] = false).is_some()
        })
    }
}


/// Whether region `b` is region `a` translated (see `THRESHOLDS.moved_overlap`).
fn translated_alike(a: &[IVec3], b: &[IVec3]) -> bool {
    let (na, nb) = (a.len() as f64, b.len() as f64);
    if na.min(nb) / na.max(nb) < THRESHOLDS.moved_size_ratio {
        return false;
    }
    let centroid = |r: &[IVec3]| r.iter().fold(glam::DVec3::ZERO, |s, c| s + c.as_dvec3()) / r.len() as f64;
    let d = (centroid(b) - centroid(a)).round().as_ivec3();
    let moved: Vec<IVec3> = a.iter().map(|&c| c + d).collect();
    let set = |r: &[IVec3]| -> HashSet<IVec3> { r.iter().copied().collect() };
    let (sm, sb) = (set(&moved), set(b));
    let near = |from: &HashSet<IVec3>, to: &HashSet<IVec3>| 1.0 - unmatched(from, to).len() as f64 / from.len() as f64;
    near(&sm, &sb) >= THRESHOLDS.moved_overlap && near(&sb, &sm) >= THRESHOLDS.moved_overlap
}

/// The voxels of `from` with no voxel of `to` within 1 voxel (Chebyshev).
fn unmatched(from: &HashSet<IVec3>, to: &HashSet<IVec3>) -> Vec<IVec3> {
    from.iter().filter(|&&c| !(to.contains(&c) || NEIGHBOURS_26.iter().any(|&d| to.contains(&(c + d))))).copied().collect()
}

/// Two levels' surface voxels matched both ways with a 1-voxel (Chebyshev)
/// tolerance: the voxels of each with none of the other within 1 voxel.
pub struct Matching {
    a_voxels: usize,
    b_voxels: usize,
    a_unmatched: Vec<IVec3>,
    b_unmatched: Vec<IVec3>,
}

impl Matching {
    pub fn of(a: &Level, b: &Level) -> Matching {
        let set = |l: &Level| -> HashSet<IVec3> { (0..l.len()).filter(|&i| l.mask[i] > 0.0).map(|i| l.coords[i]).collect() };
        let (sa, sb) = (set(a), set(b));
        Matching {
            a_voxels: sa.len(),
            b_voxels: sb.len(),
            a_unmatched: unmatched(&sa, &sb),
            b_unmatched: unmatched(&sb, &sa),
        }
    }
}
