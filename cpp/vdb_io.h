// @brief Level files: one .vdb per level with the grids DESIGN.md lists.
#pragma once
#include "rust/cxx.h"
#include "shapeshifter/src/ffi.rs.h"

namespace shapeshifter {
void write_level_file(rust::Str path, const LevelData &level, bool half_floats);
LevelData read_level_file(rust::Str path);
rust::Vec<GridSummary> summarise_vdb_file(rust::Str path);
}
