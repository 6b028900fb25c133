//! The USD step: each variant folder's `variant.usda` (its mesh, its finest
//! level's points, its level files as volumes) and the run's
//! `variants.usda`, an asset with one variant set over them
//! ([`crate::io::usd`] describes and encodes them; `.usdc` instead with
//! `output.usd_format = "usdc"`). Read from the files the other
//! stages wrote, so `run`, `stage mesh` and the `usd` command for an
//! existing run folder take this one path.

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::error::{Error, Result};
use crate::io::usd::{self, LevelVolume, MeshPrim, PointsPrim, StageMetadata, UsdFormat, VariantLayer};
use crate::io::{mesh, vdb};

use super::stamp::StampOf;
use super::RunPaths;
use super::layout::{asset_usd, variant_dir, variant_usd, MESH_OBJ, MESH_PLY, MESH_TEXTURE};

/// What a variant's USD layer depends on (its stamp's digest): the variant's
/// sample stamp, its mesh stamp with the mesh's time, the units, the name.
#[derive(serde::Serialize)]
struct UsdInputs<'a> {
    sampled: &'a str,
    meshed: &'a str,
    meters_per_unit: f64,
    exemplar: &'a str,
    /// Absent (text) in the digests written before binary layers.
    #[serde(skip_serializing_if = "is_text")]
    format: UsdFormat,
}

fn is_text(f: &UsdFormat) -> bool {
    *f == UsdFormat::Usda
}

/// Removes the layer of the other encoding `name` (e.g. `variant.usdc`
/// when writing `variant.usda`): a run folder holds one asset, whose layers
/// are those it references.
fn remove_other_encoding(dir: &Path, format: UsdFormat, name: impl Fn(UsdFormat) -> String) {
    for other in [UsdFormat::Usda, UsdFormat::Usdc] {
        if other != format {
            let _ = std::fs::remove_file(dir.join(name(other)));
        }
    }
}

/// What the variant layer holds, for the log and `--json` (counts 0 where
/// the layer was reused as it was).
#[derive(Clone, Debug, serde::Serialize)]
pub struct VariantUsd {
    pub path: PathBuf,
    pub triangles: usize,
    pub textured: bool,
    pub points: usize,
    pub levels: usize,
}

/// Stage metadata of a run's layers: the exemplar's up axis (from its finest
/// level), `meters_per_unit`, and who wrote it from what.
pub fn metadata(up: crate::level::Up, meters_per_unit: f64, exemplar: &str) -> StageMetadata {
    StageMetadata { up, meters_per_unit, doc: format!("{}: variants of {exemplar}", vdb::CREATOR) }
}

/// Writes `dir/variant.usda` (or `.usdc`) from the folder's files: the textured
/// `mesh.obj` where there is one, else `mesh.ply`, else no mesh; the finest
/// level's points; every `level_K.vdb` as a choice of the volume's `level`
/// set. None (and no layer) for a variant whose finest level has no surface
/// voxels (pruned to nothing). Errors: no level files, a file that does not
/// read, the layer not written.
pub fn write_variant(dir: &Path, meters_per_unit: f64, exemplar: &str, format: UsdFormat) -> Result<Option<VariantUsd>> {
    let files = crate::eval::evaluate::level_files(dir)?;
    let mut levels = Vec::with_capacity(files.len());
    let mut finest = None;
    for (k, path) in &files {
        let (level, _) = vdb::read_level(path)?;
        let points = crate::level::Level::surface_points(&level);
        let (lo, hi) = usd::bounds_of(&points.positions);
        let half = Vec3::splat(points.spacing * 0.5);
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        levels.push(LevelVolume { index: *k, file: format!("./{name}"), bounds: (lo - half, hi + half) });
        finest = Some((level, points));
    }
    let (finest, mut points) = finest.expect("level_files returns at least one");
    if points.is_empty() {
        let _ = std::fs::remove_file(dir.join(variant_usd(format)));
        return Ok(None);
    }
    points.normals.iter_mut().for_each(|n| *n = n.normalize_or_zero());

    let obj = dir.join(MESH_OBJ);
    let ply = dir.join(MESH_PLY);
    let m = if obj.is_file() && dir.join(MESH_TEXTURE).is_file() {
        Some(mesh::load(&obj)?)
    } else if ply.is_file() {
        Some(mesh::load(&ply)?)
    } else {
        None
    };
    let normals = m.as_ref().map(|m| m.vertex_normals()).unwrap_or_default();
    let colours = m.as_ref().and_then(|m| m.vertex_colours());
    let mesh_prim = m.as_ref().map(|m| MeshPrim {
        positions: &m.positions,
        triangles: &m.triangles,
        normals: &normals,
        colours: colours.as_deref(),
        texture: m.texture.as_ref().filter(|t| t.uvs.len() == 3 * m.triangles.len()).map(|t| (t.uvs.as_slice(), format!("./{MESH_TEXTURE}"))),
    });
    let layer = VariantLayer {
        mesh: mesh_prim,
        points: Some(PointsPrim {
            positions: &points.positions,
            normals: &points.normals,
            colours: &points.colours,
            width: points.spacing,
        }),
        levels,
    };
    let bytes = format.encode(&usd::variant_layer(&layer, &metadata(finest.frame.up, meters_per_unit, exemplar)));
    let path = dir.join(variant_usd(format));
    crate::util::fs::write_file(&path, bytes)?;
    remove_other_encoding(dir, format, variant_usd);
    Ok(Some(VariantUsd {
        path,
        triangles: m.as_ref().map_or(0, |m| m.triangles.len()),
        textured: layer.mesh.as_ref().is_some_and(|m| m.texture.is_some()),
        points: points.len(),
        levels: layer.levels.len(),
    }))
}

