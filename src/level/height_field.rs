//! Holes through a height field. A terrain, a cliff face or a relief is an
//! open sheet that meets every column along one axis once: seen along that
//! axis, its surface voxels cover their footprint without a gap. A hole
//! through such a sheet is a column inside the footprint with no surface at
//! all, which neither the free-boundary share (the sheet's own border is free
//! edge too) nor the views of the inside (a sheet shows back faces from half
//! the views) can tell from the exemplar. Counted here along the axis, it is
//! exact: the exemplar's footprint has none.
//!
//! Measured on the surface voxels (mask > 0) of one level; every count is in
//! that level's columns (one voxel's cross-section).

use std::collections::VecDeque;

use glam::{IVec2, IVec3, Vec3};

use crate::grid::VoxelMap;

use super::Level;

/// Share of a level's occupied columns, along an axis, whose voxels form one
/// unbroken run for the level to count as a height field along it. Measured
/// (docs/lab/structure-flags.md, "Holes through a sheet"): 1.00 on the terrain of
/// ../shared/data at 32^3-128^3 along its up axis; at most 0.53 on the
/// towers, the bunny and the CAD part, along any axis.
pub const HEIGHT_FIELD_SHARE: f64 = 0.95;

/// The two axes of the plane across `axis`.
fn across(axis: usize) -> (usize, usize) {
    ((axis + 1) % 3, (axis + 2) % 3)
}

/// Per column (the plane's two coordinates), the rows of its surface voxels.
fn columns(level: &Level, axis: usize) -> VoxelMap2<Vec<usize>> {
    let (u, v) = across(axis);
    let mut cols: VoxelMap2<Vec<usize>> = VoxelMap2::default();
    for i in (0..level.len()).filter(|&i| level.mask[i] > 0.0) {
        let c = level.coords[i];
        cols.entry(IVec2::new(c[u], c[v])).or_default().push(i);
    }
    cols
}

type VoxelMap2<T> = std::collections::HashMap<IVec2, T>;

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
/// field: the one with the largest share, if at least [`HEIGHT_FIELD_SHARE`].
pub fn height_axis(shares: &[f64; 3]) -> Option<usize> {
    (0..3).filter(|&a| shares[a] >= HEIGHT_FIELD_SHARE).max_by(|&a, &b| shares[a].total_cmp(&shares[b]))
}

/// The empty columns along `axis` that the occupied ones enclose: not joined
/// to the outside of the footprint's bounding box through empty columns
/// (4-neighbours, so a diagonal step between two voxels does not leak).
/// Sorted, so that whatever is built from them does not depend on hashing.
pub fn enclosed_columns(level: &Level, axis: usize) -> Vec<IVec2> {
    let cols = columns(level, axis);
    let Some(lo) = cols.keys().copied().reduce(IVec2::min) else { return Vec::new() };
    let hi = cols.keys().copied().fold(lo, IVec2::max);
    let (lo, hi) = (lo - IVec2::ONE, hi + IVec2::ONE);
    let size = hi - lo + IVec2::ONE;
    let at = |c: IVec2| ((c.y - lo.y) * size.x + (c.x - lo.x)) as usize;
    // 0 empty, 1 occupied, 2 reached from outside.
    let mut state = vec![0u8; (size.x * size.y) as usize];
    for c in cols.keys() {
        state[at(*c)] = 1;
    }
    let mut queue = VecDeque::from([lo]);
    state[at(lo)] = 2;
    while let Some(c) = queue.pop_front() {
        for d in [IVec2::X, -IVec2::X, IVec2::Y, -IVec2::Y] {
            let n = c + d;
            if n.cmplt(lo).any() || n.cmpgt(hi).any() || state[at(n)] != 0 {
                continue;
            }
            state[at(n)] = 2;
            queue.push_back(n);
        }
    }
    let mut out = Vec::new();
    for y in lo.y..=hi.y {
        for x in lo.x..=hi.x {
            if state[at(IVec2::new(x, y))] == 0 {
                out.push(IVec2::new(x, y));
            }
        }
    }
    out
}

