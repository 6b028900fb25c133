//! The library's error type: every failure names the file and the problem.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Torch(#[from] tch::TchError),
    #[error(transparent)]
    Encode(#[from] crate::encode::EncodeError),
    #[error(transparent)]
    Render(#[from] crate::render::RenderError),
}

impl Error {
    pub fn file(path: &Path, message: impl Into<String>) -> Self {
        Error::File { path: path.to_path_buf(), message: message.into() }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Checks that `path` names an existing, readable regular file.
pub fn check_input_file(path: &Path) -> Result<()> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Err(Error::file(path, "no such file"))
        }
        Err(e) => Err(Error::file(path, e.to_string())),
        Ok(m) if m.is_dir() => Err(Error::file(path, "is a directory, expected a file")),
        Ok(m) if m.len() == 0 => Err(Error::file(path, "is empty")),
        Ok(_) => Ok(()),
    }
}

/// Writes a file atomically: `write` fills a temporary path in the same
/// folder, which is renamed onto `path` only when it succeeded. On failure
/// the temporary file is removed, so no half-written output is ever left.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Err(Error::file(path, format!("folder {} does not exist", dir.display())));
    }
    let name = path
        .file_name()
        .ok_or_else(|| Error::file(path, "is not a file name"))?
        .to_string_lossy();
    // Keep the extension last: OpenMesh and image pick the format from it.
    let tmp = dir.join(format!(".{}.{}.tmp.{}", name, std::process::id(), extension_of(path)));
    let result = write(&tmp).and_then(|_| {
        std::fs::rename(&tmp, path).map_err(|e| Error::file(path, e.to_string()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

fn extension_of(path: &Path) -> String {
    path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default()
}
