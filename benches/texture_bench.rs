//! What a baked texture buys a light mesh: a level meshed as `run` meshes
//! it (Poisson or APSS at 256), decimated to each triangle budget, and
//! drawn both with its vertex colours and with a texture baked from the
//! level's points. Each is scored against the level's coloured points, on
//! points sampled uniformly by area on the mesh (the colour there: the
//! interpolated vertex colours, or the texel):
//! - error: mean absolute difference from the nearest level point's colour,
//!   8-bit sRGB (0 = the points' colours exactly);
//! - contrast: the standard deviation of the sampled colours over the
//!   points' own (1 = as varied as the points; blurring lowers it);
//! - edges: the mean colour step between samples one voxel apart, over the
//!   points' own (the stones' and mortar lines' sharpness).
//!
//! Writes, per budget, the two previews and close-ups from one camera
//! (`B_vertex.png`, `B_texture.png`, `B_vertex_closeup.png`, ...) and
//! prints a Markdown table.
//!
//! Usage: texture_bench LEVEL.vdb OUT_DIR [--budget N ...] [--texture 2048]

use std::path::PathBuf;

use clap::Parser;
use glam::{Vec2, Vec3};
use shapeshifter::io::mesh::Mesh;
use shapeshifter::io::vdb;
use shapeshifter::pipeline;
use shapeshifter::render::{self, RenderOptions, Zoom};

#[derive(Parser, Debug)]
struct Args {
    /// The level file the meshes are made from and scored against.
    level: PathBuf,
    /// Where the meshes' pictures go.
    out: PathBuf,
    #[arg(long = "budget", default_values_t = [20_000usize, 100_000])]
    budgets: Vec<usize>,
    /// Texture size, texels across.
    #[arg(long, default_value_t = 2048)]
    texture: u32,
    /// Surface samples per mesh.
    #[arg(long, default_value_t = 400_000)]
    samples: usize,
}

/// Area-uniform surface samples (position, colour) of a mesh; the same
/// seeds for every mesh. Not `Mesh::surface_samples`: that one gives every
/// triangle at least one sample (right for distances between surfaces),
/// which here would weigh sub-texel slivers far beyond the area a viewer
/// sees of them.
fn coloured_samples(mesh: &Mesh, n: usize) -> Vec<(Vec3, Vec3)> {
    let areas: Vec<f32> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .collect();
    let total: f32 = areas.iter().sum();
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    // Sample triangles in proportion to area by a running threshold.
    let mut out = Vec::with_capacity(n);
    let step = total / n as f32;
    let mut carry = rnd() * step;
    for (t, &area) in areas.iter().enumerate() {
        carry += area;
        while carry >= step {
            carry -= step;
            let (mut u, mut v) = (rnd(), rnd());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let w = Vec3::new(1.0 - u - v, u, v);
            let tri = mesh.triangles[t];
            let p = w.x * mesh.positions[tri[0] as usize] + w.y * mesh.positions[tri[1] as usize] + w.z * mesh.positions[tri[2] as usize];
            if let Some(c) = mesh.colour_at(t, w) {
                out.push((p, c));
            }
        }
    }
    out
}

struct Scores {
    error: f32,
    contrast: f32,
    edges: f32,
}

fn std_dev(c: &[Vec3]) -> f32 {
    let mean = c.iter().copied().sum::<Vec3>() / c.len() as f32;
    (c.iter().map(|x| (*x - mean).length_squared()).sum::<f32>() / c.len() as f32).sqrt()
}

