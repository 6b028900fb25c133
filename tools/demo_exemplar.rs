//! Writes the embedded demo exemplar (a ruined tower of coloured stones) as a
//! PLY and a preview PNG: `cargo run --release --example demo_exemplar -- --out OUT_DIR`.

use std::path::PathBuf;

use clap::Parser;
use shapeshifter::{encode::exemplar, io::mesh, render};

/// Writes the embedded demo exemplar as demo_tower.ply and demo_tower.png.
#[derive(Parser, Debug)]
struct Args {
    /// Output folder (created).
    #[arg(long, value_name = "DIR", default_value = "out/exemplar")]
    out: PathBuf,
}

fn main() -> anyhow::Result<()> {
    let dir = Args::parse().out;
    std::fs::create_dir_all(&dir)?;
    let m = exemplar::ruined_tower(&exemplar::TowerParams::default());
    mesh::save(&m, &dir.join("demo_tower.ply"), true)?;
    let img = render::render_mesh(&m, &render::RenderOptions::default())?;
    render::save_png(&img, &dir.join("demo_tower.png"))?;
    println!("{} triangles -> {}", m.triangles.len(), dir.display());
    Ok(())
}
