//! Command-line definitions and dispatch (the binary's only logic).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

use shapeshifter::encode::Pooling;
use shapeshifter::recon::Method;
use shapeshifter::render::RenderOptions;
use shapeshifter::config::Config;
use shapeshifter::learn::sample::SampleOptions;
use shapeshifter::util::lock;
use shapeshifter::{level::edit, eval::evaluate, io::info, io::mesh, pipeline, io::vdb};

#[derive(Parser, Debug)]
#[command(name = "shapeshifter", version, about = "3D shape variations from one exemplar mesh (ShapeShifter, CVPR 2025)")]
pub struct Cli {
    /// Only errors on stderr.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// More detail on stderr (-vv for debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// libtorch CPU threads (0 = libtorch's default, one per core). 1 by
    /// default: the cpu profile's small convolutions run faster on one thread
    /// per process, and independent levels and shards use the other cores
    /// (docs/performance.md).
    #[arg(long, global = true, default_value_t = 1, env = "SHAPESHIFTER_THREADS")]
    pub threads: i32,
    /// When another command is writing the same output folder, wait for it
    /// to end instead of failing at once.
    #[arg(long, global = true)]
    pub wait: bool,
    /// How progress is shown on stderr: bars (interactive), alf
    /// (`ALF_PROGRESS nn%` lines, as Houdini PDG and other task-graph
    /// schedulers parse them) or none.
    #[arg(long, global = true, value_enum, default_value_t = ProgressMode::Bars)]
    pub progress: ProgressMode,
    #[command(subcommand)]
    pub command: Command,
}

