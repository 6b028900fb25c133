//! Wavefront OBJ (+ MTL) reading in Rust.
//!
//! Why not OpenMesh: its OBJ reader asserts (`OBJReader.cc: !vhandles.empty()`)
//! on a face line whose vertices it cannot use, which aborts the whole process;
//! a batch `run` then dies on one bad file. Why not the `tobj` crate: it
//! renumbers vertices per material group (a vertex shared by two groups
//! becomes two), which opens a closed mesh along every material boundary
//! and changes what `info` and the mesher's `auto` see; and it rejects a whole
//! file for one out-of-range index. This reader keeps the file's global vertex
//! numbering, as OpenMesh did.
//!
//! What it reads: `v x y z [r g b]` (vertex colours when every vertex has
//! them), `vt u v`, `f` with `v`, `v/t`, `v//n`, `v/t/n` corners (negative
//! indices count back from the last vertex), polygons fan-triangulated
//! (corners 0, i, i+1), `usemtl`, `mtllib`; from the MTL: `newmtl`, `Kd`,
//! `map_Kd`. Everything else (normals, groups, smoothing, lines) is ignored.
//!
//! Bounds: memory grows only with what the file holds (every stored value
//! comes from at least two bytes of text), so a damaged file costs a small
//! multiple of its size; a number that does not parse is an error naming the
//! line; a face with a missing or out-of-range index is dropped and counted.

use std::collections::HashMap;
use std::path::Path;

use crate::io::ffi::bridge::MeshData;

/// Why an OBJ or MTL could not be read: the message names the line.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ObjError(pub String);

/// What the reader dropped, for one warning.
#[derive(Debug, Default, PartialEq)]
pub struct Dropped {
    /// Faces with fewer than 3 corners or a vertex index outside the file's vertices.
    pub faces: usize,
    /// Faces kept without texture coordinates because a `vt` index was out of range.
    pub uvs: usize,
}

struct Material {
    kd: Option<[f32; 3]>,
    texture: Option<String>,
}

fn parse_floats<const N: usize>(tokens: &[&str], line: usize, what: &str) -> Result<[f32; N], ObjError> {
    let mut out = [0f32; N];
    if tokens.len() < N {
        return Err(ObjError(format!("line {line}: '{what}' needs {N} numbers, has {}", tokens.len())));
    }
    for (o, t) in out.iter_mut().zip(tokens) {
        *o = t
            .parse::<f32>()
            .map_err(|_| ObjError(format!("line {line}: '{t}' is not a number")))?;
    }
    Ok(out)
}

/// An OBJ index (1-based, or negative: relative to the count so far) as a
/// 0-based index below `count`, or None when it is outside.
fn resolve(token: &str, count: usize, line: usize) -> Result<Option<usize>, ObjError> {
    let i: i64 = token
        .parse()
        .map_err(|_| ObjError(format!("line {line}: face index '{token}' is not an integer")))?;
    let idx = if i > 0 { i - 1 } else { count as i64 + i };
    Ok((i != 0 && idx >= 0 && (idx as u64) < count as u64).then_some(idx as usize))
}

