//! Issue 2: mesh and level-file I/O, OpenVDB's own tools reading our files,
//! `info`, and one clean error per bad input.

use crate::common;

use std::path::Path;
use std::process::Command;

use common::*;
use glam::{DVec3, IVec3, Vec3};
use shapeshifter::level::{Frame, Level};
use shapeshifter::io::mesh::{self, Mesh, MeshColours};
use shapeshifter::io::vdb::{self, Provenance, WriteOptions};

/// A deterministic pseudo-random level: a noisy shell of voxels with every
/// feature varied, placed in a non-trivial exemplar frame.
fn sample_level() -> Level {
    let res = 32u32;
    let mut level = Level {
        index: 1,
        resolution: res,
        frame: Frame { centre: DVec3::new(12.5, -3.0, 100.25), scale: 0.037, ..Default::default() },
        ..Default::default()
    };
    let mut rng = shapeshifter::util::rng::Rng::new(12345);
    let mut rnd = move || rng.uniform() as f32;
    for i in 0..res as i32 {
        for j in 0..res as i32 {
            for k in 0..res as i32 {
                let c = IVec3::new(i, j, k);
                let r = (c.as_vec3() + 0.5 - res as f32 / 2.0).length();
                if (r - 10.0).abs() < 0.9 {
                    level.coords.push(c);
                    level.offsets.push(Vec3::new(rnd(), rnd(), rnd()) - 0.5);
                    level.normals.push((Vec3::new(rnd(), rnd(), rnd()) - 0.5).normalize());
                    level.colours.push(Vec3::new(rnd(), rnd(), rnd()));
                    level.mask.push(if rnd() < 0.8 { 1.0 } else { -1.0 });
                }
            }
        }
    }
    level
}

fn tmp() -> tempfile::TempDir {
    tempfile::tempdir().expect("temp dir")
}

#[test]
fn level_file_round_trip_keeps_voxels_features_and_frame() {
    let dir = tmp();
    let path = dir.path().join("level_1.vdb");
    let level = sample_level();
    assert!(level.len() > 1000);
    let prov = Provenance { exemplar: "tower".into(), seed: Some(42), config_digest: "abc123".into(), exemplar_open: true, crs: Some("EPSG:32633".into()) };
    vdb::write_level(&path, &level, &prov, WriteOptions::default()).unwrap();
    let (back, prov_back) = vdb::read_level(&path).unwrap();
    assert_eq!(prov_back, prov);
    assert_eq!(back.index, level.index);
    assert_eq!(back.resolution, level.resolution);
    assert!((back.frame.scale - level.frame.scale).abs() < 1e-12);
    assert!((back.frame.centre - level.frame.centre).length() < 1e-9);
    assert_eq!(back.len(), level.len());
    // Files store voxels in OpenVDB's order: compare by coordinate.
    let index: std::collections::HashMap<IVec3, usize> =
        back.coords.iter().enumerate().map(|(i, c)| (*c, i)).collect();
    for i in 0..level.len() {
        let j = index[&level.coords[i]];
        // Offsets come back through world-space P: float precision of P
        // relative to the voxel size.
        assert!((back.offsets[j] - level.offsets[i]).abs().max_element() < 2e-4, "offset {i}");
        assert!((back.normals[j] - level.normals[i]).abs().max_element() < 1e-6, "normal {i}");
        assert!((back.colours[j] - level.colours[i]).abs().max_element() < 1e-6, "colour {i}");
        assert_eq!(back.mask[j], level.mask[i], "mask {i}");
        let d = (back.point_world(j) - level.point_world(i)).length();
        assert!(d < 1e-3 * level.voxel_size() / level.frame.scale, "point {i} moved by {d}");
    }
}

