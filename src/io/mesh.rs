//! Meshes: the `Mesh` type, loading through OpenMesh (OBJ+MTL, PLY, OFF, STL)
//! with validation, writing PLY or glTF binary (`.glb`, [`crate::io::glb`]) with
//! vertex colours, and quadric decimation ([`decimate`]).

use std::collections::HashMap;
use std::path::Path;

use glam::{Vec2, Vec3};

use crate::error::{Error, Result};
use crate::util::fs::{check_input_file, write_atomically, write_file};
use crate::io::ffi::bridge;

pub use super::mesh_data::{Mesh, MeshColours, MeshSummary, Texture, Wrap, COLOUR_EXTENSIONS, MESH_EXTENSIONS, NO_IMAGE, WRITE_EXTENSIONS};

fn extension(path: &Path) -> String {
    path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default()
}

fn chunks3(flat: &[f32]) -> Vec<Vec3> {
    flat.chunks_exact(3).map(Vec3::from_slice).collect()
}

/// Loads a mesh, checks it, and resolves its colour source. A texture that
/// the material names but that cannot be read is a warning, not a failure.
pub fn load(path: &Path) -> Result<Mesh> {
    check_input_file(path)?;
    let ext = extension(path);
    if !MESH_EXTENSIONS.contains(&ext.as_str()) {
        return Err(Error::file(
            path,
            format!("unsupported mesh format '.{ext}' (expected .obj, .ply, .off, .stl, .glb, .gltf, .fbx or .dae; point clouds: .las, .laz, .e57)"),
        ));
    }
    if ext == "glb" || ext == "gltf" {
        // glTF is read in Rust (src/io/gltf_read.rs).
        let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let mesh = crate::io::gltf_read::read_bytes(&bytes, dir, &name).map_err(|e| Error::file(path, e))?;
        return check_mesh(path, mesh);
    }
    if crate::io::assimp::EXTENSIONS.contains(&ext.as_str()) {
        return check_mesh(path, crate::io::assimp::load(path)?);
    }
    if ext == "obj" {
        // OBJ is read in Rust (src/io/obj.rs says why: OpenMesh's reader aborts
        // the process on some malformed face lines).
        let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let (data, dropped) = crate::io::obj::read(&bytes, dir, &path.display().to_string())
            .map_err(|e| Error::file(path, e.to_string()))?;
        if dropped.faces > 0 {
            log::warn!(
                "{}: dropped {} faces with fewer than 3 corners or a vertex index outside the file's {} vertices",
                path.display(),
                dropped.faces,
                data.positions.len() / 3
            );
        }
        if dropped.uvs > 0 {
            log::warn!("{}: {} faces have a texture-coordinate index out of range: kept without UVs", path.display(), dropped.uvs);
        }
        return from_bridge(path, data);
    }
    // PLY, OFF and STL go through OpenMesh, after the sizes their headers
    // declare were checked against the file's length (src/io/mesh_check.rs).
    let declared = crate::io::mesh_check::check(path, &ext)?;
    let path_str = path.to_str().ok_or_else(|| Error::file(path, "path is not valid UTF-8"))?;
    let data = bridge::read_mesh(path_str).map_err(|e| Error::file(path, e.what()))?;
    if let Some(faces) = declared.faces {
        if data.faces_in_file < faces {
            // OpenMesh skips faces it cannot add (an index out of range, a
            // non-manifold edge) without telling: count them.
            log::warn!(
                "{}: dropped {} of the {faces} faces the file declares (invalid vertex indices or non-manifold edges)",
                path.display(),
                faces - data.faces_in_file
            );
        }
    }
    from_bridge(path, data)
}

/// The checks [`from_bridge`] makes, on a mesh read in Rust: finite
/// positions, degenerate triangles dropped (with their corners' colours,
/// UVs and image indices) with a warning, some triangle left.
fn check_mesh(path: &Path, mut mesh: Mesh) -> Result<Mesh> {
    if mesh.positions.is_empty() {
        return Err(Error::file(path, "has no vertices"));
    }
    if let Some(i) = mesh.positions.iter().position(|p| !p.is_finite()) {
        return Err(Error::file(path, format!("vertex {i} has a NaN or infinite coordinate")));
    }
    let total = mesh.triangles.len();
    let dropped = mesh.drop_degenerate_triangles();
    if dropped == total {
        return Err(Error::file(path, format!("all {dropped} triangles are degenerate (zero area or repeated vertices)")));
    }
    if dropped > 0 {
        log::warn!("{}: dropped {dropped} degenerate triangles", path.display());
    }
    Ok(mesh)
}

