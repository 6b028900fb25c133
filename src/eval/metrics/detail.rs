//! @brief Geometric detail of a level: how sharply its surface turns from one
//! voxel to the next, as a distribution compared with the exemplar's.
//!
//! Why: local-patch precision cannot fail a smoothed or blob-like variant
//! (its gentle patches all exist somewhere on the exemplar); a blur shows up
//! as a shift of this distribution towards small angles.
//!
//! 1. **Variation per voxel.** For every active voxel of the finest level, the
//!    mean angle (degrees) between its normal and the normals of its active
//!    26-neighbours (one voxel apart, whatever the resolution). A flat wall
//!    gives ~0, a 90-degree crease ~30-45 on the voxels along it, noise
//!    anything up to 180.
//! 2. **Compare distributions.** Against the exemplar's: the 1-Wasserstein
//!    distance of the two distributions (degrees; 0 = the same
//!    distribution), and the ratio of their root-mean-square angles (1 = as
//!    sharp as the exemplar, < 1 smoother, > 1 noisier). The RMS, not the
//!    mean: smoothing spreads a crease's total turning over more voxels,
//!    which keeps the mean angle roughly constant but lowers its square.

use glam::IVec3;
use rayon::prelude::*;

use crate::grid::VoxelIndex;
use crate::level::Level;

/// Angles above this (degrees) count as a sharp feature in `sharp_fraction`.
pub const SHARP_DEG: f64 = 20.0;

/// The per-voxel variation of one level, sorted ascending (degrees).
#[derive(Clone, Debug, Default)]
pub struct Variation {
    pub sorted_deg: Vec<f64>,
}

impl Variation {
    /// Mean neighbour-normal angle of every active voxel that has at least
    /// one active neighbour.
    pub fn of(level: &Level) -> Variation {
        let active: Vec<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).collect();
        let index = VoxelIndex::new(active.iter().map(|&i| level.coords[i]));
        let mut v: Vec<f64> = active
            .par_iter()
            .filter_map(|&i| {
                let (c, n) = (level.coords[i], level.normals[i].normalize_or_zero());
                let (mut sum, mut count) = (0.0f64, 0u32);
                for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            if (dx, dy, dz) == (0, 0, 0) {
                                continue;
                            }
                            if let Some(j) = index.get(c + IVec3::new(dx, dy, dz)) {
                                let m = level.normals[active[j]].normalize_or_zero();
                                sum += (n.dot(m).clamp(-1.0, 1.0) as f64).acos().to_degrees();
                                count += 1;
                            }
                        }
                    }
                }
                (count > 0 && sum.is_finite()).then(|| sum / count as f64)
            })
            .collect();
        v.par_sort_unstable_by(|a, b| a.total_cmp(b));
        Variation { sorted_deg: v }
    }

    pub fn is_empty(&self) -> bool {
        self.sorted_deg.is_empty()
    }

    pub fn mean(&self) -> f64 {
        self.sorted_deg.iter().sum::<f64>() / self.sorted_deg.len().max(1) as f64
    }

    pub fn rms(&self) -> f64 {
        (self.sorted_deg.iter().map(|v| v * v).sum::<f64>() / self.sorted_deg.len().max(1) as f64).sqrt()
    }

    /// Fraction of voxels turning by more than [`SHARP_DEG`].
    pub fn sharp_fraction(&self) -> f64 {
        let above = self.sorted_deg.len() - self.sorted_deg.partition_point(|&v| v <= SHARP_DEG);
        above as f64 / self.sorted_deg.len().max(1) as f64
    }

    /// The q-quantile (q in [0, 1]) by nearest rank.
    fn quantile(&self, q: f64) -> f64 {
        let n = self.sorted_deg.len();
        self.sorted_deg[((q * n as f64) as usize).min(n - 1)]
    }
}

