//! The studio's jobs: sampling new variants, "more like this", regenerating
//! an edit's finer levels, keeping a variant. One worker thread owns the
//! trained networks and runs one job at a time, in the order they were
//! asked for (a second job queues; it never shares the cores unseen with
//! the first), but for the run's finishing work after a keep (meshing, the
//! USD asset, the evaluation of every variant: a minute on the tower), which
//! waits while a person's jobs are queued, and is done once for several
//! keeps. Each level a job makes is added to its shape as it finishes, so
//! the page shows it at once. A job is cancelled between sampling steps.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Instant;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::io::dataset::StartRecord;
use crate::learn::sample::{load_models, Models, SampleOptions};
use crate::level::Level;
use crate::pipeline::sample::{models_needed, sample_variants_observed};

use super::shapes::{judge, SeedOf, StudioRecord, Verdict, NOT_JUDGED};
use super::Studio;

/// What a job does, with everything it needs taken when it was asked for
/// (a later edit of the draft does not change a queued job).
#[derive(Clone, Debug)]
pub enum Work {
    /// `n` new variants from fresh seeds: variants 0..n of the run seed
    /// `seed`, the level-0 box scaled by `extent` (the paper's resize).
    Sample { n: usize, seed: u64, extent: [f32; 3] },
    /// `n` variants that keep `source`'s levels up to `keep_level` and
    /// sample the finer ones from new seeds.
    MoreLike { source: String, levels: Vec<Arc<Level>>, n: usize, seed: u64 },
    /// The finer levels of an edited level, from the source's own seed (the
    /// unedited parts come back as they were).
    Regenerate { draft: String, source: String, level: Level, seed: Option<SeedOf> },
    /// Writes a session variant into the run as a variant folder.
    Keep { shape: String },
    /// The run's mesh, USD asset and evaluation brought up to date with its
    /// kept variants (queued by a keep; runs when no other job waits).
    Finish,
}

impl Work {
    fn kind(&self) -> &'static str {
        match self {
            Work::Sample { .. } => "sample",
            Work::MoreLike { .. } => "more_like",
            Work::Regenerate { .. } => "regenerate",
            Work::Keep { .. } => "keep",
            Work::Finish => "finish",
        }
    }
}

#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    Queued,
    Running,
    Done,
    Failed,
    Cancelled,
}

/// When a level of a job's output was ready, seconds after the job started
/// running (and after it was asked for).
#[derive(Clone, Debug, Serialize)]
pub struct LevelReady {
    pub shape: String,
    pub level: usize,
    pub resolution: u32,
    pub voxels: usize,
    pub seconds: f64,
    pub since_asked: f64,
}

/// A job as the page sees it.
#[derive(Clone, Debug, Serialize)]
pub struct JobStatus {
    pub id: String,
    pub kind: &'static str,
    pub state: JobState,
    /// What it is doing, or why it failed.
    pub message: String,
    /// The shapes it made (session variant ids; a kept folder's name).
    pub outputs: Vec<String>,
    /// Levels made so far over levels to make (0 to 1).
    pub progress: f64,
    pub levels: Vec<LevelReady>,
    pub seconds: f64,
    /// When the worker took it: 1 for the first job it ran, 2 for the next...
    pub started: Option<usize>,
    #[serde(skip)]
    cancel: Arc<AtomicBool>,
    #[serde(skip)]
    asked: Instant,
}

/// Jobs waiting to start at most (a job is seconds to minutes of work: more
/// than this queued is a script gone wrong, not a person).
pub const MAX_QUEUED: usize = 32;
/// Finished jobs the studio still lists (the page polls the list): older
/// ones are forgotten, their outputs stay in the gallery.
pub const FINISHED_LISTED: usize = 32;

/// Jobs asked for and not started.
#[derive(Default)]
struct Queue {
    items: VecDeque<(String, Work)>,
    closed: bool,
}

/// The queue and every job's status.
pub struct Jobs {
    status: Mutex<Vec<JobStatus>>,
    /// Signalled on every change (tests and the benchmark wait on it).
    changed: Condvar,
    queue: Mutex<Queue>,
    available: Condvar,
    ids: super::Ids,
}

