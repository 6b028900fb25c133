//! The sparse-grid vocabulary every stage shares: a voxel's packed key and
//! the fast maps keyed by it ([`key`]), and the one transform between a
//! level's voxel indices, the normalised cube and the exemplar's world units
//! ([`transform`]). Below every stage (encode, learn, transfer, recon, eval,
//! edit); it imports nothing of theirs.

pub mod key;
pub mod occupancy;
pub mod patches;
pub mod transform;

pub use key::{VoxelIndex, VoxelMap};
pub use transform::GridTransform;
