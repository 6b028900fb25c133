//! `run`: one exemplar through the five stages in one process, into one
//! output folder (a cluster runs the same stages as separate jobs: `stage`,
//! [`super::cluster`]). Independent levels train in child processes, and
//! shards of variants are sampled and meshed by children, when `jobs` > 1.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::config::Config;
use crate::error::{Error, Result};
use crate::eval::evaluate::Evaluation;
use crate::learn::sample::SampleOptions;

use super::batch::Line;
use super::{ExemplarSource, RunPaths};

/// What `run` needs besides the exemplar and the folder.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub config: Config,
    pub device: tch::Device,
    /// The `--device` text, passed on to child processes.
    pub device_spec: String,
    /// Variants to sample.
    pub n: usize,
    pub seed: u64,
    /// Levels trained, and shards sampled and meshed, at once (0: as many as
    /// the cores allow, [`auto_jobs`]).
    pub jobs: usize,
    /// libtorch threads per process (0: libtorch's own choice).
    pub threads: i32,
    pub progress: bool,
    /// This program, for the child processes.
    pub exe: PathBuf,
}

/// What a finished `run` produced.
pub struct RunSummary {
    pub source_name: String,
    pub variants: usize,
    /// Wall seconds per stage, in order.
    pub seconds: Vec<(&'static str, f64)>,
    pub total_seconds: f64,
    /// None when no variant could be scored (a warning says why).
    pub evaluation: Option<Evaluation>,
    /// Variants that pruned to nothing (left out of meshing and scoring).
    pub empty: Vec<super::EmptyVariant>,
    /// The USD asset (`variants.usda` or `.usdc`).
    pub usd_asset: std::path::PathBuf,
}

/// Levels trained at once: `jobs`, or with 0 the cores divided by the libtorch
/// threads per level (1 on a GPU: one device, shared).
pub fn auto_jobs(jobs: usize, device: tch::Device, threads: i32) -> usize {
    match jobs {
        0 if device.is_cuda() => 1,
        // libtorch's own thread count (--threads 0) already takes every core.
        0 if threads <= 0 => 1,
        0 => (std::thread::available_parallelism().map_or(1, |n| n.get()) / threads as usize).max(1),
        j => j,
    }
}

/// What a user asks of `run` or `demo`, besides the exemplar and the folder.
pub struct RunRequest<'a> {
    /// A shipped profile or a TOML file; None: [`default_profile`].
    pub profile: Option<&'a str>,
    /// `--set SECTION.KEY=VALUE` overrides.
    pub overrides: &'a [String],
    /// Settings of how the exemplar file is read, given on the command line
    /// (scale, up axis, point-cloud options), applied over the profile's.
    pub exemplar: &'a super::ExemplarSettings,
    /// `--device`: cpu, cuda, cuda:N or auto.
    pub device_spec: &'a str,
    pub n: usize,
    pub seed: u64,
    pub jobs: usize,
    pub threads: i32,
    /// Progress bars may be drawn (not with `--quiet` or other progress lines).
    pub progress: bool,
    /// One JSON record per exemplar instead of the summary; no progress
    /// bars then, as the records are for scripts and task graphs, which
    /// have no terminal to draw them on.
    pub json: bool,
    /// Wait for another writer of the folder instead of refusing at once.
    pub wait: bool,
}

/// The profile a command that trains uses when none is given (`train`,
/// `run` on a file, `stage encode`, `slurm`, the ladder's untrained rung
/// without a run's configuration): sized for a CPU.
pub const DEFAULT_PROFILE: &str = "cpu";

/// The profile a run uses when none is given: the demo's own (sized for its
/// 10-minute budget) for the embedded exemplar, [`DEFAULT_PROFILE`] for a file.
pub fn default_profile(exemplar: ExemplarSource) -> &'static str {
    if matches!(exemplar, ExemplarSource::Demo) {
        "demo"
    } else {
        DEFAULT_PROFILE
    }
}

/// This program, for the child processes and job scripts that run its
/// other commands.
pub fn this_program() -> Result<PathBuf> {
    std::env::current_exe().map_err(|e| Error::Invalid(format!("cannot find this program for its child processes: {e}")))
}

/// The device `--device SPEC` names (cpu, cuda, cuda:N, auto), with a log
/// line saying why; every command that trains or samples picks it here.
pub fn device(spec: &str) -> Result<tch::Device> {
    let (device, why) = crate::learn::sparse::pick_device(spec).map_err(|e| Error::Invalid(format!("--device {spec}: {e}")))?;
    log::info!("device: {why}");
    Ok(device)
}

