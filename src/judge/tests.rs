//! The criteria and the verdict on small synthetic shapes: spheres cut,
//! moved, doubled and grown.

use glam::{IVec3, Vec3};

use super::copy::*;
use super::measure::*;
use super::thresholds::*;
use super::unlike::*;
use super::verdict::*;
use crate::grid::components::*;
use crate::level::Level;

/// The voxel shell of a sphere (or of its part where `keep` holds) at `res`.
fn sphere(res: u32, radius: f64, keep: impl Fn(Vec3) -> bool) -> Level {
    let mut l = crate::testing::synthetic::sphere_levels(&[res], glam::DVec3::ZERO, radius).remove(0);
    let pts: Vec<Vec3> = (0..l.len()).map(|i| l.point_normalised(i).as_vec3()).collect();
    l.retain(|i| keep(pts[i]));
    l
}

#[test]
fn a_closed_sphere_has_no_free_boundary_and_a_cut_one_has_a_rim() {
    let whole = sphere(64, 0.7, |_| true);
    let s = Structure::of(&whole);
    assert_eq!(s.pieces(), 1);
    assert!(s.free_boundary_share() < 0.01, "closed: {s:?}");
    let half = sphere(64, 0.7, |p| p.x < 0.0);
    let h = Structure::of(&half);
    // The rim is a circle of radius 0.7 (~22 voxels): ~140 voxels.
    assert!(h.free_boundary > 60 && h.free_boundary_share() > 0.02, "{h:?}");
    assert!(s.enclosure > 0.99 && h.enclosure < 0.8, "enclosure {} {}", s.enclosure, h.enclosure);
    let sc = Verdict::new(&half, &h, &whole, &s, &Thresholds::default());
    assert!(sc.flags.contains(&Flag::Fragment) && sc.flags.contains(&Flag::Shrunken), "{sc:?}");
    assert!(sc.score < 0.6, "{sc:?}");
    let same = Verdict::new(&whole, &s, &whole, &s, &Thresholds::default());
    assert_eq!((same.score, same.copy_fscore, same.flags.clone()), (1.0, 1.0, vec![Flag::NearCopy]));
    assert!(same.whole());
}

#[test]
fn pieces_and_holes_are_seen() {
    let whole = sphere(64, 0.7, |_| true);
    let s = Structure::of(&whole);
    // Two caps, apart: two pieces.
    let caps = sphere(64, 0.7, |p| p.y.abs() > 0.3);
    let c = Structure::of(&caps);
    assert_eq!(c.pieces(), 2, "{c:?}");
    let sc = Verdict::new(&caps, &c, &whole, &s, &Thresholds::default());
    assert!(sc.flags.contains(&Flag::Pieces), "{sc:?}");
    // Holes: six discs of 0.2 (6.4 voxels) cut away at the poles of the
    // axes, 12% of the surface; the rest in place.
    let poles = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z].map(|a| a * 0.7);
    let holes = sphere(64, 0.7, |p| poles.iter().all(|&c| c.distance(p) > 0.2));
    let t = Structure::of(&holes);
    let sc = Verdict::new(&holes, &t, &whole, &s, &Thresholds::default());
    assert!(sc.flags.contains(&Flag::Torn), "{sc:?}");
    assert!(!sc.flags.contains(&Flag::Shrunken) && !sc.flags.contains(&Flag::Fragment), "{sc:?}");
}

#[test]
fn a_shape_cut_short_is_shrunken_and_a_trimmed_one_is_not() {
    let whole = sphere(64, 0.7, |_| true);
    let s = Structure::of(&whole);
    // The top cut at 0.5 of 0.7: 86% of the height, 86% of the surface
    // (a bunny's ears without their tips; the cut's rim is a tear too):
    // shrunken, not a fragment.
    let cut = sphere(64, 0.7, |p| p.y < 0.5);
    let sc = Verdict::new(&cut, &Structure::of(&cut), &whole, &s, &Thresholds::default());
    assert!(sc.extent_ratio < 0.9 && sc.extent_ratio > 0.8, "{sc:?}");
    assert!(sc.flags.contains(&Flag::Shrunken) && !sc.flags.contains(&Flag::Fragment), "{sc:?}");
    // Trimmed at 0.65: 96% of the height, whole.
    let trimmed = sphere(64, 0.7, |p| p.y < 0.65);
    let st = Verdict::new(&trimmed, &Structure::of(&trimmed), &whole, &s, &Thresholds::default());
    assert!(!st.flags.contains(&Flag::Shrunken), "{st:?}");
}

/// The voxel shells of `spheres` (centre, radius) at `res`, merged.
use crate::testing::synthetic::sphere_union as spheres;

