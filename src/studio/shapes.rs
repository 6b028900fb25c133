//! What the studio shows: the exemplar, the run's variants (read from their
//! folders when first asked for) and the variants made in this session
//! (held in memory until kept or discarded), each with its levels and the
//! judge's verdict.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use serde::Serialize;

use crate::error::{Error, Result};
use crate::io::dataset::{self, StartRecord};
use crate::judge::{self, structure_level, Against, Flag, Structure, Thresholds};
use crate::level::Level;
use crate::pipeline::layout::{variant_name, VARIANT_PREFIX};

/// Where a shape comes from.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Origin {
    /// The encoded exemplar.
    Exemplar,
    /// A variant folder of the run (`variants/variant_NNN`).
    Run { folder: PathBuf },
    /// Made in this session (a job's output), not written yet.
    Session { made_by: String },
}

/// What the judge says of a variant: its structure flags at the structure
/// level (and the fine level, where eval scored it), whether it is whole
/// (no broken flag) and whether it is a near copy of the exemplar.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Verdict {
    pub flags: Vec<String>,
    pub whole: bool,
    pub near_copy: bool,
    /// Who judged: "eval.json" (the run's evaluation) or "structure level"
    /// (the studio's check at the structure level, for a session variant).
    pub by: String,
}

impl Verdict {
    /// The verdict of `scores` (the structure judge's figures).
    pub fn of(scores: &judge::Verdict, by: &str) -> Verdict {
        Verdict {
            flags: scores.flags.iter().map(|f| f.name().to_string()).collect(),
            whole: scores.whole(),
            near_copy: scores.flags.contains(&Flag::NearCopy),
            by: by.to_string(),
        }
    }
}

/// The seed a shape's finer levels were sampled from: the run's seed and the
/// variant's index ([`crate::learn::sample::variant_seed`]). Continuing from
/// one of its levels with the same pair reproduces its finer levels where
/// the level is unedited.
#[derive(Clone, Copy, Debug, Serialize, serde::Deserialize, PartialEq, Eq)]
pub struct SeedOf {
    pub seed: u64,
    pub index: usize,
}

/// One shape of the gallery.
pub struct Shape {
    pub id: String,
    pub origin: Origin,
    /// Its levels by index: those in memory (a session variant's, or a
    /// run variant's once read).
    pub levels: BTreeMap<usize, Arc<Level>>,
    /// The level indices it has (on disk or in memory).
    pub present: Vec<usize>,
    pub seed: Option<SeedOf>,
    /// How its start was made (bent, or in a resized box): what it is
    /// judged against, and what its folder records when kept.
    pub start: StartRecord,
    pub verdict: Option<Verdict>,
    /// Where it was written when kept (a session variant).
    pub kept_as: Option<String>,
    /// A picture of its finest level, once drawn (PNG).
    pub preview: Option<Arc<Vec<u8>>>,
}

/// A shape as the page lists it.
#[derive(Serialize)]
pub struct ShapeSummary {
    pub id: String,
    pub origin: Origin,
    pub levels: Vec<usize>,
    pub seed: Option<SeedOf>,
    pub verdict: Option<Verdict>,
    pub kept_as: Option<String>,
    pub has_mesh: bool,
}

impl Shape {
    pub fn summary(&self) -> ShapeSummary {
        let has_mesh = match &self.origin {
            Origin::Run { folder } => folder.join(crate::pipeline::layout::MESH_PLY).is_file(),
            _ => false,
        };
        ShapeSummary {
            id: self.id.clone(),
            origin: self.origin.clone(),
            levels: self.present.clone(),
            seed: self.seed,
            verdict: self.verdict.clone(),
            kept_as: self.kept_as.clone(),
            has_mesh,
        }
    }

    /// The folder its level files are in, where it has one.
    pub fn folder(&self) -> Option<&Path> {
        match &self.origin {
            Origin::Run { folder } => Some(folder),
            _ => None,
        }
    }
}

/// What a variant kept from the studio records beside its levels
/// ([`crate::pipeline::layout::KEPT_RECORD`]): what made it, so the studio
/// can continue it with its own seed.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct StudioRecord {
    pub made_by: String,
    pub seed: Option<SeedOf>,
    /// How its networks multiplied: "f32" (as `sample`) or "bf16".
    #[serde(default)]
    pub compute: String,
}

/// The shapes of a studio: the exemplar first, then the run's variants, then
/// the session's.
pub struct Gallery {
    pub shapes: Mutex<Vec<Shape>>,
    session_ids: super::Ids,
}

