//! Whether an exemplar is a figure: a shape with no flat faces and no walls
//! standing along an axis (an animal, a statue, a knot, a scanned rock), the
//! kind a smooth random bend (`level::warp`) poses anew without leaving its
//! style. A bent wall leans and a bent plate warps: architecture, CAD parts
//! and man-made objects are made of planes and upright walls, and bending
//! them is not a variant a person keeps (docs/lab/bent-figures.md, "Bent starts").
//!
//! Read from the surface normals of one level (the structure level, 64^3),
//! each smoothed over its 3x3x3 neighbourhood of surface voxels so a stone's
//! or a scale's facets do not count as directions of their own:
//! - the normal spread: how many of [`DIRECTION_CELLS`] equal cells of
//!   directions it takes to hold 80% of the normals, over what a sphere
//!   takes (0.8 of them). Planes put their normals in a few cells (a cube
//!   0.04, the CAD part 0.33) and a cylinder's in a band (the ruined tower
//!   0.36); a figure's face every way (the bunny 0.77);
//! - the upright share: along the grid axis where it is largest, the share
//!   of normals within 15 degrees of square to that axis, which is where
//!   walls standing along it face (a sphere: 0.26 along every axis; the
//!   ruined tower 0.77 along its height, the demo tower 0.55, a cube 0.61).
//!
//! Measured on 42 meshes at 64^3 (docs/lab/bent-figures.md, "Bent starts for
//! figures"): every man-made one reads as no figure; the animals and
//! statues that face every way read as figures, and upright or elongated
//! organic ones (a cactus, a femur, a standing man) do not, so they are
//! sampled as before.

use glam::{DVec3, IVec3};

use super::thresholds::THRESHOLDS;
use crate::grid::VoxelMap;
use crate::level::Level;

/// Equal cells of directions on the sphere (Fibonacci lattice), about 14
/// degrees across.
pub const DIRECTION_CELLS: usize = 200;




/// sin(15 degrees): a normal this close to square to an axis faces as a wall
/// standing along that axis does.
const UPRIGHT_SINE: f64 = 0.258_819;

/// Share of the normals the spread's cells hold.
const SPREAD_MASS: f64 = 0.8;

/// How an exemplar's surface faces (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FigureReading {
    /// Directions the normals take, over a sphere's (1: as spread).
    pub normal_spread: f64,
    /// The largest share, over the three axes, of normals square to it.
    pub upright_share: f64,
}

impl FigureReading {
    /// The reading of an exemplar: of its structure level (the finest of at
    /// most 64^3), where that is `THRESHOLDS.min_reading_resolution`^3 or finer; None
    /// where it has no such level or no surface there.
    pub fn of_exemplar(levels: &[Level]) -> Option<FigureReading> {
        super::levels::structure_level(levels).filter(|l| l.resolution >= THRESHOLDS.min_reading_resolution).and_then(FigureReading::of)
    }

    /// The reading of `level`'s surface voxels (mask > 0); None where it has
    /// none.
    pub fn of(level: &Level) -> Option<FigureReading> {
        let surface: Vec<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).collect();
        let mut at: VoxelMap<usize> = VoxelMap::default();
        for &i in &surface {
            at.insert(level.coords[i], i);
        }
        let smoothed: Vec<DVec3> = surface
            .iter()
            .map(|&i| {
                let c = level.coords[i];
                let mut sum = DVec3::ZERO;
                for d in neighbourhood() {
                    if let Some(&j) = at.get(c + d) {
                        sum += level.normals[j].as_dvec3().normalize_or_zero();
                    }
                }
                sum.normalize_or_zero()
            })
            .filter(|n| *n != DVec3::ZERO)
            .collect();
        if smoothed.is_empty() {
            return None;
        }
        let cells = direction_cells();
        let mut counts = vec![0usize; DIRECTION_CELLS];
        for n in &smoothed {
            counts[nearest_cell(&cells, *n)] += 1;
        }
        counts.sort_unstable_by(|a, b| b.cmp(a));
        let need = SPREAD_MASS * smoothed.len() as f64;
        let mut held = 0usize;
        let taken = counts.iter().take_while(|&&c| {
            let more = (held as f64) < need;
            held += c;
            more
        });
        let normal_spread = taken.count() as f64 / (SPREAD_MASS * DIRECTION_CELLS as f64);
        let upright_share = (0..3)
            .map(|axis| smoothed.iter().filter(|n| n[axis].abs() < UPRIGHT_SINE).count() as f64 / smoothed.len() as f64)
            .fold(0.0, f64::max);
        Some(FigureReading { normal_spread, upright_share })
    }

    /// Faces every way: no flat faces, no walls along an axis.
    pub fn is_figure(&self) -> bool {
        self.normal_spread >= THRESHOLDS.min_normal_spread && self.upright_share <= THRESHOLDS.max_upright_share
    }
}

