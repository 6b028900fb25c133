//! Evaluation (METHOD.md section 7): solid voxelisation, IoU and diversity,
//! local-patch plausibility (LP-IoU, LP-F-score) and point-set distances.
//!
//! # Units
//!
//! - *World units*: the exemplar's own frame, where meshes and
//!   [`Level::point_world`] live. Everything that is voxelised is given in world
//!   units and mapped through the exemplar's [`Frame`] held by the grid.
//! - *Normalised units*: the exemplar normalised so its bounding-box diagonal is 2
//!   (METHOD.md section 2.1). [`OccupancyGrid::origin`] and
//!   [`OccupancyGrid::voxel`] are in normalised units, and so is the coarse
//!   Chamfer distance of the report ([`level_points_normalised`]).
//! - *Voxels*: cells of the evaluation lattice, `resolution` (default 256) of them
//!   along the longest side of the exemplar's normalised bounding box. Patch
//!   sizes, strides and the F-score tolerance are in voxels.
//!
//! # Why one lattice
//!
//! IoU and local patches compare bits voxel by voxel, so every shape of one
//! evaluation must be voxelised on the *same* lattice: choose an
//! [`OccupancyGrid`] once from the exemplar ([`OccupancyGrid::for_exemplar`]) and
//! reuse it for every variant. Variants are in the exemplar's frame (the
//! generator places its outputs back there), so they land on the same lattice.
//!
//! # Occupancy
//!
//! [`voxelise_mesh`]: a voxel is occupied when the winding number of the mesh at
//! its centre is, in absolute value, above 0.5 (computed exactly for closed
//! meshes, by signed ray crossings along +x per voxel column), OR when the surface
//! passes through the voxel (exact triangle/voxel overlap). The surface voxels are
//! added so that open sheets and parts thinner than a voxel are not lost; they
//! make every solid about half a voxel "fatter" (for a sphere of radius r voxels
//! the volume grows by about 2.25/r, 1.8% at r = 128), the same for every shape.

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::level::{Frame, Level};

pub mod colour;
pub mod detail;
mod voxel_index;

pub use colour::{ColourParams, ColourPatches, ColourScores};
pub use detail::{DetailScores, Variation};
use crate::io::mesh::Mesh;
use crate::geom::nearest::Nearest;
use crate::util::rng::Rng;

// ---------------------------------------------------------------------------
// Lattice and occupancy
// ---------------------------------------------------------------------------

/// Default evaluation resolution: voxels along the longest side of the
/// exemplar's bounding box (METHOD.md section 7).
pub const DEFAULT_RESOLUTION: u32 = 256;

/// Default margin around the exemplar's box, normalised units: one level-0 voxel
/// (2/16), the most a variant grown from the exemplar's coarse box can stick out.
pub const DEFAULT_MARGIN: f32 = 0.125;

/// Lattice origins fall on multiples of this many voxels (twice the patch
/// stride of 5, so both the stride cells and the half-resolution pairs are
/// the same in every evaluation).
pub const ALIGN_VOXELS: u32 = 10;

/// The evaluation lattice, shared by the exemplar and all its variants.
/// Voxel `(i, j, k)` covers `origin + [i, i+1) x [j, j+1) x [k, k+1) * voxel` in
/// normalised units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OccupancyGrid {
    /// The exemplar's normalisation: world units -> normalised units.
    pub frame: Frame,
    /// Corner of voxel (0, 0, 0), normalised units.
    pub origin: Vec3,
    /// Edge length of one voxel, normalised units.
    pub voxel: f32,
    /// Voxels along x, y, z.
    pub dims: [u32; 3],
}

impl OccupancyGrid {
    /// Lattice with `resolution` voxels along the longest side of the box
    /// `[lo, hi]` (normalised units), extended by `margin` (normalised units) on
    /// every side and centred on the box.
    pub fn from_box(frame: Frame, lo: Vec3, hi: Vec3, resolution: u32, margin: f32) -> Self {
        let resolution = resolution.max(1);
        let extent = (hi - lo).max(Vec3::ZERO);
        let longest = extent.max_element();
        let voxel = if longest > 0.0 { longest / resolution as f32 } else { 2.0 / resolution as f32 };
        let margin = margin.max(0.0);
        let mut dims = [0u32; 3];
        let mut origin = Vec3::ZERO;
        let centre = (lo + hi) * 0.5;
        for a in 0..3 {
            let n = ((extent[a] + 2.0 * margin) / voxel).ceil().max(1.0) as u32;
            dims[a] = n;
            origin[a] = centre[a] - 0.5 * n as f32 * voxel;
        }
        OccupancyGrid { frame, origin, voxel, dims }
    }

    /// Lattice of voxels of edge `voxel` (normalised units) covering the box
    /// `[lo, hi]` (normalised units) plus `margin` on every side. With
    /// `align`, voxel boundaries fall on `align + k * voxel` (a level's own
    /// grid lines, so each level voxel is one lattice voxel) and the origin on
    /// a multiple of [`ALIGN_VOXELS`] voxels from `align`, so that the patch
    /// cells and the half-resolution lattice pair the same voxels whatever
    /// else the lattice covers; else the lattice is centred on the box.
    pub fn covering(frame: Frame, lo: Vec3, hi: Vec3, voxel: f32, margin: f32, align: Option<Vec3>) -> Self {
        let voxel = if voxel.is_finite() && voxel > 0.0 { voxel } else { 2.0 / DEFAULT_RESOLUTION as f32 };
        let (lo, hi) = (lo - Vec3::splat(margin.max(0.0)), hi + Vec3::splat(margin.max(0.0)));
        let mut dims = [0u32; 3];
        let mut origin = Vec3::ZERO;
        for a in 0..3 {
            match align {
                Some(g) => {
                    let g = g[a];
                    let k = ALIGN_VOXELS as f32;
                    let first = (((lo[a] - g) / voxel).floor() / k).floor() * k;
                    let last = ((hi[a] - g) / voxel).ceil();
                    origin[a] = g + first * voxel;
                    dims[a] = (last - first).max(1.0) as u32;
                }
                None => {
                    let n = ((hi[a] - lo[a]) / voxel).ceil().max(1.0) as u32;
                    dims[a] = n;
                    origin[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * n as f32 * voxel;
                }
            }
        }
        OccupancyGrid { frame, origin, voxel, dims }
    }

    /// The same region at half the resolution (voxels twice as large, the
    /// same origin): 11^3 patches on it span 22^3 voxels of this lattice.
    pub fn halved(&self) -> Self {
        OccupancyGrid {
            frame: self.frame,
            origin: self.origin,
            voxel: self.voxel * 2.0,
            dims: self.dims.map(|d| d.div_ceil(2).max(1)),
        }
    }

    /// The lattice for an exemplar (world units) under its normalisation `frame`:
    /// `resolution` voxels along the longest side of its normalised bounding box,
    /// plus [`DEFAULT_MARGIN`] on every side.
    pub fn for_exemplar(exemplar: &Mesh, frame: Frame, resolution: u32) -> Self {
        let (lo, hi) = exemplar.bounds();
        let lo = frame.to_normalised(lo.as_dvec3()).as_vec3();
        let hi = frame.to_normalised(hi.as_dvec3()).as_vec3();
        Self::from_box(frame, lo.min(hi), lo.max(hi), resolution, DEFAULT_MARGIN)
    }

    /// Continuous lattice coordinates of a world point: voxel `(i,j,k)` spans
    /// `[i, i+1)` etc., so its centre is at `i + 0.5`.
    pub fn world_to_grid(&self, p: Vec3) -> DVec3 {
        (self.frame.to_normalised(p.as_dvec3()) - self.origin.as_dvec3()) / self.voxel as f64
    }

    pub fn voxel_count(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64).product()
    }
}

