//! A smooth random bend of a level: the exemplar deformed into a new pose,
//! the variant sampling makes where the networks offer nothing new
//! (`sample.proposers.bend_voxels`; docs/lab/bent-figures.md, "Bent starts"). A level-0 network
//! that learned one figure with nothing repeated in it (a bunny) draws that
//! figure again or loses a part of it; a bent exemplar is a new pose of the
//! whole figure with its own detail and colours. Tried and not kept: the
//! level-0 network denoising a bent level 0 (from t = 0.2 or 0.4 it broke
//! the shape or drew the exemplar again), and the networks of 32^3 and 64^3
//! refining a bent coarse level (they tore ears and left flakes the bent
//! exemplar does not have).
//!
//! The bend is a sum of a few Gaussian displacement fields in voxel units of
//! the level, each centred at one of its surface points. The level is
//! resampled by splatting: every voxel's surface point and a small grid of
//! points on its tangent plane are moved, their normals turned by the
//! inverse transpose of the bend's Jacobian, and each target voxel takes the
//! mean point and normal of what lands in it (so a stretch does not open
//! gaps between the moved points) and the colour of the point nearest a
//! voxel's own surface point (a texture's edges stay sharp).

use glam::{IVec3, Mat3, Vec3};
use rayon::prelude::*;

use super::Level;
use crate::util::rng::Rng;

/// Gaussian displacement fields summed into one bend.
pub const WARP_BUMPS: usize = 4;

/// Each field's width (its sigma) as a share of the level's bounding box's
/// longest side: a quarter bends a part (an ear, a wall top) and its
/// surroundings together, so the bend stays smooth at 16^3 (4 voxels).
pub const WARP_WIDTH_SHARE: f32 = 0.25;

/// Tangent-plane points per axis splatted per voxel, within +-0.2 voxels of
/// its surface point (5 x 5 = 25 points, 0.1 voxels apart, so a stretch of
/// the bend leaves no gap). Wider reaches into empty neighbours on a curved
/// surface and thickens the shell: unbent, +-0.25 gave the bunny's 16^3
/// level 5% more voxels and one more along an axis, +-0.15 the same voxels
/// (IoU 0.98).
const SPLAT_SIDE: usize = 5;
const SPLAT_REACH: f32 = 0.2;

/// A smooth displacement field in a level's voxel units.
#[derive(Clone, Debug, PartialEq)]
pub struct Warp {
    /// (centre, displacement) of each Gaussian field, voxel units.
    bumps: Vec<(Vec3, Vec3)>,
    /// The fields' sigma, voxels.
    sigma: f32,
}

impl Warp {
    /// A bend of `level` from `seed`: [`WARP_BUMPS`] fields centred at its
    /// surface points drawn at random, each moving its surroundings by up to
    /// `amplitude` voxels in a random direction (the magnitude uniform in
    /// [amplitude / 2, amplitude]). The identity for an empty level or a
    /// zero amplitude.
    pub fn random(level: &Level, amplitude: f32, seed: u64) -> Warp {
        let (lo, hi) = bounds(level);
        let sigma = ((hi - lo).max_element() * WARP_WIDTH_SHARE).max(1.0);
        if level.is_empty() || amplitude <= 0.0 {
            return Warp { bumps: Vec::new(), sigma };
        }
        let mut rng = Rng::new(seed);
        let bumps = (0..WARP_BUMPS)
            .map(|_| {
                let i = rng.below(level.len());
                let centre = level.point_voxels(i);
                // A direction uniform on the sphere (z and azimuth uniform).
                let z = 2.0 * rng.uniform() as f32 - 1.0;
                let phi = std::f32::consts::TAU * rng.uniform() as f32;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let dir = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                let magnitude = amplitude * (0.5 + 0.5 * rng.uniform() as f32);
                (centre, dir * magnitude)
            })
            .collect();
        Warp { bumps, sigma }
    }

    /// The same bend on a grid `factor` times finer (voxel units scaled:
    /// level-0 voxel c spans level-2 voxels 4c .. 4c + 3, factor 4).
    pub fn scaled(&self, factor: f32) -> Warp {
        Warp { bumps: self.bumps.iter().map(|&(c, a)| (c * factor, a * factor)).collect(), sigma: self.sigma * factor }
    }

    /// The displacement at `p` (voxels).
    pub fn displacement(&self, p: Vec3) -> Vec3 {
        self.bumps.iter().map(|&(c, a)| a * self.weight(p, c)).sum()
    }

