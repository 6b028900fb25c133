use super::*;
use crate::judge::{Flag, Structure, Thresholds, Verdict};
use crate::level::Level;
use super::attempts::*;
use super::gate::*;
use super::proposers::*;
use crate::config::Level0Pick as Pick;

/// Runs [`keep_attempt`] over fixed outcomes (whole, new, score); the
/// attempts run and the one kept.
fn run_attempts(reject_copies: bool, outcomes: &[(bool, bool, f64)]) -> (usize, usize) {
    let mut ran = 0;
    let (kept, _, payload) = keep_attempt(outcomes.len(), reject_copies, |a| {
        ran += 1;
        let (whole, new, score) = outcomes[a];
        Ok((AttemptRank { whole, new, score }, a))
    })
    .unwrap();
    assert_eq!(kept, payload);
    (ran, kept)
}

#[test]
fn a_whole_copy_is_passed_over_for_a_whole_new_shape_but_kept_before_a_broken_one() {
    let copy_then_new = [(true, false, 0.99), (false, true, 0.9), (true, true, 0.8), (true, true, 0.95)];
    // Without the rejection the first whole pass ends the search, copy or not.
    assert_eq!(run_attempts(false, &copy_then_new), (1, 0));
    // With it the copy and the broken pass are passed over; the first
    // whole new one is kept even though a later one scores higher.
    assert_eq!(run_attempts(true, &copy_then_new), (3, 2));
    // No whole new pass: the whole copy is kept before broken new shapes
    // of higher score, and every attempt was tried.
    assert_eq!(run_attempts(true, &[(false, true, 0.97), (true, false, 0.6), (false, true, 0.99)]), (3, 1));
    // Nothing whole: the best score of the broken (new before copy).
    assert_eq!(run_attempts(true, &[(false, false, 0.9), (false, true, 0.5), (false, true, 0.7)]), (3, 2));
}

/// Offers (score, part lost, F-score, change) in turn until the pick
/// stops; the candidates drawn and what was kept.
fn run_pick(pick: Pick, min: f64, candidates: &[(f64, bool, f64, f64)]) -> (usize, Option<(usize, Kept)>) {
    run_policy(Level0Pick::new(pick, min), candidates)
}

fn run_policy(mut p: Level0Pick, candidates: &[(f64, bool, f64, f64)]) -> (usize, Option<(usize, Kept)>) {
    let mut drawn = 0;
    for (k, &(score, part_lost, f, change)) in candidates.iter().enumerate() {
        drawn += 1;
        if p.offer(k, score, part_lost, (f, change)).stop {
            break;
        }
    }
    (drawn, p.kept())
}

#[test]
fn the_first_pick_keeps_the_first_that_passes_not_the_best_scoring() {
    // Candidate 0 scores highest but is cut short: with the gate on it
    // does not pass; candidate 2 is the first that does.
    let c = [(0.95, true, 0.97, 0.03), (0.5, false, 0.99, 0.0), (0.85, false, 0.99, 0.0), (0.9, false, 0.9, 0.1)];
    assert_eq!(run_pick(Pick::First, 0.8, &c), (3, Some((2, Kept::First))));
    // The gate off (minimum 0): the first candidate passes, cut short or not.
    assert_eq!(run_pick(Pick::First, 0.0, &c), (1, Some((0, Kept::First))));
}

#[test]
fn the_novel_pick_stops_at_the_first_new_enough_and_never_keeps_a_shape_cut_short() {
    // 0: cut short and very new (a bunny without its ear tips); 1: a
    // copy; 2: new enough; 3: never drawn.
    let c = [(0.81, true, 0.96, 0.05), (0.99, false, 1.0, 0.0), (0.9, false, 0.98, 0.03), (0.9, false, 0.9, 0.2)];
    assert_eq!(run_pick(Pick::Novel, 0.8, &c), (3, Some((2, Kept::NewEnough { fscore: 0.98, change: 0.03 }))));
    // None new enough: the least like the exemplar of those that pass
    // (the lower F-score; on a tie, the larger change).
    let c = [(0.81, true, 0.9, 0.1), (0.9, false, 0.99, 0.01), (0.9, false, 0.988, 0.01), (0.9, false, 0.988, 0.02)];
    assert_eq!(run_pick(Pick::Novel, 0.8, &c), (4, Some((3, Kept::LeastLike { fscore: 0.988, change: 0.02 }))));
}