/// Mean colour step between each point and its nearest neighbour at least
/// `min_dist` and at most `max_dist` away (one voxel), on a subset.
fn edge_strength(points: &[Vec3], colours: &[Vec3], min_dist: f32, max_dist: f32) -> f32 {
    let tree = kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(&points.iter().map(|p| p.to_array()).collect::<Vec<_>>());
    let (mut sum, mut n) = (0.0f32, 0usize);
    for i in (0..points.len()).step_by(7) {
        let near = tree.within_unsorted::<kiddo::SquaredEuclidean>(&points[i].to_array(), max_dist * max_dist);
        for nb in near.iter().filter(|nb| nb.distance >= min_dist * min_dist).take(4) {
            sum += (colours[i] - colours[nb.item as usize]).abs().element_sum() / 3.0;
            n += 1;
        }
    }
    sum / n.max(1) as f32
}

fn score(mesh: &Mesh, points: &shapeshifter::geom::points::OrientedPoints, n: usize, reference_edges: f32) -> Scores {
    let samples = coloured_samples(mesh, n);
    let tree = kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(&points.positions.iter().map(|p| p.to_array()).collect::<Vec<_>>());
    let error = samples
        .iter()
        .map(|(p, c)| {
            let near = tree.nearest_one::<kiddo::SquaredEuclidean>(&p.to_array());
            (*c - points.colours[near.item as usize]).abs().element_sum() / 3.0
        })
        .sum::<f32>()
        / samples.len() as f32;
    let colours: Vec<Vec3> = samples.iter().map(|s| s.1).collect();
    let positions: Vec<Vec3> = samples.iter().map(|s| s.0).collect();
    let h = points.spacing;
    Scores {
        error: 255.0 * error,
        contrast: std_dev(&colours) / std_dev(&points.colours),
        edges: edge_strength(&positions, &colours, 0.75 * h, 1.25 * h) / reference_edges,
    }
}

fn main() -> anyhow::Result<()> {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let args = Args::parse();
    std::fs::create_dir_all(&args.out)?;
    let (level, provenance) = vdb::read_level(&args.level)?;
    let points = pipeline::oriented_points(&level)?;
    let h = points.spacing;
    let reference_edges = edge_strength(&points.positions, &points.colours, 0.75 * h, 1.25 * h);
    let t = std::time::Instant::now();
    let (full, method) = pipeline::mesh_level(&level, provenance.exemplar_open, None, Some(256))?;
    println!("{}: {} points; {method:?} mesh at 256: {} triangles in {:.0} s", args.level.display(), points.len(), full.triangles.len(), t.elapsed().as_secs_f64());
    println!();
    println!("| triangles | colours | error (8-bit) | contrast | edges | unwrap + bake, s | files |");
    println!("|---|---|---|---|---|---|---|");
    let view = RenderOptions { up: Some(level.frame.up), ..render::preview_options() };
    let close = RenderOptions { zoom: Some(Zoom { centre: Vec2::new(0.5, 0.45), factor: 4.0 }), ..view.clone() };
    for &budget in &args.budgets {
        let light = pipeline::light_mesh(full.clone(), budget)?;
        let t = std::time::Instant::now();
        let textured = pipeline::bake_level_texture(&light, &level, args.texture)?;
        let seconds = t.elapsed().as_secs_f64();
        let ply = args.out.join(format!("{budget}.ply"));
        let obj = args.out.join(format!("{budget}.obj"));
        shapeshifter::io::mesh::save(&light, &ply, true)?;
        shapeshifter::io::mesh::save(&textured, &obj, true)?;
        for (name, m) in [("vertex", &light), ("texture", &textured)] {
            render::save_png(&render::render_mesh(m, &view)?, &args.out.join(format!("{budget}_{name}.png")))?;
            render::save_png(&render::render_mesh(m, &close)?, &args.out.join(format!("{budget}_{name}_closeup.png")))?;
            let s = score(m, &points, args.samples, reference_edges);
            let files = if name == "vertex" { format!("{}", ply.display()) } else { format!("{}", obj.display()) };
            let secs = if name == "vertex" { "-".to_string() } else { format!("{seconds:.1}") };
            println!("| {} | {name} | {:.1} | {:.2} | {:.2} | {secs} | {files} |", light.triangles.len(), s.error, s.contrast, s.edges);
        }
    }
    Ok(())
}
