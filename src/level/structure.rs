//! The structure of a shape at a coarse level: how much surface there is, how
//! far it reaches, in how many pieces, and how much of it is a free edge
//! (a wall end, the rim of a hole). Local-patch measures cannot see these
//! faults: every patch of a half tower, a torn roof or a shrunken copy exists
//! somewhere on the exemplar. Compared with the exemplar's own structure at
//! the same level, they flag the variants a user would throw away
//! ([`StructureScores`]); sampling uses the same comparison at level 0 to
//! reject broken coarse shapes before any finer level is made.
//!
//! Everything is measured on the surface voxels (mask > 0) of one level, in
//! that level's voxels.

use std::collections::HashSet;

use crate::grid::VoxelMap;

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use super::Level;

/// Resolution the structure of a shape is measured at: the coarse networks'
/// finest level, where a wall's end, a missing limb or a hole through a roof
/// is a few voxels across and nothing finer has been added.
pub const STRUCTURE_RESOLUTION: u32 = 64;

/// The finest of `levels` (coarsest first) of at most [`STRUCTURE_RESOLUTION`]^3.
pub fn structure_level(levels: &[Level]) -> Option<&Level> {
    levels.iter().filter(|l| l.resolution <= STRUCTURE_RESOLUTION).last()
}

/// The level after the structure level (128^3 in every profile): the first
/// made on a coarse shape that is already decided (by the detail transfer
/// in the `cpu` profile, by a network where one is trained), where ragged
/// sheets and flakes made on an unusual coarse shape show as surface like
/// no part of the exemplar's same level ([`Flag::FineOutOfStyle`]). None
/// where the levels stop at the structure level.
pub fn fine_level(levels: &[Level]) -> Option<&Level> {
    levels.iter().find(|l| l.resolution > STRUCTURE_RESOLUTION)
}

/// A component smaller than this share of the shape's voxels is debris, not
/// a piece (a stray stone does not make a tower "in two pieces").
pub const PIECE_SHARE: f64 = 0.05;

/// What one level's surface voxels look like as a whole.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Structure {
    pub resolution: u32,
    /// Surface voxels.
    pub voxels: usize,
    /// Bounding box of the surface voxels, voxels per axis (x, y, z).
    pub extent: [u32; 3],
    /// Sizes of the 26-connected components, largest first.
    pub components: Vec<usize>,
    /// Surface voxels on a free boundary ([`free_boundary`]).
    pub free_boundary: usize,
    /// Share of the directions from the voxels' centroid in which the
    /// surface is met ([`enclosure`]).
    pub enclosure: f64,
    /// Per view, the share of the silhouette where the inside is seen
    /// ([`super::seen_through::seen_through`]; empty below 32^3).
    #[serde(default)]
    pub seen_through: Vec<f64>,
    /// Surface voxels on a thin part ([`thin_voxels`]: a bunny's ear, a
    /// wall, a fin).
    #[serde(default)]
    pub thin: usize,
    /// Per axis, the empty columns the occupied ones enclose (holes through
    /// the shape along it, [`super::height_field::enclosed_columns`]).
    #[serde(default)]
    pub enclosed_columns: [usize; 3],
    /// The axis along which this shape is a sheet, a height field without a
    /// hole ([`super::height_field::sheet_axis`]); where a variant's holes
    /// are counted when this is the exemplar's. Sampling sets an exemplar's
    /// level 0 to the decision of its structure level
    /// ([`super::height_field::sheet_axes`]).
    #[serde(default)]
    pub sheet_axis: Option<usize>,
    /// The top height map's steps and seams ([`super::steps::top_steps`]).
    #[serde(default)]
    pub top_steps: super::steps::TopSteps,
}

impl Structure {
    /// The structure of `level`'s surface voxels.
    pub fn of(level: &Level) -> Structure {
        let active: Vec<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).collect();
        let coords: Vec<IVec3> = active.iter().map(|&i| level.coords[i]).collect();
        let extent = match (coords.iter().copied().reduce(IVec3::min), coords.iter().copied().reduce(IVec3::max)) {
            (Some(lo), Some(hi)) => (hi - lo + IVec3::ONE).to_array().map(|v| v as u32),
            _ => [0; 3],
        };
        Structure {
            resolution: level.resolution,
            voxels: coords.len(),
            extent,
            components: components(&coords),
            free_boundary: free_boundary(level).iter().filter(|&&b| b).count(),
            enclosure: enclosure(&coords),
            seen_through: super::seen_through::seen_through(level),
            thin: thin_count(level),
            enclosed_columns: super::height_field::enclosed_counts(level),
            sheet_axis: super::height_field::sheet_axis(level),
            top_steps: super::steps::top_steps(level),
        }
    }

    /// Components holding at least [`PIECE_SHARE`] of the voxels.
    pub fn pieces(&self) -> usize {
        self.components.iter().filter(|&&c| c as f64 >= PIECE_SHARE * self.voxels as f64).count()
    }

    /// Share of the voxels in the largest component (0 when empty).
    pub fn largest_share(&self) -> f64 {
        self.components.first().map_or(0.0, |&c| c as f64 / self.voxels.max(1) as f64)
    }

    /// Share of the voxels on a free boundary (0 when empty).
    pub fn free_boundary_share(&self) -> f64 {
        self.free_boundary as f64 / self.voxels.max(1) as f64
    }
}

/// How far behind a surface voxel, along its inward normal, the opposite
/// surface may be for the voxel to be on a thin part, in voxels of its level:
/// at 64^3 an ear or a wall is 2-3 voxels thick, a body 10 or more.
pub const THIN_DEPTH: f32 = 3.0;

/// Per voxel of `level`, whether it is a surface voxel on a thin part: the
/// surface facing the other way (another surface voxel whose normal points
/// away from this one's, by more than 100 degrees) is met within `depth`
/// voxels along the inward normal from the voxel's surface point (a
/// shape-diameter test, marched in quarter voxels from 0.75). The share of
/// such voxels is about 0.15 on the bunny at 64^3 (its ears), 0.5 on the ruined tower
/// (its walls), 0.75 on the demo tower.
pub fn thin_voxels(level: &Level, depth: f32) -> Vec<bool> {
    let index: VoxelMap<usize> =
        (0..level.len()).filter(|&i| level.mask[i] > 0.0).map(|i| (level.coords[i], i)).collect();
    (0..level.len())
        .into_par_iter()
        .map(|i| {
            if level.mask[i] <= 0.0 {
                return false;
            }
            // A network's normals are not unit length until written (the
            // sampler's gate sees them before): normalised here, so the gate
            // and `eval` of the written files count the same voxels.
            let n = level.normals[i].normalize_or_zero();
            if n == Vec3::ZERO {
                return false;
            }
            let p = level.point_voxels(i);
            let mut d = 0.75f32;
            while d <= depth {
                let q = (p - n * d).floor().as_ivec3();
                if let Some(&j) = index.get(q) {
                    if j != i && level.normals[j].normalize_or_zero().dot(n) < -0.2 {
                        return true;
                    }
                }
                d += 0.25;
            }
            false
        })
        .collect()
}

/// How many surface voxels of `level` are on a thin part ([`thin_voxels`]
/// at [`THIN_DEPTH`]).
pub fn thin_count(level: &Level) -> usize {
    thin_voxels(level, THIN_DEPTH).iter().filter(|&&t| t).count()
}

/// Best IoU below which a voxel's neighbourhood is like no part of the
/// exemplar ([`unlike_share`]). At 64^3, half the voxels of an 11^3 window
/// in common: a tower's wall matches another stretch of its wall at 0.7-1.0,
/// a slab fallen outward or a heap of rubble at 0.2-0.5.
pub const UNLIKE_IOU: f64 = 0.5;

/// Levels coarser than this are not compared patch by patch: at 16^3 an
/// 11^3 window holds most of the shape.
const UNLIKE_MIN_RESOLUTION: u32 = 32;

