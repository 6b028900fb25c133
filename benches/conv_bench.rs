//! Sparse convolution throughput against a plain matmul of the same arithmetic.
//!
//! One SubmConv3d 3^3 layer (C -> C, bias) on the encoded ruined tower's 64^3 and
//! 128^3 levels, on the fullest 41^3 crop of its 128^3 level (a training crop) and on a
//! dense 41^3 box (the worst case: every neighbour present), 64 and 128 channels;
//! synthetic spherical shells of the same resolutions stand in where
//! ../shared/data/towerruins is absent. Forward (under `tch::no_grad`) and
//! forward + backward (input, weight and bias gradients), median of 7 runs, each
//! beside `[N*27, C] x [C, C]` matmuls measured in the same run:
//! ratio = matmul time / our time (1.0 = as fast as the bare GEMM; fwd+bwd is compared
//! with three matmuls: forward, input gradient, weight gradient).
//! Then kernel-map construction (k = 3, 5) on the tower's 256^3 level and on a
//! ~1.8M-voxel shell.
//!
//! `cargo run --release --example conv_bench [-- [--no-tune] [--quick] [--maps-only]
//!  [--mesh PATH] [--chunk-bytes N]]`
//! `--chunk-bytes` (env `SPARSE_CHUNK_BYTES`) overrides the CPU im2col block size.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use clap::Parser;
use glam::{IVec3, Vec3};
use shapeshifter::encode::{encode, EncodeOptions};
use shapeshifter::learn::grid::SparseGrid;
use shapeshifter::io::mesh;
use shapeshifter::learn::sparse::{set_cpu_chunk_bytes, SparseTensor, SubmConv3d};
use tch::{nn::VarStore, Device, Kind, Tensor};

fn shell(res: i32, radius: f32, thickness: f32) -> Vec<IVec3> {
    let c = Vec3::splat(res as f32 / 2.0);
    let mut v = Vec::new();
    for x in 0..res {
        for y in 0..res {
            for z in 0..res {
                let p = IVec3::new(x, y, z).as_vec3() + Vec3::splat(0.5);
                if ((p - c).length() - radius).abs() < thickness / 2.0 {
                    v.push(IVec3::new(x, y, z));
                }
            }
        }
    }
    v
}

