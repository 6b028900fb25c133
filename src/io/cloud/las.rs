//! LAS and LAZ (ASPRS LiDAR) through the `las` crate (LAZ with its pure-Rust
//! LASzip codec). Positions are the scaled and offset coordinates (metres
//! for most tiles); the CRS from the WKT or GeoTIFF records.

use std::path::Path;

use glam::{DVec3, Vec3};

use super::{Attributes, PointCloud, MAX_POINTS};

/// Points read per call: memory follows the points really decoded, not the
/// count a (damaged) header declares.
const CHUNK: u64 = 1 << 20;

pub fn read(path: &Path, name: &str) -> Result<PointCloud, String> {
    let file_len = std::fs::metadata(path).map_err(|e| e.to_string())?.len();
    let mut reader = las::Reader::from_path(path).map_err(|e| format!("not a readable LAS/LAZ file: {e}"))?;
    let header = reader.header().clone();
    let format = *header.point_format();
    let declared = header.number_of_points();
    if declared == 0 {
        return Err("declares no points".into());
    }
    if declared > MAX_POINTS {
        return Err(format!("declares {declared} points, more than the {MAX_POINTS} read at once: thin or tile it first"));
    }
    // An uncompressed record has a fixed length: the file must hold them all.
    // A compressed one takes at least a few bits: 64 points per byte is a
    // bound no real LAZ file comes near.
    let bound = if format.is_compressed { file_len.saturating_mul(64) } else { file_len / format.len().max(1) as u64 };
    if declared > bound {
        return Err(format!("declares {declared} points but the file of {file_len} bytes holds at most {bound} (truncated or damaged)"));
    }
    let n = declared as usize;
    let mut positions = Vec::with_capacity(n);
    let mut intensity = Vec::with_capacity(n);
    let mut classification = Vec::with_capacity(n);
    let mut rgb: Vec<[u16; 3]> = if format.has_color { Vec::with_capacity(n) } else { Vec::new() };
    let mut points = Vec::new();
    loop {
        points.clear();
        let got = reader.read_points_into(CHUNK, &mut points).map_err(|e| format!("point {}: {e}", positions.len()))?;
        if got == 0 {
            break;
        }
        for p in &points {
            positions.push(DVec3::new(p.x, p.y, p.z));
            intensity.push(p.intensity as f32);
            classification.push(u8::from(p.classification));
            if format.has_color {
                let c = p.color.unwrap_or_default();
                rgb.push([c.red, c.green, c.blue]);
            }
        }
        if crate::util::interrupt::requested().is_some() {
            return Err("stopped".into());
        }
    }
    if (positions.len() as u64) < declared {
        return Err(format!("holds {} of the {declared} points it declares (truncated)", positions.len()));
    }
    // Many writers put 8-bit colours in LAS's 16-bit fields.
    let colours = (!rgb.is_empty()).then(|| {
        let max = rgb.iter().flatten().copied().max().unwrap_or(0);
        let full = if max <= 255 { 255.0 } else { 65535.0 };
        rgb.iter().map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) / full).collect()
    });
    let v = header.version();
    let point_format = format.to_u8().map(|f| f.to_string()).unwrap_or_else(|_| "?".into());
    let kind = if format.is_compressed { "LAZ" } else { "LAS" };
    Ok(PointCloud {
        name: name.to_string(),
        positions,
        attributes: Attributes { normals: None, colours, intensity: Some(intensity), classification: Some(classification) },
        crs: crs(&header),
        format: format!("{kind} {}.{} point format {point_format}", v.major, v.minor),
        up: crate::level::Up::Z,
    })
}

/// "EPSG:NNNN" from the GeoTIFF keys, or the WKT's name, where the file has one.
fn crs(header: &las::Header) -> Option<String> {
    if let Ok(Some(g)) = header.get_geotiff_crs() {
        if let Some(code) = g.get_projected_crs_geo_key_value().or_else(|| g.get_geodetic_crs_geo_key_value()) {
            if (1024..32767).contains(&code) {
                return Some(format!("EPSG:{code}"));
            }
        }
    }
    let wkt = header.get_wkt_crs_bytes()?;
    let text = String::from_utf8_lossy(wkt);
    let text = text.trim_matches(char::from(0)).trim();
    // The name is the first quoted string: PROJCS["NAD83 / UTM zone 10N", ...
    let name = text.split('"').nth(1).unwrap_or(text);
    let epsg = text.rsplit("AUTHORITY[\"EPSG\",\"").next().filter(|_| text.contains("AUTHORITY[\"EPSG\"")).and_then(|s| s.split('"').next());
    Some(match epsg {
        Some(code) => format!("{} (EPSG:{code})", crate::error::one_line(name)),
        None => crate::error::one_line(name),
    })
}
