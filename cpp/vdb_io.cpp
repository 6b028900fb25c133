// @brief Level files: write and read one level as the grids DESIGN.md lists
// (mask, density, P, N, Cd, points) and summarise any .vdb file for `info`.
//
// All grids share one linear transform in the exemplar's own frame: voxel
// (i,j,k)'s centre is at origin + ijk * voxel_size (world units). Reading
// takes the topology from `mask` and the features from P/N/Cd at the same
// voxels, so a level file edited in a DCC tool comes back voxel for voxel.
#include "shapeshifter/cpp/vdb_io.h"
#include "shapeshifter/src/io/ffi.rs.h"
#include "shapeshifter/cpp/vdb_common.h"

#include <openvdb/io/File.h>
#include <openvdb/io/GridDescriptor.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

#include <cstdlib>
#include <fstream>
#include <new>
#include <stdexcept>

// Reading a damaged level file under a budget.
//
// Why: OpenVDB trusts the sizes a file declares. `readString` (grid names and
// types in the grid descriptors, metadata names) and the string and unknown
// metadata readers allocate and fill a declared 32-bit length before reading
// it; a damaged type-name length in a 182 KB file cost 5-6 GB and 6-11 s before
// failing (and the "unknown grid type" error then copied the name again).
//
// How: while OpenVDB parses, no single allocation on this thread may exceed the
// cap below (a replaceable operator new that checks a thread-local limit, zero
// everywhere else), so a declared length cannot allocate more than the file
// could hold; the bad_alloc becomes a one-line error. (Parsing from a memory
// stream that throws at its end, which would also stop OpenVDB's loops over
// declared counts at the end of the bytes, was tried and dropped: OpenVDB's
// readers are not exception-safe mid-node, and 5 of 150 damaged files then
// ended in "double free or corruption".)
namespace shapeshifter {
namespace {
thread_local std::size_t g_allocation_cap = 0; // 0: no cap (every other caller)

// The cap for a file of `len` bytes: a legitimate read allocates blocks no
// larger than the file itself (compressed chunks) or a few MB (node tables).
struct AllocationCap {
  explicit AllocationCap(std::size_t len) { g_allocation_cap = 8u * 1024 * 1024 + 2 * len; }
  ~AllocationCap() { g_allocation_cap = 0; }
  AllocationCap(const AllocationCap &) = delete;
  AllocationCap &operator=(const AllocationCap &) = delete;
};
} // namespace
} // namespace shapeshifter

// The replaceable global allocation functions (the C++ standard lets a program
// define them once); identical to the library's except for the cap check.
void *operator new(std::size_t n) {
  const std::size_t cap = shapeshifter::g_allocation_cap;
  if (cap != 0 && n > cap) throw std::bad_alloc();
  if (n == 0) n = 1;
  for (;;) {
    if (void *p = std::malloc(n)) return p;
    std::new_handler handler = std::get_new_handler();
    if (!handler) throw std::bad_alloc();
    handler();
  }
}
void *operator new[](std::size_t n) { return ::operator new(n); }
void operator delete(void *p) noexcept { std::free(p); }
void operator delete[](void *p) noexcept { std::free(p); }
void operator delete(void *p, std::size_t) noexcept { std::free(p); }
void operator delete[](void *p, std::size_t) noexcept { std::free(p); }

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

Vec3fGrid::Ptr vector_grid(const char *name, const LevelData &level, const rust::Vec<float> &values,
                           openvdb::VecType type, openvdb::math::Transform::Ptr xform) {
  auto grid = Vec3fGrid::create(openvdb::Vec3f(0.f));
  auto acc = grid->getAccessor();
  const size_t n = level.coords.size() / 3;
  for (size_t i = 0; i < n; ++i) {
    acc.setValue(Coord(level.coords[3 * i], level.coords[3 * i + 1], level.coords[3 * i + 2]),
                 openvdb::Vec3f(values[3 * i], values[3 * i + 1], values[3 * i + 2]));
  }
  grid->setName(name);
  grid->setVectorType(type);
  grid->setTransform(xform);
  return grid;
}
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
    grids.push_back(vector_grid("P", level, level.points, openvdb::VEC_CONTRAVARIANT_ABSOLUTE, xform));
    grids.push_back(vector_grid("N", level, level.normals, openvdb::VEC_COVARIANT_NORMALIZE, xform));
    grids.push_back(vector_grid("Cd", level, level.colours, openvdb::VEC_INVARIANT, xform));
  }
  if (points) append_points_grid(grids, level, xform, half_floats);
  for (auto &grid : grids) {
    set_meta(*grid, level.meta);
    if (half_floats) grid->setSaveFloatAsHalf(true);
  }

  std::lock_guard<std::mutex> lock(vdb_file_mutex());
  openvdb::io::File file{std::string(path)};
  uint32_t compression = openvdb::io::COMPRESS_ACTIVE_MASK;
  compression |= openvdb::io::Archive::hasBloscCompression() ? openvdb::io::COMPRESS_BLOSC
                                                             : openvdb::io::COMPRESS_ZIP;
  file.setCompression(compression);
  file.write(grids);
  file.close();
}

