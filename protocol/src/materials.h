// What a glTF material means to the bake: a diffuse reflectance and an emission, each a factor
// times the mean of a texture over the triangle at hand.
#pragma once

#include <tiny_gltf.h>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <array>
#include <cmath>
#include <optional>
#include <string>

namespace hemibake::protocol {

/// KHR_texture_transform: uv' = T(offset) R(rotation) S(scale) uv (the extension's matrix, with
/// rotation counter-clockwise in UV space).
struct UvTransform {
  glm::dvec2 offset{0.0}, scale{1.0};
  double rotation = 0.0;
  glm::dvec2 apply(const glm::dvec2& uv) const {
    const double c = std::cos(rotation), s = std::sin(rotation);
    const glm::dvec2 q = scale * uv;
    return offset + glm::dvec2(c * q.x + s * q.y, -s * q.x + c * q.y);
  }
};

/// One material's inputs to the bake, checked.
struct MaterialInfo {
  glm::dvec3 factor{1.0};          ///< baseColorFactor rgb
  int base_texture = -1;
  int base_texcoord = 0;           ///< the TEXCOORD_n set of the base colour texture
  UvTransform base_transform;
  glm::dvec3 emissive{0.0};        ///< emissiveFactor times strength
  int emissive_texture = -1;
  int emissive_texcoord = 0;
  UvTransform emissive_transform;
  std::optional<glm::dvec3> reflectance_override, emission_override;  ///< extras.hemibake
  bool double_sided = false;
};

/// "material 3 ('glass')": how messages name a material.
std::string material_label(int index, const tinygltf::Material& mat);

/// Reads material `index` (-1: the glTF default material) into `out`; returns an error message or
/// an empty string.
std::string material_info(const tinygltf::Model& m, int index, MaterialInfo& out);

/// KHR_materials_pbrSpecularGlossiness (archived, written by older exporters): a client that
/// supports it uses its diffuse in place of the base colour. Its diffuseFactor and diffuseTexture
/// are moved into pbrMetallicRoughness, where the loader reads the base colour and the writer
/// shows it. Returns an error message or an empty string.
std::string adopt_specular_glossiness(tinygltf::Model& m);

/// Whether the material lets light through (alphaMode BLEND or MASK, KHR_materials_transmission),
/// which the solver cannot do: such a surface blocks light like a wall.
bool see_through(const tinygltf::Material& mat);

/// Mean linear colour of texture `texture` over a triangle of UVs (samples inside the triangle,
/// wrapped by the texture's sampler). Null when the texture is absent or could not be decoded.
std::optional<glm::dvec3> texture_mean(const tinygltf::Model& m, int texture, const std::array<glm::dvec2, 3>& uv);

}  // namespace hemibake::protocol