fn from_bridge(path: &Path, data: bridge::MeshData) -> Result<Mesh> {
    let positions = chunks3(&data.positions);
    if positions.is_empty() {
        return Err(Error::file(path, "has no vertices"));
    }
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(Error::file(path, format!("vertex {i} has a NaN or infinite coordinate")));
    }
    if data.faces_in_file == 0 {
        return Err(Error::file(path, "has no faces"));
    }

    // Degenerate triangles (repeated vertex or zero area) carry no surface:
    // drop them with a warning; a mesh with nothing else is an error.
    let mut keep = Vec::with_capacity(data.triangles.len() / 3);
    let mut triangles = Vec::with_capacity(data.triangles.len() / 3);
    for (t, tri) in data.triangles.chunks_exact(3).enumerate() {
        let [a, b, c] = [tri[0], tri[1], tri[2]];
        let (pa, pb, pc) = (positions[a as usize], positions[b as usize], positions[c as usize]);
        let area2 = (pb - pa).cross(pc - pa).length();
        if a != b && b != c && a != c && area2 > 0.0 {
            keep.push(t);
            triangles.push([a, b, c]);
        }
    }
    let dropped = data.triangles.len() / 3 - triangles.len();
    if triangles.is_empty() {
        return Err(Error::file(
            path,
            format!("all {dropped} triangles are degenerate (zero area or repeated vertices)"),
        ));
    }
    if dropped > 0 {
        log::warn!("{}: dropped {dropped} degenerate triangles", path.display());
    }

    let corners = |flat: &[f32], width: usize| -> Vec<f32> {
        keep.iter().flat_map(|&t| flat[t * 3 * width..(t + 1) * 3 * width].to_vec()).collect()
    };
    let mut colours = MeshColours::None;
    if !data.vertex_colours.is_empty() {
        colours = MeshColours::PerVertex(chunks3(&data.vertex_colours));
    } else if !data.face_colours.is_empty() {
        // One colour per triangle: repeat it at the three corners.
        let per_face = chunks3(&data.face_colours);
        colours = MeshColours::PerCorner(keep.iter().flat_map(|&t| [per_face[t]; 3]).collect());
    }
    let texture = if data.corner_uvs.is_empty() {
        None
    } else {
        let uvs: Vec<Vec2> =
            corners(&data.corner_uvs, 2).chunks_exact(2).map(Vec2::from_slice).collect();
        load_texture(path, &data).map(|image| Texture { uvs, image, ..Default::default() })
    };
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(Mesh { name, positions, triangles, colours, texture })
}

/// Reads the diffuse texture an OBJ's material names, relative to the OBJ.
/// Several textures: the one most triangles use. Unreadable: warn, None.
fn load_texture(path: &Path, data: &bridge::MeshData) -> Option<image::RgbImage> {
    let mut uses: HashMap<i32, usize> = HashMap::new();
    for &t in &data.face_texture {
        *uses.entry(t).or_default() += 1;
    }
    let most_used = uses.into_iter().max_by_key(|&(id, n)| (n, -id)).map(|(id, _)| id);
    let file = data
        .texture_ids
        .iter()
        .zip(&data.texture_files)
        .find(|(&id, _)| Some(id) == most_used)
        .or_else(|| data.texture_ids.iter().zip(&data.texture_files).next())
        .map(|(_, f)| f.clone())?;
    if data.texture_files.len() > 1 {
        log::warn!("{}: {} textures; using {file} for all", path.display(), data.texture_files.len());
    }
    let texture_path = path.parent().unwrap_or(Path::new(".")).join(&file);
    match image::open(&texture_path) {
        Ok(img) => Some(img.to_rgb8()),
        Err(e) => {
            log::warn!(
                "{}: texture {} cannot be read ({e}); using a constant colour",
                path.display(),
                texture_path.display()
            );
            None
        }
    }
}

