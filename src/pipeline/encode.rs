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
