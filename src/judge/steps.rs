//! Steps across a top surface the exemplar has smooth: a roof in two halves.
//! Where the networks fill a box longer than the one exemplar they learned
//! (`level::resize`), they may join two stretches of roof a voxel or two
//! apart in height; at the finest levels the joint opens into a crack across
//! the roof. It closes no view and frees no edge, so the other measures miss
//! it; a person sees it at once.
//!
//! The top surface is read as a height map over the two horizontal axes (the
//! highest surface voxel of each column). Along each horizontal axis the
//! share of neighbouring inner columns (all four neighbours in the footprint,
//! so eaves and walls' tops are not counted) whose heights differ by a step
//! is counted. Along an axis where the exemplar is smooth (a ridge's length,
//! a flat roof), a shape's steps beyond the exemplar's are what
//! [`step_excess`] measures; along an axis where the exemplar itself steps
//! (across a steep roof, a ruin's broken crown, a terrain's terraces) nothing
//! is judged.
//!
//! Lengths are in voxels of the level measured and scale with its resolution
//! against [`super::levels::STRUCTURE_RESOLUTION`].

use super::levels::STRUCTURE_RESOLUTION;
use super::thresholds::THRESHOLDS;
use crate::level::Level;





/// The top surface's steps along the two horizontal axes (across the
/// level's up axis, in x, y, z order).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TopSteps {
    /// Per axis, the share of neighbouring inner columns whose heights
    /// differ by a step (`THRESHOLDS.step_voxels`, scaled to the level's resolution).
    pub shares: [f64; 2],
    /// Per axis, the seams (`THRESHOLDS.seam_share`) across it.
    pub seams: [usize; 2],
}

