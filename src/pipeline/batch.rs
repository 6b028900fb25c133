//! Batch conversion: one command over many input files (`encode`, `mesh`,
//! `points`, `info`), files worked on in parallel, each failure isolated and
//! reported on one line, the rest written.
//!
//! Output names come from the inputs: the file stem, lengthened by parent
//! folder names only where two inputs would collide
//! (`variant_000/level_4.vdb` and `variant_001/level_4.vdb` become
//! `variant_000_level_4` and `variant_001_level_4`).

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::error::{Error, Result};

/// The distinct output names of `inputs`, in order: the shortest trailing
/// run of path components (stem last) that tells every input apart.
pub fn output_names(inputs: &[PathBuf]) -> Result<Vec<String>> {
    let parts: Vec<Vec<String>> = inputs
        .iter()
        .map(|p| {
            let mut v: Vec<String> = p
                .parent()
                .map(|d| d.components().filter_map(|c| match c {
                    std::path::Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
                    _ => None,
                }).collect())
                .unwrap_or_default();
            v.push(p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default());
            v
        })
        .collect();
    let longest = parts.iter().map(Vec::len).max().unwrap_or(0);
    let names_at = |depth: usize| -> Vec<String> {
        parts.iter().map(|p| p[p.len().saturating_sub(depth)..].join("_")).collect()
    };
    for depth in 1..longest {
        let names = names_at(depth);
        if names.iter().collect::<HashSet<_>>().len() == names.len() {
            return Ok(names);
        }
    }
    let names = names_at(longest.max(1));
    for (j, name) in names.iter().enumerate() {
        if let Some(i) = names[..j].iter().position(|n| n == name) {
            let same = |p: &Path| p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
            return Err(Error::Invalid(if same(&inputs[i]) == same(&inputs[j]) {
                format!("{}: given twice", inputs[j].display())
            } else {
                format!("{} and {} would both be written as '{name}'", inputs[i].display(), inputs[j].display())
            }));
        }
    }
    Ok(names)
}

/// What happened to one input.
#[derive(Clone, Debug, Serialize)]
pub struct Outcome<T> {
    pub input: PathBuf,
    /// What was written (a file or a folder), on success.
    pub output: Option<PathBuf>,
    /// On success: what the conversion reports.
    pub result: Option<T>,
    /// On failure: one line.
    pub error: Option<String>,
    pub seconds: f64,
}

/// Every outcome of a batch, in input order, and its wall time.
#[derive(Clone, Debug, Serialize)]
pub struct Report<T> {
    pub outcomes: Vec<Outcome<T>>,
    pub jobs: usize,
    pub seconds: f64,
}

impl<T> Report<T> {
    pub fn failed(&self) -> usize {
        self.outcomes.iter().filter(|o| o.error.is_some()).count()
    }

    /// 1 when any input failed ([`exit_status`]).
    pub fn exit_status(&self) -> u8 {
        exit_status(self.failed())
    }

    /// `encode: 12 of 13 done, 1 failed, 8.3 s on 2 threads -> OUT`.
    pub fn summary(&self, what: &str, out: Option<&Path>) -> String {
        let n = self.outcomes.len();
        let failed = self.failed();
        let mut s = format!("{what}: {} of {n} done", n - failed);
        if failed > 0 {
            s += &format!(", {failed} failed");
        }
        s += &format!(", {:.1} s on {} thread{}", self.seconds, self.jobs, if self.jobs == 1 { "" } else { "s" });
        if let Some(o) = out {
            s += &format!(" -> {}", o.display());
        }
        s
    }
}

/// A batch conversion's outcome (`encode`, `mesh`, `points`): its report
/// (what `--json` prints) and how it is told to a person.
#[derive(Clone, Debug)]
pub struct Converted<T> {
    pub report: Report<T>,
    /// The command's name, for the summary line.
    pub what: &'static str,
    /// The folder the outputs went into, when there were several inputs.
    pub folder: Option<PathBuf>,
}

impl<T> Converted<T> {
    /// One line per input (`IN -> OUT (S s)`, or its error) and, for
    /// several inputs, the summary ([`Report::summary`]).
    pub fn lines(&self) -> Vec<Line> {
        let mut lines: Vec<Line> = self
            .report
            .outcomes
            .iter()
            .filter_map(|o| match (&o.output, &o.error) {
                (_, Some(e)) => Some(Line::Error(e.clone())),
                (Some(out), None) => Some(Line::Out(format!("{} -> {} ({:.1} s)\n", o.input.display(), out.display(), o.seconds))),
                (None, None) => None,
            })
            .collect();
        if self.report.outcomes.len() > 1 {
            lines.push(Line::Out(format!("{}\n", self.report.summary(self.what, self.folder.as_deref()))));
        }
        lines
    }

    /// 1 when any input failed.
    pub fn exit_status(&self) -> u8 {
        self.report.exit_status()
    }
}

/// Where a batch command writes the input named `name` (from
/// [`output_names`]): `output` itself when it is the only input, else
/// `output/NAME.EXT`, or the folder `output/NAME` with `ext` None.
pub fn target(output: &Path, name: &str, several: bool, ext: Option<&str>) -> PathBuf {
    match ext {
        _ if !several => output.to_path_buf(),
        Some(ext) => output.join(format!("{name}.{ext}")),
        None => output.join(name),
    }
}

