//! Stage 4, meshing: each variant's finest level into a mesh (Poisson or
//! APSS), decimated to a light mesh and baked into a texture where asked.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::layout::{self, variant_dir};
use super::stamp::{digest_of, is_done, mark_done, stamp_path, StampOf};
use super::RunPaths;
use crate::config::MeshConfig;
use crate::error::{Error, Result};
use crate::io::mesh::Mesh;
use crate::io::vdb;
use crate::io::dataset;
use crate::level::Level;
use crate::render;

/// The surface voxels (mask > 0) of a level as oriented coloured points in
/// the exemplar's frame; spacing = the level's voxel size in world units. An
/// error when there are none (nothing to mesh or write).
pub fn oriented_points(level: &Level) -> Result<crate::geom::points::OrientedPoints> {
    let mut points = crate::level::Level::surface_points(level);
    if points.is_empty() {
        return Err(Error::Invalid("the level has no active voxels (mask > 0)".into()));
    }
    points.normals.iter_mut().for_each(|n| *n = n.normalize_or_zero());
    Ok(points)
}

/// Meshes a level: Poisson for closed exemplars, APSS for open ones unless
/// `method` says otherwise. `resolution`: contouring grid cells along the
/// longest axis; None: the method's default (Poisson 256, APSS 512).
pub fn mesh_level(
    level: &Level,
    exemplar_open: bool,
    method: Option<crate::recon::Method>,
    resolution: Option<u32>,
) -> Result<(Mesh, crate::recon::Method)> {
    use crate::recon::{self, ApssOptions, Method, PoissonOptions};
    let method = method.unwrap_or(if exemplar_open { Method::Apss } else { Method::Poisson });
    let points = oriented_points(level)?;
    let (mut poisson, mut apss) = (PoissonOptions::default(), ApssOptions::default());
    if let Some(resolution) = resolution {
        (poisson.resolution, apss.resolution) = (resolution, resolution);
    }
    let m = recon::reconstruct(&points, method, &poisson, &apss)?;
    let mesh = Mesh {
        name: "mesh".into(),
        positions: m.positions,
        triangles: m.triangles,
        colours: crate::io::mesh::MeshColours::PerVertex(m.colours),
        texture: None,
    };
    Ok((mesh, method))
}

/// What a variant's mesh depends on (its stamp's digest).
#[derive(serde::Serialize)]
struct MeshInputs {
    finest_level_sha256: String,
    /// Contouring cells along the longest axis.
    resolution: u32,
    exemplar_open: bool,
    faces: usize,
    glb: bool,
    /// The baked texture's size, when the light mesh is baked.
    texture: Option<u32>,
}

/// Meshes the finest level of every variant folder into `mesh.ply` (and
/// `mesh.glb` when `settings.glb`), decimated to `settings.faces` triangles
/// when that is not 0, and `mesh.png`. A light mesh is also baked into a
/// texture (`settings.texture_size()`): `mesh.obj` + `mesh.mtl` +
/// `mesh_basecolor.png` and a textured `mesh.glb`. A variant that fails to
/// mesh is reported and skipped; one whose texture fails keeps its vertex
/// colours, with a warning.
pub fn mesh_stage(dirs: &[PathBuf], exemplar_open: bool, resolution: u32, settings: &MeshConfig) -> Result<usize> {
    use layout::{MESH_GLB, MESH_MTL, MESH_OBJ, MESH_PLY, MESH_PREVIEW, MESH_TEXTURE};
    let mut done = 0;
    for (i, dir) in dirs.iter().enumerate() {
        crate::util::interrupt::check()?;
        crate::util::progress::report_parts(i, dirs.len());
        let t = Instant::now();
        // The mesh depends on the finest level's data: its file's digest,
        // checked before anything is read (a finished mesh costs one hash).
        let finest_file = match crate::eval::evaluate::level_files(dir) {
            Ok(files) => files[files.len() - 1].1.clone(),
            Err(e) => {
                log::warn!("not meshed: {e}");
                continue;
            }
        };
        let out = dir.join(MESH_PLY);
        let glb = dir.join(MESH_GLB);
        let texture = settings.texture_size();
        let d = digest_of(&MeshInputs {
            finest_level_sha256: dataset::file_sha256(&finest_file).unwrap_or_default(),
            resolution,
            exemplar_open,
            faces: settings.faces,
            glb: settings.glb,
            texture,
        });
        let textured_files = [MESH_OBJ, MESH_MTL, MESH_TEXTURE].map(|f| dir.join(f));
        let complete = out.is_file()
            && (glb.is_file() || !(settings.glb || texture.is_some()))
            && (texture.is_none() || textured_files.iter().all(|f| f.is_file()));
        if is_done(dir, StampOf::Mesh, &d) && complete {
            done += 1;
            continue;
        }
        let finest = match vdb::read_level(&finest_file) {
            Ok((level, _)) => level,
            Err(e) => {
                log::warn!("not meshed: {e}");
                continue;
            }
        };
        // No glTF or textured file from an earlier setting beside a new mesh.ply.
        let _ = std::fs::remove_file(&glb);
        for f in &textured_files {
            let _ = std::fs::remove_file(f);
        }
        match mesh_level(&finest, exemplar_open, None, Some(resolution)).and_then(|(m, _)| light_mesh(m, settings.faces)) {
            Ok(mesh) => {
                crate::io::mesh::save(&mesh, &out, true)?;
                let baked = texture.and_then(|size| match bake_level_texture(&mesh, &finest, size) {
                    Ok(m) => Some(m),
                    Err(e) => {
                        log::warn!("{}: no texture, vertex colours only: {e}", dir.display());
                        None
                    }
                });
                if let Some(textured) = &baked {
                    crate::io::mesh::save(textured, &textured_files[0], true)?;
                }
                if settings.glb || baked.is_some() {
                    crate::io::mesh::save(baked.as_ref().unwrap_or(&mesh), &glb, true)?;
                }
                let view = render::RenderOptions { up: Some(finest.frame.up), ..render::preview_options() };
                let img = render::render_mesh(baked.as_ref().unwrap_or(&mesh), &view)?;
                render::save_png(&img, &dir.join(MESH_PREVIEW))?;
                mark_done(dir, StampOf::Mesh, &d, t.elapsed().as_secs_f64())?;
                done += 1;
            }
            Err(e) => {
                // No mesh rather than a stale one.
                let _ = std::fs::remove_file(&out);
                log::warn!("{}: not meshed: {e}", dir.display());
            }
        }
    }
    Ok(done)
}

