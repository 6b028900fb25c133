//! The `shapeshifter` command: parse, call the library, map errors to exit codes:
//! 0 done; 1 an input failed (the others were still done); 2 bad usage (the
//! command line, a `--set`, a profile); 128 + N stopped by signal N.

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
    let result = cli::run(args);
    // Stopped by a signal: 128 + its number (130 SIGINT, 143 SIGTERM), with
    // one line saying so, whatever error the stop surfaced as.
    if let Some(sig) = interrupt::requested() {
        eprintln!("error: {}", shapeshifter::Error::Stopped(interrupt::name(sig)));
        return ExitCode::from(interrupt::exit_status(sig));
    }
    match result {
        Ok(code) => code,
        Err(e) => {
            // One line: the chain of causes joined.
            let msg: Vec<String> = e.chain().map(|c| c.to_string()).collect();
            eprintln!("error: {}", msg.join(": "));
            // A command line refused before any work: 2, as clap's own errors.
            if e.downcast_ref::<cli::Usage>().is_some() {
                return ExitCode::from(2);
            }
            ExitCode::FAILURE
        }
    }
}
