//! Procedural exemplars for tests and benchmarks (no mesh needed).

use glam::{DVec3, IVec3, Vec3};

use crate::level::{Frame, Level};

/// The levels (resolutions `resolutions`, coarsest first) of a sphere of
/// `radius` (normalised units) around `centre`: every voxel the sphere passes
/// through is active, with the sphere point nearest its centre (clamped into the
/// voxel), the radial normal, a colour that varies with the normal, mask +1. A
/// voxel's children that are active always have an active parent.
pub fn sphere_levels(resolutions: &[u32], centre: DVec3, radius: f64) -> Vec<Level> {
    resolutions
        .iter()
        .enumerate()
        .map(|(index, &res)| {
            let mut level = Level { index, resolution: res, frame: Frame::default(), ..Default::default() };
            let vs = 2.0 / res as f64;
            let to_vox = |x: f64| ((x + 1.0) / vs).floor() as i32;
            let lo = (centre - DVec3::splat(radius + vs)).to_array().map(to_vox);
            let hi = (centre + DVec3::splat(radius + vs)).to_array().map(to_vox);
            for i in lo[0]..=hi[0] {
                for j in lo[1]..=hi[1] {
                    for k in lo[2]..=hi[2] {
                        let c = IVec3::new(i, j, k);
                        let bmin = c.as_dvec3() * vs - DVec3::ONE;
                        let bmax = bmin + DVec3::splat(vs);
                        let near = centre.clamp(bmin, bmax).distance(centre);
                        let far = (centre - bmin).abs().max((centre - bmax).abs()).length();
                        if near > radius || far < radius {
                            continue;
                        }
                        let vc = level.voxel_centre(c);
                        let dir = (vc - centre).try_normalize().unwrap_or(DVec3::Z);
                        let p = centre + dir * radius;
                        let off = ((p - vc) / vs).clamp(DVec3::splat(-0.5), DVec3::splat(0.5));
                        level.coords.push(c);
                        level.offsets.push(off.as_vec3());
                        level.normals.push(dir.as_vec3());
                        level.colours.push(Vec3::new(0.5 + 0.4 * dir.x as f32, 0.3, 0.5 + 0.4 * dir.z as f32));
                        level.mask.push(1.0);
                    }
                }
            }
            level
        })
        .collect()
}

/// The level at resolution `res` of the union of spheres (centre, radius in
/// normalised units): each sphere's voxels ([`sphere_levels`]), a voxel two
/// spheres share kept from the first. A body with ears and rods for the
/// structure tests.
pub fn sphere_union(res: u32, spheres: &[(Vec3, f64)]) -> Level {
    let mut out: Option<Level> = None;
    for &(c, r) in spheres {
        let l = sphere_levels(&[res], c.as_dvec3(), r).remove(0);
        match out.as_mut() {
            None => out = Some(l),
            Some(o) => {
                let have: std::collections::HashSet<IVec3> = o.coords.iter().copied().collect();
                for i in (0..l.len()).filter(|&i| !have.contains(&l.coords[i])) {
                    o.push_row(&l, i, l.coords[i]);
                }
            }
        }
    }
    out.expect("at least one sphere")
}
