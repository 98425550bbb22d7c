// glTF 2.0 to patches. The file is untrusted: tinygltf parses the JSON and the GLB container, and
// everything it does not check (accessor ranges, strides, index values, node cycles, image sizes,
// external paths) is checked here before use, with an error that names the object at fault.
#include "document.h"
#include "precheck.h"

#include "hemibake/solver/solver.h"

#include <stb_image.h>

#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <unordered_map>

namespace hemibake::protocol {
namespace {

namespace fs = std::filesystem;

// Reflectance is capped below 1 (a glTF base colour of 1 would reflect everything it receives).
constexpr double kMaxReflectance = 0.95;
// Accessors with more elements than this are refused before any arithmetic on their size.
constexpr uint64_t kMaxAccessorCount = 1ull << 28;
// Sparse accessors and accessors without a bufferView are made dense in memory; without a
// bufferView nothing in the file bounds their size.
constexpr uint64_t kMaxDenseBytes = 1ull << 28;

struct LoaderContext {
  std::string base_dir;
  bool allow_external = false;
  uint64_t max_bytes = 0;
  uint32_t max_image_pixels = 0;
  SceneDocument* doc = nullptr;
  std::vector<std::string>* warnings = nullptr;
};

// Whether `path` lies inside the folder of the glTF file.
bool inside_base(const LoaderContext& ctx, const std::string& path) {
  std::error_code ec;
  const fs::path base = fs::weakly_canonical(ctx.base_dir.empty() ? fs::path(".") : fs::path(ctx.base_dir), ec);
  const fs::path target = fs::weakly_canonical(fs::path(path), ec);
  const auto rel = target.lexically_relative(base);
  return !ec && !rel.empty() && *rel.begin() != "..";
}

bool fs_exists(const std::string& path, void* user) {
  // Only files that may be read exist: the answer must not reveal anything else on the machine.
  const auto& ctx = *static_cast<const LoaderContext*>(user);
  if (!ctx.allow_external || !inside_base(ctx, path)) return false;
  std::error_code ec;
  return fs::exists(path, ec);
}
std::string fs_expand(const std::string& path, void*) { return path; }
bool fs_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err = "writing files is not allowed while loading";
  return false;
}
bool fs_read(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
  const auto* ctx = static_cast<const LoaderContext*>(user);
  if (!ctx->allow_external) {
    if (err) *err = "external file '" + path + "' is not allowed here: embed buffers and images (GLB or data URIs)";
    return false;
  }
  // The file must lie inside the folder of the .gltf file.
  std::error_code ec;
  if (!inside_base(*ctx, path)) {
    if (err) *err = "an external file lies outside the folder of the glTF file";
    return false;
  }
  const fs::path target = fs::weakly_canonical(fs::path(path), ec);
  const auto size = fs::file_size(target, ec);
  if (ec) {
    if (err) *err = "cannot read external file '" + path + "'";
    return false;
  }
  if (size > ctx->max_bytes) {
    if (err) *err = "external file '" + path + "' is larger than the limit";
    return false;
  }
  std::ifstream in(target, std::ios::binary);
  out->resize(size);
  if (!in.read(reinterpret_cast<char*>(out->data()), static_cast<std::streamsize>(size))) {
    if (err) *err = "cannot read external file '" + path + "'";
    return false;
  }
  return true;
}

// Keeps each image's encoded bytes (for the output) and decodes it to 8-bit RGBA after checking
// its size. An image that cannot be decoded is a warning: its texture counts as white.
bool load_image(tinygltf::Image* image, const int index, std::string*, std::string*, int, int,
                const unsigned char* bytes, int size, void* user) {
  auto* ctx = static_cast<LoaderContext*>(user);
  auto& doc = *ctx->doc;
  if (index >= 0) {
    if (doc.image_bytes.size() <= static_cast<size_t>(index)) {
      doc.image_bytes.resize(index + 1);
      doc.image_mime.resize(index + 1);
    }
    doc.image_bytes[index].assign(bytes, bytes + size);
    const bool png = size >= 8 && std::memcmp(bytes, "\x89PNG", 4) == 0;
    const bool jpeg = size >= 3 && bytes[0] == 0xff && bytes[1] == 0xd8;
    doc.image_mime[index] = png ? "image/png" : jpeg ? "image/jpeg" : image->mimeType;
  }
  int w = 0, h = 0, comp = 0;
  if (!stbi_info_from_memory(bytes, size, &w, &h, &comp)) {
    ctx->warnings->push_back("image " + std::to_string(index) + " cannot be decoded; its texture counts as white");
    return true;
  }
  if (w <= 0 || h <= 0 || static_cast<uint64_t>(w) * static_cast<uint64_t>(h) > ctx->max_image_pixels) {
    ctx->warnings->push_back("image " + std::to_string(index) + " (" + std::to_string(w) + " x " +
                             std::to_string(h) + ") is larger than the limit; its texture counts as white");
    return true;
  }
  unsigned char* pixels = stbi_load_from_memory(bytes, size, &w, &h, &comp, 4);
  if (!pixels) {
    ctx->warnings->push_back("image " + std::to_string(index) + " cannot be decoded; its texture counts as white");
    return true;
  }
  image->width = w;
  image->height = h;
  image->component = 4;
  image->bits = 8;
  image->pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
  image->image.assign(pixels, pixels + static_cast<size_t>(w) * h * 4);
  stbi_image_free(pixels);
  return true;
}

// A checked view of an accessor's elements.
struct View {
  const uint8_t* data = nullptr;  // first element
  size_t stride = 0;
  size_t count = 0;
  int component_type = 0;
  int components = 0;
  bool normalized = false;
  std::shared_ptr<const std::vector<uint8_t>> owned;  // a sparse accessor's elements, made dense
};

int component_size(int type) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
    default: return 0;
  }
}

int component_count(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return 1;
    case TINYGLTF_TYPE_VEC2: return 2;
    case TINYGLTF_TYPE_VEC3: return 3;
    case TINYGLTF_TYPE_VEC4: return 4;
    case TINYGLTF_TYPE_MAT2: return 4;
    case TINYGLTF_TYPE_MAT3: return 9;
    case TINYGLTF_TYPE_MAT4: return 16;
    default: return 0;
  }
}

