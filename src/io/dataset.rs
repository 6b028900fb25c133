//! An encoded exemplar on disk: one level file per level (`level_0.vdb`
//! coarsest first) and `manifest.json` (levels, resolutions, normalisation,
//! source mesh digest, encoding options and timings), optionally a preview PNG
//! per level. This is what `encode` writes and `train` reads.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::util::fs::write_file;
use crate::level::Level;
use crate::io::exemplar::Exemplar;
use crate::io::mesh::Mesh;
use crate::io::vdb::{self, Provenance, WriteOptions};

pub const MANIFEST: &str = "manifest.json";

/// How the levels were made, as the manifest records it.
#[derive(Clone, Debug, PartialEq)]
pub struct Encoding {
    pub sampling_resolution: u32,
    pub pooling: crate::level::Pooling,
    /// Seconds by encoding step.
    pub seconds: std::collections::BTreeMap<String, f64>,
}

/// Writes a level's preview picture to the path given (the renderer sits
/// above this layer: the caller passes it in).
pub type Preview<'a> = &'a dyn Fn(&Level, &Path) -> Result<()>;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelEntry {
    pub index: usize,
    pub resolution: u32,
    pub voxels: usize,
    pub file: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub creator: String,
    /// Stem of the exemplar's file name.
    pub exemplar: String,
    /// The mesh file as given, or "(embedded)" for the demo exemplar.
    pub source: String,
    /// SHA-256 of the source file's bytes (or of the generated mesh).
    pub source_sha256: String,
    pub triangles: usize,
    /// Points of a point-cloud exemplar (vertices of a mesh).
    #[serde(default)]
    pub points: usize,
    /// The exemplar's coordinate reference system, where its file named one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crs: Option<String>,
    /// The exemplar has boundary edges (meshing then prefers APSS).
    pub open_surface: bool,
    /// Normalisation: world = centre + normalised / scale.
    pub centre: [f64; 3],
    pub scale: f64,
    pub sampling_resolution: u32,
    pub pooling: crate::level::Pooling,
    pub levels: Vec<LevelEntry>,
    /// Wall seconds per encoding stage.
    pub seconds: std::collections::BTreeMap<String, f64>,
}

/// SHA-256 (hex) of a file's bytes.
pub fn file_sha256(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
    Ok(crate::util::digest::sha256(&bytes))
}

/// SHA-256 (hex) of a mesh's geometry and colours, for generated meshes.
pub fn mesh_sha256(mesh: &Mesh) -> String {
    use sha2::{Digest, Sha256};
    // Streamed: a mesh of millions of triangles is not copied to be hashed.
    let mut h = Sha256::new();
    mesh.positions.iter().flat_map(|p| p.to_array()).for_each(|v| h.update(v.to_le_bytes()));
    mesh.triangles.iter().flatten().for_each(|v| h.update(v.to_le_bytes()));
    if let crate::io::mesh::MeshColours::PerVertex(c) = &mesh.colours {
        c.iter().flat_map(|p| p.to_array()).for_each(|v| h.update(v.to_le_bytes()));
    }
    crate::util::digest::hex(&h.finalize())
}


pub use crate::level::files::level_file_name;

/// Writes levels, manifest and (optionally) previews into `dir`, which is
/// created if needed. The manifest is written last: a folder with a manifest
/// is complete.
#[allow(clippy::too_many_arguments)]
pub fn write(
    dir: &Path,
    exemplar: &Exemplar,
    source: &str,
    source_sha256: &str,
    levels: &[Level],
    encoding: &Encoding,
    preview: Option<Preview>,
    write: WriteOptions,
) -> Result<Manifest> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, format!("cannot create folder: {e}")))?;
    let open_surface = exemplar.is_open();
    let provenance = Provenance { exemplar: exemplar.name().to_string(), exemplar_open: open_surface, crs: exemplar.crs(), ..Default::default() };
    let mut entries = Vec::new();
    for level in levels {
        let file = level_file_name(level.index);
        vdb::write_level(&dir.join(&file), level, &provenance, write)?;
        if let Some(preview) = preview {
            preview(level, &dir.join(crate::level::files::preview_file_name(level.index)))?;
        }
        entries.push(LevelEntry { index: level.index, resolution: level.resolution, voxels: level.len(), file });
    }
    let frame = levels.first().map(|l| l.frame).unwrap_or_default();
    let manifest = Manifest {
        creator: vdb::CREATOR.into(),
        exemplar: exemplar.name().to_string(),
        source: source.into(),
        source_sha256: source_sha256.into(),
        triangles: exemplar.counts().0,
        points: exemplar.counts().1,
        crs: exemplar.crs(),
        open_surface,
        centre: frame.centre.to_array(),
        scale: frame.scale,
        sampling_resolution: encoding.sampling_resolution,
        pooling: encoding.pooling,
        levels: entries,
        seconds: encoding.seconds.clone(),
    };
    let path = dir.join(MANIFEST);
    let text = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
    write_file(&path, &text)?;
    Ok(manifest)
}

