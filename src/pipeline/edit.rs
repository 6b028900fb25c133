//! The `edit` command on files: a level file in, an edited level file out
//! (the edits themselves are plain data operations, [`crate::level::edit`]).

use std::path::Path;

use crate::error::{Error, Result};
use crate::io::vdb;
use crate::level::edit::{copy_box, delete_box, Edit};

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