impl Jobs {
    pub fn new() -> Jobs {
        Jobs { status: Mutex::new(Vec::new()), changed: Condvar::new(), queue: Mutex::default(), available: Condvar::new(), ids: super::Ids::new("j") }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<JobStatus>> {
        self.status.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn lock_queue(&self) -> std::sync::MutexGuard<'_, Queue> {
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Queues `work`; its id. A finishing job already queued takes this one's
    /// place (it will finish every kept variant).
    pub fn submit(&self, work: Work) -> Result<String> {
        let mut queue = self.lock_queue();
        if queue.closed {
            return Err(Error::Invalid("the studio is stopping: no new jobs".into()));
        }
        if matches!(work, Work::Finish) {
            if let Some((id, _)) = queue.items.iter().find(|(_, w)| matches!(w, Work::Finish)) {
                return Ok(id.clone());
            }
        }
        if queue.items.len() >= MAX_QUEUED {
            return Err(Error::Busy(format!("{MAX_QUEUED} jobs are waiting already: ask again when some have run (or cancel some)")));
        }
        let id = self.ids.next();
        let mut status = self.lock();
        // The oldest finished jobs beyond the listed number are forgotten.
        let finished = status.iter().filter(|j| j.finished()).count();
        if finished >= FINISHED_LISTED {
            let mut drop = finished + 1 - FINISHED_LISTED;
            status.retain(|j| {
                let forget = drop > 0 && j.finished();
                drop -= forget as usize;
                !forget
            });
        }
        status.push(JobStatus {
            id: id.clone(),
            kind: work.kind(),
            state: JobState::Queued,
            message: "queued".into(),
            outputs: Vec::new(),
            progress: 0.0,
            levels: Vec::new(),
            seconds: 0.0,
            started: None,
            cancel: Arc::new(AtomicBool::new(false)),
            asked: Instant::now(),
        });
        drop(status);
        queue.items.push_back((id.clone(), work));
        drop(queue);
        self.available.notify_all();
        self.changed.notify_all();
        Ok(id)
    }

    /// The next job to run: the first a person asked for, else the first
    /// finishing job; None once the queue is closed.
    fn take(&self) -> Option<(String, Work)> {
        let mut queue = self.lock_queue();
        loop {
            if queue.closed {
                return None;
            }
            let at = queue.items.iter().position(|(_, w)| !matches!(w, Work::Finish)).or(if queue.items.is_empty() { None } else { Some(0) });
            if let Some(at) = at {
                return queue.items.remove(at);
            }
            queue = self.available.wait(queue).unwrap_or_else(|e| e.into_inner());
        }
    }

    pub fn list(&self) -> Vec<JobStatus> {
        self.lock().clone()
    }

    pub fn get(&self, id: &str) -> Option<JobStatus> {
        self.lock().iter().find(|j| j.id == id).cloned()
    }

    /// Cancels a queued or running job (a finished one stays as it ended).
    pub fn cancel(&self, id: &str) -> Result<JobStatus> {
        let mut jobs = self.lock();
        let job = jobs.iter_mut().find(|j| j.id == id).ok_or_else(|| super::shapes::unknown(id))?;
        job.cancel.store(true, Ordering::SeqCst);
        if job.state == JobState::Queued {
            job.state = JobState::Cancelled;
            job.message = "cancelled before it started".into();
        }
        let out = job.clone();
        drop(jobs);
        self.changed.notify_all();
        Ok(out)
    }

    /// Stops taking jobs and cancels those queued or running (the studio is
    /// ending).
    pub fn close(&self) {
        self.lock_queue().closed = true;
        self.available.notify_all();
        for j in self.lock().iter() {
            j.cancel.store(true, Ordering::SeqCst);
        }
        self.changed.notify_all();
    }

    fn update(&self, id: &str, f: impl FnOnce(&mut JobStatus)) {
        if let Some(j) = self.lock().iter_mut().find(|j| j.id == id) {
            f(j);
        }
        self.changed.notify_all();
    }

    /// Waits until `done` holds of job `id`'s status or `timeout` passes;
    /// the status then.
    pub fn wait_for(&self, id: &str, timeout: std::time::Duration, done: impl Fn(&JobStatus) -> bool) -> Option<JobStatus> {
        let end = Instant::now() + timeout;
        let mut jobs = self.lock();
        loop {
            let job = jobs.iter().find(|j| j.id == id)?;
            if done(job) {
                return Some(job.clone());
            }
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Some(job.clone());
            }
            jobs = self.changed.wait_timeout(jobs, left).unwrap_or_else(|e| e.into_inner()).0;
        }
    }
}

impl JobStatus {
    pub fn finished(&self) -> bool {
        matches!(self.state, JobState::Done | JobState::Failed | JobState::Cancelled)
    }
}

/// Gives the memory a job freed back to the system. A job allocates on
/// many threads (the transfer's and the judge's rayon workers, libtorch's),
/// and glibc keeps what they free in per-thread arenas: over a session's
/// first 60 shapes the studio grew by 23 MiB a shape without this, 10 with
/// it, where a shape's levels are about 4-5 (docs/studio.md, "Limits").
fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free pages of glibc's heaps.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// The worker: loads the networks, then runs the queued jobs one at a time
/// until the queue closes.
pub fn worker(studio: Arc<Studio>) {
    let models = (|| {
        let config = &studio.config;
        let needed = models_needed(config, &studio.exemplar, None);
        load_models(&studio.paths.models(), config, needed, studio.device)
    })();
    let models = match models {
        Ok(m) => Some(m),
        Err(e) => {
            log::error!("studio: the networks cannot be loaded: {e}");
            *studio.load_error.lock().unwrap_or_else(|e| e.into_inner()) = Some(e.to_string());
            None
        }
    };
    studio.ready.store(true, Ordering::SeqCst);
    // Per thread: the products of every job this worker runs.
    let _precision = crate::learn::sparse::bf16_compute_scope(studio.bf16);
    let mut taken = 0;
    while let Some((id, work)) = studio.jobs.take() {
        let Some(job) = studio.jobs.get(&id) else { continue };
        if job.cancel.load(Ordering::SeqCst) {
            continue;
        }
        taken += 1;
        studio.jobs.update(&id, |j| {
            j.started = Some(taken);
            j.state = JobState::Running;
            j.message = "running".into();
        });
        let started = Instant::now();
        // A bug in a job fails that job, not the worker (the panic hook has
        // printed where it happened).
        let result = crate::util::interrupt::cancellable(job.cancel.clone(), || {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_job(&studio, models.as_ref(), &id, &work, started)))
                .unwrap_or_else(|_| Err(Error::Invalid("internal error: a bug in shapeshifter (the studio's log names where)".into())))
        });
        let seconds = started.elapsed().as_secs_f64();
        release_freed_memory();
        let (state, message) = match result {
            Ok(msg) => (JobState::Done, msg),
            Err(Error::Cancelled) => (JobState::Cancelled, "cancelled: what it had not finished is dropped".to_string()),
            Err(e) => (JobState::Failed, crate::error::one_line(&e.to_string())),
        };
        if state != JobState::Done {
            // Outputs that did not finish are dropped: the gallery holds whole variants only.
            for out in job_outputs(&studio, &id) {
                let unfinished = studio.gallery.with(&out, |s| Ok(s.verdict.is_none() && s.kept_as.is_none())).unwrap_or(false);
                if unfinished {
                    let _ = studio.gallery.discard(&out);
                }
            }
        }
        log::info!("studio: job {id} ({}) {state:?} in {seconds:.2} s: {message}", work.kind());
        studio.jobs.update(&id, |j| {
            j.state = state;
            j.message = message;
            j.seconds = seconds;
            if state == JobState::Done {
                j.progress = 1.0;
            }
        });
        if crate::util::interrupt::requested().is_some() {
            break;
        }
    }
}

