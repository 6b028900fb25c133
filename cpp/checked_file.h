// @brief Writing a file through a stream whose failure is reported.
//
// Why: neither openvdb::io::File nor OpenMesh's file writers check their
// stream, so on a full disk they returned normally and a truncated temporary
// file was renamed into place under its final name (src/util/fs.rs renames).
#pragma once
#include <cerrno>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <string>

namespace shapeshifter {
// Opens `file_name` for binary output, lets `write(stream)` fill it, and
// throws naming the cause (ENOSPC: "No space left on device") if creating,
// writing, flushing or closing failed.
template <typename F> void write_checked(const std::string &file_name, F write) {
  std::ofstream os(file_name, std::ios_base::out | std::ios_base::binary | std::ios_base::trunc);
  if (!os) throw std::runtime_error(std::string("cannot be created: ") + std::strerror(errno));
  errno = 0;
  write(os);
  os.flush();
  const int flush_errno = errno;
  const bool flushed = bool(os);
  os.close();
  if (!flushed || os.fail())
    throw std::runtime_error(std::string("could not be written: ") +
                             std::strerror(flush_errno != 0 ? flush_errno : EIO));
}
} // namespace shapeshifter
