// @brief The allocator CGAL's containers use in recon_poisson.cpp: blocks of
// a triangulation at increasing addresses, in the order they were asked for.
//
// Why: CGAL's Delaunay refinement (Poisson step 1) orders cells and vertices
// by handle, and a handle is an address. With the process heap, where a
// triangulation's blocks land depends on everything the process allocated
// and freed before (a longer file path, a log line, the MKL build's set-up),
// so the same points gave another refinement, another solve and another mesh
// (seen: 158 against 159 conjugate-gradient iterations, a mesh differing by up
// to 1.5 voxels, from one level file given under two path lengths). Inside a
// scope, blocks of 1 KiB and more come from one reserved region by a bump
// pointer: their order is the order of allocation, whatever the heap did
// before. Smaller requests (CGAL's number handles) stay on the heap: they are
// freed often, and their addresses are not compared.
//
// Must be included before any CGAL header: it defines CGAL_ALLOCATOR.
#pragma once

#include <sys/mman.h>

#include <atomic>
#include <cstddef>
#include <new>

namespace shapeshifter::cgal_arena {

// A reserved region (virtual, MAP_NORESERVE: pages cost memory once
// touched), freed whole when its scope ends.
struct Arena {
  char *base = nullptr;
  std::size_t size = 0;
  std::atomic<std::size_t> used{0};
};

// The calling thread's arena while a Scope is alive on it.
inline thread_local Arena *current = nullptr;

constexpr std::size_t kSmallest = 1024;  // bytes: below this, the heap
constexpr std::size_t kAlign = 64;

// An arena for the calling thread until destroyed. Without one (the
// reservation refused, e.g. under strict overcommit), CGAL allocates from the
// heap as before: the same shapes, without the guarantee.
class Scope {
 public:
  Scope() {
    // The largest reservation the system grants, from 1 TiB down to 1 GiB.
    for (std::size_t size = std::size_t(1) << 40; size >= (std::size_t(1) << 30); size >>= 2) {
      void *p = mmap(nullptr, size, PROT_READ | PROT_WRITE,
                     MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
      if (p != MAP_FAILED) {
        arena_.base = static_cast<char *>(p);
        arena_.size = size;
        break;
      }
    }
    previous_ = current;
    if (arena_.base) current = &arena_;
  }
  ~Scope() {
    current = previous_;
    if (arena_.base) munmap(arena_.base, arena_.size);
  }
  Scope(const Scope &) = delete;
  Scope &operator=(const Scope &) = delete;

 private:
  Arena arena_;
  Arena *previous_ = nullptr;
};

}  // namespace shapeshifter::cgal_arena

// A container takes the arena of the thread that made it (none outside a
// Scope: the heap).
template <class T>
struct ShapeshifterCgalAllocator {
  using value_type = T;
  shapeshifter::cgal_arena::Arena *arena;

  ShapeshifterCgalAllocator() noexcept : arena(shapeshifter::cgal_arena::current) {}
  template <class U>
  ShapeshifterCgalAllocator(const ShapeshifterCgalAllocator<U> &other) noexcept : arena(other.arena) {}
  template <class U>
  struct rebind {
    using other = ShapeshifterCgalAllocator<U>;
  };

  T *allocate(std::size_t n) {
    using namespace shapeshifter::cgal_arena;
    const std::size_t bytes = n * sizeof(T);
    if (arena && bytes >= kSmallest) {
      const std::size_t rounded = (bytes + kAlign - 1) / kAlign * kAlign;
      const std::size_t at = arena->used.fetch_add(rounded);
      if (at + rounded <= arena->size) return reinterpret_cast<T *>(arena->base + at);
    }
    return static_cast<T *>(::operator new(bytes));
  }
  void deallocate(T *p, std::size_t) noexcept {
    const char *c = reinterpret_cast<const char *>(p);
    // Arena memory goes back with its scope.
    if (arena && c >= arena->base && c < arena->base + arena->size) return;
    ::operator delete(p);
  }
  friend bool operator==(const ShapeshifterCgalAllocator &a, const ShapeshifterCgalAllocator &b) {
    return a.arena == b.arena;
  }
  friend bool operator!=(const ShapeshifterCgalAllocator &a, const ShapeshifterCgalAllocator &b) {
    return a.arena != b.arena;
  }
};

#define CGAL_ALLOCATOR(T) ShapeshifterCgalAllocator<T>
