//! Training and sampling on a tiny procedural exemplar (spheres at 8 and 16).
use std::sync::atomic::AtomicBool;

use glam::{DVec3, IVec3};
use tch::{Device, Kind, Tensor};
use shapeshifter::config::{BendExemplars, Config};
use shapeshifter::level::Level;
use shapeshifter::learn::nn::{new_diffusion, new_upsampler};
use shapeshifter::learn::sample::{level0_box, load_models, SampleOptions};

/// [`shapeshifter::learn::sample::sample`], each variant's levels only.
fn sample(
    models: &shapeshifter::learn::sample::Models,
    levels: &[Level],
    opts: &SampleOptions,
    from: Option<Level>,
) -> shapeshifter::error::Result<Vec<Vec<Level>>> {
    Ok(shapeshifter::learn::sample::sample(models, levels, opts, from)?.into_iter().map(|v| v.levels).collect())
}
use shapeshifter::learn::sparse::SparseTensor;
use shapeshifter::testing::synthetic::sphere_levels;
use shapeshifter::learn::train::{state_path, train_level, TrainJob, TrainState};

/// libtorch's CPU kernels are bitwise reproducible only when one thread at a time
/// runs them (concurrent callers share the intra-op pool and split work
/// differently), so these tests, which compare runs bit for bit, take turns.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    let g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // one intra-op thread: ~10x faster on the shared 2-core machine (see report)
    tch::set_num_threads(1);
    g
}

fn exemplar() -> Vec<Level> {
    sphere_levels(&[8, 16], DVec3::new(0.05, -0.1, 0.0), 0.55)
}

