//! One evaluation of a set of variants against the exemplar: [`evaluate`]
//! refuses degenerate shapes ([`check_shape`]), then gathers every measure
//! per variant ([`VariantScores`]), their mean, the diversity and the set's
//! coverage into an [`EvalReport`], which also prints the terminal table.

use glam::Vec3;

use super::colour::{self, ColourParams, ColourPatches, ColourScores};
use super::detail::{DetailScores, Variation};
use crate::judge::patches::{best_patch_matches, ExemplarPatches, LpParams, LpScores, PatchMatches};
use super::occupancy::{diversity, same_lattice, Occupancy};
use super::point_distances::chamfer;
use crate::judge::{Against, Flag, Structure, Thresholds, Verdict};
use crate::level::Level;

/// Scores of one variant (or one rung of the degradation ladder) against the
/// exemplar. "Precision" compares the shape's patches with the exemplar's
/// (does everything here look like the exemplar?), "coverage" the exemplar's
/// with the shape's (is everything of the exemplar here?).
#[derive(serde::Serialize, serde::Deserialize, Clone, Debug, PartialEq)]
pub struct VariantScores {
    pub name: String,
    /// The literature's LP-IoU (precision, 11^3 patches on the evaluation
    /// lattice): mean best patch IoU, in [0, 1].
    pub lp_iou: f64,
    /// Fraction of patches whose best IoU > 0.95.
    pub lp_iou_above_95: f64,
    /// The literature's LP-F: mean best boundary F-score (1-voxel tolerance).
    pub lp_fscore: f64,
    /// Fraction of patches whose best F-score > 0.95.
    pub lp_fscore_above_95: f64,
    /// Coverage: the exemplar's 11^3 patches matched in this shape.
    pub coverage: LpScores,
    /// Precision with 11^3 patches on the half-resolution lattice (each
    /// spans 22^3 voxels of the evaluation lattice).
    pub precision_22: LpScores,
    /// Coverage on the half-resolution lattice.
    pub coverage_22: LpScores,
    /// Surface detail of the finest level against the exemplar's.
    pub detail: DetailScores,
    /// Colour patches of the finest level against the exemplar's; None (not
    /// applicable) when the exemplar has one colour: nothing to compare.
    pub colour: Option<ColourScores>,
    /// The shape as a whole at the structure level (64^3) against the
    /// exemplar's, with its flags; None when not measured.
    #[serde(default)]
    pub structure: Option<Verdict>,
    /// Whether the variant is the exemplar bent, so the views of its inside
    /// and its out-of-style patches are judged against the exemplar bent the
    /// same way ([`Verdict::against_bend`]). Not written when false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub bent: bool,
    /// The extent of its level-0 box against the exemplar's, where it is not
    /// the exemplar's: its structure is judged against the exemplar at that
    /// extent ([`Verdict::at_extent`]). Not written when none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extent: Option<[f32; 3]>,
    /// Chamfer distance of the level-0 point set to the exemplar's, normalised
    /// units (bounding-box diagonal 2); None when not measured.
    pub coarse_chamfer: Option<f64>,
}

/// Parameters of one evaluation, recorded with its scores.
#[derive(serde::Serialize, Clone, Debug, PartialEq, Default)]
pub struct EvalParams {
    pub lp: LpParams,
    pub colour: ColourParams,
    pub structure: Thresholds,
}

/// Below this RMS colour spread (RGB units) an exemplar has one colour, and
/// the colour measures are not applicable.
pub const ONE_COLOUR_SPREAD: f64 = 0.02;

/// The structural flags of a set, for reading diversity per variant.
#[derive(serde::Serialize, Clone, Debug, PartialEq, Default)]
pub struct StructureSummary {
    /// Resolution of the level the structure was measured at.
    pub resolution: u32,
    /// Variants with no flag that says broken (every flag but near-copy:
    /// fragment, shrunken, pieces, torn, open; [`crate::judge::Flag::broken`]).
    pub whole: usize,
    pub scored: usize,
    /// Variants flagged as near copies of the exemplar.
    pub near_copies: usize,
    /// Each flagged variant with its flags.
    pub flagged: Vec<(String, Vec<Flag>)>,
}

