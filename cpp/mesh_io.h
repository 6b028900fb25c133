// @brief Mesh reading and writing through OpenMesh (OBJ+MTL, PLY, OFF, STL).
#pragma once
#include "rust/cxx.h"
#include "shapeshifter/src/ffi.rs.h"

namespace shapeshifter {
MeshData read_mesh(rust::Str path);
void write_mesh(rust::Str path, const MeshData &mesh, bool binary);
}