fn tiny(over: &[&str]) -> Config {
    let mut o: Vec<String> = [
        "model.channels=8",
        "model.upsampler_channels=8",
        "train.level0_batch=2",
        "train.upper_batch=2",
        "train.crop=7",
        "train.level0_iterations=60",
        "train.upper_iterations=60",
        "train.upsampler_iterations=60",
        "train.lr=3e-3",
        "train.upsampler_lr=3e-3",
        "sample.level0_steps=8",
        "sample.upper_steps=4",
        // The profile's rejection, made cheap: two candidates, two attempts.
        "sample.level0.candidates=2",
        "sample.attempts.count=2",
        // f32: these tests compare runs bit for bit (bf16 has its own test)
        "train.bf16=false",
        // The sphere is a figure: these tests follow the networks' passes
        // (bends have their own test).
        "sample.proposers.bend_voxels=0",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    o.extend(over.iter().map(|s| s.to_string()));
    Config::load("cpu", &o).unwrap()
}

fn read_state(dir: &std::path::Path, level: usize) -> TrainState {
    serde_json::from_str(&std::fs::read_to_string(state_path(dir, level)).unwrap()).unwrap()
}

#[test]
fn training_lowers_the_loss_at_level_0_and_1() {
    let _guard = serial();
    let levels = exemplar();
    let config = tiny(&[]);
    let dir = tempfile::tempdir().unwrap();
    let r0 = train_level(&TrainJob::new(&levels, 0, &config, Device::Cpu, dir.path())).unwrap();
    assert_eq!(r0.diffusion_steps, 60);
    assert!(r0.finished && !r0.interrupted);
    assert!(r0.diffusion_loss_end < 0.8 * r0.diffusion_loss_start, "level 0: {r0:?}");
    let r1 = train_level(&TrainJob::new(&levels, 1, &config, Device::Cpu, dir.path())).unwrap();
    assert_eq!((r1.upsampler_steps, r1.diffusion_steps), (60, 60));
    assert!(r1.upsampler_loss_end < 0.8 * r1.upsampler_loss_start, "upsampler: {r1:?}");
    assert!(r1.diffusion_loss_end < 0.8 * r1.diffusion_loss_start, "level 1: {r1:?}");
    // The training stage draws each level's loss plot from its recorded state.
    for k in 0..2 {
        shapeshifter::pipeline::write_loss_plot(dir.path(), k, &config).unwrap();
    }
    for f in ["level_0_diffusion.safetensors", "level_1_diffusion.safetensors", "level_1_upsampler.safetensors",
              "level_0_loss.png", "level_1_loss.png", "level_0_state.json", "level_1_state.json"] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
    assert!(dir.path().join("level_0_upsampler.safetensors").exists() == false);
    let st = read_state(dir.path(), 1);
    assert_eq!(st.diffusion_loss.len(), 60);
    assert_eq!(st.upsampler_loss.len(), 60);
    assert!(st.finished);
    // no temporary files left
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap()
        .filter_map(|e| e.ok()).filter(|e| e.file_name().to_string_lossy().contains(".tmp")).collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // same seed, same run
    let dir2 = tempfile::tempdir().unwrap();
    let r0b = train_level(&TrainJob::new(&levels, 0, &config, Device::Cpu, dir2.path())).unwrap();
    assert_eq!(read_state(dir.path(), 0).diffusion_loss, read_state(dir2.path(), 0).diffusion_loss);
    assert_eq!(r0.diffusion_loss_end, r0b.diffusion_loss_end);
}

/// Level 0's and level 1's weights do not depend on libtorch's thread count,
/// not even when it changes while a level trains (a finished level's cores
/// granted to one still training, pipeline::children): the same bytes with 1
/// thread (a step's two parts one after the other), 2 threads (side by
/// side), and 1 thread granted 2 at the first step. (Level 0's differed
/// with 2 threads when its target's blur used them.)
#[test]
fn weights_do_not_depend_on_the_thread_count() {
    use shapeshifter::learn::checkpoint::{diffusion_checkpoint, thread_grant_path};
    let _guard = serial();
    let levels = sphere_levels(&[16, 32], DVec3::new(0.05, -0.1, 0.0), 0.55);
    let config = tiny(&["model.channels=32", "train.level0_iterations=6", "train.upper_iterations=4",
                        "train.upsampler_iterations=4", "train.crop=11"]);
    let weights = |threads: i32, grant: Option<i32>| {
        tch::set_num_threads(threads);
        let dir = tempfile::tempdir().unwrap();
        let (mut files, mut cores) = (Vec::new(), 0);
        for k in 0..2 {
            if let Some(g) = grant {
                std::fs::write(thread_grant_path(dir.path(), k), g.to_string()).unwrap();
            }
            cores = train_level(&TrainJob::new(&levels, k, &config, Device::Cpu, dir.path())).unwrap().cores;
            files.push(std::fs::read(diffusion_checkpoint(dir.path(), k)).unwrap());
        }
        (files, cores)
    };
    let (one, _) = weights(1, None);
    let (two, two_cores) = weights(2, None);
    let (granted, threads_after) = weights(1, Some(2));
    tch::set_num_threads(1);
    assert_eq!(threads_after, 2, "the grant was read");
    assert_eq!(two_cores, 2, "two threads: two cores, the parts side by side");
    for k in 0..2 {
        assert!(one[k] == two[k], "level {k}: the weights differ between 1 and 2 threads");
        assert!(one[k] == granted[k], "level {k}: the weights differ when 2 threads are granted while training");
    }
}

#[test]
fn checkpoint_round_trip_gives_the_same_outputs() {
    let _guard = serial();
    let config = tiny(&[]);
    let dir = tempfile::tempdir().unwrap();
    let x = SparseTensor::from_level(&exemplar()[0], Device::Cpu).unwrap();
    tch::manual_seed(1);
    let a = new_diffusion(&config.model, 1, Device::Cpu).unwrap();
    let ua = new_upsampler(&config.model, Device::Cpu).unwrap();
    a.save(&dir.path().join("d.safetensors")).unwrap();
    ua.save(&dir.path().join("u.safetensors")).unwrap();
    tch::manual_seed(2);
    let mut b = new_diffusion(&config.model, 1, Device::Cpu).unwrap();
    let mut ub = new_upsampler(&config.model, Device::Cpu).unwrap();
    let ya = a.net.forward_at(&x, 0.2, false).unwrap().feats;
    let before = b.net.forward_at(&x, 0.2, false).unwrap().feats;
    assert!(!ya.equal(&before), "different seeds must give different models");
    b.load(&dir.path().join("d.safetensors")).unwrap();
    ub.load(&dir.path().join("u.safetensors")).unwrap();
    assert!(ya.equal(&b.net.forward_at(&x, 0.2, false).unwrap().feats));
    assert!(ua.net.forward_t(&x, false).unwrap().feats.equal(&ub.net.forward_t(&x, false).unwrap().feats));
    // a level-0 model does not load into a level-1 shape
    let mut c = new_diffusion(&config.model, 0, Device::Cpu).unwrap();
    assert!(c.load(&dir.path().join("d.safetensors")).is_err());
}

#[test]
fn resume_continues_the_step_count() {
    let _guard = serial();
    let levels = exemplar();
    let dir = tempfile::tempdir().unwrap();
    let short = tiny(&["train.upper_iterations=5", "train.upsampler_iterations=4", "train.checkpoint_minutes=0"]);
    // interrupted right after the first step
    let stop = AtomicBool::new(true);
    let r = train_level(&TrainJob { interrupt: Some(&stop), ..TrainJob::new(&levels, 1, &short, Device::Cpu, dir.path()) }).unwrap();
    assert!(r.interrupted && !r.finished);
    assert_eq!((r.upsampler_steps, r.diffusion_steps), (1, 0));
    assert_eq!(read_state(dir.path(), 1).upsampler_steps, 1);
    let r = train_level(&TrainJob { resume: true, ..TrainJob::new(&levels, 1, &short, Device::Cpu, dir.path()) }).unwrap();
    assert_eq!((r.upsampler_steps_now, r.diffusion_steps_now), (3, 5));
    assert_eq!((r.upsampler_steps, r.diffusion_steps), (4, 5));
    assert!(r.finished);
    let first = read_state(dir.path(), 1);
    // more iterations: the count goes on, the history is kept
    let long = tiny(&["train.upper_iterations=8", "train.upsampler_iterations=4"]);
    let r = train_level(&TrainJob { resume: true, ..TrainJob::new(&levels, 1, &long, Device::Cpu, dir.path()) }).unwrap();
    assert_eq!((r.upsampler_steps_now, r.diffusion_steps_now), (0, 3));
    assert_eq!(r.diffusion_steps, 8);
    let second = read_state(dir.path(), 1);
    assert_eq!(second.diffusion_loss.len(), 8);
    assert_eq!(&second.diffusion_loss[..5], &first.diffusion_loss[..]);
    assert_eq!(second.upsampler_loss, first.upsampler_loss);
    // finished: resuming again does nothing
    let r = train_level(&TrainJob { resume: true, ..TrainJob::new(&levels, 1, &long, Device::Cpu, dir.path()) }).unwrap();
    assert_eq!((r.upsampler_steps_now, r.diffusion_steps_now), (0, 0));
    // another model configuration refuses to resume
    let other = tiny(&["model.channels=4"]);
    assert!(train_level(&TrainJob { resume: true, ..TrainJob::new(&levels, 1, &other, Device::Cpu, dir.path()) }).is_err());
    // without resume it starts afresh
    let r = train_level(&TrainJob::new(&levels, 1, &short, Device::Cpu, dir.path())).unwrap();
    assert_eq!((r.upsampler_steps_now, r.diffusion_steps_now), (4, 5));
}

fn trained(dir: &std::path::Path, config: &Config) -> Vec<Level> {
    let levels = exemplar();
    for l in 0..2 {
        train_level(&TrainJob::new(&levels, l, config, Device::Cpu, dir)).unwrap();
    }
    levels
}

fn same(a: &[Vec<Level>], b: &[Vec<Level>]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x.len() == y.len()
                && x.iter().zip(y).all(|(p, q)| p.coords == q.coords && p.offsets == q.offsets && p.normals == q.normals && p.colours == q.colours)
        })
}

