//! @brief Colour where it lives: neighbourhoods of surface colours compared
//! both ways with the exemplar's, plus global colour statistics as secondary
//! figures.
//!
//! Why not global statistics alone: shuffling the exemplar's colours among
//! its voxels keeps every global statistic and destroys every stone, and a
//! washed-out variant can keep most of the per-voxel spread as speckle.
//!
//! 1. **Lattice.** Levels finer than 128^3 are pooled to 128^3 first (mean
//!    colour of the active voxels of each 2^k block), so the neighbourhoods
//!    below span the same fraction of the shape at every resolution and cost
//!    the same.
//! 2. **Colour patch descriptor** of an active voxel (14 numbers, RGB units):
//!    its own colour; the mean colour of the active voxels within Chebyshev
//!    radius 1, 2 and 4 voxels (3^3, 5^3, 9^3 windows that follow the
//!    surface, so the geometry decides what is a neighbour); the RMS colour
//!    deviation within radius 1 and 2 (how much the colour changes locally:
//!    0 inside a stone, large at joints, large everywhere for speckle).
//! 3. **Both ways**, as improved precision and recall (Kynkaanniemi et al.
//!    2019), so that no colour tolerance has to be chosen per exemplar:
//!    distance of two descriptors = RMS over the 14 numbers; up to 4000
//!    voxels are sampled from each shape; each sample's radius is the
//!    distance to its 3rd nearest sample of the same shape (the local scale
//!    of that shape's descriptors). Precision = fraction of the shape's
//!    samples within the radius of some exemplar sample; coverage = fraction
//!    of the exemplar's samples within the radius of some sample of the
//!    shape. Washed-out colours fail coverage (one descriptor, radius 0:
//!    the exemplar's distinct stones are not there); shuffled colours fail
//!    precision (speckle is not in the exemplar); both fail their harmonic
//!    mean, the colour F-score.

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use crate::grid::VoxelIndex;
use crate::level::Level;
use crate::util::rng::Rng;

/// Numbers per descriptor.
pub const DIMS: usize = 14;
/// Finest lattice the descriptors are computed on (voxels per axis).
pub const MAX_RESOLUTION: u32 = 128;
/// Window radii, voxels of the (pooled) lattice.
const RADII: [i32; 3] = [1, 2, 4];

/// Parameters of the colour-patch measure.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ColourParams {
    /// Neighbourhood size of the k-nearest-neighbour manifolds (improved
    /// precision and recall, Kynkaanniemi et al. 2019: k = 3).
    pub k: usize,
    /// At most this many voxels are sampled on each side.
    pub max_samples: usize,
    /// Seed of the sampling.
    pub seed: u64,
    /// Projections of the sliced Wasserstein distance.
    pub slices: usize,
}

impl Default for ColourParams {
    fn default() -> Self {
        ColourParams { k: 3, max_samples: 4000, seed: 4321, slices: 32 }
    }
}

/// The colour-patch descriptors of one level and the per-voxel colours.
pub struct ColourPatches {
    descriptors: Vec<[f32; DIMS]>,
    tree: Option<kiddo::ImmutableKdTree<f32, DIMS>>,
    /// Active voxels' colours at the level's own resolution (for the global
    /// statistics).
    colours: Vec<Vec3>,
}

impl ColourPatches {
    pub fn of(level: &Level) -> ColourPatches {
        let colours: Vec<Vec3> =
            (0..level.len()).filter(|&i| level.mask[i] > 0.0 && level.colours[i].is_finite()).map(|i| level.colours[i]).collect();
        let (coords, pooled) = pool(level);
        let index = VoxelIndex::new(coords.iter().copied());
        let descriptors: Vec<[f32; DIMS]> =
            coords.par_iter().map(|&c| descriptor(c, &index, &pooled)).collect();
        let tree = (!descriptors.is_empty()).then(|| kiddo::ImmutableKdTree::new_from_slice(&descriptors));
        ColourPatches { descriptors, tree, colours }
    }

    pub fn is_empty(&self) -> bool {
        self.descriptors.is_empty()
    }

