//! The library's error type: every failure names the file and the problem.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },
    #[error("{0}")]
    Invalid(String),
    /// A setting the user gave is invalid (a profile, a `--set`, an encoding
    /// setting, a command-line value such as `--extent`), found before any
    /// work: the command exits 2, as for clap's own usage errors.
    #[error("{0}")]
    Usage(String),
    /// A stop signal arrived (util::interrupt); what is on disk is whole and
    /// the same command resumes.
    #[error("stopped by {0}: what is on disk is whole; run the same command again to resume")]
    Stopped(&'static str),
    /// A job was cancelled by who asked for it (the studio's cancel): it
    /// stopped between steps and wrote nothing.
    #[error("cancelled")]
    Cancelled,
    /// Over a bound of what a long-lived process holds (the studio's queue,
    /// its open drafts): nothing was taken; ask again when some is done.
    #[error("{0}")]
    Busy(String),
    #[error(transparent)]
    Torch(#[from] tch::TchError),
    /// A stage's own error (encoding, rendering, the sparse grid and
    /// tensors, meshing, the detail transfer, a degenerate shape): each
    /// stage converts its error type into this one where it is defined
    /// ([`stage_error!`]), so this base module imports no stage.
    #[error(transparent)]
    Stage(Box<dyn std::error::Error + Send + Sync + 'static>),
}

impl Error {
    /// The message is made one short line: C++ readers quote what they read
    /// from a damaged file (a grid type name of a million spaces, a newline)
    /// and the error must stay the one line the command line promises.
    pub fn file(path: &Path, message: impl Into<String>) -> Self {
        Error::File { path: path.to_path_buf(), message: one_line(&message.into()) }
    }

    /// A usage error ([`Error::Usage`]) with the message of `e`.
    pub fn usage(e: impl std::fmt::Display) -> Self {
        Error::Usage(one_line(&e.to_string()))
    }
}

/// Longest message kept, in characters; longer ones are cut with an ellipsis.
const MAX_MESSAGE: usize = 300;

/// `message` with control characters as spaces, runs of whitespace collapsed
/// and at most [`MAX_MESSAGE`] characters.
pub fn one_line(message: &str) -> String {
    let mut out = String::new();
    let mut kept = 0;
    for word in message.split(|c: char| c.is_whitespace() || c.is_control()).filter(|w| !w.is_empty()) {
        if kept > 0 {
            out.push(' ');
            kept += 1;
        }
        for c in word.chars() {
            if kept == MAX_MESSAGE {
                out.push('…');
                return out;
            }
            out.push(c);
            kept += 1;
        }
    }
    out
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// `From<$stage_error> for Error`, written beside the stage's error type.
#[macro_export]
macro_rules! stage_error {
    ($t:ty) => {
        impl From<$t> for $crate::error::Error {
            fn from(e: $t) -> Self {
                $crate::error::Error::Stage(Box::new(e))
            }
        }
    };
}

#[cfg(test)]
mod tests {
    #[test]
    fn messages_become_one_short_line() {
        assert_eq!(super::one_line("Grid type \n  x\r\0y  "), "Grid type x y");
        let long = super::one_line(&"ab ".repeat(1000));
        assert!(long.chars().count() <= super::MAX_MESSAGE + 1 && long.ends_with('…'), "{long}");
    }
}
