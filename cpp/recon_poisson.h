// @brief Poisson surface reconstruction through CGAL 5.5 (Kazhdan et al. 2006
// on a refined 3D Delaunay triangulation; not screened Poisson), sampled on a
// sparse grid for surface nets.
#pragma once
#include "rust/cxx.h"

// The bridge header includes this one before it defines the shared structs.
namespace shapeshifter {
struct PoissonParams;
struct PoissonGrid;
/// points, normals: 3 floats per point, world units; normals oriented outwards.
/// The implicit function (negative inside) sampled at the corners of the grid
/// cells (params.grid_cell, world units) around its zero set; NaN elsewhere.
/// Throws std::runtime_error on invalid input or when CGAL fails.
PoissonGrid poisson_grid(rust::Slice<const float> points,
                         rust::Slice<const float> normals,
                         const PoissonParams &params);
}  // namespace shapeshifter
