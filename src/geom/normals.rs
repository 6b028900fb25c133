//! Normals for point clouds that have none: a plane fitted to each point's
//! k nearest neighbours (the covariance's least eigenvector), then signs made
//! consistent by propagation along a minimum spanning tree of the neighbour
//! graph (Hoppe et al. 1992; Kruskal's, the edges sorted in parallel): an
//! edge costs 1 - |n_i . n_j|, so the signs travel first across flat regions
//! and last across creases. Each connected part of the graph is seeded at its highest point (along `up`), its normal
//! pointing away from the whole cloud's centroid there: up on the top of an
//! object or a terrain, down under the separate bottom of one.

use std::num::NonZero;

use glam::{DMat3, DVec3, Vec3};
use rayon::prelude::*;

/// How estimated normals are given their sign.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Orientation {
    /// Propagated along the neighbour graph's minimum spanning tree, each
    /// part seeded at its highest point, pointing away from the centroid:
    /// closed objects and terrain with walls alike.
    #[default]
    Graph,
    /// Every normal towards +up (height fields: terrain, facades seen from above).
    Up,
    /// Away from the cloud's centroid (star-shaped objects).
    Outward,
}

/// Unit normals for `points` (relative positions, any units) from their `k`
/// nearest neighbours, oriented per `orientation`; `up` is the vertical axis.
/// Also returns the median distance to the nearest other point (the cloud's
/// spacing, same units).
pub fn estimate(points: &[Vec3], k: usize, orientation: Orientation, up: Vec3) -> (Vec<Vec3>, f32) {
    let n = points.len();
    if n == 0 {
        return (Vec::new(), 0.0);
    }
    let k = k.clamp(3, 64).min(n);
    let started = std::time::Instant::now();
    let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
    let tree = kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(&coords);
    let qty = NonZero::new(k).unwrap();
    // Neighbours (without the point itself) and the fitted normal, per point.
    let fitted: Vec<(Vec<u32>, Vec3, f32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let near = tree.nearest_n::<kiddo::SquaredEuclidean>(&p.to_array(), qty);
            let ids: Vec<u32> = near.iter().map(|m| m.item as u32).filter(|&j| j as usize != i).collect();
            let spacing = near.iter().filter(|m| m.item as usize != i).map(|m| m.distance.sqrt()).fold(f32::INFINITY, f32::min);
            let normal = plane_normal(points, i, &ids).unwrap_or(up);
            (ids, normal, spacing)
        })
        .collect();
    let mut spacings: Vec<f32> = fitted.iter().map(|f| f.2).filter(|s| s.is_finite()).collect();
    let spacing = if spacings.is_empty() {
        0.0
    } else {
        let mid = spacings.len() / 2;
        *spacings.select_nth_unstable_by(mid, f32::total_cmp).1
    };
    let mut normals: Vec<Vec3> = fitted.iter().map(|f| f.1).collect();
    match orientation {
        Orientation::Up => normals.iter_mut().for_each(|nm| {
            if nm.dot(up) < 0.0 {
                *nm = -*nm
            }
        }),
        Orientation::Outward => {
            let c = points.iter().fold(DVec3::ZERO, |s, p| s + p.as_dvec3()) / n as f64;
            for (nm, p) in normals.iter_mut().zip(points) {
                if nm.dot(*p - c.as_vec3()) < 0.0 {
                    *nm = -*nm;
                }
            }
        }
        Orientation::Graph => {
            let neighbours: Vec<Vec<u32>> = fitted.into_iter().map(|f| f.0).collect();
            log::debug!("normals: {n} planes fitted in {:.2} s", started.elapsed().as_secs_f64());
            propagate(points, &neighbours, &mut normals, up);
        }
    }
    log::debug!("normals: {n} estimated and oriented in {:.2} s", started.elapsed().as_secs_f64());
    (normals, spacing)
}

/// The median distance from a point to its nearest other point (0 for fewer
/// than two points): the cloud's spacing, in the points' units.
pub fn median_spacing(points: &[Vec3]) -> f32 {
    if points.len() < 2 {
        return 0.0;
    }
    let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
    let tree = kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(&coords);
    let two = NonZero::new(2).unwrap();
    // Every 7th point is plenty for a median.
    let mut d: Vec<f32> = points
        .par_iter()
        .step_by(7)
        .map(|p| tree.nearest_n::<kiddo::SquaredEuclidean>(&p.to_array(), two).iter().map(|m| m.distance.sqrt()).fold(0.0, f32::max))
        .collect();
    let mid = d.len() / 2;
    *d.select_nth_unstable_by(mid, f32::total_cmp).1
}

