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

use std::ffi::OsStr;
use std::path::Path;
use std::time::Duration;

use crate::error::{Error, Result};
use crate::io::helper;

/// The probe program's file name: it sits beside `shapeshifter` (cargo
/// builds and installs both).
pub const PROBE_PROGRAM: &str = "shapeshifter-vdb-probe";

/// Environment variable naming the probe program, for a library user whose
/// program is not installed beside it.
pub const PROBE_ENV: &str = "SHAPESHIFTER_VDB_PROBE";

/// Parses grids `names` (all if empty) of `path` in the probe process; an
/// error naming the file when the parse failed, crashed or ran past its time
/// (10 s plus 1 s per 10 MB of file). A parse that fails cleanly in the probe
/// is not tried again here: OpenVDB's readers are not exception-safe
/// mid-node, and unwinding from a damaged grid corrupted the heap ("double
/// free or corruption") in a process whose heap happened to notice.
pub fn probe(path: &Path, names: &[&str]) -> Result<()> {
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let limit = Duration::from_millis(10_000 + bytes / 10_000);
    let program = helper::find(PROBE_PROGRAM, PROBE_ENV, "check .vdb files")?;
    let mut args: Vec<&OsStr> = vec![path.as_os_str()];
    args.extend(names.iter().map(OsStr::new));
    let ended = helper::run(&program, "the .vdb probe", &args, path, limit, "OpenVDB's reader")?;
    use std::os::unix::process::ExitStatusExt;
    // OpenVDB's message, one line of at most 511 bytes (the probe cuts it).
    match (ended.status.code(), ended.status.signal()) {
        (_, Some(sig)) => Err(Error::file(path, format!("OpenVDB's reader crashed on it (signal {sig}): damaged .vdb file"))),
        (Some(0), _) => Ok(()),
        (Some(1), _) => Err(Error::file(path, read_failure(&ended.said))),
        (Some(c), _) => Err(Error::file(path, format!("the .vdb probe {} failed (exit status {c})", program.display()))),
        (None, None) => Err(Error::file(path, "the .vdb probe ended without a status")),
    }
}

/// OpenVDB's message for a file it could not read, with what it usually
/// means: a cut-off file makes OpenVDB read garbage as the next grid's type
/// name and report "Grid type is not registered" (a whole file with a grid
/// type this build of OpenVDB lacks says the same).
pub(crate) fn read_failure(what: &str) -> String {
    if what.contains("not registered") {
        format!("truncated or damaged level file, or a grid type OpenVDB 10 does not know (OpenVDB: {what})")
    } else if what.contains("end of file") || what.contains("EOF") {
        format!("truncated or damaged level file (OpenVDB: {what})")
    } else {
        what.to_string()
    }
}
