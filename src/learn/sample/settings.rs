//! The `[sample]` section of a configuration, nested as the pipeline is
//! (see [`super`]): the reverse process at its top, then one table per
//! stage that has settings: `[sample.level0]` (the gate),
//! `[sample.attempts]` (the choice among attempts), `[sample.filters]`
//! (the level filters) and `[sample.proposers]` (bent and resized starts).
//! Checked when it loads ([`SampleConfig::check`]): a setting that cannot
//! apply with the others is an error, never silently off.
//!
//! Configurations written before the nesting (`sample.level0_candidates`,
//! `sample.attempts = 6`, ...) still read: [`migrate`] moves each old key to
//! its table, and `--set` takes the old names with a warning naming the new.
//! Sampling stamps hash the section as the old layout wrote it
//! ([`SampleConfig::stamp_toml`]), so run folders sampled before keep their
//! variants.

use serde::{Deserialize, Serialize};

use crate::learn::schedule::{FinalStep, Sampler};

/// `[sample]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleConfig {
    pub sampler: Sampler,
    pub level0_steps: usize,
    pub upper_steps: usize,
    /// The last reverse step's rule (not written at its default).
    #[serde(default, skip_serializing_if = "FinalStep::is_default")]
    pub final_step: FinalStep,
    #[serde(default, skip_serializing_if = "is_default")]
    pub level0: Level0Settings,
    #[serde(default, skip_serializing_if = "is_default")]
    pub attempts: AttemptSettings,
    #[serde(default, skip_serializing_if = "is_default")]
    pub filters: FilterSettings,
    #[serde(default, skip_serializing_if = "is_default")]
    pub proposers: ProposerSettings,
}

/// `[sample.level0]`: the level-0 gate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Level0Settings {
    /// Level-0 shapes drawn per variant, at most (1: no gate): each is kept
    /// only when its structure against the exemplar's level 0 scores at
    /// least `min_structure`; which of those is the variant's is `pick`;
    /// when none does, the best. 16^3 costs little, and a broken coarse
    /// shape is what no finer level mends.
    #[serde(default = "one_usize")]
    pub candidates: usize,
    #[serde(default)]
    pub min_structure: f64,
    /// Which of the candidates that pass the variant keeps: the first, or
    /// the first new enough against the exemplar's level 0, else the least
    /// like it of all. A level-0 network that learned its one exemplar draws
    /// it again most of the time; the finer levels then copy it too.
    #[serde(default)]
    pub pick: Level0Pick,
    /// The reverse process at level 0, when it differs from `sample.sampler`
    /// (DDPM's fresh noise at every step strays from the learned shape where
    /// deterministic DDIM returns to it).
    #[serde(default)]
    pub sampler: Level0Sampler,
}

impl Default for Level0Settings {
    fn default() -> Self {
        Level0Settings { candidates: 1, min_structure: 0.0, pick: Level0Pick::First, sampler: Level0Sampler::Same }
    }
}

/// `[sample.attempts]`: the choice among attempts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttemptSettings {
    /// Coarse-to-fine passes per variant at most (1: one pass): until one is
    /// whole (no broken flag of the judge) at the structure level (64^3);
    /// else the best is kept.
    #[serde(default = "one_usize")]
    pub count: usize,
    /// A pass that is a near copy of the exemplar (`near_copy`) is not kept
    /// while attempts are left: the first whole pass that is not a copy is;
    /// when none is, a whole copy before anything broken.
    #[serde(default)]
    pub reject_copies: bool,
}

impl Default for AttemptSettings {
    fn default() -> Self {
        AttemptSettings { count: 1, reject_copies: false }
    }
}

/// `[sample.filters]`: what every level gets once made.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilterSettings {
    /// Where the exemplar is a height field without a hole through it (a
    /// terrain, a cliff), every level sampled or transferred has its holes
    /// through the sheet and cracks at its steps closed before the next
    /// level is made (`level::sheet::mend_sheet`); other exemplars are not
    /// touched.
    #[serde(default)]
    pub mend_sheets: bool,
    /// Every level sampled or transferred loses its specks, pieces smaller
    /// than 0.5% of its voxels and than every piece of the exemplar's level
    /// (`level::repair`), before the next level is made: the detail
    /// transfer's loose flecks.
    #[serde(default)]
    pub remove_specks: bool,
}

