//! Fidelity against size of light meshes: a level's full mesh decimated to
//! several triangle budgets, each compared with the exemplar by Chamfer and
//! Hausdorff distance (both surfaces sampled uniformly by area, as in
//! mesh_fidelity), in voxels of the level, with the decimation time and the
//! sizes of the binary PLY and .glb files. Prints a Markdown table.
//!
//! Usage: decimate_bench EXEMPLAR LEVEL.vdb FULL_MESH.ply OUT_DIR [BUDGET ...]
//! (budgets default to 200000 100000 50000 20000; the meshes are kept in OUT_DIR)

use std::path::{Path, PathBuf};

use shapeshifter::mesh::{self, DecimateOptions};
use shapeshifter::{metrics, vdb};

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

    println!("| triangles | vertices | Chamfer (voxels) | Hausdorff (voxels) | decimation (s) | PLY (MB) | GLB (MB) |");
    println!("|---:|---:|---:|---:|---:|---:|---:|");
    for budget in std::iter::once(0).chain(budgets) {
        let t = std::time::Instant::now();
        let m = if budget == 0 { full.clone() } else { mesh::decimate(&full, &DecimateOptions::new(budget))?.0 };
        let seconds = t.elapsed().as_secs_f64();
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
        let time = if budget == 0 { "-".to_string() } else { format!("{seconds:.1}") };
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