#[test]
fn sampling_is_reproducible_and_follows_options() {
    let _guard = serial();
    let config = tiny(&["train.level0_iterations=30", "train.upper_iterations=20", "train.upsampler_iterations=20"]);
    let dir = tempfile::tempdir().unwrap();
    let levels = trained(dir.path(), &config);
    let models = load_models(dir.path(), &config, 2, Device::Cpu).unwrap();
    assert!(load_models(dir.path(), &config, 3, Device::Cpu).is_err());
    let opts = SampleOptions::from_config(&config, 3, 7);
    let a = sample(&models, &levels, &opts, None).unwrap();
    let b = sample(&models, &levels, &opts, None).unwrap();
    assert_eq!(a.len(), 3);
    for v in &a {
        assert_eq!(v.len(), 2);
        assert_eq!((v[0].index, v[0].resolution, v[1].index, v[1].resolution), (0, 8, 1, 16));
        assert_eq!(v[0].frame, levels[0].frame);
        assert!(v[0].mask.iter().all(|&m| m == 1.0));
    }
    assert!(a.iter().map(|v| v[0].len()).sum::<usize>() > 0, "nothing sampled");
    assert!(same(&a, &b), "same seed, different output");
    // Shards: variants 1..3 and 2 alone are exactly those of the full set, bit for bit.
    let shard = sample(&models, &levels, &SampleOptions { first: 1, n: 2, ..opts.clone() }, None).unwrap();
    assert!(same(&shard, &a[1..3]), "a shard differs from the same variants of the whole set");
    let one = sample(&models, &levels, &SampleOptions { first: 2, n: 1, ..opts.clone() }, None).unwrap();
    assert!(same(&one, &a[2..3]) && one[0][1].mask == a[2][1].mask);
    let c = sample(&models, &levels, &SampleOptions { seed: 8, ..opts.clone() }, None).unwrap();
    assert!(!same(&a, &c), "different seed, same output");
    assert!(!same(&a[0..1], &a[1..2]), "variants are identical");
    // ddpm works too
    let ddpm = shapeshifter::learn::schedule::Sampler::Ddpm;
    let d = sample(&models, &levels, &SampleOptions { sampler: ddpm, level0_sampler: ddpm, ..opts.clone() }, None).unwrap();
    assert_eq!(d[0].len(), 2);
    assert!(!same(&d, &a), "ddpm and ddim gave the same variants: the sampler setting is ignored");
    // The novel level-0 pick keeps the variant's own first candidate (the
    // one a single-candidate run keeps) when it is new enough, else one no
    // more like the exemplar's level 0 than it.
    let novel_opts = SampleOptions {
        level0_candidates: 6,
        level0_min_structure: 0.0,
        level0_pick: shapeshifter::config::Level0Pick::Novel,
        level0_sampler: ddpm,
        stop_level: Some(0),
        ..opts.clone()
    };
    let first_opts = SampleOptions { level0_candidates: 1, level0_pick: shapeshifter::config::Level0Pick::First, ..novel_opts.clone() };
    let (novel, first) = (sample(&models, &levels, &novel_opts, None).unwrap(), sample(&models, &levels, &first_opts, None).unwrap());
    let likeness = |v: &[Vec<Level>]| v.iter().map(|l| shapeshifter::judge::tolerant_fscore(&l[0], &levels[0])).collect::<Vec<f64>>();
    let (ln, lf) = (likeness(&novel), likeness(&first));
    let new_enough = shapeshifter::learn::sample::NEW_ENOUGH_LEVEL0_FSCORE;
    for ((n, f), (nv, fv)) in ln.iter().zip(&lf).zip(novel.iter().zip(&first)) {
        if *f < new_enough {
            assert_eq!(nv[0].coords, fv[0].coords, "the first candidate was new enough ({f:.3}) and was not kept");
        } else {
            assert!(n <= f, "a novel pick more like the exemplar than the first candidate: {ln:?} vs {lf:?}");
        }
    }
    // Clamped clean estimates: every sampled feature within its range.
    for v in a.iter().chain(&d) {
        for l in v {
            assert!(l.offsets.iter().all(|o| o.abs().max_element() <= 0.5), "offset outside its voxel");
            assert!(l.colours.iter().all(|c| c.min_element() >= 0.0 && c.max_element() <= 1.0));
        }
    }

    // fine levels only contain children of the coarse level
    for v in &a {
        let parents: std::collections::HashSet<IVec3> = v[0].coords.iter().cloned().collect();
        assert!(v[1].coords.iter().all(|c| parents.contains(&c.div_euclid(IVec3::splat(2)))));
    }

    // extent [2, 1, 1]: a level-0 box twice as long in x, same centre
    let (lo, size) = level0_box(&levels[0], [1.0; 3]).unwrap();
    let (lo2, size2) = level0_box(&levels[0], [2.0, 1.0, 1.0]).unwrap();
    assert_eq!(size2, IVec3::new(2 * size.x, size.y, size.z));
    assert_eq!(lo2.y, lo.y);
    assert_eq!(2 * lo2.x + size2.x, 2 * lo.x + size.x, "centre kept");
    let wide = sample(&models, &levels, &SampleOptions { extent: [2.0, 1.0, 1.0], stop_level: Some(0), ..opts.clone() }, None).unwrap();
    let mut xmin = i32::MAX;
    let mut xmax = i32::MIN;
    for v in &wide {
        assert_eq!(v.len(), 1);
        for c in &v[0].coords {
            assert!(c.cmpge(lo2).all() && c.cmplt(lo2 + size2).all());
            xmin = xmin.min(c.x);
            xmax = xmax.max(c.x);
        }
    }
    assert!(xmax - xmin + 1 > size.x, "wide variants span {}..{} only", xmin, xmax);

    // continuing from an edited level 0 gives level 1 only, under the edited voxels
    let mut edited = a[0][0].clone();
    let keep_x = edited.coords.iter().map(|c| c.x).min().unwrap() + 2;
    let xs: Vec<i32> = edited.coords.iter().map(|c| c.x).collect();
    edited.retain(|i| xs[i] < keep_x);
    let kept: std::collections::HashSet<IVec3> = edited.coords.iter().cloned().collect();
    assert!(!kept.is_empty());
    let cont = sample(&models, &levels, &SampleOptions { n: 2, ..opts.clone() }, Some(edited.clone())).unwrap();
    assert_eq!(cont.len(), 2);
    for v in &cont {
        assert_eq!(v.len(), 1);
        assert_eq!((v[0].index, v[0].resolution), (1, 16));
        assert!(v[0].coords.iter().all(|c| kept.contains(&c.div_euclid(IVec3::splat(2)))));
    }
    // continuing from the unedited level reproduces the full run's finer level
    // (up to the float round trip of the colours through a Level)
    let full1 = sample(&models, &levels, &SampleOptions { n: 1, ..opts.clone() }, None).unwrap();
    let cont1 = sample(&models, &levels, &SampleOptions { n: 1, ..opts.clone() }, Some(full1[0][0].clone())).unwrap();
    assert_eq!(cont1[0][0].coords, full1[0][1].coords);
    let d = cont1[0][0].offsets.iter().zip(&full1[0][1].offsets).map(|(a, b)| (*a - *b).abs().max_element()).fold(0f32, f32::max);
    assert!(d < 1e-3, "{d}");
    // nothing finer than the last level
    let mut last = a[0][1].clone();
    last.index = 1;
    assert!(sample(&models, &levels, &opts, Some(last)).is_err());
    let _ = Tensor::zeros([1], (Kind::Float, Device::Cpu));
}

