//! Sample new variants from a run's trained models, in memory, and write
//! each variant's finest level: what `shapeshifter sample` does, without its
//! folders and stamps.
//!
//! ```sh
//! shapeshifter run model.obj -o out/run          # encodes and trains (and samples)
//! cargo run --release --example sample_variants -- out/run 3 42 out/more
//! ```

use std::path::PathBuf;

use shapeshifter::config::Config;
use shapeshifter::io::vdb::{self, Provenance, WriteOptions};
use shapeshifter::learn::sample::{load_models, SampleOptions};
use shapeshifter::io::dataset;
use shapeshifter::pipeline::{models_needed, sample_variants, RunPaths};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [run, n, seed, out] = args.as_slice() else {
        anyhow::bail!("usage: sample_variants RUN_FOLDER N SEED OUT_DIR");
    };
    let paths = RunPaths::new(run.as_ref());
    let (manifest, levels) = dataset::read(&paths.exemplar())?;
    let config = Config::read(&paths.models().join("config.toml"))?;
    let models = load_models(&paths.models(), &config, models_needed(&config, &levels, None), tch::Device::Cpu)?;

    let options = SampleOptions::from_config(&config, n.parse()?, seed.parse()?);
    let variants = sample_variants(&models, &levels, &options, None)?;

    let out = PathBuf::from(out);
    std::fs::create_dir_all(&out)?;
    let provenance = Provenance { exemplar: manifest.exemplar.clone(), seed: Some(options.seed), ..Default::default() };
    for (i, variant) in variants.iter().enumerate() {
        // Levels coarsest first; a variant pruned to nothing has an empty finest level.
        let finest = variant.levels.last().filter(|l| !l.is_empty());
        match finest {
            Some(level) => {
                let path = out.join(format!("variant_{i:03}_level_{}.vdb", level.index));
                vdb::write_level(&path, level, &provenance, WriteOptions::default())?;
                println!("variant {i}: {} voxels at {}^3 -> {}", level.len(), level.resolution, path.display());
            }
            None => println!("variant {i}: pruned to nothing"),
        }
    }
    Ok(())
}
