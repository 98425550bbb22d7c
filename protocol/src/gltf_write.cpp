// The baked scene as GLB: the input's structure with each mesh instance replaced by its radiosity
// mesh, lit by COLOR_0 under KHR_materials_unlit, optionally compressed with
// KHR_draco_mesh_compression (Khronos extension spec: fallback accessors without bufferView that
// describe the decoded data; attributes mapped to the Draco attributes' unique ids).
#include "document.h"
#include "draco_codec.h"

#include <stb_image_write.h>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <glm/vector_relational.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <cstring>
#include <map>
#include <set>
#include <span>
#include <sstream>
#include <tuple>
#include <unordered_map>

namespace hemibake::protocol {
namespace {

using Value = tinygltf::Value;

// Appends bytes to the single output buffer as a new bufferView (4-byte aligned); returns its index.
int add_view(tinygltf::Model& m, const void* data, size_t size, int target = 0, int stride = 0) {
  auto& buf = m.buffers[0].data;
  while (buf.size() % 4 != 0) buf.push_back(0);
  tinygltf::BufferView v;
  v.buffer = 0;
  v.byteOffset = buf.size();
  v.byteLength = size;
  v.byteStride = static_cast<size_t>(stride);
  v.target = target;
  const auto* p = static_cast<const uint8_t*>(data);
  buf.insert(buf.end(), p, p + size);
  m.bufferViews.push_back(v);
  return static_cast<int>(m.bufferViews.size()) - 1;
}

int add_accessor(tinygltf::Model& m, int view, int component_type, int type, size_t count, bool normalized = false,
                 std::vector<double> min = {}, std::vector<double> max = {}) {
  tinygltf::Accessor a;
  a.bufferView = view;
  a.byteOffset = 0;
  a.componentType = component_type;
  a.type = type;
  a.count = count;
  a.normalized = normalized;
  a.minValues = std::move(min);
  a.maxValues = std::move(max);
  m.accessors.push_back(a);
  return static_cast<int>(m.accessors.size()) - 1;
}

void position_bounds(const std::vector<float>& p, std::vector<double>& lo, std::vector<double>& hi) {
  lo.assign(3, std::numeric_limits<double>::max());
  hi.assign(3, std::numeric_limits<double>::lowest());
  for (size_t i = 0; i + 2 < p.size(); i += 3)
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], static_cast<double>(p[i + c]));
      hi[c] = std::max(hi[c], static_cast<double>(p[i + c]));
    }
}