/// Where two side-by-side columns' runs (lowest, highest voxel along the
/// axis) are more than a voxel apart: whether the first is the lower, and
/// the voxels between them (from, to, inclusive).
fn step_gap(a: (i32, i32), b: (i32, i32)) -> Option<(bool, i32, i32)> {
    if b.0 > a.1 + 1 {
        Some((true, a.1 + 1, b.0 - 1))
    } else if a.0 > b.1 + 1 {
        Some((false, b.1 + 1, a.0 - 1))
    } else {
        None
    }
}

/// Cracks at steps along `axis`: pairs of side-by-side (4-neighbour)
/// occupied columns whose runs are more than a voxel apart, so that the
/// sheet is open between them seen from the side. 0 on the exemplar's
/// levels (a surface voxelised is 26-connected).
pub fn step_cracks(level: &Level, axis: usize) -> usize {
    let runs: VoxelMap2<(i32, i32)> = columns(level, axis)
        .into_iter()
        .map(|(c, rows)| {
            let h = rows.iter().map(|&i| level.coords[i][axis]);
            (c, (h.clone().min().unwrap_or(0), h.max().unwrap_or(0)))
        })
        .collect();
    runs.iter()
        .map(|(c, &a)| [IVec2::X, IVec2::Y].iter().filter(|&&d| runs.get(&(*c + d)).is_some_and(|&b| step_gap(a, b).is_some())).count())
        .sum()
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
/// with `sample.mend_sheets`, along which its levels are mended.
pub fn sheet_axes(exemplar_levels: &[Level]) -> Vec<Option<usize>> {
    let axis = super::structure::structure_level(exemplar_levels).and_then(sheet_axis);
    exemplar_levels.iter().map(|l| axis.filter(|&a| enclosed_columns(l, a).is_empty())).collect()
}

/// `level` mended as a sheet along `axis`: every hole through it closed and
/// every crack at a step bridged; with how many voxels were added (appended
/// after the level's own rows). A hole's columns are filled from its rim
/// inwards: each takes the mean height, normal and colour of its filled or
/// occupied neighbours (8 around). Then, wherever two side-by-side columns'
/// runs are more than a voxel apart (a crack the detail transfer leaves
/// between regions copied at different heights, or a filled column beside
/// a steep slope), the lower run is raised to meet the higher, so the
/// surface is 26-connected as the exemplar's is. The detail is the finer
/// levels' (a network's or the detail transfer's), which see a sheet
/// without a gap.
pub fn mend_sheet(level: &Level, axis: usize) -> (Level, usize) {
    let holes = enclosed_columns(level, axis);
    let mut out = level.clone();
    let cols = columns(level, axis);
    // Per column: height (voxels along the axis, the surface points' mean),
    // normal, colour, and the run's lowest and highest voxel.
    #[derive(Clone, Copy)]
    struct Column {
        height: f32,
        normal: Vec3,
        colour: Vec3,
        low: i32,
        high: i32,
    }
    let mut known: VoxelMap2<Column> = cols
        .iter()
        .map(|(c, rows)| {
            let n = rows.len() as f32;
            let height = rows.iter().map(|&i| level.coords[i][axis] as f32 + 0.5 + level.offsets[i][axis]).sum::<f32>() / n;
            let normal = rows.iter().map(|&i| level.normals[i].normalize_or_zero()).sum::<Vec3>().normalize_or_zero();
            let colour = rows.iter().map(|&i| level.colours[i]).sum::<Vec3>() / n;
            let low = rows.iter().map(|&i| level.coords[i][axis]).min().unwrap_or(0);
            let high = rows.iter().map(|&i| level.coords[i][axis]).max().unwrap_or(0);
            (*c, Column { height, normal, colour, low, high })
        })
        .collect();
    let around: Vec<IVec2> = (-1..=1).flat_map(|y| (-1..=1).map(move |x| IVec2::new(x, y))).filter(|d| *d != IVec2::ZERO).collect();
    let mut left: Vec<IVec2> = holes;
    let mut filled: Vec<IVec2> = Vec::new();
    while !left.is_empty() {
        // This ring: the hole's columns with a known neighbour, all set from
        // the columns known before it (so the order within a ring does not matter).
        let ring: Vec<(IVec2, Column)> = left
            .iter()
            .filter_map(|&c| {
                let near: Vec<&Column> = around.iter().filter_map(|d| known.get(&(c + *d))).collect();
                if near.is_empty() {
                    return None;
                }
                let k = near.len() as f32;
                let height = near.iter().map(|n| n.height).sum::<f32>() / k;
                let normal = near.iter().map(|n| n.normal).sum::<Vec3>().normalize_or_zero();
                let colour = near.iter().map(|n| n.colour).sum::<Vec3>() / k;
                let h = height.floor() as i32;
                Some((c, Column { height, normal, colour, low: h, high: h }))
            })
            .collect();
        if ring.is_empty() {
            break; // cannot happen for enclosed columns; kept finite regardless
        }
        for (c, col) in &ring {
            known.insert(*c, *col);
            filled.push(*c);
        }
        left.retain(|c| !known.contains_key(c));
    }
    let (u, v) = across(axis);
    let mut existing: VoxelMap<()> = (0..out.len()).map(|i| (out.coords[i], ())).collect();
    let mut add = |out: &mut Level, c: IVec2, z: i32, offset: f32, normal: Vec3, colour: Vec3| {
        let mut coord = IVec3::ZERO;
        coord[axis] = z;
        coord[u] = c.x;
        coord[v] = c.y;
        if existing.insert(coord, ()).is_some() {
            return;
        }
        let mut o = Vec3::ZERO;
        o[axis] = offset.clamp(-0.5, 0.5);
        out.coords.push(coord);
        out.offsets.push(o);
        out.normals.push(if normal == Vec3::ZERO { unit(axis) } else { normal });
        out.colours.push(colour);
        out.mask.push(1.0);
    };
    for c in &filled {
        let col = known[c];
        let h = col.height.floor() as i32;
        add(&mut out, *c, h, col.height - (h as f32 + 0.5), col.normal, col.colour);
    }
    // Steps: where two side-by-side columns' runs are more than a voxel
    // apart along the axis, the sheet is cracked between them (seen from the
    // side, the sky shows through). The lower column's run is raised to meet
    // the higher one, as a steep slope of the exemplar is a run of voxels
    // per column. Each pair is judged on the runs before any is raised, so
    // the result does not depend on the order.
    let mut keys: Vec<IVec2> = known.keys().copied().collect();
    keys.sort_unstable_by_key(|c| (c.x, c.y));
    let mut bridges: Vec<(IVec2, i32, i32, Vec3, Vec3)> = Vec::new();
    for c in &keys {
        let a = known[c];
        for d in [IVec2::X, IVec2::Y] {
            let Some(b) = known.get(&(*c + d)) else { continue };
            let Some((a_lower, from, to)) = step_gap((a.low, a.high), (b.low, b.high)) else { continue };
            let (low_col, high_col) = if a_lower { (*c, *c + d) } else { (*c + d, *c) };
            // The step's face looks across, towards the lower column where
            // the sheet faces up along the axis, away from it where it faces down.
            let sheet = (a.normal + b.normal).normalize_or_zero();
            let across_dir = (low_col - high_col).as_vec2();
            let mut side = Vec3::ZERO;
            side[u] = across_dir.x;
            side[v] = across_dir.y;
            let facing = if sheet[axis] >= 0.0 { side } else { -side };
            bridges.push((low_col, from, to, (facing + sheet).normalize_or_zero(), (a.colour + b.colour) / 2.0));
        }
    }
    for (c, from, to, normal, colour) in bridges {
        for z in from..=to {
            add(&mut out, c, z, 0.0, normal, colour);
        }
    }
    let added = out.len() - level.len();
    (out, added)
}

fn unit(axis: usize) -> Vec3 {
    let mut n = Vec3::ZERO;
    n[axis] = 1.0;
    n
}

#[cfg(test)]
mod tests {
    use super::*;

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
