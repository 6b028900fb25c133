//! The camera: the view of the shape (azimuth, elevation, orthographic) and the fit
//! of its extent into the picture.

use super::*;

/// Orthonormal camera basis in world space.
pub(super) struct View {
    pub(super) right: Vec3,
    pub(super) up: Vec3,
    /// Towards the camera (the view direction is `-back`).
    pub(super) back: Vec3,
    /// Towards the key light, world space.
    pub(super) key: Vec3,
}

impl View {
    pub(super) fn new(opts: &RenderOptions) -> View {
        let az = opts.azimuth_deg.to_radians();
        let el = opts.elevation_deg.clamp(-89.9, 89.9).to_radians();
        let back = Vec3::new(az.sin() * el.cos(), el.sin(), az.cos() * el.cos());
        let right = Vec3::Y.cross(back).normalize();
        let up = back.cross(right);
        let k = KEY_LIGHT_VIEW.normalize();
        let key = (k.x * right + k.y * up + k.z * back).normalize();
        // The basis above is for a +y-up world; a +z-up world takes it
        // rotated so that its +z plays +y (and its -y the front's +z).
        let to_world = |v: Vec3| match opts.up.unwrap_or_default() {
            crate::level::Up::Y => v,
            crate::level::Up::Z => Vec3::new(v.x, -v.z, v.y),
        };
        View { right: to_world(right), up: to_world(up), back: to_world(back), key: to_world(key) }
    }
}

/// Screen-aligned bounds of the finite positions, world units.
pub(super) struct Extents {
    pub(super) lo: Vec3,
    pub(super) hi: Vec3,
}

impl Extents {
    pub(super) fn of(positions: &[Vec3], view: &View) -> Extents {
        let empty = || (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let (lo, hi) = positions
            .par_chunks(1 << 16)
            .map(|chunk| {
                chunk.iter().filter(|p| p.is_finite()).fold(empty(), |(lo, hi), &p| {
                    let q = Vec3::new(p.dot(view.right), p.dot(view.up), p.dot(view.back));
                    (lo.min(q), hi.max(q))
                })
            })
            .reduce(empty, |a, b| (a.0.min(b.0), a.1.max(b.1)));
        Extents { lo, hi }
    }

    pub(super) fn is_empty(&self) -> bool {
        // Nothing finite was seen: lo stayed +inf, hi -inf.
        self.lo.x > self.hi.x
    }
}

/// World-to-pixel mapping fitted to the extents.
pub(super) struct Fit {
    /// Pixels per world unit.
    pub(super) scale: f32,
    /// Pixel position of the world origin.
    pub(super) origin: Vec2,
    /// Largest `dot(p, back)`: the plane nearest the camera, world units.
    pub(super) near: f32,
}

impl Fit {
    /// `pad`: world units added around the extents (the splat radius).
    pub(super) fn new(e: &Extents, pad: f32, opts: &RenderOptions) -> Fit {
        let (w, h) = (opts.width as f32, opts.height as f32);
        let size = Vec2::new(e.hi.x - e.lo.x, e.hi.y - e.lo.y) + 2.0 * pad;
        let avail = Vec2::new(w, h) * (1.0 - 2.0 * MARGIN);
        let sx = if size.x > 0.0 { avail.x / size.x } else { f32::INFINITY };
        let sy = if size.y > 0.0 { avail.y / size.y } else { f32::INFINITY };
        let mut scale = sx.min(sy);
        if !scale.is_finite() {
            // A single point and no splat size: any scale shows it as a dot.
            scale = 1.0;
        }
        let mid = Vec2::new(e.lo.x + e.hi.x, e.lo.y + e.hi.y) * 0.5;
        Fit { scale, origin: Vec2::new(w * 0.5 - mid.x * scale, h * 0.5 + mid.y * scale), near: e.hi.z }
    }

    /// The fit of `opts`: to `fit_box` when given (depth still from the
    /// object's own extents), else to the object; then the close-up, if any.
    pub(super) fn framed(e: &Extents, pad: f32, opts: &RenderOptions, view: &View) -> Fit {
        let mut fit = match opts.fit_box {
            Some((lo, hi)) => {
                let corners: Vec<Vec3> =
                    (0..8).map(|k| Vec3::new([lo.x, hi.x][k & 1], [lo.y, hi.y][(k >> 1) & 1], [lo.z, hi.z][k >> 2])).collect();
                let b = Extents::of(&corners, view);
                if b.is_empty() {
                    Fit::new(e, pad, opts)
                } else {
                    Fit { near: e.hi.z, ..Fit::new(&b, pad, opts) }
                }
            }
            None => Fit::new(e, pad, opts),
        };
        if let Some(z) = opts.zoom.filter(|z| z.factor.is_finite() && z.factor > 0.0) {
            // Pixel (c) of the framed image goes to the image centre.
            let c = z.centre * Vec2::new(opts.width as f32, opts.height as f32);
            let mid = Vec2::new(opts.width as f32, opts.height as f32) * 0.5;
            fit.origin = mid + (fit.origin - c) * z.factor;
            fit.scale *= z.factor;
        }
        fit
    }

    /// (pixel x, pixel y, distance behind the nearest plane in world units).
    #[inline]
    pub(super) fn project(&self, view: &View, p: Vec3) -> (f32, f32, f32) {
        (
            self.origin.x + p.dot(view.right) * self.scale,
            self.origin.y - p.dot(view.up) * self.scale,
            self.near - p.dot(view.back),
        )
    }
}