/// 1-Wasserstein distance between two 1-D distributions (their units),
/// integrated over 1000 evenly spaced quantiles. Infinite when either is empty.
pub fn wasserstein_1d(a: &Variation, b: &Variation) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    const Q: usize = 1000;
    (0..Q).map(|k| (k as f64 + 0.5) / Q as f64).map(|q| (a.quantile(q) - b.quantile(q)).abs()).sum::<f64>() / Q as f64
}

/// The detail of a shape against the exemplar's.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DetailScores {
    /// 1-Wasserstein distance of the neighbour-angle distributions, degrees
    /// (0 = the exemplar's distribution; lower is better).
    pub w1_deg: f64,
    /// RMS neighbour angle over the exemplar's (1 = as sharp; < 1 smoother).
    pub rms_ratio: f64,
    /// Mean neighbour angle of this shape, degrees.
    pub mean_deg: f64,
    /// RMS neighbour angle of this shape, degrees.
    pub rms_deg: f64,
    /// Fraction of voxels turning by more than 20 degrees.
    pub sharp_fraction: f64,
}

impl DetailScores {
    /// Both distributions must be non-empty (else the distance is infinite).
    pub fn new(shape: &Variation, exemplar: &Variation) -> Self {
        let er = exemplar.rms();
        DetailScores {
            w1_deg: wasserstein_1d(shape, exemplar),
            rms_ratio: super::colour::ratio(shape.rms(), er),
            mean_deg: shape.mean(),
            rms_deg: shape.rms(),
            sharp_fraction: shape.sharp_fraction(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A staircase-free test surface: a flat 40x40 sheet at z = 0 whose normals
    /// tilt by `crease` degrees on the half x >= 20 (a crease along x = 20).
    fn creased_sheet(crease: f32, blur: i32) -> Level {
        let mut l = Level { resolution: 64, ..Default::default() };
        for x in 0..40 {
            for y in 0..40 {
                // Blur: the tilt ramps linearly over 2*blur+1 voxels.
                let t = if blur == 0 {
                    if x >= 20 { 1.0 } else { 0.0 }
                } else {
                    ((x - 20 + blur) as f32 / (2 * blur) as f32).clamp(0.0, 1.0)
                };
                let a = (crease * t).to_radians();
                l.coords.push(IVec3::new(x, y, 0));
                l.offsets.push(Vec3::ZERO);
                l.normals.push(Vec3::new(a.sin(), 0.0, a.cos()));
                l.colours.push(Vec3::splat(0.5));
                l.mask.push(1.0);
            }
        }
        l
    }

    #[test]
    fn blur_lowers_rms_and_moves_the_distribution() {
        let sharp = Variation::of(&creased_sheet(90.0, 0));
        let soft = Variation::of(&creased_sheet(90.0, 4));
        let flat = Variation::of(&creased_sheet(0.0, 0));
        assert_eq!(wasserstein_1d(&sharp, &sharp), 0.0);
        let d = DetailScores::new(&soft, &sharp);
        assert!(d.rms_ratio < 0.6, "a blurred crease is less sharp: {d:?}");
        assert!(d.w1_deg > 0.5, "{d:?}");
        assert!(flat.rms() < 1e-3 && DetailScores::new(&flat, &sharp).rms_ratio < 1e-3);
        // The sharp crease: 2 columns of 40 voxels turn, each by a third to a
        // half of 90 degrees, so 5% of the voxels are above 20 degrees.
        assert!((sharp.sharp_fraction() - 0.05).abs() < 0.01, "{}", sharp.sharp_fraction());
    }

    #[test]
    fn inactive_voxels_and_empty_levels() {
        let mut l = creased_sheet(90.0, 0);
        for m in l.mask.iter_mut() {
            *m = -1.0;
        }
        assert!(Variation::of(&l).is_empty());
        assert!(wasserstein_1d(&Variation::of(&l), &Variation::of(&creased_sheet(0.0, 0))).is_infinite());
    }
}
