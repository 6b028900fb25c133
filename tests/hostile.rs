//! Hostile files: every reader turns malformed input into exit 0 or one error
//! line, never a signal, a runaway or a leftover output (docs/hostile-files.md). The harness is tests/common/hostile.rs; longer campaigns:
//! `cargo run --release --example hostile_campaign`.

use crate::hostile_harness as hostile;
use crate::common;

use std::path::{Path, PathBuf};
use std::time::Duration;

fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_shapeshifter"))
}

/// A fixed-seed campaign over every built-in format and two files nobody
/// here wrote: 3 mutations per input, two children at a time (`make test`).
#[test]
fn mutated_inputs_end_cleanly_within_bounds() {
    campaign(17, 3);
}

/// The same at 30 mutations per input (`make test-slow`, and CI).
#[test]
#[ignore = "slow (about 3 minutes): make test-slow"]
fn a_longer_campaign_ends_cleanly_within_bounds() {
    campaign(17, 30);
}

fn campaign(seed: u64, count: usize) {
    let work = tempfile::tempdir().unwrap();
    let mut seeds = hostile::builtin_seeds(work.path());
    assert!(seeds.len() >= 7, "every mesh format and a level file");
    // FBX and COLLADA (read through the Assimp converter): files nobody here
    // wrote, from Debian's assimp-testmodels.
    for rel in ["FBX/box.fbx", "Collada/cube_triangulate.dae"] {
        let p = Path::new("/usr/share/assimp/models").join(rel);
        if p.is_file() {
            seeds.push(hostile::file_seed(&p).unwrap());
        } else {
            common::skip(&format!("{} is absent (assimp-testmodels): no FBX/COLLADA mutations", p.display()));
        }
    }
    let c = hostile::Campaign {
        bin: bin(),
        seed,
        count,
        limit: Duration::from_secs(20),
        threads: 2,
        keep_failures: None,
    };
    let stats = hostile::run_campaign(&c, &seeds, work.path());
    eprintln!("{}", hostile::table(&stats));
    let runs: usize = stats.values().map(|s| s.runs).sum();
    assert_eq!(runs, count * seeds.len());
    // The mutations must reach the error paths, or the test proves nothing.
    let errors: usize = stats.values().map(|s| s.exit1).sum();
    assert!(errors > runs / 4, "only {errors} of {runs} mutated inputs were rejected");
    let failures: Vec<&String> = stats.values().flat_map(|s| &s.failures).collect();
    assert!(failures.is_empty(), "{} runs broke the contract:\n{}", failures.len(), failures.iter().map(|s| s.as_str()).collect::<Vec<_>>().join("\n"));
}

/// The verdict itself fails what it must (a test that cannot fail proves nothing).
#[test]
fn the_verdict_catches_signals_panics_runaways_and_leftovers() {
    let ok = hostile::Outcome { code: Some(1), signal: None, timed_out: false, ceiling_hit: false, wall: Duration::from_millis(300), max_rss: 100 << 20, stderr_bytes: 18, stderr: "error: x.obj: bad\n".into() };
    assert_eq!(hostile::verdict(&ok, &[], 200 << 20), None);
    let abort = hostile::Outcome { code: None, signal: Some(6), ..ok.clone() };
    assert!(hostile::verdict(&abort, &[], 200 << 20).unwrap().contains("signal 6"));
    let big = hostile::Outcome { max_rss: 300 << 20, ..ok.clone() };
    assert!(hostile::verdict(&big, &[], 200 << 20).is_some());
    let two = hostile::Outcome { stderr: "error: a\nerror: b\n".into(), ..ok.clone() };
    assert!(hostile::verdict(&two, &[], 200 << 20).is_some());
    assert!(hostile::verdict(&ok, &["p.ply".into()], 200 << 20).unwrap().contains("left output"));
    let panic = hostile::Outcome { code: Some(101), ..ok.clone() };
    assert!(hostile::verdict(&panic, &[], 200 << 20).is_some());
}

