//! Configuration: profiles shipped with the program (`profiles/*.toml`,
//! embedded at build time), overridden by `--set section.key=value`, and
//! recorded with a digest in every output so that results can be traced and
//! finished stages reused.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Profiles that ship with the program: (name, TOML text).
pub const PROFILES: &[(&str, &str)] = &[
    ("cpu", include_str!("../profiles/cpu.toml")),
    ("demo", include_str!("../profiles/demo.toml")),
    ("paper", include_str!("../profiles/paper.toml")),
];

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    pub name: String,
    pub encode: EncodeConfig,
    pub model: ModelConfig,
    pub train: TrainConfig,
    pub sample: SampleConfig,
    /// Resources of each job when the pipeline runs as a cluster job graph
    /// (`shapeshifter slurm`); absent from configurations recorded before it
    /// existed, hence the default.
    #[serde(default)]
    pub cluster: ClusterConfig,
    /// How level files are laid out (defaults for configurations recorded
    /// before the section existed).
    #[serde(default)]
    pub output: OutputConfig,
    /// Variant meshes; absent from configurations recorded before it
    /// existed, hence the default (every triangle, PLY only).
    #[serde(default)]
    pub mesh: MeshConfig,
    /// The finest levels made by detail transfer instead of a trained network
    /// (docs/configuration.md). Not written when off, so the digests of
    /// configurations without it stay valid.
    #[serde(default, skip_serializing_if = "crate::transfer::TransferConfig::is_off")]
    pub transfer: crate::transfer::TransferConfig,
}

// Each stage owns its settings (a leaf file of its folder, importing no
// stage above it); this file composes them into a `Config`.
pub use crate::encode::settings::EncodeConfig;
pub use crate::io::settings::OutputConfig;
pub use crate::learn::sample::settings::{BendExemplars, Level0Pick, Level0Sampler, SampleConfig};
pub use crate::learn::settings::{Mixing, ModelConfig, TrainConfig};
pub use crate::pipeline::cluster_settings::ClusterConfig;
pub use crate::recon::settings::{MeshConfig, DEFAULT_TEXTURE};


/// The stages whose results depend on sections of the configuration
/// ([`Config::stage_digest`]); meshing and USD name their own few settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Encode,
    Train,
    Sample,
}

/// A configuration section as the TOML text stage digests hash.
fn section_toml<T: Serialize>(section: &T) -> String {
    toml::to_string(section).expect("configuration sections serialise")
}

impl Config {
    /// A shipped profile by name, or a TOML file by path, with overrides. A
    /// profile or override that does not load is a usage error
    /// ([`Error::Usage`]: the command line asked for it).
    pub fn load(profile: &str, overrides: &[String]) -> Result<Config> {
        Self::load_profile(profile, overrides).map_err(Error::usage)
    }

    fn load_profile(profile: &str, overrides: &[String]) -> Result<Config> {
        let text = match PROFILES.iter().find(|(n, _)| *n == profile) {
            Some((_, t)) => t.to_string(),
            None => {
                let p = std::path::Path::new(profile);
                if !p.exists() {
                    let names: Vec<&str> = PROFILES.iter().map(|(n, _)| *n).collect();
                    return Err(Error::Invalid(format!(
                        "unknown profile '{profile}' (shipped: {}; or give a .toml file)",
                        names.join(", ")
                    )));
                }
                std::fs::read_to_string(p).map_err(|e| Error::file(p, e.to_string()))?
            }
        };
        let table: toml::Table =
            toml::from_str(&text).map_err(|e| Error::Invalid(format!("profile '{profile}': {}", crate::error::one_line(&e.to_string()))))?;
        Self::from_table(table, overrides)
    }

    /// This configuration with `overrides` applied (e.g. sampling settings on
    /// top of the configuration recorded at training time).
    /// A bad override is a usage error.
    pub fn with_overrides(&self, overrides: &[String]) -> Result<Config> {
        let table: toml::Table = toml::from_str(&self.to_toml()).expect("a config reads back");
        Self::from_table(table, overrides).map_err(Error::usage)
    }

