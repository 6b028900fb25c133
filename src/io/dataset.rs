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
    /// Level files under the second folder only.
    pub only_in_b: usize,
}

impl LevelComparison {
    /// Files of the first folder found the same in the second.
    pub fn identical(&self) -> usize {
        self.compared - (self.differences.len() - self.only_in_b)
    }

    /// The `compare` command's exit status: 0 when level files were compared
    /// and none differs, else 1 (no level file at all proves nothing).
    pub fn exit_status(&self) -> u8 {
        u8::from(!(self.differences.is_empty() && self.compared > 0))
    }
}

/// `N level files compared: M identical`, then one line per difference.
impl std::fmt::Display for LevelComparison {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "{} level files compared: {} identical", self.compared, self.identical())?;
        self.differences.iter().try_for_each(|d| writeln!(f, "  differs: {d}"))
    }
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
            report.only_in_b += 1;
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

/// What a variant folder records of how its start was made, beside its
/// levels: the bend of a bent variant ([`crate::level::warp::BEND_FILE`])
/// and the extent of one sampled in a resized box
/// ([`crate::level::resize::EXTENT_FILE`]). Eval and the studio judge a
/// variant against the exemplar made the same way.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StartRecord {
    pub bend: Option<crate::level::warp::Bend>,
    pub extent: Option<crate::level::resize::Extent>,
}

impl StartRecord {
    /// Reads a variant folder's records; none is the exemplar's own start. A
    /// record that does not parse, or whose values are out of range, is an
    /// error naming its file.
    pub fn read(dir: &Path) -> Result<Self> {
        let bend: Option<crate::level::warp::Bend> = read_record(dir, crate::level::warp::BEND_FILE, "a bend record")?;
        if let Some(b) = bend {
            let max = crate::level::warp::MAX_BEND_VOXELS;
            if !(b.voxels.is_finite() && (0.0..=max).contains(&(b.voxels as f64))) {
                let path = dir.join(crate::level::warp::BEND_FILE);
                return Err(Error::file(&path, format!("bend of {} voxels: a bend is 0 to {max} level-0 voxels", b.voxels)));
            }
        }
        let extent: Option<crate::level::resize::Extent> = read_record(dir, crate::level::resize::EXTENT_FILE, "an extent record")?;
        if let Some(e) = extent {
            if e.extent.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                let path = dir.join(crate::level::resize::EXTENT_FILE);
                return Err(Error::file(&path, format!("extent {}: each scale must be a positive number", e)));
            }
        }
        Ok(Self { bend, extent: extent.filter(|e| !e.is_same()) })
    }

    /// Writes the records into a variant folder, and removes a stale one
    /// where this start has none.
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_record(dir, crate::level::warp::BEND_FILE, self.bend.as_ref())?;
        write_record(dir, crate::level::resize::EXTENT_FILE, self.extent.as_ref())
    }
}

/// A JSON record `file` in `dir`, if there is one; one that does not parse
/// as `what` is an error naming the file.
fn read_record<T: serde::de::DeserializeOwned>(dir: &Path, file: &str, what: &str) -> Result<Option<T>> {
    let path = dir.join(file);
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| Error::file(&path, e.to_string()))?;
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| Error::file(&path, format!("not {what}: {}", crate::error::one_line(&e.to_string()))))
}

/// Writes `record` as JSON `file` in `dir`, or removes a stale file where
/// there is no record.
fn write_record<T: Serialize>(dir: &Path, file: &str, record: Option<&T>) -> Result<()> {
    let path = dir.join(file);
    match record {
        Some(r) => {
            let text = serde_json::to_string_pretty(r).map_err(|e| Error::file(&path, e.to_string()))?;
            write_file(&path, text.as_bytes())
        }
        None if path.exists() => std::fs::remove_file(&path).map_err(|e| Error::file(&path, e.to_string())),
        None => Ok(()),
    }
}

#[cfg(test)]
mod start_record_tests {
    use super::*;
    use crate::level::resize::{Extent, EXTENT_FILE};
    use crate::level::warp::{Bend, BEND_FILE};

    #[test]
    fn start_records_round_trip_a_stale_one_is_removed_and_a_broken_one_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(StartRecord::read(dir.path()).unwrap(), StartRecord::default());
        let made = StartRecord { bend: Some(Bend { seed: 42, voxels: 2.0 }), extent: Some(Extent { extent: [1.5, 1.0, 1.0] }) };
        made.write(dir.path()).unwrap();
        assert_eq!(StartRecord::read(dir.path()).unwrap(), made);
        // Written again without records: the stale files go.
        StartRecord::default().write(dir.path()).unwrap();
        assert!(!dir.path().join(BEND_FILE).exists() && !dir.path().join(EXTENT_FILE).exists());
        // The exemplar's own extent reads as none.
        std::fs::write(dir.path().join(EXTENT_FILE), "{\"extent\": [1, 1, 1]}").unwrap();
        assert_eq!(StartRecord::read(dir.path()).unwrap().extent, None);
        for (file, text, says) in [
            (BEND_FILE, "{\"seed\": 42", "not a bend record"),
            (BEND_FILE, "{\"seed\": 42, \"voxels\": 1e38}", "0 to 4"),
            (EXTENT_FILE, "[1.5]", "not an extent record"),
            (EXTENT_FILE, "{\"extent\": [1.5, -1, 1]}", "positive number"),
        ] {
            let other = if file == BEND_FILE { EXTENT_FILE } else { BEND_FILE };
            let _ = std::fs::remove_file(dir.path().join(other));
            std::fs::write(dir.path().join(file), text).unwrap();
            let e = StartRecord::read(dir.path()).unwrap_err().to_string();
            assert!(e.contains(file) && e.contains(says) && !e.contains('\n'), "{e}");
            std::fs::remove_file(dir.path().join(file)).unwrap();
        }
    }
}

#[cfg(test)]
mod compare_tests {
    use super::*;

    #[test]
    fn compare_counts_identical_files_of_the_first_folder_whatever_the_second_adds() {
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let level = crate::testing::synthetic::sphere_levels(&[16], glam::DVec3::ZERO, 0.5).remove(0);
        let write = |dir: &Path, k: usize| {
            vdb::write_level(&dir.join(level_file_name(k)), &level, &Provenance::default(), WriteOptions::default()).unwrap()
        };
        write(a.path(), 0);
        write(b.path(), 0);
        for k in 1..4 {
            write(b.path(), k);
        }
        let r = compare_levels(a.path(), b.path()).unwrap();
        assert_eq!((r.compared, r.identical(), r.only_in_b, r.differences.len()), (1, 1, 3, 3));
        // A file missing from the second folder is not identical.
        write(a.path(), 5);
        let r = compare_levels(a.path(), b.path()).unwrap();
        assert_eq!((r.compared, r.identical()), (2, 1));
    }
}
