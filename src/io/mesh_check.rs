//! Checks the sizes a PLY, OFF or STL file declares against its length before
//! OpenMesh reads it, so that a damaged count (a vertex count of 2 billion in a
//! 20 KB file) is a one-line error instead of a large allocation, and so that
//! faces OpenMesh skips without telling can be counted in a warning.
//!
//! Each check is a lower bound on the bytes the declared elements need: binary
//! records need at least their fixed-size fields (a list at least its count),
//! text records at least two bytes per number (a digit and a separator).

use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};

/// What the header declares, where the format says it.
#[derive(Debug, Default, PartialEq)]
pub struct Declared {
    pub vertices: Option<u64>,
    pub faces: Option<u64>,
}

/// Longest header we look for the end of: real PLY headers are a few hundred
/// bytes, comments included.
const MAX_HEADER: usize = 64 << 10;

pub fn check(path: &Path, ext: &str) -> Result<Declared> {
    let len = std::fs::metadata(path).map_err(|e| Error::file(path, e.to_string()))?.len();
    let mut head = Vec::with_capacity(MAX_HEADER.min(len as usize));
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_HEADER as u64).read_to_end(&mut head))
        .map_err(|e| Error::file(path, e.to_string()))?;
    let whole = || std::fs::read(path).map_err(|e| e.to_string());
    let r = match ext {
        "ply" => whole().and_then(|all| check_ply(&all)),
        "off" => whole().and_then(|all| check_off(&all)),
        "stl" => check_stl(path, &head, len),
        _ => Ok(Declared::default()),
    };
    r.map_err(|m| Error::file(path, m))
}

fn scalar_size(t: &str) -> Option<u64> {
    Some(match t {
        "char" | "uchar" | "int8" | "uint8" => 1,
        "short" | "ushort" | "int16" | "uint16" => 2,
        "int" | "uint" | "float" | "int32" | "uint32" | "float32" => 4,
        "double" | "float64" => 8,
        _ => return None,
    })
}

fn parse_count(t: Option<&str>, what: &str) -> Result<u64, String> {
    t.and_then(|t| t.parse::<u64>().ok()).ok_or_else(|| format!("{what} count is missing or not a number"))
}

/// A PLY property: a scalar of `size` bytes, or a list (count size, item size).
#[derive(Clone, Copy)]
enum Prop {
    Scalar(usize),
    List(usize, usize),
}

/// [`check`] of a PLY file's bytes, already read.
pub(crate) fn check_ply(all: &[u8]) -> Result<Declared, String> {
    let head = &all[..all.len().min(MAX_HEADER)];
    // The end_header line itself: a damaged newline before it ("...indicesAend_header")
    // sent OpenMesh reading binary data as header lines for minutes.
    let end = head
        .windows(12)
        .position(|w| &w[..11] == b"\nend_header" && (w[11] == b'\n' || w[11] == b'\r'))
        .map(|p| p + 1)
        .ok_or("PLY header has no 'end_header' line in its first 64 KiB")?;
    // The body starts after the end_header line's newline.
    let body_start = head[end..].iter().position(|&b| b == b'\n').map(|p| end + p + 1).unwrap_or(head.len());
    let text = String::from_utf8_lossy(&head[..end]);
    let mut lines = text.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err("does not start with 'ply'".into());
    }
    let mut format = None;
    let mut elements: Vec<(String, u64, Vec<Prop>)> = Vec::new();
    for line in lines {
        let t: Vec<&str> = line.split_whitespace().collect();
        let size = |i: usize| {
            t.get(i)
                .and_then(|s| scalar_size(s))
                .map(|s| s as usize)
                .ok_or_else(|| format!("PLY property type in '{}' is unknown", line.trim()))
        };
        match t.first().copied() {
            Some("format") => format = t.get(1).map(|f| f.to_string()),
            Some("element") => {
                let name = t.get(1).copied().unwrap_or("").to_string();
                let count = parse_count(t.get(2).copied(), &format!("PLY element '{name}'"))?;
                elements.push((name, count, Vec::new()));
            }
            Some("property") => {
                let prop = if t.get(1) == Some(&"list") { Prop::List(size(2)?, size(3)?) } else { Prop::Scalar(size(1)?) };
                elements.last_mut().ok_or("PLY property before any element")?.2.push(prop);
            }
            _ => {}
        }
    }
    let body = &all[body_start.min(all.len())..];
    match format.as_deref() {
        Some("ascii") => walk_ply_text(body, &elements)?,
        Some("binary_little_endian") => walk_ply_binary(body, &elements, false)?,
        Some("binary_big_endian") => walk_ply_binary(body, &elements, true)?,
        f => return Err(format!("PLY format '{}' is not ascii or binary", f.unwrap_or(""))),
    }
    let count_of = |n: &str| elements.iter().find(|e| e.0 == n).map(|e| e.1);
    Ok(Declared { vertices: count_of("vertex"), faces: count_of("face") })
}

