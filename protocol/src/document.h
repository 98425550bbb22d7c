// The parsed glTF document and how its triangles map to the solver's patches.
#pragma once

#include "hemibake/protocol/gltf.h"

#include <tiny_gltf.h>

#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <array>
#include <string>
#include <vector>

namespace hemibake::protocol {

/// Where a patch came from.
struct PatchSource {
  uint32_t node = 0;       ///< the node instance (each node is one instance of its mesh)
  uint32_t mesh = 0;
  uint32_t primitive = 0;
  bool has_uv = false;
  std::array<glm::dvec2, 4> uv{};  ///< TEXCOORD_0 at the patch's corners (a quad's diagonal
                                   ///< 1-3 is the edge its two source triangles shared)
  glm::dvec3 base{1.0};    ///< displayed base colour (linear): factor times the texture's mean
  bool back = false;       ///< the back side of a double-sided triangle
};

class SceneDocument {
 public:
  tinygltf::Model model;
  solver::Scene scene;
  std::vector<PatchSource> sources;          ///< per patch
  std::vector<glm::dmat4> node_world;        ///< per node: local-to-world matrix
  std::vector<std::vector<uint8_t>> image_bytes;  ///< per image: the encoded file
  std::vector<std::string> image_mime;
  uint64_t triangles = 0;
  uint64_t vertices = 0;  ///< the primitives' vertices numbered so far (solver::Patch::vertex)
};

}  // namespace hemibake::protocol
