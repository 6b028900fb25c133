//! Child processes of a stage: training levels and shards of variants run
//! as processes of their own (exactly the commands a cluster job runs), their
//! logs, progress bars, failures and stop signals.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::config::Config;
use crate::error::{Error, Result};
use crate::learn::checkpoint::thread_grant_path;

/// Runs `child(k)` for every level in `todo`, at most `jobs` at a time, the
/// costliest first ([`training_cost`]: the longest job must not start last);
/// each child's stderr goes to
/// `models/level_K_train.log`, and `progress` draws one bar per level from
/// those logs. Each child starts with `threads` libtorch threads; once no
/// level waits, the `jobs x threads` threads are shared by the children still
/// running ([`grant_free_cores`]). Fails, after the running children end,
/// naming every level whose process failed and the last line of its log.
pub fn train_in_processes(
    models: &Path,
    todo: &[usize],
    config: &Config,
    jobs: usize,
    threads: i32,
    progress: bool,
    child: impl Fn(usize) -> std::process::Command,
) -> Result<()> {
    let mut queue: Vec<usize> = todo.to_vec();
    // Popped from the end: the costliest first (the finer of equal costs).
    queue.sort_by(|&a, &b| training_cost(config, a).total_cmp(&training_cost(config, b)).then(a.cmp(&b)));
    let tc = &config.train;
    let total = |k: usize| if k == 0 { tc.level0_iterations } else { tc.upsampler_iterations + tc.upper_iterations };
    let bars = indicatif::MultiProgress::with_draw_target(if progress {
        indicatif::ProgressDrawTarget::stderr()
    } else {
        indicatif::ProgressDrawTarget::hidden()
    });
    let style = indicatif::ProgressStyle::with_template("level {prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} {msg}")
        .expect("valid template");
    let mut running: Vec<(usize, std::process::Child, indicatif::ProgressBar, PathBuf)> = Vec::new();
    let result = schedule(models, &mut queue, &mut running, (jobs, threads), &bars, &style, &total, &child);
    if result.is_err() && crate::util::interrupt::requested().is_none() {
        // Leave no orphan training on: stop the children still running.
        for (_, process, bar, _) in running.iter_mut() {
            let _ = process.kill();
            let _ = process.wait();
            crate::util::interrupt::forget(process);
            bar.abandon_with_message("stopped");
        }
    }
    result?;
    Ok(())
}

#[allow(clippy::too_many_arguments)]
/// A level's training time in units of one upper-level diffusion step, for
/// ordering the jobs: a level-0 step (the 16^3 box) costs about 0.45 of one
/// (the tower on the `cpu` profile: 41 ms against 85-110 ms per step with
/// the upsampler's share), an upsampler step about 0.25.
pub fn training_cost(config: &Config, level: usize) -> f64 {
    let tc = &config.train;
    if level == 0 {
        0.45 * tc.level0_iterations as f64
    } else {
        tc.upper_iterations as f64 + 0.25 * tc.upsampler_iterations as f64
    }
}


fn schedule(
    models: &Path,
    queue: &mut Vec<usize>,
    running: &mut Vec<(usize, std::process::Child, indicatif::ProgressBar, PathBuf)>,
    (jobs, threads): (usize, i32),
    bars: &indicatif::MultiProgress,
    style: &indicatif::ProgressStyle,
    total: &dyn Fn(usize) -> usize,
    child: &dyn Fn(usize) -> std::process::Command,
) -> Result<()> {
    let mut failed: Vec<String> = Vec::new();
    let t0 = Instant::now();
    let count = queue.len();
    // `--progress alf`: the steps of every level, finished and running.
    let all_steps: usize = queue.iter().map(|&k| total(k)).sum();
    let mut finished_steps = 0;
    let mut granted: HashMap<usize, i32> = HashMap::new();
    while !queue.is_empty() || !running.is_empty() {
        // After a stop signal (forwarded to the children): start nothing
        // more, and wait for the running children to checkpoint and end.
        let stopping = crate::util::interrupt::requested().is_some();
        while running.len() < jobs.max(1) && failed.is_empty() && !stopping {
            let Some(k) = queue.pop() else { break };
            let log_path = models.join(format!("level_{k}_train.log"));
            let log = std::fs::File::create(&log_path).map_err(|e| Error::file(&log_path, e.to_string()))?;
            let _ = std::fs::remove_file(thread_grant_path(models, k)); // an earlier run's
            let process = crate::util::interrupt::spawn(child(k).stdout(std::process::Stdio::null()).stderr(log))
                .map_err(|e| Error::Invalid(format!("cannot start the training process of level {k} ({e})")))?;
            let bar = bars.add(indicatif::ProgressBar::new(total(k) as u64));
            bar.set_style(style.clone());
            bar.set_prefix(k.to_string());
            running.push((k, process, bar, log_path));
        }
        if !failed.is_empty() || stopping {
            queue.clear(); // start nothing more after a failure or a stop
        } else if queue.is_empty() {
            grant_free_cores(models, running, jobs, threads, &mut granted);
        }
        std::thread::sleep(std::time::Duration::from_millis(if stopping { 50 } else { 500 }));
        let mut i = 0;
        let mut running_steps = 0;
        while i < running.len() {
            let (k, process, bar, log_path) = &mut running[i];
            let steps = steps_logged(log_path).min(total(*k));
            bar.set_position(steps as u64);
            match process.try_wait().map_err(|e| Error::Invalid(format!("level {k} training: {e}")))? {
                None => {
                    running_steps += steps;
                    i += 1
                }
                Some(status) => {
                    finished_steps += total(*k);
                    crate::util::interrupt::forget(process);
                    let _ = std::fs::remove_file(thread_grant_path(models, *k));
                    if status.success() {
                        bar.finish_with_message("done");
                    } else {
                        let last = last_log_line(log_path);
                        failed.push(format!("level {k} training failed ({status}): {last} (log: {})", log_path.display()));
                        bar.abandon_with_message("failed");
                    }
                    running.swap_remove(i);
                }
            }
        }
        crate::util::progress::report_parts(finished_steps + running_steps, all_steps);
    }
    crate::util::interrupt::check()?;
    if !failed.is_empty() {
        return Err(Error::Invalid(failed.join("; ")));
    }
    log::info!("train: {count} levels on {} processes in {:.0} s", jobs.max(1), t0.elapsed().as_secs_f64());
    Ok(())
}

