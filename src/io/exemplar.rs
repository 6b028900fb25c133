//! An exemplar as a user brings it: a mesh (OBJ, PLY, OFF, STL, glTF/GLB,
//! FBX, COLLADA) or
//! a point cloud (PLY points, LAS/LAZ, E57), by what the file holds.

use std::path::Path;

use crate::error::Result;
use crate::io::cloud::{self, PointCloud};
use crate::io::mesh::{self, Mesh};
use crate::grid::transform::Up;

/// Every extension an exemplar may have.
pub const EXTENSIONS: &[&str] = &["obj", "ply", "off", "stl", "glb", "gltf", "fbx", "dae", "las", "laz", "e57"];

#[derive(Clone, Debug)]
pub enum Exemplar {
    Mesh(Mesh),
    Cloud(PointCloud),
}

impl Exemplar {
    /// Reads `path`: a point cloud for LAS/LAZ/E57 and for a PLY without
    /// faces, else a mesh.
    pub fn load(path: &Path) -> Result<Exemplar> {
        if cloud::is_cloud_file(path) {
            cloud::load(path).map(Exemplar::Cloud)
        } else {
            mesh::load(path).map(Exemplar::Mesh)
        }
    }

    pub fn name(&self) -> &str {
        match self {
            Exemplar::Mesh(m) => &m.name,
            Exemplar::Cloud(c) => &c.name,
        }
    }

    /// The vertical axis of the file's format: +z for LAS/LAZ and E57,
    /// +y for meshes and PLY points.
    pub fn format_up(&self) -> Up {
        match self {
            Exemplar::Mesh(_) => Up::Y,
            Exemplar::Cloud(c) => c.up,
        }
    }

    /// True where the surface may be open: a mesh with boundary edges, and
    /// any point cloud (a scan sees one side of most things).
    pub fn is_open(&self) -> bool {
        match self {
            Exemplar::Mesh(m) => !m.is_closed(),
            Exemplar::Cloud(_) => true,
        }
    }

    /// The coordinate reference system its file names (point clouds).
    pub fn crs(&self) -> Option<String> {
        match self {
            Exemplar::Mesh(_) => None,
            Exemplar::Cloud(c) => c.crs.clone(),
        }
    }

    /// (triangles, points) for the manifest.
    pub fn counts(&self) -> (usize, usize) {
        match self {
            Exemplar::Mesh(m) => (m.triangles.len(), m.positions.len()),
            Exemplar::Cloud(c) => (0, c.len()),
        }
    }
}
