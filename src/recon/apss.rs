//! Algebraic point set surfaces (Guennebaud & Gross 2007), meshed by surface
//! nets on a sparse grid that covers only a band around the points.
//!
//! 1. Bricks: the grid (cell `c`, corners `origin + i * c`) is stored in bricks
//!    of 8^3 corners; only bricks that meet the band (distance < `band` to some
//!    point) exist. A corner is *defined* when a point lies within `band` of it
//!    and at least `min_neighbours` points lie within `radius`.
//! 2. Field: at each defined corner x, an algebraic sphere
//!    s(y) = u_c + u_l.y + u_q |y|^2 is fitted to the oriented points within
//!    `radius` (weights (1 - d^2/h^2)^4, positions and normals both fitted,
//!    in coordinates centred on x and scaled by h), normalised so that
//!    |grad s| = 1 on the sphere (Pratt); the value is s(x), an approximate
//!    signed distance, negative inside (normals point outwards).
//! 3. Surface nets: a vertex in every cell whose 8 corners are defined and
//!    change sign (the mean of its edge crossings), a quad (two triangles)
//!    around every sign-changing edge whose 4 cells all have vertices. Where a
//!    cell is undefined the quads stop: open surfaces stay open, closed ones
//!    come out watertight, and every vertex is shared by construction.

use super::contour::{local, SparseField, B, B3};
use super::spatial::{pack, unpack, HashGrid};
use glam::{DVec3, Vec3};
use rayon::prelude::*;

pub(crate) struct ApssParams {
    /// grid cell size, world units
    pub cell: f32,
    /// MLS support radius h, world units
    pub radius: f32,
    /// band half-width, world units
    pub band: f32,
    pub min_neighbours: u32,
}


/// One fit at `x` from the candidate points `cand` (those near x): the signed
/// algebraic distance (world units) and the sphere's unit gradient at x, or
/// None where fewer than `min_neighbours` points lie within `radius`.
#[inline]
fn apss_fit(cand: &[(Vec3, Vec3)], x: Vec3, radius: f32, min_neighbours: u32) -> Option<(f32, Vec3)> {
    let h = radius;
    let inv_h = 1.0 / h as f64;
    let (mut sw, mut sdpn, mut sdpp) = (0.0f64, 0.0f64, 0.0f64);
    let (mut sp, mut sn) = (DVec3::ZERO, DVec3::ZERO);
    let mut count = 0u32;
    let inv_h2 = 1.0 / (h * h);
    for &(q, n) in cand {
        let d = q - x;
        let t = 1.0 - d.length_squared() * inv_h2;
        if t <= 0.0 {
            continue;
        }
        let w = ((t * t) * (t * t)) as f64;
        let q = d.as_dvec3() * inv_h;
        let n = n.as_dvec3();
        sw += w;
        sp += w * q;
        sn += w * n;
        sdpn += w * q.dot(n);
        sdpp += w * q.dot(q);
        count += 1;
    }
    if count < min_neighbours || sw <= 0.0 {
        return None;
    }
    let inv_w = 1.0 / sw;
    let var = sdpp * inv_w - sp.dot(sp) * inv_w * inv_w;
    let cov = sdpn * inv_w - sp.dot(sn) * inv_w * inv_w;
    let uq = if var > 1e-12 { 0.5 * cov / var } else { 0.0 };
    let ul = (sn - 2.0 * uq * sp) * inv_w;
    let uc = -(ul.dot(sp) + uq * sdpp) * inv_w;
    let norm2 = ul.dot(ul) - 4.0 * uc * uq;
    if !(norm2 > 1e-12) {
        return None;
    }
    // s(0) = uc and grad s(0) = ul in x's scaled frame.
    let v = (uc / norm2.sqrt() * h as f64) as f32;
    let g = ul.normalize_or_zero().as_vec3();
    (v.is_finite() && g != Vec3::ZERO).then_some((v, g))
}

#[inline]
fn apss_value(cand: &[(Vec3, Vec3)], x: Vec3, p: &ApssParams) -> Option<f32> {
    apss_fit(cand, x, p.radius, p.min_neighbours).map(|(v, _)| v)
}

