//! Stage 5, evaluation: the variants scored against the exemplar
//! (`eval.json`), the contact sheet and `report.html`.

use std::path::{Path, PathBuf};

use super::layout::variant_dir;
use super::stamp::{read_stamp, stamp_path, StampOf};
use super::RunPaths;
use crate::error::{Error, Result};
use crate::io::vdb;
use crate::learn::train;
use crate::io::dataset;
use crate::level::Level;
use crate::render;
use crate::util::fs::write_file;

/// The finest level in a folder of `level_K.vdb` files (a variant folder, an
/// encoded exemplar, a ladder rung), with the folder's name.
pub fn finest_in(dir: &Path) -> Result<(String, Level)> {
    let files = crate::eval::evaluate::level_files(dir)?;
    let (finest, _) = vdb::read_level(&files[files.len() - 1].1)?;
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok((name, finest))
}

/// Most entries on one contact sheet (the reference and 35 more): a larger set
/// would make an image no one can read, and one over the size limit.
pub const SHEET_MAX: usize = 36;

/// Writes `OUT/contact_sheet.png` of (name, level) pairs, the first the
/// reference, from the camera of `opts`; past [`SHEET_MAX`] entries, the
/// first ones.
pub fn write_contact_sheet(path: &Path, entries: &[(String, Level)], opts: &render::SheetOptions) -> Result<()> {
    if entries.len() > SHEET_MAX {
        log::info!("contact sheet: the first {} of {} shapes", SHEET_MAX, entries.len());
    }
    let refs: Vec<(String, &Level)> = entries.iter().take(SHEET_MAX).map(|(n, l)| (n.clone(), l)).collect();
    let sheet = render::contact_sheet(&refs, opts)?;
    render::save_png(&sheet, path)?;
    Ok(())
}

/// Stage 5: scores variants `0..n` against the exemplar into
/// `OUT/eval.json`, and draws `OUT/contact_sheet.png`. `Ok(None)` (and a
/// warning naming the cause, no eval.json) when no variant can be scored,
/// e.g. every one was pruned away before the finest level.
pub fn run_eval(paths: &RunPaths, n: usize) -> Result<Option<crate::eval::evaluate::Evaluation>> {
    let (_, levels) = dataset::read(&paths.exemplar())?;
    let dirs: Vec<PathBuf> = (0..n).map(|i| variant_dir(&paths.variants(), i)).collect();
    if let Some(missing) = dirs.iter().find(|d| !stamp_path(d, StampOf::Sample).is_file()) {
        return Err(Error::file(missing, "is missing or its sampling did not finish: sample it first (did a sampling job fail?)"));
    }
    // A variant whose levels were all pruned away has no level file: reported, not scored.
    let mut unreadable = Vec::new();
    let mut files = Vec::new();
    for d in &dirs {
        match crate::eval::evaluate::read_variant(d) {
            Ok(f) => files.push(f),
            Err(e) => unreadable.push(e.to_string()),
        }
    }
    let evaluation = if files.is_empty() {
        Err(Error::Invalid(format!("no variant can be scored: {}", unreadable.join("; "))))
    } else {
        crate::eval::evaluate::evaluate(&paths.exemplar(), None, &files, 256)
    };
    let evaluation = match evaluation {
        Ok(mut e) => {
            e.unscored.extend(unreadable);
            e.write_json(&paths.eval_json())?;
            Some(e)
        }
        Err(Error::Invalid(msg)) if msg.starts_with("no variant can be scored") => {
            let _ = std::fs::remove_file(paths.eval_json());
            log::warn!("evaluate: {msg}");
            None
        }
        Err(e) => return Err(e),
    };
    // Each variant labelled with its structure flags, so the sheet says
    // which shapes the measures call broken or copied.
    let flags = |name: &str| -> String {
        let scores = evaluation.as_ref().and_then(|e| e.report.variants.iter().find(|v| v.name == name));
        match scores.and_then(|v| v.structure.as_ref()) {
            Some(s) if !s.flags.is_empty() => {
                format!("\n{}", s.flags.iter().map(|f| f.name()).collect::<Vec<_>>().join(","))
            }
            _ => String::new(),
        }
    };
    let mut sheet = vec![("exemplar".to_string(), levels[levels.len() - 1].clone())];
    sheet.extend(files.iter().map(|f| (format!("{}{}", f.name, flags(&f.name)), f.finest.clone())));
    write_contact_sheet(&paths.contact_sheet(), &sheet, &render::SheetOptions::default())?;
    write_report(paths, n, evaluation.as_ref())?;
    Ok(evaluation)
}

