//! One writer per folder: a command that writes a run folder (or a models
//! folder) holds a lock on it for its lifetime, so a second command on the
//! same folder fails at once instead of replacing the first one's files.
//!
//! The lock is flock(2) on `FOLDER/.shapeshifter.lock`, which also records
//! the holder (process id, host, command) for the error message. The kernel
//! drops a flock when its process ends, however it ends, so a killed command
//! never blocks the next. `run`, `train` and `sample` take it exclusively;
//! `stage` commands share it (a cluster's array tasks sample and mesh one
//! folder by design) but never alongside an exclusive holder. Child processes
//! of a holder work under its lock: the holder names its folders in
//! [`HELD_ENV`], which children inherit.

use std::io::{Read, Seek, Write};
use std::os::unix::io::AsRawFd;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The lock file's name inside a locked folder.
pub const LOCK_FILE: &str = ".shapeshifter.lock";
/// Folders locked by an ancestor process, separated by newlines.
pub const HELD_ENV: &str = "SHAPESHIFTER_LOCKED_FOLDERS";

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// The one writer (`run`, `train`, `sample`).
    Exclusive,
    /// One of several cooperating writers (`stage`, cluster array tasks).
    Shared,
}

/// A held lock; released when dropped (or when the process ends).
#[derive(Debug)]
pub struct FolderLock {
    _file: Option<std::fs::File>,
}

fn canonical(dir: &Path) -> PathBuf {
    dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf())
}

/// Whether an ancestor process holds `dir`'s lock for us.
fn held_by_parent(dir: &Path) -> bool {
    let me = canonical(dir);
    std::env::var(HELD_ENV).is_ok_and(|v| v.lines().any(|l| Path::new(l) == me))
}

/// Locks `dir` (created if missing) in `mode`; with `wait`, waits for the
/// holder to finish instead of failing. The error names the folder and the
/// holder.
pub fn lock(dir: &Path, mode: Mode, wait: bool, command: &str) -> Result<FolderLock> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    if held_by_parent(dir) {
        return Ok(FolderLock { _file: None });
    }
    let path = dir.join(LOCK_FILE);
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(|e| Error::file(&path, format!("cannot open the folder's lock file: {e}")))?;
    let op = match mode {
        Mode::Exclusive => libc::LOCK_EX,
        Mode::Shared => libc::LOCK_SH,
    } | if wait { 0 } else { libc::LOCK_NB };
    loop {
        // SAFETY: flock(2) on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), op) } == 0 {
            break;
        }
        let e = std::io::Error::last_os_error();
        match e.raw_os_error() {
            Some(libc::EINTR) => crate::util::interrupt::check()?,
            Some(libc::EWOULDBLOCK) => {
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                let holder = holder.trim();
                return Err(Error::file(
                    dir,
                    format!(
                        "is in use by another shapeshifter command ({}): wait for it to end, or pass --wait",
                        if holder.is_empty() { "holder unknown".to_string() } else { holder.to_string() }
                    ),
                ));
            }
            _ => return Err(Error::file(&path, format!("cannot lock the folder: {e}"))),
        }
    }
    // What is on disk now was there before this command's work began.
    crate::util::mark_command_start();
    // Who holds it, for the next command's message (shared holders: the latest).
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    let text = format!("process {} on {}, `{command}`", std::process::id(), host.trim());
    let _ = file.set_len(0);
    let _ = file.rewind();
    let _ = file.write_all(text.as_bytes());
    // Children work under this lock. (Set while the command starts, before
    // its worker threads: the environment is not safe to change beside
    // threads that read it.)
    let mut held: Vec<String> = std::env::var(HELD_ENV).map(|v| v.lines().map(String::from).collect()).unwrap_or_default();
    held.push(canonical(dir).display().to_string());
    std::env::set_var(HELD_ENV, held.join("\n"));
    Ok(FolderLock { _file: Some(file) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_writer_is_refused_and_a_dropped_lock_frees_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("run");
        let held = lock(&d, Mode::Exclusive, false, "run").unwrap();
        // flock is per open file: a second open in this process conflicts
        // as a second process would. Clear the inherited marker first.
        std::env::remove_var(HELD_ENV);
        let e = lock(&d, Mode::Exclusive, false, "run").unwrap_err().to_string();
        assert!(e.contains("in use by another shapeshifter command") && e.contains(&format!("process {}", std::process::id())), "{e}");
        assert!(lock(&d, Mode::Shared, false, "stage").is_err());
        drop(held);
        let a = lock(&d, Mode::Shared, false, "stage").unwrap();
        std::env::remove_var(HELD_ENV);
        let b = lock(&d, Mode::Shared, false, "stage").unwrap();
        std::env::remove_var(HELD_ENV);
        assert!(lock(&d, Mode::Exclusive, false, "run").is_err(), "shared holders keep an exclusive one out");
        drop((a, b));
        std::env::remove_var(HELD_ENV);
        lock(&d, Mode::Exclusive, false, "run").unwrap();
        std::env::remove_var(HELD_ENV);
    }
}
