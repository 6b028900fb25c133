//! The stages as whole-folder operations, and `run`: encode -> train ->
//! sample -> mesh -> preview -> evaluate in one output folder, reusing every
//! finished stage whose inputs and configuration are unchanged (each stage
//! writes a stamp `stage_<name>.json` holding the digest of what it depended
//! on, last, after its outputs).
//!
//! Folder layout of a run:
//! ```text
//! OUT/config.toml                  the resolved configuration
//! OUT/exemplar/                    encoded levels + manifest.json (+ previews)
//! OUT/models/                      checkpoints, training state, loss plots
//! OUT/variants/variant_000/        level_K.vdb, level_K.png, mesh.ply, mesh.png (+ mesh.glb: [mesh] glb)
//! OUT/eval.json                    metrics
//! OUT/contact_sheet.png            the exemplar and the variants, one camera
//! OUT/logs/                        logs of sampling/meshing child processes
//! ```

pub mod batch;
pub mod cluster;
pub mod layout;
pub mod run;
pub mod usd;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::config::{Config, MeshConfig};
use crate::level::dataset;
use crate::encode::{self, EncodeOptions};
use crate::error::{Error, Result};
use crate::util::fs::write_file;
use crate::level::Level;
use crate::io::exemplar::Exemplar;
use crate::io::mesh::Mesh;
use crate::render::{self, RenderOptions};
use crate::learn::sample::{self, SampleOptions};
use crate::learn::train;
use crate::io::vdb::{self, Provenance, WriteOptions};

/// Stamp of a finished stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Stamp {
    digest: String,
    seconds: f64,
}

fn stamp_path(dir: &Path, stage: &str) -> PathBuf {
    dir.join(format!("stage_{stage}.json"))
}

/// Whether `stage` finished in `dir` with the same digest.
fn is_done(dir: &Path, stage: &str, digest: &str) -> bool {
    read_stamp(dir, stage).is_some_and(|s| s.digest == digest)
}

/// The stamp `stage` left in `dir`, if there is one and it reads.
fn read_stamp(dir: &Path, stage: &str) -> Option<Stamp> {
    serde_json::from_str(&std::fs::read_to_string(stamp_path(dir, stage)).ok()?).ok()
}

fn mark_done(dir: &Path, stage: &str, digest: &str, seconds: f64) -> Result<()> {
    let path = stamp_path(dir, stage);
    let text = serde_json::to_string(&Stamp { digest: digest.into(), seconds }).expect("stamp serialises");
    write_file(&path, &text)
}

/// Whether `dir`'s stamp for `stage` was written before this command began
/// (what a "reusing" line may claim; children of this command write newer ones).
fn stamped_before_this_command(dir: &Path, stage: &str) -> bool {
    std::fs::metadata(stamp_path(dir, stage))
        .and_then(|m| m.modified())
        .is_ok_and(|t| t < crate::util::command_started())
}

/// A sampled variant with nothing at its finest level: its networks' masks
/// pruned every voxel at `first_empty` (a level index) or before.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct EmptyVariant {
    pub name: String,
    pub first_empty: usize,
}

/// The variant folders of `dirs` without a level file for level `finest`,
/// with the first level each lacks.
pub fn empty_variants(dirs: &[PathBuf], finest: usize) -> Vec<EmptyVariant> {
    dirs.iter()
        .filter_map(|d| {
            let first_empty = (0..=finest).find(|&k| !d.join(dataset::level_file_name(k)).is_file())?;
            Some(EmptyVariant { name: d.file_name()?.to_string_lossy().into_owned(), first_empty })
        })
        .collect()
}

/// The error of a sampling that yielded no usable variant, naming where the
/// shapes vanished (`resolutions[k]`: level k's voxels per axis) and what to try.
pub fn no_usable_variant(empty: &[EmptyVariant], resolutions: &[u32]) -> Error {
    let mut at: std::collections::BTreeMap<usize, usize> = Default::default();
    for e in empty {
        *at.entry(e.first_empty).or_default() += 1;
    }
    let wheres: Vec<String> = at
        .iter()
        .map(|(&k, &n)| format!("{n} at level {k} ({}^3)", resolutions.get(k).copied().unwrap_or(0)))
        .collect();
    // The level most variants vanished at names the network to train longer.
    let worst = at.iter().max_by_key(|(_, &n)| n).map_or(0, |(&k, _)| k);
    let knob = if worst == 0 { "train.level0_iterations" } else { "train.upper_iterations" };
    Error::Invalid(format!(
        "no usable variant: all {} variants pruned to nothing ({}): the level's network marked every voxel empty; \
         train it longer (--set {knob}=N), try another --seed, or check the exemplar's levels (shapeshifter info)",
        empty.len(),
        wheres.join(", ")
    ))
}

/// The variants of a sampling held in memory (`names[i]` for `variants[i]`,
/// levels coarsest first) that hold nothing at some level, with the first.
pub fn empty_sampled(variants: &[Vec<Level>], names: &[String]) -> Vec<EmptyVariant> {
    variants
        .iter()
        .zip(names)
        .filter_map(|(v, name)| {
            let first_empty = match v.iter().find(|l| l.is_empty()) {
                Some(l) => l.index,
                None if v.is_empty() => 0,
                None => return None,
            };
            Some(EmptyVariant { name: name.clone(), first_empty })
        })
        .collect()
}

/// An honest ending for `total` sampled variants of which `empty` hold
/// nothing: an error when that is all of them ([`no_usable_variant`]), a
/// warning naming them when some.
pub fn check_usable(empty: &[EmptyVariant], total: usize, resolutions: &[u32]) -> Result<()> {
    if total > 0 && empty.len() == total {
        return Err(no_usable_variant(empty, resolutions));
    }
    if !empty.is_empty() {
        let names: Vec<String> = empty.iter().map(|e| format!("{} (empty from level {})", e.name, e.first_empty)).collect();
        log::warn!("{} of {total} variants pruned to nothing and are left out: {}", empty.len(), names.join(", "));
    }
    Ok(())
}

fn digest(parts: &[&str]) -> String {
    crate::util::digest::short_of_parts(parts)
}

pub fn encode_options(config: &Config) -> EncodeOptions {
    EncodeOptions {
        sampling_resolution: config.encode.sampling_resolution,
        coarsest_resolution: config.encode.coarsest_resolution,
        finest_resolution: config.encode.finest_resolution,
        pooling: config.encode.pooling,
        voxel_size: config.encode.voxel_size,
        up: config.encode.up,
        cloud: crate::encode::CloudOptions {
            colour: config.encode.cloud_colour,
            normal_neighbours: config.encode.normal_neighbours,
            orientation: config.encode.normal_orientation,
            estimate_normals: config.encode.estimate_normals,
        },
        ..Default::default()
    }
}

