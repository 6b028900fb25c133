//! Point-cloud exemplars: PLY points (no faces), LAS/LAZ (aerial LiDAR) and
//! E57 (terrestrial scanners), read into one [`PointCloud`] type with f64
//! positions (LiDAR coordinates are in the millions of metres: f32 would
//! round them to a quarter metre). Normals the file lacks are estimated
//! (`geom::normals`); colour comes from RGB, or from intensity or the
//! classification when asked ([`CloudColour`]).

mod e57;
mod las;
mod ply;

use std::path::Path;

use glam::{DVec3, Vec3};

use crate::error::{Error, Result};
use crate::util::fs::check_input_file;

/// Extensions that are always point clouds (a PLY is one when it has no faces).
pub const CLOUD_EXTENSIONS: &[&str] = &["las", "laz", "e57"];

/// Most points read from one file: beyond this a scan should be thinned
/// first (the finest level of 256^3 holds about a million voxels anyway).
pub const MAX_POINTS: u64 = 200_000_000;

/// Per-point attributes a file may carry, each as long as the positions.
#[derive(Clone, Debug, Default)]
pub struct Attributes {
    pub normals: Option<Vec<Vec3>>,
    /// RGB in [0, 1].
    pub colours: Option<Vec<Vec3>>,
    /// The file's own units (LAS: 16-bit; E57: its limits).
    pub intensity: Option<Vec<f32>>,
    /// ASPRS classes (LAS) or the file's class property.
    pub classification: Option<Vec<u8>>,
}

/// Oriented, coloured points in the file's own frame and units.
#[derive(Clone, Debug)]
pub struct PointCloud {
    pub name: String,
    pub positions: Vec<DVec3>,
    pub attributes: Attributes,
    /// The coordinate reference system where the file names one (LAS WKT or
    /// GeoTIFF EPSG code, E57 coordinate metadata).
    pub crs: Option<String>,
    /// What the file was, for `info` ("LAS 1.4 point format 6", ...).
    pub format: String,
    /// The format's vertical axis: +z for LAS/LAZ and E57 (geodetic and
    /// scanner frames), +y for PLY (as for meshes).
    pub up: crate::grid::transform::Up,
}

/// Where an exemplar cloud's colours come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum CloudColour {
    /// RGB where the file has it, else a constant grey.
    #[default]
    Auto,
    /// RGB; an error where the file has none.
    Rgb,
    /// Intensity as grey, stretched between its 2nd and 98th percentiles.
    Intensity,
    /// The ASPRS class palette (ground brown, vegetation greens, buildings
    /// red, water blue, the rest grey).
    Classification,
    /// A constant grey.
    None,
}

/// What `info` reports about a cloud.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CloudSummary {
    pub format: String,
    pub points: usize,
    pub bbox_min: [f64; 3],
    pub bbox_max: [f64; 3],
    /// The per-point attributes present ("normals", "rgb", "intensity", "classification").
    pub attributes: Vec<String>,
    pub crs: Option<String>,
}

impl PointCloud {
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Axis-aligned bounds (min, max) in the file's units.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.positions.iter().fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    pub fn summary(&self) -> CloudSummary {
        let (lo, hi) = self.bounds();
        let a = &self.attributes;
        let attributes = [("normals", a.normals.is_some()), ("rgb", a.colours.is_some()), ("intensity", a.intensity.is_some()), ("classification", a.classification.is_some())]
            .iter()
            .filter(|(_, on)| *on)
            .map(|(n, _)| n.to_string())
            .collect();
        CloudSummary { format: self.format.clone(), points: self.len(), bbox_min: lo.to_array(), bbox_max: hi.to_array(), attributes, crs: self.crs.clone() }
    }

    /// One colour per point, RGB in [0, 1], from the source `how` names, or
    /// None for a constant colour.
    pub fn colours(&self, how: CloudColour) -> std::result::Result<Option<Vec<Vec3>>, String> {
        let a = &self.attributes;
        Ok(match how {
            CloudColour::None => None,
            CloudColour::Auto => a.colours.clone(),
            CloudColour::Rgb => Some(a.colours.clone().ok_or("has no RGB colours (try --cloud-colour intensity or classification)")?),
            CloudColour::Intensity => {
                let v = a.intensity.as_ref().ok_or("has no intensity")?;
                let mut sorted: Vec<f32> = v.iter().copied().filter(|x| x.is_finite()).collect();
                sorted.sort_by(f32::total_cmp);
                let at = |q: f64| sorted.get(((sorted.len().max(1) - 1) as f64 * q) as usize).copied().unwrap_or(0.0);
                let (lo, hi) = (at(0.02), at(0.98));
                let span = (hi - lo).max(f32::EPSILON);
                Some(v.iter().map(|&x| Vec3::splat(((x - lo) / span).clamp(0.0, 1.0))).collect())
            }
            CloudColour::Classification => {
                let c = a.classification.as_ref().ok_or("has no classification")?;
                Some(c.iter().map(|&k| class_colour(k)).collect())
            }
        })
    }
}