/// Per row of `shape` (false for inactive voxels): whether the surface
/// voxel's 11^3 neighbourhood (the voxels of its level around it) overlaps
/// each 11^3 neighbourhood of `exemplar`'s level (the same resolution), at
/// every place and shift, with an IoU below [`UNLIKE_IOU`]: a part with no
/// counterpart anywhere on the exemplar, out of its style (a wall fallen
/// outward, a heap of rubble, a wall split into ragged sheets). A new
/// arrangement of the exemplar's own parts shares its neighbourhoods; so does
/// the exemplar moved by whole voxels. Not turned: a wall at an angle the
/// exemplar has none at is unlike it. Matched exactly and exhaustively
/// ([`crate::grid::patches`], the matching of eval's LP-IoU). All false
/// below 32^3.
pub fn unlike_voxels(shape: &Level, exemplar: &Level) -> Vec<bool> {
    use crate::grid::patches::{surface_voxels_below_iou, ExemplarPatches};
    let mut unlike = vec![false; shape.len()];
    if shape.resolution < UNLIKE_MIN_RESOLUTION || shape.resolution != exemplar.resolution {
        return unlike;
    }
    let dictionary = ExemplarPatches::new(&voxel_set(exemplar), 1);
    let rows: VoxelMap<usize> = (0..shape.len()).filter(|&i| shape.mask[i] > 0.0).map(|i| (shape.coords[i], i)).collect();
    for c in surface_voxels_below_iou(&voxel_set(shape), &dictionary, UNLIKE_IOU) {
        if let Some(&i) = rows.get(IVec3::new(c[0] as i32, c[1] as i32, c[2] as i32)) {
            unlike[i] = true;
        }
    }
    unlike
}

/// The share of `shape`'s surface voxels (mask > 0) that are
/// [`unlike_voxels`] (0 for an empty shape and below 32^3). A voxel with all
/// six face neighbours in the level (inside a shell two or more voxels thick)
/// has no patch of its own and counts as like: the share is of every voxel,
/// as the limit was measured.
pub fn unlike_share(shape: &Level, exemplar: &Level) -> f64 {
    let active = shape.mask.iter().filter(|&&m| m > 0.0).count();
    if active == 0 {
        return 0.0;
    }
    unlike_voxels(shape, exemplar).iter().filter(|&&u| u).count() as f64 / active as f64
}

/// A level's surface voxels (mask > 0) as a bit set on its own lattice.
fn voxel_set(level: &Level) -> crate::grid::occupancy::Occupancy {
    let r = level.resolution;
    let mut set = crate::grid::occupancy::Occupancy::empty([r, r, r]);
    for (c, &m) in level.coords.iter().zip(&level.mask) {
        if m > 0.0 {
            set.set(c.x as i64, c.y as i64, c.z as i64);
        }
    }
    set
}

/// Sizes of the 26-connected components of a voxel set, largest first.
pub fn components(coords: &[IVec3]) -> Vec<usize> {
    let (_, mut sizes) = component_labels(coords);
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    sizes
}