/// A bit-packed voxel set on an [`OccupancyGrid`]'s lattice.
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
    fn row_bits(&self, y: i64, z: i64, start: i64, n: u32) -> u64 {
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

fn last_word_mask(nx: u32) -> u64 {
    match nx % 64 {
        0 => u64::MAX,
        r => (1u64 << r) - 1,
    }
}

/// Sets bits `lo ..= hi` of a row.
fn set_range(row: &mut [u64], lo: usize, hi: usize) {
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

// ---------------------------------------------------------------------------
// Voxelisation
// ---------------------------------------------------------------------------

/// Fixed-point scale for the exact crossing test: lattice coordinates are
/// snapped to multiples of 2^-20 voxel, then all orientation tests are exact
/// integer arithmetic (i128).
const FIXED_BITS: u32 = 20;

/// Per-triangle data for the column sweep.
struct SweepTri {
    /// Lattice coordinates (f64), for crossing positions and surface clipping.
    p: [DVec3; 3],
    /// Fixed-point (y, z) of the vertices, for the exact inside test.
    q: [[i64; 2]; 3],
    /// Twice the signed (y, z)-projected area in fixed point = the sign of the
    /// normal's x component. 0 for triangles seen edge-on from +x.
    area2: i128,
}

/// Solid voxelisation of a mesh (world units) on `grid`'s lattice.
///
/// A voxel is occupied when |winding number| > 0.5 at its centre, or when the
/// surface passes through it (see the module documentation for why).
///
/// Winding number: for each voxel column (fixed y, z) a ray along +x through the
/// voxel centres is intersected with the triangles whose projection covers the
/// column (triangles are binned by column first). Each crossing counts -1 where
/// the triangle faces -x (the ray enters an outward-oriented solid) and +1 where
/// it faces +x; the winding number at a centre is minus the sum of the crossings
/// before it plus half the total, i.e. the mean of the counts from the -x and the
/// +x end. For a closed
/// mesh the total is 0 and this is the exact winding number; rays through edges
/// and vertices are resolved by symbolic perturbation in exact integer arithmetic,
/// so no crossing is counted twice or missed. For open meshes the two ends
/// disagree and the mean is only an approximation of the generalised winding
/// number (columns through a hole get 1/2 and stay empty); the surface voxels
/// still keep the sheet itself.
///
/// The absolute value (deviation from METHOD.md's "winding number > 0.5") makes a
/// mesh with all faces flipped inward voxelise to the same solid as the correctly
/// oriented one (winding -1 inside); meshes with consistent orientation are not
/// affected.
///
/// Cost: parallel over columns; memory one bit per voxel plus the binned
/// (triangle, column) pairs.
pub fn voxelise_mesh(mesh: &Mesh, grid: &OccupancyGrid) -> Occupancy {
    voxelise_mesh_with(mesh, grid, true)
}

fn voxelise_mesh_with(mesh: &Mesh, grid: &OccupancyGrid, with_surface: bool) -> Occupancy {
    voxelise_mesh_fill(mesh, grid, with_surface, true)
}

fn voxelise_mesh_fill(mesh: &Mesh, grid: &OccupancyGrid, with_surface: bool, fill_inside: bool) -> Occupancy {
    let mut occ = Occupancy::empty(grid.dims);
    let [nx, ny, nz] = grid.dims.map(|d| d as usize);
    if nx == 0 || ny == 0 || nz == 0 {
        return occ;
    }
    let fixed = (1u64 << FIXED_BITS) as f64;
    let lattice: Vec<DVec3> = mesh.positions.iter().map(|&p| grid.world_to_grid(p)).collect();
    let snap = |v: f64| -> i64 { (v * fixed).round().clamp(-(1i64 << 60) as f64, (1i64 << 60) as f64) as i64 };

    // Triangles and their column ranges (columns whose square the bbox touches).
    let mut tris: Vec<SweepTri> = Vec::with_capacity(mesh.triangles.len());
    let mut ranges: Vec<[usize; 4]> = Vec::with_capacity(mesh.triangles.len());
    for t in &mesh.triangles {
        let Some(p) = t.iter().map(|&i| lattice.get(i as usize).copied()).collect::<Option<Vec<_>>>() else {
            continue;
        };
        if p.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let p = [p[0], p[1], p[2]];
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        if hi.y < 0.0 || hi.z < 0.0 || lo.y >= ny as f64 || lo.z >= nz as f64 {
            continue;
        }
        let r = [
            lo.y.floor().max(0.0) as usize,
            (hi.y.floor() as i64).clamp(0, ny as i64 - 1) as usize,
            lo.z.floor().max(0.0) as usize,
            (hi.z.floor() as i64).clamp(0, nz as i64 - 1) as usize,
        ];
        let q = p.map(|v| [snap(v.y), snap(v.z)]);
        let area2 = orient(q[0], q[1], q[2]);
        tris.push(SweepTri { p, q, area2 });
        ranges.push(r);
    }

    // Bin triangles by column (CSR).
    let columns = ny * nz;
    let mut start = vec![0u32; columns + 1];
    for r in &ranges {
        for k in r[2]..=r[3] {
            for j in r[0]..=r[1] {
                start[j + ny * k + 1] += 1;
            }
        }
    }
    for c in 0..columns {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut binned = vec![0u32; start[columns] as usize];
    for (t, r) in ranges.iter().enumerate() {
        for k in r[2]..=r[3] {
            for j in r[0]..=r[1] {
                let c = j + ny * k;
                binned[fill[c] as usize] = t as u32;
                fill[c] += 1;
            }
        }
    }
    drop(fill);
    log::debug!("voxelise: {} triangles, {} (triangle, column) pairs on {:?}", tris.len(), binned.len(), grid.dims);

    let w = occ.words_per_row();
    occ.bits.par_chunks_mut(w).enumerate().for_each_init(Vec::new, |crossings, (c, row)| {
        let (j, k) = (c % ny, c / ny);
        let list = &binned[start[c] as usize..start[c + 1] as usize];
        if list.is_empty() {
            return;
        }
        let ray = [((2 * j as i64 + 1) << (FIXED_BITS - 1)), ((2 * k as i64 + 1) << (FIXED_BITS - 1))];
        crossings.clear();
        for &t in list {
            let tri = &tris[t as usize];
            if fill_inside && tri.area2 != 0 {
                if let Some(x) = ray_crossing(tri, ray) {
                    crossings.push((x, if tri.area2 > 0 { 1i32 } else { -1 }));
                }
            }
            if with_surface {
                if let Some((x0, x1)) = clip_x_range(&tri.p, j as f64, k as f64) {
                    if x1 >= 0.0 && x0 < nx as f64 {
                        let lo = x0.floor().max(0.0) as usize;
                        let hi = (x1.floor() as i64).min(nx as i64 - 1) as usize;
                        set_range(row, lo, hi);
                    }
                }
            }
        }
        if crossings.is_empty() {
            return;
        }
        crossings.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let total: i32 = crossings.iter().map(|c| c.1).sum();
        // Twice the winding number before the first crossing: 0 from the -x end
        // plus total/2 (mean with the count from the +x end).
        let mut w2 = total;
        let mut prev = f64::NEG_INFINITY;
        for m in 0..=crossings.len() {
            let next = crossings.get(m).map_or(f64::INFINITY, |c| c.0);
            // Voxel centres i + 0.5 in (prev, next].
            if w2.abs() > 1 {
                let lo = if prev == f64::NEG_INFINITY { 0 } else { (prev - 0.5).floor() as i64 + 1 };
                let hi = if next == f64::INFINITY { nx as i64 - 1 } else { (next - 0.5).floor() as i64 };
                let (lo, hi) = (lo.max(0), hi.min(nx as i64 - 1));
                if lo <= hi {
                    set_range(row, lo as usize, hi as usize);
                }
            }
            if let Some(c) = crossings.get(m) {
                // Entering through a face whose normal points to -x raises it.
                w2 -= 2 * c.1;
                prev = c.0;
            }
        }
    });
    occ
}

/// Twice the signed area of (u, v, p) in the (y, z) plane, exact.
fn orient(u: [i64; 2], v: [i64; 2], p: [i64; 2]) -> i128 {
    (v[0] - u[0]) as i128 * (p[1] - u[1]) as i128 - (v[1] - u[1]) as i128 * (p[0] - u[0]) as i128
}

/// Sign of the edge function of edge u -> v at p, with zeros resolved by the
/// symbolic perturbation p + eps * (1, eps'): consistent for the two triangles
/// sharing an edge (opposite directions give opposite signs).
fn edge_sign(u: [i64; 2], v: [i64; 2], p: [i64; 2]) -> i32 {
    let o = orient(u, v, p);
    if o != 0 {
        return if o > 0 { 1 } else { -1 };
    }
    let (ey, ez) = (v[0] - u[0], v[1] - u[1]);
    if ez != 0 {
        if ez > 0 {
            -1
        } else {
            1
        }
    } else if ey > 0 {
        1
    } else {
        -1
    }
}

/// Where the +x ray through `ray` (fixed-point y, z) crosses the triangle, in
/// lattice x, or None.
fn ray_crossing(tri: &SweepTri, ray: [i64; 2]) -> Option<f64> {
    let s = if tri.area2 > 0 { 1 } else { -1 };
    let [a, b, c] = tri.q;
    if edge_sign(a, b, ray) != s || edge_sign(b, c, ray) != s || edge_sign(c, a, ray) != s {
        return None;
    }
    // Barycentric weights: the weight of a vertex is the area opposite it.
    let la = orient(b, c, ray) as f64;
    let lb = orient(c, a, ray) as f64;
    let lc = orient(a, b, ray) as f64;
    let sum = tri.area2 as f64;
    Some((la * tri.p[0].x + lb * tri.p[1].x + lc * tri.p[2].x) / sum)
}

/// The x extent of the part of a triangle (lattice coordinates) inside the
/// column `[j, j+1] x [k, k+1]` in (y, z), or None if it misses the column.
fn clip_x_range(p: &[DVec3; 3], j: f64, k: f64) -> Option<(f64, f64)> {
    let mut poly = [DVec3::ZERO; 9];
    let mut n = 3;
    poly[..3].copy_from_slice(p);
    let mut tmp = [DVec3::ZERO; 9];
    // Half-planes as (axis, bound, keep >= bound?).
    for (axis, bound, above) in [(1usize, j, true), (1, j + 1.0, false), (2, k, true), (2, k + 1.0, false)] {
        let inside = |v: &DVec3| if above { v[axis] >= bound } else { v[axis] <= bound };
        let mut m = 0;
        for i in 0..n {
            let (cur, nxt) = (poly[i], poly[(i + 1) % n]);
            let (ci, ni) = (inside(&cur), inside(&nxt));
            if ci {
                tmp[m] = cur;
                m += 1;
            }
            if ci != ni {
                let t = (bound - cur[axis]) / (nxt[axis] - cur[axis]);
                let mut v = cur + (nxt - cur) * t;
                v[axis] = bound;
                tmp[m] = v;
                m += 1;
            }
        }
        n = m;
        if n == 0 {
            return None;
        }
        poly[..n].copy_from_slice(&tmp[..n]);
    }
    let (lo, hi) = poly[..n].iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v.x), hi.max(v.x)));
    Some((lo, hi))
}

/// Surface-only occupancy of a point set given in normalised units (the
/// lattice's own), e.g. [`level_points_normalised`]. Points outside the
/// lattice are dropped.
pub fn voxelise_normalised_points(positions: &[Vec3], grid: &OccupancyGrid) -> Occupancy {
    let mut occ = Occupancy::empty(grid.dims);
    for &p in positions {
        let g = ((p - grid.origin) / grid.voxel).floor();
        if g.is_finite() {
            occ.set(g.x as i64, g.y as i64, g.z as i64);
        }
    }
    occ
}

/// The voxels a mesh's surface passes through, nothing filled: how an OPEN
/// surface is voxelised (a sheet stays a sheet; the winding number of a
/// surface with holes does not say what is inside).
pub fn voxelise_mesh_surface(mesh: &Mesh, grid: &OccupancyGrid) -> Occupancy {
    voxelise_mesh_fill(mesh, grid, true, false)
}

/// Surface-only occupancy of a point set (world units, e.g.
/// [`Level::point_world`] of a coarse level): the voxels that contain a point.
/// Nothing is filled, so compare it only with other point-set occupancies.
pub fn voxelise_points(positions: &[Vec3], grid: &OccupancyGrid) -> Occupancy {
    let mut occ = Occupancy::empty(grid.dims);
    for &p in positions {
        let g = grid.world_to_grid(p);
        if g.is_finite() {
            let f = g.floor();
            occ.set(f.x as i64, f.y as i64, f.z as i64);
        }
    }
    occ
}

// ---------------------------------------------------------------------------
// IoU and diversity
// ---------------------------------------------------------------------------

fn same_lattice(a: &Occupancy, b: &Occupancy) {
    assert_eq!(
        a.dims, b.dims,
        "occupancies on different lattices: voxelise every shape with the exemplar's OccupancyGrid"
    );
}