/// Runs `convert(input, output_name)` on every input, `jobs` at a time (0:
/// one per core), each in its own thread of a private pool; a failure (an
/// error or a panic) becomes that input's one-line error and the others go on.
pub fn run<T, F>(inputs: &[PathBuf], names: &[String], jobs: usize, convert: F) -> Report<T>
where
    T: Send,
    F: Fn(&Path, &str) -> std::result::Result<(Option<PathBuf>, T), String> + Sync,
{
    use rayon::prelude::*;
    let jobs = if jobs == 0 { std::thread::available_parallelism().map_or(1, |n| n.get()) } else { jobs };
    let jobs = jobs.min(inputs.len()).max(1);
    let t0 = Instant::now();
    let one = |(input, name): (&PathBuf, &String)| {
        let t = Instant::now();
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| convert(input, name)))
            .unwrap_or_else(|p| {
                let what = p.downcast_ref::<String>().cloned().or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()));
                Err(format!("internal error: {}", what.unwrap_or_else(|| "panic".into())))
            });
        let (output, result, error) = match r {
            Ok((o, v)) => (o, Some(v), None),
            Err(e) => (None, None, Some(crate::error::one_line(&e))),
        };
        Outcome { input: input.clone(), output, result, error, seconds: t.elapsed().as_secs_f64() }
    };
    let outcomes = match rayon::ThreadPoolBuilder::new().num_threads(jobs).build() {
        Ok(pool) => pool.install(|| inputs.par_iter().zip(names).with_max_len(1).map(one).collect()),
        // No threads to be had: one at a time is still correct.
        Err(_) => inputs.iter().zip(names).map(one).collect(),
    };
    Report { outcomes, jobs, seconds: t0.elapsed().as_secs_f64() }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    fn paths(v: &[&str]) -> Vec<PathBuf> {
        v.iter().map(PathBuf::from).collect()
    }

    #[test]
    fn names_are_stems_unless_they_collide() {
        assert_eq!(output_names(&paths(&["a/tower.obj", "b/cliff.ply"])).unwrap(), ["tower", "cliff"]);
        assert_eq!(
            output_names(&paths(&["out/v/variant_000/level_4.vdb", "out/v/variant_001/level_4.vdb"])).unwrap(),
            ["variant_000_level_4", "variant_001_level_4"]
        );
        // Same stem, different extensions: the stems collide at every depth.
        assert!(output_names(&paths(&["x/tower.obj", "x/tower.ply"])).unwrap_err().to_string().contains("both be written as 'x_tower'"));
        assert!(output_names(&paths(&["tower.obj", "tower.obj"])).unwrap_err().to_string().contains("given twice"));
    }

    /// Each input's line (its output, or its error for stderr) in input
    /// order, then the summary; one input is written to OUT itself.
    #[test]
    fn conversions_are_told_line_by_line_then_summed_up() {
        let inputs = paths(&["a/x.obj", "b/y.obj"]);
        let names = output_names(&inputs).unwrap();
        let report = run(&inputs, &names, 1, |p, name| match p.ends_with("y.obj") {
            true => Err("bad".to_string()),
            false => Ok((Some(target(Path::new("out"), name, true, Some("ply"))), ())),
        });
        let told = Converted { report, what: "mesh", folder: Some(PathBuf::from("out")) };
        let lines = told.lines();
        assert!(matches!(&lines[0], Line::Out(l) if l.starts_with("a/x.obj -> out/x.ply (") && l.ends_with(" s)\n")), "{lines:?}");
        assert_eq!(lines[1], Line::Error("bad".into()));
        assert!(matches!(&lines[2], Line::Out(l) if l.starts_with("mesh: 1 of 2 done, 1 failed") && l.ends_with(" -> out\n")), "{lines:?}");
        assert_eq!((lines.len(), told.exit_status()), (3, 1));
        assert_eq!(target(Path::new("one.ply"), "x", false, Some("ply")), Path::new("one.ply"));
        assert_eq!(target(Path::new("out"), "x", true, None), Path::new("out/x"));
    }

    #[test]
    fn failures_are_isolated_and_in_order() {
        let inputs = paths(&["a", "bad", "c", "panics"]);
        let names = output_names(&inputs).unwrap();
        let report = run(&inputs, &names, 2, |p, name| match p.to_str() {
            Some("bad") => Err("bad input:\n  line two".to_string()),
            Some("panics") => panic!("boom"),
            _ => Ok((Some(PathBuf::from(format!("{name}.out"))), name.len())),
        });
        assert_eq!(report.failed(), 2);
        let got: Vec<_> = report.outcomes.iter().map(|o| (o.result, o.error.clone())).collect();
        assert_eq!(got[0], (Some(1), None));
        assert_eq!(got[1], (None, Some("bad input: line two".to_string())));
        assert_eq!(got[2], (Some(1), None));
        assert_eq!(got[3], (None, Some("internal error: boom".to_string())));
        assert!(report.summary("encode", None).starts_with("encode: 2 of 4 done, 2 failed"));
    }
}
