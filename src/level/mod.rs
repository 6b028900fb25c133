//! One level of the multiscale representation: a sparse set of voxels with the
//! method's 10 channels (docs/method.md section 1), as plain data.
//!
//! Channel order, named once here and nowhere else by bare number:
//! offset (3), normal (3), colour (3), mask (1). See [`Channel`].

pub mod edit;
pub mod files;
pub mod repair;
pub mod resize;
pub mod sheet;
pub mod warp;

use glam::{DVec3, IVec3, Vec3};
use rayon::prelude::*;

use crate::geom::points::OrientedPoints;

pub use crate::grid::transform::{Frame, GridTransform, Up};

/// How 2x2x2 children are pooled into a parent's surface point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Pooling {
    /// Mean of the children's plane quadrics, minimised with a truncated
    /// pseudo-inverse around the voxel centre: keeps a corner's point on the corner
    /// (the paper's default, supplement "QEM averaging").
    #[default]
    Qem,
    /// Plain mean of the children's points: rounds corners and creases off.
    Average,
}

/// A level that breaks what every stage assumes of it ([`Level::check`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct InvalidLevel(pub String);

/// The 10 feature channels in storage order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    Offset = 0,
    Normal = 3,
    Colour = 6,
    Mask = 9,
}

impl Channel {
    /// First index of this channel group in a 10-wide feature row.
    pub const fn start(self) -> usize {
        self as usize
    }
    /// Number of scalars in the group.
    pub const fn width(self) -> usize {
        match self {
            Channel::Mask => 1,
            _ => 3,
        }
    }
}

/// Width of a feature row: offset, normal, colour, mask.
pub const FEATURE_CHANNELS: usize = 10;

/// A sparse level. Voxel (i, j, k) covers `[i*vs, (i+1)*vs) - 1` per axis in
/// normalised units, vs = 2 / resolution, so coarse voxel (i,j,k) has the
/// children (2i+a, 2j+b, 2k+c). Struct of arrays, all of length `len()`.
#[derive(Clone, Debug, Default)]
pub struct Level {
    /// 0 = coarsest.
    pub index: usize,
    /// Voxels per axis over [-1, 1].
    pub resolution: u32,
    pub coords: Vec<IVec3>,
    /// Surface point relative to the voxel centre, voxel units, in [-0.5, 0.5].
    pub offsets: Vec<Vec3>,
    /// Unit normals.
    pub normals: Vec<Vec3>,
    /// RGB in [0, 1].
    pub colours: Vec<Vec3>,
    /// +1 for voxels that hold surface, -1 otherwise.
    pub mask: Vec<f32>,
    pub frame: Frame,
}