/// Intersection over union of two occupancies on the same lattice; two empty
/// sets are identical (1). Panics when the lattices differ.
pub fn iou(a: &Occupancy, b: &Occupancy) -> f64 {
    same_lattice(a, b);
    let (inter, union) = a
        .bits
        .par_chunks(4096)
        .zip(b.bits.par_chunks(4096))
        .map(|(x, y)| {
            x.iter()
                .zip(y)
                .fold((0u64, 0u64), |(i, u), (p, q)| (i + (p & q).count_ones() as u64, u + (p | q).count_ones() as u64))
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// Diversity (METHOD.md section 7): mean over all unordered pairs of `1 - IoU`.
/// 0 for fewer than two shapes.
pub fn diversity(variants: &[Occupancy]) -> f64 {
    let n = variants.len();
    if n < 2 {
        return 0.0;
    }
    let pairs: Vec<(usize, usize)> = (0..n).flat_map(|i| (i + 1..n).map(move |j| (i, j))).collect();
    let sum: f64 = pairs.iter().map(|&(i, j)| 1.0 - iou(&variants[i], &variants[j])).sum();
    sum / pairs.len() as f64
}

// ---------------------------------------------------------------------------
// Local patches: LP-IoU and LP-F-score
// ---------------------------------------------------------------------------

/// Patch edge, voxels (DECOR-GAN / SSG: 11).
pub const PATCH: usize = 11;
const HALF: i64 = (PATCH / 2) as i64;
/// u64 words per 11^3 = 1331-bit patch.
pub const PATCH_WORDS: usize = (PATCH * PATCH * PATCH).div_ceil(64);

/// Parameters of the local-patch measures.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LpParams {
    /// Spacing, in voxels, of the variant's patch centres (SSG: 5).
    pub variant_stride: u32,
    /// At most this many variant patches are scored (DECOR-GAN, SSG: 1000).
    pub max_patches: usize,
    /// Spacing of the exemplar's patch centres. 1 (default) = a patch on every
    /// surface voxel, which makes the measure exactly invariant to whole-voxel
    /// translations; 2 keeps one per 2^3 cell: ~3x fewer patches and faster,
    /// but no longer translation invariant and slightly lower scores (bench:
    /// LP-IoU 0.954 vs 0.958, fraction > 0.95 0.73 vs 0.78).
    pub exemplar_stride: u32,
    /// A patch is "plausible" when its best score is above this (0.95).
    pub threshold: f64,
    /// Seed of the deterministic patch sampling.
    pub seed: u64,
}

impl Default for LpParams {
    fn default() -> Self {
        LpParams { variant_stride: 5, max_patches: 1000, exemplar_stride: 1, threshold: 0.95, seed: 1234 }
    }
}

/// One 11^3 patch in three bit layers. Bit `dx + 11 * (dy + 11 * dz)` is voxel
/// `centre + (dx, dy, dz) - 5`.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[repr(C, align(64))]
struct Patch {
    /// Occupancy.
    occ: [u64; PATCH_WORDS],
    /// DECOR-GAN boundary voxels (occupied with an empty 26-neighbour).
    edge: [u64; PATCH_WORDS],
    /// Boundary dilated by the 3^3 box (within 1 voxel, Chebyshev, of a boundary voxel).
    dil: [u64; PATCH_WORDS],
    occ_n: u32,
    edge_n: u32,
}

/// Slab histograms of a patch: for each layer (occupancy, boundary, dilated
/// boundary) and each axis, the number of set voxels in each of the 11 slabs
/// across that axis (padded to 16 bytes). `sum_s min(a_s, b_s)` over any axis
/// bounds `|A and B|` from above, which prunes most exemplar patches cheaply.
#[derive(Clone, Copy)]
#[repr(C, align(16))]
struct Sig {
    occ: [[u8; 16]; 3],
    edge: [[u8; 16]; 3],
    dil: [[u8; 16]; 3],
    /// Copies of the patch's counts, so the bound needs nothing else.
    occ_n: u32,
    edge_n: u32,
}

/// `SPREAD[b]` has byte i = bit i of `b`: adding these counts bits per position.
const SPREAD: [u64; 256] = {
    let mut t = [0u64; 256];
    let mut b = 0;
    while b < 256 {
        let mut i = 0;
        while i < 8 {
            if b >> i & 1 == 1 {
                t[b] |= 1u64 << (8 * i);
            }
            i += 1;
        }
        b += 1;
    }
    t
};

impl Sig {
    #[allow(clippy::needless_range_loop)] // parallel indices read best as loops
    fn of(p: &Patch) -> Sig {
        let mut s = Sig { occ: [[0; 16]; 3], edge: [[0; 16]; 3], dil: [[0; 16]; 3], occ_n: p.occ_n, edge_n: p.edge_n };
        for (words, hist) in [(&p.occ, &mut s.occ), (&p.edge, &mut s.edge), (&p.dil, &mut s.dil)] {
            // Row r = dy + 11 dz holds the 11 voxels along x at bits 11r ..
            let (mut lo, mut hi) = (0u64, 0u64);
            for r in 0..PATCH * PATCH {
                let bit = PATCH * r;
                let (wi, off) = (bit / 64, bit % 64);
                let mut v = words[wi] >> off;
                if off + PATCH > 64 {
                    v |= words[wi + 1] << (64 - off);
                }
                let v = v & ((1u64 << PATCH) - 1);
                let n = v.count_ones() as u8;
                hist[1][r % PATCH] += n;
                hist[2][r / PATCH] += n;
                lo += SPREAD[(v & 0xff) as usize];
                hi += SPREAD[(v >> 8) as usize];
            }
            for i in 0..8 {
                hist[0][i] = (lo >> (8 * i)) as u8;
            }
            for i in 0..PATCH - 8 {
                hist[0][8 + i] = (hi >> (8 * i)) as u8;
            }
        }
        s
    }
}

/// Exemplar patches per [`SigTile`]: one AVX2 register of u8 lanes.
const LANES: usize = 32;

/// The slab histograms of up to 32 consecutive dictionary patches, transposed
/// (lane = patch), so the bounds of a variant patch against all of them are a
/// few vector instructions per slab. Unused lanes are zero (bound 0, never
/// compared).
#[derive(Clone)]
#[repr(C, align(32))]
struct SigTile {
    /// `[layer: occupancy, boundary, dilated][axis][slab][lane]`.
    hist: [[[[u8; LANES]; PATCH]; 3]; 3],
    occ_n: [f32; LANES],
    edge_n: [f32; LANES],
}

impl SigTile {
    #[allow(clippy::needless_range_loop)] // parallel indices read best as loops
    fn new(sigs: &[Sig]) -> SigTile {
        let mut t = SigTile { hist: [[[[0; LANES]; PATCH]; 3]; 3], occ_n: [0.0; LANES], edge_n: [0.0; LANES] };
        for (l, s) in sigs.iter().enumerate().take(LANES) {
            for (layer, h) in [&s.occ, &s.edge, &s.dil].into_iter().enumerate() {
                for axis in 0..3 {
                    for slab in 0..PATCH {
                        t.hist[layer][axis][slab][l] = h[axis][slab];
                    }
                }
            }
            t.occ_n[l] = s.occ_n as f32;
            t.edge_n[l] = s.edge_n as f32;
        }
        t
    }

    /// Per lane, the tightest over the three axes of `sum_slab min(a, b)`, for
    /// variant histogram `a` against this tile's layer `layer`: an upper bound of
    /// `|A and B|`.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // parallel indices read best as loops
    fn overlap_bound(&self, a: &[[u8; 16]; 3], layer: usize) -> [f32; LANES] {
        let mut best = [u16::MAX; LANES];
        for axis in 0..3 {
            let mut acc = [0u16; LANES];
            for slab in 0..PATCH {
                let av = a[axis][slab];
                let row = &self.hist[layer][axis][slab];
                for l in 0..LANES {
                    acc[l] += av.min(row[l]) as u16;
                }
            }
            for l in 0..LANES {
                best[l] = best[l].min(acc[l]);
            }
        }
        best.map(|v| v as f32)
    }
}

/// The layers patches are cut from, computed once per shape on the whole lattice
/// (so the boundary and its dilation see the voxels just outside a patch).
struct PatchLayers {
    occ: Occupancy,
    edge: Occupancy,
    dil: Occupancy,
    surface: Occupancy,
}

impl PatchLayers {
    fn new(occ: &Occupancy) -> Self {
        let edge = occ.boundary26();
        let dil = edge.dilate26();
        let surface = occ.surface();
        PatchLayers { occ: occ.clone(), edge, dil, surface }
    }

    fn patch(&self, c: [u32; 3]) -> Patch {
        let mut p = Patch { occ: [0; PATCH_WORDS], edge: [0; PATCH_WORDS], dil: [0; PATCH_WORDS], occ_n: 0, edge_n: 0 };
        let [cx, cy, cz] = c.map(|v| v as i64);
        for dz in 0..PATCH {
            for dy in 0..PATCH {
                let (y, z) = (cy + dy as i64 - HALF, cz + dz as i64 - HALF);
                let bit = PATCH * (dy + PATCH * dz);
                for (layer, dst) in [(&self.occ, &mut p.occ), (&self.edge, &mut p.edge), (&self.dil, &mut p.dil)] {
                    let v = layer.row_bits(y, z, cx - HALF, PATCH as u32);
                    if v != 0 {
                        let (wi, off) = (bit / 64, bit % 64);
                        dst[wi] |= v << off;
                        if off + PATCH > 64 {
                            dst[wi + 1] |= v >> (64 - off);
                        }
                    }
                }
            }
        }
        p.occ_n = p.occ.iter().map(|w| w.count_ones()).sum();
        p.edge_n = p.edge.iter().map(|w| w.count_ones()).sum();
        p
    }

    /// Patch centres: surface voxels, one per `stride`^3 cell of the lattice (the
    /// one nearest the cell's centre, ties to the first in storage order);
    /// stride 1 = every surface voxel. Sorted in storage order.
    fn centres(&self, stride: u32) -> Vec<[u32; 3]> {
        let surface = self.surface.voxels();
        if stride <= 1 {
            return surface;
        }
        let s = stride;
        let mid = (s - 1) as i64; // twice the cell centre offset
        let mut best: HashMap<[u32; 3], (i64, usize)> = HashMap::new();
        for (i, v) in surface.iter().enumerate() {
            let cell = v.map(|c| c / s);
            let d: i64 = v.iter().map(|&c| (2 * (c % s) as i64 - mid).pow(2)).sum();
            best.entry(cell)
                .and_modify(|b| {
                    if d < b.0 {
                        *b = (d, i)
                    }
                })
                .or_insert((d, i));
        }
        let mut idx: Vec<usize> = best.into_values().map(|b| b.1).collect();
        idx.sort_unstable();
        idx.into_iter().map(|i| surface[i]).collect()
    }
}

/// The exemplar's patch dictionary, built once and reused for every variant.
/// Memory: about 610 bytes per distinct patch (three 1331-bit layers, counts and
/// slab histograms): ~100 MB for a 256-grid exemplar with 167k surface voxels.
pub struct ExemplarPatches {
    /// Distinct patches, sorted (so an exact match is a binary search).
    patches: Vec<Patch>,
    /// Slab histograms of `patches`, 32 per tile, for the bounds.
    tiles: Vec<SigTile>,
    /// Surface voxels the patches were centred on (before removing duplicates).
    pub centres: usize,
}

impl ExemplarPatches {
    /// Patches centred on the exemplar's surface voxels (every one for
    /// `stride = 1`), identical patches kept once (the best match is unchanged).
    pub fn new(exemplar: &Occupancy, stride: u32) -> Self {
        let layers = PatchLayers::new(exemplar);
        let centres = layers.centres(stride);
        let all: Vec<Patch> = centres.par_iter().map(|&c| layers.patch(c)).collect();
        // Sort and deduplicate indices (moving 512-byte patches around is slow).
        let mut order: Vec<u32> = (0..all.len() as u32).collect();
        order.par_sort_unstable_by(|&i, &j| all[i as usize].cmp(&all[j as usize]));
        order.dedup_by(|i, j| all[*i as usize] == all[*j as usize]);
        let patches: Vec<Patch> = order.par_iter().map(|&i| all[i as usize]).collect();
        drop(all);
        let tiles =
            patches.par_chunks(LANES).map(|c| SigTile::new(&c.iter().map(Sig::of).collect::<Vec<_>>())).collect();
        log::debug!("exemplar patches: {} centres, {} distinct", centres.len(), patches.len());
        ExemplarPatches { patches, tiles, centres: centres.len() }
    }

    /// Distinct patches in the dictionary.
    pub fn len(&self) -> usize {
        self.patches.len()
    }

    pub fn is_empty(&self) -> bool {
        self.patches.is_empty()
    }
}

/// Scores of one shape's local patches against an exemplar.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LpScores {
    /// Mean over the variant's patches of the best IoU with any exemplar patch.
    pub lp_iou: f64,
    /// Fraction of the variant's patches whose best IoU is > threshold.
    pub lp_iou_above: f64,
    /// Mean over the variant's patches of the best boundary F-score.
    pub lp_fscore: f64,
    /// Fraction of the variant's patches whose best F-score is > threshold.
    pub lp_fscore_above: f64,
    /// Number of variant patches scored.
    pub patches: usize,
}

/// The best match so far of one variant patch, as exact fractions.
#[derive(Clone, Copy)]
struct Best {
    iou_num: u32,
    iou_den: u32,
    f_num: u64,
    f_den: u64,
}

impl Default for Best {
    fn default() -> Self {
        Best { iou_num: 0, iou_den: 1, f_num: 0, f_den: 1 }
    }
}

/// LP-IoU and LP-F-score of `variant` against the exemplar's patch dictionary.
///
/// What is computed (all in voxels of the shared lattice):
/// 1. Surface voxels of the variant: occupied with an unoccupied 6-neighbour.
/// 2. Patch centres: one surface voxel per 5^3 cell of the lattice
///    (`variant_stride`), the one nearest the cell's centre; if there are more
///    than `max_patches` (1000), that many are drawn without replacement by a
///    seeded Fisher-Yates shuffle (deterministic).
/// 3. Each 11^3 patch (centred on its surface voxel) is matched against EVERY
///    exemplar patch (centred on every exemplar surface voxel, `exemplar_stride`
///    1, duplicates removed) and the best score is kept, separately for each
///    measure. The result is the exhaustive maximum; the speed comes from exact
///    upper bounds that skip most exemplar patches (see `match_patches`):
///    - IoU of the occupied voxels of the two patches;
///    - F-score of boundary voxels, as DECOR-GAN: boundary = occupied voxels with
///      an empty voxel among their 26 neighbours (computed on the whole shape);
///      precision = fraction of the variant patch's boundary voxels within 1 voxel
///      (3^3 box) of an exemplar boundary voxel, recall = fraction of the exemplar
///      patch's boundary voxels within 1 voxel of a variant boundary voxel,
///      F = 2PR / (P + R).
/// 4. LP-IoU = mean best IoU, and the fraction of patches whose best IoU >
///    `threshold` (0.95); LP-F-score likewise. (DECOR-GAN reports only the
///    fraction; SSG reports both.)
///
/// Reading the numbers: the IoU needs the patch to match voxel for voxel, so a
/// one-voxel offset of a flat surface already costs about 15%. The boundary
/// F-score tolerates one voxel and the 26-neighbour boundary of a slanted
/// surface is about 2 voxels thick, so its dilation covers ~half of a patch:
/// it is lenient (random 30%-dense voxels still average ~0.7-0.9, but almost
/// none of their patches pass 0.95), so its "> 0.95" fraction is the telling
/// part.
///
/// Patches reaching past the lattice read empty there. A shape without surface
/// voxels scores 0 with 0 patches. Cost: about 1.3 s of one core for 1000
/// patches against a 167k-patch dictionary when the variant is plausible
/// (bounds prune ~98% of the pairs); up to ~4x more for shapes with no
/// plausible patches (random voxels), where the bounds prune less.
pub fn local_patch_scores(variant: &Occupancy, exemplar: &ExemplarPatches, params: &LpParams) -> LpScores {
    if exemplar.is_empty() {
        log::warn!("LP scores: the exemplar has no surface voxels");
    }
    let best = best_patch_matches(variant, exemplar, params);
    if best.is_empty() {
        log::warn!("LP scores: the variant has no surface voxels");
    }
    best.summary(params.threshold)
}

/// The best IoU and boundary F-score of each sampled patch of one shape
/// against a dictionary (one entry per sampled patch centre, in the order of
/// [`patch_centres`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchMatches {
    pub iou: Vec<f64>,
    pub fscore: Vec<f64>,
}

