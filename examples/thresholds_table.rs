//! Prints the judge's thresholds as the Markdown page docs/thresholds.md:
//! `cargo run --release --example thresholds_table > docs/thresholds.md`.

fn main() {
    print!("{}", shapeshifter::judge::THRESHOLDS.markdown());
}
