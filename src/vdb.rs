//! Level files: one `.vdb` per level, as DESIGN.md "Files that leave the
//! program" says, through the OpenVDB shims of the bridge.
//!
//! Grids: `mask`, `density` (fog volume, 1 on surface voxels), `P` (world
//! position), `N`, `Cd`, and the PointDataGrid `points` (P, N, Cd). All share a
//! linear transform in the exemplar's own frame and units; our metadata is on
//! every grid under `shapeshifter_*` keys plus `creator`.

use std::path::Path;

use glam::{DVec3, IVec3, Vec3};

use crate::error::{check_input_file, write_atomically, Error, Result};
use crate::ffi::bridge::{self, GridSummary, LevelData, MetaEntry};
use crate::level::{Frame, Level};

/// Where a level came from, recorded in its file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Provenance {
    /// Stem of the exemplar mesh's file name.
    pub exemplar: String,
    /// Seed of the sampling run that made the level, if any.
    pub seed: Option<u64>,
    /// Digest of the configuration that made the level ("" for encoding).
    pub config_digest: String,
    /// The exemplar was an open surface (boundary edges): meshing picks APSS.
    pub exemplar_open: bool,
}

/// Options for writing level files.
#[derive(Clone, Copy, Debug, Default)]
pub struct WriteOptions {
    /// Store floats as 16-bit halves: smaller files, lossy (about 1e-3 relative).
    pub half_floats: bool,
}

pub const CREATOR: &str = concat!("shapeshifter ", env!("CARGO_PKG_VERSION"));

fn meta_str(key: &str, text: &str) -> MetaEntry {
    MetaEntry { key: key.into(), kind: "string".into(), text: text.into(), number: 0.0, vec: [0.0; 3] }
}
fn meta_num(key: &str, kind: &str, number: f64) -> MetaEntry {
    MetaEntry { key: key.into(), kind: kind.into(), text: String::new(), number, vec: [0.0; 3] }
}

/// Transform of a level: voxel (i,j,k)'s centre in world units is
/// `origin + ijk * voxel_size`.
fn world_transform(level: &Level) -> (f64, DVec3) {
    let voxel_size = level.voxel_size() / level.frame.scale;
    let origin = level.frame.to_world(level.voxel_centre(IVec3::ZERO));
    (voxel_size, origin)
}

/// Writes `level` to `path` atomically (temporary name, then rename).
pub fn write_level(path: &Path, level: &Level, provenance: &Provenance, opts: WriteOptions) -> Result<()> {
    let (voxel_size, origin) = world_transform(level);
    let mut meta = vec![
        meta_str("creator", CREATOR),
        meta_num("shapeshifter_level", "int", level.index as f64),
        meta_num("shapeshifter_resolution", "int", level.resolution as f64),
        meta_str("shapeshifter_exemplar", &provenance.exemplar),
        MetaEntry {
            key: "shapeshifter_centre".into(),
            kind: "vec3d".into(),
            text: String::new(),
            number: 0.0,
            vec: level.frame.centre.to_array(),
        },
        meta_num("shapeshifter_scale", "float", level.frame.scale),
        meta_str("shapeshifter_config_digest", &provenance.config_digest),
        meta_num("shapeshifter_exemplar_open", "int", provenance.exemplar_open as i32 as f64),
    ];
    if let Some(seed) = provenance.seed {
        // Kept as a string: OpenVDB has no unsigned 64-bit metadata.
        meta.push(meta_str("shapeshifter_seed", &seed.to_string()));
    }
    let n = level.len();
    let lengths = [level.offsets.len(), level.normals.len(), level.colours.len(), level.mask.len()];
    if lengths.iter().any(|&l| l != n) {
        return Err(Error::file(
            path,
            format!("inconsistent level: {n} voxels but {lengths:?} offsets/normals/colours/mask; not written"),
        ));
    }
    if let Some(i) = level.first_non_finite() {
        return Err(Error::file(path, format!("voxel {} has NaN or infinite features; not written", level.coords[i])));
    }
    let flat = |v: &[Vec3]| -> Vec<f32> { v.iter().flat_map(|p| p.to_array()).collect() };
    let normals: Vec<Vec3> = level.normals.iter().map(|n| n.normalize_or_zero()).collect();
    let data = LevelData {
        coords: level.coords.iter().flat_map(|c| c.to_array()).collect(),
        points: (0..level.len()).flat_map(|i| level.point_world(i).as_vec3().to_array()).collect(),
        normals: flat(&normals),
        colours: flat(&level.colours),
        mask: level.mask.clone(),
        voxel_size,
        origin: origin.to_array(),
        meta,
    };
    write_atomically(path, |tmp| {
        let tmp_str = tmp.to_str().ok_or_else(|| Error::file(path, "path is not valid UTF-8"))?;
        bridge::write_level_file(tmp_str, &data, opts.half_floats)
            .map_err(|e| Error::file(path, e.what()))
    })
}

