//! Stage 3, sampling: variants coarse to fine from the trained networks (and
//! detail transfer for the levels it makes), one stamped folder per variant.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::layout::variant_dir;
use super::stamp::{digest_of, is_done, mark_done, stamped_before_this_command, StampOf};
use super::RunPaths;
use crate::config::{Config, Stage};
use crate::error::{Error, Result};
use crate::io::vdb::Provenance;
use crate::learn::sample::{self, SampleOptions};
use crate::learn::train;
use crate::io::dataset;
use crate::level::Level;

/// A sampled variant with nothing at its finest level: its networks' masks
/// pruned every voxel at `first_empty` (a level index) or before.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct EmptyVariant {
    pub name: String,
    pub first_empty: usize,
}

/// The variant folders of `dirs` lacking a level file of `levels` (the
/// levels a sampling wrote: all, or those after a `--from` level), with the
/// first level each lacks.
pub fn empty_variants(dirs: &[PathBuf], levels: std::ops::RangeInclusive<usize>) -> Vec<EmptyVariant> {
    dirs.iter()
        .filter_map(|d| {
            let first_empty = levels.clone().find(|&k| !d.join(dataset::level_file_name(k)).is_file())?;
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

/// What one sampling stage does: which exemplar, models and options, into
/// which folder of variant folders.
pub struct SampleJob<'a> {
    /// The encoded exemplar's levels and manifest.
    pub exemplar_levels: &'a [Level],
    pub manifest: &'a dataset::Manifest,
    pub config: &'a Config,
    pub device: tch::Device,
    pub models_dir: &'a Path,
    /// Where `variant_NNN/` folders go (`OUT/variants` in a run).
    pub variants_dir: &'a Path,
    pub options: &'a SampleOptions,
    /// A level every variant continues from (`sample --from`), with the
    /// digest of its file.
    pub from: Option<(&'a Level, &'a str)>,
    /// Write `level_K.png` previews.
    pub previews: bool,
}

/// What a sampled variant depends on (its stamp's digest): the sampling
/// settings, the trained models, the options except which shard computed it,
/// the level it continued from, and its index.
#[derive(serde::Serialize)]
struct VariantInputs<'a> {
    settings: &'a str,
    models: &'a str,
    options: SampleOptions,
    from: Option<&'a str>,
    index: usize,
}

/// Samples variants `options.first .. first + n` into
/// `variants_dir/variant_XXX/` (XXX = the variant's index). Each variant
/// folder is stamped on its own, so shards written by different jobs fill one
/// folder, a re-run skips what is already there, and a stopped sampling
/// keeps the variants it finished.
pub fn sample_stage(job: &SampleJob) -> Result<Vec<PathBuf>> {
    let (config, options, levels) = (job.config, job.options, job.exemplar_levels);
    let indices: Vec<usize> = (options.first..options.first + options.n).collect();
    let dirs: Vec<PathBuf> = indices.iter().map(|&i| variant_dir(job.variants_dir, i)).collect();
    let models_state = std::fs::read_to_string(train::state_path(job.models_dir, trained_levels(config, levels) - 1)).unwrap_or_default();
    let (settings, models_digest) = (config.stage_digest(Stage::Sample), crate::util::digest::short(&models_state));
    let key = |index: usize| {
        digest_of(&VariantInputs {
            settings: &settings,
            models: &models_digest,
            options: SampleOptions { first: 0, n: 0, ..options.clone() },
            from: job.from.map(|(_, sha)| sha),
            index,
        })
    };
    // A variant is done when its stamp holds this key and, where previews are
    // asked for, each of its level files has its picture (a variant sampled
    // without them is sampled again, as it was the first time).
    let previewed = |d: &Path| {
        !job.previews
            || std::fs::read_dir(d).map_or(false, |entries| {
                entries.flatten().all(|e| {
                    let name = e.file_name().to_string_lossy().into_owned();
                    match crate::level::files::parse(&name) {
                        Some((k, crate::level::files::LevelFile::Volumes)) => d.join(crate::level::files::preview_file_name(k)).is_file(),
                        _ => true,
                    }
                })
            })
    };
    // A variant kept from the studio is the user's: never sampled over.
    let kept = |d: &Path| d.join(super::layout::KEPT_RECORD).is_file();
    for d in dirs.iter().filter(|d| kept(d)) {
        log::info!("sample: {} was kept from the studio: left as it is", d.display());
    }
    let todo: Vec<usize> = indices
        .iter()
        .zip(&dirs)
        .filter(|(&i, d)| !kept(d) && !(is_done(d, StampOf::Sample, &key(i)) && previewed(d)))
        .map(|(&i, _)| i)
        .collect();
    let reused = dirs.iter().zip(&indices).filter(|(d, i)| !todo.contains(i) && stamped_before_this_command(d, StampOf::Sample)).count();
    if reused > 0 {
        log::info!("sample: reusing {reused} variants in {}", job.variants_dir.display());
    }
    if todo.is_empty() {
        return Ok(dirs);
    }
    let t = Instant::now();
    let models = sample::load_models(job.models_dir, config, models_needed(config, levels, options.stop_level), job.device)?;
    let provenance = Provenance {
        exemplar: job.manifest.exemplar.clone(),
        seed: Some(options.seed),
        config_digest: config.digest(),
        exemplar_open: job.manifest.open_surface,
        crs: job.manifest.crs.clone(),
    };
    for (done, &i) in todo.iter().enumerate() {
        crate::util::interrupt::check()?;
        crate::util::progress::report_parts(done, todo.len());
        let tv = Instant::now();
        let one = SampleOptions { first: i, n: 1, ..options.clone() };
        let v = sample_variants(&models, levels, &one, job.from.map(|(l, _)| l.clone()))?;
        let dir = variant_dir(job.variants_dir, i);
        let preview = |level: &Level, path: &Path| super::encode::write_preview(level, &crate::render::preview_options(), path);
        dataset::write_variant(&dir, &v[0].levels, &provenance, job.previews.then_some(&preview as _), config.output.write_options())?;
        dataset::StartRecord { bend: v[0].bend, extent: v[0].extent }.write(&dir)?;
        mark_done(&dir, StampOf::Sample, &key(i), tv.elapsed().as_secs_f64())?;
    }
    log::info!("sample: {} variants in {:.1} s", todo.len(), t.elapsed().as_secs_f64());
    Ok(dirs)
}

/// The `sample` command: variants of the encoded exemplar in `exemplar_dir`
/// from the models in `models_dir` into `output` (its `config.toml` and one
/// folder per variant), optionally continuing from the level file `from`.
/// The same stage as a run's ([`sample_stage`]): the same stamps, so a
/// second call reuses what is there and `stage mesh`-style steps accept it.
/// Nothing usable is an error; some empty variants a warning.
pub fn sample_into(
    exemplar_dir: &Path,
    models_dir: &Path,
    output: &Path,
    config: &Config,
    device: tch::Device,
    options: &SampleOptions,
    from: Option<&Path>,
    previews: bool,
) -> Result<Vec<PathBuf>> {
    let (manifest, levels) = dataset::read(exemplar_dir)?;
    let from = match from {
        Some(p) => Some((crate::io::vdb::read_level(p)?.0, dataset::file_sha256(p)?)),
        None => None,
    };
    let dirs = sample_stage(&SampleJob {
        exemplar_levels: &levels,
        manifest: &manifest,
        config,
        device,
        models_dir,
        variants_dir: output,
        options,
        from: from.as_ref().map(|(l, sha)| (l, sha.as_str())),
        previews,
    })?;
    super::stamp::record_config(output, config)?;
    let resolutions: Vec<u32> = levels.iter().map(|l| l.resolution).collect();
    let finest = options.stop_level.unwrap_or(resolutions.len().saturating_sub(1));
    // A continuation writes only the levels after the one it started from.
    let first_written = from.as_ref().map_or(0, |(l, _)| l.index + 1);
    let empty = empty_variants(&dirs, first_written..=finest);
    check_usable(&empty, dirs.len(), &resolutions)?;
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
/// coarsest first (`from` itself not included) and its bend, where its start
/// was the exemplar bent.
pub fn sample_variants(
    models: &sample::Models,
    exemplar_levels: &[Level],
    opts: &SampleOptions,
    from: Option<Level>,
) -> Result<Vec<sample::SampledVariant>> {
    sample_variants_observed(models, exemplar_levels, opts, from, None)
}

/// [`sample_variants`], telling `sink` of every level of every variant as it
/// is made, network levels and transferred ones alike (the studio shows each
/// level as it finishes).
pub fn sample_variants_observed(
    models: &sample::Models,
    exemplar_levels: &[Level],
    opts: &SampleOptions,
    from: Option<Level>,
    sink: Option<sample::LevelSink>,
) -> Result<Vec<sample::SampledVariant>> {
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
        Some(level) if level.index >= diffusion_last && level.index < last => {
            vec![sample::SampledVariant { levels: Vec::new(), bend: None, extent: None }; opts.n]
        }
        _ => sample::sample_observed(models, exemplar_levels, &SampleOptions { stop_level: Some(diffusion_last), ..opts.clone() }, from.clone(), sink)?,
    };
    if last > diffusion_last {
        let config = &models.config.transfer;
        let sheet_axes = crate::judge::sheet::sheet_axes(exemplar_levels);
        let repairs = crate::level::repair::repairs(exemplar_levels, &sheet_axes, opts.remove_specks, opts.mend_sheets);
        for (i, v) in variants.iter_mut().enumerate() {
            let coarse = v.levels.last().or(from.as_ref()).ok_or_else(|| Error::Invalid("nothing to transfer from".into()))?;
            let seed = sample::variant_seed(opts.seed, opts.first + i);
            // A bent variant takes its detail from the exemplar bent the
            // same way: the exemplar's own patches, turned by the bend,
            // fit the bent surface where the unbent ones leave facets and
            // flakes (docs/lab/bent-figures.md, "Bent starts").
            let bent_source: Option<Vec<Level>> = v.bend.map(|b| {
                exemplar_levels[..=last]
                    .iter()
                    .map(|l| if l.index >= coarse.index { b.bent(exemplar_levels, l.index) } else { l.clone() })
                    .collect()
            });
            let source = bent_source.as_deref().unwrap_or(exemplar_levels);
            let index = opts.first + i;
            let mut tell = |l: &Level| {
                if let Some(sink) = sink {
                    sink(index, l)
                }
            };
            let finer = crate::transfer::extend_observed(source, coarse, last, config, seed, &repairs, &mut tell)?;
            v.levels.extend(finer);
        }
    }
    Ok(variants)
}

/// Stage 3: samples variants `options.first ..` into `OUT/variants`.
pub fn run_sample(paths: &RunPaths, config: &Config, device: tch::Device, options: &SampleOptions) -> Result<Vec<PathBuf>> {
    let (manifest, levels) = dataset::read(&paths.exemplar())?;
    sample_stage(&SampleJob {
        exemplar_levels: &levels,
        manifest: &manifest,
        config,
        device,
        models_dir: &paths.models(),
        variants_dir: &paths.variants(),
        options,
        from: None,
        previews: true,
    })
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
        let empty = empty_variants(&dirs, 0..=1);
        assert_eq!(
            empty,
            [EmptyVariant { name: "variant_001".into(), first_empty: 1 }, EmptyVariant { name: "variant_002".into(), first_empty: 0 }]
        );
        assert!(check_usable(&empty, 3, &[16, 32]).is_ok(), "one whole variant of three: a warning");
        let all = empty_variants(&dirs[1..], 0..=1);
        let e = check_usable(&all, 2, &[16, 32]).unwrap_err().to_string();
        assert!(e.contains("all 2 variants pruned to nothing (1 at level 0 (16^3), 1 at level 1 (32^3))"), "{e}");
        let from_memory = empty_sampled(&[vec![Level { index: 0, resolution: 16, ..Default::default() }], vec![]], &["a".into(), "b".into()]);
        assert_eq!(from_memory.len(), 2);
        assert_eq!(from_memory[0].first_empty, 0);
    }
}

