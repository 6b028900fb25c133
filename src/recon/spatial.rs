//! A uniform hash grid over points for radius queries (nearest-point queries
//! are `crate::geom::nearest`'s: they must stay fast far from the points, where the
//! Poisson surface of an open sheet wraps around it at many cells' distance).
//!
//! Points are sorted by cell so that every occupied cell is one contiguous run
//! of the sorted arrays; a query visits the cells around it and scans those runs.

use glam::Vec3;

pub(crate) use crate::grid::key::{pack, unpack, KeyMap, KEY_LIMIT};

pub(crate) struct HashGrid {
    inv_cell: f32,
    /// cell key -> (start, end) in the sorted arrays
    runs: KeyMap<(u32, u32)>,
    /// original index of each sorted point
    pub(crate) index: Vec<u32>,
    /// positions, in sorted order
    pub(crate) pos: Vec<Vec3>,
}

impl HashGrid {
    /// `cell` in world units, > 0; points must be finite.
    pub(crate) fn new(points: &[Vec3], cell: f32) -> Self {
        use rayon::prelude::*;
        let inv_cell = 1.0 / cell;
        let mut keyed: Vec<(u64, u32)> = points
            .par_iter()
            .enumerate()
            .map(|(i, p)| (pack(cell_of(*p, inv_cell)), i as u32))
            .collect();
        keyed.par_sort_unstable();
        let mut runs = KeyMap::default();
        let mut start = 0usize;
        for i in 1..=keyed.len() {
            if i == keyed.len() || keyed[i].0 != keyed[start].0 {
                runs.insert(keyed[start].0, (start as u32, i as u32));
                start = i;
            }
        }
        let index: Vec<u32> = keyed.iter().map(|&(_, i)| i).collect();
        let pos = index.iter().map(|&i| points[i as usize]).collect();
        HashGrid { inv_cell, runs, index, pos }
    }

    #[inline]
    pub(crate) fn cell_of(&self, p: Vec3) -> [i32; 3] {
        cell_of(p, self.inv_cell)
    }

    /// Calls `f(sorted_index, squared_distance)` for every point within `r` of `p`.
    #[inline]
    pub(crate) fn for_each_within(&self, p: Vec3, r: f32, mut f: impl FnMut(usize, f32)) {
        let a = self.cell_of(p - Vec3::splat(r));
        let b = self.cell_of(p + Vec3::splat(r));
        let r2 = r * r;
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    if let Some(&(s, e)) = self.runs.get(&pack([x, y, z])) {
                        for j in s as usize..e as usize {
                            let d2 = self.pos[j].distance_squared(p);
                            if d2 < r2 {
                                f(j, d2);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Calls `f(sorted_index)` for every point in the cells that meet the box.
    pub(crate) fn for_each_in_box(&self, lo: Vec3, hi: Vec3, mut f: impl FnMut(usize)) {
        let (a, b) = (self.cell_of(lo), self.cell_of(hi));
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    if let Some(&(s, e)) = self.runs.get(&pack([x, y, z])) {
                        (s as usize..e as usize).for_each(&mut f);
                    }
                }
            }
        }
    }
}

#[inline]
fn cell_of(p: Vec3, inv_cell: f32) -> [i32; 3] {
    let q = (p * inv_cell).floor();
    let clamp = |v: f32| v.clamp(-(KEY_LIMIT as f32), KEY_LIMIT as f32) as i32;
    [clamp(q.x), clamp(q.y), clamp(q.z)]
}
