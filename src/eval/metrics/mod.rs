//! Evaluation (docs/method.md section 7): solid voxelisation, IoU and diversity,
//! local-patch plausibility (LP-IoU, LP-F-score) and point-set distances.
//!
//! # Units
//!
//! - *World units*: the exemplar's own frame, where meshes and
//!   [`Level::point_world`](crate::level::Level::point_world) live. Everything
//!   that is voxelised is given in world units and mapped through the
//!   exemplar's [`Frame`](crate::level::Frame) held by the grid.
//! - *Normalised units*: the exemplar normalised so its bounding-box diagonal is 2
//!   (docs/method.md section 2.1). [`OccupancyGrid::origin`] and
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
//!
//! # The measures, in the order of an evaluation
//!
//! 1. **Lattice and occupancy** (`occupancy.rs`): the [`OccupancyGrid`] and
//!    bit-packed voxel sets on it ([`Occupancy`]), with the surface (patch
//!    centres), the 26-neighbour boundary and its dilation (the F-score's
//!    layers).
//! 2. **Voxelisation** (`voxelise.rs`): closed meshes as solids
//!    ([`voxelise_mesh`], above), open surfaces as their voxels alone
//!    ([`voxelise_mesh_surface`]), point sets as the voxels that hold a point
//!    ([`voxelise_points`], [`voxelise_normalised_points`]).
//! 3. **IoU and diversity** (`occupancy.rs`): [`iou`] of two occupancies;
//!    [`diversity`], the mean `1 - IoU` over all pairs of variants.
//! 4. **Local patches** (`crate::judge::patches`, shared with the structure
//!    flags): every sampled 11^3 patch of a
//!    shape against every patch of the exemplar's dictionary
//!    ([`ExemplarPatches`]); the best IoU and the best boundary F-score (1-voxel
//!    tolerance) per patch, averaged, are LP-IoU and LP-F-score, with the
//!    fractions of patches above 0.95 ([`local_patch_scores`],
//!    [`best_patch_matches`]). This is precision; the same matching the other
//!    way round (the exemplar's patches in the shape's dictionary) is
//!    coverage.
//! 5. **Point-set distances** (`point_distances.rs`): [`chamfer`] and
//!    [`hausdorff`], in the units of the points.
//! 6. **Surface detail and colour** (`detail.rs`, `colour.rs`): the finest
//!    level's neighbour-normal angles and colour patches against the
//!    exemplar's ([`DetailScores`], [`ColourScores`]).
//! 7. **Report** (`report.rs`): [`evaluate`] refuses degenerate shapes
//!    ([`check_shape`]), then scores every variant with all of the above
//!    (precision and coverage on the evaluation lattice and on the
//!    half-resolution one, detail, colour, coarse Chamfer), adds diversity and
//!    the coverage of the exemplar by the set, and returns an [`EvalReport`]
//!    (scores, their mean, the terminal table).

pub mod colour;
pub mod detail;
mod occupancy;
mod point_distances;
mod report;
#[cfg(test)]
pub(crate) mod test_shapes;
mod voxelise;

pub use colour::{ColourParams, ColourPatches, ColourScores};
pub use detail::{DetailScores, Variation};
pub use crate::judge::patches::{
    best_patch_matches, local_patch_scores, lp_scores, ExemplarPatches, LpParams, LpScores, PatchMatches, PATCH,
    PATCH_WORDS,
};
pub use occupancy::{diversity, iou, Occupancy, OccupancyGrid, ALIGN_VOXELS, DEFAULT_MARGIN, DEFAULT_RESOLUTION};
pub use point_distances::{chamfer, hausdorff, level_points_normalised};
pub use report::{
    check_shape, evaluate, DegenerateShape, EvalParams, EvalReport, SetCoverage, ShapeInput, VariantScores,
    FILLED_FRACTION,
};
pub use voxelise::{voxelise_mesh, voxelise_mesh_surface, voxelise_normalised_points, voxelise_points};
