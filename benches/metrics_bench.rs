//! Timings of the evaluation building blocks (docs/method.md section 7):
//! voxelisation at 256 of a ~20k-triangle procedural mesh, the exemplar's patch
//! dictionary, and LP-IoU/LP-F-score with 1000 patches. Median of 3 runs each.
//!
//! cargo run --release --example metrics_bench [-- --resolution N]

use std::time::Instant;

use clap::Parser;
use glam::Vec3;
use shapeshifter::level::Frame;
use shapeshifter::io::mesh::Mesh;
use shapeshifter::eval::metrics::*;
use shapeshifter::util::rng::Rng;

/// Times voxelisation, the patch dictionary, LP scores, IoU and Chamfer on
/// procedural bumpy spheres.
#[derive(Parser, Debug)]
struct Args {
    /// Evaluation lattice: voxels along the longest side of the exemplar.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_RESOLUTION)]
    resolution: u32,
}

/// A closed bumpy sphere: UV sphere with `rings` x `segs` quads, radius
/// modulated by a few sines (phase `phase`), about 2 * rings * segs triangles.
fn bumpy_sphere(rings: u32, segs: u32, phase: f32) -> Mesh {
    let radius = |th: f32, ph: f32| {
        1.0 + 0.08 * (5.0 * ph + phase).sin() * (4.0 * th).sin()
            + 0.04 * (11.0 * ph - 2.0 * phase).cos() * (9.0 * th).sin()
    };
    shapeshifter::testing::shapes::uv_sphere(Vec3::ZERO, rings, segs, radius)
}

fn frame_of(mesh: &Mesh) -> Frame {
    let (lo, hi) = mesh.bounds();
    Frame { centre: ((lo + hi) * 0.5).as_dvec3(), scale: 2.0 / (hi - lo).as_dvec3().length(), ..Default::default() }
}

/// CPU time of this process (user + system, all threads), seconds (Linux).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<f64> = after.split_whitespace().map(|v| v.parse().unwrap_or(0.0)).collect();
    // Fields 14 and 15 of the file (utime, stime) in clock ticks of 1/100 s.
    if f.len() > 13 {
        (f[11] + f[12]) / 100.0
    } else {
        f64::NAN
    }
}

/// Median wall time of 3 runs and the CPU seconds of that run.
fn median3<T>(mut f: impl FnMut() -> T) -> ((f64, f64), T) {
    let mut times = Vec::new();
    let mut out = None;
    for _ in 0..3 {
        let (t, c) = (Instant::now(), cpu_seconds());
        out = Some(f());
        times.push((t.elapsed().as_secs_f64(), cpu_seconds() - c));
    }
    times.sort_by(|a, b| a.0.total_cmp(&b.0));
    (times[1], out.unwrap())
}

