//! @brief Shaded PNG previews of a level's oriented, coloured points and of a
//! triangle mesh, so that a user (or a test, or a report) can see a result
//! without opening a DCC tool.
//!
//! Both renderers share one fixed-function pipeline, in three steps:
//!
//! 1. **Fit.** An orthographic camera orbits the object (y up; `azimuth_deg`
//!    turns about +y starting from a front view down -z, `elevation_deg` looks
//!    down from above). Every point or vertex is projected once to find the
//!    screen-space extents, and the view is scaled so that those extents
//!    (plus the splat radius) fill the image less a small margin. Orthographic
//!    because a preview should show proportions, not perspective.
//! 2. **Visibility.** Each worker thread rasterises a contiguous slice of the
//!    primitives (screen-space disc splats, or triangles) into its own
//!    *visibility buffer* of `u64` keys, `depth_bits << 32 | primitive_id`,
//!    keeping the minimum per pixel. Depth is the non-negative distance from
//!    the nearest plane as an `f32`, whose bit pattern orders like the value,
//!    so one integer `min` is the z-test and ties break by id, which makes the
//!    picture independent of how the work was split. The per-thread buffers
//!    are merged with the same `min`. No locks, no atomics.
//! 3. **Shading.** Only the primitive that won each pixel is shaded: its
//!    normal, turned to face the viewer (two-sided, so flipped normals still
//!    show), lit by a headlight and a key light from the upper left (Lambert
//!    plus a little ambient), times its colour.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use image::RgbImage;
use rayon::prelude::*;

use crate::geom::points::OrientedPoints;
use crate::level::Level;
use crate::io::mesh::{Mesh, MeshColours};

mod contact;
pub mod report;
pub use contact::{contact_sheet, SheetOptions};

/// Largest accepted image side, pixels.
pub const MAX_SIDE: u32 = 16384;
/// Largest accepted image, pixels in all: each worker thread holds an 8-byte
/// key per pixel, so this bounds memory at 512 MiB per thread.
pub const MAX_PIXELS: u64 = 1 << 26;

/// Fraction of the image left empty on each side around the fitted object.
const MARGIN: f32 = 0.04;
/// Lighting weights (dimensionless; at most ~1 summed, results are clamped).
const AMBIENT: f32 = 0.14;
const HEADLIGHT: f32 = 0.40;
const KEY: f32 = 0.58;
/// Direction *towards* the key light in view space (x right, y up, z towards
/// the viewer): upper left and in front, the usual studio key.
pub const KEY_LIGHT_VIEW: Vec3 = Vec3::new(-0.45, 0.65, 0.62);
/// Colour of a mesh without colours or texture, RGB in [0, 1].
const MESH_GREY: Vec3 = Vec3::new(0.78, 0.78, 0.78);
/// Key of a pixel nothing covers.
const EMPTY: u64 = u64::MAX;

/// How a preview is framed and drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Camera orbit about the vertical (+y) axis, degrees; 0 looks at the
    /// front (down -z), positive turns the camera towards +x.
    pub azimuth_deg: f32,
    /// Camera height above the horizontal plane, degrees (clamped to +-89.9).
    pub elevation_deg: f32,
    /// Splat radius in voxel sizes (multiples of [`OrientedPoints::spacing`]).
    /// 0.9 leaves no holes in a one-point-per-voxel surface sampling (a test
    /// checks it) while keeping splats small enough to show detail.
    pub point_size: f32,
    /// Colour of pixels that nothing covers, 8-bit RGB.
    pub background: [u8; 3],
    /// Frame this world-space box (its 8 corners) instead of the object's
    /// own extents: every image rendered with the same box and angles shares
    /// one camera (a contact sheet).
    pub fit_box: Option<(Vec3, Vec3)>,
    /// Close-up: after framing, magnify by `factor` about the point at
    /// `centre` (fractions of the framed image's width and height, 0..1).
    pub zoom: Option<Zoom>,
    /// The vertical axis of the world: the camera orbits it. None: the
    /// data's own (a level's frame; +y for meshes and bare points).
    pub up: Option<crate::level::Up>,
}

