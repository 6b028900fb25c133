//! `shapeshifter eval`: METHOD.md section 7 on files: the exemplar (an
//! encoded folder) against variant folders (one `level_K.vdb` per level, and
//! `mesh.ply` where meshing ran).
//!
//! Two ways to voxelise, chosen once for the whole set so that every shape
//! lands on the same lattice in the same way:
//! - `Solid` (the paper's): meshes, occupancy by winding number, 256 voxels
//!   along the exemplar's longest axis. Needs the exemplar mesh and a
//!   `mesh.ply` in every variant folder.
//! - `Surface`: the finest level's points, one lattice voxel per level voxel
//!   (a shell, no meshing needed). Works on any level files.

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::dataset;
use crate::error::{Error, Result};
use crate::level::Level;
use crate::mesh::{self, Mesh};
use crate::metrics::{self, EvalReport, LpParams, Occupancy, OccupancyGrid, VariantInput};
use crate::vdb;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Voxelisation {
    Solid,
    Surface,
}

/// A variant on disk: its finest level, its coarsest level, its mesh if any.
pub struct VariantFiles {
    pub name: String,
    pub finest: Level,
    pub coarsest: Level,
    pub mesh: Option<Mesh>,
}

/// Reads a variant folder: the highest and lowest `level_K.vdb` present and
/// `mesh.ply` if there.
pub fn read_variant(dir: &Path) -> Result<VariantFiles> {
    let mut levels: Vec<(usize, PathBuf)> = std::fs::read_dir(dir)
        .map_err(|e| Error::file(dir, e.to_string()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let k = name.strip_prefix("level_")?.strip_suffix(".vdb")?.parse().ok()?;
            Some((k, e.path()))
        })
        .collect();
    levels.sort();
    let (Some(lo), Some(hi)) = (levels.first(), levels.last()) else {
        return Err(Error::file(dir, "holds no level_K.vdb files"));
    };
    let (finest, _) = vdb::read_level(&hi.1)?;
    let (coarsest, _) = vdb::read_level(&lo.1)?;
    let mesh_path = dir.join("mesh.ply");
    let mesh = if mesh_path.is_file() { Some(mesh::load(&mesh_path)?) } else { None };
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(VariantFiles { name, finest, coarsest, mesh })
}

fn points_normalised(level: &Level) -> Vec<Vec3> {
    metrics::level_points_normalised(level)
}

/// Lattice over `level`'s points with one voxel per level voxel.
fn surface_lattice(level: &Level) -> OccupancyGrid {
    let pts = points_normalised(level);
    let (lo, hi) = pts.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(a, b), p| (a.min(*p), b.max(*p)));
    let longest = (hi - lo).max_element();
    let res = (longest / level.voxel_size() as f32).ceil().max(1.0) as u32;
    OccupancyGrid::from_box(level.frame, lo, hi, res, metrics::DEFAULT_MARGIN)
}

/// Evaluates variants against the encoded exemplar in `exemplar_dir`.
/// `exemplar_mesh`: the exemplar mesh for `Solid` voxelisation.
pub fn evaluate(
    exemplar_dir: &Path,
    exemplar_mesh: Option<&Mesh>,
    variants: &[VariantFiles],
    resolution: u32,
) -> Result<(EvalReport, Voxelisation)> {
    if variants.is_empty() {
        return Err(Error::Invalid("no variants to evaluate".into()));
    }
    let (_, levels) = dataset::read(exemplar_dir)?;
    let (Some(ex_coarse), Some(ex_fine)) = (levels.first(), levels.last()) else {
        return Err(Error::file(exemplar_dir, "manifest lists no levels"));
    };
    let mode = match exemplar_mesh {
        Some(_) if variants.iter().all(|v| v.mesh.is_some()) => Voxelisation::Solid,
        _ => Voxelisation::Surface,
    };
    let frame = ex_fine.frame;
    let (grid, exemplar_occ): (OccupancyGrid, Occupancy) = match (mode, exemplar_mesh) {
        (Voxelisation::Solid, Some(m)) => {
            let grid = OccupancyGrid::for_exemplar(m, frame, resolution);
            let occ = metrics::voxelise_mesh(m, &grid);
            (grid, occ)
        }
        _ => {
            let grid = surface_lattice(ex_fine);
            let occ = metrics::voxelise_points(&points_normalised(ex_fine), &grid);
            (grid, occ)
        }
    };
    let occupancies: Vec<Occupancy> = variants
        .iter()
        .map(|v| match (mode, &v.mesh) {
            (Voxelisation::Solid, Some(m)) => metrics::voxelise_mesh(m, &grid),
            _ => metrics::voxelise_points(&points_normalised(&v.finest), &grid),
        })
        .collect();
    let coarse: Vec<Vec<Vec3>> = variants.iter().map(|v| points_normalised(&v.coarsest)).collect();
    let inputs: Vec<VariantInput> = variants
        .iter()
        .zip(&occupancies)
        .zip(&coarse)
        .map(|((v, occ), c)| VariantInput { name: v.name.clone(), occupancy: occ, coarse_points: Some(c) })
        .collect();
    let ex_coarse_pts = points_normalised(ex_coarse);
    let report = metrics::evaluate(&exemplar_occ, Some(&ex_coarse_pts), &inputs, &LpParams::default());
    Ok((report, mode))
}