namespace {
// Bytes of one value of a grid's value type as its root node stores it; 0 if
// the type is not one we know (its root counts are then not checked).
std::size_t value_bytes(const std::string &type) {
  if (type == "float" || type == "int32" || type == "ptdataidx32") return 4;
  if (type == "double" || type == "int64" || type == "ptdataidx64") return 8;
  if (type == "vec3s" || type == "vec3i") return 12;
  if (type == "vec3d") return 24;
  if (type == "bool" || type == "mask") return 1;
  return 0;
}

// Checks each grid's root-node counts before OpenVDB reads the tree.
//
// Why: RootNode::readTopology loops over the declared tile count (and child
// count) without checking the stream: a tile count of 0xFFFFFFFF in a 182 KB
// level file ran for minutes on reads that had already failed. Each tile needs
// 12 bytes of coordinates, a value and an active flag, each child at least its
// 12 bytes of coordinates, and all of it lies before the grid's buffers
// (`blockPos`), so the counts are checked against those bytes. The walk uses
// OpenVDB's own readers for the variable-sized parts (descriptors, metadata,
// transform); where it cannot follow the file it stops and leaves the verdict
// to OpenVDB's reader (still under the allocation cap).
void check_root_counts(const std::string &file_name) {
  std::ifstream is(file_name, std::ios::binary);
  int64_t magic = 0;
  uint32_t version = 0, major = 0, minor = 0;
  is.read(reinterpret_cast<char *>(&magic), 8);
  is.read(reinterpret_cast<char *>(&version), 4);
  if (!is || magic != openvdb::OPENVDB_MAGIC ||
      version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION)
    return;
  is.read(reinterpret_cast<char *>(&major), 4);
  is.read(reinterpret_cast<char *>(&minor), 4);
  char has_offsets = 0;
  is.read(&has_offsets, 1);
  is.ignore(36); // uuid
  if (!is || !has_offsets) return;
  openvdb::io::setVersion(is, openvdb::VersionId(major, minor), version);
  openvdb::MetaMap().readMeta(is);
  int32_t count = 0;
  is.read(reinterpret_cast<char *>(&count), 4);
  if (!is || count < 0) return;
  std::vector<std::pair<openvdb::io::GridDescriptor, std::size_t>> grids;
  for (int32_t i = 0; i < count && is; ++i) {
    openvdb::io::GridDescriptor gd;
    openvdb::GridBase::Ptr grid = gd.read(is);
    if (!is || !grid) return;
    grids.emplace_back(gd, value_bytes(grid->valueType()));
    is.seekg(gd.getEndPos());
  }
  for (const auto &[gd, vbytes] : grids) {
    if (gd.isInstance() || vbytes == 0) continue;
    is.clear();
    is.seekg(gd.getGridPos());
    uint32_t compression = 0;
    is.read(reinterpret_cast<char *>(&compression), 4);
    openvdb::io::setDataCompression(is, compression);
    openvdb::MetaMap().readMeta(is);
    openvdb::math::Transform().read(is);
    int32_t buffer_count = 0;
    is.read(reinterpret_cast<char *>(&buffer_count), 4);
    is.ignore(static_cast<std::streamsize>(vbytes)); // background
    uint32_t tiles = 0, children = 0;
    is.read(reinterpret_cast<char *>(&tiles), 4);
    is.read(reinterpret_cast<char *>(&children), 4);
    if (!is) return;
    const std::streamoff at = is.tellg();
    const std::streamoff room = gd.getBlockPos() - at;
    const double need = double(tiles) * double(13 + vbytes) + double(children) * 12.0;
    if (room < 0 || need > double(room))
      throw std::runtime_error("grid '" + gd.gridName() + "' declares " + std::to_string(tiles) +
                               " root tiles and " + std::to_string(children) +
                               " child nodes, more than its " + std::to_string(std::max<std::streamoff>(room, 0)) +
                               " bytes of topology can hold (damaged .vdb file)");
  }
}

} // namespace

