// @brief Poisson surface reconstruction through CGAL 5.5, with phase timings.
//
// CGAL's Poisson (Alliez et al., after Kazhdan, Bolitho & Hoppe 2006) is not the
// octree-based screened Poisson of Kazhdan & Hoppe 2013 that the paper used
// (depth 9, point weight 10, samples per node 1). It works in three steps:
//
//   1. Delaunay refinement: the input points are inserted into a 3D Delaunay
//      triangulation in growing random fractions, each followed by a refinement
//      pass (radius-edge ratio 2.5, cells no larger than 1/5 of the bounding
//      radius) that adds Steiner points with zero normal.
//   2. Solve: a piecewise linear indicator function on that triangulation from
//      a cotangent Laplacian (plus 0.1 on the diagonal of input vertices)
//      against the divergence of the normal field, by conjugate gradients;
//      shifted so that its median over the input points is 0, negative inside.
//   3. Contouring (poisson_grid): the function sampled, in parallel (TBB), at
//      the corners of the grid cells around its zero set; the Rust side
//      polygonises them (surface nets). Dense and uniform, like marching
//      cubes. (CGAL's own surface mesher, adaptive and sequential, took ~50
//      CPU-s for triangles near the spacing and is not used.)
//
// Steps 1 and 2 are CGAL's own sequential code and grow with the
// triangulation (mostly Steiner points around near-duplicate points), so the
// Rust side hands over points clustered per 1.5 spacings and normal direction
// (src/recon/mod.rs; figures in docs/performance.md).
//
// Units: `spacing` and `grid_cell` in world units.

// NDEBUG and CGAL_DEBUG come from build.rs for every translation unit: Eigen
// and Boost without their debug assertions, CGAL's preconditions kept (they
// throw, and the bridge turns that into an error).
// First: CGAL's containers take the allocator it defines (see there why).
#include "shapeshifter/cpp/cgal_arena.h"
#include "shapeshifter/cpp/recon_poisson.h"
#include "shapeshifter/src/io/ffi.rs.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Poisson_reconstruction_function.h>
#include <CGAL/compute_average_spacing.h>
#include <CGAL/property_map.h>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bitset>
#include <limits>
#include <cmath>
#include <ctime>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace shapeshifter {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using FT = Kernel::FT;
using Point = Kernel::Point_3;
using Vector = Kernel::Vector_3;
using Sphere = Kernel::Sphere_3;
using PointWithNormal = std::pair<Point, Vector>;
using PointMap = CGAL::First_of_pair_property_map<PointWithNormal>;
using NormalMap = CGAL::Second_of_pair_property_map<PointWithNormal>;
using PoissonFunction = CGAL::Poisson_reconstruction_function<Kernel>;
// Phase times are process CPU seconds (std::clock): CGAL's Poisson runs on the
// calling thread, and CPU time stays meaningful on a loaded machine.
struct Clock {
  using time_point = std::clock_t;
  static time_point now() { return std::clock(); }
};

double seconds_since(Clock::time_point t0) {
  return double(std::clock() - t0) / CLOCKS_PER_SEC;
}

using EigenMatrix = CGAL::Eigen_sparse_symmetric_matrix<double>::EigenType;
using ConjugateGradient = Eigen::ConjugateGradient<EigenMatrix>;

// CGAL's Eigen solver traits with a tolerance, an iteration cap and a record
// of what the solve cost. CGAL takes the traits by value: the record lives
// behind a pointer so the caller's copy sees it.
struct SolveRecord {
  double seconds = 0.0;
  Clock::time_point started{};
  long iterations = 0;
  double error = 0.0;
};

class TimedSolver : public CGAL::Eigen_solver_traits<ConjugateGradient> {
  using Base = CGAL::Eigen_solver_traits<ConjugateGradient>;

public:
  TimedSolver(double tolerance, unsigned max_iterations, SolveRecord *record)
      : record_(record) {
    if (tolerance > 0.0) solver().setTolerance(tolerance);
    if (max_iterations > 0) solver().setMaxIterations(max_iterations);
  }

  bool linear_solver(const Matrix &A, const Vector &B, Vector &X, NT &D) {
    record_->started = Clock::now();
    const bool ok = Base::linear_solver(A, B, X, D);
    record_->seconds = seconds_since(record_->started);
    record_->iterations = static_cast<long>(solver().iterations());
    record_->error = solver().error();
    return ok;
  }

private:
  SolveRecord *record_;
};

