//! Fidelity against size of light meshes: a level's full mesh decimated to
//! several triangle budgets, each compared with the exemplar by Chamfer and
//! Hausdorff distance (both surfaces sampled uniformly by area, as in
//! mesh_fidelity), in voxels of the level, with the decimation time (wall, and
//! CPU of this process: the decimater is sequential, so CPU time is what an
//! idle machine would take) and the sizes of the binary PLY and .glb files.
//! Prints a Markdown table.
//!
//! Usage: decimate_bench --mesh EXEMPLAR --level LEVEL.vdb --full-mesh FULL_MESH.ply
//!   --out OUT_DIR [--budget N ...]
//! (budgets default to 200000 100000 50000 20000; the meshes are kept in OUT_DIR)

use std::path::PathBuf;

use clap::Parser;
use shapeshifter::io::mesh::{self, DecimateOptions};
use shapeshifter::{eval::metrics, io::vdb};

/// CPU seconds used by this process so far.
fn cpu_seconds() -> f64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// Decimates a level's full mesh to triangle budgets and compares each with
/// the exemplar; prints a Markdown table.
#[derive(Parser, Debug)]
struct Args {
    /// The exemplar mesh the light meshes are compared with.
    #[arg(long, value_name = "PATH")]
    mesh: PathBuf,
    /// The level file the full mesh was made from (its voxel is the unit of
    /// the distances).
    #[arg(long, value_name = "PATH")]
    level: PathBuf,
    /// The level's full mesh, to be decimated.
    #[arg(long, value_name = "PATH")]
    full_mesh: PathBuf,
    /// Folder for the light meshes (PLY and .glb; created).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Triangle budgets (repeatable, or comma-separated).
    #[arg(long = "budget", value_name = "N", value_delimiter = ',', default_values_t = [200_000, 100_000, 50_000, 20_000])]
    budgets: Vec<usize>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let budgets = args.budgets;
    let out = args.out;
    std::fs::create_dir_all(&out)?;
    let exemplar = mesh::load(&args.mesh)?;
    let (level, _) = vdb::read_level(&args.level)?;
    // One voxel of the level in the exemplar's units.
    let voxel = (level.voxel_size() / level.frame.scale) as f32;
    let full = mesh::load(&args.full_mesh)?;
    let reference = exemplar.surface_samples(300_000);

    println!("| triangles | vertices | Chamfer (voxels) | Hausdorff (voxels) | decimation wall / CPU (s) | PLY (MB) | GLB (MB) |");
    println!("|---:|---:|---:|---:|---:|---:|---:|");
    for budget in std::iter::once(0).chain(budgets) {
        let (t, cpu) = (std::time::Instant::now(), cpu_seconds());
        let m = if budget == 0 { full.clone() } else { mesh::decimate(&full, &DecimateOptions::new(budget))?.0 };
        let (seconds, cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - cpu);
        let name = if budget == 0 { "full".to_string() } else { budget.to_string() };
        let mut sizes = Vec::new();
        for ext in ["ply", "glb"] {
            let p = out.join(format!("{}_{name}.{ext}", exemplar.name));
            mesh::save(&m, &p, true)?;
            sizes.push(std::fs::metadata(&p)?.len() as f64 / 1e6);
        }
        let samples = m.surface_samples(300_000);
        let chamfer = metrics::chamfer(&reference, &samples) / voxel;
        let hausdorff = metrics::hausdorff(&reference, &samples) / voxel;
        let time = if budget == 0 { "-".to_string() } else { format!("{seconds:.1} / {cpu:.1}") };
        println!(
            "| {} | {} | {chamfer:.3} | {hausdorff:.2} | {time} | {:.1} | {:.1} |",
            m.triangles.len(),
            m.positions.len(),
            sizes[0],
            sizes[1]
        );
    }
    Ok(())
}
