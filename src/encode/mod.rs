//! Encoding an exemplar mesh into the multiscale sparse levels (docs/method.md section 2).
//!
//! Deterministic, no learning. The pipeline, in the order [`EncodeStats`] times it:
//!
//! 1. **Normalise**: move the bounding-box centre to the origin and scale so the
//!    bounding-box diagonal is 2 ([`normalisation_frame`]); all later geometry is in
//!    these *normalised units*, in f64. Face normals and the angle-weighted
//!    pseudo-normals of edges and vertices are precomputed here.
//! 2. **Voxelise** at the sampling resolution R_s (1024 in the paper): every triangle
//!    emits the voxels it really intersects (separating-axis triangle/box test, not
//!    just the voxels holding its vertices), as packed `(Morton key, triangle)` pairs,
//!    in parallel over triangles. Memory grows with the surface, never with R_s^3.
//! 3. **Sort** the pairs (parallel sort of packed u64) and group them by voxel.
//! 4. **Sample** each active voxel: the closest point to the voxel centre on the
//!    triangles that touch the voxel, the normal there (face normal, or the
//!    pseudo-normal on an edge or vertex, so closed shapes get outward normals at
//!    creases too) and the colour there.
//! 5. **Pool** 2x2x2 children into their parent, level by level down to the coarsest
//!    resolution: mean normal, mean colour and either the mean plane quadric with its
//!    pseudo-inverse minimiser ([`Pooling::Qem`], keeps corners and creases sharp) or
//!    the mean point ([`Pooling::Average`], rounds them off).
//! 6. **Output** the levels coarsest..finest as [`Level`]s.
//!
//! Voxel keys are 3D Morton codes (bit-interleaved i, j, k), so the parent of key `m`
//! is `m >> 3` and a sorted child array is already grouped by parent: pooling is one
//! linear pass per level, with no hash map. Every level's voxels therefore come out in
//! Morton (Z-curve) order of their coordinates.
//!
//! Units: *normalised units* are the [-1, 1] cube; *voxel units* are multiples of the
//! voxel size `vs = 2 / resolution`; *grid units* (voxelisation only) put voxel
//! `(i, j, k)` at `[i, i+1) x [j, j+1) x [k, k+1)`.

pub mod cloud;
pub mod exemplar;
pub mod settings;

use std::time::Instant;

use glam::{DVec3, IVec3, Vec3};
use rayon::prelude::*;

use crate::level::{Frame, Level};
use crate::io::mesh::{Mesh, MeshColours};

pub use crate::level::Pooling;

/// Encoding parameters. Resolutions are voxels per axis over the normalised cube
/// [-1, 1]^3 and must be powers of two with `coarsest <= finest <= sampling`.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodeOptions {
    /// Resolution of the grid the mesh is sampled on (paper: 1024, 4x the finest
    /// level, so every finest voxel pools up to 64 surface samples).
    pub sampling_resolution: u32,
    /// Resolution of output level 0 (paper: 16).
    pub coarsest_resolution: u32,
    /// Resolution of the last output level (paper: 256).
    pub finest_resolution: u32,
    pub pooling: Pooling,
    /// RGB in [0, 1] for meshes without colour or texture. Mid grey by default: it
    /// maps to 0 under the networks' `2*(2c-1)` colour scaling.
    pub default_colour: Vec3,
    /// The finest level's voxel edge in the exemplar's own units (metres for a
    /// scan): the grid is this fine whatever the exemplar's size, and must hold
    /// it. None: the bounding box is fitted to the cube (diagonal 2).
    pub voxel_size: Option<f64>,
    /// The exemplar's vertical axis (previews' cameras, the graph orientation's
    /// seeds); None: the format's own (z for LAS/LAZ/E57, y otherwise).
    pub up: Option<crate::level::Up>,
    /// How point-cloud exemplars get their normals and colours.
    pub cloud: CloudOptions,
}

/// Settings for point-cloud exemplars.
#[derive(Clone, Debug, PartialEq)]
pub struct CloudOptions {
    /// Where colours come from.
    pub colour: crate::io::cloud::CloudColour,
    /// Neighbours of the plane fitted for an estimated normal.
    pub normal_neighbours: usize,
    /// How estimated normals get their sign.
    pub orientation: crate::geom::normals::Orientation,
    /// Estimate normals even where the file has them.
    pub estimate_normals: bool,
}

impl Default for CloudOptions {
    fn default() -> Self {
        CloudOptions {
            colour: Default::default(),
            normal_neighbours: 16,
            orientation: Default::default(),
            estimate_normals: false,
        }
    }
}

impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions {
            sampling_resolution: 1024,
            coarsest_resolution: 16,
            finest_resolution: 256,
            pooling: Pooling::Qem,
            default_colour: Vec3::splat(0.5),
            voxel_size: None,
            up: None,
            cloud: CloudOptions::default(),
        }
    }
}

/// Largest sampling resolution accepted: Morton keys hold 21 bits per axis, and a
/// finer grid would not fit in memory anyway.
pub const MAX_SAMPLING_RESOLUTION: u32 = 1 << 20;

impl EncodeOptions {
    /// Checks the resolutions (powers of two, ordered, within
    /// [`MAX_SAMPLING_RESOLUTION`]) and the default colour (finite, in [0, 1]).
    pub fn validate(&self) -> Result<(), EncodeError> {
        let bad = |msg: String| Err(EncodeError::InvalidOptions(msg));
        for (name, r) in [
            ("sampling_resolution", self.sampling_resolution),
            ("coarsest_resolution", self.coarsest_resolution),
            ("finest_resolution", self.finest_resolution),
        ] {
            if !r.is_power_of_two() {
                return bad(format!("{name} = {r} is not a power of two"));
            }
        }
        if self.coarsest_resolution > self.finest_resolution
            || self.finest_resolution > self.sampling_resolution
        {
            return bad(format!(
                "resolutions must satisfy coarsest <= finest <= sampling, got {} / {} / {}",
                self.coarsest_resolution, self.finest_resolution, self.sampling_resolution
            ));
        }
        if self.sampling_resolution > MAX_SAMPLING_RESOLUTION {
            return bad(format!(
                "sampling_resolution = {} exceeds the maximum {MAX_SAMPLING_RESOLUTION}",
                self.sampling_resolution
            ));
        }
        let c = self.default_colour;
        if !c.is_finite() || c.min_element() < 0.0 || c.max_element() > 1.0 {
            return bad(format!("default_colour {c} is not an RGB triple in [0, 1]"));
        }
        if let Some(v) = self.voxel_size {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("voxel size {v} must be a positive number (the finest voxel's edge in the exemplar's units)"));
            }
        }
        if !(3..=64).contains(&self.cloud.normal_neighbours) {
            return bad(format!("normal_neighbours = {} must be between 3 and 64", self.cloud.normal_neighbours));
        }
        Ok(())
    }
}

/// Why an encoding failed.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    #[error("invalid encoding options: {0}")]
    InvalidOptions(String),
    #[error("mesh '{0}' has no vertices or no triangles")]
    EmptyMesh(String),
    #[error("mesh '{name}' is invalid: {reason}")]
    InvalidMesh { name: String, reason: String },
    #[error("mesh '{0}' covers no voxel (all of its triangles are degenerate)")]
    NoActiveVoxels(String),
    #[error("'{name}' is {extent:.6} units across: at a voxel size of {voxel_size} the finest level ({resolution}^3) spans {span:.6}; use --voxel-size {suggest:.6} or more, or a finer level")]
    DoesNotFit { name: String, extent: f64, voxel_size: f64, resolution: u32, span: f64, suggest: f64 },
    #[error("point cloud '{name}': {reason}")]
    Cloud { name: String, reason: String },
}

crate::stage_error!(EncodeError);

/// Wall-clock seconds per stage and sizes, for logs and benchmarks.
#[derive(Clone, Debug, Default)]
pub struct EncodeStats {
    /// Normalisation and normals / pseudo-normals.
    pub normalise_s: f64,
    /// Triangle/voxel intersection at the sampling resolution.
    pub voxelise_s: f64,
    /// Sorting the (voxel, triangle) pairs and finding the voxel groups.
    pub sort_s: f64,
    /// Closest point, normal and colour per sampling voxel.
    pub sample_s: f64,
    /// 2x2x2 pooling through all resolutions, and the surface points (QEM solves)
    /// of the output levels.
    pub pool_s: f64,
    /// Building the output [`Level`]s (clamping, normalising, decoding keys).
    pub output_s: f64,
    pub total_s: f64,
    /// Number of (voxel, triangle) intersections found at the sampling resolution.
    pub triangle_voxel_pairs: usize,
    /// Active voxels at the sampling resolution.
    pub sampling_voxels: usize,
    /// (resolution, active voxels) for every resolution from coarsest up to sampling,
    /// coarsest first (intermediate resolutions that are not output included).
    pub voxels_per_resolution: Vec<(u32, usize)>,
}