std::vector<PointWithNormal> to_points(rust::Slice<const float> points,
                                       rust::Slice<const float> normals) {
  if (points.size() % 3 != 0)
    throw std::runtime_error("poisson: point array length " +
                             std::to_string(points.size()) +
                             " is not a multiple of 3");
  if (normals.size() != points.size())
    throw std::runtime_error("poisson: " + std::to_string(points.size() / 3) +
                             " points but " + std::to_string(normals.size() / 3) +
                             " normals");
  const std::size_t n = points.size() / 3;
  std::vector<PointWithNormal> out;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float *p = points.data() + 3 * i;
    const float *q = normals.data() + 3 * i;
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]) ||
        !std::isfinite(q[0]) || !std::isfinite(q[1]) || !std::isfinite(q[2]))
      throw std::runtime_error("poisson: point " + std::to_string(i) +
                               " has a non-finite position or normal");
    out.emplace_back(Point(p[0], p[1], p[2]), Vector(q[0], q[1], q[2]));
  }
  return out;
}

// Steps 1 and 2: the implicit function, f < 0 inside, 0 at the median input point.
std::unique_ptr<PoissonFunction> implicit_function(rust::Slice<const float> points,
                                                   rust::Slice<const float> normals,
                                                   const PoissonParams &params,
                                                   PoissonStats &stats) {
  const std::vector<PointWithNormal> pwn = to_points(points, normals);
  if (pwn.size() < 16)
    throw std::runtime_error("poisson: " + std::to_string(pwn.size()) +
                             " points are too few (need 16)");
  auto t0 = Clock::now();
  double spacing = params.spacing;
  if (!(spacing > 0.0))
    spacing = CGAL::compute_average_spacing<CGAL::Sequential_tag>(
        pwn, 6, CGAL::parameters::point_map(PointMap()));
  if (!(spacing > 0.0) || !std::isfinite(spacing))
    throw std::runtime_error("poisson: the points have no positive spacing");
  stats.spacing = spacing;

  // Delaunay triangulation of a first fraction of the points (CGAL also
  // computes its own average spacing here, for an option not used).
  auto function =
      std::make_unique<PoissonFunction>(pwn.begin(), pwn.end(), PointMap(), NormalMap());
  stats.seconds_setup = seconds_since(t0);

  // The rest of the points interleaved with refinement, assembly, solve.
  t0 = Clock::now();
  SolveRecord record;
  TimedSolver solver(params.solver_tolerance, params.solver_max_iterations, &record);
  if (!function->compute_implicit_function(solver, /*smoother_hole_filling=*/false))
    throw std::runtime_error("poisson: the sparse linear solver failed (" +
                             std::to_string(record.iterations) + " iterations, error " +
                             std::to_string(record.error) + ")");
  stats.seconds_solve = record.seconds;
  stats.seconds_refine = seconds_since(t0) - record.seconds;
  stats.solver_iterations = record.iterations;
  stats.solver_error = record.error;
  stats.delaunay_vertices = function->tr().number_of_vertices();
  return function;
}

constexpr int kBrick = 8;  // brick edge in corners, as in src/recon/contour.rs
constexpr int kBrick3 = kBrick * kBrick * kBrick;

int floor_div(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

uint64_t pack(int x, int y, int z) {
  auto f = [](int v) { return uint64_t(int64_t(v) + (1 << 20)) & ((1u << 21) - 1); };
  return (f(x) << 42) | (f(y) << 21) | f(z);
}

}  // namespace