/// `[sample.proposers]`: where a pass starts when none of its level-0
/// candidates is new enough. Both need `level0.pick = "novel"` with more
/// than one candidate, and the exemplar's box (no `--extent`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProposerSettings {
    /// The pass is instead the exemplar bent at random (`level::warp`),
    /// each field of the bend moving its part by up to this many level-0
    /// voxels, at every level (the finer levels' detail is transferred from
    /// the exemplar bent the same way); 0: never. For a figure with nothing
    /// repeated in it (a bunny, a statue): a bent exemplar is a new pose of
    /// the whole figure.
    #[serde(default)]
    pub bend_voxels: f64,
    /// Which exemplars `bend_voxels` bends: `figures`, only an exemplar
    /// whose surface faces every way, with no flat faces and no walls
    /// standing along an axis (`judge::figure`: a bent wall leans and a bent
    /// plate warps); `all`, any.
    #[serde(default)]
    pub bend_exemplars: BendExemplars,
    /// Where the exemplar is not bent (a building, a part, a terrain): the
    /// pass starts from a level-0 box resized along its longer horizontal
    /// axis by a factor in [1.25, `resize_max`] (the paper's resize,
    /// `level::resize`): the networks fill a longer box in their own way (a
    /// house with more windows), where in the exemplar's box they draw the
    /// exemplar again. The variant records its extent (`extent.json`) and
    /// is judged against the exemplar at that extent. 0: never.
    #[serde(default)]
    pub resize_max: f64,
}

/// Which exemplars sampling may bend (`sample.proposers.bend_exemplars`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BendExemplars {
    /// Those [`crate::judge::figure::FigureReading`] reads as figures.
    #[default]
    Figures,
    /// Any exemplar.
    All,
}

impl BendExemplars {
    /// The default (serde's skip test).
    pub fn is_figures(&self) -> bool {
        *self == BendExemplars::Figures
    }
}

/// Which level-0 candidate a variant keeps (`sample.level0.pick`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Level0Pick {
    /// The first whose structure passes.
    #[default]
    First,
    /// Of those whose structure passes, the first new enough against the
    /// exemplar's level 0, else the least like it
    /// ([`crate::learn::sample::NEW_ENOUGH_LEVEL0_FSCORE`]).
    Novel,
}

/// The reverse process at level 0 (`sample.level0.sampler`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Level0Sampler {
    /// `sample.sampler`, as at every level.
    #[default]
    Same,
    Ddpm,
    Ddim,
}

impl Level0Sampler {
    /// The sampler level 0 uses, given the one of the other levels.
    pub fn or(self, others: Sampler) -> Sampler {
        match self {
            Level0Sampler::Same => others,
            Level0Sampler::Ddpm => Sampler::Ddpm,
            Level0Sampler::Ddim => Sampler::Ddim,
        }
    }
}

/// The four tables at their defaults, every key written: what a
/// configuration's `[sample]` is filled with before `--set` applies, so a
/// key is found whether or not the profile names it.
#[derive(Default, Serialize)]
pub struct NestedDefaults {
    level0: Level0Settings,
    attempts: AttemptSettings,
    filters: FilterSettings,
    proposers: ProposerSettings,
}

/// Each key of the layout before the nesting, and where it is now (both
/// under `[sample]`).
pub const MOVED_KEYS: [(&str, &str, &str); 11] = [
    ("level0_candidates", "level0", "candidates"),
    ("level0_min_structure", "level0", "min_structure"),
    ("level0_pick", "level0", "pick"),
    ("level0_sampler", "level0", "sampler"),
    ("attempts", "attempts", "count"),
    ("reject_copies", "attempts", "reject_copies"),
    ("mend_sheets", "filters", "mend_sheets"),
    ("remove_specks", "filters", "remove_specks"),
    ("bend_voxels", "proposers", "bend_voxels"),
    ("bend_exemplars", "proposers", "bend_exemplars"),
    ("resize_max", "proposers", "resize_max"),
];

