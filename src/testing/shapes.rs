//! Procedural primitive meshes (closed, outward-oriented), for tests and
//! benchmarks that need a shape with a known answer, and the signed volume that
//! checks their orientation. The demo exemplar (`exemplar.rs`) is built elsewhere.

use crate::io::mesh::{Mesh, MeshColours};
use glam::Vec3;

fn mesh(name: &str, positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
    Mesh { name: name.into(), positions, triangles, colours: MeshColours::None, texture: None }
}

/// UV sphere around `centre`: two poles on the z axis and `rings - 1` rings of
/// `segs` vertices, `2 * rings * segs - 2 * segs` triangles; the radius may vary
/// with the polar angle theta (0 at +z) and the azimuth phi: `radius(theta, phi)`.
pub fn uv_sphere(centre: Vec3, rings: u32, segs: u32, radius: impl Fn(f32, f32) -> f32) -> Mesh {
    use std::f32::consts::{PI, TAU};
    let mut pos = vec![centre + Vec3::Z * radius(0.0, 0.0), centre - Vec3::Z * radius(PI, 0.0)];
    for i in 1..rings {
        let th = PI * i as f32 / rings as f32;
        for j in 0..segs {
            let ph = TAU * j as f32 / segs as f32;
            pos.push(centre + radius(th, ph) * Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()));
        }
    }
    let v = |i: u32, j: u32| 2 + (i - 1) * segs + (j % segs);
    let mut tris = Vec::new();
    for j in 0..segs {
        tris.push([0, v(1, j), v(1, j + 1)]);
        tris.push([1, v(rings - 1, j + 1), v(rings - 1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segs {
            tris.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
            tris.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
        }
    }
    mesh("sphere", pos, tris)
}

/// Axis-aligned box [lo, hi]: 8 vertices (vertex i has hi.x where bit 0 of i is
/// set, hi.y for bit 1, hi.z for bit 2), 12 triangles.
pub fn axis_box(lo: Vec3, hi: Vec3) -> Mesh {
    let pos = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let tris = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    mesh("box", pos, tris)
}

/// Signed volume enclosed by triangles (positive for a closed, outward-oriented
/// surface), in cubed units of the positions.
pub fn signed_volume(positions: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_are_closed_and_outward_with_the_right_volume() {
        let b = axis_box(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.0, 3.0, 2.5));
        assert!((signed_volume(&b.positions, &b.triangles) - 3.0).abs() < 1e-5);
        let s = uv_sphere(Vec3::new(1.0, 2.0, 3.0), 64, 128, |_, _| 0.5);
        let v = signed_volume(&s.positions, &s.triangles);
        let exact = 4.0 / 3.0 * std::f32::consts::PI * 0.125;
        assert!((v - exact).abs() < 0.01 * exact, "sphere volume {v} vs {exact}");
        for m in [&b, &s] {
            assert_eq!(m.edge_counts().0, 0, "{} is not closed", m.name);
        }
    }
}

/// One point per voxel of size `vs` (world units) that the surface of `sdf`
/// crosses (|sdf| at the voxel centre below vs/2) within the box [lo, hi],
/// moved onto the surface along the numerical gradient, like the finest level
/// of an encoded exemplar; colours from `colour` of the point. Slabs of x in
/// parallel, points in (x, y, z) voxel order.
pub fn surface_points(
    sdf: impl Fn(glam::Vec3) -> f32 + Sync,
    lo: glam::Vec3,
    hi: glam::Vec3,
    vs: f32,
    colour: impl Fn(glam::Vec3) -> glam::Vec3,
) -> crate::geom::points::OrientedPoints {
    use glam::Vec3;
    use rayon::prelude::*;
    // A hair below the exact count, so that float rounding of (hi - lo) / vs
    // never adds a slab outside the box.
    let n = ((hi - lo) / vs - Vec3::splat(1e-4)).ceil().as_ivec3();
    let e = vs * 1e-2;
    let slabs: Vec<Vec<(Vec3, Vec3)>> = (0..n.x)
        .into_par_iter()
        .map(|i| {
            let mut out = Vec::new();
            for j in 0..n.y {
                for k in 0..n.z {
                    let c = lo + (Vec3::new(i as f32, j as f32, k as f32) + 0.5) * vs;
                    let d = sdf(c);
                    if d.abs() >= 0.5 * vs {
                        continue;
                    }
                    let g = Vec3::new(
                        sdf(c + Vec3::X * e) - sdf(c - Vec3::X * e),
                        sdf(c + Vec3::Y * e) - sdf(c - Vec3::Y * e),
                        sdf(c + Vec3::Z * e) - sdf(c - Vec3::Z * e),
                    )
                    .normalize();
                    out.push((c - g * d, g));
                }
            }
            out
        })
        .collect();
    let mut pts = crate::geom::points::OrientedPoints { spacing: vs, ..Default::default() };
    for (p, g) in slabs.into_iter().flatten() {
        pts.positions.push(p);
        pts.normals.push(g);
        pts.colours.push(colour(p));
    }
    pts
}

/// `n` points spread evenly over a sphere (a Fibonacci lattice, poles on z).
pub fn sphere_points(n: usize, radius: f64, centre: glam::DVec3) -> Vec<glam::DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let th = golden * i as f64;
            centre + radius * glam::DVec3::new(r * th.cos(), r * th.sin(), z)
        })
        .collect()
}
