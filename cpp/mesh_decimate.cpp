// @brief Quadric-error decimation of a triangle mesh (Garland-Heckbert
// quadrics, OpenMesh's DecimaterT), with sharp features kept.
//
// 1. The triangles go into an OpenMesh TriMesh, which holds only manifold
//    surfaces. A triangle it refuses (an edge with more than two triangles,
//    as surface nets make where two sheets touch, or a vertex joining two
//    fans) is added with the fewest of its corners replaced by a second copy
//    of their vertex, copies shared by all such triangles so that they form
//    patches of their own; failing that, with three fresh copies. No surface
//    is lost; the copies and the vertices they copy are locked, so the seams
//    stay closed. Every vertex remembers the input vertex it came from.
// 2. Sharp edges (dihedral angle above `feature_angle_deg`) are marked as
//    features: a vertex on a feature line may only slide along it, and a
//    vertex where the line ends or branches (a corner) is locked.
// 3. Halfedge collapses in order of quadric error, each refused if it would
//    turn a nearby face's normal by more than `max_normal_deviation_deg`
//    (no fold-overs), until `target_faces` faces remain or no legal collapse
//    is left. Collapses never move the surviving vertex, so survivors keep
//    their input position and whatever the caller attaches to their source
//    index (colours).
//
// Errors are thrown as std::runtime_error and reach Rust as `Err`.

// OpenMesh's headers assert on every property access (comparing type names
// as std::strings): NDEBUG, set for every translation unit by build.rs,
// turns them off; they guard OpenMesh's own invariants, not our input
// (checked below).

// GCC 12 warns "may be used uninitialized" inside OpenMesh's property
// containers: a false positive in library headers (see mesh_io.cpp).
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

