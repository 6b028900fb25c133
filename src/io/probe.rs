//! A .vdb file is parsed once in a process of its own before the program
//! reads it.
//!
//! Why: OpenVDB's readers assert (StreamCompression.cc "uncompressedSize !=
//! 0"), segfault or corrupt the heap on some damaged files: 5 of 7000 damaged
//! level files in a campaign took `info` down. Nothing outside the damaged
//! bytes tells, so the parse is first tried where a crash costs nothing: the
//! probe program ([`PROBE_PROGRAM`], built beside `shapeshifter`) parses the
//! same grids on one thread under the same allocation cap and exits. A probe
//! killed by a signal, or still busy after its time limit, is a one-line
//! error here; a probe that cannot be started is an error too (the file is
//! never parsed in-process unchecked). A spawned process, not a fork: a
//! forked copy of a multi-threaded program inherits locks and a TBB
//! scheduler mid-state. Cost: one process start (a few ms, no libtorch) and
//! a second parse (about 0.1 s for a 9 MB 256^3 level).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};

/// The probe program's file name: it sits beside `shapeshifter` (cargo
/// builds and installs both).
pub const PROBE_PROGRAM: &str = "shapeshifter-vdb-probe";

/// Environment variable naming the probe program, for a library user whose
/// program is not installed beside it.
pub const PROBE_ENV: &str = "SHAPESHIFTER_VDB_PROBE";

/// The probe program: `$SHAPESHIFTER_VDB_PROBE`, else [`PROBE_PROGRAM`] in the
/// running program's folder or the one above it (cargo puts tests and
/// examples one folder below the binaries).
fn program() -> Result<PathBuf> {
    if let Some(p) = std::env::var_os(PROBE_ENV) {
        return Ok(PathBuf::from(p));
    }
    let exe = std::env::current_exe().map_err(|e| Error::Invalid(format!("cannot find this program's path ({e})")))?;
    let dir = exe.parent().map(Path::to_path_buf).unwrap_or_default();
    [dir.join(PROBE_PROGRAM), dir.parent().map(|d| d.join(PROBE_PROGRAM)).unwrap_or_default()]
        .into_iter()
        .find(|p| p.is_file())
        .ok_or_else(|| {
            Error::Invalid(format!(
                "cannot check .vdb files: the probe program {PROBE_PROGRAM} is not beside {} \
                 (build it with `cargo build --release`, or set {PROBE_ENV})",
                exe.display()
            ))
        })
}

/// Parses grids `names` (all if empty) of `path` in the probe process; an
/// error naming the file when the parse failed, crashed or ran past its time
/// (10 s plus 1 s per 10 MB of file). A parse that fails cleanly in the probe
/// is not tried again here: OpenVDB's readers are not exception-safe
/// mid-node, and unwinding from a damaged grid corrupted the heap ("double
/// free or corruption") in a process whose heap happened to notice.
pub fn probe(path: &Path, names: &[&str]) -> Result<()> {
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let limit = Duration::from_millis(10_000 + bytes / 10_000);
    let program = program()?;
    let mut child = Command::new(&program)
        .arg(path)
        .args(names)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| Error::file(path, format!("cannot start the .vdb probe {} ({e})", program.display())))?;
    let t0 = Instant::now();
    let mut pause = Duration::from_millis(1);
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if t0.elapsed() >= limit => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(Error::file(
                    path,
                    format!("OpenVDB's reader did not finish it in {} s (damaged .vdb file?)", limit.as_secs()),
                ));
            }
            Ok(None) => {
                std::thread::sleep(pause);
                pause = (pause * 2).min(Duration::from_millis(20));
            }
            Err(e) => return Err(Error::file(path, format!("the .vdb probe could not be waited for ({e})"))),
        }
    };
    use std::io::Read;
    use std::os::unix::process::ExitStatusExt;
    // OpenVDB's message, one line of at most 511 bytes (the probe cuts it).
    let mut said = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut said);
    }
    match (status.code(), status.signal()) {
        (_, Some(sig)) => Err(Error::file(path, format!("OpenVDB's reader crashed on it (signal {sig}): damaged .vdb file"))),
        (Some(0), _) => Ok(()),
        (Some(1), _) => Err(Error::file(path, crate::io::vdb::read_failure(said.lines().next().unwrap_or("").trim()))),
        (Some(c), _) => Err(Error::file(path, format!("the .vdb probe {} failed (exit status {c})", program.display()))),
        (None, None) => Err(Error::file(path, "the .vdb probe ended without a status")),
    }
}
