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
    let r = match ext {
        "ply" => check_ply(&head, len),
        "off" => check_off(&head, len),
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

fn check_ply(head: &[u8], len: u64) -> Result<Declared, String> {
    let end = find(head, b"end_header").ok_or("PLY header has no end_header in its first 64 KiB")?;
    // The body starts after the end_header line's newline.
    let body_start = head[end..].iter().position(|&b| b == b'\n').map(|p| end + p + 1).unwrap_or(head.len());
    let body = len.saturating_sub(body_start as u64);
    let text = String::from_utf8_lossy(&head[..end]);
    let mut lines = text.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err("does not start with 'ply'".into());
    }
    let mut binary = None;
    // (name, count, bytes per record at least, numbers per record at least)
    let mut elements: Vec<(String, u64, u64, u64)> = Vec::new();
    for line in lines {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first().copied() {
            Some("format") => binary = Some(t.get(1).copied() != Some("ascii")),
            Some("element") => {
                let name = t.get(1).copied().unwrap_or("").to_string();
                let count = parse_count(t.get(2).copied(), &format!("PLY element '{name}'"))?;
                elements.push((name, count, 0, 0));
            }
            Some("property") => {
                let e = elements.last_mut().ok_or("PLY property before any element")?;
                let size = if t.get(1) == Some(&"list") {
                    t.get(2).and_then(|s| scalar_size(s))
                } else {
                    t.get(1).and_then(|s| scalar_size(s))
                };
                e.2 += size.ok_or_else(|| format!("PLY property type in '{}' is unknown", line.trim()))?;
                e.3 += 1;
            }
            _ => {}
        }
    }
    let binary = binary.ok_or("PLY header has no format line")?;
    let mut need = 0u64;
    for (name, count, bytes, numbers) in &elements {
        let per = if binary { *bytes } else { 2 * *numbers };
        need = need.saturating_add(count.saturating_mul(per));
        if need > body {
            return Err(format!(
                "declares {count} {name} records, at least {need} bytes, but holds {body} bytes after its header (truncated or damaged)"
            ));
        }
    }
    let count_of = |n: &str| elements.iter().find(|e| e.0 == n).map(|e| e.1);
    Ok(Declared { vertices: count_of("vertex"), faces: count_of("face") })
}

fn check_off(head: &[u8], len: u64) -> Result<Declared, String> {
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
    fn ply_counts_beyond_the_file_are_errors() {
        let h = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
        let len = h.len() as u64 + 3 * 12 + 13;
        assert_eq!(check_ply(h, len).unwrap(), Declared { vertices: Some(3), faces: Some(1) });
        let e = check_ply(h, len - 20).unwrap_err();
        assert!(e.contains("truncated"), "{e}");
        let huge = String::from_utf8_lossy(h).replace("vertex 3", "vertex 2000000000");
        assert!(check_ply(huge.as_bytes(), len).is_err());
        let bad = String::from_utf8_lossy(h).replace("vertex 3", "vertex -3");
        assert!(check_ply(bad.as_bytes(), len).unwrap_err().contains("not a number"));
    }

    #[test]
    fn off_counts_beyond_the_file_are_errors() {
        let f = b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        assert_eq!(check_off(f, f.len() as u64).unwrap(), Declared { vertices: Some(3), faces: Some(1) });
        let f2 = b"OFF\n3000000 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        assert!(check_off(f2, f2.len() as u64).is_err());
        assert!(check_off(b"FOO\n1 2 3\n", 10).is_err());
    }
}