impl EncodeStats {
    /// The timings as `manifest.json` records them (seconds by step).
    pub fn seconds(&self) -> std::collections::BTreeMap<String, f64> {
        [
            ("normalise", self.normalise_s),
            ("voxelise", self.voxelise_s),
            ("sort", self.sort_s),
            ("sample", self.sample_s),
            ("pool", self.pool_s),
            ("output", self.output_s),
            ("total", self.total_s),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }
}

/// The frame that maps the mesh's bounding box to the normalised cube: centre = bbox
/// centre, scale = 2 / bbox diagonal (normalised units per world unit), so the
/// diagonal becomes 2 and all coordinates lie in [-1, 1]. A mesh without vertices gets
/// the identity frame, a single point (zero diagonal) scale 1.
pub fn normalisation_frame(mesh: &Mesh) -> Frame {
    if mesh.positions.is_empty() {
        return Frame::default();
    }
    let (lo, hi) = mesh
        .positions
        .iter()
        .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| {
            (lo.min(p.as_dvec3()), hi.max(p.as_dvec3()))
        });
    box_frame(lo, hi)
}

/// The frame fitting the box `lo..hi` into the normalised cube (diagonal 2).
pub fn box_frame(lo: DVec3, hi: DVec3) -> Frame {
    let diagonal = (hi - lo).length();
    let scale = if diagonal > 0.0 && diagonal.is_finite() { 2.0 / diagonal } else { 1.0 };
    Frame { centre: (lo + hi) * 0.5, scale, ..Default::default() }
}

/// The frame of an exemplar with bounds `lo..hi` under `options`: fitted to
/// the cube, or (voxel_size) with the finest voxel that many world units, the
/// box centred; an error where the box does not fit in the cube then.
pub fn exemplar_frame(name: &str, lo: DVec3, hi: DVec3, options: &EncodeOptions, format_up: crate::level::Up) -> Result<Frame, EncodeError> {
    let mut frame = box_frame(lo, hi);
    frame.up = options.up.unwrap_or(format_up);
    if let Some(vs) = options.voxel_size {
        let r = options.finest_resolution;
        frame.scale = 2.0 / (r as f64 * vs);
        // One sampling voxel of margin: a point on the cube's face has no voxel.
        let room = 2.0 - 2.0 * 2.0 / options.sampling_resolution as f64;
        let extent = (hi - lo).max_element();
        if extent * frame.scale > room {
            let span = room / frame.scale;
            return Err(EncodeError::DoesNotFit {
                name: name.to_string(),
                extent,
                voxel_size: vs,
                resolution: r,
                span,
                suggest: vs * extent / span,
            });
        }
    }
    Ok(frame)
}

/// Encodes `mesh` into levels `coarsest_resolution ..= finest_resolution`, coarsest
/// first (index 0). Every level carries the normalisation frame, mask +1 everywhere,
/// offsets in voxel units within [-0.5, 0.5] (L-inf), unit normals and colours in
/// [0, 1]. Pools through every resolution from the sampling grid down.
pub fn encode(mesh: &Mesh, options: &EncodeOptions) -> Result<(Vec<Level>, EncodeStats), EncodeError> {
    options.validate()?;
    let start = Instant::now();
    let mut stats = EncodeStats::default();

    let t = Instant::now();
    let (lo, hi) = mesh.bounds();
    let frame = if mesh.positions.is_empty() { Frame::default() } else { exemplar_frame(&mesh.name, lo.as_dvec3(), hi.as_dvec3(), options, crate::level::Up::Y)? };
    let prep = Prepared::new(mesh, frame)?;
    let colours = ColourSource::new(mesh, options.default_colour)?;
    stats.normalise_s = t.elapsed().as_secs_f64();

    let rs = options.sampling_resolution;
    let t = Instant::now();
    let mut pairs = voxelise(&prep, rs);
    stats.voxelise_s = t.elapsed().as_secs_f64();
    stats.triangle_voxel_pairs = pairs.len();
    if pairs.len() == 0 {
        return Err(EncodeError::NoActiveVoxels(mesh.name.clone()));
    }

    let t = Instant::now();
    pairs.sort();
    let groups = group_starts(pairs.len(), |i| pairs.key(i));
    stats.sort_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let samples = sample_voxels(&prep, &pairs, &groups, rs, &colours);
    drop((pairs, groups));
    stats.sample_s = t.elapsed().as_secs_f64();
    let mut levels = pool_levels(&samples, options, frame, &mut stats);
    // Triangles wound inward give normals into the shape (many exported
    // game assets): turned here, once, for every stage after.
    if let Some((share, turned)) = orientation::face_outward(&mut levels) {
        if turned {
            log::info!(
                "'{}': its triangles are wound inward ({:.0}% of the surface seen from outside faces the eye): every normal turned outward",
                mesh.name,
                100.0 * share
            );
        } else {
            log::debug!("'{}': {:.0}% of the surface seen from outside faces the eye", mesh.name, 100.0 * share);
        }
    }
    stats.total_s = start.elapsed().as_secs_f64();
    log::debug!(
        "encoded '{}': {} pairs, {} sampling voxels, {:?} in {:.3} s",
        mesh.name,
        stats.triangle_voxel_pairs,
        stats.sampling_voxels,
        stats.voxels_per_resolution,
        stats.total_s
    );
    Ok((levels, stats))
}

