//! `[output]`: how the files that leave the program are laid out (level
//! files' points, the USD layers' units and encoding).

use serde::{Deserialize, Serialize};

/// Files that leave the program.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    /// Where each level's PointDataGrid goes: "separate" (level_K.points.vdb
    /// beside level_K.vdb: every client reads the volumes file), "embedded"
    /// (one file; pyopenvdb's readAll then fails on it) or "none".
    #[serde(default)]
    pub points: crate::io::vdb::PointsLayout,
    /// Metres per unit of the exemplar's coordinates, stated in the USD
    /// layers (`metersPerUnit`); 1: the exemplar is in metres. Left out of
    /// recorded configurations at 1.
    #[serde(default = "one_f64", skip_serializing_if = "is_one_f64")]
    pub meters_per_unit: f64,
    /// The encoding of the USD layers: "usda" (text) or "usdc" (binary: a
    /// fraction of the size, opened faster). Left out of recorded
    /// configurations at "usda".
    #[serde(default, skip_serializing_if = "is_usda")]
    pub usd_format: crate::io::usd::UsdFormat,
}

fn is_usda(f: &crate::io::usd::UsdFormat) -> bool {
    *f == crate::io::usd::UsdFormat::Usda
}

/// A serde default of 1.
fn one_f64() -> f64 {
    1.0
}
fn is_one_f64(v: &f64) -> bool {
    *v == 1.0
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig { points: Default::default(), meters_per_unit: 1.0, usd_format: Default::default() }
    }
}

impl OutputConfig {
    pub fn write_options(&self) -> crate::io::vdb::WriteOptions {
        crate::io::vdb::WriteOptions { points: self.points, ..Default::default() }
    }
}