/// Coverage of the exemplar by the variants as a set: an exemplar patch
/// counts as found when any variant holds it.
#[derive(serde::Serialize, serde::Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SetCoverage {
    pub patch_11: LpScores,
    pub patch_22: LpScores,
}

/// All scores of one evaluation.
#[derive(serde::Serialize, Clone, Debug)]
pub struct EvalReport {
    /// Every parameter the scores depend on.
    pub parameters: EvalParams,
    pub variants: Vec<VariantScores>,
    /// Mean of every figure over the variants (name "mean"; the Chamfer mean
    /// is over the variants that have one).
    pub mean: VariantScores,
    /// Mean pairwise 1 - IoU over the variants' occupancies (higher = more
    /// diverse).
    pub diversity: f64,
    /// None with fewer than two variants (nothing a set adds).
    pub set_coverage: Option<SetCoverage>,
    /// None when no structure level was given.
    pub structure: Option<StructureSummary>,
}

/// One shape to evaluate: its occupancy on the evaluation lattice and on the
/// half-resolution lattice, its finest level, and optionally its level-0
/// points in normalised units.
pub struct ShapeInput<'a> {
    pub name: String,
    pub occupancy: &'a Occupancy,
    pub occupancy_22: &'a Occupancy,
    pub finest: &'a Level,
    pub coarse_points: Option<&'a [Vec3]>,
    /// The level the structure is measured at (64^3, or the finest level
    /// below it), if any.
    pub structure_level: Option<&'a Level>,
    /// For a variant that is the exemplar bent: the exemplar's structure
    /// level bent the same way, which the views of its inside and its
    /// out-of-style patches are judged against
    /// ([`Verdict::against_bend`]).
    pub bent_reference: Option<&'a Level>,
    /// For a variant sampled in a resized box: its extent and the exemplar's
    /// structure level at that extent ([`crate::level::resize::stretched`]).
    pub at_extent: Option<([f32; 3], &'a Level)>,
    /// Its level 0 and the exemplar's, where it was sampled in the
    /// exemplar's box and not bent ([`Verdict::with_coarse`]).
    pub level0: Option<(&'a Level, &'a Level)>,
    /// The level after the structure level (128^3) and the exemplar's same
    /// level to compare it with (bent where the variant was), if both exist
    /// ([`Verdict::with_fine`]).
    pub fine_level: Option<(&'a Level, &'a Level)>,
}

/// What makes a voxelisation unusable for comparison, with the shape's name.
#[derive(thiserror::Error, Debug, Clone, PartialEq)]
pub enum DegenerateShape {
    #[error("{0}: nothing to compare: its voxelisation has no surface voxels (empty shape, or every point outside the evaluation lattice)")]
    NoSurface(String),
    #[error("{0}: its voxelisation fills {1:.0}% of the evaluation lattice: nothing is left to compare (a solid voxelisation of a surface that is not closed?)")]
    Filled(String, f64),
    #[error("{0}: the finest level has no active voxels")]
    EmptyLevel(String),
}

crate::stage_error!(DegenerateShape);

/// Above this fraction of the lattice, an occupancy is "everything".
pub const FILLED_FRACTION: f64 = 0.9;

/// The degenerate cases of item 3: a voxelisation that leaves nothing, or
/// everything, to compare is an error, never a perfect score.
pub fn check_shape(s: &ShapeInput) -> Result<(), DegenerateShape> {
    if !s.finest.mask.iter().any(|&m| m > 0.0) {
        return Err(DegenerateShape::EmptyLevel(s.name.clone()));
    }
    for occ in [s.occupancy, s.occupancy_22] {
        if occ.surface().count() == 0 {
            return Err(DegenerateShape::NoSurface(s.name.clone()));
        }
        let f = occ.count() as f64 / occ.dims.iter().map(|&d| d as f64).product::<f64>();
        if f > FILLED_FRACTION {
            return Err(DegenerateShape::Filled(s.name.clone(), 100.0 * f));
        }
    }
    Ok(())
}

