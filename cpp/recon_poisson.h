// @brief Poisson surface reconstruction through CGAL 5.5 (Kazhdan et al. 2006
// on a refined 3D Delaunay triangulation; not screened Poisson), contoured by
// CGAL's surface mesher or sampled on a sparse grid for surface nets.
#pragma once
#include "rust/cxx.h"

// The bridge header includes this one before it defines the shared structs.
namespace shapeshifter {
struct MeshOut;
struct PoissonParams;
struct PoissonGrid;
/// points, normals: 3 floats per point, world units; normals oriented outwards.
/// Triangles counter-clockwise seen from outside. Throws std::runtime_error on
/// invalid input or when CGAL fails.
MeshOut poisson_reconstruct(rust::Slice<const float> points,
                            rust::Slice<const float> normals,
                            const PoissonParams &params);
/// The same implicit function sampled at the corners of the grid cells
/// (params.grid_cell, world units) around its zero set; NaN elsewhere.
PoissonGrid poisson_grid(rust::Slice<const float> points,
                         rust::Slice<const float> normals,
                         const PoissonParams &params);
}  // namespace shapeshifter