/// The 26-connected components of a voxel set: per voxel, its component's
/// index, and per component its size (in the order first met).
pub fn component_labels(coords: &[IVec3]) -> (Vec<usize>, Vec<usize>) {
    let index: VoxelMap<usize> = coords.iter().enumerate().map(|(i, &c)| (c, i)).collect();
    let mut label = vec![usize::MAX; coords.len()];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..coords.len() {
        if label[start] != usize::MAX {
            continue;
        }
        let id = sizes.len();
        label[start] = id;
        stack.push(start);
        let mut size = 0;
        while let Some(i) = stack.pop() {
            size += 1;
            for d in NEIGHBOURS_26 {
                if let Some(&j) = index.get(coords[i] + d) {
                    if label[j] == usize::MAX {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
        }
        sizes.push(size);
    }
    (label, sizes)
}

const NEIGHBOURS_26: [IVec3; 26] = {
    let mut out = [IVec3::ZERO; 26];
    let mut k = 0;
    let mut i = 0;
    while i < 27 {
        let d = IVec3::new(i % 3 - 1, (i / 3) % 3 - 1, i / 9 - 1);
        if !(d.x == 0 && d.y == 0 && d.z == 0) {
            out[k] = d;
            k += 1;
        }
        i += 1;
    }
    out
};

/// Rays cast by [`enclosure`] (a Fibonacci sphere of directions).
const ENCLOSURE_RAYS: usize = 2048;

/// How much of the view from inside the shape its surface fills: the share
/// of [`ENCLOSURE_RAYS`] directions, evenly spread over the sphere, in which a
/// ray from the voxels' centroid meets a surface voxel or passes within one
/// voxel of one (so a shell with gaps between its voxels does not leak). A
/// whole tower surrounds its centre all round but for its top and its door; a
/// ring with one side gone, a wall standing alone or a roof with a hole lets
/// the rays through there. 0 for no voxels.
pub fn enclosure(coords: &[IVec3]) -> f64 {
    if coords.is_empty() {
        return 0.0;
    }
    let set: HashSet<IVec3> = coords.iter().copied().collect();
    let lo = coords.iter().copied().reduce(IVec3::min).expect("not empty") - IVec3::ONE;
    let hi = coords.iter().copied().reduce(IVec3::max).expect("not empty") + IVec3::ONE;
    let centre = coords.iter().fold(Vec3::ZERO, |a, c| a + c.as_vec3()) / coords.len() as f32 + Vec3::splat(0.5);
    let reach = (hi - lo).as_vec3().length() + 2.0;
    let near = |p: Vec3| {
        let c = p.floor().as_ivec3();
        set.contains(&c) || NEIGHBOURS_26.iter().any(|&d| set.contains(&(c + d)))
    };
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let hits = (0..ENCLOSURE_RAYS)
        .into_par_iter()
        .filter(|&k| {
            let z = 1.0 - 2.0 * (k as f32 + 0.5) / ENCLOSURE_RAYS as f32;
            let r = (1.0 - z * z).sqrt();
            let a = golden * k as f32;
            let dir = Vec3::new(r * a.cos(), r * a.sin(), z);
            // Half-voxel steps from one voxel out of the centre (the centroid
            // of a shell lies inside it, where no surface is).
            let mut t = 1.0;
            while t < reach {
                if near(centre + dir * t) {
                    return true;
                }
                t += 0.5;
            }
            false
        })
        .count();
    hits as f64 / ENCLOSURE_RAYS as f64
}

/// Directions around a voxel's normal in which a neighbour is looked for.
const SECTORS: usize = 8;
/// A voxel is on a free boundary when this many consecutive sectors (of
/// [`SECTORS`], 45 degrees each: 135 degrees) hold no neighbour.
const OPEN_SECTORS: usize = 3;

/// Per voxel of `level` (in row order; false for inactive voxels): whether its
/// surface point lies on a free boundary of the surface. The neighbours are
/// the surface points of the active voxels within 2 voxels (the 5^3 window)
/// on the same side (normals less than 90 degrees apart) and near the tangent
/// plane (within 1 voxel of it), 0.5 to 2.9 voxels away along it. Their
/// directions in the tangent plane are binned into 8 sectors; where 3
/// consecutive sectors are empty, half or more of the voxel's surroundings
/// hold no surface: a wall's end, a hole's rim, the edge of an open sheet. A
/// voxel inside a surface has neighbours all round; a sharp crease keeps its
/// neighbours on both faces (within the window, near the plane of either).
pub fn free_boundary(level: &Level) -> Vec<bool> {
    let index: VoxelMap<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).map(|i| (level.coords[i], i)).collect();
    let point = |i: usize| level.point_voxels(i);
    (0..level.len())
        .into_par_iter()
        .map(|i| {
            if level.mask[i] <= 0.0 {
                return false;
            }
            let Some(n) = level.normals[i].try_normalize() else { return false };
            let u = n.any_orthonormal_vector();
            let w = n.cross(u);
            let p = point(i);
            let mut filled = [false; SECTORS];
            for dz in -2..=2 {
                for dy in -2..=2 {
                    for dx in -2..=2 {
                        let Some(&j) = index.get(level.coords[i] + IVec3::new(dx, dy, dz)) else {
                            continue;
                        };
                        if j == i || level.normals[j].dot(n) <= 0.0 {
                            continue;
                        }
                        let d = point(j) - p;
                        let along = d.dot(n);
                        let t = d - along * n;
                        let r = t.length();
                        if along.abs() > 1.0 || !(0.5..=2.9).contains(&r) {
                            continue;
                        }
                        let a = t.dot(w).atan2(t.dot(u)).rem_euclid(std::f32::consts::TAU);
                        filled[((a / std::f32::consts::TAU * SECTORS as f32) as usize).min(SECTORS - 1)] = true;
                    }
                }
            }
            // The longest cyclic run of empty sectors.
            let (mut run, mut best) = (0, 0);
            for k in 0..2 * SECTORS {
                if filled[k % SECTORS] {
                    run = 0;
                } else {
                    run += 1;
                    best = best.max(run);
                }
            }
            best >= OPEN_SECTORS
        })
        .collect()
}

/// A bounding box side this many voxels shorter or longer than the
/// exemplar's counts as the same (`extent_ratio`): on a fault-line terrain
/// whose relief is 6 voxels at 64^3, whole variants read 5, a ratio of 0.83
/// that flagged 7 of 10 `shrunken`; a bunny whose ears lost their tips is
/// 13 voxels of 16 at 16^3, still shrunken at (13 + 1) / 16.
pub const EXTENT_TOLERANCE_VOXELS: f64 = 1.0;

/// Thresholds of the structural flags, in the figures' own units. Chosen on
/// the degradation ladder and on sampled variants (docs/lab/whole-shapes.md, "Whole shapes").
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StructureParams {
    /// A variant with less surface than this share of the exemplar's (or
    /// more than its inverse) is a fragment (or an overgrowth).
    pub min_mass_ratio: f64,
    /// The bounding box along some axis shorter than this share of the
    /// exemplar's: shrunken. 0.9, measured (docs/lab/new-shapes.md, "New shapes"):
    /// the bunny's variants whose ears lost their tips (and came apart into
    /// flakes at the finer levels) read 0.81 (13 of 16 voxels at level 0),
    /// the whole ones 0.975; every tower and demo variant, whole or ruined,
    /// 0.97-1.0. At 0.8 the bunny's torn ears passed.
    pub min_extent_ratio: f64,
    /// More free-boundary share than `free_boundary_ratio` times the
    /// exemplar's plus `free_boundary_slack`: torn (or open: a wall's end).
    pub free_boundary_ratio: f64,
    pub free_boundary_slack: f64,
    /// Enclosure below this share of the exemplar's: open.
    pub min_enclosure_ratio: f64,
    /// Boundary F-score (1-voxel tolerance) to the exemplar at or above
    /// which a variant is a near copy, unless it also differs in one place
    /// of at least `copy_max_change` of the exemplar's surface
    /// ([`largest_change`]: a ruin, a wing of its own).
    pub copy_fscore: f64,
    pub copy_max_change: f64,
    /// A shape whose differences from the exemplar are all parts of it
    /// moved ([`Matching::moved_parts_only`]: every changed region of at
    /// least `moved_min_share` of the exemplar's surface voxels gone in one
    /// place and found again, the same shape, in another), with as much
    /// surface as the exemplar (within `moved_mass_slack`), is a near copy
    /// too: the exemplar with one building shifted, where a doubled
    /// courtyard adds surface and is new. 0.04, as `copy_max_change`: a
    /// window moved along a longer house (1-2% of its surface) is a new
    /// arrangement, a building moved is not.
    pub moved_min_share: f64,
    pub moved_mass_slack: f64,
    /// Boundary F-score (1-voxel tolerance) at level 0 (16^3) at or above
    /// which a shape sampled in the exemplar's box is a near copy whatever
    /// its finer levels did ([`StructureScores::with_coarse`]): the finer
    /// networks add cracks and notches to a single house whose level 0 is
    /// the exemplar's voxel for voxel (F 1.000), and those damages read as
    /// changes at 64^3. Measured: a single house's level 0, drawn by its
    /// network, reads 1.000 against the exemplar's; the ruined tower's and
    /// the demo's whole variants 0.960-0.995.
    pub coarse_copy_fscore: f64,
    /// A shape sampled in the exemplar's box whose outline, from every one
    /// of the 24 views, is the exemplar's but for less than this share of
    /// the pixels either covers ([`super::outline::outline_difference`], 1
    /// pixel a voxel of 64^3, 1 pixel of tolerance) is a near copy: a person
    /// sees the exemplar again, whatever moved inside or behind its outline.
    /// 0.08, measured at 64^3 (`examples/seen_difference.rs`): a Greek stone
    /// house's copies, their hidden courtyard floors moved, read
    /// 0.012-0.064; the ruined tower's variants 0.097-0.151; the demo's
    /// 0.101-0.133 but for one, 0.036, the exemplar with its notch filled.
    pub max_copy_outline_difference: f64,
    /// More of the inside seen than the exemplar shows, in some view band (a
    /// share of the silhouette, [`super::seen_through::seen_through_excess`]):
    /// split open or torn through. 0.02, measured (docs/lab/new-shapes.md, "New shapes: the level-0 choice and the seen-through flag"): on real
    /// runs it flags the one tower of ten torn open, and two of the demo's
    /// ten, its most ruined, which a person would keep; on the ladder it
    /// flags the slit on five meshes of seven (not the airplane, 0.015, nor a
    /// gable house, 0.013) and the roof strip on four of five (not the
    /// airplane).
    pub max_seen_through_excess: f64,
    /// Fewer thin-part voxels ([`thin_voxels`]) than this share of the
    /// exemplar's: a thin part lost (an ear gone inside the bounding box,
    /// where no other figure moves past its limit). 0.8, measured at 64^3
    /// (docs/lab/new-shapes.md, "Thin parts"): every bunny variant of the last runs
    /// 0.36-0.73 (each lost or cut short its back ear); every tower and demo
    /// variant 0.90-1.23.
    pub min_thin_ratio: f64,
    /// The thin-part flag applies when the exemplar has at least this share
    /// of its surface voxels on thin parts (a sphere has none to lose).
    pub min_exemplar_thin_share: f64,
    /// Where the exemplar is a height field without a hole (a terrain, a
    /// cliff; `Structure::sheet_axis`), more columns with no surface
    /// inside the footprint than this share of the exemplar's surface voxels:
    /// holed. 0.001, measured (docs/lab/structure-flags.md, "Holes through a sheet"):
    /// 3 columns at 64^3 on the terrain of ../shared/data, where its
    /// variants with holes seen from above have 3-62.
    pub max_hole_share: f64,
    /// More of the surface like no part of the exemplar than this share
    /// ([`unlike_share`], at the structure level): out of style. 0.09,
    /// measured (docs/lab/structure-flags.md, "Out of style"): the ruined tower's
    /// variants with a wall fallen outward or a heap of rubble read
    /// 0.098-0.157, those a person keeps 0-0.085; every terrain variant
    /// 0.006-0.084, every bunny variant 0-0.065; the CAD part's broken fin 0.096.
    pub max_unlike_share: f64,
    /// The same limit on the unlike share at the level after the structure
    /// level ([`fine_level`], 128^3, against the exemplar's same level):
    /// fine out of style. MEASURED_FINE
    pub max_fine_unlike_share: f64,
    /// More seams across the top surface than the exemplar's, along an
    /// axis where its top is smooth ([`super::steps::extra_seams`]):
    /// stepped. 0: a roof in two halves is broken.
    pub max_extra_seams: usize,
    /// Along an axis where the exemplar's top is smooth, more of the shape's
    /// columns stepping than this share beyond the exemplar's
    /// ([`super::steps::smooth_step_excess`]): stepped, a roof creased or
    /// cracked across. 0.02, measured at 64^3 (`examples/fine_steps.rs`
    /// with `LEVEL=2`): a village house's resized variants whose roofs
    /// crack at 128^3 read 0.027-0.050, its whole ones 0.006-0.009; no other
    /// exemplar here has a smooth axis (the church steps 2.3% along its
    /// nave, the temple 3.5%), so nothing else is judged.
    pub max_smooth_step_excess: f64,
}

impl Default for StructureParams {
    fn default() -> Self {
        StructureParams {
            min_mass_ratio: 0.8,
            min_extent_ratio: 0.9,
            free_boundary_ratio: 1.15,
            free_boundary_slack: 0.002,
            min_enclosure_ratio: 0.85,
            copy_fscore: 0.95,
            copy_max_change: 0.04,
            moved_min_share: 0.04,
            moved_mass_slack: 0.06,
            coarse_copy_fscore: 0.998,
            max_copy_outline_difference: 0.08,
            max_seen_through_excess: 0.02,
            min_thin_ratio: 0.8,
            min_exemplar_thin_share: 0.02,
            max_hole_share: 0.001,
            max_unlike_share: 0.09,
            max_fine_unlike_share: 0.09,
            max_extra_seams: 0,
            max_smooth_step_excess: 0.02,
        }
    }
}

impl StructureParams {
    /// The free-boundary share above which a shape is torn, given the
    /// exemplar's.
    pub fn free_boundary_limit(&self, exemplar_share: f64) -> f64 {
        self.free_boundary_ratio * exemplar_share + self.free_boundary_slack
    }
}

/// What a structural comparison found wrong with a shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Flag {
    /// Much less surface than the exemplar (a large part missing), or far more.
    Fragment,
    /// Shorter than the exemplar along some axis.
    Shrunken,
    /// More pieces than the exemplar (components of 5% or more).
    Pieces,
    /// Far more free edges than the exemplar: holes, wall ends.
    Torn,
    /// Surrounds much less of its centre than the exemplar does: a side
    /// gone, a wall standing alone, a hole through a roof.
    Open,
    /// Shows more of its inside than the exemplar does, through a slit
    /// along its height, a missing strip of roof, a hole in a closed shell.
    SeenThrough,
    /// Far fewer voxels on thin parts than the exemplar: an ear, a spire or
    /// a fin lost or cut short.
    ThinPartLost,
    /// Holes through a sheet the exemplar has none in (a terrain seen from
    /// above with the sky through it).
    Holed,
    /// Much of its surface like no part of the exemplar: a wall fallen
    /// outward, a heap of rubble, ragged sheets.
    OutOfStyle,
    /// The same at the level after the structure level ([`fine_level`],
    /// 128^3): ragged sheets and flakes that the finer stage (the detail
    /// transfer, or a network) made where the 64^3 level passes.
    FineOutOfStyle,
    /// Its top surface steps where the exemplar's is smooth: a roof in two
    /// halves a voxel or two apart, a crack across it at the finest level
    /// ([`super::steps`]).
    Stepped,
    /// Nearly the exemplar itself.
    NearCopy,
}

impl Flag {
    pub fn name(self) -> &'static str {
        match self {
            Flag::Fragment => "fragment",
            Flag::Shrunken => "shrunken",
            Flag::Pieces => "pieces",
            Flag::Torn => "torn",
            Flag::Open => "open",
            Flag::SeenThrough => "seen_through",
            Flag::ThinPartLost => "thin_part_lost",
            Flag::Holed => "holed",
            Flag::OutOfStyle => "out_of_style",
            Flag::FineOutOfStyle => "fine_out_of_style",
            Flag::Stepped => "stepped",
            Flag::NearCopy => "near_copy",
        }
    }
    /// The flag of a name [`Flag::name`] gives (as eval.json writes it).
    pub fn from_name(name: &str) -> Option<Flag> {
        use Flag::*;
        [Fragment, Shrunken, Pieces, Torn, Open, SeenThrough, ThinPartLost, Holed, OutOfStyle, FineOutOfStyle, Stepped, NearCopy]
            .into_iter()
            .find(|f| f.name() == name)
    }
    /// Whether the flag says the shape is not whole (a near copy is whole,
    /// just not new).
    pub fn broken(self) -> bool {
        !matches!(self, Flag::NearCopy)
    }
}

