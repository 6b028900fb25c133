//! Fidelity of encode -> mesh without learning: the exemplar is encoded, its
//! finest level meshed, and the mesh compared with the exemplar by Chamfer and
//! Hausdorff distance (both surfaces sampled uniformly by area), reported in
//! voxels of the finest level.
//!
//! Usage: mesh_fidelity [poisson|apss] --mesh MESH [--finest N] [--sampling N]
//!
//! Or, to score meshes made elsewhere (ours and Open3D's in
//! scripts/poisson-vs-open3d.sh) with the same code:
//!
//!   mesh_fidelity compare --mesh EXEMPLAR --level LEVEL.vdb CANDIDATE...
//!
//! prints one line per candidate: vertices, Chamfer and Hausdorff in voxels of
//! LEVEL (a level file of EXEMPLAR, whose frame the candidates share).

use std::path::{Path, PathBuf};

use clap::{Parser, Subcommand};
use shapeshifter::encode::{encode, EncodeOptions};
use shapeshifter::{io::mesh, eval::metrics, pipeline, recon};

/// Encodes a mesh, meshes its finest level and compares the result with the
/// mesh (or, with `compare`, scores meshes made elsewhere).
#[derive(Parser, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    /// Meshing method; none: the one `shapeshifter mesh` chooses.
    #[arg(value_enum)]
    method: Option<recon::Method>,
    /// The exemplar mesh.
    #[arg(long, value_name = "PATH", required = true)]
    mesh: Option<PathBuf>,
    /// Resolution of the finest level (the mesher's grid is twice this).
    #[arg(long, value_name = "N", default_value_t = 256)]
    finest: u32,
    /// Voxels per axis of the finest sampling grid of the encoder.
    #[arg(long, value_name = "N", default_value_t = 1024)]
    sampling: u32,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Chamfer and Hausdorff of each candidate mesh against the exemplar, in
    /// voxels of LEVEL (a level file of the exemplar, whose frame the
    /// candidates share).
    Compare {
        /// The exemplar mesh.
        #[arg(long, value_name = "PATH")]
        mesh: PathBuf,
        /// A level file of the exemplar (its voxel is the unit).
        #[arg(long, value_name = "PATH")]
        level: PathBuf,
        /// The meshes to score.
        #[arg(value_name = "CANDIDATE", required = true)]
        candidates: Vec<PathBuf>,
    },
}

/// `compare`: Chamfer and Hausdorff of each candidate.
fn compare(exemplar: &Path, level: &Path, candidates: &[PathBuf]) -> anyhow::Result<()> {
    anyhow::ensure!(!candidates.is_empty(), "compare: no candidate meshes");
    let exemplar = mesh::load(exemplar)?;
    let (level, _) = shapeshifter::io::vdb::read_level(level)?;
    // Exemplar units per voxel of the level.
    let voxel = (level.voxel_size() / level.frame.scale) as f32;
    let a = exemplar.surface_samples(300_000);
    for path in candidates {
        let m = mesh::load(path)?;
        let b = m.surface_samples(300_000);
        let chamfer = metrics::chamfer(&a, &b) / voxel;
        let hausdorff = metrics::hausdorff(&a, &b) / voxel;
        println!(
            "{}: {} vertices, {} triangles, Chamfer {chamfer:.3} voxels, Hausdorff {hausdorff:.2} voxels",
            path.display(),
            m.positions.len(),
            m.triangles.len()
        );
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    if let Some(Command::Compare { mesh, level, candidates }) = &args.command {
        return compare(mesh, level, candidates);
    }
    let path = args.mesh.as_deref().expect("--mesh is required");
    let method = args.method;
    let (finest, sampling) = (args.finest, args.sampling);
    let exemplar = mesh::load(path)?;
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
