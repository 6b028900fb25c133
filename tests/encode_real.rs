//! Encoding real meshes from the workplace's shared test data. Each test is
//! recorded as skipped when the data folder is absent (a user's fresh
//! checkout; `common::skip`).

use std::collections::HashMap;

use shapeshifter::encode::{encode, normalisation_frame, EncodeOptions, Pooling};
use shapeshifter::level::Level;
use shapeshifter::io::mesh::{self, Mesh};
use glam::{DVec3, Vec3};

use crate::common;
use common::shared_data;

fn sharp_corners(mesh: &Mesh) -> Vec<usize> {
    let p = |v: u32| mesh.positions[v as usize].as_dvec3();
    let normal = |t: &[u32; 3]| (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).normalize();
    let mut faces: HashMap<(u32, u32), Vec<DVec3>> = HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            faces.entry((a.min(b), a.max(b))).or_default().push(normal(t));
        }
    }
    let mut sharp = vec![0; mesh.positions.len()];
    for ((a, b), n) in &faces {
        if n.len() == 2 && n[0].dot(n[1]) < 0.5 {
            sharp[*a as usize] += 1;
            sharp[*b as usize] += 1;
        }
    }
    (0..sharp.len()).filter(|&v| sharp[v] >= 3).collect()
}

/// Distance (voxel units) from each corner to the point of the voxel holding it.
fn corner_errors(mesh: &Mesh, level: &Level, corners: &[usize]) -> Vec<f64> {
    let frame = normalisation_frame(mesh);
    let vs = level.voxel_size();
    let index: HashMap<_, _> = level.coords.iter().enumerate().map(|(i, c)| (*c, i)).collect();
    corners
        .iter()
        .map(|&v| {
            let c = frame.to_normalised(mesh.positions[v].as_dvec3());
            let i = index[&((c + DVec3::ONE) / vs).floor().as_ivec3()];
            level.point_normalised(i).distance(c) / vs
        })
        .collect()
}

#[test]
fn fandisk_corners_stay_sharp_with_qem() {
    let Some(path) = shared_data("cgal/fandisk.off") else {
        return;
    };
    let mesh = mesh::load(&path).expect("fandisk loads");
    let corners = sharp_corners(&mesh);
    assert!(corners.len() >= 8, "found only {} sharp corners", corners.len());
    let options = |pooling| EncodeOptions {
        sampling_resolution: 512,
        finest_resolution: 128,
        pooling,
        ..Default::default()
    };
    let (qem, _) = encode(&mesh, &options(Pooling::Qem)).unwrap();
    let (avg, _) = encode(&mesh, &options(Pooling::Average)).unwrap();
    // A corner's voxel keeps it exactly when all the planes there pass through the
    // corner and each of them carries enough weight (>= 5% singular-value ratio); a
    // corner near a voxel face or another feature in the same voxel is not kept, so
    // the test asks for most corners, not all. Averaging keeps none.
    let sharp = |e: &[f64]| e.iter().filter(|&&d| d < 0.01).count() as f64 / e.len() as f64;
    for (q, a) in qem.iter().zip(&avg) {
        let (eq, ea) = (corner_errors(&mesh, q, &corners), corner_errors(&mesh, a, &corners));
        eprintln!(
            "resolution {}: {} corners kept within 0.01 voxel: QEM {:.0}%, average {:.0}%; mean error QEM {:.3}, average {:.3} voxels",
            q.resolution,
            corners.len(),
            100.0 * sharp(&eq),
            100.0 * sharp(&ea),
            eq.iter().sum::<f64>() / eq.len() as f64,
            ea.iter().sum::<f64>() / ea.len() as f64,
        );
        assert_eq!(sharp(&ea), 0.0, "averaging kept a corner at {}", a.resolution);
        assert!(ea.iter().sum::<f64>() > 1.5 * eq.iter().sum::<f64>(), "QEM no better than averaging");
        if q.resolution >= 32 {
            assert!(sharp(&eq) >= 0.6, "QEM kept too few corners at {}", q.resolution);
        }
    }
}

/// Vertex colours reach the encoded points: every finest-level colour is
/// close to the colour of the nearest mesh vertex.
#[test]
fn airplane_vertex_colours_land_on_the_points() {
    let Some(path) = shared_data("pymeshlab/colored_airplane.ply") else {
        return;
    };
    let mesh = mesh::load(&path).expect("airplane loads");
    let shapeshifter::io::mesh::MeshColours::PerVertex(vc) = &mesh.colours else { panic!("airplane has no vertex colours") };
    let options = EncodeOptions { sampling_resolution: 256, finest_resolution: 64, ..Default::default() };
    let (levels, _) = encode(&mesh, &options).unwrap();
    let fine = levels.last().unwrap();
    let mut total = 0.0f64;
    for i in 0..fine.len() {
        let p = fine.point_world(i).as_vec3();
        let nearest = (0..mesh.positions.len())
            .min_by(|&a, &b| (mesh.positions[a] - p).length_squared().total_cmp(&(mesh.positions[b] - p).length_squared()))
            .unwrap();
        total += (fine.colours[i] - vc[nearest]).abs().max_element() as f64;
    }
    let mean = total / fine.len() as f64;
    assert!(mean < 0.1, "mean colour error {mean} against the nearest vertex");
}

/// An open height field encodes as one sheet: its normals agree with the
/// terrain's up direction (a closing surface would add a bottom facing down).
#[test]
fn three_peaks_stays_open() {
    let Some(path) = shared_data("cgal/three_peaks.off") else {
        return;
    };
    let mesh = mesh::load(&path).expect("three_peaks loads");
    let up: Vec3 = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            (b - a).cross(c - a)
        })
        .sum::<Vec3>()
        .normalize();
    let options = EncodeOptions { sampling_resolution: 256, finest_resolution: 64, ..Default::default() };
    let (levels, _) = encode(&mesh, &options).unwrap();
    let fine = levels.last().unwrap();
    let facing_up = fine.normals.iter().filter(|n| n.dot(up) > 0.0).count();
    assert!(facing_up as f64 > 0.97 * fine.len() as f64, "{facing_up} of {} normals face up", fine.len());
}
