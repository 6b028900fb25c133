//! The studio (`shapeshifter studio RUN`): a local web page to steer the
//! variants of a run with trained networks. It keeps the exemplar, the
//! networks and the variants in memory; a person looks at any level of any
//! variant beside the exemplar, samples new ones, asks for more like one,
//! resizes the level-0 box, edits a coarse level (delete, copy, paste, move,
//! paste from the exemplar, undo, redo) and has the finer levels
//! regenerated, then keeps what is worth keeping as a variant folder of the
//! run (level files, previews, mesh, the USD asset, the evaluation).
//!
//! The studio calls the library functions the commands call: sampling is
//! [`crate::pipeline::sample::sample_variants_observed`] (`sample`'s, told of
//! each level as it is made), editing is [`crate::level::edit`] (`edit`'s),
//! keeping is [`crate::pipeline::keep`] then the run's own mesh, USD and eval
//! stages.
//!
//! - [`shapes`]: the gallery (exemplar, run variants, session variants) and
//!   the judge's verdicts;
//! - [`drafts`]: edits of a level with undo and redo;
//! - [`jobs`]: the one worker that owns the networks, and the job queue;
//! - [`http`]: the local HTTP server (token, Host check, routes);
//! - [`assets`]: the page and the vendored three.js, built into the binary.

pub mod assets;
pub mod drafts;
pub mod http;
pub mod jobs;
pub mod saved;
pub mod shapes;

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use crate::config::Config;
use crate::error::{Error, Result};
use crate::io::dataset;
use crate::level::Level;
use crate::pipeline::layout::{RunPaths, CONFIG};

pub use drafts::{Clipboard, Draft, DraftSummary, EditRequest};
pub use jobs::{JobState, JobStatus, Jobs, Work};
pub use shapes::{Gallery, ShapeSummary, Verdict};

/// Most variants one job may ask for (each is a full coarse-to-fine pass).
pub const MAX_VARIANTS_PER_JOB: usize = 16;

/// How the studio's networks multiply.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// bf16 where the device multiplies it in hardware (a GPU, a CPU with
    /// AVX512-BF16: 2.2x faster to 64^3 on the 2-core machine), else f32.
    #[default]
    Auto,
    /// f32, as `sample` does: a kept variant is what `sample --from` makes.
    F32,
    /// bf16 products (f32 weights and features, cast for each convolution's
    /// GEMM, as the `cpu` profile trains); emulated and slow without hardware bf16.
    Bf16,
}

/// A run folder opened for steering.
pub struct Studio {
    pub paths: RunPaths,
    /// The configuration the networks were trained under (`models/config.toml`).
    pub config: Config,
    pub exemplar: Vec<Level>,
    pub exemplar_name: String,
    /// The exemplar's structure level and its structure, for the verdicts.
    pub exemplar_structure: Option<(usize, crate::judge::Structure)>,
    pub device: tch::Device,
    /// Whether the networks multiply in bf16 (see [`Precision`]).
    pub bf16: bool,
    pub gallery: Gallery,
    drafts: Mutex<Vec<Draft>>,
    draft_ids: Ids,
    /// What a saved draft's level file records of its making.
    draft_provenance: crate::io::vdb::Provenance,
    clipboard: Mutex<Option<Clipboard>>,
    pub jobs: Jobs,
    /// Set once the worker has loaded the networks (or failed to).
    pub ready: AtomicBool,
    pub load_error: Mutex<Option<String>>,
}

/// A job as the page asks for it.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum JobRequest {
    /// `n` new variants from a fresh seed (`seed`, else one drawn), the
    /// level-0 box scaled by `extent` per axis.
    Sample { n: usize, seed: Option<u64>, extent: Option<[f32; 3]> },
    /// `n` variants keeping `source`'s levels up to `keep_level`.
    MoreLike { source: String, keep_level: usize, n: usize, seed: Option<u64> },
    /// The finer levels of a draft.
    Regenerate { draft: String },
    /// A session variant written into the run.
    Keep { shape: String },
}