impl PatchMatches {
    pub fn len(&self) -> usize {
        self.iou.len()
    }

    pub fn is_empty(&self) -> bool {
        self.iou.is_empty()
    }

    /// Means and fractions above `threshold`; all 0 without patches.
    pub fn summary(&self, threshold: f64) -> LpScores {
        let n = self.len().max(1) as f64;
        let above = |v: &[f64]| v.iter().filter(|&&x| x > threshold).count() as f64 / n;
        LpScores {
            lp_iou: self.iou.iter().sum::<f64>() / n,
            lp_iou_above: above(&self.iou),
            lp_fscore: self.fscore.iter().sum::<f64>() / n,
            lp_fscore_above: above(&self.fscore),
            patches: self.len(),
        }
    }

    /// Patch by patch, the better of two match sets of the same centres (the
    /// coverage of an exemplar by a SET of variants: each exemplar patch counts
    /// as found when any variant holds it).
    pub fn max_with(&self, other: &PatchMatches) -> PatchMatches {
        assert_eq!(self.len(), other.len(), "patch matches of different centre sets");
        let m = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x.max(*y)).collect();
        PatchMatches { iou: m(&self.iou, &other.iou), fscore: m(&self.fscore, &other.fscore) }
    }
}

/// The sampled patch centres of a shape: one surface voxel per
/// `variant_stride`^3 cell, at most `max_patches` of them drawn by a seeded
/// Fisher-Yates shuffle (deterministic for a given shape and seed).
fn patch_centres(layers: &PatchLayers, params: &LpParams) -> Vec<[u32; 3]> {
    let mut centres = layers.centres(params.variant_stride);
    if centres.len() > params.max_patches {
        let mut rng = Rng::new(params.seed);
        for i in 0..params.max_patches {
            let j = i + (rng.next_u64() % (centres.len() - i) as u64) as usize;
            centres.swap(i, j);
        }
        centres.truncate(params.max_patches);
    }
    centres
}

/// Best matches of the sampled patches of `shape` in `dict` (see
/// [`local_patch_scores`] for what is sampled and compared). Empty when the
/// shape has no surface voxels; every score 0 when the dictionary is empty.
pub fn best_patch_matches(shape: &Occupancy, dict: &ExemplarPatches, params: &LpParams) -> PatchMatches {
    let layers = PatchLayers::new(shape);
    let centres = patch_centres(&layers, params);
    if centres.is_empty() {
        return PatchMatches::default();
    }
    if dict.is_empty() {
        return PatchMatches { iou: vec![0.0; centres.len()], fscore: vec![0.0; centres.len()] };
    }
    let patches: Vec<Patch> = centres.par_iter().map(|&c| layers.patch(c)).collect();
    let best = match_patches(&patches, dict);
    PatchMatches {
        iou: best.iter().map(|b| b.iou_num as f64 / b.iou_den as f64).collect(),
        fscore: best.iter().map(|b| b.f_num as f64 / b.f_den as f64).collect(),
    }
}

/// Convenience: [`local_patch_scores`] with a fresh exemplar dictionary.
pub fn lp_scores(variant: &Occupancy, exemplar: &Occupancy, params: &LpParams) -> LpScores {
    same_lattice(variant, exemplar);
    local_patch_scores(variant, &ExemplarPatches::new(exemplar, params.exemplar_stride), params)
}

/// Best IoU and best F-score of every patch of `a` over all patches of the
/// dictionary `b`. Exact (the result equals the exhaustive maximum), made fast by:
/// - an exact match (binary search in the sorted dictionary) scores 1 and 1 at once;
/// - the best scores are seeded with an evenly spaced sample of 512 dictionary
///   patches, then every dictionary patch is first checked against upper bounds of
///   its IoU and F-score and compared bit by bit only when a bound could beat the
///   best so far. With slab histograms ([`Sig`]), `|A and B| <= U = min over the 3
///   axes of sum_slab min(a_slab, b_slab)`, so `IoU <= U / (|A| + |B| - U)`; the
///   same bound on `|Ea and Db|` and `|Da and Eb|` bounds the F-score (it grows
///   with both). The tests are exact (integers held in f32/f64 without rounding),
///   vectorised 32 dictionary patches at a time ([`SigTile`]);
/// - blocking: a tile of the dictionary stays in cache while a group of `a`
///   patches is matched against it; parallel over groups of `a`.
fn match_patches(a: &[Patch], b: &ExemplarPatches) -> Vec<Best> {
    const GROUP: usize = 16;
    let sigs_a: Vec<Sig> = a.par_iter().map(Sig::of).collect();
    let mut best = vec![Best::default(); a.len()];
    best.par_chunks_mut(GROUP).zip(a.par_chunks(GROUP)).zip(sigs_a.par_chunks(GROUP)).for_each(|((best, a), sa)| {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("popcnt") {
                // SAFETY: the CPU supports the features the function is compiled for.
                unsafe { match_group_avx2(a, sa, b, best) };
                return;
            }
        }
        match_group(a, sa, b, best);
    });
    best
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
unsafe fn match_group_avx2(a: &[Patch], sa: &[Sig], b: &ExemplarPatches, best: &mut [Best]) {
    match_group(a, sa, b, best)
}

/// Full bit-by-bit comparison of two patches, folded into `bst`.
#[inline(always)]
fn compare(pa: &Patch, pb: &Patch, bst: &mut Best) {
    let (mut inter, mut tp_p, mut tp_r) = (0u32, 0u32, 0u32);
    for i in 0..PATCH_WORDS {
        inter += (pa.occ[i] & pb.occ[i]).count_ones();
        tp_p += (pa.edge[i] & pb.dil[i]).count_ones();
        tp_r += (pa.dil[i] & pb.edge[i]).count_ones();
    }
    bst.offer_iou(inter, pa.occ_n + pb.occ_n - inter);
    bst.offer_f(tp_p, tp_r, pa.edge_n, pb.edge_n);
}

impl Best {
    /// Keeps `inter / union` if it beats the best IoU (exact fractions).
    #[inline(always)]
    fn offer_iou(&mut self, inter: u32, union: u32) {
        if inter as u64 * self.iou_den as u64 > self.iou_num as u64 * union as u64 {
            self.iou_num = inter;
            self.iou_den = union;
        }
    }

    /// F = 2PR/(P+R) with P = tp_p/|Ea|, R = tp_r/|Eb|
    ///   = 2 tp_p tp_r / (tp_p |Eb| + tp_r |Ea|): as an exact fraction.
    #[inline(always)]
    fn f_fraction(tp_p: u32, tp_r: u32, ea: u32, eb: u32) -> (u64, u64) {
        (2 * tp_p as u64 * tp_r as u64, tp_p as u64 * eb as u64 + tp_r as u64 * ea as u64)
    }

    #[inline(always)]
    fn beats_f(&self, tp_p: u32, tp_r: u32, ea: u32, eb: u32) -> bool {
        let (num, den) = Self::f_fraction(tp_p, tp_r, ea, eb);
        num > 0 && num * self.f_den > self.f_num * den
    }

    #[inline(always)]
    fn offer_f(&mut self, tp_p: u32, tp_r: u32, ea: u32, eb: u32) {
        if self.beats_f(tp_p, tp_r, ea, eb) {
            let (num, den) = Self::f_fraction(tp_p, tp_r, ea, eb);
            self.f_num = num;
            self.f_den = den;
        }
    }