/// Everything of docs/method.md section 7 and the two-sided measures for a set of
/// variants: precision and coverage of 11^3 patches on two lattices (the
/// exemplar's dictionaries built once, one dictionary per variant for
/// coverage), surface detail, colour patches, coarse Chamfer where both point
/// sets are given, diversity and the set's coverage. Fails on a degenerate
/// shape ([`check_shape`]).
pub fn evaluate(exemplar: &ShapeInput, variants: &[ShapeInput], params: &EvalParams) -> Result<EvalReport, DegenerateShape> {
    check_shape(exemplar)?;
    for v in variants {
        check_shape(v)?;
    }
    let lp = &params.lp;
    let (dict, dict_22) = rayon::join(
        || ExemplarPatches::new(exemplar.occupancy, lp.exemplar_stride),
        || ExemplarPatches::new(exemplar.occupancy_22, lp.exemplar_stride),
    );
    let ex_detail = Variation::of(exemplar.finest);
    let ex_colour = ColourPatches::of(exemplar.finest);
    let colourful = colour::spread(&exemplar.finest.colours) > ONE_COLOUR_SPREAD;
    let ex_structure = exemplar.structure_level.map(|l| (l, Structure::of(l)));
    let mut cover_sets: Option<(PatchMatches, PatchMatches)> = None;
    let mut scores = Vec::with_capacity(variants.len());
    for v in variants {
        same_lattice(v.occupancy, exemplar.occupancy);
        same_lattice(v.occupancy_22, exemplar.occupancy_22);
        let precision = best_patch_matches(v.occupancy, &dict, lp);
        let precision_22 = best_patch_matches(v.occupancy_22, &dict_22, lp);
        let (cover, cover_22) = rayon::join(
            || best_patch_matches(exemplar.occupancy, &ExemplarPatches::new(v.occupancy, lp.exemplar_stride), lp),
            || best_patch_matches(exemplar.occupancy_22, &ExemplarPatches::new(v.occupancy_22, lp.exemplar_stride), lp),
        );
        let p = precision.summary(lp.threshold);
        let cd = match (exemplar.coarse_points, v.coarse_points) {
            (Some(e), Some(c)) => Some(chamfer(c, e) as f64),
            _ => None,
        };
        scores.push(VariantScores {
            name: v.name.clone(),
            lp_iou: p.lp_iou,
            lp_iou_above_95: p.lp_iou_above,
            lp_fscore: p.lp_fscore,
            lp_fscore_above_95: p.lp_fscore_above,
            coverage: cover.summary(lp.threshold),
            precision_22: precision_22.summary(lp.threshold),
            coverage_22: cover_22.summary(lp.threshold),
            detail: DetailScores::new(&Variation::of(v.finest), &ex_detail),
            colour: colourful.then(|| colour::colour_scores(&ColourPatches::of(v.finest), &ex_colour, &params.colour)),
            structure: match (&ex_structure, v.structure_level) {
                (Some((el, es)), Some(vl)) if vl.resolution == el.resolution => {
                    let bent = v.bent_reference.filter(|b| b.resolution == el.resolution).map(|b| (b, Structure::of(b)));
                    let at = v.at_extent.filter(|(_, a)| a.resolution == el.resolution).map(|(_, a)| (a, Structure::of(a)));
                    let against = match (&bent, &at) {
                        (Some((b, bs)), _) => Against::Bent(b, bs),
                        (None, Some((a, s))) => Against::AtExtent(a, s),
                        (None, None) => Against::Exemplar { level0: v.level0 },
                    };
                    Some(Verdict::judged(vl, (el, es), against, v.fine_level, &params.structure))
                }
                _ => None,
            },
            bent: v.bent_reference.is_some(),
            extent: v.at_extent.map(|(e, _)| e),
            coarse_chamfer: cd,
        });
        cover_sets = Some(match cover_sets {
            None => (cover, cover_22),
            Some((a, b)) => (a.max_with(&cover), b.max_with(&cover_22)),
        });
    }
    let occs: Vec<Occupancy> = variants.iter().map(|v| v.occupancy.clone()).collect();
    let set_coverage = cover_sets.filter(|_| variants.len() > 1).map(|(a, b)| SetCoverage {
        patch_11: a.summary(lp.threshold),
        patch_22: b.summary(lp.threshold),
    });
    Ok(EvalReport::new(params.clone(), scores, diversity(&occs), set_coverage))
}

