//! The command line's declarations: every argument, its default and its
//! `--help` text (the doc comments). No logic: `cli.rs` turns what clap
//! parsed into library requests.

use std::path::PathBuf;

use clap::{Parser, Subcommand};

use shapeshifter::encode::Pooling;
use shapeshifter::io::vdb;
use shapeshifter::pipeline::mesh::{MeshFormat, MethodChoice};
use shapeshifter::pipeline::sample::{parse_extent, Extent};
use shapeshifter::pipeline::DEFAULT_PROFILE;

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
        #[arg(long, default_value = DEFAULT_PROFILE)]
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
        #[arg(long, default_value = DEFAULT_PROFILE)]
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
