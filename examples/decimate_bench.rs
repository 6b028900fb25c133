//! Fidelity against size of light meshes: a level's full mesh decimated to
//! several triangle budgets, each compared with the exemplar by Chamfer and
//! Hausdorff distance (both surfaces sampled uniformly by area, as in
//! mesh_fidelity), in voxels of the level, with the decimation time (wall, and
//! CPU of this process: the decimater is sequential, so CPU time is what an
//! idle machine would take) and the sizes of the binary PLY and .glb files.
//! Prints a Markdown table.
//!
//! Usage: decimate_bench EXEMPLAR LEVEL.vdb FULL_MESH.ply OUT_DIR [BUDGET ...]
//! (budgets default to 200000 100000 50000 20000; the meshes are kept in OUT_DIR)

use std::path::{Path, PathBuf};

use shapeshifter::io::mesh::{self, DecimateOptions};
use shapeshifter::{eval::metrics, io::vdb};

/// CPU seconds used by this process so far.
fn cpu_seconds() -> f64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        anyhow::bail!("usage: decimate_bench EXEMPLAR LEVEL.vdb FULL_MESH.ply OUT_DIR [BUDGET ...]");
    }
    let (exemplar, level, full, out) = (&args[0], &args[1], &args[2], &args[3]);
    let budgets: Vec<usize> = if args.len() > 4 {
        args[4..].iter().map(|s| s.parse()).collect::<Result<_, _>>()?
    } else {
        vec![200_000, 100_000, 50_000, 20_000]
    };
    let out = PathBuf::from(out);
    std::fs::create_dir_all(&out)?;
    let exemplar = mesh::load(Path::new(exemplar))?;
    let (level, _) = vdb::read_level(Path::new(level))?;
    // One voxel of the level in the exemplar's units.
    let voxel = (level.voxel_size() / level.frame.scale) as f32;
    let full = mesh::load(Path::new(full))?;
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