/// Encodes the mesh file `mesh_path` into `dir` (the `encode` command, one
/// file of a batch): level files, previews if asked, manifest.json.
pub fn encode_file(
    mesh_path: &Path,
    dir: &Path,
    options: &EncodeOptions,
    previews: Option<&RenderOptions>,
    write: WriteOptions,
) -> Result<dataset::Manifest> {
    let exemplar = Exemplar::load(mesh_path)?;
    let digest = dataset::file_sha256(mesh_path)?;
    let (levels, stats) = encode::encode_exemplar(&exemplar, options).map_err(|e| Error::file(mesh_path, e.to_string()))?;
    let source = mesh_path.display().to_string();
    let manifest = dataset::write(dir, &exemplar, &source, &digest, &levels, options, &stats, previews, write)?;
    log::info!(
        "encoded {source} in {:.2} s: {}",
        stats.total_s,
        manifest.levels.iter().map(|l| format!("{}^3: {} voxels", l.resolution, l.voxels)).collect::<Vec<_>>().join(", ")
    );
    Ok(manifest)
}

/// Encodes `mesh` into `dir` unless already done with the same source and
/// options. Returns the levels.
pub fn encode_stage(exemplar: &Exemplar, source: &str, source_sha: &str, config: &Config, dir: &Path) -> Result<Vec<Level>> {
    let d = digest(&[source_sha, &config.stage_digest("encode")]);
    if is_done(dir, "encode", &d) {
        log::info!("encode: reusing {}", dir.display());
        return Ok(dataset::read(dir)?.1);
    }
    let t = Instant::now();
    let options = encode_options(config);
    let (levels, stats) = encode::encode_exemplar(exemplar, &options)?;
    dataset::write(dir, exemplar, source, source_sha, &levels, &options, &stats, Some(&render::preview_options()), config.output.write_options())?;
    log::info!(
        "encode: {} levels in {:.1} s ({})",
        levels.len(),
        stats.total_s,
        levels.iter().map(|l| format!("{}^3 {}", l.resolution, l.len())).collect::<Vec<_>>().join(", ")
    );
    mark_done(dir, "encode", &d, t.elapsed().as_secs_f64())?;
    Ok(levels)
}

/// What level `k`'s trained models depend on.
fn train_digest(source_sha: &str, config: &Config, k: usize) -> String {
    digest(&[source_sha, &config.stage_digest("train"), &k.to_string()])
}

/// A level's training time in units of one upper-level diffusion step, for
/// ordering the jobs: a level-0 step (the 16^3 box) costs about 0.45 of one
/// (the tower on the `cpu` profile: 41 ms against 85-110 ms per step with
/// the upsampler's share), an upsampler step about 0.25.
pub fn training_cost(config: &Config, level: usize) -> f64 {
    let tc = &config.train;
    if level == 0 {
        0.45 * tc.level0_iterations as f64
    } else {
        tc.upper_iterations as f64 + 0.25 * tc.upsampler_iterations as f64
    }
}

/// The levels whose training is not finished (no stamp for this exemplar and
/// configuration) in `models`: of the exemplar's `level_count` levels, those
/// with a network (detail transfer makes those of `transfer.from_resolution` and finer).
pub fn levels_to_train(level_count: usize, source_sha: &str, config: &Config, models: &Path) -> Vec<usize> {
    (0..level_count.min(config.trained_levels()))
        .filter(|&k| !is_done(models, &format!("train_level_{k}"), &train_digest(source_sha, config, k)))
        .collect()
}

/// Trains the levels not yet trained of a run folder as concurrent child
/// processes, each running `exe --threads T stage train OUT --level K` exactly
/// as a cluster task does (so the weights are those of a sequential run:
/// every step reseeds its own process's generators). See
/// [`train_in_processes`]. Returns the levels trained.
pub fn train_concurrently(
    paths: &RunPaths,
    config: &Config,
    exe: &Path,
    threads: i32,
    device: &str,
    jobs: usize,
    progress: bool,
) -> Result<Vec<usize>> {
    let (manifest, levels) = dataset::read(&paths.exemplar())?;
    let models = paths.models();
    record_config(&models, config)?;
    let todo = levels_to_train(levels.len(), &manifest.source_sha256, config, &models);
    train_in_processes(&models, &todo, config, jobs, progress, |k| {
        let mut c = std::process::Command::new(exe);
        c.args(["--threads", &threads.to_string(), "stage", "train"])
            .arg(&paths.root)
            .args(["--level", &k.to_string(), "--device", device]);
        c
    })?;
    Ok(todo)
}