    fn from_table(mut table: toml::Table, overrides: &[String]) -> Result<Config> {
        // A section that is not written when off can still be set.
        if !table.contains_key("transfer") {
            let off = toml::Value::try_from(crate::transfer::TransferConfig::default()).expect("serialises");
            table.insert("transfer".into(), off);
        }
        // Settings not written at their defaults can still be set.
        fill_sample_defaults(&mut table);
        if let Some(train) = table.get_mut("train").and_then(|s| s.as_table_mut()) {
            train.entry("bf16").or_insert(toml::Value::Boolean(false));
        }
        for o in overrides {
            apply_override(&mut table, o)?;
            // A table given whole (`sample.level0={candidates = 1}`) has its
            // other keys again, for the overrides after it.
            fill_sample_defaults(&mut table);
        }
        let mut config: Config = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| Error::Invalid(format!("configuration: {}", crate::error::one_line(&e.to_string()))))?;
        config.normalise();
        config.validate()?;
        Ok(config)
    }

    /// Reads a configuration recorded in an output folder.
    pub fn read(path: &std::path::Path) -> Result<Config> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
        let mut table: toml::Table = toml::from_str(&text).map_err(|e| Error::file(path, crate::error::one_line(&e.to_string())))?;
        if let Some(sample) = table.get_mut("sample").and_then(|s| s.as_table_mut()) {
            crate::learn::sample::settings::migrate(sample);
        }
        let mut c: Config =
            toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| Error::file(path, crate::error::one_line(&e.to_string())))?;
        c.normalise();
        c.validate()?;
        Ok(c)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("config serialises")
    }

    /// Short digest of the whole configuration (hex, 16 chars).
    pub fn digest(&self) -> String {
        digest_str(&self.digest_toml())
    }

    /// The text [`Config::digest`] hashes: the configuration with its
    /// `[sample]` section in the layout before the nesting
    /// ([`SampleConfig::stamp_toml`]), so digests recorded before stay valid.
    fn digest_toml(&self) -> String {
        let text = self.to_toml();
        let Some(start) = text.find("[sample]\n") else { return text };
        let body = start + "[sample]\n".len();
        // The section ends at the next header that is not one of its tables.
        let end = text[body..]
            .match_indices("\n[")
            .map(|(i, _)| body + i + 1)
            .find(|&i| !text[i..].starts_with("[sample."))
            .unwrap_or(text.len());
        let tail = if end < text.len() { "\n" } else { "" };
        format!("{}[sample]\n{}{tail}{}", &text[..start], self.sample.stamp_toml(), &text[end..])
    }

    /// Digest of the settings one stage depends on, so changing the sampler
    /// does not invalidate trained models, and so on. The text hashed is the
    /// TOML of those sections (as it always was: stamps of existing run
    /// folders stay valid).
    pub fn stage_digest(&self, stage: Stage) -> String {
        use crate::learn::schedule::{SAMPLING_PARAMETERISATION, TRAINING_PARAMETERISATION};
        let parts: Vec<String> = match stage {
            // The layout of the files a stage writes is part of what it did.
            Stage::Encode => vec![section_toml(&self.encode), section_toml(&self.output)],
            Stage::Train => vec![TRAINING_PARAMETERISATION.into(), section_toml(&self.encode), section_toml(&self.model), section_toml(&self.train)],
            Stage::Sample => vec![
                // How networks were taught and how their predictions are stepped.
                TRAINING_PARAMETERISATION.into(),
                SAMPLING_PARAMETERISATION.into(),
                section_toml(&self.encode),
                section_toml(&self.model),
                section_toml(&self.train),
                self.sample.stamp_toml(),
                section_toml(&self.output),
                // Detail transfer, where on (absent before it existed).
                if self.transfer.is_off() { String::new() } else { section_toml(&self.transfer) },
            ],
        };
        digest_str(&parts.join("\n"))
    }

    /// Number of levels, from the resolutions.
    pub fn levels(&self) -> usize {
        (self.encode.finest_resolution / self.encode.coarsest_resolution).trailing_zeros() as usize + 1
    }

    /// Detail transfer off: its other settings do nothing and are not
    /// written, so they are reset, and a configuration reads back equal.
    fn normalise(&mut self) {
        if self.transfer.is_off() {
            self.transfer = crate::transfer::TransferConfig::default();
        }
    }

    /// Number of levels with a trained diffusion model: all below
    /// `transfer.from_resolution` (every level when transfer is off, 0); the
    /// levels at and above it are made by detail transfer.
    pub fn trained_levels(&self) -> usize {
        let from = self.transfer.from_resolution;
        (0..self.levels()).take_while(|&l| from == 0 || self.encode.coarsest_resolution << l < from).count()
    }

    fn validate(&self) -> Result<()> {
        self.transfer.validate().map_err(Error::Invalid)?;
        let t = self.mesh.texture;
        if t != 0 && !(64..=16384).contains(&t) {
            return Err(Error::Invalid(format!("mesh.texture = {t}: expected 0 (no texture) or 64 to 16384 texels")));
        }
        let m = self.output.meters_per_unit;
        if !(m.is_finite() && m > 0.0) {
            return Err(Error::Invalid(format!("output.meters_per_unit = {m}: expected a positive number")));
        }
        let from = self.transfer.from_resolution;
        if from != 0 && from <= self.encode.coarsest_resolution {
            return Err(Error::Invalid(format!(
                "transfer.from_resolution = {from} would leave level 0 ({}^3) without a network: it must be finer",
                self.encode.coarsest_resolution
            )));
        }
        let e = &self.encode;
        let pow2 = |v: u32| v >= 4 && v.is_power_of_two();
        if !(pow2(e.sampling_resolution) && pow2(e.coarsest_resolution) && pow2(e.finest_resolution)) {
            return Err(Error::Invalid("encode resolutions must be powers of two >= 4".into()));
        }
        if !(e.coarsest_resolution <= e.finest_resolution && e.finest_resolution <= e.sampling_resolution) {
            return Err(Error::Invalid(
                "encode resolutions must satisfy coarsest <= finest <= sampling".into(),
            ));
        }
        let m = &self.model;
        for k in [m.level0_first_kernel, m.upper_first_kernel] {
            if ![1, 3, 5].contains(&k) {
                return Err(Error::Invalid(format!("model kernel size {k} must be 1, 3 or 5")));
            }
        }
        if m.channels < 1 || m.upsampler_channels < 1 || m.level0_layers < 1 || m.upper_layers < 1 {
            return Err(Error::Invalid("model channels and layers must be at least 1".into()));
        }
        let t = &self.train;
        if !(t.lr_final_ratio > 0.0 && t.lr_final_ratio <= 1.0) {
            return Err(Error::Invalid("train.lr_final_ratio must be in (0, 1]".into()));
        }
        if !(0.0..1.0).contains(&t.ema_decay) {
            return Err(Error::Invalid("train.ema_decay must be in [0, 1)".into()));
        }
        if !(t.upper_t_max > 0.0 && t.upper_t_max <= 1.0) {
            return Err(Error::Invalid("train.upper_t_max must be in (0, 1]".into()));
        }
        if t.crop < 3 || t.level0_batch == 0 || t.upper_batch == 0 {
            return Err(Error::Invalid("train.crop must be >= 3 and batches >= 1".into()));
        }
        if !(t.lr > 0.0 && t.upsampler_lr > 0.0) {
            return Err(Error::Invalid("learning rates must be positive".into()));
        }
        self.sample.check().map_err(Error::Invalid)?;
        Ok(())
    }
}


