//! Base-colour textures for light meshes: a UV atlas (the pure-Rust
//! `uvunwrap` crate: charts grown from flat regions, LSCM + ARAP
//! parameterisation, packed into one page) and a texture baked from the
//! level's coloured points.
//!
//! Why: a light mesh (20k-100k triangles) keeps one colour per vertex, so a
//! vertex stands for a whole stone or more and the exemplar's stones and
//! mortar lines blur into their neighbours. A texel of a 2048^2 atlas is
//! smaller than a voxel of the finest level, so the texture carries the
//! points' colours at their own resolution, whatever the triangle count.
//!
//! Baking: every texel whose centre lies in a chart triangle takes the colour
//! at its surface point, a Gaussian-weighted mean of the 8 nearest level
//! points (sigma half a voxel: the points are one per voxel, so this blends
//! neighbours only across a voxel's width). The charts' padding is then
//! filled outwards from their edges, so bilinear filtering and mipmaps never
//! pull in the empty background.

use std::num::NonZeroUsize;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geom::points::OrientedPoints;
use crate::io::mesh::{Mesh, MeshColours, Texture, Wrap};

/// Empty texels kept around each chart (charts are twice this apart), filled
/// by [`dilate`]: enough for bilinear filtering and the first mipmaps. Light
/// meshes of bumpy surfaces have ~10k small charts, so padding is much of
/// the page: 4 gave the charts 26% of it, 2 gives them 47% (the demo tower
/// at 100k triangles, 12k charts).
const PADDING: u32 = 2;

/// Nearest level points blended into one texel's colour.
const NEIGHBOURS: usize = 8;

/// What baking did, for the log and the report.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BakeReport {
    pub width: u32,
    pub height: u32,
    pub charts: u32,
    /// Share of the page's texels inside a chart.
    pub utilization: f32,
    /// Vertices after splitting at chart seams (was: the mesh's).
    pub vertices_before: usize,
    pub vertices_after: usize,
    pub seconds_unwrap: f64,
    pub seconds_bake: f64,
}