#[test]
fn a_thin_part_lost_inside_the_box_is_flagged() {
    // A body (radius 0.5, 16 voxels at 64^3) with an ear: a rod of small
    // spheres (radius 0.045, a diameter of about 3 voxels) up from its
    // top, and a second ear's worth of rod kept below the body, so that
    // losing the top ear leaves the bounding box as it was.
    let body = (Vec3::ZERO, 0.5);
    let rod = |y0: f32, sign: f32| (0..10).map(move |k| (Vec3::new(0.0, sign * (y0 + 0.04 * k as f32), 0.0), 0.045));
    let ears: Vec<(Vec3, f64)> = std::iter::once(body).chain(rod(0.5, 1.0)).chain(rod(0.5, -1.0)).collect();
    let one_ear: Vec<(Vec3, f64)> = std::iter::once(body)
        .chain(rod(0.5, 1.0).take(1))
        .chain(rod(0.5, -1.0))
        .chain([(Vec3::new(0.0, 0.86, 0.0), 0.045)]) // the top ear's tip alone keeps the box
        .collect();
    let exemplar = spheres(64, &ears);
    let e = Structure::of(&exemplar);
    assert!(e.thin as f64 > 0.05 * e.voxels as f64, "the ears are thin: {} of {}", e.thin, e.voxels);
    let p = Thresholds::default();
    let same = Verdict::new(&exemplar, &e, &exemplar, &e, &p);
    assert_eq!(same.thin_ratio, 1.0);
    assert!(!same.flags.contains(&Flag::ThinPartLost));
    let lost = spheres(64, &one_ear);
    let l = Structure::of(&lost);
    let sc = Verdict::new(&lost, &l, &exemplar, &e, &p);
    assert!(sc.thin_ratio < 0.8 && sc.flags.contains(&Flag::ThinPartLost) && !sc.whole(), "{sc:?}");
    assert!(!sc.flags.contains(&Flag::Shrunken), "the box is kept: {sc:?}");
    // A body without thin parts has nothing to lose: the flag does not apply.
    let ball = spheres(64, &[body]);
    let b = Structure::of(&ball);
    assert!((b.thin as f64) < 0.02 * b.voxels as f64, "a ball is not thin: {} of {}", b.thin, b.voxels);
    let smaller = spheres(64, &[(Vec3::ZERO, 0.45)]);
    let sc = Verdict::new(&smaller, &Structure::of(&smaller), &ball, &b, &p);
    assert_eq!(sc.thin_ratio, 1.0, "{sc:?}");
    // Normals of any length (a network's, before they are written) count
    // the same thin voxels as unit ones.
    let mut short = exemplar.clone();
    for (k, n) in short.normals.iter_mut().enumerate() {
        *n *= if k % 2 == 0 { 0.3 } else { 1.7 };
    }
    assert_eq!(Structure::of(&short).thin, e.thin);
}

#[test]
fn a_cap_cut_off_is_gone_with_nothing_added_and_a_cap_moved_is_both() {
    let whole = sphere(32, 0.7, |_| true);
    assert_eq!(Matching::of(&whole, &whole).gone_and_added(), (0, 0));
    // The cap above y = 0.5 (a sphere's shell, 1-voxel tolerance: the
    // voxels more than a voxel above the cut are gone, as one region).
    let capless = sphere(32, 0.7, |p| p.y < 0.5);
    let (gone, added) = Matching::of(&capless, &whole).gone_and_added();
    let above = (0..whole.len()).filter(|&i| whole.point_normalised(i).y > 0.5 + 2.0 / 16.0).count();
    assert!(gone >= above && gone < whole.len() / 4 && added == 0, "gone {gone}, added {added}, {above} above the cut");
    // The other way round the cap is added and nothing is gone.
    assert_eq!(Matching::of(&whole, &capless).gone_and_added(), (0, gone));
}