// A 1 x 1 white PNG for an image whose bytes could not be kept.
std::vector<uint8_t> white_png() {
  std::vector<uint8_t> out;
  const uint8_t pixel[4] = {255, 255, 255, 255};
  stbi_write_png_to_func(
      [](void* ctx, void* data, int size) {
        auto* v = static_cast<std::vector<uint8_t>*>(ctx);
        v->insert(v->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
      },
      &out, 1, 1, 4, pixel, 4);
  return out;
}

double mean3(const glm::dvec3& v) { return (v.x + v.y + v.z) / 3.0; }

// The light a viewer must multiply the base colour by to show radiosity b: b / base per channel.
glm::dvec3 light_of(const glm::dvec3& b, const glm::dvec3& base) {
  glm::dvec3 out;
  for (int c = 0; c < 3; ++c) out[c] = base[c] > 1e-4 ? b[c] / base[c] : 0.0;
  return out;
}

// The matrix that takes world points of a node's triangles into the node's frame: the inverse of
// its world matrix A (with translation t), or, when A flattens space (a zero scale on one axis,
// which glTF allows), an inverse on the plane it flattens onto. There B = A + s n m^T, with m
// spanning A's kernel and n normal to its image, is invertible, and A B^-1 x = x for every x in the
// image, where the node's triangles lie. (A flattened further has no triangles that are not
// degenerate, so nothing of it is written.)
glm::dmat4 world_to_node(const glm::dmat4& world) {
  const glm::dmat3 a(world);
  const double s = std::max({glm::length(a[0]), glm::length(a[1]), glm::length(a[2])});
  if (std::abs(glm::determinant(a)) > 1e-12 * s * s * s) return glm::inverse(world);
  // The longest cross product of two of three vectors: a normal to the plane they span.
  auto normal = [](const glm::dvec3& u, const glm::dvec3& v, const glm::dvec3& w) {
    glm::dvec3 best = glm::cross(u, v);
    for (const glm::dvec3& c : {glm::cross(v, w), glm::cross(w, u)})
      if (glm::length(c) > glm::length(best)) best = c;
    return glm::length(best) > 0.0 ? glm::normalize(best) : glm::dvec3(0.0);
  };
  const glm::dmat3 rows = glm::transpose(a);
  const glm::dvec3 m = normal(rows[0], rows[1], rows[2]);  // orthogonal to every row: A m = 0
  const glm::dvec3 n = normal(a[0], a[1], a[2]);           // orthogonal to every column
  const glm::dmat3 inv = glm::inverse(a + s * glm::outerProduct(n, m));
  glm::dmat4 out(inv);
  out[3] = glm::dvec4(-(inv * glm::dvec3(world[3])), 1.0);
  return out;
}


// Every element refines a patch of this document's scene.
bool mesh_belongs(const SceneDocument& doc, const solver::Mesh& mesh) {
  for (const auto& el : mesh.elements)
    if (el.patch >= doc.sources.size()) return false;
  return true;
}

// The tone curve's white point: the exposed light (mean of the channels) of the brightest vertex on
// a surface that does not emit, the values COLOR_0 is written from (an element's centre is the mean
// of its loop, never brighter). Its largest, not a percentile: a pool of light under a spot lamp,
// and a small box standing in it, can be the brightest few hundredths of a percent of a room, and
// a percentile below them would clip them flat together again.
double white_point(const SceneDocument& doc, const solver::Mesh& mesh, double exposure) {
  double brightest = 0.0;
  for (const auto& el : mesh.elements) {
    if (el.buried || mean3(doc.scene.patches[el.patch].emission) > 0.0) continue;
    const glm::dvec3& base = doc.sources[el.patch].base;
    for (uint32_t k = el.boundary_begin; k < el.boundary_end; ++k)
      brightest = std::max(brightest, mean3(light_of(mesh.radiosity[mesh.boundary[k]], base)));
  }
  return exposure * brightest;
}

// The elements of each output primitive, by (node, primitive, back side), in that order. Buried
// elements (Mesh::Element::buried) are not written: each lies in the plane of a face that is seen,
// and where the two meet at an edge a viewer's depth test showed the buried one's dark in dots (a
// wall box's end against the next wall, along a room's corner in the Blender house, in three.js).
using Groups = std::map<std::tuple<uint32_t, uint32_t, bool>, std::vector<uint32_t>>;

Groups group_elements(const SceneDocument& doc, const solver::Mesh& mesh) {
  Groups groups;
  for (uint32_t i = 0; i < mesh.elements.size(); ++i) {
    if (mesh.elements[i].buried) continue;
    const PatchSource& s = doc.sources[mesh.elements[i].patch];
    groups[{s.node, s.primitive, s.back}].push_back(i);
  }
  return groups;
}

// The inside of a closed double-sided mesh is not written unless a light lies within it. Blender's
// exporter marks every material double-sided by default, so each closed object (a cabinet, a wall
// built as a box, a chair's leg) comes with the faces of its inside, which no one outside can
// see: hidden behind its outside, except along its edges, where an inside face behind and an outside
// face in front meet at one depth and a viewer's depth test lets the dark one through in dots (the
// study's table and room corners in three.js, every few pixels). A primitive's side is its inside
// when the primitive's own triangles close up, every edge met twice and once each way, around a
// volume (its sign says which side looks in). A room built as one closed box keeps both sides when
// a punctual light or another object's emitting surface lies in it; an open mesh (a plate, a wall
// between two rooms) always does.

using Corner = std::array<double, 3>;

Corner corner_key(const glm::dvec3& p) { return {p.x, p.y, p.z}; }

// Of a primitive's front patches, within the box [lo, hi]: 1 when they enclose a volume with their
// fronts facing out, -1 facing in, 0 when they do not close up (an edge met other than once each
// way, or no volume).
int closed_side(std::span<const solver::Patch> fronts, const glm::dvec3& lo, const glm::dvec3& hi) {
  std::map<std::pair<Corner, Corner>, int> edges;  // directed
  for (const solver::Patch& patch : fronts)
    for (uint32_t k = 0; k < patch.corner_count; ++k)
      ++edges[{corner_key(patch.corners[k]), corner_key(patch.corners[(k + 1) % patch.corner_count])}];
  if (edges.empty()) return 0;
  for (const auto& [edge, count] : edges) {
    if (count != 1) return 0;
    const auto back = edges.find({edge.second, edge.first});
    if (back == edges.end() || back->second != 1) return 0;
  }
  const double volume = solver::signed_volume(fronts);
  const double tiny = 1e-9 * std::pow(glm::length(hi - lo), 3.0);
  return volume > tiny ? 1 : volume < -tiny ? -1 : 0;
}

// The output primitives (node, primitive, back side) that are the unlit insides of closed meshes.
std::set<std::tuple<uint32_t, uint32_t, bool>> closed_insides(const SceneDocument& doc, const Groups& groups) {
  std::set<std::tuple<uint32_t, uint32_t, bool>> out;
  std::map<std::pair<uint32_t, uint32_t>, std::vector<solver::Patch>> fronts;
  // Where the scene's emitters are (their centres), with their primitives.
  struct Emitter {
    uint32_t node, primitive;
    glm::dvec3 centre;
  };
  std::vector<Emitter> emitters;
  for (uint32_t p = 0; p < doc.sources.size(); ++p) {
    const PatchSource& src = doc.sources[p];
    const solver::Patch& patch = doc.scene.patches[p];
    if (!src.back) fronts[{src.node, src.primitive}].push_back(patch);
    if (patch.emission == glm::dvec3(0.0)) continue;
    glm::dvec3 centre(0.0);
    for (uint32_t k = 0; k < patch.corner_count; ++k) centre += patch.corners[k] / static_cast<double>(patch.corner_count);
    emitters.push_back({src.node, src.primitive, centre});
  }
  for (const auto& key : groups) {
    const auto [node, prim, back] = key.first;
    if (!back || !groups.count({node, prim, false})) continue;
    const std::vector<solver::Patch>& surface = fronts[{node, prim}];
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
    for (const solver::Patch& patch : surface)
      for (uint32_t k = 0; k < patch.corner_count; ++k) {
        lo = glm::min(lo, patch.corners[k]);
        hi = glm::max(hi, patch.corners[k]);
      }
    const int side = closed_side(surface, lo, hi);
    if (side == 0) continue;
    auto encloses = [&](const glm::dvec3& x) {
      return glm::all(glm::greaterThanEqual(x, lo)) && glm::all(glm::lessThanEqual(x, hi)) && solver::encloses(surface, x);
    };
    bool lit = false;
    for (const solver::Light& l : doc.scene.lights)
      lit = lit || (l.type != solver::Light::Type::kDirectional && encloses(l.position));
    for (const Emitter& e : emitters)
      lit = lit || ((e.node != node || e.primitive != prim) && encloses(e.centre));
    if (!lit) out.insert({node, prim, side > 0});
  }
  return out;
}

// The surfaces the automatic exposure is chosen from (protocol::key_exposure): those written
// (not the hidden insides of closed meshes, which would count dark area no one sees) that do not
// emit (emitters are far brighter than what they light), each element's light and area.
std::vector<LitArea> exposed_surfaces(const SceneDocument& doc, const solver::Mesh& mesh,
                                      const std::set<std::tuple<uint32_t, uint32_t, bool>>& hidden) {
  std::vector<LitArea> out;
  out.reserve(mesh.elements.size());
  for (const auto& el : mesh.elements) {
    if (el.buried || mean3(doc.scene.patches[el.patch].emission) > 0.0) continue;
    const PatchSource& src = doc.sources[el.patch];
    if (hidden.count({src.node, src.primitive, src.back})) continue;
    out.push_back({mean3(light_of(el.radiosity, src.base)), el.area});
  }
  return out;
}

// Unlit shading shows the base colour alone: emission (its light is in COLOR_0 now), normal,
// occlusion and metal-roughness textures and the PBR extensions (specular, IOR, ...) go. The
// base colour texture reads TEXCOORD_0, the only UV set written (its set in the input). Both sides
// of a double-sided material are baked as separate primitives, so none is double-sided.
void make_unlit(tinygltf::Material& mat) {
  mat.extensions.clear();
  mat.extensions["KHR_materials_unlit"] = Value(Value::Object());
  mat.emissiveFactor = {0.0, 0.0, 0.0};
  mat.emissiveTexture = tinygltf::TextureInfo();
  mat.normalTexture = tinygltf::NormalTextureInfo();
  mat.occlusionTexture = tinygltf::OcclusionTextureInfo();
  mat.pbrMetallicRoughness.metallicRoughnessTexture = tinygltf::TextureInfo();
  mat.doubleSided = false;
  tinygltf::TextureInfo& base = mat.pbrMetallicRoughness.baseColorTexture;
  base.texCoord = 0;
  tinygltf::ExtensionMap kept;
  if (auto it = base.extensions.find("KHR_texture_transform"); it != base.extensions.end() && it->second.IsObject()) {
    Value::Object t = it->second.Get<Value::Object>();
    t.erase("texCoord");
    kept["KHR_texture_transform"] = Value(t);
  }
  base.extensions = std::move(kept);
}

// An emitting material (emissiveFactor, or extras.hemibake.emission) gets its emission's hue and
// texture as its base colour; the loader's PatchSource::base is the same colour, so that COLOR_0 =
// exposure x radiosity / base gives base x COLOR_0 = exposure x radiosity.
void show_emission(tinygltf::Material& mat) {
  glm::dvec3 hue(0.0);
  if (mat.emissiveFactor.size() == 3) hue = glm::dvec3(mat.emissiveFactor[0], mat.emissiveFactor[1], mat.emissiveFactor[2]);
  bool textured = hue != glm::dvec3(0.0) && mat.emissiveTexture.index >= 0;
  const Value& extras = mat.extras;
  if (extras.IsObject() && extras.Has("hemibake") && extras.Get("hemibake").Has("emission")) {
    const Value& e = extras.Get("hemibake").Get("emission");
    if (e.IsArray() && e.ArrayLen() == 3) {
      hue = glm::dvec3(e.Get(0).GetNumberAsDouble(), e.Get(1).GetNumberAsDouble(), e.Get(2).GetNumberAsDouble());
      textured = false;  // the override replaces the texture's emission
    }
  }
  const double top = std::max({hue.x, hue.y, hue.z});
  if (!(top > 0.0)) return;
  tinygltf::PbrMetallicRoughness& pbr = mat.pbrMetallicRoughness;
  // Only TEXCOORD_0, the base colour texture's set, is written: an emissive texture on another set
  // is left out (COLOR_0 still carries its mean over each element).
  const int base_set = pbr.baseColorTexture.index >= 0 ? pbr.baseColorTexture.texCoord : 0;
  pbr.baseColorFactor = {hue.x / top, hue.y / top, hue.z / top, 1.0};
  pbr.baseColorTexture = tinygltf::TextureInfo();
  if (textured && mat.emissiveTexture.texCoord == base_set) {
    pbr.baseColorTexture.index = mat.emissiveTexture.index;
    pbr.baseColorTexture.texCoord = mat.emissiveTexture.texCoord;
    pbr.baseColorTexture.extensions = mat.emissiveTexture.extensions;
  }
}

// Images keep their encoded bytes, now inside the GLB; one whose bytes were not kept becomes white.
void embed_images(const SceneDocument& doc, tinygltf::Model& out) {
  out.images = doc.model.images;
  for (size_t i = 0; i < out.images.size(); ++i) {
    tinygltf::Image& img = out.images[i];
    std::vector<uint8_t> bytes = i < doc.image_bytes.size() ? doc.image_bytes[i] : std::vector<uint8_t>{};
    std::string mime = i < doc.image_mime.size() ? doc.image_mime[i] : std::string();
    if (bytes.empty() || (mime != "image/png" && mime != "image/jpeg")) {
      bytes = white_png();
      mime = "image/png";
    }
    img.image.clear();
    img.uri.clear();
    img.width = img.height = img.component = img.bits = -1;
    img.bufferView = add_view(out, bytes.data(), bytes.size());
    img.mimeType = mime;
  }
}

// The input's scenes, nodes (without their meshes), cameras, textures and materials (unlit), and
// its images in the single buffer.
tinygltf::Model copy_structure(const SceneDocument& doc) {
  const tinygltf::Model& in = doc.model;
  tinygltf::Model out;
  out.asset.version = "2.0";
  out.asset.generator = "hemibake";
  out.buffers.resize(1);
  out.scenes = in.scenes;
  out.defaultScene = in.defaultScene;
  out.cameras = in.cameras;
  out.samplers = in.samplers;
  out.textures = in.textures;
  out.nodes = in.nodes;
  // Extensions of copied objects go (lights, instancing, ...): the output declares only its own, and
  // every extension an object carries must be declared (glTF 2.0, section 3.12).
  for (auto& n : out.nodes) {
    n.mesh = -1;
    n.skin = -1;
    n.weights.clear();
    n.extensions.clear();
  }
  for (auto& x : out.scenes) x.extensions.clear();
  for (auto& x : out.cameras) x.extensions.clear();
  for (auto& x : out.samplers) x.extensions.clear();
  for (auto& x : out.textures) x.extensions.clear();
  // Shown unlit, so that base colour x COLOR_0 is exactly the baked light. An emitting material
  // shows its emission instead of its base colour (a dark stone with glowing veins would look
  // like dark stone): the emissive factor's hue and texture become the base colour, and COLOR_0
  // (scaled by the same exposure as every surface) its brightness.
  out.materials = in.materials;
  for (auto& mat : out.materials) {
    show_emission(mat);
    make_unlit(mat);
  }
  embed_images(doc, out);
  return out;
}

// Texture coordinates at a world point of a patch: linear over each source triangle, a triangle
// patch's own, or for a quad the half (0, 1, 3) or (1, 2, 3) that holds the point.
glm::dvec2 patch_uv(const solver::Patch& patch, const PatchSource& src, const glm::dvec3& world) {
  const auto& c = patch.corners;
  auto interpolate = [&](int i0, int i1, int i2, glm::dvec2& out_uv) {
    const glm::dvec3 e0 = c[i1] - c[i0], e1 = c[i2] - c[i0], d = world - c[i0];
    const double d00 = glm::dot(e0, e0), d01 = glm::dot(e0, e1), d11 = glm::dot(e1, e1);
    const double d20 = glm::dot(d, e0), d21 = glm::dot(d, e1);
    const double den = d00 * d11 - d01 * d01;
    const double v = den != 0.0 ? (d11 * d20 - d01 * d21) / den : 0.0;
    const double w = den != 0.0 ? (d00 * d21 - d01 * d20) / den : 0.0;
    out_uv = (1.0 - v - w) * src.uv[i0] + v * src.uv[i1] + w * src.uv[i2];
    return std::min({1.0 - v - w, v, w});  // inside the triangle when not negative
  };
  glm::dvec2 uv(0.0);
  if (patch.corner_count == 3) {
    interpolate(0, 1, 2, uv);
  } else {
    glm::dvec2 other;
    if (interpolate(0, 1, 3, uv) < interpolate(1, 2, 3, other)) uv = other;
  }
  return uv;
}

// The vertices of one output primitive: one per (solver vertex, texture coordinate), so UV seams
// stay seams, in the node's frame, with COLOR_0 and _RADIOSITY.
struct VertexWriter {
  const SceneDocument& doc;
  glm::dmat4 to_local;
  double exposure = 1.0;
  ToneCurve tone;
  bool has_uv = false;
  PrimitiveData data;
  std::unordered_map<uint64_t, std::vector<std::pair<glm::dvec2, uint32_t>>> vertex_of;  // by key

  // The vertex at world point `world` with radiosity `b` on patch `patch`; `key` is the solver
  // vertex (points with one key are one vertex unless their texture coordinates differ).
  uint32_t add(const glm::dvec3& world, const glm::dvec3& b, uint32_t patch, uint64_t key) {
    const PatchSource& src = doc.sources[patch];
    const glm::dvec2 uv = has_uv ? patch_uv(doc.scene.patches[patch], src, world) : glm::dvec2(0.0);
    auto& list = vertex_of[key];
    for (const auto& [u, idx] : list)
      if (glm::length(u - uv) <= 1e-7) return idx;
    const uint32_t idx = static_cast<uint32_t>(data.vertex_count());
    list.emplace_back(uv, idx);
    const glm::dvec3 local(to_local * glm::dvec4(world, 1.0));
    for (int k = 0; k < 3; ++k) data.positions.push_back(static_cast<float>(local[k]));
    if (has_uv) {
      data.texcoords.push_back(static_cast<float>(uv.x));
      data.texcoords.push_back(static_cast<float>(uv.y));
    }
    const glm::dvec3 light = tone.map(exposure * light_of(b, src.base));
    for (int k = 0; k < 3; ++k) {
      data.colors.push_back(static_cast<uint16_t>(std::lround(light[k] * 65535.0)));
      data.radiosity.push_back(static_cast<float>(b[k]));
    }
    return idx;
  }
};

// The triangles of one output primitive: an element without hanging vertices is one triangle;
// one with them on its edges is a fan from its centre, which keeps the mesh crack-free without
// thin triangles along the edges. The centre is the mean of the loop's vertices that are not
// interpolated (Mesh::interpolated): the points of other surfaces taken into the loop add no light
// of their own, and with them a coarse floor element beside a finely cut wall showed at its centre
// little but the light of its edge along the wall.
PrimitiveData primitive_triangles(const SceneDocument& doc, const solver::Mesh& mesh, const std::vector<uint32_t>& elements,
                                  uint32_t node, double exposure, const ToneCurve& tone) {
  VertexWriter writer{doc, world_to_node(doc.node_world[node]), exposure, tone,
                      doc.sources[mesh.elements[elements[0]].patch].has_uv, {}, {}};
  PrimitiveData& data = writer.data;
  uint64_t extra_key = 1ull << 63;  // element centres are never shared
  for (uint32_t ei : elements) {
    const auto& el = mesh.elements[ei];
    const uint32_t nb = el.boundary_end - el.boundary_begin;
    std::vector<uint32_t> loop(nb);
    for (uint32_t k = 0; k < nb; ++k) {
      const uint32_t v = mesh.boundary[el.boundary_begin + k];
      loop[k] = writer.add(mesh.positions[v], mesh.radiosity[v], el.patch, v);
    }
    if (nb == 3) {
      data.indices.insert(data.indices.end(), {loop[0], loop[1], loop[2]});
      continue;
    }
    glm::dvec3 centre(0.0), b(0.0);
    uint32_t own = 0;
    for (uint32_t k = 0; k < nb; ++k) {
      const uint32_t v = mesh.boundary[el.boundary_begin + k];
      if (v < mesh.interpolated.size() && mesh.interpolated[v]) continue;
      centre += mesh.positions[v];
      b += mesh.radiosity[v];
      ++own;
    }
    const uint32_t c = writer.add(centre / static_cast<double>(own), b / static_cast<double>(own), el.patch, extra_key++);
    for (uint32_t k = 0; k < nb; ++k) data.indices.insert(data.indices.end(), {c, loop[k], loop[(k + 1) % nb]});
  }
  // Elements run counter-clockwise in world space; under a mirroring node transform glTF reverses
  // the winding rule, so the triangles are written the other way round.
  if (glm::determinant(glm::dmat3(doc.node_world[node])) < 0.0)
    for (size_t t = 0; t + 2 < data.indices.size(); t += 3) std::swap(data.indices[t + 1], data.indices[t + 2]);
  return std::move(writer.data);
}

// `material`, or an unlit default material made on first use (a primitive without one shows the
// glTF default material, white).
int output_material(int material, tinygltf::Model& out, int& default_material) {
  if (material >= 0) return material;
  if (default_material < 0) {
    tinygltf::Material mat;
    mat.name = "hemibake default";
    mat.extensions["KHR_materials_unlit"] = Value(Value::Object());
    out.materials.push_back(mat);
    default_material = static_cast<int>(out.materials.size()) - 1;
  }
  return default_material;
}

// One output primitive before encoding: its elements (indices into the mesh), its node and data.
struct OutputPrimitive {
  std::tuple<uint32_t, uint32_t, bool> key;  // (node, primitive, back side)
  const std::vector<uint32_t>* elements;
  PrimitiveData data;
};

// Draco's grid for a primitive's positions (DracoSettings::position_origin, position_range).
struct PositionGrid {
  std::array<float, 3> origin{};
  float range = 0.0f;  // 0: Draco's own, fitted to the primitive
};

// Draco quantizes each primitive's positions on a grid fitted to its own bounding cube, so a point
// that two primitives share (the floor and a wall at its foot, the two slopes of a roof at the
// ridge, a gable under them) decoded to two points up to half a step apart, and rasterizers left
// dotted gaps along such seams (the wedge's ridge and gables in three.js). Primitives that share a
// point and whose nodes' frames differ at most by a translation are quantized in one cube instead,
// the bounding cube of them all, placed in world space: a shared point then quantizes and decodes
// by the same arithmetic in each, to the same value (where the nodes' translations differ, to
// within a micrometre: Draco passes the cube's origin and size through std::to_string, six
// decimals, so both are given with six decimals). A primitive that shares no point with another (a
// vase on a table) keeps its own cube and precision; so do primitives of nodes rotated or scaled
// otherwise, which cannot share a grid.
std::vector<PositionGrid> shared_position_grids(const SceneDocument& doc, const solver::Mesh& mesh,
                                                const std::vector<OutputPrimitive>& prims, int bits) {
  std::vector<PositionGrid> grids(prims.size());
  if (bits <= 0) return grids;
  const size_t n = prims.size();
  // Primitives sharing a point (equal world positions) and a linear frame: one set.
  std::vector<uint32_t> parent(n);
  for (uint32_t i = 0; i < n; ++i) parent[i] = i;
  auto find = [&](uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  auto world = [&](size_t i) -> const glm::dmat4& { return doc.node_world[std::get<0>(prims[i].key)]; };
  std::map<Corner, uint32_t> first_at;
  for (uint32_t i = 0; i < n; ++i)
    for (uint32_t e : *prims[i].elements) {
      const auto& el = mesh.elements[e];
      for (uint32_t k = el.boundary_begin; k < el.boundary_end; ++k) {
        const auto [it, fresh] = first_at.try_emplace(corner_key(mesh.positions[mesh.boundary[k]]), i);
        const uint32_t a = find(it->second), b = find(i);
        if (fresh || a == b || glm::dmat3(world(it->second)) != glm::dmat3(world(i))) continue;
        parent[std::max(a, b)] = std::min(a, b);
      }
    }
  // Each primitive's box in its node's frame moved by `offset` (the node's translation in its
  // frame's axes), where the points of all nodes of one linear frame have the same coordinates.
  std::vector<glm::dvec3> offset(n, glm::dvec3(0.0)), lo(n, glm::dvec3(std::numeric_limits<double>::max())),
      hi(n, glm::dvec3(std::numeric_limits<double>::lowest()));
  std::vector<uint32_t> members(n, 0);
  for (uint32_t i = 0; i < n; ++i) {
    const glm::dmat3 linear(world(i));
    if (std::abs(glm::determinant(linear)) > 0.0) offset[i] = glm::inverse(linear) * glm::dvec3(world(i)[3]);
    const std::vector<float>& p = prims[i].data.positions;
    for (size_t k = 0; k + 2 < p.size(); k += 3) {
      const glm::dvec3 x = glm::dvec3(p[k], p[k + 1], p[k + 2]) + offset[i];
      lo[i] = glm::min(lo[i], x);
      hi[i] = glm::max(hi[i], x);
    }
    const uint32_t r = find(i);
    ++members[r];
    if (r != i) {
      lo[r] = glm::min(lo[r], lo[i]);
      hi[r] = glm::max(hi[r], hi[i]);
    }
  }
  // The cube starts 2e-6 below the set's box, and each member's origin is that corner in its own
  // frame rounded to six decimals (within 5e-7, so still below its positions): where the members'
  // translations differ, their grids then lie within 5e-7 of each other.
  auto nearest = [](double x) { return std::round(x * 1e6) / 1e6; };
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t r = find(i);
    if (members[r] < 2 || prims[i].data.positions.empty()) continue;
    const glm::dvec3 extent = hi[r] - lo[r];
    grids[i].range = static_cast<float>(std::ceil((std::max({extent.x, extent.y, extent.z}) + 5e-6) * 1e6) / 1e6);
    for (int c = 0; c < 3; ++c) grids[i].origin[c] = static_cast<float>(nearest(lo[r][c] - 2e-6 - offset[i][c]));
  }
  return grids;
}

// KHR_draco_mesh_compression: one bufferView of Draco data, and fallback accessors without a
// bufferView that describe the decoded data (Draco may reorder vertices).
std::string add_draco_attributes(const PrimitiveData& data, const WriteOptions& options, const PositionGrid& grid,
                                 tinygltf::Model& out, tinygltf::Primitive& prim) {
  DracoSettings ds;
  ds.position_origin = grid.origin;
  ds.position_range = grid.range;
  ds.position_bits = options.position_bits;
  ds.texcoord_bits = options.texcoord_bits;
  ds.encode_speed = options.encode_speed;
  ds.decode_speed = options.decode_speed;
  DracoEncoded enc;
  if (std::string e = draco_encode(data, ds, enc); !e.empty()) return e;
  const PrimitiveData& d = enc.decoded;
  const int view = add_view(out, enc.bytes.data(), enc.bytes.size());
  std::vector<double> lo, hi;
  position_bounds(d.positions, lo, hi);
  const size_t n = d.vertex_count();
  prim.attributes["POSITION"] = add_accessor(out, -1, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, n, false, lo, hi);
  Value::Object attrs;
  attrs["POSITION"] = Value(enc.position_id);
  if (enc.texcoord_id >= 0) {
    prim.attributes["TEXCOORD_0"] = add_accessor(out, -1, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2, n);
    attrs["TEXCOORD_0"] = Value(enc.texcoord_id);
  }
  prim.attributes["COLOR_0"] = add_accessor(out, -1, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_VEC3, n, true);
  attrs["COLOR_0"] = Value(enc.color_id);
  prim.attributes["_RADIOSITY"] = add_accessor(out, -1, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, n);
  attrs["_RADIOSITY"] = Value(enc.radiosity_id);
  prim.indices = add_accessor(out, -1, n <= 65535 ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT : TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                              TINYGLTF_TYPE_SCALAR, d.indices.size());
  Value::Object ext;
  ext["bufferView"] = Value(view);
  ext["attributes"] = Value(attrs);
  prim.extensions["KHR_draco_mesh_compression"] = Value(ext);
  return {};
}

// Plain accessors, each on a bufferView of its own.
void add_plain_attributes(const PrimitiveData& data, tinygltf::Model& out, tinygltf::Primitive& prim) {
  const size_t n = data.vertex_count();
  std::vector<double> lo, hi;
  position_bounds(data.positions, lo, hi);
  prim.attributes["POSITION"] = add_accessor(
      out, add_view(out, data.positions.data(), data.positions.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER),
      TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, n, false, lo, hi);
  if (!data.texcoords.empty())
    prim.attributes["TEXCOORD_0"] = add_accessor(
        out, add_view(out, data.texcoords.data(), data.texcoords.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER),
        TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2, n);
  // Vertex attribute elements must start on 4-byte boundaries: three shorts take a stride of 8.
  std::vector<uint16_t> colors(n * 4, 0);
  for (size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) colors[i * 4 + k] = data.colors[i * 3 + k];
  prim.attributes["COLOR_0"] = add_accessor(
      out, add_view(out, colors.data(), colors.size() * 2, TINYGLTF_TARGET_ARRAY_BUFFER, 8),
      TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_VEC3, n, true);
  prim.attributes["_RADIOSITY"] = add_accessor(
      out, add_view(out, data.radiosity.data(), data.radiosity.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER),
      TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, n);
  if (n <= 65535) {
    std::vector<uint16_t> idx(data.indices.begin(), data.indices.end());
    prim.indices = add_accessor(out, add_view(out, idx.data(), idx.size() * 2, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                                TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_SCALAR, idx.size());
  } else {
    prim.indices = add_accessor(
        out, add_view(out, data.indices.data(), data.indices.size() * 4, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
        TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, data.indices.size());
  }
}

// Extensions: what the copied materials and textures use, and ours.
void declare_extensions(const tinygltf::Model& in, bool used_draco, tinygltf::Model& out) {
  for (const std::string& e : in.extensionsUsed)
    if (e == "KHR_texture_transform") out.extensionsUsed.push_back(e);
  out.extensionsUsed.push_back("KHR_materials_unlit");
  if (used_draco) {
    out.extensionsUsed.push_back("KHR_draco_mesh_compression");
    out.extensionsRequired.push_back("KHR_draco_mesh_compression");
  }
  for (const std::string& e : in.extensionsRequired)
    if (e == "KHR_texture_transform") out.extensionsRequired.push_back(e);
}

// How it was made: asset.extras.hemibake.
Value bake_record(Method method, const solver::Params& params, const solver::Stats& stats, double exposure,
                  const ToneCurve& tone) {
  Value::Object p;
  p["method"] = Value(std::string(to_string(method)));
  p["resolution"] = Value(static_cast<int>(params.resolution));
  p["feps"] = Value(params.feps);
  p["aeps"] = Value(params.aeps);
  p["beps"] = Value(params.beps);
  p["convergence"] = Value(params.convergence);
  Value::Object s;
  s["shots"] = Value(static_cast<double>(stats.shots));
  s["elements"] = Value(static_cast<double>(stats.elements));
  s["patches"] = Value(static_cast<double>(stats.patches));
  s["shooters"] = Value(static_cast<double>(stats.shooters));
  s["seconds"] = Value(stats.seconds);
  s["unshot_fraction"] = Value(stats.unshot_fraction);
  s["converged"] = Value(stats.converged);
  Value::Object h;
  h["exposure"] = Value(exposure);
  // The curve, with the numbers that invert it (README, "GLB out").
  Value::Object t;
  t["curve"] = Value(std::string(to_string(tone.tone)));
  if (tone.tone == Tone::kShoulder) {
    t["knee"] = Value(tone.knee);
    t["white"] = Value(tone.white);
    t["scale"] = Value(tone.scale);
  }
  h["tone"] = Value(t);
  h["colors"] = Value(std::string(
      tone.tone == Tone::kClamp
          ? "COLOR_0 = L clamped to [0, 1], L = exposure * radiosity / base colour; _RADIOSITY = radiosity"
          : "COLOR_0 = L * f(m) / m, each channel clamped to [0, 1], L = exposure * radiosity / base colour, "
            "m = (L.r + L.g + L.b) / 3; f(m) = m for m <= tone.knee, tone.knee + tone.scale * ln(1 + (m - tone.knee) / "
            "tone.scale) up to tone.white, 1 above (tone.scale 0: f(m) = min(m, 1)). Where no channel is 1: "
            "y = (COLOR_0.r + COLOR_0.g + COLOR_0.b) / 3, m = y for y <= tone.knee, else tone.knee + tone.scale * "
            "(exp((y - tone.knee) / tone.scale) - 1), and L = COLOR_0 * m / y; _RADIOSITY = radiosity"));
  // The units, for whoever turns _RADIOSITY into an engine's lightmap (README, "Units").
  h["radiosity"] = Value(std::string(
      "_RADIOSITY is exitance B: rho * E for a surface of irradiance E, pi * L for an emitter of "
      "radiance L (emissiveFactor x emissive texture x emissive strength); "
      "point and spot intensities are candela, directional lux, the sky a radiance, with no 683 lm/W factor. "
      "three.js lightMap: E = B / rho; bevy and Godot lightmaps: E / pi"));
  h["parameters"] = Value(p);
  h["statistics"] = Value(s);
  Value::Object extras;
  extras["hemibake"] = Value(h);
  return Value(extras);
}

}  // namespace

WriteResult write_baked_glb(const SceneDocument& doc, const solver::Mesh& mesh, Method method, const solver::Params& params,
                            const solver::Stats& stats, const WriteOptions& options) {
  WriteResult result;
  if (!mesh_belongs(doc, mesh)) {
    result.error = "the mesh does not belong to this scene";
    return result;
  }
  const Groups groups = group_elements(doc, mesh);
  const auto hidden = closed_insides(doc, groups);
  result.exposure = options.exposure > 0.0 ? options.exposure : key_exposure(exposed_surfaces(doc, mesh, hidden));
  result.tone = tone_curve(options.tone, white_point(doc, mesh, result.exposure));
  tinygltf::Model out = copy_structure(doc);
  int default_material = -1;
  bool used_draco = false;
  std::map<uint32_t, int> node_mesh;  // node -> new mesh
  std::vector<OutputPrimitive> prims;
  for (const auto& [key, elements] : groups) {
    if (hidden.count(key)) continue;
    prims.push_back({key, &elements, primitive_triangles(doc, mesh, elements, std::get<0>(key), result.exposure, result.tone)});
  }
  const std::vector<PositionGrid> grids =
      options.draco ? shared_position_grids(doc, mesh, prims, options.position_bits) : std::vector<PositionGrid>(prims.size());
  for (size_t i = 0; i < prims.size(); ++i) {
    const auto [node_index, prim_index, back] = prims[i].key;
    const tinygltf::Node& node = doc.model.nodes[node_index];
    const PrimitiveData& data = prims[i].data;
    tinygltf::Primitive prim;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    prim.material = output_material(doc.model.meshes[node.mesh].primitives[prim_index].material, out, default_material);
    if (options.draco) {
      if (std::string e = add_draco_attributes(data, options, grids[i], out, prim); !e.empty()) {
        result.error = e;
        return result;
      }
      used_draco = true;
    } else {
      add_plain_attributes(data, out, prim);
    }
    auto [it, fresh] = node_mesh.try_emplace(node_index, static_cast<int>(out.meshes.size()));
    if (fresh) {
      tinygltf::Mesh m;
      m.name = doc.model.meshes[node.mesh].name;
      out.meshes.push_back(m);
      out.nodes[node_index].mesh = it->second;
    }
    out.meshes[it->second].primitives.push_back(prim);
  }
  out.buffers[0].data.resize((out.buffers[0].data.size() + 3) & ~size_t{3}, 0);
  declare_extensions(doc.model, used_draco, out);
  out.asset.extras = bake_record(method, params, stats, result.exposure, result.tone);

  std::ostringstream stream;
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&out, stream, false, true)) {
    result.error = "writing the GLB failed";
    return result;
  }
  const std::string bytes = stream.str();
  result.glb.assign(bytes.begin(), bytes.end());
  return result;
}

}  // namespace hemibake::protocol