/// Once no level waits to start, the cores of the levels that finished go to
/// those still training: the `jobs x threads` libtorch threads shared by the
/// running children (the earlier started, the costlier, takes a remainder),
/// each one's share written to its grant file ([`thread_grant_path`], read by
/// the child about once a second) when it changes. With 2 cores and the
/// `cpu` profile, level 0 trains on 2 threads once levels 1 and 2 are done.
/// The weights do not depend on the thread count (learn::train).
fn grant_free_cores(
    models: &Path,
    running: &[(usize, std::process::Child, indicatif::ProgressBar, PathBuf)],
    jobs: usize,
    threads: i32,
    granted: &mut HashMap<usize, i32>,
) {
    if threads <= 0 || running.is_empty() {
        return; // libtorch's own thread count (0) already takes every core
    }
    let mut order: Vec<usize> = running.iter().map(|r| r.0).collect();
    order.sort_unstable(); // level 0 (the longest training) first
    // Never more threads than cores (`--jobs` above the core count).
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get()) as i32;
    let total = (jobs.max(1) as i32 * threads).min(cores).max(threads);
    let n = order.len() as i32;
    for (i, k) in order.into_iter().enumerate() {
        // Never below what the child started with (`--threads` as asked).
        let share = (total / n + i32::from((i as i32) < total % n)).max(threads);
        if granted.get(&k).copied().unwrap_or(threads) != share
            && crate::util::fs::write_file(&thread_grant_path(models, k), share.to_string()).is_ok()
        {
            granted.insert(k, share);
        }
    }
}

/// Runs shards `0..n` of a stage as at most `jobs` concurrent child processes,
/// `child(first, count)` building each one's command (e.g. `stage sample OUT
/// --first K -n N`), with `jobs` contiguous shards of near-equal size. Each
/// child's stderr goes to `log_dir/<what>_K.log`; fails naming every shard
/// that failed and the last line of its log.
pub fn run_shards(
    n: usize,
    jobs: usize,
    log_dir: &Path,
    what: &str,
    child: impl Fn(usize, usize) -> std::process::Command,
) -> Result<()> {
    let jobs = jobs.clamp(1, n.max(1));
    let mut running = Vec::new();
    let mut first = 0;
    for j in 0..jobs {
        let count = n / jobs + usize::from(j < n % jobs);
        if count == 0 {
            continue;
        }
        let log_path = log_dir.join(format!("{what}_{first}.log"));
        let log = std::fs::File::create(&log_path).map_err(|e| Error::file(&log_path, e.to_string()))?;
        let spawned = crate::util::interrupt::spawn(child(first, count).stdout(std::process::Stdio::null()).stderr(log));
        match spawned {
            Ok(c) => running.push((first, c, log_path)),
            Err(e) => {
                for (_, c, _) in running.iter_mut() {
                    let _ = c.kill();
                    let _ = c.wait();
                    crate::util::interrupt::forget(c);
                }
                return Err(Error::Invalid(format!("cannot start a {what} process ({e})")));
            }
        }
        first += count;
    }
    let mut failed = Vec::new();
    for (first, mut c, log_path) in running {
        let status = c.wait().map_err(|e| Error::Invalid(format!("{what} shard {first}: {e}")))?;
        crate::util::interrupt::forget(&c);
        if !status.success() {
            let last = last_log_line(&log_path);
            failed.push(format!("{what} from variant {first} failed ({status}): {last} (log: {})", log_path.display()));
        }
    }
    // Children stopped by a forwarded signal are not failures of their own.
    crate::util::interrupt::check()?;
    if failed.is_empty() {
        Ok(())
    } else {
        Err(Error::Invalid(failed.join("; ")))
    }
}

/// The last line of a child's log, or what explains an empty one: a child
/// whose disk is full cannot write its log either.
fn last_log_line(log: &Path) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    match text.lines().rev().find(|l| !l.trim().is_empty()) {
        Some(l) => l.to_string(),
        None if crate::util::fs::disk_is_full(log) => "no output: No space left on device (its disk is full)".into(),
        None => "no output".into(),
    }
}

/// Steps a training log reports (upsampler steps, then diffusion steps,
/// from the "<phase> step X/Y" lines written every tenth of a phase).
fn steps_logged(log: &Path) -> usize {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let mut upsampler = 0;
    let mut diffusion = 0;
    for line in text.lines() {
        let Some((head, rest)) = line.split_once(" step ") else { continue };
        let Some(done) = rest.split('/').next().and_then(|v| v.trim().parse::<usize>().ok()) else { continue };
        if head.ends_with("upsampler") {
            upsampler = done;
        } else if head.ends_with("diffusion") {
            diffusion = done;
        }
    }
    upsampler + diffusion
}
