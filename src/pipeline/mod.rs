//! The stages as whole-folder operations, and `run`: encode -> train ->
//! sample -> mesh -> USD -> evaluate in one output folder, reusing every
//! finished stage whose inputs and configuration are unchanged
//! ([`stamp`]). The run folder's layout (every name) is [`layout`]'s.
//!
//! One module per stage ([`encode`], [`train`], [`sample`], [`mesh`],
//! [`usd`], [`evaluate`]); [`run`] chains them, [`children`] runs a stage's
//! shards as processes of their own, [`cluster`] writes them as a SLURM job
//! graph, [`batch`] runs the one-file commands over many files. The
//! commands (`run`, `stage`, `train`, `sample`, `usd`, ...) and the cluster's
//! jobs call the same functions, so they write the same files and stamps.
//!
//! Every command is one function here taking a request and returning a
//! record (`sample_command`, `train_command`, [`stage::stage_command`],
//! ...): its policy (configuration, locks, checks, output names) is the
//! library's, and the binary only parses, calls and prints ([`command`]).

pub mod batch;
pub mod children;
pub mod cluster;
pub mod cluster_settings;
pub mod command;
pub mod edit;
pub mod encode;
pub mod evaluate;
pub mod keep;
pub mod ladder;
pub mod layout;
pub mod mesh;
pub mod run;
pub mod sample;
pub mod stage;
pub mod stamp;
pub mod train;
pub mod usd;

pub use children::{run_shards, train_in_processes};
pub use batch::Line;
pub use edit::edit_file;
pub use encode::*;
pub use evaluate::*;
pub use ladder::*;
pub use layout::{variant_dir, variant_name, RunPaths};
pub use mesh::*;
pub use sample::*;
pub use stamp::record_config;
pub use train::*;
pub use run::DEFAULT_PROFILE;
pub use usd::run_usd;