/// Moves the keys of a `[sample]` table written before the nesting into
/// their tables; the old names found, for a warning. A key given both ways
/// keeps the nested one.
pub fn migrate(sample: &mut toml::Table) -> Vec<&'static str> {
    let mut moved = Vec::new();
    for (old, table, key) in MOVED_KEYS {
        // `attempts` is both an old key (a count) and a new table.
        let Some(value) = sample.get(old).filter(|v| !v.is_table()).cloned() else { continue };
        sample.remove(old);
        let sub = sample.entry(table).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let Some(sub) = sub.as_table_mut() {
            sub.entry(key).or_insert(value);
        }
        moved.push(old);
    }
    moved
}

/// The nested path of an old `--set sample.KEY` name, if it is one.
pub fn moved_path(old: &str) -> Option<String> {
    MOVED_KEYS.iter().find(|(o, _, _)| *o == old).map(|(_, t, k)| format!("sample.{t}.{k}"))
}

/// The section as the layout before the nesting wrote it: what sampling
/// stamps hash, field for field, so nesting the settings changed no stamp.
#[derive(Serialize)]
struct StampLayout<'a> {
    sampler: Sampler,
    level0_steps: usize,
    upper_steps: usize,
    #[serde(skip_serializing_if = "FinalStep::is_default")]
    final_step: FinalStep,
    #[serde(skip_serializing_if = "is_one")]
    level0_candidates: usize,
    #[serde(skip_serializing_if = "is_zero")]
    level0_min_structure: f64,
    #[serde(skip_serializing_if = "is_default")]
    level0_pick: Level0Pick,
    #[serde(skip_serializing_if = "is_default")]
    level0_sampler: Level0Sampler,
    #[serde(skip_serializing_if = "is_one")]
    attempts: usize,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    reject_copies: bool,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    mend_sheets: bool,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    remove_specks: bool,
    #[serde(skip_serializing_if = "is_zero")]
    bend_voxels: f64,
    #[serde(skip_serializing_if = "BendExemplars::is_figures")]
    bend_exemplars: &'a BendExemplars,
    #[serde(skip_serializing_if = "is_zero")]
    resize_max: f64,
}

impl SampleConfig {
    /// The TOML text sampling stamps hash ([`StampLayout`]).
    pub fn stamp_toml(&self) -> String {
        let (l, a, f, p) = (&self.level0, &self.attempts, &self.filters, &self.proposers);
        let layout = StampLayout {
            sampler: self.sampler,
            level0_steps: self.level0_steps,
            upper_steps: self.upper_steps,
            final_step: self.final_step,
            level0_candidates: l.candidates,
            level0_min_structure: l.min_structure,
            level0_pick: l.pick,
            level0_sampler: l.sampler,
            attempts: a.count,
            reject_copies: a.reject_copies,
            mend_sheets: f.mend_sheets,
            remove_specks: f.remove_specks,
            bend_voxels: p.bend_voxels,
            bend_exemplars: &p.bend_exemplars,
            resize_max: p.resize_max,
        };
        toml::to_string(&layout).expect("the sample section serialises")
    }

