//! The top surface's steps of each variant against the exemplar's
//! ([`shapeshifter::judge::steps`]): per horizontal axis the share of
//! neighbouring inner columns that step and the seams, the seams beyond the
//! exemplar's and the step share beyond it along an axis the exemplar has
//! smooth (the two figures of the `stepped` flag). Level 3 (128^3) unless
//! `LEVEL` says otherwise; the flag reads level 2 (64^3).
//!
//! `cargo run --release --example fine_steps -- EXEMPLAR_DIR VARIANT_DIR...`

use std::path::Path;
fn main() -> anyhow::Result<()> {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    let l: usize = std::env::var("LEVEL").ok().and_then(|s| s.parse().ok()).unwrap_or(3);
    let read = |d: &str| shapeshifter::io::vdb::read_level(&Path::new(d).join(format!("level_{l}.vdb"))).map(|x| x.0);
    let ex = read(&dirs[0])?;
    let te = shapeshifter::judge::steps::top_steps(&ex);
    println!("exemplar {:?}", te);
    for d in &dirs[1..] {
        let v = read(d)?;
        let t = shapeshifter::judge::steps::top_steps(&v);
        let seams = shapeshifter::judge::steps::extra_seams(&t, &te);
        let excess = shapeshifter::judge::steps::smooth_step_excess(&t, &te);
        println!("{d} {t:?} extra seams {seams}, smooth-axis step excess {excess:.3}");
    }
    Ok(())
}