/// The configuration of a run: the profile, the overrides, then the exemplar
/// settings; any of them invalid is [`Error::Usage`] (nothing was done).
pub fn run_config(exemplar: ExemplarSource, r: &RunRequest) -> Result<Config> {
    let mut config = Config::load(r.profile.unwrap_or(default_profile(exemplar)), r.overrides)?;
    r.exemplar.apply(&mut config.encode);
    super::encode_options(&config).validate().map_err(Error::usage)?;
    Ok(config)
}

/// `run` as a user asks for it: the configuration ([`run_config`]), the
/// folder's lock, the device, then [`run`].
pub fn run_exemplar(exemplar: ExemplarSource, out: &Path, r: &RunRequest) -> Result<RunSummary> {
    let config = run_config(exemplar, r)?;
    let _lock = crate::util::lock::lock(out, crate::util::lock::Mode::Exclusive, r.wait, "run")?;
    let device = device(r.device_spec)?;
    let exe = this_program()?;
    let options = RunOptions {
        config,
        device,
        device_spec: r.device_spec.to_string(),
        n: r.n,
        seed: r.seed,
        jobs: r.jobs,
        threads: r.threads,
        progress: r.progress && !r.json,
        exe,
    };
    run(exemplar, out, &options)
}

/// The exemplars of a `run` command, each with its name as given and its
/// folder: one input into `output` itself, several into `output/NAME`
/// (named as the batch commands name them: a/x.off and b/x.off become a_x
/// and b_x, never one folder).
pub fn batch_of<'a>(inputs: &'a [PathBuf], output: &Path) -> Result<Vec<(ExemplarSource<'a>, String, PathBuf)>> {
    let names = super::batch::output_names(inputs)?;
    let several = inputs.len() > 1;
    Ok(inputs
        .iter()
        .zip(names)
        .map(|(m, name)| {
            let out = if several { output.join(name) } else { output.to_path_buf() };
            (ExemplarSource::File(m), m.display().to_string(), out)
        })
        .collect())
}

/// Runs exemplars one after the other, each into its folder, and hands each
/// outcome to `report` as it finishes (with its seconds). A failed exemplar
/// is reported and the next goes on; a stop signal or a usage error ends the
/// batch with that error (nothing more is worth running). Returns how many
/// failed.
pub fn run_batch(
    exemplars: &[(ExemplarSource, String, PathBuf)],
    r: &RunRequest,
    mut report: impl FnMut(&str, &Path, std::result::Result<&RunSummary, &Error>, f64),
) -> Result<usize> {
    let mut failed = 0;
    for (i, (source, name, out)) in exemplars.iter().enumerate() {
        let t = Instant::now();
        // `--progress alf`: each exemplar an equal part of the batch.
        let _progress = crate::util::progress::span(i as f64 / exemplars.len() as f64, (i + 1) as f64 / exemplars.len() as f64);
        match run_exemplar(*source, out, r) {
            Ok(summary) => report(name, out, Ok(&summary), t.elapsed().as_secs_f64()),
            Err(e) if crate::util::interrupt::requested().is_some() || matches!(e, Error::Usage(_) | Error::Stopped(_)) => {
                return Err(e)
            }
            Err(e) => {
                report(name, out, Err(&e), t.elapsed().as_secs_f64());
                failed += 1;
            }
        }
    }
    if failed > 0 {
        log::error!("{failed} of {} inputs failed", exemplars.len());
    }
    Ok(failed)
}

/// What `run` or `demo` works on.
#[derive(Clone, Copy, Debug)]
pub enum Exemplars<'a> {
    /// Exemplar files: one into the output folder, several into one folder each ([`batch_of`]).
    Files(&'a [PathBuf]),
    /// The embedded demo exemplar, into the output folder.
    Demo,
}

