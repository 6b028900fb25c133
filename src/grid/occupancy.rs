//! A bit-packed set of voxels on a box lattice ([`Occupancy`]), with the
//! surface, boundary and dilation that local patches are cut from. Shared by
//! the structure measures of a level (its voxels on their own lattice) and by
//! evaluation (shapes voxelised on the exemplar's lattice).

use rayon::prelude::*;

/// A bit-packed voxel set on a box lattice of `dims` voxels (evaluation's
/// `OccupancyGrid`, or a level's own voxels).
///
/// Storage: one row of `words_per_row() = ceil(dims[0] / 64)` words per `(y, z)`,
/// rows in order `y + dims[1] * z`; voxel `(x, y, z)` is bit `x % 64` of word
/// `x / 64` of its row. Bits past `dims[0]` in a row's last word are always 0.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Occupancy {
    pub dims: [u32; 3],
    pub bits: Vec<u64>,
}

impl Occupancy {
    pub fn empty(dims: [u32; 3]) -> Self {
        let wpr = words_for(dims[0]);
        Occupancy { dims, bits: vec![0; wpr * dims[1] as usize * dims[2] as usize] }
    }

    pub fn words_per_row(&self) -> usize {
        words_for(self.dims[0])
    }

    fn row_index(&self, y: usize, z: usize) -> usize {
        y + self.dims[1] as usize * z
    }

    fn row(&self, y: usize, z: usize) -> &[u64] {
        let w = self.words_per_row();
        let r = self.row_index(y, z);
        &self.bits[r * w..(r + 1) * w]
    }

    fn in_bounds(&self, x: i64, y: i64, z: i64) -> bool {
        x >= 0 && y >= 0 && z >= 0 && x < self.dims[0] as i64 && y < self.dims[1] as i64 && z < self.dims[2] as i64
    }

    /// Whether voxel `(x, y, z)` is set; outside the lattice is empty.
    pub fn get(&self, x: i64, y: i64, z: i64) -> bool {
        if !self.in_bounds(x, y, z) {
            return false;
        }
        let row = self.row(y as usize, z as usize);
        row[x as usize / 64] >> (x as usize % 64) & 1 == 1
    }

    /// Sets voxel `(x, y, z)`; ignored outside the lattice.
    pub fn set(&mut self, x: i64, y: i64, z: i64) {
        if !self.in_bounds(x, y, z) {
            return;
        }
        let w = self.words_per_row();
        let r = self.row_index(y as usize, z as usize);
        self.bits[r * w + x as usize / 64] |= 1u64 << (x as usize % 64);
    }

    /// Number of set voxels.
    pub fn count(&self) -> u64 {
        self.bits.iter().map(|w| w.count_ones() as u64).sum()
    }

    /// Coordinates of all set voxels, in storage order (x fastest, then y, z).
    pub fn voxels(&self) -> Vec<[u32; 3]> {
        let w = self.words_per_row();
        let ny = self.dims[1] as usize;
        let mut out = Vec::new();
        for (r, row) in self.bits.chunks_exact(w.max(1)).enumerate() {
            let (y, z) = ((r % ny) as u32, (r / ny) as u32);
            for (wi, &word) in row.iter().enumerate() {
                let mut m = word;
                while m != 0 {
                    let b = m.trailing_zeros();
                    out.push([(wi * 64) as u32 + b, y, z]);
                    m &= m - 1;
                }
            }
        }
        out
    }

    /// Surface voxels: set voxels with at least one unset 6-neighbour (outside the
    /// lattice counts as unset). Patch centres of LP-IoU / LP-F-score.
    pub fn surface(&self) -> Occupancy {
        let interior = self.neighbourhood(Neighbourhood::Six, false);
        self.and_not(&interior)
    }

    /// Boundary voxels as DECOR-GAN defines them: set voxels with at least one
    /// unset voxel among their 26 neighbours (`x - min_pool3(x)`).
    pub fn boundary26(&self) -> Occupancy {
        let eroded = self.neighbourhood(Neighbourhood::Box, false);
        self.and_not(&eroded)
    }

    /// Dilation by the 3x3x3 box (Chebyshev distance <= 1 voxel).
    pub fn dilate26(&self) -> Occupancy {
        self.neighbourhood(Neighbourhood::Box, true)
    }

    fn and_not(&self, other: &Occupancy) -> Occupancy {
        let bits = self.bits.iter().zip(&other.bits).map(|(a, b)| a & !b).collect();
        Occupancy { dims: self.dims, bits }
    }