fn job_outputs(studio: &Studio, id: &str) -> Vec<String> {
    studio.jobs.get(id).map(|j| j.outputs).unwrap_or_default()
}

/// What a sampling job makes: `n` variants, indices `first..first + n` of
/// the run seed `seed`, each starting with the levels `given` and sampled
/// from `from` (the last given level) or from noise.
struct Plan {
    first: usize,
    n: usize,
    seed: u64,
    extent: [f32; 3],
    given: Vec<Level>,
    made_by: String,
    /// How the start of the shape continued from was made (none for new
    /// variants: theirs is what sampling reports).
    start: StartRecord,
}

fn run_job(studio: &Studio, models: Option<&Models>, id: &str, work: &Work, started: Instant) -> Result<String> {
    let plan = match work {
        Work::Keep { shape } => return keep(studio, id, shape),
        Work::Finish => return finish(studio, id),
        Work::Sample { n, seed, extent } => {
            let how = if *extent == [1.0; 3] { String::new() } else { format!(", extent {extent:?}") };
            Plan { first: 0, n: *n, seed: *seed, extent: *extent, given: Vec::new(), made_by: format!("new variant (seed {seed}{how})"), start: StartRecord::default() }
        }
        Work::MoreLike { source, levels, n, seed } => {
            let k = levels.last().map_or(0, |l| l.index);
            let made_by = format!("more like {source} (its levels up to {k}, seed {seed})");
            Plan { first: 0, n: *n, seed: *seed, extent: [1.0; 3], given: levels.iter().map(|l| (**l).clone()).collect(), made_by, start: studio.start_of(source) }
        }
        // From the source's own seed and index: where the level is unedited,
        // the finer levels are the source's.
        Work::Regenerate { draft, source, level, seed } => {
            let s = seed.unwrap_or(SeedOf { seed: studio.config.train.seed, index: 0 });
            let made_by = format!("edit of {source} at level {} ({draft})", level.index);
            Plan { first: s.index, n: 1, seed: s.seed, extent: [1.0; 3], given: vec![level.clone()], made_by, start: studio.start_of(source) }
        }
    };
    let models = models.ok_or_else(|| {
        let why = studio.load_error.lock().unwrap_or_else(|e| e.into_inner()).clone().unwrap_or_default();
        Error::Invalid(format!("no networks loaded: {why}"))
    })?;
    let finest = studio.exemplar.len() - 1;
    let from = plan.given.last().cloned();
    let start = from.as_ref().map_or(0, |l| l.index + 1);
    if start > finest {
        return Err(Error::Invalid(format!("nothing finer to make: the finest level is {finest}")));
    }
    let indices = plan.first..plan.first + plan.n;
    let ids: Vec<String> = indices
        .clone()
        .map(|index| studio.gallery.add_session(plan.made_by.clone(), Some(SeedOf { seed: plan.seed, index }), plan.start, plan.given.clone()))
        .collect();
    studio.jobs.update(id, |j| j.outputs = ids.clone());
    let per_variant = finest + 1 - start;
    let total = (plan.n * per_variant) as f64;
    for (k, (index, shape)) in indices.zip(&ids).enumerate() {
        crate::util::interrupt::check()?;
        let opts = SampleOptions { first: index, extent: plan.extent, ..SampleOptions::from_config(&studio.config, 1, plan.seed) };
        let sink = |_: usize, level: &Level| studio.level_made(id, shape, level, started, k * per_variant, total);
        let made = sample_variants_observed(models, &studio.exemplar, &opts, from.clone(), Some(&sink))?;
        // A continued shape keeps its source's start; a new one has the
        // start sampling made (bent, or in a resized box).
        if plan.given.is_empty() {
            let start = made.first().map(|v| StartRecord { bend: v.bend, extent: v.extent }).unwrap_or_default();
            studio.gallery.with(shape, |s| {
                s.start = start;
                Ok(())
            })?;
        }
        studio.judge_shape(shape);
    }
    Ok(format!("{} made (levels {start}..{finest})", if plan.n == 1 { "1 variant".into() } else { format!("{} variants", plan.n) }))
}

