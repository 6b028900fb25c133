//! `[encode]`: the grids an exemplar is encoded into, and the settings for
//! scans and real-world units.

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncodeConfig {
    /// Voxels per axis of the finest sampling grid.
    pub sampling_resolution: u32,
    /// Resolution of level 0.
    pub coarsest_resolution: u32,
    /// Resolution of the last level.
    pub finest_resolution: u32,
    /// How children are pooled into a parent's surface point.
    pub pooling: crate::encode::Pooling,
    // Settings for scans and real-world units. Left out of the recorded
    // configuration (and so of the stage digests) at their defaults, so that
    // folders encoded before they existed are still reused.
    /// The finest voxel's edge in the exemplar's units; unset: fit the cube.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub voxel_size: Option<f64>,
    /// The exemplar's vertical axis; unset: the format's own (z for scans).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<crate::level::Up>,
    /// Point clouds: where colour comes from (auto, rgb, intensity, classification, none).
    #[serde(default, skip_serializing_if = "is_default")]
    pub cloud_colour: crate::io::cloud::CloudColour,
    /// Point clouds: neighbours of each estimated normal's plane.
    #[serde(default = "default_normal_neighbours", skip_serializing_if = "is_default_normal_neighbours")]
    pub normal_neighbours: usize,
    /// Point clouds: how estimated normals get their sign (graph, up, outward).
    #[serde(default, skip_serializing_if = "is_default")]
    pub normal_orientation: crate::geom::normals::Orientation,
    /// Point clouds: estimate normals even where the file has them.
    #[serde(default, skip_serializing_if = "is_default")]
    pub estimate_normals: bool,
}

impl EncodeConfig {
    /// The grid settings given, every other setting at its default (the
    /// `encode` command's configuration: no profile).
    pub fn grids(sampling_resolution: u32, coarsest_resolution: u32, finest_resolution: u32, pooling: crate::encode::Pooling) -> Self {
        EncodeConfig {
            sampling_resolution,
            coarsest_resolution,
            finest_resolution,
            pooling,
            voxel_size: None,
            up: None,
            cloud_colour: Default::default(),
            normal_neighbours: default_normal_neighbours(),
            normal_orientation: Default::default(),
            estimate_normals: false,
        }
    }
}

fn is_default<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}
fn default_normal_neighbours() -> usize {
    crate::encode::CloudOptions::default().normal_neighbours
}
fn is_default_normal_neighbours(n: &usize) -> bool {
    *n == default_normal_neighbours()
}