/// The 27 offsets of a voxel's 3x3x3 neighbourhood, itself included.
fn neighbourhood() -> impl Iterator<Item = IVec3> {
    (0..27).map(|k| IVec3::new(k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1))
}

/// [`DIRECTION_CELLS`] unit directions spread evenly over the sphere (a
/// Fibonacci lattice), the centres of the cells.
fn direction_cells() -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..DIRECTION_CELLS)
        .map(|k| {
            let y = 1.0 - 2.0 * (k as f64 + 0.5) / DIRECTION_CELLS as f64;
            let r = (1.0 - y * y).sqrt();
            let phi = k as f64 * golden;
            DVec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect()
}

fn nearest_cell(cells: &[DVec3], n: DVec3) -> usize {
    (0..cells.len()).max_by(|&a, &b| cells[a].dot(n).total_cmp(&cells[b].dot(n))).expect("cells")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::synthetic::sphere_levels;
    use glam::Vec3;

    /// A level of the surface voxels of a shape given by its signed distance
    /// (voxel units, negative inside) on a `res`^3 grid: the voxels the zero
    /// set passes through, with the distance's gradient as normal.
    fn level_of(res: u32, sdf: impl Fn(DVec3) -> f64) -> Level {
        let mut coords = vec![];
        let mut normals = vec![];
        for k in 0..res.pow(3) as i32 {
            let r = res as i32;
            let c = IVec3::new(k % r, (k / r) % r, k / (r * r));
            let p = c.as_dvec3() + DVec3::splat(0.5);
            if sdf(p).abs() < 0.5 {
                let e = 1e-3;
                let g = DVec3::new(
                    sdf(p + DVec3::X * e) - sdf(p - DVec3::X * e),
                    sdf(p + DVec3::Y * e) - sdf(p - DVec3::Y * e),
                    sdf(p + DVec3::Z * e) - sdf(p - DVec3::Z * e),
                );
                coords.push(c);
                normals.push(g.normalize().as_vec3());
            }
        }
        let n = coords.len();
        Level {
            resolution: res,
            coords,
            normals,
            offsets: vec![Vec3::ZERO; n],
            colours: vec![Vec3::splat(0.5); n],
            mask: vec![1.0; n],
            ..Default::default()
        }
    }

    #[test]
    fn a_ball_and_a_lumpy_ball_are_figures() {
        let ball = level_of(48, |p| (p - DVec3::splat(24.0)).length() - 18.0);
        let r = FigureReading::of(&ball).unwrap();
        assert!(r.is_figure(), "{r:?}");
        assert!(r.normal_spread > 0.9 && r.upright_share < 0.32, "{r:?}");
        let lumpy = level_of(48, |p| {
            let q = p - DVec3::splat(24.0);
            q.length() - 16.0 - 1.0 * (q.x * 0.3).sin() * (q.y * 0.25).cos()
        });
        assert!(FigureReading::of(&lumpy).unwrap().is_figure(), "{:?}", FigureReading::of(&lumpy));
    }

    #[test]
    fn a_tower_a_box_and_a_tilted_box_are_not() {
        // An upright tube with a wall 4 voxels thick: walls along y.
        let tower = level_of(48, |p| {
            let r = ((p.x - 24.0).powi(2) + (p.z - 24.0).powi(2)).sqrt();
            let wall = (r - 14.0).abs() - 2.0;
            wall.max((p.y - 24.0).abs() - 20.0)
        });
        let r = FigureReading::of(&tower).unwrap();
        assert!(!r.is_figure() && r.upright_share > 0.6, "{r:?}");
        let cube = |rot: glam::DQuat| {
            level_of(48, move |p| {
                let q = (rot * (p - DVec3::splat(24.0))).abs() - DVec3::splat(12.25);
                q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
            })
        };
        let r = FigureReading::of(&cube(glam::DQuat::IDENTITY)).unwrap();
        assert!(!r.is_figure() && r.normal_spread < 0.2, "{r:?}");
        // Tilted off every axis: no wall along a grid axis, but six faces.
        let tilted = cube(glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.5, 0.7, 0.3));
        let r = FigureReading::of(&tilted).unwrap();
        assert!(!r.is_figure() && r.normal_spread < 0.3, "{r:?}");
    }

    #[test]
    fn an_empty_level_has_no_reading() {
        let mut level = sphere_levels(&[16], DVec3::ZERO, 0.5).remove(0);
        level.retain(|_| false);
        assert_eq!(FigureReading::of(&level), None);
    }
}
