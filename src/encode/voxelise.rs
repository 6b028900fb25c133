//! Step 2: voxelisation: the (voxel, triangle) pairs of the sampling grid.

use super::*;

/// (voxel, triangle) pairs. Packed into one u64 (Morton key above the triangle
/// index) whenever both fit, which is the fast path (R_s = 1024 leaves 34 bits for
/// triangles); wide pairs otherwise.
pub(super) enum Pairs {
    Packed { data: Vec<u64>, tri_bits: u32 },
    Wide(Vec<(u64, u32)>),
}

impl Pairs {
    pub(super) fn len(&self) -> usize {
        match self {
            Pairs::Packed { data, .. } => data.len(),
            Pairs::Wide(data) => data.len(),
        }
    }
    pub(super) fn key(&self, i: usize) -> u64 {
        match self {
            Pairs::Packed { data, tri_bits } => data[i] >> tri_bits,
            Pairs::Wide(data) => data[i].0,
        }
    }
    pub(super) fn triangle(&self, i: usize) -> usize {
        match self {
            Pairs::Packed { data, tri_bits } => (data[i] & ((1u64 << tri_bits) - 1)) as usize,
            Pairs::Wide(data) => data[i].1 as usize,
        }
    }
    /// Sorts by voxel key, then triangle (which makes closest-point ties
    /// deterministic). (An LSD radix sort measured no cheaper than this.)
    pub(super) fn sort(&mut self) {
        match self {
            Pairs::Packed { data, .. } => data.par_sort_unstable(),
            Pairs::Wide(data) => data.par_sort_unstable(),
        }
    }
}

/// All (voxel, triangle) intersections at resolution `r`, unsorted.
pub(super) fn voxelise(prep: &Prepared, r: u32) -> Pairs {
    let tri_bits = (usize::BITS - (prep.corners.len().max(2) - 1).leading_zeros()).max(1);
    let packed = 3 * r.trailing_zeros() + tri_bits <= 64;
    voxelise_as(prep, r, packed)
}

/// [`voxelise`] into packed pairs (`packed`, which the caller checked fits) or wide.
pub(super) fn voxelise_as(prep: &Prepared, r: u32, packed: bool) -> Pairs {
    let n = prep.corners.len();
    let tri_bits = (usize::BITS - (n.max(2) - 1).leading_zeros()).max(1);
    let chunk = (n / (rayon::current_num_threads() * 16)).max(64);
    let chunks = n.div_ceil(chunk);
    let range = |c: usize| c * chunk..((c + 1) * chunk).min(n);
    if packed {
        let parts: Vec<Vec<u64>> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let mut out = Vec::new();
                voxelise_range(prep, range(c), r, |key, t| out.push(key << tri_bits | t as u64));
                out
            })
            .collect();
        Pairs::Packed { data: concat(parts), tri_bits }
    } else {
        let parts: Vec<Vec<(u64, u32)>> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let mut out = Vec::new();
                voxelise_range(prep, range(c), r, |key, t| out.push((key, t as u32)));
                out
            })
            .collect();
        Pairs::Wide(concat(parts))
    }
}

/// Calls `emit(morton key, triangle)` for the triangles `range`, degenerate ones skipped.
pub(super) fn voxelise_range(prep: &Prepared, range: std::ops::Range<usize>, r: u32, mut emit: impl FnMut(u64, usize)) {
    let to_grid = r as f64 * 0.5;
    for t in range {
        let normal = prep.face_normals[t];
        if normal == DVec3::ZERO {
            continue;
        }
        let g = prep.corners[t].map(|p| (p + DVec3::ONE) * to_grid);
        voxelise_triangle(&g, normal, r, |i, j, k| emit(morton(i, j, k), t));
    }
}

pub(super) fn concat<T: Copy>(parts: Vec<Vec<T>>) -> Vec<T> {
    let mut all = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for part in parts {
        all.extend_from_slice(&part);
    }
    all
}

/// One separating axis of the triangle/box test: the triangle's projection onto
/// `axis` spans `[lo, hi]`; a unit box centred at c is separated from it along
/// `axis` iff the interval misses `axis.c +- rad`.
#[derive(Clone, Copy)]
pub(super) struct Axis {
    pub(super) axis: DVec3,
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) rad: f64,
}

