//! @brief Contact sheets: the exemplar and its variants side by side from ONE
//! camera, each with a close-up of the same region, so detail and colour can
//! be judged at a glance.
//!
//! 1. **One camera.** The framing box is the union of every shape's active
//!    points (world units), so every tile shares scale and viewpoint and a
//!    larger variant is not shrunk to fit.
//! 2. **One close-up.** The region is where the exemplar's bounding-box centre
//!    falls on screen (for most exemplars, the middle of the surface facing
//!    the camera), magnified [`SheetOptions::zoom`] times in every column.
//! 3. **Layout.** Columns of (label, full view, close-up); the first column
//!    (the reference) has an orange frame.

use glam::Vec3;
use image::{Rgb, RgbImage};

use super::{render_points, OrientedPoints, RenderError, RenderOptions, Result, Zoom};
use crate::level::Level;

/// How a contact sheet is laid out.
#[derive(Clone, Debug, PartialEq)]
pub struct SheetOptions {
    /// Side of one square tile, pixels.
    pub tile: u32,
    /// Tiles per row of the sheet (each entry is one column of two tiles).
    pub columns: usize,
    /// Magnification of the close-up.
    pub zoom: f32,
    pub azimuth_deg: f32,
    pub elevation_deg: f32,
}

impl Default for SheetOptions {
    fn default() -> Self {
        SheetOptions { tile: 320, columns: 6, zoom: 4.0, azimuth_deg: 35.0, elevation_deg: 25.0 }
    }
}

const GAP: u32 = 6;
const LABEL: u32 = 18;
const FRAME: Rgb<u8> = Rgb([230, 120, 20]);
const SHEET_BG: Rgb<u8> = Rgb([255, 255, 255]);

/// Renders `entries` (name, level; the first is the reference) as one sheet.
pub fn contact_sheet(entries: &[(String, &Level)], opts: &SheetOptions) -> Result<RgbImage> {
    if entries.is_empty() {
        return Err(RenderError::Invalid("a contact sheet needs at least one level".into()));
    }
    let sets: Vec<OrientedPoints> = entries.iter().map(|(_, l)| crate::level::Level::surface_points(l)).collect();
    let bounds = |s: &OrientedPoints| {
        s.positions.iter().filter(|p| p.is_finite()).fold(None, |acc: Option<(Vec3, Vec3)>, &p| match acc {
            None => Some((p, p)),
            Some((lo, hi)) => Some((lo.min(p), hi.max(p))),
        })
    };
    let ref_box = bounds(&sets[0]).ok_or(RenderError::NoPoints)?;
    let fit_box = sets.iter().filter_map(bounds).fold(ref_box, |(lo, hi), (l, h)| (lo.min(l), hi.max(h)));
    let base = RenderOptions {
        width: opts.tile,
        height: opts.tile,
        azimuth_deg: opts.azimuth_deg,
        elevation_deg: opts.elevation_deg,
        fit_box: Some(fit_box),
        // The reference's vertical axis: one camera for all.
        up: Some(entries[0].1.frame.up),
        ..Default::default()
    };
    let centre = super::screen_fraction(0.5 * (ref_box.0 + ref_box.1), &base);
    let close = RenderOptions { zoom: Some(Zoom { centre, factor: opts.zoom }), ..base.clone() };

    let cols = opts.columns.max(1).min(entries.len()) as u32;
    let rows = entries.len().div_ceil(cols as usize) as u32;
    let cell_w = opts.tile + GAP;
    let cell_h = LABEL + 2 * opts.tile + GAP + GAP;
    let (w, h) = (GAP + cols * cell_w, GAP + rows * cell_h);
    super::check_size(&RenderOptions { width: w, height: h, ..Default::default() })?;
    let mut sheet = RgbImage::from_pixel(w, h, SHEET_BG);
    for (k, ((name, _), set)) in entries.iter().zip(&sets).enumerate() {
        let (cx, cy) = (GAP + (k as u32 % cols) * cell_w, GAP + (k as u32 / cols) * cell_h);
        // "name\nnote": the note (a variant's structure flags) in red at the
        // foot of its full view.
        let (name, note) = name.split_once('\n').unwrap_or((name.as_str(), ""));
        draw_text(&mut sheet, cx + 2, cy + 4, name, Rgb([30, 30, 30]));
        for (row, o) in [&base, &close].into_iter().enumerate() {
            let ty = cy + LABEL + row as u32 * (opts.tile + GAP);
            match render_points(set, o) {
                Ok(img) => image::imageops::replace(&mut sheet, &img, cx as i64, ty as i64),
                Err(RenderError::NoPoints) => {
                    let empty = RgbImage::from_pixel(opts.tile, opts.tile, Rgb(o.background));
                    image::imageops::replace(&mut sheet, &empty, cx as i64, ty as i64);
                    draw_text(&mut sheet, cx + 8, ty + opts.tile / 2, "empty", Rgb([150, 30, 30]));
                }
                Err(e) => return Err(e),
            }
            if k == 0 {
                frame(&mut sheet, cx, ty, opts.tile, FRAME);
            }
            if row == 0 && !note.is_empty() {
                draw_text(&mut sheet, cx + 6, ty + opts.tile - 22, note, Rgb([200, 30, 30]));
            }
        }
    }
    Ok(sheet)
}

