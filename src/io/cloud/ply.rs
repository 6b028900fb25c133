//! PLY files of points (a `vertex` element and no faces): ASCII or binary,
//! either byte order, any scalar types. Reads x/y/z, nx/ny/nz, red/green/blue
//! (8-bit, 16-bit or float in [0, 1]), intensity (or scalar_intensity) and
//! class (or classification, scalar_classification); ignores the rest. The
//! sizes the header declares were checked against the file's length first
//! (`io::mesh_check`), so no count here can ask for more than the file holds.

use glam::{DVec3, Vec3};

use super::{Attributes, PointCloud};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(t: &str) -> Option<Scalar> {
        Some(match t {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    /// Full scale of an integer colour channel (255 for 8 bits), 1 for floats.
    fn colour_scale(self) -> f64 {
        match self {
            Scalar::U8 | Scalar::I8 => 255.0,
            Scalar::U16 | Scalar::I16 => 65535.0,
            Scalar::U32 | Scalar::I32 => u32::MAX as f64,
            Scalar::F32 | Scalar::F64 => 1.0,
        }
    }
    fn read(self, b: &[u8], big: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap();
                (if big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => num!(i16, 2),
            Scalar::U16 => num!(u16, 2),
            Scalar::I32 => num!(i32, 4),
            Scalar::U32 => num!(u32, 4),
            Scalar::F32 => num!(f32, 4),
            Scalar::F64 => num!(f64, 8),
        }
    }
}

enum Property {
    Scalar(String, Scalar),
    List(Scalar, Scalar),
}

struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
}

/// Which column of a vertex record feeds which attribute.
#[derive(Default)]
struct Columns {
    xyz: [Option<usize>; 3],
    normal: [Option<usize>; 3],
    rgb: [Option<(usize, Scalar)>; 3],
    intensity: Option<usize>,
    class: Option<usize>,
}

/// True when the header declares vertices and no (or zero) faces.
pub fn is_point_cloud(bytes: &[u8]) -> bool {
    match header(bytes) {
        Ok((_, elements, _)) => {
            let count = |n: &str| elements.iter().find(|e| e.name == n).map(|e| e.count);
            count("vertex").unwrap_or(0) > 0 && count("face").unwrap_or(0) == 0
        }
        Err(_) => false,
    }
}

fn header(bytes: &[u8]) -> Result<(String, Vec<Element>, usize), String> {
    let head = &bytes[..bytes.len().min(64 << 10)];
    let end = head
        .windows(11)
        .position(|w| w == b"end_header\n" || w == b"end_header\r")
        .ok_or("PLY header has no 'end_header' line in its first 64 KiB")?;
    let body = head[end..].iter().position(|&b| b == b'\n').map(|p| end + p + 1).unwrap_or(head.len());
    let text = String::from_utf8_lossy(&head[..end]);
    let mut format = String::new();
    let mut elements: Vec<Element> = Vec::new();
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        let scalar = |i: usize| t.get(i).and_then(|s| Scalar::parse(s)).ok_or_else(|| format!("PLY property type in '{}' is unknown", line.trim()));
        match t.first().copied() {
            Some("format") => format = t.get(1).copied().unwrap_or("").to_string(),
            Some("element") => elements.push(Element {
                name: t.get(1).copied().unwrap_or("").to_string(),
                count: t.get(2).and_then(|c| c.parse().ok()).ok_or_else(|| format!("PLY element line '{}' has no count", line.trim()))?,
                properties: Vec::new(),
            }),
            Some("property") => {
                let p = if t.get(1) == Some(&"list") {
                    Property::List(scalar(2)?, scalar(3)?)
                } else {
                    Property::Scalar(t.get(2).copied().unwrap_or("").to_string(), scalar(1)?)
                };
                elements.last_mut().ok_or("PLY property before any element")?.properties.push(p);
            }
            _ => {}
        }
    }
    Ok((format, elements, body))
}

fn columns(vertex: &Element) -> Result<Columns, String> {
    let mut c = Columns::default();
    for (i, p) in vertex.properties.iter().enumerate() {
        let Property::Scalar(name, ty) = p else { continue };
        match name.as_str() {
            "x" => c.xyz[0] = Some(i),
            "y" => c.xyz[1] = Some(i),
            "z" => c.xyz[2] = Some(i),
            "nx" | "normal_x" => c.normal[0] = Some(i),
            "ny" | "normal_y" => c.normal[1] = Some(i),
            "nz" | "normal_z" => c.normal[2] = Some(i),
            "red" | "r" | "diffuse_red" => c.rgb[0] = Some((i, *ty)),
            "green" | "g" | "diffuse_green" => c.rgb[1] = Some((i, *ty)),
            "blue" | "b" | "diffuse_blue" => c.rgb[2] = Some((i, *ty)),
            "intensity" | "scalar_intensity" | "scalar_Intensity" => c.intensity = Some(i),
            "class" | "classification" | "scalar_classification" | "scalar_Classification" => c.class = Some(i),
            _ => {}
        }
    }
    if c.xyz.iter().any(Option::is_none) {
        return Err("PLY vertex element has no x, y and z properties".into());
    }
    Ok(c)
}