#[test]
fn in_a_resized_box_the_pick_keeps_the_first_like_enough_else_the_likest_never_a_shape_cut_short() {
    let likest = || Level0Pick::with_policy(Policy::Likest, 0.8);
    // 0: the likest of all but cut short; 1: a house that lost its rear
    // hall (F 0.957); 2: like enough, ends the draws; 3: never drawn.
    let c = [(0.9, true, 1.0, 0.0), (0.88, false, 0.957, 0.077), (0.95, false, 0.996, 0.004), (0.99, false, 1.0, 0.0)];
    assert_eq!(run_policy(likest(), &c), (3, Some((2, Kept::LikeEnough { fscore: 0.996, change: 0.004 }))));
    // None like enough: every candidate is drawn and the likest of those
    // that pass is kept (the higher F-score; on a tie, the smaller change),
    // not the first that passed, as the `first` pick would.
    let c = [(0.9, false, 0.957, 0.077), (0.9, false, 0.99, 0.02), (0.9, false, 0.99, 0.01), (0.7, false, 0.994, 0.0)];
    assert!(c.iter().all(|&(_, _, f, _)| f < LIKE_ENOUGH_AT_EXTENT_FSCORE));
    assert_eq!(run_policy(likest(), &c), (4, Some((2, Kept::Likest { fscore: 0.99, change: 0.01 }))));
    assert_eq!(run_pick(Pick::First, 0.8, &c), (1, Some((0, Kept::First))));
    // Nothing passes: the best scoring, as for the other picks.
    let c = [(0.5, false, 0.9, 0.1), (0.7, true, 0.99, 0.0)];
    assert_eq!(run_policy(likest(), &c), (2, Some((1, Kept::BestScoring { score: 0.7, fscore: 0.99 }))));
}

/// A bunny at `res`^3 made of spheres: a body (radius 0.5) with two ears
/// up from its top side by side, rods of spheres (radius 0.12, 0.9 long,
/// 0.6 apart); the same with one ear; the body alone.
fn bunny_of_spheres(res: u32) -> (Level, Level, Level) {
    use crate::testing::synthetic::sphere_union;
    use glam::Vec3;
    let body = (Vec3::new(0.0, -0.45, 0.0), 0.5);
    let ear = |x: f32| (0..10).map(move |k| (Vec3::new(x, -0.05 + 0.1 * k as f32, 0.0), 0.12));
    (
        sphere_union(res, &std::iter::once(body).chain(ear(-0.3)).chain(ear(0.3)).collect::<Vec<_>>()),
        sphere_union(res, &std::iter::once(body).chain(ear(-0.3)).collect::<Vec<_>>()),
        sphere_union(res, &[body]),
    )
}

#[test]
fn at_16_cubed_an_ear_lost_inside_the_box_is_a_part_lost_not_a_new_shape() {
    // At 16^3 (a voxel is 0.125) the ears are 2 voxels across, 4.8
    // apart. Losing one ear leaves the box as it was (the other ear keeps
    // its height).
    let (exemplar, one_ear, _) = bunny_of_spheres(16);
    let e = Structure::of(&exemplar);
    let p = Thresholds::default();
    assert_eq!(level0_gate(&exemplar, &exemplar, &e, &p), (1.0, false, (1.0, 0.0)));
    let (score, part_lost, (fscore, _)) = level0_gate(&one_ear, &exemplar, &e, &p);
    let m = crate::judge::Matching::of(&one_ear, &exemplar);
    assert_eq!(fscore, m.fscore());
    // What the pick saw before: a passing score and "new enough".
    let sc = Verdict::new(&one_ear, &Structure::of(&one_ear), &exemplar, &e, &p);
    assert!(score >= 0.8 && m.fscore() < NEW_ENOUGH_LEVEL0_FSCORE, "score {score}, F {}: {sc:?}", m.fscore());
    assert!(!sc.flags.contains(&crate::judge::Flag::Shrunken), "{sc:?}");
    assert!(part_lost, "the ear is lost: thin voxels {} of {}: {sc:?}", Structure::of(&one_ear).thin, e.thin);
    assert!(!Level0Pick::new(Pick::Novel, 0.8).passes(score, part_lost));
    assert_eq!(level0_gate(&Level::default(), &exemplar, &e, &p), (0.0, true, (0.0, 0.0)));
}

