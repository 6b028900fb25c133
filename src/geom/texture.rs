//! Texture lookups, one convention for encoding and previews.

use glam::Vec2;
use glam::Vec3;

/// Bilinear lookup with wrap-around on both axes, RGB in [0, 1]. OBJ
/// convention: v = 0 is the bottom row of the image, (u, v) = (0, 1) the
/// top-left corner; texel centres sit at half-integer pixel coordinates.
/// `None` for a non-finite `uv`.
pub fn sample_bilinear(image: &image::RgbImage, uv: Vec2) -> Option<Vec3> {
    sample_bilinear_wrapped(image, uv, [Wrap::Repeat; 2])
}

/// How texel coordinates outside the image are brought back into it (glTF's
/// sampler wrap modes; OBJ repeats).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    #[default]
    Repeat,
    MirroredRepeat,
    ClampToEdge,
}

impl Wrap {
    fn texel(self, i: i64, n: i64) -> u32 {
        (match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m >= n {
                    2 * n - 1 - m
                } else {
                    m
                }
            }
        }) as u32
    }
}

/// [`sample_bilinear`] with the wrap modes along u and v.
pub fn sample_bilinear_wrapped(image: &image::RgbImage, uv: Vec2, wrap: [Wrap; 2]) -> Option<Vec3> {
    if !uv.is_finite() || image.width() == 0 || image.height() == 0 {
        return None;
    }
    let (w, h) = (image.width() as i64, image.height() as i64);
    let x = uv.x as f64 * w as f64 - 0.5;
    let y = (1.0 - uv.y as f64) * h as f64 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let texel = |xi: i64, yi: i64| {
        let p = image.get_pixel(wrap[0].texel(xi, w), wrap[1].texel(yi, h)).0;
        Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32) / 255.0
    };
    let (x0, y0) = (x0 as i64, y0 as i64);
    let top = texel(x0, y0).lerp(texel(x0 + 1, y0), fx);
    let bottom = texel(x0, y0 + 1).lerp(texel(x0 + 1, y0 + 1), fx);
    Some(top.lerp(bottom, fy))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_centres_exact_between_blended_and_wrapping() {
        // 2x1 image: left red, right blue.
        let img = image::RgbImage::from_fn(2, 1, |x, _| if x == 0 { image::Rgb([255, 0, 0]) } else { image::Rgb([0, 0, 255]) });
        let at = |u: f32| sample_bilinear(&img, Vec2::new(u, 0.5)).unwrap();
        assert!((at(0.25) - Vec3::X).length() < 1e-6, "left texel centre");
        assert!((at(0.75) - Vec3::Z).length() < 1e-6, "right texel centre");
        assert!((at(0.5) - Vec3::new(0.5, 0.0, 0.5)).length() < 1e-6, "halfway");
        // Across the seam at u = 0 (= 1), the two texels blend the same way.
        assert!((at(0.0) - at(1.0)).length() < 1e-6);
        assert!((at(0.0) - Vec3::new(0.5, 0.0, 0.5)).length() < 1e-6);
        assert!(sample_bilinear(&img, Vec2::new(f32::NAN, 0.0)).is_none());
    }

    #[test]
    fn clamped_and_mirrored_wrapping() {
        let img = image::RgbImage::from_fn(2, 1, |x, _| if x == 0 { image::Rgb([255, 0, 0]) } else { image::Rgb([0, 0, 255]) });
        let at = |u: f32, w: Wrap| sample_bilinear_wrapped(&img, Vec2::new(u, 0.5), [w, Wrap::Repeat]).unwrap();
        // Clamped: beyond the right edge stays blue, beyond the left red.
        assert!((at(1.7, Wrap::ClampToEdge) - Vec3::Z).length() < 1e-6);
        assert!((at(-0.4, Wrap::ClampToEdge) - Vec3::X).length() < 1e-6);
        // Mirrored: u = 1.25 is the mirror of 0.75 (blue), 1.75 of 0.25 (red).
        assert!((at(1.25, Wrap::MirroredRepeat) - Vec3::Z).length() < 1e-6);
        assert!((at(1.75, Wrap::MirroredRepeat) - Vec3::X).length() < 1e-6);
        // Repeat: 1.25 is 0.25 (red).
        assert!((at(1.25, Wrap::Repeat) - Vec3::X).length() < 1e-6);
    }
}
