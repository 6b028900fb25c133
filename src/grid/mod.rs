//! The sparse-grid vocabulary every stage shares: a voxel's packed key and
//! the fast maps keyed by it ([`key`]), and the one transform between a
//! level's voxel indices, the normalised cube and the exemplar's world units
//! ([`transform`]); bit-packed voxel sets ([`occupancy`]) and the exact
//! matching of 11^3 local patches against an exemplar's ([`patches`]: eval's
//! LP scores and the structure flags' out-of-style share). Below every stage
//! (encode, learn, transfer, recon, eval, edit); it imports nothing of theirs
//! (only `patches`' tests borrow eval's test shapes and voxeliser).

pub mod components;
pub mod key;
pub mod occupancy;
pub mod transform;

pub use key::{VoxelIndex, VoxelMap};
pub use transform::GridTransform;
