//! The structure of variants at every coarse level against the exemplar's
//! (shapeshifter::level::structure): the figures the level-0 rejection and
//! the eval flags are thresholded on, one row per variant and level, to tune
//! them against what the contact sheet shows.
//!
//! cargo run --release --example structure_probe -- RUN/exemplar RUN/variants/*

use std::path::PathBuf;

use clap::Parser;
use shapeshifter::judge::sheet as height_field;
use shapeshifter::level::sheet::{enclosed_columns, step_cracks};
use glam::Vec3;
use shapeshifter::judge::{structure_level, unlike_voxels, Matching, Structure, Thresholds, Verdict, STRUCTURE_RESOLUTION};

/// Prints mass and extent ratios, pieces, loose pieces (`loose`: how many
/// pieces are under the flags' piece share, and their share of the voxels:
/// the specks `sample.remove_specks` removes), free-boundary shares, enclosure and
/// thin-part ratios, copy F-score, the exemplar's largest region the variant
/// lacks and the voxels it has where the exemplar has none (`gone`, `added`:
/// a part lost with nothing in its place is gone > 0, added 0), where the
/// exemplar is a sheet its holes and cracks at steps (`holes`, `cracks`;
/// the exemplar's single-run shares per level and its sheet axis first), the
/// share of the surface like no part of the exemplar (`unlike`, from 32^3),
/// score and flags per variant and level (16^3 .. 64^3).
#[derive(Parser, Debug)]
struct Args {
    /// An encoded exemplar folder (manifest.json and level files).
    exemplar: PathBuf,
    /// Variant folders (level_K.vdb files).
    variants: Vec<PathBuf>,
    /// Probe levels up to this resolution (the flags use 64^3; 128 shows
    /// what the finer networks tore, e.g. a thin part shredded into flakes).
    #[arg(long, default_value_t = STRUCTURE_RESOLUTION)]
    max_resolution: u32,
    /// Write each variant's structure level (64^3, or the finest coarser one
    /// the exemplar has) here (DIR/<variant>/level_K.vdb),
    /// its voxels like no part of the exemplar red and the rest grey, for
    /// `shapeshifter render`.
    #[arg(long)]
    unlike_map: Option<PathBuf>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let (_, levels) = shapeshifter::io::dataset::read(&args.exemplar)?;
    let params = Thresholds::default();
    // Where the exemplar is a sheet (decided at 64^3, as sampling decides),
    // its holes and cracks at steps at every level probed.
    let sheet = structure_level(&levels).and_then(height_field::sheet_axis);
    // The exemplar's single-run shares per level (x, y, z): a sheet is 0.95 or
    // more along one axis at its structure level.
    for l in levels.iter().filter(|l| l.resolution <= args.max_resolution) {
        let [x, y, z] = height_field::single_run_shares(l);
        println!("exemplar {:>4}^3: columns of one run along x {x:.2}, y {y:.2}, z {z:.2}", l.resolution);
    }
    println!("exemplar sheet axis (decided at the structure level): {}", sheet.map_or("none".into(), |a| ["x", "y", "z"][a].to_string()));
    println!("{:<14} {:>4} {:>6} {:>6} {:>6} {:>13} {:>9} {:>11} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6}  flags", "variant", "res", "mass", "extent", "pieces", "loose", "fb", "exemplar fb", "encl", "thin", "copyF", "gone", "added", "holes", "cracks", "unlike", "score");
    for dir in &args.variants {
        let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        for ex in levels.iter().filter(|l| l.resolution <= args.max_resolution) {
            let path = dir.join(format!("level_{}.vdb", ex.index));
            let Ok((v, provenance)) = shapeshifter::io::vdb::read_level(&path) else {
                println!("{name:<14} {:>4} missing", ex.resolution);
                continue;
            };
            if let (Some(map_dir), true) = (&args.unlike_map, structure_level(&levels).is_some_and(|s| s.index == ex.index)) {
                let unlike = unlike_voxels(&v, ex);
                let mut painted = v.clone();
                for (c, &u) in painted.colours.iter_mut().zip(&unlike) {
                    *c = if u { Vec3::new(0.9, 0.1, 0.1) } else { Vec3::splat(0.7) };
                }
                let out = map_dir.join(&name);
                std::fs::create_dir_all(&out)?;
                shapeshifter::io::vdb::write_level(&out.join(format!("level_{}.vdb", ex.index)), &painted, &provenance, Default::default())?;
            }
            let (vs, es) = (Structure::of(&v), Structure::of(ex));
            let s = Verdict::new(&v, &vs, ex, &es, &params);
            let (gone, added) = Matching::of(&v, ex).gone_and_added();
            if std::env::var("PROBE_RAW").is_ok() { eprintln!("raw enclosure {} vs {}", vs.enclosure, es.enclosure); }
            let (holes, cracks) = match sheet {
                Some(a) => (enclosed_columns(&v, a).len().to_string(), step_cracks(&v, a).to_string()),
                None => ("-".into(), "-".into()),
            };
            let loose = vs.components.len() - vs.pieces();
            // Components are sorted largest first: the pieces, then the loose ones.
            let loose_share = vs.components[vs.pieces()..].iter().sum::<usize>() as f64 / vs.voxels.max(1) as f64;
            println!(
                "{name:<14} {:>4} {:>6.3} {:>6.3} {:>3}/{:<2} {:>5} {:>7.4} {:>9.3} {:>11.3} {:>6.3} {:>6.3} {:>6.3} {:>6} {:>6} {:>6} {:>6} {:>6.3} {:>6.3}  {}",
                ex.resolution,
                s.mass_ratio,
                s.extent_ratio,
                s.pieces,
                s.exemplar_pieces,
                loose,
                loose_share,
                s.free_boundary,
                s.exemplar_free_boundary,
                s.enclosure_ratio,
                s.thin_ratio,
                s.copy_fscore,
                gone,
                added,
                holes,
                cracks,
                s.unlike_share,
                s.score,
                s.flags.iter().map(|f| f.name()).collect::<Vec<_>>().join(",")
            );
        }
    }
    Ok(())
}
