// @brief Mesh reading and writing through OpenMesh (OBJ+MTL, PLY, OFF, STL).
#pragma once
#include "rust/cxx.h"

// The bridge header includes this one before it defines the shared structs:
// declare them here, the .cpp files include the full definitions.
namespace shapeshifter {
struct MeshData;
MeshData read_mesh(rust::Str path);
void write_mesh(rust::Str path, const MeshData &mesh, bool binary);
// OpenMesh reports problems on its own streams (stderr); we report them
// ourselves, as values: turn its streams off (once per process).
void silence_openmesh();
}
