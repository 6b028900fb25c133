//! Read a level file and use its voxels: surface points in the exemplar's
//! own units (metres for a scan), their normals and colours.
//!
//! ```sh
//! cargo run --release --example read_level -- out/run/variants/variant_000/level_4.vdb
//! ```

use shapeshifter::io::vdb;

fn main() -> anyhow::Result<()> {
    let Some(path) = std::env::args().nth(1) else {
        anyhow::bail!("usage: read_level LEVEL.vdb");
    };
    let (level, provenance) = vdb::read_level(path.as_ref())?;
    let grid = level.transform();
    println!(
        "{path}: level {} of '{}', {}^3 voxels of {:.4} world units, {} active",
        level.index,
        provenance.exemplar,
        level.resolution,
        grid.voxel_world(),
        level.len()
    );
    // Only voxels with mask > 0 hold surface.
    let surface: Vec<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).collect();
    let (mut lo, mut hi) = (glam::DVec3::splat(f64::INFINITY), glam::DVec3::splat(f64::NEG_INFINITY));
    let mut colour = glam::Vec3::ZERO;
    for &i in &surface {
        let p = level.point_world(i);
        (lo, hi) = (lo.min(p), hi.max(p));
        colour += level.colours[i];
    }
    if surface.is_empty() {
        println!("no surface voxels");
        return Ok(());
    }
    println!("surface points: {}, bounds {lo:.3} .. {hi:.3} (world units)", surface.len());
    println!("mean colour (linear RGB): {:.3}", colour / surface.len() as f32);
    let i = surface[0];
    println!("first: voxel {} at {:.3}, normal {:.3}", level.coords[i], level.point_world(i), level.normals[i]);
    Ok(())
}