fn keep(studio: &Studio, id: &str, shape: &str) -> Result<String> {
    let (levels, seed, made_by, start) = studio.gallery.with(shape, |s| {
        let made_by = match &s.origin {
            super::shapes::Origin::Session { made_by } => made_by.clone(),
            _ => return Err(Error::Invalid(format!("{shape} is already a variant of the run"))),
        };
        if let Some(k) = &s.kept_as {
            return Err(Error::Invalid(format!("{shape} is already kept as {k}")));
        }
        Ok((s.levels.values().map(|l| (**l).clone()).collect::<Vec<Level>>(), s.seed, made_by, s.start))
    })?;
    let record = serde_json::to_vec_pretty(&StudioRecord { made_by, seed, compute: (if studio.bf16 { "bf16" } else { "f32" }).into() }).map_err(|e| Error::Invalid(e.to_string()))?;
    let kept = crate::pipeline::keep::KeptVariant {
        levels: &levels,
        seed: seed.map(|s| s.seed),
        start,
        record: &record,
    };
    let (name, dir) = crate::pipeline::keep::write_kept(&studio.paths, &studio.config, &kept)?;
    studio.gallery.add_run_variant(name.clone(), dir.clone(), None);
    studio.gallery.with(shape, |s| {
        s.kept_as = Some(name.clone());
        Ok(())
    })?;
    studio.jobs.update(id, |j| j.outputs = vec![shape.to_string(), name.clone()]);
    studio.jobs.submit(Work::Finish)?;
    Ok(format!("kept as {}; its mesh, the USD asset and the evaluation follow", dir.display()))
}

