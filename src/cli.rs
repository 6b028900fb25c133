//! The command line's dispatch: what clap parsed ([`args`]) into one library
//! request per command, the call, its record printed, its exit status. Every
//! decision (configuration, locks, checks, output names, formats) is the
//! library's ([`shapeshifter::pipeline`]); here only the translation from
//! arguments and the choice between a record's JSON and its text.

use std::process::ExitCode;

use anyhow::Result;

use shapeshifter::pipeline::{self, Line};
use shapeshifter::render::RenderOptions;

mod args;
pub use args::*;

/// Log lines on stderr, as many as `--quiet` and `-v` ask for (`RUST_LOG` overrides).
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
    // How a panic ends the command (one line, exit 1) is checked by the tests
    // through this variable: on this thread, or on a worker thread.
    match std::env::var("SHAPESHIFTER_TEST_PANIC").as_deref() {
        Ok("main") => panic!("a test panic on the main thread"),
        Ok("worker") => rayon::scope(|s| s.spawn(|_| panic!("a test panic on a worker thread"))),
        _ => {}
    }
    if cli.progress == ProgressMode::Alf {
        shapeshifter::util::progress::enable_alf();
    }
    // No progress bars with --quiet, or with ALF lines (or none) instead.
    let bars = !cli.quiet && cli.progress == ProgressMode::Bars;
    shapeshifter::learn::reproducible_kernels();
    if cli.threads > 0 {
        tch::set_num_threads(cli.threads);
    }
    let wait = cli.wait;
    match cli.command {
        Command::Info { files, batch } => {
            let report = pipeline::command::info_command(&files, batch.jobs);
            if batch.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print_lines(&report.info_lines());
            }
            Ok(ExitCode::from(report.exit_status()))
        }
        Command::Encode { meshes, output, sampling_resolution, coarsest, finest, pooling, preview, points, view, exemplar, batch } => {
            let previews = preview.then(|| render_options(&view));
            let converted = pipeline::encode_command(&pipeline::EncodeRequest {
                meshes: &meshes,
                output: &output,
                sampling_resolution,
                coarsest,
                finest,
                pooling,
                exemplar: &exemplar_settings(&exemplar),
                previews: previews.as_ref(),
                points,
                jobs: batch.jobs,
            })?;
            finish_batch(&converted, batch.json)
        }
        Command::Edit { input, output, op } => {
            let (region, to) = match &op {
                EditOp::Delete { region } => (region, None),
                EditOp::Copy { region, to } => (region, Some(to.as_str())),
            };
            let request = pipeline::edit::EditRequest { input: &input, output: &output, region, to };
            // Edited first, logged after: a log macro's arguments are not
            // evaluated at the quiet level.
            let what = pipeline::edit::edit_command(&request)?;
            log::info!("{what}");
            Ok(ExitCode::SUCCESS)
        }
        Command::Eval { exemplar, variants, exemplar_mesh, resolution, output, json } => {
            let evaluation = pipeline::eval_command(&pipeline::EvalRequest {
                exemplar: &exemplar,
                variants: &variants,
                exemplar_mesh: exemplar_mesh.as_deref(),
                resolution,
                output: output.as_deref(),
            })?;
            if json {
                println!("{}", serde_json::to_string_pretty(&evaluation)?);
            } else {
                print!("{}", evaluation.table());
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Train { dir, models, level, resume, jobs, setup } => {
            let record = pipeline::train_command(&pipeline::TrainRequest {
                dir: &dir,
                models: models.as_deref(),
                level,
                resume,
                jobs,
                profile: setup.profile.as_deref(),
                overrides: &setup.overrides,
                device_spec: &setup.device,
                threads: cli.threads,
                progress: bars,
                wait,
            })?;
            print!("{record}");
            Ok(ExitCode::SUCCESS)
        }
        Command::Sample { dir, output, models, n, first, seed, extent, stop_level, from, preview, overrides, device, json } => {
            let request = pipeline::sample::SampleRequest {
                models: models.as_deref(),
                n,
                first,
                seed,
                extent: extent.0,
                stop_level,
                from: from.as_deref(),
                previews: preview,
                overrides: &overrides,
                device_spec: &device,
                wait,
            };
            let record = pipeline::sample::sample_command(&dir, &output, &request)?;
            if json {
                println!("{}", serde_json::to_string(&record)?);
            } else {
                println!("{record}");
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Run { meshes, output, run } => run_many(pipeline::run::Exemplars::Files(&meshes), &output, &run, bars, cli.threads, wait),
        Command::Demo { output, run } => run_many(pipeline::run::Exemplars::Demo, &output, &run, bars, cli.threads, wait),
        Command::Mesh { inputs, output, format, method, resolution, depth, faces, preview, batch } => {
            let converted = pipeline::mesh::mesh_command(&pipeline::mesh::MeshRequest {
                inputs: &inputs,
                output: &output,
                format,
                method,
                resolution,
                depth,
                faces,
                preview: preview.as_deref(),
                jobs: batch.jobs,
            })?;
            finish_batch(&converted, batch.json)
        }
        Command::Points { inputs, output, batch } => finish_batch(&pipeline::mesh::points_command(&inputs, &output, batch.jobs)?, batch.json),
        Command::Render { inputs, output, view, up } => {
            if let Some(sheet) = pipeline::render_inputs(&inputs, &output, &render_options(&view), up)? {
                log::info!("{sheet}");
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Stage { stage } => {
            print!("{}", pipeline::stage::stage_command(&stage_request(&stage), bars, wait)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::Slurm { meshes, output, n, seed, profile, overrides, partition, gpus_per_job, dry_run } => {
            let request = pipeline::cluster::SlurmRequest {
                meshes: &meshes,
                output: &output,
                n,
                seed,
                profile: &profile,
                overrides: &overrides,
                partition: partition.as_deref(),
                gpus_per_job,
                dry_run,
            };
            pipeline::cluster::slurm_command(&request, |text| print!("{text}"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Usd { dir, meters_per_unit, format, json } => {
            let outcome = pipeline::usd::usd_command(&pipeline::usd::UsdRequest { dir: &dir, meters_per_unit, format, wait })?;
            if json {
                println!("{}", serde_json::to_string_pretty(&outcome)?);
            } else {
                println!("{outcome}");
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Compare { a, b } => {
            let report = shapeshifter::io::dataset::compare_levels(&a, &b)?;
            print!("{report}");
            Ok(ExitCode::from(report.exit_status()))
        }
        Command::Studio { dir, port, device, precision } => {
            // Whether the thread count was chosen: clap's default looks the
            // same as a given value, so the command line itself is asked.
            let given = std::env::var_os("SHAPESHIFTER_THREADS").is_some() || std::env::args().any(|a| a.starts_with("--threads"));
            let request = shapeshifter::studio::StudioRequest { dir: &dir, port, device_spec: &device, precision, wait };
            shapeshifter::studio::studio_command(&request, given, &mut |url| {
                // On stdout, whatever the log level: a script reads the address.
                println!("studio: {url}");
                let _ = std::io::Write::flush(&mut std::io::stdout());
                log::info!("studio: open {url} in a browser on this machine; Ctrl-C ends it");
            })?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Ladder { dir, output, profile, device } => {
            let request = pipeline::LadderRequest { dir: &dir, output: &output, profile: profile.as_deref(), device_spec: &device };
            let record = pipeline::ladder_command(&request, &mut |line| println!("{line}"))?;
            print!("{record}");
            Ok(ExitCode::from(record.exit_status()?))
        }
    }
}

/// `run` and `demo`: each exemplar's summary (or JSON record) printed as it
/// finishes.
fn run_many(exemplars: pipeline::run::Exemplars, output: &std::path::Path, args: &RunArgs, bars: bool, threads: i32, wait: bool) -> Result<ExitCode> {
    let request = pipeline::run::RunRequest {
        profile: args.setup.profile.as_deref(),
        overrides: &args.setup.overrides,
        exemplar: &exemplar_settings(&args.exemplar),
        device_spec: &args.setup.device,
        n: args.n,
        seed: args.seed,
        jobs: args.jobs,
        threads,
        progress: bars,
        json: args.json,
        wait,
    };
    Ok(ExitCode::from(pipeline::run::run_command(exemplars, output, &request, print_lines)?))
}

/// A batch conversion's report: as JSON on request, else its lines.
fn finish_batch<T: serde::Serialize>(converted: &pipeline::batch::Converted<T>, json: bool) -> Result<ExitCode> {
    if json {
        println!("{}", serde_json::to_string_pretty(&converted.report)?);
    } else {
        print_lines(&converted.lines());
    }
    Ok(ExitCode::from(converted.exit_status()))
}

/// A command's human output, each piece to its stream, in order.
fn print_lines(lines: &[Line]) {
    for line in lines {
        match line {
            Line::Out(text) => print!("{text}"),
            Line::Error(e) => eprintln!("error: {e}"),
        }
    }
}

// What clap parsed, as the library's requests: field for field, no choices.

fn stage_request(stage: &StageCmd) -> pipeline::stage::StageRequest<'_> {
    use pipeline::stage::StageRequest as R;
    match stage {
        StageCmd::Encode { mesh, output, profile, overrides } => R::Encode { mesh, output, profile, overrides },
        StageCmd::Train { dir, level, device } => R::Train { dir, level: *level, device_spec: device },
        StageCmd::Sample { dir, first, n, seed, device } => R::Sample { dir, first: *first, n: *n, seed: *seed, device_spec: device },
        StageCmd::Mesh { dir, first, n } => R::Mesh { dir, first: *first, n: *n },
        StageCmd::Usd { dir, n } => R::Usd { dir, n: *n },
        StageCmd::Eval { dir, n } => R::Eval { dir, n: *n },
    }
}

fn exemplar_settings(a: &ExemplarArgs) -> pipeline::ExemplarSettings {
    pipeline::ExemplarSettings {
        voxel_size: a.voxel_size,
        up: a.up,
        cloud_colour: a.cloud_colour,
        normal_orientation: a.normal_orientation,
        normal_neighbours: a.normal_neighbours,
        estimate_normals: a.estimate_normals,
    }
}

fn render_options(v: &ViewArgs) -> RenderOptions {
    RenderOptions {
        width: v.width,
        height: v.height,
        azimuth_deg: v.azimuth,
        elevation_deg: v.elevation,
        point_size: v.point_size,
        ..Default::default()
    }
}
