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
    let levels = pool_levels(&samples, options, frame, &mut stats);
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

// ---------------------------------------------------------------------------------
// Morton keys
// ---------------------------------------------------------------------------------

/// Spreads the low 21 bits of `x` to every third bit.
fn spread_bits(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// Inverse of [`spread_bits`].
fn compact_bits(x: u64) -> u64 {
    let mut x = x & 0x1249_2492_4924_9249;
    x = (x ^ (x >> 2)) & 0x10c3_0c30_c30c_30c3;
    x = (x ^ (x >> 4)) & 0x100f_00f0_0f00_f00f;
    x = (x ^ (x >> 8)) & 0x1f_0000_ff00_00ff;
    x = (x ^ (x >> 16)) & 0x1f_0000_0000_ffff;
    x = (x ^ (x >> 32)) & 0x1f_ffff;
    x
}

/// Morton key of voxel (i, j, k): i in the most significant interleaved bit, so the
/// parent's key is `key >> 3` and sorting by key sorts by parent first.
fn morton(i: u32, j: u32, k: u32) -> u64 {
    spread_bits(i as u64) << 2 | spread_bits(j as u64) << 1 | spread_bits(k as u64)
}

fn morton_decode(key: u64) -> IVec3 {
    IVec3::new(compact_bits(key >> 2) as i32, compact_bits(key >> 1) as i32, compact_bits(key) as i32)
}

/// Centre of the voxel with Morton key `key` at `resolution`, normalised units.
fn voxel_centre(key: u64, resolution: u32) -> DVec3 {
    crate::grid::GridTransform { resolution, frame: Default::default() }.centre_normalised(morton_decode(key))
}

// ---------------------------------------------------------------------------------
// 1. Normalisation and normals
// ---------------------------------------------------------------------------------

/// The mesh in normalised units, with what the closest-point queries need.
struct Prepared {
    /// Corner positions per triangle (normalised units), stored flat so a query
    /// touches one cache line instead of chasing vertex indices.
    corners: Vec<[DVec3; 3]>,
    triangles: Vec<[u32; 3]>,
    /// Unit face normals; zero for degenerate triangles, which are skipped.
    face_normals: Vec<DVec3>,
    /// Per triangle edge k (vertex k to k+1): unit sum of the normals of all faces
    /// sharing the edge (the angle-weighted pseudo-normal, every face angle being pi).
    edge_normals: Vec<[DVec3; 3]>,
    /// Unit angle-weighted sum of incident face normals (Baerentzen & Aanaes).
    vertex_normals: Vec<DVec3>,
}

/// Twice the triangle area below which a triangle counts as degenerate, in squared
/// normalised units (far below any voxel: 1e-20 vs 4e-6 at R = 1024).
const DEGENERATE_AREA2: f64 = 1e-20;

impl Prepared {
    fn new(mesh: &Mesh, frame: Frame) -> Result<Self, EncodeError> {
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

// ---------------------------------------------------------------------------------
// 2. Voxelisation
// ---------------------------------------------------------------------------------

/// (voxel, triangle) pairs. Packed into one u64 (Morton key above the triangle
/// index) whenever both fit, which is the fast path (R_s = 1024 leaves 34 bits for
/// triangles); wide pairs otherwise.
enum Pairs {
    Packed { data: Vec<u64>, tri_bits: u32 },
    Wide(Vec<(u64, u32)>),
}

impl Pairs {
    fn len(&self) -> usize {
        match self {
            Pairs::Packed { data, .. } => data.len(),
            Pairs::Wide(data) => data.len(),
        }
    }
    fn key(&self, i: usize) -> u64 {
        match self {
            Pairs::Packed { data, tri_bits } => data[i] >> tri_bits,
            Pairs::Wide(data) => data[i].0,
        }
    }
    fn triangle(&self, i: usize) -> usize {
        match self {
            Pairs::Packed { data, tri_bits } => (data[i] & ((1u64 << tri_bits) - 1)) as usize,
            Pairs::Wide(data) => data[i].1 as usize,
        }
    }
    /// Sorts by voxel key, then triangle (which makes closest-point ties
    /// deterministic). (An LSD radix sort measured no cheaper than this.)
    fn sort(&mut self) {
        match self {
            Pairs::Packed { data, .. } => data.par_sort_unstable(),
            Pairs::Wide(data) => data.par_sort_unstable(),
        }
    }
}

/// All (voxel, triangle) intersections at resolution `r`, unsorted.
fn voxelise(prep: &Prepared, r: u32) -> Pairs {
    let tri_bits = (usize::BITS - (prep.corners.len().max(2) - 1).leading_zeros()).max(1);
    let packed = 3 * r.trailing_zeros() + tri_bits <= 64;
    voxelise_as(prep, r, packed)
}

/// [`voxelise`] into packed pairs (`packed`, which the caller checked fits) or wide.
fn voxelise_as(prep: &Prepared, r: u32, packed: bool) -> Pairs {
    let n = prep.corners.len();
    let tri_bits = (usize::BITS - (n.max(2) - 1).leading_zeros()).max(1);
    let chunk = (n / (rayon::current_num_threads() * 16)).max(64);
    let chunks = n.div_ceil(chunk);
    let range = |c: usize| c * chunk..((c + 1) * chunk).min(n);
    if packed {
        let parts: Vec<Vec<u64>> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let mut out = Vec::new();
                voxelise_range(prep, range(c), r, |key, t| out.push(key << tri_bits | t as u64));
                out
            })
            .collect();
        Pairs::Packed { data: concat(parts), tri_bits }
    } else {
        let parts: Vec<Vec<(u64, u32)>> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let mut out = Vec::new();
                voxelise_range(prep, range(c), r, |key, t| out.push((key, t as u32)));
                out
            })
            .collect();
        Pairs::Wide(concat(parts))
    }
}