impl Gallery {
    /// The exemplar (its levels in memory) and every variant folder of
    /// `variants_dir` (levels read when asked for), with the verdicts of
    /// `eval` (the run's eval.json, where there is one).
    pub fn open(exemplar: &[Level], variants_dir: &Path, eval: Option<&serde_json::Value>) -> Result<Gallery> {
        let mut shapes = vec![Shape {
            id: "exemplar".into(),
            origin: Origin::Exemplar,
            levels: exemplar.iter().map(|l| (l.index, Arc::new(l.clone()))).collect(),
            present: exemplar.iter().map(|l| l.index).collect(),
            seed: None,
            start: StartRecord::default(),
            verdict: None,
            kept_as: None,
            preview: None,
        }];
        shapes.extend(run_variants(variants_dir)?.into_iter().map(|(name, folder)| run_shape(name, folder, eval)));
        Ok(Gallery { shapes: Mutex::new(shapes), session_ids: super::Ids::new("s") })
    }

    pub fn summaries(&self) -> Vec<ShapeSummary> {
        self.lock().iter().map(Shape::summary).collect()
    }

    pub fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Shape>> {
        self.shapes.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Runs `f` on the shape `id`; an unknown id is [`Error::NotFound`]-like
    /// (the studio answers 404).
    pub fn with<T>(&self, id: &str, f: impl FnOnce(&mut Shape) -> Result<T>) -> Result<T> {
        let mut shapes = self.lock();
        let shape = shapes.iter_mut().find(|s| s.id == id).ok_or_else(|| unknown(id))?;
        f(shape)
    }

    /// Level `k` of shape `id`, read from its folder the first time.
    pub fn level(&self, id: &str, k: usize) -> Result<Arc<Level>> {
        let (held, folder) = self.with(id, |s| {
            if !s.present.contains(&k) {
                return Err(Error::Invalid(format!("{id} has no level {k} (it has {:?})", s.present)));
            }
            Ok((s.levels.get(&k).cloned(), s.folder().map(Path::to_path_buf)))
        })?;
        if let Some(level) = held {
            return Ok(level);
        }
        // A present level not in memory is a run variant's file (a session
        // variant's levels are all in memory). Read outside the lock: a
        // 256^3 level takes a while.
        let folder = folder.ok_or_else(|| Error::Invalid(format!("{id}: level {k} is not in memory")))?;
        let (level, _) = crate::io::vdb::read_level(&folder.join(dataset::level_file_name(k)))?;
        let level = Arc::new(level);
        self.with(id, |s| {
            s.levels.insert(k, level.clone());
            Ok(())
        })?;
        Ok(level)
    }

    /// Adds a session shape; returns its id.
    pub fn add_session(&self, made_by: String, seed: Option<SeedOf>, start: StartRecord, levels: Vec<Level>) -> String {
        let id = self.session_ids.next();
        let mut shapes = self.lock();
        shapes.push(Shape {
            id: id.clone(),
            origin: Origin::Session { made_by },
            present: levels.iter().map(|l| l.index).collect(),
            levels: levels.into_iter().map(|l| (l.index, Arc::new(l))).collect(),
            seed,
            start,
            verdict: None,
            kept_as: None,
            preview: None,
        });
        id
    }

    /// Adds (or replaces) a run variant read from `folder` after it was
    /// written (a kept shape).
    pub fn add_run_variant(&self, name: String, folder: PathBuf, eval: Option<&serde_json::Value>) {
        let shape = run_shape(name, folder, eval);
        let mut shapes = self.lock();
        match shapes.iter_mut().find(|s| s.id == shape.id) {
            Some(s) => *s = shape,
            None => shapes.push(shape),
        }
    }

    /// Refreshes the run variants' verdicts from a new eval.json.
    pub fn refresh_verdicts(&self, eval: &serde_json::Value) {
        for s in self.lock().iter_mut() {
            if matches!(s.origin, Origin::Run { .. }) {
                s.verdict = eval_verdict(eval, &s.id);
            }
        }
    }

    /// Removes a session shape (discard). The exemplar and the run's
    /// variants are not discarded from here (their files are the user's).
    pub fn discard(&self, id: &str) -> Result<()> {
        let mut shapes = self.lock();
        let at = shapes.iter().position(|s| s.id == id).ok_or_else(|| unknown(id))?;
        if !matches!(shapes[at].origin, Origin::Session { .. }) {
            return Err(Error::Invalid(format!("{id} is not a session variant: only those are discarded here (its files are left as they are)")));
        }
        shapes.remove(at);
        Ok(())
    }
}

/// The error of an id the studio does not hold.
pub fn unknown(id: &str) -> Error {
    Error::Invalid(format!("no shape or draft '{}' in this studio", crate::error::one_line(id)))
}

/// Whether an error is [`unknown`]'s (the studio answers 404).
pub fn is_unknown(e: &Error) -> bool {
    matches!(e, Error::Invalid(m) if m.starts_with("no shape or draft '"))
}

/// The variant folders of `variants_dir` (`variant_NNN` with a finished
/// sampling), in order.
pub fn run_variants(variants_dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    let Ok(entries) = std::fs::read_dir(variants_dir) else { return Ok(Vec::new()) };
    let mut found: Vec<(String, PathBuf)> = entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let index: usize = name.strip_prefix(VARIANT_PREFIX)?.parse().ok()?;
            (name == variant_name(index) && e.path().is_dir()).then(|| (name, e.path()))
        })
        .filter(|(_, p)| crate::pipeline::stamp::stamp_path(p, crate::pipeline::stamp::StampOf::Sample).is_file())
        .collect();
    found.sort();
    Ok(found)
}

