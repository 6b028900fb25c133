//! Enclosure: how much of the view from inside a shape its surface fills
//! (`open`: a side gone, a wall standing alone, a hole through a roof).

use std::collections::HashSet;

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use crate::grid::components::NEIGHBOURS_26;

/// Rays cast by [`enclosure`] (a Fibonacci sphere of directions).
const ENCLOSURE_RAYS: usize = 2048;

/// How much of the view from inside the shape its surface fills: the share
/// of [`ENCLOSURE_RAYS`] directions, evenly spread over the sphere, in which a
/// ray from the voxels' centroid meets a surface voxel or passes within one
/// voxel of one (so a shell with gaps between its voxels does not leak). A
/// whole tower surrounds its centre all round but for its top and its door; a
/// ring with one side gone, a wall standing alone or a roof with a hole lets
/// the rays through there. 0 for no voxels.
pub fn enclosure(coords: &[IVec3]) -> f64 {
    if coords.is_empty() {
        return 0.0;
    }
    let set: HashSet<IVec3> = coords.iter().copied().collect();
    let lo = coords.iter().copied().reduce(IVec3::min).expect("not empty") - IVec3::ONE;
    let hi = coords.iter().copied().reduce(IVec3::max).expect("not empty") + IVec3::ONE;
    let centre = coords.iter().fold(Vec3::ZERO, |a, c| a + c.as_vec3()) / coords.len() as f32 + Vec3::splat(0.5);
    let reach = (hi - lo).as_vec3().length() + 2.0;
    let near = |p: Vec3| {
        let c = p.floor().as_ivec3();
        set.contains(&c) || NEIGHBOURS_26.iter().any(|&d| set.contains(&(c + d)))
    };
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let hits = (0..ENCLOSURE_RAYS)
        .into_par_iter()
        .filter(|&k| {
            let z = 1.0 - 2.0 * (k as f32 + 0.5) / ENCLOSURE_RAYS as f32;
            let r = (1.0 - z * z).sqrt();
            let a = golden * k as f32;
            let dir = Vec3::new(r * a.cos(), r * a.sin(), z);
            // Half-voxel steps from one voxel out of the centre (the centroid
            // of a shell lies inside it, where no surface is).
            let mut t = 1.0;
            while t < reach {
                if near(centre + dir * t) {
                    return true;
                }
                t += 0.5;
            }
            false
        })
        .count();
    hits as f64 / ENCLOSURE_RAYS as f64
}