double read_component(const View& v, size_t i, int c) {
  const uint8_t* p = v.data + v.stride * i + static_cast<size_t>(c) * component_size(v.component_type);
  switch (v.component_type) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float f;
      std::memcpy(&f, p, 4);
      return f;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return v.normalized ? p[0] / 255.0 : p[0];
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      const double x = static_cast<int8_t>(p[0]);
      return v.normalized ? std::max(x / 127.0, -1.0) : x;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      uint16_t s;
      std::memcpy(&s, p, 2);
      return v.normalized ? s / 65535.0 : s;
    }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t s;
      std::memcpy(&s, p, 2);
      return v.normalized ? std::max(s / 32767.0, -1.0) : s;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      uint32_t u;
      std::memcpy(&u, p, 4);
      return u;
    }
    default: return 0.0;
  }
}

// The first of `count` elements of `element` bytes, `stride` apart, from byte `offset` of
// bufferView `view`, after checking that they lie inside it; or an error message about `name`.
std::string view_bytes(const tinygltf::Model& m, int view, uint64_t offset, uint64_t count, size_t element,
                       size_t stride, const std::string& name, const uint8_t*& data) {
  if (view < 0 || static_cast<size_t>(view) >= m.bufferViews.size()) return name + " has no valid bufferView";
  const tinygltf::BufferView& bv = m.bufferViews[view];
  if (bv.buffer < 0 || static_cast<size_t>(bv.buffer) >= m.buffers.size())
    return "bufferView " + std::to_string(view) + " refers to buffer " + std::to_string(bv.buffer) + ", which does not exist";
  const tinygltf::Buffer& buf = m.buffers[bv.buffer];
  if (bv.byteOffset > buf.data.size() || bv.byteLength > buf.data.size() - bv.byteOffset)
    return "bufferView " + std::to_string(view) + " (offset " + std::to_string(bv.byteOffset) +
           ", length " + std::to_string(bv.byteLength) + ") lies outside buffer " + std::to_string(bv.buffer) +
           " (" + std::to_string(buf.data.size()) + " bytes)";
  // Last byte used: offset + stride * (count - 1) + element, within the view (no overflow: count,
  // stride and offset are bounded above).
  const uint64_t need = offset + static_cast<uint64_t>(stride) * (count - 1) + element;
  if (offset > bv.byteLength || need > bv.byteLength)
    return name + " needs " + std::to_string(need) + " bytes but bufferView " + std::to_string(view) +
           " has " + std::to_string(bv.byteLength);
  data = buf.data.data() + bv.byteOffset + offset;
  return {};
}

// Checks accessor `index` for use as `what` and returns a view of it, or an error message. An
// accessor without a bufferView is zeros (glTF 2.0, section 3.6.2); a sparse accessor (3.6.2.3)
// is those or its bufferView's elements, with the elements at `sparse.indices` replaced by
// `sparse.values`. Either is made dense in a copy.
std::string view_accessor(const tinygltf::Model& m, int index, const std::string& what, View& out) {
  const std::string name = "accessor " + std::to_string(index) + " (" + what + ")";
  if (index < 0 || static_cast<size_t>(index) >= m.accessors.size())
    return what + " refers to accessor " + std::to_string(index) + ", which does not exist";
  const tinygltf::Accessor& a = m.accessors[index];
  const int csize = component_size(a.componentType);
  const int ncomp = component_count(a.type);
  if (csize == 0 || ncomp == 0) return name + " has an invalid componentType or type";
  if (a.count == 0) return name + " has no elements";
  if (a.count > kMaxAccessorCount) return name + " has too many elements (" + std::to_string(a.count) + ")";
  const size_t element = static_cast<size_t>(csize) * static_cast<size_t>(ncomp);
  out = View();
  out.count = a.count;
  out.component_type = a.componentType;
  out.components = ncomp;
  out.normalized = a.normalized;
  if (a.bufferView >= 0) {
    if (static_cast<size_t>(a.bufferView) >= m.bufferViews.size()) return name + " has no valid bufferView";
    const tinygltf::BufferView& bv = m.bufferViews[a.bufferView];
    const size_t stride = bv.byteStride != 0 ? bv.byteStride : element;
    if (stride < element || stride % static_cast<size_t>(csize) != 0 || stride > 252)
      return "bufferView " + std::to_string(a.bufferView) + " has byteStride " + std::to_string(bv.byteStride) +
             ", invalid for " + name;
    if (a.byteOffset % static_cast<size_t>(csize) != 0) return name + " has a misaligned byteOffset";
    if (std::string e = view_bytes(m, a.bufferView, a.byteOffset, a.count, element, stride, name, out.data); !e.empty())
      return e;
    out.stride = stride;
    if (!a.sparse.isSparse) return {};
  }

  // Without a bufferView the elements are zeros (exporters write an unused morph target so).
  if (a.count * element > kMaxDenseBytes) return name + " is too large to expand (" + std::to_string(a.count) + " elements)";
  auto dense = std::make_shared<std::vector<uint8_t>>(a.count * element, uint8_t{0});
  if (out.data)
    for (size_t i = 0; i < a.count; ++i) std::memcpy(dense->data() + i * element, out.data + i * out.stride, element);
  if (a.sparse.isSparse) {
    const auto& sp = a.sparse;
    if (sp.count <= 0 || static_cast<size_t>(sp.count) > a.count)
      return name + " has sparse.count " + std::to_string(sp.count) + "; it must be 1 to count (" + std::to_string(a.count) + ")";
    View indices;
    indices.count = static_cast<size_t>(sp.count);
    indices.component_type = sp.indices.componentType;
    indices.components = 1;
    indices.stride = static_cast<size_t>(component_size(sp.indices.componentType));
    if (sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
      return name + " has sparse indices that are not unsigned byte, short or int";
    if (sp.indices.byteOffset < 0 || sp.values.byteOffset < 0 ||
        static_cast<size_t>(sp.indices.byteOffset) % indices.stride != 0 || sp.values.byteOffset % csize != 0)
      return name + " has a negative or misaligned sparse byteOffset";
    const uint8_t* values = nullptr;
    if (std::string e = view_bytes(m, sp.indices.bufferView, static_cast<uint64_t>(sp.indices.byteOffset), indices.count,
                                   indices.stride, indices.stride, name + " sparse indices", indices.data);
        !e.empty())
      return e;
    if (std::string e = view_bytes(m, sp.values.bufferView, static_cast<uint64_t>(sp.values.byteOffset), indices.count,
                                   element, element, name + " sparse values", values);
        !e.empty())
      return e;
    double previous = -1.0;
    for (size_t k = 0; k < indices.count; ++k) {
      const double i = read_component(indices, k, 0);
      // The specification requires strictly increasing indices; that also makes each one unique.
      if (i >= static_cast<double>(a.count) || i <= previous)
        return name + " has sparse index " + std::to_string(static_cast<uint64_t>(i)) + " at " + std::to_string(k) +
               ": the indices must increase and be below count (" + std::to_string(a.count) + ")";
      previous = i;
      std::memcpy(dense->data() + static_cast<size_t>(i) * element, values + k * element, element);
    }
  }
  out.data = dense->data();
  out.stride = element;
  out.owned = std::move(dense);
  return {};
}

glm::dmat4 local_matrix(const tinygltf::Node& n) {
  if (n.matrix.size() == 16) {
    glm::dmat4 m;
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) m[c][r] = n.matrix[static_cast<size_t>(c * 4 + r)];  // column-major
    return m;
  }
  glm::dmat4 m(1.0);
  if (n.translation.size() == 3) m = glm::translate(m, glm::dvec3(n.translation[0], n.translation[1], n.translation[2]));
  if (n.rotation.size() == 4) {
    const glm::dquat q(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]);  // w, x, y, z
    m = m * glm::mat4_cast(glm::normalize(q));
  }
  if (n.scale.size() == 3) m = glm::scale(m, glm::dvec3(n.scale[0], n.scale[1], n.scale[2]));
  return m;
}