/// `mesh` (made from `level`) with a UV atlas and a texture of `size`
/// texels baked from the level's points ([`crate::recon::bake`]).
pub fn bake_level_texture(mesh: &Mesh, level: &Level, size: u32) -> Result<Mesh> {
    let points = oriented_points(level)?;
    let (textured, r) = crate::recon::bake::bake_texture(mesh, &points, size)?;
    log::info!(
        "texture: {} charts in {}x{} texels ({:.0}% used), {} -> {} vertices, unwrap {:.1} s, bake {:.1} s",
        r.charts,
        r.width,
        r.height,
        100.0 * r.utilization,
        r.vertices_before,
        r.vertices_after,
        r.seconds_unwrap,
        r.seconds_bake
    );
    Ok(textured)
}

/// `mesh` decimated to `faces` triangles (0: as many as it has), with a
/// log line saying what the decimation did, and without zero-area
/// triangles: decimation leaves a few (corners copied onto one position),
/// they carry no surface and every reader drops them, so a mesh file and
/// the USD layer read from it count the same triangles.
pub fn light_mesh(mesh: Mesh, faces: usize) -> Result<Mesh> {
    let mut light = if faces == 0 {
        mesh
    } else {
        let t = std::time::Instant::now();
        let (light, report) = crate::io::mesh::decimate(&mesh, &crate::io::mesh::DecimateOptions::new(faces))?;
        log::info!(
            "decimated {} -> {} triangles (budget {faces}, {} sharp edges kept) in {:.1} s",
            report.faces_before,
            report.faces_after,
            report.feature_edges,
            t.elapsed().as_secs_f64()
        );
        if report.faces_after > faces {
            log::warn!("{} triangles remain above the budget of {faces}: no further collapse was legal", report.faces_after);
        }
        light
    };
    let dropped = light.drop_degenerate_triangles();
    if dropped > 0 {
        log::debug!("{dropped} zero-area triangles left out of the mesh");
    }
    Ok(light)
}

/// Stage 4: meshes the variants with indices in `range` that exist, as
/// `settings` say (the configuration's `[mesh]`).
pub fn run_mesh(paths: &RunPaths, range: std::ops::Range<usize>, settings: &MeshConfig) -> Result<usize> {
    let manifest = dataset::read_manifest(&paths.exemplar())?;
    let dirs: Vec<PathBuf> = range
        .map(|i| variant_dir(&paths.variants(), i))
        .filter(|d| {
            let done = stamp_path(d, StampOf::Sample).is_file();
            if d.is_dir() && !done {
                log::warn!("{}: its sampling did not finish: not meshed", d.display());
            }
            done
        })
        .collect();
    mesh_stage(&dirs, manifest.open_surface, 256, settings)
}

/// What the `mesh` command reports per input.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MeshedSummary {
    pub method: String,
    pub vertices: usize,
    pub triangles: usize,
    pub boundary_edges: usize,
}

