// Material inputs of the bake (glTF 2.0, section 3.9), the extensions that change them
// (KHR_materials_emissive_strength, KHR_texture_transform, KHR_materials_pbrSpecularGlossiness) and
// the mean of a texture over a triangle.
#include "materials.h"

#include <glm/common.hpp>

#include <algorithm>
#include <vector>

namespace hemibake::protocol {
namespace {

double srgb_to_linear(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

// A texture coordinate brought into [0, 1] by a sampler's wrap mode (glTF 2.0, section 3.8.4;
// REPEAT without a sampler).
double wrap(double t, int mode) {
  if (mode == TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE) return std::clamp(t, 0.0, 1.0);
  if (mode == TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT) {
    const double f = t - 2.0 * std::floor(t / 2.0);
    return f <= 1.0 ? f : 2.0 - f;
  }
  return t - std::floor(t);
}

// Reads [r, g, b] from a tinygltf value, if it is an array of three finite numbers.
std::optional<glm::dvec3> value_rgb(const tinygltf::Value& v) {
  if (!v.IsArray() || v.ArrayLen() != 3) return std::nullopt;
  glm::dvec3 out;
  for (int i = 0; i < 3; ++i) {
    const tinygltf::Value& c = v.Get(i);
    if (!c.IsNumber() && !c.IsInt()) return std::nullopt;
    out[i] = c.GetNumberAsDouble();
    if (!std::isfinite(out[i])) return std::nullopt;
  }
  return out;
}

// A texture reference's set and transform (KHR_texture_transform's texCoord overrides the set).
std::string texture_mapping(const tinygltf::TextureInfo& info, const std::string& what, int& texcoord, UvTransform& t) {
  texcoord = info.texCoord;
  const auto it = info.extensions.find("KHR_texture_transform");
  if (it == info.extensions.end()) return {};
  const tinygltf::Value& x = it->second;
  auto number = [](const tinygltf::Value& v, double& out) {
    if (!v.IsNumber() && !v.IsInt()) return false;
    out = v.GetNumberAsDouble();
    return std::isfinite(out);
  };
  auto pair = [&](const char* key, glm::dvec2& out) {
    if (!x.Has(key)) return true;
    const tinygltf::Value& v = x.Get(key);
    return v.IsArray() && v.ArrayLen() == 2 && number(v.Get(0), out.x) && number(v.Get(1), out.y);
  };
  if (!pair("offset", t.offset) || !pair("scale", t.scale) || (x.Has("rotation") && !number(x.Get("rotation"), t.rotation)))
    return what + " has an invalid KHR_texture_transform";
  if (x.Has("texCoord")) {
    double set = 0.0;
    if (!number(x.Get("texCoord"), set) || set < 0.0 || set > 255.0 || set != std::floor(set))
      return what + " has an invalid KHR_texture_transform texCoord";
    texcoord = static_cast<int>(set);
  }
  return {};
}

// The bake's own overrides: "extras": {"hemibake": {"reflectance": [r, g, b], "emission": [r, g, b]}}.
std::string bake_overrides(const tinygltf::Material& mat, const std::string& name, MaterialInfo& out) {
  if (!mat.extras.IsObject() || !mat.extras.Has("hemibake")) return {};
  const tinygltf::Value& h = mat.extras.Get("hemibake");
  if (h.Has("reflectance")) {
    out.reflectance_override = value_rgb(h.Get("reflectance"));
    if (!out.reflectance_override) return name + ": extras.hemibake.reflectance must be [r, g, b]";
  }
  if (h.Has("emission")) {
    out.emission_override = value_rgb(h.Get("emission"));
    if (!out.emission_override || glm::min(out.emission_override->x, glm::min(out.emission_override->y, out.emission_override->z)) < 0.0)
      return name + ": extras.hemibake.emission must be [r, g, b] with non-negative numbers";
  }
  return {};
}

}  // namespace

std::string material_label(int index, const tinygltf::Material& mat) {
  return "material " + std::to_string(index) + (mat.name.empty() ? "" : " ('" + mat.name + "')");
}

std::string material_info(const tinygltf::Model& m, int index, MaterialInfo& out) {
  if (index < 0) {
    out.factor = glm::dvec3(1.0);  // the glTF default material
    return {};
  }
  if (static_cast<size_t>(index) >= m.materials.size()) return "material " + std::to_string(index) + " does not exist";
  const tinygltf::Material& mat = m.materials[index];
  const std::string name = material_label(index, mat);
  const auto& bcf = mat.pbrMetallicRoughness.baseColorFactor;
  if (bcf.size() >= 3) out.factor = glm::dvec3(bcf[0], bcf[1], bcf[2]);
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(out.factor[i])) return name + " has a non-finite baseColorFactor";
  out.base_texture = mat.pbrMetallicRoughness.baseColorTexture.index;
  if (std::string e = texture_mapping(mat.pbrMetallicRoughness.baseColorTexture, name + "'s baseColorTexture",
                                      out.base_texcoord, out.base_transform);
      !e.empty())
    return e;
  if (mat.emissiveFactor.size() == 3) out.emissive = glm::dvec3(mat.emissiveFactor[0], mat.emissiveFactor[1], mat.emissiveFactor[2]);
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(out.emissive[i]) || out.emissive[i] < 0.0) return name + " has an invalid emissiveFactor";
  if (auto it = mat.extensions.find("KHR_materials_emissive_strength"); it != mat.extensions.end()) {
    const tinygltf::Value& s = it->second.Get("emissiveStrength");
    if (s.IsNumber() || s.IsInt()) {
      const double k = s.GetNumberAsDouble();
      if (!std::isfinite(k) || k < 0.0) return name + " has an invalid emissiveStrength";
      out.emissive *= k;
    }
  }
  out.emissive_texture = mat.emissiveTexture.index;
  if (std::string e = texture_mapping(mat.emissiveTexture, name + "'s emissiveTexture", out.emissive_texcoord,
                                      out.emissive_transform);
      !e.empty())
    return e;
  out.double_sided = mat.doubleSided;
  return bake_overrides(mat, name, out);
}

