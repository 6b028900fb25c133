//! Which of a shape's levels the judge reads: the structure level (the
//! finest of at most [`STRUCTURE_RESOLUTION`]^3) and the level after it.

use super::thresholds::THRESHOLDS;
use crate::level::Level;

/// [`super::thresholds::Thresholds::structure_resolution`], as a constant for
/// the places that size by it.
pub const STRUCTURE_RESOLUTION: u32 = THRESHOLDS.structure_resolution;


/// The finest of `levels` (coarsest first) of at most [`STRUCTURE_RESOLUTION`]^3.
pub fn structure_level(levels: &[Level]) -> Option<&Level> {
    levels.iter().filter(|l| l.resolution <= STRUCTURE_RESOLUTION).last()
}

/// The level after the structure level (128^3 in every profile): the first
/// made on a coarse shape that is already decided (by the detail transfer
/// in the `cpu` profile, by a network where one is trained), where ragged
/// sheets and flakes made on an unusual coarse shape show as surface like
/// no part of the exemplar's same level ([`super::verdict::Flag::FineOutOfStyle`]). None
/// where the levels stop at the structure level.
pub fn fine_level(levels: &[Level]) -> Option<&Level> {
    levels.iter().find(|l| l.resolution > STRUCTURE_RESOLUTION)
}
