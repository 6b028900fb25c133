//! How different each variant looks from the exemplar, from the outside:
//! both levels splatted into depth images from the 24 views of the
//! seen-through measure (elevations -20, 15, 50 degrees, 8 azimuths; one pixel
//! a voxel; the exemplar's centroid at the centre of every view), and per view
//! the share of the pixels either covers where they differ: one is hit and the
//! other not (the silhouette), or, without `SIL`, the depths differ by more
//! than `TOL` voxels. Prints the mean, min, median and max over the views.
//! A probe for a near-copy measure by what a person sees (a house whose hidden
//! courtyard floor moved is still the house); not used by the judge.
//!
//! `cargo run --release --example seen_difference -- EXEMPLAR_DIR VARIANT_DIR...`
//! Environment: `LEVEL` (default 2, 64^3), `TOL` (voxels, default 2), `SIL=1`
//! (silhouette only), `W` (pixels: a silhouette pixel counts only with none of
//! the other's within W), `ALIGN=1` (each variant's centroid moved onto the
//! exemplar's).

use glam::Vec3;
use std::path::Path;

fn depth(points: &[Vec3], centre: Vec3, half: i64, up: Vec3, toward: Vec3) -> Vec<f32> {
    let right = up.cross(toward).try_normalize().unwrap_or_else(|| toward.any_orthonormal_vector());
    let su = toward.cross(right);
    let size = (2 * half + 1) as usize;
    let mut near = vec![f32::NEG_INFINITY; size * size];
    for &p in points {
        let d = p - centre;
        let (x, y, z) = (d.dot(right) + half as f32, d.dot(su) + half as f32, d.dot(toward));
        let (cx, cy) = (x.floor() as i64, y.floor() as i64);
        for py in (cy - 1).max(0)..=(cy + 1).min(size as i64 - 1) {
            for px in (cx - 1).max(0)..=(cx + 1).min(size as i64 - 1) {
                let (dx, dy) = (px as f32 + 0.5 - x, py as f32 + 0.5 - y);
                if dx * dx + dy * dy > 1.0 { continue; }
                let k = py as usize * size + px as usize;
                if z > near[k] { near[k] = z; }
            }
        }
    }
    near
}

fn main() -> anyhow::Result<()> {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    let l: usize = std::env::var("LEVEL").ok().and_then(|s| s.parse().ok()).unwrap_or(2);
    let tol: f32 = std::env::var("TOL").ok().and_then(|s| s.parse().ok()).unwrap_or(2.0);
    let read = |d: &str| shapeshifter::io::vdb::read_level(&Path::new(d).join(format!("level_{l}.vdb"))).map(|x| x.0);
    let pts = |lv: &shapeshifter::level::Level| -> Vec<Vec3> { (0..lv.len()).filter(|&i| lv.mask[i] > 0.0).map(|i| lv.point_voxels(i)).collect() };
    let ex = read(&dirs[0])?;
    let pe = pts(&ex);
    let centre = pe.iter().fold(Vec3::ZERO, |a, &p| a + p) / pe.len() as f32;
    let up = ex.frame.up.axis();
    let side = up.any_orthonormal_vector();
    let other = up.cross(side);
    let mut views = Vec::new();
    for e in [-20f32, 15.0, 50.0] { let e = e.to_radians(); for k in 0..8 { let a = std::f32::consts::TAU * k as f32 / 8.0; views.push((side * a.cos() + other * a.sin()) * e.cos() + up * e.sin()); } }
    let half = ex.resolution as i64;
    for d in &dirs[1..] {
        let v = read(d)?;
        let mut pv = pts(&v);
        if std::env::var_os("ALIGN").is_some() {
            let cv = pv.iter().fold(Vec3::ZERO, |a, &p| a + p) / pv.len() as f32;
            for p in pv.iter_mut() { *p += centre - cv; }
        }
        let mut shares: Vec<f64> = views.iter().map(|&t| {
            let a = depth(&pe, centre, half, up, t);
            let b = depth(&pv, centre, half, up, t);
            let (mut union, mut diff) = (0usize, 0usize);
            let n = (2 * half + 1) as usize;
            let w: i64 = std::env::var("W").ok().and_then(|s| s.parse().ok()).unwrap_or(0);
            let any = |img: &[f32], k: usize| -> bool {
                let (x, y) = ((k % n) as i64, (k / n) as i64);
                (-w..=w).any(|dy| (-w..=w).any(|dx| { let (xx, yy) = (x + dx, y + dy); xx >= 0 && yy >= 0 && (xx as usize) < n && (yy as usize) < n && img[yy as usize * n + xx as usize].is_finite() }))
            };
            for k in 0..a.len() {
                let (ha, hb) = (a[k].is_finite(), b[k].is_finite());
                if w > 0 && ha != hb {
                    let off = if ha { !any(&b, k) } else { !any(&a, k) };
                    if ha || hb { union += 1; if off { diff += 1; } }
                    continue;
                }
                if ha || hb { union += 1; if ha != hb || (std::env::var_os("SIL").is_none() && (a[k] - b[k]).abs() > tol) { diff += 1; } }
            }
            diff as f64 / union.max(1) as f64
        }).collect();
        let mean = shares.iter().sum::<f64>() / shares.len() as f64;
        shares.sort_by(|a, b| a.partial_cmp(b).unwrap());
        println!("{d}: seen difference mean {:.3} min {:.3} median {:.3} max {:.3}", mean, shares[0], shares[12], shares[23]);
    }
    Ok(())
}
