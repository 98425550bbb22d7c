// glTF 2.0 to patches. The file is untrusted: tinygltf parses the JSON and the GLB container, and
// everything it does not check (accessor ranges, strides, index values, node cycles, image sizes,
// external paths) is checked here before use, with an error that names the object at fault.
//
// Loading runs in stages, each a function over the previous one's output:
//   parse_document   pre-check, tinygltf, supported extensions        -> the model
//   place_nodes      the default scene's node tree                    -> world matrices, node order
//   per primitive of each node instance (add_primitive):
//     read_vertices, read_colours   checked accessor reads            -> flat per-vertex arrays
//     shade_triangles               material and texture means        -> triangles with colours
//     merge_triangle_pairs          planar convex pairs become quads  -> outlines (quads.cpp)
//     add_patches                   outlines with colours, both sides -> solver patches
// The first fault found ends the load; the stages run in the order the checks always had, so a
// file with several faults is refused for the same one.
#include "accessor.h"
#include "document.h"
#include "gltf_parse.h"
#include "materials.h"
#include "precheck.h"
#include "quads.h"

#include "hemibake/solver/solver.h"

#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <numbers>

namespace hemibake::protocol {
namespace {

namespace fs = std::filesystem;

// Reflectance is capped below 1 (a glTF base colour of 1 would reflect everything it receives).
constexpr double kMaxReflectance = 0.95;

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

bool finite(const glm::dvec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// glTF makes a transform with a negative determinant reverse the winding rule: such a node's
// triangles are clockwise on their front side.
bool mirrors(const glm::dmat4& world) { return glm::determinant(glm::dmat3(world)) < 0.0; }

// ---- Parse and checks ----

// Extensions that change nothing the bake reads, or that the loader applies.
bool supported_extension(const std::string& ext) {
  return ext == "KHR_draco_mesh_compression" || ext == "KHR_materials_emissive_strength" || ext == "KHR_lights_punctual" ||
         ext == "KHR_materials_unlit" || ext == "KHR_texture_transform" || ext == "KHR_mesh_quantization" ||
         ext == "KHR_materials_pbrSpecularGlossiness";
}

// What the file has that the bake leaves out, said rather than left for the user to find.
void ignored_feature_warnings(const tinygltf::Model& m, std::vector<std::string>& warnings) {
  // Environment lighting has no ratified glTF form; the vendor and draft extensions are not read.
  for (const char* env : {"EXT_lights_image_based", "KHR_environment_map"})
    if (std::find(m.extensionsUsed.begin(), m.extensionsUsed.end(), env) != m.extensionsUsed.end())
      warnings.push_back(std::string(env) + " (environment lighting) is not read; set a uniform sky with the job parameter sky (--sky R,G,B)");
  if (!m.skins.empty()) warnings.push_back("skins are ignored: meshes are baked in their bind pose");
  if (!m.animations.empty()) warnings.push_back("animations are ignored: the scene is baked as it stands");
}

// Reads the file into doc.model: size limits, the pre-check (tinygltf trusts what it reads), the
// parse, then what the bake cannot honour.
std::string parse_document(std::span<const uint8_t> bytes, const std::string& base_dir, const LoadLimits& limits,
                           SceneDocument& doc, std::vector<std::string>& warnings) {
  if (bytes.size() > limits.max_file_bytes)
    return "the file is " + std::to_string(bytes.size()) + " bytes, more than the limit of " +
           std::to_string(limits.max_file_bytes);
  if (bytes.size() > 0xffffffffull) return "the file is too large";  // tinygltf takes an unsigned int
  PrecheckResult pre;
  if (std::string e = precheck_gltf(bytes, limits.allow_external_files, pre); !e.empty()) return e;
  const ParseOptions options{base_dir, limits.allow_external_files, limits.max_file_bytes, limits.max_image_pixels,
                             limits.max_total_image_pixels};
  std::string err;
  bool ok = false;
  try {
    ok = parse_gltf(bytes, options, doc, warnings, err);
  } catch (const std::exception& e) {
    ok = false;
    err = e.what();
  }
  if (!ok && err.rfind(kTooManyImagePixels, 0) == 0) return err;
  if (!ok) {
    while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
    if (err.size() > 300) err = err.substr(0, 300) + "...";
    return "not a valid glTF file: " + (err.empty() ? std::string("unreadable") : err);
  }
  for (const std::string& ext : doc.model.extensionsRequired)
    if (!supported_extension(ext)) return "the file requires extension " + ext + ", which hemibake does not support";
  if (std::string e = adopt_specular_glossiness(doc.model); !e.empty()) return e;
  ignored_feature_warnings(doc.model, warnings);
  return {};
}

// ---- Nodes: a tree (one parent each, no cycles) with finite transforms ----

// Each node's parent, or -1.
std::string node_parents(const tinygltf::Model& m, std::vector<int>& parent) {
  parent.assign(m.nodes.size(), -1);
  for (size_t i = 0; i < m.nodes.size(); ++i) {
    for (int c : m.nodes[i].children) {
      if (c < 0 || static_cast<size_t>(c) >= m.nodes.size())
        return "node " + std::to_string(i) + " has child " + std::to_string(c) + ", which does not exist";
      if (parent[c] != -1 || static_cast<size_t>(c) == i)
        return "node " + std::to_string(c) + " has more than one parent (or is its own child): the node hierarchy must be a tree";
      parent[c] = static_cast<int>(i);
    }
  }
  return {};
}

// The nodes of scene `scene`, parents before children.
std::string scene_nodes(const tinygltf::Model& m, int scene, const std::vector<int>& parent, std::vector<int>& order) {
  std::vector<int> stack;
  for (int root : m.scenes[scene].nodes) {
    if (root < 0 || static_cast<size_t>(root) >= m.nodes.size())
      return "scene " + std::to_string(scene) + " refers to node " + std::to_string(root) + ", which does not exist";
    if (parent[root] != -1)
      return "node " + std::to_string(root) + " is a scene root and also a child of node " + std::to_string(parent[root]);
    stack.push_back(root);
  }
  std::vector<uint8_t> seen(m.nodes.size(), 0);
  while (!stack.empty()) {
    const int n = stack.back();
    stack.pop_back();
    if (seen[n]) return "node " + std::to_string(n) + " appears twice in the scene (a cycle or a repeated root)";
    seen[n] = 1;
    order.push_back(n);
    for (int c : m.nodes[n].children) stack.push_back(c);
  }
  return {};
}

// The default scene's nodes (`order`, parents first) and every node's local-to-world matrix (the
// identity for nodes outside the scene).
std::string place_nodes(const tinygltf::Model& m, std::vector<int>& order, std::vector<glm::dmat4>& world) {
  if (m.scenes.empty()) return "the file has no scene";
  const int scene = m.defaultScene >= 0 ? m.defaultScene : 0;
  if (static_cast<size_t>(scene) >= m.scenes.size()) return "the default scene " + std::to_string(scene) + " does not exist";
  std::vector<int> parent;
  if (std::string e = node_parents(m, parent); !e.empty()) return e;
  if (std::string e = scene_nodes(m, scene, parent, order); !e.empty()) return e;
  world.assign(m.nodes.size(), glm::dmat4(1.0));
  for (int n : order) {
    const glm::dmat4 local = local_matrix(m.nodes[n]);
    world[n] = parent[n] >= 0 ? world[parent[n]] * local : local;
    if (!finite(world[n])) return "node " + std::to_string(n) + " has a transform that is not finite";
  }
  return {};
}

// ---- Lights: KHR_lights_punctual, placed by the nodes that refer to them ----

std::string number_text(double x) {
  if (x == std::floor(x) && std::abs(x) < 1e15) return std::to_string(static_cast<long long>(x));
  return std::to_string(x);
}

std::string light_label(size_t index, const tinygltf::Light& l) {
  return "light " + std::to_string(index) + (l.name.empty() ? std::string() : " ('" + l.name + "')");
}

// Light `index` of the file as the solver's light (placed at the origin, pointing down -Z), or
// what is wrong with it.
std::string read_light(const tinygltf::Model& m, size_t index, solver::Light& out) {
  const tinygltf::Light& l = m.lights[index];
  const std::string name = light_label(index, l);
  if (l.type == "point") out.type = solver::Light::Type::kPoint;
  else if (l.type == "spot") out.type = solver::Light::Type::kSpot;
  else if (l.type == "directional") out.type = solver::Light::Type::kDirectional;
  else return name + " has the unknown type '" + l.type + "' (KHR_lights_punctual has point, spot and directional)";
  glm::dvec3 color(1.0);
  if (!l.color.empty()) {
    if (l.color.size() != 3) return name + ": color must have three numbers";
    color = glm::dvec3(l.color[0], l.color[1], l.color[2]);
  }
  if (!finite(color) || glm::min(color.x, glm::min(color.y, color.z)) < 0.0)
    return name + ": color must be three finite numbers, none negative";
  if (!std::isfinite(l.intensity) || l.intensity < 0.0) return name + ": intensity must be a finite number, not negative";
  // tinygltf reads an absent range as 0; the extension's range must be above 0.
  if (!std::isfinite(l.range) || l.range < 0.0) return name + ": range must be a finite number above 0";
  out.intensity = color * l.intensity;  // candela, or lux for a directional light, as given
  out.range = out.type == solver::Light::Type::kDirectional ? 0.0 : l.range;
  if (out.type == solver::Light::Type::kSpot) {
    const double inner = l.spot.innerConeAngle, outer = l.spot.outerConeAngle;
    if (!(inner >= 0.0 && inner < outer && outer <= std::numbers::pi / 2))
      return name + ": the spot's cone angles (innerConeAngle " + std::to_string(inner) + ", outerConeAngle " +
             std::to_string(outer) + ") must satisfy 0 <= inner < outer <= pi / 2";
    out.inner_cone = inner;
    out.outer_cone = outer;
  }
  return {};
}

// Every node of the scene with a light (a light used by several nodes shines from each): at the
// node's world position, pointing along its world -Z (the node's scale does not change the light).
std::string add_lights(SceneDocument& doc, const std::vector<int>& order) {
  const tinygltf::Model& m = doc.model;
  std::vector<solver::Light> lights(m.lights.size());
  for (size_t i = 0; i < m.lights.size(); ++i)
    if (std::string e = read_light(m, i, lights[i]); !e.empty()) return e;
  for (int n : order) {
    const auto it = m.nodes[n].extensions.find("KHR_lights_punctual");
    if (it == m.nodes[n].extensions.end()) continue;
    const tinygltf::Value& ref = it->second.Get("light");
    const std::string where = "node " + std::to_string(n) + "'s KHR_lights_punctual";
    if (!ref.IsInt() && !ref.IsNumber()) return where + " has no light index";
    const double index = ref.GetNumberAsDouble();
    if (!(index >= 0.0) || index != std::floor(index) || index >= static_cast<double>(m.lights.size()))
      return where + " refers to light " + number_text(index) + ", which does not exist (the file has " +
             std::to_string(m.lights.size()) + " lights)";
    solver::Light light = lights[static_cast<size_t>(index)];
    const glm::dmat4& world = doc.node_world[n];
    light.position = glm::dvec3(world[3]);
    const glm::dvec3 down_z = glm::dmat3(world) * glm::dvec3(0.0, 0.0, -1.0);
    if (!(glm::length(down_z) > 1e-12))
      return where + ": the node's transform has no direction for the light (a zero scale)";
    light.direction = glm::normalize(down_z);
    doc.scene.lights.push_back(light);
  }
  return {};
}

// ---- Accessors: one primitive's vertices, read and checked ----

// A primitive's vertices as its triangles use them, renumbered compactly (an instance of a large
// mesh costs what its triangles use, not the accessor's length).
struct Vertices {
  std::vector<uint32_t> indices;  // per index: a compact vertex
  std::vector<uint32_t> used;     // per compact vertex: its element in the accessors
  std::vector<glm::dvec3> points;  // per compact vertex: world position
  size_t count = 0;                // elements in POSITION, and in every per-vertex attribute
};

// A morph target's displacements and weight (glTF 2.0, section 3.7.2.2).
struct Morph {
  View displacement;
  double weight = 0.0;
};

std::string read_indices(const tinygltf::Model& m, int accessor, const std::string& where, size_t vertex_count,
                         std::vector<uint32_t>& idx) {
  if (accessor < 0) {
    idx.resize(vertex_count);
    for (size_t i = 0; i < vertex_count; ++i) idx[i] = static_cast<uint32_t>(i);
    return {};
  }
  View iv;
  if (std::string e = view_accessor(m, accessor, "indices of " + where, iv); !e.empty()) return e;
  if (iv.components != 1 || (iv.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
                              iv.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
                              iv.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
    return "accessor " + std::to_string(accessor) + " (indices of " + where + ") must be SCALAR unsigned byte, short or int";
  iv.normalized = false;
  idx.resize(iv.count);
  for (size_t i = 0; i < iv.count; ++i) {
    const double v = read_component(iv, i, 0);
    if (v >= static_cast<double>(vertex_count))
      return "accessor " + std::to_string(accessor) + " (indices of " + where + ") has index " +
             std::to_string(static_cast<uint64_t>(v)) + " at element " + std::to_string(i) + ", but there are only " +
             std::to_string(vertex_count) + " vertices";
    idx[i] = static_cast<uint32_t>(v);
  }
  return {};
}

// The accessor elements that `idx` uses, sorted; `idx` is renumbered to index them.
std::vector<uint32_t> compact_vertices(std::vector<uint32_t>& idx) {
  std::vector<uint32_t> used(idx);
  std::sort(used.begin(), used.end());
  used.erase(std::unique(used.begin(), used.end()), used.end());
  for (uint32_t& i : idx) i = static_cast<uint32_t>(std::lower_bound(used.begin(), used.end(), i) - used.begin());
  return used;
}

// The POSITION targets with a weight that is not zero, at the instance's weights: the node's, else
// the mesh's, else none.
std::string morph_targets(const tinygltf::Model& m, int n, const tinygltf::Primitive& prim, const std::string& where,
                          size_t vertex_count, std::vector<Morph>& morphs) {
  const tinygltf::Node& node = m.nodes[n];
  const std::vector<double>& weights = !node.weights.empty() ? node.weights : m.meshes[node.mesh].weights;
  for (size_t t = 0; t < prim.targets.size() && t < weights.size(); ++t) {
    const auto it = prim.targets[t].find("POSITION");
    if (weights[t] == 0.0 || it == prim.targets[t].end()) continue;
    const std::string what = "POSITION of morph target " + std::to_string(t) + " of " + where;
    if (!std::isfinite(weights[t]))
      return "the weight of morph target " + std::to_string(t) + " of " + where + " (node " + std::to_string(n) +
             ") is not finite";
    View d;
    if (std::string e = view_accessor(m, it->second, what, d); !e.empty()) return e;
    if (d.components != 3 || d.count != vertex_count)
      return "accessor " + std::to_string(it->second) + " (" + what + ") must be VEC3 with one element per vertex";
    morphs.push_back({d, weights[t]});
  }
  return {};
}

// World positions of the used vertices: base + sum of weight x target displacement, transformed.
std::string world_points(const View& pos, int accessor, const std::string& where, const std::vector<Morph>& morphs,
                         const glm::dmat4& world, Vertices& v) {
  v.points.resize(v.used.size());
  for (size_t k = 0; k < v.used.size(); ++k) {
    const size_t i = v.used[k];
    glm::dvec3 p = read_vec3(pos, i);
    for (const Morph& morph : morphs) p += morph.weight * read_vec3(morph.displacement, i);
    if (!finite(p))
      return "accessor " + std::to_string(accessor) + " (POSITION of " + where + ") has a non-finite value at element " +
             std::to_string(i);
    v.points[k] = glm::dvec3(world * glm::dvec4(p, 1.0));
  }
  return {};
}

// POSITION (any component type: KHR_mesh_quantization allows integers), indices and morph
// targets of primitive `prim` of node `n`'s mesh.
std::string read_vertices(const tinygltf::Model& m, int n, const tinygltf::Primitive& prim, const std::string& where,
                          const glm::dmat4& world, Vertices& out) {
  const auto pos_it = prim.attributes.find("POSITION");
  if (pos_it == prim.attributes.end()) return where + " has no POSITION attribute";
  View pos;
  if (std::string e = view_accessor(m, pos_it->second, "POSITION of " + where, pos); !e.empty()) return e;
  if (pos.components != 3)
    return "accessor " + std::to_string(pos_it->second) + " (POSITION of " + where + ") must be VEC3";
  out.count = pos.count;
  if (std::string e = read_indices(m, prim.indices, where, pos.count, out.indices); !e.empty()) return e;
  out.used = compact_vertices(out.indices);
  std::vector<Morph> morphs;
  if (std::string e = morph_targets(m, n, prim, where, pos.count, morphs); !e.empty()) return e;
  return world_points(pos, pos_it->second, where, morphs, world, out);
}

// Per compact vertex: what a triangle's colours are made of (each empty when the primitive lacks it).
struct VertexColours {
  std::vector<glm::dvec2> uv;       // the base colour texture's set; also the output's TEXCOORD_0
  std::vector<glm::dvec2> uv_emit;  // the emissive texture's set
  std::vector<glm::dvec3> tint;     // COLOR_0
};

std::string read_texcoords(const tinygltf::Model& m, const tinygltf::Primitive& prim, int set, const std::string& where,
                           const Vertices& v, std::vector<glm::dvec2>& uvs) {
  const std::string name = "TEXCOORD_" + std::to_string(set);
  const auto it = prim.attributes.find(name);
  if (it == prim.attributes.end()) return {};
  View uv;
  if (std::string e = view_accessor(m, it->second, name + " of " + where, uv); !e.empty()) return e;
  if (uv.components != 2 || uv.count != v.count)
    return "accessor " + std::to_string(it->second) + " (" + name + " of " + where + ") must be VEC2 with one element per vertex";
  uvs.resize(v.used.size());
  for (size_t k = 0; k < v.used.size(); ++k) {
    uvs[k] = glm::dvec2(read_component(uv, v.used[k], 0), read_component(uv, v.used[k], 1));
    // A NaN or infinite coordinate has no texel to average, and Draco's quantization of the
    // output's TEXCOORD_0 crashed on one.
    if (!std::isfinite(uvs[k].x) || !std::isfinite(uvs[k].y))
      return "accessor " + std::to_string(it->second) + " (" + name + " of " + where + ") has a non-finite value at element " +
             std::to_string(v.used[k]);
  }
  return {};
}

// COLOR_0 multiplies the base colour (glTF 2.0, section 3.9.2), so it tints the reflectance.
std::string read_tint(const tinygltf::Model& m, const tinygltf::Primitive& prim, const std::string& where,
                      const Vertices& v, std::vector<glm::dvec3>& tint) {
  const auto it = prim.attributes.find("COLOR_0");
  if (it == prim.attributes.end()) return {};
  const std::string what = "COLOR_0 of " + where;
  View cv;
  if (std::string e = view_accessor(m, it->second, what, cv); !e.empty()) return e;
  const bool type_ok = cv.component_type == TINYGLTF_COMPONENT_TYPE_FLOAT ||
                       (cv.normalized && (cv.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                                          cv.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT));
  if ((cv.components != 3 && cv.components != 4) || !type_ok || cv.count != v.count)
    return "accessor " + std::to_string(it->second) + " (" + what +
           ") must be VEC3 or VEC4, float or normalized unsigned byte or short, with one element per vertex";
  tint.resize(v.used.size());
  for (size_t k = 0; k < v.used.size(); ++k) {
    tint[k] = read_vec3(cv, v.used[k]);
    if (!finite(tint[k]))
      return "accessor " + std::to_string(it->second) + " (" + what + ") has a non-finite value at element " +
             std::to_string(v.used[k]);
  }
  return {};
}

std::string read_colours(const tinygltf::Model& m, const tinygltf::Primitive& prim, const std::string& where,
                         const MaterialInfo& mat, const Vertices& v, VertexColours& out) {
  if (std::string e = read_texcoords(m, prim, mat.base_texcoord, where, v, out.uv); !e.empty()) return e;
  if (std::string e = read_texcoords(m, prim, mat.emissive_texcoord, where, v, out.uv_emit); !e.empty()) return e;
  return read_tint(m, prim, where, v, out.tint);
}

// ---- Materials: each triangle's colours ----

// A primitive's triangles that are not degenerate, with their colours (one entry each).
struct ShadedTriangles {
  std::vector<std::array<uint32_t, 3>> corners;  // compact vertices, counter-clockwise in world space
  std::vector<glm::dvec3> base;      // displayed base colour: factor x texture mean
  std::vector<glm::dvec3> reflect;   // base colour x vertex colour
  std::vector<glm::dvec3> emission;
  std::vector<double> area;
};

size_t count_triangles(int mode, size_t index_count) {
  if (mode == TINYGLTF_MODE_TRIANGLES) return index_count / 3;
  return index_count >= 3 ? index_count - 2 : 0;
}

// Triangle `t` in glTF order (strips alternate winding; fans turn about the first vertex).
std::array<uint32_t, 3> triangle_corners(int mode, const std::vector<uint32_t>& idx, size_t t, bool mirrored) {
  std::array<uint32_t, 3> v;
  if (mode == TINYGLTF_MODE_TRIANGLES) v = {idx[3 * t], idx[3 * t + 1], idx[3 * t + 2]};
  else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP)
    v = t % 2 == 0 ? std::array{idx[t], idx[t + 1], idx[t + 2]} : std::array{idx[t + 1], idx[t], idx[t + 2]};
  else v = {idx[t + 1], idx[t + 2], idx[0]};
  if (mirrored) std::swap(v[1], v[2]);
  return v;
}

// `factor` times the mean of `texture` over the triangle, where the texture and UVs exist.
glm::dvec3 textured(const tinygltf::Model& m, glm::dvec3 factor, int texture, const UvTransform& tf,
                    const std::vector<glm::dvec2>& uv, const std::array<uint32_t, 3>& v) {
  if (uv.empty()) return factor;
  if (auto mean = texture_mean(m, texture, {tf.apply(uv[v[0]]), tf.apply(uv[v[1]]), tf.apply(uv[v[2]])})) factor *= *mean;
  return factor;
}

ShadedTriangles shade_triangles(const tinygltf::Model& m, int mode, bool mirrored, const Vertices& v,
                                const MaterialInfo& mat, const VertexColours& colours, uint64_t& degenerate) {
  const size_t ntri = count_triangles(mode, v.indices.size());
  ShadedTriangles out;
  out.corners.reserve(ntri);
  for (size_t t = 0; t < ntri; ++t) {
    const std::array<uint32_t, 3> c = triangle_corners(mode, v.indices, t, mirrored);
    const glm::dvec3 a = v.points[c[0]], b = v.points[c[1]], d = v.points[c[2]];
    // Slivers (area tiny next to the longest edge) have no reliable normal.
    const double scale = std::max({glm::length(b - a), glm::length(d - b), glm::length(a - d)});
    const double area = 0.5 * glm::length(glm::cross(b - a, d - a));
    if (!(area > 0.5e-10 * scale * scale)) {
      ++degenerate;
      continue;
    }
    const glm::dvec3 base = textured(m, mat.factor, mat.base_texture, mat.base_transform, colours.uv, c);
    const auto& tint = colours.tint;
    out.corners.push_back(c);
    out.base.push_back(base);
    // The mean of the vertex colours, linear over the triangle.
    out.reflect.push_back(tint.empty() ? base : base * (tint[c[0]] + tint[c[1]] + tint[c[2]]) / 3.0);
    out.emission.push_back(textured(m, mat.emissive, mat.emissive_texture, mat.emissive_transform, colours.uv_emit, c));
    out.area.push_back(area);
  }
  return out;
}

// ---- Patches ----

// One patch (and its back side for a double-sided material) with corners `v` (the first
// `count`); `source` names its node, mesh and primitive.
void add_patch(const std::array<uint32_t, 4>& v, uint32_t count, const glm::dvec3& base, const glm::dvec3& reflect,
               const glm::dvec3& emission, const Vertices& vertices, const std::vector<glm::dvec2>& uv,
               const MaterialInfo& mat, uint32_t material, PatchSource src, uint64_t vertex_base, SceneDocument& doc) {
  solver::Patch patch;
  patch.corner_count = count;
  for (uint32_t k = 0; k < count; ++k) {
    patch.corners[k] = vertices.points[v[k]];
    if (!uv.empty()) src.uv[k] = uv[v[k]];
    // The exporter's vertex (its smooth shading shares one between faces), numbered across the
    // scene's primitives from 1; past 32 bits, unknown.
    const uint64_t id = vertex_base + v[k] + 1;
    patch.vertex[k] = id <= std::numeric_limits<uint32_t>::max() ? static_cast<uint32_t>(id) : 0;
  }
  src.has_uv = !uv.empty();
  src.base = glm::clamp(base, 0.0, 1.0);
  patch.reflectance = glm::clamp(mat.reflectance_override.value_or(reflect), 0.0, kMaxReflectance);
  // glTF's emission is a radiance (what three.js and the sample viewer add to the outgoing
  // light); a Lambertian emitter of radiance L sends out the exitance pi L, the solver's unit.
  // extras.hemibake.emission is given in the solver's unit already.
  patch.emission = mat.emission_override.value_or(std::numbers::pi * emission);
  // An emitter is shown in its emissive colour, not its base colour (the writer gives its material
  // the emissive factor and texture as the unlit base colour): emissiveFactor's hue times the
  // emissive texture's mean here, so that COLOR_0 carries the brightness.
  if (patch.emission != glm::dvec3(0.0)) {
    const glm::dvec3 shown = mat.emission_override ? *mat.emission_override : emission;
    const double top = mat.emission_override ? std::max({shown.x, shown.y, shown.z})
                                             : std::max({mat.emissive.x, mat.emissive.y, mat.emissive.z});
    if (top > 0.0) src.base = glm::clamp(shown / top, 0.0, 1.0);
  }
  patch.material = material;
  doc.scene.patches.push_back(patch);
  doc.sources.push_back(src);
  if (!mat.double_sided) return;
  // The back side: the same corners in reverse order (a quad keeps its diagonal 1-3).
  std::reverse(patch.corners.begin(), patch.corners.begin() + count);
  std::reverse(patch.vertex.begin(), patch.vertex.begin() + count);
  std::reverse(src.uv.begin(), src.uv.begin() + count);
  if (count == 4) {
    std::rotate(patch.corners.begin(), patch.corners.begin() + 1, patch.corners.begin() + 4);
    std::rotate(patch.vertex.begin(), patch.vertex.begin() + 1, patch.vertex.begin() + 4);
    std::rotate(src.uv.begin(), src.uv.begin() + 1, src.uv.begin() + 4);
  }
  src.back = true;
  doc.scene.patches.push_back(patch);
  doc.sources.push_back(src);
}

// A quad's colours are its triangles' means, weighted by area.
void add_patches(const std::vector<Outline>& outlines, const ShadedTriangles& tris, const Vertices& vertices,
                 const std::vector<glm::dvec2>& uv, const MaterialInfo& mat, uint32_t material, const PatchSource& src,
                 bool has_normals, SceneDocument& doc) {
  // Without NORMAL a primitive's faces are flat (glTF 2.0, 3.7.2.1), whatever vertices they share.
  const uint64_t vertex_base = has_normals ? doc.vertices : std::numeric_limits<uint64_t>::max() / 2;
  doc.vertices += vertices.points.size();
  for (const Outline& o : outlines) {
    const uint32_t t = o.first, u = o.second;
    if (o.count == 3) {
      add_patch(o.v, 3, tris.base[t], tris.reflect[t], tris.emission[t], vertices, uv, mat, material, src, vertex_base, doc);
      continue;
    }
    const double wa = tris.area[t], wb = tris.area[u];
    add_patch(o.v, 4, (wa * tris.base[t] + wb * tris.base[u]) / (wa + wb),
              (wa * tris.reflect[t] + wb * tris.reflect[u]) / (wa + wb),
              (wa * tris.emission[t] + wb * tris.emission[u]) / (wa + wb), vertices, uv, mat, material, src, vertex_base, doc);
  }
}

// ---- The stages, per primitive ----

// What the primitives add up to, for the warnings after the last one.
struct Tally {
  uint64_t degenerate = 0;
  uint64_t skipped_primitives = 0;
  std::vector<int> see_through;  // baked materials with alphaMode BLEND or MASK, or transmission
};

// Primitive `pi` of node `n`'s mesh, as patches in doc.
std::string add_primitive(SceneDocument& doc, int n, size_t pi, const LoadLimits& limits, Tally& tally) {
  const tinygltf::Model& m = doc.model;
  const tinygltf::Node& node = m.nodes[n];
  const tinygltf::Primitive& prim = m.meshes[node.mesh].primitives[pi];
  const std::string where = "mesh " + std::to_string(node.mesh) + " primitive " + std::to_string(pi);
  const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
  if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP && mode != TINYGLTF_MODE_TRIANGLE_FAN) {
    if (mode > 3) return where + " has an invalid mode " + std::to_string(mode);
    ++tally.skipped_primitives;  // points or lines have no area to bake
    return {};
  }
  Vertices vertices;
  if (std::string e = read_vertices(m, n, prim, where, doc.node_world[n], vertices); !e.empty()) return e;
  if (prim.material >= 0 && static_cast<size_t>(prim.material) < m.materials.size() &&
      see_through(m.materials[prim.material]) &&
      std::find(tally.see_through.begin(), tally.see_through.end(), prim.material) == tally.see_through.end())
    tally.see_through.push_back(prim.material);
  MaterialInfo mat;
  if (std::string e = material_info(m, prim.material, mat); !e.empty()) return e;
  VertexColours colours;
  if (std::string e = read_colours(m, prim, where, mat, vertices, colours); !e.empty()) return e;
  doc.triangles += count_triangles(mode, vertices.indices.size());
  if (doc.triangles > limits.max_triangles)
    return "the scene has more than " + std::to_string(limits.max_triangles) + " triangles (the limit)";
  const ShadedTriangles tris =
      shade_triangles(m, mode, mirrors(doc.node_world[n]), vertices, mat, colours, tally.degenerate);
  const std::vector<Outline> outlines = merge_triangle_pairs(vertices.points, tris.corners, colours.uv);
  PatchSource src;
  src.node = static_cast<uint32_t>(n);
  src.mesh = static_cast<uint32_t>(node.mesh);
  src.primitive = static_cast<uint32_t>(pi);
  add_patches(outlines, tris, vertices, colours.uv, mat, static_cast<uint32_t>(prim.material + 1), src,
              prim.attributes.count("NORMAL") > 0, doc);
  return {};
}

// Every primitive of node `n`'s mesh (each node is one instance of its mesh).
std::string add_instance(SceneDocument& doc, int n, const LoadLimits& limits, Tally& tally) {
  const tinygltf::Node& node = doc.model.nodes[n];
  if (node.mesh < 0) return {};
  if (static_cast<size_t>(node.mesh) >= doc.model.meshes.size())
    return "node " + std::to_string(n) + " refers to mesh " + std::to_string(node.mesh) + ", which does not exist";
  for (size_t pi = 0; pi < doc.model.meshes[node.mesh].primitives.size(); ++pi)
    if (std::string e = add_primitive(doc, n, pi, limits, tally); !e.empty()) return e;
  return {};
}

void tally_warnings(const tinygltf::Model& m, const Tally& tally, std::vector<std::string>& warnings) {
  // The solver has no transmission: a glass pane (BLEND, or Blender's KHR_materials_transmission)
  // or a cut-out leaf (MASK) blocks light like a wall. Say so, rather than leave the user to wonder
  // at the shadow.
  for (int i : tally.see_through) {
    const tinygltf::Material& mt = m.materials[i];
    const std::string what = mt.alphaMode != "OPAQUE" ? "alphaMode " + mt.alphaMode : std::string("KHR_materials_transmission");
    warnings.push_back(material_label(i, mt) + " has " + what +
                       "; it is baked as opaque (transparency and cut-outs are not supported)");
  }
  if (tally.skipped_primitives > 0)
    warnings.push_back(std::to_string(tally.skipped_primitives) + " primitive(s) of points or lines were skipped");
  if (tally.degenerate > 0) warnings.push_back(std::to_string(tally.degenerate) + " degenerate triangle(s) were skipped");
}

std::string check_patches(const solver::Scene& scene) {
  if (scene.patches.empty()) return "the scene has no triangles to bake";
  if (std::string e = solver::validate(scene); !e.empty()) return "the scene cannot be baked: " + e;
  return {};
}

// ---- Reading a baked file back ----

// Triangles of a baked primitive (POSITION and _RADIOSITY, or COLOR_0) in world space.
std::string add_baked_primitive(const tinygltf::Model& m, int mesh, size_t pi, const glm::dmat4& world, solver::Mesh& out) {
  const tinygltf::Primitive& prim = m.meshes[mesh].primitives[pi];
  if (prim.mode >= 0 && prim.mode != TINYGLTF_MODE_TRIANGLES) return {};
  const std::string where = "mesh " + std::to_string(mesh) + " primitive " + std::to_string(pi);
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
    out.positions.push_back(glm::dvec3(world * glm::dvec4(read_vec3(pos, i), 1.0)));
    out.radiosity.push_back(read_vec3(rad, i));
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
  const bool mirrored = mirrors(world);
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
  return {};
}

}  // namespace

const solver::Scene& scene_of(const SceneDocument& document) { return document.scene; }
uint64_t triangle_count(const SceneDocument& document) { return document.triangles; }

uint64_t image_pixel_count(const SceneDocument& document) {
  uint64_t n = 0;
  for (const auto& image : document.model.images) n += static_cast<uint64_t>(image.image.size() / 4);
  return n;
}

std::string bake_error(const SceneDocument& document) {
  // Radiosity is the light of emitting surfaces and lights: without one, every bake is black.
  const auto& patches = document.scene.patches;
  if (!document.scene.lights.empty() && std::any_of(document.scene.lights.begin(), document.scene.lights.end(), [](const solver::Light& l) {
        return l.intensity != glm::dvec3(0.0);
      }))
    return {};
  if (document.scene.sky != glm::dvec3(0.0)) return {};
  if (std::any_of(patches.begin(), patches.end(), [](const solver::Patch& p) { return p.emission != glm::dvec3(0.0); }))
    return {};
  return "the scene emits no light: it has no emissive material (give the light sources' materials an "
         "emissiveFactor, with KHR_materials_emissive_strength above 1, or set extras.hemibake.emission), no "
         "KHR_lights_punctual light (point, spot or directional, with an intensity above 0), and no sky (set the "
         "job parameter sky, --sky R,G,B)";
}

LoadResult load_gltf_memory(std::span<const uint8_t> bytes, const std::string& base_dir, const LoadLimits& limits) {
  LoadResult result;
  auto failed = [&](std::string e) {
    result.error = std::move(e);
    return !result.error.empty();
  };
  auto doc = std::make_shared<SceneDocument>();
  if (failed(parse_document(bytes, base_dir, limits, *doc, result.warnings))) return result;
  std::vector<int> order;
  if (failed(place_nodes(doc->model, order, doc->node_world))) return result;
  if (failed(add_lights(*doc, order))) return result;
  Tally tally;
  for (int n : order)
    if (failed(add_instance(*doc, n, limits, tally))) return result;
  tally_warnings(doc->model, tally, result.warnings);
  if (failed(check_patches(doc->scene))) return result;
  // Each node's primitive is an object of its own (the solver finds closed meshes within one).
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> objects;
  for (size_t i = 0; i < doc->scene.patches.size(); ++i)
    doc->scene.patches[i].object =
        objects.try_emplace({doc->sources[i].node, doc->sources[i].primitive}, static_cast<uint32_t>(objects.size() + 1))
            .first->second;
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
  // Images are not needed here: a limit of one pixel leaves them undecoded.
  const ParseOptions options{fs::path(path).parent_path().string(), true, size, 1};
  std::string err;
  if (!parse_gltf(bytes, options, doc, warnings, err)) return "not a valid glTF file: " + err.substr(0, 300);
  const tinygltf::Model& m = doc.model;
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
    for (size_t pi = 0; pi < m.meshes[node.mesh].primitives.size(); ++pi)
      if (std::string e = add_baked_primitive(m, node.mesh, pi, world, out); !e.empty()) return e;
  }
  if (out.elements.empty()) return "the file has no triangles";
  return {};
}

}  // namespace hemibake::protocol
