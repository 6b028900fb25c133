//! `shapeshifter info`: what a file holds, for level files (like
//! `vdb_print -l -m`) and meshes.

use std::fmt::Write;
use std::path::Path;

use crate::error::{Error, Result};
use crate::{mesh, vdb};

/// A human-readable description of a .vdb file or a mesh.
pub fn describe(path: &Path) -> Result<String> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    if ext == "vdb" {
        describe_vdb(path)
    } else if mesh::MESH_EXTENSIONS.contains(&ext.as_str()) {
        describe_mesh(path)
    } else {
        crate::error::check_input_file(path)?;
        Err(Error::file(path, format!("unknown file type '.{ext}' (expected .vdb or a mesh)")))
    }
}

fn describe_vdb(path: &Path) -> Result<String> {
    let grids = vdb::summarise(path)?;
    let mut s = format!("{}: OpenVDB file, {} grids\n", path.display(), grids.len());
    for g in &grids {
        let [x0, y0, z0, x1, y1, z1] = g.bbox;
        let _ = write!(
            s,
            "  {:<8} {:<10} {:>9} voxels  bbox ({x0},{y0},{z0})-({x1},{y1},{z1})  class {}",
            g.name, g.value_type, g.active_voxels, g.grid_class
        );
        if g.value_type.starts_with("vec3") {
            let _ = write!(s, "  vector_type {}", g.vector_type);
        }
        if g.point_count > 0 || !g.attributes.is_empty() {
            let _ = write!(s, "  {} points [{}]", g.point_count, g.attributes.join(", "));
        }
        s.push('\n');
    }
    if let Some(g) = grids.first() {
        let _ = writeln!(
            s,
            "  transform: voxel size {:.6} world units, voxel (0,0,0) centre at ({:.6}, {:.6}, {:.6})",
            g.voxel_size[0], g.origin[0], g.origin[1], g.origin[2]
        );
        let mut meta: Vec<_> = g
            .meta
            .iter()
            .filter(|m| !["name", "class", "vector_type", "is_saved_as_half_float", "is_local_space"]
                .contains(&m.key.as_str()) && !m.key.starts_with("file_"))
            .collect();
        meta.sort_by(|a, b| a.key.cmp(&b.key));
        for m in meta {
            let _ = writeln!(s, "  {} = {}", m.key, m.text);
        }
    }
    Ok(s)
}

fn describe_mesh(path: &Path) -> Result<String> {
    let m = mesh::load(path)?;
    let info = m.summary();
    let [x0, y0, z0] = info.bbox_min;
    let [x1, y1, z1] = info.bbox_max;
    let closed = if info.boundary_edges == 0 {
        "closed".to_string()
    } else {
        format!("open ({} boundary edges)", info.boundary_edges)
    };
    let mut s = format!(
        "{}: mesh, {} vertices, {} triangles, {closed}\n  bounds ({x0:.4}, {y0:.4}, {z0:.4}) - ({x1:.4}, {y1:.4}, {z1:.4})\n  colour: {}\n",
        path.display(),
        info.vertices,
        info.triangles,
        info.colour_source
    );
    if info.non_manifold_edges > 0 {
        let _ = writeln!(s, "  {} non-manifold edges", info.non_manifold_edges);
    }
    Ok(s)
}