/// Writes `root/variants.usda` (or `.usdc`) over the variant folders in
/// `dirs` that hold a layer of that encoding; the first is the default
/// selection. The asset prim is named after the exemplar.
pub fn write_asset(root: &Path, dirs: &[PathBuf], exemplar: &str, up: crate::level::Up, meters_per_unit: f64, format: UsdFormat) -> Result<PathBuf> {
    let layer_name = variant_usd(format);
    let variants: Vec<(String, String)> = dirs
        .iter()
        .filter(|d| d.join(&layer_name).is_file())
        .filter_map(|d| {
            let rel = d.strip_prefix(root).ok()?;
            let name = d.file_name()?.to_string_lossy().into_owned();
            Some((name, format!("./{}/{layer_name}", rel.to_string_lossy())))
        })
        .collect();
    let Some((default, _)) = variants.first() else {
        return Err(Error::file(root, format!("no variant folder holds a {layer_name}: nothing for the USD asset to select")));
    };
    let layer = usd::asset_layer(exemplar, &variants, &usd::identifier(default), &metadata(up, meters_per_unit, exemplar));
    let path = root.join(asset_usd(format));
    crate::util::fs::write_file(&path, format.encode(&layer))?;
    remove_other_encoding(root, format, asset_usd);
    Ok(path)
}

/// What the USD step wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct UsdOutcome {
    pub asset: PathBuf,
    pub variants: Vec<VariantUsd>,
}

/// `ASSET (N variant layers)`: what `usd`, `stage usd` and `run`'s log say.
impl std::fmt::Display for UsdOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({} variant layers)", self.asset.display(), self.variants.len())
    }
}

/// What a user asks of the `usd` command.
pub struct UsdRequest<'a> {
    /// A run folder.
    pub dir: &'a Path,
    /// None: the run's `output.meters_per_unit`.
    pub meters_per_unit: Option<f64>,
    /// None: the run's `output.usd_format`.
    pub format: Option<UsdFormat>,
    /// Wait for another writer of the folder instead of refusing at once.
    pub wait: bool,
}

/// The `usd` command: the USD asset of every variant folder of a run
/// ([`run_usd`]). The folder must be a run (its configuration is read
/// before its lock is taken, so nothing is made in a wrong folder); a
/// meters-per-unit that is not a positive number is [`Error::Usage`].
pub fn usd_command(r: &UsdRequest) -> Result<UsdOutcome> {
    let paths = RunPaths::existing(r.dir)?;
    let config = paths.read_config()?;
    let _lock = crate::util::lock::lock(r.dir, crate::util::lock::Mode::Exclusive, r.wait, "usd")?;
    let mpu = r.meters_per_unit.unwrap_or(config.output.meters_per_unit);
    if !(mpu.is_finite() && mpu > 0.0) {
        return Err(Error::Usage(format!("--meters-per-unit {mpu}: expected a positive number")));
    }
    run_usd(&paths, None, mpu, r.format.unwrap_or(config.output.usd_format))
}

