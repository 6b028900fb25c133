//! shapeshifter: 3D shape variations from a single exemplar mesh
//! (ShapeShifter, CVPR 2025), with every level of its sparse multiscale grids
//! exchanged as OpenVDB files.
//!
//! Data flows one way, one folder per stage:
//!
//! ```text
//! io::mesh ──> encode ──> level ──> learn::train ──> learn::sample ──> transfer ──> recon / io::vdb ──> eval, render
//! ```
//!
//! - [`io`]: the only callers of C++ (the one cxx bridge): meshes through
//!   OpenMesh, level files through OpenVDB, Poisson through CGAL; also the
//!   formats written in Rust (OBJ reading, glTF binary) and `info`.
//! - [`encode`]: an exemplar mesh into the multiscale levels.
//! - [`level`]: one level as plain data, an encoded folder on disk, editing.
//! - [`learn`]: the only users of tensors: sparse grids and convolution, the
//!   networks, the diffusion schedule, checkpoints, training and sampling.
//! - [`transfer`]: detail transfer: the fine levels copied from the exemplar
//!   where the coarse neighbourhoods match (no network, no tensors).
//! - [`recon`]: oriented points into triangle meshes.
//! - [`eval`]: quality measures, the `eval` command, the degradation ladder.
//! - [`render`]: previews, contact sheets, `report.html`.
//! - [`pipeline`]: the stages on whole folders, `run`, batches, cluster graphs.
//! - [`grid`]: the sparse-grid vocabulary below every stage: voxel keys and
//!   fast maps, the index / normalised / world transform.
//! - [`geom`], [`util`]: helpers with one home each.

pub mod config;
pub mod encode;
pub mod error;
pub mod eval;
pub mod geom;
pub mod grid;
pub mod io;
pub mod judge;
pub mod learn;
pub mod level;
pub mod pipeline;
pub mod recon;
pub mod render;
pub mod studio;
pub mod transfer;
// Fixtures (shapes with known answers, synthetic levels) for the tests,
// benchmarks and tools. Always compiled, so that `cargo build` and `cargo
// test` build the library (and its C++) once, with one feature set.
#[doc(hidden)]
pub mod testing;
pub mod util;

pub use error::{Error, Result};
