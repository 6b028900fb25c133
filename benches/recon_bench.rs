//! Meshes a procedural shape sampled one point per voxel at 256^3 (like the
//! finest level of an encoded exemplar, ~150k points), or with `--mesh PATH`
//! the 256^3 level of that mesh as `encode` makes it (paper settings), with each
//! method and prints time and peak memory. Each method runs in its own child
//! process so that its peak RSS (VmHWM) is its own.
//!
//!   cargo run --release --example recon_bench [-- [METHOD] [OPTIONS]]
//!   cargo run --release --example recon_bench -- all --mesh ../shared/data/towerruins/towerruins.obj
//!   cargo run --release --example recon_bench -- poisson --level out/tower/level_4.vdb --out tower.ply
//!
//! `--level PATH` meshes the points of a level file (as `shapeshifter mesh`
//! does); `--out PATH` also writes the mesh (PLY with vertex colours, exemplar
//! frame). METHOD: all (default), poisson, apss. `--help` lists the options.

use std::path::PathBuf;

use clap::Parser;
use glam::Vec3;
use rayon::prelude::*;
use shapeshifter::recon::{apss, poisson_report, ApssOptions, OrientedPoints, PoissonOptions, ReconMesh};
use std::time::Instant;

/// Sphere and torus, smoothly united, with a small wave on top, filling most of [-1,1]^3.
pub fn sdf(p: Vec3) -> f32 {
    const S: f32 = 1.18;
    shape(p / S) * S
}

fn shape(p: Vec3) -> f32 {
    let sphere = p.length() - 0.62;
    let q = glam::Vec2::new(glam::Vec2::new(p.x, p.z).length() - 0.62, p.y);
    let torus = q.length() - 0.2;
    let k = 0.1;
    let h = (0.5 + 0.5 * (torus - sphere) / k).clamp(0.0, 1.0);
    let blend = torus + (sphere - torus) * h - k * h * (1.0 - h);
    blend + 0.015 * (9.0 * p.x).sin() * (9.0 * p.y).sin() * (9.0 * p.z).sin()
}

/// One point per voxel at `res`^3 over [-1, 1]^3, coloured by position.
pub fn sample(res: i32) -> OrientedPoints {
    let vs = 2.0 / res as f32;
    shapeshifter::testing::shapes::surface_points(sdf, Vec3::splat(-1.0), Vec3::ONE, vs, |p| p * 0.5 + 0.5)
}

/// User + system CPU seconds of this process.
pub fn cpu_seconds() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let rest = s.rsplit(')').next().unwrap_or("");
    let f: Vec<f64> = rest.split_whitespace().filter_map(|v| v.parse().ok()).collect();
    // after the command name: state(skipped, not numeric) ppid ... utime is field 14 overall
    if f.len() > 12 { (f[10] + f[11]) / 100.0 } else { f64::NAN }
}

pub fn peak_rss_mib() -> f64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    s.lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// Connected components (over shared edges), edges used by more than two
/// triangles, and the Euler characteristic V - E + F.
pub fn topology(m: &ReconMesh) -> (usize, usize, i64) {
    let mut edges: Vec<(u32, u32, u32)> = m
        .triangles
        .iter()
        .enumerate()
        .flat_map(|(t, v)| (0..3).map(move |i| (v[i].min(v[(i + 1) % 3]), v[i].max(v[(i + 1) % 3]), t as u32)))
        .collect();
    edges.par_sort_unstable();
    let mut parent: Vec<u32> = (0..m.triangles.len() as u32).collect();
    fn find(p: &mut [u32], mut a: u32) -> u32 {
        while p[a as usize] != a {
            p[a as usize] = p[p[a as usize] as usize];
            a = p[a as usize];
        }
        a
    }
    let (mut unique, mut non_manifold, mut i) = (0i64, 0, 0);
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 && edges[j].1 == edges[i].1 {
            let (a, b) = (find(&mut parent, edges[i].2), find(&mut parent, edges[j].2));
            parent[a as usize] = b;
            j += 1;
        }
        unique += 1;
        non_manifold += (j - i > 2) as usize;
        i = j;
    }
    let components = (0..m.triangles.len() as u32).filter(|&t| find(&mut parent, t) == t).count();
    (components, non_manifold, m.positions.len() as i64 - unique + m.triangles.len() as i64)
}

