//! Long mutation campaigns against the readers: the same harness as
//! `tests/hostile.rs` (tests/common/hostile.rs), with a count and a seed.
//!
//! ```sh
//! cargo build --release
//! cargo run --release --example hostile_campaign -- count=2000 seed=7
//! cargo run --release --example hostile_campaign -- count=150 seed=1 \
//!     file=../shared/data/cgal/fandisk.obj file=out/tower/level_1.vdb builtin=0
//! ```
//! Arguments (`key=value`): `count` mutated inputs per seed input (default
//! 500), `seed` (default 1), `threads` (default 2), `timeout` seconds per run
//! (default 60), `bin` (default target/release/shapeshifter), `file=PATH` (also
//! mutate this file; repeatable), `builtin=0` (skip the generated inputs),
//! `keep=DIR` (copy every input that broke the contract there, with its
//! siblings). Prints one table row per format and every contract breach; exits
//! 1 if there was any.

#[path = "../tests/common/hostile.rs"]
mod hostile;

use std::path::PathBuf;
use std::time::{Duration, Instant};

fn main() -> anyhow::Result<()> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut c = hostile::Campaign {
        bin: root.join("target/release/shapeshifter"),
        seed: 1,
        count: 500,
        limit: Duration::from_secs(60),
        threads: 2,
        keep_failures: None,
    };
    let (mut files, mut builtin) = (Vec::new(), true);
    for a in std::env::args().skip(1) {
        let (k, v) = a.split_once('=').ok_or_else(|| anyhow::anyhow!("expected key=value, got {a}"))?;
        match k {
            "count" => c.count = v.parse()?,
            "seed" => c.seed = v.parse()?,
            "threads" => c.threads = v.parse()?,
            "timeout" => c.limit = Duration::from_secs_f64(v.parse()?),
            "bin" => c.bin = PathBuf::from(v),
            "file" => files.push(PathBuf::from(v)),
            "builtin" => builtin = v != "0",
            "keep" => c.keep_failures = Some(PathBuf::from(v)),
            _ => anyhow::bail!("unknown argument {k}"),
        }
    }
    let work = tempfile::tempdir()?;
    let mut seeds = if builtin { hostile::builtin_seeds(work.path()) } else { Vec::new() };
    for f in &files {
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