/// Writes `OUT/report.html` from what the run folder holds: the contact
/// sheet, `evaluation`'s table, a preview per variant (its mesh, else its
/// finest level), the loss plots, the seconds each stage recorded, the
/// configuration.
pub fn write_report(paths: &RunPaths, n: usize, evaluation: Option<&crate::eval::evaluate::Evaluation>) -> Result<()> {
    let read = |p: &Path| std::fs::read(p).ok();
    let seconds = |dir: &Path, of: StampOf| read_stamp(dir, of).map(|s| s.seconds);
    let config = paths.read_config()?;
    let exemplar_name = dataset::read_manifest(&paths.exemplar()).map(|m| m.exemplar).unwrap_or_default();
    let levels = config.levels();
    let mut timings = Vec::new();
    if let Some(t) = seconds(&paths.exemplar(), StampOf::Encode) {
        timings.push(("encode".to_string(), t));
    }
    for k in 0..levels {
        if let Some(state) = train::read_state(&paths.models(), k) {
            timings.push((format!("train level {k}"), state.seconds));
        }
    }
    let dirs: Vec<PathBuf> = (0..n).map(|i| variant_dir(&paths.variants(), i)).collect();
    for (stage, of) in [("sample", StampOf::Sample), ("mesh", StampOf::Mesh)] {
        let recorded: Vec<f64> = dirs.iter().filter_map(|d| seconds(d, of)).collect();
        if !recorded.is_empty() {
            timings.push((format!("{stage} ({} variants)", recorded.len()), recorded.iter().sum()));
        }
    }
    let variants = dirs
        .iter()
        .filter_map(|d| {
            let name = d.file_name()?.to_string_lossy().into_owned();
            let finest = (0..levels).rev().map(|k| d.join(crate::level::files::preview_file_name(k))).find(|p| p.is_file());
            let png = read(&d.join("mesh.png")).or_else(|| finest.and_then(|p| read(&p)))?;
            Some((name, png))
        })
        .collect();
    let inputs = render::report::ReportInputs {
        title: format!("shapeshifter: {} ({})", exemplar_name, paths.root.display()),
        contact_sheet: read(&paths.contact_sheet()),
        eval_table: evaluation.map(|e| e.table()),
        variants,
        loss_plots: (0..levels).filter_map(|k| Some((k, read(&train::loss_plot_path(&paths.models(), k))?))).collect(),
        timings,
        config_toml: config.to_toml(),
        config_digest: config.digest(),
    };
    let page = render::report::html(&inputs);
    let path = paths.report();
    write_file(&path, &page)
}

/// The `render` command: one picture of a level file, a mesh or a point
/// cloud (`up`: the exemplar's vertical axis, where the file does not say),
/// or, given folders of level files, a contact sheet of their finest levels
/// from the same camera (`options`' azimuth and elevation; the sheet's tiles
/// keep their own size). Returns, for a contact sheet, what it holds (for the log).
pub fn render_inputs(inputs: &[PathBuf], output: &Path, options: &render::RenderOptions, up: Option<crate::level::Up>) -> Result<Option<String>> {
    use crate::io::exemplar::Exemplar;
    if inputs.iter().any(|p| p.is_dir()) {
        let entries = inputs.iter().map(|d| finest_in(d)).collect::<Result<Vec<_>>>()?;
        let camera = render::SheetOptions {
            azimuth_deg: options.azimuth_deg,
            elevation_deg: options.elevation_deg,
            ..Default::default()
        };
        write_contact_sheet(output, &entries, &camera)?;
        return Ok(Some(format!("contact sheet of {} folders -> {}", entries.len(), output.display())));
    }
    let [input] = inputs else {
        return Err(Error::Invalid("render: one file (a .vdb level or a mesh), or folders of level files for a contact sheet".into()));
    };
    let opts = render::RenderOptions { up, ..options.clone() };
    let failed = |e: render::RenderError| Error::file(input, e.to_string());
    let is_level = input.extension().is_some_and(|e| e.eq_ignore_ascii_case("vdb"));
    let img = if is_level {
        render::render_level(&vdb::read_level(input)?.0, &opts).map_err(failed)?
    } else {
        match Exemplar::load(input)? {
            Exemplar::Mesh(m) => render::render_mesh(&m, &opts).map_err(failed)?,
            Exemplar::Cloud(c) => {
                let up = up.unwrap_or(c.up);
                render::render_points(&c.oriented_points(up), &render::RenderOptions { up: Some(up), ..opts }).map_err(failed)?
            }
        }
    };
    render::save_png(&img, output)?;
    Ok(None)
}

/// What a user asks of the `eval` command.
pub struct EvalRequest<'a> {
    /// The encoded exemplar's folder.
    pub exemplar: &'a Path,
    /// Variant folders.
    pub variants: &'a [PathBuf],
    /// The exemplar mesh: with it (and a mesh in every variant), shapes are
    /// voxelised as solids.
    pub exemplar_mesh: Option<&'a Path>,
    /// Solid voxelisation: voxels along the exemplar's longest axis.
    pub resolution: u32,
    /// Where the report's JSON goes, if anywhere.
    pub output: Option<&'a Path>,
}

/// The `eval` command: the variants scored against the exemplar
/// ([`crate::eval::evaluate::evaluate`]), the report written where asked.
pub fn eval_command(r: &EvalRequest) -> Result<crate::eval::evaluate::Evaluation> {
    let mesh = r.exemplar_mesh.map(crate::io::mesh::load).transpose()?;
    let files = r.variants.iter().map(|d| crate::eval::evaluate::read_variant(d)).collect::<Result<Vec<_>>>()?;
    let evaluation = crate::eval::evaluate::evaluate(r.exemplar, mesh.as_ref(), &files, r.resolution)?;
    if let Some(out) = r.output {
        evaluation.write_json(out)?;
    }
    Ok(evaluation)
}