/// Everything the page lists.
#[derive(Serialize)]
pub struct StudioState {
    pub run: String,
    pub exemplar: String,
    /// Resolution of each level, coarsest first.
    pub resolutions: Vec<u32>,
    /// Levels made by networks (the finer ones by detail transfer).
    pub network_levels: usize,
    /// The structure level's index (where the judge looks).
    pub structure_level: Option<usize>,
    /// The exemplar's frame: normalised = (world - centre) * scale (a
    /// mesh, in world units, is placed with it); `up` the vertical axis.
    pub frame_centre: [f64; 3],
    pub frame_scale: f64,
    pub up: &'static str,
    /// "bf16" or "f32": how the networks multiply.
    pub compute: &'static str,
    pub ready: bool,
    pub load_error: Option<String>,
    pub shapes: Vec<ShapeSummary>,
    pub drafts: Vec<DraftSummary>,
    pub clipboard: Option<String>,
    pub jobs: Vec<JobStatus>,
}

impl Studio {
    /// Opens the run folder `dir` (its encoded exemplar, the configuration
    /// its networks were trained under, its variants). The networks are
    /// loaded by the worker ([`Studio::start`]).
    pub fn open(dir: &Path, device: tch::Device, precision: Precision) -> Result<Arc<Studio>> {
        let paths = RunPaths::new(dir);
        let recorded = paths.models().join(CONFIG);
        if !recorded.is_file() {
            return Err(Error::Usage(format!(
                "{}: no trained models here (no models/config.toml): the studio opens a run folder after `shapeshifter run` (or `train`)",
                dir.display()
            )));
        }
        let config = Config::read(&recorded)?;
        let (manifest, exemplar) = dataset::read(&paths.exemplar())?;
        let eval = read_json(&paths.eval_json());
        let gallery = Gallery::open(&exemplar, &paths.variants(), eval.as_ref())?;
        let jobs = Jobs::new();
        let draft_provenance = crate::io::vdb::Provenance {
            exemplar: manifest.exemplar.clone(),
            seed: None,
            config_digest: config.digest(),
            exemplar_open: manifest.open_surface,
            crs: manifest.crs.clone(),
        };
        // Drafts a former studio left open, where they still fit the run's
        // levels (a coarser level than the finest, at its resolution).
        let finest = exemplar.len() - 1;
        let restored: Vec<Draft> = saved::load(&paths)
            .into_iter()
            .filter(|d| {
                let l = d.level();
                let fits = l.index < finest && exemplar[l.index].resolution == l.resolution;
                if !fits {
                    log::warn!("saved draft {}: level {} of {}^3 does not fit this run's levels: left out", d.id, l.index, l.resolution);
                }
                fits
            })
            .collect();
        let draft_ids = Ids::new("d");
        if let Some(last) = restored.iter().filter_map(|d| saved::draft_number(&d.id)).max() {
            draft_ids.continue_after(last);
        }
        if !restored.is_empty() {
            log::info!("{} drafts reopened from {}", restored.len(), saved::DRAFTS_DIR);
        }
        let studio = Studio {
            paths,
            config,
            exemplar_structure: shapes::exemplar_structure(&exemplar),
            exemplar,
            exemplar_name: manifest.exemplar,
            device,
            bf16: match precision {
                Precision::Auto => crate::learn::sparse::bf16_is_native(device),
                Precision::F32 => false,
                Precision::Bf16 => true,
            },
            gallery,
            drafts: Mutex::new(restored),
            draft_ids,
            draft_provenance,
            clipboard: Mutex::new(None),
            jobs,
            ready: AtomicBool::new(false),
            load_error: Mutex::new(None),
        };
        // Kept variants a stopped studio did not finish (no mesh yet).
        if !crate::pipeline::keep::unfinished_kept(&studio.paths).is_empty() {
            studio.jobs.submit(Work::Finish)?;
        }
        Ok(Arc::new(studio))
    }

    /// Starts the worker that loads the networks and runs the jobs.
    pub fn start(self: &Arc<Self>) -> std::thread::JoinHandle<()> {
        let studio = self.clone();
        std::thread::Builder::new().name("studio-worker".into()).spawn(move || jobs::worker(studio)).expect("a thread starts")
    }