fn main() {
    let res = Args::parse().resolution;
    println!("threads: {}", rayon::current_num_threads());
    let exemplar = bumpy_sphere(100, 100, 0.0);
    let variant = bumpy_sphere(100, 100, 1.3);
    let frame = frame_of(&exemplar);
    let grid = OccupancyGrid::for_exemplar(&exemplar, frame, res);
    println!("mesh: {} triangles; lattice {:?}", exemplar.triangles.len(), grid.dims);

    let (t_vox, ex) = median3(|| voxelise_mesh(&exemplar, &grid));
    println!(
        "voxelise_mesh: {:.3} s wall (median of 3), {:.2} s CPU; {} occupied voxels",
        t_vox.0,
        t_vox.1,
        ex.count()
    );
    let var = voxelise_mesh(&variant, &grid);
    println!("surface voxels: exemplar {}, variant {}", ex.surface().count(), var.surface().count());

    let params = LpParams::default();
    let (t_dict, dict) = median3(|| ExemplarPatches::new(&ex, params.exemplar_stride));
    println!(
        "exemplar patches: {:.3} s wall, {:.2} s CPU; {} centres, {} distinct",
        t_dict.0,
        t_dict.1,
        dict.centres,
        dict.len()
    );
    let (t_lp, s) = median3(|| local_patch_scores(&var, &dict, &params));
    println!(
        "LP scores ({} patches vs {} exemplar patches): {:.3} s wall, {:.2} s CPU; LP-IoU {:.4} (>0.95: {:.3}), LP-F {:.4} (>0.95: {:.3})",
        s.patches, dict.len(), t_lp.0, t_lp.1, s.lp_iou, s.lp_iou_above, s.lp_fscore, s.lp_fscore_above
    );
    // Harder cases for the pruning: a damaged variant (10% of its surface voxels
    // removed) and random voxels (30% density) in the exemplar's box.
    let mut rough = var.clone();
    let mut rng = Rng::new(12345);
    let w = rough.words_per_row();
    for v in var.surface().voxels() {
        if rng.below(10) == 0 {
            let r = v[1] as usize + rough.dims[1] as usize * v[2] as usize;
            rough.bits[r * w + v[0] as usize / 64] &= !(1u64 << (v[0] % 64));
        }
    }
    let (t_rough, sr) = median3(|| local_patch_scores(&rough, &dict, &params));
    println!(
        "LP damaged variant: {:.3} s wall, {:.2} s CPU; LP-IoU {:.4} (>0.95: {:.3}), LP-F {:.4} (>0.95: {:.3})",
        t_rough.0, t_rough.1, sr.lp_iou, sr.lp_iou_above, sr.lp_fscore, sr.lp_fscore_above
    );
    let mut noise = Occupancy::empty(grid.dims);
    let [nx, ny, nz] = grid.dims.map(|d| d as i64);
    for z in nz / 6..nz * 5 / 6 {
        for y in ny / 6..ny * 5 / 6 {
            for x in nx / 6..nx * 5 / 6 {
                if rng.below(10) < 3 {
                    noise.set(x, y, z);
                }
            }
        }
    }
    let (t_noise, sn) = median3(|| local_patch_scores(&noise, &dict, &params));
    println!(
        "LP random voxels: {:.3} s wall, {:.2} s CPU; LP-IoU {:.4} (>0.95: {:.3}), LP-F {:.4} (>0.95: {:.3})",
        t_noise.0, t_noise.1, sn.lp_iou, sn.lp_iou_above, sn.lp_fscore, sn.lp_fscore_above
    );
    let p2 = LpParams { exemplar_stride: 2, ..params.clone() };
    let d2 = ExemplarPatches::new(&ex, 2);
    let (t2, s2) = median3(|| local_patch_scores(&var, &d2, &p2));
    println!(
        "exemplar stride 2 ({} patches): {:.3} s wall; LP-IoU {:.4} (>0.95: {:.3}), LP-F {:.4} (>0.95: {:.3})",
        d2.len(),
        t2.0,
        s2.lp_iou,
        s2.lp_iou_above,
        s2.lp_fscore,
        s2.lp_fscore_above
    );
    let (t_self, own) = median3(|| local_patch_scores(&ex, &dict, &params));
    println!("LP self: {:.3} s wall; LP-IoU {:.4}, LP-F {:.4}", t_self.0, own.lp_iou, own.lp_fscore);
    let (t_iou, i) = median3(|| iou(&ex, &var));
    println!(
        "IoU(exemplar, variant) = {:.4} in {:.4} s; diversity {:.4}",
        i,
        t_iou.0,
        diversity(&[ex.clone(), var.clone()])
    );

    let pa: Vec<Vec3> = exemplar.positions.clone();
    let pb: Vec<Vec3> = variant.positions.clone();
    let (t_cd, cd) = median3(|| chamfer(&pa, &pb));
    println!(
        "chamfer of {} vs {} points: {:.5} in {:.4} s; hausdorff {:.5}",
        pa.len(),
        pb.len(),
        cd,
        t_cd.0,
        hausdorff(&pa, &pb)
    );
}