/// A close-up of a framed view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Zoom {
    pub centre: Vec2,
    pub factor: f32,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 800,
            height: 800,
            azimuth_deg: 35.0,
            elevation_deg: 25.0,
            point_size: 0.9,
            background: [236, 236, 240],
            fit_box: None,
            zoom: None,
            up: None,
        }
    }
}

/// What can go wrong while making or writing a preview.
#[derive(thiserror::Error, Debug)]
pub enum RenderError {
    #[error("nothing to render: no active voxels")]
    NoPoints,
    #[error("nothing to render: the mesh has no triangles")]
    NoTriangles,
    #[error(
        "bad image size {width}x{height}: each side must be 1..={MAX_SIDE} pixels \
         and the image at most {MAX_PIXELS} pixels"
    )]
    BadSize { width: u32, height: u32 },
    #[error("bad render input: {0}")]
    Invalid(String),
    #[error("cannot encode {} as PNG: {source}", path.display())]
    Encode { path: PathBuf, source: image::ImageError },
}

pub type Result<T> = std::result::Result<T, RenderError>;


/// Renders a level's active voxels as lit splats (see [`render_points`]).
pub fn render_level(level: &Level, opts: &RenderOptions) -> Result<RgbImage> {
    let opts = RenderOptions { up: opts.up.or(Some(level.frame.up)), ..opts.clone() };
    render_points(&OrientedPoints::from_level(level), &opts)
}

/// Renders oriented points as z-buffered, lit screen-space disc splats of
/// radius `opts.point_size * points.spacing` (world units, projected).
/// Points with a non-finite position are skipped.
pub fn render_points(points: &OrientedPoints, opts: &RenderOptions) -> Result<RgbImage> {
    check_size(opts)?;
    let n = points.len();
    if n == 0 {
        return Err(RenderError::NoPoints);
    }
    if points.normals.len() != n || points.colours.len() != n {
        return Err(RenderError::Invalid(format!(
            "{n} positions but {} normals and {} colours",
            points.normals.len(),
            points.colours.len()
        )));
    }
    if n >= u32::MAX as usize {
        return Err(RenderError::Invalid(format!("{n} points is more than a preview can hold")));
    }
    if !(opts.point_size.is_finite() && opts.point_size > 0.0) {
        return Err(RenderError::Invalid(format!("point size {} must be > 0", opts.point_size)));
    }
    if !(points.spacing.is_finite() && points.spacing >= 0.0) {
        return Err(RenderError::Invalid(format!("point spacing {} must be >= 0", points.spacing)));
    }

    let view = View::new(opts);
    let extents = Extents::of(&points.positions, &view);
    if extents.is_empty() {
        return Err(RenderError::Invalid("every point position is NaN or infinite".into()));
    }
    let radius_world = opts.point_size * points.spacing;
    let fit = Fit::framed(&extents, radius_world, opts, &view);
    let radius_px = radius_world * fit.scale;
    log::debug!("rendering {n} points at {}x{}, splat radius {radius_px:.2} px", opts.width, opts.height);
    let grid = Grid::new(opts);

    let keys = visibility(n, &grid, |range, zb| {
        for id in range {
            let p = points.positions[id];
            if !p.is_finite() {
                continue;
            }
            let (sx, sy, dist) = fit.project(&view, p);
            splat_disc(zb, &grid, sx, sy, radius_px, key(dist, id));
        }
    });

    Ok(resolve(&keys, &grid, opts, |_, _, id| shade(points.normals[id], points.colours[id], &view)))
}