/// Calls `emit(morton key, triangle)` for the triangles `range`, degenerate ones skipped.
fn voxelise_range(prep: &Prepared, range: std::ops::Range<usize>, r: u32, mut emit: impl FnMut(u64, usize)) {
    let to_grid = r as f64 * 0.5;
    for t in range {
        let normal = prep.face_normals[t];
        if normal == DVec3::ZERO {
            continue;
        }
        let g = prep.corners[t].map(|p| (p + DVec3::ONE) * to_grid);
        voxelise_triangle(&g, normal, r, |i, j, k| emit(morton(i, j, k), t));
    }
}

fn concat<T: Copy>(parts: Vec<Vec<T>>) -> Vec<T> {
    let mut all = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for part in parts {
        all.extend_from_slice(&part);
    }
    all
}

/// One separating axis of the triangle/box test: the triangle's projection onto
/// `axis` spans `[lo, hi]`; a unit box centred at c is separated from it along
/// `axis` iff the interval misses `axis.c +- rad`.
#[derive(Clone, Copy)]
struct Axis {
    axis: DVec3,
    lo: f64,
    hi: f64,
    rad: f64,
}

impl Axis {
    fn new(axis: DVec3, g: &[DVec3; 3]) -> Self {
        let p = g.map(|q| axis.dot(q));
        Axis {
            axis,
            lo: p[0].min(p[1]).min(p[2]),
            hi: p[0].max(p[1]).max(p[2]),
            rad: 0.5 * axis.abs().element_sum(),
        }
    }
    fn overlaps(&self, c: DVec3) -> bool {
        let pc = self.axis.dot(c);
        self.lo <= pc + self.rad && self.hi >= pc - self.rad
    }
}

/// Calls `emit(i, j, k)` for every voxel of the `r`^3 grid that triangle `g` (grid
/// units, voxel (i,j,k) = [i,i+1) x [j,j+1) x [k,k+1)) intersects, closed boxes;
/// `n` is the unit face normal. Exact: the separating-axis theorem (Akenine-Moeller)
/// with its 13 axes, organised so that most of them are settled once per column.
///
/// Walks columns along the dominant axis `w` of `n`. A column is kept if it overlaps
/// the triangle's bounding box (axes u, v) and the triangle's projection (the three
/// axes e_w x edge). Over one column the triangle's plane spans at most
/// `(|n_u| + |n_v|) / |n_w| <= 2` voxels; clipped to the triangle's w extent, those
/// are the candidates, and they pass the plane and w-box axes by construction. The
/// six axes e_u x edge and e_v x edge are tested per candidate. The work is thus
/// O(intersected voxels), not O(bounding-box volume) (quadratic in size for a
/// slanted triangle).
fn voxelise_triangle(g: &[DVec3; 3], n: DVec3, r: u32, mut emit: impl FnMut(u32, u32, u32)) {
    let lo = g[0].min(g[1]).min(g[2]);
    let hi = g[0].max(g[1]).max(g[2]);
    let last = (r - 1) as f64;
    let cell = |x: f64| x.floor().clamp(0.0, last) as u32;
    let a = n.abs();
    let w = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    let (u, v) = ((w + 1) % 3, (w + 2) % 3);
    let unit = |k: usize| DVec3::AXES[k];
    let edges = [g[1] - g[0], g[2] - g[1], g[0] - g[2]];
    let column_axes = edges.map(|f| Axis::new(unit(w).cross(f), g));
    let voxel_axes: [Axis; 6] =
        std::array::from_fn(|i| Axis::new(unit(if i < 3 { u } else { v }).cross(edges[i % 3]), g));
    let d = n.dot(g[0]);
    let half_span = 0.5 * (a[u] + a[v]) / a[w];
    let mut c = DVec3::ZERO;
    for iu in cell(lo[u])..=cell(hi[u]) {
        c[u] = iu as f64 + 0.5;
        for iv in cell(lo[v])..=cell(hi[v]) {
            c[v] = iv as f64 + 0.5;
            c[w] = 0.0; // column axes have no w component
            if !column_axes.iter().all(|ax| ax.overlaps(c)) {
                continue;
            }
            let wc = (d - n[u] * c[u] - n[v] * c[v]) / n[w];
            let (wlo, whi) = ((wc - half_span).max(lo[w]), (wc + half_span).min(hi[w]));
            if wlo > whi {
                continue;
            }
            for iw in cell(wlo)..=cell(whi) {
                c[w] = iw as f64 + 0.5;
                if voxel_axes.iter().all(|ax| ax.overlaps(c)) {
                    let mut ijk = [0u32; 3];
                    ijk[u] = iu;
                    ijk[v] = iv;
                    ijk[w] = iw;
                    emit(ijk[0], ijk[1], ijk[2]);
                }
            }
        }
    }
}

/// Indices where `key(i)` changes, plus `n` at the end: group g is
/// `starts[g]..starts[g+1]`.
fn group_starts(n: usize, key: impl Fn(usize) -> u64) -> Vec<usize> {
    let mut starts = Vec::new();
    let mut prev = None;
    for i in 0..n {
        let k = key(i);
        if prev != Some(k) {
            starts.push(i);
            prev = Some(k);
        }
    }
    starts.push(n);
    starts
}

// ---------------------------------------------------------------------------------
// 4. Closest points, normals, colours
// ---------------------------------------------------------------------------------

