//! Where a pass starts, besides the network's own level 0 in the exemplar's
//! box: the exemplar bent (a figure with nothing repeated in it,
//! `sample.proposers.bend_voxels`), or a resized box (`--extent`, or
//! `sample.proposers.resize_max` where the networks only copy) judged against the
//! exemplar at that extent ([`AtExtent`]).

use glam::IVec3;

use crate::config::BendExemplars;
use crate::judge::{thin_count, Structure, Thresholds};
use crate::error::{Error, Result};
use crate::level::Level;
use crate::learn::sparse::SparseTensor;
use crate::judge::figure::FigureReading;
use crate::judge::THRESHOLDS;
use crate::level::resize::Extent;
use crate::level::warp::Bend;

use super::options::SampleOptions;
use crate::level::resize::level0_box;

/// Whether sampling bends a pass whose level-0 candidates are none new
/// enough (`sample.proposers.bend_voxels`, `sample.proposers.bend_exemplars`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Bending {
    /// No bends asked for, or none possible (not the novel pick of several
    /// candidates over the exemplar's box, or continuing from a level).
    Never,
    /// Bends asked for `figures`, and the exemplar is none.
    NotAFigure,
    /// The exemplar bent by up to this many level-0 voxels.
    Bends(f64),
}

impl Bending {
    pub(super) fn of(opts: &SampleOptions, exemplar_levels: &[Level], continuing: bool) -> Bending {
        if opts.bend_voxels == 0.0 || !could_bend(opts) || continuing {
            return Bending::Never;
        }
        if opts.bend_exemplars == BendExemplars::All {
            return Bending::Bends(opts.bend_voxels);
        }
        let reading = FigureReading::of_exemplar(exemplar_levels);
        let (bending, why) = match reading {
            None => (Bending::NotAFigure, format!("the exemplar has no level of {}^3 to 64^3 to read whether it is a figure: it is not bent", THRESHOLDS.min_reading_resolution)),
            Some(r) => {
                let figures = format!(
                    "normal spread {:.2}, a figure's at least {}; upright share {:.2}, a figure's at most {}",
                    r.normal_spread, THRESHOLDS.min_normal_spread, r.upright_share, THRESHOLDS.max_upright_share
                );
                if r.is_figure() {
                    (Bending::Bends(opts.bend_voxels), format!("the exemplar is a figure ({figures}): a pass with nothing new at level 0 is the exemplar bent"))
                } else {
                    (Bending::NotAFigure, format!("the exemplar has flat faces or upright walls ({figures}): it is not bent"))
                }
            }
        };
        // Said once per process: the pipeline samples one variant per call.
        static SAID: std::sync::Once = std::sync::Once::new();
        SAID.call_once(|| log::info!("{why}"));
        bending
    }
}

/// The exemplar as sampling judges a pass at one extent
/// ([`crate::level::resize`]): its level-0 box; its level 0 and structure
/// (the level-0 gate); its level 1's thin parts (the level-0 candidates'
/// thin parts are counted a level finer, see [`AtExtent::thin_ratio`]); its
/// structure level and structure (the attempts). The exemplar's own at its
/// own extent, else stretched to the extent.
pub(super) struct AtExtent {
    pub(super) extent: Extent,
    pub(super) box0: (IVec3, IVec3),
    pub(super) level0: Level,
    pub(super) structure0: Structure,
    /// Level 1 and its thin-part voxel count, where it has thin parts
    /// enough to lose ([`Thresholds::min_exemplar_thin_share`]).
    pub(super) thin1: Option<(Level, usize)>,
    pub(super) reference: Option<(Level, Structure)>,
}

