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
pub mod loss_plot;
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

crate::stage_error!(RenderError);

pub type Result<T> = std::result::Result<T, RenderError>;


/// Renders a level's active voxels as lit splats (see [`render_points`]).
pub fn render_level(level: &Level, opts: &RenderOptions) -> Result<RgbImage> {
    let opts = RenderOptions { up: opts.up.or(Some(level.frame.up)), ..opts.clone() };
    render_points(&crate::level::Level::surface_points(level), &opts)
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

mod camera;
use camera::*;
mod raster;
use raster::*;
mod shade;
use shade::*;

#[cfg(test)]
mod tests;
