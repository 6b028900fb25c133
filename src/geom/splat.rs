//! Points splatted into an orthographic depth image: per pixel, the nearest
//! of the points whose disc covers it. What a view of a level sees first
//! (the judge's inside seen, encode's facing share).

use glam::Vec3;

/// An orthographic view: screen axes (`right`, `up`), the direction towards
/// the eye (`toward`), the point at the image's centre, the pixel size and
/// the half-width in pixels (the image is `2 * half + 1` pixels square).
pub struct View {
    pub right: Vec3,
    pub up: Vec3,
    pub toward: Vec3,
    pub centre: Vec3,
    pub pixel: f32,
    pub half: i64,
}

/// A depth image: per pixel the nearness of the nearest splatted point
/// (its depth towards the eye; -inf where nothing is) and that point's index
/// (`u32::MAX` where nothing is).
pub struct DepthImage {
    pub size: usize,
    pub near: Vec<f32>,
    pub point: Vec<u32>,
}

impl DepthImage {
    /// `points` seen from `view`, each covering the pixels within `radius`
    /// (the units of the points) of it.
    pub fn splat(points: &[Vec3], view: &View, radius: f32) -> DepthImage {
        let half = view.half;
        let size = (2 * half + 1) as usize;
        let mut near = vec![f32::NEG_INFINITY; size * size];
        let mut point = vec![u32::MAX; size * size];
        let r = radius / view.pixel;
        let ri = r.ceil() as i64;
        for (i, &p) in points.iter().enumerate() {
            let d = p - view.centre;
            let (x, y, z) = (d.dot(view.right) / view.pixel + half as f32, d.dot(view.up) / view.pixel + half as f32, d.dot(view.toward));
            let (cx, cy) = (x.floor() as i64, y.floor() as i64);
            for py in (cy - ri).max(0)..=(cy + ri).min(size as i64 - 1) {
                for px in (cx - ri).max(0)..=(cx + ri).min(size as i64 - 1) {
                    let (dx, dy) = (px as f32 + 0.5 - x, py as f32 + 0.5 - y);
                    if dx * dx + dy * dy > r * r {
                        continue;
                    }
                    let k = py as usize * size + px as usize;
                    if z > near[k] {
                        near[k] = z;
                        point[k] = i as u32;
                    }
                }
            }
        }
        DepthImage { size, near, point }
    }
}
