use super::*;
use std::collections::HashSet;
use crate::io::mesh::Texture;

use crate::util::rng::Rng;

/// A random point of [-1, 1]^3.
fn random_point(rng: &mut Rng) -> DVec3 {
    DVec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - DVec3::ONE
}

fn mesh(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
    Mesh { name: "test".into(), positions, triangles, colours: MeshColours::None, texture: None }
}

/// Icosahedron subdivided `levels` times, vertices projected on the unit sphere,
/// outward-oriented triangles.
fn icosphere(levels: u32) -> Mesh {
    let phi = (1.0 + 5f32.sqrt()) / 2.0;
    #[rustfmt::skip]
    let mut pos: Vec<Vec3> = [
        (-1.0, phi, 0.0), (1.0, phi, 0.0), (-1.0, -phi, 0.0), (1.0, -phi, 0.0),
        (0.0, -1.0, phi), (0.0, 1.0, phi), (0.0, -1.0, -phi), (0.0, 1.0, -phi),
        (phi, 0.0, -1.0), (phi, 0.0, 1.0), (-phi, 0.0, -1.0), (-phi, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    #[rustfmt::skip]
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
        [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
        [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
        [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::new();
        for t in &tris {
            let m: [u32; 3] = std::array::from_fn(|k| {
                let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                *mid.entry((a, b)).or_insert_with(|| {
                    pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                    pos.len() as u32 - 1
                })
            });
            next.extend([[t[0], m[0], m[2]], [t[1], m[1], m[0]], [t[2], m[2], m[1]], [m[0], m[1], m[2]]]);
        }
        tris = next;
    }
    mesh(pos, tris)
}

/// Axis-aligned box [lo, hi], 12 outward triangles.
use crate::testing::shapes::axis_box as cube;

/// Height field z = f(x, y) over [-1, 1]^2, n x n quads, normals facing +z.
fn height_field(n: u32, f: impl Fn(f32, f32) -> f32) -> Mesh {
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (2.0 * i as f32 / n as f32 - 1.0, 2.0 * j as f32 / n as f32 - 1.0);
            pos.push(Vec3::new(x, y, f(x, y)));
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    mesh(pos, tris)
}

/// Distance from `p` to the mesh (normalised units), brute force over triangles.
fn distance_to_mesh(prep: &Prepared, p: DVec3) -> f64 {
    (0..prep.triangles.len())
        .filter(|&t| prep.face_normals[t] != DVec3::ZERO)
        .map(|t| {
            let c = prep.corners[t];
            let (w, _) = closest_on_triangle(p, &c);
            (w.x * c[0] + w.y * c[1] + w.z * c[2]).distance(p)
        })
        .fold(f64::INFINITY, f64::min)
}

/// The sampling level alone, as `encode` builds it.
fn sampling_level(m: &Mesh, r: u32) -> (Prepared, Vec<Sample>) {
    let prep = Prepared::new(m, normalisation_frame(m)).unwrap();
    let colours = ColourSource::new(m, Vec3::splat(0.5)).unwrap();
    let mut pairs = voxelise(&prep, r);
    pairs.sort();
    let groups = group_starts(pairs.len(), |i| pairs.key(i));
    let samples = sample_voxels(&prep, &pairs, &groups, r, &colours);
    (prep, samples)
}

fn options(sampling: u32, coarsest: u32, finest: u32, pooling: Pooling) -> EncodeOptions {
    EncodeOptions {
        sampling_resolution: sampling,
        coarsest_resolution: coarsest,
        finest_resolution: finest,
        pooling,
        ..Default::default()
    }
}

fn level_of(levels: &[Level], r: u32) -> &Level {
    levels.iter().find(|l| l.resolution == r).unwrap()
}

#[test]
fn morton_round_trip_and_parent() {
    let mut rng = Rng::new(7);
    for _ in 0..1000 {
        let c = [0; 3].map(|_: i32| (rng.uniform() * (1 << 21) as f64) as u32);
        let key = morton(c[0], c[1], c[2]);
        assert_eq!(morton_decode(key), IVec3::new(c[0] as i32, c[1] as i32, c[2] as i32));
        assert_eq!(key >> 3, morton(c[0] / 2, c[1] / 2, c[2] / 2));
    }
}

#[test]
fn offsets_are_clamped_along_their_direction() {
    assert_eq!(clamp_offset(DVec3::new(0.8, -0.2, 0.4)), Vec3::new(0.5, -0.125, 0.25));
    assert_eq!(clamp_offset(DVec3::new(0.3, -0.5, 0.1)), Vec3::new(0.3, -0.5, 0.1));
    assert_eq!(clamp_offset(DVec3::NAN), Vec3::ZERO);
}

#[test]
fn closest_point_matches_dense_search() {
    let mut rng = Rng::new(11);
    for _ in 0..200 {
        let t = [random_point(&mut rng), random_point(&mut rng), random_point(&mut rng)];
        let p = random_point(&mut rng) * 1.5;
        let (w, _) = closest_on_triangle(p, &t);
        assert!((w.element_sum() - 1.0).abs() < 1e-12 && w.min_element() >= -1e-12);
        let d = (w.x * t[0] + w.y * t[1] + w.z * t[2]).distance(p);
        // No barycentric grid point may be closer.
        let n = 60;
        for i in 0..=n {
            for j in 0..=n - i {
                let (a, b) = (i as f64 / n as f64, j as f64 / n as f64);
                let q = t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0]);
                assert!(q.distance(p) >= d - 1e-12, "closest point is not closest");
            }
        }
    }
}

#[test]
fn symmetric_eigen_reconstructs() {
    let mut rng = Rng::new(3);
    for _ in 0..200 {
        let (x, y) = (random_point(&mut rng), random_point(&mut rng));
        let a = [[x.x, y.x, y.y], [y.x, x.y, y.z], [y.y, y.z, x.z]];
        let (l, v) = symmetric_eigen(a);
        for i in 0..3 {
            for j in 0..3 {
                let r: f64 = (0..3).map(|k| l[k] * v[k][i] * v[k][j]).sum();
                assert!((r - a[i][j]).abs() < 1e-12);
            }
            assert!((v[i].length() - 1.0).abs() < 1e-12);
        }
    }
}

/// Reference separating-axis test of a triangle against the closed unit box at
/// `c`, all 13 axes, written out independently of `voxelise_triangle`.
fn triangle_box_overlap(g: &[DVec3; 3], c: DVec3) -> bool {
    let p = g.map(|q| q - c);
    let e = [p[1] - p[0], p[2] - p[1], p[0] - p[2]];
    let mut axes = vec![DVec3::X, DVec3::Y, DVec3::Z, e[0].cross(e[1])];
    for f in e {
        for b in [DVec3::X, DVec3::Y, DVec3::Z] {
            axes.push(b.cross(f));
        }
    }
    axes.iter().all(|a| {
        let s = p.map(|q| a.dot(q));
        let rad = 0.5 * a.abs().element_sum();
        s[0].min(s[1]).min(s[2]) <= rad && s[0].max(s[1]).max(s[2]) >= -rad
    })
}

/// Every voxel holding a point of the triangle is found, and every voxel found is
/// within half a voxel diagonal of the triangle.
#[test]
fn voxelisation_is_exact() {
    let mut rng = Rng::new(5);
    let r = 16u32;
    for _ in 0..100 {
        let g = [0; 3].map(|_: i32| (random_point(&mut rng) * 0.45 + DVec3::splat(0.5)) * r as f64);
        let n = (g[1] - g[0]).cross(g[2] - g[0]).normalize();
        let mut found = HashSet::new();
        voxelise_triangle(&g, n, r, |i, j, k| assert!(found.insert((i, j, k)), "duplicate"));
        // Same set as the full 13-axis test over the whole bounding box.
        let (lo, hi) = (g[0].min(g[1]).min(g[2]).floor(), g[0].max(g[1]).max(g[2]).floor());
        let mut reference = HashSet::new();
        for i in lo.x as u32..=hi.x as u32 {
            for j in lo.y as u32..=hi.y as u32 {
                for k in lo.z as u32..=hi.z as u32 {
                    let c = DVec3::new(i as f64, j as f64, k as f64) + DVec3::splat(0.5);
                    if triangle_box_overlap(&g, c) {
                        reference.insert((i, j, k));
                    }
                }
            }
        }
        assert_eq!(found, reference);
        let s = 200;
        for i in 0..=s {
            for j in 0..=s - i {
                let q =
                    g[0] + (i as f64 / s as f64) * (g[1] - g[0]) + (j as f64 / s as f64) * (g[2] - g[0]);
                let c = q.floor().as_uvec3().min(glam::UVec3::splat(r - 1));
                assert!(found.contains(&(c.x, c.y, c.z)), "missed voxel {c}");
            }
        }
        for &(i, j, k) in &found {
            let c = DVec3::new(i as f64, j as f64, k as f64) + DVec3::splat(0.5);
            let (w, _) = closest_on_triangle(c, &g);
            let d = (w.x * g[0] + w.y * g[1] + w.z * g[2]).distance(c);
            assert!(d <= 0.75f64.sqrt() + 1e-9, "voxel {i},{j},{k} is {d} voxels away");
        }
    }
}

#[test]
fn packed_and_wide_pairs_agree() {
    let m = icosphere(2);
    let prep = Prepared::new(&m, normalisation_frame(&m)).unwrap();
    let (mut packed, mut wide) = (voxelise_as(&prep, 64, true), voxelise_as(&prep, 64, false));
    assert!(matches!(packed, Pairs::Packed { .. }) && matches!(wide, Pairs::Wide(_)));
    packed.sort();
    wide.sort();
    assert_eq!(packed.len(), wide.len());
    for i in 0..packed.len() {
        assert_eq!((packed.key(i), packed.triangle(i)), (wide.key(i), wide.triangle(i)));
    }
}

#[test]
fn sphere_points_lie_on_the_mesh_and_the_sphere() {
    let m = icosphere(4);
    let r = 128;
    let vs = 2.0 / r as f64;
    let (prep, samples) = sampling_level(&m, r);
    let frame = normalisation_frame(&m);
    let (centre, radius) = (frame.to_normalised(DVec3::ZERO), frame.scale);
    // The polyhedron lies between its faces' planes and the sphere it is inscribed
    // in: the deepest face plane bounds how far a mesh point can be inside.
    let sag = (0..prep.triangles.len())
        .map(|t| radius - prep.face_normals[t].dot(prep.corners[t][0] - centre))
        .fold(0.0, f64::max);
    assert!(sag > 0.0 && sag < 0.05 * vs, "sag {sag}");
    for (i, s) in samples.iter().enumerate() {
        let p = voxel_centre(s.key, r) + s.offset.as_dvec3() * vs;
        let rho = (p - centre).length();
        assert!(rho <= radius + 1e-6 * vs && rho >= radius - sag - 1e-6 * vs, "point off the sphere");
        if i % 16 == 0 {
            let d = distance_to_mesh(&prep, p);
            assert!(d < 1e-3 * vs, "point {d} voxels off the mesh");
        }
        // A triangle that touches the voxel has a point within half a diagonal.
        assert!(s.offset.length() <= 0.75f32.sqrt() + 1e-4);
    }
}

#[test]
fn sphere_levels_have_outward_unit_normals_and_points_near_the_sphere() {
    let m = icosphere(4);
    let (levels, stats) = encode(&m, &options(128, 16, 64, Pooling::Qem)).unwrap();
    assert_eq!(levels.iter().map(|l| l.resolution).collect::<Vec<_>>(), vec![16, 32, 64]);
    assert_eq!(
        stats.voxels_per_resolution.iter().map(|c| c.0).collect::<Vec<_>>(),
        vec![16, 32, 64, 128]
    );
    let frame = normalisation_frame(&m);
    let (centre, radius) = (frame.to_normalised(DVec3::ZERO), frame.scale);
    for (idx, level) in levels.iter().enumerate() {
        assert_eq!(level.index, idx);
        assert_eq!(level.frame, frame);
        let vs = level.voxel_size();
        for i in 0..level.len() {
            let n = level.normals[i];
            assert!((n.length() - 1.0).abs() < 1e-5);
            assert!(level.offsets[i].abs().max_element() <= 0.5);
            assert!(level.colours[i] == Vec3::splat(0.5) && level.mask[i] == 1.0);
            let p = level.point_normalised(i);
            let radial = (p - centre).normalize();
            assert!(n.as_dvec3().dot(radial) > 0.95, "normal not outward at level {idx}");
            // A voxel's QEM point sits on the mean tangent plane of a patch about
            // one voxel wide: off the sphere by the patch sag (measured <= 0.021
            // voxels here). Points clamped into their voxel (the surface only clips
            // the voxel) leave the surface, but stay within half a diagonal.
            let off = ((p - centre).length() - radius).abs() / vs;
            if level.offsets[i].abs().max_element() < 0.4999 {
                assert!(off < 0.05, "level {idx}: point {off} voxels off the sphere");
            } else {
                assert!(off < 0.75f64.sqrt());
            }
        }
    }
}

/// On a cube, a closest point on an edge gets the bisector of the two faces and
/// one on a corner the diagonal: pseudo-normals, angle-weighted so that a face
/// split into two triangles at the corner does not count twice.
#[test]
fn cube_edges_and_corners_get_pseudo_normals() {
    let m = cube(Vec3::new(-1.0, 2.0, 0.5), Vec3::new(3.0, 6.0, 4.5));
    let (_, samples) = sampling_level(&m, 64);
    let frame = normalisation_frame(&m);
    let half = frame.scale * 2.0; // half the side, normalised units
    let centre = frame.to_normalised(DVec3::new(1.0, 4.0, 2.5));
    let vs = 2.0 / 64.0;
    let mut seen = [0; 4];
    for s in &samples {
        let p = voxel_centre(s.key, 64) + s.offset.as_dvec3() * vs - centre;
        let on_bound = p.to_array().map(|x| (x.abs() - half).abs() < 1e-6);
        let expected =
            DVec3::from_array(std::array::from_fn(|i| if on_bound[i] { p[i].signum() } else { 0.0 }));
        let count = on_bound.iter().filter(|&&b| b).count();
        seen[count] += 1;
        assert!(count >= 1, "point off the cube");
        let err = (s.normal.as_dvec3() - expected.normalize()).length();
        assert!(err < 1e-5, "normal {} at a point on {count} faces", s.normal);
    }
    assert!(seen[2] > 0 && seen[3] >= 8, "edge/corner samples: {seen:?}");
}

#[test]
fn every_parent_has_a_child_and_every_child_a_parent() {
    let m = icosphere(3);
    for pooling in [Pooling::Qem, Pooling::Average] {
        let (levels, _) = encode(&m, &options(128, 8, 128, pooling)).unwrap();
        assert_eq!(levels.len(), 5);
        for pair in levels.windows(2) {
            let (coarse, fine) = (&pair[0], &pair[1]);
            assert_eq!(fine.resolution, 2 * coarse.resolution);
            let parents: HashSet<IVec3> = coarse.coords.iter().copied().collect();
            let with_children: HashSet<IVec3> = fine.coords.iter().map(|c| *c >> 1).collect();
            assert_eq!(parents.len(), coarse.len(), "duplicate coordinates");
            assert_eq!(parents, with_children);
        }
        // Sorted sparse output: Morton order, no duplicates.
        for l in &levels {
            let keys: Vec<u64> =
                l.coords.iter().map(|c| morton(c.x as u32, c.y as u32, c.z as u32)).collect();
            assert!(keys.windows(2).all(|w| w[0] < w[1]));
        }
    }
}

#[test]
fn cube_corners_stay_sharp_with_qem_and_round_off_with_average() {
    // Box corners land at 0.62 of a level-16 voxel: not on a lattice plane.
    let m = cube(Vec3::new(-1.0, 2.0, 0.5), Vec3::new(3.0, 6.0, 4.5));
    let frame = normalisation_frame(&m);
    for pooling in [Pooling::Qem, Pooling::Average] {
        let (levels, _) = encode(&m, &options(256, 16, 64, pooling)).unwrap();
        for r in [16, 32] {
            let level = level_of(&levels, r);
            let vs = level.voxel_size();
            for corner in &m.positions {
                let c = frame.to_normalised(corner.as_dvec3());
                let ijk = ((c + DVec3::ONE) / vs).floor().as_ivec3();
                let i = level.coords.iter().position(|x| *x == ijk).expect("corner voxel");
                let d = level.point_normalised(i).distance(c) / vs;
                match pooling {
                    Pooling::Qem => assert!(d < 1e-3, "QEM corner {d} voxels off at {r}"),
                    Pooling::Average => assert!(d > 0.1, "average kept a corner ({d} voxels) at {r}"),
                }
            }
        }
    }
}

#[test]
fn vertex_and_corner_colours_are_interpolated() {
    // Colours affine in position: barycentric interpolation is exact, and plain
    // averaging keeps colour = f(point) through every level.
    let mut m = icosphere(3);
    let f = |p: Vec3| (p * 0.4 + Vec3::splat(0.5)).clamp(Vec3::ZERO, Vec3::ONE);
    let per_vertex: Vec<Vec3> = m.positions.iter().map(|p| f(*p)).collect();
    let per_corner: Vec<Vec3> =
        m.triangles.iter().flat_map(|t| t.map(|v| per_vertex[v as usize])).collect();
    let frame = normalisation_frame(&m);
    for colours in [MeshColours::PerVertex(per_vertex), MeshColours::PerCorner(per_corner)] {
        m.colours = colours;
        let (levels, _) = encode(&m, &options(128, 16, 128, Pooling::Average)).unwrap();
        let mut checked = 0;
        for level in &levels {
            for i in 0..level.len() {
                if level.offsets[i].abs().max_element() >= 0.4999 {
                    continue; // clamped point: no longer the mean point
                }
                let p = frame.to_world(level.point_normalised(i)).as_vec3();
                let err = (level.colours[i] - f(p)).abs().max_element();
                assert!(err < 1e-4, "colour off by {err} at resolution {}", level.resolution);
                checked += 1;
            }
        }
        assert!(checked > 10_000);
    }
}

#[test]
fn texture_is_sampled_bilinearly_at_the_uv() {
    // A tilted quad whose UVs are affine in (x, y), and a texture whose red and
    // green grow linearly with the pixel column and row.
    let (w, h) = (64u32, 32u32);
    let image = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(4 * x) as u8, (8 * y) as u8, 77]));
    let z = |x: f32, y: f32| 0.3 * x - 0.2 * y;
    let positions: Vec<Vec3> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .iter()
        .map(|&(x, y)| Vec3::new(x, y, z(x, y)))
        .collect();
    let uv_of = |p: Vec3| glam::Vec2::new(0.1 + 0.4 * (p.x + 1.0), 0.15 + 0.35 * (p.y + 1.0));
    let triangles = vec![[0, 1, 2], [0, 2, 3]];
    let uvs = triangles.iter().flat_map(|t: &[u32; 3]| t.map(|v| uv_of(positions[v as usize]))).collect();
    let mut m = mesh(positions, triangles);
    m.texture = Some(Texture { uvs, image, ..Default::default() });
    let expected = |p: Vec3| {
        let uv = uv_of(p);
        let (px, py) = (uv.x * w as f32 - 0.5, (1.0 - uv.y) * h as f32 - 0.5);
        Vec3::new(4.0 * px, 8.0 * py, 77.0) / 255.0
    };
    let frame = normalisation_frame(&m);
    let (levels, _) = encode(&m, &options(128, 16, 128, Pooling::Average)).unwrap();
    let mut checked = 0;
    for level in &levels {
        for i in 0..level.len() {
            if level.offsets[i].abs().max_element() >= 0.4999 {
                continue;
            }
            let p = frame.to_world(level.point_normalised(i)).as_vec3();
            let err = (level.colours[i] - expected(p)).abs().max_element();
            assert!(err < 1e-3, "texture colour off by {err}");
            checked += 1;
        }
    }
    assert!(checked > 5000);
}

