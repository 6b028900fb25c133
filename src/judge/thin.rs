//! Thin parts: surface voxels whose opposite surface is near behind them (an
//! ear, a wall, a fin, a spire). A figure that loses one inside its bounding
//! box keeps its size and its surface; only the thin-part count drops
//! (`thin_part_lost`).

use glam::Vec3;
use rayon::prelude::*;

use super::thresholds::THRESHOLDS;
use crate::grid::VoxelMap;
use crate::level::Level;


/// Per voxel of `level`, whether it is a surface voxel on a thin part: the
/// surface facing the other way (another surface voxel whose normal points
/// away from this one's, by more than 100 degrees) is met within `depth`
/// voxels along the inward normal from the voxel's surface point (a
/// shape-diameter test, marched in quarter voxels from 0.75). The share of
/// such voxels is about 0.15 on the bunny at 64^3 (its ears), 0.5 on the ruined tower
/// (its walls), 0.75 on the demo tower.
pub fn thin_voxels(level: &Level, depth: f32) -> Vec<bool> {
    let index: VoxelMap<usize> =
        (0..level.len()).filter(|&i| level.mask[i] > 0.0).map(|i| (level.coords[i], i)).collect();
    (0..level.len())
        .into_par_iter()
        .map(|i| {
            if level.mask[i] <= 0.0 {
                return false;
            }
            // A network's normals are not unit length until written (the
            // sampler's gate sees them before): normalised here, so the gate
            // and `eval` of the written files count the same voxels.
            let n = level.normals[i].normalize_or_zero();
            if n == Vec3::ZERO {
                return false;
            }
            let p = level.point_voxels(i);
            let mut d = 0.75f32;
            while d <= depth {
                let q = (p - n * d).floor().as_ivec3();
                if let Some(&j) = index.get(q) {
                    if j != i && level.normals[j].normalize_or_zero().dot(n) < THRESHOLDS.thin_opposite_cos {
                        return true;
                    }
                }
                d += 0.25;
            }
            false
        })
        .collect()
}

/// How many surface voxels of `level` are on a thin part ([`thin_voxels`]
/// at `THRESHOLDS.thin_depth`).
pub fn thin_count(level: &Level) -> usize {
    thin_voxels(level, THRESHOLDS.thin_depth).iter().filter(|&&t| t).count()
}