    /// RMS distance from `d` to the nearest descriptor of this set.
    fn nearest(&self, d: &[f32; DIMS]) -> f32 {
        match &self.tree {
            Some(t) => (t.nearest_one::<kiddo::SquaredEuclidean>(d).distance / DIMS as f32).sqrt(),
            None => f32::INFINITY,
        }
    }

    /// Up to `n` descriptors drawn without replacement (seeded).
    fn sample(&self, n: usize, seed: u64) -> Vec<[f32; DIMS]> {
        let mut idx: Vec<usize> = (0..self.descriptors.len()).collect();
        if idx.len() > n {
            let mut rng = Rng::new(seed);
            for i in 0..n {
                let j = i + rng.below(idx.len() - i);
                idx.swap(i, j);
            }
            idx.truncate(n);
        }
        idx.into_iter().map(|i| self.descriptors[i]).collect()
    }
}

/// Active voxels pooled to at most [`MAX_RESOLUTION`]: (coordinates, mean colours).
fn pool(level: &Level) -> (Vec<IVec3>, Vec<Vec3>) {
    let mut shift = 0;
    while level.resolution >> shift > MAX_RESOLUTION {
        shift += 1;
    }
    let mut sums: std::collections::BTreeMap<(i32, i32, i32), (Vec3, u32)> = Default::default();
    for i in 0..level.len() {
        if level.mask[i] > 0.0 && level.colours[i].is_finite() {
            let c: IVec3 = level.coords[i] >> IVec3::splat(shift);
            let e = sums.entry((c.z, c.y, c.x)).or_insert((Vec3::ZERO, 0));
            e.0 += level.colours[i];
            e.1 += 1;
        }
    }
    sums.into_iter().map(|((z, y, x), (s, n))| (IVec3::new(x, y, z), s / n as f32)).unzip()
}

/// The 14 numbers of step 2 for the voxel at `c`.
fn descriptor(c: IVec3, index: &VoxelIndex, colours: &[Vec3]) -> [f32; DIMS] {
    let r_max = RADII[RADII.len() - 1];
    let mut sum = [Vec3::ZERO; 3];
    let mut sq = [0.0f32; 3];
    let mut n = [0u32; 3];
    for dz in -r_max..=r_max {
        for dy in -r_max..=r_max {
            for dx in -r_max..=r_max {
                let Some(j) = index.get(c + IVec3::new(dx, dy, dz)) else { continue };
                let col = colours[j];
                let cheb = dx.abs().max(dy.abs()).max(dz.abs());
                for (k, &r) in RADII.iter().enumerate() {
                    if cheb <= r {
                        sum[k] += col;
                        sq[k] += col.length_squared();
                        n[k] += 1;
                    }
                }
            }
        }
    }
    let own = index.get(c).map_or(Vec3::ZERO, |i| colours[i]);
    let mean = |k: usize| sum[k] / n[k].max(1) as f32;
    // RMS deviation from the window mean: sqrt(E|c|^2 - |E c|^2).
    let dev = |k: usize| (sq[k] / n[k].max(1) as f32 - mean(k).length_squared()).max(0.0).sqrt();
    let (m1, m2, m4) = (mean(0), mean(1), mean(2));
    [own.x, own.y, own.z, m1.x, m1.y, m1.z, m2.x, m2.y, m2.z, m4.x, m4.y, m4.z, dev(0), dev(1)]
}

/// Colour scores of a shape against the exemplar.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ColourScores {
    /// Fraction of the shape's colour patches with an exemplar patch within
    /// the tolerance (higher is better).
    pub precision: f64,
    /// Fraction of the exemplar's colour patches with a patch of the shape
    /// within the tolerance (higher is better).
    pub coverage: f64,
    /// Harmonic mean of precision and coverage.
    pub fscore: f64,
    /// Mean RMS distance of the shape's patches to their nearest exemplar patch.
    pub distance_to_exemplar: f64,
    /// Mean RMS distance of the exemplar's patches to their nearest shape patch.
    pub distance_from_exemplar: f64,
    /// Secondary, global: sliced 1-Wasserstein distance between the two sets
    /// of per-voxel colours (RGB units; 0 = the same colour histogram).
    pub sliced_wasserstein: f64,
    /// Secondary, global: RMS spread of the shape's colours about their mean
    /// over the exemplar's (1 = as varied; says nothing about where).
    pub spread_ratio: f64,
}