/// Renders a triangle mesh, flat shaded by face normals (a preview should
/// show the facets that are really there). Colour: the texture sampled
/// bilinearly at the interpolated UV if present, else interpolated vertex or
/// corner colours, else light grey.
pub fn render_mesh(mesh: &Mesh, opts: &RenderOptions) -> Result<RgbImage> {
    check_size(opts)?;
    let nt = mesh.triangles.len();
    if nt == 0 {
        return Err(RenderError::NoTriangles);
    }
    if nt >= u32::MAX as usize {
        return Err(RenderError::Invalid(format!("{nt} triangles is more than a preview can hold")));
    }
    let nv = mesh.positions.len();
    if let Some(t) = mesh.triangles.par_iter().find_any(|t| t.iter().any(|&v| v as usize >= nv)) {
        return Err(RenderError::Invalid(format!("triangle {t:?} refers past the mesh's {nv} vertices")));
    }
    match &mesh.colours {
        MeshColours::PerVertex(c) if c.len() != nv => {
            return Err(RenderError::Invalid(format!("{} vertex colours for {nv} vertices", c.len())))
        }
        MeshColours::PerCorner(c) if c.len() != 3 * nt => {
            return Err(RenderError::Invalid(format!("{} corner colours for {nt} triangles", c.len())))
        }
        _ => {}
    }
    if let Some(t) = &mesh.texture {
        if t.uvs.len() != 3 * nt {
            return Err(RenderError::Invalid(format!("{} texture UVs for {nt} triangles", t.uvs.len())));
        }
        if !t.triangle_image.is_empty() && t.triangle_image.len() != nt {
            return Err(RenderError::Invalid(format!("{} texture image indices for {nt} triangles", t.triangle_image.len())));
        }
    }

    let view = View::new(opts);
    let extents = Extents::of(&mesh.positions, &view);
    if extents.is_empty() {
        return Err(RenderError::Invalid("every vertex position is NaN or infinite".into()));
    }
    let fit = Fit::framed(&extents, 0.0, opts, &view);
    // Screen x, y (pixels) and distance from the nearest plane (world units).
    let screen: Vec<Vec3> = mesh
        .positions
        .par_iter()
        .map(|&p| {
            let (x, y, d) = fit.project(&view, p);
            Vec3::new(x, y, d)
        })
        .collect();
    let grid = Grid::new(opts);

    let keys = visibility(nt, &grid, |range, zb| {
        for id in range {
            let [a, b, c] = mesh.triangles[id].map(|v| screen[v as usize]);
            raster_triangle(zb, &grid, a, b, c, id);
        }
    });

    Ok(resolve(&keys, &grid, opts, |x, y, id| {
        let tri = mesh.triangles[id];
        let [a, b, c] = tri.map(|v| screen[v as usize]);
        let wts = barycentric(a, b, c, Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
        let colour = mesh.colour_at(id, wts).unwrap_or(MESH_GREY);
        let [pa, pb, pc] = tri.map(|v| mesh.positions[v as usize]);
        shade((pb - pa).cross(pc - pa), colour, &view)
    }))
}

/// Where world point `p` falls in an image framed by `opts` (fractions of
/// width and height, before any zoom): the centre of a close-up.
pub fn screen_fraction(p: Vec3, opts: &RenderOptions) -> Vec2 {
    let view = View::new(opts);
    let e = Extents::of(&[p], &view);
    let fit = Fit::framed(&e, 0.0, &RenderOptions { zoom: None, ..opts.clone() }, &view);
    let (x, y, _) = fit.project(&view, p);
    Vec2::new(x / opts.width.max(1) as f32, y / opts.height.max(1) as f32)
}

/// The size of the previews written beside level files and meshes.
pub fn preview_options() -> RenderOptions {
    RenderOptions { width: 640, height: 640, ..Default::default() }
}

/// Writes `img` as a PNG at `path`, atomically ([`crate::util::fs::write_file`]):
/// encoded in memory first, so an encoding failure writes nothing.
pub fn save_png(img: &RgbImage, path: &Path) -> crate::Result<()> {
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|source| RenderError::Encode { path: path.to_path_buf(), source })?;
    crate::util::fs::write_file(path, bytes.into_inner())
}

fn check_size(opts: &RenderOptions) -> Result<()> {
    let (width, height) = (opts.width, opts.height);
    let ok = (1..=MAX_SIDE).contains(&width)
        && (1..=MAX_SIDE).contains(&height)
        && width as u64 * height as u64 <= MAX_PIXELS;
    if ok {
        Ok(())
    } else {
        Err(RenderError::BadSize { width, height })
    }
}

/// Orthonormal camera basis in world space.
struct View {
    right: Vec3,
    up: Vec3,
    /// Towards the camera (the view direction is `-back`).
    back: Vec3,
    /// Towards the key light, world space.
    key: Vec3,
}