/// The USD step over the finished variant folders in `dirs`: each one's
/// `variant.usda` (reused when its levels, its mesh and `meters_per_unit`
/// are those it was written from), then `root/variants.usda`.
pub fn usd_stage(root: &Path, dirs: &[PathBuf], exemplar: &str, meters_per_unit: f64, format: UsdFormat) -> Result<UsdOutcome> {
    let mut variants = Vec::new();
    // The up axis every level of a run shares: from a coarsest level (small).
    let up = dirs
        .iter()
        .find_map(|d| crate::eval::evaluate::level_files(d).ok())
        .and_then(|files| vdb::read_level(&files[0].1).ok())
        .map(|(l, _)| l.frame.up)
        .unwrap_or_default();
    // Variants' layers are independent (each reads its own folder's files):
    // written on every core, told in the variants' order.
    use rayon::prelude::*;
    let layers: Vec<Result<Option<VariantUsd>>> = dirs
        .par_iter()
        .map(|dir| {
            crate::util::interrupt::check()?;
            let t = std::time::Instant::now();
            let Some(sampled) = super::stamp::read_stamp(dir, StampOf::Sample) else {
                log::warn!("{}: its sampling did not finish: not in the USD asset", dir.display());
                return Ok(None);
            };
            // The mesh stamp's digest names the mesh's inputs, its time names
            // this very mesh (a mesh made again from the same inputs by another
            // program version is a new file the layer must be read from).
            let mesh_stamp = super::stamp::stamp_path(dir, StampOf::Mesh);
            let meshed = match (super::stamp::read_stamp(dir, StampOf::Mesh), std::fs::metadata(&mesh_stamp).and_then(|m| m.modified())) {
                (Some(s), Ok(t)) => format!("{} {:?}", s.digest, t),
                _ => String::new(),
            };
            let d = super::stamp::digest_of(&UsdInputs { sampled: &sampled.digest, meshed: &meshed, meters_per_unit, exemplar, format });
            if super::stamp::is_done(dir, StampOf::Usd, &d) && dir.join(variant_usd(format)).is_file() {
                // Reused: its summary is what the layer holds (read cheaply from the stamp's files).
                return Ok(Some(VariantUsd { path: dir.join(variant_usd(format)), triangles: 0, textured: dir.join(MESH_TEXTURE).is_file(), points: 0, levels: 0 }));
            }
            // A variant pruned to nothing has no layer (a warning); any other
            // failure (a full disk, an unreadable file) is the step's error.
            match write_variant(dir, meters_per_unit, exemplar, format)? {
                Some(v) => {
                    super::stamp::mark_done(dir, StampOf::Usd, &d, t.elapsed().as_secs_f64())?;
                    Ok(Some(v))
                }
                None => {
                    log::warn!("{}: pruned to nothing: not in the USD asset", dir.display());
                    Ok(None)
                }
            }
        })
        .collect();
    for layer in layers {
        if let Some(v) = layer? {
            variants.push(v);
        }
    }
    let asset = write_asset(root, dirs, exemplar, up, meters_per_unit, format)?;
    Ok(UsdOutcome { asset, variants })
}

/// The USD step ([`usd::usd_stage`]) over variants `0..n`, or every variant
/// folder there is (None: the `usd` command on an existing run folder):
/// each sampled variant's `variant.usda`, then `OUT/variants.usda`.
pub fn run_usd(paths: &RunPaths, n: Option<usize>, meters_per_unit: f64, format: UsdFormat) -> Result<UsdOutcome> {
    let manifest = crate::io::dataset::read_manifest(&paths.exemplar())?;
    let dirs: Vec<PathBuf> = match n {
        Some(n) => (0..n).map(|i| variant_dir(&paths.variants(), i)).filter(|d| d.is_dir()).collect(),
        None => {
            let mut dirs: Vec<PathBuf> = std::fs::read_dir(paths.variants())
                .map_err(|e| Error::file(&paths.variants(), e.to_string()))?
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.is_dir() && p.file_name().is_some_and(|n| n.to_string_lossy().starts_with(super::layout::VARIANT_PREFIX)))
                .collect();
            dirs.sort();
            dirs
        }
    };
    usd_stage(&paths.root, &dirs, &manifest.exemplar, meters_per_unit, format)
}