/// Mean and max distance from the mesh vertices to the exact surface, in spacings.
pub fn accuracy(m: &ReconMesh, vs: f32) -> (f32, f32) {
    let d: Vec<f32> = m.positions.par_iter().map(|p| sdf(*p).abs() / vs).collect();
    (d.iter().sum::<f32>() / d.len().max(1) as f32, d.iter().cloned().fold(0.0, f32::max))
}

/// Meshes a procedural shape, a mesh's 256^3 level or a level file with each
/// method; prints time, peak memory and topology.
#[derive(Parser, Debug)]
struct Args {
    /// Meshing method; `all` runs apss and poisson, each in a child process.
    #[arg(default_value = "all", value_parser = ["all", "poisson", "apss"])]
    method: String,
    /// Mesh the 256^3 level of this exemplar mesh (encoded at paper settings)
    /// instead of the procedural shape.
    #[arg(long, value_name = "PATH")]
    mesh: Option<PathBuf>,
    /// Mesh the points of this level file (takes precedence over --mesh).
    #[arg(long, value_name = "PATH")]
    level: Option<PathBuf>,
    /// Also write the mesh here (PLY with vertex colours, exemplar frame).
    #[arg(long, value_name = "PATH")]
    out: Option<PathBuf>,
    /// Sampling resolution of the procedural shape (one point per voxel).
    #[arg(long, value_name = "N", default_value_t = 256)]
    res: i32,
    /// Grid resolution of the mesher (both methods; default: the method's).
    #[arg(long, value_name = "N")]
    resolution: Option<u32>,
    /// Poisson: solver tolerance (default: the method's).
    #[arg(long, value_name = "X")]
    tol: Option<f64>,
    /// Poisson: width of the point-clustering cells, in spacings (<= 1:
    /// every point; default: the method's).
    #[arg(long, value_name = "X")]
    cluster: Option<f32>,
    /// Poisson: projection steps onto the points (default: the method's).
    #[arg(long, value_name = "N")]
    project: Option<u32>,
    /// APSS: MLS support radius, in spacings (default: the method's).
    #[arg(long, value_name = "X")]
    radius: Option<f32>,
    /// APSS: band around the points, in spacings (default: the method's).
    #[arg(long, value_name = "X")]
    band: Option<f32>,
}

impl Args {
    /// The options again as command-line flags (METHOD left out), for the
    /// child processes of `all`.
    fn flags(&self) -> Vec<String> {
        let mut v = Vec::new();
        let mut push = |flag: &str, value: Option<String>| {
            if let Some(value) = value {
                v.push(format!("--{flag}"));
                v.push(value);
            }
        };
        push("mesh", self.mesh.as_ref().map(|p| p.display().to_string()));
        push("level", self.level.as_ref().map(|p| p.display().to_string()));
        push("out", self.out.as_ref().map(|p| p.display().to_string()));
        push("res", Some(self.res.to_string()));
        push("resolution", self.resolution.map(|x| x.to_string()));
        push("tol", self.tol.map(|x| x.to_string()));
        push("cluster", self.cluster.map(|x| x.to_string()));
        push("project", self.project.map(|x| x.to_string()));
        push("radius", self.radius.map(|x| x.to_string()));
        push("band", self.band.map(|x| x.to_string()));
        v
    }
}

