//! The level filters: what every level of a variant gets once it is made
//! (by a network, or bent) and before the next level is made from it,
//! specks removed and sheets mended, as the exemplar's level of its index
//! says ([`crate::level::repair`]: the detail transfer applies the same).

use tch::Device;

use crate::error::Result;
use crate::learn::sparse::SparseTensor;
use crate::level::repair::LevelRepair;
use crate::level::{Frame, Level};

/// `level` (and its pruned tensor `pruned`) repaired as `repairs` says for
/// its index; else as it is. A repaired level goes back through the tensor,
/// so its rows are in the grid's order as ever.
pub(super) fn repaired(repairs: &[LevelRepair], device: Device, frame: Frame, pruned: SparseTensor, level: Level) -> Result<(SparseTensor, Level)> {
    let Some(repair) = repairs.get(level.index) else { return Ok((pruned, level)) };
    let Some(r) = repair.apply(&level) else { return Ok((pruned, level)) };
    log::debug!("level {}: {} speck voxels removed, {} voxels mend the sheet", level.index, r.removed(level.len()), r.added);
    let pruned = SparseTensor::from_level(&r.level, device)?.prune_by_mask()?;
    let level = pruned.to_level(level.index, frame)?;
    Ok((pruned, level))
}