/// Inputs that once crashed or ran away (tests/inputs/hostile/README.md says
/// what each did): each command now ends with one error line, within bounds.
#[test]
fn regression_inputs_fail_cleanly() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/inputs/hostile");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).filter(|p| p.extension().is_some_and(|e| e != "md")).collect();
    files.sort();
    assert!(files.len() >= 3, "regression inputs present");
    let work = tempfile::tempdir().unwrap();
    for f in &files {
        let out = work.path().join("out");
        let is_vdb = f.extension().is_some_and(|e| e == "vdb");
        let mut commands = vec![vec!["info".to_string(), f.display().to_string()]];
        if is_vdb {
            commands.push(vec!["points".into(), f.display().to_string(), "-o".into(), out.join("p.ply").display().to_string()]);
        } else {
            commands.push(vec!["encode".into(), f.display().to_string(), "-o".into(), out.join("enc").display().to_string(), "--finest".into(), "32".into(), "--sampling-resolution".into(), "64".into()]);
        }
        for argv in commands {
            std::fs::create_dir_all(&out).unwrap();
            let o = hostile::run_child(&bin(), &argv, &work.path().join("stderr"), Duration::from_secs(20));
            let left: Vec<String> = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
            let bound = 256 << 20;
            assert_eq!(hostile::verdict(&o, &left, bound), None, "{argv:?}: {}", o.stderr);
            // `info` reads every part of a file, so it must reject each one; a
            // level command may succeed where the damage lies in a grid it
            // does not read (the point-data grid).
            if argv[0] == "info" || !is_vdb {
                assert_eq!(o.code, Some(1), "{argv:?} must fail: {}", o.stderr);
                let name = f.file_name().unwrap().to_string_lossy();
                assert!(o.stderr.lines().any(|l| l.starts_with("error") && l.contains(&*name)), "{argv:?}: {}", o.stderr);
            }
            std::fs::remove_dir_all(&out).unwrap();
        }
    }
}

/// Level files another tool edited so that their grids disagree
/// (tests/inputs/levels, written with pyopenvdb from a level of ours): a
/// voxel of the mask that P lacks, a P far outside its voxel (both read as
/// wild points before: P's background, the origin, or the stray position)
/// are refused with one line; voxels only Cd has are ignored with a warning.
#[test]
fn level_files_whose_grids_disagree_are_refused_or_read_with_a_warning() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/inputs/levels");
    let work = tempfile::tempdir().unwrap();
    let points = |name: &str| {
        let out = work.path().join(format!("{name}.ply"));
        let o = std::process::Command::new(bin()).arg("points").arg(dir.join(name)).arg("-o").arg(&out).output().unwrap();
        (o, out)
    };
    for (name, problem) in [
        ("mask_voxel_missing_in_P.vdb", "is active in grid 'mask' but not in 'P'"),
        ("P_outside_its_voxel.vdb", "lies 5.3 voxels from its voxel's centre"),
    ] {
        let (o, out) = points(name);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(1), "{name}: {err}");
        let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
        assert_eq!(errors.len(), 1, "{name}: {err}");
        assert!(errors[0].contains(name) && errors[0].contains(problem), "{name}: {}", errors[0]);
        assert!(!out.exists(), "{name}: no output");
    }
    let (o, out) = points("Cd_voxel_outside_the_mask.vdb");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    assert!(err.contains("1 voxels active in P, N or Cd but not in the mask are ignored"), "{err}");
    let (level, _) = shapeshifter::io::vdb::read_level(&dir.join("Cd_voxel_outside_the_mask.vdb")).unwrap();
    assert_eq!(level.len(), 454, "the mask's voxels, not Cd's extra one");
    assert!(out.is_file());
}

/// A level file is never parsed in the program without the probe process:
/// when the probe cannot start, reading fails with one line saying so.
#[test]
fn a_missing_probe_is_an_error_not_an_unguarded_parse() {
    let level = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/inputs/levels/Cd_voxel_outside_the_mask.vdb");
    let o = std::process::Command::new(bin())
        .arg("info")
        .arg(&level)
        .env(shapeshifter::io::probe::PROBE_ENV, "/nonexistent/shapeshifter-vdb-probe")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{err}");
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errors.len(), 1, "{err}");
    assert!(errors[0].contains("cannot start the .vdb probe"), "{}", errors[0]);
}
