//! Stage 1, encoding: an exemplar file (or the embedded demo) into the
//! multiscale levels of `OUT/exemplar`.

use std::path::Path;
use std::time::Instant;

use super::stamp::{digest, is_done, mark_done, record_config, StampOf};
use super::RunPaths;
use crate::config::{Config, Stage};
use crate::encode::{self, EncodeOptions};
use crate::error::{Error, Result};
use crate::io::exemplar::Exemplar;
use crate::io::vdb::WriteOptions;
use crate::io::dataset;
use crate::level::Level;
use crate::render::{self, RenderOptions};

pub fn encode_options(config: &Config) -> EncodeOptions {
    options_of(&config.encode)
}

/// The encoder's options for the settings `c`.
pub fn options_of(c: &crate::config::EncodeConfig) -> EncodeOptions {
    EncodeOptions {
        sampling_resolution: c.sampling_resolution,
        coarsest_resolution: c.coarsest_resolution,
        finest_resolution: c.finest_resolution,
        pooling: c.pooling,
        voxel_size: c.voxel_size,
        up: c.up,
        cloud: crate::encode::CloudOptions {
            colour: c.cloud_colour,
            normal_neighbours: c.normal_neighbours,
            orientation: c.normal_orientation,
            estimate_normals: c.estimate_normals,
        },
        ..Default::default()
    }
}

/// The `encode` command's options: `c`, checked; invalid settings (a finest
/// resolution that is not a power of two, ...) are [`Error::Usage`].
pub fn command_options(c: &crate::config::EncodeConfig) -> Result<EncodeOptions> {
    let options = options_of(c);
    options.validate().map_err(crate::error::Error::usage)?;
    Ok(options)
}

/// Encodes the mesh file `mesh_path` into `dir` (the `encode` command, one
/// file of a batch): level files, previews if asked, manifest.json.
pub fn encode_file(
    mesh_path: &Path,
    dir: &Path,
    options: &EncodeOptions,
    previews: Option<&RenderOptions>,
    write: WriteOptions,
) -> Result<dataset::Manifest> {
    let exemplar = Exemplar::load(mesh_path)?;
    let digest = dataset::file_sha256(mesh_path)?;
    let (levels, stats) = encode::encode_exemplar(&exemplar, options).map_err(|e| Error::file(mesh_path, e.to_string()))?;
    let source = mesh_path.display().to_string();
    let preview = previews.map(|opts| move |level: &Level, path: &Path| write_preview(level, opts, path));
    let manifest = dataset::write(dir, &exemplar, &source, &digest, &levels, &encoding(options, &stats), preview.as_ref().map(|p| p as _), write)?;
    log::info!(
        "encoded {source} in {:.2} s: {}",
        stats.total_s,
        manifest.levels.iter().map(|l| format!("{}^3: {} voxels", l.resolution, l.voxels)).collect::<Vec<_>>().join(", ")
    );
    Ok(manifest)
}

/// Encodes `mesh` into `dir` unless already done with the same source and
/// options. Returns the levels.
pub fn encode_stage(exemplar: &Exemplar, source: &str, source_sha: &str, config: &Config, dir: &Path) -> Result<Vec<Level>> {
    let d = digest(&[source_sha, &config.stage_digest(Stage::Encode)]);
    if is_done(dir, StampOf::Encode, &d) {
        log::info!("encode: reusing {}", dir.display());
        return Ok(dataset::read(dir)?.1);
    }
    let t = Instant::now();
    let options = encode_options(config);
    let (levels, stats) = encode::encode_exemplar(exemplar, &options)?;
    let preview = |level: &Level, path: &Path| write_preview(level, &render::preview_options(), path);
    dataset::write(dir, exemplar, source, source_sha, &levels, &encoding(&options, &stats), Some(&preview), config.output.write_options())?;
    log::info!(
        "encode: {} levels in {:.1} s ({})",
        levels.len(),
        stats.total_s,
        levels.iter().map(|l| format!("{}^3 {}", l.resolution, l.len())).collect::<Vec<_>>().join(", ")
    );
    mark_done(dir, StampOf::Encode, &d, t.elapsed().as_secs_f64())?;
    Ok(levels)
}

/// Where an exemplar comes from.
#[derive(Clone, Copy, Debug)]
pub enum ExemplarSource<'a> {
    File(&'a Path),
    /// The embedded demo tower.
    Demo,
}