fn main() {
    let args = Args::parse();
    let method = args.method.clone();
    if method == "all" {
        let exe = std::env::current_exe().unwrap();
        for m in ["apss", "poisson"] {
            let status = std::process::Command::new(&exe).arg(m).args(args.flags()).status();
            if !matches!(status, Ok(s) if s.success()) {
                eprintln!("{m}: failed ({status:?})");
            }
        }
        return;
    }
    let res = args.res;
    let exemplar = args.mesh.as_deref();
    let level = args.level.as_deref();
    let t = Instant::now();
    let pts = match (exemplar, level) {
        (_, Some(path)) => {
            let (level, _) = shapeshifter::io::vdb::read_level(path).expect("read --level PATH");
            shapeshifter::pipeline::oriented_points(&level).expect("active voxels")
        }
        (Some(path), None) => {
            let m = shapeshifter::io::mesh::load(path).expect("load --mesh PATH");
            let (levels, _) = shapeshifter::encode::encode(&m, &Default::default()).expect("encode");
            shapeshifter::pipeline::oriented_points(levels.last().expect("levels")).expect("active voxels")
        }
        (None, None) => sample(res),
    };
    let vs = pts.spacing;
    println!(
        "{method}: {} points (one per voxel at {}^3 of {}), made in {:.2} s, {} rayon threads",
        pts.positions.len(),
        if exemplar.is_some() || level.is_some() { 256 } else { res },
        level.or(exemplar).map_or("the procedural shape".into(), |p| p.to_string_lossy()),
        t.elapsed().as_secs_f64(),
        rayon::current_num_threads()
    );
    let rss0 = peak_rss_mib();
    let cpu0 = cpu_seconds();
    let t = Instant::now();
    let mesh = match method.as_str() {
        "apss" => {
            let mut o = ApssOptions::default();
            o.resolution = args.resolution.unwrap_or(o.resolution);
            o.radius = args.radius.unwrap_or(o.radius);
            o.band = args.band.unwrap_or(o.band);
            apss(&pts, &o).unwrap()
        }
        "poisson" => {
            let mut o = PoissonOptions::default();
            o.solver_tolerance = args.tol.unwrap_or(o.solver_tolerance);
            o.resolution = args.resolution.unwrap_or(o.resolution);
            o.cluster = args.cluster.unwrap_or(o.cluster);
            o.project_steps = args.project.unwrap_or(o.project_steps);
            let (m, r) = poisson_report(&pts, &o).unwrap();
            println!("  {o:?}");
            println!(
                "  {} points to CGAL; CPU s: setup {:.2}, refine+assemble {:.2}, solve {:.2} ({} CG iterations, error {:.1e}, {} unknowns), mesher/grid {:.2} ({} corners), output {:.2}",
                r.points, r.seconds_setup, r.seconds_refine, r.seconds_solve, r.solver_iterations, r.solver_error,
                r.delaunay_vertices.saturating_sub(1), r.seconds_mesh, r.grid_corners, r.seconds_output
            );
            m
        }
        other => panic!("unknown method {other}"),
    };
    let secs = t.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - cpu0;
    // Accuracy against the exact surface: only the procedural shape has one.
    let accuracy = match exemplar.or(level) {
        Some(_) => String::new(),
        None => {
            let (mean, max) = accuracy(&mesh, vs);
            format!(" (the shape is a topological sphere: 2), vertex-to-surface mean {mean:.3} / max {max:.3} spacings")
        }
    };
    let (components, non_manifold, euler) = topology(&mesh);
    println!(
        "  {method}: {:.2} s wall, {cpu:.2} s CPU, {} vertices, {} triangles, {} boundary edges, {components} component(s), {non_manifold} non-manifold edges, Euler characteristic {euler}{accuracy}, peak RSS {:.0} MiB (points alone {:.0} MiB)",
        secs,
        mesh.positions.len(),
        mesh.triangles.len(),
        mesh.boundary_edge_count(),
        peak_rss_mib(),
        rss0
    );
    if let Some(out) = &args.out {
        let m = shapeshifter::io::mesh::Mesh {
            name: method.clone(),
            positions: mesh.positions,
            triangles: mesh.triangles,
            colours: shapeshifter::io::mesh::MeshColours::PerVertex(mesh.colours),
            texture: None,
        };
        shapeshifter::io::mesh::save(&m, out, true).expect("write --out PATH");
    }
}