/// The run's mesh, USD asset and evaluation for its kept variants; the
/// gallery's verdicts from the new eval.json.
fn finish(studio: &Studio, id: &str) -> Result<String> {
    let mut progress = |what: &str| studio.jobs.update(id, |j| j.message = what.to_string());
    crate::pipeline::keep::finish_kept(&studio.paths, &studio.config, &mut progress)?;
    if let Some(e) = studio.read_eval() {
        studio.gallery.refresh_verdicts(&e);
    }
    Ok("the run's mesh, USD asset and eval.json include every kept variant".into())
}

impl Studio {
    /// A level of `shape` is made: it joins the shape, and the job's status
    /// says when.
    fn level_made(&self, job: &str, shape: &str, level: &Level, started: Instant, done_before: usize, total: f64) {
        let l = Arc::new(level.clone());
        let _ = self.gallery.with(shape, |s| {
            s.levels.insert(level.index, l);
            if !s.present.contains(&level.index) {
                s.present.push(level.index);
                s.present.sort_unstable();
            }
            s.preview = None;
            Ok(())
        });
        let seconds = started.elapsed().as_secs_f64();
        self.jobs.update(job, |j| {
            let made = j.levels.iter().filter(|r| r.shape == shape).count() + 1;
            j.progress = ((done_before + made) as f64 / total.max(1.0)).min(1.0);
            j.message = format!("{shape}: level {} ({}^3) made", level.index, level.resolution);
            j.levels.push(LevelReady {
                shape: shape.to_string(),
                level: level.index,
                resolution: level.resolution,
                voxels: level.len(),
                seconds,
                since_asked: j.asked.elapsed().as_secs_f64(),
            });
        });
    }

    /// The structure judge's verdict on a finished session variant.
    /// How `shape`'s start was made (none for the exemplar or a shape
    /// not found).
    fn start_of(&self, shape: &str) -> StartRecord {
        self.gallery.with(shape, |s| Ok(s.start)).unwrap_or_default()
    }

    fn judge_shape(&self, shape: &str) {
        let (levels, start): (Vec<Arc<Level>>, StartRecord) =
            self.gallery.with(shape, |s| Ok((s.levels.values().cloned().collect(), s.start))).unwrap_or_default();
        let verdict = judge(&self.exemplar, self.exemplar_structure.as_ref(), &levels, &start).unwrap_or_else(|| Verdict {
            by: NOT_JUDGED.into(),
            ..Verdict::default()
        });
        let _ = self.gallery.with(shape, |s| {
            s.verdict = Some(verdict);
            Ok(())
        });
    }
}