    fn is_perfect(&self) -> bool {
        self.iou_num == self.iou_den && self.f_num == self.f_den
    }
}

#[inline(always)]
fn match_group(a: &[Patch], sa: &[Sig], b: &ExemplarPatches, best: &mut [Best]) {
    const TILE: usize = 8; // SigTiles per block: 256 dictionary patches
    const SEEDS: usize = 512;
    let n = b.patches.len();
    let mut open: Vec<usize> = Vec::with_capacity(a.len());
    for (i, (pa, bst)) in a.iter().zip(best.iter_mut()).enumerate() {
        if b.patches.binary_search(pa).is_ok() {
            *bst = Best { iou_num: 1, iou_den: 1, f_num: 1, f_den: 1 };
            continue;
        }
        let step = n.div_ceil(SEEDS).max(1);
        for pb in b.patches.iter().step_by(step) {
            compare(pa, pb, bst);
        }
        if !bst.is_perfect() {
            open.push(i);
        }
    }
    if open.is_empty() {
        return;
    }
    // Blocks of TILE dictionary patches stay in cache while the group runs.
    for (block, tiles) in b.patches.chunks(TILE * LANES).zip(b.tiles.chunks(TILE)) {
        for &i in &open {
            let (pa, sga, bst) = (&a[i], &sa[i], &mut best[i]);
            let (ca, ea) = (sga.occ_n as f32, sga.edge_n as f32);
            for (t, tile) in tiles.iter().enumerate() {
                let u = tile.overlap_bound(&sga.occ, 0);
                let up = tile.overlap_bound(&sga.edge, 2);
                let ur = tile.overlap_bound(&sga.dil, 1);
                // Exact tests in floating point: every product below is an integer
                // under 2^24 (f32) or 2^53 (f64), so nothing is rounded.
                let (inum, iden) = (bst.iou_num as f32, bst.iou_den as f32);
                let (fnum, fden) = (bst.f_num as f64, bst.f_den as f64);
                let mut need = [false; LANES];
                for l in 0..LANES {
                    let iou_ub = u[l] * iden > inum * (ca + tile.occ_n[l] - u[l]);
                    let f_lhs = (2.0 * up[l] * ur[l]) as f64 * fden;
                    let f_rhs = fnum * (up[l] * tile.edge_n[l] + ur[l] * ea) as f64;
                    need[l] = iou_ub | (f_lhs > f_rhs);
                }
                for (l, pb) in block.iter().skip(t * LANES).take(LANES).enumerate() {
                    if need[l] {
                        compare(pa, pb, bst);
                    }
                }
            }
        }
    }
}


// ---------------------------------------------------------------------------
// Point-set distances
// ---------------------------------------------------------------------------

/// Nearest-neighbour distances from every point of `from` to the set behind `to`.
fn nearest_distances(from: &[Vec3], to: &Nearest) -> Vec<f32> {
    from.par_iter().map(|&p| to.nearest(p).map_or(f32::INFINITY, |(_, d)| d)).collect()
}

/// The nearest-neighbour distances of the finite points of `a` to those of `b`,
/// and of `b` to `a`; when a side has no finite point, `Err` with the answer of
/// both distances: 0 when both are empty, infinite when one is.
fn distances_both_ways(a: &[Vec3], b: &[Vec3]) -> Result<(Vec<f32>, Vec<f32>), f32> {
    let finite = |s: &[Vec3]| -> Vec<Vec3> { s.iter().copied().filter(|p| p.is_finite()).collect() };
    let (a, b) = (finite(a), finite(b));
    match (a.is_empty(), b.is_empty()) {
        (true, true) => return Err(0.0),
        (true, false) | (false, true) => return Err(f32::INFINITY),
        _ => {}
    }
    let (ta, tb) = rayon::join(|| Nearest::new(&a), || Nearest::new(&b));
    Ok(rayon::join(|| nearest_distances(&a, &tb), || nearest_distances(&b, &ta)))
}

/// Symmetric Chamfer distance, in the units of the points (normalised units for
/// [`level_points_normalised`]): the mean of the two one-sided means of
/// nearest-neighbour distances (not squared),
/// `(mean_a min_b |a-b| + mean_b min_a |a-b|) / 2`, so a set against a copy of
/// itself shifted by `t` (less than half the point spacing) gives `|t|`.
/// 0 for two empty sets, infinite when only one is empty.
pub fn chamfer(a: &[Vec3], b: &[Vec3]) -> f32 {
    match distances_both_ways(a, b) {
        Err(d) => d,
        Ok((da, db)) => {
            let mean = |d: &[f32]| d.iter().map(|&v| v as f64).sum::<f64>() / d.len() as f64;
            (0.5 * (mean(&da) + mean(&db))) as f32
        }
    }
}

/// Symmetric Hausdorff distance: the largest nearest-neighbour distance in either
/// direction, in the units of the points. Same conventions for empty sets as
/// [`chamfer`].
pub fn hausdorff(a: &[Vec3], b: &[Vec3]) -> f32 {
    match distances_both_ways(a, b) {
        Err(d) => d,
        Ok((da, db)) => da.iter().chain(&db).fold(0.0f32, |m, &d| m.max(d)),
    }
}

/// A level's surface points in normalised units (the exemplar's bounding-box
/// diagonal is 2), for the coarse Chamfer check.
pub fn level_points_normalised(level: &Level) -> Vec<Vec3> {
    (0..level.len()).map(|i| level.point_normalised(i).as_vec3()).collect()
}

// ---------------------------------------------------------------------------
// Report
// ---------------------------------------------------------------------------

/// Scores of one variant (or one rung of the degradation ladder) against the
/// exemplar. "Precision" compares the shape's patches with the exemplar's
/// (does everything here look like the exemplar?), "coverage" the exemplar's
/// with the shape's (is everything of the exemplar here?).
#[derive(serde::Serialize, serde::Deserialize, Clone, Debug, PartialEq)]
pub struct VariantScores {
    pub name: String,
    /// The literature's LP-IoU (precision, 11^3 patches on the evaluation
    /// lattice): mean best patch IoU, in [0, 1].
    pub lp_iou: f64,
    /// Fraction of patches whose best IoU > 0.95.
    pub lp_iou_above_95: f64,
    /// The literature's LP-F: mean best boundary F-score (1-voxel tolerance).
    pub lp_fscore: f64,
    /// Fraction of patches whose best F-score > 0.95.
    pub lp_fscore_above_95: f64,
    /// Coverage: the exemplar's 11^3 patches matched in this shape.
    pub coverage: LpScores,
    /// Precision with 11^3 patches on the half-resolution lattice (each
    /// spans 22^3 voxels of the evaluation lattice).
    pub precision_22: LpScores,
    /// Coverage on the half-resolution lattice.
    pub coverage_22: LpScores,
    /// Surface detail of the finest level against the exemplar's.
    pub detail: DetailScores,
    /// Colour patches of the finest level against the exemplar's.
    pub colour: ColourScores,
    /// Chamfer distance of the level-0 point set to the exemplar's, normalised
    /// units (bounding-box diagonal 2); None when not measured.
    pub coarse_chamfer: Option<f64>,
}

/// Parameters of one evaluation, recorded with its scores.
#[derive(serde::Serialize, Clone, Debug, PartialEq, Default)]
pub struct EvalParams {
    pub lp: LpParams,
    pub colour: ColourParams,
}

/// Coverage of the exemplar by the variants as a set: an exemplar patch
/// counts as found when any variant holds it.
#[derive(serde::Serialize, serde::Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SetCoverage {
    pub patch_11: LpScores,
    pub patch_22: LpScores,
}

/// All scores of one evaluation.
#[derive(serde::Serialize, Clone, Debug)]
pub struct EvalReport {
    /// Every parameter the scores depend on.
    pub parameters: EvalParams,
    pub variants: Vec<VariantScores>,
    /// Mean of every figure over the variants (name "mean"; the Chamfer mean
    /// is over the variants that have one).
    pub mean: VariantScores,
    /// Mean pairwise 1 - IoU over the variants' occupancies (higher = more
    /// diverse).
    pub diversity: f64,
    /// None with fewer than two variants (nothing a set adds).
    pub set_coverage: Option<SetCoverage>,
}

/// One shape to evaluate: its occupancy on the evaluation lattice and on the
/// half-resolution lattice, its finest level, and optionally its level-0
/// points in normalised units.
pub struct ShapeInput<'a> {
    pub name: String,
    pub occupancy: &'a Occupancy,
    pub occupancy_22: &'a Occupancy,
    pub finest: &'a Level,
    pub coarse_points: Option<&'a [Vec3]>,
}

/// What makes a voxelisation unusable for comparison, with the shape's name.
#[derive(thiserror::Error, Debug, Clone, PartialEq)]
pub enum DegenerateShape {
    #[error("{0}: nothing to compare: its voxelisation has no surface voxels (empty shape, or every point outside the evaluation lattice)")]
    NoSurface(String),
    #[error("{0}: its voxelisation fills {1:.0}% of the evaluation lattice: nothing is left to compare (a solid voxelisation of a surface that is not closed?)")]
    Filled(String, f64),
    #[error("{0}: the finest level has no active voxels")]
    EmptyLevel(String),
}

/// Above this fraction of the lattice, an occupancy is "everything".
pub const FILLED_FRACTION: f64 = 0.9;

/// The degenerate cases of item 3: a voxelisation that leaves nothing, or
/// everything, to compare is an error, never a perfect score.
pub fn check_shape(s: &ShapeInput) -> Result<(), DegenerateShape> {
    if !s.finest.mask.iter().any(|&m| m > 0.0) {
        return Err(DegenerateShape::EmptyLevel(s.name.clone()));
    }
    for occ in [s.occupancy, s.occupancy_22] {
        if occ.surface().count() == 0 {
            return Err(DegenerateShape::NoSurface(s.name.clone()));
        }
        let f = occ.count() as f64 / occ.dims.iter().map(|&d| d as f64).product::<f64>();
        if f > FILLED_FRACTION {
            return Err(DegenerateShape::Filled(s.name.clone(), 100.0 * f));
        }
    }
    Ok(())
}

