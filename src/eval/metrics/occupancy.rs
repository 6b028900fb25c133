//! The evaluation lattice ([`OccupancyGrid`]), on which every shape is
//! voxelised as an [`Occupancy`] (`crate::grid::occupancy`), and the two
//! measures of whole occupancies:
//! [`iou`] and [`diversity`] (docs/method.md section 7).

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::io::mesh::Mesh;
use crate::level::Frame;

pub use crate::grid::occupancy::Occupancy;
pub(crate) use crate::grid::occupancy::{same_lattice, set_range};

/// Default evaluation resolution: voxels along the longest side of the
/// exemplar's bounding box (docs/method.md section 7).
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
}

// ---------------------------------------------------------------------------
// IoU and diversity
// ---------------------------------------------------------------------------

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

/// Diversity (docs/method.md section 7): mean over all unordered pairs of `1 - IoU`.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::occupancy::last_word_mask;
    use crate::eval::metrics::test_shapes::{cube, sphere, unit_grid};
    use crate::eval::metrics::voxelise_mesh;
    use crate::util::rng::Rng;

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
}
