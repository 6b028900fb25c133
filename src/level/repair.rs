//! What each level of a variant gets once it is made (by a network or the
//! detail transfer) and before the next level is made from it: specks
//! removed (`sample.filters.remove_specks`) and, on a sheet, holes and cracks mended
//! (`sample.filters.mend_sheets`, [`super::sheet::mend_sheet`]). Decided once
//! per exemplar level ([`repairs`]), so sampling and the transfer do the same.

use crate::grid::components::component_labels;
use super::Level;

/// A speck is a piece smaller than this share of the level's surface voxels
/// (and smaller than every piece of the exemplar's own level). The detail
/// transfer leaves 22-67 such pieces at 256^3 on the ruined tower, up to
/// 138 voxels each (0.1% of the level; 0.14-0.64% of its voxels in all),
/// where the exemplar is one piece; the networks' levels have none but
/// single voxels. 0.5% keeps every piece the structure flags count
/// (`judge::THRESHOLDS.piece_share`, 5%) and every part the networks make.
pub const SPECK_SHARE: f64 = 0.005;

/// What one level of a variant gets once made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LevelRepair {
    /// Pieces smaller than this many voxels (the exemplar's smallest piece
    /// at this level) and than [`SPECK_SHARE`] of the level are removed;
    /// None: none are.
    pub exemplar_smallest_piece: Option<usize>,
    /// The axis along which holes through the sheet and cracks at its steps
    /// are mended; None: the level is not a sheet, or mending is off.
    pub sheet_axis: Option<usize>,
}

/// A level after [`LevelRepair::apply`]: its first `kept.len()` rows are
/// the input's rows `kept` (in order), then `added` new rows.
pub struct Repaired {
    pub level: Level,
    pub kept: Vec<usize>,
    pub added: usize,
}

impl Repaired {
    /// Rows of the input removed.
    pub fn removed(&self, input_len: usize) -> usize {
        input_len - self.kept.len()
    }
}

/// Per exemplar level, what a variant's level of the same index gets:
/// specks below the exemplar's smallest piece removed where `remove_specks`,
/// holes and cracks mended along its `sheet_axes`
/// (`judge::sheet::sheet_axes`) where `mend_sheets`. Empty when
/// both are off.
pub fn repairs(exemplar_levels: &[Level], sheet_axes: &[Option<usize>], remove_specks: bool, mend_sheets: bool) -> Vec<LevelRepair> {
    if !remove_specks && !mend_sheets {
        return Vec::new();
    }
    exemplar_levels
        .iter()
        .zip(sheet_axes)
        .map(|(l, &axis)| LevelRepair {
            exemplar_smallest_piece: remove_specks.then(|| smallest_piece(l)),
            sheet_axis: axis.filter(|_| mend_sheets),
        })
        .collect()
}

/// The size of the smallest 26-connected piece of `level`'s surface voxels
/// (0 when empty: nothing is then smaller).
pub fn smallest_piece(level: &Level) -> usize {
    let coords: Vec<_> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).map(|i| level.coords[i]).collect();
    component_labels(&coords).1.into_iter().min().unwrap_or(0)
}

/// The rows of `level` kept when its specks are removed: every row but the
/// surface voxels of pieces smaller than both `exemplar_smallest` voxels and
/// [`SPECK_SHARE`] of its surface voxels. The largest piece is always kept.
pub fn without_specks(level: &Level, exemplar_smallest: usize) -> Vec<usize> {
    let active: Vec<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).collect();
    let coords: Vec<_> = active.iter().map(|&i| level.coords[i]).collect();
    let (label, sizes) = component_labels(&coords);
    let floor = exemplar_smallest.min((SPECK_SHARE * active.len() as f64).ceil() as usize);
    let largest = sizes.iter().enumerate().max_by_key(|&(_, &s)| s).map(|(k, _)| k);
    let mut speck = vec![false; level.len()];
    for (a, &i) in active.iter().enumerate() {
        speck[i] = sizes[label[a]] < floor && Some(label[a]) != largest;
    }
    (0..level.len()).filter(|&i| !speck[i]).collect()
}

impl LevelRepair {
    /// `level` repaired: specks removed, then the sheet mended (so a speck
    /// under a sheet is not taken for a second run of its column). None
    /// when nothing changed.
    pub fn apply(&self, level: &Level) -> Option<Repaired> {
        let mut kept: Vec<usize> = (0..level.len()).collect();
        let mut out = None;
        if let Some(smallest) = self.exemplar_smallest_piece {
            let k = without_specks(level, smallest);
            if k.len() < level.len() {
                out = Some(level.rows(&k));
                kept = k;
            }
        }
        let mut added = 0;
        if let Some(axis) = self.sheet_axis {
            let (mended, a) = super::sheet::mend_sheet(out.as_ref().unwrap_or(level), axis);
            if a > 0 {
                added = a;
                out = Some(mended);
            }
        }
        out.map(|level| Repaired { level, kept, added })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{IVec3, Vec3};

    /// A level of the voxels `coords` (flat, normals up).
    fn level(coords: &[IVec3]) -> Level {
        let n = coords.len();
        Level {
            index: 4,
            resolution: 256,
            coords: coords.to_vec(),
            offsets: vec![Vec3::ZERO; n],
            normals: vec![Vec3::Y; n],
            colours: vec![Vec3::splat(0.5); n],
            mask: vec![1.0; n],
            ..Default::default()
        }
    }

    #[test]
    fn specks_go_and_pieces_the_exemplar_has_stay() {
        // A 20 x 20 plate (400 voxels) and loose bits of one, two and five voxels.
        let mut coords: Vec<IVec3> = (0..400).map(|k| IVec3::new(k % 20, 5, k / 20)).collect();
        let small = [IVec3::new(2, 12, 2), IVec3::new(8, 12, 8), IVec3::new(9, 12, 8)];
        coords.extend(small);
        coords.extend((0..5).map(|k| IVec3::new(14 + k, 14, 15)));
        let l = level(&coords);
        // 0.5% of 408 voxels: pieces under 3 voxels are specks.
        assert_eq!((SPECK_SHARE * l.len() as f64).ceil() as usize, 3);
        // Against a one-piece exemplar (its smallest piece the whole plate):
        // the one- and two-voxel bits go, the five-voxel piece stays.
        assert_eq!(smallest_piece(&level(&coords[..400])), 400);
        let kept = without_specks(&l, 400);
        assert_eq!(kept.len(), l.len() - 3);
        assert!(kept.iter().all(|&i| !small.contains(&l.coords[i])));
        // Against an exemplar with a two-voxel piece of its own: only the
        // single voxel goes.
        assert_eq!(without_specks(&l, 2).len(), l.len() - 1);
        // Applied: the rows kept are the input's, in order; nothing is
        // left to remove a second time.
        let repair = LevelRepair { exemplar_smallest_piece: Some(400), sheet_axis: None };
        let r = repair.apply(&l).expect("specks removed");
        assert_eq!((r.removed(l.len()), r.added), (3, 0));
        for (row, &i) in r.kept.iter().enumerate() {
            assert_eq!(r.level.coords[row], l.coords[i]);
        }
        assert!(repair.apply(&r.level).is_none());
        // Off: nothing changes.
        assert!(LevelRepair::default().apply(&l).is_none());
    }

    #[test]
    fn the_largest_piece_stays_however_small() {
        // 300 loose voxels, none touching: all specks by size (under 2), one kept.
        let coords: Vec<IVec3> = (0..300).map(|k| IVec3::new(2 * (k % 20), 0, 2 * (k / 20))).collect();
        assert_eq!(without_specks(&level(&coords), 1000).len(), 1);
    }
}