std::string adopt_specular_glossiness(tinygltf::Model& m) {
  for (size_t i = 0; i < m.materials.size(); ++i) {
    tinygltf::Material& mat = m.materials[i];
    const auto it = mat.extensions.find("KHR_materials_pbrSpecularGlossiness");
    if (it == mat.extensions.end() || !it->second.IsObject()) continue;
    const std::string name = material_label(static_cast<int>(i), mat);
    const tinygltf::Value& sg = it->second;
    std::vector<double> factor = {1.0, 1.0, 1.0, 1.0};
    if (sg.Has("diffuseFactor")) {
      const tinygltf::Value& f = sg.Get("diffuseFactor");
      if (!f.IsArray() || f.ArrayLen() != 4) return name + ": KHR_materials_pbrSpecularGlossiness diffuseFactor must be [r, g, b, a]";
      for (int c = 0; c < 4; ++c) {
        if (!f.Get(c).IsNumber() && !f.Get(c).IsInt()) return name + ": KHR_materials_pbrSpecularGlossiness diffuseFactor must be numbers";
        factor[c] = f.Get(c).GetNumberAsDouble();
      }
    }
    tinygltf::TextureInfo diffuse;
    if (sg.Has("diffuseTexture")) {
      const tinygltf::Value& t = sg.Get("diffuseTexture");
      const tinygltf::Value& index = t.Get("index");
      if (!t.IsObject() || !index.IsInt() || index.Get<int>() < 0 || static_cast<size_t>(index.Get<int>()) >= m.textures.size())
        return name + ": KHR_materials_pbrSpecularGlossiness diffuseTexture must refer to an existing texture";
      diffuse.index = index.Get<int>();
      if (t.Has("texCoord")) {
        if (!t.Get("texCoord").IsInt() || t.Get("texCoord").Get<int>() < 0)
          return name + ": KHR_materials_pbrSpecularGlossiness diffuseTexture.texCoord must be a non-negative integer";
        diffuse.texCoord = t.Get("texCoord").Get<int>();
      }
      if (t.Has("extensions") && t.Get("extensions").Has("KHR_texture_transform"))
        diffuse.extensions["KHR_texture_transform"] = t.Get("extensions").Get("KHR_texture_transform");
    }
    mat.pbrMetallicRoughness.baseColorFactor = factor;
    mat.pbrMetallicRoughness.baseColorTexture = diffuse;
  }
  return {};
}

bool see_through(const tinygltf::Material& mat) {
  return mat.alphaMode != "OPAQUE" || mat.extensions.count("KHR_materials_transmission") > 0;
}

std::optional<glm::dvec3> texture_mean(const tinygltf::Model& m, int texture, const std::array<glm::dvec2, 3>& uv) {
  if (texture < 0 || static_cast<size_t>(texture) >= m.textures.size()) return std::nullopt;
  const int source = m.textures[texture].source;
  if (source < 0 || static_cast<size_t>(source) >= m.images.size()) return std::nullopt;
  const tinygltf::Image& img = m.images[source];
  if (img.width <= 0 || img.height <= 0 || img.component != 4 ||
      img.image.size() < static_cast<size_t>(img.width) * img.height * 4)
    return std::nullopt;
  const int si = m.textures[texture].sampler;
  const bool has_sampler = si >= 0 && static_cast<size_t>(si) < m.samplers.size();
  const int wrap_s = has_sampler ? m.samplers[si].wrapS : TINYGLTF_TEXTURE_WRAP_REPEAT;
  const int wrap_t = has_sampler ? m.samplers[si].wrapT : TINYGLTF_TEXTURE_WRAP_REPEAT;
  // Barycentric sample points: the centroid and points towards each corner and each edge.
  static constexpr std::array<std::array<double, 3>, 7> kSamples{{{1 / 3.0, 1 / 3.0, 1 / 3.0},
                                                                  {2 / 3.0, 1 / 6.0, 1 / 6.0},
                                                                  {1 / 6.0, 2 / 3.0, 1 / 6.0},
                                                                  {1 / 6.0, 1 / 6.0, 2 / 3.0},
                                                                  {0.45, 0.45, 0.1},
                                                                  {0.1, 0.45, 0.45},
                                                                  {0.45, 0.1, 0.45}}};
  glm::dvec3 sum(0.0);
  for (const auto& b : kSamples) {
    const glm::dvec2 t = b[0] * uv[0] + b[1] * uv[1] + b[2] * uv[2];
    if (!std::isfinite(t.x) || !std::isfinite(t.y)) return std::nullopt;
    const double fx = wrap(t.x, wrap_s), fy = wrap(t.y, wrap_t);
    const int x = std::clamp(static_cast<int>(fx * img.width), 0, img.width - 1);
    const int y = std::clamp(static_cast<int>(fy * img.height), 0, img.height - 1);
    const uint8_t* px = &img.image[(static_cast<size_t>(y) * img.width + x) * 4];
    sum += glm::dvec3(srgb_to_linear(px[0] / 255.0), srgb_to_linear(px[1] / 255.0), srgb_to_linear(px[2] / 255.0));
  }
  return sum / static_cast<double>(kSamples.size());
}

}  // namespace hemibake::protocol
