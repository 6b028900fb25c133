// @brief The `points` PointDataGrid of a level file: one point per active
// voxel with attributes P (world position), N and Cd, so Houdini shows the
// point cloud directly. Kept in its own translation unit because the
// PointDataGrid headers are the slowest part of OpenVDB to compile.
#include "shapeshifter/cpp/vdb_common.h"

#include <openvdb/points/PointConversion.h>
#include <openvdb/points/PointDataGrid.h>
#include <openvdb/tools/PointIndexGrid.h>

namespace shapeshifter {
namespace {
template <typename V, typename T> std::vector<V> as_vec3(const rust::Vec<T> &flat) {
  std::vector<V> out(flat.size() / 3);
  for (size_t i = 0; i < out.size(); ++i)
    out[i] = V(flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]);
  return out;
}
} // namespace

void append_points_grid(openvdb::GridPtrVec &grids, const LevelData &level,
                        openvdb::math::Transform::Ptr xform, bool half_floats) {
  using namespace openvdb::points;
  // Only voxels that hold surface (mask > 0) become points.
  // Positions in double: the point grid stores them relative to their voxel,
  // so georeferenced coordinates keep their precision.
  std::vector<openvdb::Vec3d> positions;
  std::vector<openvdb::Vec3f> normals, colours;
  const auto all_p = as_vec3<openvdb::Vec3d>(level.points);
  const auto all_n = as_vec3<openvdb::Vec3f>(level.normals), all_c = as_vec3<openvdb::Vec3f>(level.colours);
  for (size_t i = 0; i < level.mask.size(); ++i) {
    if (level.mask[i] > 0.f) {
      positions.push_back(all_p[i]);
      normals.push_back(all_n[i]);
      colours.push_back(all_c[i]);
    }
  }
  PointAttributeVector<openvdb::Vec3d> pos_wrapper(positions);
  auto index_grid = openvdb::tools::createPointIndexGrid<openvdb::tools::PointIndexGrid>(
      pos_wrapper, *xform);
  PointDataGrid::Ptr points;
  if (half_floats) {
    points = createPointDataGrid<TruncateCodec, PointDataGrid>(*index_grid, pos_wrapper, *xform);
  } else {
    points = createPointDataGrid<NullCodec, PointDataGrid>(*index_grid, pos_wrapper, *xform);
  }
  auto add = [&](const char *name, const std::vector<openvdb::Vec3f> &values) {
    appendAttribute<openvdb::Vec3f>(points->tree(), name);
    PointAttributeVector<openvdb::Vec3f> wrapper(values);
    populateAttribute<PointDataTree, openvdb::tools::PointIndexTree,
                      PointAttributeVector<openvdb::Vec3f>>(points->tree(), index_grid->tree(),
                                                            name, wrapper);
  };
  add("N", normals);
  add("Cd", colours);
  points->setName("points");
  grids.push_back(points);
}
} // namespace shapeshifter

namespace shapeshifter {
// Number of points in a PointDataGrid (0 for other grids) and its attribute names.
uint64_t count_points(const openvdb::GridBase &grid, rust::Vec<rust::String> &attributes) {
  const auto *points = dynamic_cast<const openvdb::points::PointDataGrid *>(&grid);
  if (!points) return 0;
  auto leaf = points->tree().cbeginLeaf();
  if (leaf) {
    for (const auto &name : leaf->attributeSet().descriptor().map())
      attributes.push_back(rust::String(name.first));
  }
  return openvdb::points::pointCount(points->tree());
}
} // namespace shapeshifter
