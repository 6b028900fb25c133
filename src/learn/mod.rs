//! Learning: the only code that touches tensors. Sparse voxel grids and their
//! topology ([`grid`]), sparse tensors and convolution ([`sparse`]), the two
//! networks of a level ([`nn`]), the diffusion schedule ([`schedule`]),
//! training ([`train`]) and sampling ([`sample`]). Sampling reads checkpoints
//! through [`checkpoint`]; it does not import training.

pub mod checkpoint;
pub mod grid;
pub mod nn;
pub mod sample;
pub mod schedule;
pub mod noise;
pub mod sparse;
pub mod train;
