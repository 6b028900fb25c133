//! The judge: whether a shape is whole and new against its exemplar. It
//! reads a shape's structure level (64^3) and the level after it, measures
//! one thing per criterion file, and gives one [`Verdict`] with its flags,
//! by the thresholds of one table ([`thresholds::THRESHOLDS`]). Sampling
//! (the level-0 gate, the choice among attempts), `eval` and the studio all
//! judge through [`Verdict::judged`]; nothing else decides what "whole" or
//! "a near copy" is.
//!
//! Above `level` and `grid` (plain data), below `learn`, `eval`, `studio`.
//!
//! | file | criterion | flag |
//! |---|---|---|
//! | `measure.rs` | a shape's structure: surface, extent, pieces, and each measure below | `fragment`, `shrunken`, `pieces` |
//! | `free_edge.rs` | free edges (wall ends, hole rims) | `torn` |
//! | `enclosure.rs` | how much of the view from inside the surface fills | `open` |
//! | `seen_through.rs` | the inside seen from 24 views | `seen_through` |
//! | `thin.rs` | thin parts (ears, walls, spires) | `thin_part_lost` |
//! | `sheet.rs` | holes through a height field | `holed` |
//! | `unlike.rs` (with `patches.rs`) | surface like no part of the exemplar | `out_of_style`, `fine_out_of_style` |
//! | `steps.rs` | steps across a top the exemplar has smooth | `stepped` |
//! | `copy.rs`, `outline.rs` | the exemplar's surface or outline again | `near_copy` |
//! | `figure.rs` | whether the exemplar is a figure (may be bent) | - |
//! | `verdict.rs` | the criteria together: [`Verdict`], [`Flag`], [`Against`] | - |
//! | `thresholds.rs` | every threshold, its unit and its measurement | - |

pub mod copy;
pub mod enclosure;
pub mod figure;
pub mod free_edge;
pub mod levels;
pub mod measure;
pub mod outline;
pub mod patches;
pub mod seen_through;
pub mod sheet;
pub mod steps;
pub mod thin;
pub mod thresholds;
pub mod unlike;
pub mod verdict;

#[cfg(test)]
mod tests;

pub use levels::{fine_level, structure_level, STRUCTURE_RESOLUTION};
pub use measure::Structure;
pub use thresholds::{Thresholds, THRESHOLDS};
pub use verdict::{Against, Flag, Verdict};
pub use copy::{largest_change, tolerant_fscore, Matching};
pub use thin::{thin_count, thin_voxels};
pub use unlike::{unlike_share, unlike_voxels};
