//! Both ways of the out-of-style matching at one level: the share of each
//! variant's surface like no part of the exemplar (`out_of_style`'s figure)
//! and the share of the exemplar's surface like no part of the variant (a
//! part of the exemplar lost), with the largest connected lost region; for a
//! resized variant (`extent.json`) also its outline and lost share against
//! the exemplar stretched to its extent. A probe for a "part lost" criterion,
//! not used by the judge (docs/lab/single-buildings.md: it does not separate
//! a lost vault from a temple's whole longer halls). Level 2 (64^3) unless
//! `LEVEL` says otherwise; `MARK=DIR` writes the exemplar's level per variant
//! with its lost voxels red.
//!
//! `cargo run --release --example lost_parts -- EXEMPLAR_DIR VARIANT_DIR...`

use std::path::Path;
fn main() -> anyhow::Result<()> {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    let l: usize = std::env::var("LEVEL").ok().and_then(|s| s.parse().ok()).unwrap_or(2);
    let read = |d: &str| shapeshifter::io::vdb::read_level(&Path::new(d).join(format!("level_{l}.vdb"))).map(|x| x.0);
    let ex = read(&dirs[0])?;
    for d in &dirs[1..] {
        let v = read(d)?;
        let unlike = shapeshifter::judge::unlike::unlike_share(&v, &ex);
        let lost = shapeshifter::judge::unlike::unlike_share(&ex, &v);
        let extent: Option<[f32; 3]> = std::fs::read_to_string(Path::new(d).join("extent.json")).ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|j| serde_json::from_value(j["extent"].clone()).ok());
        if let Some(e) = extent {
            let l0 = shapeshifter::io::vdb::read_level(&Path::new(&dirs[0]).join("level_0.vdb"))?.0;
            let at = shapeshifter::level::resize::stretched(&l0, &ex, e)?;
            let outline = shapeshifter::judge::outline::outline_difference(&v, &at);
            let lost_at = shapeshifter::judge::unlike::unlike_share(&at, &v);
            println!("{d} extent {e:?} outline vs stretched {outline:.3} lost vs stretched {lost_at:.3}");
        }
        let lost_coords: Vec<glam::IVec3> = shapeshifter::judge::unlike::unlike_voxels(&ex, &v).iter().enumerate().filter(|(_, &u)| u).map(|(i, _)| ex.coords[i]).collect();
        let sizes = shapeshifter::grid::components::components(&lost_coords);
        let active = ex.mask.iter().filter(|&&m| m > 0.0).count() as f64;
        let largest = sizes.iter().copied().max().unwrap_or(0) as f64 / active;
        println!("{d} unlike {unlike:.3} lost {lost:.3} largest lost part {largest:.3}");
        // MARK=DIR: the exemplar's level with its lost voxels red, per variant.
        if let Some(mark) = std::env::var_os("MARK") {
            let mut marked = ex.clone();
            for (i, lost) in shapeshifter::judge::unlike::unlike_voxels(&ex, &v).into_iter().enumerate() {
                if lost { marked.colours[i] = glam::Vec3::new(1.0, 0.0, 0.0); }
            }
            let name = Path::new(d).file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let out = Path::new(&mark).join(name);
            std::fs::create_dir_all(&out)?;
            shapeshifter::io::vdb::write_level(&out.join(format!("level_{l}.vdb")), &marked, &Default::default(), Default::default())?;
        }
    }
    Ok(())
}
