//! What the files of a run folder are: the names the mesh and USD steps
//! write, and a tag for every file a run or `sample` leaves, so a task graph
//! (Houdini's TOPs, a shell loop) can pick outputs by kind from `--json`.

use std::path::{Path, PathBuf};

use serde::Serialize;

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
/// A variant's own USD layer.
pub const VARIANT_USD: &str = "variant.usda";
/// The run's USD asset, one variant set over the variant layers.
pub const ASSET_USD: &str = "variants.usda";

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
    let level = |suffix: &str| {
        name.strip_prefix("level_").and_then(|r| r.strip_suffix(suffix)).is_some_and(|k| k.parse::<usize>().is_ok())
    };
    Some(match name {
        _ if level(".vdb") => FileKind::LevelVolume,
        _ if level(".points.vdb") => FileKind::LevelPoints,
        MESH_PLY | MESH_GLB | MESH_OBJ | "exemplar.ply" => FileKind::Mesh,
        MESH_MTL | MESH_TEXTURE => FileKind::MeshTexture,
        _ if name.ends_with(".usda") => FileKind::Usd,
        "report.html" => FileKind::Report,
        "eval.json" => FileKind::Eval,
        _ if name.ends_with(".png") => FileKind::Preview,
        _ if name.ends_with(".safetensors") => FileKind::Model,
        "config.toml" | "manifest.json" => FileKind::Record,
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
            let level = name.strip_prefix("level_").and_then(|r| r.split('.').next()).and_then(|k| k.parse().ok());
            let variant = path
                .parent()
                .and_then(|p| p.file_name())
                .and_then(|n| n.to_str())
                .filter(|n| n.starts_with("variant_"))
                .map(str::to_string);
            found.push(OutputFile { path, kind, level, variant, bytes: meta.len() });
        }
    }
    found.sort_by(|a, b| a.path.cmp(&b.path));
    found
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