/// The output levels, coarsest first, pooled from the sampling grid's
/// `samples` (sorted by key); fills the pooling figures of `stats`.
fn pool_levels(samples: &[Sample], options: &EncodeOptions, frame: Frame, stats: &mut EncodeStats) -> Vec<Level> {
    stats.sampling_voxels = samples.len();
    let mut counts = vec![(options.sampling_resolution, samples.len())];
    // Pool level by level. Output levels are collected finest first.
    let (mut levels, pool_s, output_s) = match options.pooling {
        Pooling::Qem => pool_all::<Quadric>(samples, options, frame, &mut counts),
        Pooling::Average => pool_all::<MeanPoint>(samples, options, frame, &mut counts),
    };
    stats.pool_s = pool_s;
    stats.output_s = output_s;
    levels.reverse();
    for (i, level) in levels.iter_mut().enumerate() {
        level.index = i;
    }
    counts.reverse();
    stats.voxels_per_resolution = counts;
    levels
}

/// Encodes a mesh or a point cloud (see [`encode`] and [`cloud::encode_cloud`]).
pub fn encode_exemplar(exemplar: &crate::io::exemplar::Exemplar, options: &EncodeOptions) -> Result<(Vec<Level>, EncodeStats), EncodeError> {
    match exemplar {
        crate::io::exemplar::Exemplar::Mesh(m) => encode(m, options),
        crate::io::exemplar::Exemplar::Cloud(c) => cloud::encode_cloud(c, options, exemplar.format_up()),
    }
}

/// Pools from the sampling level down to the coarsest resolution with point rule `G`,
/// returning the output levels finest first and the pooling / output seconds.
fn pool_all<G: PointRule>(
    samples: &[Sample],
    options: &EncodeOptions,
    frame: Frame,
    counts: &mut Vec<(u32, usize)>,
) -> (Vec<Level>, f64, f64) {
    let (mut pool_s, mut output_s) = (0.0, 0.0);
    let mut levels = Vec::new();
    let rs = options.sampling_resolution;
    if rs == options.finest_resolution {
        let t = Instant::now();
        levels.push(level_from_samples(samples, rs, frame));
        output_s += t.elapsed().as_secs_f64();
    }
    let mut r = rs / 2;
    let mut nodes: Vec<Node<G>> = Vec::new();
    let mut first = true;
    while r >= options.coarsest_resolution {
        let t = Instant::now();
        nodes = if first {
            let fine_vs = 2.0 / rs as f64;
            pool(
                samples.len(),
                |i| samples[i].key,
                |i| {
                    let s = &samples[i];
                    let p = voxel_centre(s.key, rs) + s.offset.as_dvec3() * fine_vs;
                    Node {
                        key: s.key,
                        normal: s.normal,
                        colour: s.colour,
                        geom: G::from_sample(p, s.normal.as_dvec3()),
                    }
                },
            )
        } else {
            pool(nodes.len(), |i| nodes[i].key, |i| nodes[i])
        };
        first = false;
        counts.push((r, nodes.len()));
        if r <= options.finest_resolution {
            // Points (QEM solves) only where a level is output: pooling carries the
            // quadrics or mean points, not the points.
            let points: Vec<DVec3> =
                nodes.par_iter().map(|n| n.geom.point(voxel_centre(n.key, r))).collect();
            pool_s += t.elapsed().as_secs_f64();
            let t = Instant::now();
            levels.push(level_from_nodes(&nodes, &points, r, frame));
            output_s += t.elapsed().as_secs_f64();
        } else {
            pool_s += t.elapsed().as_secs_f64();
        }
        r /= 2;
    }
    (levels, pool_s, output_s)
}

mod morton;
use morton::*;
pub mod orientation;
mod normalise;
use normalise::*;
mod voxelise;
use voxelise::*;
mod surface_samples;
use surface_samples::*;
mod pool;
use pool::*;
mod output;
use output::*;

#[cfg(test)]
mod tests;
