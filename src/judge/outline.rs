//! How alike two shapes look from outside: their outlines from the views of
//! the seen-through measure ([`super::seen_through`]: 3 elevations, 8
//! azimuths), both drawn with the exemplar's centre at the centre of every
//! view. A person tells a variant from the exemplar by its outline first: a
//! house whose hidden courtyard floor moved, or whose stones shifted by a
//! voxel, is the house again, though a tenth of its surface voxels moved; a
//! tower broken lower on one side shows a new outline from that side.
//!
//! Lengths are in voxels of the level measured, scaled with its resolution
//! against [`super::levels::STRUCTURE_RESOLUTION`]: one pixel is one
//! voxel of the 64^3 level.

use glam::Vec3;
use rayon::prelude::*;

use super::levels::STRUCTURE_RESOLUTION;
use super::thresholds::THRESHOLDS;
use crate::level::Level;

/// A surface point covers the pixels within this radius of it (pixels).
const SPLAT_RADIUS: f32 = 1.0;


/// The worst view's share of the pixels either outline covers where the two
/// differ (`THRESHOLDS.outline_tolerance`): 0 for the same outline from every view, 1 for
/// outlines that nowhere meet. `shape` and `exemplar` are levels of the same
/// resolution and frame; 1 when either has no surface.
pub fn outline_difference(shape: &Level, exemplar: &Level) -> f64 {
    let points = |l: &Level| -> Vec<Vec3> { (0..l.len()).filter(|&i| l.mask[i] > 0.0).map(|i| l.point_voxels(i)).collect() };
    let (a, b) = (points(shape), points(exemplar));
    if a.is_empty() || b.is_empty() {
        return 1.0;
    }
    let pixel = exemplar.resolution as f32 / STRUCTURE_RESOLUTION as f32;
    let centre = b.iter().fold(Vec3::ZERO, |s, &p| s + p) / b.len() as f32;
    let reach = a.iter().chain(&b).map(|p| p.distance(centre)).fold(0.0, f32::max);
    let half = (reach / pixel).ceil() as i64 + 2;
    let up = exemplar.frame.up.axis();
    super::seen_through::view_directions(up)
        .into_par_iter()
        .map(|toward| {
            let view = View::new(up, toward, centre, pixel, half);
            let (oa, ob) = (view.outline(&a), view.outline(&b));
            view.difference(&oa, &ob)
        })
        .reduce(|| 0.0, f64::max)
}

/// An orthographic view: its screen axes, centre, pixel size (voxels) and
/// half-width (pixels).
struct View {
    right: Vec3,
    screen_up: Vec3,
    centre: Vec3,
    pixel: f32,
    half: i64,
}

impl View {
    fn new(up: Vec3, toward: Vec3, centre: Vec3, pixel: f32, half: i64) -> View {
        let right = up.cross(toward).try_normalize().unwrap_or_else(|| toward.any_orthonormal_vector());
        View { right, screen_up: toward.cross(right), centre, pixel, half }
    }

    fn size(&self) -> usize {
        (2 * self.half + 1) as usize
    }

    /// The pixels the points cover.
    fn outline(&self, points: &[Vec3]) -> Vec<bool> {
        let n = self.size() as i64;
        let mut covered = vec![false; (n * n) as usize];
        let r = SPLAT_RADIUS.ceil() as i64;
        for &p in points {
            let d = p - self.centre;
            let x = d.dot(self.right) / self.pixel + self.half as f32;
            let y = d.dot(self.screen_up) / self.pixel + self.half as f32;
            let (cx, cy) = (x.floor() as i64, y.floor() as i64);
            for py in (cy - r).max(0)..=(cy + r).min(n - 1) {
                for px in (cx - r).max(0)..=(cx + r).min(n - 1) {
                    let (dx, dy) = (px as f32 + 0.5 - x, py as f32 + 0.5 - y);
                    if dx * dx + dy * dy <= SPLAT_RADIUS * SPLAT_RADIUS {
                        covered[(py * n + px) as usize] = true;
                    }
                }
            }
        }
        covered
    }

    /// Share of the pixels either outline covers that one covers with none
    /// of the other's within `THRESHOLDS.outline_tolerance`.
    fn difference(&self, a: &[bool], b: &[bool]) -> f64 {
        let n = self.size() as i64;
        let near = |o: &[bool], x: i64, y: i64| {
            (-THRESHOLDS.outline_tolerance..=THRESHOLDS.outline_tolerance).any(|dy| {
                (-THRESHOLDS.outline_tolerance..=THRESHOLDS.outline_tolerance).any(|dx| {
                    let (u, v) = (x + dx, y + dy);
                    u >= 0 && v >= 0 && u < n && v < n && o[(v * n + u) as usize]
                })
            })
        };
        let (mut union, mut differ) = (0usize, 0usize);
        for y in 0..n {
            for x in 0..n {
                let k = (y * n + x) as usize;
                if !(a[k] || b[k]) {
                    continue;
                }
                union += 1;
                if (a[k] && !near(b, x, y)) || (b[k] && !near(a, x, y)) {
                    differ += 1;
                }
            }
        }
        if union == 0 {
            0.0
        } else {
            differ as f64 / union as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::synthetic::sphere_union;
    use glam::Vec3;

    #[test]
    fn the_same_outline_reads_zero_a_ball_added_or_moved_reads_a_share_of_it() {
        let one = sphere_union(64, &[(Vec3::new(-0.3, 0.0, 0.0), 0.3)]);
        assert_eq!(outline_difference(&one, &one), 0.0);
        // A ball beside it: from every view but those along the axis
        // through both, a new outline.
        let two = sphere_union(64, &[(Vec3::new(-0.3, 0.0, 0.0), 0.3), (Vec3::new(0.4, 0.0, 0.0), 0.2)]);
        let added = outline_difference(&two, &one);
        assert!(added > 0.2, "{added}");
        // The same ball moved by a voxel: within the tolerance.
        let nudged = sphere_union(64, &[(Vec3::new(-0.3 + 1.0 / 64.0, 0.0, 0.0), 0.3)]);
        let d = outline_difference(&nudged, &one);
        assert!(d < 0.02, "{d}");
        // Moved by a tenth of the box: a new place.
        let moved = sphere_union(64, &[(Vec3::new(-0.1, 0.0, 0.0), 0.3)]);
        assert!(outline_difference(&moved, &one) > 0.1);
        let mut empty = one.clone();
        empty.mask.iter_mut().for_each(|m| *m = 0.0);
        assert_eq!(outline_difference(&empty, &one), 1.0);
    }
}
