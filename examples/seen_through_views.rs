//! Prints, for each level file given (a 64^3 structure level, e.g.
//! `OUT/variants/variant_003/level_2.vdb`), the share of its silhouette where
//! the inside is seen, per view (bands of 8 azimuths at -20, 15 and 50 degrees,
//! then the top view), and, after the first file, its excess over the first.
//!
//! `cargo run --release --example seen_through_views -- EXEMPLAR/level_2.vdb VARIANT/level_2.vdb ...`

use shapeshifter::judge::seen_through::{seen_through, seen_through_excess, AZIMUTHS};

fn main() -> anyhow::Result<()> {
    let files: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(!files.is_empty(), "usage: seen_through_views LEVEL.vdb [LEVEL.vdb ...] (the first is the reference)");
    let mut reference: Option<Vec<f64>> = None;
    for f in &files {
        let (level, _) = shapeshifter::io::vdb::read_level(std::path::Path::new(f))?;
        let views = seen_through(&level);
        let bands: Vec<String> = views
            .chunks(AZIMUTHS)
            .map(|b| b.iter().map(|v| format!("{:.3}", v)).collect::<Vec<_>>().join(" "))
            .collect();
        let excess = reference.as_ref().map_or(String::new(), |r| format!("  excess {:.4}", seen_through_excess(&views, r)));
        println!("{f}{excess}\n  {}", bands.join("\n  "));
        reference.get_or_insert(views);
    }
    Ok(())
}