/// The top height map's steps of `level` (zeros for a level with no inner
/// columns).
pub fn top_steps(level: &Level) -> TopSteps {
    let up = if level.frame.up.axis().z > 0.5 { 2 } else { 1 };
    let across: Vec<usize> = (0..3).filter(|&a| a != up).collect();
    let (u, v) = (across[0], across[1]);
    let mut top: std::collections::HashMap<(i32, i32), i32> = std::collections::HashMap::new();
    for (c, &m) in level.coords.iter().zip(&level.mask) {
        if m > 0.0 {
            let e = top.entry((c[u], c[v])).or_insert(c[up]);
            *e = (*e).max(c[up]);
        }
    }
    let step = (THRESHOLDS.step_voxels * level.resolution as f32 / STRUCTURE_RESOLUTION as f32).max(1.0).round() as i32;
    let inner = |k: (i32, i32)| [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().all(|d| top.contains_key(&(k.0 + d.0, k.1 + d.1)));
    let mut out = TopSteps::default();
    for axis in 0..2 {
        let d = if axis == 0 { (1, 0) } else { (0, 1) };
        // Per position along the axis: the inner column pairs across it, and
        // the columns across (by their other coordinate) that step there.
        let mut pairs: std::collections::BTreeMap<i32, usize> = std::collections::BTreeMap::new();
        let mut stepped: std::collections::HashSet<(i32, i32)> = std::collections::HashSet::new();
        let (mut steps, mut count) = (0usize, 0usize);
        for (&k, &h) in &top {
            let next = (k.0 + d.0, k.1 + d.1);
            if !(inner(k) && inner(next)) {
                continue;
            }
            let (along, other) = if axis == 0 { (k.0, k.1) } else { (k.1, k.0) };
            *pairs.entry(along).or_default() += 1;
            count += 1;
            if (top[&next] - h).abs() >= step {
                steps += 1;
                stepped.insert((along, other));
            }
        }
        out.shares[axis] = if count == 0 { 0.0 } else { steps as f64 / count as f64 };
        let mut last_seam: Option<i32> = None;
        for (&at, &n) in &pairs {
            let across: std::collections::HashSet<i32> =
                stepped.iter().filter(|(a, _)| (at..at + THRESHOLDS.seam_window).contains(a)).map(|&(_, o)| o).collect();
            if across.len() as f64 >= THRESHOLDS.seam_share * n as f64 {
                // Steps within the window of the last seam are that seam.
                if last_seam.is_none_or(|l| at >= l + THRESHOLDS.seam_window) {
                    out.seams[axis] += 1;
                }
                last_seam = Some(at);
            }
        }
    }
    out
}

/// The seams a shape's top has beyond the exemplar's, along the horizontal
/// axis where the exemplar's top is smooth (`THRESHOLDS.smooth_share`) and the shape
/// has most more (0 where the exemplar is smooth along no axis).
pub fn extra_seams(shape: &TopSteps, exemplar: &TopSteps) -> usize {
    (0..2).filter(|&a| exemplar.shares[a] <= THRESHOLDS.smooth_share).map(|a| shape.seams[a].saturating_sub(exemplar.seams[a])).max().unwrap_or(0)
}

/// Along an axis where the exemplar's top is smooth (`THRESHOLDS.smooth_share`), the
/// share of a shape's neighbouring inner columns that step beyond the
/// exemplar's share (the largest over such axes; 0 where the exemplar is
/// smooth along no axis): a roof creased or cracked across, whose steps
/// wander along it (a diagonal crack) and so never gather into a seam.
pub fn smooth_step_excess(shape: &TopSteps, exemplar: &TopSteps) -> f64 {
    (0..2).filter(|&a| exemplar.shares[a] <= THRESHOLDS.smooth_share).map(|a| (shape.shares[a] - exemplar.shares[a]).max(0.0)).fold(0.0, f64::max)
}

/// The voxel columns of a prism roof for the tests: a gable house `length`
/// long along x, `width` wide along z, its ridge `rise` above the eaves,
/// with the roof's height shifted by `seam` voxels from `seam_at` on (a roof
/// in two halves).
#[cfg(test)]
fn gable(length: i32, width: i32, rise: i32, seam_at: i32, seam: i32) -> Level {
    let mut coords = Vec::new();
    for x in 0..length {
        for z in 0..width {
            let from_eave = z.min(width - 1 - z);
            let h = 10 + from_eave * rise * 2 / width + if x >= seam_at { seam } else { 0 };
            for y in 0..=h {
                // The roof and the walls' outer ring: a shell.
                if y == h || x == 0 || x == length - 1 || z == 0 || z == width - 1 {
                    coords.push(glam::IVec3::new(x + 10, y, z + 20));
                }
            }
        }
    }
    let n = coords.len();
    Level {
        index: 2,
        resolution: 64,
        frame: Default::default(),
        coords,
        offsets: vec![glam::Vec3::ZERO; n],
        normals: vec![glam::Vec3::Y; n],
        colours: vec![glam::Vec3::splat(0.5); n],
        mask: vec![1.0; n],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_roof_in_two_halves_has_a_seam_along_its_ridge_and_a_whole_one_has_none() {
        let whole = top_steps(&gable(40, 20, 16, 100, 0));
        assert!(whole.shares[0] <= THRESHOLDS.smooth_share, "along the ridge a whole roof is smooth: {whole:?}");
        assert!(whole.shares[1] > 0.3, "across it, a steep roof steps at every column: {whole:?}");
        assert_eq!(whole.seams[0], 0);
        for seam in [1, 2] {
            let seamed = top_steps(&gable(40, 20, 16, 20, seam));
            assert_eq!((seamed.seams[0], extra_seams(&seamed, &whole)), (1, 1), "{seamed:?}");
        }
        // A longer whole house has no more seams than the exemplar.
        assert_eq!(extra_seams(&top_steps(&gable(56, 20, 16, 100, 0)), &whole), 0);
        // A dormer's bump (4 x 4 columns on the roof) is not a seam.
        let mut dormer = gable(40, 20, 16, 100, 0);
        let top = dormer.coords.iter().map(|c| c.y).max().unwrap();
        let extra: Vec<glam::IVec3> = (24..28).flat_map(|x| (23..27).map(move |z| glam::IVec3::new(x, top + 2, z))).collect();
        for c in extra {
            dormer.coords.push(c);
            dormer.offsets.push(glam::Vec3::ZERO);
            dormer.normals.push(glam::Vec3::Y);
            dormer.colours.push(glam::Vec3::splat(0.5));
            dormer.mask.push(1.0);
        }
        assert_eq!(extra_seams(&top_steps(&dormer), &whole), 0);
    }

    #[test]
    fn a_diagonal_crack_across_a_smooth_roof_steps_without_a_seam() {
        let whole = top_steps(&gable(40, 20, 16, 100, 0));
        let mut cracked = gable(40, 20, 16, 100, 0);
        // A slot two columns wide and two voxels deep, diagonal across the
        // roof: each row steps down and up once, at its own place.
        let tops: std::collections::HashMap<(i32, i32), i32> = cracked.coords.iter().fold(Default::default(), |mut m, c| {
            let e = m.entry((c.x, c.z)).or_insert(c.y);
            *e = (*e).max(c.y);
            m
        });
        for c in cracked.coords.iter_mut() {
            let along = c.x - 10 - (c.z - 20);
            if (10..12).contains(&along) && c.z > 20 && c.z < 39 && tops[&(c.x, c.z)] == c.y {
                c.y -= 2;
            }
        }
        let t = top_steps(&cracked);
        assert_eq!(extra_seams(&t, &whole), 0, "{t:?}");
        assert!(smooth_step_excess(&t, &whole) > 0.02, "{t:?}");
        // A whole longer house and a dormer stay under it.
        assert!(smooth_step_excess(&top_steps(&gable(56, 20, 16, 100, 0)), &whole) < 0.005);
    }

    #[test]
    fn where_the_exemplar_steps_along_both_axes_nothing_is_judged() {
        let rough = TopSteps { shares: [0.05, 0.2], seams: [0, 0] };
        assert_eq!(extra_seams(&TopSteps { shares: [0.5, 0.5], seams: [3, 3] }, &rough), 0);
        assert_eq!(smooth_step_excess(&TopSteps { shares: [0.5, 0.5], seams: [3, 3] }, &rough), 0.0);
        let smooth_x = TopSteps { shares: [0.0, 0.4], seams: [0, 5] };
        assert_eq!(extra_seams(&TopSteps { shares: [0.5, 0.0], seams: [2, 9] }, &smooth_x), 2);
        assert_eq!(smooth_step_excess(&TopSteps { shares: [0.5, 0.0], seams: [2, 9] }, &smooth_x), 0.5);
    }
}