impl Axis {
    pub(super) fn new(axis: DVec3, g: &[DVec3; 3]) -> Self {
        let p = g.map(|q| axis.dot(q));
        Axis {
            axis,
            lo: p[0].min(p[1]).min(p[2]),
            hi: p[0].max(p[1]).max(p[2]),
            rad: 0.5 * axis.abs().element_sum(),
        }
    }
    pub(super) fn overlaps(&self, c: DVec3) -> bool {
        let pc = self.axis.dot(c);
        self.lo <= pc + self.rad && self.hi >= pc - self.rad
    }
}

/// Calls `emit(i, j, k)` for every voxel of the `r`^3 grid that triangle `g` (grid
/// units, voxel (i,j,k) = [i,i+1) x [j,j+1) x [k,k+1)) intersects, closed boxes;
/// `n` is the unit face normal. Exact: the separating-axis theorem (Akenine-Moeller)
/// with its 13 axes, organised so that most of them are settled once per column.
///
/// Walks columns along the dominant axis `w` of `n`. A column is kept if it overlaps
/// the triangle's bounding box (axes u, v) and the triangle's projection (the three
/// axes e_w x edge). Over one column the triangle's plane spans at most
/// `(|n_u| + |n_v|) / |n_w| <= 2` voxels; clipped to the triangle's w extent, those
/// are the candidates, and they pass the plane and w-box axes by construction. The
/// six axes e_u x edge and e_v x edge are tested per candidate. The work is thus
/// O(intersected voxels), not O(bounding-box volume) (quadratic in size for a
/// slanted triangle).
pub(super) fn voxelise_triangle(g: &[DVec3; 3], n: DVec3, r: u32, mut emit: impl FnMut(u32, u32, u32)) {
    let lo = g[0].min(g[1]).min(g[2]);
    let hi = g[0].max(g[1]).max(g[2]);
    let last = (r - 1) as f64;
    let cell = |x: f64| x.floor().clamp(0.0, last) as u32;
    let a = n.abs();
    let w = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    let (u, v) = ((w + 1) % 3, (w + 2) % 3);
    let unit = |k: usize| DVec3::AXES[k];
    let edges = [g[1] - g[0], g[2] - g[1], g[0] - g[2]];
    let column_axes = edges.map(|f| Axis::new(unit(w).cross(f), g));
    let voxel_axes: [Axis; 6] =
        std::array::from_fn(|i| Axis::new(unit(if i < 3 { u } else { v }).cross(edges[i % 3]), g));
    let d = n.dot(g[0]);
    let half_span = 0.5 * (a[u] + a[v]) / a[w];
    let mut c = DVec3::ZERO;
    for iu in cell(lo[u])..=cell(hi[u]) {
        c[u] = iu as f64 + 0.5;
        for iv in cell(lo[v])..=cell(hi[v]) {
            c[v] = iv as f64 + 0.5;
            c[w] = 0.0; // column axes have no w component
            if !column_axes.iter().all(|ax| ax.overlaps(c)) {
                continue;
            }
            let wc = (d - n[u] * c[u] - n[v] * c[v]) / n[w];
            let (wlo, whi) = ((wc - half_span).max(lo[w]), (wc + half_span).min(hi[w]));
            if wlo > whi {
                continue;
            }
            for iw in cell(wlo)..=cell(whi) {
                c[w] = iw as f64 + 0.5;
                if voxel_axes.iter().all(|ax| ax.overlaps(c)) {
                    let mut ijk = [0u32; 3];
                    ijk[u] = iu;
                    ijk[v] = iv;
                    ijk[w] = iw;
                    emit(ijk[0], ijk[1], ijk[2]);
                }
            }
        }
    }
}

/// Indices where `key(i)` changes, plus `n` at the end: group g is
/// `starts[g]..starts[g+1]`.
pub(super) fn group_starts(n: usize, key: impl Fn(usize) -> u64) -> Vec<usize> {
    let mut starts = Vec::new();
    let mut prev = None;
    for i in 0..n {
        let k = key(i);
        if prev != Some(k) {
            starts.push(i);
            prev = Some(k);
        }
    }
    starts.push(n);
    starts
}
