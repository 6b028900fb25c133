//! Meshes: the `Mesh` type, loading through OpenMesh (OBJ+MTL, PLY, OFF, STL)
//! with validation, writing PLY or glTF binary (`.glb`, [`crate::io::glb`]) with
//! vertex colours, and quadric decimation ([`decimate`]).

use std::collections::HashMap;
use std::path::Path;

use glam::{Vec2, Vec3};

use crate::error::{Error, Result};
use crate::util::fs::{check_input_file, write_atomically, write_file};
use crate::io::ffi::bridge;

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

/// A diffuse texture with per-corner UVs (OBJ convention: v = 0 is the
/// image's bottom row).
#[derive(Clone, Debug, Default)]
pub struct Texture {
    pub uvs: Vec<Vec2>,
    pub image: image::RgbImage,
    /// Wrap modes along u and v of `image` (OBJ: repeat).
    pub wrap: [Wrap; 2],
    /// Further images, for meshes whose materials differ (glTF), with their
    /// wrap modes: triangle t samples `triangle_image[t]`, where 0 is `image`,
    /// k > 0 is `more[k - 1]` and [`NO_IMAGE`] none (its colours alone).
    /// Empty: every triangle samples `image`.
    pub more: Vec<(image::RgbImage, [Wrap; 2])>,
    pub triangle_image: Vec<u32>,
    /// The texture is multiplied by the mesh's colours, in linear light
    /// (glTF: baseColorFactor x COLOR_0 x texture); else it replaces them (OBJ).
    pub tinted: bool,
}

pub use crate::geom::texture::Wrap;

/// `Texture::triangle_image` of a triangle that samples no image.
pub const NO_IMAGE: u32 = u32::MAX;

impl Texture {
    /// The texel colour at `uv` for triangle `t`: None where it has no image
    /// (or an empty one), or `uv` is not finite.
    pub fn sample(&self, t: usize, uv: Vec2) -> Option<Vec3> {
        let (image, wrap) = match self.triangle_image.get(t).copied().unwrap_or(0) {
            0 => (&self.image, self.wrap),
            NO_IMAGE => return None,
            k => self.more.get(k as usize - 1).map(|(i, w)| (i, *w))?,
        };
        crate::geom::texture::sample_bilinear_wrapped(image, uv, wrap)
    }

    /// True when some image has pixels.
    pub fn has_pixels(&self) -> bool {
        std::iter::once(&self.image).chain(self.more.iter().map(|m| &m.0)).any(|i| i.width() > 0 && i.height() > 0)
    }
}

/// Mesh formats we read, by extension.
pub const MESH_EXTENSIONS: &[&str] = &["obj", "ply", "off", "stl", "glb", "gltf", "fbx", "dae"];

/// Mesh formats [`save`] writes, by extension: the ones we read, and glTF binary.
pub const WRITE_EXTENSIONS: &[&str] = &["obj", "ply", "off", "stl", "glb"];