/// One active voxel of the sampling grid.
#[derive(Clone, Copy, Debug)]
struct Sample {
    key: u64,
    /// Closest surface point minus the voxel centre, voxel units, NOT clamped: the
    /// closest point of a triangle that only clips a voxel corner can lie slightly
    /// outside the voxel (L-inf up to ~0.6); pooling wants the true surface point.
    offset: Vec3,
    /// Unit normal.
    normal: Vec3,
    /// RGB in [0, 1].
    colour: Vec3,
}

/// Where the closest point of a triangle lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Feature {
    Face,
    /// Edge from corner k to corner k+1 (mod 3).
    Edge(usize),
    Vertex(usize),
}

/// Closest point on triangle `t` to `p` (Ericson, Real-Time Collision Detection
/// 5.1.5), as barycentric weights of the corners and the feature it lies on.
fn closest_on_triangle(p: DVec3, t: &[DVec3; 3]) -> (DVec3, Feature) {
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
struct ColourSource<'a> {
    mesh: &'a Mesh,
    default: Vec3,
}

impl<'a> ColourSource<'a> {
    /// The mesh's texture where it covers a triangle, else its colours, else
    /// `default` ([`Mesh::colour_at`]); an empty texture image falls back to
    /// the colours with a warning; wrong array lengths are errors.
    fn new(mesh: &'a Mesh, default: Vec3) -> Result<Self, EncodeError> {
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
    fn at(&self, t: usize, _tri: &[u32; 3], w: DVec3) -> Vec3 {
        self.mesh.colour_at(t, w.as_vec3()).unwrap_or(self.default).clamp(Vec3::ZERO, Vec3::ONE)
    }
}

/// Closest point, normal and colour for every voxel group of the sorted `pairs`.
fn sample_voxels(
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

// ---------------------------------------------------------------------------------
// 5. Pooling
// ---------------------------------------------------------------------------------

/// How a voxel's surface point is carried from children to parent.
trait PointRule: Copy + Send + Sync {
    /// From one surface sample: point `p` (normalised units) with unit normal `n`.
    fn from_sample(p: DVec3, n: DVec3) -> Self;
    fn add(&mut self, other: &Self);
    fn scale(&mut self, s: f64);
    /// The voxel's point, normalised units (not yet clamped to the voxel).
    fn point(&self, centre: DVec3) -> DVec3;
}

/// Plane quadric Q = q q^T, q = (n, -n.p), symmetric 4x4 stored as its upper
/// triangle: a00 a01 a02 a03 a11 a12 a13 a22 a23 a33. Normalised units, f64: the
/// minimiser is a small correction of O(1) numbers.
#[derive(Clone, Copy, Debug)]
struct Quadric([f64; 10]);

/// Singular values below this fraction of the largest are dropped from the
/// pseudo-inverse (docs/method.md section 2.5): directions the planes do not pin down (along a
/// flat patch or a crease) stay at the voxel centre instead of running off.
const QEM_RELATIVE_THRESHOLD: f64 = 0.05;

impl PointRule for Quadric {
    fn from_sample(p: DVec3, n: DVec3) -> Self {
        let q = [n.x, n.y, n.z, -n.dot(p)];
        #[rustfmt::skip]
        let upper = [
            q[0] * q[0], q[0] * q[1], q[0] * q[2], q[0] * q[3],
            q[1] * q[1], q[1] * q[2], q[1] * q[3],
            q[2] * q[2], q[2] * q[3],
            q[3] * q[3],
        ];
        Quadric(upper)
    }
    fn add(&mut self, o: &Self) {
        for (a, b) in self.0.iter_mut().zip(&o.0) {
            *a += b;
        }
    }
    fn scale(&mut self, s: f64) {
        for a in &mut self.0 {
            *a *= s;
        }
    }
    /// Minimises `v^T A v - 2 b.v` (+ const) with `A = Q[:3,:3]`, `b = -Q[:3,3]`, by the
    /// truncated pseudo-inverse around the centre c: v = c + A+ (b - A c). A is
    /// symmetric positive semi-definite, so its SVD is its eigen-decomposition.
    fn point(&self, c: DVec3) -> DVec3 {
        let q = &self.0;
        let a = [[q[0], q[1], q[2]], [q[1], q[4], q[5]], [q[2], q[5], q[7]]];
        let b = -DVec3::new(q[3], q[6], q[8]);
        let ac = DVec3::new(
            a[0][0] * c.x + a[0][1] * c.y + a[0][2] * c.z,
            a[1][0] * c.x + a[1][1] * c.y + a[1][2] * c.z,
            a[2][0] * c.x + a[2][1] * c.y + a[2][2] * c.z,
        );
        let rhs = b - ac;
        let (values, vectors) = symmetric_eigen(a);
        let s_max = values.iter().fold(0.0f64, |m, s| m.max(s.abs()));
        let mut v = c;
        if s_max > 0.0 {
            for (s, e) in values.iter().zip(&vectors) {
                if s.abs() > QEM_RELATIVE_THRESHOLD * s_max {
                    v += *e * (e.dot(rhs) / s);
                }
            }
        }
        if v.is_finite() {
            v
        } else {
            c
        }
    }
}

/// Plain mean of the children's points (normalised units).
#[derive(Clone, Copy, Debug)]
struct MeanPoint(DVec3);

impl PointRule for MeanPoint {
    fn from_sample(p: DVec3, _n: DVec3) -> Self {
        MeanPoint(p)
    }
    fn add(&mut self, o: &Self) {
        self.0 += o.0;
    }
    fn scale(&mut self, s: f64) {
        self.0 *= s;
    }
    fn point(&self, _c: DVec3) -> DVec3 {
        self.0
    }
}

/// Eigenvalues and unit eigenvectors of a symmetric 3x3 matrix (cyclic Jacobi;
/// converges to machine precision in a handful of sweeps).
fn symmetric_eigen(mut a: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for _ in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-18 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            // A <- J^T A J: columns p, q, then rows p, q.
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = cs * akp - sn * akq;
                row[q] = sn * akp + cs * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| cs * rp[k] - sn * rq[k]);
            a[q] = std::array::from_fn(|k| sn * rp[k] + cs * rq[k]);
            for row in &mut v {
                let (vkp, vkq) = (row[p], row[q]);
                row[p] = cs * vkp - sn * vkq;
                row[q] = sn * vkp + cs * vkq;
            }
        }
    }
    let col = |j: usize| DVec3::new(v[0][j], v[1][j], v[2][j]);
    ([a[0][0], a[1][1], a[2][2]], [col(0), col(1), col(2)])
}

