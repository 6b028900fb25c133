//! Keeping a variant made outside the sampling stage (the studio's edits and
//! continuations) as a variant folder of the run: its level files and
//! previews, then the run's later stages for it (its mesh, the USD asset,
//! the evaluation, the contact sheet and report), so it is a variant like
//! any other.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::layout::{variant_dir, variant_name};
use super::stamp::{mark_done, StampOf};
use super::RunPaths;
use crate::config::Config;
use crate::error::{Error, Result};
use crate::io::dataset;
use crate::io::vdb::Provenance;
use crate::level::Level;

/// What a kept variant's folder records of how it was made
/// ([`crate::studio::STUDIO_RECORD`]), and its stamp's digest.
pub struct KeptVariant<'a> {
    pub levels: &'a [Level],
    /// The seed its finer levels were sampled from, where it has one.
    pub seed: Option<u64>,
    /// The record written beside its levels (JSON).
    pub record: &'a [u8],
    pub record_name: &'a str,
}

/// The first free variant index of the run (one past the last variant
/// folder; kept variants go after the sampled ones).
pub fn next_index(paths: &RunPaths) -> usize {
    (0..).find(|&i| !variant_dir(&paths.variants(), i).exists()).unwrap_or(0)
}

/// Writes `kept` as the run's next variant folder and brings the run's
/// outputs up to date with it: its mesh (the run's `[mesh]` settings), the
/// USD asset over every variant, eval.json, the contact sheet and the
/// report. The folder is written under a temporary name and renamed when
/// whole, so a stop leaves either no folder or a whole one. Returns the
/// folder and its name. `progress` is told of each step.
pub fn keep_variant(paths: &RunPaths, config: &Config, kept: &KeptVariant, progress: &mut dyn FnMut(&str)) -> Result<(String, PathBuf)> {
    let t = Instant::now();
    if kept.levels.iter().all(Level::is_empty) {
        return Err(Error::Invalid("the variant has no voxels: nothing to keep".into()));
    }
    let manifest = dataset::read_manifest(&paths.exemplar())?;
    let index = next_index(paths);
    let name = variant_name(index);
    let dir = variant_dir(&paths.variants(), index);
    let staging = paths.variants().join(format!(".{name}.partial"));
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(|e| Error::file(&staging, e.to_string()))?;
    }
    progress("writing the level files");
    let provenance = Provenance {
        exemplar: manifest.exemplar.clone(),
        seed: kept.seed,
        config_digest: config.digest(),
        exemplar_open: manifest.open_surface,
        crs: manifest.crs.clone(),
    };
    let preview = |level: &Level, path: &Path| super::encode::write_preview(level, &crate::render::preview_options(), path);
    dataset::write_variant(&staging, kept.levels, &provenance, Some(&preview), config.output.write_options())?;
    crate::util::fs::write_file(&staging.join(kept.record_name), kept.record)?;
    mark_done(&staging, StampOf::Sample, &format!("kept:{}", crate::util::digest::short(&String::from_utf8_lossy(kept.record))), t.elapsed().as_secs_f64())?;
    crate::util::interrupt::check()?;
    std::fs::rename(&staging, &dir).map_err(|e| Error::file(&dir, e.to_string()))?;
    let count = index + 1;
    progress("meshing");
    super::run_mesh(paths, index..count, &config.mesh)?;
    progress("writing the USD asset");
    super::run_usd(paths, Some(count), config.output.meters_per_unit, config.output.usd_format)?;
    progress("evaluating every variant");
    super::run_eval(paths, count)?;
    log::info!("kept {name} in {:.1} s", t.elapsed().as_secs_f64());
    Ok((name, dir))
}