/// The `size`^3 box (a training crop) around one of a sample of the voxels that holds
/// the most voxels.
fn fullest_crop(coords: &[IVec3], size: i32) -> Vec<IVec3> {
    let grid = SparseGrid::from_coords(512, coords).unwrap();
    let step = (coords.len() / 200).max(1);
    let best = (0..coords.len())
        .step_by(step)
        .map(|i| grid.crop(coords[i], 0, size).0)
        .max_by_key(|g| g.len())
        .unwrap();
    best.coords()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

/// Sparse convolution against a matmul of the same arithmetic, then
/// kernel-map construction.
#[derive(Parser, Debug)]
struct Args {
    /// Leave the allocator untuned.
    #[arg(long)]
    no_tune: bool,
    /// 3 timed runs per case instead of 7.
    #[arg(long)]
    quick: bool,
    /// Only the kernel maps, no convolutions.
    #[arg(long)]
    maps_only: bool,
    /// The mesh whose levels are measured (synthetic shells where absent).
    #[arg(long, value_name = "PATH", default_value = "../shared/data/towerruins/towerruins.obj")]
    mesh: PathBuf,
    /// CPU im2col block size, bytes (default: the library's).
    #[arg(long, value_name = "N", env = "SPARSE_CHUNK_BYTES")]
    chunk_bytes: Option<usize>,
}

fn main() {
    let args = Args::parse();
    if !args.no_tune {
        shapeshifter::util::alloc::tune_allocator();
    }
    if let Some(b) = args.chunk_bytes {
        set_cpu_chunk_bytes(b);
    }
    let quick = args.quick;
    let reps = if quick { 3 } else { 7 };
    tch::manual_seed(0);
    println!(
        "libtorch threads: {}, rayon threads: {}, malloc tuned: {}",
        tch::get_num_threads(),
        rayon::current_num_threads(),
        !args.no_tune
    );

    let maps_only = args.maps_only;
    let mesh_path = args.mesh.display();
    // The exemplar's own levels (paper settings: 1024 sampling, 16..256), coordinates only.
    let levels: Option<Vec<Vec<IVec3>>> = if args.mesh.exists() {
        let m = mesh::load(&args.mesh).expect("load the benchmark mesh");
        let (levels, _) = encode(&m, &EncodeOptions::default()).expect("encode");
        println!("{mesh_path}: levels {:?}", levels.iter().map(|l| (l.resolution, l.len())).collect::<Vec<_>>());
        Some(levels.into_iter().map(|l| l.coords).collect())
    } else {
        println!("{mesh_path} absent: synthetic shells of the same resolutions instead");
        None
    };
    let dense41 = || {
        let mut v = Vec::new();
        for x in 0..41 {
            for y in 0..41 {
                for z in 0..41 {
                    v.push(IVec3::new(x, y, z));
                }
            }
        }
        v
    };
    let cases: Vec<(String, Vec<IVec3>)> = match (&levels, maps_only) {
        (_, true) => vec![],
        (Some(levels), false) => vec![
            ("tower 64^3".into(), levels[2].clone()),
            ("tower 128^3".into(), levels[3].clone()),
            ("tower 41^3 crop".into(), fullest_crop(&levels[3], 41)),
            ("dense 41^3".into(), dense41()),
        ],
        (None, false) => vec![
            ("shell 64^3".into(), shell(64, 0.45 * 64.0, 2.0)),
            ("shell 128^3".into(), shell(128, 0.45 * 128.0, 2.0)),
            ("dense 41^3".into(), dense41()),
        ],
    };
    println!(
        "\n{:<12} {:>7} {:>4} | {:>9} {:>9} {:>6} | {:>9} {:>9} {:>6} | {:>8}",
        "grid", "N", "C", "fwd ms", "mm ms", "ratio", "fwd+bwd", "3 mm ms", "ratio", "GFLOP/s"
    );
    for (name, coords) in &cases {
        let grid = Arc::new(SparseGrid::from_coords(512, coords).unwrap());
        let n = grid.len() as i64;
        let t_map = Instant::now();
        let _ = grid.kernel_map(3).unwrap();
        let t_map = t_map.elapsed().as_secs_f64();
        for c in [64i64, 128] {
            let vs = VarStore::new(Device::Cpu);
            let conv = SubmConv3d::new(&vs.root(), c, c, 3, true).unwrap();
            let feats = Tensor::randn([n, c], (Kind::Float, Device::Cpu));
            let x = SparseTensor::new(grid.clone(), feats.shallow_clone()).unwrap();
            let a = Tensor::randn([n * 27, c], (Kind::Float, Device::Cpu));
            let b = Tensor::randn([c, c], (Kind::Float, Device::Cpu));
            let g = Tensor::randn([n * 27, c], (Kind::Float, Device::Cpu));
            let fx = feats.copy().set_requires_grad(true);
            let xg = SparseTensor::new(grid.clone(), fx.shallow_clone()).unwrap();
            let r = Tensor::randn([n, c], (Kind::Float, Device::Cpu));
            let bias = conv.bias.as_ref().unwrap();
            // The four measurements interleaved, so that the load of a shared machine
            // drifts over all of them alike; warm-up round first.
            let (mut t_mm, mut t_fwd, mut t_3mm, mut t_fb) = (vec![], vec![], vec![], vec![]);
            for rep in 0..=reps {
                let clock = Instant::now();
                tch::no_grad(|| {
                    let _ = a.mm(&b);
                });
                let d_mm = clock.elapsed().as_secs_f64();
                let clock = Instant::now();
                tch::no_grad(|| {
                    let _ = conv.forward(&x).unwrap();
                });
                let d_fwd = clock.elapsed().as_secs_f64();
                let clock = Instant::now();
                tch::no_grad(|| {
                    let _ = a.mm(&b);
                    let _ = g.mm(&b.tr());
                    let _ = a.tr().mm(&g);
                });
                let d_3mm = clock.elapsed().as_secs_f64();
                let clock = Instant::now();
                {
                    let y = conv.forward(&xg).unwrap();
                    let loss = (&y.feats * &r).sum(Kind::Float);
                    let grads = Tensor::run_backward(&[loss], &[&fx, &conv.weight, bias], false, false);
                    assert_eq!(grads.len(), 3);
                }
                let d_fb = clock.elapsed().as_secs_f64();
                if rep > 0 {
                    t_mm.push(d_mm);
                    t_fwd.push(d_fwd);
                    t_3mm.push(d_3mm);
                    t_fb.push(d_fb);
                }
            }
            let (t_mm, t_fwd, t_3mm, t_fb) = (median(t_mm), median(t_fwd), median(t_3mm), median(t_fb));
            let flops = 2.0 * (n * 27 * c * c) as f64;
            println!(
                "{:<15} {:>7} {:>4} | {:>9.2} {:>9.2} {:>6.2} | {:>9.2} {:>9.2} {:>6.2} | {:>8.1}",
                name,
                n,
                c,
                t_fwd * 1e3,
                t_mm * 1e3,
                t_mm / t_fwd,
                t_fb * 1e3,
                t_3mm * 1e3,
                t_3mm / t_fb,
                flops / t_fwd / 1e9
            );
        }
        println!("{:<15} kernel map k=3 (first use): {:.1} ms", "", t_map * 1e3);
    }

    // Kernel maps on the finest level the method uses (a fresh grid each time: no cache).
    if let Some(levels) = &levels {
        let finest = &levels[levels.len() - 1];
        println!("\nkernel maps on the tower's finest level ({} voxels):", finest.len());
        for k in [3usize, 5] {
            let mut tk = vec![];
            for _ in 0..5 {
                let g = SparseGrid::from_coords(512, finest).unwrap();
                let t = Instant::now();
                let m = g.kernel_map(k).unwrap();
                tk.push(t.elapsed().as_secs_f64());
                assert_eq!(m.rows(), g.len());
            }
            println!("  kernel map k={k} (median of 5): {:8.1} ms", median(tk) * 1e3);
        }
    }

    // Kernel maps on a ~1.8M-voxel shell.
    let big = shell(480, 0.45 * 480.0, 3.0);
    println!("\nkernel maps on a shell of {} voxels at 480^3:", big.len());
    let t = Instant::now();
    let base = SparseGrid::from_coords(512, &big).unwrap();
    println!("  grid from coords (sort):   {:8.1} ms", t.elapsed().as_secs_f64() * 1e3);
    for k in [3usize, 5] {
        // Interleaved with a plain fill of a fresh tensor of the same size (the memory
        // traffic and page faults any [N, k^3] int64 table costs on this machine).
        let (mut tk, mut tf) = (vec![], vec![]);
        for _ in 0..3 {
            let g = SparseGrid::from_coords(512, &big).unwrap(); // fresh cache
            let t = Instant::now();
            let m = g.kernel_map(k).unwrap();
            tk.push(t.elapsed().as_secs_f64());
            assert_eq!(m.rows(), g.len());
            drop(m);
            drop(g);
            let t = Instant::now();
            let f = Tensor::full([big.len() as i64, (k * k * k) as i64], -1, (Kind::Int64, Device::Cpu));
            tf.push(t.elapsed().as_secs_f64());
            drop(f);
        }
        println!(
            "  kernel map k={k} (median of 3): {:8.1} ms   (fill of a fresh {:.2} GB int64 tensor: {:.1} ms)",
            median(tk) * 1e3,
            (big.len() * k * k * k * 8) as f64 / 1e9,
            median(tf) * 1e3
        );
    }
    let t = Instant::now();
    let s = base.subdivide().unwrap();
    println!("  subdivision -> {} voxels:  {:8.1} ms", s.fine.len(), t.elapsed().as_secs_f64() * 1e3);
    let t = Instant::now();
    let d = base.dilate(1).unwrap();
    println!("  dilate(1) -> {} voxels:    {:8.1} ms", d.len(), t.elapsed().as_secs_f64() * 1e3);
}