#[test]
fn half_float_level_files_are_smaller_and_close() {
    let dir = tmp();
    let level = sample_level();
    let full = dir.path().join("full.vdb");
    let half = dir.path().join("half.vdb");
    vdb::write_level(&full, &level, &Provenance::default(), WriteOptions::default()).unwrap();
    vdb::write_level(&half, &level, &Provenance::default(), WriteOptions { half_floats: true, ..Default::default() }).unwrap();
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    assert!(size(&half) < size(&full), "half {} vs full {}", size(&half), size(&full));
    let (back, _) = vdb::read_level(&half).unwrap();
    assert_eq!(back.len(), level.len());
    // Half floats round to 11 significant bits: normals and colours (at most
    // 1) within 2^-11; positions P are stored in world units, so an offset (in
    // voxels) is off by up to 2^-11 of the largest world coordinate over the
    // voxel size.
    let index: std::collections::HashMap<IVec3, usize> = back.coords.iter().enumerate().map(|(i, c)| (*c, i)).collect();
    let mut worst = [0f32; 3];
    for (i, c) in level.coords.iter().enumerate() {
        let j = index[c];
        worst[0] = worst[0].max((back.offsets[j] - level.offsets[i]).abs().max_element());
        worst[1] = worst[1].max((back.normals[j] - level.normals[i]).abs().max_element());
        worst[2] = worst[2].max((back.colours[j] - level.colours[i]).abs().max_element());
        assert_eq!(back.mask[j], level.mask[i], "mask of {c}");
    }
    eprintln!("largest half-float errors: offset {:.2e} voxels, normal {:.2e}, colour {:.2e}", worst[0], worst[1], worst[2]);
    let largest = level.coords.iter().enumerate().map(|(i, _)| level.point_world(i).abs().max_element()).fold(0.0, f64::max);
    let voxel = level.voxel_size() / level.frame.scale;
    let offset_bound = (largest * 2f64.powi(-11) / voxel) as f32;
    assert!(worst.iter().all(|&w| w > 0.0), "nothing was rounded: not half floats? {worst:?}");
    assert!(worst[0] <= offset_bound, "offsets off by {} voxels, bound {offset_bound}", worst[0]);
    assert!(worst[1] <= 2f32.powi(-11) && worst[2] <= 2f32.powi(-11), "normals or colours not close: {worst:?}");
}

#[test]
fn vdb_print_reads_our_level_files() {
    if Command::new("vdb_print").arg("-version").output().is_err() {
        skip("vdb_print (libopenvdb-tools) is not installed (scripts/setup.sh installs it)");
        return;
    }
    let dir = tmp();
    let path = dir.path().join("level_1.vdb");
    let level = sample_level();
    vdb::write_level(&path, &level, &Provenance { exemplar: "tower".into(), ..Default::default() }, WriteOptions::default())
        .unwrap();
    let print = |p: &std::path::Path| {
        let out = Command::new("vdb_print").args(["-l", "-m"]).arg(p).output().unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        stdout(&out)
    };
    let names = |text: &str| -> Vec<String> {
        let mut v: Vec<String> = text.lines().filter_map(|l| l.strip_prefix("Name: ")).map(String::from).collect();
        v.sort();
        v
    };
    // The volumes in the level file, the PointDataGrid in the points file beside it.
    let text = print(&path);
    assert_eq!(names(&text), ["Cd", "N", "P", "density", "mask"], "{text}");
    assert!(text.contains("vec3s") && !text.contains("ptdataidx"), "types:\n{text}");
    assert!(text.contains("shapeshifter_resolution: 32"), "metadata:\n{text}");
    for vector_type in ["vector_type: contravariant absolute", "vector_type: covariant normalize", "vector_type: invariant"] {
        assert!(text.contains(vector_type), "no '{vector_type}':\n{text}");
    }
    let active = level.len().to_string();
    assert!(text.contains(&active), "voxel count {active} not reported:\n{text}");
    let points = print(&vdb::points_path(&path));
    assert_eq!(names(&points), ["points"], "{points}");
    assert!(points.contains("ptdataidx") && points.contains("shapeshifter_resolution: 32"), "{points}");
}

#[test]
fn python_openvdb_reads_our_level_files() {
    let probe = Command::new("/usr/bin/python3").args(["-c", "import pyopenvdb"]).output();
    if !matches!(probe, Ok(ref o) if o.status.success()) {
        skip("Debian's python3-openvdb is not installed (scripts/setup.sh installs it)");
        return;
    }
    let dir = tmp();
    let path = dir.path().join("level_1.vdb");
    let level = sample_level();
    vdb::write_level(&path, &level, &Provenance::default(), WriteOptions::default()).unwrap();
    // The grid part (pyopenvdb cannot read PointDataGrids): counts, vector
    // types, and a P value equal to our world point.
    let (i, c) = (5usize, level.coords[5]);
    let p = level.point_world(i);
    let script = format!(
        r#"
import pyopenvdb as vdb, sys
path = sys.argv[1]
grids = {{n: vdb.read(path, n) for n in ['mask', 'density', 'P', 'N', 'Cd']}}
print('names', sorted(g.name for g in grids.values()))
mask, P, N = grids['mask'], grids['P'], grids['N']
print('active', mask.activeVoxelCount(), P.activeVoxelCount())
print('vt', P.vectorType, N.vectorType)
acc = P.getConstAccessor()
v = acc.getValue(({}, {}, {}))
print('p', *v)
"#,
        c.x, c.y, c.z
    );
    let out = Command::new("/usr/bin/python3").arg("-c").arg(&script).arg(&path).output().unwrap();
    let text = stdout(&out);
    assert!(out.status.success(), "python failed: {}\n{}", stderr(&out), text);
    assert!(text.contains(&format!("active {} {}", level.len(), level.len())), "{text}");
    for g in ["'Cd'", "'N'", "'P'", "'density'", "'mask'"] {
        assert!(text.contains(g), "{g} missing: {text}");
    }
    let pline = text.lines().find(|l| l.starts_with("p ")).unwrap();
    let v: Vec<f64> = pline[2..].split_whitespace().map(|s| s.parse().unwrap()).collect();
    assert!((DVec3::new(v[0], v[1], v[2]) - p).length() < 1e-3, "P {v:?} vs {p}");
}

