//! Keeping a variant made outside the sampling stage (the studio's edits and
//! continuations) as a variant folder of the run: its level files and
//! previews ([`write_kept`]), then the run's later stages for it (its mesh,
//! the USD asset, the evaluation, the contact sheet and report:
//! [`finish_kept`]), so it is a variant like any other.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::layout::{variant_dir, variant_name, KEPT_RECORD};
use super::stamp::{mark_done, stamp_path, StampOf};
use super::RunPaths;
use crate::config::Config;
use crate::error::{Error, Result};
use crate::io::dataset;
use crate::io::vdb::Provenance;
use crate::level::Level;

/// A variant to keep: its levels, and what its folder records of how it
/// was made.
pub struct KeptVariant<'a> {
    pub levels: &'a [Level],
    /// The run seed its finer levels were sampled from, where it has one.
    pub seed: Option<u64>,
    /// How its start was made (bent, or in a resized box), recorded beside
    /// its levels so eval judges it as sampling did.
    pub start: dataset::StartRecord,
    /// The record written beside its levels as [`KEPT_RECORD`] (JSON); its
    /// digest is the folder's sampling stamp.
    pub record: &'a [u8],
}

/// The first free variant index of the run (one past the last variant
/// folder; kept variants go after the sampled ones).
pub fn next_index(paths: &RunPaths) -> usize {
    (0..).find(|&i| !variant_dir(&paths.variants(), i).exists()).unwrap_or(0)
}

/// Writes `kept` as the run's next variant folder: its level files,
/// previews, record and stamp, under a temporary name renamed when whole, so
/// a stop leaves either no folder or a whole one. Returns its name and path.
/// The run's later stages for it are [`finish_kept`]'s.
pub fn write_kept(paths: &RunPaths, config: &Config, kept: &KeptVariant) -> Result<(String, PathBuf)> {
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
    let provenance = Provenance {
        exemplar: manifest.exemplar.clone(),
        seed: kept.seed,
        config_digest: config.digest(),
        exemplar_open: manifest.open_surface,
        crs: manifest.crs.clone(),
    };
    let preview = |level: &Level, path: &Path| super::encode::write_preview(level, &crate::render::preview_options(), path);
    dataset::write_variant(&staging, kept.levels, &provenance, Some(&preview), config.output.write_options())?;
    kept.start.write(&staging)?;
    crate::util::fs::write_file(&staging.join(KEPT_RECORD), kept.record)?;
    let digest = format!("kept:{}", crate::util::digest::short(&String::from_utf8_lossy(kept.record)));
    mark_done(&staging, StampOf::Sample, &digest, t.elapsed().as_secs_f64())?;
    crate::util::interrupt::check()?;
    std::fs::rename(&staging, &dir).map_err(|e| Error::file(&dir, e.to_string()))?;
    log::info!("kept {name} ({:.1} s)", t.elapsed().as_secs_f64());
    Ok((name, dir))
}

/// The kept variant folders (with a [`KEPT_RECORD`]) whose later stages
/// are not all done yet: no stamp says it is in the USD asset and eval.json.
pub fn unfinished_kept(paths: &RunPaths) -> Vec<usize> {
    (0..next_index(paths))
        .filter(|&i| {
            let d = variant_dir(&paths.variants(), i);
            d.join(KEPT_RECORD).is_file() && !stamp_path(&d, StampOf::Kept).is_file()
        })
        .collect()
}

/// Brings the run's outputs up to date with its kept variants: the mesh of
/// each kept folder that has none (the run's `[mesh]` settings), then the
/// USD asset over every variant, eval.json, the contact sheet and the
/// report. `progress` is told of each step.
pub fn finish_kept(paths: &RunPaths, config: &Config, progress: &mut dyn FnMut(&str)) -> Result<()> {
    let t = Instant::now();
    let count = next_index(paths);
    let unfinished = unfinished_kept(paths);
    // A stop (SIGINT, SIGTERM, a cancel) is taken between steps; each step
    // writes whole files, and the kept variants' stamps come last, so the
    // next opening of the run does what is missing.
    for &i in &unfinished {
        crate::util::interrupt::check()?;
        progress(&format!("meshing {}", variant_name(i)));
        super::run_mesh(paths, i..i + 1, &config.mesh)?;
    }
    crate::util::interrupt::check()?;
    progress("writing the USD asset");
    super::run_usd(paths, Some(count), config.output.meters_per_unit, config.output.usd_format)?;
    crate::util::interrupt::check()?;
    progress(&format!("evaluating the {count} variants"));
    super::run_eval(paths, count)?;
    crate::util::interrupt::check()?;
    for &i in &unfinished {
        mark_done(&variant_dir(&paths.variants(), i), StampOf::Kept, "in the run's USD asset and eval.json", t.elapsed().as_secs_f64())?;
    }
    log::info!("the run's mesh, USD asset and evaluation updated for its {count} variants in {:.1} s", t.elapsed().as_secs_f64());
    Ok(())
}