/// The level-0 rejection: candidate 0 is the variant's own noise, so one
/// candidate, or a threshold the first one passes, changes nothing; with an
/// unreachable threshold the best of the candidates is kept, never worse than
/// the first by the structure score.
#[test]
fn level0_rejection_keeps_the_best_candidate() {
    use shapeshifter::judge::{Structure, Thresholds, Verdict};
    let _guard = serial();
    let config = tiny(&["train.level0_iterations=30", "train.upper_iterations=10", "train.upsampler_iterations=10"]);
    let dir = tempfile::tempdir().unwrap();
    let levels = trained(dir.path(), &config);
    let models = load_models(dir.path(), &config, 2, Device::Cpu).unwrap();
    let opts = SampleOptions { stop_level: Some(0), level0_candidates: 1, attempts: 1, ..SampleOptions::from_config(&config, 4, 3) };
    let plain = sample(&models, &levels, &opts, None).unwrap();
    let easy = sample(&models, &levels, &SampleOptions { level0_candidates: 4, level0_min_structure: 0.0, ..opts.clone() }, None).unwrap();
    let one = sample(&models, &levels, &SampleOptions { level0_candidates: 1, level0_min_structure: 1.0, ..opts.clone() }, None).unwrap();
    assert!(same(&plain, &one), "one candidate is no rejection, whatever the threshold");
    assert!(same(&plain, &easy), "a threshold the first candidate passes changed the variants");
    let hard = sample(&models, &levels, &SampleOptions { level0_candidates: 4, level0_min_structure: 1.0, ..opts.clone() }, None).unwrap();
    let ex = Structure::of(&levels[0]);
    let score = |l: &Level| {
        if l.is_empty() {
            0.0
        } else {
            Verdict::new(l, &Structure::of(l), &levels[0], &ex, &Thresholds::default()).score
        }
    };
    let mut better = 0;
    for (p, h) in plain.iter().zip(&hard) {
        let (sp, sh) = (score(&p[0]), score(&h[0]));
        assert!(sh >= sp, "rejection kept a worse level 0: {sh} < {sp}");
        better += (sh > sp) as usize;
    }
    assert!(better > 0, "four candidates never beat the first one of four variants");
}