fn coloured_tetra() -> Mesh {
    Mesh {
        name: "tetra".into(),
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z],
        triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        colours: MeshColours::PerVertex(vec![
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.2, 0.4, 0.6),
        ]),
        texture: None,
    }
}

#[test]
fn ply_round_trip_keeps_vertex_colours_binary_and_ascii() {
    let dir = tmp();
    let m = coloured_tetra();
    for binary in [true, false] {
        let path = dir.path().join(format!("t{binary}.ply"));
        mesh::save(&m, &path, binary).unwrap();
        let back = mesh::load(&path).unwrap();
        assert_eq!(back.positions, m.positions);
        assert_eq!(back.triangles.len(), 4);
        assert!(back.is_closed());
        let (MeshColours::PerVertex(a), MeshColours::PerVertex(b)) = (&back.colours, &m.colours) else {
            panic!("colours lost: {:?}", back.colours)
        };
        for (x, y) in a.iter().zip(b) {
            assert!((*x - *y).abs().max_element() <= 0.5 / 255.0 + 1e-6, "{x} vs {y}");
        }
    }
}

#[test]
fn demo_tower_round_trips_through_ply() {
    let dir = tmp();
    let m = shapeshifter::encode::exemplar::small_tower();
    let path = dir.path().join("tower.ply");
    mesh::save(&m, &path, true).unwrap();
    let back = mesh::load(&path).unwrap();
    assert_eq!(back.triangles.len(), m.triangles.len());
    assert_eq!(back.positions.len(), m.positions.len());
}

#[test]
fn obj_with_material_colour_and_texture() {
    let dir = tmp();
    let d = dir.path();
    // A quad with UVs over a 2x2 texture: red, green / blue, white.
    let mut img = image::RgbImage::new(2, 2);
    img.put_pixel(0, 0, image::Rgb([255, 0, 0]));
    img.put_pixel(1, 0, image::Rgb([0, 255, 0]));
    img.put_pixel(0, 1, image::Rgb([0, 0, 255]));
    img.put_pixel(1, 1, image::Rgb([255, 255, 255]));
    img.save(d.join("tex.png")).unwrap();
    std::fs::write(d.join("tex.mtl"), "newmtl stone\nKd 1 1 1\nmap_Kd tex.png\n").unwrap();
    std::fs::write(
        d.join("quad.obj"),
        "mtllib tex.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl stone\nf 1/1 2/2 3/3 4/4\n",
    )
    .unwrap();
    let m = mesh::load(&d.join("quad.obj")).unwrap();
    assert_eq!(m.triangles.len(), 2);
    let t = m.texture.as_ref().expect("texture loaded");
    assert_eq!((t.image.width(), t.image.height()), (2, 2));
    assert_eq!(t.uvs.len(), 6);
    assert!(t.uvs.iter().all(|uv| uv.x >= 0.0 && uv.x <= 1.0));

    // Kd only: a per-corner material colour.
    std::fs::write(d.join("kd.mtl"), "newmtl red\nKd 0.8 0.1 0.2\n").unwrap();
    std::fs::write(d.join("kd.obj"), "mtllib kd.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n").unwrap();
    let m = mesh::load(&d.join("kd.obj")).unwrap();
    let MeshColours::PerCorner(c) = &m.colours else { panic!("Kd colour lost: {:?}", m.colours) };
    assert!((c[0] - Vec3::new(0.8, 0.1, 0.2)).abs().max_element() < 0.01, "{}", c[0]);

    // A texture named but missing: loads, constant colour, no failure.
    std::fs::write(d.join("gone.mtl"), "newmtl x\nmap_Kd nowhere.png\n").unwrap();
    std::fs::write(d.join("gone.obj"), "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl x\nf 1/1 2/2 3/3\n").unwrap();
    let m = mesh::load(&d.join("gone.obj")).unwrap();
    assert!(m.texture.is_none());
}