#[test]
fn open_surface_gets_no_closing_surface() {
    let m = height_field(24, |x, y| 0.25 * (2.0 * x).sin() * (1.5 * y).cos());
    let prep = Prepared::new(&m, normalisation_frame(&m)).unwrap();
    for pooling in [Pooling::Qem, Pooling::Average] {
        let (levels, _) = encode(&m, &options(128, 16, 128, pooling)).unwrap();
        for level in &levels {
            let vs = level.voxel_size();
            for i in (0..level.len()).step_by(3) {
                // Active voxels touch the surface: centre within half a diagonal.
                let d = distance_to_mesh(&prep, level.voxel_centre(level.coords[i]));
                assert!(d <= 0.75f64.sqrt() * vs + 1e-9, "voxel {} voxels from the surface", d / vs);
                assert!(level.normals[i].z > 0.0, "normal flipped on an open sheet");
            }
        }
    }
}

#[test]
fn options_and_meshes_are_validated() {
    let m = icosphere(1);
    for bad in [
        options(1000, 16, 256, Pooling::Qem),
        options(1024, 64, 32, Pooling::Qem),
        options(128, 16, 256, Pooling::Qem),
    ] {
        assert!(matches!(encode(&m, &bad), Err(EncodeError::InvalidOptions(_))));
    }
    let grey = EncodeOptions { default_colour: Vec3::splat(2.0), ..Default::default() };
    assert!(matches!(encode(&m, &grey), Err(EncodeError::InvalidOptions(_))));
    assert!(matches!(
        encode(&mesh(vec![], vec![]), &EncodeOptions::default()),
        Err(EncodeError::EmptyMesh(_))
    ));
    let dangling = mesh(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 3]]);
    assert!(matches!(encode(&dangling, &EncodeOptions::default()), Err(EncodeError::InvalidMesh { .. })));
    let flat = mesh(vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0], vec![[0, 1, 2]]);
    assert!(matches!(encode(&flat, &EncodeOptions::default()), Err(EncodeError::NoActiveVoxels(_))));
    let mut wrong = m.clone();
    wrong.colours = MeshColours::PerVertex(vec![Vec3::ONE; 3]);
    assert!(matches!(encode(&wrong, &EncodeOptions::default()), Err(EncodeError::InvalidMesh { .. })));
}

#[test]
fn sampling_level_can_be_an_output_level() {
    let m = icosphere(2);
    let (levels, stats) = encode(&m, &options(64, 64, 64, Pooling::Qem)).unwrap();
    assert_eq!(levels.len(), 1);
    assert_eq!(levels[0].len(), stats.sampling_voxels);
    assert!(levels[0].offsets.iter().all(|o| o.abs().max_element() <= 0.5));
}
