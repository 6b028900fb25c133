//! Step 1: normalisation of the exemplar into the cube [-1, 1]^3, and its normals.

use super::*;

/// The mesh in normalised units, with what the closest-point queries need.
pub(super) struct Prepared {
    /// Corner positions per triangle (normalised units), stored flat so a query
    /// touches one cache line instead of chasing vertex indices.
    pub(super) corners: Vec<[DVec3; 3]>,
    pub(super) triangles: Vec<[u32; 3]>,
    /// Unit face normals; zero for degenerate triangles, which are skipped.
    pub(super) face_normals: Vec<DVec3>,
    /// Per triangle edge k (vertex k to k+1): unit sum of the normals of all faces
    /// sharing the edge (the angle-weighted pseudo-normal, every face angle being pi).
    pub(super) edge_normals: Vec<[DVec3; 3]>,
    /// Unit angle-weighted sum of incident face normals (Baerentzen & Aanaes).
    pub(super) vertex_normals: Vec<DVec3>,
}

/// Twice the triangle area below which a triangle counts as degenerate, in squared
/// normalised units (far below any voxel: 1e-20 vs 4e-6 at R = 1024).
pub(super) const DEGENERATE_AREA2: f64 = 1e-20;

impl Prepared {
    pub(super) fn new(mesh: &Mesh, frame: Frame) -> Result<Self, EncodeError> {
        let invalid = |reason: String| EncodeError::InvalidMesh { name: mesh.name.clone(), reason };
        if mesh.positions.is_empty() || mesh.triangles.is_empty() {
            return Err(EncodeError::EmptyMesh(mesh.name.clone()));
        }
        if let Some(i) = mesh.positions.iter().position(|p| !p.is_finite()) {
            return Err(invalid(format!("vertex {i} has a NaN or infinite coordinate")));
        }
        let nv = mesh.positions.len();
        if let Some(t) = mesh.triangles.iter().position(|t| t.iter().any(|&v| v as usize >= nv)) {
            return Err(invalid(format!("triangle {t} indexes a vertex beyond the {nv} vertices")));
        }
        let positions: Vec<DVec3> =
            mesh.positions.iter().map(|p| frame.to_normalised(p.as_dvec3())).collect();
        let corners = |t: &[u32; 3]| t.map(|v| positions[v as usize]);

        let face_normals: Vec<DVec3> = mesh
            .triangles
            .par_iter()
            .map(|t| {
                let [a, b, c] = corners(t);
                let n = (b - a).cross(c - a);
                if n.length() > DEGENERATE_AREA2 {
                    n.normalize()
                } else {
                    DVec3::ZERO
                }
            })
            .collect();
        let degenerate = face_normals.iter().filter(|n| **n == DVec3::ZERO).count();
        if degenerate > 0 {
            log::warn!("{}: ignoring {degenerate} degenerate triangles", mesh.name);
        }

        // Vertex pseudo-normals: angle-weighted face normals.
        let mut vertex_normals = vec![DVec3::ZERO; nv];
        for (t, n) in mesh.triangles.iter().zip(&face_normals) {
            if *n == DVec3::ZERO {
                continue;
            }
            let p = corners(t);
            for k in 0..3 {
                let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
                let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
                let angle = e1.dot(e2).clamp(-1.0, 1.0).acos();
                vertex_normals[t[k] as usize] += angle * *n;
            }
        }
        for n in &mut vertex_normals {
            *n = n.normalize_or_zero();
        }

        // Edge pseudo-normals: group triangle edges by their (min, max) vertex pair.
        let mut edges: Vec<(u64, u32)> = Vec::with_capacity(3 * mesh.triangles.len());
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                edges.push(((a.min(b) as u64) << 32 | a.max(b) as u64, (3 * t + k) as u32));
            }
        }
        edges.par_sort_unstable();
        let mut edge_normals = vec![[DVec3::ZERO; 3]; mesh.triangles.len()];
        let mut s = 0;
        while s < edges.len() {
            let mut e = s;
            let mut sum = DVec3::ZERO;
            while e < edges.len() && edges[e].0 == edges[s].0 {
                sum += face_normals[edges[e].1 as usize / 3];
                e += 1;
            }
            let n = sum.normalize_or_zero();
            for &(_, slot) in &edges[s..e] {
                edge_normals[slot as usize / 3][slot as usize % 3] = n;
            }
            s = e;
        }
        let corners = mesh.triangles.iter().map(corners).collect();
        Ok(Prepared {
            corners,
            triangles: mesh.triangles.clone(),
            face_normals,
            edge_normals,
            vertex_normals,
        })
    }
}
