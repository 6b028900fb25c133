use super::*;
use crate::level::Frame;
use glam::{DVec3, IVec3};

/// A background no shaded pixel produces by accident.
const BG: [u8; 3] = [3, 200, 7];

fn opts(size: u32) -> RenderOptions {
    RenderOptions { width: size, height: size, background: BG, ..Default::default() }
}

/// One point per voxel that the sphere of `radius` (normalised units)
/// crosses, at the closest surface point to the voxel centre: the
/// sampling a level has.
fn sphere_level(resolution: u32, radius: f64, colour: Vec3) -> Level {
    let mut level = Level { resolution, ..Default::default() };
    let vs = level.voxel_size();
    let n = resolution as i32;
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let c = IVec3::new(i, j, k);
                let lo = level.transform().corner_normalised(c);
                let hi = lo + DVec3::splat(vs);
                let near = DVec3::ZERO.clamp(lo, hi).length();
                let far = lo.abs().max(hi.abs()).length();
                if near <= radius && radius <= far {
                    let centre = level.voxel_centre(c);
                    let p = centre.normalize() * radius;
                    level.coords.push(c);
                    level.offsets.push(((p - centre) / vs).as_vec3());
                    level.normals.push(p.normalize().as_vec3());
                    level.colours.push(colour);
                    level.mask.push(1.0);
                }
            }
        }
    }
    level
}

fn covered(img: &RgbImage) -> Vec<(u32, u32)> {
    img.enumerate_pixels().filter(|(_, _, p)| p.0 != BG).map(|(x, y, _)| (x, y)).collect()
}

fn luma(img: &RgbImage, x: f32, y: f32) -> f32 {
    // Mean over a 5x5 patch.
    let mut sum = 0.0;
    for dy in -2..=2 {
        for dx in -2..=2 {
            let p = img.get_pixel((x as i32 + dx) as u32, (y as i32 + dy) as u32).0;
            sum += p.iter().map(|&v| v as f32).sum::<f32>();
        }
    }
    sum / 75.0
}

#[test]
fn sphere_is_a_centred_disc_without_holes() {
    let level = sphere_level(64, 0.8, Vec3::ONE);
    let img = render_level(&level, &opts(256)).unwrap();
    let px = covered(&img);
    let (mut lo, mut hi) = ((u32::MAX, u32::MAX), (0, 0));
    let (mut sx, mut sy) = (0.0, 0.0);
    for &(x, y) in &px {
        lo = (lo.0.min(x), lo.1.min(y));
        hi = (hi.0.max(x), hi.1.max(y));
        sx += x as f64;
        sy += y as f64;
    }
    let n = px.len() as f64;
    let (cx, cy) = (sx / n, sy / n);
    assert!((cx - 128.0).abs() < 2.0 && (cy - 128.0).abs() < 2.0, "centroid ({cx}, {cy})");
    // The fit leaves a 4% margin each side, so the disc spans ~92% of it.
    let (dw, dh) = ((hi.0 - lo.0 + 1) as f64, (hi.1 - lo.1 + 1) as f64);
    assert!((dw - dh).abs() <= 2.0, "not round: {dw} x {dh}");
    assert!((dw / 256.0 - 0.92).abs() < 0.02, "diameter {dw}");
    let expected = std::f64::consts::PI / 4.0 * dw * dh / (256.0 * 256.0);
    let fraction = n / (256.0 * 256.0);
    assert!((fraction / expected - 1.0).abs() < 0.03, "area {fraction} vs {expected}");
    // No holes: every pixel well inside the silhouette is covered.
    let r = dw / 2.0;
    for y in 0..256u32 {
        for x in 0..256u32 {
            let d = ((x as f64 + 0.5 - cx).powi(2) + (y as f64 + 0.5 - cy).powi(2)).sqrt();
            if d < 0.97 * r {
                assert_ne!(img.get_pixel(x, y).0, BG, "hole at ({x}, {y})");
            }
        }
    }
}

