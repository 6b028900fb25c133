//! Helper programs: readers that are run in a process of their own, so that
//! a crash or a runaway on a damaged file ends that process and not the
//! program (the .vdb probe, [`crate::io::probe`]; the Assimp converter,
//! [`crate::io::assimp`]). Each sits beside `shapeshifter` (cargo builds and
//! installs them together) or where an environment variable names it.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};

/// The helper `name`: `$env`, else `name` in the running program's folder or
/// the one above it (cargo puts tests and examples one folder below the
/// binaries).
pub fn find(name: &str, env: &str, what: &str) -> Result<PathBuf> {
    if let Some(p) = std::env::var_os(env) {
        return Ok(PathBuf::from(p));
    }
    let exe = std::env::current_exe().map_err(|e| Error::Invalid(format!("cannot find this program's path ({e})")))?;
    let dir = exe.parent().map(Path::to_path_buf).unwrap_or_default();
    [dir.join(name), dir.parent().map(|d| d.join(name)).unwrap_or_default()]
        .into_iter()
        .find(|p| p.is_file())
        .ok_or_else(|| {
            Error::Invalid(format!(
                "cannot {what}: the helper program {name} is not beside {} (build it with `cargo build --release`, or set {env})",
                exe.display()
            ))
        })
}

/// How a helper ended: its status and the first line it wrote on stderr.
pub struct Ended {
    pub status: ExitStatus,
    pub said: String,
}

/// Runs `program` (called `helper` in messages, "the .vdb probe") with
/// `args` for the file `path`, killing it after `limit`: an error naming
/// `path` when it cannot start or runs too long (`slow` says what did not
/// finish).
pub fn run(program: &Path, helper: &str, args: &[&std::ffi::OsStr], path: &Path, limit: Duration, slow: &str) -> Result<Ended> {
    let mut command = Command::new(program);
    command.args(args).stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::piped());
    // Registered, so that a stop signal reaches it too.
    let mut child = crate::util::interrupt::spawn(&mut command)
        .map_err(|e| Error::file(path, format!("cannot start {helper} {} ({e})", program.display())))?;
    let status = wait(&mut child, program, helper, path, limit, slow);
    crate::util::interrupt::forget(&child);
    let status = status?;
    use std::io::Read;
    let mut said = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut said);
    }
    let said = said.lines().next().unwrap_or("").trim().to_string();
    Ok(Ended { status, said })
}

fn wait(child: &mut std::process::Child, program: &Path, helper: &str, path: &Path, limit: Duration, slow: &str) -> Result<ExitStatus> {
    let t0 = Instant::now();
    let mut pause = Duration::from_millis(1);
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return Ok(status),
            Ok(None) if t0.elapsed() >= limit => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(Error::file(path, format!("{slow} did not finish it in {} s (damaged file?)", limit.as_secs())));
            }
            Ok(None) => {
                std::thread::sleep(pause);
                pause = (pause * 2).min(Duration::from_millis(20));
            }
            Err(e) => return Err(Error::file(path, format!("{helper} {} could not be waited for ({e})", program.display()))),
        }
    }
}
