// @brief Reading .vdb files under a budget, with no Rust types: shared by the
// bridge's readers (vdb_io.cpp) and the probe program
// (src/bin/shapeshifter-vdb-probe.rs, through cpp/vdb_probe_main.cpp).
#include "shapeshifter/cpp/vdb_guard.h"

#include <openvdb/io/File.h>
#include <openvdb/io/GridDescriptor.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <new>
#include <stdexcept>
#include <vector>

// The allocation cap (why and how: cpp/vdb_probe_main.cpp) is enforced only
// in the probe program, which replaces the global operator new; this file
// sets it around every parse, where it is a no-op in any other process.
namespace shapeshifter {
thread_local std::size_t g_allocation_cap = 0; // 0: no cap
} // namespace shapeshifter

namespace shapeshifter {
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
} // namespace

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

void parse_grids(const std::string &file_name, const std::vector<std::string> &names) {
  read_capped(file_name, [&] {
    openvdb::io::File file{file_name};
    file.open(false);
    if (names.empty()) {
      file.getGrids();
    } else {
      for (const auto &name : names)
        if (file.hasGrid(name)) file.readGrid(name);
    }
    file.close();
    return 0;
  });
}
} // namespace shapeshifter
