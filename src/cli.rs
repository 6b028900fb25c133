//! Command-line definitions and dispatch (the binary's only logic).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

use shapeshifter::encode::{self, EncodeOptions, Pooling};
use shapeshifter::render::{self, RenderOptions};
use shapeshifter::{dataset, edit, evaluate, info, mesh, vdb};

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
    /// Encode an exemplar mesh into the multiscale feature grids: one level
    /// file per level (level_0.vdb coarsest) and manifest.json in DIR.
    ///
    /// Example: shapeshifter encode tower.obj -o out/tower --preview
    Encode {
        /// The exemplar (.obj with .mtl, .ply, .off, .stl).
        mesh: PathBuf,
        /// Output folder (created).
        #[arg(short, long)]
        output: PathBuf,
        /// Voxels per axis of the finest sampling grid.
        #[arg(long, default_value_t = 1024)]
        sampling_resolution: u32,
        /// Resolution of level 0.
        #[arg(long, default_value_t = 16)]
        coarsest: u32,
        /// Resolution of the last level.
        #[arg(long, default_value_t = 256)]
        finest: u32,
        /// How children pool into parents.
        #[arg(long, value_enum, default_value_t = PoolingArg::Qem)]
        pooling: PoolingArg,
        /// Also write level_K.png previews.
        #[arg(long)]
        preview: bool,
        #[command(flatten)]
        view: ViewArgs,
    },
    /// Edit a level file: delete a box of voxels, or copy one elsewhere
    /// (voxel coordinates as `info` prints them). Writes a new level file;
    /// `sample --from` continues the finer levels from it.
    ///
    /// Example: shapeshifter edit v/level_1.vdb -o edited.vdb copy --box 10,0,10:20,40,20 --to 30,0,10
    Edit {
        input: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        #[command(subcommand)]
        op: EditOp,
    },
    /// Evaluate variants against the exemplar (METHOD.md section 7): LP-IoU
    /// and LP-F-score per variant, diversity (mean pairwise 1 - IoU), and the
    /// Chamfer distance of the coarsest level. Prints a table; writes JSON.
    ///
    /// Example: shapeshifter eval out/tower/exemplar out/tower/variants/variant_* -o eval.json
    Eval {
        /// The encoded exemplar folder (from `encode`).
        exemplar: PathBuf,
        /// Variant folders (level_K.vdb files, and mesh.ply where meshed).
        #[arg(required = true)]
        variants: Vec<PathBuf>,
        /// The exemplar mesh: with it, and a mesh.ply in every variant, shapes
        /// are voxelised as solids (the paper's way); else as point shells.
        #[arg(long)]
        exemplar_mesh: Option<PathBuf>,
        /// Solid voxelisation: voxels along the exemplar's longest axis.
        #[arg(long, default_value_t = 256)]
        resolution: u32,
        /// Write the report as JSON here.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Render a level file's oriented coloured points, or a mesh, to a PNG.
    ///
    /// Example: shapeshifter render out/tower/level_4.vdb -o level_4.png --azimuth 120
    Render {
        /// A level file (.vdb) or a mesh.
        input: PathBuf,
        /// The PNG to write.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        view: ViewArgs,
    },
}

