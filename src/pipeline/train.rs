//! Stage 2, training: one network pair per level into `OUT/models`, in this
//! process or as concurrent child processes (one per level).

use std::path::Path;
use std::time::Instant;

use super::children::{train_in_processes, training_cost};
use super::sample::trained_levels;
use super::stamp::{digest, is_done, mark_done, record_config, StampOf};
use super::RunPaths;
use crate::config::{Config, Stage};
use crate::error::{Error, Result};
use crate::learn::train;
use crate::io::dataset;
use crate::level::Level;

/// What level `k`'s trained models depend on.
fn train_digest(source_sha: &str, config: &Config, k: usize) -> String {
    digest(&[source_sha, &config.stage_digest(Stage::Train), &k.to_string()])
}

/// The levels whose training is not finished (no stamp for this exemplar and
/// configuration) in `models`: of the exemplar's `level_count` levels, those
/// with a network (detail transfer makes those of `transfer.from_resolution` and finer).
pub fn levels_to_train(level_count: usize, source_sha: &str, config: &Config, models: &Path) -> Vec<usize> {
    (0..level_count.min(config.trained_levels()))
        .filter(|&k| !is_done(models, StampOf::TrainLevel(k), &train_digest(source_sha, config, k)))
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
    train_in_processes(&models, &todo, config, jobs, threads, progress, |k| {
        let mut c = std::process::Command::new(exe);
        c.args(["--threads", &threads.to_string(), "stage", "train"])
            .arg(&paths.root)
            .args(["--level", &k.to_string(), "--device", device]);
        c
    })?;
    Ok(todo)
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
    // Each level's part of the stage's progress, by its cost.
    let costs: Vec<f64> = which.iter().map(|&k| training_cost(config, k)).collect();
    let all: f64 = costs.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let mut before = 0.0;
    for (i, k) in which.into_iter().enumerate() {
        let _span = crate::util::progress::span(before / all, (before + costs[i]) / all);
        before += costs[i];
        let d = train_digest(source_sha, config, k);
        let stage = StampOf::TrainLevel(k);
        if is_done(models_dir, stage, &d) {
            log::info!("train level {k}: reusing {}", models_dir.display());
            continue;
        }
        let t = Instant::now();
        // Resume whatever a previous (killed) run of this level left.
        let resume = train::state_path(models_dir, k).exists();
        let r = train::train_level(&train::TrainJob { resume, progress, ..train::TrainJob::new(levels, k, config, device, models_dir) })?;
        write_loss_plot(models_dir, k, config)?;
        log::info!(
            "train level {k}: {} + {} steps in {:.0} s, loss {:.4} -> {:.4}",
            r.upsampler_steps,
            r.diffusion_steps,
            r.seconds,
            r.diffusion_loss_start,
            r.diffusion_loss_end
        );
        if r.finished {
            mark_done(models_dir, stage, &d, t.elapsed().as_secs_f64())?;
        }
        if r.interrupted {
            crate::util::interrupt::check()?;
        }
        reports.push(r);
    }
    Ok(reports)
}

/// Stage 2: trains every level (or `only` one, as one task of a job array)
/// into `OUT/models`, resuming what a killed job left.
pub fn run_train(paths: &RunPaths, config: &Config, device: tch::Device, only: Option<usize>, progress: bool) -> Result<Vec<train::TrainReport>> {
    let (manifest, levels) = dataset::read(&paths.exemplar())?;
    record_config(&paths.models(), config)?;
    train_stage(&levels, &manifest.source_sha256, config, device, &paths.models(), only, progress)
}

/// How `train` starts a level's child process: its own command line with
/// `--level K` (the same command a user or a cluster job could run).
pub struct TrainChild<'a> {
    pub exe: &'a Path,
    /// libtorch threads per child.
    pub threads: i32,
    pub profile: &'a str,
    pub device_spec: &'a str,
    pub overrides: &'a [String],
}

/// What the `train` command asks: the encoded exemplar in `exemplar_dir`,
/// models into `models`, all levels or one.
pub struct TrainFolder<'a> {
    pub exemplar_dir: &'a Path,
    pub models: &'a Path,
    pub config: &'a Config,
    pub device: tch::Device,
    pub level: Option<usize>,
    /// Refuse when there is nothing to resume.
    pub resume: bool,
    /// Levels trained at once (child processes when more than 1 and no `level`).
    pub jobs: usize,
    pub child: TrainChild<'a>,
    pub progress: bool,
    /// Wait for another command's lock on `models` instead of refusing.
    pub wait: bool,
}

/// How [`train_folder`] trained.
pub enum Trained {
    /// The levels trained by child processes, `jobs` at a time.
    InProcesses { levels: Vec<usize>, jobs: usize },
    InThisProcess(Vec<train::TrainReport>),
}

