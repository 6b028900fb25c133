//! shapeshifter: 3D shape variations from a single exemplar mesh
//! (ShapeShifter, CVPR 2025), with every level of its sparse multiscale grids
//! exchanged as OpenVDB files.
//!
//! Data flows one way: [`mesh`] -> `encode` -> [`level`] -> train -> sample ->
//! mesh / [`vdb`]. Only [`vdb`] and [`mesh`] (and `recon`) talk to C++.

pub mod batch;
pub mod cluster;
pub mod config;
pub mod dataset;
pub mod diffusion;
pub mod edit;
pub mod encode;
pub mod error;
pub mod evaluate;
pub mod exemplar;
pub mod grid;
mod ffi;
pub mod glb;
pub mod info;
pub mod ladder;
pub mod level;
pub mod mesh;
mod mesh_check;
mod nearest;
pub mod nn;
mod obj;
pub mod pipeline;
pub mod metrics;
pub mod recon;
pub mod render;
pub mod rng;
pub mod sample;
pub mod shapes;
pub mod sparse_conv;
pub mod train;
pub mod vdb;

pub use error::{Error, Result};

/// Tunes glibc's allocator for large tensors: by default it returns every big
/// block to the OS, which made sparse convolution 1.5-3x slower on CPU
/// (DESIGN.md). Call once at start-up.
pub fn tune_allocator() {
    // SAFETY: mallopt only changes allocator thresholds.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 30);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}