/// Writes a mesh, in the format its extension names (`WRITE_EXTENSIONS`),
/// atomically. PLY (`binary` or ASCII) keeps vertex colours (per-corner
/// colours are averaged onto vertices); glTF binary (`.glb`) keeps them or a
/// mesh's texture; a textured mesh's OBJ is OBJ + MTL + PNG
/// ([`crate::io::obj::write_textured`]); otherwise OBJ, OFF and STL are
/// written without colour.
pub fn save(mesh: &Mesh, path: &Path, binary: bool) -> Result<()> {
    let ext = extension(path);
    if !WRITE_EXTENSIONS.contains(&ext.as_str()) {
        return Err(Error::file(path, format!("cannot write mesh format '.{ext}' (expected .ply, .glb, .obj, .off or .stl)")));
    }
    if ext == "glb" {
        let bytes = crate::io::glb::to_bytes(mesh).map_err(|e| Error::file(path, e.to_string()))?;
        return write_file(path, &bytes);
    }
    if ext == "obj" && mesh.texture.is_some() {
        return crate::io::obj::write_textured(mesh, path);
    }
    let vertex_colours: Vec<f32> = match mesh.vertex_colours() {
        Some(c) if ext == "ply" => c.iter().flat_map(|c| c.to_array()).collect(),
        _ => Vec::new(),
    };
    let data = bridge::MeshData {
        positions: mesh.positions.iter().flat_map(|p| p.to_array()).collect(),
        triangles: mesh.triangles.iter().flatten().copied().collect(),
        vertex_colours,
        faces_in_file: mesh.triangles.len() as u64,
        ..Default::default()
    };
    write_atomically(path, |tmp| {
        let tmp_str = tmp.to_str().ok_or_else(|| Error::file(path, "path is not valid UTF-8"))?;
        bridge::write_mesh(tmp_str, &data, binary).map_err(|e| Error::file(path, e.what()))
    })
}

/// Settings of [`decimate`].
#[derive(Clone, Debug, PartialEq)]
pub struct DecimateOptions {
    /// Triangles to keep. At least 1; a budget at or above the mesh's count
    /// leaves the mesh as it is.
    pub target_faces: usize,
    /// Dihedral angle (degrees between face normals) above which an edge is a
    /// sharp feature: feature lines are simplified only along themselves and
    /// their corners stay. 180 (the default) marks none: the quadric error
    /// alone already keeps creases (a collapse off a crease costs the squared
    /// distance to both planes), while explicit lines at 60 or 80 degrees
    /// marked 7-11% of the edges of a Poisson mesh at 256 (the demo tower's
    /// stones) and stopped its decimation at 8-10 times the budget.
    pub feature_angle_deg: f64,
    /// Largest turn (degrees) of a face's normal that one collapse may cause:
    /// no fold-overs, no slivers flipping over.
    pub max_normal_deviation_deg: f64,
}

impl DecimateOptions {
    pub fn new(target_faces: usize) -> Self {
        DecimateOptions { target_faces, feature_angle_deg: 180.0, max_normal_deviation_deg: 60.0 }
    }
}

/// What [`decimate`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct DecimateReport {
    pub faces_before: usize,
    pub faces_after: usize,
    /// Edges kept as sharp features.
    pub feature_edges: usize,
}

