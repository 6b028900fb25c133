// @brief Quadric-error mesh decimation through OpenMesh's Decimater.
#pragma once
#include "rust/cxx.h"

// Declared only: the bridge header defines the shared structs after including this.
namespace shapeshifter {
struct DecimateParams;
struct DecimatedMesh;
DecimatedMesh decimate_mesh(rust::Slice<const float> positions,
                            rust::Slice<const uint32_t> triangles,
                            const DecimateParams &params);
}
