// @brief Level files: one .vdb per level with the grids docs/design.md lists.
#pragma once
#include "rust/cxx.h"

// The bridge header includes this one before it defines the shared structs:
// declare them here, the .cpp files include the full definitions.
namespace shapeshifter {
struct LevelData;
struct GridSummary;
// Volumes: the grids mask, density, P, N, Cd; points: the PointDataGrid
// `points`. Either or both (a points file beside the volumes, or one file).
void write_level_file(rust::Str path, const LevelData &level, bool half_floats, bool volumes,
                      bool points);
LevelData read_level_file(rust::Str path);
rust::Vec<GridSummary> summarise_vdb_file(rust::Str path);
}
