//! Encode an exemplar file into its multiscale levels and write each one as
//! a `.vdb` level file, the way an integrator would call the library:
//!
//! ```sh
//! cargo run --release --example encode_mesh -- model.obj out/levels 128
//! ```
//! (the third argument, the finest resolution, defaults to 128).

use std::path::PathBuf;

use shapeshifter::encode::{encode_exemplar, EncodeOptions};
use shapeshifter::io::exemplar::Exemplar;
use shapeshifter::io::vdb::{self, Provenance, WriteOptions};
use shapeshifter::level::files::level_file_name;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let (Some(input), Some(out)) = (args.next().map(PathBuf::from), args.next().map(PathBuf::from)) else {
        anyhow::bail!("usage: encode_mesh MESH_OR_CLOUD OUT_DIR [FINEST_RESOLUTION]");
    };
    let finest: u32 = args.next().map(|a| a.parse()).transpose()?.unwrap_or(128);

    // Meshes (OBJ, PLY, OFF, STL, glTF, FBX, COLLADA) and point clouds (PLY, LAS/LAZ, E57).
    let exemplar = Exemplar::load(&input)?;
    let options = EncodeOptions { finest_resolution: finest, sampling_resolution: 4 * finest, ..Default::default() };
    let (levels, stats) = encode_exemplar(&exemplar, &options)?;

    std::fs::create_dir_all(&out)?;
    let provenance = Provenance { exemplar: input.file_stem().unwrap_or_default().to_string_lossy().into_owned(), ..Default::default() };
    for level in &levels {
        let path = out.join(level_file_name(level.index));
        vdb::write_level(&path, level, &provenance, WriteOptions::default())?;
        println!("level {} ({}^3): {} voxels -> {}", level.index, level.resolution, level.len(), path.display());
    }
    println!("encoded in {:.2} s", stats.total_s);
    Ok(())
}