impl StructureSummary {
    /// The flags of the variants that have structure scores; None if none has.
    pub fn of(variants: &[VariantScores]) -> Option<Self> {
        let scored: Vec<(&str, &Verdict)> =
            variants.iter().filter_map(|v| v.structure.as_ref().map(|s| (v.name.as_str(), s))).collect();
        let first = scored.first()?;
        Some(StructureSummary {
            resolution: first.1.resolution,
            whole: scored.iter().filter(|(_, s)| s.whole()).count(),
            scored: scored.len(),
            near_copies: scored.iter().filter(|(_, s)| s.flags.contains(&Flag::NearCopy)).count(),
            flagged: scored.iter().filter(|(_, s)| !s.flags.is_empty()).map(|(n, s)| (n.to_string(), s.flags.clone())).collect(),
        })
    }
}

/// Mean of JSON values leaf by leaf: numbers averaged (integers stay
/// integers, rounded), the first value's strings kept, nulls skipped.
fn mean_json(values: &[serde_json::Value]) -> serde_json::Value {
    use serde_json::Value;
    match values.first() {
        Some(Value::Object(first)) => Value::Object(
            first
                .keys()
                .map(|k| {
                    let children: Vec<Value> = values.iter().filter_map(|v| v.get(k).cloned()).collect();
                    (k.clone(), mean_json(&children))
                })
                .collect(),
        ),
        Some(Value::Number(_)) | Some(Value::Null) => {
            let nums: Vec<&serde_json::Number> = values.iter().filter_map(|v| v.as_number()).collect();
            if nums.is_empty() {
                return Value::Null;
            }
            let mean = nums.iter().filter_map(|n| n.as_f64()).sum::<f64>() / nums.len() as f64;
            if nums.iter().all(|n| n.is_u64()) {
                Value::from(mean.round() as u64)
            } else {
                serde_json::Number::from_f64(mean).map_or(Value::Null, Value::Number)
            }
        }
        Some(other) => other.clone(),
        None => Value::Null,
    }
}

impl EvalReport {
    pub fn new(
        parameters: EvalParams,
        variants: Vec<VariantScores>,
        diversity: f64,
        set_coverage: Option<SetCoverage>,
    ) -> Self {
        let rows: Vec<serde_json::Value> =
            variants.iter().map(|v| serde_json::to_value(v).expect("scores serialise")).collect();
        let mut mean: VariantScores = match serde_json::from_value(mean_json(&rows)) {
            Ok(m) if !variants.is_empty() => m,
            Ok(_) => VariantScores::zero(),
            Err(e) => {
                log::warn!("eval: the mean row cannot be formed ({e}): a figure is not finite for every variant");
                VariantScores::zero()
            }
        };
        mean.name = "mean".into();
        // Flags and the bent mark are per variant: the mean has none.
        mean.bent = false;
        mean.extent = None;
        if let Some(s) = mean.structure.as_mut() {
            s.flags.clear();
        }
        let structure = StructureSummary::of(&variants);
        EvalReport { parameters, variants, mean, diversity, set_coverage, structure }
    }

