//! Oriented, coloured point sets.

use glam::Vec3;


/// Oriented, coloured points: what a level looks like as a surface, what
/// the meshers mesh and the previews splat. Struct of arrays, all of the same
/// length (`colours` may be empty: no colours).
#[derive(Clone, Debug, Default)]
pub struct OrientedPoints {
    /// World units (the exemplar's own frame).
    pub positions: Vec<Vec3>,
    /// Outward normals, one per position (not always unit length: a level
    /// stores what the network gave).
    pub normals: Vec<Vec3>,
    /// RGB in [0, 1], one per position, or empty.
    pub colours: Vec<Vec3>,
    /// Typical distance between neighbouring points, world units (a level's
    /// voxel size); <= 0: unknown (the meshers estimate it).
    pub spacing: f32,
}

impl OrientedPoints {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}