/// Reads a folder written by [`write`]: its manifest and its levels.
pub fn read(dir: &Path) -> Result<(Manifest, Vec<Level>)> {
    let manifest = read_manifest(dir)?;
    let mut levels = Vec::with_capacity(manifest.levels.len());
    for e in &manifest.levels {
        let (level, _) = vdb::read_level(&dir.join(&e.file))?;
        levels.push(level);
    }
    Ok((manifest, levels))
}

pub fn read_manifest(dir: &Path) -> Result<Manifest> {
    let path: PathBuf = dir.join(MANIFEST);
    if !dir.is_dir() {
        return Err(Error::file(dir, "no such folder (expected the output of `shapeshifter encode`)"));
    }
    let text = std::fs::read_to_string(&path)
        .map_err(|_| Error::file(dir, "has no manifest.json (expected the output of `shapeshifter encode`)"))?;
    serde_json::from_str(&text).map_err(|e| Error::file(&path, format!("invalid manifest: {e}")))
}

/// What [`compare_levels`] found.
#[derive(Clone, Debug, Default)]
pub struct LevelComparison {
    /// Level files found under the first folder.
    pub compared: usize,
    /// One line per file that is missing from the second folder or differs.
    pub differences: Vec<String>,
}

/// Every `level_K.vdb` under `a` (recursively) against the file at the same
/// relative path under `b`: the same voxels, offsets, normals, colours and
/// mask, bit for bit (the files themselves differ: OpenVDB writes a fresh
/// UUID into each).
pub fn compare_levels(a: &Path, b: &Path) -> Result<LevelComparison> {
    fn walk(dir: &Path, out: &mut Vec<std::path::PathBuf>) -> Result<()> {
        let mut entries: Vec<_> = std::fs::read_dir(dir)
            .map_err(|e| Error::file(dir, e.to_string()))?
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .collect();
        entries.sort();
        for p in entries {
            if p.is_dir() && !p.is_symlink() {
                walk(&p, out)?;
            } else if p.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                // Points files hold the same points as their level file's volumes.
                crate::level::files::parse(n).is_some_and(|(_, kind)| kind == crate::level::files::LevelFile::Volumes)
            }) {
                out.push(p);
            }
        }
        Ok(())
    }
    let mut files = Vec::new();
    walk(a, &mut files)?;
    let mut in_b = Vec::new();
    walk(b, &mut in_b)?;
    let mut report = LevelComparison { compared: files.len(), ..Default::default() };
    for fa in files {
        let rel = fa.strip_prefix(a).unwrap_or(&fa).to_path_buf();
        let fb = b.join(&rel);
        if !fb.is_file() {
            report.differences.push(format!("{}: missing from {}", rel.display(), b.display()));
            continue;
        }
        let (la, _) = crate::io::vdb::read_level(&fa)?;
        let (lb, _) = crate::io::vdb::read_level(&fb)?;
        let bits = |v: &[glam::Vec3]| v.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<u32>>();
        let same = la.resolution == lb.resolution
            && la.coords == lb.coords
            && bits(&la.offsets) == bits(&lb.offsets)
            && bits(&la.normals) == bits(&lb.normals)
            && bits(&la.colours) == bits(&lb.colours)
            && la.mask.iter().map(|m| m.to_bits()).eq(lb.mask.iter().map(|m| m.to_bits()));
        if !same {
            report.differences.push(format!("{}: {} vs {} voxels, features differ", rel.display(), la.len(), lb.len()));
        }
    }
    for fb in in_b {
        let rel = fb.strip_prefix(b).unwrap_or(&fb).to_path_buf();
        if !a.join(&rel).is_file() {
            report.differences.push(format!("{}: only in {}", rel.display(), b.display()));
        }
    }
    Ok(report)
}

/// Writes one variant's levels (and previews) into its folder.
pub fn write_variant(dir: &Path, levels: &[Level], provenance: &Provenance, preview: Option<Preview>, write: WriteOptions) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    // What an earlier sampling left (levels that are now empty, a mesh of
    // other levels) must not be read as part of this variant.
    for e in std::fs::read_dir(dir).map_err(|e| Error::file(dir, e.to_string()))?.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let stale = crate::level::files::is_level_file(&name)
            || name.starts_with("mesh.")
            || name.starts_with("stage_");
        if stale {
            std::fs::remove_file(e.path()).map_err(|err| Error::file(&e.path(), err.to_string()))?;
        }
    }
    for level in levels {
        if level.is_empty() {
            log::warn!("{}: level {} is empty after pruning", dir.display(), level.index);
            continue;
        }
        vdb::write_level(&dir.join(level_file_name(level.index)), level, provenance, write)?;
        if let Some(preview) = preview {
            preview(level, &dir.join(crate::level::files::preview_file_name(level.index)))?;
        }
    }
    Ok(())
}
