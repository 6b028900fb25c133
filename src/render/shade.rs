//! Shading the visible surface: ambient, headlight and key light over the colour.

use super::*;

/// Lit colour of a surface element with normal `n` (any length, any sign)
/// and RGB `colour` in [0,1].
#[inline]
pub(super) fn shade(n: Vec3, colour: Vec3, view: &View) -> [u8; 3] {
    let mut n = n.normalize_or_zero();
    if n == Vec3::ZERO {
        n = view.back; // no normal: light it as if it faced the viewer
    }
    if n.dot(view.back) < 0.0 {
        n = -n; // two-sided
    }
    let light = AMBIENT + HEADLIGHT * n.dot(view.back) + KEY * n.dot(view.key).max(0.0);
    // + 0.5 then truncation rounds these non-negative values (no libm call).
    let c = colour.clamp(Vec3::ZERO, Vec3::ONE) * (light.min(1.0) * 255.0) + 0.5;
    [c.x as u8, c.y as u8, c.z as u8]
}

/// Turns merged keys into an image, shading each covered pixel once with
/// `colour(x, y, id)`.
pub(super) fn resolve<F>(keys: &[u64], grid: &Grid, opts: &RenderOptions, colour: F) -> RgbImage
where
    F: Fn(u32, u32, usize) -> [u8; 3] + Sync,
{
    let w = opts.width as usize;
    let mut buf = vec![0u8; w * opts.height as usize * 3];
    buf.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            let k = keys[grid.at(x, y)];
            let rgb = if k == EMPTY {
                opts.background
            } else {
                colour(x as u32, y as u32, (k & 0xFFFF_FFFF) as usize)
            };
            px.copy_from_slice(&rgb);
        }
    });
    RgbImage::from_raw(opts.width, opts.height, buf).expect("buffer sized to the image")
}