/// Runs `child(k)` for every level in `todo`, at most `jobs` at a time, the
/// costliest first ([`training_cost`]: the longest job must not start last);
/// each child's stderr goes to
/// `models/level_K_train.log`, and `progress` draws one bar per level from
/// those logs. Fails, after the running children end, naming every level
/// whose process failed and the last line of its log.
pub fn train_in_processes(
    models: &Path,
    todo: &[usize],
    config: &Config,
    jobs: usize,
    progress: bool,
    child: impl Fn(usize) -> std::process::Command,
) -> Result<()> {
    let mut queue: Vec<usize> = todo.to_vec();
    // Popped from the end: the costliest first (the finer of equal costs).
    queue.sort_by(|&a, &b| training_cost(config, a).total_cmp(&training_cost(config, b)).then(a.cmp(&b)));
    let tc = &config.train;
    let total = |k: usize| if k == 0 { tc.level0_iterations } else { tc.upsampler_iterations + tc.upper_iterations };
    let bars = indicatif::MultiProgress::with_draw_target(if progress {
        indicatif::ProgressDrawTarget::stderr()
    } else {
        indicatif::ProgressDrawTarget::hidden()
    });
    let style = indicatif::ProgressStyle::with_template("level {prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} {msg}")
        .expect("valid template");
    let mut running: Vec<(usize, std::process::Child, indicatif::ProgressBar, PathBuf)> = Vec::new();
    let result = schedule(models, &mut queue, &mut running, jobs, &bars, &style, &total, &child);
    if result.is_err() && crate::util::interrupt::requested().is_none() {
        // Leave no orphan training on: stop the children still running.
        for (_, process, bar, _) in running.iter_mut() {
            let _ = process.kill();
            let _ = process.wait();
            crate::util::interrupt::forget(process);
            bar.abandon_with_message("stopped");
        }
    }
    result?;
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn schedule(
    models: &Path,
    queue: &mut Vec<usize>,
    running: &mut Vec<(usize, std::process::Child, indicatif::ProgressBar, PathBuf)>,
    jobs: usize,
    bars: &indicatif::MultiProgress,
    style: &indicatif::ProgressStyle,
    total: &dyn Fn(usize) -> usize,
    child: &dyn Fn(usize) -> std::process::Command,
) -> Result<()> {
    let mut failed: Vec<String> = Vec::new();
    let t0 = Instant::now();
    let count = queue.len();
    while !queue.is_empty() || !running.is_empty() {
        // After a stop signal (forwarded to the children): start nothing
        // more, and wait for the running children to checkpoint and end.
        let stopping = crate::util::interrupt::requested().is_some();
        while running.len() < jobs.max(1) && failed.is_empty() && !stopping {
            let Some(k) = queue.pop() else { break };
            let log_path = models.join(format!("level_{k}_train.log"));
            let log = std::fs::File::create(&log_path).map_err(|e| Error::file(&log_path, e.to_string()))?;
            let process = crate::util::interrupt::spawn(child(k).stdout(std::process::Stdio::null()).stderr(log))
                .map_err(|e| Error::Invalid(format!("cannot start the training process of level {k} ({e})")))?;
            let bar = bars.add(indicatif::ProgressBar::new(total(k) as u64));
            bar.set_style(style.clone());
            bar.set_prefix(k.to_string());
            running.push((k, process, bar, log_path));
        }
        if !failed.is_empty() || stopping {
            queue.clear(); // start nothing more after a failure or a stop
        }
        std::thread::sleep(std::time::Duration::from_millis(if stopping { 50 } else { 500 }));
        let mut i = 0;
        while i < running.len() {
            let (k, process, bar, log_path) = &mut running[i];
            bar.set_position(steps_logged(log_path) as u64);
            match process.try_wait().map_err(|e| Error::Invalid(format!("level {k} training: {e}")))? {
                None => i += 1,
                Some(status) => {
                    crate::util::interrupt::forget(process);
                    if status.success() {
                        bar.finish_with_message("done");
                    } else {
                        let last = last_log_line(log_path);
                        failed.push(format!("level {k} training failed ({status}): {last} (log: {})", log_path.display()));
                        bar.abandon_with_message("failed");
                    }
                    running.swap_remove(i);
                }
            }
        }
    }
    crate::util::interrupt::check()?;
    if !failed.is_empty() {
        return Err(Error::Invalid(failed.join("; ")));
    }
    log::info!("train: {count} levels on {} processes in {:.0} s", jobs.max(1), t0.elapsed().as_secs_f64());
    Ok(())
}

/// Runs shards `0..n` of a stage as at most `jobs` concurrent child processes,
/// `child(first, count)` building each one's command (e.g. `stage sample OUT
/// --first K -n N`), with `jobs` contiguous shards of near-equal size. Each
/// child's stderr goes to `log_dir/<what>_K.log`; fails naming every shard
/// that failed and the last line of its log.
pub fn run_shards(
    n: usize,
    jobs: usize,
    log_dir: &Path,
    what: &str,
    child: impl Fn(usize, usize) -> std::process::Command,
) -> Result<()> {
    let jobs = jobs.clamp(1, n.max(1));
    let mut running = Vec::new();
    let mut first = 0;
    for j in 0..jobs {
        let count = n / jobs + usize::from(j < n % jobs);
        if count == 0 {
            continue;
        }
        let log_path = log_dir.join(format!("{what}_{first}.log"));
        let log = std::fs::File::create(&log_path).map_err(|e| Error::file(&log_path, e.to_string()))?;
        let spawned = crate::util::interrupt::spawn(child(first, count).stdout(std::process::Stdio::null()).stderr(log));
        match spawned {
            Ok(c) => running.push((first, c, log_path)),
            Err(e) => {
                for (_, c, _) in running.iter_mut() {
                    let _ = c.kill();
                    let _ = c.wait();
                    crate::util::interrupt::forget(c);
                }
                return Err(Error::Invalid(format!("cannot start a {what} process ({e})")));
            }
        }
        first += count;
    }
    let mut failed = Vec::new();
    for (first, mut c, log_path) in running {
        let status = c.wait().map_err(|e| Error::Invalid(format!("{what} shard {first}: {e}")))?;
        crate::util::interrupt::forget(&c);
        if !status.success() {
            let last = last_log_line(&log_path);
            failed.push(format!("{what} from variant {first} failed ({status}): {last} (log: {})", log_path.display()));
        }
    }
    // Children stopped by a forwarded signal are not failures of their own.
    crate::util::interrupt::check()?;
    if failed.is_empty() {
        Ok(())
    } else {
        Err(Error::Invalid(failed.join("; ")))
    }
}

/// The last line of a child's log, or what explains an empty one: a child
/// whose disk is full cannot write its log either.
fn last_log_line(log: &Path) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    match text.lines().rev().find(|l| !l.trim().is_empty()) {
        Some(l) => l.to_string(),
        None if crate::util::fs::disk_is_full(log) => "no output: No space left on device (its disk is full)".into(),
        None => "no output".into(),
    }
}

/// Steps a training log reports (upsampler steps, then diffusion steps,
/// from the "<phase> step X/Y" lines written every tenth of a phase).
fn steps_logged(log: &Path) -> usize {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let mut upsampler = 0;
    let mut diffusion = 0;
    for line in text.lines() {
        let Some((head, rest)) = line.split_once(" step ") else { continue };
        let Some(done) = rest.split('/').next().and_then(|v| v.trim().parse::<usize>().ok()) else { continue };
        if head.ends_with("upsampler") {
            upsampler = done;
        } else if head.ends_with("diffusion") {
            diffusion = done;
        }
    }
    upsampler + diffusion
}

/// The levels `train --level` (`only`) or a whole training asks for: an
/// error for a level the exemplar lacks or that detail transfer makes.
pub fn levels_to_run(config: &Config, levels: &[Level], only: Option<usize>) -> Result<Vec<usize>> {
    let trained = trained_levels(config, levels);
    Ok(match only {
        Some(k) if k >= levels.len() => {
            return Err(Error::Invalid(format!("--level {k}: the exemplar has levels 0..{}", levels.len() - 1)))
        }
        Some(k) if k >= trained => {
            return Err(Error::Invalid(format!(
                "--level {k}: made by detail transfer (transfer.from_resolution = {}), nothing to train",
                config.transfer.from_resolution
            )))
        }
        Some(k) => vec![k],
        None => (0..trained).collect(),
    })
}