/// Where no level-0 candidate is new enough (here: an untrained network,
/// whose draws pass nothing), a pass is the exemplar bent: every level is
/// the exemplar's bent by the recorded bend. Without `bend_voxels`, never.
#[test]
fn a_pass_with_nothing_new_starts_from_the_exemplar_bent() {
    use std::collections::HashSet;
    let _guard = serial();
    let levels = sphere_levels(&[8, 16, 32], DVec3::new(0.05, -0.1, 0.0), 0.55);
    // `all`: the sphere's levels stop at 32^3, too coarse to be read as a
    // figure (the reading's own wiring is checked below).
    let config = tiny(&["sample.proposers.bend_voxels=1.5", "sample.proposers.bend_exemplars=all", "sample.filters={}"]);
    let models = shapeshifter::learn::sample::untrained_models(&config, 3, Device::Cpu, 3).unwrap();
    let opts = SampleOptions { stop_level: Some(2), ..SampleOptions::from_config(&config, 2, 5) };
    let bent = shapeshifter::learn::sample::sample(&models, &levels, &opts, None).unwrap();
    let set = |l: &Level| l.coords.iter().copied().collect::<HashSet<IVec3>>();
    for v in &bent {
        let bend = v.bend.expect("nothing new enough: the exemplar bent");
        assert_eq!(v.levels.len(), 3);
        for l in 0..3 {
            assert_eq!(set(&v.levels[l]), set(&bend.bent(&levels, l)), "level {l} is not the exemplar bent");
        }
        assert_ne!(set(&v.levels[1]), set(&levels[1]), "the bend moved nothing");
    }
    assert_ne!(bent[0].bend, bent[1].bend, "two variants, one bend");
    let again = shapeshifter::learn::sample::sample(&models, &levels, &opts, None).unwrap();
    assert_eq!(bent.iter().map(|v| v.bend).collect::<Vec<_>>(), again.iter().map(|v| v.bend).collect::<Vec<_>>());
    let off = SampleOptions { bend_voxels: 0.0, ..opts.clone() };
    let plain = shapeshifter::learn::sample::sample(&models, &levels, &off, None).unwrap();
    assert!(plain.iter().all(|v| v.bend.is_none()), "bent without bend_voxels");

    // Bends for figures only (the profiles'), read at 64^3 (the exemplars'
    // fourth level here, sampling stops at the third): the sphere is one and
    // is bent; a block with flat faces and upright walls is not, and is never
    // bent; `all` bends it.
    let figures = SampleOptions { bend_exemplars: BendExemplars::Figures, ..opts.clone() };
    let sphere4 = sphere_levels(&[8, 16, 32, 64], DVec3::new(0.05, -0.1, 0.0), 0.55);
    let posed = shapeshifter::learn::sample::sample(&models, &sphere4, &figures, None).unwrap();
    assert!(posed.iter().all(|v| v.bend.is_some()), "the sphere, a figure, not bent");
    let to64 = shapeshifter::encode::EncodeOptions { sampling_resolution: 128, coarsest_resolution: 8, finest_resolution: 64, ..Default::default() };
    let block = shapeshifter::testing::shapes::axis_box(glam::Vec3::new(-0.6, -0.9, -0.5), glam::Vec3::new(0.6, 0.9, 0.5));
    let block = shapeshifter::encode::encode(&block, &to64).unwrap().0;
    let figures_only = shapeshifter::learn::sample::sample(&models, &block, &figures, None).unwrap();
    assert!(figures_only.iter().all(|v| v.bend.is_none()), "a block bent as a figure");
    let all = SampleOptions { bend_exemplars: BendExemplars::All, ..figures.clone() };
    let any = shapeshifter::learn::sample::sample(&models, &block, &all, None).unwrap();
    assert!(any.iter().all(|v| v.bend.is_some()), "bend_exemplars = all did not bend the block");
    // Levels that stop below 48^3 are not read: not bent as a figure.
    let coarse = shapeshifter::learn::sample::sample(&models, &levels, &figures, None).unwrap();
    assert!(coarse.iter().all(|v| v.bend.is_none()), "bent on a reading at 32^3");

    // Networks finer than the structure level (64^3), several attempts: the
    // kept bent pass stays bent past the level the attempts stop at.
    let deep = sphere_levels(&[8, 16, 32, 64, 128], DVec3::new(0.05, -0.1, 0.0), 0.55);
    let models5 = shapeshifter::learn::sample::untrained_models(&config, 5, Device::Cpu, 3).unwrap();
    let v = shapeshifter::learn::sample::sample(&models5, &deep, &SampleOptions { n: 1, ..SampleOptions::from_config(&config, 1, 5) }, None).unwrap();
    let bend = v[0].bend.expect("bent");
    assert_eq!(v[0].levels.len(), 5);
    assert_eq!(set(&v[0].levels[4]), set(&bend.bent(&deep, 4)), "128^3 made by a network after a bent 64^3");

    // With the finer levels transferred, a bent variant's detail comes from
    // the exemplar bent the same way: its finest level is close to that,
    // and further from the exemplar itself.
    let transfer = tiny(&[
        "sample.proposers.bend_voxels=1.5",
        "sample.proposers.bend_exemplars=all",
        "sample.filters={}",
        "encode.sampling_resolution=64",
        "encode.coarsest_resolution=8",
        "encode.finest_resolution=32",
        "transfer.from_resolution=16",
    ]);
    let one = shapeshifter::learn::sample::untrained_models(&transfer, 1, Device::Cpu, 3).unwrap();
    let v = shapeshifter::pipeline::sample_variants(&one, &levels, &SampleOptions::from_config(&transfer, 1, 5), None).unwrap();
    let bend = v[0].bend.expect("bent");
    let iou = |a: &Level, b: &Level| {
        let (a, b) = (set(a), set(b));
        a.intersection(&b).count() as f64 / a.union(&b).count() as f64
    };
    let finest = &v[0].levels[2];
    let (to_bent, to_exemplar) = (iou(finest, &bend.bent(&levels, 2)), iou(finest, &levels[2]));
    assert!(to_bent > 0.8 && to_bent > to_exemplar + 0.1, "finest level: IoU {to_bent:.3} with the bent exemplar, {to_exemplar:.3} with the exemplar");
}

