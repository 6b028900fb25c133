//! Exemplars as artists and scanners bring them: glTF/GLB (Debian's
//! assimp-testmodels: files nobody here wrote, broken ones included), point
//! clouds (PLY points as `points` writes them, LAS/LAZ and E57 written by the
//! `las` and `e57` crates' writers), and real-world scale (`--voxel-size`,
//! georeferenced coordinates kept in the level files).

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use shapeshifter::encode::{encode_exemplar, EncodeOptions};
use shapeshifter::io::cloud::{self, CloudColour};
use shapeshifter::io::exemplar::Exemplar;
use shapeshifter::io::{mesh, vdb};
use shapeshifter::level::Up;

use crate::common;
use common::{assert_clean_failure, shapeshifter, skip, stdout};

/// Debian's assimp-testmodels glTF 2.0 folder (`make test`'s setup installs it).
fn assimp_gltf(rel: &str) -> Option<PathBuf> {
    assimp_model(&format!("glTF2/{rel}"))
}

/// The JSON of a .gltf, or of a .glb's first chunk.
fn json_of(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap();
    if bytes.starts_with(b"glTF") {
        let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        serde_json::from_slice(&bytes[20..20 + len]).unwrap()
    } else {
        serde_json::from_slice(&bytes).unwrap()
    }
}

fn small() -> EncodeOptions {
    EncodeOptions { sampling_resolution: 128, coarsest_resolution: 16, finest_resolution: 64, ..Default::default() }
}

fn area(m: &mesh::Mesh) -> (f32, Vec3) {
    let mut a = 0.0;
    let mut n = Vec3::ZERO;
    for t in &m.triangles {
        let [p, q, r] = t.map(|i| m.positions[i as usize]);
        let c = (q - p).cross(r - p);
        a += 0.5 * c.length();
        n += c;
    }
    (a, n)
}

/// The same textured box as glTF with an external buffer and PNG, as GLB,
/// and as glTF with both embedded as data URIs: one mesh, one texture, and
/// the colour at every face centre is the texture's there.
#[test]
fn the_textured_box_reads_alike_from_gltf_glb_and_embedded_gltf() {
    let Some(dir) = assimp_gltf("") else { return };
    let files = ["BoxTextured-glTF/BoxTextured.gltf", "BoxTextured-glTF-Binary/BoxTextured.glb", "BoxTextured-glTF-Embedded/BoxTextured.gltf"];
    let meshes: Vec<mesh::Mesh> = files.iter().map(|f| mesh::load(&dir.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"))).collect();
    let png = image::open(dir.join("BoxTextured-glTF/CesiumLogoFlat.png")).unwrap().to_rgb8();
    for (f, m) in files.iter().zip(&meshes) {
        assert_eq!(m.triangles.len(), 12, "{f}");
        let t = m.texture.as_ref().unwrap_or_else(|| panic!("{f}: no texture"));
        assert_eq!((t.image.width(), t.image.height()), png.dimensions(), "{f}");
        assert_eq!(t.image.as_raw(), png.as_raw(), "{f}: the decoded texture is the PNG");
        assert_eq!(m.positions, meshes[0].positions, "{f}");
        // At each triangle's centroid: the PNG's pixel at the UV, sampled by
        // hand in glTF's own convention (v down the image) with the sampler
        // the file declares (u runs to 6: the .gltf mirrors it and clamps v,
        // the .glb repeats both).
        let json = json_of(&dir.join(f));
        let mode = |k: &str| json["samplers"][0][k].as_u64().unwrap_or(10497);
        let wrap_of = |m: u64| match m {
            33648 => mesh::Wrap::MirroredRepeat,
            33071 => mesh::Wrap::ClampToEdge,
            _ => mesh::Wrap::Repeat,
        };
        assert_eq!(t.wrap, [wrap_of(mode("wrapS")), wrap_of(mode("wrapT"))], "{f}");
        let by_hand = |x: f32, m: u64| match m {
            33648 => {
                let r = x.rem_euclid(2.0);
                if r > 1.0 { 2.0 - r } else { r }
            }
            33071 => x.clamp(0.0, 1.0),
            _ => x.rem_euclid(1.0),
        };
        for ti in 0..m.triangles.len() {
            let w = Vec3::splat(1.0 / 3.0);
            let uv = (t.uvs[3 * ti] + t.uvs[3 * ti + 1] + t.uvs[3 * ti + 2]) / 3.0;
            // Back to glTF's v before wrapping it.
            let (u, v) = (by_hand(uv.x, mode("wrapS")), by_hand(1.0 - uv.y, mode("wrapT")));
            let (x, y) = ((u * png.width() as f32) as u32, (v * png.height() as f32) as u32);
            let px = png.get_pixel(x.min(png.width() - 1), y.min(png.height() - 1)).0;
            let want = Vec3::new(px[0] as f32, px[1] as f32, px[2] as f32) / 255.0;
            let got = m.colour_at(ti, w).unwrap();
            assert!((got - want).abs().max_element() < 0.08, "{f} triangle {ti}: {got} against the PNG's {want}");
        }
    }
}

/// Triangle lists, strips and fans, indexed or not (glTF Asset Generator's
/// primitive modes): each is the same unit square facing +z; points and
/// lines alone are an error naming the file.
#[test]
fn strips_and_fans_make_the_same_square_and_points_alone_are_refused() {
    let Some(dir) = assimp_gltf("glTF-Asset-Generator/Mesh_PrimitiveMode") else { return };
    let json = |k: usize| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(format!("Mesh_PrimitiveMode_{k:02}.gltf"))).unwrap()).unwrap()
    };
    let mut triangle_modes = 0;
    for k in 0..16 {
        let path = dir.join(format!("Mesh_PrimitiveMode_{k:02}.gltf"));
        let mode = json(k)["meshes"][0]["primitives"][0]["mode"].as_u64().unwrap_or(4);
        if mode >= 4 {
            let m = mesh::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let (a, n) = area(&m);
            assert!((a - 1.0).abs() < 1e-5, "mode {mode} file {k}: area {a}");
            assert!(n.normalize().dot(Vec3::Z) > 0.999, "mode {mode} file {k}: faces {n}");
            triangle_modes += 1;
        } else {
            let o = shapeshifter(&["info", path.to_str().unwrap()]);
            assert_clean_failure(&o, &path.display().to_string(), "has no triangles");
        }
    }
    assert!(triangle_modes >= 6, "only {triangle_modes} files with triangles");
}