/// A shape's structure against the exemplar's at the same level.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StructureScores {
    /// Resolution of the level compared.
    pub resolution: u32,
    /// Surface voxels, variant / exemplar.
    pub mass_ratio: f64,
    /// Bounding box, variant / exemplar, along the axis where it is
    /// smallest, the variant's side moved one voxel toward the exemplar's
    /// ([`EXTENT_TOLERANCE_VOXELS`]).
    pub extent_ratio: f64,
    /// Pieces (components of 5% or more) of the variant, and of the exemplar.
    pub pieces: usize,
    pub exemplar_pieces: usize,
    /// Share of the surface voxels on a free boundary, and the exemplar's.
    pub free_boundary: f64,
    pub exemplar_free_boundary: f64,
    /// Enclosure ([`enclosure`]), variant / exemplar.
    pub enclosure_ratio: f64,
    /// How much more of its inside the variant shows than the exemplar, in
    /// the view where it shows most more (share of the silhouette).
    #[serde(default)]
    pub seen_through_excess: f64,
    /// Thin-part voxels ([`thin_voxels`]), variant / exemplar (1 when the
    /// exemplar has fewer than `min_exemplar_thin_share` of them). Not a
    /// term of `score`: the level-0 gate scores 16^3 shapes, where an ear is
    /// a voxel or two.
    #[serde(default = "crate::config::one_f64")]
    pub thin_ratio: f64,
    /// Where the exemplar is a sheet (`Structure::sheet_axis`), the columns
    /// inside the variant's footprint with no surface along that axis: holes
    /// through it (0 elsewhere).
    #[serde(default)]
    pub hole_columns: usize,
    /// The axis along which the exemplar is a sheet (0 x, 1 y, 2 z), where
    /// `hole_columns` are counted; none for other shapes.
    #[serde(default)]
    pub sheet_axis: Option<usize>,
    /// Share of the surface voxels like no part of the exemplar
    /// ([`unlike_share`]; 0 below 32^3).
    #[serde(default)]
    pub unlike_share: f64,
    /// Seams across its top surface beyond the exemplar's, along an axis
    /// where the exemplar's is smooth ([`super::steps::extra_seams`]).
    #[serde(default)]
    pub extra_seams: usize,
    /// Along an axis where the exemplar's top is smooth, the share of
    /// neighbouring columns that step beyond the exemplar's
    /// ([`super::steps::smooth_step_excess`]).
    #[serde(default)]
    pub smooth_step_excess: f64,
    /// The same share at the level after the structure level
    /// ([`fine_level`], 128^3; [`StructureScores::with_fine`]); not written
    /// where that level was not compared.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fine_unlike_share: Option<f64>,
    /// Boundary F-score to the exemplar's voxels with a 1-voxel tolerance
    /// (1: the exemplar's surface, voxel for voxel).
    pub copy_fscore: f64,
    /// Boundary F-score (1-voxel tolerance) of the variant's level 0 to the
    /// exemplar's ([`StructureScores::with_coarse`]); not written where not
    /// compared (a bent or resized variant, whose level 0 is new by its
    /// pose or size).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_copy_fscore: Option<f64>,
    /// The worst view's share of the outline that differs from the
    /// exemplar's ([`StructureScores::with_outline`]); not written where not
    /// compared (a bent or resized variant).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outline_difference: Option<f64>,
    /// The largest connected place where the variant differs from the
    /// exemplar, a share of the exemplar's surface voxels ([`largest_change`]).
    #[serde(default)]
    pub largest_change: f64,
    /// One figure in [0, 1], 1 = the exemplar's structure: the worst of the
    /// mass, extent, piece, free-boundary, enclosure, seen-through, hole and
    /// out-of-style terms
    /// ([`StructureScores::new`]).
    pub score: f64,
    pub flags: Vec<Flag>,
}

impl StructureScores {
    /// `shape` (structure `s` of level `shape_level`) against the exemplar
    /// (`e` of `exemplar_level`, the same resolution). The score's terms,
    /// each 1 at the exemplar: mass min(r, 1/r); extent min over axes of
    /// min(r, 1/r); pieces (largest share of the variant / the exemplar's,
    /// at most 1); free boundary (the torn limit
    /// [`StructureParams::free_boundary_limit`] / the variant's share, at most
    /// 1: below 1 exactly when flagged torn); enclosure (variant / exemplar, at most 1);
    /// seen through (the limit / the excess, at most 1: below 1 exactly when flagged);
    /// holes (the limit / the hole columns, at most 1: below 1 exactly when flagged);
    /// out of style (the limit / the unlike share, at most 1: below 1 exactly when flagged).
    pub fn new(shape_level: &Level, s: &Structure, exemplar_level: &Level, e: &Structure, p: &StructureParams) -> Self {
        Self::with_pose(shape_level, s, exemplar_level, e, (exemplar_level, e), p)
    }

