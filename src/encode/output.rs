//! Step 6: output levels from the pooled nodes.

use super::*;

/// Offset in voxel units, scaled down (direction kept) so that its L-inf norm is at
/// most 0.5: the point stays inside its voxel.
pub(super) fn clamp_offset(o: DVec3) -> Vec3 {
    if !o.is_finite() {
        return Vec3::ZERO;
    }
    let m = o.abs().max_element();
    let o = if m > 0.5 { o * (0.5 / m) } else { o };
    o.as_vec3().clamp(Vec3::splat(-0.5), Vec3::splat(0.5))
}

/// Unit normal; a mean that cancelled out (opposite sheets in one voxel) becomes +Z.
pub(super) fn unit_normal(n: Vec3) -> Vec3 {
    let n = n.normalize_or_zero();
    if n == Vec3::ZERO {
        Vec3::Z
    } else {
        n
    }
}

pub(super) fn level_from_rows(rows: Vec<(IVec3, Vec3, Vec3, Vec3)>, resolution: u32, frame: Frame) -> Level {
    let mut level = Level { index: 0, resolution, frame, ..Default::default() };
    level.coords.reserve(rows.len());
    level.offsets.reserve(rows.len());
    level.normals.reserve(rows.len());
    level.colours.reserve(rows.len());
    for (c, o, n, col) in rows {
        level.coords.push(c);
        level.offsets.push(o);
        level.normals.push(n);
        level.colours.push(col);
    }
    level.mask = vec![1.0; level.coords.len()];
    level
}

/// `points[i]`: the surface point of `nodes[i]`, normalised units.
pub(super) fn level_from_nodes<G: PointRule>(nodes: &[Node<G>], points: &[DVec3], r: u32, frame: Frame) -> Level {
    let vs = 2.0 / r as f64;
    let rows = nodes
        .par_iter()
        .zip(points)
        .map(|(node, &p)| {
            let c = voxel_centre(node.key, r);
            (
                morton_decode(node.key),
                clamp_offset((p - c) / vs),
                unit_normal(node.normal),
                node.colour.clamp(Vec3::ZERO, Vec3::ONE),
            )
        })
        .collect();
    level_from_rows(rows, r, frame)
}

pub(super) fn level_from_samples(samples: &[Sample], r: u32, frame: Frame) -> Level {
    let rows = samples
        .par_iter()
        .map(|s| (morton_decode(s.key), clamp_offset(s.offset.as_dvec3()), unit_normal(s.normal), s.colour))
        .collect();
    level_from_rows(rows, r, frame)
}
