//! The `stage` command: one stage of `run` on a run folder, as one job of a
//! cluster runs it ([`super::cluster`] writes the jobs). The same functions
//! as `run`, so the stages together write what `run` writes.

use std::path::{Path, PathBuf};

use super::train::{training_line, TrainFigure};
use super::RunPaths;
use crate::config::Config;
use crate::error::{Error, Result};
use crate::eval::evaluate::Evaluation;
use crate::learn::sample::SampleOptions;
use crate::learn::train::TrainReport;

/// Which stage, on which run folder, with what.
pub enum StageRequest<'a> {
    /// Record the configuration in `output` and encode `mesh` into its exemplar folder.
    Encode { mesh: &'a Path, output: &'a Path, profile: &'a str, overrides: &'a [String] },
    /// Train every level, or one (one task of a job array).
    Train { dir: &'a Path, level: Option<usize>, device_spec: &'a str },
    /// Sample variants `first .. first + n`.
    Sample { dir: &'a Path, first: usize, n: usize, seed: u64, device_spec: &'a str },
    /// Mesh variants `first .. first + n`.
    Mesh { dir: &'a Path, first: usize, n: usize },
    /// USD layers of variants `0 .. n` and the run's asset.
    Usd { dir: &'a Path, n: usize },
    /// Score variants `0 .. n`.
    Eval { dir: &'a Path, n: usize },
}

/// What a stage did.
pub enum StageRecord {
    Encoded { levels: usize, exemplar: PathBuf },
    Trained(Vec<TrainReport>),
    Sampled { variants: usize, first: usize, n: usize, folder: PathBuf },
    Meshed(usize),
    Usd(super::usd::UsdOutcome),
    Evaluated(Evaluation),
}

/// Runs one stage. Every stage but `encode` needs an existing run folder
/// and its recorded configuration. Stages take the folder's lock shared: a
/// cluster's array tasks write one folder by design. A stage that can
/// score no variant is an error (the warning before it says why).
pub fn stage_command(r: &StageRequest, progress: bool, wait: bool) -> Result<StageRecord> {
    let folder = match *r {
        StageRequest::Encode { output, .. } => output,
        StageRequest::Train { dir, .. }
        | StageRequest::Sample { dir, .. }
        | StageRequest::Mesh { dir, .. }
        | StageRequest::Usd { dir, .. }
        | StageRequest::Eval { dir, .. } => dir,
    };
    // `stage encode` makes the run folder; the others work in one.
    let paths = match r {
        StageRequest::Encode { .. } => RunPaths::new(folder),
        _ => RunPaths::existing(folder)?,
    };
    let _lock = crate::util::lock::lock(folder, crate::util::lock::Mode::Shared, wait, "stage")?;
    Ok(match *r {
        StageRequest::Encode { mesh, profile, overrides, .. } => {
            let config = Config::load(profile, overrides)?;
            let (_, levels) = super::run_encode(super::ExemplarSource::File(mesh), &paths, &config)?;
            StageRecord::Encoded { levels: levels.len(), exemplar: paths.exemplar() }
        }
        StageRequest::Train { level, device_spec, .. } => {
            let config = paths.read_config()?;
            StageRecord::Trained(super::run_train(&paths, &config, super::run::device(device_spec)?, level, progress)?)
        }
        StageRequest::Sample { first, n, seed, device_spec, .. } => {
            let config = paths.read_config()?;
            let options = SampleOptions { first, ..SampleOptions::from_config(&config, n, seed) };
            let dirs = super::run_sample(&paths, &config, super::run::device(device_spec)?, &options)?;
            StageRecord::Sampled { variants: dirs.len(), first, n, folder: paths.variants() }
        }
        StageRequest::Mesh { first, n, .. } => {
            let config = paths.read_config()?;
            StageRecord::Meshed(super::run_mesh(&paths, first..first + n, &config.mesh)?)
        }
        StageRequest::Usd { n, .. } => {
            let config = paths.read_config()?;
            StageRecord::Usd(super::run_usd(&paths, Some(n), config.output.meters_per_unit, config.output.usd_format)?)
        }
        StageRequest::Eval { n, .. } => match super::run_eval(&paths, n)? {
            Some(evaluation) => StageRecord::Evaluated(evaluation),
            None => return Err(Error::file(folder, "no variant can be scored (see the warning above)")),
        },
    })
}

impl std::fmt::Display for StageRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StageRecord::Encoded { levels, exemplar } => writeln!(f, "encoded {levels} levels -> {}", exemplar.display()),
            StageRecord::Trained(reports) => reports.iter().try_for_each(|r| writeln!(f, "{}", training_line(r, TrainFigure::Speed))),
            StageRecord::Sampled { variants, first, n, folder } => {
                writeln!(f, "{variants} variants ({first}..{}) -> {}", first + n, folder.display())
            }
            StageRecord::Meshed(done) => writeln!(f, "{done} variants meshed"),
            StageRecord::Usd(usd) => writeln!(f, "{usd}"),
            StageRecord::Evaluated(evaluation) => f.write_str(&evaluation.table()),
        }
    }
}
