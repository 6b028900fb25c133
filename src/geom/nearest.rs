//! Nearest-point queries over a fixed point set (a kiddo k-d tree): colour
//! transfer onto meshes, and the point-set distances of the metrics.

use glam::Vec3;

pub(crate) struct Nearest {
    /// None for an empty set (kiddo wants at least one point).
    tree: Option<kiddo::ImmutableKdTree<f32, 3>>,
}

impl Nearest {
    /// Points must be finite; indices returned by [`Nearest::nearest`] are
    /// positions in `points`.
    pub(crate) fn new(points: &[Vec3]) -> Self {
        let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
        Nearest { tree: (!coords.is_empty()).then(|| kiddo::ImmutableKdTree::new_from_slice(&coords)) }
    }

    /// The index of the point nearest to `p`, and its distance (None without points).
    pub(crate) fn nearest(&self, p: Vec3) -> Option<(u32, f32)> {
        let n = self.tree.as_ref()?.nearest_one::<kiddo::SquaredEuclidean>(&p.to_array());
        Some((n.item as u32, n.distance.sqrt()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_is_exact_on_grid_aligned_points_and_empty_sets() {
        // Voxel points share coordinates along whole planes (flat faces): the k-d
        // tree must still find the exact nearest, here against a brute-force scan.
        let pts: Vec<Vec3> = (0..40)
            .flat_map(|x| (0..40).flat_map(move |y| (0..3).map(move |z| Vec3::new(x as f32, y as f32, z as f32 * 0.5))))
            .collect();
        let tree = Nearest::new(&pts);
        let mut rng = crate::util::rng::Rng::new(7);
        for _ in 0..500 {
            let mut u = |scale: f64| (rng.uniform() * scale - 10.0) as f32;
            let q = Vec3::new(u(60.0), u(60.0), u(30.0));
            let (_, d) = tree.nearest(q).unwrap();
            let best = pts.iter().map(|p| p.distance(q)).fold(f32::INFINITY, f32::min);
            assert!((d - best).abs() < 1e-4, "nearest {d} vs brute force {best} at {q}");
        }
        assert!(Nearest::new(&[]).nearest(Vec3::ZERO).is_none());
    }
}
