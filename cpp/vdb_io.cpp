// @brief Level files: write and read one level as the grids docs/design.md lists
// (mask, density, P, N, Cd, points) and summarise any .vdb file for `info`.
//
// All grids share one linear transform in the exemplar's own frame: voxel
// (i,j,k)'s centre is at origin + ijk * voxel_size (world units). Reading
// takes the topology from `mask` and the features from P/N/Cd at the same
// voxels, so a level file edited in a DCC tool comes back voxel for voxel.
#include "shapeshifter/cpp/vdb_io.h"
#include "shapeshifter/src/io/ffi.rs.h"
#include "shapeshifter/cpp/vdb_common.h"
#include "shapeshifter/cpp/vdb_guard.h"
#include "shapeshifter/cpp/checked_file.h"

#include <openvdb/io/File.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/Archive.h>

#include <stdexcept>
#include <vector>

namespace shapeshifter {
namespace {
using openvdb::Coord;
using openvdb::FloatGrid;
using openvdb::Vec3fGrid;

void set_meta(openvdb::GridBase &grid, const rust::Vec<MetaEntry> &meta) {
  for (const auto &m : meta) {
    const std::string key(m.key);
    if (m.kind == MetaKind::Text) {
      grid.insertMeta(key, openvdb::StringMetadata(std::string(m.text)));
    } else if (m.kind == MetaKind::Int) {
      grid.insertMeta(key, openvdb::Int64Metadata(static_cast<int64_t>(m.number)));
    } else if (m.kind == MetaKind::Float) {
      grid.insertMeta(key, openvdb::DoubleMetadata(m.number));
    } else if (m.kind == MetaKind::Vec3) {
      grid.insertMeta(key, openvdb::Vec3DMetadata(openvdb::Vec3d(m.vec[0], m.vec[1], m.vec[2])));
    } else {
      throw std::invalid_argument("metadata " + key + ": unknown kind");
    }
  }
}

rust::Vec<MetaEntry> get_meta(const openvdb::GridBase &grid) {
  rust::Vec<MetaEntry> out;
  for (auto it = grid.beginMeta(); it != grid.endMeta(); ++it) {
    MetaEntry e{rust::String(it->first), MetaKind::Text, rust::String(), 0.0, {0, 0, 0}};
    const auto &value = *it->second;
    const std::string type = value.typeName();
    if (type == "int32" || type == "int64" || type == "bool") {
      e.kind = MetaKind::Int;
      e.number = value.asBool() ? 1.0 : 0.0;
      if (type == "int64") e.number = double(static_cast<const openvdb::Int64Metadata &>(value).value());
      if (type == "int32") e.number = double(static_cast<const openvdb::Int32Metadata &>(value).value());
    } else if (type == "float" || type == "double") {
      e.kind = MetaKind::Float;
      e.number = type == "double" ? static_cast<const openvdb::DoubleMetadata &>(value).value()
                                  : static_cast<const openvdb::FloatMetadata &>(value).value();
    } else if (type == "vec3d") {
      e.kind = MetaKind::Vec3;
      const auto v = static_cast<const openvdb::Vec3DMetadata &>(value).value();
      e.vec = {v[0], v[1], v[2]};
    } else if (type == "vec3i") {
      e.kind = MetaKind::Vec3;
      const auto v = static_cast<const openvdb::Vec3IMetadata &>(value).value();
      e.vec = {double(v[0]), double(v[1]), double(v[2])};
    }
    e.text = rust::String(value.str());
    out.push_back(std::move(e));
  }
  return out;
}

template <typename GridT, typename T>
typename GridT::Ptr vector_grid(const char *name, const LevelData &level, const rust::Vec<T> &values,
                                openvdb::VecType type, openvdb::math::Transform::Ptr xform) {
  using V = typename GridT::ValueType;
  auto grid = GridT::create(V(0));
  auto acc = grid->getAccessor();
  const size_t n = level.coords.size() / 3;
  for (size_t i = 0; i < n; ++i) {
    acc.setValue(Coord(level.coords[3 * i], level.coords[3 * i + 1], level.coords[3 * i + 2]),
                 V(values[3 * i], values[3 * i + 1], values[3 * i + 2]));
  }
  grid->setName(name);
  grid->setVectorType(type);
  grid->setTransform(xform);
  return grid;
}
} // namespace

namespace {
// Writes grids exactly as openvdb::io::File::write does (a seekable archive:
// grid offsets, so readers may load grids one at a time), into a stream whose
// failure is reported (checked_file.h: io::File does not report one).
class CheckedArchive : public openvdb::io::Archive {
public:
  void write_file(const std::string &file_name, const openvdb::GridPtrVec &grids) const {
    write_checked(file_name, [&](std::ostream &os) { Archive::write(os, grids, /*seekable=*/true); });
  }
};
} // namespace

void write_level_file(rust::Str path, const LevelData &level, bool half_floats, bool volumes,
                      bool points) {
  ensure_openvdb();
  if (!volumes && !points) throw std::invalid_argument("a level file needs volumes or points");
  const size_t n = level.coords.size() / 3;
  if (level.points.size() != 3 * n || level.normals.size() != 3 * n ||
      level.colours.size() != 3 * n || level.mask.size() != n) {
    throw std::invalid_argument("level arrays have inconsistent lengths");
  }
  auto xform = level_transform(level);
  openvdb::GridPtrVec grids;
  if (volumes) {
    // Inactive space is "not surface": mask background -1, density background 0.
    auto mask = FloatGrid::create(-1.f);
    auto density = FloatGrid::create(0.f);
    {
      auto macc = mask->getAccessor();
      auto dacc = density->getAccessor();
      for (size_t i = 0; i < n; ++i) {
        const Coord ijk(level.coords[3 * i], level.coords[3 * i + 1], level.coords[3 * i + 2]);
        macc.setValue(ijk, level.mask[i]);
        if (level.mask[i] > 0.f) dacc.setValue(ijk, 1.f);
      }
    }
    mask->setName("mask");
    mask->setTransform(xform);
    density->setName("density");
    density->setGridClass(openvdb::GRID_FOG_VOLUME);
    density->setTransform(xform);
    grids.push_back(mask);
    grids.push_back(density);
    if (level.double_positions) {
      grids.push_back(vector_grid<openvdb::Vec3DGrid>("P", level, level.points, openvdb::VEC_CONTRAVARIANT_ABSOLUTE, xform));
    } else {
      grids.push_back(vector_grid<Vec3fGrid>("P", level, level.points, openvdb::VEC_CONTRAVARIANT_ABSOLUTE, xform));
    }
    grids.push_back(vector_grid<Vec3fGrid>("N", level, level.normals, openvdb::VEC_COVARIANT_NORMALIZE, xform));
    grids.push_back(vector_grid<Vec3fGrid>("Cd", level, level.colours, openvdb::VEC_INVARIANT, xform));
  }
  if (points) append_points_grid(grids, level, xform, half_floats);
  for (auto &grid : grids) {
    set_meta(*grid, level.meta);
    if (half_floats) grid->setSaveFloatAsHalf(true);
  }

  std::lock_guard<std::mutex> lock(vdb_file_mutex());
  CheckedArchive archive;
  uint32_t compression = openvdb::io::COMPRESS_ACTIVE_MASK;
  compression |= openvdb::io::Archive::hasBloscCompression() ? openvdb::io::COMPRESS_BLOSC
                                                             : openvdb::io::COMPRESS_ZIP;
  archive.setCompression(compression);
  archive.write_file(std::string(path), grids);
}

namespace {
// The features at the mask's voxels. A voxel the mask has and a feature grid
// lacks would read as the grid's background (a point at the origin), so it is
// refused; voxels only the feature grids have carry nothing the level uses
// and are counted (the caller warns).
template <typename PGrid>
void read_features(const FloatGrid &mask, const PGrid &P, const Vec3fGrid &N, const Vec3fGrid &Cd,
                   LevelData &out) {
  const size_t n = mask.activeVoxelCount();
  out.coords.reserve(3 * n);
  out.points.reserve(3 * n);
  out.normals.reserve(3 * n);
  out.colours.reserve(3 * n);
  out.mask.reserve(n);
  auto pacc = P.getConstAccessor();
  auto nacc = N.getConstAccessor();
  auto cacc = Cd.getConstAccessor();
  for (auto it = mask.cbeginValueOn(); it; ++it) {
    if (!it.isVoxelValue())
      throw std::runtime_error("has tiles in its mask grid; expected single voxels");
    const Coord ijk = it.getCoord();
    const std::pair<const char *, bool> on[] = {
        {"P", pacc.isValueOn(ijk)}, {"N", nacc.isValueOn(ijk)}, {"Cd", cacc.isValueOn(ijk)}};
    for (const auto &[name, active] : on) {
      if (!active)
        throw std::runtime_error("voxel (" + std::to_string(ijk[0]) + "," + std::to_string(ijk[1]) +
                                 "," + std::to_string(ijk[2]) + ") is active in grid 'mask' but not in '" +
                                 name + "': its grids disagree (edited by another tool?)");
    }
    for (int k = 0; k < 3; ++k) out.coords.push_back(ijk[k]);
    out.mask.push_back(*it);
    const auto p = pacc.getValue(ijk);
    const auto nn = nacc.getValue(ijk), c = cacc.getValue(ijk);
    for (int k = 0; k < 3; ++k) {
      out.points.push_back(double(p[k]));
      out.normals.push_back(nn[k]);
      out.colours.push_back(c[k]);
    }
  }
  auto macc = mask.getConstAccessor();
  uint64_t unmatched = 0;
  auto count = [&](const auto &grid) {
    for (auto it = grid.cbeginValueOn(); it; ++it) {
      if (!it.isVoxelValue()) {
        unmatched += it.getVoxelCount();
      } else if (!macc.isValueOn(it.getCoord())) {
        ++unmatched;
      }
    }
  };
  count(P);
  count(N);
  count(Cd);
  out.unmatched_voxels = unmatched;
}
} // namespace

LevelData read_level_file(rust::Str path) {
  const std::string file_name(path);
  // Only the four grids a level needs (not the point grid): less of a damaged
  // file is parsed.
  auto grids = read_capped(std::string(path), [&] {
    openvdb::io::File file{file_name};
    file.open(false); // no delayed loading: a truncated file must fail here
    std::vector<openvdb::GridBase::Ptr> out;
    for (const char *name : {"mask", "P", "N", "Cd"}) {
      if (!file.hasGrid(name))
        throw std::runtime_error(std::string("is not a shapeshifter level file (no grid '") + name +
                                 "')");
      out.push_back(file.readGrid(name));
    }
    file.close();
    return out;
  });
  auto mask = openvdb::GridBase::grid<FloatGrid>(grids[0]);
  // P is vec3s, or vec3d for georeferenced levels.
  auto Pd = openvdb::GridBase::grid<openvdb::Vec3DGrid>(grids[1]);
  auto Pf = openvdb::GridBase::grid<Vec3fGrid>(grids[1]);
  auto N = openvdb::GridBase::grid<Vec3fGrid>(grids[2]);
  auto Cd = openvdb::GridBase::grid<Vec3fGrid>(grids[3]);
  if (!mask || !(Pd || Pf) || !N || !Cd)
    throw std::runtime_error("has grids mask/P/N/Cd of the wrong value types");
  const auto &xform = mask->transform();
  if (!xform.isLinear() || !xform.hasUniformScale())
    throw std::runtime_error("has a non-uniform or non-linear transform");

  LevelData out{};
  out.voxel_size = xform.voxelSize()[0];
  const auto o = xform.indexToWorld(openvdb::Vec3d(0.0));
  out.origin = {o[0], o[1], o[2]};
  out.meta = get_meta(*mask);
  out.double_positions = bool(Pd);
  if (Pd) {
    read_features(*mask, *Pd, *N, *Cd, out);
  } else {
    read_features(*mask, *Pf, *N, *Cd, out);
  }
  return out;
}

uint64_t count_points(const openvdb::GridBase &grid, rust::Vec<rust::String> &attributes);

rust::Vec<GridSummary> summarise_vdb_file(rust::Str path) {
  const std::string file_name(path);
  auto grids = read_capped(std::string(path), [&] {
    openvdb::io::File file{file_name};
    file.open(false);
    auto all = file.getGrids();
    file.close();
    return all;
  });
  rust::Vec<GridSummary> out;
  for (const auto &grid : *grids) {
    if (!grid) continue;
    GridSummary s{};
    s.name = grid->getName();
    s.value_type = grid->valueType();
    s.grid_class = openvdb::GridBase::gridClassToString(grid->getGridClass());
    s.vector_type = openvdb::GridBase::vecTypeToString(grid->getVectorType());
    s.active_voxels = grid->activeVoxelCount();
    const auto bbox = grid->evalActiveVoxelBoundingBox();
    s.bbox = {bbox.min()[0], bbox.min()[1], bbox.min()[2],
              bbox.max()[0], bbox.max()[1], bbox.max()[2]};
    const auto vs = grid->voxelSize();
    s.voxel_size = {vs[0], vs[1], vs[2]};
    const auto o = grid->transform().indexToWorld(openvdb::Vec3d(0.0));
    s.origin = {o[0], o[1], o[2]};
    s.point_count = count_points(*grid, s.attributes);
    s.meta = get_meta(*grid);
    out.push_back(std::move(s));
  }
  return out;
}
} // namespace shapeshifter
