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
//! OUT/variants/variant_000/        level_K.vdb, level_K.png, mesh.ply, mesh.png
//! OUT/eval.json                    metrics
//! ```

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::config::Config;
use crate::dataset;
use crate::encode::{self, EncodeOptions, Pooling};
use crate::error::{write_atomically, Error, Result};
use crate::level::Level;
use crate::mesh::Mesh;
use crate::render::{self, RenderOptions};
use crate::sample::{self, SampleOptions};
use crate::train;
use crate::vdb::{self, Provenance, WriteOptions};

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
    std::fs::read_to_string(stamp_path(dir, stage))
        .ok()
        .and_then(|t| serde_json::from_str::<Stamp>(&t).ok())
        .is_some_and(|s| s.digest == digest)
}

fn mark_done(dir: &Path, stage: &str, digest: &str, seconds: f64) -> Result<()> {
    let path = stamp_path(dir, stage);
    let text = serde_json::to_string(&Stamp { digest: digest.into(), seconds }).expect("stamp serialises");
    write_atomically(&path, |tmp| std::fs::write(tmp, &text).map_err(|e| Error::file(&path, e.to_string())))
}

fn digest(parts: &[&str]) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    for p in parts {
        h.update(p.as_bytes());
        h.update([0u8]);
    }
    h.finalize().iter().take(8).map(|b| format!("{b:02x}")).collect()
}

pub fn encode_options(config: &Config) -> EncodeOptions {
    EncodeOptions {
        sampling_resolution: config.encode.sampling_resolution,
        coarsest_resolution: config.encode.coarsest_resolution,
        finest_resolution: config.encode.finest_resolution,
        pooling: if config.encode.pooling == "average" { Pooling::Average } else { Pooling::Qem },
        ..Default::default()
    }
}

/// Preview options for the pipeline's pictures.
pub fn preview_options() -> RenderOptions {
    RenderOptions { width: 640, height: 640, ..Default::default() }
}

/// Encodes `mesh` into `dir` unless already done with the same source and
/// options. Returns the levels.
pub fn encode_stage(mesh: &Mesh, source: &str, source_sha: &str, config: &Config, dir: &Path) -> Result<Vec<Level>> {
    let d = digest(&[source_sha, &config.stage_digest("encode")]);
    if is_done(dir, "encode", &d) {
        log::info!("encode: reusing {}", dir.display());
        return Ok(dataset::read(dir)?.1);
    }
    let t = Instant::now();
    let options = encode_options(config);
    let (levels, stats) = encode::encode(mesh, &options)?;
    dataset::write(dir, mesh, source, source_sha, &levels, &options, &stats, Some(&preview_options()))?;
    log::info!(
        "encode: {} levels in {:.1} s ({})",
        levels.len(),
        stats.total_s,
        levels.iter().map(|l| format!("{}^3 {}", l.resolution, l.len())).collect::<Vec<_>>().join(", ")
    );
    mark_done(dir, "encode", &d, t.elapsed().as_secs_f64())?;
    Ok(levels)
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
    std::fs::create_dir_all(models_dir).map_err(|e| Error::file(models_dir, e.to_string()))?;
    let which: Vec<usize> = match only {
        Some(k) if k >= levels.len() => {
            return Err(Error::Invalid(format!("--level {k}: the exemplar has levels 0..{}", levels.len() - 1)))
        }
        Some(k) => vec![k],
        None => (0..levels.len()).collect(),
    };
    let mut reports = Vec::new();
    for k in which {
        let d = digest(&[source_sha, &config.stage_digest("train"), &k.to_string()]);
        let stage = format!("train_level_{k}");
        if is_done(models_dir, &stage, &d) {
            log::info!("train level {k}: reusing {}", models_dir.display());
            continue;
        }
        let t = Instant::now();
        // Resume whatever a previous (killed) run of this level left.
        let resume = train::state_path(models_dir, k).exists();
        let r = train::train_level(levels, k, config, device, models_dir, resume, progress)?;
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
        reports.push(r);
    }
    Ok(reports)
}

pub fn variant_dir(variants_dir: &Path, i: usize) -> PathBuf {
    variants_dir.join(format!("variant_{i:03}"))
}

/// Writes one variant's levels (and previews) into its folder.
pub fn write_variant(dir: &Path, levels: &[Level], provenance: &Provenance, previews: bool) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    for level in levels {
        if level.is_empty() {
            log::warn!("{}: level {} is empty after pruning", dir.display(), level.index);
            continue;
        }
        vdb::write_level(&dir.join(dataset::level_file_name(level.index)), level, provenance, WriteOptions::default())?;
        if previews {
            let img = render::render_level(level, &preview_options())?;
            render::save_png(&img, &dir.join(format!("level_{}.png", level.index)))?;
        }
    }
    Ok(())
}

/// Samples `options.n` variants into `variants_dir/variant_XXX/`.
#[allow(clippy::too_many_arguments)]
pub fn sample_stage(
    exemplar_levels: &[Level],
    exemplar_name: &str,
    exemplar_open: bool,
    config: &Config,
    device: tch::Device,
    models_dir: &Path,
    variants_dir: &Path,
    options: &SampleOptions,
    previews: bool,
) -> Result<Vec<PathBuf>> {
    let d = digest(&[
        &config.digest(),
        &std::fs::read_to_string(train::state_path(models_dir, exemplar_levels.len() - 1)).unwrap_or_default(),
        &format!("{:?}", options),
    ]);
    let dirs: Vec<PathBuf> = (0..options.n).map(|i| variant_dir(variants_dir, i)).collect();
    if is_done(variants_dir, "sample", &d) {
        log::info!("sample: reusing {}", variants_dir.display());
        return Ok(dirs);
    }
    let t = Instant::now();
    let levels = options.stop_level.map_or(exemplar_levels.len(), |k| k + 1);
    let models = sample::load_models(models_dir, config, levels, device)?;
    let variants = sample::sample(&models, exemplar_levels, options, None)?;
    for (i, v) in variants.iter().enumerate() {
        let provenance = Provenance {
            exemplar: exemplar_name.into(),
            seed: Some(options.seed),
            config_digest: config.digest(),
            exemplar_open,
        };
        write_variant(&dirs[i], v, &provenance, previews)?;
    }
    log::info!("sample: {} variants in {:.1} s", options.n, t.elapsed().as_secs_f64());
    mark_done(variants_dir, "sample", &d, t.elapsed().as_secs_f64())?;
    Ok(dirs)
}

/// Writes the resolved configuration into a folder (`config.toml`).
pub fn record_config(dir: &Path, config: &Config) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    let path = dir.join("config.toml");
    let text = config.to_toml();
    write_atomically(&path, |tmp| std::fs::write(tmp, &text).map_err(|e| Error::file(&path, e.to_string())))
}