fn frame(img: &mut RgbImage, x: u32, y: u32, side: u32, c: Rgb<u8>) {
    for t in 0..2u32 {
        for i in 0..side {
            for (px, py) in [(x + i, y + t), (x + i, y + side - 1 - t), (x + t, y + i), (x + side - 1 - t, y + i)] {
                if px < img.width() && py < img.height() {
                    img.put_pixel(px, py, c);
                }
            }
        }
    }
}

/// 5x7 glyphs, one byte per row (bit 4 = leftmost column), for the
/// characters a level or folder name holds; others draw as a box.
fn glyph(ch: char) -> [u8; 7] {
    match ch.to_ascii_uppercase() {
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1E],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        ' ' => [0; 7],
        _ => [0x1F, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1F],
    }
}

/// Draws `text` at (x, y) (top left) at twice the glyph size, clipped to the image.
fn draw_text(img: &mut RgbImage, x: u32, y: u32, text: &str, c: Rgb<u8>) {
    const S: u32 = 2;
    for (k, ch) in text.chars().enumerate() {
        let g = glyph(ch);
        let gx = x + k as u32 * 6 * S;
        for (row, bits) in g.iter().enumerate() {
            for col in 0..5u32 {
                if bits >> (4 - col) & 1 == 1 {
                    for dy in 0..S {
                        for dx in 0..S {
                            let (px, py) = (gx + col * S + dx, y + row as u32 * S + dy);
                            if px < img.width() && py < img.height() {
                                img.put_pixel(px, py, c);
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::IVec3;

    fn plate(colour: Vec3, size: i32) -> Level {
        let mut l = Level { resolution: 64, ..Default::default() };
        for x in 0..size {
            for y in 0..size {
                l.coords.push(IVec3::new(x, y, 10));
                l.offsets.push(Vec3::ZERO);
                l.normals.push(Vec3::Z);
                l.colours.push(colour);
                l.mask.push(1.0);
            }
        }
        l
    }

    #[test]
    fn one_camera_for_all_tiles_and_a_framed_reference() {
        let (a, b) = (plate(Vec3::new(0.9, 0.1, 0.1), 20), plate(Vec3::new(0.1, 0.1, 0.9), 40));
        let opts = SheetOptions { tile: 100, azimuth_deg: 0.0, elevation_deg: 0.0, ..Default::default() };
        let sheet = contact_sheet(&[("a".into(), &a), ("b".into(), &b)], &opts).unwrap();
        assert_eq!(sheet.width(), GAP + 2 * (100 + GAP));
        let count = |x0: u32, c: fn(&Rgb<u8>) -> bool| {
            let mut n = 0;
            for y in GAP + LABEL..GAP + LABEL + 100 {
                for x in x0..x0 + 100 {
                    n += c(sheet.get_pixel(x, y)) as u32;
                }
            }
            n
        };
        // (The reference's orange frame is not red: its green is 120.)
        let red = count(GAP, |p| p[0] > 150 && p[1] < 90 && p[2] < 100);
        let blue = count(GAP + 100 + GAP, |p| p[2] > 150 && p[0] < 100);
        // The same camera: the plate of twice the side covers ~4x the pixels.
        assert!(red > 0 && (blue as f64 / red as f64 - 4.0).abs() < 0.8, "red {red} blue {blue}");
        assert_eq!(*sheet.get_pixel(GAP, GAP + LABEL), FRAME);
        assert!(contact_sheet(&[], &opts).is_err());
    }
}