/// A binary glTF of 29 meshes under a node hierarchy: every primitive is
/// read (triangle count from the JSON itself) and placed by its nodes'
/// transforms (the mesh spans more than any one untransformed primitive).
#[test]
fn a_multi_node_engine_reads_every_primitive_in_place() {
    let Some(path) = assimp_gltf("2CylinderEngine-glTF-Binary/2CylinderEngine.glb") else { return };
    let json = json_of(&path);
    // Triangles per mesh, counted once per node that instances it.
    let per_mesh: Vec<u64> = json["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["primitives"].as_array().unwrap().iter().map(|p| json["accessors"][p["indices"].as_u64().unwrap() as usize]["count"].as_u64().unwrap() / 3).sum())
        .collect();
    fn count(json: &serde_json::Value, node: usize, per_mesh: &[u64]) -> u64 {
        let n = &json["nodes"][node];
        n["mesh"].as_u64().map_or(0, |m| per_mesh[m as usize])
            + n["children"].as_array().map_or(0, |c| c.iter().map(|k| count(json, k.as_u64().unwrap() as usize, per_mesh)).sum())
    }
    let scene = &json["scenes"][json["scene"].as_u64().unwrap_or(0) as usize];
    let declared: u64 = scene["nodes"].as_array().unwrap().iter().map(|k| count(&json, k.as_u64().unwrap() as usize, &per_mesh)).sum();
    assert!(declared > per_mesh.iter().sum::<u64>(), "some meshes are instanced more than once");
    let m = mesh::load(&path).unwrap();
    // Degenerate triangles (a repeated index, zero area) are dropped.
    assert!(m.triangles.len() as u64 <= declared && m.triangles.len() as u64 > declared * 8 / 10, "{} of {declared}", m.triangles.len());
    let (lo, hi) = m.bounds();
    let one = json["accessors"].as_array().unwrap().iter().filter_map(|a| a["max"].as_array().filter(|v| v.len() == 3)).map(|mx| mx[0].as_f64().unwrap().abs()).fold(0.0, f64::max);
    assert!((hi - lo).max_element() as f64 > 0.5 * one, "placed by the node transforms");
    let (levels, _) = encode_exemplar(&Exemplar::Mesh(m), &small()).unwrap();
    assert!(levels.last().unwrap().len() > 1000);
}

/// Broken files nobody here wrote: one error line each, naming the file and
/// what is wrong, no panic, no signal.
#[test]
fn broken_gltf_files_fail_with_one_line() {
    let Some(dir) = assimp_gltf("") else { return };
    for (file, problem) in [
        ("IndexOutOfRange/IndexOutOfRange.gltf", "past its 24 vertices"),
        ("IndexOutOfRange/AllIndicesOutOfRange.gltf", "past its"),
        ("RecursiveNodes/RecursiveNodes.gltf", "deeper than"),
        ("MissingBin/BoxTextured.gltf", "no such file"),
        ("draco/2CylinderEngine.gltf", "draco"),
        ("BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb", "not a valid gltf"),
        ("wrongTypes/badNumber.gltf", "not a valid gltf"),
        ("TestNoRootNode/NoScene.gltf", "not a valid gltf"),
        ("IncorrectVertexArrays/Cube.gltf", "not a valid gltf"),
    ] {
        let p = dir.join(file);
        let o = shapeshifter(&["info", p.to_str().unwrap()]);
        assert_clean_failure(&o, &p.display().to_string(), problem);
    }
}

/// Our own GLB (vertex colours as linear COLOR_0) reads back with its colours.
#[test]
fn our_glb_reads_back_with_its_colours() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = shapeshifter::testing::shapes::uv_sphere(Vec3::ZERO, 12, 24, |_, _| 1.0);
    let colours: Vec<Vec3> = m.positions.iter().map(|p| (*p * 0.5 + Vec3::splat(0.5)).clamp(Vec3::ZERO, Vec3::ONE)).collect();
    m.colours = mesh::MeshColours::PerVertex(colours.clone());
    let path = dir.path().join("s.glb");
    mesh::save(&m, &path, true).unwrap();
    let back = mesh::load(&path).unwrap();
    assert_eq!(back.triangles.len(), m.triangles.len());
    let mesh::MeshColours::PerCorner(c) = &back.colours else { panic!("colours lost: {:?}", back.colour_source()) };
    for (t, tri) in back.triangles.iter().enumerate() {
        for k in 0..3 {
            let orig = colours[tri[k] as usize];
            assert!((c[3 * t + k] - orig).abs().max_element() < 1.5 / 255.0, "corner {t}/{k}: {} vs {orig}", c[3 * t + k]);
        }
    }
}

