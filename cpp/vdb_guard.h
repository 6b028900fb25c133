// @brief Reading .vdb files under a budget (no Rust types: the probe program
// links this without the bridge). See vdb_guard.cpp for why each guard exists.
#pragma once
#include <openvdb/openvdb.h>

#include <cstddef>
#include <fstream>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

namespace shapeshifter {
inline void ensure_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

// Held for every OpenVDB file read and write: one at a time in the process.
// Why: the allocation cap of a read is per thread, but OpenVDB's file code
// shares process-wide registries (grid types, metadata types, stream
// settings); batch conversions run files on several threads. File I/O is a
// small part of each conversion (meshing and encoding dominate), so little
// is serialised.
inline std::mutex &vdb_file_mutex() {
  static std::mutex m;
  return m;
}

// While non-zero, no single allocation on this thread may exceed it. Only
// the probe program enforces it (its replaceable operator new, in
// cpp/vdb_probe_main.cpp); in the library's process it is set and unused.
extern thread_local std::size_t g_allocation_cap;

// The cap for a file of `len` bytes: a legitimate read allocates blocks no
// larger than the file itself (compressed chunks) or a few MB (node tables).
struct AllocationCap {
  explicit AllocationCap(std::size_t len) { g_allocation_cap = 8u * 1024 * 1024 + 2 * len; }
  ~AllocationCap() { g_allocation_cap = 0; }
  AllocationCap(const AllocationCap &) = delete;
  AllocationCap &operator=(const AllocationCap &) = delete;
};

// Throws when a grid's root node declares more tiles or children than its
// bytes can hold (see vdb_guard.cpp).
void check_root_counts(const std::string &file_name);

// Runs `read` (which opens `path` with openvdb::io::File) under the allocation
// cap for a file of that size, and names what a failure means in the file's
// terms.
template <typename F> auto read_capped(const std::string &path, F read) -> decltype(read()) {
  ensure_openvdb();
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw std::runtime_error("cannot be opened");
  const std::streamoff len = in.tellg();
  if (len < 0) throw std::runtime_error("cannot be read");
  in.close();
  std::lock_guard<std::mutex> lock(vdb_file_mutex());
  try {
    AllocationCap cap(static_cast<std::size_t>(len));
    check_root_counts(path);
    return read();
  } catch (const std::bad_alloc &) {
    throw std::runtime_error("declares a size larger than the file can hold (damaged .vdb file)");
  } catch (const std::length_error &) {
    throw std::runtime_error("declares a size larger than the file can hold (damaged .vdb file)");
  }
}

// Parses grids `names` of a file (all if empty) under the cap and drops them.
void parse_grids(const std::string &file_name, const std::vector<std::string> &names);
} // namespace shapeshifter

// The probe program's entry (cpp/vdb_probe_main.cpp, linked into that program
// only): parses as `parse_grids`; 0, or 1 with the error in `message`
// (NUL-terminated, cut to `message_len`). Never throws.
extern "C" int shapeshifter_probe_vdb(const char *path, const char *const *names, size_t count,
                                      char *message, size_t message_len);