#[test]
fn side_facing_the_key_light_is_brighter() {
    let level = sphere_level(48, 0.8, Vec3::ONE);
    let img = render_level(&level, &opts(200)).unwrap();
    // The key light's direction on screen (y down), from the disc centre.
    let k = KEY_LIGHT_VIEW.normalize();
    let dir = Vec2::new(k.x, -k.y).normalize();
    let r = 0.92 * 200.0 / 2.0 * 0.6;
    let lit = luma(&img, 100.0 + dir.x * r, 100.0 + dir.y * r);
    let dark = luma(&img, 100.0 - dir.x * r, 100.0 - dir.y * r);
    assert!(lit > dark + 60.0, "lit {lit} vs away {dark}");
}

#[test]
fn flipped_normals_still_light() {
    let mut points = crate::level::Level::surface_points(&sphere_level(32, 0.8, Vec3::ONE));
    let a = render_points(&points, &opts(128)).unwrap();
    points.normals.iter_mut().for_each(|n| *n = -*n);
    let b = render_points(&points, &opts(128)).unwrap();
    assert_eq!(a, b);
}

/// A `size` x `size` square of points at depth `z` (towards a camera at
/// azimuth 0, elevation 0), facing it.
fn square(size: f32, z: f32, colour: Vec3, spacing: f32) -> OrientedPoints {
    let n = (size / spacing) as i32;
    let mut points = OrientedPoints { spacing, ..Default::default() };
    for i in 0..=n {
        for j in 0..=n {
            let p = Vec3::new(i as f32 * spacing - size / 2.0, j as f32 * spacing - size / 2.0, z);
            points.positions.push(p);
            points.normals.push(Vec3::Z);
            points.colours.push(colour);
        }
    }
    points
}

#[test]
fn nearer_points_hide_farther_ones_whatever_their_order() {
    let front = RenderOptions { azimuth_deg: 0.0, elevation_deg: 0.0, ..opts(100) };
    let red = square(1.0, 0.5, Vec3::X, 0.02);
    let blue = square(2.0, -0.5, Vec3::Z, 0.02);
    for (first, second) in [(&red, &blue), (&blue, &red)] {
        let mut all = first.clone();
        all.positions.extend(&second.positions);
        all.normals.extend(&second.normals);
        all.colours.extend(&second.colours);
        let img = render_points(&all, &front).unwrap();
        let [r, _, b] = img.get_pixel(50, 50).0;
        assert!(r > 100 && b == 0, "centre ({r}, _, {b})");
        let [r, _, b] = img.get_pixel(8, 50).0;
        assert!(b > 100 && r == 0, "edge ({r}, _, {b})");
    }
}

#[test]
fn red_points_give_red_pixels() {
    let level = sphere_level(32, 0.8, Vec3::new(0.9, 0.1, 0.05));
    let img = render_level(&level, &opts(128)).unwrap();
    let px = covered(&img);
    assert!(px.len() > 128 * 128 / 3);
    for (x, y) in px {
        let [r, g, b] = img.get_pixel(x, y).0;
        assert!(r > 20 && r as u32 > 3 * g as u32 && r as u32 > 3 * b as u32, "({r},{g},{b})");
    }
}

#[test]
fn from_level_keeps_active_voxels_in_world_units() {
    let mut level = sphere_level(16, 0.8, Vec3::ONE);
    level.frame = Frame { centre: DVec3::new(10.0, 0.0, -5.0), scale: 0.5, ..Default::default() };
    level.mask[0] = -1.0;
    let points = crate::level::Level::surface_points(&level);
    assert_eq!(points.len(), level.len() - 1);
    assert!((points.spacing - 2.0 / 16.0 / 0.5).abs() < 1e-6);
    let p = points.positions[0];
    assert!(((p - Vec3::new(10.0, 0.0, -5.0)).length() - 1.6).abs() < 1e-4, "{p}");
}

fn cube(colours: bool) -> Mesh {
    let mut m = crate::testing::shapes::axis_box(Vec3::ZERO, Vec3::ONE);
    if colours {
        m.colours = MeshColours::PerVertex(m.positions.clone());
    }
    m
}

