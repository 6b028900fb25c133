//! FBX, COLLADA (.dae) and the other formats Assimp reads: converted to glTF
//! binary by the helper program `shapeshifter-assimp` (Assimp's importer and
//! its glTF exporter, in a process of its own under a memory limit: Assimp's
//! importers were not written against hostile files), then read by the glTF
//! reader, which resolves the textures the file names beside it.

use std::ffi::OsStr;
use std::path::Path;
use std::time::Duration;

use crate::error::{Error, Result};
use crate::io::helper;
use crate::io::mesh_data::Mesh;

pub const ASSIMP_PROGRAM: &str = "shapeshifter-assimp";
pub const ASSIMP_ENV: &str = "SHAPESHIFTER_ASSIMP";

/// Formats read through Assimp, by extension.
pub const EXTENSIONS: &[&str] = &["fbx", "dae"];

/// The converter's address-space limit: 1 GiB for Assimp and its libraries,
/// plus 64 bytes per byte of input.
fn memory_limit(bytes: u64) -> u64 {
    (1u64 << 30).saturating_add(bytes.saturating_mul(64))
}

/// Reads `path` (FBX or COLLADA) as a mesh, through the converter.
pub fn load(path: &Path) -> Result<Mesh> {
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let program = helper::find(ASSIMP_PROGRAM, ASSIMP_ENV, "read FBX or COLLADA files")?;
    let scratch = tempfile::tempdir().map_err(|e| Error::file(path, format!("cannot make a scratch folder ({e})")))?;
    let glb = scratch.path().join("converted.glb");
    let limit = Duration::from_millis(30_000 + bytes / 1_000);
    let memory = memory_limit(bytes).to_string();
    let args = [path.as_os_str(), glb.as_os_str(), OsStr::new(&memory)];
    let ended = helper::run(&program, "the Assimp converter", &args, path, limit, "Assimp")?;
    use std::os::unix::process::ExitStatusExt;
    match (ended.status.code(), ended.status.signal()) {
        (_, Some(sig)) => return Err(Error::file(path, format!("Assimp crashed on it (signal {sig}): damaged file?"))),
        (Some(0), _) => {}
        (Some(1), _) => return Err(Error::file(path, ended.said)),
        (c, _) => return Err(Error::file(path, format!("the Assimp converter {} failed (exit status {c:?})", program.display()))),
    }
    let converted = std::fs::read(&glb).map_err(|e| Error::file(path, format!("the converter wrote nothing readable ({e})")))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    crate::io::gltf_read::read_bytes(&converted, dir, &name).map_err(|e| Error::file(path, format!("as converted by Assimp: {e}")))
}
