//! LAS and LAZ (ASPRS LiDAR) through the `las` crate (LAZ with its pure-Rust
//! LASzip codec). Positions are the scaled and offset coordinates (metres
//! for most tiles); the CRS from the WKT or GeoTIFF records.

use std::path::Path;

use glam::{DVec3, Vec3};

use super::{Attributes, PointCloud, MAX_POINTS};

/// Points read per call: memory follows the points really decoded, not the
/// count a (damaged) header declares.
const CHUNK: u64 = 1 << 20;

/// Checks a LAZ file's chunk table count before the decoder sizes a table by
/// it (a damaged count of 4 billion chunks aborts the process on allocation):
/// every chunk holds a point and at least a byte.
fn check_laz_chunk_table(path: &Path) -> Result<(), String> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let len = f.metadata().map_err(|e| e.to_string())?.len();
    let u32_at = |f: &mut std::fs::File, at: u64| -> std::io::Result<u32> {
        let mut b = [0u8; 4];
        f.seek(SeekFrom::Start(at))?;
        f.read_exact(&mut b)?;
        Ok(u32::from_le_bytes(b))
    };
    let short = |_| "ends inside its header (truncated)".to_string();
    let points_at = u32_at(&mut f, 96).map_err(short)? as u64;
    // The point count: 32 bits at byte 107, and from LAS 1.4 64 bits at 247.
    let legacy = u32_at(&mut f, 107).map_err(short)? as u64;
    let mut v = [0u8; 8];
    let extended = f.seek(SeekFrom::Start(247)).and_then(|_| f.read_exact(&mut v)).map(|_| u64::from_le_bytes(v)).unwrap_or(0);
    let declared_points = legacy.max(extended);
    let vlr = check_laszip_items(&mut f, len)?.ok_or("is compressed but has no LASzip record (damaged, or not a LAZ file)")?;
    let mut b = [0u8; 8];
    f.seek(SeekFrom::Start(points_at)).and_then(|_| f.read_exact(&mut b)).map_err(|_| "ends before its point data (truncated)".to_string())?;
    let mut table = i64::from_le_bytes(b);
    if table <= points_at as i64 {
        // The writer could not go back: the offset is the file's last 8 bytes.
        f.seek(SeekFrom::End(-8)).and_then(|_| f.read_exact(&mut b)).map_err(|e| e.to_string())?;
        table = i64::from_le_bytes(b);
        if table <= points_at as i64 {
            return Ok(()); // no chunk table: the decoder reads chunk by chunk
        }
    }
    let table = table as u64;
    if table.saturating_add(8) > len {
        return Err(format!("its chunk table offset {table} is past the file's {len} bytes (truncated or damaged)"));
    }
    let chunks = u32_at(&mut f, table + 4).map_err(|e| e.to_string())? as u64;
    if chunks > declared_points.max(1) || chunks > len {
        return Err(format!("its chunk table declares {chunks} chunks for {declared_points} points in {len} bytes (damaged)"));
    }
    check_layers(&mut f, len, points_at, &vlr)
}