#[test]
fn cube_shows_three_flat_faces() {
    let img = render_mesh(&cube(false), &opts(200)).unwrap();
    let px = covered(&img);
    let fraction = px.len() as f32 / (200.0 * 200.0);
    assert!(fraction > 0.5 && fraction < 0.85, "fraction {fraction}");
    let mut shades: Vec<[u8; 3]> = px.iter().map(|&(x, y)| img.get_pixel(x, y).0).collect();
    shades.sort();
    shades.dedup();
    assert_eq!(shades.len(), 3, "flat shading of three visible faces: {shades:?}");
    // Grey: equal channels.
    assert!(shades.iter().all(|s| s[0] == s[1] && s[1] == s[2]));
    // Vertex colours are interpolated: many distinct values.
    let img = render_mesh(&cube(true), &opts(200)).unwrap();
    let mut shades: Vec<[u8; 3]> = covered(&img).iter().map(|&(x, y)| img.get_pixel(x, y).0).collect();
    shades.sort();
    shades.dedup();
    assert!(shades.len() > 100);
}

#[test]
fn texture_colours_the_mesh() {
    let mut mesh = cube(false);
    let image = RgbImage::from_pixel(4, 4, image::Rgb([20, 40, 230]));
    let uvs = vec![Vec2::new(0.3, 0.7); 3 * mesh.triangles.len()];
    mesh.texture = Some(crate::io::mesh::Texture { uvs, image, ..Default::default() });
    let img = render_mesh(&mesh, &opts(100)).unwrap();
    let px = covered(&img);
    assert!(!px.is_empty());
    assert!(px.iter().all(|&(x, y)| {
        let [r, g, b] = img.get_pixel(x, y).0;
        b > 2 * r.max(g)
    }));
}

#[test]
fn bad_inputs_are_errors() {
    let empty = OrientedPoints::default();
    let err = render_points(&empty, &opts(64)).unwrap_err();
    assert_eq!(err.to_string(), "nothing to render: no active voxels");
    let mut level = sphere_level(8, 0.8, Vec3::ONE);
    level.mask.iter_mut().for_each(|m| *m = -1.0);
    assert!(matches!(render_level(&level, &opts(64)), Err(RenderError::NoPoints)));
    let mut mesh = cube(false);
    mesh.triangles.clear();
    assert!(matches!(render_mesh(&mesh, &opts(64)), Err(RenderError::NoTriangles)));
    let zero = RenderOptions { width: 0, ..opts(64) };
    let points = crate::level::Level::surface_points(&sphere_level(8, 0.8, Vec3::ONE));
    assert!(matches!(render_points(&points, &zero), Err(RenderError::BadSize { .. })));
    let mut mesh = cube(false);
    mesh.triangles[0][0] = 99;
    assert!(matches!(render_mesh(&mesh, &opts(64)), Err(RenderError::Invalid(_))));
}

#[test]
fn save_png_is_atomic_and_round_trips() {
    let dir = std::env::temp_dir().join(format!("render-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let img = render_mesh(&cube(true), &RenderOptions { width: 120, height: 90, ..opts(1) }).unwrap();
    let path = dir.join("cube.png");
    save_png(&img, &path).unwrap();
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["cube.png".to_string()]);
    let back = image::open(&path).unwrap().to_rgb8();
    assert_eq!(back.dimensions(), (120, 90));
    assert_eq!(back, img);
    // The rename fails (a folder is in the way): the temporary file goes.
    let occupied = dir.join("occupied.png");
    std::fs::create_dir_all(occupied.join("inside")).unwrap();
    let err = save_png(&img, &occupied).unwrap_err();
    assert!(err.to_string().contains("occupied.png"), "{err}");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, vec!["cube.png".to_string(), "occupied.png".to_string()]);
    // A folder that does not exist: an error naming the path, no litter.
    let missing = dir.join("no/such/dir/x.png");
    let err = save_png(&img, &missing).unwrap_err();
    assert!(err.to_string().contains("no/such/dir/x.png"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
