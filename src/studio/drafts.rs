//! Edits of a coarse level in the studio: a draft is one level of a shape,
//! changed by the editing operations of [`crate::level::edit`] (delete,
//! copy, paste, move, paste from the exemplar), with undo and redo. A draft
//! is regenerated into a new variant by sampling the finer levels from it
//! (`sample --from`'s library function).

use glam::IVec3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::level::edit::{delete_box, move_box, paste, piece, VoxelBox};
use crate::level::Level;

use super::shapes::SeedOf;

/// Edits kept for undo per draft; older ones are forgotten.
pub const MAX_HISTORY: usize = 100;
/// Drafts open at once at most: each holds up to [`MAX_HISTORY`] + 1 copies
/// of its level (a 32^3 level is a few hundred KB).
pub const MAX_DRAFTS: usize = 16;

/// An edit as the page sends it. Boxes are inclusive voxel coordinates of
/// the draft's level, `min` and `max` in any order.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub enum EditRequest {
    /// Remove the voxels inside the box (and inside its mirror image).
    Delete {
        r#box: BoxRequest,
        #[serde(default)]
        mirror: Option<MirrorAxis>,
    },
    /// Put the voxels inside the box on the clipboard.
    Copy { r#box: BoxRequest },
    /// Put the voxels inside the box of the exemplar's level of the same
    /// index on the clipboard.
    CopyExemplar { r#box: BoxRequest },
    /// Paste the clipboard so that its box's minimum corner lands on `to`.
    Paste { to: [i32; 3] },
    /// Move the voxels inside the box by `by` voxels (and those inside its
    /// mirror image by the mirrored shift).
    Move {
        r#box: BoxRequest,
        by: [i32; 3],
        #[serde(default)]
        mirror: Option<MirrorAxis>,
    },
    Undo,
    Redo,
}

/// The axis across which an edit is mirrored, through the middle of the
/// level's occupied voxels along it (the shape's centre): an edit on one
/// side of a symmetric building is made on the other side too, as one undo
/// step.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MirrorAxis {
    X,
    Y,
    Z,
}

impl MirrorAxis {
    fn index(self) -> usize {
        match self {
            MirrorAxis::X => 0,
            MirrorAxis::Y => 1,
            MirrorAxis::Z => 2,
        }
    }

    /// `b`'s mirror image across the middle of `level`'s occupied voxels
    /// along this axis, clipped to the grid (None: nothing of it is in the
    /// grid, or the level is empty).
    fn image(self, b: VoxelBox, level: &Level) -> Option<VoxelBox> {
        let a = self.index();
        let (lo, hi) = level.coords.iter().fold((i32::MAX, i32::MIN), |(lo, hi), c| (lo.min(c[a]), hi.max(c[a])));
        if lo > hi {
            return None;
        }
        // Twice the plane's coordinate: voxel x goes to (lo + hi) - x.
        let twice = lo + hi;
        let (mut min, mut max) = (b.min, b.max);
        min[a] = (twice - b.max[a]).max(0);
        max[a] = (twice - b.min[a]).min(level.resolution as i32 - 1);
        (min[a] <= max[a]).then_some(VoxelBox { min, max })
    }

    fn name(self) -> &'static str {
        match self {
            MirrorAxis::X => "x",
            MirrorAxis::Y => "y",
            MirrorAxis::Z => "z",
        }
    }
}