/// Everything of METHOD.md section 7 and the two-sided measures for a set of
/// variants: precision and coverage of 11^3 patches on two lattices (the
/// exemplar's dictionaries built once, one dictionary per variant for
/// coverage), surface detail, colour patches, coarse Chamfer where both point
/// sets are given, diversity and the set's coverage. Fails on a degenerate
/// shape ([`check_shape`]).
pub fn evaluate(exemplar: &ShapeInput, variants: &[ShapeInput], params: &EvalParams) -> Result<EvalReport, DegenerateShape> {
    check_shape(exemplar)?;
    for v in variants {
        check_shape(v)?;
    }
    let lp = &params.lp;
    let (dict, dict_22) = rayon::join(
        || ExemplarPatches::new(exemplar.occupancy, lp.exemplar_stride),
        || ExemplarPatches::new(exemplar.occupancy_22, lp.exemplar_stride),
    );
    let ex_detail = Variation::of(exemplar.finest);
    let ex_colour = ColourPatches::of(exemplar.finest);
    let mut cover_sets: Option<(PatchMatches, PatchMatches)> = None;
    let mut scores = Vec::with_capacity(variants.len());
    for v in variants {
        same_lattice(v.occupancy, exemplar.occupancy);
        same_lattice(v.occupancy_22, exemplar.occupancy_22);
        let precision = best_patch_matches(v.occupancy, &dict, lp);
        let precision_22 = best_patch_matches(v.occupancy_22, &dict_22, lp);
        let (cover, cover_22) = rayon::join(
            || best_patch_matches(exemplar.occupancy, &ExemplarPatches::new(v.occupancy, lp.exemplar_stride), lp),
            || best_patch_matches(exemplar.occupancy_22, &ExemplarPatches::new(v.occupancy_22, lp.exemplar_stride), lp),
        );
        let p = precision.summary(lp.threshold);
        let cd = match (exemplar.coarse_points, v.coarse_points) {
            (Some(e), Some(c)) => Some(chamfer(c, e) as f64),
            _ => None,
        };
        scores.push(VariantScores {
            name: v.name.clone(),
            lp_iou: p.lp_iou,
            lp_iou_above_95: p.lp_iou_above,
            lp_fscore: p.lp_fscore,
            lp_fscore_above_95: p.lp_fscore_above,
            coverage: cover.summary(lp.threshold),
            precision_22: precision_22.summary(lp.threshold),
            coverage_22: cover_22.summary(lp.threshold),
            detail: DetailScores::new(&Variation::of(v.finest), &ex_detail),
            colour: colour::colour_scores(&ColourPatches::of(v.finest), &ex_colour, &params.colour),
            coarse_chamfer: cd,
        });
        cover_sets = Some(match cover_sets {
            None => (cover, cover_22),
            Some((a, b)) => (a.max_with(&cover), b.max_with(&cover_22)),
        });
    }
    let occs: Vec<Occupancy> = variants.iter().map(|v| v.occupancy.clone()).collect();
    let set_coverage = cover_sets.filter(|_| variants.len() > 1).map(|(a, b)| SetCoverage {
        patch_11: a.summary(lp.threshold),
        patch_22: b.summary(lp.threshold),
    });
    Ok(EvalReport::new(params.clone(), scores, diversity(&occs), set_coverage))
}

/// Mean of JSON values leaf by leaf: numbers averaged (integers stay
/// integers, rounded), the first value's strings kept, nulls skipped.
fn mean_json(values: &[serde_json::Value]) -> serde_json::Value {
    use serde_json::Value;
    match values.first() {
        Some(Value::Object(first)) => Value::Object(
            first
                .keys()
                .map(|k| {
                    let children: Vec<Value> = values.iter().filter_map(|v| v.get(k).cloned()).collect();
                    (k.clone(), mean_json(&children))
                })
                .collect(),
        ),
        Some(Value::Number(_)) | Some(Value::Null) => {
            let nums: Vec<&serde_json::Number> = values.iter().filter_map(|v| v.as_number()).collect();
            if nums.is_empty() {
                return Value::Null;
            }
            let mean = nums.iter().filter_map(|n| n.as_f64()).sum::<f64>() / nums.len() as f64;
            if nums.iter().all(|n| n.is_u64()) {
                Value::from(mean.round() as u64)
            } else {
                serde_json::Number::from_f64(mean).map_or(Value::Null, Value::Number)
            }
        }
        Some(other) => other.clone(),
        None => Value::Null,
    }
}

impl EvalReport {
    pub fn new(
        parameters: EvalParams,
        variants: Vec<VariantScores>,
        diversity: f64,
        set_coverage: Option<SetCoverage>,
    ) -> Self {
        let rows: Vec<serde_json::Value> =
            variants.iter().map(|v| serde_json::to_value(v).expect("scores serialise")).collect();
        let mut mean: VariantScores = match serde_json::from_value(mean_json(&rows)) {
            Ok(m) if !variants.is_empty() => m,
            Ok(_) => VariantScores::zero(),
            Err(e) => {
                log::warn!("eval: the mean row cannot be formed ({e}): a figure is not finite for every variant");
                VariantScores::zero()
            }
        };
        mean.name = "mean".into();
        EvalReport { parameters, variants, mean, diversity, set_coverage }
    }

    /// A plain-text table for the terminal: the headline figures; the JSON
    /// has every figure.
    pub fn table(&self) -> String {
        let width = self.variants.iter().map(|v| v.name.chars().count()).max().unwrap_or(0).max(7);
        let mut s = format!(
            "{:<width$}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>9}\n",
            "", "LP-IoU", "LP-F", "cover", "cover", "detail", "sharp", "colour", "colour", "chamfer0"
        );
        s += &format!(
            "{:<width$}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>9}\n",
            "variant", "", ">0.95", "IoU", "IoU 22", "W1 deg", "ratio", "F", "cover", ""
        );
        let row = |v: &VariantScores| {
            let cd = v.coarse_chamfer.map_or("-".to_string(), |c| format!("{c:.4}"));
            format!(
                "{:<width$}  {:>7.3}  {:>7.3}  {:>7.3}  {:>7.3}  {:>7.2}  {:>7.3}  {:>7.3}  {:>7.3}  {:>9}\n",
                v.name,
                v.lp_iou,
                v.lp_fscore_above_95,
                v.coverage.lp_iou,
                v.coverage_22.lp_iou,
                v.detail.w1_deg,
                v.detail.rms_ratio,
                v.colour.fscore,
                v.colour.coverage,
                cd
            )
        };
        for v in &self.variants {
            s += &row(v);
        }
        s += &"-".repeat(width + 83);
        s += "\n";
        s += &row(&self.mean);
        let n = self.variants.len();
        s += &format!("diversity (mean 1-IoU over {} pairs): {:.4}\n", n * n.saturating_sub(1) / 2, self.diversity);
        if let Some(c) = &self.set_coverage {
            s += &format!(
                "exemplar covered by the set: IoU {:.3} (22^3: {:.3}), F > 0.95 {:.3}\n",
                c.patch_11.lp_iou, c.patch_22.lp_iou, c.patch_11.lp_fscore_above
            );
        }
        s += "LP: the variant's 11^3 patches best-matched in the exemplar; cover: the exemplar's matched in the variant\n";
        s += "(22: on the half-resolution lattice); detail: neighbour-normal angles vs the exemplar's (W1, RMS ratio);\n";
        s += "colour: colour patches matched both ways (F-score, coverage); chamfer0: level-0 points, normalised units\n";
        s
    }
}

impl VariantScores {
    fn zero() -> Self {
        let lp = LpScores { lp_iou: 0.0, lp_iou_above: 0.0, lp_fscore: 0.0, lp_fscore_above: 0.0, patches: 0 };
        VariantScores {
            name: String::new(),
            lp_iou: 0.0,
            lp_iou_above_95: 0.0,
            lp_fscore: 0.0,
            lp_fscore_above_95: 0.0,
            coverage: lp,
            precision_22: lp,
            coverage_22: lp,
            detail: DetailScores { w1_deg: 0.0, rms_ratio: 0.0, mean_deg: 0.0, rms_deg: 0.0, sharp_fraction: 0.0 },
            colour: ColourScores {
                precision: 0.0,
                coverage: 0.0,
                fscore: 0.0,
                distance_to_exemplar: 0.0,
                distance_from_exemplar: 0.0,
                sliced_wasserstein: 0.0,
                spread_ratio: 0.0,
            },
            coarse_chamfer: None,
        }
    }
}

