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
    #[error(transparent)]
    Grid(#[from] crate::learn::grid::GridError),
    #[error(transparent)]
    Sparse(#[from] crate::learn::sparse::SparseError),
    #[error(transparent)]
    Recon(#[from] crate::recon::ReconError),
    #[error(transparent)]
    Shape(#[from] crate::eval::metrics::DegenerateShape),
}

impl Error {
    /// The message is made one short line: C++ readers quote what they read
    /// from a damaged file (a grid type name of a million spaces, a newline)
    /// and the error must stay the one line the command line promises.
    pub fn file(path: &Path, message: impl Into<String>) -> Self {
        Error::File { path: path.to_path_buf(), message: one_line(&message.into()) }
    }
}

/// Longest message kept, in characters; longer ones are cut with an ellipsis.
const MAX_MESSAGE: usize = 300;

/// `message` with control characters as spaces, runs of whitespace collapsed
/// and at most [`MAX_MESSAGE`] characters.
pub fn one_line(message: &str) -> String {
    let mut out = String::new();
    let mut kept = 0;
    for word in message.split(|c: char| c.is_whitespace() || c.is_control()).filter(|w| !w.is_empty()) {
        if kept > 0 {
            out.push(' ');
            kept += 1;
        }
        for c in word.chars() {
            if kept == MAX_MESSAGE {
                out.push('…');
                return out;
            }
            out.push(c);
            kept += 1;
        }
    }
    out
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
/// A short hash of this machine's host name (0 when unknown).
fn host_hash() -> u32 {
    let name = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    name.trim().bytes().fold(2166136261u32, |h, b| (h ^ b as u32).wrapping_mul(16777619))
}

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
    // Unique across processes on several hosts writing one shared folder (a
    // cluster's array tasks) and across threads: pid, host, time and a counter.
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let unique = format!(
        "{}-{:x}-{:x}-{}",
        std::process::id(),
        host_hash(),
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64),
        COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    );
    let tmp = dir.join(format!(".{}.{}.tmp.{}", name, unique, extension_of(path)));
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

#[cfg(test)]
mod tests {
    #[test]
    fn messages_become_one_short_line() {
        assert_eq!(super::one_line("Grid type \n  x\r\0y  "), "Grid type x y");
        let long = super::one_line(&"ab ".repeat(1000));
        assert!(long.chars().count() <= super::MAX_MESSAGE + 1 && long.ends_with('…'), "{long}");
    }
}