fn short_file(what: &str, count: u64, name: &str) -> String {
    format!("ends inside {name} record {what} of the {count} it declares (truncated or damaged)")
}

/// Walks the binary body record by record (nothing is stored): every record
/// must fit in the file, every list's count in the bytes that are left.
fn walk_ply_binary(body: &[u8], elements: &[(String, u64, Vec<Prop>)], big_endian: bool) -> Result<(), String> {
    let mut at = 0usize;
    for (name, count, props) in elements {
        // A quick bound first, so that a huge count fails before the walk.
        let min: usize = props.iter().map(|p| match p { Prop::Scalar(s) => *s, Prop::List(c, _) => *c }).sum();
        if count.saturating_mul(min as u64) > (body.len() - at) as u64 {
            return Err(format!(
                "declares {count} {name} records, at least {} bytes, but holds {} bytes after its header (truncated or damaged)",
                count.saturating_mul(min as u64),
                body.len() - at
            ));
        }
        for r in 0..*count {
            for p in props {
                match *p {
                    Prop::Scalar(s) => at += s,
                    Prop::List(c, item) => {
                        let bytes = body.get(at..at + c).ok_or_else(|| short_file(&r.to_string(), *count, name))?;
                        let mut v = 0u64;
                        for k in 0..c {
                            let b = bytes[if big_endian { k } else { c - 1 - k }];
                            v = (v << 8) | b as u64;
                        }
                        // A negative count (signed types) reads as huge: rejected below.
                        at += c;
                        let need = v.saturating_mul(item as u64);
                        if need > (body.len() - at.min(body.len())) as u64 {
                            return Err(format!("{name} record {r} declares a list of {v} items, more than the file holds (damaged)"));
                        }
                        at += need as usize;
                    }
                }
                if at > body.len() {
                    return Err(short_file(&r.to_string(), *count, name));
                }
            }
        }
    }
    Ok(())
}

/// Walks the text body token by token: every list count must be a number no
/// larger than the tokens that are left could hold (two bytes each).
fn walk_ply_text(body: &[u8], elements: &[(String, u64, Vec<Prop>)]) -> Result<(), String> {
    let mut tokens = body.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty());
    let mut consumed = 0u64;
    for (name, count, props) in elements {
        let numbers = props.len() as u64;
        if count.saturating_mul(2 * numbers) > body.len() as u64 {
            return Err(format!(
                "declares {count} {name} records, at least {} bytes, but holds {} bytes after its header (truncated or damaged)",
                count.saturating_mul(2 * numbers),
                body.len()
            ));
        }
        for r in 0..*count {
            for p in props {
                let t = tokens.next().ok_or_else(|| short_file(&r.to_string(), *count, name))?;
                consumed += 1;
                // OpenMesh reads "nan" or "inf" as a bad token and drops the
                // faces that use the vertex: the mesh would be reported as
                // having no faces. Say what is wrong instead.
                if name == "vertex" && t.iter().any(|b| b.is_ascii_alphabetic()) {
                    if let Some(v) = std::str::from_utf8(t).ok().and_then(|s| s.parse::<f64>().ok()) {
                        if !v.is_finite() {
                            return Err(format!("vertex {r} has a NaN or infinite coordinate ('{}')", String::from_utf8_lossy(t)));
                        }
                    }
                }
                if let Prop::List(..) = p {
                    let n = std::str::from_utf8(t).ok().and_then(|s| s.parse::<u64>().ok()).ok_or_else(|| {
                        format!("{name} record {r}: list count '{}' is not a number", String::from_utf8_lossy(t))
                    })?;
                    if n.saturating_mul(2) > (body.len() as u64).saturating_sub(consumed * 2) {
                        return Err(format!("{name} record {r} declares a list of {n} items, more than the file holds (damaged)"));
                    }
                    for _ in 0..n {
                        tokens.next().ok_or_else(|| short_file(&r.to_string(), *count, name))?;
                        consumed += 1;
                    }
                }
            }
        }
    }
    Ok(())
}

