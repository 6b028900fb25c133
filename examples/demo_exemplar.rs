//! Writes the embedded demo exemplar (a ruined tower of coloured stones) as a
//! PLY and a preview PNG: `cargo run --release --example demo_exemplar -- OUT_DIR`.

use std::path::PathBuf;

use shapeshifter::{encode::exemplar, io::mesh, render};

fn main() -> anyhow::Result<()> {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "out/exemplar".into()));
    std::fs::create_dir_all(&dir)?;
    let m = exemplar::ruined_tower(&exemplar::TowerParams::default());
    mesh::save(&m, &dir.join("demo_tower.ply"), true)?;
    let img = render::render_mesh(&m, &render::RenderOptions::default())?;
    render::save_png(&img, &dir.join("demo_tower.png"))?;
    println!("{} triangles -> {}", m.triangles.len(), dir.display());
    Ok(())
}
