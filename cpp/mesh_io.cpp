// @brief Mesh I/O through OpenMesh.
//
// Reading asks OpenMesh for every attribute it can give (vertex colours,
// material colours, corner texture coordinates, texture names) and flattens
// the polygon mesh into fan triangles. Errors are thrown as std::runtime_error
// and reach Rust as `Err` through the cxx Result.

// GCC 12 warns "may be used uninitialized" inside OpenMesh's property
// containers (a default-constructed VectorT pushed into a std::vector): a
// false positive in library headers, silenced for this file only, before any
// header, so a user's build log stays clean.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

#include "shapeshifter/cpp/mesh_io.h"
#include "shapeshifter/src/io/ffi.rs.h"
#include "shapeshifter/cpp/checked_file.h"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>

#include <map>
#include <mutex>
#include <stdexcept>
#include <string>

namespace shapeshifter {
namespace {
struct Traits : public OpenMesh::DefaultTraits {
  typedef OpenMesh::Vec3f Color;
};
using PolyMesh = OpenMesh::PolyMesh_ArrayKernelT<Traits>;
// Written meshes keep 8-bit colours: OpenMesh's PLY exporter only converts
// byte colours (a float colour type fails to compile in its colour cast).
struct WriteTraits : public OpenMesh::DefaultTraits {
  typedef OpenMesh::Vec3uc Color;
};
using TriMesh = OpenMesh::TriMesh_ArrayKernelT<WriteTraits>;

unsigned char to_byte(float c) {
  const float v = c < 0.f ? 0.f : (c > 1.f ? 1.f : c);
  return static_cast<unsigned char>(v * 255.f + 0.5f);
}
} // namespace

void silence_openmesh() {
  static std::once_flag once;
  std::call_once(once, [] {
    omerr().disable();
    omlog().disable();
    omout().disable();
  });
}

// One OpenMesh read or write at a time in the process: its readers and
// writers are singletons that keep per-file state in members (batch
// conversions run files on several threads).
std::mutex &openmesh_io_mutex() {
  static std::mutex m;
  return m;
}

MeshData read_mesh(rust::Str path) {
  silence_openmesh();
  std::lock_guard<std::mutex> lock(openmesh_io_mutex());
  const std::string file(path);
  PolyMesh mesh;
  mesh.request_vertex_colors();
  mesh.request_face_colors();
  mesh.request_halfedge_texcoords2D();
  mesh.request_face_texture_index();
  OpenMesh::IO::Options opt = OpenMesh::IO::Options::VertexColor |
                              OpenMesh::IO::Options::FaceColor |
                              OpenMesh::IO::Options::FaceTexCoord;
  if (!OpenMesh::IO::read_mesh(mesh, file, opt)) {
    throw std::runtime_error("could not be parsed as a mesh");
  }
  MeshData out;
  out.positions.reserve(mesh.n_vertices() * 3);
  for (auto v : mesh.vertices()) {
    const auto &p = mesh.point(v);
    out.positions.push_back(p[0]);
    out.positions.push_back(p[1]);
    out.positions.push_back(p[2]);
  }
  const bool vcol = opt.check(OpenMesh::IO::Options::VertexColor);
  const bool fcol = opt.check(OpenMesh::IO::Options::FaceColor);
  const bool uvs = opt.check(OpenMesh::IO::Options::FaceTexCoord);
  if (vcol) {
    out.vertex_colours.reserve(mesh.n_vertices() * 3);
    for (auto v : mesh.vertices()) {
      const auto &c = mesh.color(v);
      for (int k = 0; k < 3; ++k) out.vertex_colours.push_back(c[k]);
    }
  }
  out.faces_in_file = mesh.n_faces();
  for (auto f : mesh.faces()) {
    // Fan triangulation: corners 0, i, i+1.
    std::vector<OpenMesh::HalfedgeHandle> corners;
    for (auto h : mesh.fh_range(f)) corners.push_back(h);
    for (size_t i = 1; i + 1 < corners.size(); ++i) {
      const OpenMesh::HalfedgeHandle tri[3] = {corners[0], corners[i], corners[i + 1]};
      for (auto h : tri) {
        out.triangles.push_back(mesh.to_vertex_handle(h).idx());
        if (uvs) {
          const auto &t = mesh.texcoord2D(h);
          out.corner_uvs.push_back(t[0]);
          out.corner_uvs.push_back(t[1]);
        }
      }
      if (fcol) {
        const auto &c = mesh.color(f);
        for (int k = 0; k < 3; ++k) out.face_colours.push_back(c[k]);
      }
      if (uvs) out.face_texture.push_back(mesh.texture_index(f));
    }
  }
  OpenMesh::MPropHandleT<std::map<int, std::string>> textures;
  if (uvs && mesh.get_property_handle(textures, "TextureMapping")) {
    for (const auto &entry : mesh.property(textures)) {
      out.texture_ids.push_back(entry.first);
      out.texture_files.push_back(rust::String(entry.second));
    }
  }
  return out;
}

void write_mesh(rust::Str path, const MeshData &data, bool binary) {
  silence_openmesh();
  std::lock_guard<std::mutex> lock(openmesh_io_mutex());
  // The arrays are public fields on the Rust side: checked here, where an
  // index past their end would read out of bounds.
  const size_t nv = data.positions.size() / 3;
  if (data.positions.size() % 3 != 0)
    throw std::invalid_argument("mesh positions are not triples (" + std::to_string(data.positions.size()) + " values)");
  if (!data.vertex_colours.empty() && data.vertex_colours.size() != data.positions.size())
    throw std::invalid_argument("mesh has " + std::to_string(data.vertex_colours.size()) +
                                " colour values for " + std::to_string(nv) + " vertices");
  if (data.triangles.size() % 3 != 0)
    throw std::invalid_argument("mesh triangle indices are not triples");
  for (const auto i : data.triangles)
    if (i >= nv)
      throw std::invalid_argument("mesh triangle index " + std::to_string(i) + " past its " +
                                  std::to_string(nv) + " vertices");
  TriMesh mesh;
  const bool vcol = !data.vertex_colours.empty();
  if (vcol) mesh.request_vertex_colors();
  std::vector<TriMesh::VertexHandle> handles(nv);
  for (size_t i = 0; i < nv; ++i) {
    handles[i] = mesh.add_vertex(TriMesh::Point(
        data.positions[3 * i], data.positions[3 * i + 1], data.positions[3 * i + 2]));
    if (vcol)
      mesh.set_color(handles[i], TriMesh::Color(to_byte(data.vertex_colours[3 * i]),
                                                to_byte(data.vertex_colours[3 * i + 1]),
                                                to_byte(data.vertex_colours[3 * i + 2])));
  }
  for (size_t t = 0; t + 2 < data.triangles.size(); t += 3) {
    // add_face refuses non-manifold configurations; such triangles keep
    // their own vertex copies so no geometry is lost.
    TriMesh::VertexHandle tri[3] = {handles.at(data.triangles[t]),
                                    handles.at(data.triangles[t + 1]),
                                    handles.at(data.triangles[t + 2])};
    if (!mesh.add_face(tri[0], tri[1], tri[2]).is_valid()) {
      TriMesh::VertexHandle copy[3];
      for (int k = 0; k < 3; ++k) {
        copy[k] = mesh.add_vertex(mesh.point(tri[k]));
        if (vcol) mesh.set_color(copy[k], mesh.color(tri[k]));
      }
      mesh.add_face(copy[0], copy[1], copy[2]);
    }
  }
  OpenMesh::IO::Options opt;
  if (vcol) opt += OpenMesh::IO::Options::VertexColor;
  if (binary) opt += OpenMesh::IO::Options::Binary;
  // Through a stream whose failure is reported (checked_file.h: OpenMesh's
  // file writer does not report one).
  const std::string file(path);
  const auto dot = file.rfind('.');
  const std::string ext = dot == std::string::npos ? std::string() : file.substr(dot);
  write_checked(file, [&](std::ostream &os) {
    if (!OpenMesh::IO::write_mesh(mesh, os, ext, opt))
      throw std::runtime_error("could not be written (OpenMesh has no writer for '" + ext + "')");
  });
}
} // namespace shapeshifter