/// Trains the given levels (all when `only` is None) into `models_dir`,
/// resuming any level that was interrupted.
pub fn train_stage(
    levels: &[Level],
    source_sha: &str,
    config: &Config,
    device: tch::Device,
    models_dir: &Path,
    only: Option<usize>,
    progress: bool,
) -> Result<Vec<train::TrainReport>> {
    let which = levels_to_run(config, levels, only)?;
    std::fs::create_dir_all(models_dir).map_err(|e| Error::file(models_dir, e.to_string()))?;
    let mut reports = Vec::new();
    for k in which {
        let d = train_digest(source_sha, config, k);
        let stage = format!("train_level_{k}");
        if is_done(models_dir, &stage, &d) {
            log::info!("train level {k}: reusing {}", models_dir.display());
            continue;
        }
        let t = Instant::now();
        // Resume whatever a previous (killed) run of this level left.
        let resume = train::state_path(models_dir, k).exists();
        let r = train::train_level(&train::TrainJob { resume, progress, ..train::TrainJob::new(levels, k, config, device, models_dir) })?;
        log::info!(
            "train level {k}: {} + {} steps in {:.0} s, loss {:.4} -> {:.4}",
            r.upsampler_steps,
            r.diffusion_steps,
            r.seconds,
            r.diffusion_loss_start,
            r.diffusion_loss_end
        );
        if r.finished {
            mark_done(models_dir, &stage, &d, t.elapsed().as_secs_f64())?;
        }
        if r.interrupted {
            crate::util::interrupt::check()?;
        }
        reports.push(r);
    }
    Ok(reports)
}

/// The folder name of variant `i`: `variant_007`.
pub fn variant_name(i: usize) -> String {
    format!("variant_{i:03}")
}

pub fn variant_dir(variants_dir: &Path, i: usize) -> PathBuf {
    variants_dir.join(variant_name(i))
}

/// Samples variants `options.first .. first + n` into
/// `variants_dir/variant_XXX/` (XXX = the variant's index). Each variant
/// folder is stamped on its own, so shards written by different jobs fill one
/// folder and a re-run skips what is already there.
#[allow(clippy::too_many_arguments)]
pub fn sample_stage(
    exemplar_levels: &[Level],
    exemplar_name: &str,
    exemplar_open: bool,
    exemplar_crs: Option<&str>,
    config: &Config,
    device: tch::Device,
    models_dir: &Path,
    variants_dir: &Path,
    options: &SampleOptions,
    previews: bool,
) -> Result<Vec<PathBuf>> {
    let indices: Vec<usize> = (options.first..options.first + options.n).collect();
    let dirs: Vec<PathBuf> = indices.iter().map(|&i| variant_dir(variants_dir, i)).collect();
    // What a variant depends on: the configuration, the trained models, the
    // sampling options except which shard computed it, and its index.
    let common = digest(&[
        &config.stage_digest("sample"),
        &std::fs::read_to_string(train::state_path(models_dir, trained_levels(config, exemplar_levels) - 1)).unwrap_or_default(),
        &format!("{:?}", SampleOptions { first: 0, n: 0, ..options.clone() }),
    ]);
    let todo: Vec<usize> = indices
        .iter()
        .zip(&dirs)
        .filter(|(i, d)| !is_done(d, "sample", &digest(&[&common, &i.to_string()])))
        .map(|(&i, _)| i)
        .collect();
    let reused = dirs.iter().zip(&indices).filter(|(d, i)| !todo.contains(i) && stamped_before_this_command(d, "sample")).count();
    if reused > 0 {
        log::info!("sample: reusing {reused} variants in {}", variants_dir.display());
    }
    if todo.is_empty() {
        return Ok(dirs);
    }
    let t = Instant::now();
    let models = sample::load_models(models_dir, config, models_needed(config, exemplar_levels, options.stop_level), device)?;
    let provenance = Provenance {
        exemplar: exemplar_name.into(),
        seed: Some(options.seed),
        config_digest: config.digest(),
        exemplar_open,
        crs: exemplar_crs.map(str::to_string),
    };
    for &i in &todo {
        crate::util::interrupt::check()?;
        let tv = Instant::now();
        let one = SampleOptions { first: i, n: 1, ..options.clone() };
        let v = sample_variants(&models, exemplar_levels, &one, None)?;
        let dir = variant_dir(variants_dir, i);
        dataset::write_variant(&dir, &v[0], &provenance, previews, config.output.write_options())?;
        mark_done(&dir, "sample", &digest(&[&common, &i.to_string()]), tv.elapsed().as_secs_f64())?;
    }
    log::info!("sample: {} variants in {:.1} s", todo.len(), t.elapsed().as_secs_f64());
    Ok(dirs)
}

/// Levels of an exemplar with a trained network under `config` (level 0 always has one).
pub fn trained_levels(config: &Config, exemplar_levels: &[Level]) -> usize {
    exemplar_levels.len().min(config.trained_levels()).max(1)
}

/// How many levels' networks sampling up to `stop_level` (None: the finest) needs.
pub fn models_needed(config: &Config, exemplar_levels: &[Level], stop_level: Option<usize>) -> usize {
    stop_level.map_or(usize::MAX, |k| k + 1).min(trained_levels(config, exemplar_levels))
}

/// Samples variants: the trained levels by the reverse process
/// ([`sample::sample`]), those of `transfer.from_resolution` and finer by detail transfer
/// ([`transfer::extend`]), up to `opts.stop_level`. With `from` (a level k),
/// levels k+1 .. are produced from it. Returns, per variant, its levels
/// coarsest first (`from` itself not included).
pub fn sample_variants(
    models: &sample::Models,
    exemplar_levels: &[Level],
    opts: &SampleOptions,
    from: Option<Level>,
) -> Result<Vec<Vec<Level>>> {
    let count = exemplar_levels.len();
    let last = opts.stop_level.unwrap_or(count.saturating_sub(1));
    if last >= count {
        return Err(Error::Invalid(format!("stop level {last} asked for, the exemplar has levels 0..{}", count.saturating_sub(1))));
    }
    // Levels with a network under the configuration; the finer ones are transferred.
    let networks = trained_levels(&models.config, exemplar_levels);
    let diffusion_last = last.min(networks - 1);
    let start = from.as_ref().map_or(0, |l| l.index + 1);
    if start <= diffusion_last && models.levels() <= diffusion_last {
        return Err(Error::Invalid(format!(
            "level {diffusion_last} needs its trained network (networks of levels 0..{} loaded; detail transfer: {})",
            models.levels() - 1,
            match models.config.transfer.from_resolution {
                0 => "off".to_string(),
                r => format!("from {r}^3"),
            }
        )));
    }
    let mut variants = match &from {
        // Continuing from a level at or past the networks' last: transfer only.
        Some(level) if level.index >= diffusion_last && level.index < last => vec![Vec::new(); opts.n],
        _ => sample::sample(models, exemplar_levels, &SampleOptions { stop_level: Some(diffusion_last), ..opts.clone() }, from.clone())?,
    };
    if last > diffusion_last {
        let config = &models.config.transfer;
        for (i, v) in variants.iter_mut().enumerate() {
            let coarse = v.last().or(from.as_ref()).ok_or_else(|| Error::Invalid("nothing to transfer from".into()))?;
            let finer = crate::transfer::extend(exemplar_levels, coarse, last, config, sample::variant_seed(opts.seed, opts.first + i))?;
            v.extend(finer);
        }
    }
    Ok(variants)
}

