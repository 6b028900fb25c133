//! The exemplar at another extent: the paper's resize. Sampling may start
//! from a level-0 box longer or shorter than the exemplar's along some axes
//! (`--extent`, or a pass resized because the networks only copy,
//! `sample.proposers.resize_max`); the networks fill the box in their own way (a longer
//! house gets more windows, not wider ones). Such a variant is judged against
//! the exemplar at the same extent ([`stretched`]): its size, surface,
//! openings and copies are measured against what the exemplar would be in
//! that box, its style against the exemplar's own patches.

use glam::{IVec3, Vec3};

use super::Level;
use crate::error::{Error, Result};

/// The largest level-0 box sampling starts from, in multiples of the
/// level-0 grid's full cube (16^3 voxels at the shipped profiles: at most
/// 262,144 voxels). Sampling fills the level-0 box densely with noise, and
/// every finer level grows with it, so the box is bounded before anything
/// is allocated: `--extent 4,4,4` or `16,4,1` fit, `1000,1000,1000` does not.
pub const MAX_LEVEL0_BOX_CUBES: f64 = 64.0;

/// Where a variant whose level-0 box was not the exemplar's records its
/// extent, beside its level files: eval judges it against the exemplar at
/// that extent.
pub const EXTENT_FILE: &str = "extent.json";

/// The smallest scale of a resized pass's axis (`sample.proposers.resize_max` is the
/// largest): a quarter longer is one level-0 voxel more on a 4-voxel side
/// and a new bay on a house's length.
pub const RESIZE_MIN_SCALE: f64 = 1.25;

/// A variant's extent: the per-axis scale of its level-0 box against the
/// exemplar's (1, 1, 1: the exemplar's box).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Extent {
    pub extent: [f32; 3],
}

impl Extent {
    /// The exemplar's own box.
    pub const SAME: Extent = Extent { extent: [1.0; 3] };

    pub fn is_same(&self) -> bool {
        self.extent == [1.0; 3]
    }

    /// `levels[index]` at this extent ([`stretched`]); the level itself
    /// at the exemplar's extent.
    pub fn of(&self, levels: &[Level], index: usize) -> Result<Level> {
        if self.is_same() {
            return Ok(levels[index].clone());
        }
        stretched(&levels[0], &levels[index], self.extent)
    }

    /// A resized pass's extent, drawn from `seed`: the exemplar's longer
    /// horizontal axis (across its up axis) scaled by a factor in
    /// [[`RESIZE_MIN_SCALE`], `max`]. A house grows along its ridge; across
    /// it a gable roof would have to grow taller, which a network trained on
    /// one roof height does not do (the houses at `--extent 2,1,2`:
    /// parallel roofs torn open). None when the box would exceed
    /// [`MAX_LEVEL0_BOX_CUBES`].
    pub fn drawn(level0: &Level, max: f64, seed: u64) -> Option<Extent> {
        let (lo, hi) = bounds(level0)?;
        let size = hi - lo;
        let up = if level0.frame.up.axis().z > 0.5 { 2 } else { 1 };
        let horizontal: Vec<usize> = (0..3).filter(|&a| a != up).collect();
        let axis = if size[horizontal[0]] >= size[horizontal[1]] { horizontal[0] } else { horizontal[1] };
        // A derived seed is a non-negative i64: 63 bits, of which the top 53
        // make a uniform draw in [0, 1).
        let unit = (crate::util::seed::derive_seed(seed, 1, crate::util::seed::Stream::Resize, 0) >> 10) as f64 / (1u64 << 53) as f64;
        let scale = RESIZE_MIN_SCALE + (max - RESIZE_MIN_SCALE).max(0.0) * unit;
        let mut extent = [1.0f32; 3];
        // Two decimals: what the record and the log say is what was used.
        extent[axis] = ((scale * 100.0).round() / 100.0) as f32;
        level0_box(level0, extent).ok().map(|_| Extent { extent })
    }
}

