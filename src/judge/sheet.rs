//! Holes through a height field. A terrain, a cliff face or a relief is an
//! open sheet that meets every column along one axis once: seen along that
//! axis, its surface voxels cover their footprint without a gap. A hole
//! through such a sheet is a column inside the footprint with no surface at
//! all, which neither the free-boundary share (the sheet's own border is free
//! edge too) nor the views of the inside (a sheet shows back faces from half
//! the views) can tell from the exemplar. Counted here along the axis
//! ([`crate::level::sheet::enclosed_columns`]), it is exact: the exemplar's
//! footprint has none (`holed`).

use super::thresholds::THRESHOLDS;
use crate::level::sheet::{columns, enclosed_columns};
use crate::level::Level;

/// Per axis, the share of the occupied columns whose voxels along it form one
/// unbroken run (0 for no voxels).
pub fn single_run_shares(level: &Level) -> [f64; 3] {
    [0, 1, 2].map(|axis| {
        let cols = columns(level, axis);
        if cols.is_empty() {
            return 0.0;
        }
        let single = cols
            .values()
            .filter(|rows| {
                let mut h: Vec<i32> = rows.iter().map(|&i| level.coords[i][axis]).collect();
                h.sort_unstable();
                h.windows(2).all(|w| w[1] - w[0] <= 1)
            })
            .count();
        single as f64 / cols.len() as f64
    })
}

/// The axis along which `shares` (from [`single_run_shares`]) make a height
/// field: the one with the largest share, if at least `THRESHOLDS.height_field_share`.
pub fn height_axis(shares: &[f64; 3]) -> Option<usize> {
    (0..3).filter(|&a| shares[a] >= THRESHOLDS.height_field_share).max_by(|&a, &b| shares[a].total_cmp(&shares[b]))
}

/// Per axis, [`enclosed_columns`]' count.
pub fn enclosed_counts(level: &Level) -> [usize; 3] {
    [0, 1, 2].map(|axis| enclosed_columns(level, axis).len())
}

/// The axis along which `level` is a sheet: a height field along it with no
/// hole through it (a terrain with an arch of its own is not one).
pub fn sheet_axis(level: &Level) -> Option<usize> {
    let axis = height_axis(&single_run_shares(level))?;
    enclosed_columns(level, axis).is_empty().then_some(axis)
}

/// Per exemplar level, the axis along which it is a sheet, decided once at
/// the structure level (64^3), where walls are walls: at 16^3 a tower's wall
/// is one run of voxels per column as a terrain's slope is (0.93 of the
/// ruined tower's columns along its height, against 0.28 at 64^3), and a flat
/// airplane is a sheet. A level counts where it has no hole along that axis.
/// Where a variant's holes are counted (`holed`, also at level 0) and,
/// with `sample.filters.mend_sheets`, along which its levels are mended.
pub fn sheet_axes(exemplar_levels: &[Level]) -> Vec<Option<usize>> {
    let axis = super::levels::structure_level(exemplar_levels).and_then(sheet_axis);
    exemplar_levels.iter().map(|l| axis.filter(|&a| enclosed_columns(l, a).is_empty())).collect()
}


#[cfg(test)]
mod tests {
    use super::*;
    use crate::level::sheet::{enclosed_columns, mend_sheet, step_cracks};
    use glam::{IVec3, Vec3};

    /// A wavy height field y = f(x, z) over `n` x `n` columns, one voxel per
    /// column where `keep` holds (and a second under it on the steep side).
    fn sheet(n: i32, keep: impl Fn(i32, i32) -> bool) -> Level {
        let mut l = Level { index: 2, resolution: 64, ..Default::default() };
        for x in 0..n {
            for z in 0..n {
                if !keep(x, z) {
                    continue;
                }
                let h = 20.0 + 6.0 * ((x as f32) * 0.2).sin() + 3.0 * ((z as f32) * 0.3).cos();
                let y = h.floor() as i32;
                l.coords.push(IVec3::new(x, y, z));
                l.offsets.push(Vec3::new(0.0, h - y as f32 - 0.5, 0.0));
                l.normals.push(Vec3::Y);
                l.colours.push(Vec3::new(0.4, 0.3, 0.2));
                l.mask.push(1.0);
            }
        }
        l
    }

    #[test]
    fn a_sheet_is_a_height_field_and_a_hole_through_it_is_counted_and_closed() {
        let whole = sheet(40, |_, _| true);
        let shares = single_run_shares(&whole);
        assert_eq!(height_axis(&shares), Some(1), "{shares:?}");
        assert_eq!(enclosed_counts(&whole)[1], 0);
        assert_eq!(sheet_axis(&whole), Some(1));
        // A hole of 5 x 4 columns inside, and a bite out of the border (open
        // to the outside: not a hole through the sheet).
        let holed = sheet(40, |x, z| !((10..15).contains(&x) && (20..24).contains(&z)) && !(x < 3 && z < 3));
        let holes = enclosed_columns(&holed, 1);
        assert_eq!(holes.len(), 20, "{holes:?}");
        let (mended, added) = mend_sheet(&holed, 1);
        assert!(added >= 20, "{added}");
        assert!(enclosed_columns(&mended, 1).is_empty());
        assert_eq!(mended.len(), holed.len() + added);
        // The filled columns sit within a voxel or two of the sheet they mend.
        for i in holed.len()..mended.len() {
            let c = mended.coords[i];
            let j = (0..whole.len()).find(|&j| whole.coords[j].x == c.x && whole.coords[j].z == c.z).unwrap();
            assert!((whole.coords[j].y - c.y).abs() <= 2, "{c} against {}", whole.coords[j]);
            assert!(mended.offsets[i].abs().max_element() <= 0.5);
        }
        // The bite stays: the outline is the variant's own.
        assert!(!mended.coords.iter().any(|c| c.x < 3 && c.z < 3));
    }

