//! Efficiency of a whole diffusion training step (forward, backward, Adam),
//! per level of the demo exemplar under a profile: the step's arithmetic (3 x
//! the forward convolutions' GEMM work, `DiffusionNet::flops_per_voxel`) per
//! second, as a fraction of a dense GEMM of the same shape measured in the
//! same run (`[rows, 27 C] x [27 C, C]`), and that GEMM in bf16 (the lever
//! AVX512-BF16 CPUs offer). Batches come from training's own `TrainingData`:
//! level 0 the flooded box `level0_batch` times, above `upper_batch`
//! crops of `crop`^3 around random active voxels.
//!
//! `cargo run --release --example train_step_bench [-- --profile cpu --steps 10 --threads 1 --set model.channels=64]`

use std::time::Instant;

use clap::Parser;
use shapeshifter::config::Config;
use shapeshifter::encode::{encode, exemplar};
use shapeshifter::learn::nn::new_diffusion;
use shapeshifter::learn::train::{diffusion_step, StepSeeds, TrainingData};
use shapeshifter::util::rng::Rng;
use tch::{Device, Kind, Tensor};

#[derive(Parser)]
struct Args {
    /// Profile (shipped name or TOML file).
    #[arg(long, default_value = "cpu")]
    profile: String,
    /// Overrides, as `run --set`.
    #[arg(long = "set")]
    overrides: Vec<String>,
    /// Timed steps per level (after 2 warm-up steps); the median is reported.
    #[arg(long, default_value_t = 10)]
    steps: usize,
    /// Cores: 1, or 2 for a step's two parts side by side (libtorch itself
    /// runs on one thread in training, as here).
    #[arg(long, default_value_t = 1)]
    threads: i32,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Seconds of one `[rows, k] x [k, c]` matmul of `kind`, median of 5.
fn gemm_seconds(rows: i64, k: i64, c: i64, kind: Kind) -> f64 {
    let a = Tensor::randn([rows, k], (kind, Device::Cpu));
    let b = Tensor::randn([k, c], (kind, Device::Cpu));
    let _ = a.mm(&b);
    median((0..5).map(|_| {
        let t = Instant::now();
        let _ = a.mm(&b);
        t.elapsed().as_secs_f64()
    }).collect())
}

fn main() -> anyhow::Result<()> {
    shapeshifter::util::alloc::tune_allocator();
    let args = Args::parse();
    // Training runs libtorch on one thread per core (train::diffusion_step).
    tch::set_num_threads(1);
    let config = Config::load(&args.profile, &args.overrides)?;
    let (levels, _) = encode(&exemplar::ruined_tower(&Default::default()), &shapeshifter::pipeline::encode_options(&config))?;
    let tc = &config.train;
    let _bf16 = shapeshifter::learn::sparse::bf16_compute_scope(tc.bf16);
    println!(
        "profile {}, {} channels, {}, {} libtorch thread(s), median of {} steps; GFLOP/s = 3 x forward GEMM work / step time",
        config.name, config.model.channels, if !tc.bf16 { "f32" } else if shapeshifter::learn::sparse::bf16_is_native(tch::Device::Cpu) { "bf16 GEMMs" } else { "bf16 GEMMs, emulated (no AVX512-BF16: training itself would use f32)" }, args.threads, args.steps
    );
    println!("level  res  rows/step  step s   GFLOP/s  GEMM GFLOP/s  fraction  bf16 GEMM GF/s");
    for (l, level) in levels.iter().enumerate() {
        let mut rng = Rng::new(7);
        // The batches training draws (shapeshifter::learn::train::TrainingData).
        let mut batch = TrainingData::new(&levels, l, Device::Cpu)?.diffusion_batches(tc)?;
        tch::manual_seed(1);
        let net = new_diffusion(&config.model, l, Device::Cpu)?;
        let mut opt = shapeshifter::learn::train::optim::Adam::new(&net.vs, false);
        let (mut seconds, mut rows) = (Vec::new(), Vec::new());
        for step in 0..args.steps + 2 {
            let (x0, t) = batch(&mut rng)?;
            let t = Tensor::from_slice(&t);
            let start = Instant::now();
            let seeds = StepSeeds { noise: step as u64, dropout: step as u64 };
            diffusion_step(&net.net, &mut opt, tc.lr, &x0, &t, tc.grad_clip, seeds, args.threads >= 2)?;
            if step >= 2 {
                seconds.push(start.elapsed().as_secs_f64());
                rows.push(x0.len() as f64);
            }
        }
        let (secs, n) = (median(seconds), median(rows));
        let gflops = 3.0 * net.net.flops_per_voxel() * n / secs / 1e9;
        let c = config.model.channels;
        let work = 2.0 * n * 27.0 * (c * c) as f64 / 1e9;
        let gemm_gflops = work / gemm_seconds(n as i64, 27 * c, c, Kind::Float);
        let bf16_gflops = work / gemm_seconds(n as i64, 27 * c, c, Kind::BFloat16);
        println!(
            "{l:>5} {:>4} {:>10.0} {secs:>7.3} {gflops:>9.1} {gemm_gflops:>13.1} {:>9.2} {bf16_gflops:>14.1}",
            level.resolution,
            n,
            gflops / gemm_gflops
        );
    }
    Ok(())
}