/// A pooled voxel: means of its children's normals (not renormalised, as the
/// reference code), colours and point rule.
#[derive(Clone, Copy, Debug)]
struct Node<G> {
    key: u64,
    normal: Vec3,
    colour: Vec3,
    geom: G,
}

/// Pools `n` Morton-sorted children into their parents (`key >> 3`), keeping the
/// parents sorted. Each parent is the plain mean over its active children.
fn pool<G: PointRule>(
    n: usize,
    key: impl Fn(usize) -> u64 + Sync,
    child: impl Fn(usize) -> Node<G> + Sync,
) -> Vec<Node<G>> {
    let starts = group_starts(n, |i| key(i) >> 3);
    starts
        .par_windows(2)
        .map(|g| {
            let mut acc = child(g[0]);
            for i in g[0] + 1..g[1] {
                let c = child(i);
                acc.normal += c.normal;
                acc.colour += c.colour;
                acc.geom.add(&c.geom);
            }
            let inv = 1.0 / (g[1] - g[0]) as f64;
            acc.normal *= inv as f32;
            acc.colour *= inv as f32;
            acc.geom.scale(inv);
            acc.key >>= 3;
            acc
        })
        .collect()
}

// ---------------------------------------------------------------------------------
// 6. Output
// ---------------------------------------------------------------------------------

/// Offset in voxel units, scaled down (direction kept) so that its L-inf norm is at
/// most 0.5: the point stays inside its voxel.
fn clamp_offset(o: DVec3) -> Vec3 {
    if !o.is_finite() {
        return Vec3::ZERO;
    }
    let m = o.abs().max_element();
    let o = if m > 0.5 { o * (0.5 / m) } else { o };
    o.as_vec3().clamp(Vec3::splat(-0.5), Vec3::splat(0.5))
}

/// Unit normal; a mean that cancelled out (opposite sheets in one voxel) becomes +Z.
fn unit_normal(n: Vec3) -> Vec3 {
    let n = n.normalize_or_zero();
    if n == Vec3::ZERO {
        Vec3::Z
    } else {
        n
    }
}

fn level_from_rows(rows: Vec<(IVec3, Vec3, Vec3, Vec3)>, resolution: u32, frame: Frame) -> Level {
    let mut level = Level { index: 0, resolution, frame, ..Default::default() };
    level.coords.reserve(rows.len());
    level.offsets.reserve(rows.len());
    level.normals.reserve(rows.len());
    level.colours.reserve(rows.len());
    for (c, o, n, col) in rows {
        level.coords.push(c);
        level.offsets.push(o);
        level.normals.push(n);
        level.colours.push(col);
    }
    level.mask = vec![1.0; level.coords.len()];
    level
}

/// `points[i]`: the surface point of `nodes[i]`, normalised units.
fn level_from_nodes<G: PointRule>(nodes: &[Node<G>], points: &[DVec3], r: u32, frame: Frame) -> Level {
    let vs = 2.0 / r as f64;
    let rows = nodes
        .par_iter()
        .zip(points)
        .map(|(node, &p)| {
            let c = voxel_centre(node.key, r);
            (
                morton_decode(node.key),
                clamp_offset((p - c) / vs),
                unit_normal(node.normal),
                node.colour.clamp(Vec3::ZERO, Vec3::ONE),
            )
        })
        .collect();
    level_from_rows(rows, r, frame)
}

fn level_from_samples(samples: &[Sample], r: u32, frame: Frame) -> Level {
    let rows = samples
        .par_iter()
        .map(|s| (morton_decode(s.key), clamp_offset(s.offset.as_dvec3()), unit_normal(s.normal), s.colour))
        .collect();
    level_from_rows(rows, r, frame)
}