/// Writes the resolved configuration into a folder (`config.toml`).
pub fn record_config(dir: &Path, config: &Config) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    let path = dir.join("config.toml");
    let text = config.to_toml();
    write_file(&path, &text)
}

/// The surface voxels (mask > 0) of a level as oriented coloured points in
/// the exemplar's frame; spacing = the level's voxel size in world units. An
/// error when there are none (nothing to mesh or write).
pub fn oriented_points(level: &Level) -> Result<crate::geom::points::OrientedPoints> {
    let mut points = crate::geom::points::OrientedPoints::from_level(level);
    if points.is_empty() {
        return Err(Error::Invalid("the level has no active voxels (mask > 0)".into()));
    }
    points.normals.iter_mut().for_each(|n| *n = n.normalize_or_zero());
    Ok(points)
}

/// Meshes a level: Poisson for closed exemplars, APSS for open ones unless
/// `method` says otherwise. `resolution`: contouring grid cells along the
/// longest axis; None: the method's default (Poisson 256, APSS 512).
pub fn mesh_level(
    level: &Level,
    exemplar_open: bool,
    method: Option<crate::recon::Method>,
    resolution: Option<u32>,
) -> Result<(Mesh, crate::recon::Method)> {
    use crate::recon::{self, ApssOptions, Method, PoissonOptions};
    let method = method.unwrap_or(if exemplar_open { Method::Apss } else { Method::Poisson });
    let points = oriented_points(level)?;
    let (mut poisson, mut apss) = (PoissonOptions::default(), ApssOptions::default());
    if let Some(resolution) = resolution {
        (poisson.resolution, apss.resolution) = (resolution, resolution);
    }
    let m = recon::reconstruct(&points, method, &poisson, &apss)?;
    let mesh = Mesh {
        name: "mesh".into(),
        positions: m.positions,
        triangles: m.triangles,
        colours: crate::io::mesh::MeshColours::PerVertex(m.colours),
        texture: None,
    };
    Ok((mesh, method))
}

/// Meshes the finest level of every variant folder into `mesh.ply` (and
/// `mesh.glb` when `settings.glb`), decimated to `settings.faces` triangles
/// when that is not 0, and `mesh.png`. A light mesh is also baked into a
/// texture (`settings.texture_size()`): `mesh.obj` + `mesh.mtl` +
/// `mesh_basecolor.png` and a textured `mesh.glb`. A variant that fails to
/// mesh is reported and skipped; one whose texture fails keeps its vertex
/// colours, with a warning.
pub fn mesh_stage(dirs: &[PathBuf], exemplar_open: bool, resolution: u32, settings: &MeshConfig) -> Result<usize> {
    use layout::{MESH_GLB, MESH_MTL, MESH_OBJ, MESH_PLY, MESH_PREVIEW, MESH_TEXTURE};
    let mut done = 0;
    for dir in dirs {
        crate::util::interrupt::check()?;
        let t = Instant::now();
        // The mesh depends on the finest level's data: its file's digest,
        // checked before anything is read (a finished mesh costs one hash).
        let finest_file = match crate::eval::evaluate::level_files(dir) {
            Ok(files) => files[files.len() - 1].1.clone(),
            Err(e) => {
                log::warn!("not meshed: {e}");
                continue;
            }
        };
        let out = dir.join(MESH_PLY);
        let glb = dir.join(MESH_GLB);
        let texture = settings.texture_size();
        let mut parts = vec![
            dataset::file_sha256(&finest_file).unwrap_or_default(),
            resolution.to_string(),
            exemplar_open.to_string(),
            settings.faces.to_string(),
            settings.glb.to_string(),
        ];
        // Only a baked mesh's digest names its texture: meshes made before
        // textures existed stay reused.
        if let Some(size) = texture {
            parts.push(format!("texture {size}"));
        }
        let d = digest(&parts.iter().map(String::as_str).collect::<Vec<_>>());
        let textured_files = [MESH_OBJ, MESH_MTL, MESH_TEXTURE].map(|f| dir.join(f));
        let complete = out.is_file()
            && (glb.is_file() || !(settings.glb || texture.is_some()))
            && (texture.is_none() || textured_files.iter().all(|f| f.is_file()));
        if is_done(dir, "mesh", &d) && complete {
            done += 1;
            continue;
        }
        let finest = match vdb::read_level(&finest_file) {
            Ok((level, _)) => level,
            Err(e) => {
                log::warn!("not meshed: {e}");
                continue;
            }
        };
        // No glTF or textured file from an earlier setting beside a new mesh.ply.
        let _ = std::fs::remove_file(&glb);
        for f in &textured_files {
            let _ = std::fs::remove_file(f);
        }
        match mesh_level(&finest, exemplar_open, None, Some(resolution)).and_then(|(m, _)| light_mesh(m, settings.faces)) {
            Ok(mesh) => {
                crate::io::mesh::save(&mesh, &out, true)?;
                let baked = texture.and_then(|size| match bake_level_texture(&mesh, &finest, size) {
                    Ok(m) => Some(m),
                    Err(e) => {
                        log::warn!("{}: no texture, vertex colours only: {e}", dir.display());
                        None
                    }
                });
                if let Some(textured) = &baked {
                    crate::io::mesh::save(textured, &textured_files[0], true)?;
                }
                if settings.glb || baked.is_some() {
                    crate::io::mesh::save(baked.as_ref().unwrap_or(&mesh), &glb, true)?;
                }
                let view = render::RenderOptions { up: Some(finest.frame.up), ..render::preview_options() };
                let img = render::render_mesh(baked.as_ref().unwrap_or(&mesh), &view)?;
                render::save_png(&img, &dir.join(MESH_PREVIEW))?;
                mark_done(dir, "mesh", &d, t.elapsed().as_secs_f64())?;
                done += 1;
            }
            Err(e) => {
                // No mesh rather than a stale one.
                let _ = std::fs::remove_file(&out);
                log::warn!("{}: not meshed: {e}", dir.display());
            }
        }
    }
    Ok(done)
}