    /// Whether every setting can apply with the others: ranges, and the
    /// combinations that would leave a setting silently off (a gate setting
    /// with one candidate, `reject_copies` with one attempt, a proposer
    /// without the novel pick of several candidates, `bend_exemplars`
    /// without bends). The message names the keys.
    pub fn check(&self) -> Result<(), String> {
        let (l, a, p) = (&self.level0, &self.attempts, &self.proposers);
        if self.level0_steps == 0 || self.upper_steps == 0 {
            return Err("sample steps must be at least 1".into());
        }
        if !(1..=64).contains(&l.candidates) {
            return Err("sample.level0.candidates must be in 1..=64".into());
        }
        if !(1..=64).contains(&a.count) {
            return Err("sample.attempts.count must be in 1..=64".into());
        }
        if !(0.0..=1.0).contains(&l.min_structure) {
            return Err("sample.level0.min_structure must be in [0, 1]".into());
        }
        if !(0.0..=crate::level::warp::MAX_BEND_VOXELS).contains(&p.bend_voxels) {
            return Err(format!("sample.proposers.bend_voxels must be in [0, {}] (level-0 voxels)", crate::level::warp::MAX_BEND_VOXELS));
        }
        let r = p.resize_max;
        if !(r == 0.0 || (crate::level::resize::RESIZE_MIN_SCALE..=4.0).contains(&r)) {
            return Err(format!("sample.proposers.resize_max must be 0 (never resize) or in [{}, 4]", crate::level::resize::RESIZE_MIN_SCALE));
        }
        let gate_set = l.min_structure > 0.0 || l.pick != Level0Pick::First;
        if l.candidates == 1 && gate_set {
            return Err("sample.level0.min_structure and sample.level0.pick choose among candidates: with sample.level0.candidates = 1 there is nothing to choose (set candidates above 1, or leave them at 0 and \"first\")".into());
        }
        if a.reject_copies && a.count == 1 {
            return Err("sample.attempts.reject_copies passes over a copy for another attempt: with sample.attempts.count = 1 there is none (set count above 1, or reject_copies = false)".into());
        }
        let proposing = p.bend_voxels > 0.0 || p.resize_max > 0.0;
        if proposing && !(l.pick == Level0Pick::Novel && l.candidates > 1) {
            return Err("sample.proposers (bend_voxels, resize_max) start a pass whose level-0 candidates are none new enough: they need sample.level0.pick = \"novel\" and sample.level0.candidates above 1".into());
        }
        if p.bend_exemplars != BendExemplars::Figures && p.bend_voxels == 0.0 {
            return Err("sample.proposers.bend_exemplars says which exemplars are bent: with bend_voxels = 0 none is".into());
        }
        Ok(())
    }
}

fn one_usize() -> usize {
    1
}
fn is_one(v: &usize) -> bool {
    *v == 1
}
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}
fn is_default<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cpu() -> SampleConfig {
        crate::config::Config::load("cpu", &[]).unwrap().sample
    }

    #[test]
    fn a_section_written_before_the_nesting_reads_the_same() {
        let mut old: toml::Table = toml::from_str(
            "sampler = \"ddim\"\nlevel0_steps = 200\nupper_steps = 50\nlevel0_candidates = 16\nlevel0_min_structure = 0.8\n\
             level0_pick = \"novel\"\nattempts = 6\nreject_copies = true\nmend_sheets = true\nresize_max = 1.5\n",
        )
        .unwrap();
        let moved = migrate(&mut old);
        assert_eq!(moved.len(), 7, "{moved:?}");
        let s: SampleConfig = toml::Value::Table(old).try_into().unwrap();
        assert_eq!((s.level0.candidates, s.level0.pick, s.attempts.count), (16, Level0Pick::Novel, 6));
        assert!(s.attempts.reject_copies && s.filters.mend_sheets && !s.filters.remove_specks);
        assert_eq!(s.proposers.resize_max, 1.5);
        // Stamps hash the old layout: the keys in their old order and names.
        let stamp = s.stamp_toml();
        assert!(stamp.starts_with("sampler = \"ddim\"\nlevel0_steps = 200\nupper_steps = 50\nlevel0_candidates = 16\n"), "{stamp}");
        assert!(stamp.contains("attempts = 6\nreject_copies = true\nmend_sheets = true\nresize_max = 1.5\n"), "{stamp}");
        assert_eq!(moved_path("resize_max").as_deref(), Some("sample.proposers.resize_max"));
        assert_eq!(moved_path("sampler"), None);
    }

    #[test]
    fn a_setting_that_cannot_apply_is_refused_and_names_its_keys() {
        assert_eq!(cpu().check(), Ok(()));
        let mut one = cpu();
        one.level0.candidates = 1;
        assert!(one.check().unwrap_err().contains("sample.level0.candidates"));
        let mut no_retry = cpu();
        no_retry.attempts.count = 1;
        assert!(no_retry.check().unwrap_err().contains("reject_copies"));
        let mut first = cpu();
        first.level0.pick = Level0Pick::First;
        assert!(first.check().unwrap_err().contains("sample.proposers"));
        first.proposers = ProposerSettings::default();
        assert_eq!(first.check(), Ok(()), "the first pick without proposers is fine");
        let mut all = first.clone();
        all.proposers.bend_exemplars = BendExemplars::All;
        assert!(all.check().unwrap_err().contains("bend_exemplars"));
    }
}
