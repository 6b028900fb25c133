//! The run folder's layout: every folder and file name a run writes, and a
//! tag for every file a run or `sample` leaves, so a task graph (Houdini's
//! TOPs, a shell loop) can pick outputs by kind from `--json`.
//!
//! ```text
//! OUT/config.toml                  the resolved configuration
//! OUT/exemplar/                    encoded levels + manifest.json (+ previews)
//! OUT/models/                      checkpoints, training states, loss plots, logs
//! OUT/variants/variant_000/        level_K.vdb (+ .points.vdb), level_K.png, mesh.*, variant.usda
//! OUT/variants.usda                the USD asset: one variant set over the variant layers
//! OUT/eval.json                    metrics
//! OUT/contact_sheet.png            the exemplar and the variants, one camera
//! OUT/report.html                  everything above on one page
//! OUT/logs/                        logs of sampling/meshing child processes
//! ```
//! The level files' names are [`crate::level::files`]'s, the models'
//! [`crate::learn::checkpoint`]'s, the stage stamps [`super::stamp`]'s.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::config::Config;
use crate::error::{Error, Result};
use crate::level::files::LevelFile;
use crate::io::usd::UsdFormat;

/// The resolved configuration a run (or `sample`, or `train`'s models folder) records.
pub const CONFIG: &str = "config.toml";
/// The encoded exemplar's level folder.
pub const EXEMPLAR_DIR: &str = "exemplar";
/// Checkpoints, training states, loss plots, training logs.
pub const MODELS_DIR: &str = "models";
/// One folder per variant, `variant_NNN`.
pub const VARIANTS_DIR: &str = "variants";
pub const VARIANT_PREFIX: &str = "variant_";
/// Beside the levels of a variant kept from the studio: what made it. A
/// later sampling leaves such a folder as it is.
pub const KEPT_RECORD: &str = "studio.json";
/// The scores of the variants.
pub const EVAL_JSON: &str = "eval.json";
/// The exemplar and the variants, one camera.
pub const CONTACT_SHEET: &str = "contact_sheet.png";
pub const REPORT: &str = "report.html";
/// Logs of the sampling and meshing child processes.
pub const LOGS_DIR: &str = "logs";

/// A variant's vertex-coloured mesh.
pub const MESH_PLY: &str = "mesh.ply";
/// The same mesh as glTF binary (textured when the light mesh was baked).
pub const MESH_GLB: &str = "mesh.glb";
/// A light mesh's textured OBJ (with `mesh.mtl` and [`MESH_TEXTURE`]).
pub const MESH_OBJ: &str = "mesh.obj";
pub const MESH_MTL: &str = "mesh.mtl";
/// The baked base-colour texture (named by [`crate::io::obj::texture_path`]).
pub const MESH_TEXTURE: &str = "mesh_basecolor.png";
pub const MESH_PREVIEW: &str = "mesh.png";
/// A variant's own USD layer (`variant.usda` or `variant.usdc`).
pub fn variant_usd(format: UsdFormat) -> String {
    format!("variant.{}", format.extension())
}
/// The run's USD asset, one variant set over the variant layers
/// (`variants.usda` or `variants.usdc`).
pub fn asset_usd(format: UsdFormat) -> String {
    format!("variants.{}", format.extension())
}

/// What a file is, for scripts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FileKind {
    /// `level_K.vdb`: the level's volumes (mask, density, P, N, Cd).
    LevelVolume,
    /// `level_K.points.vdb`: its PointDataGrid.
    LevelPoints,
    /// `mesh.ply`, `mesh.glb`, `mesh.obj`, `exemplar.ply`.
    Mesh,
    /// `mesh.mtl`, `mesh_basecolor.png`: what a textured mesh names.
    MeshTexture,
    /// `variants.usda`, `variant.usda`.
    Usd,
    /// Pictures: `level_K.png`, `mesh.png`, `contact_sheet.png`, loss plots.
    Preview,
    /// `report.html`.
    Report,
    /// `eval.json`.
    Eval,
    /// Trained weights (`.safetensors`).
    Model,
    /// `config.toml`, `manifest.json`, training logs: how it was made.
    Record,
}

/// The kind of the file at `path` by its name, None for files that are
/// not outputs (stage stamps, lock files, temporary files).
pub fn kind_of(path: &Path) -> Option<FileKind> {
    let name = path.file_name()?.to_str()?;
    if name.starts_with('.') || name.starts_with("stage_") || name.ends_with(".tmp") {
        return None;
    }
    let level = crate::level::files::parse(name).map(|(_, kind)| kind);
    Some(match name {
        _ if level == Some(LevelFile::Volumes) => FileKind::LevelVolume,
        _ if level == Some(LevelFile::Points) => FileKind::LevelPoints,
        MESH_PLY | MESH_GLB | MESH_OBJ | "exemplar.ply" => FileKind::Mesh,
        MESH_MTL | MESH_TEXTURE => FileKind::MeshTexture,
        _ if name.ends_with(".usda") => FileKind::Usd,
        REPORT => FileKind::Report,
        EVAL_JSON => FileKind::Eval,
        _ if name.ends_with(".png") => FileKind::Preview,
        _ if name.ends_with(".safetensors") => FileKind::Model,
        CONFIG | crate::io::dataset::MANIFEST => FileKind::Record,
        _ if name.ends_with(".log") || name.ends_with(".csv") => FileKind::Record,
        _ => return None,
    })
}