/// The `mesh` command on one level file: meshed (`method`, or the one its
/// exemplar's openness picks; `resolution` contouring cells), decimated to
/// `faces` (0: not), written to `target` (.ply or .glb, colours kept; its
/// folder made first when `make_folder`, as a batch's output folder is), and
/// its picture to `preview`.
pub fn mesh_file(
    input: &Path,
    target: &Path,
    make_folder: bool,
    method: Option<crate::recon::Method>,
    resolution: Option<u32>,
    faces: usize,
    preview: Option<&Path>,
) -> Result<MeshedSummary> {
    let (level, provenance) = vdb::read_level(input)?;
    let named = |e: Error| Error::file(input, e.to_string());
    let (m, used) = mesh_level(&level, provenance.exemplar_open, method, resolution).map_err(named)?;
    let m = light_mesh(m, faces).map_err(named)?;
    if let Some(dir) = target.parent().filter(|d| make_folder && !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    }
    crate::io::mesh::save(&m, target, true)?;
    if let Some(png) = preview {
        let view = render::RenderOptions { up: Some(level.frame.up), ..render::preview_options() };
        let img = render::render_mesh(&m, &view).map_err(|e| Error::file(input, e.to_string()))?;
        render::save_png(&img, png)?;
    }
    Ok(MeshedSummary { method: used.to_string(), vertices: m.positions.len(), triangles: m.triangles.len(), boundary_edges: m.edge_counts().0 })
}

/// The `points` command on one level file: its surface voxels as an
/// oriented, coloured PLY point cloud at `target` (its folder made first
/// when `make_folder`). Returns the point count.
pub fn points_file(input: &Path, target: &Path, make_folder: bool) -> Result<usize> {
    let (level, _) = vdb::read_level(input)?;
    let p = oriented_points(&level).map_err(|e| Error::file(input, e.to_string()))?;
    if let Some(dir) = target.parent().filter(|d| make_folder && !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    }
    crate::io::mesh::save_points_ply(target, &p.positions, &p.normals, &p.colours)?;
    Ok(p.positions.len())
}

/// Mesh formats that keep vertex colours (`mesh --format`).
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

/// `mesh --method`: a meshing method, or the one the exemplar calls for.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum MethodChoice {
    Auto,
    Poisson,
    Apss,
}

impl MethodChoice {
    /// The method chosen; None: the exemplar's openness picks ([`mesh_level`]).
    pub fn method(self) -> Option<crate::recon::Method> {
        match self {
            MethodChoice::Auto => None,
            MethodChoice::Poisson => Some(crate::recon::Method::Poisson),
            MethodChoice::Apss => Some(crate::recon::Method::Apss),
        }
    }
}

/// What a user asks of the `mesh` command.
pub struct MeshRequest<'a> {
    pub inputs: &'a [PathBuf],
    /// The mesh file (one input; its extension is the format) or the folder.
    pub output: &'a Path,
    /// Each mesh's format when there are several inputs.
    pub format: MeshFormat,
    pub method: MethodChoice,
    /// Contouring cells along the longest axis (None: the method's default).
    pub resolution: Option<u32>,
    /// Or as an octree depth: 2^depth cells.
    pub depth: Option<u32>,
    /// Decimate to at most this many triangles (0: keep them all).
    pub faces: usize,
    /// A picture of the mesh (one input only).
    pub preview: Option<&'a Path>,
    /// Files meshed at once (0: one per core).
    pub jobs: usize,
}

/// The `mesh` command: what would drop the colours, or a preview of
/// several meshes, is refused before any work ([`Error::Usage`]); then every
/// level file is meshed ([`mesh_file`]) into `output` (one input) or
/// `output/NAME.FORMAT`.
pub fn mesh_command(r: &MeshRequest) -> Result<super::batch::Converted<MeshedSummary>> {
    use super::batch;
    let resolution = r.resolution.or(r.depth.map(|d| 1 << d));
    let several = r.inputs.len() > 1;
    let ext = if several {
        r.format.to_string()
    } else {
        r.output.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default()
    };
    if !crate::io::mesh::COLOUR_EXTENSIONS.contains(&ext.as_str()) {
        return Err(Error::Usage(format!("{}: mesh writes .ply or .glb (vertex colours), not '.{ext}'", r.output.display())));
    }
    if several && r.preview.is_some() {
        return Err(Error::Usage("--preview takes one input (several: run `render` on the meshes)".into()));
    }
    let names = batch::output_names(r.inputs)?;
    let report = batch::run(r.inputs, &names, r.jobs, |input, name| {
        let target = batch::target(r.output, name, several, Some(&ext));
        let summary = mesh_file(input, &target, several, r.method.method(), resolution, r.faces, r.preview).map_err(|e| e.to_string())?;
        Ok((Some(target), summary))
    });
    Ok(batch::Converted { report, what: "mesh", folder: several.then(|| r.output.to_path_buf()) })
}

/// The `points` command: every level file's points ([`points_file`]) into
/// `output` (one input) or `output/NAME.ply`; each input's point count.
pub fn points_command(inputs: &[PathBuf], output: &Path, jobs: usize) -> Result<super::batch::Converted<usize>> {
    use super::batch;
    let several = inputs.len() > 1;
    let names = batch::output_names(inputs)?;
    let report = batch::run(inputs, &names, jobs, |input, name| {
        let target = batch::target(output, name, several, Some("ply"));
        let count = points_file(input, &target, several).map_err(|e| e.to_string())?;
        Ok((Some(target), count))
    });
    Ok(batch::Converted { report, what: "points", folder: several.then(|| output.to_path_buf()) })
}