pub fn colour_scores(shape: &ColourPatches, exemplar: &ColourPatches, params: &ColourParams) -> ColourScores {
    let v = shape.sample(params.max_samples, params.seed);
    let e = exemplar.sample(params.max_samples, params.seed ^ 0x5EED);
    let (rv, re) = (knn_radii(&v, params.k), knn_radii(&e, params.k));
    // Precision: shape samples inside the exemplar's manifold; coverage: the
    // exemplar's samples inside the shape's.
    let precision = inside_fraction(&v, &e, &re);
    let coverage = inside_fraction(&e, &v, &rv);
    let fscore = if precision + coverage > 0.0 { 2.0 * precision * coverage / (precision + coverage) } else { 0.0 };
    let mean_nearest = |from: &ColourPatches, to: &ColourPatches, seed: u64| -> f64 {
        let q = from.sample(params.max_samples, seed);
        // Collected, then summed in order: a parallel float sum's order (and
        // last bits) would depend on the scheduling.
        let d: Vec<f64> = q.par_iter().map(|d| to.nearest(d) as f64).collect();
        d.iter().sum::<f64>() / q.len().max(1) as f64
    };
    let es = spread(&exemplar.colours);
    ColourScores {
        precision,
        coverage,
        fscore,
        distance_to_exemplar: mean_nearest(shape, exemplar, params.seed),
        distance_from_exemplar: mean_nearest(exemplar, shape, params.seed ^ 0x5EED),
        sliced_wasserstein: sliced_wasserstein(&shape.colours, &exemplar.colours, params.slices, params.seed),
        // One-colour exemplar: kept finite for JSON.
        spread_ratio: ratio(spread(&shape.colours), es),
    }
}

fn rms_distance(a: &[f32; DIMS], b: &[f32; DIMS]) -> f32 {
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>() / DIMS as f32).sqrt()
}

/// Distance of each sample to its k-th nearest other sample of the same set
/// (brute force: the sets are at most a few thousand).
fn knn_radii(set: &[[f32; DIMS]], k: usize) -> Vec<f32> {
    set.par_iter()
        .enumerate()
        .map(|(i, a)| {
            let mut d: Vec<f32> = set.iter().enumerate().filter(|&(j, _)| j != i).map(|(_, b)| rms_distance(a, b)).collect();
            if d.is_empty() {
                return 0.0;
            }
            let k = k.clamp(1, d.len());
            d.select_nth_unstable_by(k - 1, |x, y| x.total_cmp(y));
            d[k - 1]
        })
        .collect()
}

/// Fraction of `queries` within the radius of at least one member of `set`.
fn inside_fraction(queries: &[[f32; DIMS]], set: &[[f32; DIMS]], radii: &[f32]) -> f64 {
    if queries.is_empty() {
        return 0.0;
    }
    let inside = queries.par_iter().filter(|q| set.iter().zip(radii).any(|(s, &r)| rms_distance(q, s) <= r)).count();
    inside as f64 / queries.len() as f64
}

/// RMS distance of colours from their mean (RGB units; 0 for one colour).
pub fn spread(c: &[Vec3]) -> f64 {
    let m = c.iter().fold(Vec3::ZERO, |a, &b| a + b) / c.len().max(1) as f32;
    (c.iter().map(|&v| (v - m).length_squared() as f64).sum::<f64>() / c.len().max(1) as f64).sqrt()
}

/// `a / b`, with 0 / 0 = 1 (both constant) and kept finite for JSON.
pub(crate) fn ratio(a: f64, b: f64) -> f64 {
    const TINY: f64 = 1e-9;
    if b <= TINY {
        if a <= TINY { 1.0 } else { a / TINY }
    } else {
        a / b
    }
}