/// What a user asks of the `sample` command, besides the folders.
pub struct SampleRequest<'a> {
    /// The trained models' folder (None: `models/` in the exemplar's folder).
    pub models: Option<&'a Path>,
    pub n: usize,
    pub first: usize,
    pub seed: u64,
    /// Per-axis scale of the level-0 box (1,1,1: the exemplar's extent).
    pub extent: [f32; 3],
    pub stop_level: Option<usize>,
    /// A level file to continue from (e.g. an edited level).
    pub from: Option<&'a Path>,
    pub previews: bool,
    /// `--set` overrides of the sampling settings, over the trained configuration.
    pub overrides: &'a [String],
    pub device_spec: &'a str,
    pub wait: bool,
}

/// `--extent X,Y,Z`: the per-axis scale of the level-0 box.
#[derive(Clone, Copy, Debug)]
pub struct Extent(pub [f32; 3]);

/// Reads `--extent X,Y,Z`: three positive scales. The command line refuses
/// anything else as bad usage (exit 2), before any work.
pub fn parse_extent(text: &str) -> std::result::Result<Extent, String> {
    match crate::level::edit::parse_vec3(text) {
        Some(v) if v.iter().all(|e| e.is_finite() && *e > 0.0) => Ok(Extent(v)),
        Some(_) => Err("each scale must be a positive number".into()),
        None => Err("expected three numbers X,Y,Z (e.g. 2,1,1)".into()),
    }
}

