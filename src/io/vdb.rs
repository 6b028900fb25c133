//! Level files: one `.vdb` per level, as docs/design.md "Files that leave the
//! program" says, through the OpenVDB shims of the bridge.
//!
//! Grids: `mask`, `density` (fog volume, 1 on surface voxels), `P` (world
//! position), `N`, `Cd`, and the PointDataGrid `points` (P, N, Cd). All share a
//! linear transform in the exemplar's own frame and units; our metadata is on
//! every grid under `shapeshifter_*` keys plus `creator`.
//!
//! The point grid goes, by default, in a file of its own beside the volumes
//! (`level_K.points.vdb` beside `level_K.vdb`, [`PointsLayout`]): Debian's
//! pyopenvdb cannot read a PointDataGrid, and its `readAll` fails on a whole
//! file that holds one; Houdini opens either file, Blender imports the volumes.

use std::path::Path;

use glam::{DVec3, IVec3, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::util::fs::{check_input_file, write_atomically};
use crate::io::ffi::bridge::{self, GridSummary, LevelData, MetaEntry, MetaKind};
use crate::io::probe::read_failure;
use crate::grid::transform::{Frame, Up};
use crate::level::Level;

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
    /// The exemplar's coordinate reference system, where its file named one
    /// (a LAS tile's "EPSG:32633").
    pub crs: Option<String>,
}

/// Where the PointDataGrid `points` of a level goes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum PointsLayout {
    /// In its own file, [`points_path`] of the level file: every client reads
    /// the volumes file (pyopenvdb's `readAll` included).
    #[default]
    Separate,
    /// In the level file with the volumes (one file per level; pyopenvdb's
    /// `readAll` then fails on it).
    Embedded,
    /// Not written (the volumes hold everything the program reads back).
    None,
}

/// Options for writing level files.
#[derive(Clone, Copy, Debug, Default)]
pub struct WriteOptions {
    /// Store floats as 16-bit halves: smaller files, lossy (about 1e-3 relative).
    pub half_floats: bool,
    pub points: PointsLayout,
}

/// The points file of a level file: `level_3.vdb` -> `level_3.points.vdb`.
pub fn points_path(level_path: &Path) -> std::path::PathBuf {
    let stem = level_path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    level_path.with_file_name(format!("{stem}.points.vdb"))
}

/// Whether a file name is a points file written beside a level file.
pub fn is_points_file(name: &str) -> bool {
    name.ends_with(".points.vdb")
}

pub const CREATOR: &str = concat!("shapeshifter ", env!("CARGO_PKG_VERSION"));

fn meta_str(key: &str, text: &str) -> MetaEntry {
    MetaEntry { key: key.into(), kind: MetaKind::Text, text: text.into(), number: 0.0, vec: [0.0; 3] }
}
fn meta_num(key: &str, kind: MetaKind, number: f64) -> MetaEntry {
    MetaEntry { key: key.into(), kind, text: String::new(), number, vec: [0.0; 3] }
}

/// Transform of a level: voxel (i,j,k)'s centre in world units is
/// `origin + ijk * voxel_size`.
fn world_transform(level: &Level) -> (f64, DVec3) {
    let voxel_size = level.transform().voxel_world();
    let origin = level.frame.to_world(level.voxel_centre(IVec3::ZERO));
    (voxel_size, origin)
}

/// Writes `level` to `path` atomically (temporary name, then rename), and
/// its points as `opts.points` says ([`points_path`] for a separate file; a
/// stale points file from an earlier layout is removed).
pub fn write_level(path: &Path, level: &Level, provenance: &Provenance, opts: WriteOptions) -> Result<()> {
    let (voxel_size, origin) = world_transform(level);
    let mut meta = vec![
        meta_str("creator", CREATOR),
        meta_num("shapeshifter_level", MetaKind::Int, level.index as f64),
        meta_num("shapeshifter_resolution", MetaKind::Int, level.resolution as f64),
        meta_str("shapeshifter_exemplar", &provenance.exemplar),
        MetaEntry {
            key: "shapeshifter_centre".into(),
            kind: MetaKind::Vec3,
            text: String::new(),
            number: 0.0,
            vec: level.frame.centre.to_array(),
        },
        meta_num("shapeshifter_scale", MetaKind::Float, level.frame.scale),
        meta_str("shapeshifter_up", level.frame.up.name()),
        meta_str("shapeshifter_config_digest", &provenance.config_digest),
        meta_num("shapeshifter_exemplar_open", MetaKind::Int, provenance.exemplar_open as i32 as f64),
    ];
    if let Some(crs) = &provenance.crs {
        meta.push(meta_str("shapeshifter_crs", crs));
    }
    if let Some(seed) = provenance.seed {
        // Kept as a string: OpenVDB has no unsigned 64-bit metadata.
        meta.push(meta_str("shapeshifter_seed", &seed.to_string()));
    }
    level.check().map_err(|e| Error::file(path, format!("{e}; not written")))?;
    let flat = |v: &[Vec3]| -> Vec<f32> { v.iter().flat_map(|p| p.to_array()).collect() };
    let normals: Vec<Vec3> = level.normals.iter().map(|n| n.normalize_or_zero()).collect();
    let points: Vec<f64> = (0..level.len()).flat_map(|i| level.point_world(i).to_array()).collect();
    // float32 holds a coordinate x to x * 2^-24: past voxel * 2^17 that is
    // more than a 64th of a voxel (a UTM tile at 0.2 m voxels, 4e6 m north),
    // so P is written in double there, float elsewhere (what most tools expect).
    let largest = points.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let double_positions = largest > voxel_size * (1u64 << 17) as f64;
    let data = LevelData {
        coords: level.coords.iter().flat_map(|c| c.to_array()).collect(),
        points,
        double_positions,
        normals: flat(&normals),
        colours: flat(&level.colours),
        mask: level.mask.clone(),
        voxel_size,
        origin: origin.to_array(),
        meta,
        unmatched_voxels: 0,
    };
    let write = |target: &Path, volumes: bool, points: bool| {
        write_atomically(target, |tmp| {
            let tmp_str = tmp.to_str().ok_or_else(|| Error::file(target, "path is not valid UTF-8"))?;
            bridge::write_level_file(tmp_str, &data, opts.half_floats, volumes, points)
                .map_err(|e| Error::file(target, e.what()))
        })
    };
    write(path, true, opts.points == PointsLayout::Embedded)?;
    let beside = points_path(path);
    match opts.points {
        PointsLayout::Separate => write(&beside, false, true),
        PointsLayout::Embedded | PointsLayout::None => match std::fs::remove_file(&beside) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::file(&beside, e.to_string())),
            _ => Ok(()),
        },
    }
}