/// Reduces a mesh towards `options.target_faces` triangles by quadric-error
/// halfedge collapses (OpenMesh's decimater; cpp/mesh_decimate.cpp). Every
/// surviving vertex keeps its position and colour (per-corner colours are
/// averaged onto vertices first); open boundaries stay boundaries, and sharp
/// edges are kept by the quadric error (or pinned as feature lines). A budget at or above the mesh's triangle count returns the mesh
/// unchanged. The budget may be missed (more triangles remain) where no
/// collapse is legal any more: the report says how many remain. Errors: a
/// budget of 0, a textured mesh (its UVs would not survive).
pub fn decimate(mesh: &Mesh, options: &DecimateOptions) -> Result<(Mesh, DecimateReport)> {
    if options.target_faces == 0 {
        return Err(Error::Invalid("the face budget must be at least 1 triangle".into()));
    }
    if mesh.texture.is_some() {
        return Err(Error::Invalid(format!("{}: a textured mesh cannot be decimated (its UVs would be lost)", mesh.name)));
    }
    let faces_before = mesh.triangles.len();
    if options.target_faces >= faces_before {
        let report = DecimateReport { faces_before, faces_after: faces_before, feature_edges: 0 };
        return Ok((mesh.clone(), report));
    }
    let positions: Vec<f32> = mesh.positions.iter().flat_map(|p| p.to_array()).collect();
    let triangles: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let params = bridge::DecimateParams {
        target_faces: options.target_faces as u64,
        feature_angle_deg: options.feature_angle_deg,
        max_normal_deviation_deg: options.max_normal_deviation_deg,
    };
    let out = bridge::decimate_mesh(&positions, &triangles, &params)
        .map_err(|e| Error::Invalid(format!("{}: decimation failed: {}", mesh.name, e.what())))?;
    let colours = match mesh.vertex_colours() {
        None => MeshColours::None,
        Some(c) => MeshColours::PerVertex(out.source_vertex.iter().map(|&i| c[i as usize]).collect()),
    };
    let decimated = Mesh {
        name: mesh.name.clone(),
        positions: chunks3(&out.positions),
        triangles: out.triangles.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        colours,
        texture: None,
    };
    let report = DecimateReport {
        faces_before,
        faces_after: decimated.triangles.len(),
        feature_edges: out.feature_edges as usize,
    };
    Ok((decimated, report))
}

/// Writes an oriented coloured point set as a binary little-endian PLY
/// (x y z nx ny nz as float, red green blue as uchar), atomically. For tools
/// that want points, not surfaces.
pub fn save_points_ply(path: &Path, positions: &[Vec3], normals: &[Vec3], colours: &[Vec3]) -> Result<()> {
    if positions.len() != normals.len() || positions.len() != colours.len() {
        return Err(Error::Invalid("point, normal and colour counts differ".into()));
    }
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\ncomment {}\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        crate::io::vdb::CREATOR,
        positions.len()
    )
    .into_bytes();
    bytes.reserve(positions.len() * 27);
    for ((p, n), c) in positions.iter().zip(normals).zip(colours) {
        for v in p.to_array().into_iter().chain(n.to_array()) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        for v in c.to_array() {
            bytes.push((v.clamp(0.0, 1.0) * 255.0).round() as u8);
        }
    }
    write_file(path, &bytes)
}

#[cfg(test)]
mod tests {
    use crate::io::ffi::bridge::{write_mesh, MeshData};

    /// The C++ writer checks the arrays it is given (public fields on this
    /// side): a colour array shorter than the vertices, an index past them,
    /// are errors, not reads out of bounds.
    #[test]
    fn the_cxx_writer_checks_the_lengths_it_is_given() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.ply");
        let p = path.to_str().unwrap();
        let triangle = MeshData { positions: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], triangles: vec![0, 1, 2], ..Default::default() };
        write_mesh(p, &triangle, true).unwrap();
        let short_colours = MeshData { vertex_colours: vec![1.0; 3], ..triangle.clone_data() };
        assert!(write_mesh(p, &short_colours, true).unwrap_err().what().contains("colour values for 3 vertices"));
        let past_end = MeshData { triangles: vec![0, 1, 3], ..triangle.clone_data() };
        assert!(write_mesh(p, &past_end, true).unwrap_err().what().contains("past its 3 vertices"));
        let ragged = MeshData { positions: vec![0.0; 8], ..triangle.clone_data() };
        assert!(write_mesh(p, &ragged, true).unwrap_err().what().contains("not triples"));
    }

    impl MeshData {
        fn clone_data(&self) -> MeshData {
            MeshData {
                positions: self.positions.clone(),
                triangles: self.triangles.clone(),
                vertex_colours: self.vertex_colours.clone(),
                ..Default::default()
            }
        }
    }
}