#[test]
fn off_and_stl_load() {
    let dir = tmp();
    let d = dir.path();
    std::fs::write(d.join("t.off"), "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n").unwrap();
    let m = mesh::load(&d.join("t.off")).unwrap();
    assert_eq!((m.positions.len(), m.triangles.len()), (4, 4));
    assert!(m.is_closed());
    let stl = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n";
    std::fs::write(d.join("t.stl"), stl).unwrap();
    let m = mesh::load(&d.join("t.stl")).unwrap();
    assert_eq!(m.triangles.len(), 1);
}

#[test]
fn info_describes_level_files_and_meshes() {
    let dir = tmp();
    let vdb_path = dir.path().join("level_1.vdb");
    vdb::write_level(&vdb_path, &sample_level(), &Provenance { exemplar: "tower".into(), ..Default::default() }, WriteOptions::default()).unwrap();
    let ply = dir.path().join("t.ply");
    mesh::save(&coloured_tetra(), &ply, true).unwrap();
    let points = vdb::points_path(&vdb_path);
    let o = shapeshifter(&["info", vdb_path.to_str().unwrap(), points.to_str().unwrap(), ply.to_str().unwrap()]);
    let text = stdout(&o);
    assert!(o.status.success(), "{}", stderr(&o));
    for needle in ["mask", "points", "Cd", "resolution", "tower", "triangles", "closed", "vertex colours"] {
        assert!(text.contains(needle), "info lacks '{needle}':\n{text}");
    }
}

// ---- bad inputs: one clean error line each, non-zero exit, no panic ----

#[test]
fn missing_file_and_directory() {
    let dir = tmp();
    let missing = dir.path().join("nope.obj");
    assert_clean_failure(&shapeshifter(&["info", missing.to_str().unwrap()]), "nope.obj", "no such file");
    assert_clean_failure(&shapeshifter(&["info", dir.path().to_str().unwrap()]), dir.path().to_str().unwrap(), "directory");
}

#[test]
fn truncated_and_corrupt_level_files() {
    let dir = tmp();
    let good = dir.path().join("good.vdb");
    vdb::write_level(&good, &sample_level(), &Provenance::default(), WriteOptions::default()).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let truncated = dir.path().join("truncated.vdb");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert_clean_failure(&shapeshifter(&["info", truncated.to_str().unwrap()]), "truncated.vdb", "truncated or damaged");
    assert!(vdb::read_level(&truncated).is_err());
    let corrupt = dir.path().join("corrupt.vdb");
    std::fs::write(&corrupt, b"this is not an OpenVDB file at all, just text\n").unwrap();
    assert_clean_failure(&shapeshifter(&["info", corrupt.to_str().unwrap()]), "corrupt.vdb", "not a VDB file");
    assert!(vdb::read_level(&corrupt).is_err());
}

#[test]
fn truncated_and_corrupt_meshes() {
    let dir = tmp();
    let d = dir.path();
    let good = d.join("good.ply");
    mesh::save(&shapeshifter::encode::exemplar::small_tower(), &good, true).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(d.join("truncated.ply"), &bytes[..bytes.len() / 3]).unwrap();
    assert_clean_failure(&shapeshifter(&["info", d.join("truncated.ply").to_str().unwrap()]), "truncated.ply", "truncated or damaged");
    std::fs::write(d.join("corrupt.obj"), [0xffu8, 0xfe, 0x00, 0x13, 0x37, 0x00, 0xab].repeat(50)).unwrap();
    assert_clean_failure(&shapeshifter(&["info", d.join("corrupt.obj").to_str().unwrap()]), "corrupt.obj", "no vertices");
    std::fs::write(d.join("shape.xyz"), "1 2 3\n").unwrap();
    assert_clean_failure(&shapeshifter(&["info", d.join("shape.xyz").to_str().unwrap()]), "shape.xyz", "unknown file type");
}