/// Weights whose recorded parameterisation is not this program's (or was
/// never recorded) are refused with one line naming the state file.
#[test]
fn weights_of_another_parameterisation_are_refused() {
    let _guard = serial();
    let config = tiny(&["train.level0_iterations=5", "train.upper_iterations=5", "train.upsampler_iterations=5"]);
    let dir = tempfile::tempdir().unwrap();
    trained(dir.path(), &config);
    assert!(load_models(dir.path(), &config, 2, Device::Cpu).is_ok());
    let path = state_path(dir.path(), 1);
    let mut state = read_state(dir.path(), 1);
    assert_eq!(state.parameterisation, shapeshifter::learn::schedule::TRAINING_PARAMETERISATION);
    state.parameterisation.clear();
    std::fs::write(&path, serde_json::to_string(&state).unwrap()).unwrap();
    let e = load_models(dir.path(), &config, 2, Device::Cpu).err().expect("refused").to_string();
    assert!(e.contains("level_1_state.json") && e.contains("earlier parameterisation") && e.contains("train it again"), "{e}");
}

/// Training noise and dropout masks come from the step's own seeds:
/// libtorch's global generator (what initialisation draws from) does not
/// change them.
#[test]
fn training_noise_ignores_the_global_generator() {
    use shapeshifter::learn::train::{diffusion_step, optim::Adam, StepSeeds, TrainingData};
    let _guard = serial();
    let config = tiny(&["model.dropout=0.2"]);
    let levels = exemplar();
    let loss = |global: i64| {
        tch::manual_seed(5);
        let net = new_diffusion(&config.model, 0, Device::Cpu).unwrap();
        let mut opt = Adam::new(&net.vs, false);
        let mut batch = TrainingData::new(&levels, 0, Device::Cpu).unwrap().diffusion_batches(&config.train).unwrap();
        let (x0, t) = batch(&mut shapeshifter::util::rng::Rng::new(1)).unwrap();
        tch::manual_seed(global);
        diffusion_step(&net.net, &mut opt, 1e-3, &x0, &Tensor::from_slice(&t), 1.0, StepSeeds { noise: 42, dropout: 42 }, false).unwrap()
    };
    assert_eq!(loss(1), loss(2));
}

