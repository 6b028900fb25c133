//! E57 (ASTM E2807, terrestrial scanners) through the `e57` crate: every
//! scan of the file, each with its pose applied (one frame for all), spherical
//! coordinates converted to Cartesian, invalid points left out.

use std::path::Path;

use glam::{DVec3, Vec3};

use super::{Attributes, PointCloud, MAX_POINTS};

pub fn read(path: &Path, name: &str) -> Result<PointCloud, String> {
    let file_len = std::fs::metadata(path).map_err(|e| e.to_string())?.len();
    let mut reader = e57::E57Reader::from_file(path).map_err(|e| format!("not a readable E57 file: {e}"))?;
    let scans = reader.pointclouds();
    if scans.is_empty() {
        return Err("holds no point cloud".into());
    }
    let declared: u64 = scans.iter().map(|s| s.records).fold(0u64, u64::saturating_add);
    if declared > MAX_POINTS {
        return Err(format!("declares {declared} points, more than the {MAX_POINTS} read at once: thin it first"));
    }
    // Bit-packed records take at least a bit each.
    if declared > file_len.saturating_mul(8) {
        return Err(format!("declares {declared} points in {file_len} bytes (damaged)"));
    }
    let crs = reader.coordinate_metadata().map(|s| crate::error::one_line(s)).filter(|s| !s.is_empty());
    let (mut positions, mut colours, mut intensity) = (Vec::new(), Vec::new(), Vec::new());
    let (mut with_colour, mut with_intensity, mut invalid) = (true, true, 0u64);
    for scan in &scans {
        let points = reader.pointcloud_simple(scan).map_err(|e| format!("scan {}: {e}", scan.name.clone().unwrap_or_default()))?;
        for p in points {
            let p = p.map_err(|e| format!("point {}: {e}", positions.len()))?;
            let e57::CartesianCoordinate::Valid { x, y, z } = p.cartesian else {
                invalid += 1;
                continue;
            };
            positions.push(DVec3::new(x, y, z));
            match &p.color {
                Some(c) => colours.push(Vec3::new(c.red, c.green, c.blue).clamp(Vec3::ZERO, Vec3::ONE)),
                None => with_colour = false,
            }
            match p.intensity {
                Some(i) => intensity.push(i),
                None => with_intensity = false,
            }
            if positions.len() as u64 > declared {
                return Err(format!("holds more points than the {declared} it declares (damaged)"));
            }
        }
        if crate::util::interrupt::requested().is_some() {
            return Err("stopped".into());
        }
    }
    if invalid > 0 {
        log::warn!("{name}: left out {invalid} points without a valid position");
    }
    Ok(PointCloud {
        name: name.to_string(),
        positions,
        attributes: Attributes {
            normals: None,
            colours: with_colour.then_some(colours),
            intensity: with_intensity.then_some(intensity),
            classification: None,
        },
        crs,
        format: format!("E57, {} scan{}", scans.len(), if scans.len() == 1 { "" } else { "s" }),
        up: crate::grid::transform::Up::Z,
    })
}