    pub fn read_eval(&self) -> Option<serde_json::Value> {
        read_json(&self.paths.eval_json())
    }

    pub fn state(&self) -> StudioState {
        StudioState {
            run: self.paths.root.display().to_string(),
            exemplar: self.exemplar_name.clone(),
            resolutions: self.exemplar.iter().map(|l| l.resolution).collect(),
            network_levels: crate::pipeline::sample::trained_levels(&self.config, &self.exemplar),
            structure_level: self.exemplar_structure.as_ref().map(|(k, _)| *k),
            frame_centre: self.exemplar[0].frame.centre.to_array(),
            frame_scale: self.exemplar[0].frame.scale,
            up: if self.exemplar[0].frame.up == crate::level::Up::Z { "z" } else { "y" },
            compute: if self.bf16 { "bf16" } else { "f32" },
            ready: self.ready.load(std::sync::atomic::Ordering::SeqCst),
            load_error: self.load_error.lock().unwrap_or_else(|e| e.into_inner()).clone(),
            shapes: self.gallery.summaries(),
            drafts: self.lock_drafts().iter().map(Draft::summary).collect(),
            clipboard: self.clipboard.lock().unwrap_or_else(|e| e.into_inner()).as_ref().map(|c| format!("{} voxels of {}", c.piece.len(), c.from)),
            jobs: self.jobs.list(),
        }
    }

    fn lock_drafts(&self) -> std::sync::MutexGuard<'_, Vec<Draft>> {
        self.drafts.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A new draft of level `level` of shape `source`.
    pub fn new_draft(&self, source: &str, level: usize) -> Result<DraftSummary> {
        let finest = self.exemplar.len() - 1;
        if level >= finest {
            return Err(Error::Invalid(format!("level {level}: edit a coarser level than the finest ({finest}), so there is something to regenerate")));
        }
        let l = self.gallery.level(source, level)?;
        let seed = self.gallery.with(source, |s| Ok(s.seed))?;
        let mut drafts = self.lock_drafts();
        if drafts.len() >= drafts::MAX_DRAFTS {
            return Err(Error::Busy(format!("{} drafts are open: discard one first", drafts::MAX_DRAFTS)));
        }
        let draft = Draft::new(self.draft_ids.next(), source.to_string(), seed, (*l).clone());
        let summary = draft.summary();
        self.save_draft(&draft);
        drafts.push(draft);
        Ok(summary)
    }

    /// Applies an edit to a draft; what it did and the draft after it.
    pub fn edit(&self, draft: &str, edit: &EditRequest) -> Result<(String, DraftSummary)> {
        let mut drafts = self.lock_drafts();
        let d = drafts.iter_mut().find(|d| d.id == draft).ok_or_else(|| shapes::unknown(draft))?;
        let exemplar_level = self.exemplar.get(d.level().index);
        let mut clipboard = self.clipboard.lock().unwrap_or_else(|e| e.into_inner());
        let what = d.apply(edit, &mut clipboard, exemplar_level)?;
        let summary = d.summary();
        self.save_draft(d);
        Ok((what, summary))
    }

    /// Saves a draft into the run folder; a failure is logged (the draft
    /// stays open in this session).
    fn save_draft(&self, draft: &Draft) {
        if let Err(e) = saved::save(&self.paths, draft, &self.draft_provenance) {
            log::warn!("draft {} not saved into the run folder: {e}", draft.id);
        }
    }

    /// The current level of a draft.
    pub fn draft_level(&self, draft: &str) -> Result<Level> {
        let drafts = self.lock_drafts();
        let d = drafts.iter().find(|d| d.id == draft).ok_or_else(|| shapes::unknown(draft))?;
        Ok(d.level().clone())
    }

    pub fn discard_draft(&self, draft: &str) -> Result<()> {
        let mut drafts = self.lock_drafts();
        let at = drafts.iter().position(|d| d.id == draft).ok_or_else(|| shapes::unknown(draft))?;
        drafts.remove(at);
        saved::remove(&self.paths, draft);
        Ok(())
    }