    /// The largest displacement of any of `level`'s surface points (voxels).
    pub fn largest_move(&self, level: &Level) -> f32 {
        (0..level.len()).map(|i| self.displacement(level.point_voxels(i)).length()).fold(0.0, f32::max)
    }

    fn weight(&self, p: Vec3, c: Vec3) -> f32 {
        (-(p - c).length_squared() / (2.0 * self.sigma * self.sigma)).exp()
    }

    /// The Jacobian of p -> p + displacement(p).
    fn jacobian(&self, p: Vec3) -> Mat3 {
        let mut j = Mat3::IDENTITY;
        for &(c, a) in &self.bumps {
            // d/dp of a * w(p) is a (outer) grad w, grad w = -w (p - c) / sigma^2.
            let grad = -(p - c) * self.weight(p, c) / (self.sigma * self.sigma);
            j += Mat3::from_cols(a * grad.x, a * grad.y, a * grad.z);
        }
        j
    }

    /// `level` bent: its surface resampled onto the same grid (see the
    /// module documentation). Voxels moved outside `[0, resolution)` are
    /// dropped; the result is in coordinate order.
    pub fn apply(&self, level: &Level) -> Level {
        let res = level.resolution as i32;
        // Every splat as (its voxel, its place in the level's order, moved
        // point, turned normal, squared distance from its surface point,
        // colour), sorted by voxel then place and summed per voxel:
        // parallel, and the same sums in the same order whatever the thread
        // count.
        let mut splats: Vec<(IVec3, usize, Vec3, Vec3, f32, Vec3)> = (0..level.len())
            .into_par_iter()
            .flat_map_iter(|i| {
                let s = level.point_voxels(i);
                let n = level.normals[i].normalize_or_zero();
                let (t1, t2) = n.any_orthonormal_pair();
                let colour = level.colours[i];
                (0..SPLAT_SIDE * SPLAT_SIDE).filter_map(move |ab| {
                    let along = |k: usize| SPLAT_REACH * (2.0 * k as f32 / (SPLAT_SIDE - 1) as f32 - 1.0);
                    let (u, v) = (along(ab / SPLAT_SIDE), along(ab % SPLAT_SIDE));
                    let p = s + t1 * u + t2 * v;
                    let moved = p + self.displacement(p);
                    let turned = (self.jacobian(p).inverse().transpose() * n).normalize_or_zero();
                    let cell = moved.floor().as_ivec3();
                    let outside = cell.cmplt(IVec3::ZERO).any() || cell.cmpge(IVec3::splat(res)).any();
                    (!outside).then_some((cell, i * SPLAT_SIDE * SPLAT_SIDE + ab, moved, turned, u * u + v * v, colour))
                })
            })
            .collect();
        splats.par_sort_unstable_by_key(|&(c, order, ..)| (c.x, c.y, c.z, order));
        let mut out = Level { index: level.index, resolution: level.resolution, frame: level.frame, ..Default::default() };
        for run in splats.chunk_by(|a, b| a.0 == b.0) {
            let c = run[0].0;
            let k = run.len() as f32;
            let (point, normal) = run.iter().fold((Vec3::ZERO, Vec3::ZERO), |(p, n), s| (p + s.2, n + s.3));
            // The colour of the splat nearest its own surface point (the
            // first of equals), not a mean: a mean blurs a texture's edges.
            let colour = run.iter().fold((f32::INFINITY, Vec3::ZERO), |best, s| if s.4 < best.0 { (s.4, s.5) } else { best }).1;
            out.coords.push(c);
            out.offsets.push((point / k - c.as_vec3() - Vec3::splat(0.5)).clamp(Vec3::splat(-0.5), Vec3::splat(0.5)));
            out.normals.push(normal.try_normalize().unwrap_or(Vec3::Z));
            out.colours.push(colour);
            out.mask.push(1.0);
        }
        out
    }
}

/// The largest `sample.proposers.bend_voxels`, in level-0 voxels. A field folds the
/// surface over once it moves its centre by about 1.65 of its widths
/// (sigma, a quarter of the longest side: 4 voxels on a 16-voxel shape),
/// and the fields add up where they overlap; 2 was measured on the bunny.
pub const MAX_BEND_VOXELS: f64 = 4.0;

/// Where a variant that started from a bent exemplar records its bend,
/// beside its level files: eval judges its structure against the exemplar
/// bent the same way.
pub const BEND_FILE: &str = "bend.json";