// ---------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;
    use crate::io::mesh::Texture;

    use crate::util::rng::Rng;

    /// A random point of [-1, 1]^3.
    fn random_point(rng: &mut Rng) -> DVec3 {
        DVec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - DVec3::ONE
    }

    fn mesh(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh { name: "test".into(), positions, triangles, colours: MeshColours::None, texture: None }
    }

    /// Icosahedron subdivided `levels` times, vertices projected on the unit sphere,
    /// outward-oriented triangles.
    fn icosphere(levels: u32) -> Mesh {
        let phi = (1.0 + 5f32.sqrt()) / 2.0;
        #[rustfmt::skip]
        let mut pos: Vec<Vec3> = [
            (-1.0, phi, 0.0), (1.0, phi, 0.0), (-1.0, -phi, 0.0), (1.0, -phi, 0.0),
            (0.0, -1.0, phi), (0.0, 1.0, phi), (0.0, -1.0, -phi), (0.0, 1.0, -phi),
            (phi, 0.0, -1.0), (phi, 0.0, 1.0), (-phi, 0.0, -1.0), (-phi, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
        .collect();
        #[rustfmt::skip]
        let mut tris: Vec<[u32; 3]> = vec![
            [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
            [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
            [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
            [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
        ];
        for _ in 0..levels {
            let mut mid = std::collections::HashMap::new();
            let mut next = Vec::new();
            for t in &tris {
                let m: [u32; 3] = std::array::from_fn(|k| {
                    let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                    *mid.entry((a, b)).or_insert_with(|| {
                        pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                        pos.len() as u32 - 1
                    })
                });
                next.extend([[t[0], m[0], m[2]], [t[1], m[1], m[0]], [t[2], m[2], m[1]], [m[0], m[1], m[2]]]);
            }
            tris = next;
        }
        mesh(pos, tris)
    }

    /// Axis-aligned box [lo, hi], 12 outward triangles.
    use crate::testing::shapes::axis_box as cube;

    /// Height field z = f(x, y) over [-1, 1]^2, n x n quads, normals facing +z.
    fn height_field(n: u32, f: impl Fn(f32, f32) -> f32) -> Mesh {
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (2.0 * i as f32 / n as f32 - 1.0, 2.0 * j as f32 / n as f32 - 1.0);
                pos.push(Vec3::new(x, y, f(x, y)));
            }
        }
        let id = |i: u32, j: u32| j * (n + 1) + i;
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        mesh(pos, tris)
    }

    /// Distance from `p` to the mesh (normalised units), brute force over triangles.
    fn distance_to_mesh(prep: &Prepared, p: DVec3) -> f64 {
        (0..prep.triangles.len())
            .filter(|&t| prep.face_normals[t] != DVec3::ZERO)
            .map(|t| {
                let c = prep.corners[t];
                let (w, _) = closest_on_triangle(p, &c);
                (w.x * c[0] + w.y * c[1] + w.z * c[2]).distance(p)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The sampling level alone, as `encode` builds it.
    fn sampling_level(m: &Mesh, r: u32) -> (Prepared, Vec<Sample>) {
        let prep = Prepared::new(m, normalisation_frame(m)).unwrap();
        let colours = ColourSource::new(m, Vec3::splat(0.5)).unwrap();
        let mut pairs = voxelise(&prep, r);
        pairs.sort();
        let groups = group_starts(pairs.len(), |i| pairs.key(i));
        let samples = sample_voxels(&prep, &pairs, &groups, r, &colours);
        (prep, samples)
    }

    fn options(sampling: u32, coarsest: u32, finest: u32, pooling: Pooling) -> EncodeOptions {
        EncodeOptions {
            sampling_resolution: sampling,
            coarsest_resolution: coarsest,
            finest_resolution: finest,
            pooling,
            ..Default::default()
        }
    }

    fn level_of(levels: &[Level], r: u32) -> &Level {
        levels.iter().find(|l| l.resolution == r).unwrap()
    }

    #[test]
    fn morton_round_trip_and_parent() {
        let mut rng = Rng::new(7);
        for _ in 0..1000 {
            let c = [0; 3].map(|_: i32| (rng.uniform() * (1 << 21) as f64) as u32);
            let key = morton(c[0], c[1], c[2]);
            assert_eq!(morton_decode(key), IVec3::new(c[0] as i32, c[1] as i32, c[2] as i32));
            assert_eq!(key >> 3, morton(c[0] / 2, c[1] / 2, c[2] / 2));
        }
    }

    #[test]
    fn offsets_are_clamped_along_their_direction() {
        assert_eq!(clamp_offset(DVec3::new(0.8, -0.2, 0.4)), Vec3::new(0.5, -0.125, 0.25));
        assert_eq!(clamp_offset(DVec3::new(0.3, -0.5, 0.1)), Vec3::new(0.3, -0.5, 0.1));
        assert_eq!(clamp_offset(DVec3::NAN), Vec3::ZERO);
    }

    #[test]
    fn closest_point_matches_dense_search() {
        let mut rng = Rng::new(11);
        for _ in 0..200 {
            let t = [random_point(&mut rng), random_point(&mut rng), random_point(&mut rng)];
            let p = random_point(&mut rng) * 1.5;
            let (w, _) = closest_on_triangle(p, &t);
            assert!((w.element_sum() - 1.0).abs() < 1e-12 && w.min_element() >= -1e-12);
            let d = (w.x * t[0] + w.y * t[1] + w.z * t[2]).distance(p);
            // No barycentric grid point may be closer.
            let n = 60;
            for i in 0..=n {
                for j in 0..=n - i {
                    let (a, b) = (i as f64 / n as f64, j as f64 / n as f64);
                    let q = t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0]);
                    assert!(q.distance(p) >= d - 1e-12, "closest point is not closest");
                }
            }
        }
    }

    #[test]
    fn symmetric_eigen_reconstructs() {
        let mut rng = Rng::new(3);
        for _ in 0..200 {
            let (x, y) = (random_point(&mut rng), random_point(&mut rng));
            let a = [[x.x, y.x, y.y], [y.x, x.y, y.z], [y.y, y.z, x.z]];
            let (l, v) = symmetric_eigen(a);
            for i in 0..3 {
                for j in 0..3 {
                    let r: f64 = (0..3).map(|k| l[k] * v[k][i] * v[k][j]).sum();
                    assert!((r - a[i][j]).abs() < 1e-12);
                }
                assert!((v[i].length() - 1.0).abs() < 1e-12);
            }
        }
    }

    /// Reference separating-axis test of a triangle against the closed unit box at
    /// `c`, all 13 axes, written out independently of `voxelise_triangle`.
    fn triangle_box_overlap(g: &[DVec3; 3], c: DVec3) -> bool {
        let p = g.map(|q| q - c);
        let e = [p[1] - p[0], p[2] - p[1], p[0] - p[2]];
        let mut axes = vec![DVec3::X, DVec3::Y, DVec3::Z, e[0].cross(e[1])];
        for f in e {
            for b in [DVec3::X, DVec3::Y, DVec3::Z] {
                axes.push(b.cross(f));
            }
        }
        axes.iter().all(|a| {
            let s = p.map(|q| a.dot(q));
            let rad = 0.5 * a.abs().element_sum();
            s[0].min(s[1]).min(s[2]) <= rad && s[0].max(s[1]).max(s[2]) >= -rad
        })
    }

    /// Every voxel holding a point of the triangle is found, and every voxel found is
    /// within half a voxel diagonal of the triangle.
    #[test]
    fn voxelisation_is_exact() {
        let mut rng = Rng::new(5);
        let r = 16u32;
        for _ in 0..100 {
            let g = [0; 3].map(|_: i32| (random_point(&mut rng) * 0.45 + DVec3::splat(0.5)) * r as f64);
            let n = (g[1] - g[0]).cross(g[2] - g[0]).normalize();
            let mut found = HashSet::new();
            voxelise_triangle(&g, n, r, |i, j, k| assert!(found.insert((i, j, k)), "duplicate"));
            // Same set as the full 13-axis test over the whole bounding box.
            let (lo, hi) = (g[0].min(g[1]).min(g[2]).floor(), g[0].max(g[1]).max(g[2]).floor());
            let mut reference = HashSet::new();
            for i in lo.x as u32..=hi.x as u32 {
                for j in lo.y as u32..=hi.y as u32 {
                    for k in lo.z as u32..=hi.z as u32 {
                        let c = DVec3::new(i as f64, j as f64, k as f64) + DVec3::splat(0.5);
                        if triangle_box_overlap(&g, c) {
                            reference.insert((i, j, k));
                        }
                    }
                }
            }
            assert_eq!(found, reference);
            let s = 200;
            for i in 0..=s {
                for j in 0..=s - i {
                    let q =
                        g[0] + (i as f64 / s as f64) * (g[1] - g[0]) + (j as f64 / s as f64) * (g[2] - g[0]);
                    let c = q.floor().as_uvec3().min(glam::UVec3::splat(r - 1));
                    assert!(found.contains(&(c.x, c.y, c.z)), "missed voxel {c}");
                }
            }
            for &(i, j, k) in &found {
                let c = DVec3::new(i as f64, j as f64, k as f64) + DVec3::splat(0.5);
                let (w, _) = closest_on_triangle(c, &g);
                let d = (w.x * g[0] + w.y * g[1] + w.z * g[2]).distance(c);
                assert!(d <= 0.75f64.sqrt() + 1e-9, "voxel {i},{j},{k} is {d} voxels away");
            }
        }
    }

    #[test]
    fn packed_and_wide_pairs_agree() {
        let m = icosphere(2);
        let prep = Prepared::new(&m, normalisation_frame(&m)).unwrap();
        let (mut packed, mut wide) = (voxelise_as(&prep, 64, true), voxelise_as(&prep, 64, false));
        assert!(matches!(packed, Pairs::Packed { .. }) && matches!(wide, Pairs::Wide(_)));
        packed.sort();
        wide.sort();
        assert_eq!(packed.len(), wide.len());
        for i in 0..packed.len() {
            assert_eq!((packed.key(i), packed.triangle(i)), (wide.key(i), wide.triangle(i)));
        }
    }

    #[test]
    fn sphere_points_lie_on_the_mesh_and_the_sphere() {
        let m = icosphere(4);
        let r = 128;
        let vs = 2.0 / r as f64;
        let (prep, samples) = sampling_level(&m, r);
        let frame = normalisation_frame(&m);
        let (centre, radius) = (frame.to_normalised(DVec3::ZERO), frame.scale);
        // The polyhedron lies between its faces' planes and the sphere it is inscribed
        // in: the deepest face plane bounds how far a mesh point can be inside.
        let sag = (0..prep.triangles.len())
            .map(|t| radius - prep.face_normals[t].dot(prep.corners[t][0] - centre))
            .fold(0.0, f64::max);
        assert!(sag > 0.0 && sag < 0.05 * vs, "sag {sag}");
        for (i, s) in samples.iter().enumerate() {
            let p = voxel_centre(s.key, r) + s.offset.as_dvec3() * vs;
            let rho = (p - centre).length();
            assert!(rho <= radius + 1e-6 * vs && rho >= radius - sag - 1e-6 * vs, "point off the sphere");
            if i % 16 == 0 {
                let d = distance_to_mesh(&prep, p);
                assert!(d < 1e-3 * vs, "point {d} voxels off the mesh");
            }
            // A triangle that touches the voxel has a point within half a diagonal.
            assert!(s.offset.length() <= 0.75f32.sqrt() + 1e-4);
        }
    }

    #[test]
    fn sphere_levels_have_outward_unit_normals_and_points_near_the_sphere() {
        let m = icosphere(4);
        let (levels, stats) = encode(&m, &options(128, 16, 64, Pooling::Qem)).unwrap();
        assert_eq!(levels.iter().map(|l| l.resolution).collect::<Vec<_>>(), vec![16, 32, 64]);
        assert_eq!(
            stats.voxels_per_resolution.iter().map(|c| c.0).collect::<Vec<_>>(),
            vec![16, 32, 64, 128]
        );
        let frame = normalisation_frame(&m);
        let (centre, radius) = (frame.to_normalised(DVec3::ZERO), frame.scale);
        for (idx, level) in levels.iter().enumerate() {
            assert_eq!(level.index, idx);
            assert_eq!(level.frame, frame);
            let vs = level.voxel_size();
            for i in 0..level.len() {
                let n = level.normals[i];
                assert!((n.length() - 1.0).abs() < 1e-5);
                assert!(level.offsets[i].abs().max_element() <= 0.5);
                assert!(level.colours[i] == Vec3::splat(0.5) && level.mask[i] == 1.0);
                let p = level.point_normalised(i);
                let radial = (p - centre).normalize();
                assert!(n.as_dvec3().dot(radial) > 0.95, "normal not outward at level {idx}");
                // A voxel's QEM point sits on the mean tangent plane of a patch about
                // one voxel wide: off the sphere by the patch sag (measured <= 0.021
                // voxels here). Points clamped into their voxel (the surface only clips
                // the voxel) leave the surface, but stay within half a diagonal.
                let off = ((p - centre).length() - radius).abs() / vs;
                if level.offsets[i].abs().max_element() < 0.4999 {
                    assert!(off < 0.05, "level {idx}: point {off} voxels off the sphere");
                } else {
                    assert!(off < 0.75f64.sqrt());
                }
            }
        }
    }

    /// On a cube, a closest point on an edge gets the bisector of the two faces and
    /// one on a corner the diagonal: pseudo-normals, angle-weighted so that a face
    /// split into two triangles at the corner does not count twice.
    #[test]
    fn cube_edges_and_corners_get_pseudo_normals() {
        let m = cube(Vec3::new(-1.0, 2.0, 0.5), Vec3::new(3.0, 6.0, 4.5));
        let (_, samples) = sampling_level(&m, 64);
        let frame = normalisation_frame(&m);
        let half = frame.scale * 2.0; // half the side, normalised units
        let centre = frame.to_normalised(DVec3::new(1.0, 4.0, 2.5));
        let vs = 2.0 / 64.0;
        let mut seen = [0; 4];
        for s in &samples {
            let p = voxel_centre(s.key, 64) + s.offset.as_dvec3() * vs - centre;
            let on_bound = p.to_array().map(|x| (x.abs() - half).abs() < 1e-6);
            let expected =
                DVec3::from_array(std::array::from_fn(|i| if on_bound[i] { p[i].signum() } else { 0.0 }));
            let count = on_bound.iter().filter(|&&b| b).count();
            seen[count] += 1;
            assert!(count >= 1, "point off the cube");
            let err = (s.normal.as_dvec3() - expected.normalize()).length();
            assert!(err < 1e-5, "normal {} at a point on {count} faces", s.normal);
        }
        assert!(seen[2] > 0 && seen[3] >= 8, "edge/corner samples: {seen:?}");
    }

    #[test]
    fn every_parent_has_a_child_and_every_child_a_parent() {
        let m = icosphere(3);
        for pooling in [Pooling::Qem, Pooling::Average] {
            let (levels, _) = encode(&m, &options(128, 8, 128, pooling)).unwrap();
            assert_eq!(levels.len(), 5);
            for pair in levels.windows(2) {
                let (coarse, fine) = (&pair[0], &pair[1]);
                assert_eq!(fine.resolution, 2 * coarse.resolution);
                let parents: HashSet<IVec3> = coarse.coords.iter().copied().collect();
                let with_children: HashSet<IVec3> = fine.coords.iter().map(|c| *c >> 1).collect();
                assert_eq!(parents.len(), coarse.len(), "duplicate coordinates");
                assert_eq!(parents, with_children);
            }
            // Sorted sparse output: Morton order, no duplicates.
            for l in &levels {
                let keys: Vec<u64> =
                    l.coords.iter().map(|c| morton(c.x as u32, c.y as u32, c.z as u32)).collect();
                assert!(keys.windows(2).all(|w| w[0] < w[1]));
            }
        }
    }

    #[test]
    fn cube_corners_stay_sharp_with_qem_and_round_off_with_average() {
        // Box corners land at 0.62 of a level-16 voxel: not on a lattice plane.
        let m = cube(Vec3::new(-1.0, 2.0, 0.5), Vec3::new(3.0, 6.0, 4.5));
        let frame = normalisation_frame(&m);
        for pooling in [Pooling::Qem, Pooling::Average] {
            let (levels, _) = encode(&m, &options(256, 16, 64, pooling)).unwrap();
            for r in [16, 32] {
                let level = level_of(&levels, r);
                let vs = level.voxel_size();
                for corner in &m.positions {
                    let c = frame.to_normalised(corner.as_dvec3());
                    let ijk = ((c + DVec3::ONE) / vs).floor().as_ivec3();
                    let i = level.coords.iter().position(|x| *x == ijk).expect("corner voxel");
                    let d = level.point_normalised(i).distance(c) / vs;
                    match pooling {
                        Pooling::Qem => assert!(d < 1e-3, "QEM corner {d} voxels off at {r}"),
                        Pooling::Average => assert!(d > 0.1, "average kept a corner ({d} voxels) at {r}"),
                    }
                }
            }
        }
    }

    #[test]
    fn vertex_and_corner_colours_are_interpolated() {
        // Colours affine in position: barycentric interpolation is exact, and plain
        // averaging keeps colour = f(point) through every level.
        let mut m = icosphere(3);
        let f = |p: Vec3| (p * 0.4 + Vec3::splat(0.5)).clamp(Vec3::ZERO, Vec3::ONE);
        let per_vertex: Vec<Vec3> = m.positions.iter().map(|p| f(*p)).collect();
        let per_corner: Vec<Vec3> =
            m.triangles.iter().flat_map(|t| t.map(|v| per_vertex[v as usize])).collect();
        let frame = normalisation_frame(&m);
        for colours in [MeshColours::PerVertex(per_vertex), MeshColours::PerCorner(per_corner)] {
            m.colours = colours;
            let (levels, _) = encode(&m, &options(128, 16, 128, Pooling::Average)).unwrap();
            let mut checked = 0;
            for level in &levels {
                for i in 0..level.len() {
                    if level.offsets[i].abs().max_element() >= 0.4999 {
                        continue; // clamped point: no longer the mean point
                    }
                    let p = frame.to_world(level.point_normalised(i)).as_vec3();
                    let err = (level.colours[i] - f(p)).abs().max_element();
                    assert!(err < 1e-4, "colour off by {err} at resolution {}", level.resolution);
                    checked += 1;
                }
            }
            assert!(checked > 10_000);
        }
    }

    #[test]
    fn texture_is_sampled_bilinearly_at_the_uv() {
        // A tilted quad whose UVs are affine in (x, y), and a texture whose red and
        // green grow linearly with the pixel column and row.
        let (w, h) = (64u32, 32u32);
        let image = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(4 * x) as u8, (8 * y) as u8, 77]));
        let z = |x: f32, y: f32| 0.3 * x - 0.2 * y;
        let positions: Vec<Vec3> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|&(x, y)| Vec3::new(x, y, z(x, y)))
            .collect();
        let uv_of = |p: Vec3| glam::Vec2::new(0.1 + 0.4 * (p.x + 1.0), 0.15 + 0.35 * (p.y + 1.0));
        let triangles = vec![[0, 1, 2], [0, 2, 3]];
        let uvs = triangles.iter().flat_map(|t: &[u32; 3]| t.map(|v| uv_of(positions[v as usize]))).collect();
        let mut m = mesh(positions, triangles);
        m.texture = Some(Texture { uvs, image, ..Default::default() });
        let expected = |p: Vec3| {
            let uv = uv_of(p);
            let (px, py) = (uv.x * w as f32 - 0.5, (1.0 - uv.y) * h as f32 - 0.5);
            Vec3::new(4.0 * px, 8.0 * py, 77.0) / 255.0
        };
        let frame = normalisation_frame(&m);
        let (levels, _) = encode(&m, &options(128, 16, 128, Pooling::Average)).unwrap();
        let mut checked = 0;
        for level in &levels {
            for i in 0..level.len() {
                if level.offsets[i].abs().max_element() >= 0.4999 {
                    continue;
                }
                let p = frame.to_world(level.point_normalised(i)).as_vec3();
                let err = (level.colours[i] - expected(p)).abs().max_element();
                assert!(err < 1e-3, "texture colour off by {err}");
                checked += 1;
            }
        }
        assert!(checked > 5000);
    }

    #[test]
    fn open_surface_gets_no_closing_surface() {
        let m = height_field(24, |x, y| 0.25 * (2.0 * x).sin() * (1.5 * y).cos());
        let prep = Prepared::new(&m, normalisation_frame(&m)).unwrap();
        for pooling in [Pooling::Qem, Pooling::Average] {
            let (levels, _) = encode(&m, &options(128, 16, 128, pooling)).unwrap();
            for level in &levels {
                let vs = level.voxel_size();
                for i in (0..level.len()).step_by(3) {
                    // Active voxels touch the surface: centre within half a diagonal.
                    let d = distance_to_mesh(&prep, level.voxel_centre(level.coords[i]));
                    assert!(d <= 0.75f64.sqrt() * vs + 1e-9, "voxel {} voxels from the surface", d / vs);
                    assert!(level.normals[i].z > 0.0, "normal flipped on an open sheet");
                }
            }
        }
    }

    #[test]
    fn options_and_meshes_are_validated() {
        let m = icosphere(1);
        for bad in [
            options(1000, 16, 256, Pooling::Qem),
            options(1024, 64, 32, Pooling::Qem),
            options(128, 16, 256, Pooling::Qem),
        ] {
            assert!(matches!(encode(&m, &bad), Err(EncodeError::InvalidOptions(_))));
        }
        let grey = EncodeOptions { default_colour: Vec3::splat(2.0), ..Default::default() };
        assert!(matches!(encode(&m, &grey), Err(EncodeError::InvalidOptions(_))));
        assert!(matches!(
            encode(&mesh(vec![], vec![]), &EncodeOptions::default()),
            Err(EncodeError::EmptyMesh(_))
        ));
        let dangling = mesh(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 3]]);
        assert!(matches!(encode(&dangling, &EncodeOptions::default()), Err(EncodeError::InvalidMesh { .. })));
        let flat = mesh(vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0], vec![[0, 1, 2]]);
        assert!(matches!(encode(&flat, &EncodeOptions::default()), Err(EncodeError::NoActiveVoxels(_))));
        let mut wrong = m.clone();
        wrong.colours = MeshColours::PerVertex(vec![Vec3::ONE; 3]);
        assert!(matches!(encode(&wrong, &EncodeOptions::default()), Err(EncodeError::InvalidMesh { .. })));
    }

    #[test]
    fn sampling_level_can_be_an_output_level() {
        let m = icosphere(2);
        let (levels, stats) = encode(&m, &options(64, 64, 64, Pooling::Qem)).unwrap();
        assert_eq!(levels.len(), 1);
        assert_eq!(levels[0].len(), stats.sampling_voxels);
        assert!(levels[0].offsets.iter().all(|o| o.abs().max_element() <= 0.5));
    }
}