impl PointCloud {
    /// The points for a preview (`render`): positions relative to the
    /// bounding-box centre (a georeferenced tile keeps full f32 precision),
    /// the file's normals or estimated ones ([`crate::geom::normals`]), RGB
    /// colours or mid grey, spacing the median distance between neighbours.
    pub fn oriented_points(&self, up: crate::grid::transform::Up) -> crate::geom::points::OrientedPoints {
        let (lo, hi) = self.bounds();
        let positions = relative_positions(&self.positions, (lo + hi) * 0.5);
        let (normals, spacing) = match &self.attributes.normals {
            Some(n) => (n.clone(), crate::geom::normals::median_spacing(&positions)),
            None => crate::geom::normals::estimate(&positions, 16, Default::default(), up.axis()),
        };
        let colours = self.attributes.colours.clone().unwrap_or_else(|| vec![Vec3::splat(0.7); self.len()]);
        crate::geom::points::OrientedPoints { positions, normals, colours, spacing }
    }
}

/// The ASPRS standard classes (LAS 1.4 table 17) as colours.
pub fn class_colour(class: u8) -> Vec3 {
    let rgb = |r: u8, g: u8, b: u8| Vec3::new(r as f32, g as f32, b as f32) / 255.0;
    match class {
        2 => rgb(150, 110, 70),  // ground
        3 => rgb(150, 200, 100), // low vegetation
        4 => rgb(90, 160, 60),   // medium vegetation
        5 => rgb(40, 110, 40),   // high vegetation
        6 => rgb(190, 80, 60),   // building
        9 => rgb(60, 110, 200),  // water
        10 => rgb(120, 120, 120), // rail
        11 => rgb(70, 70, 70),   // road surface
        17 => rgb(200, 200, 200), // bridge deck
        _ => rgb(160, 160, 160),
    }
}

/// True when `path` holds a point cloud (LAS, LAZ, E57, or a PLY without faces).
pub fn is_cloud_file(path: &Path) -> bool {
    let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    if CLOUD_EXTENSIONS.contains(&ext.as_str()) {
        return true;
    }
    if ext == "ply" {
        let mut head = Vec::new();
        use std::io::Read;
        if std::fs::File::open(path).and_then(|f| f.take(64 << 10).read_to_end(&mut head)).is_ok() {
            return ply::is_point_cloud(&head);
        }
    }
    false
}

/// Reads a point cloud (format by extension), checking every position is
/// finite and every attribute as long as the positions.
pub fn load(path: &Path) -> Result<PointCloud> {
    check_input_file(path)?;
    let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let cloud = match ext.as_str() {
        "ply" => {
            // Read once; sizes checked against the length first, as for PLY meshes.
            let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
            crate::io::mesh_check::check_ply(&bytes).and_then(|_| ply::read(&bytes, &name))
        }
        "las" | "laz" => las::read(path, &name),
        "e57" => e57::read(path, &name),
        _ => Err(format!("unsupported point-cloud format '.{ext}' (expected .ply, .las, .laz or .e57)")),
    }
    .map_err(|m| Error::file(path, m))?;
    check(&cloud).map_err(|m| Error::file(path, m))?;
    Ok(cloud)
}

fn check(c: &PointCloud) -> std::result::Result<(), String> {
    if c.positions.is_empty() {
        return Err("has no points".into());
    }
    if let Some(i) = c.positions.iter().position(|p| !p.is_finite()) {
        return Err(format!("point {i} has a NaN or infinite coordinate"));
    }
    // Neighbour searches work in f32 about the centre: a span past 1e9 units
    // (a damaged scale or offset, not a scan) would lose every point.
    let (lo, hi) = c.bounds();
    let span = (hi - lo).max_element();
    if !(span <= 1e9) {
        return Err(format!("its points span {span:e} units (a damaged scale or offset?)"));
    }
    let n = c.len();
    let a = &c.attributes;
    for (what, len) in [
        ("normals", a.normals.as_ref().map(Vec::len)),
        ("colours", a.colours.as_ref().map(Vec::len)),
        ("intensities", a.intensity.as_ref().map(Vec::len)),
        ("classes", a.classification.as_ref().map(Vec::len)),
    ] {
        if let Some(len) = len {
            if len != n {
                return Err(format!("{len} {what} for {n} points"));
            }
        }
    }
    Ok(())
}

/// Positions as f32 relative to `origin` (for neighbour searches: metres
/// around the cloud's centre keep full precision).
pub fn relative_positions(positions: &[DVec3], origin: DVec3) -> Vec<Vec3> {
    positions.iter().map(|p| (*p - origin).as_vec3()).collect()
}