/// The `run` and `demo` commands: every exemplar run ([`run_batch`]), each
/// told to `tell` as it finishes: its summary ([`SummaryText`]) or, with
/// `r.json`, its record as a line of JSON; a failed one as its error (and,
/// with `r.json`, its record too). Returns the exit status: 1 when any
/// exemplar failed.
pub fn run_command(exemplars: Exemplars, output: &Path, r: &RunRequest, mut tell: impl FnMut(&[Line])) -> Result<u8> {
    let batch = match exemplars {
        Exemplars::Files(meshes) => batch_of(meshes, output)?,
        Exemplars::Demo => vec![(ExemplarSource::Demo, "(embedded)".to_string(), output.to_path_buf())],
    };
    let failed = run_batch(&batch, r, |name, out, outcome, seconds| {
        let lines = match outcome {
            Ok(summary) if r.json => vec![Line::Out(json_line(&RunRecord::done(name, out, summary)))],
            Ok(summary) => vec![Line::Out(SummaryText { summary, out }.to_string())],
            Err(e) if r.json => vec![Line::Error(e.to_string()), Line::Out(json_line(&RunRecord::failed(name, out, e.to_string(), seconds)))],
            Err(e) => vec![Line::Error(e.to_string())],
        };
        tell(&lines);
    })?;
    Ok(super::batch::exit_status(failed))
}

/// A record as one line of JSON Lines, newline included.
fn json_line(record: &RunRecord) -> String {
    // A record is plain data (strings, numbers, paths): it serialises.
    serde_json::to_string(record).expect("a run record serialises") + "\n"
}

/// `run`'s summary of one exemplar run into `out`: where everything went,
/// the stage times, the scores.
pub struct SummaryText<'a> {
    pub summary: &'a RunSummary,
    pub out: &'a Path,
}

impl std::fmt::Display for SummaryText<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (summary, paths) = (self.summary, RunPaths::new(self.out));
        writeln!(f, "\n{} -> {}", summary.source_name, self.out.display())?;
        writeln!(f, "  exemplar levels  {}", paths.exemplar().display())?;
        writeln!(f, "  models           {}", paths.models().display())?;
        writeln!(f, "  variants         {} ({} folders, previews level_K.png)", paths.variants().display(), summary.variants)?;
        if !summary.empty.is_empty() {
            let names: Vec<String> = summary.empty.iter().map(|e| format!("{} (from level {})", e.name, e.first_empty)).collect();
            writeln!(f, "  empty variants   {} of {}: {}", summary.empty.len(), summary.variants, names.join(", "))?;
        }
        writeln!(f, "  USD asset        {}", summary.usd_asset.display())?;
        writeln!(f, "  metrics          {}", paths.eval_json().display())?;
        writeln!(f, "  contact sheet    {}", paths.contact_sheet().display())?;
        writeln!(f, "  report           {}", paths.report().display())?;
        let stages: Vec<String> = summary.seconds.iter().map(|(k, v)| format!("{k} {v:.0} s")).collect();
        writeln!(f, "  time             {}  (total {:.0} s)", stages.join(", "), summary.total_seconds)?;
        match &summary.evaluation {
            Some(e) => f.write_str(&e.table()),
            None => writeln!(f, "  (no variant could be scored: see the warning above)"),
        }
    }
}

