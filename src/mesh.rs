//! Meshes: the `Mesh` type, loading through OpenMesh (OBJ+MTL, PLY, OFF, STL)
//! with validation, and writing PLY with vertex colours.

use std::collections::HashMap;
use std::path::Path;

use glam::{Vec2, Vec3};

use crate::error::{check_input_file, write_atomically, Error, Result};
use crate::ffi::bridge;

/// Where a mesh's colour comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum MeshColours {
    /// No colour in the file: encoders use a constant colour.
    None,
    /// One RGB in [0,1] per vertex (PLY/OFF vertex colours).
    PerVertex(Vec<Vec3>),
    /// One RGB in [0,1] per triangle corner, `3 * triangles.len()` entries
    /// (a material's Kd colour).
    PerCorner(Vec<Vec3>),
}

/// A triangle mesh in its own frame and units.
#[derive(Clone, Debug)]
pub struct Mesh {
    pub name: String,
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub colours: MeshColours,
    /// Per-corner UVs (3 per triangle) with the texture they index, so that
    /// encoders sample the texture at interior points. Takes precedence over
    /// `colours` where present.
    pub texture: Option<Texture>,
}

/// A diffuse texture with per-corner UVs.
#[derive(Clone, Debug)]
pub struct Texture {
    pub uvs: Vec<Vec2>,
    pub image: image::RgbImage,
}

/// Mesh formats we read, by extension.
pub const MESH_EXTENSIONS: &[&str] = &["obj", "ply", "off", "stl"];

/// What `info` reports about a mesh.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MeshSummary {
    pub vertices: usize,
    pub triangles: usize,
    pub bbox_min: [f32; 3],
    pub bbox_max: [f32; 3],
    /// Edges used by one triangle only; 0 means closed.
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    pub colour_source: String,
}

impl Mesh {
    /// Axis-aligned bounds (min, max) in the mesh's units.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        )
    }

    /// Counts of edges by how many triangles use them: (boundary, non-manifold).
    pub fn edge_counts(&self) -> (usize, usize) {
        let mut uses: HashMap<(u32, u32), u32> = HashMap::with_capacity(self.triangles.len() * 3 / 2);
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *uses.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let boundary = uses.values().filter(|&&n| n == 1).count();
        let non_manifold = uses.values().filter(|&&n| n > 2).count();
        (boundary, non_manifold)
    }

    pub fn is_closed(&self) -> bool {
        self.edge_counts().0 == 0
    }

    pub fn colour_source(&self) -> String {
        if let Some(t) = &self.texture {
            return format!("texture {}x{}", t.image.width(), t.image.height());
        }
        match &self.colours {
            MeshColours::None => "none (constant colour)".into(),
            MeshColours::PerVertex(_) => "vertex colours".into(),
            MeshColours::PerCorner(_) => "material colours".into(),
        }
    }

    pub fn summary(&self) -> MeshSummary {
        let (lo, hi) = self.bounds();
        let (boundary_edges, non_manifold_edges) = self.edge_counts();
        MeshSummary {
            vertices: self.positions.len(),
            triangles: self.triangles.len(),
            bbox_min: lo.to_array(),
            bbox_max: hi.to_array(),
            boundary_edges,
            non_manifold_edges,
            colour_source: self.colour_source(),
        }
    }
}

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
            format!("unsupported mesh format '.{ext}' (expected .obj, .ply, .off or .stl)"),
        ));
    }
    if ext == "obj" {
        // OBJ is read in Rust (src/obj.rs says why: OpenMesh's reader aborts
        // the process on some malformed face lines).
        let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let (data, dropped) = crate::obj::read(&bytes, dir, &path.display().to_string())
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
    // declare were checked against the file's length (src/mesh_check.rs).
    let declared = crate::mesh_check::check(path, &ext)?;
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
        load_texture(path, &data).map(|image| Texture { uvs, image })
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

/// Writes a mesh; PLY keeps vertex colours (per-corner colours are averaged
/// onto vertices). OBJ and OFF are written without colour.
pub fn save(mesh: &Mesh, path: &Path, binary: bool) -> Result<()> {
    let ext = extension(path);
    if !MESH_EXTENSIONS.contains(&ext.as_str()) {
        return Err(Error::file(path, format!("cannot write mesh format '.{ext}'")));
    }
    let vertex_colours: Vec<f32> = match &mesh.colours {
        MeshColours::None => Vec::new(),
        MeshColours::PerVertex(c) => c.iter().flat_map(|c| c.to_array()).collect(),
        MeshColours::PerCorner(c) => {
            let mut sum = vec![Vec3::ZERO; mesh.positions.len()];
            let mut count = vec![0u32; mesh.positions.len()];
            for (t, tri) in mesh.triangles.iter().enumerate() {
                for k in 0..3 {
                    sum[tri[k] as usize] += c[3 * t + k];
                    count[tri[k] as usize] += 1;
                }
            }
            sum.iter().zip(&count).flat_map(|(s, &n)| (*s / n.max(1) as f32).to_array()).collect()
        }
    };
    let data = bridge::MeshData {
        positions: mesh.positions.iter().flat_map(|p| p.to_array()).collect(),
        triangles: mesh.triangles.iter().flatten().copied().collect(),
        vertex_colours: if ext == "ply" { vertex_colours } else { Vec::new() },
        faces_in_file: mesh.triangles.len() as u64,
        ..Default::default()
    };
    write_atomically(path, |tmp| {
        let tmp_str = tmp.to_str().ok_or_else(|| Error::file(path, "path is not valid UTF-8"))?;
        bridge::write_mesh(tmp_str, &data, binary).map_err(|e| Error::file(path, e.what()))
    })
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
        crate::vdb::CREATOR,
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
    write_atomically(path, |tmp| std::fs::write(tmp, &bytes).map_err(|e| Error::file(path, e.to_string())))
}
