//! Out of style: surface like no part of the exemplar. Each surface voxel's
//! 11^3 neighbourhood is matched against every one of the exemplar's
//! (exactly, at every place and shift: [`super::patches`], the matching of
//! eval's LP-IoU); a wall fallen outward, a heap of rubble or ragged sheets
//! match nothing (`out_of_style`, `fine_out_of_style`).

use glam::IVec3;

use super::thresholds::THRESHOLDS;
use crate::grid::VoxelMap;
use crate::level::Level;



/// Per row of `shape` (false for inactive voxels): whether the surface
/// voxel's 11^3 neighbourhood (the voxels of its level around it) overlaps
/// each 11^3 neighbourhood of `exemplar`'s level (the same resolution), at
/// every place and shift, with an IoU below `THRESHOLDS.unlike_iou`: a part with no
/// counterpart anywhere on the exemplar, out of its style (a wall fallen
/// outward, a heap of rubble, a wall split into ragged sheets). A new
/// arrangement of the exemplar's own parts shares its neighbourhoods; so does
/// the exemplar moved by whole voxels. Not turned: a wall at an angle the
/// exemplar has none at is unlike it. Matched exactly and exhaustively
/// ([`crate::judge::patches`], the matching of eval's LP-IoU). All false
/// below 32^3.
pub fn unlike_voxels(shape: &Level, exemplar: &Level) -> Vec<bool> {
    use super::patches::{surface_voxels_below_iou, ExemplarPatches};
    let mut unlike = vec![false; shape.len()];
    if shape.resolution < THRESHOLDS.unlike_min_resolution || shape.resolution != exemplar.resolution {
        return unlike;
    }
    let dictionary = ExemplarPatches::new(&voxel_set(exemplar), 1);
    let rows: VoxelMap<usize> = (0..shape.len()).filter(|&i| shape.mask[i] > 0.0).map(|i| (shape.coords[i], i)).collect();
    for c in surface_voxels_below_iou(&voxel_set(shape), &dictionary, THRESHOLDS.unlike_iou) {
        if let Some(&i) = rows.get(IVec3::new(c[0] as i32, c[1] as i32, c[2] as i32)) {
            unlike[i] = true;
        }
    }
    unlike
}

/// The share of `shape`'s surface voxels (mask > 0) that are
/// [`unlike_voxels`] (0 for an empty shape and below 32^3). A voxel with all
/// six face neighbours in the level (inside a shell two or more voxels thick)
/// has no patch of its own and counts as like: the share is of every voxel,
/// as the limit was measured.
pub fn unlike_share(shape: &Level, exemplar: &Level) -> f64 {
    let active = shape.mask.iter().filter(|&&m| m > 0.0).count();
    if active == 0 {
        return 0.0;
    }
    unlike_voxels(shape, exemplar).iter().filter(|&&u| u).count() as f64 / active as f64
}

/// A level's surface voxels (mask > 0) as a bit set on its own lattice.
fn voxel_set(level: &Level) -> crate::grid::occupancy::Occupancy {
    let r = level.resolution;
    let mut set = crate::grid::occupancy::Occupancy::empty([r, r, r]);
    for (c, &m) in level.coords.iter().zip(&level.mask) {
        if m > 0.0 {
            set.set(c.x as i64, c.y as i64, c.z as i64);
        }
    }
    set
}