bool finite(const glm::dmat4& m) {
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      if (!std::isfinite(m[c][r])) return false;
  return true;
}

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

// Mean linear colour of a texture over a triangle of UVs (samples inside the triangle, wrapped by
// the texture's sampler). Null when the texture is absent or could not be decoded.
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

// KHR_texture_transform: uv' = T(offset) R(rotation) S(scale) uv (the extension's matrix, with
// rotation counter-clockwise in UV space).
struct UvTransform {
  glm::dvec2 offset{0.0}, scale{1.0};
  double rotation = 0.0;
  glm::dvec2 apply(const glm::dvec2& uv) const {
    const double c = std::cos(rotation), s = std::sin(rotation);
    const glm::dvec2 q = scale * uv;
    return offset + glm::dvec2(c * q.x + s * q.y, -s * q.x + c * q.y);
  }
};

struct MaterialInfo {
  glm::dvec3 factor{1.0};          // baseColorFactor rgb
  int base_texture = -1;
  int base_texcoord = 0;
  UvTransform base_transform;
  glm::dvec3 emissive{0.0};        // emissiveFactor times strength
  int emissive_texture = -1;
  int emissive_texcoord = 0;
  UvTransform emissive_transform;
  std::optional<glm::dvec3> reflectance_override, emission_override;
  bool double_sided = false;
};

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

std::string material_info(const tinygltf::Model& m, int index, MaterialInfo& out, std::vector<std::string>& warnings) {
  if (index < 0) {
    out.factor = glm::dvec3(1.0);  // the glTF default material
    return {};
  }
  if (static_cast<size_t>(index) >= m.materials.size()) return "material " + std::to_string(index) + " does not exist";
  const tinygltf::Material& mat = m.materials[index];
  const std::string name = "material " + std::to_string(index) + (mat.name.empty() ? "" : " ('" + mat.name + "')");
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
  // Overrides for the bake: "extras": {"hemibake": {"reflectance": [r, g, b], "emission": [r, g, b]}}.
  if (mat.extras.IsObject() && mat.extras.Has("hemibake")) {
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
  }
  (void)warnings;
  return {};
}