impl Level {
    pub fn len(&self) -> usize {
        self.coords.len()
    }
    pub fn is_empty(&self) -> bool {
        self.coords.is_empty()
    }
    /// Where this level's voxels are: index <-> normalised <-> world.
    pub fn transform(&self) -> GridTransform {
        GridTransform { resolution: self.resolution, frame: self.frame }
    }
    /// Voxel size in normalised units.
    pub fn voxel_size(&self) -> f64 {
        self.transform().voxel_normalised()
    }
    /// Centre of voxel `c` in normalised units.
    pub fn voxel_centre(&self, c: IVec3) -> DVec3 {
        self.transform().centre_normalised(c)
    }
    /// Surface point of voxel `i` in voxel units of this level (voxel `c`
    /// spans `[c, c + 1)`).
    pub fn point_voxels(&self, i: usize) -> Vec3 {
        self.coords[i].as_vec3() + Vec3::splat(0.5) + self.offsets[i]
    }
    /// Surface point of voxel `i` in normalised units.
    pub fn point_normalised(&self, i: usize) -> DVec3 {
        self.transform().point_normalised(self.coords[i], self.offsets[i])
    }
    /// Surface point of voxel `i` in the exemplar's frame (world units).
    pub fn point_world(&self, i: usize) -> DVec3 {
        self.transform().point_world(self.coords[i], self.offsets[i])
    }
    /// A level from its parts, checked ([`Level::check`]).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        index: usize,
        resolution: u32,
        frame: Frame,
        coords: Vec<IVec3>,
        offsets: Vec<Vec3>,
        normals: Vec<Vec3>,
        colours: Vec<Vec3>,
        mask: Vec<f32>,
    ) -> Result<Level, InvalidLevel> {
        let level = Level { index, resolution, coords, offsets, normals, colours, mask, frame };
        level.check()?;
        Ok(level)
    }

    /// What every stage assumes of a level: a power-of-two resolution, one
    /// offset, normal, colour and mask per voxel, finite features, each voxel
    /// once. The level files' reader and writer check it (the networks' input its
    /// shape, [`Level::check_shape`]); a
    /// level built field by field (tests, edits) can be checked here.
    pub fn check(&self) -> Result<(), InvalidLevel> {
        self.check_shape()?;
        if let Some(i) = self.first_non_finite() {
            return Err(InvalidLevel(format!("voxel {} has NaN or infinite features", self.coords[i])));
        }
        let mut seen = crate::grid::VoxelMap::with_capacity(self.len());
        for &c in &self.coords {
            if seen.insert(c, ()).is_some() {
                return Err(InvalidLevel(format!("voxel {c} appears more than once")));
            }
        }
        Ok(())
    }

    /// The part of [`Level::check`] a consumer that checks each voxel itself
    /// needs (the networks' sparse grid refuses repeated voxels as it sorts
    /// them): a power-of-two resolution, one value of each channel per voxel.
    pub fn check_shape(&self) -> Result<(), InvalidLevel> {
        if !self.resolution.is_power_of_two() {
            return Err(InvalidLevel(format!("resolution {} is not a power of two", self.resolution)));
        }
        let n = self.len();
        let lengths = [self.offsets.len(), self.normals.len(), self.colours.len(), self.mask.len()];
        if lengths.iter().any(|&l| l != n) {
            return Err(InvalidLevel(format!(
                "level {} has {n} voxels but {} offsets, {} normals, {} colours, {} mask values",
                self.index, lengths[0], lengths[1], lengths[2], lengths[3]
            )));
        }
        Ok(())
    }

    /// The first voxel with a NaN or infinite offset, normal, colour or mask.
    pub fn first_non_finite(&self) -> Option<usize> {
        (0..self.len()).find(|&i| {
            !(self.offsets[i].is_finite()
                && self.normals[i].is_finite()
                && self.colours[i].is_finite()
                && self.mask[i].is_finite())
        })
    }
    /// This level with its voxels in coordinate order (x, then y, then z:
    /// the order the networks' sparse grid gives its levels), so what is
    /// made from it does not depend on the order a file stored them in.
    pub fn in_coordinate_order(&self) -> Level {
        let key = |c: IVec3| (c.x, c.y, c.z);
        if self.coords.windows(2).all(|w| key(w[0]) < key(w[1])) {
            return self.clone();
        }
        let mut idx: Vec<usize> = (0..self.len()).collect();
        idx.sort_unstable_by_key(|&i| key(self.coords[i]));
        self.rows(&idx)
    }
    /// The level of voxels `idx` of this one, in that order.
    pub fn rows(&self, idx: &[usize]) -> Level {
        Level {
            index: self.index,
            resolution: self.resolution,
            frame: self.frame,
            coords: idx.iter().map(|&i| self.coords[i]).collect(),
            offsets: idx.iter().map(|&i| self.offsets[i]).collect(),
            normals: idx.iter().map(|&i| self.normals[i]).collect(),
            colours: idx.iter().map(|&i| self.colours[i]).collect(),
            mask: idx.iter().map(|&i| self.mask[i]).collect(),
        }
    }
    /// Appends voxel `i` of `src` (its offset, normal, colour and mask) at
    /// coordinate `at` of this level.
    pub fn push_row(&mut self, src: &Level, i: usize, at: IVec3) {
        self.coords.push(at);
        self.offsets.push(src.offsets[i]);
        self.normals.push(src.normals[i]);
        self.colours.push(src.colours[i]);
        self.mask.push(src.mask[i]);
    }
    /// Keep only the voxels for which `keep` is true.
    pub fn retain(&mut self, keep: impl Fn(usize) -> bool) {
        let idx: Vec<usize> = (0..self.len()).filter(|&i| keep(i)).collect();
        *self = self.rows(&idx);
    }
}

impl Level {
    /// The surface points of the voxels with `mask > 0`, in the exemplar's
    /// own world frame, with `spacing` = the level's voxel size in world units.
    pub fn surface_points(&self) -> OrientedPoints {
        let level = self;
        let spacing = level.transform().voxel_world() as f32;
        if level.mask.par_iter().all(|&m| m > 0.0) {
            // Every voxel active (the usual case): copy, no index list.
            return OrientedPoints {
                positions: (0..level.len()).into_par_iter().map(|i| level.point_world(i).as_vec3()).collect(),
                normals: level.normals.clone(),
                colours: level.colours.clone(),
                spacing,
            };
        }
        let keep: Vec<u32> =
            (0..level.len() as u32).into_par_iter().filter(|&i| level.mask[i as usize] > 0.0).collect();
        OrientedPoints {
            positions: keep.par_iter().map(|&i| level.point_world(i as usize).as_vec3()).collect(),
            normals: keep.par_iter().map(|&i| level.normals[i as usize]).collect(),
            colours: keep.par_iter().map(|&i| level.colours[i as usize]).collect(),
            spacing,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_voxels() -> (Vec<IVec3>, Vec<Vec3>, Vec<Vec3>, Vec<Vec3>, Vec<f32>) {
        (vec![IVec3::ZERO, IVec3::X], vec![Vec3::ZERO; 2], vec![Vec3::Y; 2], vec![Vec3::splat(0.5); 2], vec![1.0; 2])
    }

    #[test]
    fn a_level_is_checked_where_it_is_built() {
        let (c, o, n, col, m) = two_voxels();
        let level = Level::new(1, 32, Frame::default(), c.clone(), o.clone(), n.clone(), col.clone(), m.clone()).unwrap();
        assert_eq!((level.len(), level.index, level.resolution), (2, 1, 32));
        let err = |r: Result<Level, InvalidLevel>| r.unwrap_err().to_string();
        assert!(err(Level::new(1, 24, Frame::default(), c.clone(), o.clone(), n.clone(), col.clone(), m.clone())).contains("power of two"));
        assert!(err(Level::new(1, 32, Frame::default(), c.clone(), o.clone(), n.clone(), col.clone(), vec![1.0])).contains("1 mask values"));
        let mut nan = n.clone();
        nan[1].x = f32::NAN;
        assert!(err(Level::new(1, 32, Frame::default(), c.clone(), o.clone(), nan, col.clone(), m.clone())).contains("NaN"));
        assert!(err(Level::new(1, 32, Frame::default(), vec![IVec3::X; 2], o, n, col, m)).contains("more than once"));
    }
}