    /// [`StructureScores::new`] with the terms that depend on how the
    /// surface is turned, the inside seen from fixed views and the
    /// out-of-style patches, measured against `pose` (a level of the
    /// exemplar's resolution and its structure) instead of the exemplar.
    fn with_pose(
        shape_level: &Level,
        s: &Structure,
        exemplar_level: &Level,
        e: &Structure,
        pose: (&Level, &Structure),
        p: &StructureParams,
    ) -> Self {
        let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
        let sym = |r: f64| if r > 0.0 { r.min(1.0 / r) } else { 0.0 };
        let mass_ratio = ratio(s.voxels as f64, e.voxels as f64);
        // A side one voxel shorter or longer is the same size: a thin relief
        // of 5 voxels against 6 is a rounding of the surface, not a part
        // lost (EXTENT_TOLERANCE_VOXELS).
        let axis_ratios: Vec<f64> = (0..3)
            .map(|a| {
                let (v, x) = (s.extent[a] as f64, e.extent[a] as f64);
                ratio(v + (x - v).clamp(-EXTENT_TOLERANCE_VOXELS, EXTENT_TOLERANCE_VOXELS), x)
            })
            .collect();
        let extent_ratio = axis_ratios.iter().copied().fold(f64::INFINITY, f64::min);
        let (fb, efb) = (s.free_boundary_share(), e.free_boundary_share());
        let enclosure_ratio = ratio(s.enclosure, e.enclosure);
        let seen_through_excess = super::seen_through::seen_through_excess(&s.seen_through, &pose.1.seen_through);
        let thin_ratio = if e.thin as f64 >= p.min_exemplar_thin_share * e.voxels as f64 && e.thin > 0 {
            s.thin as f64 / e.thin as f64
        } else {
            1.0
        };
        let sheet_axis = e.sheet_axis;
        let hole_columns = sheet_axis.map_or(0, |a| s.enclosed_columns[a]);
        let hole_limit = p.max_hole_share * e.voxels as f64;
        let unlike_share = unlike_share(shape_level, pose.0);
        let extra_seams = super::steps::extra_seams(&s.top_steps, &e.top_steps);
        // Measured at 64^3; at 16^3 a step is a quarter voxel and a level-0
        // candidate's roof is judged by its seams alone.
        let smooth_step_excess =
            if s.resolution >= STRUCTURE_RESOLUTION / 2 { super::steps::smooth_step_excess(&s.top_steps, &e.top_steps) } else { 0.0 };
        let terms = [
            sym(mass_ratio),
            axis_ratios.iter().map(|&r| sym(r)).fold(1.0, f64::min),
            (ratio(s.largest_share(), e.largest_share())).min(1.0),
            if fb > 0.0 { (p.free_boundary_limit(efb) / fb).min(1.0) } else { 1.0 },
            enclosure_ratio.min(1.0),
            if seen_through_excess > 0.0 {
                (p.max_seen_through_excess / seen_through_excess).min(1.0)
            } else {
                1.0
            },
            if hole_columns > 0 { (hole_limit / hole_columns as f64).min(1.0) } else { 1.0 },
            if unlike_share > 0.0 { (p.max_unlike_share / unlike_share).min(1.0) } else { 1.0 },
            if extra_seams > p.max_extra_seams { 1.0 / (1 + extra_seams - p.max_extra_seams) as f64 } else { 1.0 },
            if smooth_step_excess > 0.0 { (p.max_smooth_step_excess / smooth_step_excess).min(1.0) } else { 1.0 },
        ];
        let matching = Matching::of(shape_level, exemplar_level);
        let (copy_fscore, largest_change) = (matching.fscore(), matching.largest_change());
        let mut flags = Vec::new();
        if mass_ratio < p.min_mass_ratio || mass_ratio > 1.0 / p.min_mass_ratio {
            flags.push(Flag::Fragment);
        }
        if extent_ratio < p.min_extent_ratio {
            flags.push(Flag::Shrunken);
        }
        if s.pieces() > e.pieces() {
            flags.push(Flag::Pieces);
        }
        if fb > p.free_boundary_limit(efb) {
            flags.push(Flag::Torn);
        }
        if enclosure_ratio < p.min_enclosure_ratio {
            flags.push(Flag::Open);
        }
        if seen_through_excess > p.max_seen_through_excess {
            flags.push(Flag::SeenThrough);
        }
        if thin_ratio < p.min_thin_ratio {
            flags.push(Flag::ThinPartLost);
        }
        if hole_columns as f64 > hole_limit {
            flags.push(Flag::Holed);
        }
        if unlike_share > p.max_unlike_share {
            flags.push(Flag::OutOfStyle);
        }
        if extra_seams > p.max_extra_seams || smooth_step_excess > p.max_smooth_step_excess {
            flags.push(Flag::Stepped);
        }
        let moved_only = (copy_fscore < p.copy_fscore || largest_change >= p.copy_max_change)
            && (mass_ratio - 1.0).abs() <= p.moved_mass_slack
            && matching.moved_parts_only(p.moved_min_share);
        if (copy_fscore >= p.copy_fscore && largest_change < p.copy_max_change) || moved_only {
            flags.push(Flag::NearCopy);
        }
        StructureScores {
            resolution: s.resolution,
            mass_ratio,
            extent_ratio,
            pieces: s.pieces(),
            exemplar_pieces: e.pieces(),
            free_boundary: fb,
            exemplar_free_boundary: efb,
            enclosure_ratio,
            seen_through_excess,
            thin_ratio,
            hole_columns,
            sheet_axis,
            unlike_share,
            extra_seams,
            smooth_step_excess,
            fine_unlike_share: None,
            coarse_copy_fscore: None,
            outline_difference: None,
            copy_fscore,
            largest_change,
            score: terms.iter().copied().fold(1.0, f64::min),
            flags,
        }
    }

    /// These scores with the level after the structure level compared too:
    /// `shape_fine` ([`fine_level`], 128^3) against `reference_fine`, the
    /// exemplar's same level (bent where the shape was). Its unlike share
    /// joins the score as one more term (the limit / the share, at most 1)
    /// and, above [`StructureParams::max_fine_unlike_share`], flags
    /// [`Flag::FineOutOfStyle`]. Levels of other resolutions change nothing.
    pub fn with_fine(mut self, shape_fine: &Level, reference_fine: &Level, p: &StructureParams) -> Self {
        if shape_fine.resolution != reference_fine.resolution || shape_fine.resolution <= self.resolution {
            return self;
        }
        let share = unlike_share(shape_fine, reference_fine);
        if share > 0.0 {
            self.score = self.score.min((p.max_fine_unlike_share / share).min(1.0));
        }
        if share > p.max_fine_unlike_share {
            // Before `near_copy`, where the other broken flags are.
            let at = self.flags.iter().position(|f| *f == Flag::NearCopy).unwrap_or(self.flags.len());
            self.flags.insert(at, Flag::FineOutOfStyle);
        }
        self.fine_unlike_share = Some(share);
        self
    }

    /// These scores with level 0 compared too: `shape0` (the variant's level
    /// 0) against `exemplar0` (the exemplar's, in the same box). At or above
    /// [`StructureParams::coarse_copy_fscore`] the shape is a near copy: its
    /// arrangement is the exemplar's, whatever the finer levels changed.
    /// Levels of different resolutions change nothing.
    pub fn with_coarse(mut self, shape0: &Level, exemplar0: &Level, p: &StructureParams) -> Self {
        if shape0.resolution != exemplar0.resolution || shape0.is_empty() {
            return self;
        }
        let f = Matching::of(shape0, exemplar0).fscore();
        self.coarse_copy_fscore = Some(f);
        if f >= p.coarse_copy_fscore && !self.flags.contains(&Flag::NearCopy) {
            self.flags.push(Flag::NearCopy);
        }
        self
    }

    /// These scores with the outlines compared too: `shape` against
    /// `exemplar` (the same level, in the exemplar's box) from the 24 views
    /// ([`super::outline::outline_difference`]). Under
    /// [`StructureParams::max_copy_outline_difference`] the shape is a near
    /// copy: it looks like the exemplar from everywhere.
    pub fn with_outline(mut self, shape: &Level, exemplar: &Level, p: &StructureParams) -> Self {
        if shape.resolution != exemplar.resolution {
            return self;
        }
        let d = super::outline::outline_difference(shape, exemplar);
        self.outline_difference = Some(d);
        if d < p.max_copy_outline_difference && !self.flags.contains(&Flag::NearCopy) {
            self.flags.push(Flag::NearCopy);
        }
        self
    }

    /// No flag that says the shape is broken.
    pub fn whole(&self) -> bool {
        !self.flags.iter().any(|f| f.broken())
    }

    /// The scores of a shape that is the exemplar bent (`level::warp`):
    /// against the exemplar, but for the inside seen from fixed views and the
    /// out-of-style patches, which are measured against `bent`, the
    /// exemplar's same level bent the same way (a turned surface shows other
    /// views and matches no unturned patch, and is neither torn nor out of
    /// style). So a bend that merges an ear into the head, stretches a thin
    /// part away or splits the surface is still flagged, and `near_copy` says
    /// whether the bend made anything new.
    pub fn against_bend(
        shape_level: &Level,
        s: &Structure,
        bent: (&Level, &Structure),
        exemplar_level: &Level,
        e: &Structure,
        p: &StructureParams,
    ) -> Self {
        Self::with_pose(shape_level, s, exemplar_level, e, bent, p)
    }
}

