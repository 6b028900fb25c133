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

/// The voxels of `level` inside `region`, with their features (a copied
/// piece, as the studio's clipboard holds it). A box that holds none is an
/// error.
pub fn piece(level: &Level, region: VoxelBox) -> Result<Level> {
    let picked: Vec<usize> = (0..level.len()).filter(|&i| region.contains(level.coords[i])).collect();
    if picked.is_empty() {
        return Err(Error::Invalid(format!(
            "box {}:{} holds no voxels of this level",
            fmt(region.min),
            fmt(region.max)
        )));
    }
    Ok(level.rows(&picked))
}

/// Pastes `piece` (voxels of a level of the same resolution) into `level`
/// shifted by `shift` voxels, features included (offsets are relative to the
/// voxel, so the surface moves with it). Voxels already at the destination
/// are replaced. A piece that would leave the grid is an error and changes
/// nothing. Returns how many voxels were pasted.
pub fn paste(level: &mut Level, piece: &Level, shift: IVec3) -> Result<usize> {
    let res = level.resolution as i32;
    if piece.resolution != level.resolution {
        return Err(Error::Invalid(format!(
            "a piece of a {}^3 level cannot be pasted into a {res}^3 level",
            piece.resolution
        )));
    }
    for &c in &piece.coords {
        let to = c + shift;
        if to.min_element() < 0 || to.max_element() >= res {
            return Err(Error::Invalid(format!(
                "the paste would leave the level's {res}^3 grid (voxel {} -> {})",
                fmt(c),
                fmt(to)
            )));
        }
    }
    let dest: VoxelMap<()> = piece.coords.iter().map(|&c| (c + shift, ())).collect();
    let coords = level.coords.clone();
    level.retain(|i| !dest.contains(coords[i]));
    for (i, &c) in piece.coords.iter().enumerate() {
        level.push_row(piece, i, c + shift);
    }
    Ok(piece.len())
}

/// Copies the voxels inside `region` so that `region.min` lands on `to`
/// ([`piece`] then [`paste`]). Returns how many voxels were copied.
pub fn copy_box(level: &mut Level, region: VoxelBox, to: IVec3) -> Result<usize> {
    let piece = piece(level, region)?;
    paste(level, &piece, to - region.min)
}

/// Moves the voxels inside `region` by `shift` voxels: they leave their place
/// (which becomes empty) and replace what is at the destination. Returns how
/// many voxels moved.
pub fn move_box(level: &mut Level, region: VoxelBox, shift: IVec3) -> Result<usize> {
    let piece = piece(level, region)?;
    let mut moved = level.clone();
    let coords = moved.coords.clone();
    moved.retain(|i| !region.contains(coords[i]));
    let n = paste(&mut moved, &piece, shift)?;
    *level = moved;
    Ok(n)
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

    #[test]
    fn move_empties_the_source_and_paste_refuses_to_leave_the_grid() {
        let mut l = line_level();
        let region = VoxelBox { min: IVec3::new(0, 0, 0), max: IVec3::new(1, 0, 0) };
        assert_eq!(move_box(&mut l, region, IVec3::new(0, 5, 0)).unwrap(), 2);
        let mut coords = l.coords.clone();
        coords.sort_by_key(|c| (c.x, c.y, c.z));
        assert_eq!(coords, vec![IVec3::new(0, 5, 0), IVec3::new(1, 5, 0), IVec3::new(2, 0, 0), IVec3::new(3, 0, 0)]);
        let at = |l: &Level, c: IVec3| l.coords.iter().position(|&x| x == c).unwrap();
        assert_eq!(l.offsets[at(&l, IVec3::new(1, 5, 0))], Vec3::new(0.1, 0.0, 0.0), "features move with the voxel");
        // Off the grid: an error, nothing changed.
        let before = l.coords.clone();
        let right = VoxelBox { min: IVec3::new(2, 0, 0), max: IVec3::new(3, 0, 0) };
        assert!(move_box(&mut l, right, IVec3::new(0, 20, 0)).unwrap_err().to_string().contains("leave"));
        let p = piece(&l, VoxelBox { min: IVec3::ZERO, max: IVec3::splat(15) }).unwrap();
        assert!(paste(&mut l, &p, IVec3::new(-3, 0, 0)).is_err());
        assert_eq!(l.coords, before);
        // A piece of another resolution is refused.
        let mut other = line_level();
        other.resolution = 32;
        assert!(paste(&mut l, &other, IVec3::ZERO).unwrap_err().to_string().contains("32^3"));
    }
}