fn find<'a>(meta: &'a [MetaEntry], key: &str) -> Option<&'a MetaEntry> {
    meta.iter().find(|m| m.key == key)
}

/// Reads a level file back into the 10-channel features that were written.
pub fn read_level(path: &Path) -> Result<(Level, Provenance)> {
    check_input_file(path)?;
    let path_str = path.to_str().ok_or_else(|| Error::file(path, "path is not valid UTF-8"))?;
    // Only the four grids a level needs (not the point grid): less of a
    // damaged file is parsed.
    crate::io::probe::probe(path, &["mask", "P", "N", "Cd"])?;
    let data = bridge::read_level_file(path_str).map_err(|e| Error::file(path, read_failure(e.what())))?;
    if data.unmatched_voxels > 0 {
        log::warn!(
            "{}: {} voxels active in P, N or Cd but not in the mask are ignored (the mask says which voxels the level holds)",
            path.display(),
            data.unmatched_voxels
        );
    }
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
        // Files written before the up axis was recorded are y-up.
        frame: Frame { centre, scale, up: if find(&data.meta, "shapeshifter_up").is_some_and(|m| m.text == "z") { Up::Z } else { Up::Y } },
        coords: data.coords.chunks_exact(3).map(|c| IVec3::new(c[0], c[1], c[2])).collect(),
        normals: data.normals.chunks_exact(3).map(Vec3::from_slice).collect(),
        colours: data.colours.chunks_exact(3).map(Vec3::from_slice).collect(),
        mask: data.mask,
        offsets: Vec::with_capacity(n),
    };
    // Offsets in voxel units from the world positions P.
    let voxel_world = level.transform().voxel_world();
    for (i, p) in data.points.chunks_exact(3).enumerate() {
        let centre_world = origin + level.coords[i].as_dvec3() * voxel_world;
        let offset = (DVec3::from_slice(p) - centre_world) / voxel_world;
        // A point belongs inside its voxel ([-0.5, 0.5] voxels; half floats
        // round a world position by up to about 0.15 voxels at 256^3): past
        // one voxel, P does not describe this voxel and would become a
        // stray point, so the file is refused; between, it is clamped back.
        if offset.abs().max_element() > 1.0 {
            return Err(Error::file(
                path,
                format!(
                    "P at voxel {} lies {:.1} voxels from its voxel's centre: grids P and mask disagree (edited by another tool?)",
                    level.coords[i],
                    offset.abs().max_element()
                ),
            ));
        }
        level.offsets.push(offset.clamp(DVec3::splat(-0.5), DVec3::splat(0.5)).as_vec3());
    }
    level.check().map_err(|e| Error::file(path, e.to_string()))?;
    let provenance = Provenance {
        exemplar: find(&data.meta, "shapeshifter_exemplar").map(|m| m.text.clone()).unwrap_or_default(),
        seed: find(&data.meta, "shapeshifter_seed").and_then(|m| m.text.parse().ok()),
        config_digest: find(&data.meta, "shapeshifter_config_digest").map(|m| m.text.clone()).unwrap_or_default(),
        exemplar_open: find(&data.meta, "shapeshifter_exemplar_open").is_some_and(|m| m.number != 0.0),
        crs: find(&data.meta, "shapeshifter_crs").map(|m| m.text.clone()),
    };
    Ok((level, provenance))
}

/// Per-grid summary of any .vdb file (what `vdb_print -l -m` shows).
pub fn summarise(path: &Path) -> Result<Vec<GridSummary>> {
    check_input_file(path)?;
    let path_str = path.to_str().ok_or_else(|| Error::file(path, "path is not valid UTF-8"))?;
    crate::io::probe::probe(path, &[])?;
    bridge::summarise_vdb_file(path_str).map_err(|e| Error::file(path, read_failure(e.what())))
}

