//! Prints, per level, how far each variant is from the exemplar: the
//! 1-voxel-tolerant F-score of their surface voxels and the largest changed
//! region (a share of the exemplar's voxels), the two figures of the
//! near-copy flag, at every resolution. Shows at which level a variant
//! becomes (or stays) a copy.
//!
//! `cargo run --release --example level_novelty -- EXEMPLAR_DIR VARIANT_DIR...`
//! (`NOVELTY_PR=1`: also the precision, what of the variant the exemplar
//! has, and the recall, what of the exemplar the variant has)

use shapeshifter::judge::Matching;
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(dirs.len() >= 2, "usage: level_novelty EXEMPLAR_DIR VARIANT_DIR...");
    let read = |d: &str, l: usize| shapeshifter::io::vdb::read_level(&Path::new(d).join(format!("level_{l}.vdb"))).map(|x| x.0);
    let levels: Vec<usize> = (0..8).take_while(|&l| Path::new(&dirs[0]).join(format!("level_{l}.vdb")).exists()).collect();
    let exemplar: Vec<_> = levels.iter().map(|&l| read(&dirs[0], l)).collect::<Result<_, _>>()?;
    println!("F-score / largest change per level {levels:?}");
    for d in &dirs[1..] {
        let cells: Vec<String> = levels
            .iter()
            .filter(|&&l| Path::new(d).join(format!("level_{l}.vdb")).exists())
            .map(|&l| {
                let v = read(d, l)?;
                let m = Matching::of(&v, &exemplar[l]);
                Ok(if std::env::var_os("NOVELTY_PR").is_some() {
                    format!("{:.3}/{:.3} p{:.3} r{:.3}", m.fscore(), m.largest_change(), m.precision(), m.recall())
                } else {
                    format!("{:.3}/{:.3}", m.fscore(), m.largest_change())
                })
            })
            .collect::<anyhow::Result<_>>()?;
        println!("{d}  {}", cells.join("  "));
    }
    Ok(())
}
