//! Progress for task graphs: with `--progress alf` the command prints
//! `ALF_PROGRESS nn%` lines on stderr as its work advances (the line Houdini
//! PDG's schedulers, Tractor and Alfred parse from a job's log), a line each
//! time the whole command passes another percent. stdout is left alone, so
//! `--json` records stay one per line.
//!
//! The stages say where they are as a fraction of their own work; spans
//! ([`span`]) map that onto the whole command: `run` gives training 75% of
//! it, training gives each level a share by its cost, and so on down to one
//! training step. With any other mode every call is a load of an atomic.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

static ALF: AtomicBool = AtomicBool::new(false);
static PROGRESS: Mutex<Progress> = Mutex::new(Progress::new());

/// The open spans, as absolute fractions of the whole command (innermost
/// last), and the last percent printed.
struct Progress {
    spans: Vec<(f64, f64)>,
    last: i32,
}

impl Progress {
    const fn new() -> Self {
        Progress { spans: Vec::new(), last: -1 }
    }

    fn open(&mut self, start: f64, end: f64) {
        let (a, b) = self.spans.last().copied().unwrap_or((0.0, 1.0));
        let (s, e) = (start.clamp(0.0, 1.0), end.clamp(0.0, 1.0));
        self.spans.push((a + (b - a) * s, a + (b - a) * e.max(s)));
    }

    fn close(&mut self) -> Option<i32> {
        let printed = self.at(1.0);
        self.spans.pop();
        printed
    }

    /// The percent to print when the current span is `fraction` done, if it
    /// is past the last one printed.
    fn at(&mut self, fraction: f64) -> Option<i32> {
        let (a, b) = self.spans.last().copied().unwrap_or((0.0, 1.0));
        let whole = a + (b - a) * fraction.clamp(0.0, 1.0);
        let percent = (whole * 100.0 + 1e-9).floor() as i32;
        (percent > self.last).then(|| {
            self.last = percent;
            percent
        })
    }
}

fn state() -> std::sync::MutexGuard<'static, Progress> {
    PROGRESS.lock().unwrap_or_else(|e| e.into_inner())
}

fn print(percent: Option<i32>) {
    if let Some(p) = percent {
        eprintln!("ALF_PROGRESS {p}%");
    }
}

/// Turns `ALF_PROGRESS` lines on (the `--progress alf` flag).
pub fn enable_alf() {
    ALF.store(true, Ordering::SeqCst);
}

/// Whether `ALF_PROGRESS` lines are printed (interactive bars are then off).
pub fn alf() -> bool {
    ALF.load(Ordering::Relaxed)
}

/// A part of the enclosing span, from `start` to `end` (fractions of it);
/// closed when the guard drops, which reports its end as reached.
#[must_use = "the span closes when this guard drops"]
pub struct Span {
    open: bool,
}

/// Opens the part `start..end` of the current span (the whole command when
/// none is open).
pub fn span(start: f64, end: f64) -> Span {
    if !alf() {
        return Span { open: false };
    }
    state().open(start, end);
    Span { open: true }
}

impl Drop for Span {
    fn drop(&mut self) {
        if self.open {
            let printed = state().close();
            print(printed);
        }
    }
}

/// The current span is `fraction` done: prints a line when that passes a
/// percent of the whole command not printed yet (never going back).
pub fn report(fraction: f64) {
    if alf() {
        let printed = state().at(fraction);
        print(printed);
    }
}

/// `done` of `total` parts of the current span.
pub fn report_parts(done: usize, total: usize) {
    if total > 0 {
        report(done as f64 / total as f64);
    }
}

#[cfg(test)]
mod tests {
    use super::Progress;

    #[test]
    fn nested_spans_map_onto_the_whole_and_never_go_back() {
        let mut p = Progress::new();
        p.open(0.0, 0.5);
        p.open(0.5, 1.0);
        // 0.5 of 0.5..1.0 of 0..0.5 = 0.375 of the whole.
        assert_eq!(p.at(0.5), Some(37));
        assert_eq!(p.at(0.5), None, "a percent is printed once");
        assert_eq!(p.close(), Some(50), "a closed span reports its end");
        assert_eq!(p.at(0.2), None, "progress never goes back");
        assert_eq!(p.close(), None);
        assert_eq!(p.at(1.0), Some(100));
    }
}
