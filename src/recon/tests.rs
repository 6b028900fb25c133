use super::*;
use glam::Vec3;
use crate::io::poisson::{self, PoissonParams};

const R: f32 = 0.5;
const VS: f32 = 1.0 / 32.0;

fn sphere() -> OrientedPoints {
    // Red where x > 0, blue elsewhere (the colour transfer is checked).
    let red_blue = |p: Vec3| if p.x > 0.0 { Vec3::new(1.0, 0.0, 0.0) } else { Vec3::new(0.0, 0.0, 1.0) };
    crate::testing::shapes::surface_points(|p| p.length() - R, Vec3::splat(-0.7), Vec3::splat(0.7), VS, red_blue)
}

/// A gently curved open patch: z = 0.1 sin(3x) cos(2y) over the disk x^2+y^2 < 0.5^2.
fn height(x: f32, y: f32) -> f32 {
    0.1 * (3.0 * x).sin() * (2.0 * y).cos()
}

fn patch() -> OrientedPoints {
    let mut pts = OrientedPoints { spacing: VS, ..Default::default() };
    let n = (1.2 / VS) as i32;
    for i in -n..=n {
        for j in -n..=n {
            let (x, y) = (i as f32 * VS, j as f32 * VS);
            if x * x + y * y >= R * R {
                continue;
            }
            let z = height(x, y);
            let e = 1e-3;
            let dx = (height(x + e, y) - height(x - e, y)) / (2.0 * e);
            let dy = (height(x, y + e) - height(x, y - e)) / (2.0 * e);
            pts.positions.push(Vec3::new(x, y, z));
            pts.normals.push(Vec3::new(-dx, -dy, 1.0).normalize());
            pts.colours.push(if x > 0.0 { Vec3::X } else { Vec3::Z });
        }
    }
    pts
}

fn signed_volume(m: &ReconMesh) -> f32 {
    crate::testing::shapes::signed_volume(&m.positions, &m.triangles)
}

/// Largest distance from an input point to the nearest mesh vertex.
fn coverage(points: &OrientedPoints, m: &ReconMesh) -> f32 {
    let grid = Nearest::new(&m.positions);
    points.positions.iter().map(|p| grid.nearest(*p).unwrap().1).fold(0.0, f32::max)
}

fn check_sphere(m: &ReconMesh, pts: &OrientedPoints, name: &str) {
    assert!(m.triangles.len() > 1000, "{name}: {} triangles", m.triangles.len());
    assert_eq!(m.boundary_edge_count(), 0, "{name}: the sphere is not closed");
    let worst = m.positions.iter().map(|p| (p.length() - R).abs()).fold(0.0, f32::max);
    assert!(worst < 0.35 * VS, "{name}: a vertex lies {} spacings off the sphere", worst / VS);
    let mean = m.positions.iter().map(|p| (p.length() - R).abs()).sum::<f32>() / m.positions.len() as f32;
    assert!(mean < 0.1 * VS, "{name}: mean distance {} spacings", mean / VS);
    let cov = coverage(pts, m);
    assert!(cov < 1.5 * VS, "{name}: an input point is {} spacings from the mesh", cov / VS);
    let v = signed_volume(m);
    let exact = 4.0 / 3.0 * std::f32::consts::PI * R * R * R;
    assert!((v / exact - 1.0).abs() < 0.03, "{name}: volume {v} vs {exact} (orientation?)");
}

fn check_colours(m: &ReconMesh, name: &str) {
    assert_eq!(m.colours.len(), m.positions.len(), "{name}");
    for (p, c) in m.positions.iter().zip(&m.colours) {
        if p.x > 2.0 * VS {
            assert_eq!(*c, Vec3::X, "{name}: vertex {p} has colour {c}");
        } else if p.x < -2.0 * VS {
            assert_eq!(*c, Vec3::Z, "{name}: vertex {p} has colour {c}");
        }
    }
}

#[test]
fn apss_sphere_is_closed_and_close() {
    let pts = sphere();
    let m = apss(&pts, &ApssOptions::default()).unwrap();
    check_sphere(&m, &pts, "apss");
    check_colours(&m, "apss");
}

#[test]
fn poisson_sphere_is_closed_and_close() {
    let pts = sphere();
    let (m, report) = poisson_report(&pts, &PoissonOptions::default()).unwrap();
    eprintln!("{} points: {report:?}", pts.positions.len());
    check_sphere(&m, &pts, "poisson");
    check_colours(&m, "poisson");
}

