//! Light meshes and glTF output: quadric decimation (budget, colours, shape,
//! sharp features), .glb files read back through the `gltf` crate, and the
//! `mesh` command's --faces and output formats.

use crate::common;
use crate::hostile_harness as hostile;

use common::*;
use glam::Vec3;
use shapeshifter::config::MeshConfig;
use shapeshifter::io::mesh::{self, DecimateOptions, Mesh, MeshColours};
use shapeshifter::{eval::metrics, testing::shapes};

const RED: Vec3 = Vec3::new(1.0, 0.0, 0.0);
const BLUE: Vec3 = Vec3::new(0.1, 0.2, 0.9);
const GREY: Vec3 = Vec3::new(0.5, 0.5, 0.5);

/// A unit sphere of 20,224 triangles, red above z = 0 and blue below.
fn two_tone_sphere() -> Mesh {
    let mut m = shapes::uv_sphere(Vec3::ZERO, 80, 128, |_, _| 1.0);
    m.colours = MeshColours::PerVertex(m.positions.iter().map(|p| if p.z > 0.0 { RED } else { BLUE }).collect());
    m
}

/// The cube [-1,1]^3 with each side an n x n grid of squares (shared
/// vertices: closed), its top side (z = 1) red, the rest grey.
fn grid_cube(n: u32) -> Mesh {
    let mut index = std::collections::HashMap::new();
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    let mut vertex = |p: Vec3| {
        let key = (p * n as f32).round().as_ivec3().to_array();
        *index.entry(key).or_insert_with(|| {
            positions.push(p);
            positions.len() as u32 - 1
        })
    };
    for axis in 0..3 {
        for side in [-1.0f32, 1.0] {
            // (u, v, normal) right-handed, so that triangles face outwards.
            let nrm = Vec3::from_array(std::array::from_fn(|k| if k == axis { side } else { 0.0 }));
            let u = Vec3::from_array(std::array::from_fn(|k| if k == (axis + 1) % 3 { 1.0 } else { 0.0 }));
            let v = nrm.cross(u);
            let at = |i: u32, j: u32| nrm + u * (2.0 * i as f32 / n as f32 - 1.0) + v * (2.0 * j as f32 / n as f32 - 1.0);
            for i in 0..n {
                for j in 0..n {
                    let q = [vertex(at(i, j)), vertex(at(i + 1, j)), vertex(at(i + 1, j + 1)), vertex(at(i, j + 1))];
                    triangles.push([q[0], q[1], q[2]]);
                    triangles.push([q[0], q[2], q[3]]);
                }
            }
        }
    }
    let colours = positions.iter().map(|p: &Vec3| if p.z > 0.999 { RED } else { GREY }).collect();
    Mesh { name: "cube".into(), positions, triangles, colours: MeshColours::PerVertex(colours), texture: None }
}

fn colours(m: &Mesh) -> &[Vec3] {
    match &m.colours {
        MeshColours::PerVertex(c) => c,
        other => panic!("expected vertex colours, got {other:?}"),
    }
}

#[test]
fn decimation_meets_the_budget_keeps_colours_and_stays_on_the_surface() {
    let sphere = two_tone_sphere();
    assert_eq!(sphere.triangles.len(), 20224);
    let (light, report) = mesh::decimate(&sphere, &DecimateOptions::new(1000)).unwrap();
    // Each collapse on a closed mesh removes two triangles.
    assert!((998..=1000).contains(&light.triangles.len()), "{} triangles", light.triangles.len());
    assert_eq!(report.faces_after, light.triangles.len());
    assert_eq!(report.faces_before, 20224);
    assert!(light.is_closed(), "decimation opened the sphere");
    let (_, non_manifold) = light.edge_counts();
    assert_eq!(non_manifold, 0);
    // Survivors are input vertices: on the unit sphere, with their own colour.
    let c = colours(&light);
    assert_eq!(c.len(), light.positions.len());
    for (p, c) in light.positions.iter().zip(c) {
        assert!((p.length() - 1.0).abs() < 1e-5, "vertex {p} left the sphere");
        assert_eq!(*c, if p.z > 0.0 { RED } else { BLUE }, "vertex {p} changed colour");
    }
    // Still a sphere: every point of either surface near the other.
    let h = metrics::hausdorff(&sphere.surface_samples(50_000), &light.surface_samples(50_000));
    assert!(h < 0.03, "Hausdorff {h} of the unit sphere at 1000 triangles");
    // Orientation kept: outward normals (positive volume).
    assert!(shapes::signed_volume(&light.positions, &light.triangles) > 4.0);
}

