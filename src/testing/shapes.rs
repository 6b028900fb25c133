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