fn run_shape(name: String, folder: PathBuf, eval: Option<&serde_json::Value>) -> Shape {
    let present: Vec<usize> = crate::eval::evaluate::level_files(&folder).map(|f| f.into_iter().map(|(k, _)| k).collect()).unwrap_or_default();
    let record: Option<StudioRecord> =
        std::fs::read(folder.join(crate::pipeline::layout::KEPT_RECORD)).ok().and_then(|b| serde_json::from_slice(&b).ok());
    let seed = match record {
        Some(r) => r.seed,
        None => {
            // A sampled variant: the run's seed (its level files say) and its index.
            let index = name.strip_prefix(VARIANT_PREFIX).and_then(|i| i.parse().ok());
            let first = present.first().map(|&k| folder.join(dataset::level_file_name(k)));
            let seed = first.and_then(|p| crate::io::vdb::read_level(&p).ok()).and_then(|(_, p)| p.seed);
            seed.zip(index).map(|(seed, index)| SeedOf { seed, index })
        }
    };
    // A damaged record reads as none here; eval names it.
    let start = StartRecord::read(&folder).unwrap_or_default();
    Shape {
        verdict: eval.and_then(|e| eval_verdict(e, &name)),
        id: name,
        origin: Origin::Run { folder },
        levels: BTreeMap::new(),
        present,
        seed,
        start,
        kept_as: None,
        preview: None,
    }
}

/// A run variant's verdict from eval.json: its structure flags, whole when
/// none is broken.
fn eval_verdict(eval: &serde_json::Value, name: &str) -> Option<Verdict> {
    let v = eval.get("variants")?.as_array()?.iter().find(|v| v.get("name").and_then(|n| n.as_str()) == Some(name))?;
    let flags: Vec<String> = v
        .get("structure")?
        .get("flags")?
        .as_array()?
        .iter()
        .filter_map(|f| f.as_str().map(str::to_string))
        .collect();
    let broken = flags.iter().any(|f| Flag::from_name(f).is_some_and(|f| f.broken()));
    Some(Verdict { whole: !broken, near_copy: flags.iter().any(|f| f == Flag::NearCopy.name()), flags, by: "eval.json".into() })
}

/// The verdict's `by` where there is nothing to judge: the exemplar has no
/// level at the structure resolution, or the variant lacks it (an edit of a
/// finer level).
pub const NOT_JUDGED: &str = "not judged (no level at the structure resolution)";

/// The exemplar's structure level and its structure, which every verdict
/// compares with (measured once per studio: a tenth of a second at 64^3).
pub fn exemplar_structure(exemplar: &[Level]) -> Option<(usize, Structure)> {
    structure_level(exemplar).map(|l| (l.index, Structure::of(l)))
}

/// The structure judge on a session variant: its structure level (and its
/// fine level) against the exemplar's (`reference`, [`exemplar_structure`]),
/// as the attempts and eval judge.
pub fn judge(exemplar: &[Level], reference: Option<&(usize, Structure)>, levels: &[Arc<Level>], start: &StartRecord) -> Option<Verdict> {
    let (index, ex_structure) = reference?;
    let ex = &exemplar[*index];
    let shape = levels.iter().find(|l| l.index == ex.index && l.resolution == ex.resolution)?;
    if shape.is_empty() {
        return Some(Verdict { flags: vec![Flag::Fragment.name().into()], whole: false, near_copy: false, by: "structure level".into() });
    }
    // The exemplar made as the shape's start was (eval's references).
    let reference_at = |k: usize| -> Option<Level> {
        match (start.bend, start.extent) {
            (Some(b), _) => Some(b.bent(exemplar, k)),
            (None, Some(e)) => e.of(exemplar, k).ok(),
            (None, None) => None,
        }
    };
    let made = reference_at(ex.index).map(|l| {
        let s = Structure::of(&l);
        (l, s)
    });
    let against = match (&made, start.bend.is_some()) {
        (Some((l, s)), true) => Against::Bent(l, s),
        (Some((l, s)), false) => Against::AtExtent(l, s),
        (None, _) => Against::Exemplar { level0: levels.iter().find(|l| l.index == 0).map(|l| (&**l, &exemplar[0])) },
    };
    // Its fine level against the exemplar's, bent likewise (eval's).
    let ex_fine = crate::judge::fine_level(exemplar);
    let fine_reference = ex_fine.map(|f| match start.bend {
        Some(b) => std::borrow::Cow::Owned(b.bent(exemplar, f.index)),
        None => std::borrow::Cow::Borrowed(f),
    });
    let fine = fine_reference.as_deref().and_then(|r| Some((&**levels.iter().find(|l| l.index == r.index)?, r)));
    let scores = judge::Verdict::judged(shape, (ex, ex_structure), against, fine, &Thresholds::default());
    Some(Verdict::of(&scores, "structure level"))
}