/// LAS 1.4 point formats (LASzip's layered items): each chunk starts with
/// its first point raw, a point count and the byte size of every layer,
/// which the decoder allocates before reading: they must fit in the chunk.
fn check_layers(f: &mut std::fs::File, len: u64, points_at: u64, vlr: &[u8]) -> Result<(), String> {
    use laz::LazItemType as T;
    use std::io::{Read, Seek, SeekFrom};
    let vlr = laz::LazVlr::from_buffer(vlr).map_err(|e| format!("its LASzip record is damaged: {e}"))?;
    let layers: usize = vlr
        .items()
        .iter()
        .map(|i| match i.item_type() {
            T::Point14 => 9,
            T::RGB14 | T::WavePacket14 => 1,
            T::RGBNIR14 => 2,
            T::Byte14(n) => n as usize,
            _ => 0,
        })
        .sum();
    if layers == 0 {
        return Ok(()); // LAS 1.0-1.3 point formats: no layers
    }
    let first_point = vlr.items_size();
    f.seek(SeekFrom::Start(points_at)).map_err(|e| e.to_string())?;
    // Without a usable chunk table the decoder reads one chunk after another:
    // the first is checked against the rest of the file.
    let table = laz::laszip::ChunkTable::read_from(&mut *f, &vlr).ok().filter(|t| t.len() > 0);
    let starts: Vec<(u64, u64)> = match &table {
        Some(t) => {
            let mut at = points_at + 8;
            t.as_ref()
                .iter()
                .map(|e| {
                    let s = (at, e.byte_count);
                    at = at.saturating_add(e.byte_count);
                    s
                })
                .collect()
        }
        None => vec![(points_at + 8, len.saturating_sub(points_at + 8))],
    };
    for (k, (start, bytes)) in starts.into_iter().enumerate() {
        let head = first_point + 4 + 4 * layers as u64;
        let sizes_at = start + first_point + 4;
        let mut b = vec![0u8; 4 * layers];
        if start.saturating_add(head) > len || f.seek(SeekFrom::Start(sizes_at)).and_then(|_| f.read_exact(&mut b)).is_err() {
            return Err(format!("ends inside chunk {k} (truncated)"));
        }
        let total: u64 = b.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap()) as u64).sum();
        let room = bytes.min(len - start).saturating_sub(head);
        if total > room {
            return Err(format!("chunk {k} declares {total} bytes of layers in {room} (damaged)"));
        }
    }
    Ok(())
}

/// The LASzip record's items (their sizes size the decoder's buffers) must
/// add up to the point record length the header declares, as the LASzip
/// specification has them.
fn check_laszip_items(f: &mut std::fs::File, len: u64) -> Result<Option<Vec<u8>>, String> {
    use std::io::{Read, Seek, SeekFrom};
    let mut head = [0u8; 227];
    f.seek(SeekFrom::Start(0)).and_then(|_| f.read_exact(&mut head)).map_err(|_| "ends inside its header (truncated)".to_string())?;
    let header_size = u16::from_le_bytes([head[94], head[95]]) as u64;
    let vlrs = u32::from_le_bytes(head[100..104].try_into().unwrap());
    let record_length = u16::from_le_bytes([head[105], head[106]]) as u64;
    let mut at = header_size;
    for _ in 0..vlrs.min(10_000) {
        let mut v = [0u8; 54];
        if f.seek(SeekFrom::Start(at)).and_then(|_| f.read_exact(&mut v)).is_err() {
            return Err("ends inside its variable-length records (truncated)".into());
        }
        let user = String::from_utf8_lossy(&v[2..18]).trim_end_matches('\0').to_string();
        let record = u16::from_le_bytes([v[18], v[19]]);
        let body = u16::from_le_bytes([v[20], v[21]]) as u64;
        if user == "laszip encoded" && record == 22204 {
            let mut d = vec![0u8; body as usize];
            f.read_exact(&mut d).map_err(|_| "ends inside its LASzip record (truncated)".to_string())?;
            if d.len() < 34 {
                return Err("its LASzip record is too short (damaged)".into());
            }
            let items = u16::from_le_bytes([d[32], d[33]]) as usize;
            if d.len() < 34 + 6 * items {
                return Err("its LASzip record lists more items than it holds (damaged)".into());
            }
            let total: u64 = (0..items).map(|k| u16::from_le_bytes([d[34 + 6 * k + 2], d[34 + 6 * k + 3]]) as u64).sum();
            if total != record_length {
                return Err(format!("its LASzip items take {total} bytes a point, its header {record_length} (damaged)"));
            }
            return Ok(Some(d));
        }
        at += 54 + body;
        if at > len {
            break;
        }
    }
    Ok(None)
}

pub fn read(path: &Path, name: &str) -> Result<PointCloud, String> {
    let file_len = std::fs::metadata(path).map_err(|e| e.to_string())?.len();
    let is_laz = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("laz"));
    if is_laz {
        // Before the crate opens it: opening reads the chunk table.
        check_laz_chunk_table(path)?;
    }
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
        up: crate::grid::transform::Up::Z,
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
