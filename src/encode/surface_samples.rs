//! Step 4: closest points, normals and colours per sampling voxel.

use super::*;

/// One active voxel of the sampling grid.
#[derive(Clone, Copy, Debug)]
pub(super) struct Sample {
    pub(super) key: u64,
    /// Closest surface point minus the voxel centre, voxel units, NOT clamped: the
    /// closest point of a triangle that only clips a voxel corner can lie slightly
    /// outside the voxel (L-inf up to ~0.6); pooling wants the true surface point.
    pub(super) offset: Vec3,
    /// Unit normal.
    pub(super) normal: Vec3,
    /// RGB in [0, 1].
    pub(super) colour: Vec3,
}

/// Where the closest point of a triangle lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Feature {
    Face,
    /// Edge from corner k to corner k+1 (mod 3).
    Edge(usize),
    Vertex(usize),
}

/// Closest point on triangle `t` to `p` (Ericson, Real-Time Collision Detection
/// 5.1.5), as barycentric weights of the corners and the feature it lies on.
pub(super) fn closest_on_triangle(p: DVec3, t: &[DVec3; 3]) -> (DVec3, Feature) {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (DVec3::X, Feature::Vertex(0));
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (DVec3::Y, Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (DVec3::new(1.0 - v, v, 0.0), Feature::Edge(0));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (DVec3::Z, Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (DVec3::new(1.0 - w, 0.0, w), Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (DVec3::new(0.0, 1.0 - w, w), Feature::Edge(1));
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (DVec3::new(1.0 - v - w, v, w), Feature::Face)
}

/// Where surface colour comes from, resolved once per mesh.
pub(super) struct ColourSource<'a> {
    pub(super) mesh: &'a Mesh,
    pub(super) default: Vec3,
}

impl<'a> ColourSource<'a> {
    /// The mesh's texture where it covers a triangle, else its colours, else
    /// `default` ([`Mesh::colour_at`]); an empty texture image falls back to
    /// the colours with a warning; wrong array lengths are errors.
    pub(super) fn new(mesh: &'a Mesh, default: Vec3) -> Result<Self, EncodeError> {
        let invalid = |reason: String| EncodeError::InvalidMesh { name: mesh.name.clone(), reason };
        let corners = 3 * mesh.triangles.len();
        if let Some(tex) = &mesh.texture {
            if tex.uvs.len() != corners {
                return Err(invalid(format!("{} texture UVs for {corners} triangle corners", tex.uvs.len())));
            }
            if !tex.triangle_image.is_empty() && tex.triangle_image.len() != mesh.triangles.len() {
                return Err(invalid(format!("{} texture image indices for {} triangles", tex.triangle_image.len(), mesh.triangles.len())));
            }
            if !tex.has_pixels() {
                log::warn!("{}: texture image is empty; ignoring it", mesh.name);
            }
        }
        match &mesh.colours {
            MeshColours::PerVertex(c) if c.len() != mesh.positions.len() => {
                Err(invalid(format!("{} vertex colours for {} vertices", c.len(), mesh.positions.len())))
            }
            MeshColours::PerCorner(c) if c.len() != corners => {
                Err(invalid(format!("{} corner colours for {corners} triangle corners", c.len())))
            }
            _ => Ok(ColourSource { mesh, default }),
        }
    }

    /// Colour in [0, 1] at barycentric weights `w` of triangle `t`.
    pub(super) fn at(&self, t: usize, _tri: &[u32; 3], w: DVec3) -> Vec3 {
        self.mesh.colour_at(t, w.as_vec3()).unwrap_or(self.default).clamp(Vec3::ZERO, Vec3::ONE)
    }
}

/// Closest point, normal and colour for every voxel group of the sorted `pairs`.
pub(super) fn sample_voxels(
    prep: &Prepared,
    pairs: &Pairs,
    groups: &[usize],
    r: u32,
    colours: &ColourSource,
) -> Vec<Sample> {
    let vs = 2.0 / r as f64;
    groups
        .par_windows(2)
        .map(|g| {
            let key = pairs.key(g[0]);
            let centre = voxel_centre(key, r);
            let mut best = (f64::INFINITY, 0usize, DVec3::X, Feature::Face);
            for i in g[0]..g[1] {
                let t = pairs.triangle(i);
                let corners = prep.corners[t];
                let (w, feature) = closest_on_triangle(centre, &corners);
                let p = w.x * corners[0] + w.y * corners[1] + w.z * corners[2];
                let d2 = p.distance_squared(centre);
                if d2 < best.0 {
                    best = (d2, t, w, feature);
                }
            }
            let (_, t, w, feature) = best;
            let corners = prep.corners[t];
            let tri = &prep.triangles[t];
            let p = w.x * corners[0] + w.y * corners[1] + w.z * corners[2];
            let face = prep.face_normals[t];
            let normal = match feature {
                Feature::Face => face,
                Feature::Edge(k) => prep.edge_normals[t][k],
                Feature::Vertex(k) => prep.vertex_normals[tri[k] as usize],
            };
            // A pseudo-normal cancels on a folded sheet; the face normal is the best we have.
            let normal = if normal == DVec3::ZERO { face } else { normal };
            Sample {
                key,
                offset: ((p - centre) / vs).as_vec3(),
                normal: normal.as_vec3(),
                colour: colours.at(t, tri, w),
            }
        })
        .collect()
}