    /// Erosion (`dilate = false`: AND) or dilation (OR) by a 6-neighbourhood or a
    /// 3x3x3 box, with everything outside the lattice unset.
    fn neighbourhood(&self, shape: Neighbourhood, dilate: bool) -> Occupancy {
        let w = self.words_per_row();
        let [_, ny, nz] = self.dims.map(|d| d as usize);
        if w == 0 || ny == 0 || nz == 0 {
            return self.clone();
        }
        let last_mask = last_word_mask(self.dims[0]);
        let comb = |a: u64, b: u64| if dilate { a | b } else { a & b };
        // Pass along x on each row: the row combined with its +-1 shifts.
        let along_x = |src: &[u64], dst: &mut [u64]| {
            for i in 0..w {
                let left = (src[i] << 1) | if i > 0 { src[i - 1] >> 63 } else { 0 };
                let right = (src[i] >> 1) | if i + 1 < w { src[i + 1] << 63 } else { 0 };
                dst[i] = comb(comb(src[i], left), right);
            }
            dst[w - 1] &= last_mask;
        };
        // Rows of a lattice-sized buffer combined with rows at +-1 in y or z.
        let along = |src: &Occupancy, axis_y: bool| -> Occupancy {
            let mut out = Occupancy::empty(src.dims);
            out.bits.par_chunks_mut(w).enumerate().for_each(|(r, dst)| {
                let (y, z) = (r % ny, r / ny);
                dst.copy_from_slice(src.row(y, z));
                let (c, n) = if axis_y { (y, ny) } else { (z, nz) };
                for d in [-1i64, 1] {
                    let cc = c as i64 + d;
                    if cc < 0 || cc >= n as i64 {
                        if !dilate {
                            dst.iter_mut().for_each(|v| *v = 0);
                        }
                        continue;
                    }
                    let other = if axis_y { src.row(cc as usize, z) } else { src.row(y, cc as usize) };
                    for (v, o) in dst.iter_mut().zip(other) {
                        *v = comb(*v, *o);
                    }
                }
            });
            out
        };
        match shape {
            Neighbourhood::Box => {
                // Separable: box = x pass, then y pass, then z pass.
                let mut sx = Occupancy::empty(self.dims);
                sx.bits.par_chunks_mut(w).zip(self.bits.par_chunks(w)).for_each(|(d, s)| along_x(s, d));
                let sy = along(&sx, true);
                along(&sy, false)
            }
            Neighbourhood::Six => {
                // Cross: x pass, y pass and z pass each on the original, then combined.
                let mut sx = Occupancy::empty(self.dims);
                sx.bits.par_chunks_mut(w).zip(self.bits.par_chunks(w)).for_each(|(d, s)| along_x(s, d));
                let sy = along(self, true);
                let sz = along(self, false);
                let bits =
                    sx.bits.iter().zip(&sy.bits).zip(&sz.bits).map(|((a, b), c)| comb(comb(*a, *b), *c)).collect();
                Occupancy { dims: self.dims, bits }
            }
        }
    }

    /// Bits `start .. start + n` (n <= 64) of row `(y, z)`, bit 0 first; voxels
    /// outside the lattice read as 0.
    pub(crate) fn row_bits(&self, y: i64, z: i64, start: i64, n: u32) -> u64 {
        if y < 0 || z < 0 || y >= self.dims[1] as i64 || z >= self.dims[2] as i64 {
            return 0;
        }
        let row = self.row(y as usize, z as usize);
        let (start, n, shift) = if start < 0 {
            let skip = (-start).min(n as i64) as u32;
            (0i64, n - skip, skip)
        } else {
            (start, n, 0)
        };
        if n == 0 {
            return 0;
        }
        let wi = (start / 64) as usize;
        let off = (start % 64) as u32;
        let lo = row.get(wi).copied().unwrap_or(0) >> off;
        let hi = if off + n > 64 { row.get(wi + 1).copied().unwrap_or(0) << (64 - off) } else { 0 };
        let mask = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
        ((lo | hi) & mask) << shift
    }
}

#[derive(Clone, Copy)]
enum Neighbourhood {
    Six,
    Box,
}

fn words_for(n: u32) -> usize {
    (n as usize).div_ceil(64)
}

pub(crate) fn last_word_mask(nx: u32) -> u64 {
    match nx % 64 {
        0 => u64::MAX,
        r => (1u64 << r) - 1,
    }
}

/// Sets bits `lo ..= hi` of a row.
pub(crate) fn set_range(row: &mut [u64], lo: usize, hi: usize) {
    if lo > hi {
        return;
    }
    let (wl, wh) = (lo / 64, hi / 64);
    for (wi, word) in row.iter_mut().enumerate().take(wh + 1).skip(wl) {
        let from = if wi == wl { lo % 64 } else { 0 };
        let to = if wi == wh { hi % 64 } else { 63 };
        let span = to - from + 1;
        let mask = if span == 64 { u64::MAX } else { ((1u64 << span) - 1) << from };
        *word |= mask;
    }
}

/// Panics unless `a` and `b` are on the same lattice.
pub(crate) fn same_lattice(a: &Occupancy, b: &Occupancy) {
    assert_eq!(
        a.dims, b.dims,
        "occupancies on different lattices: voxelise every shape with the exemplar's OccupancyGrid"
    );
}
