//! Drafts that outlive the studio: each open draft's current level (a level
//! file any OpenVDB tool opens) and what it was made from (a small record),
//! in the run folder's `studio_drafts/`, written after every change and read
//! when the studio opens the run. The undo history stays with the session
//! that made it.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::io::vdb::{self, PointsLayout, Provenance, WriteOptions};
use crate::pipeline::RunPaths;

use super::drafts::Draft;
use super::shapes::SeedOf;

/// The folder of saved drafts in a run folder.
pub const DRAFTS_DIR: &str = "studio_drafts";

/// What a draft was made from.
#[derive(Serialize, Deserialize)]
struct Record {
    id: String,
    source: String,
    seed: Option<SeedOf>,
}

fn folder(run: &RunPaths) -> PathBuf {
    run.root.join(DRAFTS_DIR)
}

fn files(run: &RunPaths, id: &str) -> (PathBuf, PathBuf) {
    let dir = folder(run);
    (dir.join(format!("{id}.vdb")), dir.join(format!("{id}.json")))
}

/// Writes `draft`'s current level and record: the level file first (under a
/// temporary name, renamed), the record last, so a stop leaves the former
/// draft or the new one.
pub fn save(run: &RunPaths, draft: &Draft, provenance: &Provenance) -> Result<()> {
    let dir = folder(run);
    std::fs::create_dir_all(&dir).map_err(|e| Error::file(&dir, e.to_string()))?;
    let (level_file, record_file) = files(run, &draft.id);
    let partial = dir.join(format!(".{}.partial.vdb", draft.id));
    vdb::write_level(&partial, draft.level(), provenance, WriteOptions { half_floats: false, points: PointsLayout::None })?;
    std::fs::rename(&partial, &level_file).map_err(|e| Error::file(&level_file, e.to_string()))?;
    let record = Record { id: draft.id.clone(), source: draft.source.clone(), seed: draft.seed };
    let text = serde_json::to_string_pretty(&record).map_err(|e| Error::Invalid(e.to_string()))?;
    crate::util::fs::write_file(&record_file, &text)
}

/// Forgets a saved draft (discarded in the page).
pub fn remove(run: &RunPaths, id: &str) {
    let (level_file, record_file) = files(run, id);
    let _ = std::fs::remove_file(record_file);
    let _ = std::fs::remove_file(level_file);
}

/// The drafts saved in the run folder, oldest first. One that does not read
/// (a file damaged or half-written by hand) is left where it is, with a
/// warning.
pub fn load(run: &RunPaths) -> Vec<Draft> {
    let Ok(entries) = std::fs::read_dir(folder(run)) else { return Vec::new() };
    let mut records: Vec<PathBuf> = entries.flatten().map(|e| e.path()).filter(|p| p.extension().is_some_and(|x| x == "json")).collect();
    records.sort_by_key(|p| id_number(p));
    records
        .into_iter()
        .filter_map(|p| match read(&p) {
            Ok(d) => Some(d),
            Err(e) => {
                log::warn!("{}: a saved draft that does not read is left out: {e}", p.display());
                None
            }
        })
        .collect()
}

fn read(record_file: &Path) -> Result<Draft> {
    let text = std::fs::read_to_string(record_file).map_err(|e| Error::file(record_file, e.to_string()))?;
    let record: Record = serde_json::from_str(&text).map_err(|e| Error::file(record_file, e.to_string()))?;
    if draft_number(&record.id).is_none() {
        return Err(Error::file(record_file, format!("'{}' is not a draft id", record.id)));
    }
    let (level, _) = vdb::read_level(&record_file.with_extension("vdb"))?;
    Ok(Draft::new(record.id, record.source, record.seed, level))
}

/// The number of a draft id (`d12` -> 12).
pub fn draft_number(id: &str) -> Option<usize> {
    id.strip_prefix('d')?.parse().ok()
}

/// The number of a draft, from its record's file name (oldest first).
fn id_number(record_file: &Path) -> usize {
    record_file.file_stem().and_then(|s| s.to_str()).and_then(draft_number).unwrap_or(usize::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::level::Level;
    use glam::{IVec3, Vec3};

    fn level() -> Level {
        let mut l = Level { index: 1, resolution: 8, ..Default::default() };
        for x in 0..4 {
            l.coords.push(IVec3::new(x, 2, 1));
            l.offsets.push(Vec3::ZERO);
            l.normals.push(Vec3::Y);
            l.colours.push(Vec3::splat(0.5));
            l.mask.push(1.0);
        }
        l
    }

    /// A saved draft reads back as it was; a record that does not parse, one
    /// whose level file is missing or damaged, or a foreign id is left out,
    /// and the others still load.
    #[test]
    fn saved_drafts_read_back_and_damaged_ones_are_left_out() {
        let dir = tempfile::tempdir().unwrap();
        let run = RunPaths::new(dir.path());
        let provenance = Provenance { exemplar: "t".into(), seed: None, config_digest: String::new(), exemplar_open: false, crs: None };
        for id in ["d1", "d2", "d3", "d4"] {
            save(&run, &Draft::new(id.into(), "variant_000".into(), None, level()), &provenance).unwrap();
        }
        let saved = folder(&run);
        std::fs::write(saved.join("d2.json"), "{not json").unwrap();
        std::fs::remove_file(saved.join("d3.vdb")).unwrap();
        std::fs::write(saved.join("d4.vdb"), b"not a vdb file").unwrap();
        std::fs::write(saved.join("x9.json"), r#"{"id": "x9", "source": "variant_000", "seed": null}"#).unwrap();
        let loaded = load(&run);
        let ids: Vec<&str> = loaded.iter().map(|d| d.id.as_str()).collect();
        assert_eq!(ids, ["d1"]);
        assert_eq!(loaded[0].level().coords, level().coords);
        assert_eq!(loaded[0].source, "variant_000");
        remove(&run, "d1");
        assert!(!saved.join("d1.json").exists() && !saved.join("d1.vdb").exists());
    }
}