// KHR_materials_pbrSpecularGlossiness (archived, written by older exporters): a client that
// supports it uses its diffuse in place of the base colour. Its diffuseFactor and diffuseTexture
// are moved into pbrMetallicRoughness, where the loader reads the base colour and the writer shows it.
std::string adopt_specular_glossiness(tinygltf::Model& m) {
  for (size_t i = 0; i < m.materials.size(); ++i) {
    tinygltf::Material& mat = m.materials[i];
    const auto it = mat.extensions.find("KHR_materials_pbrSpecularGlossiness");
    if (it == mat.extensions.end() || !it->second.IsObject()) continue;
    const std::string name = "material " + std::to_string(i) + (mat.name.empty() ? "" : " ('" + mat.name + "')");
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

}  // namespace

const solver::Scene& scene_of(const SceneDocument& document) { return document.scene; }
uint64_t triangle_count(const SceneDocument& document) { return document.triangles; }

std::string bake_error(const SceneDocument& document) {
  // Radiosity is the light of emitting surfaces: without one, every bake is black.
  const auto& patches = document.scene.patches;
  if (std::any_of(patches.begin(), patches.end(), [](const solver::Patch& p) { return p.emission != glm::dvec3(0.0); }))
    return {};
  std::string e = "the scene emits no light: give the light sources' materials an emissiveFactor (with "
                  "KHR_materials_emissive_strength above 1), or set extras.hemibake.emission";
  if (!document.model.lights.empty()) e += "; KHR_lights_punctual lights are not supported";
  return e;
}

LoadResult load_gltf_memory(std::span<const uint8_t> bytes, const std::string& base_dir, const LoadLimits& limits) {
  LoadResult result;
  auto doc = std::make_shared<SceneDocument>();
  if (bytes.size() > limits.max_file_bytes) {
    result.error = "the file is " + std::to_string(bytes.size()) + " bytes, more than the limit of " +
                   std::to_string(limits.max_file_bytes);
    return result;
  }
  if (bytes.size() > 0xffffffffull) {
    result.error = "the file is too large";
    return result;
  }
  LoaderContext ctx;
  ctx.base_dir = base_dir;
  ctx.allow_external = limits.allow_external_files;
  ctx.max_bytes = limits.max_file_bytes;
  ctx.max_image_pixels = limits.max_image_pixels;
  ctx.doc = doc.get();
  ctx.warnings = &result.warnings;

  {
    PrecheckResult pre;
    if (std::string e = precheck_gltf(bytes, limits.allow_external_files, pre); !e.empty()) {
      result.error = e;
      return result;
    }
  }
  tinygltf::TinyGLTF loader;
  tinygltf::FsCallbacks callbacks{&fs_exists, &fs_expand, &fs_read, &fs_write, &ctx};
  loader.SetFsCallbacks(callbacks);
  loader.SetImageLoader(&load_image, &ctx);
  std::string err, warn;
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  bool ok = false;
  try {
    ok = binary ? loader.LoadBinaryFromMemory(&doc->model, &err, &warn, bytes.data(),
                                              static_cast<unsigned int>(bytes.size()), base_dir)
                : loader.LoadASCIIFromString(&doc->model, &err, &warn, reinterpret_cast<const char*>(bytes.data()),
                                             static_cast<unsigned int>(bytes.size()), base_dir);
  } catch (const std::exception& e) {
    ok = false;
    err = e.what();
  }
  if (!ok) {
    while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
    if (err.size() > 300) err = err.substr(0, 300) + "...";
    result.error = "not a valid glTF file: " + (err.empty() ? std::string("unreadable") : err);
    return result;
  }
  tinygltf::Model& m = doc->model;
  for (const std::string& ext : m.extensionsRequired) {
    if (ext != "KHR_draco_mesh_compression" && ext != "KHR_materials_emissive_strength" &&
        ext != "KHR_materials_unlit" && ext != "KHR_texture_transform" && ext != "KHR_mesh_quantization" &&
        ext != "KHR_materials_pbrSpecularGlossiness") {
      result.error = "the file requires extension " + ext + ", which hemibake does not support";
      return result;
    }
  }
  if (std::string e = adopt_specular_glossiness(m); !e.empty()) {
    result.error = e;
    return result;
  }
  if (m.extensionsUsed.end() != std::find(m.extensionsUsed.begin(), m.extensionsUsed.end(), "KHR_lights_punctual") &&
      !m.lights.empty())
    result.warnings.push_back("KHR_lights_punctual lights (" + std::to_string(m.lights.size()) +
                              ") are not supported and are not baked; use emissive materials for light sources");
  if (!m.skins.empty()) result.warnings.push_back("skins are ignored: meshes are baked in their bind pose");
  if (!m.animations.empty()) result.warnings.push_back("animations are ignored: the scene is baked as it stands");

  // The scene graph: valid indices, a tree (one parent each, no cycles), finite transforms.
  if (m.scenes.empty()) {
    result.error = "the file has no scene";
    return result;
  }
  const int scene_index = m.defaultScene >= 0 ? m.defaultScene : 0;
  if (static_cast<size_t>(scene_index) >= m.scenes.size()) {
    result.error = "the default scene " + std::to_string(scene_index) + " does not exist";
    return result;
  }
  std::vector<int> parent(m.nodes.size(), -1);
  for (size_t i = 0; i < m.nodes.size(); ++i) {
    for (int c : m.nodes[i].children) {
      if (c < 0 || static_cast<size_t>(c) >= m.nodes.size()) {
        result.error = "node " + std::to_string(i) + " has child " + std::to_string(c) + ", which does not exist";
        return result;
      }
      if (parent[c] != -1 || static_cast<size_t>(c) == i) {
        result.error = "node " + std::to_string(c) + " has more than one parent (or is its own child): the node hierarchy must be a tree";
        return result;
      }
      parent[c] = static_cast<int>(i);
    }
  }
  doc->node_world.assign(m.nodes.size(), glm::dmat4(1.0));
  std::vector<int> order;  // nodes of the scene, parents first
  {
    std::vector<uint8_t> seen(m.nodes.size(), 0);
    std::vector<int> stack;
    for (int root : m.scenes[scene_index].nodes) {
      if (root < 0 || static_cast<size_t>(root) >= m.nodes.size()) {
        result.error = "scene " + std::to_string(scene_index) + " refers to node " + std::to_string(root) + ", which does not exist";
        return result;
      }
      if (parent[root] != -1) {
        result.error = "node " + std::to_string(root) + " is a scene root and also a child of node " + std::to_string(parent[root]);
        return result;
      }
      stack.push_back(root);
    }
    while (!stack.empty()) {
      const int n = stack.back();
      stack.pop_back();
      if (seen[n]) {
        result.error = "node " + std::to_string(n) + " appears twice in the scene (a cycle or a repeated root)";
        return result;
      }
      seen[n] = 1;
      order.push_back(n);
      for (int c : m.nodes[n].children) stack.push_back(c);
    }
  }
  for (int n : order) {
    const glm::dmat4 local = local_matrix(m.nodes[n]);
    doc->node_world[n] = parent[n] >= 0 ? doc->node_world[parent[n]] * local : local;
    if (!finite(doc->node_world[n])) {
      result.error = "node " + std::to_string(n) + " has a transform that is not finite";
      return result;
    }
  }

  // Triangles of every mesh instance.
  uint64_t degenerate = 0, skipped_prims = 0;
  std::vector<int> see_through;  // baked materials with alphaMode BLEND or MASK, or transmission
  for (int n : order) {
    const tinygltf::Node& node = m.nodes[n];
    if (node.mesh < 0) continue;
    if (static_cast<size_t>(node.mesh) >= m.meshes.size()) {
      result.error = "node " + std::to_string(n) + " refers to mesh " + std::to_string(node.mesh) + ", which does not exist";
      return result;
    }
    const glm::dmat4& world = doc->node_world[n];
    const bool mirrored = glm::determinant(glm::dmat3(world)) < 0.0;
    const tinygltf::Mesh& mesh = m.meshes[node.mesh];
    for (size_t pi = 0; pi < mesh.primitives.size(); ++pi) {
      const tinygltf::Primitive& prim = mesh.primitives[pi];
      const std::string where = "mesh " + std::to_string(node.mesh) + " primitive " + std::to_string(pi);
      const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP && mode != TINYGLTF_MODE_TRIANGLE_FAN) {
        if (mode >= 0 && mode <= 3) {
          ++skipped_prims;
          continue;
        }
        result.error = where + " has an invalid mode " + std::to_string(mode);
        return result;
      }
      const auto pos_it = prim.attributes.find("POSITION");
      if (pos_it == prim.attributes.end()) {
        result.error = where + " has no POSITION attribute";
        return result;
      }
      View pos;
      if (std::string e = view_accessor(m, pos_it->second, "POSITION of " + where, pos); !e.empty()) {
        result.error = e;
        return result;
      }
      if (pos.components != 3 || pos.component_type != TINYGLTF_COMPONENT_TYPE_FLOAT) {
        if (!(pos.components == 3 && component_size(pos.component_type) > 0)) {
          result.error = "accessor " + std::to_string(pos_it->second) + " (POSITION of " + where + ") must be VEC3";
          return result;
        }
      }
      // Indices.
      std::vector<uint32_t> idx;
      if (prim.indices >= 0) {
        View iv;
        if (std::string e = view_accessor(m, prim.indices, "indices of " + where, iv); !e.empty()) {
          result.error = e;
          return result;
        }
        if (iv.components != 1 || (iv.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
                                    iv.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
                                    iv.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)) {
          result.error = "accessor " + std::to_string(prim.indices) + " (indices of " + where +
                         ") must be SCALAR unsigned byte, short or int";
          return result;
        }
        iv.normalized = false;
        idx.resize(iv.count);
        for (size_t i = 0; i < iv.count; ++i) {
          const double v = read_component(iv, i, 0);
          if (v >= static_cast<double>(pos.count)) {
            result.error = "accessor " + std::to_string(prim.indices) + " (indices of " + where + ") has index " +
                           std::to_string(static_cast<uint64_t>(v)) + " at element " + std::to_string(i) +
                           ", but there are only " + std::to_string(pos.count) + " vertices";
            return result;
          }
          idx[i] = static_cast<uint32_t>(v);
        }
      } else {
        idx.resize(pos.count);
        for (size_t i = 0; i < pos.count; ++i) idx[i] = static_cast<uint32_t>(i);
      }
      // The vertices the triangles use, renumbered compactly (an instance of a large mesh costs
      // what its triangles use, not the accessor's length), in world space.
      std::vector<uint32_t> used(idx);
      std::sort(used.begin(), used.end());
      used.erase(std::unique(used.begin(), used.end()), used.end());
      for (uint32_t& i : idx) i = static_cast<uint32_t>(std::lower_bound(used.begin(), used.end(), i) - used.begin());
      // Morph targets at the instance's weights (glTF 2.0, section 3.7.2.2: the node's weights,
      // else the mesh's, else none): position = base + sum of weight x target displacement.
      const std::vector<double>& weights = !node.weights.empty() ? node.weights : mesh.weights;
      std::vector<std::pair<View, double>> morphs;
      for (size_t t = 0; t < prim.targets.size() && t < weights.size(); ++t) {
        const auto it = prim.targets[t].find("POSITION");
        if (weights[t] == 0.0 || it == prim.targets[t].end()) continue;
        const std::string what = "POSITION of morph target " + std::to_string(t) + " of " + where;
        if (!std::isfinite(weights[t])) {
          result.error = "the weight of morph target " + std::to_string(t) + " of " + where + " (node " + std::to_string(n) +
                         ") is not finite";
          return result;
        }
        View d;
        if (std::string e = view_accessor(m, it->second, what, d); !e.empty()) {
          result.error = e;
          return result;
        }
        if (d.components != 3 || d.count != pos.count) {
          result.error = "accessor " + std::to_string(it->second) + " (" + what + ") must be VEC3 with one element per vertex";
          return result;
        }
        morphs.emplace_back(d, weights[t]);
      }
      std::vector<glm::dvec3> points(used.size());
      for (size_t k = 0; k < used.size(); ++k) {
        const size_t i = used[k];
        glm::dvec3 p(read_component(pos, i, 0), read_component(pos, i, 1), read_component(pos, i, 2));
        for (const auto& [d, w] : morphs) p += w * glm::dvec3(read_component(d, i, 0), read_component(d, i, 1), read_component(d, i, 2));
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
          result.error = "accessor " + std::to_string(pos_it->second) + " (POSITION of " + where +
                         ") has a non-finite value at element " + std::to_string(i);
          return result;
        }
        points[k] = glm::dvec3(world * glm::dvec4(p, 1.0));
      }
      // Material and texture coordinates.
      if (prim.material >= 0 && static_cast<size_t>(prim.material) < m.materials.size() &&
          (m.materials[prim.material].alphaMode != "OPAQUE" ||
           m.materials[prim.material].extensions.count("KHR_materials_transmission") > 0) &&
          std::find(see_through.begin(), see_through.end(), prim.material) == see_through.end())
        see_through.push_back(prim.material);
      MaterialInfo mat;
      if (std::string e = material_info(m, prim.material, mat, result.warnings); !e.empty()) {
        result.error = e;
        return result;
      }
      auto read_uv = [&](int set, std::vector<glm::dvec2>& uvs) -> std::string {
        uvs.clear();
        const auto it = prim.attributes.find("TEXCOORD_" + std::to_string(set));
        if (it == prim.attributes.end()) return {};
        View uv;
        if (std::string e = view_accessor(m, it->second, "TEXCOORD_" + std::to_string(set) + " of " + where, uv); !e.empty())
          return e;
        if (uv.components != 2 || uv.count != pos.count)
          return "accessor " + std::to_string(it->second) + " (TEXCOORD_" + std::to_string(set) + " of " + where +
                 ") must be VEC2 with one element per vertex";
        uvs.resize(used.size());
        for (size_t k = 0; k < used.size(); ++k) uvs[k] = glm::dvec2(read_component(uv, used[k], 0), read_component(uv, used[k], 1));
        return {};
      };
      // The output has one UV set, TEXCOORD_0: the base colour texture's (the only texture an
      // unlit material shows).
      std::vector<glm::dvec2> uv0, uv_base, uv_emit;
      for (auto [set, dest] : {std::pair{mat.base_texcoord, &uv0}, std::pair{mat.base_texcoord, &uv_base},
                               std::pair{mat.emissive_texcoord, &uv_emit}}) {
        if (std::string e = read_uv(set, *dest); !e.empty()) {
          result.error = e;
          return result;
        }
      }
      // COLOR_0 multiplies the base colour (glTF 2.0, section 3.9.2), so it tints the reflectance.
      // The output's COLOR_0 replaces it, so the displayed base colour (PatchSource::base) leaves it out.
      std::vector<glm::dvec3> tint;
      if (const auto it = prim.attributes.find("COLOR_0"); it != prim.attributes.end()) {
        const std::string what = "COLOR_0 of " + where;
        View cv;
        if (std::string e = view_accessor(m, it->second, what, cv); !e.empty()) {
          result.error = e;
          return result;
        }
        const bool type_ok = cv.component_type == TINYGLTF_COMPONENT_TYPE_FLOAT ||
                             (cv.normalized && (cv.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                                                cv.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT));
        if ((cv.components != 3 && cv.components != 4) || !type_ok || cv.count != pos.count) {
          result.error = "accessor " + std::to_string(it->second) + " (" + what +
                         ") must be VEC3 or VEC4, float or normalized unsigned byte or short, with one element per vertex";
          return result;
        }
        tint.resize(used.size());
        for (size_t k = 0; k < used.size(); ++k) {
          tint[k] = glm::dvec3(read_component(cv, used[k], 0), read_component(cv, used[k], 1), read_component(cv, used[k], 2));
          if (!std::isfinite(tint[k].x) || !std::isfinite(tint[k].y) || !std::isfinite(tint[k].z)) {
            result.error = "accessor " + std::to_string(it->second) + " (" + what + ") has a non-finite value at element " +
                           std::to_string(used[k]);
            return result;
          }
        }
      }
      // Triangles in glTF order (strips alternate winding; fans turn about the first vertex).
      const size_t nidx = idx.size();
      size_t ntri = 0;
      if (mode == TINYGLTF_MODE_TRIANGLES) ntri = nidx / 3;
      else if (nidx >= 3) ntri = nidx - 2;
      doc->triangles += ntri;
      if (doc->triangles > limits.max_triangles) {
        result.error = "the scene has more than " + std::to_string(limits.max_triangles) + " triangles (the limit)";
        return result;
      }
      // The primitive's triangles, with their colours.
      struct Tri {
        std::array<uint32_t, 3> v;
        glm::dvec3 base, reflect, emission;  // displayed base colour; base colour x vertex colour
        double area;
        bool used;
      };
      std::vector<Tri> tris;
      tris.reserve(ntri);
      for (size_t t = 0; t < ntri; ++t) {
        std::array<uint32_t, 3> v;
        if (mode == TINYGLTF_MODE_TRIANGLES) v = {idx[3 * t], idx[3 * t + 1], idx[3 * t + 2]};
        else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP)
          v = t % 2 == 0 ? std::array{idx[t], idx[t + 1], idx[t + 2]} : std::array{idx[t + 1], idx[t], idx[t + 2]};
        else v = {idx[t + 1], idx[t + 2], idx[0]};
        if (mirrored) std::swap(v[1], v[2]);
        const glm::dvec3 a = points[v[0]], b = points[v[1]], c = points[v[2]];
        const double scale = std::max({glm::length(b - a), glm::length(c - b), glm::length(a - c)});
        const double area = 0.5 * glm::length(glm::cross(b - a, c - a));
        if (!(area > 0.5e-10 * scale * scale)) {
          ++degenerate;
          continue;
        }
        glm::dvec3 base = mat.factor;
        if (!uv_base.empty()) {
          const auto& tf = mat.base_transform;
          if (auto mean = texture_mean(m, mat.base_texture, {tf.apply(uv_base[v[0]]), tf.apply(uv_base[v[1]]), tf.apply(uv_base[v[2]])}))
            base *= *mean;
        }
        glm::dvec3 emission = mat.emissive;
        if (mat.emissive_texture >= 0 && !uv_emit.empty()) {
          const auto& tf = mat.emissive_transform;
          if (auto mean = texture_mean(m, mat.emissive_texture, {tf.apply(uv_emit[v[0]]), tf.apply(uv_emit[v[1]]), tf.apply(uv_emit[v[2]])}))
            emission *= *mean;
        }
        // The mean of the vertex colours, linear over the triangle.
        const glm::dvec3 reflect = tint.empty() ? base : base * (tint[v[0]] + tint[v[1]] + tint[v[2]]) / 3.0;
        tris.push_back({v, base, reflect, emission, area, false});
      }
      // Exporters split quads into triangle pairs. Pairs that form a planar convex quad become one
      // quad patch again: its elements are then quads, and its light is not cut along the diagonal.
      // Vertices are matched by position (bitwise), so unindexed triangle lists pair up too.
      std::vector<uint32_t> canon(points.size());
      {
        std::unordered_map<std::string, uint32_t> first;
        for (const Tri& t : tris)
          for (uint32_t v : t.v) {
            std::string key(reinterpret_cast<const char*>(&points[v]), sizeof(glm::dvec3));
            canon[v] = first.try_emplace(std::move(key), v).first->second;
          }
      }
      std::unordered_map<uint64_t, std::vector<uint32_t>> by_edge;
      auto edge_key = [&](uint32_t a, uint32_t b) {
        a = canon[a];
        b = canon[b];
        return (static_cast<uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
      };
      for (uint32_t t = 0; t < tris.size(); ++t)
        for (int k = 0; k < 3; ++k) by_edge[edge_key(tris[t].v[k], tris[t].v[(k + 1) % 3])].push_back(t);
      auto emit = [&](const std::array<uint32_t, 4>& v, uint32_t count, const glm::dvec3& base, const glm::dvec3& reflect,
                      const glm::dvec3& emission) {
        PatchSource src;
        src.node = static_cast<uint32_t>(n);
        src.mesh = static_cast<uint32_t>(node.mesh);
        src.primitive = static_cast<uint32_t>(pi);
        solver::Patch patch;
        patch.corner_count = count;
        for (uint32_t k = 0; k < count; ++k) {
          patch.corners[k] = points[v[k]];
          if (!uv0.empty()) src.uv[k] = uv0[v[k]];
        }
        src.has_uv = !uv0.empty();
        src.base = glm::clamp(base, 0.0, 1.0);
        patch.reflectance = glm::clamp(mat.reflectance_override.value_or(reflect), 0.0, kMaxReflectance);
        patch.emission = mat.emission_override.value_or(emission);
        patch.material = static_cast<uint32_t>(prim.material + 1);
        doc->scene.patches.push_back(patch);
        doc->sources.push_back(src);
        if (mat.double_sided) {
          // The back side: the same corners in reverse order (a quad keeps its diagonal 1-3).
          std::reverse(patch.corners.begin(), patch.corners.begin() + count);
          std::reverse(src.uv.begin(), src.uv.begin() + count);
          if (count == 4) {
            std::rotate(patch.corners.begin(), patch.corners.begin() + 1, patch.corners.begin() + 4);
            std::rotate(src.uv.begin(), src.uv.begin() + 1, src.uv.begin() + 4);
          }
          src.back = true;
          doc->scene.patches.push_back(patch);
          doc->sources.push_back(src);
        }
      };
      for (uint32_t t = 0; t < tris.size(); ++t) {
        if (tris[t].used) continue;
        tris[t].used = true;
        const auto& tv = tris[t].v;
        const glm::dvec3 tn = glm::normalize(glm::cross(points[tv[1]] - points[tv[0]], points[tv[2]] - points[tv[0]]));
        bool merged = false;
        for (int k = 0; k < 3 && !merged; ++k) {
          // This triangle is (p, q, r) with the shared edge q -> r; the neighbour runs r -> q -> s.
          const uint32_t q = tv[k], r = tv[(k + 1) % 3], p = tv[(k + 2) % 3];
          const auto& sharing = by_edge[edge_key(q, r)];
          if (sharing.size() != 2) continue;  // only an edge between exactly two triangles
          for (uint32_t u : sharing) {
            if (u == t || tris[u].used) continue;
            const auto& uv = tris[u].v;
            int j = -1;
            for (int i = 0; i < 3; ++i)
              if (canon[uv[i]] == canon[r] && canon[uv[(i + 1) % 3]] == canon[q]) j = i;
            if (j < 0) continue;
            const uint32_t s4 = uv[(j + 2) % 3];
            if (canon[s4] == canon[p]) continue;
            // Texture coordinates must agree along the shared edge (no UV seam inside a quad).
            if (!uv0.empty() && (uv0[uv[j]] != uv0[r] || uv0[uv[(j + 1) % 3]] != uv0[q])) continue;
            const std::array<uint32_t, 4> quad{p, q, s4, r};
            // Planar and strictly convex, seen along this triangle's normal.
            const double size = glm::length(points[s4] - points[p]) + glm::length(points[r] - points[q]);
            if (std::abs(glm::dot(tn, points[s4] - points[p])) > 1e-9 * size) continue;
            bool convex = true;
            for (int i = 0; i < 4 && convex; ++i) {
              const glm::dvec3 e0 = points[quad[(i + 1) % 4]] - points[quad[i]];
              const glm::dvec3 e1 = points[quad[(i + 2) % 4]] - points[quad[(i + 1) % 4]];
              convex = glm::dot(glm::cross(e0, e1), tn) > 1e-6 * glm::length(e0) * glm::length(e1);
            }
            if (!convex) continue;
            tris[u].used = true;
            const double wa = tris[t].area, wb = tris[u].area;
            emit(quad, 4, (wa * tris[t].base + wb * tris[u].base) / (wa + wb),
                 (wa * tris[t].reflect + wb * tris[u].reflect) / (wa + wb),
                 (wa * tris[t].emission + wb * tris[u].emission) / (wa + wb));
            merged = true;
            break;
          }
        }
        if (!merged) emit({tv[0], tv[1], tv[2], 0}, 3, tris[t].base, tris[t].reflect, tris[t].emission);
      }
    }
  }
  // The solver has no transmission: a glass pane (BLEND, or Blender's KHR_materials_transmission)
  // or a cut-out leaf (MASK) blocks light like a wall. Say so, rather than leave the user to wonder
  // at the shadow.
  for (int i : see_through) {
    const tinygltf::Material& mt = m.materials[i];
    const std::string what = mt.alphaMode != "OPAQUE" ? "alphaMode " + mt.alphaMode : std::string("KHR_materials_transmission");
    result.warnings.push_back("material " + std::to_string(i) + (mt.name.empty() ? "" : " ('" + mt.name + "')") + " has " +
                              what + "; it is baked as opaque (transparency and cut-outs are not supported)");
  }
  if (skipped_prims > 0)
    result.warnings.push_back(std::to_string(skipped_prims) + " primitive(s) of points or lines were skipped");
  if (degenerate > 0) result.warnings.push_back(std::to_string(degenerate) + " degenerate triangle(s) were skipped");
  if (doc->scene.patches.empty()) {
    result.error = "the scene has no triangles to bake";
    return result;
  }
  if (std::string e = solver::validate(doc->scene); !e.empty()) {
    result.error = "the scene cannot be baked: " + e;
    return result;
  }
  result.document = std::move(doc);
  return result;
}

