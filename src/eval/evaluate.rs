//! `shapeshifter eval`: docs/method.md section 7 on files: the exemplar (an
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

use crate::io::dataset;
use crate::error::{Error, Result};
use crate::level::Level;
use crate::io::mesh::{self, Mesh};
use crate::eval::metrics::{self, EvalParams, EvalReport, Occupancy, OccupancyGrid, ShapeInput};
use crate::io::vdb;

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Voxelisation {
    Solid,
    Surface,
}

/// A variant on disk: its finest level, its coarsest level, the level its
/// structure is measured at, its mesh if any.
pub struct VariantFiles {
    pub name: String,
    pub finest: Level,
    pub coarsest: Level,
    /// The finest level of at most [`STRUCTURE_RESOLUTION`]^3.
    pub structure: Option<Level>,
    /// The level after the structure level (128^3), if the variant has one
    /// below its finest ([`crate::judge::fine_level`]); the
    /// finest itself where that is the one.
    pub fine: Option<Level>,
    pub mesh: Option<Mesh>,
    /// The bend of its start, where it started from the exemplar bent
    /// ([`crate::level::warp::BEND_FILE`]).
    pub bend: Option<crate::level::warp::Bend>,
    /// The extent of its level-0 box, where it is not the exemplar's
    /// ([`crate::level::resize::EXTENT_FILE`]).
    pub extent: Option<crate::level::resize::Extent>,
}

pub use crate::judge::STRUCTURE_RESOLUTION;

/// The `level_K.vdb` files of a folder, coarsest first (none read).
pub fn level_files(dir: &Path) -> Result<Vec<(usize, PathBuf)>> {
    let mut levels: Vec<(usize, PathBuf)> = std::fs::read_dir(dir)
        .map_err(|e| Error::file(dir, e.to_string()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let (k, kind) = crate::level::files::parse(&name)?;
            (kind == crate::level::files::LevelFile::Volumes).then_some(())?;
            Some((k, e.path()))
        })
        .collect();
    levels.sort();
    if levels.is_empty() {
        return Err(Error::file(dir, "holds no level_K.vdb files"));
    }
    Ok(levels)
}

/// Reads a variant folder: the highest and lowest `level_K.vdb` present, the
/// structure level and the level after it (read upwards from the coarsest
/// until a level finer than [`STRUCTURE_RESOLUTION`] is reached: small files)
/// and `mesh.ply` if there.
pub fn read_variant(dir: &Path) -> Result<VariantFiles> {
    let levels = level_files(dir)?;
    let hi = &levels[levels.len() - 1];
    let (finest, _) = vdb::read_level(&hi.1)?;
    let mut coarse_levels: Vec<Level> = Vec::new();
    for (_, path) in &levels[..levels.len() - 1] {
        let (level, _) = vdb::read_level(path)?;
        // Resolutions double per level: the one after the structure level
        // (the fine level) is the last one needed.
        let reached = level.resolution > STRUCTURE_RESOLUTION;
        coarse_levels.push(level);
        if reached {
            break;
        }
    }
    let coarsest = coarse_levels.first().cloned().unwrap_or_else(|| finest.clone());
    let read: Vec<Level> = coarse_levels.into_iter().chain(std::iter::once(finest.clone())).collect();
    let structure = crate::judge::structure_level(&read).cloned();
    let fine = crate::judge::fine_level(&read).cloned();
    let mesh_path = dir.join("mesh.ply");
    let mesh = if mesh_path.is_file() { Some(mesh::load(&mesh_path)?) } else { None };
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let crate::io::dataset::StartRecord { bend, extent } = crate::io::dataset::StartRecord::read(dir)?;
    Ok(VariantFiles { name, finest, coarsest, structure, fine, mesh, bend, extent })
}

fn points_normalised(level: &Level) -> Vec<Vec3> {
    metrics::level_points_normalised(level)
}

/// Bounding box of points (normalised units); None without finite points.
fn bounds(points: &[Vec3]) -> Option<(Vec3, Vec3)> {
    points.iter().filter(|p| p.is_finite()).fold(None, |acc, &p| match acc {
        None => Some((p, p)),
        Some((lo, hi)) => Some((lo.min(p), hi.max(p))),
    })
}

fn mesh_bounds(mesh: &Mesh, frame: crate::level::Frame) -> Option<(Vec3, Vec3)> {
    let pts: Vec<Vec3> = mesh.positions.iter().map(|p| frame.to_normalised(p.as_dvec3()).as_vec3()).collect();
    bounds(&pts)
}

fn union(a: Option<(Vec3, Vec3)>, b: Option<(Vec3, Vec3)>) -> Option<(Vec3, Vec3)> {
    match (a, b) {
        (Some((l1, h1)), Some((l2, h2))) => Some((l1.min(l2), h1.max(h2))),
        (x, None) | (None, x) => x,
    }
}

