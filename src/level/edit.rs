//! Copy-and-paste editing of a level (the paper's editing, section 5): copy a
//! box of voxels with their features to another place, or delete a box. The
//! edited level is a normal level file, so `sample --from` continues the finer
//! levels from it.
//!
//! Boxes are given in voxel coordinates of the level (what `shapeshifter info`
//! prints as the grids' bounding boxes), inclusive at both ends.

use crate::grid::VoxelMap;

use glam::IVec3;

use crate::error::{Error, Result};
use crate::level::Level;

/// An inclusive box of voxel coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VoxelBox {
    pub min: IVec3,
    pub max: IVec3,
}

impl VoxelBox {
    pub fn contains(&self, c: IVec3) -> bool {
        c.cmpge(self.min).all() && c.cmple(self.max).all()
    }

    /// Parses `x0,y0,z0:x1,y1,z1` (corners in any order).
    pub fn parse(text: &str) -> Result<VoxelBox> {
        let bad = || Error::Invalid(format!("box '{text}': expected x0,y0,z0:x1,y1,z1 in voxels"));
        let (a, b) = text.split_once(':').ok_or_else(bad)?;
        let (a, b) = (parse_ivec3(a).ok_or_else(bad)?, parse_ivec3(b).ok_or_else(bad)?);
        Ok(VoxelBox { min: a.min(b), max: a.max(b) })
    }
}

/// Parses `x,y,z` integers.
pub fn parse_ivec3(text: &str) -> Option<IVec3> {
    let v: Vec<i32> = text.split(',').map(|s| s.trim().parse().ok()).collect::<Option<_>>()?;
    (v.len() == 3).then(|| IVec3::new(v[0], v[1], v[2]))
}

/// Parses `x,y,z` floats.
pub fn parse_vec3(text: &str) -> Option<[f32; 3]> {
    let v: Vec<f32> = text.split(',').map(|s| s.trim().parse().ok()).collect::<Option<_>>()?;
    (v.len() == 3).then(|| [v[0], v[1], v[2]])
}

/// Removes the voxels inside `region`; returns how many were removed. A box
/// that holds none (outside the grid, or in empty space) is an error: the
/// user meant to delete something.
pub fn delete_box(level: &mut Level, region: VoxelBox) -> Result<usize> {
    let before = level.len();
    let coords = level.coords.clone();
    level.retain(|i| !region.contains(coords[i]));
    match before - level.len() {
        0 => Err(Error::Invalid(format!(
            "box {}:{} holds no voxels of this level (its grid is 0..{} on each axis; `info` prints the occupied bounding box)",
            fmt(region.min),
            fmt(region.max),
            level.resolution as i32 - 1
        ))),
        n => Ok(n),
    }
}

/// Copies the voxels inside `region` so that `region.min` lands on `to`,
/// features included (offsets are relative to the voxel, so the surface moves
/// with it). Voxels already at the destination are replaced. Returns how many
/// voxels were copied.
pub fn copy_box(level: &mut Level, region: VoxelBox, to: IVec3) -> Result<usize> {
    let shift = to - region.min;
    let res = level.resolution as i32;
    let picked: Vec<usize> = (0..level.len()).filter(|&i| region.contains(level.coords[i])).collect();
    if picked.is_empty() {
        return Err(Error::Invalid(format!(
            "box {}:{} holds no voxels of this level",
            fmt(region.min),
            fmt(region.max)
        )));
    }
    for &i in &picked {
        let c = level.coords[i] + shift;
        if c.min_element() < 0 || c.max_element() >= res {
            return Err(Error::Invalid(format!(
                "the copy would leave the level's {res}^3 grid (voxel {} -> {})",
                fmt(level.coords[i]),
                fmt(c)
            )));
        }
    }
    let copies: Vec<(IVec3, usize)> = picked.iter().map(|&i| (level.coords[i] + shift, i)).collect();
    let dest: VoxelMap<usize> = copies.iter().copied().collect();
    // Drop voxels that the copy overwrites, then append the copies.
    let src = level.clone();
    let coords = level.coords.clone();
    level.retain(|i| !dest.contains(coords[i]));
    for (c, i) in copies {
        level.push_row(&src, i, c);
    }
    Ok(picked.len())
}

/// One edit of a level file (the `edit` command).
#[derive(Clone, Copy, Debug)]
pub enum Edit {
    /// Delete the voxels inside the box.
    Delete(VoxelBox),
    /// Copy the voxels inside the box so that its minimum corner lands on `to`.
    Copy(VoxelBox, IVec3),
}

fn fmt(c: IVec3) -> String {
    format!("{},{},{}", c.x, c.y, c.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn line_level() -> Level {
        let mut l = Level { resolution: 16, ..Default::default() };
        for x in 0..4 {
            l.coords.push(IVec3::new(x, 0, 0));
            l.offsets.push(Vec3::new(0.1 * x as f32, 0.0, 0.0));
            l.normals.push(Vec3::Y);
            l.colours.push(Vec3::splat(x as f32 / 4.0));
            l.mask.push(1.0);
        }
        l
    }

    #[test]
    fn parse_boxes() {
        let b = VoxelBox::parse("3,4,5:1,2,9").unwrap();
        assert_eq!(b.min, IVec3::new(1, 2, 5));
        assert_eq!(b.max, IVec3::new(3, 4, 9));
        assert!(VoxelBox::parse("1,2:3,4").is_err());
        assert!(VoxelBox::parse("a,b,c:1,2,3").is_err());
    }

    #[test]
    fn delete_removes_only_inside() {
        let mut l = line_level();
        let n = delete_box(&mut l, VoxelBox { min: IVec3::new(1, 0, 0), max: IVec3::new(2, 0, 0) }).unwrap();
        assert_eq!(n, 2);
        assert_eq!(l.coords, vec![IVec3::new(0, 0, 0), IVec3::new(3, 0, 0)]);
        assert_eq!(l.offsets[1], Vec3::new(0.3, 0.0, 0.0));
        // Outside the grid, or empty space: an error, the level unchanged.
        for region in [VoxelBox::parse("50,50,50:60,60,60").unwrap(), VoxelBox::parse("1,1,1:2,2,2").unwrap()] {
            let err = delete_box(&mut l, region).unwrap_err().to_string();
            assert!(err.contains("holds no voxels"), "{err}");
            assert_eq!(l.len(), 2);
        }
    }

    #[test]
    fn copy_moves_features_and_overwrites() {
        let mut l = line_level();
        let region = VoxelBox { min: IVec3::new(0, 0, 0), max: IVec3::new(1, 0, 0) };
        assert_eq!(copy_box(&mut l, region, IVec3::new(3, 0, 0)).unwrap(), 2);
        // 0,1,2 stay; 3 replaced by a copy of 0; 4 is a copy of 1.
        assert_eq!(l.len(), 5);
        let at = |c: IVec3| l.coords.iter().position(|&x| x == c).unwrap();
        assert_eq!(l.colours[at(IVec3::new(3, 0, 0))], Vec3::splat(0.0));
        assert_eq!(l.offsets[at(IVec3::new(4, 0, 0))], Vec3::new(0.1, 0.0, 0.0));
        assert!(copy_box(&mut l, region, IVec3::new(15, 0, 0)).is_err(), "out of the grid");
        let empty = VoxelBox { min: IVec3::splat(9), max: IVec3::splat(10) };
        assert!(copy_box(&mut l, empty, IVec3::ZERO).is_err());
    }
}