#[test]
fn a_part_moved_elsewhere_is_a_near_copy_and_a_part_doubled_is_new() {
    use crate::testing::synthetic::sphere_union;
    let (a, b, b_moved, c) = (Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.3, 0.0, 0.0), Vec3::new(0.3, 0.0, 0.6), Vec3::new(-0.5, 0.0, 0.6));
    let ex = sphere_union(64, &[(a, 0.2), (b, 0.2)]);
    let moved = sphere_union(64, &[(a, 0.2), (b_moved, 0.2)]);
    let doubled = sphere_union(64, &[(a, 0.2), (b, 0.2), (c, 0.2)]);
    let lost = sphere_union(64, &[(a, 0.2)]);
    let p = Thresholds::default();
    let (es, params) = (Structure::of(&ex), &p);
    let score = |l: &Level| Verdict::new(l, &Structure::of(l), &ex, &es, params);
    let m = score(&moved);
    assert!(m.copy_fscore < p.copy_fscore, "not a copy by the F-score alone: {m:?}");
    assert!(m.flags.contains(&Flag::NearCopy), "{m:?}");
    let d = score(&doubled);
    assert!(!d.flags.contains(&Flag::NearCopy), "{d:?}");
    let l = score(&lost);
    assert!(!l.flags.contains(&Flag::NearCopy), "{l:?}");
    // Moved and turned into something else: a ball where a ball was, a
    // long rod somewhere new.
    let rod = sphere_union(64, &[(a, 0.2), (Vec3::new(0.3, 0.0, 0.5), 0.12), (Vec3::new(0.3, 0.0, 0.68), 0.12), (Vec3::new(0.3, 0.0, 0.32), 0.12)]);
    let r = score(&rod);
    assert!(!r.flags.contains(&Flag::NearCopy), "{r:?}");
}

#[test]
fn a_part_like_nothing_on_the_exemplar_is_out_of_style_and_the_exemplar_moved_is_not() {
    let p = Thresholds::default();
    let voxel = 2.0 / 64.0;
    let exemplar = spheres(64, &[(Vec3::ZERO, 0.55)]);
    let e = Structure::of(&exemplar);
    let same = Verdict::new(&exemplar, &e, &exemplar, &e, &p);
    assert_eq!(same.unlike_share, 0.0);
    // Moved by whole voxels, every neighbourhood is one of the exemplar's.
    let moved = spheres(64, &[(Vec3::new(2.0 * voxel, voxel, 0.0), 0.55)]);
    let m = Verdict::new(&moved, &Structure::of(&moved), &exemplar, &e, &p);
    assert!(m.unlike_share < 0.01 && !m.flags.contains(&Flag::OutOfStyle), "{m:?}");
    // A fan of thin rods (small spheres, 3 voxels across) splayed out and
    // down from its side, as a wall fallen outward: nothing on a ball is
    // like it.
    let mut fan = vec![(Vec3::ZERO, 0.55)];
    for a in [20.0f32, 35.0, 50.0] {
        let dir = Vec3::new(a.to_radians().cos(), -a.to_radians().sin(), 0.0);
        for z in [-0.12f32, 0.0, 0.12] {
            fan.extend((0..10).map(|k| (dir * (0.5 + 0.04 * k as f32) + Vec3::Z * z, 0.045)));
        }
    }
    let fallen = spheres(64, &fan);
    let f = Verdict::new(&fallen, &Structure::of(&fallen), &exemplar, &e, &p);
    assert!(f.unlike_share > p.max_unlike_share && f.flags.contains(&Flag::OutOfStyle) && !f.whole(), "{f:?}");
    assert!(f.score < 1.0, "{f:?}");
    // At 16^3 a window spans most of the shape: not compared.
    let coarse = spheres(16, &fan);
    let ball = spheres(16, &[(Vec3::ZERO, 0.55)]);
    assert_eq!(unlike_share(&coarse, &ball), 0.0);
}

#[test]
fn rods_made_at_the_fine_level_on_a_sound_structure_level_are_fine_out_of_style() {
    let p = Thresholds::default();
    let ball = |r| spheres(r, &[(Vec3::ZERO, 0.55)]);
    let (exemplar, exemplar_fine) = (ball(64), ball(128));
    let e = Structure::of(&exemplar);
    let sound = Verdict::new(&exemplar, &e, &exemplar, &e, &p);
    assert!(sound.whole() && sound.fine_unlike_share.is_none(), "{sound:?}");
    // The same ball at 128^3: nothing unlike, whole, the share recorded.
    let same = sound.clone().with_fine(&exemplar_fine, &exemplar_fine, &p);
    assert_eq!(same.fine_unlike_share, Some(0.0));
    assert!(same.whole() && same.score == sound.score, "{same:?}");
    // Thin rods (2-3 voxels across at 128^3) sticking out of the ball at
    // 128^3 only, as a finer network's ragged flakes: flagged, the score
    // lowered, the structure level's own flags kept (the ball against
    // itself is a near copy).
    let mut rods = vec![(Vec3::ZERO, 0.55)];
    for a in (0..12).map(|k| 30.0 * k as f32) {
        for y in [-0.5f32, 0.0, 0.5] {
            let dir = Vec3::new(a.to_radians().cos(), y, a.to_radians().sin()).normalize();
            rods.extend((0..15).map(|k| (dir * (0.52 + 0.02 * k as f32), 0.02)));
        }
    }
    let ragged = sound.clone().with_fine(&spheres(128, &rods), &exemplar_fine, &p);
    let share = ragged.fine_unlike_share.unwrap();
    assert!(share > p.max_fine_unlike_share, "{ragged:?}");
    assert_eq!(ragged.flags, vec![Flag::FineOutOfStyle, Flag::NearCopy], "{ragged:?}");
    assert!(!ragged.whole() && ragged.score < 1.0, "{ragged:?}");
    // A level of the structure level's resolution, or two levels that
    // differ, compare nothing.
    assert_eq!(sound.clone().with_fine(&exemplar, &exemplar, &p), sound);
    assert_eq!(sound.clone().with_fine(&spheres(128, &rods), &spheres(256, &[(Vec3::ZERO, 0.55)]), &p), sound);
}

