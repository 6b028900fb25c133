//! CGAL's Poisson reconstruction across the bridge (`cpp/recon_poisson.cpp`):
//! the implicit function sampled on a sparse grid around its zero set. The
//! meshing itself (clustering, surface nets, projection) is `crate::recon`'s.

pub use crate::io::ffi::bridge::{PoissonGrid, PoissonParams, PoissonStats};

/// `points` and `normals`: 3 floats per point, world units, normals outwards.
/// Errors are CGAL's (or the input checks') one-line messages.
pub fn sample_grid(points: &[f32], normals: &[f32], params: &PoissonParams) -> Result<PoissonGrid, String> {
    crate::io::ffi::bridge::poisson_grid(points, normals, params).map_err(|e| e.what().to_string())
}
