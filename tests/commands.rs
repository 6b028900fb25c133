//! The encode, render and edit commands as a user runs them: outputs, and
//! clean failures that leave nothing behind.

use crate::common;
use crate::hostile_harness as hostile;

use common::*;
use hostile::sphere_level;
use std::path::Path;
use shapeshifter::{io::dataset, encode::exemplar, io::mesh, io::vdb};

/// Writes the small demo tower as a PLY in `dir`.
fn small_tower_ply(dir: &std::path::Path) -> std::path::PathBuf {
    let p = dir.join("tower.ply");
    mesh::save(&exemplar::small_tower(), &p, true).unwrap();
    p
}

#[test]
fn encode_writes_levels_manifest_and_previews() {
    let dir = tempfile::tempdir().unwrap();
    let ply = small_tower_ply(dir.path());
    let out = dir.path().join("enc");
    let o = shapeshifter(&[
        "encode", ply.to_str().unwrap(), "-o", out.to_str().unwrap(),
        "--sampling-resolution", "128", "--finest", "64", "--preview", "--width", "200", "--height", "200",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (manifest, levels) = dataset::read(&out).unwrap();
    assert_eq!(manifest.levels.len(), 3);
    assert_eq!(levels.iter().map(|l| l.resolution).collect::<Vec<_>>(), vec![16, 32, 64]);
    assert!(!manifest.open_surface, "the stones are closed boxes");
    assert_eq!(manifest.source_sha256, dataset::file_sha256(&ply).unwrap());
    for l in &levels {
        assert!(out.join(format!("level_{}.png", l.index)).is_file());
        assert_eq!(l.len(), manifest.levels[l.index].voxels);
        // Points sit in the exemplar's frame: inside the mesh's bounds (plus a voxel).
        let (lo, hi) = exemplar::small_tower().bounds();
        let slack = (l.voxel_size() / l.frame.scale) as f32;
        for i in 0..l.len() {
            let p = l.point_world(i).as_vec3();
            assert!(p.cmpge(lo - slack).all() && p.cmple(hi + slack).all(), "point {p} outside {lo}..{hi}");
        }
    }
}

#[test]
fn encode_bad_inputs_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("enc");
    let missing = dir.path().join("missing.obj");
    let o = shapeshifter(&["encode", missing.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_clean_failure(&o, "missing.obj", "no such file");
    assert!(!out.exists(), "no output folder for a failed encode");
    let ply = small_tower_ply(dir.path());
    let o = shapeshifter(&["encode", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "--finest", "100"]);
    // An option error names the option, not a file: bad usage, exit 2.
    assert_usage_failure(&o, "finest_resolution = 100", "power of two");
    assert!(!out.exists());
}

#[test]
fn render_level_and_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let ply = small_tower_ply(dir.path());
    let png = dir.path().join("mesh.png");
    let o = shapeshifter(&["render", ply.to_str().unwrap(), "-o", png.to_str().unwrap(), "--width", "120", "--height", "90"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (120, 90));
    // A broken level file: clean error, no PNG.
    let bad = dir.path().join("bad.vdb");
    std::fs::write(&bad, b"not a vdb").unwrap();
    let png2 = dir.path().join("bad.png");
    assert_clean_failure(&shapeshifter(&["render", bad.to_str().unwrap(), "-o", png2.to_str().unwrap()]), "bad.vdb", "not a VDB file");
    assert!(!png2.exists());
}

#[test]
fn edit_copies_and_deletes_boxes() {
    let dir = tempfile::tempdir().unwrap();
    let ply = small_tower_ply(dir.path());
    let out = dir.path().join("enc");
    let o = shapeshifter(&["encode", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "--sampling-resolution", "64", "--finest", "32"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let src = out.join("level_1.vdb");
    let (level, _) = vdb::read_level(&src).unwrap();
    let edited = dir.path().join("deleted.vdb");
    let o = shapeshifter(&["edit", src.to_str().unwrap(), "-o", edited.to_str().unwrap(), "delete", "--box", "0,0,0:15,31,31"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (del, _) = vdb::read_level(&edited).unwrap();
    assert!(del.len() < level.len() && !del.is_empty());
    assert!(del.coords.iter().all(|c| c.x > 15));
    // Copy the right half onto the left: the level becomes mirror-free but full again.
    let copied = dir.path().join("copied.vdb");
    let o = shapeshifter(&[
        "edit", edited.to_str().unwrap(), "-o", copied.to_str().unwrap(), "copy", "--box", "16,0,0:31,31,31", "--to", "0,0,0",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (cp, _) = vdb::read_level(&copied).unwrap();
    assert_eq!(cp.len(), 2 * del.len());
    // Out of the grid: clean error, no file.
    let oob = dir.path().join("oob.vdb");
    let o = shapeshifter(&["edit", src.to_str().unwrap(), "-o", oob.to_str().unwrap(), "copy", "--box", "0,0,0:31,31,31", "--to", "10,0,0"]);
    assert_clean_failure(&o, "level_1.vdb", "grid");
    assert!(!oob.exists());
    // Quiet or not, the edit is made: the same voxels written.
    let quiet = dir.path().join("quiet.vdb");
    let o = shapeshifter(&["-q", "edit", src.to_str().unwrap(), "-o", quiet.to_str().unwrap(), "delete", "--box", "0,0,0:15,31,31"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (q, _) = vdb::read_level(&quiet).expect("edit -q writes its file");
    assert_eq!((q.coords, q.offsets, q.colours), (del.coords, del.offsets, del.colours));
}

/// `sample RUN` takes a run folder as its help says (its exemplar/ and
/// models/), and a sampling that fails leaves no output folder it made.
#[test]
fn sample_takes_a_run_folder_and_a_failed_sample_leaves_no_folder() {
    let run = tiny_trained_run();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("variants");
    let o = shapeshifter(&["-q", "sample", run.to_str().unwrap(), "-n", "1", "--seed", "3", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("variant_000/level_2.vdb").is_file());
    // The same from the exemplar folder with --models: the same variant.
    let out2 = dir.path().join("variants2");
    let o = shapeshifter(&[
        "-q", "sample", run.join("exemplar").to_str().unwrap(), "--models", run.join("models").to_str().unwrap(), "-n", "1", "--seed", "3",
        "-o", out2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let a = vdb::read_level(&out.join("variant_000/level_2.vdb")).unwrap().0;
    let b = vdb::read_level(&out2.join("variant_000/level_2.vdb")).unwrap().0;
    assert_eq!((a.coords, a.offsets), (b.coords, b.offsets));
    // Continuing from a level file of the wrong resolution (the exemplar's
    // 32^3 level relabelled level 0) fails: no folder left.
    let failed = dir.path().join("failed");
    let wrong = dir.path().join("wrong.vdb");
    let (mut level, provenance) = vdb::read_level(&run.join("exemplar/level_1.vdb")).unwrap();
    level.index = 0;
    vdb::write_level(&wrong, &level, &provenance, Default::default()).unwrap();
    let o2 = shapeshifter(&["sample", run.to_str().unwrap(), "-n", "1", "--from", wrong.to_str().unwrap(), "-o", failed.to_str().unwrap()]);
    assert_eq!(o2.status.code(), Some(1), "{}", stderr(&o2));
    assert!(!failed.exists(), "a failed sample left {}: {:?}", failed.display(), listing(&failed));
}

/// A variant's choices depend only on the run seed, its index, the models and
/// the exemplar. The tiny networks fill no longer box whole, so every variant
/// tries resized passes, they all fail, and after six the variant stays in
/// the exemplar's box: one process sampling both variants and two processes
/// sampling one each at the same time write the same variants, voxel for
/// voxel (the count of failed passes once lived in the process and steered
/// the variants after it).
#[test]
fn failing_resized_passes_steer_no_other_variant() {
    let run = tiny_trained_run();
    let dir = tempfile::tempdir().unwrap();
    let settings = [
        "--set", "sample.level0={candidates = 2, pick = \"novel\"}", "--set", "sample.attempts={count = 9}",
        "--set", "sample.proposers={resize_max = 1.5}", "--set", "sample.level0_steps=10", "--set", "sample.upper_steps=2",
    ];
    let sample = |out: &std::path::Path, first: &str, n: &str| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_shapeshifter"));
        c.args(["sample", run.to_str().unwrap(), "--seed", "4", "--progress", "none", "--first", first, "-n", n, "-o", out.to_str().unwrap()]);
        c.args(settings);
        c
    };
    let one = dir.path().join("one");
    let o = sample(&one, "0", "2").output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let gave_up = stderr(&o).matches("resized passes of this variant, none whole").count();
    assert_eq!(gave_up, 2, "each variant's resized passes all fail here: {}", stderr(&o));
    // Two processes at once, one variant each.
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let children = [sample(&a, "0", "1").stderr(std::process::Stdio::piped()).spawn().unwrap(), sample(&b, "1", "1").stderr(std::process::Stdio::piped()).spawn().unwrap()];
    for child in children {
        let o = child.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let two = dir.path().join("two");
    std::fs::create_dir(&two).unwrap();
    std::fs::rename(a.join("variant_000"), two.join("variant_000")).unwrap();
    std::fs::rename(b.join("variant_001"), two.join("variant_001")).unwrap();
    let o = shapeshifter(&["compare", one.to_str().unwrap(), two.to_str().unwrap()]);
    assert!(o.status.success() && stdout(&o).contains("identical"), "one process and two differ: {}", stdout(&o));
}

#[test]
fn a_resized_variant_records_its_extent_and_eval_judges_it_at_that_extent() {
    let run = tiny_trained_run();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("long");
    let o = shapeshifter(&["-q", "sample", run.to_str().unwrap(), "-n", "1", "--extent", "1.5,1,1", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let record: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("variant_000/extent.json")).unwrap()).unwrap();
    assert_eq!(record["extent"], serde_json::json!([1.5, 1.0, 1.0]));
    let report = dir.path().join("eval.json");
    let o = shapeshifter(&["eval", run.join("exemplar").to_str().unwrap(), out.join("variant_000").to_str().unwrap(), "-o", report.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("(extent 1.5,1,1)"), "{}", String::from_utf8_lossy(&o.stdout));
    let scores: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(scores["variants"][0]["extent"], serde_json::json!([1.5, 1.0, 1.0]));
    // In the exemplar's box no record is written, and a stale one goes.
    let o = shapeshifter(&["-q", "sample", run.to_str().unwrap(), "-n", "1", "--seed", "9", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("variant_000/extent.json").exists());
    // A broken record is a one-line error naming it, exit 1.
    std::fs::write(out.join("variant_000/extent.json"), "{\"extent\": [0, 1, 1]}").unwrap();
    let o = shapeshifter(&["eval", run.join("exemplar").to_str().unwrap(), out.join("variant_000").to_str().unwrap(), "-o", report.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("extent.json") && e.contains("positive") && e.trim().lines().count() == 1, "{e}");
}

#[test]
fn batch_run_skips_a_corrupt_input_and_fails_overall() {
    let dir = tempfile::tempdir().unwrap();
    let good = small_tower_ply(dir.path());
    let good2 = dir.path().join("tower2.ply");
    std::fs::copy(&good, &good2).unwrap();
    let corrupt = dir.path().join("corrupt.obj");
    std::fs::write(&corrupt, [0xffu8, 0x00, 0x13].repeat(40)).unwrap();
    // This one used to abort the whole batch (SIGABRT in OpenMesh's OBJ reader).
    let aborted = dir.path().join("aborted.obj");
    std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/inputs/hostile/obj_face_without_vertex.obj"), &aborted).unwrap();
    let out = dir.path().join("batch");
    // The demo profile's 32-channel f32 networks: three steps of them leave a
    // level 0 (the cpu profile's wider bf16 ones can prune it all), thirty of
    // the upper level's keep voxels at 32^3 (two pruned every variant, which
    // now fails the run).
    let tiny = [
        "--profile", "demo",
        "--set", "encode.sampling_resolution=64", "--set", "encode.finest_resolution=32",
        "--set", "train.level0_iterations=3", "--set", "train.upper_iterations=30", "--set", "train.upsampler_iterations=30",
        // One coarse shape per variant: these runs test files and stages, not wholeness.
        "--set", "sample.level0={candidates = 1}", "--set", "sample.attempts={count = 1}", "--set", "sample.proposers={}",
    ];
    let mut args = vec!["run", good.to_str().unwrap(), corrupt.to_str().unwrap(), aborted.to_str().unwrap(), good2.to_str().unwrap(), "-o", out.to_str().unwrap(), "-n", "1"];
    args.extend(tiny);
    args.extend(["--json", "--progress", "alf"]);
    let o = shapeshifter(&args);
    assert!(!o.status.success(), "a failed input must fail the batch");
    let err = stderr(&o);
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(o.status.code(), Some(1), "exit 1, no signal: {err}");
    assert_eq!(errors.len(), 2, "one error line per bad input: {err}");
    assert!(errors[0].contains("corrupt.obj"), "{}", errors[0]);
    assert!(errors[1].contains("aborted.obj") && errors[1].contains("line 7"), "{}", errors[1]);
    for stem in ["tower", "tower2"] {
        assert!(out.join(stem).join("variants/variant_000/level_0.vdb").is_file(), "{stem} has no result: {err}");
        assert!(out.join(stem).join("eval.json").is_file(), "{err}");
        assert!(out.join(stem).join("contact_sheet.png").is_file());
    }
    assert!(!out.join("corrupt").join("eval.json").exists());
    assert!(!out.join("aborted").join("eval.json").exists());
    // --json: one record per exemplar (JSON Lines), in order, failures included.
    let records: Vec<serde_json::Value> =
        String::from_utf8_lossy(&o.stdout).lines().map(|l| serde_json::from_str(l).expect("one JSON record per line")).collect();
    let status: Vec<(&str, i64)> = records.iter().map(|r| (r["status"].as_str().unwrap(), r["exit_status"].as_i64().unwrap())).collect();
    assert_eq!(status, [("done", 0), ("failed", 1), ("failed", 1), ("done", 0)]);
    assert!(records[1]["error"].as_str().unwrap().contains("corrupt.obj"));
    for r in [&records[0], &records[3]] {
        let files = r["files"].as_array().unwrap();
        let kind = |k: &str| files.iter().filter(|f| f["kind"] == k).count();
        assert!(kind("level_volume") >= 4 && kind("level_points") >= 4 && kind("mesh") >= 1 && kind("eval") == 1, "{r}");
        assert!(kind("usd") == 2 && kind("report") == 1 && kind("preview") >= 3, "{r}");
        assert!(files.iter().all(|f| Path::new(f["path"].as_str().unwrap()).is_file()), "every listed file exists");
        assert!(files.iter().any(|f| f["kind"] == "level_volume" && f["variant"] == "variant_000" && f["level"] == 1));
        let stages: Vec<&str> = r["stages"].as_array().unwrap().iter().map(|s| s["stage"].as_str().unwrap()).collect();
        assert_eq!(stages, ["encode", "train", "sample", "mesh", "usd", "evaluate"]);
    }
    // --progress alf: `ALF_PROGRESS nn%` lines on stderr (stdout holds only
    // the JSON records, checked above), rising through the whole batch to 100%.
    let percents: Vec<u32> = err
        .lines()
        .filter_map(|l| l.strip_prefix("ALF_PROGRESS ")?.strip_suffix('%')?.parse().ok())
        .collect();
    assert!(percents.len() >= 20 && percents.windows(2).all(|w| w[0] < w[1]), "{percents:?}");
    assert_eq!(percents.last(), Some(&100), "{percents:?}");
    assert!(percents.iter().any(|&p| p > 25 && p < 50), "the second exemplar's quarter is reported too: {percents:?}");
    // --extent past the budget: bad usage (2), one line, before anything is
    // made (it used to allocate the dense box and be killed for memory).
    let huge = dir.path().join("huge");
    let (exemplar, models) = (out.join("tower/exemplar"), out.join("tower/models"));
    let sample = |extent: &str| {
        shapeshifter(&["sample", exemplar.to_str().unwrap(), "--models", models.to_str().unwrap(), "-o", huge.to_str().unwrap(), "--extent", extent])
    };
    let o = sample("1000,1000,1000");
    assert_usage_failure(&o, "--extent 1000,1000,1000", "level-0 box");
    assert!(!huge.exists());
    let o = sample("0,1,1");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("positive") && !huge.exists(), "{}", stderr(&o));
    // Sampling that stops at level 0 still has level 1's upsampler for the
    // level-0 choice's thin-part count, so a variant's level 0 does not
    // depend on where its pass stops.
    let config = shapeshifter::config::Config::read(&models.join("config.toml")).unwrap();
    let m = shapeshifter::learn::sample::load_models(&models, &config, 1, tch::Device::Cpu).unwrap();
    assert_eq!((m.levels(), m.upsamplers.len()), (1, 2));
    assert!(m.upsamplers[0].is_none() && m.upsamplers[1].is_some(), "level 1's upsampler is not loaded with level 0");
    // A bad --set is bad usage: 2, one line, nothing run.
    let o = shapeshifter(&["run", good.to_str().unwrap(), "-o", dir.path().join("bad").to_str().unwrap(), "--set", "mesh.nope=1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(!dir.path().join("bad").exists());
    // `usd` on a folder that is not a run: one line, exit 1, nothing made there.
    let missing = dir.path().join("missing");
    let o = shapeshifter(&["usd", missing.to_str().unwrap()]);
    assert_eq!((o.status.code(), stderr(&o).lines().filter(|l| l.starts_with("error")).count()), (Some(1), 1), "{}", stderr(&o));
    assert!(!missing.exists());
    let o = shapeshifter(&["usd", dir.path().to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(!dir.path().join(".shapeshifter.lock").exists() && !dir.path().join("variants.usda").exists());
}

/// Exit statuses are exact: 0 done, 1 a failed input, 2 bad usage (clap's,
/// and the settings the library refuses before any work), and a panic is
/// one line and 1, not Rust's 101 and a multi-line message.
#[test]
fn exit_codes_are_exact_and_a_panic_is_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = small_tower_ply(dir.path());
    let m = mesh.to_str().unwrap();
    let out = dir.path().join("enc");
    let o = shapeshifter(&["encode", m, "-o", out.to_str().unwrap(), "--finest", "100"]);
    assert_usage_failure(&o, "finest_resolution = 100", "power of two");
    assert!(!out.exists(), "nothing made: {:?}", listing(dir.path()));
    let o = shapeshifter(&["run", m, "-o", out.to_str().unwrap(), "--profile", "nope"]);
    assert_usage_failure(&o, "nope", "unknown profile");
    let o = shapeshifter(&["encode", m, "-o", out.to_str().unwrap(), "--no-such-flag"]);
    assert_eq!(o.status.code(), Some(2), "clap's own usage errors: {}", stderr(&o));
    let o = shapeshifter(&["info", dir.path().join("absent.obj").to_str().unwrap()]);
    assert_clean_failure(&o, "absent.obj", "no such file");
    let o = shapeshifter(&["info", m]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for place in ["main", "worker"] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_shapeshifter"))
            .args(["info", m])
            .env("SHAPESHIFTER_TEST_PANIC", place)
            .env_remove("RUST_BACKTRACE")
            .output()
            .unwrap();
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{place}: {err}");
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 1, "{place}: one line: {err}");
        assert!(lines[0].starts_with("error: internal error: a test panic") && lines[0].contains("src/cli.rs"), "{place}: {err}");
    }
}

#[test]
fn mesh_and_points_bad_levels_fail_cleanly_with_no_output() {
    use shapeshifter::io::vdb::{write_level, Provenance, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, level: &shapeshifter::level::Level| {
        let p = dir.path().join(name);
        write_level(&p, level, &Provenance::default(), WriteOptions::default()).unwrap();
        p
    };
    let good = write("good.vdb", &sphere_level(2000));
    let mut inactive = sphere_level(2000);
    inactive.mask.iter_mut().for_each(|m| *m = -1.0);
    let mut cases = vec![
        (write("empty.vdb", &sphere_level(0)), "no active voxels"),
        (write("inactive.vdb", &inactive), "no active voxels"),
        (write("few.vdb", &sphere_level(5)), "too few"),
    ];
    // NaN normals, as another tool could write them (our writer refuses them,
    // below): the good level's grids rewritten by Debian's pyopenvdb.
    let nan = dir.path().join("nan.vdb");
    let script = r#"
import pyopenvdb as vdb, sys
grids = [vdb.read(sys.argv[1], n) for n in ('mask', 'P', 'N', 'Cd')]
ijk = next(grids[2].citerOnValues()).min
grids[2].getAccessor().setValueOn(ijk, (float('nan'),) * 3)
vdb.write(sys.argv[2], grids=grids)
"#;
    let python = || std::process::Command::new("/usr/bin/python3");
    if matches!(python().args(["-c", "import pyopenvdb"]).output(), Ok(ref o) if o.status.success()) {
        let o = python().args(["-c", script]).arg(&good).arg(&nan).output().unwrap();
        assert!(o.status.success(), "pyopenvdb rewrite failed: {}", String::from_utf8_lossy(&o.stderr));
        cases.push((nan, "nan"));
    } else {
        skip("the NaN-normal case: Debian's python3-openvdb is not installed (scripts/setup.sh installs it)");
    }
    let before = listing(dir.path());
    for (level, problem) in &cases {
        let problem = *problem;
        let name = level.file_name().unwrap().to_str().unwrap();
        for method in ["poisson", "apss"] {
            let out = dir.path().join(format!("{name}.{method}.ply"));
            let png = dir.path().join(format!("{name}.{method}.png"));
            let o = shapeshifter(&[
                "mesh", level.to_str().unwrap(), "-o", out.to_str().unwrap(), "--method", method,
                "--preview", png.to_str().unwrap(),
            ]);
            assert_clean_failure(&o, name, problem);
        }
        if problem != "too few" {
            let out = dir.path().join(format!("{name}.points.ply"));
            assert_clean_failure(&shapeshifter(&["points", level.to_str().unwrap(), "-o", out.to_str().unwrap()]), name, problem);
        }
    }
    assert_eq!(listing(dir.path()), before, "a failed mesh/points run left files behind");
    let mut l = sphere_level(100);
    l.normals[3] = glam::Vec3::NAN;
    let err = write_level(&dir.path().join("nan_normal.vdb"), &l, &Provenance::default(), WriteOptions::default());
    assert!(err.unwrap_err().to_string().contains("NaN"));
    assert_eq!(listing(dir.path()), before, "a refused write left a file");
    // The same command on a good level succeeds (so the failures above are the inputs').
    let out = dir.path().join("good.ply");
    let o = shapeshifter(&["mesh", good.to_str().unwrap(), "-o", out.to_str().unwrap(), "--method", "apss", "--resolution", "64"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(mesh::load(&out).unwrap().triangles.len() > 100);
}

/// `--depth N` is `--resolution 2^N` (same bytes, deterministic), one depth
/// less is about a quarter of the vertices (surface area over cell area),
/// and the two flags together are refused.
#[test]
fn mesh_depth_is_a_grid_of_two_to_the_depth() {
    use shapeshifter::io::vdb::{write_level, Provenance, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let level = dir.path().join("sphere.vdb");
    write_level(&level, &sphere_level(2000), &Provenance::default(), WriteOptions::default()).unwrap();
    let mesh_with = |name: &str, args: &[&str]| {
        let out = dir.path().join(name);
        let mut all = vec!["mesh", level.to_str().unwrap(), "-o", out.to_str().unwrap(), "--method", "poisson"];
        all.extend_from_slice(args);
        let o = shapeshifter(&all);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        out
    };
    let d6 = mesh_with("d6.ply", &["--depth", "6"]);
    let r64 = mesh_with("r64.ply", &["--resolution", "64"]);
    assert_eq!(std::fs::read(&d6).unwrap(), std::fs::read(&r64).unwrap(), "--depth 6 differs from --resolution 64");
    let d5 = mesh_with("d5.ply", &["--depth", "5"]);
    let (v6, v5) = (mesh::load(&d6).unwrap().positions.len(), mesh::load(&d5).unwrap().positions.len());
    let ratio = v6 as f64 / v5 as f64;
    assert!((3.0..5.0).contains(&ratio), "depth 6: {v6} vertices, depth 5: {v5} (ratio {ratio:.2}, expected ~4)");
    let out = dir.path().join("both.ply");
    let o = shapeshifter(&[
        "mesh", level.to_str().unwrap(), "-o", out.to_str().unwrap(), "--depth", "6", "--resolution", "64",
    ]);
    // A usage error: exit 2, before any work.
    assert!(o.status.code() == Some(2) && stderr(&o).contains("cannot be used with"), "{:?}: {}", o.status.code(), stderr(&o));
    assert!(!out.exists());
}

#[test]
fn slurm_dry_run_writes_the_job_graph_and_stages_fill_one_run_folder() {
    let dir = tempfile::tempdir().unwrap();
    let ply = small_tower_ply(dir.path());
    let out = dir.path().join("cluster");
    let o = shapeshifter(&["slurm", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "-n", "7", "--dry-run"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let slurm = out.join("slurm");
    assert_eq!(listing(&slurm), ["encode.sbatch", "eval.sbatch", "logs", "mesh.sbatch", "sample.sbatch", "submit.sh", "train.sbatch"]);
    let train = std::fs::read_to_string(slurm.join("train.sbatch")).unwrap();
    // One task per level with a network (the cpu profile: 16, 32, 64; 128 and 256 are transferred).
    assert!(train.contains("#SBATCH --array=0-2") && train.contains("#SBATCH --requeue"), "{train}");
    let sample = std::fs::read_to_string(slurm.join("sample.sbatch")).unwrap();
    assert!(sample.contains("#SBATCH --array=0-1") && sample.contains("stage sample"), "7 variants in shards of 5: {sample}");
    assert!(!out.join("exemplar").exists(), "a dry run runs nothing");
    // A mesh that does not exist: one line, nothing written.
    let o = shapeshifter(&["slurm", "nope.obj", "-o", dir.path().join("c2").to_str().unwrap(), "--dry-run"]);
    assert_clean_failure(&o, "nope.obj", "no such mesh");
    assert!(!dir.path().join("c2").exists());

    // The stages by hand, sampling in two shards, give what one `run` gives
    // (the demo profile's networks: three steps of them leave voxels to compare).
    let tiny = [
        "--profile", "demo",
        "--set", "encode.sampling_resolution=64", "--set", "encode.finest_resolution=32",
        "--set", "train.level0_iterations=3", "--set", "train.upper_iterations=30", "--set", "train.upsampler_iterations=30",
        // One coarse shape per variant: these runs test files and stages, not wholeness.
        "--set", "sample.level0={candidates = 1}", "--set", "sample.attempts={count = 1}", "--set", "sample.proposers={}",
    ];
    let staged = dir.path().join("staged");
    let s = staged.to_str().unwrap();
    let mut enc = vec!["stage", "encode", ply.to_str().unwrap(), "-o", s];
    enc.extend(tiny);
    for args in [
        enc,
        vec!["stage", "train", s, "--level", "1"],
        vec!["stage", "train", s, "--level", "0"],
        vec!["stage", "sample", s, "--first", "1", "-n", "2"],
        vec!["stage", "sample", s, "--first", "0", "-n", "1"],
    ] {
        let o = shapeshifter(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    }
    let single = dir.path().join("single");
    let mut run = vec!["run", ply.to_str().unwrap(), "-o", single.to_str().unwrap(), "-n", "3"];
    run.extend(tiny);
    let o = shapeshifter(&run);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = shapeshifter(&["compare", single.join("variants").to_str().unwrap(), staged.join("variants").to_str().unwrap()]);
    assert!(o.status.success(), "shards differ from one run: {}", stdout(&o));
    assert!(stdout(&o).contains("identical"), "{}", stdout(&o));
    // Evaluation before every variant exists names the missing one.
    let o = shapeshifter(&["stage", "eval", s, "-n", "4"]);
    assert_clean_failure(&o, "variant_003", "is missing");
}

#[test]
fn batch_conversion_isolates_a_corrupt_file_and_names_outputs_after_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).unwrap();
    let tower = small_tower_ply(&inputs);
    let tower_b = inputs.join("tower_b.ply");
    std::fs::copy(&tower, &tower_b).unwrap();
    let corrupt = inputs.join("corrupt.ply");
    std::fs::write(&corrupt, b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999\nend_header\n").unwrap();
    let enc = dir.path().join("enc");
    let files = [tower.to_str().unwrap(), corrupt.to_str().unwrap(), tower_b.to_str().unwrap()];
    let mut args = vec!["encode"];
    args.extend(files);
    args.extend(["-o", enc.to_str().unwrap(), "--sampling-resolution", "64", "--finest", "32", "--jobs", "2"]);
    let o = shapeshifter(&args);
    assert_eq!(o.status.code(), Some(1), "one bad input fails the batch: {}", stderr(&o));
    let errors: Vec<String> = stderr(&o).lines().filter(|l| l.starts_with("error")).map(String::from).collect();
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert!(errors[0].contains("corrupt.ply"), "{}", errors[0]);
    assert!(stdout(&o).contains("encode: 2 of 3 done, 1 failed"), "{}", stdout(&o));
    for name in ["tower", "tower_b"] {
        let (manifest, _) = dataset::read(&enc.join(name)).unwrap();
        assert_eq!(manifest.levels.len(), 2);
    }
    assert!(!enc.join("corrupt").exists(), "nothing written for the corrupt input");

    // info --json: one outcome per input, in order, the failure as one line.
    let o = shapeshifter(&["info", "--json", files[0], files[1], files[2]]);
    assert_eq!(o.status.code(), Some(1));
    let report: serde_json::Value = serde_json::from_str(&stdout(&o)).expect("info --json prints JSON");
    let outcomes = report["outcomes"].as_array().unwrap();
    assert_eq!(outcomes.len(), 3);
    assert_eq!(outcomes[0]["result"]["kind"], "mesh");
    assert!(outcomes[0]["result"]["triangles"].as_u64().unwrap() > 100);
    assert!(outcomes[1]["error"].as_str().unwrap().contains("corrupt.ply"));
    assert_eq!(outcomes[2]["result"]["vertices"], outcomes[0]["result"]["vertices"]);

    // Level files of the same name in different folders: names from the folders.
    let bad = dir.path().join("bad.vdb");
    std::fs::write(&bad, b"not a vdb").unwrap();
    let levels = [enc.join("tower/level_1.vdb"), bad.clone(), enc.join("tower_b/level_1.vdb")];
    let level_args: Vec<&str> = levels.iter().map(|p| p.to_str().unwrap()).collect();
    let meshes = dir.path().join("meshes");
    let mut args = vec!["mesh"];
    args.extend(&level_args);
    args.extend(["-o", meshes.to_str().unwrap(), "--method", "apss", "--resolution", "48", "--json"]);
    let o = shapeshifter(&args);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let report: serde_json::Value = serde_json::from_str(&stdout(&o)).expect("mesh --json prints JSON");
    assert!(report["outcomes"][1]["error"].as_str().unwrap().contains("bad.vdb"));
    assert_eq!(listing(&meshes), ["tower_b_level_1.ply", "tower_level_1.ply"]);
    for name in ["tower_level_1.ply", "tower_b_level_1.ply"] {
        assert!(mesh::load(&meshes.join(name)).unwrap().triangles.len() > 100);
    }
    let points = dir.path().join("points");
    let mut args = vec!["points"];
    args.extend(&level_args);
    args.extend(["-o", points.to_str().unwrap()]);
    let o = shapeshifter(&args);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(listing(&points), ["tower_b_level_1.ply", "tower_level_1.ply"]);
    assert!(stdout(&o).contains("points: 2 of 3 done, 1 failed"), "{}", stdout(&o));
}

#[test]
fn point_grids_go_beside_the_volumes_unless_asked_and_pyopenvdb_reads_every_level_file() {
    let dir = tempfile::tempdir().unwrap();
    let ply = small_tower_ply(dir.path());
    let grids_of = |file: &Path| -> Vec<(String, u64)> {
        let o = shapeshifter(&["info", "--json", file.to_str().unwrap()]);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        v["outcomes"][0]["result"]["grids"]
            .as_array()
            .unwrap()
            .iter()
            .map(|g| (g["name"].as_str().unwrap().to_string(), g["points"].as_u64().unwrap()))
            .collect()
    };
    let mut files = Vec::new();
    for layout in ["separate", "embedded", "none"] {
        let out = dir.path().join(layout);
        let o = shapeshifter(&[
            "encode", ply.to_str().unwrap(), "-o", out.to_str().unwrap(), "--sampling-resolution", "64", "--finest", "32",
            "--points", layout,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let level = out.join("level_1.vdb");
        let mut names: Vec<String> = grids_of(&level).into_iter().map(|(n, _)| n).collect();
        names.sort();
        let volumes = ["Cd", "N", "P", "density", "mask"];
        let points_file = out.join("level_1.points.vdb");
        match layout {
            "separate" => {
                assert_eq!(names, volumes);
                let points = grids_of(&points_file);
                assert_eq!(points.len(), 1);
                assert_eq!(points[0].0, "points");
                let (l, _) = vdb::read_level(&level).unwrap();
                assert_eq!(points[0].1 as usize, l.mask.iter().filter(|&&m| m > 0.0).count(), "one point per surface voxel");
                files.push(level);
            }
            "embedded" => {
                assert_eq!(names, [&volumes[..], &["points"]].concat(), "sorted names");
                assert!(!points_file.exists());
            }
            _ => {
                assert_eq!(names, volumes);
                assert!(!points_file.exists());
            }
        }
    }
    // The first thing a pipeline script does: readAll on the level file.
    let python = || std::process::Command::new("/usr/bin/python3");
    if !matches!(python().args(["-c", "import pyopenvdb"]).output(), Ok(ref o) if o.status.success()) {
        skip("Debian's python3-openvdb is not installed (scripts/setup.sh installs it)");
        return;
    }
    let script = "import pyopenvdb as v, sys\ngrids, meta = v.readAll(sys.argv[1])\nprint(sorted(g.name for g in grids))";
    let o = python().args(["-c", script]).arg(&files[0]).output().unwrap();
    assert!(o.status.success(), "readAll failed: {}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), "['Cd', 'N', 'P', 'density', 'mask']");
}

/// `train` refuses what it cannot do before writing anything: a level that
/// detail transfer makes, a resume without a models folder, a transfer
/// setting out of range.
#[test]
fn train_refusals_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let ply = small_tower_ply(dir.path());
    let enc = dir.path().join("enc");
    let e = enc.to_str().unwrap();
    let o = shapeshifter(&["encode", ply.to_str().unwrap(), "-o", e, "--sampling-resolution", "64", "--finest", "32"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let models = dir.path().join("models");
    let m = models.to_str().unwrap();
    let o = shapeshifter(&["train", e, "--models", m, "--level", "1", "--set", "transfer.from_resolution=32"]);
    assert_clean_failure(&o, "--level 1", "made by detail transfer");
    assert!(!models.exists(), "a refused train wrote {:?}", listing(&models));
    let o = shapeshifter(&["train", e, "--models", m, "--resume"]);
    assert_clean_failure(&o, "models", "--resume, but there is no models folder");
    assert!(!models.exists());
    let o = shapeshifter(&["train", e, "--models", m, "--set", "transfer.coherence=2"]);
    assert_usage_failure(&o, "transfer", "coherence below 1");
    assert!(!models.exists());
}

/// The integrator examples (examples/) do what their documentation says:
/// `encode_mesh` writes a level file per level, `read_level` reads one back
/// and reports its surface in world units. `make test` builds these two
/// examples first (`cargo test` without target filters builds every example).
#[test]
fn the_integrator_examples_encode_and_read_levels() {
    let examples = std::path::Path::new(env!("CARGO_BIN_EXE_shapeshifter")).parent().unwrap().join("examples");
    let (encode, read) = (examples.join("encode_mesh"), examples.join("read_level"));
    if !encode.is_file() || !read.is_file() {
        common::skip("the integrator examples are not built (`make test` builds them, or `cargo build --release --examples`)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let ply = small_tower_ply(dir.path());
    let out = dir.path().join("levels");
    let o = std::process::Command::new(&encode).args([ply.as_os_str(), out.as_os_str()]).arg("64").output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let written: Vec<String> = listing(&out).into_iter().filter(|n| n.ends_with(".vdb") && !n.contains("points")).collect();
    assert_eq!(written, ["level_0.vdb", "level_1.vdb", "level_2.vdb"], "16, 32, 64");
    let o = std::process::Command::new(&read).arg(out.join("level_2.vdb")).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let (level, _) = vdb::read_level(&out.join("level_2.vdb")).unwrap();
    let text = stdout(&o);
    assert!(text.contains(&format!("64^3 voxels")) && text.contains(&format!("{} active", level.len())), "{text}");
    let o = std::process::Command::new(&read).arg(dir.path().join("missing.vdb")).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "a missing file is an error: {}", stderr(&o));
}

/// Every command that writes files writes the same ones with `-q` as
/// without: quiet only silences the log (a command whose work ran inside a
/// log macro's arguments wrote nothing at the quiet level once).
#[test]
fn quiet_or_not_every_command_writes_the_same_files() {
    let run = tiny_trained_run();
    let dir = tempfile::tempdir().unwrap();
    let level = run.join("variants/variant_000/level_2.vdb");
    let (l, e) = (level.to_str().unwrap(), run.join("exemplar"));
    let e = e.to_str().unwrap();
    let variant = run.join("variants/variant_000");
    let commands: Vec<(&str, Vec<String>)> = vec![
        ("encode", vec!["encode".into(), run.join("exemplar.ply").to_str().unwrap().into(), "--finest".into(), "64".into(), "-o".into(), "OUT/enc".into()]),
        ("sample", vec!["sample".into(), run.to_str().unwrap().into(), "-n".into(), "1".into(), "--seed".into(), "5".into(), "-o".into(), "OUT/variants".into()]),
        ("mesh", vec!["mesh".into(), l.into(), "-o".into(), "OUT/mesh.ply".into()]),
        ("points", vec!["points".into(), l.into(), "-o".into(), "OUT/points.ply".into()]),
        ("render", vec!["render".into(), l.into(), "-o".into(), "OUT/level.png".into()]),
        ("edit", vec!["edit".into(), l.into(), "-o".into(), "OUT/edited.vdb".into(), "delete".into(), "--box".into(), "0,0,0:31,63,63".into()]),
        ("eval", vec!["eval".into(), e.into(), variant.to_str().unwrap().into(), "-o".into(), "OUT/eval.json".into()]),
        ("ladder", vec!["ladder".into(), e.into(), "-o".into(), "OUT/ladder".into(), "--profile".into(), "none".into()]),
        ("usd", vec!["usd".into(), "OUT/run".into()]),
    ];
    for (name, args) in commands {
        let mut written = Vec::new();
        for quiet in [false, true] {
            let out = dir.path().join(format!("{name}_{}", if quiet { "quiet" } else { "loud" }));
            std::fs::create_dir_all(&out).unwrap();
            if name == "usd" {
                // usd writes into a run folder: a copy of the tiny run each time.
                let copy = std::process::Command::new("cp").arg("-r").arg(run).arg(out.join("run")).status().unwrap();
                assert!(copy.success());
                for f in ["variants.usda", "variants.usdc"] {
                    let _ = std::fs::remove_file(out.join("run").join(f));
                }
            }
            let mut argv: Vec<String> = args.iter().map(|a| a.replace("OUT", out.to_str().unwrap())).collect();
            if quiet {
                argv.insert(0, "-q".into());
            }
            let o = shapeshifter(&argv.iter().map(String::as_str).collect::<Vec<_>>());
            // The ladder exits 1 where a check of its order fails; quiet or
            // not, the same.
            assert!(o.status.code() == Some(0) || (name == "ladder" && o.status.code() == Some(1)), "{name} (-q: {quiet}): {}", stderr(&o));
            if quiet {
                assert!(stderr(&o).lines().all(|l| !l.starts_with("[INFO")), "{name} -q logged: {}", stderr(&o));
            }
            written.push((out.clone(), files_under(&out), o.status.code()));
        }
        let [(loud, a, ca), (quiet, b, cb)] = <[_; 2]>::try_from(written).unwrap();
        assert_eq!(ca, cb, "{name}: exit codes differ with -q");
        assert_eq!(a, b, "{name}: -q wrote other files");
        assert!(!a.is_empty(), "{name} wrote nothing");
        for rel in &a {
            let (pa, pb) = (loud.join(rel), quiet.join(rel));
            if !pa.is_file() {
                continue;
            }
            let ext = pa.extension().map(|x| x.to_string_lossy().into_owned()).unwrap_or_default();
            match ext.as_str() {
                // Records and logs hold timings; level files a fresh UUID.
                "json" | "log" | "html" | "lock" | "toml" | "usda" | "usdc" => {}
                "vdb" if !rel.ends_with(".points.vdb") => {
                    let (x, _) = vdb::read_level(&pa).unwrap();
                    let (y, _) = vdb::read_level(&pb).unwrap();
                    assert_eq!((x.coords, x.offsets, x.normals, x.colours, x.mask), (y.coords, y.offsets, y.normals, y.colours, y.mask), "{name}: {rel}");
                }
                "vdb" => {}
                _ => {
                    if std::fs::read(&pa).unwrap() != std::fs::read(&pb).unwrap() {
                        // Kept for a look: the two files, beside the test binary's scratch folder.
                        let keep = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("quiet-or-not").join(name);
                        let _ = std::fs::create_dir_all(&keep);
                        let _ = std::fs::copy(&pa, keep.join(format!("loud-{}", rel.replace('/', "_"))));
                        let _ = std::fs::copy(&pb, keep.join(format!("quiet-{}", rel.replace('/', "_"))));
                        let _ = std::fs::copy(&level, keep.join("input-level_2.vdb"));
                        panic!("{name}: {rel} differs with -q (both kept in {})", keep.display());
                    }
                }
            }
        }
    }
}

/// The files under `dir`, as paths relative to it, sorted.
fn files_under(dir: &std::path::Path) -> Vec<String> {
    fn walk(root: &std::path::Path, d: &std::path::Path, out: &mut Vec<String>) {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.push(p.strip_prefix(root).unwrap().to_string_lossy().into_owned());
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}