/// A level's points for the page's 3D view, little-endian:
/// `u32 magic "SSP1", u32 count, u32 resolution, u32 level index`, then the
/// surface points (mask > 0) in normalised units [-1, 1] (f32 x3 each; the
/// exemplar's and every variant's levels share that frame, so one camera
/// frames them all), their voxel coordinates (i16 x3), unit normals (i8 x3,
/// x127) and colours (u8 x3). 24 bytes a point.
pub fn points_payload(level: &Level) -> Vec<u8> {
    let keep: Vec<usize> = (0..level.len()).filter(|&i| level.mask[i] > 0.0).collect();
    let n = keep.len();
    let mut out = Vec::with_capacity(16 + 24 * n);
    out.extend_from_slice(b"SSP1");
    for v in [n as u32, level.resolution, level.index as u32] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for &i in &keep {
        let p = level.point_normalised(i);
        for c in [p.x, p.y, p.z] {
            out.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    for &i in &keep {
        let c = level.coords[i];
        for v in [c.x, c.y, c.z] {
            out.extend_from_slice(&(v.clamp(i16::MIN as i32, i16::MAX as i32) as i16).to_le_bytes());
        }
    }
    for &i in &keep {
        let n = level.normals[i];
        out.extend([n.x, n.y, n.z].map(|v| ((v.clamp(-1.0, 1.0) * 127.0).round() as i8) as u8));
    }
    for &i in &keep {
        let c = level.colours[i];
        out.extend([c.x, c.y, c.z].map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{IVec3, Vec3};

    #[test]
    fn the_points_payload_holds_only_surface_voxels_in_its_documented_layout() {
        let mut l = Level { index: 1, resolution: 32, ..Default::default() };
        for (x, m) in [(3, 1.0), (4, -1.0), (5, 1.0)] {
            l.coords.push(IVec3::new(x, 7, 9));
            l.offsets.push(Vec3::ZERO);
            l.normals.push(Vec3::Y);
            l.colours.push(Vec3::new(1.0, 0.5, 0.0));
            l.mask.push(m);
        }
        let p = points_payload(&l);
        assert_eq!(&p[..4], b"SSP1");
        let u = |at: usize| u32::from_le_bytes(p[at..at + 4].try_into().unwrap());
        assert_eq!((u(4), u(8), u(12)), (2, 32, 1));
        assert_eq!(p.len(), 16 + 24 * 2);
        // The second point is voxel x = 5: its centre is -1 + (5.5) * 2/32.
        let x1 = f32::from_le_bytes(p[16 + 12..16 + 16].try_into().unwrap());
        assert!((x1 - (-1.0 + 5.5 / 16.0)).abs() < 1e-6, "{x1}");
        let coords = 16 + 24;
        assert_eq!(i16::from_le_bytes([p[coords + 6], p[coords + 7]]), 5);
        let normals = coords + 12;
        assert_eq!(p[normals + 1] as i8, 127);
        let colours = normals + 6;
        assert_eq!(&p[colours..colours + 3], &[255, 128, 0]);
    }

    #[test]
    fn eval_verdicts_read_flags_and_call_only_broken_flags_not_whole() {
        let eval = serde_json::json!({"variants": [
            {"name": "variant_000", "structure": {"flags": ["near_copy"]}},
            {"name": "variant_001", "structure": {"flags": ["torn", "seen_through"]}},
        ]});
        let v0 = eval_verdict(&eval, "variant_000").unwrap();
        assert!(v0.whole && v0.near_copy);
        let v1 = eval_verdict(&eval, "variant_001").unwrap();
        assert!(!v1.whole && !v1.near_copy);
        assert_eq!(eval_verdict(&eval, "variant_002"), None);
    }
}