/// A file a command wrote, with its kind.
#[derive(Clone, Debug, Serialize)]
pub struct OutputFile {
    pub path: PathBuf,
    pub kind: FileKind,
    /// The level (`level_K.*`), where the file is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub level: Option<usize>,
    /// The variant folder it is in (`variant_NNN`), if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub variant: Option<String>,
    pub bytes: u64,
}

/// Every output file under `root`, sorted by path, with its kind.
pub fn output_files(root: &Path) -> Vec<OutputFile> {
    let mut found = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for e in entries.flatten() {
            let path = e.path();
            let Ok(meta) = e.metadata() else { continue };
            if meta.is_dir() {
                stack.push(path);
                continue;
            }
            let Some(kind) = kind_of(&path) else { continue };
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            let level = crate::level::files::parse(name).map(|(k, _)| k);
            let variant = path
                .parent()
                .and_then(|p| p.file_name())
                .and_then(|n| n.to_str())
                .filter(|n| n.starts_with(VARIANT_PREFIX))
                .map(str::to_string);
            found.push(OutputFile { path, kind, level, variant, bytes: meta.len() });
        }
    }
    found.sort_by(|a, b| a.path.cmp(&b.path));
    found
}

/// The folder name of variant `i`: `variant_007`.
pub fn variant_name(i: usize) -> String {
    format!("{VARIANT_PREFIX}{i:03}")
}

pub fn variant_dir(variants_dir: &Path, i: usize) -> PathBuf {
    variants_dir.join(variant_name(i))
}

/// The folders and files of a run (see the module documentation), shared by
/// `run` (every stage in one process) and the `stage` commands (one stage per
/// process, as a cluster job runs it).
#[derive(Clone, Debug)]
pub struct RunPaths {
    pub root: PathBuf,
}

impl RunPaths {
    pub fn new(root: &Path) -> Self {
        RunPaths { root: root.to_path_buf() }
    }

    /// The run folder `root`, which must exist: a command on a run refuses
    /// a missing folder rather than make one (and a lock file in it).
    pub fn existing(root: &Path) -> Result<Self> {
        if !root.is_dir() {
            return Err(Error::file(root, "no such run folder"));
        }
        Ok(Self::new(root))
    }
    pub fn config(&self) -> PathBuf {
        self.root.join(CONFIG)
    }
    pub fn exemplar(&self) -> PathBuf {
        self.root.join(EXEMPLAR_DIR)
    }
    pub fn models(&self) -> PathBuf {
        self.root.join(MODELS_DIR)
    }
    pub fn variants(&self) -> PathBuf {
        self.root.join(VARIANTS_DIR)
    }
    pub fn eval_json(&self) -> PathBuf {
        self.root.join(EVAL_JSON)
    }
    pub fn contact_sheet(&self) -> PathBuf {
        self.root.join(CONTACT_SHEET)
    }
    pub fn report(&self) -> PathBuf {
        self.root.join(REPORT)
    }

    /// The configuration `stage encode` (or `run`) recorded in the run folder.
    pub fn read_config(&self) -> Result<Config> {
        let p = self.config();
        if !p.is_file() {
            return Err(Error::file(&self.root, "has no config.toml: run `stage encode` (or `run`) into it first"));
        }
        Config::read(&p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_output_name_has_its_kind_and_stamps_have_none() {
        let k = |n: &str| kind_of(Path::new(n));
        assert_eq!(k("v/level_3.vdb"), Some(FileKind::LevelVolume));
        assert_eq!(k("level_12.points.vdb"), Some(FileKind::LevelPoints));
        assert_eq!(k("level_x.vdb"), None);
        assert_eq!(k("mesh.obj"), Some(FileKind::Mesh));
        assert_eq!(k("mesh_basecolor.png"), Some(FileKind::MeshTexture));
        assert_eq!(k("level_2.png"), Some(FileKind::Preview));
        assert_eq!(k("variants.usda"), Some(FileKind::Usd));
        assert_eq!(k("eval.json"), Some(FileKind::Eval));
        assert_eq!(k("stage_mesh.json"), None);
        assert_eq!(k(".lock"), None);
    }

    #[test]
    fn output_files_walks_a_folder_and_names_levels_and_variants() {
        let dir = tempfile::tempdir().unwrap();
        let v = dir.path().join("variants/variant_002");
        std::fs::create_dir_all(&v).unwrap();
        for f in ["level_0.vdb", "level_1.points.vdb", "mesh.ply", "stage_mesh.json"] {
            std::fs::write(v.join(f), b"x").unwrap();
        }
        std::fs::write(dir.path().join("report.html"), b"<html>").unwrap();
        let files = output_files(dir.path());
        assert_eq!(files.len(), 4, "{files:?}");
        let l1 = files.iter().find(|f| f.kind == FileKind::LevelPoints).unwrap();
        assert_eq!((l1.level, l1.variant.as_deref()), (Some(1), Some("variant_002")));
        assert!(files.iter().any(|f| f.kind == FileKind::Report && f.variant.is_none() && f.bytes == 6));
    }
}