fn check_off(all: &[u8]) -> Result<Declared, String> {
    let head = &all[..all.len().min(MAX_HEADER)];
    let len = all.len() as u64;
    let text = String::from_utf8_lossy(head);
    // Tokens outside comments, with their byte offsets, until the counts.
    let mut tokens = Vec::new();
    let mut offset = 0usize;
    for line in text.split_inclusive('\n') {
        let content = line.split('#').next().unwrap_or("");
        let mut from = 0;
        for t in content.split_whitespace() {
            // Offset just past the token: where the body may start.
            let start = from + content[from..].find(t).unwrap_or(0);
            from = start + t.len();
            tokens.push((t, offset + from));
        }
        offset += line.len();
        if tokens.len() >= 4 {
            break;
        }
    }
    let magic = tokens.first().map(|t| t.0).unwrap_or("");
    if !magic.ends_with("OFF") || magic.len() > 6 {
        return Err("OFF header not understood: expected [ST][C][N][4]OFF, then vertex, face and edge counts".into());
    }
    let binary = tokens.get(1).map(|t| t.0) == Some("BINARY");
    let first = if binary { 2 } else { 1 };
    let nv = parse_count(tokens.get(first).map(|t| t.0), "OFF vertex")?;
    let nf = parse_count(tokens.get(first + 1).map(|t| t.0), "OFF face")?;
    let body = len.saturating_sub(tokens.get(first + 1).map(|t| t.1 as u64).unwrap_or(0));
    // A vertex: 3 coordinates; a face: its corner count and 3 indices.
    let (per_v, per_f) = if binary { (12, 16) } else { (6, 8) };
    let need = nv.saturating_mul(per_v).saturating_add(nf.saturating_mul(per_f));
    if need > body {
        return Err(format!(
            "declares {nv} vertices and {nf} faces, at least {need} bytes, but holds {body} bytes after its header (truncated or damaged)"
        ));
    }
    if !binary {
        // Text OFF: the line after the counts starts the vertices; each face
        // line starts with its corner count, which must fit in what is left.
        // (Binary OFF, rare, gets the size check above only.)
        let counts_end = tokens.get(first + 1).map(|t| t.1).unwrap_or(0).min(all.len());
        let rest = &all[counts_end..];
        let body_at = rest.iter().position(|&b| b == b'\n').map(|p| counts_end + p + 1).unwrap_or(all.len());
        let mut seen = 0u64;
        let mut at = body_at;
        for line in all[body_at..].split_inclusive(|&b| b == b'\n') {
            let start = at;
            at += line.len();
            let content = line.split(|&b| b == b'#').next().unwrap_or(&[]);
            let Some(first_token) = content.split(|b| b.is_ascii_whitespace()).find(|t| !t.is_empty()) else { continue };
            seen += 1;
            if seen <= nv {
                continue;
            }
            if seen > nv + nf {
                break;
            }
            let f = seen - nv - 1;
            let n = std::str::from_utf8(first_token).ok().and_then(|t| t.parse::<u64>().ok()).ok_or_else(|| {
                format!("face {f}: corner count '{}' is not a number", String::from_utf8_lossy(first_token))
            })?;
            if n.saturating_mul(2) > (all.len() - start) as u64 {
                return Err(format!("face {f} declares {n} corners, more than the file holds (damaged)"));
            }
        }
    }
    Ok(Declared { vertices: Some(nv), faces: Some(nf) })
}