/// A variant's bent start: enough to bend the exemplar's levels again
/// exactly as its start was bent.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bend {
    /// The seed of the bend's fields ([`Warp::random`] on the exemplar's level 0).
    pub seed: u64,
    /// The largest move of one field, in voxels of the exemplar's level 0.
    pub voxels: f32,
}

impl Bend {
    /// The bend in the voxel units of `levels[index]` (resolutions are
    /// relative to level 0's).
    pub fn warp_at(&self, levels: &[Level], index: usize) -> Warp {
        let factor = levels[index].resolution as f32 / levels[0].resolution as f32;
        Warp::random(&levels[0], self.voxels, self.seed).scaled(factor)
    }

    /// `levels[index]` bent.
    pub fn bent(&self, levels: &[Level], index: usize) -> Level {
        self.warp_at(levels, index).apply(&levels[index])
    }
}

/// The bounding box of `level`'s voxels, voxel units ((0, 0) when empty).
fn bounds(level: &Level) -> (Vec3, Vec3) {
    if level.is_empty() {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    let lo = level.coords.iter().fold(IVec3::MAX, |a, &c| a.min(c));
    let hi = level.coords.iter().fold(IVec3::MIN, |a, &c| a.max(c));
    (lo.as_vec3(), (hi + IVec3::ONE).as_vec3())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::synthetic::sphere_levels;

    fn ball() -> Level {
        sphere_levels(&[32], glam::DVec3::ZERO, 0.6).remove(0)
    }

    fn voxel_iou(a: &Level, b: &Level) -> f64 {
        let sa: std::collections::HashSet<IVec3> = a.coords.iter().copied().collect();
        let sb: std::collections::HashSet<IVec3> = b.coords.iter().copied().collect();
        sa.intersection(&sb).count() as f64 / sa.union(&sb).count() as f64
    }

    #[test]
    fn no_bend_gives_the_level_back_voxel_for_voxel() {
        let ball = ball();
        let same = Warp::random(&ball, 0.0, 1).apply(&ball);
        assert!(voxel_iou(&ball, &same) > 0.9, "IoU {}", voxel_iou(&ball, &same));
        // Normals still point out of the ball.
        let centre = Vec3::splat(16.0);
        for i in 0..same.len() {
            let p = same.point_voxels(i);
            assert!(same.normals[i].dot(p - centre) > 0.0);
        }
    }

    #[test]
    fn the_same_bend_on_a_finer_grid_moves_each_point_as_far_in_its_units() {
        let ball = ball();
        let warp = Warp::random(&ball, 2.0, 3);
        let fine = warp.scaled(4.0);
        for p in [Vec3::new(10.0, 12.5, 20.0), Vec3::splat(16.0), Vec3::new(3.0, 28.0, 9.5)] {
            assert!((fine.displacement(p * 4.0) - warp.displacement(p) * 4.0).length() < 1e-4);
        }
        // A bend record gives the bend back from the level it was drawn on.
        let bend = Bend { seed: 3, voxels: 2.0 };
        let levels = vec![ball.clone()];
        assert_eq!(bend.warp_at(&levels, 0), warp);
        let text = serde_json::to_string(&bend).unwrap();
        assert_eq!(serde_json::from_str::<Bend>(&text).unwrap(), bend);
    }

    #[test]
    fn a_bend_moves_the_shape_and_keeps_it_whole() {
        let ball = ball();
        let warp = Warp::random(&ball, 3.0, 7);
        assert!(warp.largest_move(&ball) > 1.5, "moved {}", warp.largest_move(&ball));
        let bent = warp.apply(&ball);
        assert!(voxel_iou(&ball, &bent) < 0.8, "IoU {}", voxel_iou(&ball, &bent));
        // The same seed, the same bend.
        assert_eq!(warp, Warp::random(&ball, 3.0, 7));
        // One piece, as the ball is (the judge's verdict on a bend is
        // tested in `judge::tests`).
        let coords: Vec<IVec3> = (0..bent.len()).map(|i| bent.coords[i]).collect();
        assert_eq!(crate::grid::components::components(&coords).len(), 1);
        // Normals turned with the surface: still outward from the bent
        // ball's centre for nearly all voxels.
        let centre = bent.coords.iter().map(|c| c.as_vec3()).sum::<Vec3>() / bent.len() as f32 + Vec3::splat(0.5);
        let outward = (0..bent.len())
            .filter(|&i| bent.normals[i].dot(bent.point_voxels(i) - centre) > 0.0)
            .count();
        assert!(outward as f64 > 0.95 * bent.len() as f64, "{outward} of {}", bent.len());
    }
}