#[test]
fn one_level_finer_an_ear_lost_is_a_thin_part_lost_and_a_ball_has_none_to_lose() {
    // At 32^3 (a voxel is 0.0625) the ears (4 voxels across) are thin,
    // the body is not.
    let (exemplar, one_ear, ball) = bunny_of_spheres(32);
    let (exemplar0, _, ball0) = bunny_of_spheres(16);
    let p = Thresholds::default();
    let levels = [exemplar0.clone(), exemplar.clone()];
    let at = AtExtent::of(&levels, Extent::SAME, None, false).unwrap();
    assert!(at.thin1.is_some(), "the ears are thin parts");
    assert_eq!(at.thin_ratio(&exemplar), Some(1.0));
    let r = at.thin_ratio(&one_ear).unwrap();
    assert!(r < p.min_thin_ratio, "one ear of two lost: thin ratio {r}");
    // A ball has no thin part to lose: no check.
    assert!(AtExtent::of(&[ball0, ball], Extent::SAME, None, false).unwrap().thin1.is_none());
    assert!(AtExtent::of(&levels[..1], Extent::SAME, None, false).unwrap().thin1.is_none(), "no level 1, no check");
}

#[test]
fn when_nothing_passes_the_best_scoring_is_kept() {
    let c = [(0.5, false, 0.9, 0.1), (0.95, true, 0.9, 0.1), (0.7, false, 0.9, 0.1)];
    for pick in [Pick::First, Pick::Novel] {
        assert_eq!(run_pick(pick, 0.8, &c), (3, Some((1, Kept::BestScoring { score: 0.95, fscore: 0.9 }))), "{pick:?}");
    }
    assert_eq!(Level0Pick::new(Pick::Novel, 0.8).kept(), None);
}

#[test]
fn a_resized_shape_is_judged_against_the_exemplar_at_its_extent() {
    let (exemplar0, _, _) = bunny_of_spheres(16);
    let (mut exemplar, _, _) = bunny_of_spheres(32);
    exemplar.index = 1;
    let levels = [exemplar0, exemplar.clone()];
    let extent = Extent { extent: [1.5, 1.0, 1.0] };
    let at = AtExtent::of(&levels, extent, None, false).unwrap();
    let (ref_level, ref_structure) = at.reference().expect("a structure level");
    assert_eq!(ref_level.index, 1);
    let p = Thresholds::default();
    let e = Structure::of(&exemplar);
    // The exemplar as long as the box: whole at its extent, and not the
    // exemplar's size.
    let long = extent.of(&levels, 1).unwrap();
    let judged = Verdict::at_extent(&long, &Structure::of(&long), (ref_level, ref_structure), (&exemplar, &e), &p);
    assert!(judged.whole() && judged.extent_ratio > 0.99 && (judged.mass_ratio - 1.0).abs() < 0.01, "{judged:?}");
    let plain = Verdict::new(&long, &Structure::of(&long), &exemplar, &e, &p);
    assert!(plain.score < 0.8, "against the exemplar's own box the size is off: {plain:?}");
    // The exemplar's own size in the longer box is cut short.
    let short = Verdict::at_extent(&exemplar, &e, (ref_level, ref_structure), (&exemplar, &e), &p);
    assert!(short.flags.contains(&Flag::Shrunken), "{short:?}");
}
