//! Surface nets on a sparse grid of bricks: the polygoniser of both meshers.
//!
//! 1. A vertex in every cell whose 8 corners are defined (not NaN) and change
//!    sign, at the mean of the crossings on its edges.
//! 2. A quad around every sign-changing edge whose 4 cells all have vertices,
//!    facing the positive side (f < 0 is inside), split along its shorter
//!    diagonal. The edge from a cell's min corner along an axis is visited
//!    from that cell only.
//!
//! Every vertex is shared by the quads around it (nothing to weld); a closed
//! zero set inside the defined region gives a watertight mesh, and where the
//! field is undefined the mesh simply stops (open boundary, no skirt).

use super::spatial::{pack, KeyMap};
use glam::Vec3;
use rayon::prelude::*;

/// Brick edge, in corners.
pub(crate) const B: i32 = 8;
pub(crate) const B3: usize = (B * B * B) as usize;

/// Index of corner (x, y, z) inside its brick.
#[inline]
pub(crate) fn local(x: i32, y: i32, z: i32) -> usize {
    ((x * B + y) * B + z) as usize
}

/// A scalar field on bricks of 8^3 grid corners; corner i of the grid lies at
/// `origin + i * cell`, brick b holds corners 8b .. 8b + 7 on each axis.
pub(crate) struct SparseField {
    pub origin: Vec3,
    pub cell: f32,
    pub bricks: Vec<[i32; 3]>,
    /// `B3` values per brick, NaN where undefined.
    pub values: Vec<f32>,
}

impl SparseField {
    pub(crate) fn defined_corners(&self) -> usize {
        self.values.par_iter().filter(|v| v.is_finite()).count()
    }
}