/// Stage 1: records the configuration in the run folder and encodes the
/// exemplar into `OUT/exemplar` (the demo exemplar is also written as
/// `exemplar.ply` and `exemplar.png`).
/// Returns the exemplar's name as reports show it (its path, or the demo's) and
/// its levels.
pub fn run_encode(source: ExemplarSource, paths: &RunPaths, config: &Config) -> Result<(String, Vec<Level>)> {
    let demo = matches!(source, ExemplarSource::Demo);
    let (exemplar, name, sha) = match source {
        ExemplarSource::File(p) => (Exemplar::load(p)?, p.display().to_string(), dataset::file_sha256(p)?),
        ExemplarSource::Demo => {
            let m = crate::encode::exemplar::ruined_tower(&Default::default());
            let sha = dataset::mesh_sha256(&m);
            (Exemplar::Mesh(m), "(embedded demo exemplar)".to_string(), sha)
        }
    };
    record_config(&paths.root, config)?;
    if let (true, Exemplar::Mesh(mesh)) = (demo, &exemplar) {
        crate::io::mesh::save(mesh, &paths.root.join("exemplar.ply"), true)?;
        render::save_png(&render::render_mesh(mesh, &render::preview_options())?, &paths.root.join("exemplar.png"))?;
    }
    let levels = encode_stage(&exemplar, &name, &sha, config, &paths.exemplar())?;
    Ok((name, levels))
}

/// What the manifest records of an encoding.
fn encoding(options: &EncodeOptions, stats: &encode::EncodeStats) -> dataset::Encoding {
    dataset::Encoding { sampling_resolution: options.sampling_resolution, pooling: options.pooling, seconds: stats.seconds() }
}

/// A level's preview picture (`level_K.png`), as `encode --preview` and runs draw it.
pub fn write_preview(level: &Level, options: &RenderOptions, path: &Path) -> Result<()> {
    render::save_png(&render::render_level(level, options)?, path)
}

/// How an exemplar file is read, as a user gave it (`--voxel-size`, `--up`,
/// the point-cloud options): each setting given replaces the profile's,
/// each left out keeps it.
#[derive(Clone, Debug, Default)]
pub struct ExemplarSettings {
    pub voxel_size: Option<f64>,
    pub up: Option<crate::level::Up>,
    pub cloud_colour: Option<crate::io::cloud::CloudColour>,
    pub normal_orientation: Option<crate::geom::normals::Orientation>,
    pub normal_neighbours: Option<usize>,
    /// Estimate normals even where the file has them (false: as the profile says).
    pub estimate_normals: bool,
}

impl ExemplarSettings {
    /// Sets what was given into `c`.
    pub fn apply(&self, c: &mut crate::config::EncodeConfig) {
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

/// What a user asks of the `encode` command.
pub struct EncodeRequest<'a> {
    pub meshes: &'a [std::path::PathBuf],
    /// The folder of the levels (one input), or of one folder per input.
    pub output: &'a Path,
    pub sampling_resolution: u32,
    pub coarsest: u32,
    pub finest: u32,
    pub pooling: crate::encode::Pooling,
    pub exemplar: &'a ExemplarSettings,
    /// Write `level_K.png` previews with these options.
    pub previews: Option<&'a RenderOptions>,
    pub points: crate::io::vdb::PointsLayout,
    /// Files encoded at once (0: one per core).
    pub jobs: usize,
}

/// The `encode` command: the settings checked before anything is written
/// (invalid ones are [`Error::Usage`]), then every mesh encoded
/// ([`encode_file`]) into `output` (one input) or `output/NAME`; each
/// input's voxel counts per level, or its error.
pub fn encode_command(r: &EncodeRequest) -> Result<super::batch::Converted<Vec<usize>>> {
    use super::batch;
    let mut settings = crate::config::EncodeConfig::grids(r.sampling_resolution, r.coarsest, r.finest, r.pooling);
    r.exemplar.apply(&mut settings);
    let options = command_options(&settings)?;
    let write = WriteOptions { points: r.points, ..Default::default() };
    let names = batch::output_names(r.meshes)?;
    let several = r.meshes.len() > 1;
    let report = batch::run(r.meshes, &names, r.jobs, |mesh_path, name| {
        let dir = batch::target(r.output, name, several, None);
        let manifest = encode_file(mesh_path, &dir, &options, r.previews, write).map_err(|e| e.to_string())?;
        let voxels: Vec<usize> = manifest.levels.iter().map(|l| l.voxels).collect();
        Ok((Some(dir), voxels))
    });
    Ok(batch::Converted { report, what: "encode", folder: several.then(|| r.output.to_path_buf()) })
}