/// `mesh` (made from `level`) with a UV atlas and a texture of `size`
/// texels baked from the level's points ([`crate::recon::bake`]).
pub fn bake_level_texture(mesh: &Mesh, level: &Level, size: u32) -> Result<Mesh> {
    let points = oriented_points(level)?;
    let (textured, r) = crate::recon::bake::bake_texture(mesh, &points, size)?;
    log::info!(
        "texture: {} charts in {}x{} texels ({:.0}% used), {} -> {} vertices, unwrap {:.1} s, bake {:.1} s",
        r.charts,
        r.width,
        r.height,
        100.0 * r.utilization,
        r.vertices_before,
        r.vertices_after,
        r.seconds_unwrap,
        r.seconds_bake
    );
    Ok(textured)
}

/// `mesh` decimated to `faces` triangles (0: as many as it has), with a
/// log line saying what the decimation did, and without zero-area
/// triangles: decimation leaves a few (corners copied onto one position),
/// they carry no surface and every reader drops them, so a mesh file and
/// the USD layer read from it count the same triangles.
pub fn light_mesh(mesh: Mesh, faces: usize) -> Result<Mesh> {
    let mut light = if faces == 0 {
        mesh
    } else {
        let t = std::time::Instant::now();
        let (light, report) = crate::io::mesh::decimate(&mesh, &crate::io::mesh::DecimateOptions::new(faces))?;
        log::info!(
            "decimated {} -> {} triangles (budget {faces}, {} sharp edges kept) in {:.1} s",
            report.faces_before,
            report.faces_after,
            report.feature_edges,
            t.elapsed().as_secs_f64()
        );
        if report.faces_after > faces {
            log::warn!("{} triangles remain above the budget of {faces}: no further collapse was legal", report.faces_after);
        }
        light
    };
    let dropped = light.drop_degenerate_triangles();
    if dropped > 0 {
        log::debug!("{dropped} zero-area triangles left out of the mesh");
    }
    Ok(light)
}

/// The finest level in a folder of `level_K.vdb` files (a variant folder, an
/// encoded exemplar, a ladder rung), with the folder's name.
pub fn finest_in(dir: &Path) -> Result<(String, Level)> {
    let files = crate::eval::evaluate::level_files(dir)?;
    let (finest, _) = vdb::read_level(&files[files.len() - 1].1)?;
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok((name, finest))
}

/// Most entries on one contact sheet (the reference and 35 more): a larger set
/// would make an image no one can read, and one over the size limit.
pub const SHEET_MAX: usize = 36;

/// Writes `OUT/contact_sheet.png` of (name, level) pairs, the first the
/// reference; past [`SHEET_MAX`] entries, the first ones.
pub fn write_contact_sheet(path: &Path, entries: &[(String, Level)]) -> Result<()> {
    if entries.len() > SHEET_MAX {
        log::info!("contact sheet: the first {} of {} shapes", SHEET_MAX, entries.len());
    }
    let refs: Vec<(String, &Level)> = entries.iter().take(SHEET_MAX).map(|(n, l)| (n.clone(), l)).collect();
    let sheet = render::contact_sheet(&refs, &render::SheetOptions::default())?;
    render::save_png(&sheet, path)?;
    Ok(())
}

/// The degradation ladder of an encoded exemplar, scored.
#[derive(Clone, Debug, Serialize)]
pub struct LadderOutcome {
    pub options: crate::eval::ladder::LadderOptions,
    pub evaluation: crate::eval::evaluate::Evaluation,
    /// Every expectation on every rung, and whether it held.
    pub checks: Vec<crate::eval::ladder::CheckResult>,
    /// Rungs that could not be scored, and why.
    pub skipped: Vec<String>,
}

impl LadderOutcome {
    pub fn failed(&self) -> impl Iterator<Item = &crate::eval::ladder::CheckResult> {
        self.checks.iter().filter(|c| !c.ok)
    }
}

/// Builds the ladder of the encoded exemplar in `exemplar_dir` into `out`
/// (one folder per rung, `contact_sheet.png`, `ladder.json`), scores every
/// rung as a variant and checks the expected order. With `config`, the
/// `untrained` rung is sampled from freshly initialised networks of that
/// configuration.
pub fn ladder_stage(exemplar_dir: &Path, out: &Path, config: Option<&Config>, device: tch::Device) -> Result<LadderOutcome> {
    use crate::eval::ladder::{self, LadderOptions, Rung};
    let (manifest, levels) = dataset::read(exemplar_dir)?;
    let options = LadderOptions::default();
    let mut rungs = ladder::degrade(&levels, &options)?;
    let mut skipped = Vec::new();
    match config {
        Some(config) => {
            let t = Instant::now();
            let untrained = sample::untrained_models(config, trained_levels(config, &levels), device, options.seed).and_then(|m| {
                sample_variants(&m, &levels, &SampleOptions::from_config(config, 1, options.seed), None)
            });
            match untrained {
                Ok(mut v) if v.first().and_then(|l| l.last()).is_some_and(|l| l.len() > 0 && l.index + 1 == levels.len()) => {
                    log::info!("ladder: untrained networks sampled in {:.1} s", t.elapsed().as_secs_f64());
                    rungs.push((Rung::Untrained, v.swap_remove(0)));
                }
                Ok(_) => skipped.push("untrained: every voxel was pruned before the finest level (nothing to score)".into()),
                Err(e) => skipped.push(format!("untrained: {e}")),
            }
        }
        None => skipped.push("untrained: no configuration (no models folder, no --profile)".into()),
    }
    let provenance = Provenance {
        exemplar: manifest.exemplar.clone(),
        seed: Some(options.seed),
        config_digest: config.map(|c| c.digest()).unwrap_or_default(),
        exemplar_open: manifest.open_surface,
        crs: manifest.crs.clone(),
    };
    if !rungs.iter().any(|(r, _)| *r == Rung::Untrained) {
        let _ = std::fs::remove_dir_all(out.join(Rung::Untrained.name()));
    }
    ladder::write_rungs(out, &rungs, &provenance)?;
    let files: Vec<crate::eval::evaluate::VariantFiles> = rungs
        .iter()
        .map(|(r, l)| crate::eval::evaluate::VariantFiles {
            name: r.name().into(),
            finest: l[l.len() - 1].clone(),
            coarsest: l[0].clone(),
            structure: crate::level::structure::structure_level(l).cloned(),
            mesh: None,
        })
        .collect();
    let evaluation = crate::eval::evaluate::evaluate(exemplar_dir, None, &files, 256)?;
    skipped.extend(evaluation.unscored.iter().cloned());
    let finest = &levels[levels.len() - 1];
    let colourful = crate::eval::metrics::colour::spread(&finest.colours) > 0.02;
    if !colourful {
        skipped.push("colour expectations: the exemplar has one colour (nothing to wash out or shuffle)".into());
    }
    let checks = ladder::check(&evaluation.report.variants, colourful);
    let entries: Vec<(String, Level)> = files.into_iter().map(|f| (f.name, f.finest)).collect();
    write_contact_sheet(&out.join("contact_sheet.png"), &entries)?;
    let outcome = LadderOutcome { options, evaluation, checks, skipped };
    let path = out.join("ladder.json");
    let text = serde_json::to_string_pretty(&outcome).map_err(|e| Error::file(&path, e.to_string()))?;
    write_file(&path, &text)?;
    Ok(outcome)
}