impl std::fmt::Display for Extent {
    /// "1.5,1,1": the per-axis scales as `--extent` takes them.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.extent.map(|e| e.to_string()).join(","))
    }
}

/// The level-0 box of the exemplar resized by `extent` around its centre:
/// `(min, size)` in voxels. An extent that is not positive, or whose box
/// exceeds [`MAX_LEVEL0_BOX_CUBES`], is a usage error.
pub fn level0_box(level0: &Level, extent: [f32; 3]) -> Result<(IVec3, IVec3)> {
    let Some((lo, hi)) = bounds(level0) else {
        return Err(Error::Invalid("the exemplar's level 0 has no voxels".into()));
    };
    let shown = Extent { extent };
    if extent.iter().any(|e| !(e.is_finite() && *e > 0.0)) {
        return Err(Error::Usage(format!("--extent {shown}: each scale must be a positive number")));
    }
    let size = hi - lo;
    // In f64 first: a huge extent must not overflow the i32 voxel counts.
    let sizes = [0, 1, 2].map(|a| (size[a] as f64 * extent[a] as f64).round().max(1.0));
    let voxels = sizes[0] * sizes[1] * sizes[2];
    let budget = MAX_LEVEL0_BOX_CUBES * (level0.resolution as f64).powi(3);
    if voxels > budget {
        return Err(Error::Usage(format!(
            "--extent {shown}: the level-0 box would be {}x{}x{} = {voxels:.3e} voxels, more than the {budget:.0} \
             ({MAX_LEVEL0_BOX_CUBES} level-0 grids of {r}^3) sampling allows; every finer level grows by the same factor",
            sizes[0], sizes[1], sizes[2], r = level0.resolution
        )));
    }
    let new_size = IVec3::from_array(sizes.map(|v| v as i32));
    // keep the centre: shift by half the change (floor division keeps it exact for even changes)
    let new_lo = lo + IVec3::from_array([0, 1, 2].map(|a| (size[a] - new_size[a]).div_euclid(2)));
    Ok((new_lo, new_size))
}

/// `level` (a level of the exemplar whose level 0 is `level0`) stretched to
/// the box `extent` gives level 0 ([`level0_box`]), scaled to `level`'s
/// resolution: every voxel of that box takes the voxel of `level` it falls
/// back on (nearest, per axis), so a wall stays one voxel thick and a roof
/// slope becomes a longer staircase. Normals turn as a stretched surface's
/// do (divided by the scale, renormalised); offsets and colours are kept.
pub fn stretched(level0: &Level, level: &Level, extent: [f32; 3]) -> Result<Level> {
    let (lo0, size0) = {
        let (lo, hi) = bounds(level0).ok_or_else(|| Error::Invalid("the exemplar's level 0 has no voxels".into()))?;
        (lo, hi - lo)
    };
    let (new_lo0, new_size0) = level0_box(level0, extent)?;
    let f = (level.resolution / level0.resolution.max(1)) as i32;
    let (lo, size, new_lo, new_size) = (lo0 * f, size0 * f, new_lo0 * f, new_size0 * f);
    let scale = new_size.as_vec3() / size.as_vec3();
    // The target voxels along one axis that fall back on source voxel `s`:
    // those t with floor((t - new_lo) * size / new_size) = s - lo.
    let span = |a: usize, s: i32| -> std::ops::Range<i32> {
        let k = (s - lo[a]) as i64;
        let (n, d) = (new_size[a] as i64, size[a] as i64);
        let first = (k * n + d - 1).div_euclid(d);
        let end = ((k + 1) * n + d - 1).div_euclid(d);
        (new_lo[a] + first as i32)..(new_lo[a] + end as i32)
    };
    let mut out = Level { index: level.index, resolution: level.resolution, frame: level.frame, ..Default::default() };
    for i in 0..level.len() {
        let c = level.coords[i];
        let n = (level.normals[i] / scale).normalize_or_zero();
        for x in span(0, c.x) {
            for y in span(1, c.y) {
                for z in span(2, c.z) {
                    out.push_row(level, i, IVec3::new(x, y, z));
                    *out.normals.last_mut().expect("pushed") = if n == Vec3::ZERO { level.normals[i] } else { n };
                }
            }
        }
    }
    Ok(out)
}