#[test]
fn decimation_keeps_sharp_edges_corners_and_a_red_face() {
    let cube = grid_cube(24);
    assert_eq!(cube.triangles.len(), 6 * 24 * 24 * 2);
    // The quadric error alone (the default) and explicit feature lines.
    for angle in [180.0, 60.0] {
        let options = DecimateOptions { feature_angle_deg: angle, ..DecimateOptions::new(40) };
        let (light, report) = mesh::decimate(&cube, &options).unwrap();
        assert!((36..=40).contains(&light.triangles.len()), "{} triangles", light.triangles.len());
        // At 60 degrees the cube's 12 edges, 24 grid edges each, are feature lines.
        assert_eq!(report.feature_edges, if angle < 90.0 { 12 * 24 } else { 0 });
        for corner in 0..8 {
            let p = Vec3::new([-1.0, 1.0][corner & 1], [-1.0, 1.0][(corner >> 1) & 1], [-1.0, 1.0][corner >> 2]);
            assert!(light.positions.contains(&p), "corner {p} was collapsed ({angle})");
        }
        // No triangle cuts across an edge of the cube: each lies in one side.
        for t in &light.triangles {
            let [a, b, c] = t.map(|i| light.positions[i as usize]);
            let side = (0..3).any(|k| a[k].abs() == 1.0 && a[k] == b[k] && b[k] == c[k]);
            assert!(side, "triangle {a} {b} {c} leaves the cube's sides ({angle})");
        }
        // Every triangle of the top side is still red at all three corners.
        let c = colours(&light);
        let top: Vec<&[u32; 3]> =
            light.triangles.iter().filter(|t| t.iter().all(|&i| light.positions[i as usize].z > 0.999)).collect();
        assert!(!top.is_empty());
        for t in top {
            assert!(t.iter().all(|&i| c[i as usize] == RED), "a top triangle is not red ({angle})");
        }
    }
}

#[test]
fn decimation_budgets_outside_the_mesh_are_no_op_or_refused() {
    let sphere = two_tone_sphere();
    let (same, report) = mesh::decimate(&sphere, &DecimateOptions::new(20224)).unwrap();
    assert_eq!((same.triangles.len(), report.faces_after), (20224, 20224));
    assert_eq!(same.positions, sphere.positions);
    assert!(mesh::decimate(&sphere, &DecimateOptions::new(1 << 30)).is_ok());
    let err = mesh::decimate(&sphere, &DecimateOptions::new(0)).unwrap_err().to_string();
    assert!(err.contains("at least 1"), "{err}");
}

