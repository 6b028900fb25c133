//! What the commands share: how a command's human output is handed to the
//! command line ([`Line`]), and the commands too small for a stage module of
//! their own (`info`; `studio` is the studio's). Every command is one library function taking
//! a request and returning a record; the binary parses, calls and prints.

use std::path::PathBuf;

use super::batch::{self, Line, Report};
use crate::io::info::{self, FileInfo};

/// The `info` command: every file described, `jobs` at a time (0: one per
/// core), each failure its own one-line error.
pub fn info_command(files: &[PathBuf], jobs: usize) -> Report<FileInfo> {
    // Info writes nothing, so two inputs of one name are no clash: each is
    // named as given.
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    batch::run(files, &names, jobs, |f, _| info::inspect(f).map(|i| (None, i)).map_err(|e| e.to_string()))
}

impl Report<FileInfo> {
    /// `info`'s human output: each file's description, or its error.
    pub fn info_lines(&self) -> Vec<Line> {
        self.outcomes
            .iter()
            .filter_map(|o| match (&o.result, &o.error) {
                (Some(i), _) => Some(Line::Out(i.to_text())),
                (_, Some(e)) => Some(Line::Error(e.clone())),
                _ => None,
            })
            .collect()
    }
}
