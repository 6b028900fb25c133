//! Free edges: surface voxels with no surface on one side of them along the
//! surface (a wall's end, a hole's rim, the edge of an open sheet); far more
//! of them than the exemplar has is `torn`.

use glam::IVec3;
use rayon::prelude::*;

use super::thresholds::THRESHOLDS;
use crate::grid::VoxelMap;
use crate::level::Level;

/// Directions around a voxel's normal in which a neighbour is looked for.
const SECTORS: usize = 8;

/// Per voxel of `level` (in row order; false for inactive voxels): whether its
/// surface point lies on a free boundary of the surface. The neighbours are
/// the surface points of the active voxels within 2 voxels (the 5^3 window)
/// on the same side (normals less than 90 degrees apart) and near the tangent
/// plane (within 1 voxel of it), 0.5 to 2.9 voxels away along it. Their
/// directions in the tangent plane are binned into 8 sectors; where 3
/// consecutive sectors are empty, half or more of the voxel's surroundings
/// hold no surface: a wall's end, a hole's rim, the edge of an open sheet. A
/// voxel inside a surface has neighbours all round; a sharp crease keeps its
/// neighbours on both faces (within the window, near the plane of either).
pub fn free_boundary(level: &Level) -> Vec<bool> {
    let index: VoxelMap<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).map(|i| (level.coords[i], i)).collect();
    let point = |i: usize| level.point_voxels(i);
    (0..level.len())
        .into_par_iter()
        .map(|i| {
            if level.mask[i] <= 0.0 {
                return false;
            }
            let Some(n) = level.normals[i].try_normalize() else { return false };
            let u = n.any_orthonormal_vector();
            let w = n.cross(u);
            let p = point(i);
            let mut filled = [false; SECTORS];
            for dz in -2..=2 {
                for dy in -2..=2 {
                    for dx in -2..=2 {
                        let Some(&j) = index.get(level.coords[i] + IVec3::new(dx, dy, dz)) else {
                            continue;
                        };
                        if j == i || level.normals[j].dot(n) <= 0.0 {
                            continue;
                        }
                        let d = point(j) - p;
                        let along = d.dot(n);
                        let t = d - along * n;
                        let r = t.length();
                        if along.abs() > 1.0 || !(0.5..=2.9).contains(&r) {
                            continue;
                        }
                        let a = t.dot(w).atan2(t.dot(u)).rem_euclid(std::f32::consts::TAU);
                        filled[((a / std::f32::consts::TAU * SECTORS as f32) as usize).min(SECTORS - 1)] = true;
                    }
                }
            }
            // The longest cyclic run of empty sectors.
            let (mut run, mut best) = (0, 0);
            for k in 0..2 * SECTORS {
                if filled[k % SECTORS] {
                    run = 0;
                } else {
                    run += 1;
                    best = best.max(run);
                }
            }
            best >= THRESHOLDS.open_sectors
        })
        .collect()
}