    /// Checks a job request and queues it; its id. Everything a job needs is
    /// checked here, so a bad request is refused at once and queues nothing.
    pub fn submit(&self, request: JobRequest) -> Result<String> {
        let fresh_seed = |seed: Option<u64>| seed.unwrap_or_else(random_seed);
        let check_n = |n: usize| {
            if n == 0 || n > MAX_VARIANTS_PER_JOB {
                return Err(Error::Invalid(format!("n = {n}: ask for 1 to {MAX_VARIANTS_PER_JOB} variants")));
            }
            Ok(n)
        };
        let work = match request {
            JobRequest::Sample { n, seed, extent } => {
                let extent = extent.unwrap_or([1.0; 3]);
                crate::learn::sample::level0_box(&self.exemplar[0], extent)?;
                Work::Sample { n: check_n(n)?, seed: fresh_seed(seed), extent }
            }
            JobRequest::MoreLike { source, keep_level, n, seed } => {
                let finest = self.exemplar.len() - 1;
                if keep_level >= finest {
                    return Err(Error::Invalid(format!("keep_level {keep_level}: keep levels up to at most {} (the finest is {finest})", finest - 1)));
                }
                let levels = (0..=keep_level).map(|k| self.gallery.level(&source, k)).collect::<Result<Vec<_>>>()?;
                Work::MoreLike { source, levels, n: check_n(n)?, seed: fresh_seed(seed) }
            }
            JobRequest::Regenerate { draft } => {
                let drafts = self.lock_drafts();
                let d = drafts.iter().find(|d| d.id == draft).ok_or_else(|| shapes::unknown(&draft))?;
                if d.level().is_empty() {
                    return Err(Error::Invalid(format!("{draft} has no voxels left: nothing to regenerate from")));
                }
                Work::Regenerate { draft: draft.clone(), source: d.source.clone(), level: d.level().clone(), seed: d.seed }
            }
            JobRequest::Keep { shape } => {
                self.gallery.with(&shape, |s| match (&s.origin, &s.kept_as, &s.verdict) {
                    (shapes::Origin::Session { .. }, None, Some(_)) => Ok(()),
                    (shapes::Origin::Session { .. }, Some(k), _) => Err(Error::Invalid(format!("{shape} is already kept as {k}"))),
                    (shapes::Origin::Session { .. }, None, None) => Err(Error::Invalid(format!("{shape} is not finished yet"))),
                    _ => Err(Error::Invalid(format!("{shape} is already a variant of the run"))),
                })?;
                Work::Keep { shape }
            }
        };
        self.jobs.submit(work)
    }

    /// A PNG of the finest level of shape `id` (its preview file where the
    /// folder has one), drawn once.
    pub fn preview(&self, id: &str) -> Result<Arc<Vec<u8>>> {
        let (cached, folder, finest) = self.gallery.with(id, |s| Ok((s.preview.clone(), s.folder().map(Path::to_path_buf), s.present.last().copied())))?;
        if let Some(png) = cached {
            return Ok(png);
        }
        let finest = finest.ok_or_else(|| Error::Invalid(format!("{id} has no level yet")))?;
        let file = folder.map(|f| f.join(crate::level::files::preview_file_name(finest))).filter(|p| p.is_file());
        let png = match file {
            Some(p) => std::fs::read(&p).map_err(|e| Error::file(&p, e.to_string()))?,
            None => {
                let level = self.gallery.level(id, finest)?;
                let img = crate::render::render_level(&level, &crate::render::preview_options())?;
                let mut bytes = std::io::Cursor::new(Vec::new());
                img.write_to(&mut bytes, image::ImageFormat::Png).map_err(|e| Error::Invalid(format!("preview: {e}")))?;
                bytes.into_inner()
            }
        };
        let png = Arc::new(png);
        self.gallery.with(id, |s| {
            s.preview = Some(png.clone());
            Ok(())
        })?;
        Ok(png)
    }
}

fn read_json(path: &Path) -> Option<serde_json::Value> {
    serde_json::from_slice(&std::fs::read(path).ok()?).ok()
}