    /// A plain-text table for the terminal: the headline figures; the JSON
    /// has every figure.
    pub fn table(&self) -> String {
        let width = self.variants.iter().map(|v| v.name.chars().count()).max().unwrap_or(0).max(7);
        let mut s = format!(
            "{:<width$}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>9}  {:>6}  {}\n",
            "", "LP-IoU", "LP-F", "cover", "cover", "detail", "sharp", "colour", "colour", "chamfer0", "struct", "flags"
        );
        s += &format!(
            "{:<width$}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>9}  {:>6}\n",
            "variant", "", ">0.95", "IoU", "IoU 22", "W1 deg", "ratio", "F", "cover", "", "score"
        );
        let row = |v: &VariantScores| {
            let cd = v.coarse_chamfer.map_or("-".to_string(), |c| format!("{c:.4}"));
            let colour = |f: fn(&ColourScores) -> f64| v.colour.as_ref().map_or("n/a".to_string(), |c| format!("{:.3}", f(c)));
            let (score, mut flags) = v.structure.as_ref().map_or(("-".to_string(), String::new()), |s| {
                (format!("{:.3}", s.score), s.flags.iter().map(|f| f.name()).collect::<Vec<_>>().join(","))
            });
            if v.bent {
                flags = if flags.is_empty() { "(bent)".into() } else { format!("{flags} (bent)") };
            }
            if let Some(e) = v.extent {
                let e = format!("(extent {})", crate::level::resize::Extent { extent: e });
                flags = if flags.is_empty() { e } else { format!("{flags} {e}") };
            }
            format!(
                "{:<width$}  {:>7.3}  {:>7.3}  {:>7.3}  {:>7.3}  {:>7.2}  {:>7.3}  {:>7}  {:>7}  {:>9}  {:>6}  {}\n",
                v.name,
                v.lp_iou,
                v.lp_fscore_above_95,
                v.coverage.lp_iou,
                v.coverage_22.lp_iou,
                v.detail.w1_deg,
                v.detail.rms_ratio,
                colour(|c| c.fscore),
                colour(|c| c.coverage),
                cd,
                score,
                flags
            )
            .trim_end()
            .to_string()
                + "\n"
        };
        for v in &self.variants {
            s += &row(v);
        }
        s += &"-".repeat(width + 91);
        s += "\n";
        s += &row(&self.mean);
        let n = self.variants.len();
        s += &format!("diversity (mean 1-IoU over {} pairs): {:.4}\n", n * n.saturating_sub(1) / 2, self.diversity);
        if let Some(c) = &self.set_coverage {
            s += &format!(
                "exemplar covered by the set: IoU {:.3} (22^3: {:.3}), F > 0.95 {:.3}\n",
                c.patch_11.lp_iou, c.patch_22.lp_iou, c.patch_11.lp_fscore_above
            );
        }
        if let Some(st) = &self.structure {
            s += &format!(
                "structure at {r}^3: {} of {} whole, {} near copies of the exemplar\n",
                st.whole,
                st.scored,
                st.near_copies,
                r = st.resolution
            );
            let resized = self.variants.iter().filter(|v| v.extent.is_some()).count();
            if resized > 0 {
                s += &format!("{resized} of {} sampled in a resized box (extent), as the networks drew only copies in the exemplar's box\n", st.scored);
            }
            if st.near_copies * 3 >= st.scored.max(1) {
                s += &format!(
                    "{} of {} are near copies: the networks draw again what the exemplar has only once (a single building). \
                     Try --set sample.proposers.resize_max=1.5 (variants in longer boxes), --extent, or an exemplar with its parts repeated\n",
                    st.near_copies, st.scored
                );
            }
        }
        s += "LP: the variant's 11^3 patches best-matched in the exemplar; cover: the exemplar's matched in the variant\n";
        s += "(22: on the half-resolution lattice); detail: neighbour-normal angles vs the exemplar's (W1, RMS ratio);\n";
        s += "colour: colour patches matched both ways (F-score, coverage; n/a: a one-colour exemplar); chamfer0: level-0 points,\n";
        s += "normalised units; struct: the shape as a whole vs the exemplar at the structure level (1 = its structure),\n";
        s += "flags: fragment, shrunken, pieces, torn, open, seen_through, thin_part_lost, holed, out_of_style,\n";
        s += "fine_out_of_style (the out-of-style share on the level after, 128^3), stepped (not whole), near_copy\n";
        if self.variants.iter().any(|v| v.bent) {
            s += "(bent): the exemplar bent; seen_through and the out-of-style flags are judged against the exemplar bent the same way\n";
        }
        if self.variants.iter().any(|v| v.extent.is_some()) {
            s += "(extent): sampled in a box resized by these factors; judged against the exemplar at that extent\n";
        }
        s
    }
}