fn sphere_points(n: usize, radius: f64, centre: DVec3) -> (Vec<DVec3>, Vec<Vec3>) {
    let p = shapeshifter::testing::shapes::sphere_points(n, radius, centre);
    let c = p.iter().map(|q| Vec3::new(((q.z - centre.z) / (2.0 * radius) + 0.5) as f32, 0.3, 0.7)).collect();
    (p, c)
}

/// LAS, LAZ and E57 written by independent writers read back point for
/// point (millimetres, 8- or 16-bit colours), with intensity, classes and the
/// CRS; each encodes into a closed shell with outward normals estimated.
#[test]
fn las_laz_and_e57_read_back_and_encode() {
    let dir = tempfile::tempdir().unwrap();
    let centre = DVec3::new(512_000.0, 5_400_000.0, 300.0);
    let (p, c) = sphere_points(40_000, 8.0, centre);
    let intensity: Vec<u16> = (0..p.len()).map(|i| (i % 4000) as u16 * 10).collect();
    let classes: Vec<u8> = (0..p.len()).map(|i| if i % 3 == 0 { 6 } else { 2 }).collect();
    let wkt = r#"PROJCS["WGS 84 / UTM zone 32N",GEOGCS["WGS 84"],AUTHORITY["EPSG","32632"]]"#;
    let las = dir.path().join("s.las");
    let laz = dir.path().join("s.laz");
    let e57 = dir.path().join("s.e57");
    shapeshifter::testing::clouds::write_las(&las, &p, Some(&c), &intensity, &classes, Some(wkt)).unwrap();
    shapeshifter::testing::clouds::write_las(&laz, &p, None, &intensity, &classes, None).unwrap();
    let unit: Vec<f32> = intensity.iter().map(|&i| i as f32 / 40000.0).collect();
    shapeshifter::testing::clouds::write_e57(&e57, &p, Some(&c), &unit).unwrap();
    assert!(std::fs::metadata(&laz).unwrap().len() < std::fs::metadata(&las).unwrap().len() / 2, "LAZ is compressed");

    for (path, rgb) in [(&las, true), (&laz, false), (&e57, true)] {
        let cloud = cloud::load(path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(cloud.len(), p.len(), "{}", path.display());
        assert_eq!(cloud.up, Up::Z);
        for (a, b) in cloud.positions.iter().zip(&p) {
            assert!((*a - *b).abs().max_element() < 0.0006, "{}: {a} vs {b}", path.display());
        }
        assert_eq!(cloud.attributes.colours.is_some(), rgb, "{}", path.display());
        if let Some(cc) = &cloud.attributes.colours {
            for (a, b) in cc.iter().zip(&c) {
                assert!((*a - *b).abs().max_element() < 1.0 / 255.0 + 1e-4, "{}: colour {a} vs {b}", path.display());
            }
        }
        if path != &e57 {
            assert_eq!(cloud.attributes.classification.as_deref(), Some(&classes[..]));
            assert_eq!(cloud.attributes.intensity.as_ref().unwrap()[123], intensity[123] as f32);
        }
        let (levels, _) = encode_exemplar(&Exemplar::Cloud(cloud.clone()), &small()).unwrap();
        let finest = levels.last().unwrap();
        let outward = (0..finest.len())
            .filter(|&i| finest.normals[i].as_dvec3().dot((finest.frame.to_world(finest.point_normalised(i)) - centre).normalize()) > 0.8)
            .count();
        assert!(outward as f64 > 0.98 * finest.len() as f64, "{}: {outward} of {} normals outward", path.display(), finest.len());
        assert_eq!(finest.frame.up, Up::Z);
    }
    let las_cloud = cloud::load(&las).unwrap();
    assert_eq!(las_cloud.crs.as_deref(), Some("WGS 84 / UTM zone 32N (EPSG:32632)"));
    let classified = las_cloud.colours(CloudColour::Classification).unwrap().unwrap();
    assert_eq!(classified[0], cloud::class_colour(6));
    assert!(cloud::load(&laz).unwrap().colours(CloudColour::Rgb).unwrap_err().contains("no RGB"));

    // `info` describes a cloud.
    let o = shapeshifter(&["info", las.to_str().unwrap()]);
    let text = stdout(&o);
    assert!(o.status.success() && text.contains("40000 points") && text.contains("EPSG:32632") && text.contains("rgb, intensity, classification"), "{text}");
}

/// `points` output read back as an exemplar: the voxels of the level it came
/// from (its normals and colours used as they are). Not all of them: a point
/// clamped onto its voxel's face (the mesh encoder's QEM points) bins into
/// the neighbour, which has its own point; none lands anywhere else.
#[test]
fn our_points_ply_encodes_to_the_level_it_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let m = shapeshifter::testing::shapes::uv_sphere(Vec3::ZERO, 40, 80, |_, _| 1.0);
    let (levels, _) = shapeshifter::encode::encode(&m, &small()).unwrap();
    let level = levels.last().unwrap();
    let pts = shapeshifter::level::Level::surface_points(level);
    let ply = dir.path().join("p.ply");
    mesh::save_points_ply(&ply, &pts.positions, &pts.normals, &pts.colours).unwrap();
    let Exemplar::Cloud(cloud) = Exemplar::load(&ply).unwrap() else { panic!("a PLY of points is a cloud") };
    assert!(cloud.attributes.normals.is_some() && cloud.attributes.colours.is_some());
    assert_eq!(cloud.up, Up::Y);
    let (again, _) = encode_exemplar(&Exemplar::Cloud(cloud), &small()).unwrap();
    let back = again.last().unwrap();
    let a: std::collections::HashSet<_> = level.coords.iter().collect();
    let b: std::collections::HashSet<_> = back.coords.iter().collect();
    let common = a.intersection(&b).count();
    assert_eq!(common, b.len(), "every re-encoded voxel is one of the level's");
    assert!(common as f64 > 0.85 * a.len() as f64, "{common} of {} voxels", a.len());
}