#[test]
fn glb_reads_back_through_the_gltf_crate() {
    let (sphere, _) = mesh::decimate(&two_tone_sphere(), &DecimateOptions::new(2000)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sphere.glb");
    mesh::save(&sphere, &path, true).unwrap();
    // from_slice validates the document against the glTF 2.0 schema rules.
    let bytes = std::fs::read(&path).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = gltf.blob.as_deref().expect("a BIN chunk");
    assert_eq!(gltf.meshes().count(), 1);
    let prim = gltf.meshes().next().unwrap().primitives().next().unwrap();
    assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);
    let pbr = prim.material().pbr_metallic_roughness();
    assert_eq!(pbr.metallic_factor(), 0.0);
    let bounds = prim.bounding_box();
    let (lo, hi) = sphere.bounds();
    assert_eq!((Vec3::from(bounds.min), Vec3::from(bounds.max)), (lo, hi));
    let reader = prim.reader(|b| (b.index() == 0).then_some(blob));
    let positions: Vec<Vec3> = reader.read_positions().unwrap().map(Vec3::from).collect();
    assert_eq!(positions, sphere.positions);
    let normals: Vec<Vec3> = reader.read_normals().unwrap().map(Vec3::from).collect();
    for (p, n) in positions.iter().zip(&normals) {
        assert!((n.length() - 1.0).abs() < 1e-4 && n.dot(*p) > 0.9, "normal {n} at {p}");
    }
    // COLOR_0 is linear: red stays (1, 0, 0), the blue is sRGB-decoded.
    let read: Vec<Vec3> = reader.read_colors(0).unwrap().into_rgb_f32().map(Vec3::from).collect();
    for (got, want) in read.iter().zip(colours(&sphere)) {
        let linear = Vec3::from_array(want.to_array().map(shapeshifter::geom::colour::srgb_to_linear));
        assert!((*got - linear).abs().max_element() < 1e-6, "{got} vs {linear}");
    }
    assert!((shapeshifter::geom::colour::srgb_to_linear(0.5) - 0.2140).abs() < 1e-3);
    let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
    assert_eq!(indices, sphere.triangles.iter().flatten().copied().collect::<Vec<_>>());
    // A mesh without colours has no COLOR_0.
    let plain = shapes::axis_box(Vec3::ZERO, Vec3::ONE);
    let p = dir.path().join("box.glb");
    mesh::save(&plain, &p, true).unwrap();
    let gltf = gltf::Gltf::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    let prim = gltf.meshes().next().unwrap().primitives().next().unwrap();
    assert!(prim.get(&gltf::Semantic::Colors(0)).is_none());
    assert!(prim.get(&gltf::Semantic::Normals).is_some());
}