#[test]
fn apss_patch_stays_open_without_skirt() {
    let pts = patch();
    // A narrow band (default 1.5), so that the band, not the neighbour count,
    // is what stops the surface at the rim.
    let opts = ApssOptions { band: 1.0, ..Default::default() };
    let m = apss(&pts, &opts).unwrap();
    assert!(m.triangles.len() > 1000);
    let boundary = m.boundary_edge_count();
    // The rim of a disk of radius R is about 2 pi R / cell edges long.
    assert!(boundary > 100, "only {boundary} boundary edges");
    let grid = Nearest::new(&pts.positions);
    for p in &m.positions {
        let d = grid.nearest(*p).unwrap().1;
        // cells are spacing / 4 here: a vertex lies within band + cell diagonal
        assert!(d < (opts.band + 0.45) * VS, "vertex {p} is {} spacings from the points", d / VS);
        let off = (p.z - height(p.x, p.y)).abs();
        assert!(off < 0.25 * VS, "vertex {p} is {} spacings off the patch (skirt?)", off / VS);
    }
    // The patch is covered, up to its rim.
    let cov = coverage(&pts, &m);
    assert!(cov < 1.5 * VS, "an input point is {} spacings from the mesh", cov / VS);
    // One sheet, facing up.
    let up = m
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            (b - a).cross(c - a).z
        })
        .filter(|z| *z > 0.0)
        .count();
    assert_eq!(up, m.triangles.len(), "some triangles face down");
    check_colours(&m, "apss patch");
}

#[test]
fn errors_for_bad_input() {
    let p = PoissonOptions::default();
    let a = ApssOptions::default();
    let empty = OrientedPoints::default();
    let mut few = sphere();
    few.positions.truncate(10);
    few.normals.truncate(10);
    few.colours.truncate(10);
    let mut nan_pos = sphere();
    nan_pos.positions[7].y = f32::NAN;
    let mut nan_normal = sphere();
    nan_normal.normals[3] = Vec3::new(f32::NAN, 0.0, 1.0);
    let mut short_colours = sphere();
    short_colours.colours.pop();
    for method in [Method::Poisson, Method::Apss] {
        let run = |pts: &OrientedPoints| reconstruct(pts, method, &p, &a);
        assert!(matches!(run(&empty), Err(ReconError::NoPoints)), "{method}");
        assert!(matches!(run(&few), Err(ReconError::TooFewPoints { count: 10, .. })), "{method}");
        assert!(matches!(run(&nan_pos), Err(ReconError::NonFinite { index: 7, what: "position" })), "{method}");
        assert!(matches!(run(&nan_normal), Err(ReconError::NonFinite { index: 3, what: "normal" })), "{method}");
        assert!(matches!(run(&short_colours), Err(ReconError::LengthMismatch { what: "colours", .. })), "{method}");
    }
    let bad = PoissonOptions { resolution: 1, ..Default::default() };
    assert!(matches!(poisson(&sphere(), &bad), Err(ReconError::InvalidOption(_))));
}

#[test]
fn cxx_errors_become_failed() {
    // Past Rust's own checks, the C++ side still refuses bad input with a message.
    let params = poisson::PoissonParams { spacing: 0.0, solver_tolerance: 1e-6, solver_max_iterations: 0, grid_cell: 0.0 };
    let e = poisson::sample_grid(&[0.0; 9], &[0.0; 6], &PoissonParams { grid_cell: 0.1, ..params.clone() }).unwrap_err();
    assert!(e.contains("normals"), "{e}");
    let e = poisson::sample_grid(&[0.0, 0.0, f32::NAN], &[0.0, 0.0, 1.0], &params).unwrap_err();
    assert!(e.contains("grid_cell"), "{e}");
    let params = PoissonParams { grid_cell: 0.1, ..params };
    let e = poisson::sample_grid(&[0.0, 0.0, f32::NAN], &[0.0, 0.0, 1.0], &params).unwrap_err();
    assert!(e.contains("non-finite"), "{e}");
    let e = poisson::sample_grid(&[0.0; 30], &[0.0; 30], &params).unwrap_err();
    assert!(e.contains("too few"), "{e}");
}

#[test]
fn colours_are_empty_without_input_colours() {
    let mut pts = sphere();
    pts.colours.clear();
    let m = apss(&pts, &ApssOptions::default()).unwrap();
    assert!(m.colours.is_empty());
}

#[test]
fn spacing_is_estimated_when_missing() {
    let mut pts = sphere();
    pts.spacing = 0.0;
    let s = estimate_spacing(&pts.positions);
    assert!(s > 0.5 * VS && s < 1.5 * VS, "estimated spacing {s} vs {VS}");
    let m = apss(&pts, &ApssOptions::default()).unwrap();
    assert_eq!(m.boundary_edge_count(), 0);
}