/// What `sample --json` prints: where the variants went and every file.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SampleRecord {
    pub models: PathBuf,
    pub output: PathBuf,
    pub status: &'static str,
    pub exit_status: u8,
    pub variants: usize,
    pub first: usize,
    pub seed: u64,
    pub seconds: f64,
    pub files: Vec<super::layout::OutputFile>,
}

/// `N variants -> OUTPUT`.
impl std::fmt::Display for SampleRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} variants -> {}", self.variants, self.output.display())
    }
}

/// The `sample` command: variants of the exemplar encoded in `dir` from its
/// trained models into `output` ([`sample_into`]), under the configuration
/// recorded at training time with the request's overrides.
pub fn sample_command(dir: &Path, output: &Path, r: &SampleRequest) -> Result<SampleRecord> {
    let t = Instant::now();
    // A run folder (what `run` writes) stands for its exemplar/ and models/.
    let run = RunPaths::new(dir);
    let is_run = !dir.join(dataset::MANIFEST).is_file() && run.exemplar().join(dataset::MANIFEST).is_file();
    let exemplar_dir = if is_run { run.exemplar() } else { dir.to_path_buf() };
    let dir = exemplar_dir.as_path();
    let models = r.models.map_or_else(|| run.models(), Path::to_path_buf);
    let recorded = models.join(super::layout::CONFIG);
    if !recorded.is_file() {
        return Err(Error::Invalid(format!(
            "{}: no trained models here (no config.toml): train first (`shapeshifter train {}`), or give --models",
            models.display(),
            dir.display()
        )));
    }
    let config = Config::read(&recorded)?.with_overrides(r.overrides)?;
    let device = super::run::device(r.device_spec)?;
    let options = SampleOptions {
        first: r.first,
        extent: r.extent,
        stop_level: r.stop_level,
        ..SampleOptions::from_config(&config, r.n, r.seed)
    };
    // An extent past the budget is refused before anything is made.
    let level0 = crate::io::vdb::read_level(&dir.join(dataset::level_file_name(0)))?.0;
    sample::level0_box(&level0, r.extent)?;
    let made_output = !output.exists();
    let lock = crate::util::lock::lock(output, crate::util::lock::Mode::Exclusive, r.wait, "sample")?;
    let dirs = match sample_into(dir, &models, output, &config, device, &options, r.from, r.previews) {
        Ok(dirs) => dirs,
        Err(e) => {
            // A folder this command made and left with nothing but its lock
            // is removed: a failed command leaves nothing behind.
            drop(lock);
            let only_lock = std::fs::read_dir(output).map_or(false, |entries| {
                entries.flatten().all(|e| e.file_name() == std::ffi::OsStr::new(crate::util::lock::LOCK_FILE))
            });
            if made_output && only_lock {
                let _ = std::fs::remove_dir_all(output);
            }
            return Err(e);
        }
    };
    Ok(SampleRecord {
        models,
        output: output.to_path_buf(),
        status: "done",
        exit_status: 0,
        variants: dirs.len(),
        first: r.first,
        seed: r.seed,
        seconds: t.elapsed().as_secs_f64(),
        files: dirs.iter().flat_map(|d| super::layout::output_files(d)).collect(),
    })
}
