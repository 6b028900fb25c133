//! Fidelity of encode -> mesh without learning: the exemplar is encoded, its
//! finest level meshed, and the mesh compared with the exemplar by Chamfer and
//! Hausdorff distance (both surfaces sampled uniformly by area), reported in
//! voxels of the finest level.
//!
//! Usage: mesh_fidelity MESH [poisson|apss|auto] [FINEST] [SAMPLING]
//!
//! Or, to score meshes made elsewhere (ours and Open3D's in
//! scripts/poisson-vs-open3d.sh) with the same code:
//!
//!   mesh_fidelity compare EXEMPLAR LEVEL.vdb CANDIDATE...
//!
//! prints one line per candidate: vertices, Chamfer and Hausdorff in voxels of
//! LEVEL (a level file of EXEMPLAR, whose frame the candidates share).

use shapeshifter::encode::{encode, EncodeOptions};
use shapeshifter::{io::mesh, eval::metrics, pipeline, recon};

/// `compare EXEMPLAR LEVEL CANDIDATE...`: Chamfer and Hausdorff of each candidate.
fn compare(args: &[String]) -> anyhow::Result<()> {
    let [exemplar, level, candidates @ ..] = args else {
        anyhow::bail!("usage: mesh_fidelity compare EXEMPLAR LEVEL.vdb CANDIDATE...");
    };
    anyhow::ensure!(!candidates.is_empty(), "compare: no candidate meshes");
    let exemplar = mesh::load(std::path::Path::new(exemplar))?;
    let (level, _) = shapeshifter::io::vdb::read_level(std::path::Path::new(level))?;
    // Exemplar units per voxel of the level.
    let voxel = (level.voxel_size() / level.frame.scale) as f32;
    let a = exemplar.surface_samples(300_000);
    for path in candidates {
        let m = mesh::load(std::path::Path::new(path))?;
        let b = m.surface_samples(300_000);
        let chamfer = metrics::chamfer(&a, &b) / voxel;
        let hausdorff = metrics::hausdorff(&a, &b) / voxel;
        println!(
            "{path}: {} vertices, {} triangles, Chamfer {chamfer:.3} voxels, Hausdorff {hausdorff:.2} voxels",
            m.positions.len(),
            m.triangles.len()
        );
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("compare") {
        return compare(&args[2..]);
    }
    let path = args.get(1).ok_or_else(|| anyhow::anyhow!("usage: mesh_fidelity MESH [method] [finest] [sampling]"))?;
    let method: Option<recon::Method> = match args.get(2).map(String::as_str) {
        None | Some("auto") => None,
        Some(m) => Some(<shapeshifter::recon::Method as clap::ValueEnum>::from_str(m, true).map_err(|e| anyhow::anyhow!(e))?),
    };
    let finest: u32 = args.get(3).map_or(Ok(256), |s| s.parse())?;
    let sampling: u32 = args.get(4).map_or(Ok(1024), |s| s.parse())?;
    let exemplar = mesh::load(std::path::Path::new(path))?;
    let options = EncodeOptions { finest_resolution: finest, sampling_resolution: sampling, ..Default::default() };
    let (levels, _) = encode(&exemplar, &options)?;
    let level = levels.last().expect("levels");
    let t = std::time::Instant::now();
    let (meshed, used) = pipeline::mesh_level(level, !exemplar.is_closed(), method, Some(2 * finest))?;
    let seconds = t.elapsed().as_secs_f64();
    let voxel = (level.voxel_size() / level.frame.scale) as f32;
    let a = exemplar.surface_samples(300_000);
    let b = meshed.surface_samples(300_000);
    let chamfer = metrics::chamfer(&a, &b) / voxel;
    let hausdorff = metrics::hausdorff(&a, &b) / voxel;
    println!(
        "{}: {used} at {}^3 -> {} vertices, {} boundary edges, {seconds:.1} s; Chamfer {chamfer:.3} voxels, Hausdorff {hausdorff:.2} voxels",
        exemplar.name, finest, meshed.positions.len(), meshed.edge_counts().0
    );
    Ok(())
}