/// Reads the materials of one MTL file (text already in memory).
fn parse_mtl(text: &str, into: &mut Vec<(String, Material)>) -> Result<(), ObjError> {
    for (n, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("");
        let tokens: Vec<&str> = line.split_whitespace().collect();
        match tokens.first().copied() {
            Some("newmtl") => {
                let name = tokens[1..].join(" ");
                into.push((name, Material { kd: None, texture: None }));
            }
            Some("Kd") => {
                let kd = parse_floats::<3>(&tokens[1..], n + 1, "Kd")?;
                if let Some((_, m)) = into.last_mut() {
                    m.kd = Some(kd);
                }
            }
            // Options (-s, -o, -bm ...) come before the file name: take the last token.
            Some("map_Kd") => {
                if let (Some((_, m)), Some(file)) = (into.last_mut(), tokens.last().filter(|_| tokens.len() > 1)) {
                    m.texture = Some(file.to_string());
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Reads an OBJ file's bytes; MTL files it names are read relative to `dir`
/// (an MTL that cannot be read is a warning). Returns the flattened mesh in
/// the bridge's layout (so one validation path serves every format) and
/// what was dropped.
pub fn read(bytes: &[u8], dir: &Path, name: &str) -> Result<(MeshData, Dropped), ObjError> {
    let text = String::from_utf8_lossy(bytes);
    let mut positions: Vec<f32> = Vec::new();
    let mut colours: Vec<f32> = Vec::new();
    let mut uvs: Vec<[f32; 2]> = Vec::new();
    let mut materials: Vec<(String, Material)> = Vec::new();
    let mut by_name: HashMap<String, usize> = HashMap::new();
    let mut current: Option<usize> = None;
    let mut pending_usemtl: Option<String> = None;
    let mut out = MeshData::default();
    // Per triangle: the material, or None.
    let mut tri_material: Vec<Option<usize>> = Vec::new();
    let mut tri_uvs: Vec<Option<[[f32; 2]; 3]>> = Vec::new();
    let mut dropped = Dropped::default();
    let mut faces = 0u64;
    let mut corners: Vec<(usize, Option<usize>)> = Vec::new();

    for (n, raw) in text.lines().enumerate() {
        let line_no = n + 1;
        let line = raw.split('#').next().unwrap_or("");
        let mut tokens = line.split_whitespace();
        let Some(key) = tokens.next() else { continue };
        let rest: Vec<&str> = tokens.collect();
        match key {
            "v" => {
                let p = parse_floats::<3>(&rest, line_no, "v")?;
                positions.extend_from_slice(&p);
                // x y z r g b: a vertex colour (x y z w has 4 numbers: no colour).
                if rest.len() >= 6 {
                    colours.extend_from_slice(&parse_floats::<3>(&rest[3..], line_no, "v colour")?);
                }
            }
            "vt" => {
                // A single u is allowed by the format: v defaults to 0.
                let uv = if rest.len() == 1 { [parse_floats::<1>(&rest, line_no, "vt")?[0], 0.0] } else { parse_floats::<2>(&rest, line_no, "vt")? };
                uvs.push(uv);
            }
            "f" => {
                faces += 1;
                let nv = positions.len() / 3;
                corners.clear();
                let mut bad = false;
                let mut bad_uv = false;
                for t in &rest {
                    let mut parts = t.split('/');
                    let v = resolve(parts.next().unwrap_or(""), nv, line_no)?;
                    let vt = match parts.next() {
                        Some(s) if !s.is_empty() => {
                            let r = resolve(s, uvs.len(), line_no)?;
                            bad_uv |= r.is_none();
                            r
                        }
                        _ => None,
                    };
                    match v {
                        Some(v) => corners.push((v, vt)),
                        None => bad = true,
                    }
                }
                if bad || corners.len() < 3 {
                    dropped.faces += 1;
                    continue;
                }
                let all_uv = corners.iter().all(|c| c.1.is_some());
                if bad_uv {
                    dropped.uvs += 1;
                }
                if let Some(name) = pending_usemtl.take() {
                    current = by_name.get(&name).copied();
                }
                for i in 1..corners.len() - 1 {
                    let tri = [corners[0], corners[i], corners[i + 1]];
                    out.triangles.extend(tri.iter().map(|c| c.0 as u32));
                    tri_material.push(current);
                    tri_uvs.push(all_uv.then(|| tri.map(|c| uvs[c.1.unwrap_or(0)])));
                }
            }
            "usemtl" => pending_usemtl = Some(rest.join(" ")),
            "mtllib" => {
                // One or more file names; a missing one is a warning, as a
                // missing texture is.
                for file in &rest {
                    let path = dir.join(file);
                    match std::fs::read(&path) {
                        Ok(b) => {
                            let before = materials.len();
                            parse_mtl(&String::from_utf8_lossy(&b), &mut materials)
                                .map_err(|e| ObjError(format!("material file {}: {}", path.display(), e.0)))?;
                            for (i, (name, _)) in materials.iter().enumerate().skip(before) {
                                by_name.entry(name.clone()).or_insert(i);
                            }
                        }
                        Err(e) => log::warn!("{name}: material file {} cannot be read ({e}); no material colours", path.display()),
                    }
                }
            }
            _ => {}
        }
    }

    let nv = positions.len() / 3;
    out.positions = positions;
    // Colours only when every vertex has one (a partial set cannot be trusted).
    if !colours.is_empty() && colours.len() == 3 * nv {
        out.vertex_colours = colours;
    }
    out.faces_in_file = faces - dropped.faces as u64;
    let used_material = tri_material.iter().any(|m| m.is_some());
    if used_material && materials.iter().any(|(_, m)| m.kd.is_some()) {
        // Faces without a material, or with one without Kd: white, the MTL default.
        out.face_colours = tri_material
            .iter()
            .flat_map(|m| m.and_then(|m| materials[m].1.kd).unwrap_or([1.0; 3]))
            .collect();
    }
    if tri_uvs.iter().any(|t| t.is_some()) {
        out.corner_uvs = tri_uvs.iter().flat_map(|t| t.unwrap_or([[0.0; 2]; 3])).flatten().collect();
        out.face_texture = tri_material
            .iter()
            .map(|m| m.filter(|&m| materials[m].1.texture.is_some()).map_or(-1, |m| m as i32))
            .collect();
        for (i, (_, m)) in materials.iter().enumerate() {
            if let Some(t) = &m.texture {
                out.texture_ids.push(i as i32);
                out.texture_files.push(t.clone());
            }
        }
    }
    Ok((out, dropped))
}

/// The image file a textured OBJ's material names: `<stem>_basecolor.png`
/// beside the `.obj`.
pub fn texture_path(obj: &Path) -> std::path::PathBuf {
    let stem = obj.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "mesh".into());
    obj.with_file_name(format!("{stem}_basecolor.png"))
}

/// Writes a textured mesh as OBJ + MTL + PNG (`X.obj`, `X.mtl`,
/// `X_basecolor.png`), each atomically, the image and material first so an
/// `.obj` never names a file that is not there. Corners carry `v/vt/vn`;
/// one `vt` per corner (OBJ's v = 0 is the image's bottom row, as in
/// [`Texture`](crate::io::mesh_data::Texture)); the material is matte, its
/// `map_Kd` the image.
pub fn write_textured(mesh: &crate::io::mesh_data::Mesh, path: &Path) -> crate::error::Result<()> {
    use std::fmt::Write as _;
    use crate::error::Error;
    let tex = mesh.texture.as_ref().ok_or_else(|| Error::file(path, "the mesh has no texture"))?;
    let image_path = texture_path(path);
    let mtl_path = path.with_extension("mtl");
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut png = std::io::Cursor::new(Vec::new());
    tex.image.write_to(&mut png, image::ImageFormat::Png).map_err(|e| Error::file(&image_path, e.to_string()))?;
    crate::util::fs::write_file(&image_path, png.into_inner())?;
    let mtl = format!(
        "# {}\nnewmtl baked\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nNs 1\nillum 1\nmap_Kd {}\n",
        crate::io::vdb::CREATOR,
        name(&image_path)
    );
    crate::util::fs::write_file(&mtl_path, mtl)?;
    let normals = mesh.vertex_normals();
    let mut s = String::with_capacity(mesh.positions.len() * 80 + mesh.triangles.len() * 60);
    let _ = write!(s, "# {}\nmtllib {}\nusemtl baked\n", crate::io::vdb::CREATOR, name(&mtl_path));
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
    }
    for n in &normals {
        let _ = writeln!(s, "vn {} {} {}", n.x, n.y, n.z);
    }
    for uv in &tex.uvs {
        let _ = writeln!(s, "vt {} {}", uv.x, uv.y);
    }
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let c = |k: usize| format!("{}/{}/{}", tri[k] + 1, 3 * t + k + 1, tri[k] + 1);
        let _ = writeln!(s, "f {} {} {}", c(0), c(1), c(2));
    }
    crate::util::fs::write_file(path, s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_str(s: &str) -> Result<(MeshData, Dropped), ObjError> {
        read(s.as_bytes(), Path::new("."), "test.obj")
    }

    #[test]
    fn quads_are_fans_and_negative_indices_count_back() {
        let (m, d) = read_str("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\nf -4 -3 -1\n").unwrap();
        assert_eq!(m.triangles, vec![0, 1, 2, 0, 2, 3, 0, 1, 3]);
        assert_eq!(m.faces_in_file, 2);
        assert_eq!(d, Dropped::default());
    }

    #[test]
    fn faces_with_bad_indices_are_dropped_and_counted() {
        let (m, d) = read_str("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 1 2 9\nf 0 1 2\nf 1 2\nf\n").unwrap();
        assert_eq!(m.triangles, vec![0, 1, 2]);
        assert_eq!(d.faces, 4);
        assert_eq!(m.faces_in_file, 1);
    }

    #[test]
    fn garbage_numbers_are_errors_naming_the_line() {
        let e = read_str("v 0 0 0\nv 1 zero 0\n").err().expect("an error");
        assert!(e.0.contains("line 2") && e.0.contains("zero"), "{}", e.0);
        let e = read_str("v 0 0 0\nf 1 x 3\n").err().expect("an error");
        assert!(e.0.contains("line 2"), "{}", e.0);
    }

    #[test]
    fn vertex_colours_and_uvs_come_through() {
        let (m, _) = read_str("v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n").unwrap();
        assert_eq!(m.vertex_colours.len(), 9);
        assert_eq!(m.corner_uvs, vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0]);
    }
}