/// Sliced 1-Wasserstein distance between two colour sets: the mean over
/// `slices` seeded directions of the 1-D distance of the projections (1000
/// quantiles). Infinite when either set is empty.
pub fn sliced_wasserstein(a: &[Vec3], b: &[Vec3], slices: usize, seed: u64) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    let mut rng = Rng::new(seed);
    let dirs: Vec<Vec3> = (0..slices.max(1))
        .map(|_| loop {
            let v = Vec3::new(rng.uniform() as f32 * 2.0 - 1.0, rng.uniform() as f32 * 2.0 - 1.0, rng.uniform() as f32 * 2.0 - 1.0);
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                break v / l;
            }
        })
        .collect();
    const Q: usize = 1000;
    let per_direction: Vec<f64> = dirs
        .par_iter()
        .map(|d| {
            let proj = |s: &[Vec3]| {
                let mut p: Vec<f32> = s.iter().map(|v| v.dot(*d)).collect();
                p.sort_unstable_by(|x, y| x.total_cmp(y));
                p
            };
            let (pa, pb) = (proj(a), proj(b));
            let q = |p: &[f32], t: f64| p[((t * p.len() as f64) as usize).min(p.len() - 1)] as f64;
            (0..Q).map(|k| (k as f64 + 0.5) / Q as f64).map(|t| (q(&pa, t) - q(&pb, t)).abs()).sum::<f64>() / Q as f64
        })
        .collect();
    per_direction.iter().sum::<f64>() / dirs.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 48x48 wall at z = 0 of 8x6-voxel "stones" in three colours, with
    /// one-voxel dark joints.
    fn wall() -> Level {
        let palette = [Vec3::new(0.6, 0.45, 0.3), Vec3::new(0.5, 0.5, 0.5), Vec3::new(0.35, 0.5, 0.3)];
        let mut l = Level { resolution: 64, ..Default::default() };
        for x in 0..48 {
            for y in 0..48 {
                let course = y / 6;
                let sx = (x + 4 * (course % 2)) / 8;
                let joint = y % 6 == 0 || (x + 4 * (course % 2)) % 8 == 0;
                let c = if joint { Vec3::splat(0.2) } else { palette[((sx * 7 + course * 3) % 3) as usize] };
                l.coords.push(IVec3::new(x, y, 0));
                l.offsets.push(Vec3::ZERO);
                l.normals.push(Vec3::Z);
                l.colours.push(c);
                l.mask.push(1.0);
            }
        }
        l
    }

    #[test]
    fn shuffled_and_washed_out_colours_fail_both_ways() {
        let ex = wall();
        let p = ColourParams::default();
        let e = ColourPatches::of(&ex);
        let same = colour_scores(&e, &e, &p);
        assert_eq!((same.precision, same.coverage, same.fscore), (1.0, 1.0, 1.0));
        assert!(same.sliced_wasserstein < 1e-9);

        let mut washed = ex.clone();
        let mean = ex.colours.iter().fold(Vec3::ZERO, |a, &b| a + b) / ex.len() as f32;
        washed.colours.iter_mut().for_each(|c| *c = mean);
        let w = colour_scores(&ColourPatches::of(&washed), &e, &p);
        assert!(w.coverage < 0.1 && w.fscore < 0.2, "washed out: {w:?}");
        assert!(w.spread_ratio < 1e-3);

        let mut shuffled = ex.clone();
        let mut rng = Rng::new(3);
        for i in (1..shuffled.len()).rev() {
            let j = rng.below(i + 1);
            shuffled.colours.swap(i, j);
        }
        let s = colour_scores(&ColourPatches::of(&shuffled), &e, &p);
        assert!(s.precision < 0.2 && s.fscore < 0.3, "shuffled: {s:?}");
        // Global statistics cannot see the shuffle: that is why they are secondary.
        assert!(s.sliced_wasserstein < 1e-6 && (s.spread_ratio - 1.0).abs() < 1e-6, "{s:?}");
    }

    #[test]
    fn pooling_keeps_fine_levels_on_a_128_lattice() {
        let mut l = wall();
        l.resolution = 512;
        let (coords, _) = pool(&l);
        // 48x48 voxels at 512 -> 12x12 blocks at 128.
        assert_eq!(coords.len(), 144);
        assert!(ColourPatches::of(&Level { resolution: 64, ..Default::default() }).is_empty());
    }
}
