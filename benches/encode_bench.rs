//! Encodes a mesh (default: the ruined tower of ../shared/data, or the embedded
//! demo exemplar where that is absent) several times at the paper's settings
//! and prints the median time of every stage and the voxel counts.
//!
//! Usage: encode_bench [--mesh MESH.obj] [--runs N] [--pooling qem|average]

use std::path::{Path, PathBuf};

use clap::Parser;
use shapeshifter::encode::{encode, EncodeOptions, EncodeStats, Pooling};
use shapeshifter::io::mesh;

/// Encodes a mesh several times at the paper's settings; prints the median
/// time of every stage and the voxel counts.
#[derive(Parser, Debug)]
struct Args {
    /// The mesh to encode (default: ../shared/data/towerruins/towerruins.obj,
    /// or the embedded demo exemplar where that is absent).
    #[arg(long, value_name = "PATH")]
    mesh: Option<PathBuf>,
    /// Encodings to take the medians of.
    #[arg(long, value_name = "N", default_value_t = 5)]
    runs: usize,
    /// How children pool into parents.
    #[arg(long, value_enum, default_value_t = Pooling::Qem)]
    pooling: Pooling,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).map(|l| l.to_string()))
        .and_then(|l| l.split_whitespace().nth(1).and_then(|kb| kb.parse::<f64>().ok()))
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// User + system CPU seconds of this process so far (Linux), to read the timings
/// against when other jobs share the cores.
fn cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .map(|s| {
            let after = &s[s.rfind(')').unwrap_or(0) + 2..];
            after.split_whitespace().skip(11).take(2).filter_map(|x| x.parse::<f64>().ok()).sum::<f64>()
                / 100.0
        })
        .unwrap_or(f64::NAN)
}

fn main() {
    let args = Args::parse();
    let default = Path::new("../shared/data/towerruins/towerruins.obj");
    let path = args.mesh.as_deref().unwrap_or(default);
    let runs = args.runs;
    let pooling = args.pooling;
    let mesh = match mesh::load(path) {
        Ok(m) => m,
        Err(_) if args.mesh.is_none() && !default.exists() => {
            println!("{} absent: the embedded demo exemplar instead", default.display());
            shapeshifter::encode::exemplar::ruined_tower(&Default::default())
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    println!(
        "{}: {} vertices, {} triangles, {} threads, {pooling:?}",
        mesh.name,
        mesh.positions.len(),
        mesh.triangles.len(),
        rayon::current_num_threads()
    );
    let options = EncodeOptions { pooling, ..Default::default() };
    let mut all: Vec<EncodeStats> = Vec::new();
    let cpu_start = cpu_seconds();
    for _ in 0..runs {
        let (levels, stats) = encode(&mesh, &options).expect("encode");
        assert_eq!(levels.len(), 5);
        all.push(stats);
    }
    let cpu_per_run = (cpu_seconds() - cpu_start) / runs as f64;
    let m = |f: fn(&EncodeStats) -> f64| median(all.iter().map(f).collect());
    println!("median of {runs} runs (s):");
    println!("  normalise {:.3}", m(|s| s.normalise_s));
    println!("  voxelise  {:.3}", m(|s| s.voxelise_s));
    println!("  sort      {:.3}", m(|s| s.sort_s));
    println!("  sample    {:.3}", m(|s| s.sample_s));
    println!("  pool      {:.3}", m(|s| s.pool_s));
    println!("  output    {:.3}", m(|s| s.output_s));
    println!("  total     {:.3}   (CPU {cpu_per_run:.2} s per run, mean)", m(|s| s.total_s));
    let s = &all[0];
    println!("triangle/voxel pairs {}, sampling voxels {}", s.triangle_voxel_pairs, s.sampling_voxels);
    for (r, n) in &s.voxels_per_resolution {
        println!("  {r:5}: {n}");
    }
    println!("peak RSS {:.0} MiB", peak_rss_mib());
}
