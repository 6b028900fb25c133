//! The `shapeshifter` command: parse, call the library, map errors to exit codes:
//! 0 done; 1 an input failed (the others were still done), or an internal
//! error (a panic, reported as one line); 2 bad usage (the command line, a
//! `--set`, a profile, an encoding setting); 128 + N stopped by signal N.

use std::process::ExitCode;

use clap::Parser;

mod cli;

fn main() -> ExitCode {
    use shapeshifter::util::interrupt;
    shapeshifter::util::alloc::tune_allocator();
    shapeshifter::util::mark_command_start();
    let args = cli::Cli::parse();
    cli::init_logging(&args);
    if let Err(e) = interrupt::install() {
        eprintln!("error: cannot watch for stop signals: {e}");
        return ExitCode::FAILURE;
    }
    report_panics_as_one_line();
    // A panic is a bug, but the command still ends as the command line
    // promises: one error line (printed by the hook) and exit status 1, not
    // Rust's 101 and a multi-line message.
    let result = std::panic::catch_unwind(|| cli::run(args));
    // Stopped by a signal: 128 + its number (130 SIGINT, 143 SIGTERM), with
    // one line saying so, whatever error the stop surfaced as.
    if let Some(sig) = interrupt::requested() {
        eprintln!("error: {}", shapeshifter::Error::Stopped(interrupt::name(sig)));
        return ExitCode::from(interrupt::exit_status(sig));
    }
    match result {
        Err(_) => ExitCode::FAILURE,
        Ok(Ok(code)) => code,
        Ok(Err(e)) => {
            // One line: the chain of causes joined.
            let msg: Vec<String> = e.chain().map(|c| c.to_string()).collect();
            eprintln!("error: {}", shapeshifter::error::one_line(&msg.join(": ")));
            // A setting refused before any work: 2, as clap's own errors.
            let usage = e.chain().any(|c| matches!(c.downcast_ref::<shapeshifter::Error>(), Some(shapeshifter::Error::Usage(_))));
            if usage {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// A panic (on any thread) prints one line naming where it happened; with
/// RUST_BACKTRACE set, the backtrace follows it.
fn report_panics_as_one_line() {
    std::panic::set_hook(Box::new(|info| {
        let payload = info.payload();
        let what = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into());
        let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
        eprintln!(
            "error: internal error: {}{at} (a bug in shapeshifter; please report it with the command line)",
            shapeshifter::error::one_line(&what)
        );
        if std::env::var_os("RUST_BACKTRACE").is_some_and(|v| v != "0") {
            eprintln!("{}", std::backtrace::Backtrace::force_capture());
        }
    }));
}