impl View {
    fn new(opts: &RenderOptions) -> View {
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
struct Extents {
    lo: Vec3,
    hi: Vec3,
}

impl Extents {
    fn of(positions: &[Vec3], view: &View) -> Extents {
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

    fn is_empty(&self) -> bool {
        // Nothing finite was seen: lo stayed +inf, hi -inf.
        self.lo.x > self.hi.x
    }
}

/// World-to-pixel mapping fitted to the extents.
struct Fit {
    /// Pixels per world unit.
    scale: f32,
    /// Pixel position of the world origin.
    origin: Vec2,
    /// Largest `dot(p, back)`: the plane nearest the camera, world units.
    near: f32,
}

impl Fit {
    /// `pad`: world units added around the extents (the splat radius).
    fn new(e: &Extents, pad: f32, opts: &RenderOptions) -> Fit {
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
    fn framed(e: &Extents, pad: f32, opts: &RenderOptions, view: &View) -> Fit {
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
    fn project(&self, view: &View, p: Vec3) -> (f32, f32, f32) {
        (
            self.origin.x + p.dot(view.right) * self.scale,
            self.origin.y - p.dot(view.up) * self.scale,
            self.near - p.dot(view.back),
        )
    }
}

/// Visibility key: nearer wins the integer `min`, then the lower id.
#[inline]
fn key(dist: f32, id: usize) -> u64 {
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
struct Grid {
    w: usize,
    h: usize,
    tiles_x: usize,
    /// Keys in a buffer (the image padded to whole tiles).
    len: usize,
}

const TILE_SHIFT: usize = 4;
const TILE: usize = 1 << TILE_SHIFT;

impl Grid {
    fn new(opts: &RenderOptions) -> Grid {
        let (w, h) = (opts.width as usize, opts.height as usize);
        let tiles_x = w.div_ceil(TILE);
        Grid { w, h, tiles_x, len: tiles_x * h.div_ceil(TILE) * TILE * TILE }
    }

    /// Buffer index of pixel (x, y); both must be inside the image.
    #[inline]
    fn at(&self, x: usize, y: usize) -> usize {
        let tile = (y >> TILE_SHIFT) * self.tiles_x + (x >> TILE_SHIFT);
        (tile << (2 * TILE_SHIFT)) | ((y & (TILE - 1)) << TILE_SHIFT) | (x & (TILE - 1))
    }
}

/// Runs `draw` over slices of `0..n` in parallel, each worker into its own
/// buffer, and merges the buffers by `min`.
fn visibility<F>(n: usize, grid: &Grid, draw: F) -> Vec<u64>
where
    F: Fn(std::ops::Range<usize>, &mut [u64]) + Sync,
{
    // Blocks of consecutive primitives: each worker walks them in storage
    // order, which for voxels is spatially coherent. `fold` makes one buffer
    // per piece of work rayon actually splits off (about one per thread
    // unless threads steal), so a busy core does not hold up the others.
    const BLOCK: usize = 1 << 15;
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
fn floor_i(x: f32) -> i32 {
    let i = x as i32;
    i - ((i as f32) > x) as i32
}

/// `x.ceil() as i32`, like [`floor_i`].
#[inline]
fn ceil_i(x: f32) -> i32 {
    let i = x as i32;
    i + ((i as f32) < x) as i32
}

/// Covers every pixel whose centre lies within `r` pixels of (sx, sy), and
/// always the pixel holding the centre, so sub-pixel splats never vanish.
#[inline]
fn splat_disc(zb: &mut [u64], grid: &Grid, sx: f32, sy: f32, r: f32, k: u64) {
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
fn edge(a: Vec3, b: Vec3, px: f32, py: f32) -> f32 {
    (b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x)
}

/// Covers the pixels whose centres lie inside the triangle (edges included;
/// a pixel on a shared edge is then decided by the z-test and the id).
/// Vertices: (pixel x, pixel y, distance).
fn raster_triangle(zb: &mut [u64], grid: &Grid, a: Vec3, b: Vec3, c: Vec3, id: usize) {
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
fn barycentric(a: Vec3, b: Vec3, c: Vec3, p: Vec2) -> Vec3 {
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


/// Lit colour of a surface element with normal `n` (any length, any sign)
/// and RGB `colour` in [0,1].
#[inline]
fn shade(n: Vec3, colour: Vec3, view: &View) -> [u8; 3] {
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
fn resolve<F>(keys: &[u64], grid: &Grid, opts: &RenderOptions, colour: F) -> RgbImage
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::level::Frame;
    use glam::{DVec3, IVec3};

    /// A background no shaded pixel produces by accident.
    const BG: [u8; 3] = [3, 200, 7];

    fn opts(size: u32) -> RenderOptions {
        RenderOptions { width: size, height: size, background: BG, ..Default::default() }
    }

    /// One point per voxel that the sphere of `radius` (normalised units)
    /// crosses, at the closest surface point to the voxel centre: the
    /// sampling a level has.
    fn sphere_level(resolution: u32, radius: f64, colour: Vec3) -> Level {
        let mut level = Level { resolution, ..Default::default() };
        let vs = level.voxel_size();
        let n = resolution as i32;
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    let c = IVec3::new(i, j, k);
                    let lo = level.transform().corner_normalised(c);
                    let hi = lo + DVec3::splat(vs);
                    let near = DVec3::ZERO.clamp(lo, hi).length();
                    let far = lo.abs().max(hi.abs()).length();
                    if near <= radius && radius <= far {
                        let centre = level.voxel_centre(c);
                        let p = centre.normalize() * radius;
                        level.coords.push(c);
                        level.offsets.push(((p - centre) / vs).as_vec3());
                        level.normals.push(p.normalize().as_vec3());
                        level.colours.push(colour);
                        level.mask.push(1.0);
                    }
                }
            }
        }
        level
    }

    fn covered(img: &RgbImage) -> Vec<(u32, u32)> {
        img.enumerate_pixels().filter(|(_, _, p)| p.0 != BG).map(|(x, y, _)| (x, y)).collect()
    }

    fn luma(img: &RgbImage, x: f32, y: f32) -> f32 {
        // Mean over a 5x5 patch.
        let mut sum = 0.0;
        for dy in -2..=2 {
            for dx in -2..=2 {
                let p = img.get_pixel((x as i32 + dx) as u32, (y as i32 + dy) as u32).0;
                sum += p.iter().map(|&v| v as f32).sum::<f32>();
            }
        }
        sum / 75.0
    }

    #[test]
    fn sphere_is_a_centred_disc_without_holes() {
        let level = sphere_level(64, 0.8, Vec3::ONE);
        let img = render_level(&level, &opts(256)).unwrap();
        let px = covered(&img);
        let (mut lo, mut hi) = ((u32::MAX, u32::MAX), (0, 0));
        let (mut sx, mut sy) = (0.0, 0.0);
        for &(x, y) in &px {
            lo = (lo.0.min(x), lo.1.min(y));
            hi = (hi.0.max(x), hi.1.max(y));
            sx += x as f64;
            sy += y as f64;
        }
        let n = px.len() as f64;
        let (cx, cy) = (sx / n, sy / n);
        assert!((cx - 128.0).abs() < 2.0 && (cy - 128.0).abs() < 2.0, "centroid ({cx}, {cy})");
        // The fit leaves a 4% margin each side, so the disc spans ~92% of it.
        let (dw, dh) = ((hi.0 - lo.0 + 1) as f64, (hi.1 - lo.1 + 1) as f64);
        assert!((dw - dh).abs() <= 2.0, "not round: {dw} x {dh}");
        assert!((dw / 256.0 - 0.92).abs() < 0.02, "diameter {dw}");
        let expected = std::f64::consts::PI / 4.0 * dw * dh / (256.0 * 256.0);
        let fraction = n / (256.0 * 256.0);
        assert!((fraction / expected - 1.0).abs() < 0.03, "area {fraction} vs {expected}");
        // No holes: every pixel well inside the silhouette is covered.
        let r = dw / 2.0;
        for y in 0..256u32 {
            for x in 0..256u32 {
                let d = ((x as f64 + 0.5 - cx).powi(2) + (y as f64 + 0.5 - cy).powi(2)).sqrt();
                if d < 0.97 * r {
                    assert_ne!(img.get_pixel(x, y).0, BG, "hole at ({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn side_facing_the_key_light_is_brighter() {
        let level = sphere_level(48, 0.8, Vec3::ONE);
        let img = render_level(&level, &opts(200)).unwrap();
        // The key light's direction on screen (y down), from the disc centre.
        let k = KEY_LIGHT_VIEW.normalize();
        let dir = Vec2::new(k.x, -k.y).normalize();
        let r = 0.92 * 200.0 / 2.0 * 0.6;
        let lit = luma(&img, 100.0 + dir.x * r, 100.0 + dir.y * r);
        let dark = luma(&img, 100.0 - dir.x * r, 100.0 - dir.y * r);
        assert!(lit > dark + 60.0, "lit {lit} vs away {dark}");
    }

    #[test]
    fn flipped_normals_still_light() {
        let mut points = OrientedPoints::from_level(&sphere_level(32, 0.8, Vec3::ONE));
        let a = render_points(&points, &opts(128)).unwrap();
        points.normals.iter_mut().for_each(|n| *n = -*n);
        let b = render_points(&points, &opts(128)).unwrap();
        assert_eq!(a, b);
    }

    /// A `size` x `size` square of points at depth `z` (towards a camera at
    /// azimuth 0, elevation 0), facing it.
    fn square(size: f32, z: f32, colour: Vec3, spacing: f32) -> OrientedPoints {
        let n = (size / spacing) as i32;
        let mut points = OrientedPoints { spacing, ..Default::default() };
        for i in 0..=n {
            for j in 0..=n {
                let p = Vec3::new(i as f32 * spacing - size / 2.0, j as f32 * spacing - size / 2.0, z);
                points.positions.push(p);
                points.normals.push(Vec3::Z);
                points.colours.push(colour);
            }
        }
        points
    }

    #[test]
    fn nearer_points_hide_farther_ones_whatever_their_order() {
        let front = RenderOptions { azimuth_deg: 0.0, elevation_deg: 0.0, ..opts(100) };
        let red = square(1.0, 0.5, Vec3::X, 0.02);
        let blue = square(2.0, -0.5, Vec3::Z, 0.02);
        for (first, second) in [(&red, &blue), (&blue, &red)] {
            let mut all = first.clone();
            all.positions.extend(&second.positions);
            all.normals.extend(&second.normals);
            all.colours.extend(&second.colours);
            let img = render_points(&all, &front).unwrap();
            let [r, _, b] = img.get_pixel(50, 50).0;
            assert!(r > 100 && b == 0, "centre ({r}, _, {b})");
            let [r, _, b] = img.get_pixel(8, 50).0;
            assert!(b > 100 && r == 0, "edge ({r}, _, {b})");
        }
    }

    #[test]
    fn red_points_give_red_pixels() {
        let level = sphere_level(32, 0.8, Vec3::new(0.9, 0.1, 0.05));
        let img = render_level(&level, &opts(128)).unwrap();
        let px = covered(&img);
        assert!(px.len() > 128 * 128 / 3);
        for (x, y) in px {
            let [r, g, b] = img.get_pixel(x, y).0;
            assert!(r > 20 && r as u32 > 3 * g as u32 && r as u32 > 3 * b as u32, "({r},{g},{b})");
        }
    }

    #[test]
    fn from_level_keeps_active_voxels_in_world_units() {
        let mut level = sphere_level(16, 0.8, Vec3::ONE);
        level.frame = Frame { centre: DVec3::new(10.0, 0.0, -5.0), scale: 0.5, ..Default::default() };
        level.mask[0] = -1.0;
        let points = OrientedPoints::from_level(&level);
        assert_eq!(points.len(), level.len() - 1);
        assert!((points.spacing - 2.0 / 16.0 / 0.5).abs() < 1e-6);
        let p = points.positions[0];
        assert!(((p - Vec3::new(10.0, 0.0, -5.0)).length() - 1.6).abs() < 1e-4, "{p}");
    }

    fn cube(colours: bool) -> Mesh {
        let mut m = crate::testing::shapes::axis_box(Vec3::ZERO, Vec3::ONE);
        if colours {
            m.colours = MeshColours::PerVertex(m.positions.clone());
        }
        m
    }

    #[test]
    fn cube_shows_three_flat_faces() {
        let img = render_mesh(&cube(false), &opts(200)).unwrap();
        let px = covered(&img);
        let fraction = px.len() as f32 / (200.0 * 200.0);
        assert!(fraction > 0.5 && fraction < 0.85, "fraction {fraction}");
        let mut shades: Vec<[u8; 3]> = px.iter().map(|&(x, y)| img.get_pixel(x, y).0).collect();
        shades.sort();
        shades.dedup();
        assert_eq!(shades.len(), 3, "flat shading of three visible faces: {shades:?}");
        // Grey: equal channels.
        assert!(shades.iter().all(|s| s[0] == s[1] && s[1] == s[2]));
        // Vertex colours are interpolated: many distinct values.
        let img = render_mesh(&cube(true), &opts(200)).unwrap();
        let mut shades: Vec<[u8; 3]> = covered(&img).iter().map(|&(x, y)| img.get_pixel(x, y).0).collect();
        shades.sort();
        shades.dedup();
        assert!(shades.len() > 100);
    }

    #[test]
    fn texture_colours_the_mesh() {
        let mut mesh = cube(false);
        let image = RgbImage::from_pixel(4, 4, image::Rgb([20, 40, 230]));
        let uvs = vec![Vec2::new(0.3, 0.7); 3 * mesh.triangles.len()];
        mesh.texture = Some(crate::io::mesh::Texture { uvs, image, ..Default::default() });
        let img = render_mesh(&mesh, &opts(100)).unwrap();
        let px = covered(&img);
        assert!(!px.is_empty());
        assert!(px.iter().all(|&(x, y)| {
            let [r, g, b] = img.get_pixel(x, y).0;
            b > 2 * r.max(g)
        }));
    }

    #[test]
    fn bad_inputs_are_errors() {
        let empty = OrientedPoints::default();
        let err = render_points(&empty, &opts(64)).unwrap_err();
        assert_eq!(err.to_string(), "nothing to render: no active voxels");
        let mut level = sphere_level(8, 0.8, Vec3::ONE);
        level.mask.iter_mut().for_each(|m| *m = -1.0);
        assert!(matches!(render_level(&level, &opts(64)), Err(RenderError::NoPoints)));
        let mut mesh = cube(false);
        mesh.triangles.clear();
        assert!(matches!(render_mesh(&mesh, &opts(64)), Err(RenderError::NoTriangles)));
        let zero = RenderOptions { width: 0, ..opts(64) };
        let points = OrientedPoints::from_level(&sphere_level(8, 0.8, Vec3::ONE));
        assert!(matches!(render_points(&points, &zero), Err(RenderError::BadSize { .. })));
        let mut mesh = cube(false);
        mesh.triangles[0][0] = 99;
        assert!(matches!(render_mesh(&mesh, &opts(64)), Err(RenderError::Invalid(_))));
    }

    #[test]
    fn save_png_is_atomic_and_round_trips() {
        let dir = std::env::temp_dir().join(format!("render-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let img = render_mesh(&cube(true), &RenderOptions { width: 120, height: 90, ..opts(1) }).unwrap();
        let path = dir.join("cube.png");
        save_png(&img, &path).unwrap();
        let names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec!["cube.png".to_string()]);
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back.dimensions(), (120, 90));
        assert_eq!(back, img);
        // The rename fails (a folder is in the way): the temporary file goes.
        let occupied = dir.join("occupied.png");
        std::fs::create_dir_all(occupied.join("inside")).unwrap();
        let err = save_png(&img, &occupied).unwrap_err();
        assert!(err.to_string().contains("occupied.png"), "{err}");
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, vec!["cube.png".to_string(), "occupied.png".to_string()]);
        // A folder that does not exist: an error naming the path, no litter.
        let missing = dir.join("no/such/dir/x.png");
        let err = save_png(&img, &missing).unwrap_err();
        assert!(err.to_string().contains("no/such/dir/x.png"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