/// How the shapes of one evaluation are voxelised, chosen once for the set.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Lattice {
    pub voxelisation: Voxelisation,
    /// Meshes voxelised as solids (closed exemplar) or as surfaces only (open
    /// exemplar: a sheet stays a sheet).
    pub filled: bool,
    /// Voxels of the evaluation lattice (x, y, z); the 22^3 patches use a
    /// lattice of half this resolution.
    pub dims: [u32; 3],
    /// Voxel edge, normalised units (the exemplar's bounding-box diagonal is 2).
    pub voxel: f32,
}

/// An evaluation as `eval.json` holds it: how the shapes were voxelised, then
/// every figure with its parameters.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Evaluation {
    pub lattice: Lattice,
    /// Variants that could not be scored, each with the reason.
    pub unscored: Vec<String>,
    #[serde(flatten)]
    pub report: EvalReport,
}

impl Evaluation {
    /// Writes the evaluation as pretty JSON, atomically.
    pub fn write_json(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(|e| Error::file(path, e.to_string()))?;
        crate::util::fs::write_file(path, &text)
    }

    /// The lattice in one line, then the report's table.
    pub fn table(&self) -> String {
        let l = &self.lattice;
        format!(
            "voxelisation: {:?}{} on {}x{}x{} voxels\n{}{}",
            l.voxelisation,
            if l.voxelisation == Voxelisation::Solid && !l.filled { " (open exemplar: surfaces only)" } else { "" },
            l.dims[0],
            l.dims[1],
            l.dims[2],
            self.unscored.iter().map(|u| format!("not scored: {u}\n")).collect::<String>(),
            self.report.table()
        )
    }
}