/// `mesh` with a UV atlas and a base-colour texture of `size` texels across
/// baked from `points` (the level the mesh was made from). The result has
/// vertices split at chart seams, per-corner UVs in the OBJ convention
/// (v = 0 the image's bottom row) and keeps its vertex colours for clients
/// that ignore textures.
pub fn bake_texture(mesh: &Mesh, points: &OrientedPoints, size: u32) -> Result<(Mesh, BakeReport)> {
    if !(64..=16384).contains(&size) {
        return Err(Error::Invalid(format!("texture size {size}: expected 64 to 16384 texels")));
    }
    if mesh.triangles.is_empty() || points.is_empty() || points.colours.is_empty() {
        return Err(Error::Invalid("a texture needs triangles and coloured points".into()));
    }
    let t = std::time::Instant::now();
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let options = uvunwrap::Options {
        density: uvunwrap::Density::Auto { page_size: size },
        padding: PADDING,
        // Shape packing nests charts a little tighter (27% of the page used
        // against 26% on the demo tower at 100k triangles, 12k charts) but
        // took 109 s there against 9 s.
        packing: uvunwrap::Packing::Fast,
        ..Default::default()
    };
    // A panic inside the unwrapper (a dependency's bug on some mesh) is this
    // mesh's error, not the end of the stage: the caller keeps vertex colours.
    let atlas = std::panic::catch_unwind(|| uvunwrap::generate(&[uvunwrap::MeshInput::new(&positions, &indices)], &options))
        .map_err(|p| {
            let why = p.downcast_ref::<String>().cloned().or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()));
            Error::Invalid(format!("UV atlas: the unwrapper failed ({})", why.unwrap_or_else(|| "panic".into())))
        })?
        .map_err(|e| Error::Invalid(format!("UV atlas: {e}")))?;
    if atlas.page_count != 1 {
        return Err(Error::Invalid(format!(
            "UV atlas: {} charts need {} pages of {size}^2 texels (one texture holds one page): use a larger texture or fewer triangles",
            atlas.chart_count, atlas.page_count
        )));
    }
    let out = &atlas.meshes[0];
    let seconds_unwrap = t.elapsed().as_secs_f64();

    let t = std::time::Instant::now();
    let (w, h) = (atlas.width, atlas.height);
    let vertex_positions: Vec<Vec3> = out.vertices.iter().map(|v| mesh.positions[v.xref as usize]).collect();
    // Texel coordinates: uvunwrap's (0,0) is the corner of texel row 0.
    let texel_uv: Vec<Vec2> = out.vertices.iter().map(|v| Vec2::new(v.uv[0] * w as f32, v.uv[1] * h as f32)).collect();
    let triangles: Vec<[u32; 3]> = out.indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();

    // Every texel centre inside a triangle, with its surface point.
    let covered: Vec<(u32, Vec3)> = triangles
        .par_iter()
        .flat_map_iter(|tri| {
            let [a, b, c] = tri.map(|i| texel_uv[i as usize]);
            let [pa, pb, pc] = tri.map(|i| vertex_positions[i as usize]);
            let area = (b - a).perp_dot(c - a);
            let mut found = Vec::new();
            if area.abs() < 1e-12 {
                return found.into_iter();
            }
            let lo = a.min(b).min(c).floor().max(Vec2::ZERO);
            let hi = a.max(b).max(c).ceil().min(Vec2::new(w as f32, h as f32));
            for y in lo.y as u32..hi.y as u32 {
                for x in lo.x as u32..hi.x as u32 {
                    let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let wa = (b - p).perp_dot(c - p) / area;
                    let wb = (c - p).perp_dot(a - p) / area;
                    let wc = 1.0 - wa - wb;
                    if wa >= -1e-4 && wb >= -1e-4 && wc >= -1e-4 {
                        found.push((y * w + x, wa * pa + wb * pb + wc * pc));
                    }
                }
            }
            // A sliver covering no texel centre still gets the texel under
            // its centroid, with its own colour: else dilation would fill it
            // from whichever chart lies next to it in the atlas.
            if found.is_empty() {
                let m = (a + b + c) / 3.0;
                let (x, y) = ((m.x as u32).min(w - 1), (m.y as u32).min(h - 1));
                found.push((y * w + x, (pa + pb + pc) / 3.0));
            }
            found.into_iter()
        })
        .collect();

    let tree = kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(
        &points.positions.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
    );
    let sigma = if points.spacing > 0.0 { 0.5 * points.spacing } else { 1e-3 };
    let k = NonZeroUsize::new(NEIGHBOURS.min(points.len())).expect("points are not empty");
    let colours: Vec<Vec3> = covered
        .par_iter()
        .map(|(_, p)| {
            let near = tree.nearest_n::<kiddo::SquaredEuclidean>(&p.to_array(), k);
            let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
            for n in &near {
                let wgt = (-n.distance / (2.0 * sigma * sigma)).exp();
                sum += wgt * points.colours[n.item as usize];
                weight += wgt;
            }
            // Past a few sigmas every weight underflows: the nearest point.
            if weight > 1e-20 {
                sum / weight
            } else {
                points.colours[near[0].item as usize]
            }
        })
        .collect();

    let mut texels = vec![Vec3::ZERO; (w * h) as usize];
    let mut filled = vec![false; (w * h) as usize];
    for ((i, _), c) in covered.iter().zip(&colours) {
        texels[*i as usize] = *c;
        filled[*i as usize] = true;
    }
    dilate(&mut texels, &mut filled, w, h, PADDING + 2);
    let image = image::RgbImage::from_fn(w, h, |x, y| {
        let c = texels[(y * w + x) as usize];
        image::Rgb(c.to_array().map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
    });

    // Per-corner UVs, OBJ convention (v up from the bottom row).
    let uvs: Vec<Vec2> = out.indices.iter().map(|&i| {
        let uv = out.vertices[i as usize].uv;
        Vec2::new(uv[0], 1.0 - uv[1])
    }).collect();
    let colours = match &mesh.colours {
        MeshColours::PerVertex(c) => MeshColours::PerVertex(out.vertices.iter().map(|v| c[v.xref as usize]).collect()),
        _ => MeshColours::None,
    };
    let report = BakeReport {
        width: w,
        height: h,
        charts: atlas.chart_count,
        utilization: atlas.utilization,
        vertices_before: mesh.positions.len(),
        vertices_after: vertex_positions.len(),
        seconds_unwrap,
        seconds_bake: t.elapsed().as_secs_f64(),
    };
    let textured = Mesh {
        name: mesh.name.clone(),
        positions: vertex_positions,
        triangles,
        colours,
        texture: Some(Texture {
            uvs,
            image,
            wrap: [Wrap::ClampToEdge; 2],
            more: Vec::new(),
            triangle_image: Vec::new(),
            tinted: false,
        }),
    };
    Ok((textured, report))
}

