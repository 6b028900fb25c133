//! Shapes and lattices the unit tests of the metrics share.

use glam::Vec3;

use super::{voxelise_mesh, Occupancy, OccupancyGrid};
use crate::io::mesh::Mesh;
use crate::level::Frame;

pub use crate::testing::shapes::axis_box as cube;

/// UV sphere of radius `r`, outward-oriented, closed.
pub fn sphere(centre: Vec3, r: f32, rings: u32, segs: u32) -> Mesh {
    crate::testing::shapes::uv_sphere(centre, rings, segs, |_, _| r)
}

/// Identity frame, lattice [-1, 1]^3 at `res` (dyadic voxel size).
pub fn unit_grid(res: u32) -> OccupancyGrid {
    OccupancyGrid { frame: Frame::default(), origin: Vec3::splat(-1.0), voxel: 2.0 / res as f32, dims: [res; 3] }
}

/// A smooth exemplar: a torus-like union of two spheres and a box.
pub fn smooth_shape(grid: &OccupancyGrid, shift: Vec3) -> Occupancy {
    let mut m = sphere(Vec3::new(-0.3, 0.05, 0.0) + shift, 0.45, 48, 96);
    let b = cube(Vec3::new(0.0, -0.3, -0.25) + shift, Vec3::new(0.7, 0.25, 0.3) + shift);
    let off = m.positions.len() as u32;
    m.positions.extend(b.positions);
    m.triangles.extend(b.triangles.iter().map(|t| t.map(|i| i + off)));
    voxelise_mesh(&m, grid)
}
