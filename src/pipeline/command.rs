//! What the commands share: how a command's human output is handed to the
//! command line ([`Line`]), and the commands too small for a stage module of
//! their own (`info`, `studio`). Every command is one library function taking
//! a request and returning a record; the binary parses, calls and prints.

use std::path::PathBuf;

use super::batch::{self, Report};
use crate::error::Result;
use crate::io::info::{self, FileInfo};

/// One piece of a command's human output, in the order it happens: text for
/// stdout (printed as it is, newlines included), or one input's error for
/// stderr (printed as `error: MESSAGE`, as every error line of the command
/// line is). A batch's output interleaves the two, so it is a list of these
/// rather than one text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Line {
    Out(String),
    Error(String),
}

/// The exit status of a command whose inputs may fail one by one: 1 when
/// any failed (the others were still done), else 0.
pub fn exit_status(failed: usize) -> u8 {
    u8::from(failed > 0)
}

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

/// The `studio` command: the interactive page on a run folder until a stop
/// signal, telling `on_url` the page's address once it serves.
/// `threads_given`: whether the user chose the libtorch thread count; if
/// not, the studio takes every core, since it runs one job at a time (the
/// batch default of one thread suits processes that run side by side).
pub fn studio_command(request: &crate::studio::StudioRequest, threads_given: bool, on_url: &mut dyn FnMut(&str)) -> Result<()> {
    if !threads_given {
        tch::set_num_threads(std::thread::available_parallelism().map_or(1, |n| n.get()) as i32);
    }
    crate::studio::run_studio(request, on_url)
}