/// The folders and files of a run (see the module documentation), shared by
/// `run` (every stage in one process) and the `stage` commands (one stage per
/// process, as a cluster job runs it).
#[derive(Clone, Debug)]
pub struct RunPaths {
    pub root: PathBuf,
}

impl RunPaths {
    pub fn new(root: &Path) -> Self {
        RunPaths { root: root.to_path_buf() }
    }
    pub fn config(&self) -> PathBuf {
        self.root.join("config.toml")
    }
    pub fn exemplar(&self) -> PathBuf {
        self.root.join("exemplar")
    }
    pub fn models(&self) -> PathBuf {
        self.root.join("models")
    }
    pub fn variants(&self) -> PathBuf {
        self.root.join("variants")
    }
    pub fn eval_json(&self) -> PathBuf {
        self.root.join("eval.json")
    }
    pub fn contact_sheet(&self) -> PathBuf {
        self.root.join("contact_sheet.png")
    }
    pub fn report(&self) -> PathBuf {
        self.root.join("report.html")
    }

    /// The configuration `stage encode` (or `run`) recorded in the run folder.
    pub fn read_config(&self) -> Result<Config> {
        let p = self.config();
        if !p.is_file() {
            return Err(Error::file(&self.root, "has no config.toml: run `stage encode` (or `run`) into it first"));
        }
        Config::read(&p)
    }
}

/// Where an exemplar comes from.
#[derive(Clone, Copy, Debug)]
pub enum ExemplarSource<'a> {
    File(&'a Path),
    /// The embedded demo tower.
    Demo,
}

/// Stage 1: records the configuration in the run folder and encodes the
/// exemplar into `OUT/exemplar` (the demo exemplar is also written as
/// `exemplar.ply` and `exemplar.png`).
/// Returns the exemplar's name as reports show it (its path, or the demo's) and
/// its levels.
pub fn run_encode(source: ExemplarSource, paths: &RunPaths, config: &Config) -> Result<(String, Vec<Level>)> {
    let demo = matches!(source, ExemplarSource::Demo);
    let (exemplar, name, sha) = match source {
        ExemplarSource::File(p) => (Exemplar::load(p)?, p.display().to_string(), dataset::file_sha256(p)?),
        ExemplarSource::Demo => {
            let m = crate::encode::exemplar::ruined_tower(&Default::default());
            let sha = dataset::mesh_sha256(&m);
            (Exemplar::Mesh(m), "(embedded demo exemplar)".to_string(), sha)
        }
    };
    record_config(&paths.root, config)?;
    if let (true, Exemplar::Mesh(mesh)) = (demo, &exemplar) {
        crate::io::mesh::save(mesh, &paths.root.join("exemplar.ply"), true)?;
        render::save_png(&render::render_mesh(mesh, &render::preview_options())?, &paths.root.join("exemplar.png"))?;
    }
    let levels = encode_stage(&exemplar, &name, &sha, config, &paths.exemplar())?;
    Ok((name, levels))
}

/// Stage 2: trains every level (or `only` one, as one task of a job array)
/// into `OUT/models`, resuming what a killed job left.
pub fn run_train(paths: &RunPaths, config: &Config, device: tch::Device, only: Option<usize>, progress: bool) -> Result<Vec<train::TrainReport>> {
    let (manifest, levels) = dataset::read(&paths.exemplar())?;
    record_config(&paths.models(), config)?;
    train_stage(&levels, &manifest.source_sha256, config, device, &paths.models(), only, progress)
}

/// Stage 3: samples variants `options.first ..` into `OUT/variants`.
pub fn run_sample(paths: &RunPaths, config: &Config, device: tch::Device, options: &SampleOptions) -> Result<Vec<PathBuf>> {
    let (manifest, levels) = dataset::read(&paths.exemplar())?;
    sample_stage(&levels, &manifest.exemplar, manifest.open_surface, manifest.crs.as_deref(), config, device, &paths.models(), &paths.variants(), options, true)
}

/// Stage 4: meshes the variants with indices in `range` that exist, as
/// `settings` say (the configuration's `[mesh]`).
pub fn run_mesh(paths: &RunPaths, range: std::ops::Range<usize>, settings: &MeshConfig) -> Result<usize> {
    let manifest = dataset::read_manifest(&paths.exemplar())?;
    let dirs: Vec<PathBuf> = range
        .map(|i| variant_dir(&paths.variants(), i))
        .filter(|d| {
            let done = stamp_path(d, "sample").is_file();
            if d.is_dir() && !done {
                log::warn!("{}: its sampling did not finish: not meshed", d.display());
            }
            done
        })
        .collect();
    mesh_stage(&dirs, manifest.open_surface, 256, settings)
}

/// The USD step ([`usd::usd_stage`]) over variants `0..n`, or every variant
/// folder there is (None: the `usd` command on an existing run folder):
/// each sampled variant's `variant.usda`, then `OUT/variants.usda`.
pub fn run_usd(paths: &RunPaths, n: Option<usize>, meters_per_unit: f64) -> Result<usd::UsdOutcome> {
    let manifest = dataset::read_manifest(&paths.exemplar())?;
    let dirs: Vec<PathBuf> = match n {
        Some(n) => (0..n).map(|i| variant_dir(&paths.variants(), i)).filter(|d| d.is_dir()).collect(),
        None => {
            let mut dirs: Vec<PathBuf> = std::fs::read_dir(paths.variants())
                .map_err(|e| Error::file(&paths.variants(), e.to_string()))?
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.is_dir() && p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("variant_")))
                .collect();
            dirs.sort();
            dirs
        }
    };
    usd::usd_stage(&paths.root, &dirs, &manifest.exemplar, meters_per_unit)
}