/// A configuration's `[sample]` section in the nested layout
/// ([`crate::learn::sample::settings::migrate`], warned once per key), each
/// table with every key, so `--set` finds them whether or not the profile
/// names them.
fn fill_sample_defaults(table: &mut toml::Table) {
    if let Some(sample) = table.get_mut("sample").and_then(|s| s.as_table_mut()) {
        let moved = crate::learn::sample::settings::migrate(sample);
        if !moved.is_empty() {
            log::warn!(
                "configuration: sample.{} written before [sample.level0], [sample.attempts], [sample.filters] and [sample.proposers]: read into those tables",
                moved.join(", sample.")
            );
        }
        sample.entry("final_step").or_insert(toml::Value::String("prediction".into()));
        let defaults = toml::Value::try_from(crate::learn::sample::settings::NestedDefaults::default()).expect("serialises");
        for (name, value) in defaults.as_table().expect("a table") {
            let sub = sample.entry(name.as_str()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
            if let (Some(sub), Some(keys)) = (sub.as_table_mut(), value.as_table()) {
                for (k, v) in keys {
                    sub.entry(k.as_str()).or_insert(v.clone());
                }
            }
        }
    }
}

fn digest_str(s: &str) -> String {
    crate::util::digest::short(s)
}

/// `section.key=value`, value parsed as TOML (number, bool, string) or taken
/// as a bare string.
/// Keys a profile may leave out (their defaults are not recorded).
const OPTIONAL_KEYS: &[(&str, &str)] = &[
    ("encode", "voxel_size"),
    ("encode", "up"),
    ("encode", "cloud_colour"),
    ("encode", "normal_neighbours"),
    ("encode", "normal_orientation"),
    ("encode", "estimate_normals"),
    ("mesh", "texture"),
    ("output", "meters_per_unit"),
    ("output", "usd_format"),
];

fn apply_override(table: &mut toml::Table, spec: &str) -> Result<()> {
    let bad = || Error::Invalid(format!("--set '{spec}': expected section.key=value"));
    let (path, value) = spec.split_once('=').ok_or_else(bad)?;
    let value = value.trim();
    let parsed: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(value.to_string()));
    let mut path = path.trim().to_string();
    // A sampling key of the layout before the nesting: its new place
    // (`sample.attempts` given a table is the new table itself).
    if let Some(moved) = path.strip_prefix("sample.").and_then(crate::learn::sample::settings::moved_path).filter(|_| !parsed.is_table()) {
        log::warn!("--set {path}: now {moved}");
        path = moved;
    }
    // section.key, or section.table.key within a section's table.
    let (section, key) = path.rsplit_once('.').ok_or_else(bad)?;
    let (section, key) = (section.to_string(), key.to_string());
    let (section, key) = (section.as_str(), key.as_str());
    let mut sec = Some(&mut *table);
    for part in section.split('.') {
        sec = sec.and_then(|s| s.get_mut(part)).and_then(|s| s.as_table_mut());
    }
    let sec = sec.ok_or_else(|| Error::Invalid(format!("--set '{spec}': no section '{section}'")))?;
    if !sec.contains_key(key) && OPTIONAL_KEYS.contains(&(section, key)) {
        // Left out at their defaults: typed by the struct when it is read.
        sec.insert(key.to_string(), parsed);
        return Ok(());
    }
    let old = sec
        .get(key)
        .ok_or_else(|| Error::Invalid(format!("--set '{spec}': no key '{key}' in [{section}]")))?;
    // Keep the type: an integer key given "3.0" is an error, a float key given "3" is fine.
    let parsed = match (old, parsed) {
        (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(i as f64),
        (o, p) if std::mem::discriminant(o) == std::mem::discriminant(&p) => p,
        (o, p) => {
            return Err(Error::Invalid(format!(
                "--set '{spec}': {section}.{key} is a {}, not a {}",
                o.type_str(),
                p.type_str()
            )))
        }
    };
    sec.insert(key.to_string(), parsed);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_profiles_load() {
        let paper = Config::load("paper", &[]).unwrap();
        assert_eq!(paper.levels(), 5);
        assert_eq!(paper.train.crop, 41);
        assert_eq!(paper.model.channels, 128);
        let cpu = Config::load("cpu", &[]).unwrap();
        assert!(cpu.model.channels < paper.model.channels);
        assert_ne!(cpu.digest(), paper.digest());
    }

    #[test]
    fn overrides_apply_and_are_checked() {
        let c = Config::load("cpu", &["train.level0_iterations=7".into(), "sample.sampler=ddpm".into()]).unwrap();
        assert_eq!(c.train.level0_iterations, 7);
        assert_eq!(c.sample.sampler, crate::learn::schedule::Sampler::Ddpm);
        let c = Config::load("cpu", &["train.lr=1".into()]).unwrap();
        assert_eq!(c.train.lr, 1.0);
        assert!(Config::load("cpu", &["train.nothing=1".into()]).is_err());
        assert!(Config::load("cpu", &["train.crop=big".into()]).is_err());
        assert!(Config::load("cpu", &["sample.sampler=euler".into()]).is_err());
        assert!(Config::load("cpu", &["encode.finest_resolution=100".into()]).is_err());
        assert!(Config::load("nonexistent", &[]).is_err());
    }

    #[test]
    fn overrides_on_a_recorded_config() {
        let a = Config::load("cpu", &["train.crop=17".into()]).unwrap();
        let b = a.with_overrides(&["sample.sampler=ddpm".into()]).unwrap();
        assert_eq!(b.train.crop, 17, "recorded values are kept");
        assert_eq!(b.sample.sampler, crate::learn::schedule::Sampler::Ddpm);
        assert_eq!(a.with_overrides(&[]).unwrap(), a);
        assert!(a.with_overrides(&["sample.sampler=euler".into()]).is_err());
    }

    /// Digests are recorded in every stamp and level file: a change of the
    /// configuration's text (a field renamed, retyped or dropped) makes every
    /// existing run retrain. The cpu profile's digest as 67f8725 recorded it
    /// (four levels to 128^3, no detail transfer: the profile before 2026-12-01).
    #[test]
    fn detail_transfer_levels() {
        let cpu = Config::load("cpu", &[]).unwrap();
        assert_eq!((cpu.levels(), cpu.trained_levels()), (5, 3), "networks 16..64, transfer 128 and 256");
        let demo = Config::load("demo", &[]).unwrap();
        assert_eq!((demo.levels(), demo.trained_levels()), (4, 3));
        let paper = Config::load("paper", &[]).unwrap();
        assert!(paper.transfer.is_off());
        assert_eq!(paper.trained_levels(), 5);
        // A small test configuration keeps its networks: 16, 32 are below 128.
        let small = Config::load("cpu", &["encode.finest_resolution=32".into()]).unwrap();
        assert_eq!(small.trained_levels(), 2);
        let all = Config::load("cpu", &["transfer.from_resolution=32".into()]).unwrap();
        assert_eq!(all.trained_levels(), 1);
        // Recorded, transfer changes what sampling depends on, not training.
        assert_ne!(all.stage_digest(Stage::Sample), cpu.stage_digest(Stage::Sample));
        assert_eq!(all.stage_digest(Stage::Train), cpu.stage_digest(Stage::Train));
        for bad in ["transfer.from_resolution=16", "transfer.from_resolution=100", "transfer.radius=0", "transfer.coherence=1.5"] {
            let e = Config::load("cpu", &[bad.into()]).unwrap_err().to_string();
            assert!(e.contains("transfer"), "{bad}: {e}");
        }
    }

    #[test]
    fn settings_not_written_at_their_defaults_can_be_set() {
        // The paper profile writes none of the rejection settings nor bf16.
        let paper = Config::load("paper", &[]).unwrap();
        assert!(!paper.to_toml().contains("attempts") && !paper.to_toml().contains("final_step"));
        let set = paper
            .with_overrides(&[
                "sample.final_step=update".into(),
                "sample.attempts.count=3".into(),
                "sample.level0.candidates=4".into(),
                // The name before the nesting still sets its key.
                "sample.level0_min_structure=0.7".into(),
                "train.bf16=true".into(),
            ])
            .unwrap();
        assert_eq!(set.sample.final_step, crate::learn::schedule::FinalStep::Update);
        assert_eq!((set.sample.attempts.count, set.sample.level0.candidates, set.sample.level0.min_structure), (3, 4, 0.7));
        assert!(set.train.bf16);
        assert_eq!(paper.with_overrides(&[]).unwrap(), paper, "defaults filled in change nothing");
        assert_eq!(paper.with_overrides(&[]).unwrap().digest(), paper.digest());
        let e = paper.with_overrides(&["sample.final_step=halfway".into()]).unwrap_err().to_string();
        assert!(e.contains("final_step") || e.contains("halfway"), "{e}");
        assert!(paper.with_overrides(&["sample.attempts.count=0".into()]).is_err());
        // resize_max: 0 (never) or a factor of at least the smallest resize,
        // with the novel pick of several candidates (else it cannot apply).
        assert_eq!(paper.sample.proposers.resize_max, 0.0);
        let novel = |more: &str| vec!["sample.level0={candidates = 8, pick = \"novel\"}".to_string(), more.to_string()];
        assert_eq!(paper.with_overrides(&novel("sample.proposers.resize_max=1.75")).unwrap().sample.proposers.resize_max, 1.75);
        // A whole table given: `sample.attempts` is the new table, not the old count.
        let quick = Config::load("cpu", &["sample.level0={candidates = 1}".into(), "sample.attempts={count = 1}".into(), "sample.proposers={}".into()]).unwrap();
        assert_eq!((quick.sample.level0.candidates, quick.sample.attempts.count, quick.sample.proposers.resize_max), (1, 1, 0.0));
        assert!(!quick.sample.attempts.reject_copies && quick.sample.filters.mend_sheets, "the other tables are the profile's");
        // A key set after its table was given whole.
        let then = Config::load("cpu", &["sample.level0={candidates = 1}".into(), "sample.proposers={}".into(), "sample.level0.sampler=ddim".into()]).unwrap();
        assert_eq!(then.sample.level0.sampler, Level0Sampler::Ddim);
        let old = Config::load("cpu", &["sample.attempts=2".into()]).unwrap();
        assert_eq!(old.sample.attempts.count, 2, "the old name sets the count");
        let e = paper.with_overrides(&["sample.proposers.resize_max=1.75".into()]).unwrap_err().to_string();
        assert!(e.contains("novel"), "{e}");
        for bad in ["1.1", "5", "-1"] {
            let e = paper.with_overrides(&novel(&format!("sample.resize_max={bad}"))).unwrap_err().to_string();
            assert!(e.contains("resize_max"), "{e}");
        }
    }

    #[test]
    fn digests_of_existing_runs_stay_valid() {
        let before: Vec<String> = [
            "encode.sampling_resolution=512",
            "encode.finest_resolution=128",
            "transfer.from_resolution=0",
            "model.channels=32",
            "model.upsampler_channels=16",
            "train.level0_iterations=2500",
            "train.upper_iterations=1000",
            "train.upsampler_iterations=400",
            "train.bf16=false",
            // The sampling rejection settings at their defaults are not
            // written: a configuration recorded before they existed.
            "sample.level0_candidates=1",
            "sample.level0_min_structure=0.0",
            "sample.attempts=1",
            "sample.reject_copies=false",
            "sample.mend_sheets=false",
            "sample.remove_specks=false",
            "sample.bend_voxels=0",
            "sample.resize_max=0",
            "sample.level0_pick=first",
            "sample.level0_sampler=same",
            "sample.level0_steps=50",
        ]
        .map(String::from)
        .to_vec();
        assert_eq!(Config::load("cpu", &before).unwrap().digest(), "ec8270f7727c41f7");
        let mut with_mixing = before.to_vec();
        with_mixing.push("train.mixing=\"code\"".into());
        let recorded = Config::load("cpu", &with_mixing).unwrap();
        assert_eq!(recorded.digest(), "ec8270f7727c41f7");
        // Transfer off is not written: the configuration reads back the same.
        assert!(!recorded.to_toml().contains("transfer"));
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("config.toml");
        std::fs::write(&p, recorded.to_toml()).unwrap();
        assert_eq!(Config::read(&p).unwrap(), recorded);
        let err = Config::load("cpu", &["train.mixing=\"paper\"".into()]).unwrap_err().to_string();
        assert!(err.contains("paper"), "{err}");
    }

    /// `output.usd_format`: text unless set (and then not recorded), binary
    /// on request, anything else refused with the accepted values.
    #[test]
    fn the_usd_format_is_text_unless_set() {
        use crate::io::usd::UsdFormat;
        let a = Config::load("cpu", &[]).unwrap();
        assert_eq!(a.output.usd_format, UsdFormat::Usda);
        assert!(!a.to_toml().contains("usd_format"));
        let b = Config::load("cpu", &["output.usd_format=usdc".into()]).unwrap();
        assert_eq!(b.output.usd_format, UsdFormat::Usdc);
        assert!(b.to_toml().contains("usd_format = \"usdc\""));
        let err = Config::load("cpu", &["output.usd_format=usdz".into()]).unwrap_err().to_string();
        assert!(err.contains("usdz") && err.contains("usdc"), "{err}");
    }

    /// The exemplar-file keys are left out at their defaults (old run folders'
    /// digests hold), and `--set` can still give them.
    #[test]
    fn exemplar_keys_are_optional_and_settable() {
        let a = Config::load("cpu", &[]).unwrap();
        assert!(!a.to_toml().contains("voxel_size") && !a.to_toml().contains("normal_orientation"));
        let b = Config::load("cpu", &["encode.voxel_size=2".into(), "encode.up=z".into(), "encode.cloud_colour=intensity".into()]).unwrap();
        assert_eq!(b.encode.voxel_size, Some(2.0));
        assert_eq!(b.encode.up, Some(crate::level::Up::Z));
        assert_eq!(b.encode.cloud_colour, crate::io::cloud::CloudColour::Intensity);
        assert_ne!(a.stage_digest(Stage::Encode), b.stage_digest(Stage::Encode));
        assert_eq!(b.with_overrides(&[]).unwrap().encode, b.encode, "recorded and read back");
        assert!(Config::load("cpu", &["encode.voxel_sise=2".into()]).is_err(), "a misspelt key");
    }

    #[test]
    fn stage_digests_ignore_later_stages() {
        let a = Config::load("cpu", &[]).unwrap();
        let b = Config::load("cpu", &["sample.upper_steps=99".into()]).unwrap();
        assert_eq!(a.stage_digest(Stage::Train), b.stage_digest(Stage::Train));
        assert_ne!(a.digest(), b.digest());
        let c = Config::load("cpu", &["train.crop=17".into()]).unwrap();
        assert_ne!(a.stage_digest(Stage::Train), c.stage_digest(Stage::Train));
        assert_eq!(a.stage_digest(Stage::Encode), c.stage_digest(Stage::Encode));
    }

    #[test]
    fn recorded_config_reads_back() {
        let a = Config::load("paper", &[]).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("config.toml");
        std::fs::write(&p, a.to_toml()).unwrap();
        assert_eq!(Config::read(&p).unwrap(), a);
    }

    #[test]
    fn mesh_settings_default_for_old_configs_and_take_overrides() {
        // (Configurations from before [mesh] had no [transfer] either.)
        let a = Config::load("cpu", &["transfer.from_resolution=0".into()]).unwrap();
        assert_eq!(a.mesh, MeshConfig { faces: 0, glb: false, texture: DEFAULT_TEXTURE });
        // A configuration recorded before [mesh] existed still reads.
        let old: String = a.to_toml().split("[mesh]").next().unwrap().to_string();
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("config.toml");
        std::fs::write(&p, old).unwrap();
        assert_eq!(Config::read(&p).unwrap(), a);
        let b = a.with_overrides(&["mesh.faces=50000".into(), "mesh.glb=true".into()]).unwrap();
        assert_eq!(b.mesh, MeshConfig { faces: 50000, glb: true, texture: DEFAULT_TEXTURE });
        let c = a.with_overrides(&["mesh.faces=20000".into(), "mesh.texture=1024".into()]).unwrap();
        assert_eq!(c.mesh.texture_size(), Some(1024));
        assert!(c.to_toml().contains("texture = 1024"));
        assert!(!a.to_toml().contains("texture"), "the default is left out of recorded configurations");
        assert_eq!(a.mesh.texture_size(), None);
        assert!(a.with_overrides(&["mesh.faces=-1".into()]).is_err());
    }
}
