// @brief Helpers shared by the OpenVDB translation units (not part of the bridge).
#pragma once
#include "shapeshifter/src/io/ffi.rs.h"
#include <openvdb/openvdb.h>
#include "shapeshifter/cpp/vdb_guard.h"

namespace shapeshifter {
// Voxel centre (i,j,k) sits at origin + ijk * voxel_size, world units.
inline openvdb::math::Transform::Ptr level_transform(const LevelData &level) {
  auto xform = openvdb::math::Transform::createLinearTransform(level.voxel_size);
  xform->postTranslate(openvdb::Vec3d(level.origin[0], level.origin[1], level.origin[2]));
  return xform;
}

void append_points_grid(openvdb::GridPtrVec &grids, const LevelData &level,
                        openvdb::math::Transform::Ptr xform, bool half_floats);
} // namespace shapeshifter
