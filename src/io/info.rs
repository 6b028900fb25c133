//! `shapeshifter info`: what a file holds, for level files (like
//! `vdb_print -l -m`) and meshes, as text for people and as JSON for scripts.

use std::fmt::Write;
use std::path::Path;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::{io::mesh, io::vdb};

/// What one file holds.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum FileInfo {
    Vdb(VdbInfo),
    Mesh(MeshInfo),
    Cloud(CloudInfo),
}

/// A point cloud: its format, points, attributes, bounds and CRS.
#[derive(Clone, Debug, Serialize)]
pub struct CloudInfo {
    pub path: String,
    #[serde(flatten)]
    pub summary: crate::io::cloud::CloudSummary,
}

/// An OpenVDB file: its grids, the transform and metadata of the first grid.
#[derive(Clone, Debug, Serialize)]
pub struct VdbInfo {
    pub path: String,
    pub grids: Vec<GridInfo>,
    /// Voxel size, world units.
    pub voxel_size: f64,
    /// Centre of voxel (0,0,0), world units.
    pub origin: [f64; 3],
    /// The first grid's metadata (OpenVDB's own bookkeeping keys left out).
    pub metadata: std::collections::BTreeMap<String, String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct GridInfo {
    pub name: String,
    pub value_type: String,
    pub class: String,
    /// Empty for scalar grids.
    pub vector_type: String,
    pub active_voxels: u64,
    /// Index-space bounds of the active voxels: min then max.
    pub bbox: [i32; 6],
    /// Points of a PointDataGrid (0 otherwise) and their attributes.
    pub points: u64,
    pub attributes: Vec<String>,
}

/// A mesh file: counts, bounds in the file's units, closed or open.
#[derive(Clone, Debug, Serialize)]
pub struct MeshInfo {
    pub path: String,
    #[serde(flatten)]
    pub summary: mesh::MeshSummary,
}

/// What `path` holds (.vdb or a mesh).
pub fn inspect(path: &Path) -> Result<FileInfo> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    if ext == "vdb" {
        inspect_vdb(path).map(FileInfo::Vdb)
    } else if crate::io::cloud::is_cloud_file(path) {
        let c = crate::io::cloud::load(path)?;
        Ok(FileInfo::Cloud(CloudInfo { path: path.display().to_string(), summary: c.summary() }))
    } else if mesh::MESH_EXTENSIONS.contains(&ext.as_str()) {
        let m = mesh::load(path)?;
        Ok(FileInfo::Mesh(MeshInfo { path: path.display().to_string(), summary: m.summary() }))
    } else {
        crate::util::fs::check_input_file(path)?;
        Err(Error::file(path, format!("unknown file type '.{ext}' (expected .vdb, a mesh or a point cloud)")))
    }
}

fn inspect_vdb(path: &Path) -> Result<VdbInfo> {
    let grids = vdb::summarise(path)?;
    let first = grids.first();
    let metadata = first
        .map(|g| {
            g.meta
                .iter()
                .filter(|m| {
                    !["name", "class", "vector_type", "is_saved_as_half_float", "is_local_space"]
                        .contains(&m.key.as_str())
                        && !m.key.starts_with("file_")
                })
                .map(|m| (m.key.clone(), m.text.clone()))
                .collect()
        })
        .unwrap_or_default();
    Ok(VdbInfo {
        path: path.display().to_string(),
        voxel_size: first.map_or(0.0, |g| g.voxel_size[0]),
        origin: first.map_or([0.0; 3], |g| g.origin),
        metadata,
        grids: grids
            .iter()
            .map(|g| GridInfo {
                name: g.name.clone(),
                value_type: g.value_type.clone(),
                class: g.grid_class.clone(),
                vector_type: if g.value_type.starts_with("vec3") { g.vector_type.clone() } else { String::new() },
                active_voxels: g.active_voxels,
                bbox: g.bbox,
                points: g.point_count,
                attributes: g.attributes.clone(),
            })
            .collect(),
    })
}

impl FileInfo {
    pub fn to_text(&self) -> String {
        match self {
            FileInfo::Vdb(v) => v.to_text(),
            FileInfo::Mesh(m) => m.to_text(),
            FileInfo::Cloud(c) => c.to_text(),
        }
    }
}

impl VdbInfo {
    fn to_text(&self) -> String {
        let mut s = format!("{}: OpenVDB file, {} grids\n", self.path, self.grids.len());
        for g in &self.grids {
            let [x0, y0, z0, x1, y1, z1] = g.bbox;
            let _ = write!(
                s,
                "  {:<8} {:<10} {:>9} voxels  bbox ({x0},{y0},{z0})-({x1},{y1},{z1})  class {}",
                g.name, g.value_type, g.active_voxels, g.class
            );
            if !g.vector_type.is_empty() {
                let _ = write!(s, "  vector_type {}", g.vector_type);
            }
            if g.points > 0 || !g.attributes.is_empty() {
                let _ = write!(s, "  {} points [{}]", g.points, g.attributes.join(", "));
            }
            s.push('\n');
        }
        if !self.grids.is_empty() {
            let [ox, oy, oz] = self.origin;
            let _ = writeln!(
                s,
                "  transform: voxel size {:.6} world units, voxel (0,0,0) centre at ({ox:.6}, {oy:.6}, {oz:.6})",
                self.voxel_size
            );
            for (k, v) in &self.metadata {
                let _ = writeln!(s, "  {k} = {v}");
            }
        }
        s
    }
}

impl MeshInfo {
    fn to_text(&self) -> String {
        let info = &self.summary;
        let [x0, y0, z0] = info.bbox_min;
        let [x1, y1, z1] = info.bbox_max;
        let closed = if info.boundary_edges == 0 {
            "closed".to_string()
        } else {
            format!("open ({} boundary edges)", info.boundary_edges)
        };
        let mut s = format!(
            "{}: mesh, {} vertices, {} triangles, {closed}\n  bounds ({x0:.4}, {y0:.4}, {z0:.4}) - ({x1:.4}, {y1:.4}, {z1:.4})\n  colour: {}\n",
            self.path, info.vertices, info.triangles, info.colour_source
        );
        if info.non_manifold_edges > 0 {
            let _ = writeln!(s, "  {} non-manifold edges", info.non_manifold_edges);
        }
        s
    }
}

impl CloudInfo {
    fn to_text(&self) -> String {
        let c = &self.summary;
        let [x0, y0, z0] = c.bbox_min;
        let [x1, y1, z1] = c.bbox_max;
        let attributes = if c.attributes.is_empty() { "none".to_string() } else { c.attributes.join(", ") };
        let mut s = format!(
            "{}: point cloud ({}), {} points\n  bounds ({x0:.4}, {y0:.4}, {z0:.4}) - ({x1:.4}, {y1:.4}, {z1:.4})\n  attributes: {attributes}\n",
            self.path, c.format, c.points
        );
        let _ = writeln!(s, "  crs: {}", c.crs.as_deref().unwrap_or("none given"));
        s
    }
}