/// A LiDAR-like tile in UTM metres at 0.2 m voxels: the level file lands
/// where the scan was (its transform in metres) and keeps positions to a
/// small fraction of a voxel (P in double there), and `--voxel-size` too
/// fine for the tile is refused with the size that fits.
#[test]
fn a_georeferenced_tile_at_metric_voxels_lands_where_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let origin = DVec3::new(500_000.0, 4_100_000.0, 120.0);
    let mut p = Vec::new();
    for i in 0..250 {
        for j in 0..250 {
            let (x, y) = (i as f64 * 0.2 + 0.05, j as f64 * 0.2 + 0.05);
            p.push(origin + DVec3::new(x, y, 2.0 * (x / 7.0).sin() + (y / 5.0).cos()));
        }
    }
    let n = p.len();
    let laz = dir.path().join("tile.laz");
    let wkt = r#"PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84"],AUTHORITY["EPSG","32633"]]"#;
    shapeshifter::testing::clouds::write_las(&laz, &p, None, &vec![100; n], &vec![2; n], Some(wkt)).unwrap();
    let out = dir.path().join("enc");
    let o = shapeshifter(&["encode", laz.to_str().unwrap(), "-o", out.to_str().unwrap(), "--voxel-size", "0.2", "--finest", "256", "--sampling-resolution", "512"]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    let (level, _) = vdb::read_level(&out.join("level_4.vdb")).unwrap();
    assert!((level.voxel_size() / level.frame.scale - 0.2).abs() < 1e-9);
    // Every finest point within 2 cm (a tenth of a voxel) of the terrain.
    for i in 0..level.len() {
        let q = level.frame.to_world(level.point_normalised(i)) - origin;
        let z = 2.0 * (q.x / 7.0).sin() + (q.y / 5.0).cos();
        assert!((q.z - z).abs() < 0.02, "point {i} at {q}: terrain at {z}");
    }
    let info = stdout(&shapeshifter(&["info", out.join("level_4.vdb").to_str().unwrap()]));
    assert!(info.contains("vec3d") && info.contains("voxel size 0.200000"), "{info}");
    assert!(info.contains("shapeshifter_crs = WGS 84 / UTM zone 33N (EPSG:32633)") && info.contains("shapeshifter_up = z"), "{info}");
    let o = shapeshifter(&["encode", laz.to_str().unwrap(), "-o", dir.path().join("x").to_str().unwrap(), "--voxel-size", "0.1", "--finest", "256", "--sampling-resolution", "512"]);
    assert_clean_failure(&o, "tile", "use --voxel-size 0.19");
    assert!(!dir.path().join("x").join("manifest.json").exists());
}