#[test]
fn mesh_command_writes_light_glb_and_ply_and_refuses_bad_requests_cleanly() {
    use shapeshifter::io::vdb::{write_level, Provenance, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let level = dir.path().join("sphere.vdb");
    write_level(&level, &hostile::sphere_level(2000), &Provenance::default(), WriteOptions::default()).unwrap();
    let lv = level.to_str().unwrap();
    let before = listing(dir.path());
    for (out, extra, problem) in [
        ("x.obj", "0", "not '.obj'"),
        ("x", "0", "not '.'"),
        ("x.glb", "many", "--faces"),
    ] {
        let o = dir.path().join(out);
        let r = shapeshifter(&["mesh", lv, "-o", o.to_str().unwrap(), "--resolution", "64", "--faces", extra]);
        // Refused before any work: bad usage, exit 2.
        assert_usage_failure(&r, if problem == "--faces" { "--faces" } else { out }, problem);
    }
    assert_eq!(listing(dir.path()), before, "a refused mesh command left files behind");

    let full = dir.path().join("full.ply");
    let r = shapeshifter(&["mesh", lv, "-o", full.to_str().unwrap(), "--resolution", "64", "--method", "apss"]);
    assert!(r.status.success(), "{}", stderr(&r));
    let full_faces = mesh::load(&full).unwrap().triangles.len();
    assert!(full_faces > 1000, "{full_faces}");
    for out in ["light.ply", "light.glb"] {
        let o = dir.path().join(out);
        let r = shapeshifter(&[
            "mesh", lv, "-o", o.to_str().unwrap(), "--resolution", "64", "--method", "apss", "--faces", "500",
        ]);
        assert!(r.status.success(), "{}", stderr(&r));
        let faces = if out.ends_with("ply") {
            mesh::load(&o).unwrap().triangles.len()
        } else {
            let g = gltf::Gltf::from_slice(&std::fs::read(&o).unwrap()).unwrap();
            let prim = g.meshes().next().unwrap().primitives().next().unwrap();
            assert!(prim.get(&gltf::Semantic::Colors(0)).is_some(), "no vertex colours in {out}");
            prim.indices().unwrap().count() / 3
        };
        assert!(faces <= 500 && faces >= 450, "{out}: {faces} triangles for a budget of 500");
    }
}

#[test]
fn mesh_stage_writes_light_ply_and_glb_as_configured() {
    use shapeshifter::io::vdb::{write_level, Provenance, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let variant = dir.path().join("variant_000");
    std::fs::create_dir(&variant).unwrap();
    let level = hostile::sphere_level(2000);
    write_level(&variant.join("level_1.vdb"), &level, &Provenance::default(), WriteOptions::default()).unwrap();
    let dirs = [variant.clone()];
    let both = MeshConfig { faces: 600, glb: true, texture: 0 };
    assert_eq!(shapeshifter::pipeline::mesh_stage(&dirs, false, 64, &both).unwrap(), 1);
    let ply = mesh::load(&variant.join("mesh.ply")).unwrap();
    assert!(ply.triangles.len() <= 600 && ply.triangles.len() >= 550, "{}", ply.triangles.len());
    let glb = std::fs::read(variant.join("mesh.glb")).unwrap();
    assert!(gltf::Gltf::from_slice(&glb).is_ok());
    // Settings changed: meshed again, and no mesh.glb left from before.
    let ply_only = MeshConfig { faces: 0, glb: false, texture: 0 };
    assert_eq!(shapeshifter::pipeline::mesh_stage(&dirs, false, 64, &ply_only).unwrap(), 1);
    assert!(!variant.join("mesh.glb").exists());
    assert!(mesh::load(&variant.join("mesh.ply")).unwrap().triangles.len() > 600);
}

#[test]
fn a_light_mesh_is_baked_into_a_texture_and_its_usd_layer_counts_as_its_files() {
    use shapeshifter::io::usd::UsdFormat;
    use shapeshifter::io::vdb::{write_level, Provenance, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let variant = dir.path().join("variants/variant_000");
    std::fs::create_dir_all(&variant).unwrap();
    let mut level = hostile::sphere_level(2000);
    // Two colours by hemisphere, so the texture has something to carry.
    for i in 0..level.len() {
        level.colours[i] = if level.coords[i].x >= level.resolution as i32 / 2 { glam::Vec3::X } else { glam::Vec3::Z };
    }
    write_level(&variant.join("level_1.vdb"), &level, &Provenance::default(), WriteOptions::default()).unwrap();
    let dirs = [variant.clone()];
    let baked = MeshConfig { faces: 600, glb: false, texture: 256 };
    assert_eq!(shapeshifter::pipeline::mesh_stage(&dirs, false, 64, &baked).unwrap(), 1);
    for f in ["mesh.ply", "mesh.obj", "mesh.mtl", "mesh_basecolor.png", "mesh.glb"] {
        assert!(variant.join(f).is_file(), "{f} missing");
    }
    let obj = mesh::load(&variant.join("mesh.obj")).unwrap();
    let ply = mesh::load(&variant.join("mesh.ply")).unwrap();
    assert_eq!(obj.triangles.len(), ply.triangles.len(), "one mesh, two files");
    let tex = obj.texture.as_ref().expect("the OBJ names its texture");
    assert_eq!(tex.uvs.len(), 3 * obj.triangles.len());
    // The texture holds both hemispheres' colours (red and blue texels).
    let (mut red, mut blue) = (0, 0);
    for p in tex.image.pixels() {
        red += usize::from(p[0] > 200 && p[2] < 60);
        blue += usize::from(p[2] > 200 && p[0] < 60);
    }
    assert!(red > 100 && blue > 100, "red {red}, blue {blue} texels");
    // The GLB: baseColorTexture through TEXCOORD_0, no COLOR_0 to darken it.
    let doc = gltf::Gltf::from_slice(&std::fs::read(variant.join("mesh.glb")).unwrap()).unwrap();
    let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
    assert!(prim.get(&gltf::Semantic::TexCoords(0)).is_some());
    assert!(prim.get(&gltf::Semantic::Colors(0)).is_none());
    let info = prim.material().pbr_metallic_roughness().base_color_texture().expect("baseColorTexture");
    assert!(matches!(info.texture().source().source(), gltf::image::Source::View { mime_type: "image/png", .. }));
    // And our own reader reads it back textured, as it reads other glTF files.
    let back = mesh::load(&variant.join("mesh.glb")).unwrap();
    assert_eq!(back.triangles.len(), obj.triangles.len());
    assert_eq!(back.texture.as_ref().map(|t| (t.image.width(), t.image.height())), Some((tex.image.width(), tex.image.height())));

    // The USD step: a variant layer whose counts are the OBJ's, and the asset.
    std::fs::write(variant.join("stage_sample.json"), r#"{"digest":"d","seconds":0.0}"#).unwrap();
    let outcome = shapeshifter::pipeline::usd::usd_stage(dir.path(), &dirs, "sphere", 1.0, UsdFormat::Usda).unwrap();
    assert_eq!(outcome.variants.len(), 1);
    let v = &outcome.variants[0];
    assert!(v.textured);
    assert_eq!(v.triangles, obj.triangles.len());
    assert_eq!(v.points, shapeshifter::level::Level::surface_points(&level).len());
    let layer = std::fs::read_to_string(variant.join("variant.usda")).unwrap();
    let counts = layer.split("int[] faceVertexCounts = [").nth(1).unwrap().split(']').next().unwrap();
    assert_eq!(counts.split(',').count(), obj.triangles.len());
    assert!(layer.contains("asset inputs:file = @./mesh_basecolor.png@"));
    assert!(layer.contains("asset filePath = @./level_1.vdb@"));
    let asset = std::fs::read_to_string(dir.path().join("variants.usda")).unwrap();
    assert!(asset.contains("prepend references = @./variants/variant_000/variant.usda@"));
    assert!(asset.contains("defaultPrim = \"sphere\""));
    // Pixar's usd-core opens it and its validators find nothing.
    let usd_python = usd_core_python();
    if let Some(py) = &usd_python {
        usd_core_check(py, dir.path(), "usda");
    }

    // Binary layers instead: written (not reused from the text's stamp), the
    // text ones removed, so the folder holds one asset (what they hold, and
    // that usd-core reads it as the text: `make interop`).
    let binary = shapeshifter::pipeline::usd::usd_stage(dir.path(), &dirs, "sphere", 1.0, UsdFormat::Usdc).unwrap();
    assert_eq!(binary.variants[0].triangles, obj.triangles.len(), "written, not reused");
    assert_eq!(binary.asset, dir.path().join("variants.usdc"));
    for f in [variant.join("variant.usdc"), dir.path().join("variants.usdc")] {
        assert_eq!(&std::fs::read(&f).unwrap()[..8], b"PXR-USDC", "{}", f.display());
    }
    assert!(!variant.join("variant.usda").exists() && !dir.path().join("variants.usda").exists());
    if let Some(py) = &usd_python {
        usd_core_check(py, dir.path(), "usdc");
    }

    // Texture off: meshed again, no baked file left from before.
    let plain = MeshConfig { faces: 600, glb: false, texture: 0 };
    assert_eq!(shapeshifter::pipeline::mesh_stage(&dirs, false, 64, &plain).unwrap(), 1);
    for f in ["mesh.obj", "mesh.mtl", "mesh_basecolor.png", "mesh.glb"] {
        assert!(!variant.join(f).exists(), "{f} left from the baked mesh");
    }
}