/// Evaluates variants against the encoded exemplar in `exemplar_dir`.
/// `exemplar_mesh`: the exemplar mesh for `Solid` voxelisation.
///
/// The lattice covers the exemplar AND every variant (a variant larger than
/// the exemplar is not clipped); its voxel is the exemplar's finest level
/// voxel for point shells (aligned with that level's grid, so each level voxel
/// is one lattice voxel), or `resolution` voxels along the exemplar's longest
/// side for solids.
pub fn evaluate(
    exemplar_dir: &Path,
    exemplar_mesh: Option<&Mesh>,
    variants: &[VariantFiles],
    resolution: u32,
) -> Result<Evaluation> {
    if variants.is_empty() {
        return Err(Error::Invalid("no variants to evaluate".into()));
    }
    let (_, levels) = dataset::read(exemplar_dir)?;
    let ex_structure = crate::judge::structure_level(&levels);
    let (Some(ex_coarse), Some(ex_fine)) = (levels.first(), levels.last()) else {
        return Err(Error::file(exemplar_dir, "manifest lists no levels"));
    };
    let mode = match exemplar_mesh {
        Some(_) if variants.iter().all(|v| v.mesh.is_some()) => Voxelisation::Solid,
        Some(_) => {
            log::warn!("eval: not every variant has a mesh.ply: scoring the finest levels' point shells instead");
            Voxelisation::Surface
        }
        None => Voxelisation::Surface,
    };
    // A variant whose finer levels were pruned away stops at a coarser level:
    // reported, not scored against the exemplar's finest level.
    let (variants, stopped): (Vec<&VariantFiles>, Vec<&VariantFiles>) =
        variants.iter().partition(|v| v.finest.resolution == ex_fine.resolution);
    let stopped: Vec<String> = stopped
        .iter()
        .map(|v| {
            format!(
                "{}: its finest level is level {} ({}^3), not the exemplar's {}^3 (the finer levels were pruned away)",
                v.name, v.finest.index, v.finest.resolution, ex_fine.resolution
            )
        })
        .collect();
    if variants.is_empty() {
        return Err(Error::Invalid(format!("no variant can be scored: {}", stopped.join("; "))));
    }
    let frame = ex_fine.frame;
    let ex_points = points_normalised(ex_fine);
    let variant_points: Vec<Vec<Vec3>> = variants.iter().map(|v| points_normalised(&v.finest)).collect();
    let margin = metrics::DEFAULT_MARGIN;
    // The union of the shapes' boxes, clipped to the exemplar's box plus one
    // normalised unit (half its diagonal) on each side: a stray point of a
    // diverged variant must not make the lattice huge.
    let clip = |(lo, hi): (Vec3, Vec3), (elo, ehi): (Vec3, Vec3)| (lo.max(elo - Vec3::ONE), hi.min(ehi + Vec3::ONE));
    let (grid, filled) = match (mode, exemplar_mesh) {
        (Voxelisation::Solid, Some(m)) => {
            let ex_box = mesh_bounds(m, frame)
                .ok_or_else(|| Error::Invalid("the exemplar mesh has no finite vertex".into()))?;
            let all = variants.iter().filter_map(|v| v.mesh.as_ref()).fold(Some(ex_box), |b, vm| union(b, mesh_bounds(vm, frame)));
            let (lo, hi) = clip(all.unwrap_or(ex_box), ex_box);
            let voxel = (ex_box.1 - ex_box.0).max_element() / resolution.max(1) as f32;
            // Anchored at the exemplar's box, so its voxelisation is the same
            // whatever variants are evaluated with it.
            (OccupancyGrid::covering(frame, lo, hi, voxel, margin, Some(ex_box.0)), m.is_closed())
        }
        _ => {
            let ex_box = bounds(&ex_points).ok_or_else(|| Error::file(exemplar_dir, "the finest level has no finite point"))?;
            let all = variant_points.iter().fold(Some(ex_box), |b, p| union(b, bounds(p)));
            let (lo, hi) = clip(all.unwrap_or(ex_box), ex_box);
            // Aligned with the finest level's grid lines (-1 + k * voxel).
            let voxel = ex_fine.voxel_size() as f32;
            (OccupancyGrid::covering(frame, lo, hi, voxel, margin, Some(Vec3::splat(-1.0))), false)
        }
    };
    let half = grid.halved();
    let voxelise = |mesh: Option<&Mesh>, points: &[Vec3], g: &OccupancyGrid| -> Occupancy {
        match (mode, mesh) {
            (Voxelisation::Solid, Some(m)) if filled => metrics::voxelise_mesh(m, g),
            (Voxelisation::Solid, Some(m)) => metrics::voxelise_mesh_surface(m, g),
            _ => metrics::voxelise_normalised_points(points, g),
        }
    };
    let ex_occ = [voxelise(exemplar_mesh, &ex_points, &grid), voxelise(exemplar_mesh, &ex_points, &half)];
    let occs: Vec<[Occupancy; 2]> = variants
        .iter()
        .zip(&variant_points)
        .map(|(v, p)| [voxelise(v.mesh.as_ref(), p, &grid), voxelise(v.mesh.as_ref(), p, &half)])
        .collect();
    let coarse: Vec<Vec<Vec3>> = variants.iter().map(|v| points_normalised(&v.coarsest)).collect();
    let ex_coarse_pts = points_normalised(ex_coarse);
    // The exemplar's structure level bent as each bent variant's start was.
    let bent: Vec<Option<Level>> =
        variants.iter().map(|v| v.bend.zip(ex_structure).map(|(b, l)| b.bent(&levels, l.index))).collect();
    // And at the extent of each resized variant's box.
    let at_extent: Vec<Option<([f32; 3], Level)>> = variants
        .iter()
        .map(|v| match (v.extent, ex_structure) {
            (Some(e), Some(l)) if v.bend.is_none() => e.of(&levels, l.index).map(|at| Some((e.extent, at))),
            _ => Ok(None),
        })
        .collect::<Result<_>>()?;
    // And its fine level, to compare each variant's with (bent likewise).
    let ex_fine_level = crate::judge::fine_level(&levels);
    let fine_references: Vec<Option<std::borrow::Cow<Level>>> = variants
        .iter()
        .map(|v| {
            let ex = ex_fine_level?;
            Some(match v.bend {
                Some(b) => std::borrow::Cow::Owned(b.bent(&levels, ex.index)),
                None => std::borrow::Cow::Borrowed(ex),
            })
        })
        .collect();
    let exemplar = ShapeInput {
        name: "exemplar".into(),
        occupancy: &ex_occ[0],
        occupancy_22: &ex_occ[1],
        finest: ex_fine,
        coarse_points: Some(&ex_coarse_pts),
        structure_level: ex_structure,
        bent_reference: None,
        at_extent: None,
        level0: None,
        fine_level: None,
    };
    let inputs: Vec<ShapeInput> = variants
        .iter()
        .zip(&occs)
        .zip(&coarse)
        .zip(&bent)
        .zip(&fine_references)
        .zip(&at_extent)
        .map(|(((((v, occ), c), b), fr), ae)| ShapeInput {
            name: v.name.clone(),
            occupancy: &occ[0],
            occupancy_22: &occ[1],
            finest: &v.finest,
            coarse_points: Some(c),
            structure_level: v.structure.as_ref(),
            bent_reference: b.as_ref(),
            at_extent: ae.as_ref().map(|(e, l)| (*e, l)),
            level0: (v.bend.is_none() && ae.is_none() && v.coarsest.index == 0).then_some((&v.coarsest, &levels[0])),
            fine_level: v.fine.as_ref().zip(fr.as_deref()),
        })
        .collect();
    metrics::check_shape(&exemplar)
        .map_err(|e| Error::file(exemplar_dir, format!("the exemplar cannot be scored: {e}")))?;
    // A degenerate variant (empty, or filling the lattice) is reported, not
    // scored: a score for it would be meaningless, and the rest still count.
    let (inputs, unscored): (Vec<ShapeInput>, Vec<ShapeInput>) =
        inputs.into_iter().partition(|v| metrics::check_shape(v).is_ok());
    let mut unscored: Vec<String> = unscored.iter().filter_map(|v| metrics::check_shape(v).err()).map(|e| e.to_string()).collect();
    unscored.extend(stopped);
    for u in &unscored {
        log::warn!("eval: not scored: {u}");
    }
    if inputs.is_empty() {
        return Err(Error::Invalid(format!("no variant can be scored: {}", unscored.join("; "))));
    }
    let report = metrics::evaluate(&exemplar, &inputs, &EvalParams::default())?;
    Ok(Evaluation { lattice: Lattice { voxelisation: mode, filled, dims: grid.dims, voxel: grid.voxel }, unscored, report })
}
