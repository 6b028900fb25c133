//! Meshing of oriented points (docs/method.md section 6): Poisson reconstruction for
//! closed shapes, algebraic point set surfaces (APSS) for open ones. Vertex
//! colours come from the nearest input point.
//!
//! * [`poisson`] goes through CGAL 5.5 (C++, `cpp/recon_poisson.cpp`). CGAL's
//!   Poisson is NOT the paper's screened Poisson (Kazhdan & Hoppe 2013, octree
//!   depth 9, point weight 10, samples per node 1): it solves the original
//!   (unscreened) Poisson equation of Kazhdan et al. 2006 for a piecewise
//!   linear function on a refined 3D Delaunay triangulation of the points
//!   (not an octree: no depth, no samples per node; the resolution follows the
//!   points), with only a weak pull towards the points (0.1 on the diagonal
//!   of the input vertices, where screened Poisson interpolates with point
//!   weight 10), and its iso-value is the median of the function at the
//!   points. It closes small holes; around an open sheet its zero set runs on
//!   to the hull of the triangulation, so the grid mesher clips it to the
//!   points' box plus a tenth of its longest side and caps it there (closed,
//!   see the tests).
//!   The zero set is meshed by surface nets on a sparse grid at `resolution`
//!   (default 256 = depth 8; 512 is marching cubes at the paper's depth 9).
//!   CGAL gets fewer, feature-aware points (`cluster`) and the vertices are
//!   then projected onto all the points (`project_steps`).
//! * [`apss`] is pure Rust: Guennebaud & Gross 2007 sphere fits evaluated on a
//!   sparse grid near the points only, polygonised by surface nets
//!   (`recon/apss.rs`, `recon/contour.rs`); boundaries of open surfaces stay
//!   open.
//!
//! Why the points are clustered: CGAL's Delaunay refinement and assembly are
//! sequential and grow with the triangulation, and near-duplicate points (two
//! points a fraction of a voxel apart) make short-edged tetrahedra and many
//! Steiner points. Clustering per 1.5 spacings and normal direction keeps the
//! two sides of thin sheets apart (a plain grid or Poisson-disk thinning
//! merged them); projection onto the APSS surface of all the points restores
//! what the coarser function loses. Timings and distances against Open3D are
//! in docs/performance.md (`make bench-poisson`).

mod apss;
pub mod bake;
pub mod settings;
mod contour;
pub(crate) mod spatial;
#[cfg(test)]
mod tests;

use glam::Vec3;
use crate::geom::nearest::Nearest;
pub use crate::geom::points::OrientedPoints;
use crate::io::poisson;
use spatial::HashGrid;
use std::time::Instant;

/// Fewer points than this are refused by both methods.
pub const MIN_POINTS: usize = 16;

/// The meshing method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Closed surfaces (CGAL's Poisson reconstruction).
    Poisson,
    /// Open surfaces (algebraic point set surfaces on a sparse grid).
    Apss,
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Method::Poisson => "poisson",
            Method::Apss => "apss",
        })
    }
}

/// A triangle mesh with optional vertex colours (empty when the points had none).
#[derive(Clone, Debug, Default)]
pub struct ReconMesh {
    pub positions: Vec<Vec3>,
    /// Counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    pub colours: Vec<Vec3>,
}

