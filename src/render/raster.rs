//! Rasterising into a visibility buffer: depth-and-id keys, tiled buffers, discs for
//! points, triangles for meshes.

use super::*;

/// Visibility key: nearer wins the integer `min`, then the lower id.
#[inline]
pub(super) fn key(dist: f32, id: usize) -> u64 {
    // Positive f32 bit patterns order like their values; -0.0 and rounding
    // noise below zero go to 0.
    let d = if dist > 0.0 { dist } else { 0.0 };
    ((d.to_bits() as u64) << 32) | id as u64
}

/// Storage order of a visibility buffer: square tiles of `TILE` x `TILE`
/// pixels, row-major inside a tile and tiles row-major over the image. A
/// splat or a triangle then touches a few tiles (a few pages) rather than one
/// page per image row, which measured faster than a row-major buffer
/// (docs/performance.md).
pub(super) struct Grid {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) tiles_x: usize,
    /// Keys in a buffer (the image padded to whole tiles).
    pub(super) len: usize,
}

pub(super) const TILE_SHIFT: usize = 4;
pub(super) const TILE: usize = 1 << TILE_SHIFT;

impl Grid {
    pub(super) fn new(opts: &RenderOptions) -> Grid {
        let (w, h) = (opts.width as usize, opts.height as usize);
        let tiles_x = w.div_ceil(TILE);
        Grid { w, h, tiles_x, len: tiles_x * h.div_ceil(TILE) * TILE * TILE }
    }

    /// Buffer index of pixel (x, y); both must be inside the image.
    #[inline]
    pub(super) fn at(&self, x: usize, y: usize) -> usize {
        let tile = (y >> TILE_SHIFT) * self.tiles_x + (x >> TILE_SHIFT);
        (tile << (2 * TILE_SHIFT)) | ((y & (TILE - 1)) << TILE_SHIFT) | (x & (TILE - 1))
    }
}

/// Runs `draw` over slices of `0..n` in parallel, each worker into its own
/// buffer, and merges the buffers by `min`.
pub(super) fn visibility<F>(n: usize, grid: &Grid, draw: F) -> Vec<u64>
where
    F: Fn(std::ops::Range<usize>, &mut [u64]) + Sync,
{
    // Blocks of consecutive primitives: each worker walks them in storage
    // order, which for voxels is spatially coherent. `fold` makes one buffer
    // per piece of work rayon actually splits off (about one per thread
    // unless threads steal), so a busy core does not hold up the others.
    pub(super) const BLOCK: usize = 1 << 15;
    let blocks = n.div_ceil(BLOCK);
    (0..blocks)
        .into_par_iter()
        .fold(
            || vec![EMPTY; grid.len],
            |mut zb, b| {
                draw(b * BLOCK..((b + 1) * BLOCK).min(n), &mut zb);
                zb
            },
        )
        .reduce_with(|mut a, b| {
            a.par_chunks_mut(1 << 16).zip(b.par_chunks(1 << 16)).for_each(|(a, b)| {
                a.iter_mut().zip(b).for_each(|(a, &b)| *a = (*a).min(b));
            });
            a
        })
        .unwrap_or_else(|| vec![EMPTY; grid.len])
}

/// `x.floor() as i32` without a libm call (the baseline x86-64 target has
/// no SSE4.1 rounding instruction); saturates far outside the image.
#[inline]
pub(super) fn floor_i(x: f32) -> i32 {
    let i = x as i32;
    i - ((i as f32) > x) as i32
}

/// `x.ceil() as i32`, like [`floor_i`].
#[inline]
pub(super) fn ceil_i(x: f32) -> i32 {
    let i = x as i32;
    i + ((i as f32) < x) as i32
}

/// Covers every pixel whose centre lies within `r` pixels of (sx, sy), and
/// always the pixel holding the centre, so sub-pixel splats never vanish.
#[inline]
pub(super) fn splat_disc(zb: &mut [u64], grid: &Grid, sx: f32, sy: f32, r: f32, k: u64) {
    let (w, h) = (grid.w as i32, grid.h as i32);
    let (cx, cy) = (floor_i(sx), floor_i(sy));
    if (0..w).contains(&cx) && (0..h).contains(&cy) {
        let i = grid.at(cx as usize, cy as usize);
        zb[i] = zb[i].min(k);
    }
    // Test every pixel centre in the disc's bounding box: no square root,
    // and for the usual sub-pixel to few-pixel radii the box is tiny.
    let r2 = r * r;
    let x0 = ceil_i(sx - r - 0.5).max(0);
    let x1 = floor_i(sx + r - 0.5).min(w - 1);
    let y0 = ceil_i(sy - r - 0.5).max(0);
    let y1 = floor_i(sy + r - 0.5).min(h - 1);
    for y in y0..=y1 {
        let dy = y as f32 + 0.5 - sy;
        let rest = r2 - dy * dy;
        for x in x0..=x1 {
            let dx = x as f32 + 0.5 - sx;
            if dx * dx <= rest {
                let i = grid.at(x as usize, y as usize);
                zb[i] = zb[i].min(k);
            }
        }
    }
}

/// Twice the signed area of (a, b, p) in screen space.
#[inline]
pub(super) fn edge(a: Vec3, b: Vec3, px: f32, py: f32) -> f32 {
    (b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x)
}

/// Covers the pixels whose centres lie inside the triangle (edges included;
/// a pixel on a shared edge is then decided by the z-test and the id).
/// Vertices: (pixel x, pixel y, distance).
pub(super) fn raster_triangle(zb: &mut [u64], grid: &Grid, a: Vec3, b: Vec3, c: Vec3, id: usize) {
    let area = edge(a, b, c.x, c.y);
    if area.is_nan() || area.abs() <= 1e-12 {
        return; // degenerate in view, or NaN
    }
    let inv = 1.0 / area;
    let lo = a.min(b).min(c);
    let hi = a.max(b).max(c);
    let x0 = ceil_i(lo.x - 0.5).max(0);
    let x1 = floor_i(hi.x - 0.5).min(grid.w as i32 - 1);
    let y0 = ceil_i(lo.y - 0.5).max(0);
    let y1 = floor_i(hi.y - 0.5).min(grid.h as i32 - 1);
    for y in y0..=y1 {
        let py = y as f32 + 0.5;
        for x in x0..=x1 {
            let px = x as f32 + 0.5;
            // Normalised barycentrics: all >= 0 inside, whatever the winding.
            let wa = edge(b, c, px, py) * inv;
            let wb = edge(c, a, px, py) * inv;
            let wc = edge(a, b, px, py) * inv;
            if wa >= 0.0 && wb >= 0.0 && wc >= 0.0 {
                let i = grid.at(x as usize, y as usize);
                zb[i] = zb[i].min(key(wa * a.z + wb * b.z + wc * c.z, id));
            }
        }
    }
}

/// Barycentric weights of screen point `p` in (a, b, c), clamped into the
/// triangle and summing to 1.
pub(super) fn barycentric(a: Vec3, b: Vec3, c: Vec3, p: Vec2) -> Vec3 {
    let area = edge(a, b, c.x, c.y);
    let wts = Vec3::new(edge(b, c, p.x, p.y), edge(c, a, p.x, p.y), edge(a, b, p.x, p.y)) / area;
    let wts = wts.max(Vec3::ZERO);
    let sum = wts.x + wts.y + wts.z;
    if sum > 0.0 && sum.is_finite() {
        wts / sum
    } else {
        Vec3::splat(1.0 / 3.0)
    }
}
