//! Distances between point sets, in the units of the points: [`chamfer`]
//! and [`hausdorff`]; and a level's points in normalised units
//! ([`level_points_normalised`]) for the coarse Chamfer check of the report.

use glam::Vec3;
use rayon::prelude::*;

use crate::geom::nearest::Nearest;
use crate::level::Level;

/// Nearest-neighbour distances from every point of `from` to the set behind `to`.
fn nearest_distances(from: &[Vec3], to: &Nearest) -> Vec<f32> {
    from.par_iter().map(|&p| to.nearest(p).map_or(f32::INFINITY, |(_, d)| d)).collect()
}

/// The nearest-neighbour distances of the finite points of `a` to those of `b`,
/// and of `b` to `a`; when a side has no finite point, `Err` with the answer of
/// both distances: 0 when both are empty, infinite when one is.
fn distances_both_ways(a: &[Vec3], b: &[Vec3]) -> Result<(Vec<f32>, Vec<f32>), f32> {
    let finite = |s: &[Vec3]| -> Vec<Vec3> { s.iter().copied().filter(|p| p.is_finite()).collect() };
    let (a, b) = (finite(a), finite(b));
    match (a.is_empty(), b.is_empty()) {
        (true, true) => return Err(0.0),
        (true, false) | (false, true) => return Err(f32::INFINITY),
        _ => {}
    }
    let (ta, tb) = rayon::join(|| Nearest::new(&a), || Nearest::new(&b));
    Ok(rayon::join(|| nearest_distances(&a, &tb), || nearest_distances(&b, &ta)))
}

/// Symmetric Chamfer distance, in the units of the points (normalised units for
/// [`level_points_normalised`]): the mean of the two one-sided means of
/// nearest-neighbour distances (not squared),
/// `(mean_a min_b |a-b| + mean_b min_a |a-b|) / 2`, so a set against a copy of
/// itself shifted by `t` (less than half the point spacing) gives `|t|`.
/// 0 for two empty sets, infinite when only one is empty.
pub fn chamfer(a: &[Vec3], b: &[Vec3]) -> f32 {
    match distances_both_ways(a, b) {
        Err(d) => d,
        Ok((da, db)) => {
            let mean = |d: &[f32]| d.iter().map(|&v| v as f64).sum::<f64>() / d.len() as f64;
            (0.5 * (mean(&da) + mean(&db))) as f32
        }
    }
}

/// Symmetric Hausdorff distance: the largest nearest-neighbour distance in either
/// direction, in the units of the points. Same conventions for empty sets as
/// [`chamfer`].
pub fn hausdorff(a: &[Vec3], b: &[Vec3]) -> f32 {
    match distances_both_ways(a, b) {
        Err(d) => d,
        Ok((da, db)) => da.iter().chain(&db).fold(0.0f32, |m, &d| m.max(d)),
    }
}

/// A level's surface points in normalised units (the exemplar's bounding-box
/// diagonal is 2), for the coarse Chamfer check.
pub fn level_points_normalised(level: &Level) -> Vec<Vec3> {
    (0..level.len()).map(|i| level.point_normalised(i).as_vec3()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    #[test]
    fn chamfer_and_hausdorff() {
        let pts: Vec<Vec3> =
            (0..2000).map(|i| Vec3::new((i % 20) as f32, ((i / 20) % 10) as f32, (i / 200) as f32)).collect();
        assert_eq!(chamfer(&pts, &pts), 0.0);
        assert_eq!(hausdorff(&pts, &pts), 0.0);
        let t = Vec3::new(0.1, -0.2, 0.05);
        let moved: Vec<Vec3> = pts.iter().map(|&p| p + t).collect();
        assert!((chamfer(&pts, &moved) - t.length()).abs() < 1e-5);
        assert!((hausdorff(&pts, &moved) - t.length()).abs() < 1e-5);
        // Asymmetric: one extra far point.
        let mut extra = pts.clone();
        extra.push(Vec3::new(100.0, 0.0, 0.0));
        assert!((hausdorff(&pts, &extra) - 81.0).abs() < 1e-4);
        let expect = 0.5 * (81.0 / 2001.0);
        assert!((chamfer(&pts, &extra) as f64 - expect).abs() < 1e-5);
        // Brute force agreement on random points.
        let mut rng = Rng::new(5);
        let mut rnd = |n: usize| -> Vec<Vec3> {
            (0..n)
                .map(|_| {
                    Vec3::new(
                        rng.next_u64() as f32 / u64::MAX as f32,
                        rng.next_u64() as f32 / u64::MAX as f32,
                        rng.next_u64() as f32 / u64::MAX as f32,
                    )
                })
                .collect()
        };
        let (a, b) = (rnd(500), rnd(700));
        let one = |x: &[Vec3], y: &[Vec3]| -> Vec<f32> {
            x.iter().map(|p| y.iter().map(|q| p.distance(*q)).fold(f32::INFINITY, f32::min)).collect()
        };
        let (da, db) = (one(&a, &b), one(&b, &a));
        let cd = 0.5 * (da.iter().sum::<f32>() / 500.0 + db.iter().sum::<f32>() / 700.0);
        assert!((chamfer(&a, &b) - cd).abs() < 1e-5);
        let hd = da.iter().chain(&db).fold(0.0f32, |m, &d| m.max(d));
        assert_eq!(hausdorff(&a, &b), hd);
        assert_eq!(chamfer(&[], &[]), 0.0);
        assert!(chamfer(&a, &[]).is_infinite());
    }
}
