//! The one transform of a level's grid: voxel indices (integers, 0 ..
//! resolution per axis) <-> the normalised cube [-1, 1]^3 (voxel edge
//! 2 / resolution) <-> the exemplar's own frame (world units: metres for a
//! scan, whatever a mesh was modelled in). Every conversion between them is
//! written here once.

use glam::{DVec3, IVec3, Vec3};

/// Where the normalised cube [-1, 1]^3 sits in the exemplar's own frame.
/// `world = centre + normalised / scale`; scale = 2 / (bbox diagonal), so the
/// exemplar's bounding-box diagonal has length 2 after normalisation, or
/// (`encode --voxel-size`) whatever makes the finest voxel that many world units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Bounding-box centre of the exemplar, world units.
    pub centre: DVec3,
    /// Normalised units per world unit.
    pub scale: f64,
    /// The exemplar's vertical axis. Coordinates are never rotated (a level
    /// file lands where its exemplar was); only cameras use it.
    pub up: Up,
}

impl Default for Frame {
    fn default() -> Self {
        Frame { centre: DVec3::ZERO, scale: 1.0, up: Up::Y }
    }
}

/// Which axis of an exemplar's own coordinates points up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Up {
    /// +Y (OBJ, glTF, Houdini, Maya).
    #[default]
    Y,
    /// +Z (LAS/LAZ, E57, Blender, most CAD and GIS).
    Z,
}

impl Up {
    pub fn axis(self) -> Vec3 {
        match self {
            Up::Y => Vec3::Y,
            Up::Z => Vec3::Z,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Up::Y => "y",
            Up::Z => "z",
        }
    }
}

impl Frame {
    pub fn to_world(&self, p: DVec3) -> DVec3 {
        self.centre + p / self.scale
    }
    pub fn to_normalised(&self, p: DVec3) -> DVec3 {
        (p - self.centre) * self.scale
    }
}


/// A level's grid: `resolution` voxels per axis over the normalised cube,
/// placed in the exemplar's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridTransform {
    pub resolution: u32,
    pub frame: Frame,
}

impl GridTransform {
    /// Voxel edge in normalised units (2 / resolution).
    pub fn voxel_normalised(&self) -> f64 {
        2.0 / self.resolution as f64
    }
    /// Voxel edge in world units.
    pub fn voxel_world(&self) -> f64 {
        self.voxel_normalised() / self.frame.scale
    }
    /// The minimum corner of voxel `c`, normalised units.
    pub fn corner_normalised(&self, c: IVec3) -> DVec3 {
        c.as_dvec3() * self.voxel_normalised() - DVec3::ONE
    }
    /// The centre of voxel `c`, normalised units.
    pub fn centre_normalised(&self, c: IVec3) -> DVec3 {
        (c.as_dvec3() + DVec3::splat(0.5)) * self.voxel_normalised() - DVec3::ONE
    }
    /// The point `offset` (voxel units, from the centre) in voxel `c`, normalised units.
    pub fn point_normalised(&self, c: IVec3, offset: Vec3) -> DVec3 {
        self.centre_normalised(c) + offset.as_dvec3() * self.voxel_normalised()
    }
    /// The same point in world units.
    pub fn point_world(&self, c: IVec3, offset: Vec3) -> DVec3 {
        self.frame.to_world(self.point_normalised(c, offset))
    }
    /// The voxel holding a normalised point.
    pub fn voxel_of_normalised(&self, p: DVec3) -> IVec3 {
        ((p + DVec3::ONE) / self.voxel_normalised()).floor().as_ivec3()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_normalised_and_world_agree() {
        let t = GridTransform { resolution: 64, frame: Frame { centre: DVec3::new(500.0, -3.0, 10.0), scale: 0.004, up: Up::Z } };
        assert_eq!(t.voxel_normalised(), 2.0 / 64.0);
        assert!((t.voxel_world() - 7.8125).abs() < 1e-9, "{}", t.voxel_world());
        let c = IVec3::new(0, 31, 63);
        assert_eq!(t.centre_normalised(c), t.corner_normalised(c) + DVec3::splat(t.voxel_normalised() / 2.0));
        assert_eq!(t.voxel_of_normalised(t.centre_normalised(c)), c);
        assert_eq!(t.voxel_of_normalised(t.point_normalised(c, Vec3::splat(0.49))), c);
        let w = t.point_world(c, Vec3::new(0.25, 0.0, -0.5));
        assert!((t.frame.to_normalised(w) - t.point_normalised(c, Vec3::new(0.25, 0.0, -0.5))).length() < 1e-12);
        assert_eq!(t.centre_normalised(IVec3::splat(32)), DVec3::splat(t.voxel_normalised() / 2.0));
    }
}
