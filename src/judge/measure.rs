//! The structure of a shape at a coarse level: how much surface there is, how
//! far it reaches, in how many pieces, and how much of it is a free edge
//! (a wall end, the rim of a hole), each read by one criterion of
//! [`super`]. Local-patch measures cannot see these faults: every patch of a
//! half tower, a torn roof or a shrunken copy exists somewhere on the
//! exemplar. Compared with the exemplar's own structure at the same level
//! ([`super::verdict`]) they flag the variants a user would throw away.
//!
//! Everything is measured on the surface voxels (mask > 0) of one level, in
//! that level's voxels.

use glam::IVec3;

use super::enclosure::enclosure;
use super::free_edge::free_boundary;
use super::thin::thin_count;
use super::thresholds::THRESHOLDS;
use crate::grid::components::components;
use crate::level::Level;


/// What one level's surface voxels look like as a whole.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Structure {
    pub resolution: u32,
    /// Surface voxels.
    pub voxels: usize,
    /// Bounding box of the surface voxels, voxels per axis (x, y, z).
    pub extent: [u32; 3],
    /// Sizes of the 26-connected components, largest first.
    pub components: Vec<usize>,
    /// Surface voxels on a free boundary ([`free_boundary`]).
    pub free_boundary: usize,
    /// Share of the directions from the voxels' centroid in which the
    /// surface is met ([`enclosure`]).
    pub enclosure: f64,
    /// Per view, the share of the silhouette where the inside is seen
    /// ([`super::seen_through::seen_through`]; empty below 32^3).
    #[serde(default)]
    pub seen_through: Vec<f64>,
    /// Surface voxels on a thin part ([`thin_voxels`]: a bunny's ear, a
    /// wall, a fin).
    #[serde(default)]
    pub thin: usize,
    /// Per axis, the empty columns the occupied ones enclose (holes through
    /// the shape along it, [`super::sheet::enclosed_columns`]).
    #[serde(default)]
    pub enclosed_columns: [usize; 3],
    /// The axis along which this shape is a sheet, a height field without a
    /// hole ([`super::sheet::sheet_axis`]); where a variant's holes
    /// are counted when this is the exemplar's. Sampling sets an exemplar's
    /// level 0 to the decision of its structure level
    /// ([`super::sheet::sheet_axes`]).
    #[serde(default)]
    pub sheet_axis: Option<usize>,
    /// The top height map's steps and seams ([`super::steps::top_steps`]).
    #[serde(default)]
    pub top_steps: super::steps::TopSteps,
}

impl Structure {
    /// The exemplar's structure as a shape in a resized box is judged against
    /// it: `stretched`'s (the exemplar stretched to the box), but for its
    /// thin parts, which keep the exemplar's own count (`own`). Stretching
    /// makes thin parts where there were none (the Mauryan hall's 64^3 level
    /// 1.28 times longer: 1.24 times the voxels, 1.67 times the thin ones),
    /// and a part that appears once (a porch's columns, an ear) does not grow
    /// with the box.
    pub fn at_extent(stretched: &Structure, own: &Structure) -> Structure {
        Structure { thin: own.thin, ..stretched.clone() }
    }

    /// The structure of `level`'s surface voxels.
    pub fn of(level: &Level) -> Structure {
        let active: Vec<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).collect();
        let coords: Vec<IVec3> = active.iter().map(|&i| level.coords[i]).collect();
        let extent = match (coords.iter().copied().reduce(IVec3::min), coords.iter().copied().reduce(IVec3::max)) {
            (Some(lo), Some(hi)) => (hi - lo + IVec3::ONE).to_array().map(|v| v as u32),
            _ => [0; 3],
        };
        Structure {
            resolution: level.resolution,
            voxels: coords.len(),
            extent,
            components: components(&coords),
            free_boundary: free_boundary(level).iter().filter(|&&b| b).count(),
            enclosure: enclosure(&coords),
            seen_through: super::seen_through::seen_through(level),
            thin: thin_count(level),
            enclosed_columns: super::sheet::enclosed_counts(level),
            sheet_axis: super::sheet::sheet_axis(level),
            top_steps: super::steps::top_steps(level),
        }
    }

    /// Components holding at least `THRESHOLDS.piece_share` of the voxels.
    pub fn pieces(&self) -> usize {
        self.components.iter().filter(|&&c| c as f64 >= THRESHOLDS.piece_share * self.voxels as f64).count()
    }

    /// Share of the voxels in the largest component (0 when empty).
    pub fn largest_share(&self) -> f64 {
        self.components.first().map_or(0.0, |&c| c as f64 / self.voxels.max(1) as f64)
    }

    /// Share of the voxels on a free boundary (0 when empty).
    pub fn free_boundary_share(&self) -> f64 {
        self.free_boundary as f64 / self.voxels.max(1) as f64
    }
}