/// What an edit's message adds when it was mirrored.
fn mirrored_too(mirror: Option<MirrorAxis>) -> String {
    mirror.map(|axis| format!(" and its mirror image across {}", axis.name())).unwrap_or_default()
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxRequest {
    pub min: [i32; 3],
    pub max: [i32; 3],
}

impl BoxRequest {
    /// The box, checked against a grid of `resolution` voxels per axis: a
    /// box reaching outside it is refused (the user aimed at nothing there).
    pub fn inside(self, resolution: u32) -> Result<VoxelBox> {
        let (a, b) = (IVec3::from_array(self.min), IVec3::from_array(self.max));
        let b = VoxelBox { min: a.min(b), max: a.max(b) };
        let r = resolution as i32;
        if b.min.min_element() < 0 || b.max.max_element() >= r {
            return Err(Error::Invalid(format!(
                "box {:?}..{:?} reaches outside the level's grid (0..{} on each axis)",
                b.min.to_array(),
                b.max.to_array(),
                r - 1
            )));
        }
        Ok(b)
    }
}

/// What the clipboard holds: a piece of a level and its box's minimum corner.
#[derive(Clone, Debug)]
pub struct Clipboard {
    pub piece: Level,
    pub min: IVec3,
    /// Where it was copied from ("variant_003 level 1", "the exemplar level 1").
    pub from: String,
}

/// One level of a shape under edit.
pub struct Draft {
    pub id: String,
    /// The shape it was taken from.
    pub source: String,
    /// The source's seed, continued when the draft is regenerated (so the
    /// unedited parts come back as they were).
    pub seed: Option<SeedOf>,
    /// States of the level, oldest first; `at` is the current one.
    history: Vec<Level>,
    at: usize,
    /// What each state after the first did, for the page.
    done: Vec<String>,
}

/// A draft as the page shows it.
#[derive(Serialize)]
pub struct DraftSummary {
    pub id: String,
    pub source: String,
    pub level: usize,
    pub resolution: u32,
    pub voxels: usize,
    pub edits: Vec<String>,
    pub can_undo: bool,
    pub can_redo: bool,
}

impl Draft {
    pub fn new(id: String, source: String, seed: Option<SeedOf>, level: Level) -> Draft {
        Draft { id, source, seed, history: vec![level], at: 0, done: Vec::new() }
    }

    pub fn level(&self) -> &Level {
        &self.history[self.at]
    }

    pub fn summary(&self) -> DraftSummary {
        let l = self.level();
        DraftSummary {
            id: self.id.clone(),
            source: self.source.clone(),
            level: l.index,
            resolution: l.resolution,
            voxels: l.len(),
            edits: self.done[..self.at].to_vec(),
            can_undo: self.at > 0,
            can_redo: self.at + 1 < self.history.len(),
        }
    }

    /// Applies `edit`; `exemplar_level` is the exemplar's level of the
    /// draft's index (for `copy_exemplar`). A refused edit changes nothing.
    /// Returns what it did, for the page.
    pub fn apply(&mut self, edit: &EditRequest, clipboard: &mut Option<Clipboard>, exemplar_level: Option<&Level>) -> Result<String> {
        let res = self.level().resolution;
        match *edit {
            EditRequest::Undo => {
                if self.at == 0 {
                    return Err(Error::Invalid("nothing to undo".into()));
                }
                self.at -= 1;
                return Ok(format!("undid: {}", self.done[self.at]));
            }
            EditRequest::Redo => {
                if self.at + 1 >= self.history.len() {
                    return Err(Error::Invalid("nothing to redo".into()));
                }
                self.at += 1;
                return Ok(format!("redid: {}", self.done[self.at - 1]));
            }
            EditRequest::Copy { r#box } => {
                let b = r#box.inside(res)?;
                let p = piece(self.level(), b)?;
                let what = format!("copied {} voxels", p.len());
                *clipboard = Some(Clipboard { piece: p, min: b.min, from: format!("{} level {}", self.source, self.level().index) });
                return Ok(what);
            }
            EditRequest::CopyExemplar { r#box } => {
                let b = r#box.inside(res)?;
                let ex = exemplar_level
                    .filter(|l| l.resolution == res)
                    .ok_or_else(|| Error::Invalid(format!("the exemplar has no level of {res}^3 to copy from")))?;
                let p = piece(ex, b)?;
                let what = format!("copied {} voxels of the exemplar", p.len());
                *clipboard = Some(Clipboard { piece: p, min: b.min, from: format!("the exemplar level {}", ex.index) });
                return Ok(what);
            }
            _ => {}
        }
        let mut next = self.level().clone();
        let what = match *edit {
            EditRequest::Delete { r#box, mirror } => {
                let b = r#box.inside(res)?;
                let mut n = delete_box(&mut next, b)?;
                // The image may hold nothing (already deleted, or empty there).
                if let Some(m) = mirror.and_then(|axis| axis.image(b, self.level())).filter(|&m| m != b) {
                    n += delete_box(&mut next, m).unwrap_or(0);
                }
                format!("deleted {n} voxels in {:?}..{:?}{}", b.min.to_array(), b.max.to_array(), mirrored_too(mirror))
            }
            EditRequest::Move { r#box, by, mirror } => {
                let b = r#box.inside(res)?;
                let mut n = move_box(&mut next, b, IVec3::from_array(by))?;
                if let Some(axis) = mirror {
                    if let Some(m) = axis.image(b, self.level()).filter(|&m| m != b) {
                        let mut mirrored = by;
                        mirrored[axis.index()] = -by[axis.index()];
                        // move_box changes nothing where it fails (the image
                        // would leave the grid): the first move stands alone.
                        n += move_box(&mut next, m, IVec3::from_array(mirrored)).unwrap_or(0);
                    }
                }
                format!("moved {n} voxels by {by:?}{}", mirrored_too(mirror))
            }
            EditRequest::Paste { to } => {
                let clip = clipboard.as_ref().ok_or_else(|| Error::Invalid("the clipboard is empty: copy a box first".into()))?;
                let n = paste(&mut next, &clip.piece, IVec3::from_array(to) - clip.min)?;
                format!("pasted {n} voxels of {} at {to:?}", clip.from)
            }
            _ => unreachable!("handled above"),
        };
        // A new edit after undos forgets the undone ones.
        self.history.truncate(self.at + 1);
        self.done.truncate(self.at);
        self.history.push(next);
        self.done.push(what.clone());
        self.at += 1;
        if self.history.len() > MAX_HISTORY + 1 {
            self.history.remove(0);
            self.done.remove(0);
            self.at -= 1;
        }
        Ok(what)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn slab() -> Level {
        let mut l = Level { index: 1, resolution: 8, ..Default::default() };
        for x in 0..4 {
            for z in 0..4 {
                l.coords.push(IVec3::new(x, 2, z));
                l.offsets.push(Vec3::ZERO);
                l.normals.push(Vec3::Y);
                l.colours.push(Vec3::splat(0.5));
                l.mask.push(1.0);
            }
        }
        l
    }

    fn bx(min: [i32; 3], max: [i32; 3]) -> BoxRequest {
        BoxRequest { min, max }
    }

    #[test]
    fn edits_undo_and_redo_and_a_new_edit_forgets_the_undone() {
        let mut d = Draft::new("d1".into(), "variant_000".into(), None, slab());
        let mut clip = None;
        d.apply(&EditRequest::Delete { mirror: None, r#box: bx([0, 0, 0], [1, 7, 7]) }, &mut clip, None).unwrap();
        assert_eq!(d.level().len(), 8);
        d.apply(&EditRequest::Copy { r#box: bx([2, 2, 0], [3, 2, 3]) }, &mut clip, None).unwrap();
        assert_eq!(d.summary().edits.len(), 1, "a copy changes nothing");
        d.apply(&EditRequest::Paste { to: [2, 5, 0] }, &mut clip, None).unwrap();
        assert_eq!(d.level().len(), 16);
        d.apply(&EditRequest::Undo, &mut clip, None).unwrap();
        assert_eq!(d.level().len(), 8);
        d.apply(&EditRequest::Redo, &mut clip, None).unwrap();
        assert_eq!(d.level().len(), 16);
        d.apply(&EditRequest::Undo, &mut clip, None).unwrap();
        d.apply(&EditRequest::Undo, &mut clip, None).unwrap();
        assert_eq!(d.level().len(), 16, "back to the source");
        assert!(d.apply(&EditRequest::Undo, &mut clip, None).is_err());
        d.apply(&EditRequest::Move { mirror: None, r#box: bx([0, 2, 0], [0, 2, 3]), by: [0, 1, 0] }, &mut clip, None).unwrap();
        assert!(!d.summary().can_redo, "the undone edits are forgotten");
        assert_eq!(d.level().coords.iter().filter(|c| c.y == 3).count(), 4);
    }

    #[test]
    fn refused_edits_change_nothing() {
        let mut d = Draft::new("d1".into(), "s1".into(), None, slab());
        let mut clip = None;
        for bad in [
            EditRequest::Delete { mirror: None, r#box: bx([0, 0, 0], [8, 1, 1]) },
            EditRequest::Delete { mirror: None, r#box: bx([5, 5, 5], [6, 6, 6]) },
            EditRequest::Paste { to: [0, 0, 0] },
            EditRequest::Move { mirror: None, r#box: bx([0, 2, 0], [3, 2, 3]), by: [0, 6, 0] },
            EditRequest::CopyExemplar { r#box: bx([0, 0, 0], [1, 1, 1]) },
            EditRequest::Redo,
        ] {
            assert!(d.apply(&bad, &mut clip, None).is_err(), "{bad:?}");
            assert_eq!(d.level().len(), 16);
            assert!(!d.summary().can_undo);
        }
        let e = d.apply(&EditRequest::Delete { mirror: None, r#box: bx([-1, 0, 0], [1, 1, 1]) }, &mut clip, None).unwrap_err().to_string();
        assert!(e.contains("outside the level's grid (0..7"), "{e}");
    }

    #[test]
    fn a_mirrored_delete_removes_both_sides_in_one_undo_step() {
        // A row of voxels x = 1..=6 at y = z = 0: the middle is at x = 3.5.
        let mut level = Level { index: 1, resolution: 8, ..Default::default() };
        let donor = slab();
        for x in 1..=6 {
            level.push_row(&donor, 0, IVec3::new(x, 0, 0));
        }
        let mut d = Draft::new("d1".into(), "s1".into(), None, level);
        let mut clip = None;
        let what = d.apply(&EditRequest::Delete { r#box: bx([1, 0, 0], [2, 0, 0]), mirror: Some(MirrorAxis::X) }, &mut clip, None).unwrap();
        let mut left: Vec<i32> = d.level().coords.iter().map(|c| c.x).collect();
        left.sort();
        assert_eq!(left, vec![3, 4], "{what}");
        assert!(what.starts_with("deleted 4 voxels"), "{what}");
        d.apply(&EditRequest::Undo, &mut clip, None).unwrap();
        assert_eq!(d.level().len(), 6, "one undo step brings back both sides");
        // A box across the middle is its own image: deleted once.
        let what = d.apply(&EditRequest::Delete { r#box: bx([3, 0, 0], [4, 0, 0]), mirror: Some(MirrorAxis::X) }, &mut clip, None).unwrap();
        assert!(what.starts_with("deleted 2 voxels"), "{what}");
        // Moving up on the left moves up on the right, mirrored across x.
        d.apply(&EditRequest::Undo, &mut clip, None).unwrap();
        d.apply(&EditRequest::Move { r#box: bx([1, 0, 0], [1, 0, 0]), by: [-1, 1, 0], mirror: Some(MirrorAxis::X) }, &mut clip, None).unwrap();
        let mut moved: Vec<[i32; 3]> = d.level().coords.iter().map(|c| c.to_array()).filter(|c| c[1] == 1).collect();
        moved.sort();
        assert_eq!(moved, vec![[0, 1, 0], [7, 1, 0]]);
    }

    #[test]
    fn paste_from_the_exemplar_takes_its_voxels() {
        let mut d = Draft::new("d1".into(), "s1".into(), None, Level { index: 1, resolution: 8, ..Default::default() });
        let mut clip = None;
        let ex = slab();
        d.apply(&EditRequest::CopyExemplar { r#box: bx([0, 0, 0], [1, 7, 1]) }, &mut clip, Some(&ex)).unwrap();
        d.apply(&EditRequest::Paste { to: [4, 0, 4] }, &mut clip, Some(&ex)).unwrap();
        let mut got: Vec<[i32; 3]> = d.level().coords.iter().map(|c| c.to_array()).collect();
        got.sort();
        assert_eq!(got, vec![[4, 2, 4], [4, 2, 5], [5, 2, 4], [5, 2, 5]]);
    }
}
