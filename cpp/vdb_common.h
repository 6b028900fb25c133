// @brief Helpers shared by the OpenVDB translation units (not part of the bridge).
#pragma once
#include "shapeshifter/src/io/ffi.rs.h"
#include <openvdb/openvdb.h>
#include <mutex>

namespace shapeshifter {
inline void ensure_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

// Held for every OpenVDB file read and write: one at a time in the process.
// Why: a read first parses in a forked child (vdb_io.cpp, probe_parse), and a
// child of a multi-threaded process (batch conversions run files on several
// threads) must not inherit a lock that another thread holds inside OpenVDB's
// grid and metadata registries; with this held, no other thread is inside
// OpenVDB's file code when the child is forked. File I/O is a small part of
// each conversion (meshing and encoding dominate), so little is serialised.
inline std::mutex &vdb_file_mutex() {
  static std::mutex m;
  return m;
}

// Voxel centre (i,j,k) sits at origin + ijk * voxel_size, world units.
inline openvdb::math::Transform::Ptr level_transform(const LevelData &level) {
  auto xform = openvdb::math::Transform::createLinearTransform(level.voxel_size);
  xform->postTranslate(openvdb::Vec3d(level.origin[0], level.origin[1], level.origin[2]));
  return xform;
}

void append_points_grid(openvdb::GridPtrVec &grids, const LevelData &level,
                        openvdb::math::Transform::Ptr xform, bool half_floats);
} // namespace shapeshifter
