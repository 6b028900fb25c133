//! Whether encoded exemplars are figures, the reading that decides whether
//! sampling may bend them (`sample.bend_exemplars = "figures"`): the normal
//! spread and the upright share of each one's structure level (48^3 to 64^3), see
//! `shapeshifter::judge::figure`.
//!
//! `cargo run --release --example figure_reading -- ENCODED_DIR...` (folders
//! written by `shapeshifter encode`, e.g. `encode MESHES... --finest 64 -o DIR`
//! and then `DIR/*`)

use shapeshifter::judge::figure::FigureReading;
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(!dirs.is_empty(), "usage: figure_reading ENCODED_DIR...");
    println!("{:<40} {:>13} {:>14}  figure", "exemplar", "normal spread", "upright share");
    for d in &dirs {
        let levels: Vec<_> = (0..8)
            .map(|l| Path::new(d).join(format!("level_{l}.vdb")))
            .take_while(|p| p.exists())
            .map(|p| shapeshifter::io::vdb::read_level(&p).map(|x| x.0))
            .collect::<Result<_, _>>()?;
        let Some(r) = FigureReading::of_exemplar(&levels) else {
            println!("{d:<40} no level of 48^3 to 64^3 with surface voxels");
            continue;
        };
        let name = Path::new(d).file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| d.clone());
        println!("{name:<40} {:>13.2} {:>14.2}  {}", r.normal_spread, r.upright_share, if r.is_figure() { "yes" } else { "no" });
    }
    Ok(())
}
