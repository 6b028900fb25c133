//! The `Mesh` type: positions, triangles, normals, colours (per vertex, per
//! corner, or a texture), as every mesh reader gives it and every writer
//! takes it. Reading and writing files is [`super::mesh`]'s.


use glam::{Vec2, Vec3};


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
                    (true, Some(b)) => crate::geom::colour::tint(c, b),
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