namespace {
// Parses the grids `names` of `file_name` (all grids if empty) in a forked
// child first.
//
// Why: OpenVDB's readers assert (StreamCompression.cc: "uncompressedSize !=
// 0"), segfault or corrupt the heap ("double free or corruption") on some
// damaged files, in the original reader as much as here: 5 of 7000 damaged
// level files in a campaign took `info` down, one of them `points` too. Nothing
// outside the damaged bytes tells, so the parse is tried where a crash costs
// nothing: the child only parses (no TBB, no logging, under the same
// allocation cap) and leaves with _exit; a child killed by a signal becomes a
// one-line error here, and a clean child lets the parse run in this process.
// Cost: the file is parsed twice (about 0.1 s for the tower's 9 MB 256^3 level).
void probe_parse(const std::string &file_name, const std::vector<std::string> &names) {
  const pid_t pid = fork();
  if (pid < 0) return; // cannot isolate: parse in-process, as before
  if (pid == 0) {
    // What the parse makes is not destroyed here: freeing a tree runs a TBB
    // parallel_for, and TBB's scheduler, copied mid-state from a parent that
    // has used it (a batch reading its second file), spins for ever in the
    // child; the objects are left to _exit. (A parse that throws midway
    // still frees its partial tree while unwinding: the time limit below
    // catches that case.)
    int code = 0;
    try {
      auto *file = new openvdb::io::File(file_name);
      file->open(false);
      auto *kept = new std::vector<openvdb::GridBase::Ptr>();
      if (names.empty()) {
        new openvdb::GridPtrVecPtr(file->getGrids());
      } else {
        for (const auto &name : names)
          if (file->hasGrid(name)) kept->push_back(file->readGrid(name));
      }
    } catch (...) {
      code = 1; // the parent's own parse reports the error
    }
    _exit(code);
  }
  // A child still busy after 10 s plus 1 s per 10 MB of file (a level file
  // parses in well under a second per 10 MB) is stopped, and the parse goes
  // on here as it would without the probe.
  struct stat st {};
  const long limit_ms = 10000 + (::stat(file_name.c_str(), &st) == 0 ? long(st.st_size / 10000) : 0);
  int status = 0;
  for (long waited_ms = 0;; waited_ms += 10) {
    const pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) break;
    if (r < 0 && errno != EINTR) return;
    if (waited_ms >= limit_ms) {
      kill(pid, SIGKILL);
      while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
      }
      return;
    }
    usleep(10000);
  }
  if (WIFSIGNALED(status))
    throw std::runtime_error("OpenVDB's reader crashed on it (signal " +
                             std::to_string(WTERMSIG(status)) + "): damaged .vdb file");
}
} // namespace

namespace {
// Runs `read` (which opens `path` with openvdb::io::File) under the allocation
// cap for a file of that size, and names what a failure means in the file's
// terms.
template <typename F> auto read_capped(rust::Str path, F read) -> decltype(read()) {
  ensure_openvdb();
  std::ifstream in(std::string(path), std::ios::binary | std::ios::ate);
  if (!in) throw std::runtime_error("cannot be opened");
  const std::streamoff len = in.tellg();
  if (len < 0) throw std::runtime_error("cannot be read");
  in.close();
  std::lock_guard<std::mutex> lock(vdb_file_mutex());
  try {
    AllocationCap cap(static_cast<std::size_t>(len));
    check_root_counts(std::string(path));
    return read();
  } catch (const std::bad_alloc &) {
    throw std::runtime_error("declares a size larger than the file can hold (damaged .vdb file)");
  } catch (const std::length_error &) {
    throw std::runtime_error("declares a size larger than the file can hold (damaged .vdb file)");
  }
}
} // namespace

LevelData read_level_file(rust::Str path) {
  const std::string file_name(path);
  // Only the four grids a level needs (not the point grid): less of a damaged
  // file is parsed.
  auto grids = read_capped(path, [&] {
    probe_parse(file_name, {"mask", "P", "N", "Cd"});
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
  auto P = openvdb::GridBase::grid<Vec3fGrid>(grids[1]);
  auto N = openvdb::GridBase::grid<Vec3fGrid>(grids[2]);
  auto Cd = openvdb::GridBase::grid<Vec3fGrid>(grids[3]);
  if (!mask || !P || !N || !Cd)
    throw std::runtime_error("has grids mask/P/N/Cd of the wrong value types");
  const auto &xform = mask->transform();
  if (!xform.isLinear() || !xform.hasUniformScale())
    throw std::runtime_error("has a non-uniform or non-linear transform");

  LevelData out{};
  out.voxel_size = xform.voxelSize()[0];
  const auto o = xform.indexToWorld(openvdb::Vec3d(0.0));
  out.origin = {o[0], o[1], o[2]};
  out.meta = get_meta(*mask);
  const size_t n = mask->activeVoxelCount();
  out.coords.reserve(3 * n);
  out.points.reserve(3 * n);
  out.normals.reserve(3 * n);
  out.colours.reserve(3 * n);
  out.mask.reserve(n);
  auto pacc = P->getConstAccessor();
  auto nacc = N->getConstAccessor();
  auto cacc = Cd->getConstAccessor();
  for (auto it = mask->cbeginValueOn(); it; ++it) {
    if (!it.isVoxelValue())
      throw std::runtime_error("has tiles in its mask grid; expected single voxels");
    const Coord ijk = it.getCoord();
    for (int k = 0; k < 3; ++k) out.coords.push_back(ijk[k]);
    out.mask.push_back(*it);
    const auto p = pacc.getValue(ijk), nn = nacc.getValue(ijk), c = cacc.getValue(ijk);
    for (int k = 0; k < 3; ++k) {
      out.points.push_back(p[k]);
      out.normals.push_back(nn[k]);
      out.colours.push_back(c[k]);
    }
  }
  return out;
}

uint64_t count_points(const openvdb::GridBase &grid, rust::Vec<rust::String> &attributes);

rust::Vec<GridSummary> summarise_vdb_file(rust::Str path) {
  const std::string file_name(path);
  auto grids = read_capped(path, [&] {
    probe_parse(file_name, {});
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