impl VariantScores {
    fn zero() -> Self {
        let lp = LpScores { lp_iou: 0.0, lp_iou_above: 0.0, lp_fscore: 0.0, lp_fscore_above: 0.0, patches: 0 };
        VariantScores {
            name: String::new(),
            lp_iou: 0.0,
            lp_iou_above_95: 0.0,
            lp_fscore: 0.0,
            lp_fscore_above_95: 0.0,
            coverage: lp,
            precision_22: lp,
            coverage_22: lp,
            detail: DetailScores { w1_deg: 0.0, rms_ratio: 0.0, mean_deg: 0.0, rms_deg: 0.0, sharp_fraction: 0.0 },
            colour: None,
            structure: None,
            bent: false,
            extent: None,
            coarse_chamfer: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::occupancy::last_word_mask;
    use crate::eval::metrics::test_shapes::{smooth_shape, unit_grid};

    fn scores(name: &str, lp_iou: f64, chamfer: Option<f64>) -> VariantScores {
        VariantScores { name: name.into(), lp_iou, coarse_chamfer: chamfer, ..VariantScores::zero() }
    }

    #[test]
    fn report_table_and_means() {
        let mut a = scores("a", 0.9, Some(0.01));
        a.coverage.patches = 1000;
        let mut b = scores("variant_b", 0.5, None);
        b.coverage.patches = 999;
        let r = EvalReport::new(EvalParams::default(), vec![a, b], 0.3, None);
        assert!(r.structure.is_none(), "no structure measured");
        assert!((r.mean.lp_iou - 0.7).abs() < 1e-12 && r.mean.coarse_chamfer == Some(0.01));
        assert_eq!(r.mean.coverage.patches, 1000, "integer figures stay integers (rounded)");
        let t = r.table();
        assert!(t.contains("variant_b") && t.contains("0.900") && t.contains("mean") && t.contains("0.3000"), "{t}");
        assert!(t.contains("over 1 pairs"));
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["parameters"]["lp"]["variant_stride"], 5, "parameters are recorded: {json}");
    }

    /// A level whose active voxels are the surface voxels of `occ` (normals +z,
    /// one colour), on a lattice that matches the level's grid.
    fn level_of(occ: &Occupancy) -> Level {
        let s = occ.surface().voxels();
        Level {
            resolution: 64,
            coords: s.iter().map(|v| glam::IVec3::new(v[0] as i32, v[1] as i32, v[2] as i32)).collect(),
            offsets: vec![Vec3::ZERO; s.len()],
            normals: vec![Vec3::Z; s.len()],
            colours: vec![Vec3::splat(0.5); s.len()],
            mask: vec![1.0; s.len()],
            ..Default::default()
        }
    }

    fn halve(occ: &Occupancy) -> Occupancy {
        let mut h = Occupancy::empty(occ.dims.map(|d| d.div_ceil(2)));
        for v in occ.voxels() {
            h.set(v[0] as i64 / 2, v[1] as i64 / 2, v[2] as i64 / 2);
        }
        h
    }

    #[test]
    fn evaluate_end_to_end_with_coverage() {
        let grid = unit_grid(64);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        let v1 = smooth_shape(&grid, Vec3::new(2.0, 0.0, 0.0) * grid.voxel);
        // Half the exemplar: its patches are all in the exemplar (precision
        // high), but half of the exemplar is missing (coverage lower).
        let mut part = Occupancy::empty(ex.dims);
        for v in ex.voxels().into_iter().filter(|v| v[0] < 32) {
            part.set(v[0] as i64, v[1] as i64, v[2] as i64);
        }
        let pts = vec![Vec3::ZERO, Vec3::X];
        let shifted = vec![Vec3::new(0.0, 0.1, 0.0), Vec3::new(1.0, 0.1, 0.0)];
        let (exh, v1h, parth) = (halve(&ex), halve(&v1), halve(&part));
        let (lex, lv1, lpart) = (level_of(&ex), level_of(&v1), level_of(&part));
        let shape = |name: &str, o, h, l, c| ShapeInput { name: name.into(), occupancy: o, occupancy_22: h, finest: l, coarse_points: c, structure_level: None, bent_reference: None, at_extent: None, level0: None, fine_level: None };
        let r = evaluate(
            &shape("exemplar", &ex, &exh, &lex, Some(&pts)),
            &[
                shape("same", &ex, &exh, &lex, Some(&pts)),
                shape("moved", &v1, &v1h, &lv1, Some(&shifted)),
                shape("part", &part, &parth, &lpart, None),
            ],
            &EvalParams::default(),
        )
        .unwrap();
        let [same, moved, part] = [&r.variants[0], &r.variants[1], &r.variants[2]];
        assert_eq!((same.lp_iou, same.coverage.lp_iou, same.coverage_22.lp_iou), (1.0, 1.0, 1.0));
        assert_eq!(same.detail.w1_deg, 0.0);
        assert_eq!(same.coarse_chamfer, Some(0.0));
        assert!((moved.coarse_chamfer.unwrap() - 0.1).abs() < 1e-6);
        assert!(part.lp_iou > 0.9, "a part of the exemplar is plausible: {part:?}");
        assert!(part.coverage.lp_iou < part.lp_iou - 0.03, "but covers less: {part:?}");
        assert!(part.coverage_22.lp_iou < part.precision_22.lp_iou - 0.03, "{part:?}");
        assert!(r.diversity > 0.0);
        let set = r.set_coverage.expect("three variants");
        assert_eq!(set.patch_11.lp_iou, 1.0, "the set holds the exemplar itself");
    }

    #[test]
    fn degenerate_voxelisations_are_errors() {
        let grid = unit_grid(16);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        let mut full = Occupancy::empty(ex.dims);
        full.bits.iter_mut().for_each(|w| *w = u64::MAX);
        let full = Occupancy { bits: full.bits.iter().map(|&w| w & last_word_mask(16)).collect(), ..full };
        let empty = Occupancy::empty(ex.dims);
        let l = level_of(&ex);
        let shape = |o| ShapeInput { name: "v".into(), occupancy: o, occupancy_22: o, finest: &l, coarse_points: None, structure_level: None, bent_reference: None, at_extent: None, level0: None, fine_level: None };
        assert!(matches!(check_shape(&shape(&empty)), Err(DegenerateShape::NoSurface(_))));
        let e = check_shape(&shape(&full)).unwrap_err();
        assert!(matches!(e, DegenerateShape::Filled(..)) && e.to_string().contains("fills 100%"), "{e}");
        assert!(check_shape(&shape(&ex)).is_ok());
        let empty_level = Level { resolution: 16, ..Default::default() };
        let s = ShapeInput { name: "v".into(), occupancy: &ex, occupancy_22: &ex, finest: &empty_level, coarse_points: None, structure_level: None, bent_reference: None, at_extent: None, level0: None, fine_level: None };
        assert!(matches!(check_shape(&s), Err(DegenerateShape::EmptyLevel(_))));
    }
}