#[test]
fn empty_nan_and_degenerate_meshes() {
    let dir = tmp();
    let d = dir.path();
    std::fs::write(d.join("empty.obj"), "# nothing here\n").unwrap();
    assert_clean_failure(&shapeshifter(&["info", d.join("empty.obj").to_str().unwrap()]), "empty.obj", "no vertices");
    std::fs::write(d.join("nofaces.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
    assert_clean_failure(&shapeshifter(&["info", d.join("nofaces.obj").to_str().unwrap()]), "nofaces.obj", "no faces");
    std::fs::write(d.join("nan.off"), "OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n").unwrap();
    assert_clean_failure(&shapeshifter(&["info", d.join("nan.off").to_str().unwrap()]), "nan.off", "nan");
    // Binary STL carries raw floats: one vertex at +infinity.
    let mut stl = vec![0u8; 80];
    stl.extend(1u32.to_le_bytes());
    for v in [0.0f32, 0.0, 1.0, 0.0, 0.0, 0.0, f32::INFINITY, 0.0, 0.0, 0.0, 1.0, 0.0] {
        stl.extend(v.to_le_bytes());
    }
    stl.extend(0u16.to_le_bytes());
    std::fs::write(d.join("inf.stl"), stl).unwrap();
    assert_clean_failure(&shapeshifter(&["info", d.join("inf.stl").to_str().unwrap()]), "inf.stl", "infinite");
    // All triangles degenerate (collinear): an error.
    std::fs::write(d.join("flat.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n").unwrap();
    assert_clean_failure(&shapeshifter(&["info", d.join("flat.off").to_str().unwrap()]), "flat.off", "degenerate");
    // Some degenerate: dropped with a warning, the rest kept.
    std::fs::write(d.join("some.off"), "OFF\n5 2 0\n0 0 0\n1 0 0\n0 1 0\n2 0 0\n3 0 0\n3 0 1 2\n3 0 3 4\n").unwrap();
    let m = mesh::load(&d.join("some.off")).unwrap();
    assert_eq!(m.triangles.len(), 1);
}

#[test]
fn failed_writes_leave_nothing_behind() {
    let dir = tmp();
    // A level with nothing in a folder that does not exist: error, no file.
    let missing_dir = dir.path().join("no/such/folder/level_0.vdb");
    assert!(vdb::write_level(&missing_dir, &sample_level(), &Provenance::default(), WriteOptions::default()).is_err());
    // A mesh format we cannot write: error, nothing left in the folder.
    let bad = dir.path().join("out.xyz");
    assert!(mesh::save(&coloured_tetra(), &bad, true).is_err());
    // A write that fails inside the writer (NaN-free but inconsistent level).
    let mut broken = sample_level();
    broken.mask.pop();
    let path = dir.path().join("broken.vdb");
    let r = std::panic::catch_unwind(|| vdb::write_level(&path, &broken, &Provenance::default(), WriteOptions::default()));
    assert!(matches!(r, Ok(Err(_))), "inconsistent level must be an error, not a panic or success");
    assert!(listing(dir.path()).is_empty(), "left behind: {:?}", listing(dir.path()));
}

// ---- real meshes (../shared/data), skipped where absent ----

#[test]
fn real_meshes_load_with_counts_and_colours() {
    if let Some(p) = shared_data("towerruins/towerruins.obj") {
        let m = mesh::load(&p).unwrap();
        assert_eq!(m.triangles.len(), 23_952);
        assert!(m.texture.is_none(), "the tower's texture is missing: constant colour");
    }
    if let Some(p) = shared_data("cgal/fandisk.off") {
        let m = mesh::load(&p).unwrap();
        assert_eq!(m.triangles.len(), 12_946);
        assert!(m.is_closed());
    }
    if let Some(p) = shared_data("cgal/three_peaks.off") {
        let m = mesh::load(&p).unwrap();
        assert_eq!(m.triangles.len(), 3_671);
        assert_eq!(m.edge_counts().0, 141);
    }
    if let Some(p) = shared_data("pymeshlab/colored_airplane.ply") {
        let m = mesh::load(&p).unwrap();
        assert_eq!(m.triangles.len(), 10_796);
        let MeshColours::PerVertex(c) = &m.colours else { panic!("airplane colours lost") };
        let distinct: std::collections::HashSet<[u32; 3]> =
            c.iter().map(|v| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()]).collect();
        assert!(distinct.len() > 500, "{} distinct colours", distinct.len());
    }
    if let Some(p) = shared_data("pymeshlab/bunny10k_textured.obj") {
        let m = mesh::load(&p).unwrap();
        assert_eq!(m.triangles.len(), 9_999);
        let t = m.texture.as_ref().expect("bunny texture");
        assert_eq!((t.image.width(), t.image.height()), (512, 512));
        assert_eq!(t.uvs.len(), 3 * m.triangles.len());
    }
}