/// Moves every vertex onto the APSS surface of the points (Guennebaud & Gross
/// 2007's projection: fit at the vertex, step along the fit's gradient by its
/// signed distance, `steps` times). A step longer than `max_step` (world
/// units) is shortened to it, and a vertex with fewer than `min_neighbours`
/// points within `radius` (a hole the caller filled) stays where it is.
pub(crate) fn project(
    vertices: &mut [Vec3],
    points: &[Vec3],
    normals: &[Vec3],
    radius: f32,
    min_neighbours: u32,
    max_step: f32,
    steps: u32,
) {
    let grid = HashGrid::new(points, radius);
    let normals: Vec<Vec3> = grid.index.iter().map(|&i| normals[i as usize].normalize_or_zero()).collect();
    vertices.par_iter_mut().for_each_init(Vec::new, |cand, v| {
        for _ in 0..steps {
            cand.clear();
            grid.for_each_within(*v, radius, |j, _| cand.push((grid.pos[j], normals[j])));
            let Some((d, g)) = apss_fit(cand, *v, radius, min_neighbours) else { return };
            *v -= g * d.clamp(-max_step, max_step);
        }
    });
}

/// Steps 1 and 2: the APSS field on the bricks near the points.
pub(crate) fn field(points: &[Vec3], normals: &[Vec3], p: &ApssParams) -> SparseField {
    let c = p.cell;
    let lo = points.iter().fold(Vec3::splat(f32::INFINITY), |a, &b| a.min(b));
    let origin = lo - Vec3::splat(p.band + 2.0 * c);
    let grid = HashGrid::new(points, p.radius);
    let normals: Vec<Vec3> = grid.index.iter().map(|&i| normals[i as usize].normalize_or_zero()).collect();

    // 1. Bricks that meet the band of some point.
    let mut bricks: Vec<u64> = points
        .par_iter()
        .flat_map_iter(|&q| {
            let a = ((q - p.band - origin) / c).ceil().as_ivec3().max(glam::IVec3::ZERO);
            let b = ((q + p.band - origin) / c).floor().as_ivec3().max(glam::IVec3::ZERO);
            let (a, b) = (a / B, b / B);
            let mut out = Vec::with_capacity(8);
            for x in a.x..=b.x {
                for y in a.y..=b.y {
                    for z in a.z..=b.z {
                        out.push(pack([x, y, z]));
                    }
                }
            }
            out.into_iter()
        })
        .collect();
    bricks.par_sort_unstable();
    bricks.dedup();

    // 2. The field at every corner of every brick (NaN: undefined).
    let mut values = vec![f32::NAN; bricks.len() * B3];
    values.par_chunks_mut(B3).zip(bricks.par_iter()).for_each(|(v, &k)| {
            let b = unpack(k);
            // The points that can reach a corner of this brick, gathered once.
            let lo = origin + Vec3::new(b[0] as f32, b[1] as f32, b[2] as f32) * (B as f32 * c);
            let hi = lo + Vec3::splat((B - 1) as f32 * c);
            let mut cand = Vec::new();
            let r2 = p.radius * p.radius;
            grid.for_each_in_box(lo - p.radius, hi + p.radius, |j| {
                let q = grid.pos[j];
                if (q - q.clamp(lo, hi)).length_squared() < r2 {
                    cand.push((q, normals[j]));
                }
            });
            // Corners within the band, splatted from the points near the brick.
            let band2 = p.band * p.band;
            let mut in_band = [false; B3];
            for &(q, _) in &cand {
                let a = ((q - p.band - origin) / c).ceil().as_ivec3();
                let e = ((q + p.band - origin) / c).floor().as_ivec3();
                let base = glam::IVec3::from(b) * B;
                let (a, e) = ((a - base).max(glam::IVec3::ZERO), (e - base).min(glam::IVec3::splat(B - 1)));
                for x in a.x..=e.x {
                    for y in a.y..=e.y {
                        for z in a.z..=e.z {
                            let corner = origin + (base + glam::IVec3::new(x, y, z)).as_vec3() * c;
                            if corner.distance_squared(q) < band2 {
                                in_band[local(x, y, z)] = true;
                            }
                        }
                    }
                }
            }
            for x in 0..B {
                for y in 0..B {
                    for z in 0..B {
                        if !in_band[local(x, y, z)] {
                            continue;
                        }
                        let i = [b[0] * B + x, b[1] * B + y, b[2] * B + z];
                        let pos = origin + Vec3::new(i[0] as f32, i[1] as f32, i[2] as f32) * c;
                        if let Some(f) = apss_value(&cand, pos, p) {
                            v[local(x, y, z)] = f;
                        }
                    }
                }
            }
        });
    SparseField { origin, cell: c, bricks: bricks.iter().map(|&k| unpack(k)).collect(), values }
}