/// What a shape's structure level is judged against, besides the exemplar's
/// own level (its style).
#[derive(Clone, Copy)]
pub enum Against<'a> {
    /// The exemplar in its own box; with level 0 (the shape's, the
    /// exemplar's) where known: a level 0 that is the exemplar's makes a
    /// near copy ([`StructureScores::with_coarse`]).
    Exemplar { level0: Option<(&'a Level, &'a Level)> },
    /// The exemplar bent as the shape's start was (its level bent, with its
    /// structure): [`StructureScores::against_bend`].
    Bent(&'a Level, &'a Structure),
    /// The exemplar at the extent of the shape's resized box (its level
    /// stretched, with its structure): [`StructureScores::at_extent`].
    AtExtent(&'a Level, &'a Structure),
}

impl StructureScores {
    /// The one verdict sampling, eval and the studio give a shape: its
    /// structure level `shape` against `exemplar` (the exemplar's same level
    /// and structure) made as the shape's start was (`against`), then, where
    /// given, its fine level against the exemplar's (`fine`: the shape's, the
    /// reference's, bent likewise; [`StructureScores::with_fine`]).
    pub fn judged(
        shape: &Level,
        exemplar: (&Level, &Structure),
        against: Against,
        fine: Option<(&Level, &Level)>,
        p: &StructureParams,
    ) -> Self {
        let s = Structure::of(shape);
        let scores = match against {
            Against::Bent(bent, b) => Self::against_bend(shape, &s, (bent, b), exemplar.0, exemplar.1, p),
            Against::AtExtent(at, a) => Self::at_extent(shape, &s, (at, a), exemplar, p),
            Against::Exemplar { level0 } => {
                let scores = Self::new(shape, &s, exemplar.0, exemplar.1, p).with_outline(shape, exemplar.0, p);
                match level0 {
                    Some((l0, e0)) => scores.with_coarse(l0, e0, p),
                    None => scores,
                }
            }
        };
        match fine {
            Some((f, reference)) => scores.with_fine(f, reference, p),
            None => scores,
        }
    }
}

impl StructureScores {
    /// The scores of a shape sampled in a resized box
    /// ([`crate::level::resize`]): against the exemplar at that extent
    /// (`at_extent`: its level stretched, and that level's structure) for
    /// size, surface, pieces, openings, the inside seen and copies; its
    /// out-of-style patches against the exemplar's own level (`style`: a
    /// stretched wall's stones are not the exemplar's style, a longer wall
    /// of the same stones is).
    pub fn at_extent(
        shape_level: &Level,
        s: &Structure,
        at_extent: (&Level, &Structure),
        style: (&Level, &Structure),
        p: &StructureParams,
    ) -> Self {
        Self::with_pose(shape_level, s, at_extent.0, at_extent.1, (style.0, at_extent.1), p)
    }
}

/// The largest place where shape `a` differs from `b` (same resolution): the
/// voxels of either with no voxel of the other within 1 voxel (Chebyshev),
/// grouped into 26-connected regions, the largest region's size as a share of
/// `b`'s voxels (0 for the same surface; 0 when `b` is empty). A copy with its
/// surface jittered differs in many small places; a tower with a ruin of its
/// own differs in one large one.
pub fn largest_change(a: &Level, b: &Level) -> f64 {
    Matching::of(a, b).largest_change()
}

/// F-score of two levels' surface voxels (same resolution) where a voxel
/// counts as matched when the other set has a voxel within 1 voxel
/// (Chebyshev): 1 for the same surface, low for a shape that is elsewhere.
pub fn tolerant_fscore(a: &Level, b: &Level) -> f64 {
    Matching::of(a, b).fscore()
}

impl Matching {
    /// [`largest_change`] of the two.
    pub fn largest_change(&self) -> f64 {
        let m = self;
        if m.b_voxels == 0 {
            return 0.0;
        }
        // A voxel of `a` and one of `b` share a coordinate only if both matched,
        // so the unmatched voxels hold no duplicates.
        let changed: Vec<IVec3> = m.a_unmatched.iter().chain(&m.b_unmatched).copied().collect();
        components(&changed).first().map_or(0.0, |&c| c as f64 / m.b_voxels as f64)
    }

    /// The voxels of `b`'s largest region that `a` lacks (none of `a`'s
    /// within 1 voxel), and the voxels `a` has where `b` has none: an ear
    /// gone with nothing in its place is (9, 0) on the bunny at 16^3.
    pub fn gone_and_added(&self) -> (usize, usize) {
        (components(&self.b_unmatched).first().copied().unwrap_or(0), self.a_unmatched.len())
    }

    /// Share of `a`'s voxels with one of `b` within 1 voxel (0 when either
    /// is empty): below 1 where `a` has something `b` does not.
    pub fn precision(&self) -> f64 {
        if self.a_voxels == 0 || self.b_voxels == 0 {
            return 0.0;
        }
        1.0 - self.a_unmatched.len() as f64 / self.a_voxels as f64
    }

    /// Share of `b`'s voxels with one of `a` within 1 voxel (0 when either
    /// is empty): below 1 where `a` lacks something of `b`.
    pub fn recall(&self) -> f64 {
        if self.a_voxels == 0 || self.b_voxels == 0 {
            return 0.0;
        }
        1.0 - self.b_unmatched.len() as f64 / self.b_voxels as f64
    }

    /// [`tolerant_fscore`] of the two.
    pub fn fscore(&self) -> f64 {
        let (precision, recall) = (self.precision(), self.recall());
        if precision + recall == 0.0 {
            0.0
        } else {
            2.0 * precision * recall / (precision + recall)
        }
    }
}

impl Matching {
    /// Whether every difference of `a` from `b` is a part of `b` moved: each
    /// region (26-connected) of `b`'s voxels that `a` lacks and each region
    /// of voxels `a` adds, of at least `min_share` of `b`'s voxels, pairs
    /// with a region of the other kind that is its shape translated (its
    /// voxels, moved by the difference of the two centroids, within 1 voxel
    /// of the other's for [`MOVED_OVERLAP`] of them both ways, and sizes
    /// within a third of each other); smaller regions are a surface's
    /// jitter. False where nothing large changed (that is
    /// [`largest_change`]'s case) or something is left unpaired: a part
    /// added, lost or made anew.
    pub fn moved_parts_only(&self, min_share: f64) -> bool {
        let min = (min_share * self.b_voxels as f64).max(1.0);
        let regions = |set: &[IVec3]| -> Vec<Vec<IVec3>> {
            let (labels, sizes) = component_labels(set);
            let mut out: Vec<Vec<IVec3>> = sizes.iter().map(|&n| Vec::with_capacity(n)).collect();
            for (c, l) in set.iter().zip(labels) {
                out[l].push(*c);
            }
            out.retain(|r| r.len() as f64 >= min);
            out
        };
        let (gone, added) = (regions(&self.b_unmatched), regions(&self.a_unmatched));
        if gone.is_empty() || gone.len() != added.len() {
            return false;
        }
        let mut free = vec![true; gone.len()];
        added.iter().all(|a| {
            let found = (0..gone.len()).find(|&g| free[g] && translated_alike(&gone[g], a));
            found.map(|g| free[g] = false).is_some()
        })
    }
}

/// Share of each of two regions' voxels that must lie within 1 voxel of the
/// other's, once moved onto it, for [`Matching::moved_parts_only`] to call
/// one the other moved.
pub const MOVED_OVERLAP: f64 = 0.7;

/// Whether region `b` is region `a` translated (see [`MOVED_OVERLAP`]).
fn translated_alike(a: &[IVec3], b: &[IVec3]) -> bool {
    let (na, nb) = (a.len() as f64, b.len() as f64);
    if na.min(nb) / na.max(nb) < 2.0 / 3.0 {
        return false;
    }
    let centroid = |r: &[IVec3]| r.iter().fold(glam::DVec3::ZERO, |s, c| s + c.as_dvec3()) / r.len() as f64;
    let d = (centroid(b) - centroid(a)).round().as_ivec3();
    let moved: Vec<IVec3> = a.iter().map(|&c| c + d).collect();
    let set = |r: &[IVec3]| -> HashSet<IVec3> { r.iter().copied().collect() };
    let (sm, sb) = (set(&moved), set(b));
    let near = |from: &HashSet<IVec3>, to: &HashSet<IVec3>| 1.0 - unmatched(from, to).len() as f64 / from.len() as f64;
    near(&sm, &sb) >= MOVED_OVERLAP && near(&sb, &sm) >= MOVED_OVERLAP
}