/// CGAL's Poisson is not screened Poisson: around an open patch its zero set
/// runs on past the rim to the hull of its Delaunay triangulation. The grid
/// mesher clips it to the points' box plus a margin and caps it there: a
/// closed surface through the patch, no farther out than the margin.
#[test]
fn poisson_closes_an_open_patch_within_its_margin() {
    let pts = patch();
    let (m, report) = poisson_report(&pts, &PoissonOptions::default()).unwrap();
    eprintln!("{} points: {report:?}", pts.positions.len());
    assert!(m.triangles.len() > 1000);
    assert_eq!(m.boundary_edge_count(), 0, "Poisson left the open patch open");
    // The closing surface stays within the domain: the points' box plus a
    // tenth of its longest side (and a cell to spare).
    let (lo, hi) = bounds(&pts.positions);
    let margin = 0.1 * (hi - lo).max_element() + VS;
    for p in &m.positions {
        assert!(p.cmpge(lo - margin).all() && p.cmple(hi + margin).all(), "vertex {p} outside {lo}..{hi} + {margin}");
    }
    // The patch itself is part of the surface.
    let cov = coverage(&pts, &m);
    assert!(cov < 1.5 * VS, "an input point is {} spacings from the mesh", cov / VS);
}

/// Two sides of a sheet half a spacing thick, with opposite normals, share
/// every cluster cell: clustering by cell alone would merge them into one
/// side; by cell and normal direction both stay, each thinned.
#[test]
fn clustering_keeps_both_sides_of_a_thin_sheet() {
    let (mut p, mut n) = (Vec::new(), Vec::new());
    for i in 0..40 {
        for j in 0..40 {
            for (z, nz) in [(0.0, -1.0), (0.5 * VS, 1.0)] {
                p.push(Vec3::new(i as f32 * VS, j as f32 * VS, z));
                n.push(Vec3::new(0.0, 0.0, nz));
            }
        }
    }
    let keep = cluster_representatives(&p, &n, 2.0 * VS);
    let up = keep.iter().filter(|&&i| n[i as usize].z > 0.0).count();
    let down = keep.len() - up;
    // 40 points per side and axis in cells of 2 spacings: 20 x 20 per side.
    assert_eq!((up, down), (400, 400));
    assert!(keep.windows(2).all(|w| w[0] != w[1]));
}

/// Fewer points for CGAL cost accuracy that the projection onto all the
/// points brings back (a sphere is exactly what an APSS fit represents).
#[test]
fn projection_brings_clustered_poisson_onto_the_sphere() {
    let pts = sphere();
    let off = |m: &ReconMesh| m.positions.iter().map(|p| (p.length() - R).abs() / VS).fold(0.0, f32::max);
    let coarse = PoissonOptions { cluster: 2.0, project_steps: 0, ..Default::default() };
    let (raw, report) = poisson_report(&pts, &coarse).unwrap();
    assert!(
        (report.points as usize) < pts.positions.len() / 2,
        "clustering per 2 spacings kept {} of {} points",
        report.points,
        pts.positions.len()
    );
    let projected = poisson(&pts, &PoissonOptions { project_steps: 2, ..coarse }).unwrap();
    assert_eq!(projected.triangles, raw.triangles, "projection moves vertices only");
    let (before, after) = (off(&raw), off(&projected));
    assert!(after < 0.05 && after < 0.5 * before, "worst vertex {before} -> {after} spacings off the sphere");
    check_sphere(&projected, &pts, "poisson (clustered, projected)");
}

/// The same points give the same Poisson mesh whatever the process allocated
/// before: CGAL's refinement orders cells by address, so its blocks come
/// from an arena in allocation order (cpp/cgal_arena.h). Without it, heap
/// holes left by earlier allocations gave another refinement (a level file
/// meshed under a longer path gave a mesh up to 1.5 voxels away).
#[test]
fn poisson_does_not_depend_on_the_heap_before_it() {
    // A voxelised box and sphere: points on a lattice, as a level's are.
    let boxed = crate::testing::shapes::surface_points(
        |p| (p.abs() - Vec3::new(0.45, 0.3, 0.2)).max_element(),
        Vec3::splat(-0.7),
        Vec3::splat(0.7),
        VS,
        |_| Vec3::ONE,
    );
    for (name, pts) in [("sphere", sphere()), ("box", boxed)] {
        let options = PoissonOptions::default();
        let first = poisson(&pts, &options).unwrap();
        let mut differ = Vec::new();
        for round in 0..6usize {
            // Holes of many sizes in the heap, some kept alive across the call.
            let mut kept: Vec<Vec<u8>> =
                (0..2000).map(|i| vec![i as u8; 16 + (i * 7919 + round * 104_729) % (1 << (8 + round))]).collect();
            let mut i = 0;
            kept.retain(|_| {
                i += 1;
                (i + round) % 3 == 0
            });
            let again = poisson(&pts, &options).unwrap();
            if again.positions != first.positions || again.triangles != first.triangles {
                differ.push(round);
            }
            drop(kept);
        }
        assert!(differ.is_empty(), "{name}: another mesh after heap pattern(s) {differ:?}");
    }
}