/// Stage 5: scores variants `0..n` against the exemplar into
/// `OUT/eval.json`, and draws `OUT/contact_sheet.png`. `Ok(None)` (and a
/// warning naming the cause, no eval.json) when no variant can be scored,
/// e.g. every one was pruned away before the finest level.
pub fn run_eval(paths: &RunPaths, n: usize) -> Result<Option<crate::eval::evaluate::Evaluation>> {
    let (_, levels) = dataset::read(&paths.exemplar())?;
    let dirs: Vec<PathBuf> = (0..n).map(|i| variant_dir(&paths.variants(), i)).collect();
    if let Some(missing) = dirs.iter().find(|d| !stamp_path(d, "sample").is_file()) {
        return Err(Error::file(missing, "is missing or its sampling did not finish: sample it first (did a sampling job fail?)"));
    }
    // A variant whose levels were all pruned away has no level file: reported, not scored.
    let mut unreadable = Vec::new();
    let mut files = Vec::new();
    for d in &dirs {
        match crate::eval::evaluate::read_variant(d) {
            Ok(f) => files.push(f),
            Err(e) => unreadable.push(e.to_string()),
        }
    }
    let evaluation = if files.is_empty() {
        Err(Error::Invalid(format!("no variant can be scored: {}", unreadable.join("; "))))
    } else {
        crate::eval::evaluate::evaluate(&paths.exemplar(), None, &files, 256)
    };
    let evaluation = match evaluation {
        Ok(mut e) => {
            e.unscored.extend(unreadable);
            e.write_json(&paths.eval_json())?;
            Some(e)
        }
        Err(Error::Invalid(msg)) if msg.starts_with("no variant can be scored") => {
            let _ = std::fs::remove_file(paths.eval_json());
            log::warn!("evaluate: {msg}");
            None
        }
        Err(e) => return Err(e),
    };
    // Each variant labelled with its structure flags, so the sheet says
    // which shapes the measures call broken or copied.
    let flags = |name: &str| -> String {
        let scores = evaluation.as_ref().and_then(|e| e.report.variants.iter().find(|v| v.name == name));
        match scores.and_then(|v| v.structure.as_ref()) {
            Some(s) if !s.flags.is_empty() => {
                format!("\n{}", s.flags.iter().map(|f| f.name()).collect::<Vec<_>>().join(","))
            }
            _ => String::new(),
        }
    };
    let mut sheet = vec![("exemplar".to_string(), levels[levels.len() - 1].clone())];
    sheet.extend(files.iter().map(|f| (format!("{}{}", f.name, flags(&f.name)), f.finest.clone())));
    write_contact_sheet(&paths.contact_sheet(), &sheet)?;
    write_report(paths, n, evaluation.as_ref())?;
    Ok(evaluation)
}

/// Writes `OUT/report.html` from what the run folder holds: the contact
/// sheet, `evaluation`'s table, a preview per variant (its mesh, else its
/// finest level), the loss plots, the seconds each stage recorded, the
/// configuration.
pub fn write_report(paths: &RunPaths, n: usize, evaluation: Option<&crate::eval::evaluate::Evaluation>) -> Result<()> {
    let read = |p: &Path| std::fs::read(p).ok();
    let seconds = |dir: &Path, stage: &str| read_stamp(dir, stage).map(|s| s.seconds);
    let config = paths.read_config()?;
    let exemplar_name = dataset::read_manifest(&paths.exemplar()).map(|m| m.exemplar).unwrap_or_default();
    let levels = config.levels();
    let mut timings = Vec::new();
    if let Some(t) = seconds(&paths.exemplar(), "encode") {
        timings.push(("encode".to_string(), t));
    }
    for k in 0..levels {
        if let Some(state) = train::read_state(&paths.models(), k) {
            timings.push((format!("train level {k}"), state.seconds));
        }
    }
    let dirs: Vec<PathBuf> = (0..n).map(|i| variant_dir(&paths.variants(), i)).collect();
    for stage in ["sample", "mesh"] {
        let recorded: Vec<f64> = dirs.iter().filter_map(|d| seconds(d, stage)).collect();
        if !recorded.is_empty() {
            timings.push((format!("{stage} ({} variants)", recorded.len()), recorded.iter().sum()));
        }
    }
    let variants = dirs
        .iter()
        .filter_map(|d| {
            let name = d.file_name()?.to_string_lossy().into_owned();
            let finest = (0..levels).rev().map(|k| d.join(format!("level_{k}.png"))).find(|p| p.is_file());
            let png = read(&d.join("mesh.png")).or_else(|| finest.and_then(|p| read(&p)))?;
            Some((name, png))
        })
        .collect();
    let inputs = render::report::ReportInputs {
        title: format!("shapeshifter: {} ({})", exemplar_name, paths.root.display()),
        contact_sheet: read(&paths.contact_sheet()),
        eval_table: evaluation.map(|e| e.table()),
        variants,
        loss_plots: (0..levels).filter_map(|k| Some((k, read(&train::loss_plot_path(&paths.models(), k))?))).collect(),
        timings,
        config_toml: config.to_toml(),
        config_digest: config.digest(),
    };
    let page = render::report::html(&inputs);
    let path = paths.report();
    write_file(&path, &page)
}

#[cfg(test)]
mod endings {
    use super::*;

    /// Variant folders that stop short of the finest level are named with
    /// the first level they lack; all of them empty is an error naming where
    /// they vanished, some of them a warning.
    #[test]
    fn empty_variants_are_named_and_all_empty_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let dirs: Vec<PathBuf> = (0..3).map(|i| variant_dir(dir.path(), i)).collect();
        for (d, levels) in dirs.iter().zip([2usize, 1, 0]) {
            std::fs::create_dir_all(d).unwrap();
            for k in 0..levels {
                std::fs::write(d.join(dataset::level_file_name(k)), b"x").unwrap();
            }
        }
        let empty = empty_variants(&dirs, 1);
        assert_eq!(
            empty,
            [EmptyVariant { name: "variant_001".into(), first_empty: 1 }, EmptyVariant { name: "variant_002".into(), first_empty: 0 }]
        );
        assert!(check_usable(&empty, 3, &[16, 32]).is_ok(), "one whole variant of three: a warning");
        let all = empty_variants(&dirs[1..], 1);
        let e = check_usable(&all, 2, &[16, 32]).unwrap_err().to_string();
        assert!(e.contains("all 2 variants pruned to nothing (1 at level 0 (16^3), 1 at level 1 (32^3))"), "{e}");
        let from_memory = empty_sampled(&[vec![Level { index: 0, resolution: 16, ..Default::default() }], vec![]], &["a".into(), "b".into()]);
        assert_eq!(from_memory.len(), 2);
        assert_eq!(from_memory[0].first_empty, 0);
    }
}