// ---------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::mesh::MeshColours;

    fn mesh(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh { name: "t".into(), positions, triangles, colours: MeshColours::None, texture: None }
    }

    /// UV sphere of radius `r`, outward-oriented, closed.
    fn sphere(centre: Vec3, r: f32, rings: u32, segs: u32) -> Mesh {
        crate::testing::shapes::uv_sphere(centre, rings, segs, |_, _| r)
    }

    use crate::testing::shapes::axis_box as cube;

    fn signed_volume(m: &Mesh) -> f32 {
        crate::testing::shapes::signed_volume(&m.positions, &m.triangles)
    }

    /// Identity frame, lattice [-1, 1]^3 at `res` (dyadic voxel size).
    fn unit_grid(res: u32) -> OccupancyGrid {
        OccupancyGrid { frame: Frame::default(), origin: Vec3::splat(-1.0), voxel: 2.0 / res as f32, dims: [res; 3] }
    }

    #[test]
    fn helper_meshes_are_outward() {
        assert!(signed_volume(&sphere(Vec3::ZERO, 1.0, 16, 32)) > 0.0);
        assert!(signed_volume(&cube(Vec3::ZERO, Vec3::ONE)) > 0.0);
    }

    #[test]
    fn sphere_volume_and_empty_outside() {
        // Sphere of radius 0.8 normalised; grid 256 voxels along its diameter.
        let r = 0.8f32;
        let m = sphere(Vec3::ZERO, r, 128, 256);
        let grid = OccupancyGrid::for_exemplar(&m, Frame::default(), 256);
        assert!((grid.voxel - 2.0 * r / 256.0).abs() < 1e-6);
        let occ = voxelise_mesh(&m, &grid);
        let rv = r / grid.voxel; // radius in voxels (128)
        let exact = 4.0 / 3.0 * std::f64::consts::PI * (rv as f64).powi(3);
        let vol = occ.count() as f64;
        assert!((vol / exact - 1.0).abs() < 0.02, "volume {vol} vs {exact}");
        // Interior by winding number only: much closer.
        let solid = voxelise_mesh_with(&m, &grid, false).count() as f64;
        assert!((solid / exact - 1.0).abs() < 0.005, "solid volume {solid} vs {exact}");
        // Empty outside (beyond the radius + a voxel's half-diagonal), full inside.
        for v in occ.surface().voxels() {
            let c = grid.origin + (Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32) + 0.5) * grid.voxel;
            assert!(c.length() / grid.voxel <= rv + 0.87, "occupied voxel {v:?} outside the sphere");
        }
        let [nx, ny, nz] = grid.dims.map(|d| d as i64);
        for z in (0..nz).step_by(3) {
            for y in (0..ny).step_by(3) {
                for x in 0..nx {
                    let c = grid.origin + (Vec3::new(x as f32, y as f32, z as f32) + 0.5) * grid.voxel;
                    if c.length() / grid.voxel < rv - 1.0 {
                        assert!(occ.get(x, y, z), "inside voxel ({x},{y},{z}) empty");
                    }
                }
            }
        }
    }

    #[test]
    fn cube_on_voxel_centres_is_exact_and_flip_invariant() {
        // Faces exactly on voxel-centre planes: rays hit edges and vertices, the
        // exact test must neither double count nor miss (no streaks).
        let res = 64;
        let grid = unit_grid(res);
        let g = |i: f32| i * grid.voxel - 1.0; // lattice coordinate -> normalised
        let (lo, hi) = (Vec3::new(g(10.5), g(20.5), g(30.5)), Vec3::new(g(40.5), g(33.5), g(50.5)));
        let m = cube(lo, hi);
        let occ = voxelise_mesh_with(&m, &grid, false);
        // Along x a centre exactly on the entry face (10.5) is outside, on the exit
        // face (40.5) inside; columns on the y/z faces are decided by the symbolic
        // perturbation (+y, then +z): the low faces are in, the high faces out.
        let mut expect = Occupancy::empty(grid.dims);
        for z in 30..=49 {
            for y in 20..=32 {
                for x in 11..=40 {
                    expect.set(x, y, z);
                }
            }
        }
        assert_eq!(occ.count(), expect.count());
        assert_eq!(occ, expect);
        // With the surface: exactly the box of voxels the closed cube touches.
        let full = voxelise_mesh(&m, &grid);
        let mut touched = Occupancy::empty(grid.dims);
        for z in 30..=50 {
            for y in 20..=33 {
                for x in 10..=40 {
                    touched.set(x, y, z);
                }
            }
        }
        assert_eq!(full, touched);

        // Inward-flipped: the winding number is -1 inside; |w| > 0.5 gives the same solid.
        let mut flipped = m.clone();
        flipped.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        assert!(signed_volume(&flipped) < 0.0);
        assert_eq!(voxelise_mesh_with(&flipped, &grid, false), occ);
        assert_eq!(voxelise_mesh(&flipped, &grid), full);
    }

    #[test]
    fn open_sheet_keeps_its_surface_voxels() {
        let grid = unit_grid(32);
        let sheet = mesh(
            vec![
                Vec3::new(-0.5, -0.5, 0.01),
                Vec3::new(0.5, -0.5, 0.01),
                Vec3::new(0.5, 0.5, 0.01),
                Vec3::new(-0.5, 0.5, 0.01),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let occ = voxelise_mesh(&sheet, &grid);
        // One voxel thick, 16 x 16 (plus the boundary row of touched voxels).
        assert!(occ.count() >= 16 * 16 && occ.count() <= 17 * 17, "{}", occ.count());
        assert!(voxelise_mesh_with(&sheet, &grid, false).count() == 0);
    }

    #[test]
    fn iou_and_diversity() {
        let grid = unit_grid(48);
        let a = voxelise_mesh(&sphere(Vec3::new(-0.4, 0.0, 0.0), 0.3, 16, 32), &grid);
        let b = voxelise_mesh(&sphere(Vec3::new(0.45, 0.0, 0.0), 0.3, 16, 32), &grid);
        let c = voxelise_mesh(&cube(Vec3::splat(-0.5), Vec3::splat(0.3)), &grid);
        assert!(a.count() > 0 && b.count() > 0);
        assert_eq!(iou(&a, &a), 1.0);
        assert_eq!(iou(&a, &b), 0.0);
        let ac = iou(&a, &c);
        assert!(ac > 0.0 && ac < 1.0);
        assert_eq!(diversity(&[a.clone(), a.clone(), a.clone()]), 0.0);
        let d = diversity(&[a.clone(), b.clone(), c.clone()]);
        let expect = ((1.0 - iou(&a, &b)) + (1.0 - ac) + (1.0 - iou(&b, &c))) / 3.0;
        assert!(d > 0.0 && (d - expect).abs() < 1e-12);
    }

    #[test]
    #[should_panic(expected = "different lattices")]
    fn iou_refuses_different_lattices() {
        iou(&Occupancy::empty([8, 8, 8]), &Occupancy::empty([8, 8, 9]));
    }

    #[test]
    fn morphology_matches_brute_force() {
        let mut occ = Occupancy::empty([70, 9, 7]);
        let mut rng = Rng::new(7);
        for z in 0..7 {
            for y in 0..9 {
                for x in 0..70 {
                    if rng.next_u64() % 3 >= 1 {
                        occ.set(x, y, z);
                    }
                }
            }
        }
        let (surf, edge, dil) = (occ.surface(), occ.boundary26(), occ.boundary26().dilate26());
        let e = occ.boundary26();
        for z in 0..7i64 {
            for y in 0..9i64 {
                for x in 0..70i64 {
                    let on = occ.get(x, y, z);
                    let six = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)];
                    let s = on && six.iter().any(|d| !occ.get(x + d.0, y + d.1, z + d.2));
                    let mut any_empty = false;
                    let mut near_edge = false;
                    for dz in -1..=1 {
                        for dy in -1..=1 {
                            for dx in -1..=1 {
                                any_empty |= !occ.get(x + dx, y + dy, z + dz);
                                near_edge |= e.get(x + dx, y + dy, z + dz);
                            }
                        }
                    }
                    assert_eq!(surf.get(x, y, z), s, "surface {x} {y} {z}");
                    assert_eq!(edge.get(x, y, z), on && any_empty, "edge {x} {y} {z}");
                    assert_eq!(dil.get(x, y, z), near_edge, "dilated {x} {y} {z}");
                }
            }
        }
        // Padding bits stay clear.
        let m = last_word_mask(70);
        for layer in [&surf, &edge, &dil] {
            assert!(layer.bits.chunks(2).all(|r| r[1] & !m == 0));
        }
    }

    #[test]
    fn patch_extraction_matches_get() {
        let mut occ = Occupancy::empty([70, 20, 20]);
        let mut rng = Rng::new(3);
        for v in 0..70 * 20 * 20 {
            if rng.next_u64() & 1 == 0 {
                occ.set(v % 70, (v / 70) % 20, v / 1400);
            }
        }
        let layers = PatchLayers::new(&occ);
        for c in [[0u32, 0, 0], [3, 10, 10], [60, 5, 18], [69, 19, 19], [64, 7, 2]] {
            let p = layers.patch(c);
            for dz in 0..PATCH {
                for dy in 0..PATCH {
                    for dx in 0..PATCH {
                        let bit = dx + PATCH * (dy + PATCH * dz);
                        let got = p.occ[bit / 64] >> (bit % 64) & 1 == 1;
                        let (x, y, z) =
                            (c[0] as i64 + dx as i64 - 5, c[1] as i64 + dy as i64 - 5, c[2] as i64 + dz as i64 - 5);
                        assert_eq!(got, occ.get(x, y, z), "{c:?} {dx} {dy} {dz}");
                    }
                }
            }
            assert_eq!(p.occ_n, p.occ.iter().map(|w| w.count_ones()).sum::<u32>());
            // Slab histograms against a direct count.
            let sig = Sig::of(&p);
            for axis in 0..3 {
                for slab in 0..PATCH {
                    let mut n = 0;
                    for dz in 0..PATCH {
                        for dy in 0..PATCH {
                            for dx in 0..PATCH {
                                let d = [dx, dy, dz];
                                let bit = dx + PATCH * (dy + PATCH * dz);
                                if d[axis] == slab && p.edge[bit / 64] >> (bit % 64) & 1 == 1 {
                                    n += 1;
                                }
                            }
                        }
                    }
                    assert_eq!(sig.edge[axis][slab], n, "{c:?} axis {axis} slab {slab}");
                }
            }
        }
    }

    /// A smooth exemplar: a torus-like union of two spheres and a box.
    fn smooth_shape(grid: &OccupancyGrid, shift: Vec3) -> Occupancy {
        let mut m = sphere(Vec3::new(-0.3, 0.05, 0.0) + shift, 0.45, 48, 96);
        let b = cube(Vec3::new(0.0, -0.3, -0.25) + shift, Vec3::new(0.7, 0.25, 0.3) + shift);
        let off = m.positions.len() as u32;
        m.positions.extend(b.positions);
        m.triangles.extend(b.triangles.iter().map(|t| t.map(|i| i + off)));
        voxelise_mesh(&m, grid)
    }

    #[test]
    fn lp_self_is_one_noise_is_low_translation_invariant() {
        let grid = unit_grid(96);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        let params = LpParams::default();
        let dict = ExemplarPatches::new(&ex, 1);
        let own = local_patch_scores(&ex, &dict, &params);
        assert!(own.patches > 100, "{own:?}");
        assert_eq!(own.lp_iou, 1.0);
        assert_eq!(own.lp_iou_above, 1.0);
        assert_eq!(own.lp_fscore, 1.0);
        assert_eq!(own.lp_fscore_above, 1.0);

        // Whole-voxel translation (3, -2, 1) voxels: local patches are unchanged.
        let t = Vec3::new(3.0, -2.0, 1.0) * grid.voxel;
        let moved = smooth_shape(&grid, t);
        assert!(iou(&moved, &ex) < 0.95);
        let s = local_patch_scores(&moved, &dict, &params);
        assert!(s.lp_iou > 0.995 && s.lp_iou_above > 0.99, "{s:?}");
        assert!(s.lp_fscore > 0.995 && s.lp_fscore_above > 0.99, "{s:?}");

        // Random voxels in the same box: no plausible patches.
        let mut noise = Occupancy::empty(grid.dims);
        let mut rng = Rng::new(99);
        for z in 20..76 {
            for y in 20..76 {
                for x in 15..85 {
                    if rng.next_u64() % 10 < 3 {
                        noise.set(x, y, z);
                    }
                }
            }
        }
        let n = local_patch_scores(&noise, &dict, &params);
        assert_eq!(n.patches, 1000);
        assert!(n.lp_iou < 0.6, "{n:?}");
        assert!(n.lp_iou_above == 0.0 && n.lp_fscore_above == 0.0, "{n:?}");

        // Deterministic sampling.
        assert_eq!(local_patch_scores(&noise, &dict, &params), n);
    }

    #[test]
    fn lp_scores_degrade_with_damage() {
        let grid = unit_grid(96);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        // Carve a pattern of small holes: new local geometry the exemplar lacks.
        let mut damaged = ex.clone();
        for v in ex.voxels() {
            if v[0] % 9 < 2 && v[1] % 9 < 2 {
                let w = damaged.words_per_row();
                let r = v[1] as usize + grid.dims[1] as usize * v[2] as usize;
                damaged.bits[r * w + v[0] as usize / 64] &= !(1u64 << (v[0] % 64));
            }
        }
        let s = lp_scores(&damaged, &ex, &LpParams::default());
        assert!(s.lp_iou < 0.99 && s.lp_iou_above < 0.9, "{s:?}");
        assert!(s.lp_fscore < 0.99, "{s:?}");
    }

    #[test]
    fn chamfer_and_hausdorff() {
        let pts: Vec<Vec3> =
            (0..2000).map(|i| Vec3::new((i % 20) as f32, ((i / 20) % 10) as f32, (i / 200) as f32)).collect();
        assert_eq!(chamfer(&pts, &pts), 0.0);
        assert_eq!(hausdorff(&pts, &pts), 0.0);
        let t = Vec3::new(0.1, -0.2, 0.05);
        let moved: Vec<Vec3> = pts.iter().map(|&p| p + t).collect();
        assert!((chamfer(&pts, &moved) - t.length()).abs() < 1e-5);
        assert!((hausdorff(&pts, &moved) - t.length()).abs() < 1e-5);
        // Asymmetric: one extra far point.
        let mut extra = pts.clone();
        extra.push(Vec3::new(100.0, 0.0, 0.0));
        assert!((hausdorff(&pts, &extra) - 81.0).abs() < 1e-4);
        let expect = 0.5 * (81.0 / 2001.0);
        assert!((chamfer(&pts, &extra) as f64 - expect).abs() < 1e-5);
        // Brute force agreement on random points.
        let mut rng = Rng::new(5);
        let mut rnd = |n: usize| -> Vec<Vec3> {
            (0..n)
                .map(|_| {
                    Vec3::new(
                        rng.next_u64() as f32 / u64::MAX as f32,
                        rng.next_u64() as f32 / u64::MAX as f32,
                        rng.next_u64() as f32 / u64::MAX as f32,
                    )
                })
                .collect()
        };
        let (a, b) = (rnd(500), rnd(700));
        let one = |x: &[Vec3], y: &[Vec3]| -> Vec<f32> {
            x.iter().map(|p| y.iter().map(|q| p.distance(*q)).fold(f32::INFINITY, f32::min)).collect()
        };
        let (da, db) = (one(&a, &b), one(&b, &a));
        let cd = 0.5 * (da.iter().sum::<f32>() / 500.0 + db.iter().sum::<f32>() / 700.0);
        assert!((chamfer(&a, &b) - cd).abs() < 1e-5);
        let hd = da.iter().chain(&db).fold(0.0f32, |m, &d| m.max(d));
        assert_eq!(hausdorff(&a, &b), hd);
        assert_eq!(chamfer(&[], &[]), 0.0);
        assert!(chamfer(&a, &[]).is_infinite());
    }

    #[test]
    fn points_voxelise_to_their_voxels() {
        let grid = unit_grid(16);
        let occ =
            voxelise_points(&[Vec3::new(-0.99, -0.99, -0.99), Vec3::new(0.01, 0.01, 0.01), Vec3::splat(5.0)], &grid);
        assert_eq!(occ.voxels(), vec![[0, 0, 0], [8, 8, 8]]);
    }

    fn scores(name: &str, lp_iou: f64, chamfer: Option<f64>) -> VariantScores {
        VariantScores { name: name.into(), lp_iou, coarse_chamfer: chamfer, ..VariantScores::zero() }
    }

    #[test]
    fn report_table_and_means() {
        let mut a = scores("a", 0.9, Some(0.01));
        a.coverage.patches = 1000;
        let mut b = scores("variant_b", 0.5, None);
        b.coverage.patches = 999;
        let r = EvalReport::new(EvalParams::default(), vec![a, b], 0.3, None);
        assert!((r.mean.lp_iou - 0.7).abs() < 1e-12 && r.mean.coarse_chamfer == Some(0.01));
        assert_eq!(r.mean.coverage.patches, 1000, "integer figures stay integers (rounded)");
        let t = r.table();
        assert!(t.contains("variant_b") && t.contains("0.900") && t.contains("mean") && t.contains("0.3000"), "{t}");
        assert!(t.contains("over 1 pairs"));
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["parameters"]["lp"]["variant_stride"], 5, "parameters are recorded: {json}");
    }

    /// A level whose active voxels are the surface voxels of `occ` (normals +z,
    /// one colour), on a lattice that matches the level's grid.
    fn level_of(occ: &Occupancy) -> Level {
        let s = occ.surface().voxels();
        Level {
            resolution: 64,
            coords: s.iter().map(|v| glam::IVec3::new(v[0] as i32, v[1] as i32, v[2] as i32)).collect(),
            offsets: vec![Vec3::ZERO; s.len()],
            normals: vec![Vec3::Z; s.len()],
            colours: vec![Vec3::splat(0.5); s.len()],
            mask: vec![1.0; s.len()],
            ..Default::default()
        }
    }

    fn halve(occ: &Occupancy) -> Occupancy {
        let mut h = Occupancy::empty(occ.dims.map(|d| d.div_ceil(2)));
        for v in occ.voxels() {
            h.set(v[0] as i64 / 2, v[1] as i64 / 2, v[2] as i64 / 2);
        }
        h
    }

    #[test]
    fn evaluate_end_to_end_with_coverage() {
        let grid = unit_grid(64);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        let v1 = smooth_shape(&grid, Vec3::new(2.0, 0.0, 0.0) * grid.voxel);
        // Half the exemplar: its patches are all in the exemplar (precision
        // high), but half of the exemplar is missing (coverage lower).
        let mut part = Occupancy::empty(ex.dims);
        for v in ex.voxels().into_iter().filter(|v| v[0] < 32) {
            part.set(v[0] as i64, v[1] as i64, v[2] as i64);
        }
        let pts = vec![Vec3::ZERO, Vec3::X];
        let shifted = vec![Vec3::new(0.0, 0.1, 0.0), Vec3::new(1.0, 0.1, 0.0)];
        let (exh, v1h, parth) = (halve(&ex), halve(&v1), halve(&part));
        let (lex, lv1, lpart) = (level_of(&ex), level_of(&v1), level_of(&part));
        let shape = |name: &str, o, h, l, c| ShapeInput { name: name.into(), occupancy: o, occupancy_22: h, finest: l, coarse_points: c };
        let r = evaluate(
            &shape("exemplar", &ex, &exh, &lex, Some(&pts)),
            &[
                shape("same", &ex, &exh, &lex, Some(&pts)),
                shape("moved", &v1, &v1h, &lv1, Some(&shifted)),
                shape("part", &part, &parth, &lpart, None),
            ],
            &EvalParams::default(),
        )
        .unwrap();
        let [same, moved, part] = [&r.variants[0], &r.variants[1], &r.variants[2]];
        assert_eq!((same.lp_iou, same.coverage.lp_iou, same.coverage_22.lp_iou), (1.0, 1.0, 1.0));
        assert_eq!(same.detail.w1_deg, 0.0);
        assert_eq!(same.coarse_chamfer, Some(0.0));
        assert!((moved.coarse_chamfer.unwrap() - 0.1).abs() < 1e-6);
        assert!(part.lp_iou > 0.9, "a part of the exemplar is plausible: {part:?}");
        assert!(part.coverage.lp_iou < part.lp_iou - 0.03, "but covers less: {part:?}");
        assert!(part.coverage_22.lp_iou < part.precision_22.lp_iou - 0.03, "{part:?}");
        assert!(r.diversity > 0.0);
        let set = r.set_coverage.expect("three variants");
        assert_eq!(set.patch_11.lp_iou, 1.0, "the set holds the exemplar itself");
    }

    #[test]
    fn degenerate_voxelisations_are_errors() {
        let grid = unit_grid(16);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        let mut full = Occupancy::empty(ex.dims);
        full.bits.iter_mut().for_each(|w| *w = u64::MAX);
        let full = Occupancy { bits: full.bits.iter().map(|&w| w & last_word_mask(16)).collect(), ..full };
        let empty = Occupancy::empty(ex.dims);
        let l = level_of(&ex);
        let shape = |o| ShapeInput { name: "v".into(), occupancy: o, occupancy_22: o, finest: &l, coarse_points: None };
        assert!(matches!(check_shape(&shape(&empty)), Err(DegenerateShape::NoSurface(_))));
        let e = check_shape(&shape(&full)).unwrap_err();
        assert!(matches!(e, DegenerateShape::Filled(..)) && e.to_string().contains("fills 100%"), "{e}");
        assert!(check_shape(&shape(&ex)).is_ok());
        let empty_level = Level { resolution: 16, ..Default::default() };
        let s = ShapeInput { name: "v".into(), occupancy: &ex, occupancy_22: &ex, finest: &empty_level, coarse_points: None };
        assert!(matches!(check_shape(&s), Err(DegenerateShape::EmptyLevel(_))));
    }

    #[test]
    fn surface_voxelisation_keeps_sheets_and_hollows_solids() {
        let grid = unit_grid(32);
        let b = cube(Vec3::splat(-0.5), Vec3::splat(0.5));
        let solid = voxelise_mesh(&b, &grid);
        let shell = voxelise_mesh_surface(&b, &grid);
        // 16^3 cube (plus the touched boundary layer) vs its one-voxel shell.
        assert!(solid.count() >= 16 * 16 * 16, "{}", solid.count());
        assert!(shell.count() < solid.count() / 2 && shell.count() >= 6 * 15 * 15, "{}", shell.count());
        assert!(!shell.get(16, 16, 16), "nothing inside");
        // An open sheet: the same voxels whichever way (nothing to fill).
        let sheet = mesh(
            vec![Vec3::new(-0.5, -0.5, 0.01), Vec3::new(0.5, -0.5, 0.01), Vec3::new(0.5, 0.5, 0.01), Vec3::new(-0.5, 0.5, 0.01)],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        assert_eq!(voxelise_mesh_surface(&sheet, &grid), voxelise_mesh(&sheet, &grid));
    }

    #[test]
    fn covering_lattice_aligns_with_a_level_grid() {
        let g = OccupancyGrid::covering(Frame::default(), Vec3::splat(-0.3), Vec3::new(0.5, 0.2, 0.1), 2.0 / 64.0, 0.1, Some(Vec3::splat(-1.0)));
        for a in 0..3 {
            let k = (g.origin[a] + 1.0) / g.voxel;
            assert!((k - k.round()).abs() < 1e-4, "origin on a grid line: {g:?}");
            assert_eq!(k.round() as i64 % ALIGN_VOXELS as i64, 0, "origin on a multiple of 10 voxels: {g:?}");
            assert!(g.origin[a] <= -0.4 + 1e-6);
        }
        assert!(g.origin.x + g.dims[0] as f32 * g.voxel >= 0.6 - 1e-6);
        let h = g.halved();
        assert_eq!((h.voxel, h.origin), (g.voxel * 2.0, g.origin));
    }

    /// The pruned matcher returns exactly the exhaustive maxima.
    #[test]
    fn pruned_matching_equals_brute_force() {
        let mut ex = Occupancy::empty([64, 64, 64]);
        for z in 0..64i64 {
            for y in 0..64i64 {
                for x in 0..64i64 {
                    let d = ((x - 32).pow(2) + (y - 30).pow(2) * 2 + (z - 32).pow(2)) as f64;
                    if d.sqrt() < 20.0 || (x > 30 && y < 20 && z < 40) {
                        ex.set(x, y, z);
                    }
                }
            }
        }
        // Variants: random voxels, and the exemplar with voxels removed.
        let mut rng = Rng::new(1);
        let mut noise = Occupancy::empty([64, 64, 64]);
        let mut damaged = ex.clone();
        for z in 10..54 {
            for y in 10..54 {
                for x in 10..54 {
                    if rng.next_u64() % 10 < 3 {
                        noise.set(x, y, z);
                    }
                    if rng.next_u64() % 10 < 1 && ex.get(x, y, z) {
                        let w = damaged.words_per_row();
                        let r = (y + 64 * z) as usize;
                        damaged.bits[r * w + x as usize / 64] &= !(1u64 << (x % 64));
                    }
                }
            }
        }
        let dict = ExemplarPatches::new(&ex, 1);
        for shape in [&noise, &damaged, &ex] {
            let layers = PatchLayers::new(shape);
            let pats: Vec<Patch> = layers.centres(5).iter().take(120).map(|&c| layers.patch(c)).collect();
            let fast = match_patches(&pats, &dict);
            for (k, pa) in pats.iter().enumerate() {
                let mut brute = Best::default();
                for pb in &dict.patches {
                    compare(pa, pb, &mut brute);
                }
                assert_eq!(fast[k].f_num * brute.f_den, brute.f_num * fast[k].f_den, "F of patch {k}");
                assert_eq!(
                    fast[k].iou_num as u64 * brute.iou_den as u64,
                    brute.iou_num as u64 * fast[k].iou_den as u64,
                    "IoU of patch {k}"
                );
            }
        }
    }
}
