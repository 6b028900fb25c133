// @brief FBX, COLLADA and the other formats Assimp reads, converted to glTF
// binary by Assimp's own exporter, for the `shapeshifter-assimp` program
// (src/bin/shapeshifter-assimp.rs), which runs it in a process of its own
// under an address-space limit: Assimp's importers are large and were not
// written against hostile files, so a crash or a runaway allocation ends that
// process only. Linked into that program alone (not the library, which then
// needs no libassimp), through a C entry point.
#include <assimp/Exporter.hpp>
#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <cstring>
#include <exception>
#include <new>
#include <string>

namespace {
void say(char *message, std::size_t len, const std::string &text) {
  if (len == 0) return;
  std::strncpy(message, text.c_str(), len - 1);
  message[len - 1] = '\0';
}
} // namespace

// Reads `in` and writes its triangles, materials and textures as GLB to
// `out`. 0 on success; 1 with Assimp's message in `message` otherwise.
extern "C" int shapeshifter_assimp_convert(const char *in, const char *out, char *message, std::size_t message_len) {
  try {
    Assimp::Importer importer;
    // Points and lines are split from triangles (the glTF reader leaves them
    // out); ValidateDataStructure refuses indices past a mesh's vertices.
    const unsigned flags = aiProcess_Triangulate | aiProcess_SortByPType | aiProcess_ValidateDataStructure |
                           aiProcess_JoinIdenticalVertices;
    const aiScene *scene = importer.ReadFile(in, flags);
    if (!scene) {
      say(message, message_len, std::string("Assimp cannot read it: ") + importer.GetErrorString());
      return 1;
    }
    if (!scene->HasMeshes()) {
      say(message, message_len, "has no meshes");
      return 1;
    }
    Assimp::Exporter exporter;
    if (exporter.Export(scene, "glb2", out) != AI_SUCCESS) {
      say(message, message_len, std::string("Assimp cannot convert it to glTF: ") + exporter.GetErrorString());
      return 1;
    }
    return 0;
  } catch (const std::bad_alloc &) {
    say(message, message_len, "Assimp ran out of its memory limit reading it (damaged file?)");
    return 1;
  } catch (const std::exception &e) {
    say(message, message_len, std::string("Assimp failed on it: ") + e.what());
    return 1;
  } catch (...) {
    // Nothing may unwind into Rust (undefined behaviour across extern "C").
    say(message, message_len, "Assimp failed on it with an unknown C++ exception");
    return 1;
  }
}
