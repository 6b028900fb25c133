//! The names of a level folder's files (an encoded exemplar, a variant, a
//! ladder rung): `level_K.vdb` (the volumes), `level_K.points.vdb` (its
//! PointDataGrid), `level_K.png` (its preview), K = 0 coarsest. Written and
//! parsed here only, so every reader agrees with every writer.

/// What a level file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LevelFile {
    /// `level_K.vdb`: mask, density, P, N, Cd volumes.
    Volumes,
    /// `level_K.points.vdb`: the same points as a PointDataGrid.
    Points,
    /// `level_K.png`: the level's preview.
    Preview,
}

impl LevelFile {
    fn suffix(self) -> &'static str {
        match self {
            LevelFile::Volumes => ".vdb",
            LevelFile::Points => ".points.vdb",
            LevelFile::Preview => ".png",
        }
    }

    /// The file name of level `k`.
    pub fn name(self, k: usize) -> String {
        format!("level_{k}{}", self.suffix())
    }
}

/// `level_K.vdb`.
pub fn level_file_name(k: usize) -> String {
    LevelFile::Volumes.name(k)
}

/// `level_K.png`.
pub fn preview_file_name(k: usize) -> String {
    LevelFile::Preview.name(k)
}

/// The level and kind of a level file's name; None for any other name.
pub fn parse(name: &str) -> Option<(usize, LevelFile)> {
    let rest = name.strip_prefix("level_")?;
    // The longer suffix first: `level_3.points.vdb` is not a `.vdb` of level "3.points".
    [LevelFile::Points, LevelFile::Volumes, LevelFile::Preview].into_iter().find_map(|kind| {
        let k = rest.strip_suffix(kind.suffix())?;
        (!k.is_empty() && k.bytes().all(|b| b.is_ascii_digit())).then(|| k.parse().ok().map(|k| (k, kind)))?
    })
}

/// Whether a name is one of a level folder's files (what a new sampling of
/// the folder replaces).
pub fn is_level_file(name: &str) -> bool {
    parse(name).is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_nothing_else_parses() {
        for kind in [LevelFile::Volumes, LevelFile::Points, LevelFile::Preview] {
            for k in [0, 4, 12] {
                assert_eq!(parse(&kind.name(k)), Some((k, kind)));
            }
        }
        for bad in ["level_x.vdb", "level_.vdb", "level_3.vdb.tmp", "level_-1.vdb", "level_3_loss.png", "mesh.png", "level_3.points.png"] {
            assert_eq!(parse(bad), None, "{bad}");
        }
    }
}
