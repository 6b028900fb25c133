//! Files that are either whole or absent: every output goes to a temporary
//! file in the same folder (tempfile) and is renamed onto its name only once
//! it is complete, so an interrupted or failed write never leaves a
//! half-written file, and readers (a DCC watching the folder, another array
//! task) never see one. The file is flushed to disk before the rename and
//! the folder after it.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Checks that `path` names an existing, non-empty regular file.
pub fn check_input_file(path: &Path) -> Result<()> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(Error::file(path, "no such file")),
        Err(e) => Err(Error::file(path, e.to_string())),
        Ok(m) if m.is_dir() => Err(Error::file(path, "is a directory, expected a file")),
        Ok(m) if m.len() == 0 => Err(Error::file(path, "is empty")),
        Ok(_) => Ok(()),
    }
}

/// Writes `path` atomically: `write` fills a temporary path in the same
/// folder (named `.NAME.XXXXXX.tmp.EXT`: the extension stays last because
/// OpenMesh, OpenVDB and image pick the format from it; unique across
/// processes and hosts sharing a folder), which is renamed onto `path` only
/// when `write` succeeded. On failure the temporary file is removed.
pub fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Err(Error::file(path, format!("folder {} does not exist", dir.display())));
    }
    let name = path.file_name().ok_or_else(|| Error::file(path, "is not a file name"))?.to_string_lossy();
    let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    let tmp = tempfile::Builder::new()
        .prefix(&format!(".{name}."))
        .suffix(&format!(".tmp.{ext}"))
        // As a plain create would (the umask applies): outputs are shared.
        .permissions(std::fs::Permissions::from_mode(0o666))
        .tempfile_in(&dir)
        .map_err(|e| Error::file(path, format!("cannot create a temporary file: {e}")))?;
    // A stop by signal that outlives its grace removes what is registered
    // here before the process ends (util::interrupt); tempfile removes it on
    // every other path out.
    let _registered = crate::util::interrupt::Temporary::register(tmp.path());
    write(tmp.path())?;
    // On disk before it gets its name, and the name on disk after: a power
    // cut or a crash of the machine leaves the old file or the whole new one.
    tmp.as_file().sync_all().map_err(|e| Error::file(path, format!("cannot be flushed to disk: {e}")))?;
    tmp.persist(path).map_err(|e| Error::file(path, e.error.to_string()))?;
    sync_folder(&dir).map_err(|e| Error::file(path, format!("its folder cannot be flushed to disk: {e}")))?;
    Ok(())
}

/// Whether the filesystem holding `path` has no block left for a user.
pub fn disk_is_full(path: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let Ok(c) = std::ffi::CString::new(dir.as_os_str().as_bytes()) else { return false };
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: a NUL-terminated path and a statvfs struct to fill.
    unsafe { libc::statvfs(c.as_ptr(), &mut st) == 0 && st.f_bavail == 0 }
}

/// Flushes a folder's entries (a rename into it) to disk.
pub fn sync_folder(dir: &Path) -> std::io::Result<()> {
    std::fs::File::open(dir)?.sync_all()
}

/// Writes `bytes` to `path` atomically ([`write_atomically`]).
pub fn write_file(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    write_atomically(path, |tmp| std::fs::write(tmp, bytes.as_ref()).map_err(|e| Error::file(path, e.to_string())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_writes_leave_nothing_and_good_ones_replace() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.txt");
        write_file(&target, "first").unwrap();
        let failed = write_atomically(&target, |tmp| {
            std::fs::write(tmp, "half").unwrap();
            Err(Error::Invalid("disk full".into()))
        });
        assert!(failed.is_err());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "first");
        write_file(&target, "second").unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "second");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
        let mode = std::fs::metadata(&target).unwrap().permissions().mode() & 0o777;
        assert_ne!(mode & 0o044, 0, "outputs are readable by others under a usual umask: {mode:o}");
        assert!(write_file(&dir.path().join("no/such/folder.txt"), "x").is_err());
    }
}
