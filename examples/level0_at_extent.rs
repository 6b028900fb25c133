//! A probe: each resized variant's level 0 judged as the level-0 gate
//! judges a candidate, against the exemplar's level 0 stretched to the
//! variant's extent (thin parts at the exemplar's own count): the verdict's
//! figures, one line per variant. `LEVEL` another level (the structure
//! level: 2); `STRETCHED=DIR` writes the exemplar at each variant's extent.
//!
//! `cargo run --release --example level0_at_extent -- EXEMPLAR_DIR VARIANT_DIR...`

use shapeshifter::judge::{Structure, Thresholds, Verdict};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    let l: usize = std::env::var("LEVEL").ok().and_then(|s| s.parse().ok()).unwrap_or(0);
    let read = |d: &str, k: usize| shapeshifter::io::vdb::read_level(&Path::new(d).join(format!("level_{k}.vdb"))).map(|x| x.0);
    let ex0 = read(&dirs[0], 0)?;
    let ex = read(&dirs[0], l)?;
    for d in &dirs[1..] {
        let Some(e) = std::fs::read_to_string(Path::new(d).join("extent.json")).ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|j| serde_json::from_value::<[f32; 3]>(j["extent"].clone()).ok()) else { continue };
        let at = shapeshifter::level::resize::stretched(&ex0, &ex, e)?;
        // STRETCHED=DIR: the exemplar's level at this variant's extent, to
        // read with the other probes (`seen_through_views`).
        if let Some(dir) = std::env::var_os("STRETCHED") {
            let out = Path::new(&dir).join(Path::new(d).file_name().unwrap_or_default());
            std::fs::create_dir_all(&out)?;
            shapeshifter::io::vdb::write_level(&out.join(format!("level_{l}.vdb")), &at, &Default::default(), Default::default())?;
        }
        let s_at = Structure::at_extent(&Structure::of(&at), &Structure::of(&ex));
        let v = read(d, l)?;
        let r = Verdict::new(&v, &Structure::of(&v), &at, &s_at, &Thresholds::default());
        println!("{} mass {:.3} ext {:.3} fb {:.3}/{:.3} encl {:.3} seen {:.3} thin {:.3} F {:.3} change {:.3} score {:.3} {:?}",
            Path::new(d).file_name().unwrap().to_string_lossy(), r.mass_ratio, r.extent_ratio, r.free_boundary, r.exemplar_free_boundary, r.enclosure_ratio, r.seen_through_excess, r.thin_ratio, r.copy_fscore, r.largest_change, r.score, r.flags);
    }
    Ok(())
}
