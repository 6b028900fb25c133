//! A uniform hash grid over points: radius queries and nearest-point queries.
//!
//! Points are sorted by cell so that every occupied cell is one contiguous run
//! of the sorted arrays; a query visits the cells around it and scans those runs.

use glam::Vec3;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// A small multiplicative hasher for packed integer keys (the std SipHash is
/// several times slower for the millions of lookups the meshers make).
#[derive(Default, Clone, Copy)]
pub(crate) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 ^= self.0 >> 29;
    }
}

pub(crate) type KeyMap<V> = HashMap<u64, V, BuildHasherDefault<KeyHasher>>;

const KEY_BITS: u32 = 21;
const KEY_BIAS: i64 = 1 << (KEY_BITS - 1);
const KEY_MASK: u64 = (1 << KEY_BITS) - 1;

/// Packs integer coordinates in [-2^20, 2^20) into one key.
#[inline]
pub(crate) fn pack(c: [i32; 3]) -> u64 {
    let f = |v: i32| ((v as i64 + KEY_BIAS) as u64) & KEY_MASK;
    (f(c[0]) << (2 * KEY_BITS)) | (f(c[1]) << KEY_BITS) | f(c[2])
}

/// Inverse of [`pack`].
#[inline]
pub(crate) fn unpack(k: u64) -> [i32; 3] {
    let f = |v: u64| ((v & KEY_MASK) as i64 - KEY_BIAS) as i32;
    [f(k >> (2 * KEY_BITS)), f(k >> KEY_BITS), f(k)]
}

/// Largest coordinate magnitude [`pack`] keeps apart.
pub(crate) const KEY_LIMIT: i32 = (KEY_BIAS - 1) as i32;

pub(crate) struct HashGrid {
    cell: f32,
    inv_cell: f32,
    /// cell key -> (start, end) in the sorted arrays
    runs: KeyMap<(u32, u32)>,
    /// original index of each sorted point
    pub(crate) index: Vec<u32>,
    /// positions, in sorted order
    pub(crate) pos: Vec<Vec3>,
    /// occupied cell bounds (inclusive), to stop nearest searches
    lo: [i32; 3],
    hi: [i32; 3],
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
        let mut lo = [i32::MAX; 3];
        let mut hi = [i32::MIN; 3];
        let mut start = 0usize;
        for i in 1..=keyed.len() {
            if i == keyed.len() || keyed[i].0 != keyed[start].0 {
                runs.insert(keyed[start].0, (start as u32, i as u32));
                let c = unpack(keyed[start].0);
                for a in 0..3 {
                    lo[a] = lo[a].min(c[a]);
                    hi[a] = hi[a].max(c[a]);
                }
                start = i;
            }
        }
        let index: Vec<u32> = keyed.iter().map(|&(_, i)| i).collect();
        let pos = index.iter().map(|&i| points[i as usize]).collect();
        HashGrid { cell, inv_cell, runs, index, pos, lo, hi }
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

    /// The original index of the point nearest to `p`, and its distance.
    pub(crate) fn nearest(&self, p: Vec3) -> Option<(u32, f32)> {
        if self.pos.is_empty() {
            return None;
        }
        let c = self.cell_of(p);
        let mut best = (u32::MAX, f32::INFINITY);
        // Chebyshev shells of cells around c; a point in shell r is at least
        // (r - 1) * cell away, so shell r + 1 cannot beat best once r * cell >= best.
        let max_r = (0..3)
            .map(|a| (c[a] - self.lo[a]).abs().max((c[a] - self.hi[a]).abs()))
            .max()
            .unwrap_or(0);
        for r in 0..=max_r {
            let mut visit = |x: i32, y: i32, z: i32| {
                if let Some(&(s, e)) = self.runs.get(&pack([x, y, z])) {
                    for j in s as usize..e as usize {
                        let d2 = self.pos[j].distance_squared(p);
                        if d2 < best.1 {
                            best = (j as u32, d2);
                        }
                    }
                }
            };
            if r == 0 {
                visit(c[0], c[1], c[2]);
            } else {
                for x in c[0] - r..=c[0] + r {
                    for y in c[1] - r..=c[1] + r {
                        let on_side = x == c[0] - r || x == c[0] + r || y == c[1] - r || y == c[1] + r;
                        if on_side {
                            for z in c[2] - r..=c[2] + r {
                                visit(x, y, z);
                            }
                        } else {
                            visit(x, y, c[2] - r);
                            visit(x, y, c[2] + r);
                        }
                    }
                }
            }
            if best.0 != u32::MAX {
                let reach = r as f32 * self.cell;
                if reach * reach >= best.1 {
                    break;
                }
            }
        }
        (best.0 != u32::MAX).then(|| (self.index[best.0 as usize], best.1.sqrt()))
    }
}

#[inline]
fn cell_of(p: Vec3, inv_cell: f32) -> [i32; 3] {
    let q = (p * inv_cell).floor();
    let clamp = |v: f32| v.clamp(-(KEY_LIMIT as f32), KEY_LIMIT as f32) as i32;
    [clamp(q.x), clamp(q.y), clamp(q.z)]
}