/// With detail transfer from 16^3, a model trained at level 0 only gives
/// variants through 32^3: level 0 from the network, levels 1 and 2 copied
/// from the exemplar (its colours exactly), each inside its coarse level;
/// reproducible per variant and shard, and `--from` a level continues it.
#[test]
fn sampling_with_detail_transfer() {
    use shapeshifter::pipeline::{models_needed, sample_variants};
    let _guard = serial();
    let config = tiny(&[
        "train.level0_iterations=40",
        "encode.sampling_resolution=64",
        "encode.coarsest_resolution=8",
        "encode.finest_resolution=32",
        "transfer.from_resolution=16",
    ]);
    let levels = sphere_levels(&[8, 16, 32], DVec3::new(0.05, -0.1, 0.0), 0.55);
    assert_eq!(shapeshifter::pipeline::trained_levels(&config, &levels), 1);
    let dir = tempfile::tempdir().unwrap();
    train_level(&TrainJob::new(&levels, 0, &config, Device::Cpu, dir.path())).unwrap();
    assert_eq!(models_needed(&config, &levels, None), 1);
    let models = load_models(dir.path(), &config, 1, Device::Cpu).unwrap();
    let opts = SampleOptions::from_config(&config, 3, 5);
    let levels_of = |v: Vec<shapeshifter::learn::sample::SampledVariant>| v.into_iter().map(|s| s.levels).collect::<Vec<_>>();
    let a = levels_of(sample_variants(&models, &levels, &opts, None).unwrap());
    let exemplar_colours: Vec<std::collections::HashSet<[u32; 3]>> =
        levels.iter().map(|l| l.colours.iter().map(|c| c.to_array().map(f32::to_bits)).collect()).collect();
    for v in &a {
        assert_eq!(v.iter().map(|l| (l.index, l.resolution)).collect::<Vec<_>>(), vec![(0, 8), (1, 16), (2, 32)]);
        assert!(!v[2].is_empty(), "transfer produced nothing");
        for l in 1..3 {
            let parents: std::collections::HashSet<IVec3> = v[l - 1].coords.iter().cloned().collect();
            assert!(v[l].coords.iter().all(|c| parents.contains(&c.div_euclid(IVec3::splat(2)))), "level {l} leaves its coarse level");
            assert!(v[l].colours.iter().all(|c| exemplar_colours[l].contains(&c.to_array().map(f32::to_bits))), "level {l}: a colour the exemplar does not have");
            assert_eq!(v[l].frame, levels[0].frame);
        }
    }
    let b = levels_of(sample_variants(&models, &levels, &opts, None).unwrap());
    assert!(same(&a, &b), "same seed, different output");
    let shard = levels_of(sample_variants(&models, &levels, &SampleOptions { first: 1, n: 2, ..opts.clone() }, None).unwrap());
    assert!(same(&shard, &a[1..3]), "a shard differs");
    // Stopping at level 1, and continuing from it, reproduce the same levels.
    let stop = levels_of(sample_variants(&models, &levels, &SampleOptions { stop_level: Some(1), ..opts.clone() }, None).unwrap());
    assert!(same(&stop, &a.iter().map(|v| v[..2].to_vec()).collect::<Vec<_>>()));
    let one = SampleOptions { first: 1, n: 1, ..opts.clone() };
    let cont = levels_of(sample_variants(&models, &levels, &one, Some(a[1][0].clone())).unwrap());
    assert_eq!(cont[0].len(), 2, "levels 1 and 2 from level 0");
    // Nothing finer than the exemplar's last level.
    assert!(sample_variants(&models, &levels, &SampleOptions { stop_level: Some(3), ..opts.clone() }, None).is_err(), "level 3 sampled");
    // Without transfer, the missing networks are an error, not a silent stop.
    let off = tiny(&["train.level0_iterations=40", "transfer.from_resolution=0"]);
    let models_off = load_models(dir.path(), &off, 1, Device::Cpu).unwrap();
    match sample_variants(&models_off, &levels, &opts, None) {
        Ok(_) => panic!("sampled three levels with one network and no transfer"),
        Err(e) => assert!(e.to_string().contains("needs its trained network"), "{e}"),
    }
}