impl AtExtent {
    /// `sheet_axis0`: whether level 0 is a sheet (the `holed` term of the
    /// level-0 gate) is the structure level's decision, not 16^3's own. A
    /// continuation from a level has no level-0 gate nor attempts: level 1
    /// and the structure level are not measured then (a tenth of a second
    /// of the studio's regeneration).
    pub(super) fn of(levels: &[Level], extent: Extent, sheet_axis0: Option<usize>, continuing: bool) -> Result<AtExtent> {
        let level0 = levels.first().ok_or_else(|| Error::Invalid("no exemplar levels".into()))?;
        let box0 = level0_box(level0, extent.extent)?;
        let level0 = extent.of(levels, 0)?;
        let mut structure0 = Structure::of(&level0);
        if !extent.is_same() {
            // The level-0 gate judges as the structure level does.
            structure0 = Structure::at_extent(&structure0, &Structure::of(&levels[0]));
        }
        structure0.sheet_axis = sheet_axis0;
        if continuing {
            return Ok(AtExtent { extent, box0, level0, structure0, thin1: None, reference: None });
        }
        // Also when sampling stops at level 0 (see `Models::upsamplers`).
        let thin1 = match levels.get(1) {
            Some(_) => {
                let level = extent.of(levels, 1)?;
                let thin = thin_count(&level);
                let surface = level.mask.iter().filter(|&&m| m > 0.0).count();
                let enough = thin > 0 && thin as f64 >= Thresholds::default().min_exemplar_thin_share * surface as f64;
                enough.then_some((level, thin))
            }
            None => None,
        };
        let reference = match crate::judge::structure_level(levels) {
            Some(l) => {
                let level = extent.of(levels, l.index)?;
                let structure = Structure::of(&level);
                Some((level, structure))
            }
            None => None,
        };
        Ok(AtExtent { extent, box0, level0, structure0, thin1, reference })
    }

    /// The thin-part check of a level-0 candidate one level finer: its
    /// thin-part voxels taken to level 1 over the exemplar's. At 16^3 a
    /// bunny's body is itself "thin" (3 voxels deep; 83 of its 299 voxels),
    /// so an ear gone is 10% of the thin voxels, as much as a ruined wall
    /// top of the demo tower, and the rim of the hole it leaves adds thin
    /// voxels back (thin ratio 0.81-0.96 with the ear gone). At 32^3 the
    /// body is not thin and the ear is: ratio 0.58-0.72 with the ear gone,
    /// 0.9 with it, 0.83 or more for the demo's and the tower's ruins. The
    /// candidate is taken there by the level-1 upsampler alone (no
    /// diffusion steps: a fraction of a second).
    pub(super) fn thin_ratio(&self, level1: &Level) -> Option<f64> {
        let (ex, thin) = self.thin1.as_ref()?;
        debug_assert_eq!(level1.resolution, ex.resolution);
        Some(thin_count(level1) as f64 / *thin as f64)
    }

    /// The exemplar's structure level at this extent and its structure.
    pub(super) fn reference(&self) -> Option<(&Level, &Structure)> {
        self.reference.as_ref().map(|(l, s)| (l, s))
    }
}

/// Whether sampling with `opts` could bend a pass, given `bend_voxels`: the
/// novel pick of more than one level-0 candidate, in the exemplar's box.
pub(super) fn could_bend(opts: &SampleOptions) -> bool {
    opts.level0_pick == crate::config::Level0Pick::Novel && opts.level0_candidates > 1 && opts.extent == [1.0; 3]
}

/// Resized passes that may all fail (none whole at the structure level)
/// before sampling stops resizing for the networks that made them: a
/// church's networks, trained on one nave and one steeple, broke every
/// longer box, where a house's and a temple's filled most.
pub const RESIZE_TRIES: usize = 6;

/// Level-0 candidates drawn at most in a resized box (the first like enough
/// to the exemplar at that extent is kept, else the likest that passes): on
/// the house and the temple one of the first 12 passed every time one did.
pub const RESIZED_CANDIDATES: usize = 12;

/// How a pass starts: a level-0 shape drawn by the network (its pruned
/// tensor and level), the exemplar bent, or a box resized.
pub(super) enum Start {
    Drawn(SparseTensor, Level),
    Bent(Bend),
    /// The networks offer only copies: the pass starts again in a resized box.
    Resized(Extent),
}

