//! Encoding a point-cloud exemplar: the points go straight into the sampling
//! grid (no triangles to intersect), then pool through the levels exactly as a
//! mesh's samples do (QEM or mean points, [`super::pool_all`]).
//!
//! Per sampling voxel (normalised units, vs = 2 / R_s): the mean of its
//! points' positions as the surface point, their normals' mean (unit) and
//! their colours' mean. Normals the file lacks are estimated first
//! ([`crate::geom::normals`]); the cloud's spacing is checked against the
//! finest voxel, which a sparser cloud leaves with holes.

use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::{exemplar_frame, group_starts, morton, EncodeError, EncodeOptions, EncodeStats, Sample};
use crate::io::cloud::PointCloud;
use crate::level::{Level, Up};

/// Encodes `cloud` into levels `coarsest_resolution ..= finest_resolution`,
/// coarsest first, as [`super::encode`] does for a mesh. `format_up` is the
/// file format's vertical axis (z for LAS/LAZ/E57) where options leave it open.
pub fn encode_cloud(cloud: &PointCloud, options: &EncodeOptions, format_up: Up) -> Result<(Vec<Level>, EncodeStats), EncodeError> {
    options.validate()?;
    let start = Instant::now();
    let fail = |reason: String| EncodeError::Cloud { name: cloud.name.clone(), reason };
    if cloud.is_empty() {
        return Err(fail("has no points".into()));
    }
    let mut stats = EncodeStats::default();

    let t = Instant::now();
    let (lo, hi) = cloud.bounds();
    let frame = exemplar_frame(&cloud.name, lo, hi, options, format_up)?;
    let colours = cloud.colours(options.cloud.colour).map_err(fail)?;
    // Neighbour searches in f32 about the cloud's centre (full precision
    // there whatever the file's georeferenced offsets).
    let relative = crate::io::cloud::relative_positions(&cloud.positions, frame.centre);
    let given = if options.cloud.estimate_normals { None } else { cloud.attributes.normals.as_ref() };
    let usable = given.is_some_and(|n| n.iter().all(|v| v.is_finite() && v.length_squared() > 1e-12));
    let (normals, spacing) = if usable {
        let n: Vec<Vec3> = given.unwrap().iter().map(|v| v.normalize()).collect();
        (n, crate::geom::normals::median_spacing(&relative))
    } else {
        if given.is_some() {
            log::warn!("{}: some normals in the file are zero or not finite: estimating all of them", cloud.name);
        }
        let t = Instant::now();
        let r = crate::geom::normals::estimate(&relative, options.cloud.normal_neighbours, options.cloud.orientation, frame.up.axis());
        log::info!(
            "{}: estimated {} normals from {} neighbours each, {:?} orientation, in {:.1} s",
            cloud.name,
            cloud.len(),
            options.cloud.normal_neighbours,
            options.cloud.orientation,
            t.elapsed().as_secs_f64()
        );
        r
    };
    let finest_voxel = 2.0 / options.finest_resolution as f64 / frame.scale;
    if spacing as f64 > 0.75 * finest_voxel {
        log::warn!(
            "{}: points are {:.3} units apart (median), {:.2} of the finest voxel ({:.3}): the finest level will have holes; use a coarser --voxel-size or fewer levels",
            cloud.name,
            spacing,
            spacing as f64 / finest_voxel,
            finest_voxel
        );
    }
    stats.normalise_s = t.elapsed().as_secs_f64();

    // Bin the points into the sampling grid: (voxel key, point) pairs.
    let t = Instant::now();
    let rs = options.sampling_resolution;
    let vs = 2.0 / rs as f64;
    let max = rs as i64 - 1;
    let mut pairs: Vec<(u64, u32)> = cloud
        .positions
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let q = (frame.to_normalised(*p) + DVec3::ONE) / vs;
            let c = q.floor().as_i64vec3().clamp(glam::I64Vec3::ZERO, glam::I64Vec3::splat(max));
            (morton(c.x as u32, c.y as u32, c.z as u32), i as u32)
        })
        .collect();
    stats.voxelise_s = t.elapsed().as_secs_f64();
    stats.triangle_voxel_pairs = pairs.len();
    let t = Instant::now();
    pairs.par_sort_unstable();
    let groups = group_starts(pairs.len(), |i| pairs[i].0);
    stats.sort_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let samples: Vec<Sample> = groups
        .par_windows(2)
        .map(|g| {
            let key = pairs[g[0]].0;
            let members = &pairs[g[0]..g[1]];
            let m = members.len() as f64;
            let mean = members.iter().map(|&(_, i)| frame.to_normalised(cloud.positions[i as usize])).sum::<DVec3>() / m;
            let n_sum: Vec3 = members.iter().map(|&(_, i)| normals[i as usize]).sum();
            let normal = n_sum.try_normalize().unwrap_or(normals[members[0].1 as usize]);
            let colour = match &colours {
                Some(c) => members.iter().map(|&(_, i)| c[i as usize]).sum::<Vec3>() / m as f32,
                None => options.default_colour,
            };
            let centre = super::voxel_centre(key, rs);
            Sample { key, offset: ((mean - centre) / vs).as_vec3(), normal, colour }
        })
        .collect();
    drop(pairs);
    stats.sample_s = t.elapsed().as_secs_f64();
    let levels = super::pool_levels(&samples, options, frame, &mut stats);
    stats.total_s = start.elapsed().as_secs_f64();
    Ok((levels, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::cloud::{Attributes, PointCloud};

    fn sphere_cloud(n: usize, radius: f64, centre: DVec3) -> PointCloud {
        // Even spacing, no normals, colour by height.
        let positions = crate::testing::shapes::sphere_points(n, radius, centre);
        let colours = positions.iter().map(|p| Vec3::splat((((p.z - centre.z) / radius + 1.0) * 0.5) as f32)).collect();
        PointCloud { name: "sphere".into(), positions, attributes: Attributes { colours: Some(colours), ..Default::default() }, crs: None, format: "test".into(), up: Up::Y }
    }

    fn small() -> EncodeOptions {
        EncodeOptions { sampling_resolution: 128, coarsest_resolution: 16, finest_resolution: 64, ..Default::default() }
    }

    /// A sphere given as points far from the origin (georeferenced-like
    /// coordinates) encodes to a shell of outward normals whose points lie on
    /// the sphere, like the mesh encoder's.
    #[test]
    fn a_sphere_of_points_encodes_to_an_outward_shell() {
        let centre = DVec3::new(500_000.0, 4_100_000.0, 120.0);
        let cloud = sphere_cloud(60_000, 10.0, centre);
        let (levels, _) = encode_cloud(&cloud, &small(), Up::Y).unwrap();
        assert_eq!(levels.iter().map(|l| l.resolution).collect::<Vec<_>>(), vec![16, 32, 64]);
        let finest = levels.last().unwrap();
        let frame = finest.frame;
        for i in 0..finest.len() {
            let p = frame.to_world(finest.point_normalised(i));
            let radial = (p - centre).normalize().as_vec3();
            assert!(((p - centre).length() - 10.0).abs() < 0.35, "point {i} at radius {}", (p - centre).length());
            assert!(finest.normals[i].dot(radial) > 0.9, "normal {i} {} not outward", finest.normals[i]);
        }
        // The top (+z) is white, the bottom black.
        let top = (0..finest.len()).max_by(|&a, &b| finest.point_normalised(a).z.total_cmp(&finest.point_normalised(b).z)).unwrap();
        assert!(finest.colours[top].x > 0.9);
    }

    #[test]
    fn voxel_size_sets_the_scale_and_refuses_what_does_not_fit() {
        let cloud = sphere_cloud(20_000, 10.0, DVec3::ZERO);
        let o = EncodeOptions { voxel_size: Some(0.5), ..small() };
        let (levels, _) = encode_cloud(&cloud, &o, Up::Z).unwrap();
        let finest = levels.last().unwrap();
        assert!((finest.voxel_size() / finest.frame.scale - 0.5).abs() < 1e-12, "finest voxel in world units");
        assert_eq!(finest.frame.up, Up::Z);
        let too_fine = EncodeOptions { voxel_size: Some(0.2), ..small() };
        let e = encode_cloud(&cloud, &too_fine, Up::Z).unwrap_err().to_string();
        assert!(e.contains("use --voxel-size 0.3") && e.contains("at a voxel size of 0.2"), "{e}");
    }
}
