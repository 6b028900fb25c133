//! Oriented, coloured point sets.

use glam::Vec3;
use rayon::prelude::*;

use crate::level::Level;

/// Oriented, coloured points: what a level looks like as a surface, what
/// the meshers mesh and the previews splat. Struct of arrays, all of the same
/// length (`colours` may be empty: no colours).
#[derive(Clone, Debug, Default)]
pub struct OrientedPoints {
    /// World units (the exemplar's own frame).
    pub positions: Vec<Vec3>,
    /// Outward normals, one per position (not always unit length: a level
    /// stores what the network gave).
    pub normals: Vec<Vec3>,
    /// RGB in [0, 1], one per position, or empty.
    pub colours: Vec<Vec3>,
    /// Typical distance between neighbouring points, world units (a level's
    /// voxel size); <= 0: unknown (the meshers estimate it).
    pub spacing: f32,
}

impl OrientedPoints {
    /// The surface points of the voxels with `mask > 0`, in the exemplar's
    /// own world frame, with `spacing` = the level's voxel size in world units.
    pub fn from_level(level: &Level) -> OrientedPoints {
        let spacing = level.transform().voxel_world() as f32;
        if level.mask.par_iter().all(|&m| m > 0.0) {
            // Every voxel active (the usual case): copy, no index list.
            return OrientedPoints {
                positions: (0..level.len()).into_par_iter().map(|i| level.point_world(i).as_vec3()).collect(),
                normals: level.normals.clone(),
                colours: level.colours.clone(),
                spacing,
            };
        }
        let keep: Vec<u32> =
            (0..level.len() as u32).into_par_iter().filter(|&i| level.mask[i as usize] > 0.0).collect();
        OrientedPoints {
            positions: keep.par_iter().map(|&i| level.point_world(i as usize).as_vec3()).collect(),
            normals: keep.par_iter().map(|&i| level.normals[i as usize]).collect(),
            colours: keep.par_iter().map(|&i| level.colours[i as usize]).collect(),
            spacing,
        }
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}
