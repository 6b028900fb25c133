//! The one verdict on a shape ([`Verdict`]): its structure level measured
//! ([`super::measure::Structure`]) and compared with the exemplar's, one
//! criterion after another, against the thresholds of
//! [`super::thresholds`]. Sampling's attempts, `eval` and the studio all call
//! [`Verdict::judged`], so a shape is whole, broken or a copy the same way
//! everywhere.

use super::copy::Matching;
use super::levels::STRUCTURE_RESOLUTION;
use super::measure::Structure;
use super::thresholds::Thresholds;
use super::unlike::unlike_share;
use crate::level::Level;

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
pub struct Verdict {
    /// Resolution of the level compared.
    pub resolution: u32,
    /// Surface voxels, variant / exemplar.
    pub mass_ratio: f64,
    /// Bounding box, variant / exemplar, along the axis where it is
    /// smallest, the variant's side moved one voxel toward the exemplar's
    /// (`extent_tolerance_voxels`).
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
    #[serde(default = "one")]
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
    /// ([`fine_level`], 128^3; [`Verdict::with_fine`]); not written
    /// where that level was not compared.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fine_unlike_share: Option<f64>,
    /// Boundary F-score to the exemplar's voxels with a 1-voxel tolerance
    /// (1: the exemplar's surface, voxel for voxel).
    pub copy_fscore: f64,
    /// Boundary F-score (1-voxel tolerance) of the variant's level 0 to the
    /// exemplar's ([`Verdict::with_coarse`]); not written where not
    /// compared (a bent or resized variant, whose level 0 is new by its
    /// pose or size).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_copy_fscore: Option<f64>,
    /// The worst view's share of the outline that differs from the
    /// exemplar's ([`Verdict::with_outline`]); not written where not
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
    /// ([`Verdict::new`]).
    pub score: f64,
    pub flags: Vec<Flag>,
}

impl Verdict {
    /// `shape` (structure `s` of level `shape_level`) against the exemplar
    /// (`e` of `exemplar_level`, the same resolution). The score's terms,
    /// each 1 at the exemplar: mass min(r, 1/r); extent min over axes of
    /// min(r, 1/r); pieces (largest share of the variant / the exemplar's,
    /// at most 1); free boundary (the torn limit
    /// [`Thresholds::free_boundary_limit`] / the variant's share, at most
    /// 1: below 1 exactly when flagged torn); enclosure (variant / exemplar, at most 1);
    /// seen through (the limit / the excess, at most 1: below 1 exactly when flagged);
    /// holes (the limit / the hole columns, at most 1: below 1 exactly when flagged);
    /// out of style (the limit / the unlike share, at most 1: below 1 exactly when flagged).
    pub fn new(shape_level: &Level, s: &Structure, exemplar_level: &Level, e: &Structure, p: &Thresholds) -> Self {
        Self::with_pose(shape_level, s, exemplar_level, e, (exemplar_level, e), p)
    }

    /// [`Verdict::new`] with the terms that depend on how the
    /// surface is turned, the inside seen from fixed views and the
    /// out-of-style patches, measured against `pose` (a level of the
    /// exemplar's resolution and its structure) instead of the exemplar.
    fn with_pose(
        shape_level: &Level,
        s: &Structure,
        exemplar_level: &Level,
        e: &Structure,
        pose: (&Level, &Structure),
        p: &Thresholds,
    ) -> Self {
        let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
        let sym = |r: f64| if r > 0.0 { r.min(1.0 / r) } else { 0.0 };
        let mass_ratio = ratio(s.voxels as f64, e.voxels as f64);
        // A side one voxel shorter or longer is the same size: a thin relief
        // of 5 voxels against 6 is a rounding of the surface, not a part
        // lost (`extent_tolerance_voxels`).
        let axis_ratios: Vec<f64> = (0..3)
            .map(|a| {
                let (v, x) = (s.extent[a] as f64, e.extent[a] as f64);
                ratio(v + (x - v).clamp(-p.extent_tolerance_voxels, p.extent_tolerance_voxels), x)
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
        Verdict {
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
    /// and, above [`Thresholds::max_fine_unlike_share`], flags
    /// [`Flag::FineOutOfStyle`]. Levels of other resolutions change nothing.
    pub fn with_fine(mut self, shape_fine: &Level, reference_fine: &Level, p: &Thresholds) -> Self {
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
    /// [`Thresholds::coarse_copy_fscore`] the shape is a near copy: its
    /// arrangement is the exemplar's, whatever the finer levels changed.
    /// Levels of different resolutions change nothing.
    pub fn with_coarse(mut self, shape0: &Level, exemplar0: &Level, p: &Thresholds) -> Self {
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
    /// [`Thresholds::max_copy_outline_difference`] the shape is a near
    /// copy: it looks like the exemplar from everywhere.
    pub fn with_outline(mut self, shape: &Level, exemplar: &Level, p: &Thresholds) -> Self {
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
        p: &Thresholds,
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
    /// near copy ([`Verdict::with_coarse`]).
    Exemplar { level0: Option<(&'a Level, &'a Level)> },
    /// The exemplar bent as the shape's start was (its level bent, with its
    /// structure): [`Verdict::against_bend`].
    Bent(&'a Level, &'a Structure),
    /// The exemplar at the extent of the shape's resized box (its level
    /// stretched, with its structure): [`Verdict::at_extent`].
    AtExtent(&'a Level, &'a Structure),
}

impl Verdict {
    /// The one verdict sampling, eval and the studio give a shape: its
    /// structure level `shape` against `exemplar` (the exemplar's same level
    /// and structure) made as the shape's start was (`against`), then, where
    /// given, its fine level against the exemplar's (`fine`: the shape's, the
    /// reference's, bent likewise; [`Verdict::with_fine`]).
    pub fn judged(
        shape: &Level,
        exemplar: (&Level, &Structure),
        against: Against,
        fine: Option<(&Level, &Level)>,
        p: &Thresholds,
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

impl Verdict {
    /// The scores of a shape sampled in a resized box
    /// ([`crate::level::resize`]): against the exemplar at that extent
    /// (`at_extent`: its level stretched, and that level's structure) for
    /// size, surface, pieces, openings, the inside seen and copies; its
    /// out-of-style patches against the exemplar's own level (`style`: a
    /// stretched wall's stones are not the exemplar's style, a longer wall
    /// of the same stones is). Its thin parts against the exemplar's own
    /// count ([`Structure::at_extent`]): a longer hall the networks made
    /// whole read 0.55 against the stretched count, 0.92 against its own.
    pub fn at_extent(
        shape_level: &Level,
        s: &Structure,
        at_extent: (&Level, &Structure),
        style: (&Level, &Structure),
        p: &Thresholds,
    ) -> Self {
        let reference = Structure::at_extent(at_extent.1, style.1);
        Self::with_pose(shape_level, s, at_extent.0, &reference, (style.0, at_extent.1), p)
    }
}

/// A ratio's serde default where the field was not written: 1, the exemplar's.
fn one() -> f64 {
    1.0
}
