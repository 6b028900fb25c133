//! The `edit` command on files: a level file in, an edited level file out
//! (the edits themselves are plain data operations, [`crate::level::edit`]).

use std::path::Path;

use crate::error::{Error, Result};
use crate::io::vdb;
use crate::level::edit::{copy_box, delete_box, parse_ivec3, Edit, VoxelBox};

/// Reads `input`, applies `edit`, writes `output` (the input's provenance
/// kept). Returns what it did, for the log.
pub fn edit_file(input: &Path, output: &Path, edit: Edit) -> Result<String> {
    let (mut level, provenance) = vdb::read_level(input)?;
    let named = |e: Error| Error::file(input, e.to_string());
    let what = match edit {
        Edit::Delete(region) => format!("deleted {} voxels", delete_box(&mut level, region).map_err(named)?),
        Edit::Copy(region, to) => format!("copied {} voxels", copy_box(&mut level, region, to).map_err(named)?),
    };
    vdb::write_level(output, &level, &provenance, Default::default())?;
    Ok(format!("{what}; {} voxels -> {}", level.len(), output.display()))
}

/// What a user asks of the `edit` command: a box (`x0,y0,z0:x1,y1,z1`, in
/// voxels) deleted, or copied so that its minimum corner lands on `to`
/// (`x,y,z`).
pub struct EditRequest<'a> {
    pub input: &'a Path,
    pub output: &'a Path,
    pub region: &'a str,
    /// Some: a copy to there; None: a delete.
    pub to: Option<&'a str>,
}

/// The `edit` command: the box and destination read, then [`edit_file`].
/// Returns what it did, for the log.
pub fn edit_command(r: &EditRequest) -> Result<String> {
    let to = r.to.map(|to| parse_ivec3(to).ok_or_else(|| Error::Invalid(format!("--to '{to}': expected x,y,z in voxels")))).transpose()?;
    let region = VoxelBox::parse(r.region)?;
    let edit = match to {
        None => Edit::Delete(region),
        Some(to) => Edit::Copy(region, to),
    };
    edit_file(r.input, r.output, edit)
}
