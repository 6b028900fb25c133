//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod http;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `../shared/data` beside the project, if present; where it is absent (a
/// user's fresh checkout has none) the test is recorded as skipped ([`skip`]).
/// (`../../shared/data` too: a worktree one folder deeper.)
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let found = ["../shared/data", "../../shared/data"].iter().map(|d| root.join(d).join(rel)).find(|p| p.exists());
    if found.is_none() {
        skip(&format!("../shared/data/{rel} is absent (../shared/data is not beside this checkout)"));
    }
    found
}

/// Records that the calling test (or a part of it) cannot run here: a line
/// on stderr and in the skip log ($SHAPESHIFTER_SKIP_LOG, which `make test`
/// sets, clears and prints at the end; else `skips.log` in cargo's
/// test scratch folder), so a skip never passes as "ok" unseen. With
/// SHAPESHIFTER_NO_SKIPS set (CI, where ../shared/data and every client are
/// present) a skip is a failure.
pub fn skip(reason: &str) {
    let test = std::thread::current().name().unwrap_or("?").to_string();
    if std::env::var_os("SHAPESHIFTER_NO_SKIPS").is_some() {
        panic!("{test} would skip, and SHAPESHIFTER_NO_SKIPS is set: {reason}");
    }
    eprintln!("SKIPPED {test}: {reason}");
    let log = std::env::var_os("SHAPESHIFTER_SKIP_LOG")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_TARGET_TMPDIR")).join("skips.log"));
    if let Some(dir) = log.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let line = format!("{test}: {reason}\n");
    let written = std::fs::OpenOptions::new().create(true).append(true).open(&log).and_then(|mut f| {
        use std::io::Write;
        f.write_all(line.as_bytes())
    });
    if let Err(e) = written {
        eprintln!("warning: cannot record the skip in {}: {e}", log.display());
    }
}

/// Runs the real binary with `args`.
pub fn shapeshifter(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_shapeshifter"))
        .args(args)
        .output()
        .expect("binary runs")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Asserts that a run failed with exit status 1 (a failed input) and ONE
/// error line that names `file` and contains `problem`.
pub fn assert_clean_failure(o: &Output, file: &str, problem: &str) {
    assert_failure_with(o, 1, file, problem);
}

/// Asserts that a command line was refused as bad usage: exit status 2 and
/// ONE error line that names `what` and contains `problem`.
pub fn assert_usage_failure(o: &Output, what: &str, problem: &str) {
    assert_failure_with(o, 2, what, problem);
}

/// Exit status exactly `code` (not a panic's 101, not a signal) and ONE
/// error line naming `file` and saying `problem`.
pub fn assert_failure_with(o: &Output, code: i32, file: &str, problem: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(code), "expected exit status {code}; stderr: {err}");
    assert!(!err.contains("panicked at") && !err.contains("internal error"), "panicked: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(lines.len(), 1, "expected one error line, got: {err}");
    assert!(!file.is_empty() && lines[0].contains(file), "error does not name '{file}': {}", lines[0]);
    assert!(!problem.trim().is_empty(), "say which problem the error must name");
    assert!(lines[0].to_lowercase().contains(&problem.to_lowercase()), "error does not say '{problem}': {}", lines[0]);
}

/// Files in `dir` (names), sorted, to check nothing half-written is left.
pub fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|r| r.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

/// A run of the demo exemplar through 64^3 (levels 16, 32, 64, every one by
/// a small network), two variants: made once per test binary (about 30 s).
/// Tests that write into a run copy it first.
pub fn tiny_trained_run() -> &'static Path {
    static RUN: std::sync::OnceLock<(tempfile::TempDir, PathBuf)> = std::sync::OnceLock::new();
    &RUN.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("run");
        let mut args = vec!["-q", "demo", "-o", out.to_str().unwrap(), "-n", "2", "--jobs", "2"];
        for s in [
            "encode.sampling_resolution=128",
            "encode.finest_resolution=64",
            "model.channels=8",
            "model.upsampler_channels=8",
            "train.level0_iterations=150",
            "train.upper_iterations=60",
            "train.upsampler_iterations=60",
            "sample.level0={candidates = 1}",
            "sample.attempts={count = 1}",
            "sample.proposers={}",
            "sample.level0_steps=20",
            "sample.upper_steps=4",
        ] {
            args.extend(["--set", s]);
        }
        let o = shapeshifter(&args);
        assert!(o.status.success(), "tiny run: {}", stderr(&o));
        (dir, out)
    })
    .1
}

/// The Python of the usd-core virtual environment `make test` installs
/// (`scripts/venv.sh usd-venv`), where it is complete; else the test is recorded
/// as skipped ([`skip`]).
pub fn usd_core_python() -> Option<PathBuf> {
    let cache = std::env::var_os("SHAPESHIFTER_CACHE").map(PathBuf::from).unwrap_or_else(|| {
        std::env::var_os("XDG_CACHE_HOME")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(std::env::var_os("HOME").unwrap_or_default()).join(".cache"))
            .join("shapeshifter")
    });
    let venv = cache.join("usd-venv");
    if venv.join(".complete").is_file() {
        return Some(venv.join("bin/python"));
    }
    skip(&format!("usd-core is not installed in {} (`make test` installs it: scripts/venv.sh)", venv.display()));
    None
}

/// Pixar's usd-core opens the USD asset of run folder `run` and checks it
/// (`scripts/interop/usd_check.py`: the stage, its variants, meshes,
/// volumes, textures, and usd-core's validators); `ext`: usda or usdc.
/// Returns the script's output; panics with it when a check fails.
pub fn usd_core_check(python: &Path, run: &Path, ext: &str) -> String {
    let counts = run.join(".usd_check_counts.json");
    std::fs::write(&counts, "{}").unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/interop/usd_check.py");
    let o = Command::new(python).arg(script).arg(run).arg(&counts).arg(ext).output().expect("usd-core's python runs");
    let _ = std::fs::remove_file(&counts);
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "usd-core rejects {}'s asset ({ext}):\n{text}", run.display());
    text
}