    #[test]
    fn a_cliff_face_is_a_sheet_along_its_own_axis() {
        // The holed sheet turned on its side (its height along x): a cliff.
        let swap = |v: Vec3| Vec3::new(v.y, v.x, v.z);
        let mut cliff = sheet(40, |x, z| !((10..15).contains(&x) && (20..24).contains(&z)));
        for i in 0..cliff.len() {
            let c = cliff.coords[i];
            cliff.coords[i] = IVec3::new(c.y, c.x, c.z);
            cliff.offsets[i] = swap(cliff.offsets[i]);
            cliff.normals[i] = swap(cliff.normals[i]);
        }
        assert_eq!(height_axis(&single_run_shares(&cliff)), Some(0));
        assert_eq!(enclosed_columns(&cliff, 0).len(), 20);
        let (mended, _) = mend_sheet(&cliff, 0);
        assert!(enclosed_columns(&mended, 0).is_empty() && step_cracks(&mended, 0) == 0);
        // Filled along x: each of the hole's columns (y, z) holds surface now.
        for y in 10..15 {
            for z in 20..24 {
                assert!(mended.coords.iter().any(|c| c.y == y && c.z == z), "column {y}, {z}");
            }
        }
    }

    #[test]
    fn a_crack_at_a_step_is_bridged_from_the_lower_side() {
        // Two halves of a flat sheet, 5 voxels apart in height: seen from the
        // side, the sky shows between them.
        let mut l = Level { index: 2, resolution: 64, ..Default::default() };
        for x in 0..10 {
            for z in 0..6 {
                l.coords.push(IVec3::new(x, if x < 5 { 10 } else { 15 }, z));
                l.offsets.push(Vec3::ZERO);
                l.normals.push(Vec3::Y);
                l.colours.push(Vec3::splat(0.5));
                l.mask.push(1.0);
            }
        }
        assert!(enclosed_columns(&l, 1).is_empty());
        let (mended, added) = mend_sheet(&l, 1);
        // Columns x = 4 raised by 4 voxels (11..=14), 6 of them.
        assert_eq!(added, 24);
        for i in l.len()..mended.len() {
            let c = mended.coords[i];
            assert!(c.x == 4 && (11..=14).contains(&c.y), "{c}");
            // The step's face looks across, towards the lower side (the sheet faces up).
            assert!(mended.normals[i].x < -0.5 && mended.normals[i].y > 0.0, "{}", mended.normals[i]);
        }
        // One half alone has neither a step nor a hole: left as it is. And a
        // mended sheet needs no second mending.
        let mut half = l.clone();
        half.retain(|i| i < 30);
        assert_eq!(mend_sheet(&half, 1).1, 0);
        assert_eq!(mend_sheet(&mended, 1).1, 0);
        assert_eq!((step_cracks(&l, 1), step_cracks(&mended, 1)), (6, 0));
        let (wavy, steps) = mend_sheet(&sheet(20, |_, _| true), 1);
        assert!(steps > 0 && mend_sheet(&wavy, 1).1 == 0, "{steps}");
    }

    #[test]
    fn a_tube_is_no_height_field() {
        // A ring of 12 voxels' radius, 20 high: along its axis every column
        // of the wall is one run, but across it each column meets the wall
        // twice.
        let mut l = Level { index: 2, resolution: 64, ..Default::default() };
        for y in 0..20 {
            for k in 0..120 {
                let a = k as f32 / 120.0 * std::f32::consts::TAU;
                let c = IVec3::new((32.0 + 12.0 * a.cos()).floor() as i32, y, (32.0 + 12.0 * a.sin()).floor() as i32);
                if !l.coords.contains(&c) {
                    l.coords.push(c);
                    l.offsets.push(Vec3::ZERO);
                    l.normals.push(Vec3::new(a.cos(), 0.0, a.sin()));
                    l.colours.push(Vec3::ONE);
                    l.mask.push(1.0);
                }
            }
        }
        let shares = single_run_shares(&l);
        assert!(shares[0] < 0.5 && shares[2] < 0.5, "{shares:?}");
        // Along its axis the inside of the ring is enclosed: a height field
        // there would call it a hole, which is why the exemplar must not have one.
        assert!(enclosed_counts(&l)[1] > 300);
        assert!(sheet_axis(&l).is_none());
    }
}