/// The voxel box of `level`: (min, max + 1); None when empty.
fn bounds(level: &Level) -> Option<(IVec3, IVec3)> {
    if level.is_empty() {
        return None;
    }
    let lo = level.coords.iter().fold(IVec3::MAX, |a, &c| a.min(c));
    let hi = level.coords.iter().fold(IVec3::MIN, |a, &c| a.max(c));
    Some((lo, hi + IVec3::ONE))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::synthetic::sphere_levels;

    #[test]
    fn the_same_extent_is_the_level_and_a_longer_one_is_longer_by_its_scale() {
        let levels = sphere_levels(&[16, 64], glam::DVec3::ZERO, 0.5);
        let same = stretched(&levels[0], &levels[1], [1.0; 3]).unwrap();
        assert_eq!(same.coords, levels[1].coords);
        let long = stretched(&levels[0], &levels[1], [1.5, 1.0, 1.0]).unwrap();
        let (lo, hi) = bounds(&levels[1]).unwrap();
        let (llo, lhi) = bounds(&long).unwrap();
        let (size, lsize) = (hi - lo, lhi - llo);
        assert_eq!((lsize.y, lsize.z), (size.y, size.z));
        // 1.5 times as long (the level-0 box's own ratio, 6 voxels to 9) and
        // about the same centre.
        let (_, box_size) = level0_box(&levels[0], [1.5, 1.0, 1.0]).unwrap();
        let ratio = box_size.x as f32 / (bounds(&levels[0]).map(|(l, h)| h - l).unwrap().x as f32);
        assert!((lsize.x as f32 - size.x as f32 * ratio).abs() <= 1.0, "{} vs {} x {ratio}", lsize.x, size.x);
        assert!(((llo.x + lhi.x) - (lo.x + hi.x)).abs() <= 8, "centred: {llo}..{lhi} against {lo}..{hi}");
        // A stretched shell is still a shell: each voxel once, no gaps along x.
        long.check().unwrap();
        let xs: std::collections::BTreeSet<i32> = long.coords.iter().map(|c| c.x).collect();
        assert_eq!(xs.len() as i32, lsize.x);
        // Normals tilt toward the axes not stretched.
        let i = (0..long.len()).max_by(|&a, &b| long.coords[a].x.cmp(&long.coords[b].x)).unwrap();
        assert!(long.normals[i].x > 0.9, "{}", long.normals[i]);
    }

    #[test]
    fn a_drawn_extent_scales_the_longer_horizontal_axis_over_its_whole_range() {
        // A box longer along z than x (y up).
        let mut level0 = sphere_levels(&[16], glam::DVec3::ZERO, 0.5).remove(0);
        let keep: Vec<bool> = level0.coords.iter().map(|c| (5..=10).contains(&c.x)).collect();
        level0.retain(|i| keep[i]);
        let scales: Vec<f32> = (0..200)
            .map(|seed| {
                let e = Extent::drawn(&level0, 1.75, seed).unwrap().extent;
                assert_eq!((e[0], e[1]), (1.0, 1.0), "z is the longer horizontal axis: {e:?}");
                e[2]
            })
            .collect();
        assert!(scales.iter().all(|s| (1.25..=1.75).contains(s)), "{scales:?}");
        let (lo, hi) = (scales.iter().copied().fold(f32::MAX, f32::min), scales.iter().copied().fold(0.0, f32::max));
        assert!(lo < 1.3 && hi > 1.7, "the whole range is drawn: {lo}..{hi}");
    }
}