/// Reads a point cloud from the bytes of a PLY file whose sizes were checked.
pub fn read(bytes: &[u8], name: &str) -> Result<PointCloud, String> {
    let (format, elements, body_start) = header(bytes)?;
    let vi = elements.iter().position(|e| e.name == "vertex").ok_or("PLY file has no vertex element")?;
    let cols = columns(&elements[vi])?;
    let n = elements[vi].count as usize;
    let stride = elements[vi].properties.len();
    // One flat array of the vertex records' numbers, `stride` per point.
    let mut values: Vec<f64> = Vec::with_capacity(n.saturating_mul(stride).min(bytes.len()));
    let body = &bytes[body_start.min(bytes.len())..];
    match format.as_str() {
        "ascii" => {
            let mut tokens = body.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty());
            let mut number = |what: &str| -> Result<f64, String> {
                let t = tokens.next().ok_or_else(|| format!("ends inside {what} (truncated)"))?;
                std::str::from_utf8(t).ok().and_then(|s| s.parse::<f64>().ok()).ok_or_else(|| format!("'{}' in {what} is not a number", String::from_utf8_lossy(&t[..t.len().min(20)])))
            };
            for (ei, e) in elements.iter().enumerate().take(vi + 1) {
                for r in 0..e.count {
                    let what = format!("{} record {r}", e.name);
                    for p in &e.properties {
                        match p {
                            Property::Scalar(..) => {
                                let v = number(&what)?;
                                if ei == vi {
                                    values.push(v);
                                }
                            }
                            Property::List(..) => {
                                let k = number(&what)?;
                                if !(0.0..=1e9).contains(&k) {
                                    return Err(format!("{what}: list count {k} is out of range"));
                                }
                                for _ in 0..k as u64 {
                                    number(&what)?;
                                }
                                if ei == vi {
                                    values.push(f64::NAN);
                                }
                            }
                        }
                    }
                }
            }
        }
        "binary_little_endian" | "binary_big_endian" => {
            let big = format == "binary_big_endian";
            let mut at = 0usize;
            let short = |e: &Element, r: u64| format!("ends inside {} record {r} of {} (truncated)", e.name, e.count);
            for (ei, e) in elements.iter().enumerate().take(vi + 1) {
                for r in 0..e.count {
                    for p in &e.properties {
                        match p {
                            Property::Scalar(_, s) => {
                                let b = body.get(at..at + s.size()).ok_or_else(|| short(e, r))?;
                                if ei == vi {
                                    values.push(s.read(b, big));
                                }
                                at += s.size();
                            }
                            Property::List(c, item) => {
                                let b = body.get(at..at + c.size()).ok_or_else(|| short(e, r))?;
                                let k = c.read(b, big);
                                at += c.size();
                                let bytes = (k.max(0.0) as u64).saturating_mul(item.size() as u64);
                                if k < 0.0 || bytes > (body.len() - at.min(body.len())) as u64 {
                                    return Err(format!("{} record {r}: list of {k} items is longer than the file", e.name));
                                }
                                at += bytes as usize;
                                if ei == vi {
                                    values.push(f64::NAN);
                                }
                            }
                        }
                    }
                }
            }
        }
        f => return Err(format!("PLY format '{f}' is not ascii or binary")),
    }

    let rows = || values.chunks_exact(stride.max(1));
    let col = |row: &[f64], i: usize| row[i];
    let mut positions = Vec::with_capacity(n);
    for (r, row) in rows().enumerate() {
        let p = DVec3::new(col(row, cols.xyz[0].unwrap()), col(row, cols.xyz[1].unwrap()), col(row, cols.xyz[2].unwrap()));
        if !p.is_finite() {
            return Err(format!("point {r} has a NaN or infinite coordinate"));
        }
        positions.push(p);
    }
    let normals = if let [Some(a), Some(b), Some(c)] = cols.normal {
        Some(rows().map(|row| Vec3::new(row[a] as f32, row[b] as f32, row[c] as f32)).collect())
    } else {
        None
    };
    let colours = if let [Some((a, ta)), Some((b, tb)), Some((c, tc))] = cols.rgb {
        Some(
            rows()
                .map(|row| {
                    Vec3::new((row[a] / ta.colour_scale()) as f32, (row[b] / tb.colour_scale()) as f32, (row[c] / tc.colour_scale()) as f32)
                        .clamp(Vec3::ZERO, Vec3::ONE)
                })
                .collect(),
        )
    } else {
        None
    };
    let intensity = cols.intensity.map(|i| rows().map(|row| row[i] as f32).collect());
    let classification = cols.class.map(|i| rows().map(|row| row[i].clamp(0.0, 255.0) as u8).collect());
    Ok(PointCloud {
        name: name.to_string(),
        positions,
        attributes: Attributes { normals, colours, intensity, classification },
        crs: None,
        format: format!("PLY points ({format})"),
        up: crate::grid::transform::Up::Y,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_ascii_and_binary_points_with_and_without_attributes() {
        let ascii = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0 0 0 255 0 0\n1 2 3 0 0 255\n";
        assert!(is_point_cloud(ascii));
        let c = read(ascii, "a").unwrap();
        assert_eq!(c.positions, vec![DVec3::ZERO, DVec3::new(1.0, 2.0, 3.0)]);
        assert_eq!(c.attributes.colours.as_ref().unwrap()[0], Vec3::X);
        assert!(c.attributes.normals.is_none());

        let mut bin = b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty ushort intensity\nend_header\n".to_vec();
        for v in [1.5f64, -2.0, 1e6] {
            bin.extend_from_slice(&v.to_be_bytes());
        }
        for v in [0.0f32, 0.0, 1.0] {
            bin.extend_from_slice(&v.to_be_bytes());
        }
        bin.extend_from_slice(&700u16.to_be_bytes());
        let c = read(&bin, "b").unwrap();
        assert_eq!(c.positions[0], DVec3::new(1.5, -2.0, 1e6));
        assert_eq!(c.attributes.normals.as_ref().unwrap()[0], Vec3::Z);
        assert_eq!(c.attributes.intensity.as_ref().unwrap()[0], 700.0);

        let truncated = &bin[..bin.len() - 3];
        assert!(read(truncated, "t").unwrap_err().contains("truncated"));
        let faces = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        assert!(!is_point_cloud(faces));
    }
}
