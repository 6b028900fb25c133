//! Command-line definitions and dispatch (the binary's only logic).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

use shapeshifter::info;

#[derive(Parser, Debug)]
#[command(name = "shapeshifter", version, about = "3D shape variations from one exemplar mesh (ShapeShifter, CVPR 2025)")]
pub struct Cli {
    /// Only errors on stderr.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// More detail on stderr (-vv for debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Describe level files (.vdb: grids, types, voxels, bounds, transform,
    /// metadata) and meshes (counts, bounds, closed/open, colour source).
    ///
    /// Example: shapeshifter info out/levels/level_4.vdb tower.obj
    Info {
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
}

pub fn init_logging(cli: &Cli) {
    let level = if cli.quiet {
        "error"
    } else {
        match cli.verbose {
            0 => "info",
            1 => "debug",
            _ => "trace",
        }
    };
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(level))
        .format_timestamp(None)
        .format_target(false)
        .init();
}

pub fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Info { files } => {
            let mut failed = 0;
            for f in &files {
                match info::describe(f) {
                    Ok(text) => print!("{text}"),
                    Err(e) => {
                        eprintln!("error: {e}");
                        failed += 1;
                    }
                }
            }
            Ok(if failed > 0 { ExitCode::FAILURE } else { ExitCode::SUCCESS })
        }
    }
}