PoissonGrid poisson_grid(rust::Slice<const float> points, rust::Slice<const float> normals,
                         const PoissonParams &params) {
  if (!(params.grid_cell > 0.0) || !std::isfinite(params.grid_cell))
    throw std::runtime_error("poisson: grid_cell must be positive, got " +
                             std::to_string(params.grid_cell));
  // Before the function: its triangulation lives in the arena, and goes
  // before the arena does.
  const cgal_arena::Scope arena;
  PoissonGrid out;
  PoissonStats &stats = out.stats;
  const auto function = implicit_function(points, normals, params, stats);
  const auto &tr = function->tr();
  auto t0 = Clock::now();

  // 3a. Where the surface can be: in a tetrahedron whose vertex values change
  //     sign, the zero set of the linear function is the convex hull of its
  //     crossings of the tetrahedron's edges. The grid cells that meet the
  //     bounding box of those crossings (one cell to spare on each side)
  //     therefore hold every sign-changing grid edge and the four cells
  //     around it, holes filled by the Poisson function included. Their
  //     corners are marked, in bricks of 8^3.
  const double cell = params.grid_cell;
  const Sphere bsphere = function->bounding_sphere();
  const Point centre = bsphere.center();
  const double radius = std::sqrt(CGAL::to_double(bsphere.squared_radius()));
  const double origin[3] = {centre.x() - radius, centre.y() - radius, centre.z() - radius};
  if (4.0 * radius / cell > double(1 << 19))
    throw std::runtime_error("poisson: grid_cell " + std::to_string(cell) +
                             " is too small for a shape of radius " + std::to_string(radius));
  // 3a'. The domain: the points' bounding box plus a margin (a tenth of its
  //      longest side, at least 4 cells). Around an open sheet the zero set
  //      wraps round in a bubble that runs out to the triangulation's hull
  //      (tens of millions of corners, minutes); clipped to the domain, and
  //      with the domain's faces held outside (f > 0), it is closed by a cap
  //      one margin away. A closed shape's zero set lies well inside it.
  double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  for (std::size_t i = 0; i + 2 < points.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], double(points[i + a]));
      hi[a] = std::max(hi[a], double(points[i + a]));
    }
  const double margin =
      std::max(0.1 * std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]}), 4.0 * cell);
  int domain[6];  // corner index range, inclusive
  for (int a = 0; a < 3; ++a) {
    domain[a] = int(std::floor((lo[a] - margin - origin[a]) / cell));
    domain[3 + a] = int(std::ceil((hi[a] + margin - origin[a]) / cell));
  }
  auto on_domain_face = [&](int x, int y, int z) {
    return x <= domain[0] || y <= domain[1] || z <= domain[2] || x >= domain[3] ||
           y >= domain[4] || z >= domain[5];
  };
  std::vector<std::array<int, 6>> boxes;  // corner ranges, inclusive
  // Corner range of a world-space box, one cell to spare below and two above
  // (the cells around every corner in it), clipped to the domain; false if
  // nothing is left.
  auto corner_box = [&](const double mn[3], const double mx[3], std::array<int, 6> &box) {
    for (int a = 0; a < 3; ++a) {
      box[a] = std::max(int(std::floor((mn[a] - origin[a]) / cell)) - 1, domain[a]);
      box[3 + a] = std::min(int(std::floor((mx[a] - origin[a]) / cell)) + 2, domain[3 + a]);
    }
    return box[0] <= box[3] && box[1] <= box[4] && box[2] <= box[5];
  };
  // The cap needs two layers along every face: the face (held outside) and
  // the one inside it. A corner there can be negative only in a tetrahedron
  // with a negative vertex, so the layers are marked only where such a
  // tetrahedron's box meets them. A closed shape's inside stays far from the
  // faces and marks none (at 512 cells, full layers were ~3M corners, a third
  // of the grid).
  auto add_face_layers = [&](const std::array<int, 6> &box) {
    for (int a = 0; a < 3; ++a)
      for (int side = 0; side < 2; ++side) {
        std::array<int, 6> layer = box;
        if (side == 0) layer[3 + a] = std::min(box[3 + a], domain[a] + 1);
        else layer[a] = std::max(box[a], domain[3 + a] - 1);
        if (layer[a] <= layer[3 + a]) boxes.push_back(layer);
      }
  };
  std::size_t crossings = 0;
  for (auto c = tr.finite_cells_begin(); c != tr.finite_cells_end(); ++c) {
    double f[4];
    bool neg = false, pos = false;
    for (int i = 0; i < 4; ++i) {
      f[i] = c->vertex(i)->f();
      neg |= f[i] < 0.0;
      pos |= f[i] >= 0.0;
    }
    if (!neg) continue;
    double mn[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, mx[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 3; ++k) {
        mn[k] = std::min(mn[k], c->vertex(i)->point()[k]);
        mx[k] = std::max(mx[k], c->vertex(i)->point()[k]);
      }
    std::array<int, 6> box;
    if (corner_box(mn, mx, box)) add_face_layers(box);
    if (!pos) continue;
    for (int k = 0; k < 3; ++k) {
      mn[k] = HUGE_VAL;
      mx[k] = -HUGE_VAL;
    }
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) {
        if ((f[i] < 0.0) == (f[j] < 0.0)) continue;
        const double t = f[i] / (f[i] - f[j]);
        const Point &a = c->vertex(i)->point(), &b = c->vertex(j)->point();
        for (int k = 0; k < 3; ++k) {
          const double x = a[k] + t * (b[k] - a[k]);
          mn[k] = std::min(mn[k], x);
          mx[k] = std::max(mx[k], x);
        }
      }
    if (!corner_box(mn, mx, box)) continue;
    boxes.push_back(box);
    ++crossings;
  }
  if (crossings == 0) throw std::runtime_error("poisson: the implicit function has no zero set");
  std::vector<uint64_t> keys;
  for (const auto &box : boxes)
    for (int x = floor_div(box[0], kBrick); x <= floor_div(box[3], kBrick); ++x)
      for (int y = floor_div(box[1], kBrick); y <= floor_div(box[4], kBrick); ++y)
        for (int z = floor_div(box[2], kBrick); z <= floor_div(box[5], kBrick); ++z)
          keys.push_back(pack(x, y, z));
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  std::vector<std::array<int, 3>> bricks;
  bricks.reserve(keys.size());
  for (uint64_t k : keys) {
    auto f = [](uint64_t v) { return int(int64_t(v & ((1u << 21) - 1)) - (1 << 20)); };
    bricks.push_back({f(k >> 42), f(k >> 21), f(k)});
  }
  std::vector<std::bitset<kBrick3>> marked(bricks.size());
  for (const auto &box : boxes)
    for (int bx = floor_div(box[0], kBrick); bx <= floor_div(box[3], kBrick); ++bx)
      for (int by = floor_div(box[1], kBrick); by <= floor_div(box[4], kBrick); ++by)
        for (int bz = floor_div(box[2], kBrick); bz <= floor_div(box[5], kBrick); ++bz) {
          const std::size_t bi =
              std::lower_bound(keys.begin(), keys.end(), pack(bx, by, bz)) - keys.begin();
          auto &m = marked[bi];
          const int x0 = std::max(box[0] - bx * kBrick, 0), x1 = std::min(box[3] - bx * kBrick, kBrick - 1);
          const int y0 = std::max(box[1] - by * kBrick, 0), y1 = std::min(box[4] - by * kBrick, kBrick - 1);
          const int z0 = std::max(box[2] - bz * kBrick, 0), z1 = std::min(box[5] - bz * kBrick, kBrick - 1);
          for (int x = x0; x <= x1; ++x)
            for (int y = y0; y <= y1; ++y)
              for (int z = z0; z <= z1; ++z) m.set((x * kBrick + y) * kBrick + z);
        }

  // 3b. The function at every marked corner (NaN elsewhere), in parallel;
  //     each thread walks the triangulation with its own copy (own hint).
  //     A corner on a face shared by two cells takes its value from the cell
  //     the walk ends in, which depends on where the walk started: each brick
  //     first locates a point strictly inside a cell (a generic offset from
  //     its corner), so its walks start from the same cell whichever thread
  //     ran which bricks before.
  std::vector<float> grid_values(bricks.size() * kBrick3,
                                 std::numeric_limits<float>::quiet_NaN());
  float *values = grid_values.data();
  tbb::enumerable_thread_specific<PoissonFunction> local(*function);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, bricks.size(), 4),
                    [&](const tbb::blocked_range<std::size_t> &r) {
                      PoissonFunction &f = local.local();
                      for (std::size_t b = r.begin(); b != r.end(); ++b) {
                        float *v = values + b * kBrick3;
                        const double generic = 0.3719;
                        (void)f(Point(origin[0] + (bricks[b][0] * kBrick + generic) * cell,
                                      origin[1] + (bricks[b][1] * kBrick + 2 * generic) * cell,
                                      origin[2] + (bricks[b][2] * kBrick + 3 * generic) * cell));
                        for (int x = 0; x < kBrick; ++x)
                          for (int y = 0; y < kBrick; ++y)
                            for (int z = 0; z < kBrick; ++z) {
                              const int i = (x * kBrick + y) * kBrick + z;
                              if (!marked[b].test(i)) continue;
                              const int gx = bricks[b][0] * kBrick + x,
                                        gy = bricks[b][1] * kBrick + y,
                                        gz = bricks[b][2] * kBrick + z;
                              const Point p(origin[0] + gx * cell, origin[1] + gy * cell,
                                            origin[2] + gz * cell);
                              const float value = float(f(p));
                              // Held outside on the domain's faces; |f| puts
                              // the cap halfway to an inside neighbour.
                              v[i] = on_domain_face(gx, gy, gz)
                                         ? std::max(std::abs(value), 1e-6f)
                                         : value;
                            }
                      }
                    });
  uint64_t evaluated = 0;
  for (const auto &m : marked) evaluated += m.count();
  out.values.reserve(grid_values.size());
  for (float v : grid_values) out.values.push_back(v);
  out.bricks.reserve(3 * bricks.size());
  for (const auto &b : bricks)
    for (int v : b) out.bricks.push_back(v);
  out.origin = {origin[0], origin[1], origin[2]};
  out.cell = cell;
  stats.grid_corners = evaluated;
  stats.seconds_mesh = seconds_since(t0);
  return out;
}

}  // namespace shapeshifter