#[test]
fn a_hole_through_a_sheet_is_holed_and_a_closed_shell_has_no_sheet_axis() {
    // A sphere's cap is a height field along y; a hole of 0.3 x 0.3 (about
    // 10 x 10 columns at 64^3) punched through its top.
    let cap = sphere(64, 0.7, |p| p.y > 0.3);
    let c = Structure::of(&cap);
    assert_eq!(c.sheet_axis, Some(1), "{c:?}");
    let holed = sphere(64, 0.7, |p| p.y > 0.3 && (p.x.abs() > 0.15 || p.z.abs() > 0.15));
    let p = Thresholds::default();
    let sc = Verdict::new(&holed, &Structure::of(&holed), &cap, &c, &p);
    assert_eq!(sc.sheet_axis, Some(1));
    assert!(sc.hole_columns >= 50 && sc.flags.contains(&Flag::Holed) && !sc.whole(), "{sc:?}");
    assert!(sc.score < 0.2, "{sc:?}");
    let same = Verdict::new(&cap, &c, &cap, &c, &p);
    assert_eq!((same.hole_columns, same.whole()), (0, true));
    // A closed sphere is no sheet: the flag does not apply.
    let whole = sphere(64, 0.7, |_| true);
    assert_eq!(Structure::of(&whole).sheet_axis, None);
}

#[test]
fn components_count_26_connected_sets() {
    let c = [IVec3::ZERO, IVec3::ONE, IVec3::new(5, 5, 5), IVec3::new(5, 6, 5), IVec3::new(5, 7, 5)];
    assert_eq!(components(&c), vec![3, 2]);
    assert!(components(&[]).is_empty());
}

#[test]
fn a_bent_shape_is_judged_against_the_exemplar_but_for_its_views_and_patches() {
    use crate::level::warp::Warp;
    let ball = crate::testing::synthetic::sphere_levels(&[32], glam::DVec3::ZERO, 0.6).remove(0);
    // A third of the ball's diameter: a smaller bend of a smooth ball
    // stays within the copy flag's 1-voxel tolerance almost everywhere.
    let bent = Warp::random(&ball, 6.0, 7).apply(&ball);
    let params = Thresholds::default();
    let (sb, se) = (Structure::of(&bent), Structure::of(&ball));
    // The bent ball against the ball: moved, so new, and whole.
    let s = Verdict::against_bend(&bent, &sb, (&bent, &sb), &ball, &se, &params);
    assert!(s.whole() && !s.flags.contains(&Flag::NearCopy), "{:?}", s.flags);
    assert!(s.copy_fscore < 0.95, "copy F {}", s.copy_fscore);
    // The ball itself, with that bend: a copy of the exemplar.
    let c = Verdict::against_bend(&ball, &se, (&bent, &sb), &ball, &se, &params);
    assert!(c.flags.contains(&Flag::NearCopy), "{:?}", c.flags);
    // Half of the bent ball: a fragment against the exemplar, whatever
    // the bend's own views say.
    let mut half = bent.clone();
    let mid = bent.coords.iter().map(|c| c.x).sum::<i32>() / bent.len() as i32;
    half.retain(|i| bent.coords[i].x < mid);
    let h = Verdict::against_bend(&half, &Structure::of(&half), (&bent, &sb), &ball, &se, &params);
    assert!(h.flags.contains(&Flag::Fragment) && !h.whole(), "{:?}", h.flags);
    // A smaller bend of the ball, judged against the ball itself: whole.
    let small = Warp::random(&ball, 3.0, 7).apply(&ball);
    let w = Verdict::new(&small, &Structure::of(&small), &ball, &se, &params);
    assert!(w.whole(), "flags {:?}", w.flags);
}