/// Copy-and-paste editing of a level file.
#[derive(Subcommand, Debug)]
pub enum EditOp {
    /// Delete the voxels inside a box.
    Delete {
        /// Inclusive box in voxel coordinates: x0,y0,z0:x1,y1,z1.
        #[arg(long = "box", value_name = "BOX")]
        region: String,
    },
    /// Copy the voxels inside a box, with their features, so that the box's
    /// minimum corner lands on --to.
    Copy {
        /// Inclusive box in voxel coordinates: x0,y0,z0:x1,y1,z1.
        #[arg(long = "box", value_name = "BOX")]
        region: String,
        /// Destination of the box's minimum corner: x,y,z (voxels).
        #[arg(long, allow_hyphen_values = true)]
        to: String,
    },
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum PoolingArg {
    /// Quadric error minimisation: keeps corners and creases sharp.
    Qem,
    /// Plain averaging of points (rounds corners; for comparison).
    Average,
}

/// How previews look.
#[derive(clap::Args, Debug, Clone)]
pub struct ViewArgs {
    /// Image width, pixels.
    #[arg(long, default_value_t = 800)]
    pub width: u32,
    /// Image height, pixels.
    #[arg(long, default_value_t = 800)]
    pub height: u32,
    /// Camera angle around the vertical axis, degrees.
    #[arg(long, default_value_t = 35.0, allow_hyphen_values = true)]
    pub azimuth: f32,
    /// Camera angle above the horizon, degrees.
    #[arg(long, default_value_t = 25.0, allow_hyphen_values = true)]
    pub elevation: f32,
    /// Splat radius in voxel sizes.
    #[arg(long, default_value_t = 0.9)]
    pub point_size: f32,
}

impl ViewArgs {
    pub fn options(&self) -> RenderOptions {
        RenderOptions {
            width: self.width,
            height: self.height,
            azimuth_deg: self.azimuth,
            elevation_deg: self.elevation,
            point_size: self.point_size,
            ..Default::default()
        }
    }
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
        Command::Encode { mesh: mesh_path, output, sampling_resolution, coarsest, finest, pooling, preview, view } => {
            let options = EncodeOptions {
                sampling_resolution,
                coarsest_resolution: coarsest,
                finest_resolution: finest,
                pooling: match pooling {
                    PoolingArg::Qem => Pooling::Qem,
                    PoolingArg::Average => Pooling::Average,
                },
                ..Default::default()
            };
            options.validate().map_err(shapeshifter::Error::from)?;
            let mesh = mesh::load(&mesh_path)?;
            let digest = dataset::file_sha256(&mesh_path)?;
            let (levels, stats) =
                encode::encode(&mesh, &options).map_err(|e| anyhow::anyhow!("{}: {e}", mesh_path.display()))?;
            let previews = preview.then(|| view.options());
            let manifest = dataset::write(
                &output,
                &mesh,
                &mesh_path.display().to_string(),
                &digest,
                &levels,
                &options,
                &stats,
                previews.as_ref(),
            )?;
            log::info!(
                "encoded {} in {:.2} s: {}",
                mesh_path.display(),
                stats.total_s,
                manifest.levels.iter().map(|l| format!("{}^3: {} voxels", l.resolution, l.voxels)).collect::<Vec<_>>().join(", ")
            );
            println!("{}", output.join(dataset::MANIFEST).display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Edit { input, output, op } => {
            let (mut level, provenance) = vdb::read_level(&input)?;
            let what = match op {
                EditOp::Delete { region } => {
                    let n = edit::delete_box(&mut level, edit::VoxelBox::parse(&region)?);
                    format!("deleted {n} voxels")
                }
                EditOp::Copy { region, to } => {
                    let to = edit::parse_ivec3(&to)
                        .ok_or_else(|| anyhow::anyhow!("--to '{to}': expected x,y,z in voxels"))?;
                    let n = edit::copy_box(&mut level, edit::VoxelBox::parse(&region)?, to)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", input.display()))?;
                    format!("copied {n} voxels")
                }
            };
            vdb::write_level(&output, &level, &provenance, vdb::WriteOptions::default())?;
            log::info!("{what}; {} voxels -> {}", level.len(), output.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Eval { exemplar, variants, exemplar_mesh, resolution, output } => {
            let mesh = exemplar_mesh.as_deref().map(mesh::load).transpose()?;
            let files = variants.iter().map(|d| evaluate::read_variant(d)).collect::<Result<Vec<_>, _>>()?;
            let (report, mode) = evaluate::evaluate(&exemplar, mesh.as_ref(), &files, resolution)?;
            println!("voxelisation: {mode:?}");
            print!("{}", report.table());
            if let Some(out) = output {
                let text = serde_json::to_string_pretty(&report)?;
                shapeshifter::error::write_atomically(&out, |tmp| {
                    std::fs::write(tmp, &text).map_err(|e| shapeshifter::Error::file(&out, e.to_string()))
                })?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Render { input, output, view } => {
            let opts = view.options();
            let ext = input.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
            let img = if ext == "vdb" {
                let (level, _) = vdb::read_level(&input)?;
                render::render_level(&level, &opts).map_err(|e| anyhow::anyhow!("{}: {e}", input.display()))?
            } else {
                let m = mesh::load(&input)?;
                render::render_mesh(&m, &opts).map_err(|e| anyhow::anyhow!("{}: {e}", input.display()))?
            };
            render::save_png(&img, &output)?;
            Ok(ExitCode::SUCCESS)
        }
    }
}