/// The voxels of `from` with no voxel of `to` within 1 voxel (Chebyshev).
fn unmatched(from: &HashSet<IVec3>, to: &HashSet<IVec3>) -> Vec<IVec3> {
    from.iter().filter(|&&c| !(to.contains(&c) || NEIGHBOURS_26.iter().any(|&d| to.contains(&(c + d))))).copied().collect()
}

/// Two levels' surface voxels matched both ways with a 1-voxel (Chebyshev)
/// tolerance: the voxels of each with none of the other within 1 voxel.
pub struct Matching {
    a_voxels: usize,
    b_voxels: usize,
    a_unmatched: Vec<IVec3>,
    b_unmatched: Vec<IVec3>,
}

impl Matching {
    pub fn of(a: &Level, b: &Level) -> Matching {
        let set = |l: &Level| -> HashSet<IVec3> { (0..l.len()).filter(|&i| l.mask[i] > 0.0).map(|i| l.coords[i]).collect() };
        let (sa, sb) = (set(a), set(b));
        Matching {
            a_voxels: sa.len(),
            b_voxels: sb.len(),
            a_unmatched: unmatched(&sa, &sb),
            b_unmatched: unmatched(&sb, &sa),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The voxel shell of a sphere (or of its part where `keep` holds) at `res`.
    fn sphere(res: u32, radius: f64, keep: impl Fn(Vec3) -> bool) -> Level {
        let mut l = crate::testing::synthetic::sphere_levels(&[res], glam::DVec3::ZERO, radius).remove(0);
        let pts: Vec<Vec3> = (0..l.len()).map(|i| l.point_normalised(i).as_vec3()).collect();
        l.retain(|i| keep(pts[i]));
        l
    }

    #[test]
    fn a_closed_sphere_has_no_free_boundary_and_a_cut_one_has_a_rim() {
        let whole = sphere(64, 0.7, |_| true);
        let s = Structure::of(&whole);
        assert_eq!(s.pieces(), 1);
        assert!(s.free_boundary_share() < 0.01, "closed: {s:?}");
        let half = sphere(64, 0.7, |p| p.x < 0.0);
        let h = Structure::of(&half);
        // The rim is a circle of radius 0.7 (~22 voxels): ~140 voxels.
        assert!(h.free_boundary > 60 && h.free_boundary_share() > 0.02, "{h:?}");
        assert!(s.enclosure > 0.99 && h.enclosure < 0.8, "enclosure {} {}", s.enclosure, h.enclosure);
        let sc = StructureScores::new(&half, &h, &whole, &s, &StructureParams::default());
        assert!(sc.flags.contains(&Flag::Fragment) && sc.flags.contains(&Flag::Shrunken), "{sc:?}");
        assert!(sc.score < 0.6, "{sc:?}");
        let same = StructureScores::new(&whole, &s, &whole, &s, &StructureParams::default());
        assert_eq!((same.score, same.copy_fscore, same.flags.clone()), (1.0, 1.0, vec![Flag::NearCopy]));
        assert!(same.whole());
    }

    #[test]
    fn pieces_and_holes_are_seen() {
        let whole = sphere(64, 0.7, |_| true);
        let s = Structure::of(&whole);
        // Two caps, apart: two pieces.
        let caps = sphere(64, 0.7, |p| p.y.abs() > 0.3);
        let c = Structure::of(&caps);
        assert_eq!(c.pieces(), 2, "{c:?}");
        let sc = StructureScores::new(&caps, &c, &whole, &s, &StructureParams::default());
        assert!(sc.flags.contains(&Flag::Pieces), "{sc:?}");
        // Holes: six discs of 0.2 (6.4 voxels) cut away at the poles of the
        // axes, 12% of the surface; the rest in place.
        let poles = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z].map(|a| a * 0.7);
        let holes = sphere(64, 0.7, |p| poles.iter().all(|&c| c.distance(p) > 0.2));
        let t = Structure::of(&holes);
        let sc = StructureScores::new(&holes, &t, &whole, &s, &StructureParams::default());
        assert!(sc.flags.contains(&Flag::Torn), "{sc:?}");
        assert!(!sc.flags.contains(&Flag::Shrunken) && !sc.flags.contains(&Flag::Fragment), "{sc:?}");
    }

    #[test]
    fn a_shape_cut_short_is_shrunken_and_a_trimmed_one_is_not() {
        let whole = sphere(64, 0.7, |_| true);
        let s = Structure::of(&whole);
        // The top cut at 0.5 of 0.7: 86% of the height, 86% of the surface
        // (a bunny's ears without their tips; the cut's rim is a tear too):
        // shrunken, not a fragment.
        let cut = sphere(64, 0.7, |p| p.y < 0.5);
        let sc = StructureScores::new(&cut, &Structure::of(&cut), &whole, &s, &StructureParams::default());
        assert!(sc.extent_ratio < 0.9 && sc.extent_ratio > 0.8, "{sc:?}");
        assert!(sc.flags.contains(&Flag::Shrunken) && !sc.flags.contains(&Flag::Fragment), "{sc:?}");
        // Trimmed at 0.65: 96% of the height, whole.
        let trimmed = sphere(64, 0.7, |p| p.y < 0.65);
        let st = StructureScores::new(&trimmed, &Structure::of(&trimmed), &whole, &s, &StructureParams::default());
        assert!(!st.flags.contains(&Flag::Shrunken), "{st:?}");
    }

    /// The voxel shells of `spheres` (centre, radius) at `res`, merged.
    use crate::testing::synthetic::sphere_union as spheres;

    #[test]
    fn a_thin_part_lost_inside_the_box_is_flagged() {
        // A body (radius 0.5, 16 voxels at 64^3) with an ear: a rod of small
        // spheres (radius 0.045, a diameter of about 3 voxels) up from its
        // top, and a second ear's worth of rod kept below the body, so that
        // losing the top ear leaves the bounding box as it was.
        let body = (Vec3::ZERO, 0.5);
        let rod = |y0: f32, sign: f32| (0..10).map(move |k| (Vec3::new(0.0, sign * (y0 + 0.04 * k as f32), 0.0), 0.045));
        let ears: Vec<(Vec3, f64)> = std::iter::once(body).chain(rod(0.5, 1.0)).chain(rod(0.5, -1.0)).collect();
        let one_ear: Vec<(Vec3, f64)> = std::iter::once(body)
            .chain(rod(0.5, 1.0).take(1))
            .chain(rod(0.5, -1.0))
            .chain([(Vec3::new(0.0, 0.86, 0.0), 0.045)]) // the top ear's tip alone keeps the box
            .collect();
        let exemplar = spheres(64, &ears);
        let e = Structure::of(&exemplar);
        assert!(e.thin as f64 > 0.05 * e.voxels as f64, "the ears are thin: {} of {}", e.thin, e.voxels);
        let p = StructureParams::default();
        let same = StructureScores::new(&exemplar, &e, &exemplar, &e, &p);
        assert_eq!(same.thin_ratio, 1.0);
        assert!(!same.flags.contains(&Flag::ThinPartLost));
        let lost = spheres(64, &one_ear);
        let l = Structure::of(&lost);
        let sc = StructureScores::new(&lost, &l, &exemplar, &e, &p);
        assert!(sc.thin_ratio < 0.8 && sc.flags.contains(&Flag::ThinPartLost) && !sc.whole(), "{sc:?}");
        assert!(!sc.flags.contains(&Flag::Shrunken), "the box is kept: {sc:?}");
        // A body without thin parts has nothing to lose: the flag does not apply.
        let ball = spheres(64, &[body]);
        let b = Structure::of(&ball);
        assert!((b.thin as f64) < 0.02 * b.voxels as f64, "a ball is not thin: {} of {}", b.thin, b.voxels);
        let smaller = spheres(64, &[(Vec3::ZERO, 0.45)]);
        let sc = StructureScores::new(&smaller, &Structure::of(&smaller), &ball, &b, &p);
        assert_eq!(sc.thin_ratio, 1.0, "{sc:?}");
        // Normals of any length (a network's, before they are written) count
        // the same thin voxels as unit ones.
        let mut short = exemplar.clone();
        for (k, n) in short.normals.iter_mut().enumerate() {
            *n *= if k % 2 == 0 { 0.3 } else { 1.7 };
        }
        assert_eq!(Structure::of(&short).thin, e.thin);
    }

    #[test]
    fn a_cap_cut_off_is_gone_with_nothing_added_and_a_cap_moved_is_both() {
        let whole = sphere(32, 0.7, |_| true);
        assert_eq!(Matching::of(&whole, &whole).gone_and_added(), (0, 0));
        // The cap above y = 0.5 (a sphere's shell, 1-voxel tolerance: the
        // voxels more than a voxel above the cut are gone, as one region).
        let capless = sphere(32, 0.7, |p| p.y < 0.5);
        let (gone, added) = Matching::of(&capless, &whole).gone_and_added();
        let above = (0..whole.len()).filter(|&i| whole.point_normalised(i).y > 0.5 + 2.0 / 16.0).count();
        assert!(gone >= above && gone < whole.len() / 4 && added == 0, "gone {gone}, added {added}, {above} above the cut");
        // The other way round the cap is added and nothing is gone.
        assert_eq!(Matching::of(&whole, &capless).gone_and_added(), (0, gone));
    }

    #[test]
    fn a_part_moved_elsewhere_is_a_near_copy_and_a_part_doubled_is_new() {
        use crate::testing::synthetic::sphere_union;
        let (a, b, b_moved, c) = (Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.3, 0.0, 0.0), Vec3::new(0.3, 0.0, 0.6), Vec3::new(-0.5, 0.0, 0.6));
        let ex = sphere_union(64, &[(a, 0.2), (b, 0.2)]);
        let moved = sphere_union(64, &[(a, 0.2), (b_moved, 0.2)]);
        let doubled = sphere_union(64, &[(a, 0.2), (b, 0.2), (c, 0.2)]);
        let lost = sphere_union(64, &[(a, 0.2)]);
        let p = StructureParams::default();
        let (es, params) = (Structure::of(&ex), &p);
        let score = |l: &Level| StructureScores::new(l, &Structure::of(l), &ex, &es, params);
        let m = score(&moved);
        assert!(m.copy_fscore < p.copy_fscore, "not a copy by the F-score alone: {m:?}");
        assert!(m.flags.contains(&Flag::NearCopy), "{m:?}");
        let d = score(&doubled);
        assert!(!d.flags.contains(&Flag::NearCopy), "{d:?}");
        let l = score(&lost);
        assert!(!l.flags.contains(&Flag::NearCopy), "{l:?}");
        // Moved and turned into something else: a ball where a ball was, a
        // long rod somewhere new.
        let rod = sphere_union(64, &[(a, 0.2), (Vec3::new(0.3, 0.0, 0.5), 0.12), (Vec3::new(0.3, 0.0, 0.68), 0.12), (Vec3::new(0.3, 0.0, 0.32), 0.12)]);
        let r = score(&rod);
        assert!(!r.flags.contains(&Flag::NearCopy), "{r:?}");
    }