/// Polygonises the zero set of `field`: positions and counter-clockwise
/// (seen from the positive side) triangles.
pub(crate) fn surface_nets(field: &SparseField) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let SparseField { origin, cell: c, bricks, values } = field;
    let (origin, c) = (*origin, *c);
    let brick_of: KeyMap<u32> = bricks.iter().enumerate().map(|(i, &b)| (pack(b), i as u32)).collect();
    let corner = |i: [i32; 3]| -> f32 {
        let b = [i[0].div_euclid(B), i[1].div_euclid(B), i[2].div_euclid(B)];
        match brick_of.get(&pack(b)) {
            Some(&bi) => {
                values[bi as usize * B3 + local(i[0].rem_euclid(B), i[1].rem_euclid(B), i[2].rem_euclid(B))]
            }
            None => f32::NAN,
        }
    };

    // 1. One vertex per defined sign-changing cell (cell = its min corner).
    const EDGES: [([i32; 3], [i32; 3]); 12] = [
        ([0, 0, 0], [1, 0, 0]),
        ([0, 1, 0], [1, 1, 0]),
        ([0, 0, 1], [1, 0, 1]),
        ([0, 1, 1], [1, 1, 1]),
        ([0, 0, 0], [0, 1, 0]),
        ([1, 0, 0], [1, 1, 0]),
        ([0, 0, 1], [0, 1, 1]),
        ([1, 0, 1], [1, 1, 1]),
        ([0, 0, 0], [0, 0, 1]),
        ([1, 0, 0], [1, 0, 1]),
        ([0, 1, 0], [0, 1, 1]),
        ([1, 1, 0], [1, 1, 1]),
    ];
    let per_brick: Vec<(Vec<u32>, Vec<Vec3>)> = bricks
        .par_iter()
        .enumerate()
        .map(|(bi, &b)| {
            // 9^3 corners: this brick plus the first layer of its + neighbours.
            const N: i32 = B + 1;
            let mut f = vec![f32::NAN; (N * N * N) as usize];
            let at = |x: i32, y: i32, z: i32| ((x * N + y) * N + z) as usize;
            for x in 0..N {
                for y in 0..N {
                    for z in 0..N {
                        f[at(x, y, z)] = if x < B && y < B && z < B {
                            values[bi * B3 + local(x, y, z)]
                        } else {
                            corner([b[0] * B + x, b[1] * B + y, b[2] * B + z])
                        };
                    }
                }
            }
            let mut vid = vec![u32::MAX; B3];
            let mut verts = Vec::new();
            for x in 0..B {
                for y in 0..B {
                    for z in 0..B {
                        let mut inside = 0;
                        let mut ok = true;
                        for d in 0..8 {
                            let v = f[at(x + (d & 1), y + ((d >> 1) & 1), z + ((d >> 2) & 1))];
                            if !v.is_finite() {
                                ok = false;
                                break;
                            }
                            inside += (v < 0.0) as i32;
                        }
                        if !ok || inside == 0 || inside == 8 {
                            continue;
                        }
                        let mut sum = Vec3::ZERO;
                        let mut n = 0.0;
                        for (a, e) in EDGES {
                            let fa = f[at(x + a[0], y + a[1], z + a[2])];
                            let fb = f[at(x + e[0], y + e[1], z + e[2])];
                            if (fa < 0.0) != (fb < 0.0) {
                                let t = fa / (fa - fb);
                                let pa = Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32);
                                let pb = Vec3::new(e[0] as f32, e[1] as f32, e[2] as f32);
                                sum += pa + (pb - pa) * t;
                                n += 1.0;
                            }
                        }
                        let cell = [b[0] * B + x, b[1] * B + y, b[2] * B + z];
                        let local_pos = sum / n;
                        vid[local(x, y, z)] = verts.len() as u32;
                        verts.push(
                            origin
                                + (Vec3::new(cell[0] as f32, cell[1] as f32, cell[2] as f32) + local_pos) * c,
                        );
                    }
                }
            }
            (vid, verts)
        })
        .collect();

    // Global vertex numbering: brick offsets.
    let mut offsets = Vec::with_capacity(per_brick.len());
    let mut total = 0u32;
    for (_, v) in &per_brick {
        offsets.push(total);
        total += v.len() as u32;
    }
    let vertex = |cell: [i32; 3]| -> Option<u32> {
        let b = [cell[0].div_euclid(B), cell[1].div_euclid(B), cell[2].div_euclid(B)];
        let bi = *brick_of.get(&pack(b))? as usize;
        let l = per_brick[bi].0[local(cell[0].rem_euclid(B), cell[1].rem_euclid(B), cell[2].rem_euclid(B))];
        (l != u32::MAX).then(|| offsets[bi] + l)
    };

    // 2. Quads around sign-changing edges; the edge from a cell's min corner
    // along axis a is visited from that cell only.
    let quads: Vec<[u32; 4]> = bricks
        .par_iter()
        .enumerate()
        .flat_map_iter(|(bi, &b)| {
            let vid = &per_brick[bi].0;
            let base = offsets[bi];
            let mut quads = Vec::new();
            for x in 0..B {
                for y in 0..B {
                    for z in 0..B {
                        let l = vid[local(x, y, z)];
                        if l == u32::MAX {
                            continue;
                        }
                        let cell = [b[0] * B + x, b[1] * B + y, b[2] * B + z];
                        let f0 = values[bi * B3 + local(x, y, z)];
                        for a in 0..3 {
                            let (u, w) = ((a + 1) % 3, (a + 2) % 3);
                            let mut far = cell;
                            far[a] += 1;
                            let f1 = corner(far);
                            if !f1.is_finite() || (f0 < 0.0) == (f1 < 0.0) {
                                continue;
                            }
                            let mut c1 = cell;
                            c1[u] -= 1;
                            let mut c2 = c1;
                            c2[w] -= 1;
                            let mut c3 = cell;
                            c3[w] -= 1;
                            let (Some(v1), Some(v2), Some(v3)) = (vertex(c1), vertex(c2), vertex(c3)) else {
                                continue;
                            };
                            // (cell, -u, -u-w, -w) runs counter-clockwise seen
                            // from +a (u, w, a right-handed): keep it when the
                            // outside (f >= 0) lies towards +a.
                            let q = [base + l, v1, v2, v3];
                            quads.push(if f0 < 0.0 { q } else { [q[0], q[3], q[2], q[1]] });
                        }
                    }
                }
            }
            quads.into_iter()
        })
        .collect();

    let positions: Vec<Vec3> = per_brick.into_iter().flat_map(|(_, v)| v).collect();
    // Split each quad along its shorter diagonal.
    let triangles: Vec<[u32; 3]> = quads
        .par_iter()
        .flat_map_iter(|q| {
            let p = |i: usize| positions[q[i] as usize];
            if p(0).distance_squared(p(2)) <= p(1).distance_squared(p(3)) {
                [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
            } else {
                [[q[0], q[1], q[3]], [q[1], q[2], q[3]]]
            }
        })
        .collect();
    (positions, triangles)
}
