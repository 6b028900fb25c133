//! The studio's speed on trained runs: from an edit of a coarse level to
//! each finer level ready to show (the studio's own job queue and worker,
//! the networks already loaded, as the page uses them), and the cost of the
//! page's points for the finest level. Prints, per run and per edited level,
//! the median and range over several regenerations.
//!
//! cargo run --release --example studio_bench -- RUN_DIR... [--repeats N] [--precision auto|f32|bf16]

use std::path::PathBuf;
use std::time::{Duration, Instant};

use shapeshifter::studio::{EditRequest, JobRequest, Studio};

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() -> anyhow::Result<()> {
    let mut runs: Vec<PathBuf> = Vec::new();
    let mut repeats = 5usize;
    let mut precision = shapeshifter::studio::Precision::Auto;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--repeats" => repeats = args.next().and_then(|n| n.parse().ok()).unwrap_or(5),
            "--precision" => {
                precision = match args.next().as_deref() {
                    Some("f32") => shapeshifter::studio::Precision::F32,
                    Some("bf16") => shapeshifter::studio::Precision::Bf16,
                    _ => shapeshifter::studio::Precision::Auto,
                }
            }
            _ => runs.push(a.into()),
        }
    }
    if runs.is_empty() {
        anyhow::bail!("usage: studio_bench RUN_DIR... [--repeats N] (run folders with trained models, e.g. out/demo)");
    }
    // As the studio command: every core for the one job at a time.
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    tch::set_num_threads(threads as i32);
    println!("studio_bench: {threads} libtorch threads, {repeats} regenerations per edit; seconds from the request to each level ready");
    for run in &runs {
        let studio = Studio::open(run, tch::Device::Cpu, precision)?;
        let _worker = studio.start();
        while !studio.ready.load(std::sync::atomic::Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(20));
        }
        let resolutions: Vec<u32> = studio.exemplar.iter().map(|l| l.resolution).collect();
        let st = studio.state();
        println!("\n{} ({} levels {:?}, networks for {}, products in {})", run.display(), resolutions.len(), resolutions, st.network_levels, st.compute);
        let source = studio.gallery.summaries().into_iter().find(|s| s.id.starts_with("variant_")).map(|s| s.id)
            .ok_or_else(|| anyhow::anyhow!("{}: no variant to edit", run.display()))?;
        for edit_level in [0usize, 1] {
            let draft = studio.new_draft(&source, edit_level)?;
            // Delete the side of the shape with the largest x: a quarter of
            // its occupied box.
            let level = studio.draft_level(&draft.id)?;
            let lo = level.coords.iter().fold(glam::IVec3::MAX, |a, &c| a.min(c));
            let hi = level.coords.iter().fold(glam::IVec3::MIN, |a, &c| a.max(c));
            let x0 = hi.x - (hi.x - lo.x) / 4;
            let edit: EditRequest = serde_json::from_value(serde_json::json!({
                "op": "delete", "box": {"min": [x0, lo.y, lo.z], "max": [hi.x, hi.y, hi.z]}
            }))?;
            let (did, _) = studio.edit(&draft.id, &edit)?;
            let mut per_level: Vec<Vec<f64>> = vec![Vec::new(); resolutions.len()];
            let mut points_ms = Vec::new();
            for _ in 0..repeats {
                let id = studio.submit(JobRequest::Regenerate { draft: draft.id.clone() })?;
                let job = studio.jobs.wait_for(&id, Duration::from_secs(600), |j| j.finished()).expect("the job is known");
                anyhow::ensure!(job.state == shapeshifter::studio::JobState::Done, "job {id}: {}", job.message);
                for l in &job.levels {
                    per_level[l.level].push(l.since_asked);
                }
                // The page's points of the finest level, as the server makes them.
                let shape = &job.outputs[0];
                let finest = studio.gallery.level(shape, resolutions.len() - 1)?;
                let t = Instant::now();
                let bytes = shapeshifter::studio::shapes::points_payload(&finest);
                points_ms.push(t.elapsed().as_secs_f64() * 1e3);
                std::hint::black_box(bytes);
                studio.gallery.discard(shape)?;
            }
            println!("  edit at level {edit_level} ({}^3): {did}", resolutions[edit_level]);
            for (k, times) in per_level.iter_mut().enumerate().filter(|(_, t)| !t.is_empty()) {
                let (lo, hi) = (times.iter().cloned().fold(f64::MAX, f64::min), times.iter().cloned().fold(0.0, f64::max));
                println!("    level {k} ({:>3}^3) ready: median {:.2} s (min {lo:.2}, max {hi:.2})", resolutions[k], median(times));
            }
            println!("    points of the finest level for the page: median {:.1} ms", median(&mut points_ms));
        }
        studio.jobs.close();
    }
    Ok(())
}