fn find<'a>(meta: &'a [MetaEntry], key: &str) -> Option<&'a MetaEntry> {
    meta.iter().find(|m| m.key == key)
}

/// Reads a level file back into the 10-channel features that were written.
pub fn read_level(path: &Path) -> Result<(Level, Provenance)> {
    check_input_file(path)?;
    let path_str = path.to_str().ok_or_else(|| Error::file(path, "path is not valid UTF-8"))?;
    let data = bridge::read_level_file(path_str).map_err(|e| Error::file(path, e.what()))?;
    let missing = |key: &str| Error::file(path, format!("has no '{key}' metadata; not a shapeshifter level file"));
    let resolution = find(&data.meta, "shapeshifter_resolution").ok_or_else(|| missing("shapeshifter_resolution"))?.number;
    let index = find(&data.meta, "shapeshifter_level").ok_or_else(|| missing("shapeshifter_level"))?.number;
    if !(resolution >= 1.0 && resolution.fract() == 0.0 && index >= 0.0) {
        return Err(Error::file(path, "has an invalid level or resolution in its metadata"));
    }
    let resolution = resolution as u32;
    let origin = DVec3::from_array(data.origin);
    // Normalisation from metadata; else derived from the transform, which
    // fixes it once the resolution is known (voxel_size = (2/res) / scale).
    let scale = find(&data.meta, "shapeshifter_scale")
        .map(|m| m.number)
        .unwrap_or(2.0 / resolution as f64 / data.voxel_size);
    let probe = Level { resolution, ..Default::default() };
    let centre = find(&data.meta, "shapeshifter_centre")
        .map(|m| DVec3::from_array(m.vec))
        .unwrap_or_else(|| origin - probe.voxel_centre(IVec3::ZERO) / scale);
    if !(scale.is_finite() && scale > 0.0 && centre.is_finite()) {
        return Err(Error::file(path, "has an invalid normalisation in its metadata"));
    }
    let n = data.mask.len();
    let mut level = Level {
        index: index as usize,
        resolution,
        frame: Frame { centre, scale },
        coords: data.coords.chunks_exact(3).map(|c| IVec3::new(c[0], c[1], c[2])).collect(),
        normals: data.normals.chunks_exact(3).map(Vec3::from_slice).collect(),
        colours: data.colours.chunks_exact(3).map(Vec3::from_slice).collect(),
        mask: data.mask,
        offsets: Vec::with_capacity(n),
    };
    // Offsets in voxel units from the world positions P.
    let voxel_world = level.voxel_size() / scale;
    for (i, p) in data.points.chunks_exact(3).enumerate() {
        let centre_world = origin + level.coords[i].as_dvec3() * voxel_world;
        let p = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        level.offsets.push(((p - centre_world) / voxel_world).as_vec3());
    }
    if let Some(i) = level.first_non_finite() {
        return Err(Error::file(path, format!("voxel {} has NaN or infinite features", level.coords[i])));
    }
    let provenance = Provenance {
        exemplar: find(&data.meta, "shapeshifter_exemplar").map(|m| m.text.clone()).unwrap_or_default(),
        seed: find(&data.meta, "shapeshifter_seed").and_then(|m| m.text.parse().ok()),
        config_digest: find(&data.meta, "shapeshifter_config_digest").map(|m| m.text.clone()).unwrap_or_default(),
        exemplar_open: find(&data.meta, "shapeshifter_exemplar_open").is_some_and(|m| m.number != 0.0),
    };
    Ok((level, provenance))
}

/// Per-grid summary of any .vdb file (what `vdb_print -l -m` shows).
pub fn summarise(path: &Path) -> Result<Vec<GridSummary>> {
    check_input_file(path)?;
    let path_str = path.to_str().ok_or_else(|| Error::file(path, "path is not valid UTF-8"))?;
    bridge::summarise_vdb_file(path_str).map_err(|e| Error::file(path, e.what()))
}