/// Formats [`save`] writes with vertex colours.
pub const COLOUR_EXTENSIONS: &[&str] = &["ply", "glb"];

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
        crate::geom::edges::edge_counts(&self.triangles)
    }

    pub fn is_closed(&self) -> bool {
        self.edge_counts().0 == 0
    }

    pub fn colour_source(&self) -> String {
        if let Some(t) = &self.texture {
            return if t.more.is_empty() {
                format!("texture {}x{}", t.image.width(), t.image.height())
            } else {
                format!("{} textures, the first {}x{}", t.more.len() + 1, t.image.width(), t.image.height())
            };
        }
        match &self.colours {
            MeshColours::None => "none (constant colour)".into(),
            MeshColours::PerVertex(_) => "vertex colours".into(),
            MeshColours::PerCorner(_) => "material colours".into(),
        }
    }

    /// One colour per vertex, or None without colours: per-corner colours
    /// are averaged onto their vertices. A texture is not sampled (None).
    pub fn vertex_colours(&self) -> Option<Vec<Vec3>> {
        match &self.colours {
            MeshColours::None => None,
            MeshColours::PerVertex(c) => Some(c.clone()),
            MeshColours::PerCorner(c) => {
                let mut sum = vec![Vec3::ZERO; self.positions.len()];
                let mut count = vec![0u32; self.positions.len()];
                for (t, tri) in self.triangles.iter().enumerate() {
                    for k in 0..3 {
                        sum[tri[k] as usize] += c[3 * t + k];
                        count[tri[k] as usize] += 1;
                    }
                }
                Some(sum.iter().zip(&count).map(|(s, &n)| *s / n.max(1) as f32).collect())
            }
        }
    }

    /// The surface colour at barycentric weights `w` of triangle `t`: the
    /// texture where it covers the triangle (tinted by the colours where the
    /// texture says so), else the interpolated colours; None for neither.
    /// Array lengths must have been checked (the encoder and renderer do).
    pub fn colour_at(&self, t: usize, w: Vec3) -> Option<Vec3> {
        let tri = self.triangles[t];
        let base = match &self.colours {
            MeshColours::None => None,
            MeshColours::PerVertex(c) => Some(w.x * c[tri[0] as usize] + w.y * c[tri[1] as usize] + w.z * c[tri[2] as usize]),
            MeshColours::PerCorner(c) => Some(w.x * c[3 * t] + w.y * c[3 * t + 1] + w.z * c[3 * t + 2]),
        };
        if let Some(tex) = &self.texture {
            let uv = w.x * tex.uvs[3 * t] + w.y * tex.uvs[3 * t + 1] + w.z * tex.uvs[3 * t + 2];
            if let Some(c) = tex.sample(t, uv) {
                return Some(match (tex.tinted, base) {
                    (true, Some(b)) => crate::io::glb::tint(c, b),
                    _ => c,
                });
            }
        }
        base
    }

    /// Drops the triangles that carry no surface (a repeated vertex, or zero
    /// area in float32: two corners at one position), with their corners'
    /// colours, UVs and image indices; returns how many. The readers drop
    /// them too, so a mesh cleaned before it is written reads back whole.
    pub fn drop_degenerate_triangles(&mut self) -> usize {
        let p = &self.positions;
        let keep: Vec<bool> = self
            .triangles
            .iter()
            .map(|&[a, b, c]| a != b && b != c && a != c && (p[b as usize] - p[a as usize]).cross(p[c as usize] - p[a as usize]).length() > 0.0)
            .collect();
        let dropped = keep.iter().filter(|k| !**k).count();
        if dropped == 0 {
            return 0;
        }
        let mut k = keep.iter();
        self.triangles.retain(|_| *k.next().unwrap());
        fn corners<T: Copy>(v: &mut Vec<T>, keep: &[bool]) {
            let mut i = 0;
            v.retain(|_| {
                i += 1;
                keep[(i - 1) / 3]
            });
        }
        if let MeshColours::PerCorner(c) = &mut self.colours {
            corners(c, &keep);
        }
        if let Some(t) = &mut self.texture {
            corners(&mut t.uvs, &keep);
            if !t.triangle_image.is_empty() {
                let mut k = keep.iter();
                t.triangle_image.retain(|_| *k.next().unwrap());
            }
        }
        dropped
    }

    /// Area-weighted vertex normals, unit length; +Z for a vertex whose
    /// triangles have no area (or that no triangle uses).
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut sum = vec![Vec3::ZERO; self.positions.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.positions[i as usize]);
            // The cross product's length is twice the area: area weighting.
            let n = (b - a).cross(c - a);
            for &i in t {
                sum[i as usize] += n;
            }
        }
        sum.iter().map(|n| n.try_normalize().unwrap_or(Vec3::Z)).collect()
    }

    /// `n` points (about: at least one per triangle) spread over the
    /// triangles in proportion to their area; deterministic, for distances
    /// between surfaces.
    pub fn surface_samples(&self, n: usize) -> Vec<Vec3> {
        let areas: Vec<f32> = self
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize]);
                0.5 * (b - a).cross(c - a).length()
            })
            .collect();
        let total: f32 = areas.iter().sum();
        let mut out = Vec::with_capacity(n);
        // The same samples on every run.
        let mut rng = crate::util::rng::Rng::new(0x2545_F491_4F6C_DD1D);
        let mut rnd = move || rng.uniform() as f32;
        for (t, area) in self.triangles.iter().zip(&areas) {
            let k = (area / total * n as f32).round() as usize;
            let [a, b, c] = t.map(|i| self.positions[i as usize]);
            for _ in 0..k.max(1) {
                let (mut u, mut v) = (rnd(), rnd());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                out.push(a + (b - a) * u + (c - a) * v);
            }
        }
        out
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
