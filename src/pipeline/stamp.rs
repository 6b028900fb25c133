//! Stage stamps: each stage writes `stage_<name>.json` in the folder it
//! filled, last, after its outputs, holding the digest of everything its
//! result depended on and its seconds. A stage whose stamp holds the digest it
//! would compute now is reused; anything else is redone.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::config::Config;
use crate::error::{Error, Result};
use crate::util::fs::write_file;

/// What a stamp is of: its file is `stage_<name>.json` in the folder the
/// stage filled (`exemplar/` for encoding, `models/` for a level's training,
/// a variant folder for sampling, meshing and its USD layer).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StampOf {
    Encode,
    TrainLevel(usize),
    Sample,
    Mesh,
    Usd,
    /// A kept variant (the studio's keep) is in the run's USD asset and
    /// eval.json: written last, after both.
    Kept,
}

impl StampOf {
    /// The stamp's file name (these names are on disk in existing run folders).
    pub fn file_name(self) -> String {
        let name = match self {
            StampOf::Encode => "encode".to_string(),
            StampOf::TrainLevel(k) => format!("train_level_{k}"),
            StampOf::Sample => "sample".into(),
            StampOf::Mesh => "mesh".into(),
            StampOf::Usd => "usd".into(),
            StampOf::Kept => "kept".into(),
        };
        format!("stage_{name}.json")
    }
}

/// Stamp of a finished stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stamp {
    pub digest: String,
    pub seconds: f64,
}

pub fn stamp_path(dir: &Path, of: StampOf) -> PathBuf {
    dir.join(of.file_name())
}

/// Whether the stage finished in `dir` with the same digest.
pub fn is_done(dir: &Path, of: StampOf, digest: &str) -> bool {
    read_stamp(dir, of).is_some_and(|s| s.digest == digest)
}

/// The stamp the stage left in `dir`, if there is one and it reads.
pub fn read_stamp(dir: &Path, of: StampOf) -> Option<Stamp> {
    serde_json::from_str(&std::fs::read_to_string(stamp_path(dir, of)).ok()?).ok()
}

/// Writes the stamp, last, after the stage's outputs (atomically).
pub fn mark_done(dir: &Path, of: StampOf, digest: &str, seconds: f64) -> Result<()> {
    let path = stamp_path(dir, of);
    let text = serde_json::to_string(&Stamp { digest: digest.into(), seconds }).expect("stamp serialises");
    write_file(&path, &text)
}

/// Whether `dir`'s stamp was written before this command began (what a
/// "reusing" line may claim; children of this command write newer ones).
pub fn stamped_before_this_command(dir: &Path, of: StampOf) -> bool {
    std::fs::metadata(stamp_path(dir, of))
        .and_then(|m| m.modified())
        .is_ok_and(|t| t < crate::util::command_started())
}

/// Short digest of delimited parts: the form of the encoding and training
/// stamps (the source's digest, [`Config::stage_digest`], the level), kept
/// so that encoded exemplars and trained models of earlier versions (hours of
/// CPU) stay reused; every other stage hashes a typed record ([`digest_of`]).
pub fn digest(parts: &[&str]) -> String {
    crate::util::digest::short_of_parts(parts)
}

/// Short digest of a typed value: its JSON (struct fields in declaration
/// order, so the text is a function of the value).
pub fn digest_of<T: Serialize>(value: &T) -> String {
    crate::util::digest::short(&serde_json::to_string(value).expect("stamp inputs serialise"))
}

/// Writes the resolved configuration into a folder (`config.toml`).
pub fn record_config(dir: &Path, config: &Config) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    let path = dir.join(super::layout::CONFIG);
    let text = config.to_toml();
    write_file(&path, &text)
}