/// Encode, train, sample, mesh and evaluate `exemplar` into `out`, reusing
/// every stage whose inputs and configuration are unchanged.
pub fn run(exemplar: ExemplarSource, out: &Path, o: &RunOptions) -> Result<RunSummary> {
    let t0 = Instant::now();
    let config = &o.config;
    let paths = RunPaths::new(out);
    let mut seconds = Vec::new();
    let mut stage = |name: &'static str, t: Instant| seconds.push((name, t.elapsed().as_secs_f64()));

    // `--progress alf`: each stage's part of the whole (training dominates).
    use crate::util::progress::span;
    let t = Instant::now();
    let (source_name, exemplar_levels) = {
        let _p = span(0.0, 0.05);
        super::run_encode(exemplar, &paths, config)?
    };
    stage("encode", t);

    crate::util::interrupt::check()?;
    let t = Instant::now();
    let train_span = span(0.05, 0.80);
    log::info!("{}", crate::learn::sparse::compute_path(o.device, config.train.bf16));
    let jobs = auto_jobs(o.jobs, o.device, o.threads);
    let threads = o.threads.max(1).to_string();
    if jobs > 1 {
        super::train_concurrently(&paths, config, &o.exe, o.threads.max(1), &o.device_spec, jobs, o.progress)?;
    } else {
        super::run_train(&paths, config, o.device, None, o.progress)?;
    }
    drop(train_span);
    stage("train", t);

    // Variants are independent: with several jobs, shards of them are sampled
    // and meshed by child processes (`stage sample/mesh --first K -n N`), which
    // write exactly what one process writes; the final in-process call then
    // finds every shard done.
    let t = Instant::now();
    let sample_span = span(0.80, 0.93);
    let sharded = jobs > 1 && o.n > 1;
    let logs = out.join(super::layout::LOGS_DIR);
    if sharded {
        std::fs::create_dir_all(&logs).map_err(|e| Error::file(&logs, e.to_string()))?;
        super::run_shards(o.n, jobs, &logs, "sample", |first, count| {
            let mut c = std::process::Command::new(&o.exe);
            c.args(["--threads", &threads, "stage", "sample"])
                .arg(out)
                .args(["--first", &first.to_string(), "-n", &count.to_string(), "--seed", &o.seed.to_string()])
                .args(["--device", &o.device_spec]);
            c
        })?;
    }
    let dirs = super::run_sample(&paths, config, o.device, &SampleOptions::from_config(config, o.n, o.seed))?;
    drop(sample_span);
    stage("sample", t);
    // A run that made nothing usable is a failure, with the cause in its
    // one error line; some empty variants are a warning.
    let resolutions: Vec<u32> = exemplar_levels.iter().map(|l| l.resolution).collect();
    let empty = super::empty_variants(&dirs, 0..=resolutions.len().saturating_sub(1));
    super::check_usable(&empty, dirs.len(), &resolutions)?;

    let t = Instant::now();
    let mesh_span = span(0.93, 0.97);
    if sharded {
        super::run_shards(o.n, jobs, &logs, "mesh", |first, count| {
            let mut c = std::process::Command::new(&o.exe);
            c.args(["stage", "mesh"]).arg(out).args(["--first", &first.to_string(), "-n", &count.to_string()]);
            c
        })?;
    }
    let meshed = super::run_mesh(&paths, 0..o.n, &config.mesh)?;
    log::info!("mesh: {meshed} of {} variants meshed", dirs.len());
    drop(mesh_span);
    stage("mesh", t);

    let t = Instant::now();
    let usd = {
        let _p = span(0.97, 0.98);
        super::run_usd(&paths, Some(o.n), config.output.meters_per_unit, config.output.usd_format)?
    };
    log::info!("usd: {usd}");
    stage("usd", t);

    let t = Instant::now();
    let evaluation = {
        let _p = span(0.98, 1.0);
        super::run_eval(&paths, o.n)?
    };
    stage("evaluate", t);
    Ok(RunSummary { source_name, variants: dirs.len(), seconds, total_seconds: t0.elapsed().as_secs_f64(), evaluation, empty, usd_asset: usd.asset })
}

/// One stage's wall time in a [`RunRecord`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct StageTime {
    pub stage: &'static str,
    pub seconds: f64,
}

/// What `run --json` prints per exemplar (one line of JSON Lines): where it
/// went, whether it finished, every file with its kind, the stage times.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunRecord {
    /// The exemplar file as given ("(embedded)" for the demo).
    pub exemplar: String,
    pub output: PathBuf,
    /// "done" or "failed".
    pub status: &'static str,
    /// The exit status this exemplar alone would give (0 done, 1 failed).
    pub exit_status: u8,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    pub variants: usize,
    /// Variants that pruned to nothing (no mesh, not scored).
    pub empty_variants: Vec<String>,
    pub stages: Vec<StageTime>,
    pub total_seconds: f64,
    /// Every output under `output`, sorted by path ([`super::layout`]).
    pub files: Vec<super::layout::OutputFile>,
}

impl RunRecord {
    pub fn done(exemplar: &str, out: &Path, s: &RunSummary) -> Self {
        RunRecord {
            exemplar: exemplar.into(),
            output: out.to_path_buf(),
            status: "done",
            exit_status: 0,
            error: None,
            variants: s.variants,
            empty_variants: s.empty.iter().map(|e| e.name.clone()).collect(),
            stages: s.seconds.iter().map(|&(stage, seconds)| StageTime { stage, seconds }).collect(),
            total_seconds: s.total_seconds,
            files: super::layout::output_files(out),
        }
    }

    /// An exemplar that failed: its one error line, and what it left (a
    /// finished stage's files stay, for the next run to reuse).
    pub fn failed(exemplar: &str, out: &Path, error: String, seconds: f64) -> Self {
        RunRecord {
            exemplar: exemplar.into(),
            output: out.to_path_buf(),
            status: "failed",
            exit_status: 1,
            error: Some(error),
            variants: 0,
            empty_variants: Vec::new(),
            stages: Vec::new(),
            total_seconds: seconds,
            files: super::layout::output_files(out),
        }
    }
}