/// The least-variance direction of point `i` and its neighbours; None when
/// they do not span a plane (fewer than 3, or all on one line).
fn plane_normal(points: &[Vec3], i: usize, ids: &[u32]) -> Option<Vec3> {
    if ids.len() < 2 {
        return None;
    }
    let all = || std::iter::once(i).chain(ids.iter().map(|&j| j as usize)).map(|j| points[j].as_dvec3());
    let m = ids.len() as f64 + 1.0;
    let mean = all().sum::<DVec3>() / m;
    let mut c = DMat3::ZERO;
    for q in all() {
        let d = q - mean;
        c += DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    least_eigenvector(c / m)
}

/// The eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix
/// (cyclic Jacobi rotations); None for a matrix of rank < 2 (a line or a point).
fn least_eigenvector(mut a: DMat3) -> Option<Vec3> {
    let scale = a.x_axis.x + a.y_axis.y + a.z_axis.z;
    if !(scale > 0.0) || !scale.is_finite() {
        return None;
    }
    let mut v = DMat3::IDENTITY;
    for _ in 0..24 {
        let off = a.y_axis.x.abs() + a.z_axis.x.abs() + a.z_axis.y.abs();
        if off < 1e-15 * scale {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            let apq = a.col(q)[p];
            if apq.abs() < 1e-300 {
                continue;
            }
            let (app, aqq) = (a.col(p)[p], a.col(q)[q]);
            let theta = (aqq - app) / (2.0 * apq);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            let mut r = DMat3::IDENTITY;
            r.col_mut(p)[p] = cs;
            r.col_mut(q)[q] = cs;
            r.col_mut(q)[p] = sn;
            r.col_mut(p)[q] = -sn;
            a = r.transpose() * a * r;
            v *= r;
        }
    }
    let eig = [a.x_axis.x, a.y_axis.y, a.z_axis.z];
    let mut order = [0usize, 1, 2];
    order.sort_by(|&x, &y| eig[x].total_cmp(&eig[y]));
    // Rank < 2: the middle eigenvalue vanishes too (collinear points).
    if eig[order[1]] <= 1e-12 * scale {
        return None;
    }
    v.col(order[0]).as_vec3().try_normalize()
}

/// Neighbours per point that make the orientation graph (of the k fitted):
/// enough to keep thin parts connected, few enough to sort quickly.
const GRAPH_NEIGHBOURS: usize = 10;

/// Kruskal's algorithm over the neighbour graph (edges sorted by cost in
/// parallel, a union-find keeps the tree's), then each tree walked from its
/// seed, flipping each normal to agree with its parent's.
fn propagate(points: &[Vec3], neighbours: &[Vec<u32>], normals: &mut [Vec3], up: Vec3) {
    let n = points.len();
    // (cost bits, from, to): a non-negative f32's bits sort as the f32 does.
    let fixed: &[Vec3] = normals;
    let mut edges: Vec<(u32, u32, u32)> = neighbours
        .par_iter()
        .enumerate()
        .flat_map_iter(|(i, ns)| {
            let ni = fixed[i];
            // Each edge once: i -> j, unless j also lists i and j < i.
            ns.iter().take(GRAPH_NEIGHBOURS).filter(move |&&j| (j as usize) > i || !neighbours[j as usize][..neighbours[j as usize].len().min(GRAPH_NEIGHBOURS)].contains(&(i as u32))).map(move |&j| {
                let cost = (1.0 - ni.dot(fixed[j as usize]).abs()).max(0.0);
                (cost.to_bits(), i as u32, j)
            })
        })
        .collect();
    edges.par_sort_unstable();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            let up = parent[parent[x as usize] as usize];
            parent[x as usize] = up;
            x = up;
        }
        x
    }
    // The tree as adjacency lists (compressed: offsets into one array).
    let mut tree: Vec<(u32, u32)> = Vec::with_capacity(2 * n);
    for &(_, a, b) in &edges {
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra != rb {
            parent[ra as usize] = rb;
            tree.push((a, b));
            tree.push((b, a));
        }
    }
    drop(edges);
    tree.par_sort_unstable();
    let mut offsets = vec![0u32; n + 1];
    for &(a, _) in &tree {
        offsets[a as usize + 1] += 1;
    }
    for i in 0..n {
        offsets[i + 1] += offsets[i];
    }

    let centroid = (points.iter().fold(DVec3::ZERO, |s, p| s + p.as_dvec3()) / n as f64).as_vec3();
    let mut by_height: Vec<u32> = (0..n as u32).collect();
    by_height.par_sort_unstable_by(|&a, &b| points[b as usize].dot(up).total_cmp(&points[a as usize].dot(up)));
    let mut reached = vec![false; n];
    let mut stack = Vec::new();
    for &seed in &by_height {
        let s = seed as usize;
        if reached[s] {
            continue;
        }
        let away = points[s] - centroid;
        let outward = if normals[s].dot(away).abs() > 1e-3 * away.length() { away } else { up };
        if normals[s].dot(outward) < 0.0 {
            normals[s] = -normals[s];
        }
        reached[s] = true;
        stack.push(seed);
        while let Some(a) = stack.pop() {
            for &(_, b) in &tree[offsets[a as usize] as usize..offsets[a as usize + 1] as usize] {
                if !reached[b as usize] {
                    reached[b as usize] = true;
                    if normals[b as usize].dot(normals[a as usize]) < 0.0 {
                        normals[b as usize] = -normals[b as usize];
                    }
                    stack.push(b);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a sphere and a closed box: every estimated normal points
    /// outward (the graph orientation seeds at the top and must carry the
    /// sign all round, across the box's creases too).
    #[test]
    fn graph_orientation_points_out_of_a_sphere_and_a_box() {
        let mut sphere = Vec::new();
        let (rings, segs) = (40, 80);
        for r in 1..rings {
            let th = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..segs {
                let ph = std::f32::consts::TAU * s as f32 / segs as f32;
                sphere.push(Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()));
            }
        }
        let (n, spacing) = estimate(&sphere, 12, Orientation::Graph, Vec3::Y);
        let wrong = sphere.iter().zip(&n).filter(|(p, n)| p.dot(**n) < 0.9).count();
        assert_eq!(wrong, 0, "{wrong} of {} sphere normals not outward", sphere.len());
        assert!(spacing > 0.0 && spacing < 0.1, "spacing {spacing}");

        let mut cube = Vec::new();
        let m = 20;
        for a in 0..=m {
            for b in 0..=m {
                let (u, v) = (a as f32 / m as f32 * 2.0 - 1.0, b as f32 / m as f32 * 2.0 - 1.0);
                for p in [Vec3::new(1.0, u, v), Vec3::new(-1.0, u, v), Vec3::new(u, 1.0, v), Vec3::new(u, -1.0, v), Vec3::new(u, v, 1.0), Vec3::new(u, v, -1.0)] {
                    cube.push(p);
                }
            }
        }
        let (n, _) = estimate(&cube, 10, Orientation::Graph, Vec3::Y);
        // Away from the edges the normal is the face's axis, pointing out.
        let mut checked = 0;
        for (p, nm) in cube.iter().zip(&n) {
            let on_face: Vec<usize> = (0..3).filter(|&a| p[a].abs() == 1.0).collect();
            if on_face.len() == 1 && (0..3).all(|a| a == on_face[0] || p[a].abs() < 0.85) {
                let mut out = Vec3::ZERO;
                out[on_face[0]] = p[on_face[0]];
                assert!(nm.dot(out) > 0.9, "normal {nm} at {p}");
                checked += 1;
            }
        }
        assert!(checked > 1000);

        let (n, _) = estimate(&sphere, 12, Orientation::Up, Vec3::Y);
        assert!(n.iter().all(|v| v.y >= 0.0));
        let (n, _) = estimate(&sphere, 12, Orientation::Outward, Vec3::Y);
        assert!(sphere.iter().zip(&n).all(|(p, n)| p.dot(*n) > 0.9));
    }

    #[test]
    fn collinear_points_fall_back_to_up() {
        let line: Vec<Vec3> = (0..10).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect();
        let (n, spacing) = estimate(&line, 4, Orientation::Graph, Vec3::Z);
        assert!(n.iter().all(|v| *v == Vec3::Z));
        assert_eq!(spacing, 1.0);
    }
}