/// The `train` command: checks what is asked before anything is written (a
/// level detail transfer makes, a resume of nothing), locks and records
/// `models`, then trains the levels in this process or, with several jobs,
/// one child process per level ([`train_in_processes`]), as `run` does.
pub fn train_folder(job: &TrainFolder) -> Result<Trained> {
    let (manifest, levels) = dataset::read(job.exemplar_dir)?;
    levels_to_run(job.config, &levels, job.level)?;
    if job.resume && !job.models.is_dir() {
        return Err(Error::file(job.models, "--resume, but there is no models folder"));
    }
    let _lock = crate::util::lock::lock(job.models, crate::util::lock::Mode::Exclusive, job.wait, "train")?;
    record_config(job.models, job.config)?;
    if job.level.is_none() && job.jobs > 1 {
        let todo = levels_to_train(levels.len(), &manifest.source_sha256, job.config, job.models);
        let c = &job.child;
        train_in_processes(job.models, &todo, job.config, job.jobs, c.threads.max(1), job.progress, |k| {
            let mut command = std::process::Command::new(c.exe);
            command
                .args(["--threads", &c.threads.max(1).to_string(), "train"])
                .arg(job.exemplar_dir)
                .arg("--models")
                .arg(job.models)
                .args(["--level", &k.to_string(), "--profile", c.profile, "--device", c.device_spec]);
            for o in c.overrides {
                command.args(["--set", o]);
            }
            command
        })?;
        return Ok(Trained::InProcesses { levels: todo, jobs: job.jobs });
    }
    let reports = train_stage(&levels, &manifest.source_sha256, job.config, job.device, job.models, job.level, job.progress)?;
    Ok(Trained::InThisProcess(reports))
}

/// `models/level_K_loss.png` from the level's recorded state: the loss of
/// every step, and the learning rate where a schedule makes it vary.
pub fn write_loss_plot(models: &Path, k: usize, config: &Config) -> Result<()> {
    use crate::render::loss_plot::{self, PhaseCurve};
    let Some(state) = train::read_state(models, k) else { return Ok(()) };
    let (up_lr, diff_lr) = train::learning_rates(&state, config);
    loss_plot::write_loss_plot(
        &train::loss_plot_path(models, k),
        k,
        PhaseCurve { loss: &state.upsampler_loss, lr: up_lr.as_deref() },
        PhaseCurve { loss: &state.diffusion_loss, lr: diff_lr.as_deref() },
    )
}

/// What a user asks of the `train` command.
pub struct TrainRequest<'a> {
    /// The encoded exemplar's folder.
    pub dir: &'a Path,
    /// Where the models go (None: `DIR/models`).
    pub models: Option<&'a Path>,
    /// Train only this level.
    pub level: Option<usize>,
    pub resume: bool,
    /// Levels trained at once (0: [`super::run::auto_jobs`]).
    pub jobs: usize,
    /// A shipped profile or a TOML file (None: [`super::run::DEFAULT_PROFILE`]).
    pub profile: Option<&'a str>,
    pub overrides: &'a [String],
    pub device_spec: &'a str,
    /// libtorch threads per process.
    pub threads: i32,
    pub progress: bool,
    pub wait: bool,
}

/// What the `train` command did, and where the models are.
pub struct TrainRecord {
    pub models: std::path::PathBuf,
    pub trained: Trained,
}

/// The `train` command: the configuration (a bad profile or `--set` is
/// [`Error::Usage`]) and the device, then [`train_folder`]; child processes
/// get the same profile, overrides and device.
pub fn train_command(r: &TrainRequest) -> Result<TrainRecord> {
    let profile = r.profile.unwrap_or(super::run::DEFAULT_PROFILE);
    let config = Config::load(profile, r.overrides)?;
    let device = super::run::device(r.device_spec)?;
    let models = r.models.map_or_else(|| r.dir.join(super::layout::MODELS_DIR), Path::to_path_buf);
    let exe = super::run::this_program()?;
    let trained = train_folder(&TrainFolder {
        exemplar_dir: r.dir,
        models: &models,
        config: &config,
        device,
        level: r.level,
        resume: r.resume,
        jobs: super::run::auto_jobs(r.jobs, device, r.threads),
        child: TrainChild { exe: &exe, threads: r.threads, profile, device_spec: r.device_spec, overrides: r.overrides },
        progress: r.progress,
        wait: r.wait,
    })?;
    Ok(TrainRecord { models, trained })
}

/// What a training line tells besides the steps and the time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrainFigure {
    /// The diffusion loss, first tenth -> last tenth: whether the level
    /// learned (`train`, run by a person on one exemplar).
    Loss,
    /// Each network's steps per second: the figure GPU and cluster timings
    /// are read from (`stage train`, one job of a cluster).
    Speed,
}

/// One level's training as one line (no newline): its steps, `figure`, its
/// time, and whether it must be resumed.
pub fn training_line(r: &train::TrainReport, figure: TrainFigure) -> String {
    let unfinished = if r.finished { "" } else { " (not finished: run again to resume)" };
    let steps = format!("level {}: {} upsampler + {} diffusion steps", r.level, r.upsampler_steps, r.diffusion_steps);
    match figure {
        TrainFigure::Loss => format!("{steps}, loss {:.4} -> {:.4}, {:.0} s{unfinished}", r.diffusion_loss_start, r.diffusion_loss_end, r.seconds),
        TrainFigure::Speed => {
            format!("{steps}, {:.0} s ({:.1} + {:.1} steps/s){unfinished}", r.seconds, r.upsampler_it_per_s, r.diffusion_it_per_s)
        }
    }
}

impl std::fmt::Display for TrainRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.trained {
            Trained::InProcesses { levels, jobs } => writeln!(f, "{} levels trained on {jobs} processes -> {}", levels.len(), self.models.display()),
            Trained::InThisProcess(reports) => reports.iter().try_for_each(|r| writeln!(f, "{}", training_line(r, TrainFigure::Loss))),
        }
    }
}
