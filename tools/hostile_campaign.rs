//! Long mutation campaigns against the readers: the same harness as
//! `tests/hostile.rs` (tests/common/hostile.rs), with a count and a seed.
//!
//! ```sh
//! cargo build --release
//! cargo run --release --example hostile_campaign -- --count 2000 --seed 7
//! cargo run --release --example hostile_campaign -- --count 150 --seed 1 --no-builtin \
//!     --file ../shared/data/cgal/fandisk.obj --file out/tower/level_1.vdb
//! ```
//! Prints one table row per format and every contract breach; exits 1 if
//! there was any. `--help` lists the options.

#[path = "../tests/common/hostile.rs"]
mod hostile;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;

/// Mutates the seed inputs and runs the real binary on every mutation.
#[derive(Parser, Debug)]
struct Args {
    /// Mutated inputs per seed input.
    #[arg(long, value_name = "N", default_value_t = 500)]
    count: usize,
    /// Seed of the mutations.
    #[arg(long, value_name = "N", default_value_t = 1)]
    seed: u64,
    /// Children run at a time.
    #[arg(long, value_name = "N", default_value_t = 2)]
    threads: usize,
    /// Time limit of one run, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 60.0)]
    timeout: f64,
    /// The binary under test (default: target/release/shapeshifter of this
    /// checkout).
    #[arg(long, value_name = "PATH")]
    bin: Option<PathBuf>,
    /// Also mutate this file (repeatable).
    #[arg(long, value_name = "PATH")]
    file: Vec<PathBuf>,
    /// Skip the generated seed inputs (mutate only the --file ones).
    #[arg(long)]
    no_builtin: bool,
    /// Copy every input that broke the contract into this folder, with its
    /// siblings.
    #[arg(long, value_name = "DIR")]
    keep: Option<PathBuf>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let c = hostile::Campaign {
        bin: args.bin.unwrap_or_else(|| root.join("target/release/shapeshifter")),
        seed: args.seed,
        count: args.count,
        limit: Duration::from_secs_f64(args.timeout),
        threads: args.threads,
        keep_failures: args.keep,
    };
    let work = tempfile::tempdir()?;
    let mut seeds = if args.no_builtin { Vec::new() } else { hostile::builtin_seeds(work.path()) };
    for f in &args.file {
        seeds.push(hostile::file_seed(f)?);
    }
    let start = Instant::now();
    let stats = hostile::run_campaign(&c, &seeds, work.path());
    println!("binary {}, seed {}, {} mutations per input, {:.0} s", c.bin.display(), c.seed, c.count, start.elapsed().as_secs_f64());
    print!("{}", hostile::table(&stats));
    let failures: Vec<&String> = stats.values().flat_map(|s| &s.failures).collect();
    for f in &failures {
        println!("BROKEN {f}");
    }
    if failures.is_empty() {
        Ok(())
    } else {
        std::process::exit(1)
    }
}