fn check_stl(path: &Path, head: &[u8], len: u64) -> Result<Declared, String> {
    // Binary STL: 80-byte header, a u32 triangle count, 50 bytes per triangle.
    if head.len() >= 84 {
        let n = u32::from_le_bytes([head[80], head[81], head[82], head[83]]) as u64;
        if 84 + 50 * n == len {
            return Ok(Declared { vertices: None, faces: Some(n) });
        }
    }
    if head.starts_with(b"solid") {
        // Text STL: one face per "endfacet"; its memory grows with its text.
        let all = std::fs::read(path).map_err(|e| e.to_string())?;
        let faces = all.windows(8).filter(|w| w == b"endfacet").count() as u64;
        // Text STL declares no count: a missing last line is the one sign of a
        // cut file. OpenMesh reads what is there.
        if find(&all[all.len().saturating_sub(256)..], b"endsolid").is_none() {
            log::warn!("{}: text STL has no closing 'endsolid' (cut short?); read {faces} facets", path.display());
        }
        return Ok(Declared { vertices: None, faces: Some(faces) });
    }
    Err(if head.len() >= 84 {
        let n = u32::from_le_bytes([head[80], head[81], head[82], head[83]]) as u64;
        format!("binary STL declares {n} triangles ({} bytes) but is {len} bytes long (truncated or damaged)", 84 + 50 * n)
    } else {
        "is neither a text STL ('solid ...') nor a binary one (shorter than its 84-byte header)".into()
    })
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ply_text_nan_vertices_are_named() {
        let ply = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\nnan 1 0\n0 0 1\n3 0 1 2\n";
        let err = check_ply(ply).unwrap_err();
        assert!(err.contains("vertex 1 has a NaN"), "{err}");
        let fine = String::from_utf8_lossy(ply).replace("nan", "1e-3");
        assert!(check_ply(fine.as_bytes()).is_ok());
    }

    #[test]
    fn ply_counts_beyond_the_file_are_errors() {
        let h = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
        let len = h.len() as u64 + 3 * 12 + 13;
        let mut file = h.to_vec();
        file.extend(std::iter::repeat(0u8).take(36));
        file.extend([3u8, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]);
        assert_eq!(file.len() as u64, len, "the header, 3 vertices of 12 bytes, one 13-byte face");
        assert_eq!(check_ply(&file).unwrap(), Declared { vertices: Some(3), faces: Some(1) });
        let e = check_ply(&file[..file.len() - 20]).unwrap_err();
        assert!(e.contains("truncated"), "{e}");
        let huge = String::from_utf8_lossy(&file).replace("vertex 3", "vertex 2000000000");
        assert!(check_ply(huge.as_bytes()).is_err());
        let bad = String::from_utf8_lossy(&file).replace("vertex 3", "vertex -3");
        assert!(check_ply(bad.as_bytes()).unwrap_err().contains("not a number"));
        // A face whose list count (uchar 255) runs past the end.
        let mut long_face = file.clone();
        let n = long_face.len();
        long_face[n - 13] = 255;
        assert!(check_ply(&long_face).unwrap_err().contains("list of 255"));
    }

    #[test]
    fn off_counts_beyond_the_file_are_errors() {
        let f = b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        assert_eq!(check_off(f).unwrap(), Declared { vertices: Some(3), faces: Some(1) });
        let f2 = b"OFF\n3000000 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        assert!(check_off(f2).is_err());
        assert!(check_off(b"FOO\n1 2 3\n").is_err());
        // The corner count of a face trusted by OpenMesh: 12 GB and 35 s before.
        let f3 = b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2000000000 0 1 2\n";
        assert!(check_off(f3).unwrap_err().contains("2000000000 corners"));
    }
}