/// `--progress`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgressMode {
    Bars,
    Alf,
    None,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Describe level files (.vdb: grids, types, voxels, bounds, transform,
    /// metadata) and meshes (counts, bounds, closed/open, colour source).
    ///
    /// Example: shapeshifter info out/levels/level_4.vdb tower.obj --json
    Info {
        #[arg(required = true)]
        files: Vec<PathBuf>,
        #[command(flatten)]
        batch: BatchArgs,
    },
    /// Encode exemplar meshes into the multiscale feature grids: one level
    /// file per level (level_0.vdb coarsest) and manifest.json in OUT; with
    /// several meshes, one folder each in OUT (named after the files).
    ///
    /// Example: shapeshifter encode tower.obj -o out/tower --preview
    /// Example: shapeshifter encode meshes/*.obj -o out/encoded --json
    Encode {
        /// The exemplars (.obj with .mtl, .ply, .off, .stl).
        #[arg(required = true)]
        meshes: Vec<PathBuf>,
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
        #[arg(long, value_enum, default_value_t = Pooling::Qem)]
        pooling: Pooling,
        /// Also write level_K.png previews.
        #[arg(long)]
        preview: bool,
        /// Where each level's PointDataGrid goes: a file of its own beside
        /// the volumes (level_K.points.vdb), in the level file, or nowhere.
        #[arg(long, value_enum, default_value_t = vdb::PointsLayout::Separate)]
        points: vdb::PointsLayout,
        #[command(flatten)]
        view: ViewArgs,
        #[command(flatten)]
        exemplar: ExemplarArgs,
        #[command(flatten)]
        batch: BatchArgs,
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
    /// Evaluate variants against the exemplar (docs/method.md section 7): LP-IoU
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
        /// Print the report as JSON on stdout instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Train the hierarchy on an encoded exemplar: per level the upsampler,
    /// then the diffusion model. Levels are independent: `--level K` trains
    /// one alone (e.g. one job of a cluster array per level). A killed run
    /// resumes from its last checkpoint.
    ///
    /// Example: shapeshifter train out/tower --profile cpu --level 2
    Train {
        /// Folder written by `encode`.
        dir: PathBuf,
        /// Where checkpoints go (default DIR/models).
        #[arg(long)]
        models: Option<PathBuf>,
        /// Train only this level (0 = coarsest).
        #[arg(long)]
        level: Option<usize>,
        /// Resume from the checkpoints in the models folder (also automatic
        /// when a level's state file is there).
        #[arg(long)]
        resume: bool,
        /// Levels trained at once, each in its own process (without --level).
        /// 0: the CPU cores divided by --threads (1 on a GPU).
        #[arg(long, default_value_t = 0)]
        jobs: usize,
        #[command(flatten)]
        setup: SetupArgs,
    },
    /// Sample variants coarse to fine from trained models: one folder per
    /// variant (variant_000, ...) with one level file per level.
    ///
    /// Example: shapeshifter sample out/tower -n 10 --seed 1 -o out/tower_variants --extent 2,1,1
    Sample {
        /// A run folder (its exemplar/ and models/), or a folder written by
        /// `encode` (and `train`).
        dir: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        /// Where checkpoints are (default DIR/models).
        #[arg(long)]
        models: Option<PathBuf>,
        /// Number of variants.
        #[arg(short, default_value_t = 10)]
        n: usize,
        /// Index of the first variant: `--first 5 -n 5` writes variant_005 ..
        /// variant_009, exactly as `-n 10` writes them (a shard of a job array).
        #[arg(long, default_value_t = 0)]
        first: usize,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Per-axis scale of the coarse grid: X,Y,Z (2,1,1 = twice as long in x;
        /// the box may hold at most 64 level-0 grids, e.g. 4,4,4 or 16,4,1).
        #[arg(long, default_value = "1,1,1", value_parser = parse_extent)]
        extent: Extent,
        /// Stop after this level.
        #[arg(long)]
        stop_level: Option<usize>,
        /// Continue from this level file (e.g. edited) to the finer levels.
        #[arg(long)]
        from: Option<PathBuf>,
        /// Write a preview PNG per level.
        #[arg(long)]
        preview: bool,
        /// Override sampling settings: --set sample.sampler=ddpm
        #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
        overrides: Vec<String>,
        #[arg(long, default_value = "auto")]
        device: String,
        /// Print a JSON record on stdout: every file written with its kind,
        /// the time, the exit status.
        #[arg(long)]
        json: bool,
    },
    /// A local web page to steer a run's variants: look at any level of any
    /// variant beside the exemplar, sample new ones, "more like this", resize,
    /// edit a coarse level and regenerate the finer ones, keep what you like
    /// (written into the run as a variant folder, meshed, in the USD asset and
    /// eval.json). Serves on 127.0.0.1 and prints the page's address with its
    /// token; ends on Ctrl-C (SIGINT) or SIGTERM.
    ///
    /// Example: shapeshifter studio out/tower --port 8765
    Studio {
        /// A run folder with trained models (what `run` writes).
        dir: PathBuf,
        /// Port on 127.0.0.1 (0: a free one).
        #[arg(long, default_value_t = 0)]
        port: u16,
        #[arg(long, default_value = "auto")]
        device: String,
        /// How the networks multiply: auto (bf16 where the device has it in
        /// hardware, else f32), f32 (as `sample`), bf16.
        #[arg(long, value_enum, default_value_t = shapeshifter::studio::Precision::Auto)]
        precision: shapeshifter::studio::Precision,
    },
    /// The whole pipeline: encode, train, sample, preview, evaluate. Several
    /// meshes: one sub-folder each; a failing mesh is reported and skipped.
    /// Re-running reuses finished stages.
    ///
    /// Example: shapeshifter run tower.obj -o out/tower -n 10
    Run {
        #[arg(required = true)]
        meshes: Vec<PathBuf>,
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Run the whole pipeline on the embedded demo exemplar (a ruined tower of
    /// coloured stones generated by the program).
    ///
    /// Example: shapeshifter demo -o out/demo
    Demo {
        #[arg(short, long, default_value = "out/demo")]
        output: PathBuf,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Mesh a level file's oriented coloured points: Poisson (CGAL; closed
    /// shapes) or APSS (algebraic point set surfaces; open surfaces stay
    /// open). `auto` picks APSS when the exemplar was open. Vertex colours
    /// from the nearest points; output in the exemplar's frame, as PLY or
    /// glTF binary (.glb), both with vertex colours. --faces makes a light
    /// mesh: quadric decimation that keeps colours and sharp edges.
    ///
    /// Several level files: one mesh each in the folder OUT, named after the
    /// inputs, in --format.
    ///
    /// Example: shapeshifter mesh out/tower/level_4.vdb -o tower.ply --method poisson --depth 8
    /// Example: shapeshifter mesh out/tower/level_4.vdb -o tower.glb --faces 100000
    /// Example: shapeshifter mesh out/tower/variants/*/level_3.vdb -o meshes/ --format glb
    Mesh {
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// The mesh file, .ply or .glb (one input), or the folder for several.
        #[arg(short, long)]
        output: PathBuf,
        /// Format of each mesh when there are several inputs (one input: the
        /// extension of OUT).
        #[arg(long, value_enum, default_value_t = MeshFormat::Ply)]
        format: MeshFormat,
        /// Decimate to at most this many triangles (0: keep every triangle).
        #[arg(long, default_value_t = 0)]
        faces: usize,
        /// Meshing method; auto: APSS when the exemplar was an open surface,
        /// Poisson otherwise.
        #[arg(long, value_enum, ignore_case = true, default_value_t = MethodChoice::Auto)]
        method: MethodChoice,
        /// Contouring grid cells along the longest axis of the points' box
        /// [default: Poisson 256, APSS 512].
        #[arg(long, conflicts_with = "depth")]
        resolution: Option<u32>,
        /// Like screened Poisson's octree depth: a contouring grid of 2^DEPTH
        /// cells along the longest axis (8 = --resolution 256, the Poisson
        /// default; 9 = 512: ~4x the vertices, ~2x the time).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=12))]
        depth: Option<u32>,
        /// Also write a PNG preview of the mesh here (one input only).
        #[arg(long)]
        preview: Option<PathBuf>,
        #[command(flatten)]
        batch: BatchArgs,
    },
    /// Write level files' oriented coloured points as PLY point clouds
    /// (x y z nx ny nz red green blue), for tools that want points; several
    /// inputs: one cloud each in the folder OUT.
    ///
    /// Example: shapeshifter points out/tower/level_4.vdb -o tower_points.ply
    Points {
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// The PLY file (one input), or the folder for several.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        batch: BatchArgs,
    },
    /// Render a level file's oriented coloured points, or a mesh, to a PNG;
    /// or, given folders of level files (an encoded exemplar, variants, ladder
    /// rungs), a contact sheet: the finest level of each from one camera, with
    /// a close-up of the same region, the first folder framed as the reference.
    ///
    /// Example: shapeshifter render out/tower/level_4.vdb -o level_4.png --azimuth 120
    /// Example: shapeshifter render out/demo/exemplar out/demo/variants/variant_* -o sheet.png
    Render {
        /// A level file (.vdb), a mesh or a point cloud; or folders of level files.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// The PNG to write.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        view: ViewArgs,
        /// The vertical axis the camera orbits [default: a level's own; z for
        /// LAS/LAZ and E57, y for meshes and PLY].
        #[arg(long, value_enum)]
        up: Option<shapeshifter::level::Up>,
    },
    /// One stage of `run` on a run folder, as one job of a cluster runs it
    /// (`slurm` writes the jobs): encode, train, sample, mesh, eval. The same
    /// code as `run`, so the stages together write what `run` writes.
    ///
    /// Example: shapeshifter stage train out/tower --level 2
    Stage {
        #[command(subcommand)]
        stage: StageCmd,
    },
    /// Write (and submit, unless --dry-run) the pipeline as a SLURM job graph
    /// per exemplar: encode; training as a job array, one task per level
    /// (requeue resumes from checkpoints); sampling and meshing as arrays of
    /// shards; one evaluation. Scripts in OUT/slurm (OUT/<name>/slurm for
    /// several meshes), with `submit.sh`.
    ///
    /// Example: shapeshifter slurm tower.obj cliff.obj -o /shared/runs -n 50 --partition gpu --gpus-per-job 1 --profile paper
    Slurm {
        #[arg(required = true)]
        meshes: Vec<PathBuf>,
        #[arg(short, long)]
        output: PathBuf,
        /// Number of variants per exemplar.
        #[arg(short, default_value_t = 10)]
        n: usize,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// A shipped profile (cpu, demo, paper) or a TOML file.
        #[arg(long, default_value = "cpu")]
        profile: String,
        /// Override one value: --set cluster.variants_per_job=10 (repeatable).
        #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
        overrides: Vec<String>,
        #[arg(long)]
        partition: Option<String>,
        /// GPUs per training and sampling job (0: CPU jobs).
        #[arg(long, default_value_t = 0)]
        gpus_per_job: u32,
        /// Only write the scripts.
        #[arg(long)]
        dry_run: bool,
    },
    /// Compare the level data of two folders (runs, variant folders, encoded
    /// exemplars): every level_K.vdb under A must be in B with bit-identical
    /// voxels and features. Exit 1 on any difference.
    ///
    /// Example: shapeshifter compare out/single out/cluster
    Compare {
        a: PathBuf,
        b: PathBuf,
    },
    /// Write the USD asset of a run folder (what `run` writes after meshing):
    /// each variant's variants/variant_NNN/variant.usda (mesh, finest
    /// level's points, level files as volumes) and DIR/variants.usda, one
    /// asset prim with a variant set over them (.usdc with --format usdc).
    ///
    /// Example: shapeshifter usd out/tower --meters-per-unit 0.01 --format usdc
    Usd {
        /// A run folder (the output of `run`, or of its stages).
        dir: PathBuf,
        /// Metres per unit of the exemplar's coordinates [default: the run's
        /// output.meters_per_unit, 1].
        #[arg(long)]
        meters_per_unit: Option<f64>,
        /// usda (text) or usdc (binary) [default: the run's
        /// output.usd_format, usda].
        #[arg(long, value_enum)]
        format: Option<shapeshifter::io::usd::UsdFormat>,
        /// Print what was written as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Build the degradation ladder of an encoded exemplar: its finest level
    /// smoothed (two strengths), washed out, colour-shuffled, a blob upsampled
    /// from level 0, and untrained networks' output; score every rung with
    /// `eval`'s measures and check that each measure ranks them as expected.
    /// Writes one folder per rung, ladder.json and contact_sheet.png; exits 1
    /// when an expectation fails.
    ///
    /// Example: shapeshifter ladder out/demo/exemplar -o out/demo_ladder
    Ladder {
        /// The encoded exemplar folder (from `encode`, or OUT/exemplar of `run`).
        dir: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        /// Configuration of the untrained networks. Default: the config.toml
        /// of DIR/models or DIR/../models (as `run` lays them out), else the
        /// cpu profile; `none` skips the untrained rung.
        #[arg(long)]
        profile: Option<String>,
        #[arg(long, default_value = "auto")]
        device: String,
    },
}

/// The stages of `run`, one per cluster job.
#[derive(Subcommand, Debug)]
pub enum StageCmd {
    /// Record the configuration in OUT and encode the exemplar into OUT/exemplar.
    Encode {
        mesh: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
        #[arg(long, default_value = "cpu")]
        profile: String,
        #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
        overrides: Vec<String>,
    },
    /// Train every level, or one (`--level K`: one task of a job array).
    Train {
        dir: PathBuf,
        #[arg(long)]
        level: Option<usize>,
        #[arg(long, default_value = "auto")]
        device: String,
    },
    /// Sample variants FIRST .. FIRST+N-1 into DIR/variants.
    Sample {
        dir: PathBuf,
        #[arg(long, default_value_t = 0)]
        first: usize,
        #[arg(short, default_value_t = 10)]
        n: usize,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        #[arg(long, default_value = "auto")]
        device: String,
    },
    /// Mesh variants FIRST .. FIRST+N-1 (mesh.ply, mesh.png in each folder).
    Mesh {
        dir: PathBuf,
        #[arg(long, default_value_t = 0)]
        first: usize,
        #[arg(short, default_value_t = 10)]
        n: usize,
    },
    /// USD layers of variants 0 .. N-1 and DIR/variants.usda (.usdc with
    /// output.usd_format = "usdc").
    Usd {
        dir: PathBuf,
        #[arg(short, default_value_t = 10)]
        n: usize,
    },
    /// Score variants 0 .. N-1: DIR/eval.json and DIR/contact_sheet.png.
    Eval {
        dir: PathBuf,
        #[arg(short, default_value_t = 10)]
        n: usize,
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

impl SetupArgs {
    /// The profile given, or `default`.
    pub fn profile<'a>(&'a self, default: &'a str) -> &'a str {
        self.profile.as_deref().unwrap_or(default)
    }
}

/// Configuration and device.
#[derive(clap::Args, Debug, Clone)]
pub struct SetupArgs {
    /// A shipped profile (cpu, demo, paper) or a TOML file [default: cpu;
    /// `demo`: demo].
    #[arg(long)]
    pub profile: Option<String>,
    /// Override one value: --set train.level0_iterations=500 (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub overrides: Vec<String>,
    /// cpu, cuda or auto.
    #[arg(long, default_value = "auto")]
    pub device: String,
}

#[derive(clap::Args, Debug, Clone)]
pub struct RunArgs {
    /// Number of variants.
    #[arg(short, default_value_t = 10)]
    pub n: usize,
    /// Levels trained at once, each in its own process (levels are
    /// independent). 0: the CPU cores divided by --threads (1 on a GPU).
    #[arg(long, default_value_t = 0)]
    pub jobs: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print one JSON record per exemplar on stdout as each finishes (JSON
    /// Lines: every file written with its kind, stage times, exit status)
    /// instead of the summary, for task graphs and scripts.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub setup: SetupArgs,
    #[command(flatten)]
    pub exemplar: ExemplarArgs,
}

/// How an exemplar file is read: its scale, its vertical axis, and for point
/// clouds where normals and colours come from.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ExemplarArgs {
    /// The finest level's voxel edge in the exemplar's units (e.g. 0.2 for
    /// 20 cm voxels of a scan in metres) instead of fitting the exemplar to
    /// the grid; level files keep the exemplar's coordinates either way.
    #[arg(long, value_name = "UNITS")]
    pub voxel_size: Option<f64>,
    /// The exemplar's vertical axis [default: z for LAS/LAZ and E57, y for
    /// meshes and PLY]. Only cameras use it: nothing is rotated.
    #[arg(long, value_enum)]
    pub up: Option<shapeshifter::level::Up>,
    /// Point clouds: colour from RGB, intensity, classification or none
    /// [default: auto, RGB where the file has it].
    #[arg(long, value_enum)]
    pub cloud_colour: Option<shapeshifter::io::cloud::CloudColour>,
    /// Point clouds: how estimated normals get their sign [default: graph].
    #[arg(long, value_enum)]
    pub normal_orientation: Option<shapeshifter::geom::normals::Orientation>,
    /// Point clouds: neighbours each estimated normal is fitted to [default: 16].
    #[arg(long, value_name = "K")]
    pub normal_neighbours: Option<usize>,
    /// Point clouds: estimate normals even where the file has them.
    #[arg(long)]
    pub estimate_normals: bool,
}

impl ExemplarArgs {
    /// Sets what was given on the command line into `c`.
    pub fn apply(&self, c: &mut shapeshifter::config::EncodeConfig) {
        if self.voxel_size.is_some() {
            c.voxel_size = self.voxel_size;
        }
        if self.up.is_some() {
            c.up = self.up;
        }
        if let Some(v) = self.cloud_colour {
            c.cloud_colour = v;
        }
        if let Some(v) = self.normal_orientation {
            c.normal_orientation = v;
        }
        if let Some(v) = self.normal_neighbours {
            c.normal_neighbours = v;
        }
        if self.estimate_normals {
            c.estimate_normals = true;
        }
    }
}

/// Mesh formats that keep vertex colours.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum MeshFormat {
    Ply,
    Glb,
}

impl std::fmt::Display for MeshFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            MeshFormat::Ply => "ply",
            MeshFormat::Glb => "glb",
        })
    }
}

/// Many inputs in one command.
#[derive(clap::Args, Debug, Clone)]
pub struct BatchArgs {
    /// Files worked on at once (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub jobs: usize,
    /// Print what happened to every input as JSON on stdout (for scripts).
    #[arg(long)]
    pub json: bool,
}

/// `mesh --method`: a meshing method, or the one the exemplar calls for.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum MethodChoice {
    Auto,
    Poisson,
    Apss,
}

impl MethodChoice {
    fn method(self) -> Option<Method> {
        match self {
            MethodChoice::Auto => None,
            MethodChoice::Poisson => Some(Method::Poisson),
            MethodChoice::Apss => Some(Method::Apss),
        }
    }
}

/// How previews look.
#[derive(clap::Args, Debug, Clone)]
pub struct ViewArgs {
    /// Image width, pixels (a contact sheet's tiles are 320 pixels; the
    /// camera angles below apply to them).
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

fn device(spec: &str) -> Result<tch::Device> {
    Ok(pipeline::run::device(spec)?)
}

/// `--extent X,Y,Z`: three positive scales (a bad one is a usage error, exit 2).
#[derive(Clone, Copy, Debug)]
pub struct Extent(pub [f32; 3]);

fn parse_extent(text: &str) -> std::result::Result<Extent, String> {
    match edit::parse_vec3(text) {
        Some(v) if v.iter().all(|e| e.is_finite() && *e > 0.0) => Ok(Extent(v)),
        Some(_) => Err("each scale must be a positive number".into()),
        None => Err("expected three numbers X,Y,Z (e.g. 2,1,1)".into()),
    }
}

/// The configuration a command line asks for (a bad profile or `--set` is
/// a usage error, exit 2).
fn load_config(profile: &str, overrides: &[String]) -> Result<Config> {
    Ok(Config::load(profile, overrides)?)
}

/// `run`'s summary: where everything went, the stage times, the scores.
fn print_run_summary(summary: &pipeline::run::RunSummary, out: &std::path::Path) {
    let paths = pipeline::RunPaths::new(out);
    println!("\n{} -> {}", summary.source_name, out.display());
    println!("  exemplar levels  {}", paths.exemplar().display());
    println!("  models           {}", paths.models().display());
    println!("  variants         {} ({} folders, previews level_K.png)", paths.variants().display(), summary.variants);
    if !summary.empty.is_empty() {
        let names: Vec<String> = summary.empty.iter().map(|e| format!("{} (from level {})", e.name, e.first_empty)).collect();
        println!("  empty variants   {} of {}: {}", summary.empty.len(), summary.variants, names.join(", "));
    }
    println!("  USD asset        {}", summary.usd_asset.display());
    println!("  metrics          {}", paths.eval_json().display());
    println!("  contact sheet    {}", paths.contact_sheet().display());
    println!("  report           {}", paths.report().display());
    let stages: Vec<String> = summary.seconds.iter().map(|(k, v)| format!("{k} {v:.0} s")).collect();
    println!("  time             {}  (total {:.0} s)", stages.join(", "), summary.total_seconds);
    match &summary.evaluation {
        Some(e) => print!("{}", e.table()),
        None => println!("  (no variant could be scored: see the warning above)"),
    }
}

/// `run` and `demo`: each exemplar's summary (or JSON record) printed as
/// it finishes ([`pipeline::run::run_batch`]). Exit status 1 when any failed.
fn run_many(exemplars: &[(pipeline::ExemplarSource, String, PathBuf)], args: &RunArgs, no_bars: bool, threads: i32, wait: bool) -> Result<ExitCode> {
    let apply = |c: &mut shapeshifter::config::EncodeConfig| args.exemplar.apply(c);
    let request = pipeline::run::RunRequest {
        profile: args.setup.profile.as_deref(),
        overrides: &args.setup.overrides,
        exemplar: &apply,
        device_spec: &args.setup.device,
        n: args.n,
        seed: args.seed,
        jobs: args.jobs,
        threads,
        progress: !no_bars && !args.json,
        wait,
    };
    let failed = pipeline::run::run_batch(exemplars, &request, |name, out, outcome, seconds| {
        match outcome {
            Ok(summary) if args.json => {
                println!("{}", json_line(&pipeline::run::RunRecord::done(name, out, summary)));
            }
            Ok(summary) => print_run_summary(summary, out),
            Err(e) => {
                eprintln!("error: {e}");
                if args.json {
                    let record = pipeline::run::RunRecord::failed(name, out, e.to_string(), seconds);
                    println!("{}", json_line(&record));
                }
            }
        }
    })?;
    Ok(if failed > 0 { ExitCode::FAILURE } else { ExitCode::SUCCESS })
}

/// A record as one line of JSON (records are plain data: they serialise).
fn json_line<T: serde::Serialize>(record: &T) -> String {
    serde_json::to_string(record).expect("a record serialises")
}

/// Reports a batch: JSON on request; else one line per input (its output, or
/// its error on stderr) and, for several inputs, a summary. Exit status 1 when
/// any input failed.
fn finish_batch<T: serde::Serialize>(
    report: &shapeshifter::pipeline::batch::Report<T>,
    what: &str,
    folder: Option<&std::path::Path>,
    json: bool,
) -> Result<ExitCode> {
    if json {
        println!("{}", serde_json::to_string_pretty(report)?);
    } else {
        for o in &report.outcomes {
            match (&o.output, &o.error) {
                (_, Some(e)) => eprintln!("error: {e}"),
                (Some(out), None) => println!("{} -> {} ({:.1} s)", o.input.display(), out.display(), o.seconds),
                (None, None) => {}
            }
        }
        if report.outcomes.len() > 1 {
            println!("{}", report.summary(what, folder));
        }
    }
    Ok(if report.failed() > 0 { ExitCode::FAILURE } else { ExitCode::SUCCESS })
}

/// One stage of `run` (see [`Command::Stage`]).
fn run_stage(stage: StageCmd, no_bars: bool, wait: bool) -> Result<()> {
    let recorded = |dir: &std::path::Path| pipeline::RunPaths::new(dir).read_config();
    // Stages share their folder: a cluster's array tasks write one folder by design.
    let folder = match &stage {
        StageCmd::Encode { output, .. } => output,
        StageCmd::Train { dir, .. }
        | StageCmd::Sample { dir, .. }
        | StageCmd::Mesh { dir, .. }
        | StageCmd::Usd { dir, .. }
        | StageCmd::Eval { dir, .. } => dir,
    };
    if !matches!(stage, StageCmd::Encode { .. }) && !folder.is_dir() {
        anyhow::bail!("{}: no such run folder", folder.display());
    }
    let _lock = lock::lock(folder, lock::Mode::Shared, wait, "stage")?;
    match stage {
        StageCmd::Encode { mesh, output, profile, overrides } => {
            let config = load_config(&profile, &overrides)?;
            let paths = pipeline::RunPaths::new(&output);
            let (_, levels) = pipeline::run_encode(pipeline::ExemplarSource::File(&mesh), &paths, &config)?;
            println!("encoded {} levels -> {}", levels.len(), paths.exemplar().display());
        }
        StageCmd::Train { dir, level, device: dev } => {
            let config = recorded(&dir)?;
            let reports = pipeline::run_train(&pipeline::RunPaths::new(&dir), &config, device(&dev)?, level, !no_bars)?;
            for r in &reports {
                println!(
                    "level {}: {} upsampler + {} diffusion steps, {:.0} s ({:.1} + {:.1} steps/s){}",
                    r.level, r.upsampler_steps, r.diffusion_steps, r.seconds, r.upsampler_it_per_s, r.diffusion_it_per_s,
                    if r.finished { "" } else { " (not finished: run again to resume)" }
                );
            }
        }
        StageCmd::Sample { dir, first, n, seed, device: dev } => {
            let config = recorded(&dir)?;
            let mut options = SampleOptions::from_config(&config, n, seed);
            options.first = first;
            let dirs = pipeline::run_sample(&pipeline::RunPaths::new(&dir), &config, device(&dev)?, &options)?;
            println!("{} variants ({}..{}) -> {}", dirs.len(), first, first + n, dir.join("variants").display());
        }
        StageCmd::Mesh { dir, first, n } => {
            let config = recorded(&dir)?;
            let done = pipeline::run_mesh(&pipeline::RunPaths::new(&dir), first..first + n, &config.mesh)?;
            println!("{done} variants meshed");
        }
        StageCmd::Usd { dir, n } => {
            let config = recorded(&dir)?;
            let usd = pipeline::run_usd(&pipeline::RunPaths::new(&dir), Some(n), config.output.meters_per_unit, config.output.usd_format)?;
            println!("{} ({} variant layers)", usd.asset.display(), usd.variants.len());
        }
        StageCmd::Eval { dir, n } => match pipeline::run_eval(&pipeline::RunPaths::new(&dir), n)? {
            Some(evaluation) => print!("{}", evaluation.table()),
            None => anyhow::bail!("{}: no variant can be scored (see the warning above)", dir.display()),
        },
    }
    Ok(())
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
    let no_bars = cli.quiet || cli.progress != ProgressMode::Bars;
    shapeshifter::learn::reproducible_kernels();
    if cli.threads > 0 {
        tch::set_num_threads(cli.threads);
    }
    match cli.command {
        Command::Info { files, batch } => {
            let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
            let report = shapeshifter::pipeline::batch::run(&files, &names, batch.jobs, |f, _| {
                info::inspect(f).map(|i| (None, i)).map_err(|e| e.to_string())
            });
            if batch.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                for o in &report.outcomes {
                    match (&o.result, &o.error) {
                        (Some(i), _) => print!("{}", i.to_text()),
                        (_, Some(e)) => eprintln!("error: {e}"),
                        _ => {}
                    }
                }
            }
            Ok(if report.failed() > 0 { ExitCode::FAILURE } else { ExitCode::SUCCESS })
        }
        Command::Encode { meshes, output, sampling_resolution, coarsest, finest, pooling, preview, points, view, exemplar, batch } => {
            let mut settings = shapeshifter::config::EncodeConfig::grids(sampling_resolution, coarsest, finest, pooling);
            exemplar.apply(&mut settings);
            let options = pipeline::encode::command_options(&settings)?;
            let previews = preview.then(|| view.options());
            let write = vdb::WriteOptions { points, ..Default::default() };
            let names = shapeshifter::pipeline::batch::output_names(&meshes)?;
            let several = meshes.len() > 1;
            let report = shapeshifter::pipeline::batch::run(&meshes, &names, batch.jobs, |mesh_path, name| {
                let dir = if several { output.join(name) } else { output.clone() };
                let manifest =
                    pipeline::encode_file(mesh_path, &dir, &options, previews.as_ref(), write).map_err(|e| e.to_string())?;
                let voxels: Vec<usize> = manifest.levels.iter().map(|l| l.voxels).collect();
                Ok((Some(dir), voxels))
            });
            finish_batch(&report, "encode", several.then_some(output.as_path()), batch.json)
        }
        Command::Edit { input, output, op } => {
            let edit = match op {
                EditOp::Delete { region } => edit::Edit::Delete(edit::VoxelBox::parse(&region)?),
                EditOp::Copy { region, to } => {
                    let to = edit::parse_ivec3(&to).ok_or_else(|| anyhow::anyhow!("--to '{to}': expected x,y,z in voxels"))?;
                    edit::Edit::Copy(edit::VoxelBox::parse(&region)?, to)
                }
            };
            // Edited first, logged after: a log macro's arguments are not
            // evaluated at the quiet level.
            let what = pipeline::edit_file(&input, &output, edit)?;
            log::info!("{what}");
            Ok(ExitCode::SUCCESS)
        }
        Command::Eval { exemplar, variants, exemplar_mesh, resolution, output, json } => {
            let mesh = exemplar_mesh.as_deref().map(mesh::load).transpose()?;
            let files = variants.iter().map(|d| evaluate::read_variant(d)).collect::<Result<Vec<_>, _>>()?;
            let evaluation = evaluate::evaluate(&exemplar, mesh.as_ref(), &files, resolution)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&evaluation)?);
            } else {
                print!("{}", evaluation.table());
            }
            if let Some(out) = output {
                evaluation.write_json(&out)?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Train { dir, models, level, resume, jobs, setup } => {
            let config = load_config(setup.profile("cpu"), &setup.overrides)?;
            let device = device(&setup.device)?;
            let models = models.unwrap_or_else(|| dir.join(pipeline::layout::MODELS_DIR));
            let exe = std::env::current_exe()?;
            let trained = pipeline::train_folder(&pipeline::TrainFolder {
                exemplar_dir: &dir,
                models: &models,
                config: &config,
                device,
                level,
                resume,
                jobs: pipeline::run::auto_jobs(jobs, device, cli.threads),
                child: pipeline::TrainChild {
                    exe: &exe,
                    threads: cli.threads,
                    profile: setup.profile("cpu"),
                    device_spec: &setup.device,
                    overrides: &setup.overrides,
                },
                progress: !no_bars,
                wait: cli.wait,
            })?;
            match trained {
                pipeline::Trained::InProcesses { levels, jobs } => {
                    println!("{} levels trained on {jobs} processes -> {}", levels.len(), models.display());
                }
                pipeline::Trained::InThisProcess(reports) => {
                    for r in &reports {
                        println!(
                            "level {}: {} upsampler + {} diffusion steps, loss {:.4} -> {:.4}, {:.0} s{}",
                            r.level, r.upsampler_steps, r.diffusion_steps, r.diffusion_loss_start, r.diffusion_loss_end, r.seconds,
                            if r.finished { "" } else { " (not finished: run again to resume)" }
                        );
                    }
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Sample { dir, output, models, n, first, seed, extent, stop_level, from, preview, overrides, device: dev, json } => {
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
                device_spec: &dev,
                wait: cli.wait,
            };
            let record = pipeline::sample::sample_command(&dir, &output, &request)?;
            if json {
                println!("{}", serde_json::to_string(&record)?);
            } else {
                println!("{} variants -> {}", record.variants, output.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Run { meshes, output, run } => {
            let exemplars = pipeline::run::batch_of(&meshes, &output)?;
            run_many(&exemplars, &run, no_bars, cli.threads, cli.wait)
        }
        Command::Demo { output, run } => {
            let exemplars = [(pipeline::ExemplarSource::Demo, "(embedded)".to_string(), output)];
            run_many(&exemplars, &run, no_bars, cli.threads, cli.wait)
        }
        Command::Mesh { inputs, output, format, method, resolution, depth, faces, preview, batch } => {
            let resolution = resolution.or(depth.map(|d| 1 << d));
            let several = inputs.len() > 1;
            // Refuse a format that would drop the colours before the work.
            let ext = if several {
                format.to_string()
            } else {
                output.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default()
            };
            if !mesh::COLOUR_EXTENSIONS.contains(&ext.as_str()) {
                let why = format!("{}: mesh writes .ply or .glb (vertex colours), not '.{ext}'", output.display());
                return Err(shapeshifter::Error::Usage(why).into());
            }
            if several && preview.is_some() {
                return Err(shapeshifter::Error::Usage("--preview takes one input (several: run `render` on the meshes)".into()).into());
            }
            let names = pipeline::batch::output_names(&inputs)?;
            let report = pipeline::batch::run(&inputs, &names, batch.jobs, |input, name| {
                let target = if several { output.join(format!("{name}.{ext}")) } else { output.clone() };
                let summary = pipeline::mesh_file(input, &target, several, method.method(), resolution, faces, preview.as_deref())
                    .map_err(|e| e.to_string())?;
                Ok((Some(target), summary))
            });
            finish_batch(&report, "mesh", several.then_some(output.as_path()), batch.json)
        }
        Command::Points { inputs, output, batch } => {
            let several = inputs.len() > 1;
            let names = pipeline::batch::output_names(&inputs)?;
            let report = pipeline::batch::run(&inputs, &names, batch.jobs, |input, name| {
                let target = if several { output.join(format!("{name}.ply")) } else { output.clone() };
                let count = pipeline::points_file(input, &target, several).map_err(|e| e.to_string())?;
                Ok((Some(target), count))
            });
            finish_batch(&report, "points", several.then_some(output.as_path()), batch.json)
        }
        Command::Render { inputs, output, view, up } => {
            if let Some(sheet) = pipeline::render_inputs(&inputs, &output, &view.options(), up)? {
                log::info!("{sheet}");
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Stage { stage } => {
            run_stage(stage, no_bars, cli.wait)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Slurm { meshes, output, n, seed, profile, overrides, partition, gpus_per_job, dry_run } => {
            let config = load_config(&profile, &overrides)?;
            let opts = pipeline::cluster::GraphOptions {
                binary: std::env::current_exe()?,
                profile,
                overrides,
                n,
                seed,
                partition,
                gpus_per_job,
            };
            pipeline::cluster::submit(&meshes, &output, &config, &opts, dry_run, |line| print!("{line}"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Usd { dir, meters_per_unit, format, json } => {
            let paths = pipeline::RunPaths::new(&dir);
            if !dir.is_dir() {
                anyhow::bail!("{}: no such run folder", dir.display());
            }
            // A run folder first (its config), then its lock: nothing made in a wrong folder.
            let config = paths.read_config()?;
            let _lock = lock::lock(&dir, lock::Mode::Exclusive, cli.wait, "usd")?;
            let mpu = meters_per_unit.unwrap_or(config.output.meters_per_unit);
            if !(mpu.is_finite() && mpu > 0.0) {
                return Err(shapeshifter::Error::Usage(format!("--meters-per-unit {mpu}: expected a positive number")).into());
            }
            let outcome = pipeline::run_usd(&paths, None, mpu, format.unwrap_or(config.output.usd_format))?;
            if json {
                println!("{}", serde_json::to_string_pretty(&outcome)?);
            } else {
                println!("{} ({} variant layers)", outcome.asset.display(), outcome.variants.len());
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Compare { a, b } => {
            let report = shapeshifter::io::dataset::compare_levels(&a, &b)?;
            println!("{} level files compared: {} identical", report.compared, report.identical());
            for d in &report.differences {
                println!("  differs: {d}");
            }
            Ok(if report.differences.is_empty() && report.compared > 0 { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
        Command::Studio { dir, port, device: dev, precision } => {
            // Interactive: one job at a time on every core, unless the
            // thread count was given (the batch default of 1 suits processes
            // that run side by side).
            let given = std::env::var_os("SHAPESHIFTER_THREADS").is_some() || std::env::args().any(|a| a.starts_with("--threads"));
            if !given {
                tch::set_num_threads(std::thread::available_parallelism().map_or(1, |n| n.get()) as i32);
            }
            let request = shapeshifter::studio::StudioRequest { dir: &dir, port, device_spec: &dev, precision, wait: cli.wait };
            shapeshifter::studio::run_studio(&request, &mut |url| {
                // On stdout, whatever the log level: a script reads the address.
                println!("studio: {url}");
                let _ = std::io::Write::flush(&mut std::io::stdout());
                log::info!("studio: open {url} in a browser on this machine; Ctrl-C ends it");
            })?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Ladder { dir, output, profile, device: dev } => {
            let (config, from) = pipeline::ladder_config(&dir, profile.as_deref())?;
            println!("untrained rung: {from}");
            let device = device(&dev)?;
            let outcome = pipeline::ladder_stage(&dir, &output, config.as_ref(), device)?;
            print!("{}", outcome.evaluation.table());
            for s in &outcome.skipped {
                println!("skipped: {s}");
            }
            let failed: Vec<_> = outcome.failed().collect();
            println!(
                "expected order: {} of {} checks hold -> {}",
                outcome.checks.len() - failed.len(),
                outcome.checks.len(),
                output.join("ladder.json").display()
            );
            for c in &failed {
                println!("  FAILS {} on {}: {:.4} vs exemplar {:.4} ({})", c.metric, c.rung, c.value, c.exemplar, c.requirement);
            }
            if outcome.checks.is_empty() {
                anyhow::bail!("{}: no check of the expected order could run (every rung skipped?)", dir.display());
            }
            Ok(if failed.is_empty() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
    }
}