/// `buf` filled from the operating system's random source.
pub fn os_random(buf: &mut [u8]) -> std::io::Result<()> {
    use std::io::Read;
    std::fs::File::open("/dev/urandom")?.read_exact(buf)
}

/// A seed for new variants: random, short enough to type back into the page;
/// from the clock where the system has no random source (a seed need not be
/// secret).
pub fn random_seed() -> u64 {
    let mut b = [0u8; 8];
    let raw = match os_random(&mut b) {
        Ok(()) => u64::from_le_bytes(b),
        Err(_) => std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64),
    };
    raw % 1_000_000_007
}

/// Ids of one kind (`s1`, `s2`, ... for session variants, `d` drafts, `j` jobs).
pub struct Ids {
    prefix: &'static str,
    next: std::sync::atomic::AtomicUsize,
}

impl Ids {
    pub const fn new(prefix: &'static str) -> Ids {
        Ids { prefix, next: std::sync::atomic::AtomicUsize::new(1) }
    }
    /// The next id is numbered after `last` (ids reopened from a run folder).
    pub fn continue_after(&self, last: usize) {
        self.next.fetch_max(last + 1, std::sync::atomic::Ordering::SeqCst);
    }
    pub fn next(&self) -> String {
        format!("{}{}", self.prefix, self.next.fetch_add(1, std::sync::atomic::Ordering::SeqCst))
    }
}

/// What `shapeshifter studio` is asked.
pub struct StudioRequest<'a> {
    pub dir: &'a Path,
    /// 0: a free port the system picks.
    pub port: u16,
    pub device_spec: &'a str,
    pub precision: Precision,
    /// Wait for another command writing the run folder instead of failing.
    pub wait: bool,
}

/// The `studio` command: holds the run folder's lock (a `run` on it is
/// refused while the studio can write), loads it, serves the page on
/// 127.0.0.1 and tells `announce` its address (with the token), then serves
/// until SIGINT or SIGTERM. On a stop, new jobs are refused, the running one
/// is cancelled between steps, and what it had not finished is dropped (a
/// kept variant's folder is renamed into place only once whole).
pub fn run_studio(r: &StudioRequest, announce: &mut dyn FnMut(&str)) -> Result<()> {
    if !r.dir.is_dir() {
        return Err(Error::Usage(format!("{}: no such run folder", r.dir.display())));
    }
    let device = crate::pipeline::run::device(r.device_spec)?;
    // Opened (read only) before the lock: a folder that is not a run gets
    // its error and no lock file.
    let studio = Studio::open(r.dir, device, r.precision)?;
    let _lock = crate::util::lock::lock(r.dir, crate::util::lock::Mode::Exclusive, r.wait, "studio")?;
    log::info!("studio: the networks multiply in {}", if studio.bf16 { "bf16" } else { "f32" });
    let worker = studio.start();
    let served = http::serve(studio.clone(), http::ServeOptions { port: r.port, token: None })?;
    announce(&served.url());
    while crate::util::interrupt::requested().is_none() && !worker.is_finished() {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let worker_ended = worker.is_finished() && crate::util::interrupt::requested().is_none();
    studio.jobs.close();
    served.stop();
    let _ = worker.join();
    crate::util::interrupt::check()?;
    if worker_ended {
        return Err(Error::Invalid("the studio's worker stopped unexpectedly (a bug in shapeshifter; the line above says where)".into()));
    }
    Ok(())
}

/// The `studio` command: the interactive page on a run folder until a stop
/// signal, telling `on_url` the page's address once it serves.
/// `threads_given`: whether the user chose the libtorch thread count; if
/// not, the studio takes every core, since it runs one job at a time (the
/// batch default of one thread suits processes that run side by side).
pub fn studio_command(request: &StudioRequest, threads_given: bool, on_url: &mut dyn FnMut(&str)) -> Result<()> {
    if !threads_given {
        tch::set_num_threads(std::thread::available_parallelism().map_or(1, |n| n.get()) as i32);
    }
    run_studio(request, on_url)
}
