// @brief The probe program's C++ (src/bin/shapeshifter-vdb-probe.rs): its C
// entry point and the allocation cap. Linked into that program alone, never
// into the library, so that no process an integrator builds on the library
// has its global operator new replaced.
//
// Why the cap: OpenVDB trusts the sizes a file declares. `readString` (grid
// names and types in the grid descriptors, metadata names) and the string and
// unknown metadata readers allocate and fill a declared 32-bit length before
// reading it; a damaged type-name length in a 182 KB file cost 5-6 GB and
// 6-11 s before failing (and the "unknown grid type" error then copied the
// name again).
//
// How: while OpenVDB parses, no single allocation on this thread may exceed
// the cap that `read_capped` sets (a replaceable operator new that checks a
// thread-local limit, zero everywhere else), so a declared length cannot
// allocate more than the file could hold; the bad_alloc becomes a one-line
// error. The library reads a .vdb in-process only after this program has
// parsed the same grids (src/io/probe.rs), so the cap is needed here only.
// (Parsing from a memory stream that throws at its end was tried and dropped:
// OpenVDB's readers are not exception-safe mid-node, and 5 of 150 damaged
// files then ended in "double free or corruption".)
#include "shapeshifter/cpp/vdb_guard.h"

#include <tbb/global_control.h>

#include <cstdlib>
#include <cstring>
#include <new>
#include <string>
#include <vector>

// The replaceable global allocation functions (the C++ standard lets a program
// define them once); identical to the standard ones except for the cap check.
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

namespace {
void say(char *message, std::size_t len, const char *text) {
  if (len == 0) return;
  std::strncpy(message, text, len - 1);
  message[len - 1] = 0;
}
} // namespace

extern "C" int shapeshifter_probe_vdb(const char *path, const char *const *names, size_t count,
                                      char *message, size_t message_len) {
  try {
    // One thread: the probe is a process of its own and needs no more.
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    std::vector<std::string> grids(names, names + count);
    shapeshifter::parse_grids(path, grids);
    return 0;
  } catch (const std::exception &e) {
    say(message, message_len, e.what());
    return 1;
  } catch (...) {
    // Nothing may unwind into Rust: a throw of a non-standard type is one
    // more failed parse.
    say(message, message_len, "the reader failed with an unknown C++ exception");
    return 1;
  }
}
