//! A level read as a sheet along one axis (a terrain, a cliff face, a
//! relief: a surface that meets every column along the axis once): its
//! columns, the holes through it (empty columns its occupied ones enclose),
//! the cracks at its steps, and the sheet mended. Whether an exemplar is a
//! sheet, and whether a variant's holes make it broken, is the judge's
//! (`judge::sheet`); mending is a level filter of sampling and the transfer
//! (`level::repair`).
//!
//! Every count is in the level's columns (one voxel's cross-section), on its
//! surface voxels (mask > 0).

use std::collections::VecDeque;

use glam::{IVec2, IVec3, Vec3};

use crate::grid::VoxelMap;

use super::Level;

/// The two axes of the plane across `axis`.
pub fn across(axis: usize) -> (usize, usize) {
    ((axis + 1) % 3, (axis + 2) % 3)
}

/// Per column (the plane's two coordinates), the rows of its surface voxels.
pub fn columns(level: &Level, axis: usize) -> VoxelMap2<Vec<usize>> {
    let (u, v) = across(axis);
    let mut cols: VoxelMap2<Vec<usize>> = VoxelMap2::default();
    for i in (0..level.len()).filter(|&i| level.mask[i] > 0.0) {
        let c = level.coords[i];
        cols.entry(IVec2::new(c[u], c[v])).or_default().push(i);
    }
    cols
}

pub type VoxelMap2<T> = std::collections::HashMap<IVec2, T>;

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