    #[test]
    fn a_part_like_nothing_on_the_exemplar_is_out_of_style_and_the_exemplar_moved_is_not() {
        let p = StructureParams::default();
        let voxel = 2.0 / 64.0;
        let exemplar = spheres(64, &[(Vec3::ZERO, 0.55)]);
        let e = Structure::of(&exemplar);
        let same = StructureScores::new(&exemplar, &e, &exemplar, &e, &p);
        assert_eq!(same.unlike_share, 0.0);
        // Moved by whole voxels, every neighbourhood is one of the exemplar's.
        let moved = spheres(64, &[(Vec3::new(2.0 * voxel, voxel, 0.0), 0.55)]);
        let m = StructureScores::new(&moved, &Structure::of(&moved), &exemplar, &e, &p);
        assert!(m.unlike_share < 0.01 && !m.flags.contains(&Flag::OutOfStyle), "{m:?}");
        // A fan of thin rods (small spheres, 3 voxels across) splayed out and
        // down from its side, as a wall fallen outward: nothing on a ball is
        // like it.
        let mut fan = vec![(Vec3::ZERO, 0.55)];
        for a in [20.0f32, 35.0, 50.0] {
            let dir = Vec3::new(a.to_radians().cos(), -a.to_radians().sin(), 0.0);
            for z in [-0.12f32, 0.0, 0.12] {
                fan.extend((0..10).map(|k| (dir * (0.5 + 0.04 * k as f32) + Vec3::Z * z, 0.045)));
            }
        }
        let fallen = spheres(64, &fan);
        let f = StructureScores::new(&fallen, &Structure::of(&fallen), &exemplar, &e, &p);
        assert!(f.unlike_share > p.max_unlike_share && f.flags.contains(&Flag::OutOfStyle) && !f.whole(), "{f:?}");
        assert!(f.score < 1.0, "{f:?}");
        // At 16^3 a window spans most of the shape: not compared.
        let coarse = spheres(16, &fan);
        let ball = spheres(16, &[(Vec3::ZERO, 0.55)]);
        assert_eq!(unlike_share(&coarse, &ball), 0.0);
    }

    #[test]
    fn rods_made_at_the_fine_level_on_a_sound_structure_level_are_fine_out_of_style() {
        let p = StructureParams::default();
        let ball = |r| spheres(r, &[(Vec3::ZERO, 0.55)]);
        let (exemplar, exemplar_fine) = (ball(64), ball(128));
        let e = Structure::of(&exemplar);
        let sound = StructureScores::new(&exemplar, &e, &exemplar, &e, &p);
        assert!(sound.whole() && sound.fine_unlike_share.is_none(), "{sound:?}");
        // The same ball at 128^3: nothing unlike, whole, the share recorded.
        let same = sound.clone().with_fine(&exemplar_fine, &exemplar_fine, &p);
        assert_eq!(same.fine_unlike_share, Some(0.0));
        assert!(same.whole() && same.score == sound.score, "{same:?}");
        // Thin rods (2-3 voxels across at 128^3) sticking out of the ball at
        // 128^3 only, as a finer network's ragged flakes: flagged, the score
        // lowered, the structure level's own flags kept (the ball against
        // itself is a near copy).
        let mut rods = vec![(Vec3::ZERO, 0.55)];
        for a in (0..12).map(|k| 30.0 * k as f32) {
            for y in [-0.5f32, 0.0, 0.5] {
                let dir = Vec3::new(a.to_radians().cos(), y, a.to_radians().sin()).normalize();
                rods.extend((0..15).map(|k| (dir * (0.52 + 0.02 * k as f32), 0.02)));
            }
        }
        let ragged = sound.clone().with_fine(&spheres(128, &rods), &exemplar_fine, &p);
        let share = ragged.fine_unlike_share.unwrap();
        assert!(share > p.max_fine_unlike_share, "{ragged:?}");
        assert_eq!(ragged.flags, vec![Flag::FineOutOfStyle, Flag::NearCopy], "{ragged:?}");
        assert!(!ragged.whole() && ragged.score < 1.0, "{ragged:?}");
        // A level of the structure level's resolution, or two levels that
        // differ, compare nothing.
        assert_eq!(sound.clone().with_fine(&exemplar, &exemplar, &p), sound);
        assert_eq!(sound.clone().with_fine(&spheres(128, &rods), &spheres(256, &[(Vec3::ZERO, 0.55)]), &p), sound);
    }

    #[test]
    fn a_hole_through_a_sheet_is_holed_and_a_closed_shell_has_no_sheet_axis() {
        // A sphere's cap is a height field along y; a hole of 0.3 x 0.3 (about
        // 10 x 10 columns at 64^3) punched through its top.
        let cap = sphere(64, 0.7, |p| p.y > 0.3);
        let c = Structure::of(&cap);
        assert_eq!(c.sheet_axis, Some(1), "{c:?}");
        let holed = sphere(64, 0.7, |p| p.y > 0.3 && (p.x.abs() > 0.15 || p.z.abs() > 0.15));
        let p = StructureParams::default();
        let sc = StructureScores::new(&holed, &Structure::of(&holed), &cap, &c, &p);
        assert_eq!(sc.sheet_axis, Some(1));
        assert!(sc.hole_columns >= 50 && sc.flags.contains(&Flag::Holed) && !sc.whole(), "{sc:?}");
        assert!(sc.score < 0.2, "{sc:?}");
        let same = StructureScores::new(&cap, &c, &cap, &c, &p);
        assert_eq!((same.hole_columns, same.whole()), (0, true));
        // A closed sphere is no sheet: the flag does not apply.
        let whole = sphere(64, 0.7, |_| true);
        assert_eq!(Structure::of(&whole).sheet_axis, None);
    }

    #[test]
    fn components_count_26_connected_sets() {
        let c = [IVec3::ZERO, IVec3::ONE, IVec3::new(5, 5, 5), IVec3::new(5, 6, 5), IVec3::new(5, 7, 5)];
        assert_eq!(components(&c), vec![3, 2]);
        assert!(components(&[]).is_empty());
    }
}