fn assimp_model(rel: &str) -> Option<PathBuf> {
    let p = Path::new("/usr/share/assimp/models").join(rel);
    if !p.exists() {
        skip(&format!("{} is absent (Debian package assimp-testmodels; scripts/setup.sh installs it)", p.display()));
        return None;
    }
    Some(p)
}

/// FBX and COLLADA through the Assimp converter: a closed box, cubes with
/// their material colours, the COLLADA duck with its TGA texture; each
/// encodes. Damaged files and a missing converter are one error line.
#[test]
fn fbx_and_collada_read_through_assimp() {
    let (Some(fbx), Some(cubes), Some(duck)) = (assimp_model("FBX/box.fbx"), assimp_model("FBX/cubes_with_names.fbx"), assimp_model("Collada/duck.dae")) else { return };
    let b = mesh::load(&fbx).unwrap();
    assert_eq!((b.positions.len(), b.triangles.len()), (8, 12));
    assert!(b.is_closed(), "welded: a closed box");
    let c = mesh::load(&cubes).unwrap();
    let colours: std::collections::HashSet<[u8; 3]> = match &c.colours {
        mesh::MeshColours::PerCorner(v) => v.iter().map(|c| (*c * 255.0).round().as_uvec3().to_array().map(|x| x as u8)).collect(),
        other => panic!("no material colours: {other:?}"),
    };
    assert!(colours.len() >= 2, "the cubes' materials differ: {colours:?}");
    let d = mesh::load(&duck).unwrap();
    let t = d.texture.as_ref().expect("the duck's TGA texture");
    assert_eq!((t.image.width(), t.image.height()), (512, 512));
    // Mostly yellow where the texture is sampled at the triangles' centres.
    let yellow = (0..d.triangles.len()).filter(|&i| {
        let c = d.colour_at(i, Vec3::splat(1.0 / 3.0)).unwrap();
        c.x > 0.6 && c.y > 0.5 && c.z < 0.3
    });
    assert!(yellow.count() * 2 > d.triangles.len());
    let (levels, _) = encode_exemplar(&Exemplar::Mesh(d), &small()).unwrap();
    assert!(levels.last().unwrap().len() > 500);

    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(&fbx).unwrap();
    let cut = dir.path().join("cut.fbx");
    std::fs::write(&cut, &bytes[..bytes.len() / 3]).unwrap();
    assert_clean_failure(&shapeshifter(&["info", cut.to_str().unwrap()]), "cut.fbx", "assimp");
    let bad = dir.path().join("bad.dae");
    std::fs::write(&bad, "<?xml version=\"1.0\"?><COLLADA><library_geometries><geometry><mesh><source id=\"p\"><float_array count=\"999999999\">1 2").unwrap();
    assert_clean_failure(&shapeshifter(&["info", bad.to_str().unwrap()]), "bad.dae", "assimp");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_shapeshifter"))
        .args(["info", fbx.to_str().unwrap()])
        .env(shapeshifter::io::assimp::ASSIMP_ENV, "/nonexistent/shapeshifter-assimp")
        .output()
        .unwrap();
    assert_clean_failure(&o, "box.fbx", "cannot start the assimp converter");
}