LoadResult load_gltf_file(const std::string& path, const LoadLimits& limits) {
  LoadResult result;
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) {
    result.error = "cannot read '" + path + "': " + ec.message();
    return result;
  }
  if (size > limits.max_file_bytes) {
    result.error = "'" + path + "' is " + std::to_string(size) + " bytes, more than the limit of " +
                   std::to_string(limits.max_file_bytes);
    return result;
  }
  std::ifstream in(path, std::ios::binary);
  std::vector<uint8_t> bytes(size);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size))) {
    result.error = "cannot read '" + path + "'";
    return result;
  }
  const std::string dir = fs::path(path).parent_path().string();
  return load_gltf_memory(bytes, dir.empty() ? "." : dir, limits);
}

std::string read_baked_mesh(const std::string& path, solver::Mesh& out) {
  out = solver::Mesh();
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) return "cannot read '" + path + "': " + ec.message();
  std::vector<uint8_t> bytes(size);
  std::ifstream in(path, std::ios::binary);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size))) return "cannot read '" + path + "'";
  PrecheckResult pre;
  if (std::string e = precheck_gltf(bytes, true, pre); !e.empty()) return e;
  SceneDocument doc;
  std::vector<std::string> warnings;
  LoaderContext ctx;
  ctx.base_dir = fs::path(path).parent_path().string();
  ctx.allow_external = true;
  ctx.max_bytes = size;
  ctx.max_image_pixels = 1;  // images are not needed here
  ctx.doc = &doc;
  ctx.warnings = &warnings;
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks(tinygltf::FsCallbacks{&fs_exists, &fs_expand, &fs_read, &fs_write, &ctx});
  loader.SetImageLoader(&load_image, &ctx);
  tinygltf::Model& m = doc.model;
  std::string err, warn;
  const bool glb = size >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  const bool ok = glb ? loader.LoadBinaryFromMemory(&m, &err, &warn, bytes.data(), static_cast<unsigned>(size), ctx.base_dir)
                      : loader.LoadASCIIFromString(&m, &err, &warn, reinterpret_cast<const char*>(bytes.data()),
                                                   static_cast<unsigned>(size), ctx.base_dir);
  if (!ok) return "not a valid glTF file: " + err.substr(0, 300);
  if (m.scenes.empty()) return "the file has no scene";
  // Walk the default scene (the pre-check refused cycles) with world matrices.
  std::vector<std::pair<int, glm::dmat4>> stack;
  for (int root : m.scenes[m.defaultScene >= 0 ? m.defaultScene : 0].nodes) stack.emplace_back(root, glm::dmat4(1.0));
  while (!stack.empty()) {
    const auto [n, parent] = stack.back();
    stack.pop_back();
    const tinygltf::Node& node = m.nodes[n];
    const glm::dmat4 world = parent * local_matrix(node);
    for (int c : node.children) stack.emplace_back(c, world);
    if (node.mesh < 0) continue;
    for (size_t pi = 0; pi < m.meshes[node.mesh].primitives.size(); ++pi) {
      const tinygltf::Primitive& prim = m.meshes[node.mesh].primitives[pi];
      if (prim.mode >= 0 && prim.mode != TINYGLTF_MODE_TRIANGLES) continue;
      const std::string where = "mesh " + std::to_string(node.mesh) + " primitive " + std::to_string(pi);
      const auto pos_it = prim.attributes.find("POSITION");
      auto rad_it = prim.attributes.find("_RADIOSITY");
      if (rad_it == prim.attributes.end()) rad_it = prim.attributes.find("COLOR_0");
      if (pos_it == prim.attributes.end() || rad_it == prim.attributes.end())
        return where + " has no POSITION and _RADIOSITY (or COLOR_0): is it a hemibake result?";
      View pos, rad, idx;
      if (std::string e = view_accessor(m, pos_it->second, "POSITION of " + where, pos); !e.empty()) return e;
      if (std::string e = view_accessor(m, rad_it->second, rad_it->first + " of " + where, rad); !e.empty()) return e;
      if (pos.components != 3 || rad.components < 3 || rad.count != pos.count) return where + ": unexpected attribute layout";
      const uint32_t base = static_cast<uint32_t>(out.positions.size());
      for (size_t i = 0; i < pos.count; ++i) {
        const glm::dvec3 p(read_component(pos, i, 0), read_component(pos, i, 1), read_component(pos, i, 2));
        out.positions.push_back(glm::dvec3(world * glm::dvec4(p, 1.0)));
        out.radiosity.emplace_back(read_component(rad, i, 0), read_component(rad, i, 1), read_component(rad, i, 2));
      }
      std::vector<uint32_t> tri;
      if (prim.indices >= 0) {
        if (std::string e = view_accessor(m, prim.indices, "indices of " + where, idx); !e.empty()) return e;
        idx.normalized = false;
        for (size_t i = 0; i < idx.count; ++i) {
          const double v = read_component(idx, i, 0);
          if (v >= static_cast<double>(pos.count)) return "accessor " + std::to_string(prim.indices) + " has an index out of range";
          tri.push_back(static_cast<uint32_t>(v));
        }
      } else {
        for (uint32_t i = 0; i < pos.count; ++i) tri.push_back(i);
      }
      const bool mirrored = glm::determinant(glm::dmat3(world)) < 0.0;
      for (size_t t = 0; t + 2 < tri.size(); t += 3) {
        solver::Mesh::Element el;
        el.patch = static_cast<uint32_t>(pi);
        el.corner_count = 3;
        el.corners = {base + tri[t], base + tri[t + (mirrored ? 2 : 1)], base + tri[t + (mirrored ? 1 : 2)], 0};
        el.radiosity = (out.radiosity[el.corners[0]] + out.radiosity[el.corners[1]] + out.radiosity[el.corners[2]]) / 3.0;
        el.boundary_begin = static_cast<uint32_t>(out.boundary.size());
        out.boundary.insert(out.boundary.end(), el.corners.begin(), el.corners.begin() + 3);
        el.boundary_end = static_cast<uint32_t>(out.boundary.size());
        out.elements.push_back(el);
      }
    }
  }
  if (out.elements.empty()) return "the file has no triangles";
  return {};
}

}  // namespace hemibake::protocol