#include "shapeshifter/cpp/mesh_decimate.h"
#include "shapeshifter/cpp/mesh_io.h"
#include "shapeshifter/src/io/ffi.rs.h"

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace shapeshifter {
namespace {
using TriMesh = OpenMesh::TriMesh_ArrayKernelT<>;
using Decimater = OpenMesh::Decimater::DecimaterT<TriMesh>;
using ModQuadric = OpenMesh::Decimater::ModQuadricT<TriMesh>::Handle;
using ModNormalFlipping = OpenMesh::Decimater::ModNormalFlippingT<TriMesh>::Handle;

// Marks edges whose two faces meet at more than `angle_deg` (between their
// normals) as features, with their vertices; locks vertices where a feature
// line ends or branches. Returns the number of feature edges.
size_t mark_features(TriMesh &mesh, double angle_deg) {
  const double cos_limit = std::cos(angle_deg * M_PI / 180.0);
  size_t count = 0;
  for (auto e : mesh.edges()) {
    if (mesh.is_boundary(e)) continue;  // boundaries are kept by the decimater itself
    const auto n0 = mesh.normal(mesh.face_handle(mesh.halfedge_handle(e, 0)));
    const auto n1 = mesh.normal(mesh.face_handle(mesh.halfedge_handle(e, 1)));
    if (OpenMesh::dot(n0, n1) < cos_limit) {
      mesh.status(e).set_feature(true);
      ++count;
    }
  }
  for (auto v : mesh.vertices()) {
    int lines = 0;
    for (auto e : mesh.ve_range(v)) lines += mesh.status(e).feature() ? 1 : 0;
    if (lines > 0) mesh.status(v).set_feature(true);
    if (lines == 1 || lines > 2) mesh.status(v).set_locked(true);
  }
  return count;
}
} // namespace

DecimatedMesh decimate_mesh(rust::Slice<const float> positions,
                            rust::Slice<const uint32_t> triangles,
                            const DecimateParams &params) {
  if (positions.size() % 3 != 0 || triangles.size() % 3 != 0)
    throw std::runtime_error("positions and triangles must hold 3 values per entry");
  silence_openmesh();
  const size_t nv = positions.size() / 3;
  TriMesh mesh;
  mesh.request_vertex_status();
  mesh.request_edge_status();
  mesh.request_face_status();
  mesh.request_face_normals();
  OpenMesh::VPropHandleT<uint32_t> source;
  mesh.add_property(source);

  // 1. Build the mesh; refused triangles get their own vertex copies.
  std::vector<TriMesh::VertexHandle> handles(nv);
  // The second copy of each input vertex, made when first needed.
  std::vector<TriMesh::VertexHandle> second(nv);
  auto copy_of = [&](uint32_t i) {
    auto v = mesh.add_vertex(mesh.point(handles[i]));
    mesh.property(source, v) = i;
    return v;
  };
  for (size_t i = 0; i < nv; ++i) {
    handles[i] = mesh.add_vertex(
        TriMesh::Point(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]));
    mesh.property(source, handles[i]) = static_cast<uint32_t>(i);
  }
  for (size_t t = 0; t < triangles.size(); t += 3) {
    uint32_t idx[3] = {triangles[t], triangles[t + 1], triangles[t + 2]};
    TriMesh::VertexHandle tri[3];
    for (int k = 0; k < 3; ++k) {
      if (idx[k] >= nv)
        throw std::runtime_error("triangle " + std::to_string(t / 3) + " has vertex index " +
                                 std::to_string(idx[k]) + " out of range");
      tri[k] = handles[idx[k]];
    }
    if (mesh.add_face(tri[0], tri[1], tri[2]).is_valid()) continue;
    // Subsets of the corners to replace by second copies, smallest first
    // (bit k: corner k), then three fresh copies (subset 8).
    bool added = false;
    for (int subset : {1, 2, 4, 3, 5, 6, 7, 8}) {
      TriMesh::VertexHandle alt[3];
      for (int k = 0; k < 3; ++k) {
        if (subset == 8) {
          alt[k] = copy_of(idx[k]);
        } else if (subset & (1 << k)) {
          if (!second[idx[k]].is_valid()) second[idx[k]] = copy_of(idx[k]);
          alt[k] = second[idx[k]];
        } else {
          alt[k] = tri[k];
        }
      }
      if (mesh.add_face(alt[0], alt[1], alt[2]).is_valid()) {
        for (int k = 0; k < 3; ++k) {
          if (alt[k] != tri[k]) {
            mesh.status(alt[k]).set_locked(true);
            mesh.status(tri[k]).set_locked(true);
          }
        }
        added = true;
        break;
      }
    }
    if (!added)  // three fresh vertices always make a face
      throw std::runtime_error("triangle " + std::to_string(t / 3) + " could not be added");
  }
  mesh.update_face_normals();

  // 2. Sharp features.
  DecimatedMesh out;
  out.feature_edges = mark_features(mesh, params.feature_angle_deg);

  // 3. Decimate.
  {
    Decimater decimater(mesh);
    ModQuadric quadric;
    ModNormalFlipping flipping;
    decimater.add(quadric);
    decimater.add(flipping);
    // Quadric error ranks collapses only (no error bound): the face budget decides.
    decimater.module(quadric).unset_max_err();
    decimater.module(flipping).set_max_normal_deviation(params.max_normal_deviation_deg);
    if (!decimater.initialize()) throw std::runtime_error("the decimater could not be set up");
    decimater.decimate_to_faces(0, params.target_faces);
  }
  mesh.garbage_collection();

  out.positions.reserve(mesh.n_vertices() * 3);
  out.source_vertex.reserve(mesh.n_vertices());
  for (auto v : mesh.vertices()) {
    const auto &p = mesh.point(v);
    for (int k = 0; k < 3; ++k) out.positions.push_back(p[k]);
    out.source_vertex.push_back(mesh.property(source, v));
  }
  out.triangles.reserve(mesh.n_faces() * 3);
  for (auto f : mesh.faces())
    for (auto v : mesh.fv_range(f)) out.triangles.push_back(static_cast<uint32_t>(v.idx()));
  return out;
}
} // namespace shapeshifter
