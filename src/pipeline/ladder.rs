//! The degradation ladder of an encoded exemplar (`ladder` command): rungs
//! written, scored as variants, and the expected order checked.

use std::path::Path;
use std::time::Instant;

use serde::Serialize;

use super::evaluate::write_contact_sheet;
use super::sample::{sample_variants, trained_levels};
use crate::config::Config;
use crate::error::{Error, Result};
use crate::io::vdb::Provenance;
use crate::learn::sample::{self, SampleOptions};
use crate::io::dataset;
use crate::level::Level;
use crate::util::fs::write_file;

/// The configuration of the ladder's untrained rung, and where it came
/// from (said in the command's output): `profile` when given (`none`: no
/// untrained rung), else the `config.toml` of `dir/models` or
/// `dir/../models` (a run's layout), else [`super::run::DEFAULT_PROFILE`].
pub fn ladder_config(dir: &Path, profile: Option<&str>) -> Result<(Option<Config>, String)> {
    use super::layout::{CONFIG, MODELS_DIR};
    use super::run::DEFAULT_PROFILE;
    Ok(match profile {
        Some("none") => (None, "none (--profile none)".into()),
        Some(p) => (Some(Config::load(p, &[])?), format!("the '{p}' profile (--profile)")),
        None => {
            let found = [dir.join(MODELS_DIR), dir.join("..").join(MODELS_DIR)].into_iter().map(|m| m.join(CONFIG)).find(|p| p.is_file());
            match found {
                Some(p) => (Some(Config::read(&p)?), format!("the configuration of {}", p.display())),
                None => (
                    Some(Config::load(DEFAULT_PROFILE, &[])?),
                    format!(
                        "the '{DEFAULT_PROFILE}' profile: no {CONFIG} in {0}/{MODELS_DIR} or {0}/../{MODELS_DIR} (--profile P to choose, none to skip)",
                        dir.display()
                    ),
                ),
            }
        }
    })
}

/// The ladder's record in its output folder.
pub const LADDER_JSON: &str = "ladder.json";

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
    if !rungs.iter().any(|(r, _)| *r == Rung::RoofStrip) {
        skipped.push(format!(
            "roof_strip: no upper skin runs {} voxels across at 64^3 (no roof to tear)",
            crate::eval::ladder::ROOF_STRIP_MIN_LENGTH
        ));
        let _ = std::fs::remove_dir_all(out.join(Rung::RoofStrip.name()));
    }
    match config {
        Some(config) => {
            let t = Instant::now();
            let untrained = sample::untrained_models(config, trained_levels(config, &levels), device, options.seed).and_then(|m| {
                // One level-0 shape and one pass: the rung is what the method
                // makes of noise, and the whole-and-new search (16 candidates
                // and retries at the demo profile) only spent half a minute
                // finding that every one of them prunes away.
                let one_pass = SampleOptions {
                    level0_candidates: 1,
                    level0_min_structure: 0.0,
                    attempts: 1,
                    bend_voxels: 0.0,
                    ..SampleOptions::from_config(config, 1, options.seed)
                };
                sample_variants(&m, &levels, &one_pass, None)
            });
            match untrained {
                Ok(mut v) if v.first().and_then(|s| s.levels.last()).is_some_and(|l| l.len() > 0 && l.index + 1 == levels.len()) => {
                    log::info!("ladder: untrained networks sampled in {:.1} s", t.elapsed().as_secs_f64());
                    rungs.push((Rung::Untrained, v.swap_remove(0).levels));
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
            structure: crate::judge::structure_level(l).cloned(),
            fine: crate::judge::fine_level(l).cloned(),
            mesh: None,
            bend: None,
            extent: None,
        })
        .collect();
    let evaluation = crate::eval::evaluate::evaluate(exemplar_dir, None, &files, 256)?;
    skipped.extend(evaluation.unscored.iter().cloned());
    let finest = &levels[levels.len() - 1];
    let colourful = crate::eval::metrics::colour::spread(&finest.colours) > 0.02;
    if !colourful {
        skipped.push("colour expectations: the exemplar has one colour (nothing to wash out or shuffle)".into());
    }
    let finer_than_structure = finest.resolution > crate::judge::STRUCTURE_RESOLUTION;
    if !finer_than_structure {
        skipped.push(ladder::skipped_at_the_structure_level().into());
    }
    let checks = ladder::check(&evaluation.report.variants, colourful, finer_than_structure);
    let entries: Vec<(String, Level)> = files.into_iter().map(|f| (f.name, f.finest)).collect();
    write_contact_sheet(&out.join(super::layout::CONTACT_SHEET), &entries, &crate::render::SheetOptions::default())?;
    let outcome = LadderOutcome { options, evaluation, checks, skipped };
    let path = out.join(LADDER_JSON);
    let text = serde_json::to_string_pretty(&outcome).map_err(|e| Error::file(&path, e.to_string()))?;
    write_file(&path, &text)?;
    Ok(outcome)
}

/// What a user asks of the `ladder` command.
pub struct LadderRequest<'a> {
    /// The encoded exemplar's folder.
    pub dir: &'a Path,
    pub output: &'a Path,
    /// The untrained rung's configuration ([`ladder_config`]).
    pub profile: Option<&'a str>,
    pub device_spec: &'a str,
}

/// The `ladder` command's outcome, and where it went.
pub struct LadderRecord {
    pub outcome: LadderOutcome,
    pub dir: std::path::PathBuf,
    pub output: std::path::PathBuf,
}

/// The `ladder` command: the untrained rung's configuration (told to
/// `tell` at once, as one line, before the minutes the ladder takes), then
/// [`ladder_stage`].
pub fn ladder_command(r: &LadderRequest, tell: &mut dyn FnMut(&str)) -> Result<LadderRecord> {
    let (config, from) = ladder_config(r.dir, r.profile)?;
    tell(&format!("untrained rung: {from}"));
    let device = super::run::device(r.device_spec)?;
    let outcome = ladder_stage(r.dir, r.output, config.as_ref(), device)?;
    Ok(LadderRecord { outcome, dir: r.dir.to_path_buf(), output: r.output.to_path_buf() })
}

impl LadderRecord {
    /// 0 when every check of the expected order holds, 1 when one fails; an
    /// error when no check could run (nothing was judged).
    pub fn exit_status(&self) -> Result<u8> {
        if self.outcome.checks.is_empty() {
            return Err(Error::file(&self.dir, "no check of the expected order could run (every rung skipped?)"));
        }
        Ok(super::batch::exit_status(self.outcome.failed().count()))
    }
}

/// The scores' table, the rungs skipped, how many checks hold and each
/// that fails.
impl std::fmt::Display for LadderRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let o = &self.outcome;
        f.write_str(&o.evaluation.table())?;
        for s in &o.skipped {
            writeln!(f, "skipped: {s}")?;
        }
        let failed: Vec<_> = o.failed().collect();
        writeln!(
            f,
            "expected order: {} of {} checks hold -> {}",
            o.checks.len() - failed.len(),
            o.checks.len(),
            self.output.join(LADDER_JSON).display()
        )?;
        for c in &failed {
            writeln!(f, "  FAILS {} on {}: {:.4} vs exemplar {:.4} ({})", c.metric, c.rung, c.value, c.exemplar, c.requirement)?;
        }
        Ok(())
    }
}