impl ReconMesh {
    /// Edges used by exactly one triangle (0 for a closed surface).
    pub fn boundary_edge_count(&self) -> usize {
        crate::geom::edges::edge_counts(&self.triangles).0
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ReconError {
    #[error("no points to mesh")]
    NoPoints,
    #[error("{count} points are too few to mesh (need at least {min})")]
    TooFewPoints { count: usize, min: usize },
    #[error("point {index} has a non-finite {what}")]
    NonFinite { index: usize, what: &'static str },
    #[error("{what} has {got} entries for {points} points")]
    LengthMismatch { what: &'static str, got: usize, points: usize },
    #[error("invalid meshing option: {0}")]
    InvalidOption(String),
    #[error("reconstruction failed: {0}")]
    Failed(String),
}

crate::stage_error!(ReconError);

/// Options of [`poisson`].
#[derive(Clone, Debug)]
pub struct PoissonOptions {
    /// Spacing in world units; None: the points' own spacing (or, when that is
    /// not positive, CGAL's average distance to the 6 nearest neighbours).
    pub spacing: Option<f32>,
    /// Cells along the longest side of the points'
    /// bounding box (cells never smaller than spacing / 4); 2^depth for a
    /// screened-Poisson-like depth. 256 (depth 8) meshes a 256^3 level at one
    /// cell per voxel.
    pub resolution: u32,
    /// Conjugate gradient: relative residual (Eigen's default, as CGAL uses
    /// it, is machine epsilon).
    pub solver_tolerance: f64,
    /// Conjugate gradient: iteration cap; 0: Eigen's default (2 x unknowns).
    pub solver_max_iterations: u32,
    /// The points are clustered on a grid of cells this many spacings wide,
    /// separately for each of the 6 normal directions (dominant axis and
    /// sign: the two sides of a sheet thinner than a cell, and the faces of a
    /// crease, stay apart), and one point per cluster goes to CGAL: the
    /// member nearest the cluster's mean, with its own normal. <= 1: every
    /// point. Projection and colours still use every point. 1.5 keeps ~40%
    /// of a level's points and about a third of CGAL's unknowns.
    pub cluster: f32,
    /// Steps of APSS projection of the mesh vertices onto all the points
    /// (sphere fits within 3 spacings, steps of at most one spacing): the
    /// pull towards the points that screened Poisson's point weight gives
    /// and CGAL's Poisson lacks. 0: the Poisson zero set as contoured.
    pub project_steps: u32,
}

impl Default for PoissonOptions {
    fn default() -> Self {
        PoissonOptions {
            spacing: None,
            resolution: 256,
            solver_tolerance: 1e-6,
            solver_max_iterations: 0,
            cluster: 1.5,
            project_steps: 2,
        }
    }
}

/// Options of [`apss`].
#[derive(Clone, Debug)]
pub struct ApssOptions {
    /// Grid cells along the longest side of the points' bounding box (the
    /// paper's marching cubes resolution). Cells are never made smaller than
    /// spacing / 4, whatever this says.
    pub resolution: u32,
    /// MLS support radius, in point spacings.
    pub radius: f32,
    /// The field is defined only within this distance of a point (spacings):
    /// the mesh never strays further from the points than about this.
    pub band: f32,
    /// Fewer points within `radius` leave the field undefined there.
    pub min_neighbours: u32,
}

impl Default for ApssOptions {
    fn default() -> Self {
        ApssOptions { resolution: 512, radius: 3.0, band: 1.5, min_neighbours: 6 }
    }
}

/// Phase times and sizes of one [`poisson`] run.
#[derive(Clone, Debug, Default)]
pub struct PoissonReport {
    /// Spacing used, world units.
    pub spacing: f64,
    /// Points given to CGAL (after clustering).
    pub points: u64,
    pub delaunay_vertices: u64,
    pub solver_iterations: u64,
    pub solver_error: f64,
    /// Grid corners evaluated.
    pub grid_corners: u64,
    /// CPU seconds (process) of each phase, from here on.
    pub seconds_setup: f64,
    /// Delaunay insertion of the points interleaved with refinement, and assembly.
    pub seconds_refine: f64,
    pub seconds_solve: f64,
    /// The grid evaluation (all threads' CPU time).
    pub seconds_mesh: f64,
    /// Surface nets (wall clock).
    pub seconds_output: f64,
    /// Wall clock, everything, including validation and colour transfer.
    pub seconds_total: f64,
}

/// Meshes `points` by `method`.
pub fn reconstruct(
    points: &OrientedPoints,
    method: Method,
    poisson_options: &PoissonOptions,
    apss_options: &ApssOptions,
) -> Result<ReconMesh, ReconError> {
    match method {
        Method::Poisson => poisson(points, poisson_options),
        Method::Apss => apss(points, apss_options),
    }
}

/// Poisson reconstruction (CGAL): a closed surface.
pub fn poisson(points: &OrientedPoints, options: &PoissonOptions) -> Result<ReconMesh, ReconError> {
    poisson_report(points, options).map(|(mesh, _)| mesh)
}

/// [`poisson`], and where its time went.
pub fn poisson_report(
    points: &OrientedPoints,
    options: &PoissonOptions,
) -> Result<(ReconMesh, PoissonReport), ReconError> {
    let start = Instant::now();
    validate(points)?;
    if options.resolution < 2 {
        return Err(ReconError::InvalidOption("Poisson grid resolution must be >= 2".into()));
    }
    let spacing = options.spacing.unwrap_or(points.spacing);
    let spacing = if spacing > 0.0 && spacing.is_finite() { spacing } else { 0.0 };
    // The spacing the Rust side works with (clusters, grid cell, projection);
    // CGAL is told 0 (estimate it yourself) when none was given.
    let s = if spacing > 0.0 { spacing } else { estimate_spacing(&points.positions) };
    let flat = |v: &[Vec3], normalise: bool| -> Vec<f32> {
        v.iter()
            .flat_map(|p| {
                let p = if normalise { p.normalize_or_zero() } else { *p };
                [p.x, p.y, p.z]
            })
            .collect()
    };
    let (positions, normals) = if options.cluster > 1.0 {
        let keep = cluster_representatives(&points.positions, &points.normals, options.cluster * s);
        let pick = |v: &[Vec3]| keep.iter().map(|&i| v[i as usize]).collect::<Vec<_>>();
        (flat(&pick(&points.positions), false), flat(&pick(&points.normals), true))
    } else {
        (flat(&points.positions, false), flat(&points.normals, true))
    };
    let (lo, hi) = bounds(&points.positions);
    let params = poisson::PoissonParams {
        spacing: spacing as f64,
        solver_tolerance: options.solver_tolerance,
        solver_max_iterations: options.solver_max_iterations,
        grid_cell: ((hi - lo).max_element() / options.resolution as f32).max(s / 4.0) as f64,
    };
    let grid = poisson::sample_grid(&positions, &normals, &params).map_err(ReconError::Failed)?;
    let t = Instant::now();
    let field = contour::SparseField {
        origin: Vec3::new(grid.origin[0] as f32, grid.origin[1] as f32, grid.origin[2] as f32),
        cell: grid.cell as f32,
        bricks: grid.bricks.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        values: grid.values,
    };
    let (mesh_positions, triangles) = contour::surface_nets(&field);
    let mut stats = grid.stats;
    stats.seconds_output = t.elapsed().as_secs_f64();
    if triangles.is_empty() {
        return Err(ReconError::Failed("the Poisson surface is empty".into()));
    }
    let mut mesh_positions = mesh_positions;
    if options.project_steps > 0 {
        apss::project(&mut mesh_positions, &points.positions, &points.normals, 3.0 * s, 6, s, options.project_steps);
    }
    let colours = transfer_colours(points, &mesh_positions);
    let s = &stats;
    let report = PoissonReport {
        spacing: s.spacing,
        points: (positions.len() / 3) as u64,
        delaunay_vertices: s.delaunay_vertices,
        solver_iterations: s.solver_iterations,
        solver_error: s.solver_error,
        grid_corners: s.grid_corners,
        seconds_setup: s.seconds_setup,
        seconds_refine: s.seconds_refine,
        seconds_solve: s.seconds_solve,
        seconds_mesh: s.seconds_mesh,
        seconds_output: s.seconds_output,
        seconds_total: start.elapsed().as_secs_f64(),
    };
    log::debug!("poisson: {report:?}");
    Ok((ReconMesh { positions: mesh_positions, triangles, colours }, report))
}


/// Algebraic point set surfaces on a sparse grid near the points: open where
/// the points end.
pub fn apss(points: &OrientedPoints, options: &ApssOptions) -> Result<ReconMesh, ReconError> {
    validate(points)?;
    if options.resolution < 2 || !(options.radius > 0.0) || !(options.band > 0.0) {
        return Err(ReconError::InvalidOption(format!(
            "APSS needs resolution >= 2 and positive radius and band, got {options:?}"
        )));
    }
    let spacing = if points.spacing > 0.0 && points.spacing.is_finite() {
        points.spacing
    } else {
        estimate_spacing(&points.positions)
    };
    let (lo, hi) = bounds(&points.positions);
    let extent = (hi - lo).max_element();
    let cell = (extent / options.resolution as f32).max(spacing / 4.0);
    if !(cell > 0.0) {
        return Err(ReconError::Failed("the points have no extent".into()));
    }
    let params = apss::ApssParams {
        cell,
        radius: (options.radius * spacing).max(cell),
        band: (options.band * spacing).max(cell),
        min_neighbours: options.min_neighbours,
    };
    let field = apss::field(&points.positions, &points.normals, &params);
    let (positions, triangles) = contour::surface_nets(&field);
    log::debug!(
        "apss: cell {cell}, {} bricks, {} defined corners, {} vertices, {} triangles",
        field.bricks.len(),
        field.defined_corners(),
        positions.len(),
        triangles.len()
    );
    if triangles.is_empty() {
        return Err(ReconError::Failed("the APSS field has no zero crossing near the points".into()));
    }
    let colours = transfer_colours(points, &positions);
    Ok(ReconMesh { positions, triangles, colours })
}

fn validate(points: &OrientedPoints) -> Result<(), ReconError> {
    let n = points.positions.len();
    if n == 0 {
        return Err(ReconError::NoPoints);
    }
    if n < MIN_POINTS {
        return Err(ReconError::TooFewPoints { count: n, min: MIN_POINTS });
    }
    if points.normals.len() != n {
        return Err(ReconError::LengthMismatch { what: "normals", got: points.normals.len(), points: n });
    }
    if !points.colours.is_empty() && points.colours.len() != n {
        return Err(ReconError::LengthMismatch { what: "colours", got: points.colours.len(), points: n });
    }
    if let Some(index) = points.positions.iter().position(|p| !p.is_finite()) {
        return Err(ReconError::NonFinite { index, what: "position" });
    }
    if let Some(index) = points.normals.iter().position(|p| !p.is_finite()) {
        return Err(ReconError::NonFinite { index, what: "normal" });
    }
    Ok(())
}

/// One point per occupied pair of grid cell (`cell`, world units) and normal
/// direction (dominant axis and its sign): the member nearest the cluster's
/// mean, so that the kept points lie on the surface (a mean would cut
/// corners). Indices in increasing key order (deterministic). Every point
/// where the grid would be too fine for [`spatial::pack`]'s keys.
fn cluster_representatives(p: &[Vec3], n: &[Vec3], cell: f32) -> Vec<u32> {
    let (lo, hi) = bounds(p);
    if !((hi - lo).max_element() / cell < spatial::KEY_LIMIT as f32) {
        return (0..p.len() as u32).collect();
    }
    let key = |i: usize| {
        let c = ((p[i] - lo) / cell).floor().as_ivec3();
        let a = n[i].abs();
        let axis = if a.x >= a.y && a.x >= a.z { 0 } else if a.y >= a.z { 1 } else { 2 };
        let bin = 2 * axis as u64 + (n[i][axis] < 0.0) as u64;
        (spatial::pack([c.x, c.y, c.z]), bin)
    };
    let mut order: Vec<((u64, u64), u32)> = (0..p.len()).map(|i| (key(i), i as u32)).collect();
    order.sort_unstable();
    let mut keep = Vec::with_capacity(order.len() / 4);
    for run in order.chunk_by(|a, b| a.0 == b.0) {
        let mean = run.iter().map(|&(_, i)| p[i as usize]).sum::<Vec3>() / run.len() as f32;
        let best = run.iter().min_by(|a, b| {
            p[a.1 as usize].distance_squared(mean).total_cmp(&p[b.1 as usize].distance_squared(mean))
        });
        keep.extend(best.map(|&(_, i)| i));
    }
    keep
}

fn bounds(p: &[Vec3]) -> (Vec3, Vec3) {
    p.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(a, b), &q| (a.min(q), b.max(q)))
}

/// Median distance to the nearest other point, over up to 2000 points.
fn estimate_spacing(p: &[Vec3]) -> f32 {
    let (lo, hi) = bounds(p);
    let guess = ((hi - lo).length() / (p.len() as f32).sqrt()).max(f32::MIN_POSITIVE);
    let grid = HashGrid::new(p, guess);
    let step = (p.len() / 2000).max(1);
    let mut d: Vec<f32> = (0..p.len())
        .step_by(step)
        .filter_map(|i| {
            let mut r = guess;
            for _ in 0..8 {
                let mut best = f32::INFINITY;
                grid.for_each_within(p[i], r, |_, d2| {
                    if d2 > 0.0 {
                        best = best.min(d2)
                    }
                });
                if best.is_finite() {
                    return Some(best.sqrt());
                }
                r *= 2.0;
            }
            None
        })
        .collect();
    if d.is_empty() {
        return guess;
    }
    d.sort_by(f32::total_cmp);
    d[d.len() / 2]
}

/// Colour of the nearest input point for every vertex (empty without colours).
fn transfer_colours(points: &OrientedPoints, vertices: &[Vec3]) -> Vec<Vec3> {
    use rayon::prelude::*;
    if points.colours.is_empty() {
        return Vec::new();
    }
    let grid = Nearest::new(&points.positions);
    vertices
        .par_iter()
        .map(|v| grid.nearest(*v).map_or(Vec3::ZERO, |(i, _)| points.colours[i as usize]))
        .collect()
}