/// Grows the filled texels outwards by `rings` texels: each empty texel next
/// to filled ones (8-neighbourhood) takes their mean.
fn dilate(texels: &mut [Vec3], filled: &mut [bool], w: u32, h: u32, rings: u32) {
    let (w, h) = (w as i64, h as i64);
    for _ in 0..rings {
        let grown: Vec<(usize, Vec3)> = (0..w * h)
            .into_par_iter()
            .filter(|&i| !filled[i as usize])
            .filter_map(|i| {
                let (x, y) = (i % w, i / w);
                let (mut sum, mut n) = (Vec3::ZERO, 0);
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (nx, ny) = (x + dx, y + dy);
                        if (0..w).contains(&nx) && (0..h).contains(&ny) && filled[(ny * w + nx) as usize] {
                            sum += texels[(ny * w + nx) as usize];
                            n += 1;
                        }
                    }
                }
                (n > 0).then(|| (i as usize, sum / n as f32))
            })
            .collect();
        if grown.is_empty() {
            break;
        }
        for (i, c) in grown {
            texels[i] = c;
            filled[i] = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube of 12 triangles, outward, and coloured points on its
    /// faces: red where x > 0.5, blue elsewhere.
    fn cube_and_points() -> (Mesh, OrientedPoints) {
        let positions: Vec<Vec3> = (0..8).map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32)).collect();
        let triangles = vec![
            [0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
            [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5],
        ];
        let mesh = Mesh { name: "cube".into(), positions, triangles, colours: MeshColours::PerVertex(vec![Vec3::splat(0.5); 8]), texture: None };
        let mut pts = OrientedPoints { positions: vec![], normals: vec![], colours: vec![], spacing: 0.05 };
        let n = 21;
        for face in 0..6 {
            for i in 0..n {
                for j in 0..n {
                    let (a, b) = (i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32);
                    let axis = face / 2;
                    let side = (face % 2) as f32;
                    let mut p = [0.0; 3];
                    p[axis] = side;
                    p[(axis + 1) % 3] = a;
                    p[(axis + 2) % 3] = b;
                    let p = Vec3::from_array(p);
                    pts.positions.push(p);
                    pts.normals.push(Vec3::ZERO);
                    pts.colours.push(if p.x > 0.5 { Vec3::X } else { Vec3::Z });
                }
            }
        }
        (mesh, pts)
    }

    #[test]
    fn a_baked_texture_carries_the_points_colours_that_vertex_colours_lose() {
        let (mesh, points) = cube_and_points();
        let (textured, report) = bake_texture(&mesh, &points, 256).unwrap();
        assert_eq!(textured.triangles.len(), 12);
        assert!(report.vertices_after >= 8 && report.charts >= 1, "{report:?}");
        assert!(textured.texture.as_ref().unwrap().image.width() <= 256);
        // Sample the surface: the texture says red on the x > 0.5 half and
        // blue on the other, where vertex colours say grey everywhere.
        let (mut right, mut total) = (0, 0);
        for t in 0..12 {
            for w in [Vec3::new(0.6, 0.2, 0.2), Vec3::new(0.2, 0.6, 0.2), Vec3::new(0.2, 0.2, 0.6)] {
                let tri = textured.triangles[t];
                let p: Vec3 = (0..3).map(|k| w[k] * textured.positions[tri[k] as usize]).sum();
                if (p.x - 0.5).abs() < 0.1 {
                    continue;
                }
                let c = textured.colour_at(t, w).unwrap();
                let want = if p.x > 0.5 { Vec3::X } else { Vec3::Z };
                total += 1;
                right += usize::from((c - want).length() < 0.15);
            }
        }
        assert!(total > 20 && right == total, "{right} of {total} surface samples took the points' colour");
    }

    #[test]
    fn sizes_out_of_range_and_uncoloured_points_are_refused() {
        let (mesh, mut points) = cube_and_points();
        assert!(bake_texture(&mesh, &points, 16).is_err());
        points.colours.clear();
        assert!(bake_texture(&mesh, &points, 256).is_err());
    }
}
