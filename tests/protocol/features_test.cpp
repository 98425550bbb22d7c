// Loader and writer features, each checked against a truth from outside the code under test:
// triangle strips and fans (the glTF 2.0 specification's topology formulas, section 3.7.2.1, expanded
// here into plain triangles), points and lines, mirrored transforms (the specification's winding
// rule for negative determinants), double-sided materials (against single-sided quads facing each
// way), base colour textures (a PNG written here, the sRGB transfer function written here), material
// extras, emissiveStrength as an integer, KHR_lights_punctual, TEXCOORD_0 against the closed form
// of an affine UV map, and the automatic exposure against light known in closed form. Scenes are
// built here as glTF JSON; results are read back from the baked GLB with Draco's own decoder or
// straight from plain accessors.
#include "gltf_builder.h"
#include "glb_reader.h"
#include "tone_formula.h"
#include "../solver/test_seed.h"

#include "hemibake/protocol/bake.h"
#include "hemibake/protocol/gltf.h"
#include "hemibake/solver/solver.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
// stb_image_write's implementation is compiled into hemibake::protocol (tinygltf_impl.cpp).
#include <stb/stb_image_write.h>

#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <glm/mat3x3.hpp>
#include <glm/mat4x4.hpp>
#include <glm/matrix.hpp>
#include <glm/vec2.hpp>

#include <algorithm>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <limits>
#include <cstring>
#include <string>
#include <vector>

namespace hemibake::protocol {
namespace {

using nlohmann::json;
using V = glm::dvec3;
using UV = glm::dvec2;

constexpr int kTriangles = 4, kTriangleStrip = 5, kTriangleFan = 6;
constexpr int kFloat = 5126, kUnsignedShort = 5123;

// The sRGB electro-optical transfer function (IEC 61966-2-1), as glTF specifies for colour textures.
double srgb_to_linear(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

// A glTF document assembled in memory, with one binary buffer.
struct Doc {
  json gltf = {{"asset", {{"version", "2.0"}}},
               {"scene", 0},
               {"scenes", json::array({json{{"nodes", json::array()}}})},
               {"nodes", json::array()},
               {"meshes", json::array()},
               {"materials", json::array()},
               {"accessors", json::array()},
               {"bufferViews", json::array()}};
  std::vector<uint8_t> bin;

  int view(const void* data, size_t size) {
    while (bin.size() % 4) bin.push_back(0);
    const size_t at = bin.size();
    bin.insert(bin.end(), static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + size);
    gltf["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", at}, {"byteLength", size}});
    return static_cast<int>(gltf["bufferViews"].size()) - 1;
  }
  int accessor(json a) {
    gltf["accessors"].push_back(std::move(a));
    return static_cast<int>(gltf["accessors"].size()) - 1;
  }
  int positions(const std::vector<V>& p) {
    std::vector<float> f;
    std::vector<double> lo(3, 1e300), hi(3, -1e300);
    for (const V& v : p)
      for (int k = 0; k < 3; ++k) {
        f.push_back(static_cast<float>(v[k]));
        lo[k] = std::min(lo[k], static_cast<double>(f.back()));
        hi[k] = std::max(hi[k], static_cast<double>(f.back()));
      }
    return accessor({{"bufferView", view(f.data(), f.size() * 4)}, {"componentType", kFloat}, {"count", p.size()},
                     {"type", "VEC3"}, {"min", lo}, {"max", hi}});
  }
  int texcoords(const std::vector<UV>& uv) {
    std::vector<float> f;
    for (const UV& t : uv) f.insert(f.end(), {static_cast<float>(t.x), static_cast<float>(t.y)});
    return accessor({{"bufferView", view(f.data(), f.size() * 4)}, {"componentType", kFloat}, {"count", uv.size()}, {"type", "VEC2"}});
  }
  int indices(const std::vector<uint32_t>& idx) {
    std::vector<uint16_t> s(idx.begin(), idx.end());
    return accessor({{"bufferView", view(s.data(), s.size() * 2)}, {"componentType", kUnsignedShort}, {"count", s.size()}, {"type", "SCALAR"}});
  }
  int material(json m) {
    gltf["materials"].push_back(std::move(m));
    return static_cast<int>(gltf["materials"].size()) - 1;
  }
  int mesh(json primitives) {
    gltf["meshes"].push_back({{"primitives", std::move(primitives)}});
    return static_cast<int>(gltf["meshes"].size()) - 1;
  }
  int node(json n, bool root = true) {
    gltf["nodes"].push_back(std::move(n));
    const int i = static_cast<int>(gltf["nodes"].size()) - 1;
    if (root) gltf["scenes"][0]["nodes"].push_back(i);
    return i;
  }
  // A primitive of `points` in `mode`, indexed when `idx` is not empty.
  json primitive(const std::vector<V>& points, const std::vector<uint32_t>& idx, int mode, int mat,
                 const std::vector<UV>& uv = {}) {
    json p = {{"attributes", {{"POSITION", positions(points)}}}, {"mode", mode}, {"material", mat}};
    if (!idx.empty()) p["indices"] = indices(idx);
    if (!uv.empty()) p["attributes"]["TEXCOORD_0"] = texcoords(uv);
    return p;
  }
  // A node with a mesh of one convex quad (corners counter-clockwise from its front) as two triangles.
  int quad_node(const std::vector<V>& corners, int mat, json node = json::object(), const std::vector<UV>& uv = {}) {
    node["mesh"] = mesh(json::array({primitive(corners, {0, 1, 2, 0, 2, 3}, kTriangles, mat, uv)}));
    return this->node(node);
  }
  std::vector<uint8_t> gltf_bytes() const {
    json j = gltf;
    j["buffers"] = json::array({json{{"byteLength", bin.size()},
                                     {"uri", "data:application/octet-stream;base64," + test::base64_encode(bin)}}});
    const std::string s = j.dump();
    return {s.begin(), s.end()};
  }
  std::vector<uint8_t> glb_bytes() const {
    json j = gltf;
    j["buffers"] = json::array({json{{"byteLength", bin.size()}}});
    return test::make_glb(j, bin);
  }
};

json plain_material(const V& base, const std::string& name = "") {
  json m = {{"pbrMetallicRoughness", {{"baseColorFactor", {base.x, base.y, base.z, 1.0}}}}};
  if (!name.empty()) m["name"] = name;
  return m;
}

// A lamp: black (reflects nothing, so that only direct light is compared) and emitting the
// exitance `e` (glTF's emission is the radiance e / pi).
json lamp_material(const V& e) {
  const double top = std::max({e.x, e.y, e.z});
  json m = plain_material(V(0.0), "lamp");
  m["emissiveFactor"] = {e.x / top, e.y / top, e.z / top};
  m["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] = top / std::numbers::pi;
  return m;
}

// The horizontal rectangle [x0, x1] x [z0, z1] at height y, corners counter-clockwise seen from +y
// (z before x: cross((0,0,dz), (dx,0,dz)) = (0, dz dx, 0)) when `up`, else seen from -y.
std::vector<V> rect(double x0, double x1, double z0, double z1, double y, bool up) {
  std::vector<V> q = {V(x0, y, z0), V(x0, y, z1), V(x1, y, z1), V(x1, y, z0)};
  if (!up) std::reverse(q.begin(), q.end());
  return q;
}

solver::Params quick_params() {
  solver::Params p;
  p.convergence = 0.02;
  p.resolution = 60;
  return p;
}

// ---- Reading the baked GLB back -------------------------------------------------------------

struct Output {
  json doc;
  std::vector<uint8_t> bin;
};

using Primitive = test::Decoded;

Primitive read_primitive(const Output& g, const json& prim) { return test::read_primitive(g.doc, g.bin, prim); }

// A node's local matrix: `matrix` (column-major) or T * R * S (glTF 2.0, section 3.5.3).
glm::dmat4 local_matrix(const json& n) {
  if (n.contains("matrix")) {
    glm::dmat4 m;
    for (int i = 0; i < 16; ++i) glm::value_ptr(m)[i] = n["matrix"][i].get<double>();
    return m;
  }
  glm::dmat4 m(1.0);
  if (n.contains("translation")) m = glm::translate(m, V(n["translation"][0], n["translation"][1], n["translation"][2]));
  if (n.contains("rotation"))
    m = m * glm::mat4_cast(glm::dquat(n["rotation"][3].get<double>(), n["rotation"][0].get<double>(),
                                      n["rotation"][1].get<double>(), n["rotation"][2].get<double>()));
  if (n.contains("scale")) m = glm::scale(m, V(n["scale"][0], n["scale"][1], n["scale"][2]));
  return m;
}

glm::dmat4 world_matrix(const json& doc, int node) {
  glm::dmat4 m = local_matrix(doc["nodes"][node]);
  for (bool found = true; found;) {
    found = false;
    for (size_t p = 0; p < doc["nodes"].size() && !found; ++p) {
      for (const auto& c : doc["nodes"][p].value("children", json::array())) {
        if (c.get<int>() != node) continue;
        m = local_matrix(doc["nodes"][p]) * m;
        node = static_cast<int>(p);
        found = true;
        break;
      }
    }
  }
  return m;
}

// A baked triangle in world space. `front` is its front side's normal (times twice its area) by the
// glTF rule: counter-clockwise in the node's frame, clockwise in the world when the node's world
// matrix has a negative determinant (glTF 2.0, section 3.7.2.1).
struct Tri {
  std::array<V, 3> p, b;
  std::array<UV, 3> uv;
  V front;
  double area() const { return 0.5 * glm::length(front); }
};

// The baked triangles of `node`, one list per output primitive.
std::vector<std::vector<Tri>> baked_node(const Output& g, int node) {
  std::vector<std::vector<Tri>> out;
  const json& n = g.doc["nodes"][node];
  if (!n.contains("mesh")) return out;
  const glm::dmat4 world = world_matrix(g.doc, node);
  const double sign = glm::determinant(glm::dmat3(world)) < 0.0 ? -1.0 : 1.0;
  for (const json& prim : g.doc["meshes"][n["mesh"].get<int>()]["primitives"]) {
    EXPECT_EQ(prim.value("mode", kTriangles), kTriangles);
    const Primitive d = read_primitive(g, prim);
    EXPECT_EQ(d.radiosity.size(), d.positions.size());
    std::vector<Tri> tris;
    for (size_t t = 0; t + 2 < d.indices.size(); t += 3) {
      Tri tri;
      for (int k = 0; k < 3; ++k) {
        const uint32_t i = d.indices[t + k];
        tri.p[k] = V(world * glm::dvec4(d.positions.at(i), 1.0));
        tri.b[k] = d.radiosity.at(i);
        tri.uv[k] = d.uv.empty() ? UV(0.0) : d.uv.at(i);
      }
      tri.front = sign * glm::cross(tri.p[1] - tri.p[0], tri.p[2] - tri.p[0]);
      tris.push_back(tri);
    }
    out.push_back(std::move(tris));
  }
  return out;
}

double total_area(const std::vector<Tri>& tris) {
  double a = 0.0;
  for (const Tri& t : tris) a += t.area();
  return a;
}

// Area of the triangles whose front side faces along `dir`.
double area_facing(const std::vector<Tri>& tris, const V& dir) {
  double a = 0.0;
  for (const Tri& t : tris)
    if (glm::dot(t.front, dir) > 0.0) a += t.area();
  return a;
}

// The mean radiosity over the surface (vertex radiosity is linear over each triangle).
V mean_radiosity(const std::vector<Tri>& tris) {
  V sum(0.0);
  double area = 0.0;
  for (const Tri& t : tris) {
    sum += t.area() * (t.b[0] + t.b[1] + t.b[2]) / 3.0;
    area += t.area();
  }
  return area > 0.0 ? sum / area : V(0.0);
}

std::vector<Tri> all_of(const std::vector<std::vector<Tri>>& prims) {
  std::vector<Tri> out;
  for (const auto& p : prims) out.insert(out.end(), p.begin(), p.end());
  return out;
}

struct Baked {
  LoadResult loaded;
  Output out;
};

Baked bake(const std::vector<uint8_t>& bytes, bool draco = false, solver::Params params = quick_params()) {
  Baked r;
  r.loaded = load_gltf_memory(bytes, ".");
  EXPECT_TRUE(r.loaded.document) << r.loaded.error;
  if (!r.loaded.document) return r;
  JobSpec spec;
  spec.params = params;
  spec.write.draco = draco;
  const BakeOutput w = protocol::bake(*r.loaded.document, spec);
  EXPECT_EQ(w.error, "");
  const auto parts = test::split_glb(w.glb);
  EXPECT_TRUE(parts.has_value()) << "the output is not a well-formed GLB";
  if (parts) r.out = {parts->gltf, parts->bin};
  return r;
}

bool mentions(const std::vector<std::string>& warnings, const std::string& word) {
  for (const auto& w : warnings)
    if (w.find(word) != std::string::npos) return true;
  return false;
}

std::string joined(const std::vector<std::string>& warnings) {
  std::string s;
  for (const auto& w : warnings) s += "[" + w + "] ";
  return s;
}

// ---- 1. Triangle strips and fans --------------------------------------------------------------

// The floor [0, 2]^2 at y = 0 as a 3 x 3 vertex grid, facing +y.
V grid(int i, int j) { return V(i, 0.0, j); }

struct Topology {
  std::vector<V> vertices;     // the vertex list the indices refer to
  std::vector<uint32_t> order; // the primitive's index sequence
  int mode;
};

// Two rows of a strip joined by degenerate triangles (as exporters stitch strips): triangle t is
// (t, t+1, t+2) for even t and (t, t+2, t+1) for odd t, so every real triangle faces +y.
Topology floor_strip() {
  Topology s{{}, {}, kTriangleStrip};
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) s.vertices.push_back(grid(i, j));
  auto at = [](int i, int j) { return static_cast<uint32_t>(3 * j + i); };
  s.order = {at(0, 0), at(0, 1), at(1, 0), at(1, 1), at(2, 0), at(2, 1),  // row 0: four triangles
             at(2, 1), at(0, 1),                                          // four degenerate ones
             at(0, 1), at(0, 2), at(1, 1), at(1, 2), at(2, 1), at(2, 2)}; // row 1
  return s;
}

// A fan about the floor's centre through the eight points of its border, counter-clockwise from +y.
Topology floor_fan() {
  Topology f{{grid(1, 1)}, {0}, kTriangleFan};
  const int ring[8][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 2}, {2, 2}, {2, 1}, {2, 0}, {1, 0}};
  for (const auto& r : ring) f.vertices.push_back(grid(r[0], r[1]));
  for (uint32_t k = 1; k <= 8; ++k) f.order.push_back(k);
  f.order.push_back(1);  // closes the ring
  return f;
}

// The same triangles as a TRIANGLES index list over the same vertices, by the specification's
// formulas (degenerate ones kept): the equivalent plain primitive.
std::vector<uint32_t> as_triangles(const std::vector<uint32_t>& order, int mode) {
  std::vector<uint32_t> out;
  for (size_t i = 0; i + 2 < order.size(); ++i) {
    if (mode == kTriangleStrip) {
      const size_t a = i, b = i + 1 + i % 2, c = i + 2 - i % 2;  // p_i = {v_i, v_{i+(1+i%2)}, v_{i+(2-i%2)}}
      out.insert(out.end(), {order[a], order[b], order[c]});
    } else {
      out.insert(out.end(), {order[i + 1], order[i + 2], order[0]});  // p_i = {v_{i+1}, v_{i+2}, v_0}
    }
  }
  return out;
}

// The floor as a primitive in the topology's mode (indexed, or one vertex per index without
// indices) or, `as_list`, as the equivalent TRIANGLES primitive over the same vertex buffer.
json floor_primitive(Doc& d, const Topology& t, bool indexed, bool as_list, int mat) {
  std::vector<V> vertices = t.vertices;
  std::vector<uint32_t> order = t.order;
  if (!indexed) {
    vertices.clear();
    for (uint32_t i : t.order) vertices.push_back(t.vertices[i]);
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  }
  if (as_list) return d.primitive(vertices, as_triangles(order, t.mode), kTriangles, mat);
  return d.primitive(vertices, indexed ? order : std::vector<uint32_t>{}, t.mode, mat);
}

struct LitFloor {
  std::vector<uint8_t> bytes;
  int floor_node = 0;
};

// The floor lit by a lamp 1 above it (facing down) or 1 below it (facing up).
LitFloor lit_floor(const Topology& t, bool indexed, bool as_list, bool lamp_above) {
  Doc d;
  const int grey = d.material(plain_material(V(0.6)));
  const int lamp = d.material(lamp_material(V(4.0)));
  const json prim = floor_primitive(d, t, indexed, as_list, grey);
  LitFloor s;
  s.floor_node = d.node({{"name", "floor"}, {"mesh", d.mesh(json::array({prim}))}});
  d.quad_node(lamp_above ? rect(0.5, 1.5, 0.5, 1.5, 1.0, false) : rect(0.5, 1.5, 0.5, 1.5, -1.0, true), lamp, {{"name", "lamp"}});
  s.bytes = d.gltf_bytes();
  return s;
}

// The patches of the floor (material 1 here is the grey one: patch.material is the glTF index + 1),
// each as (centroid, area, unit normal), sorted: the same list means the same surface.
std::vector<std::array<double, 7>> floor_patches(const solver::Scene& scene) {
  std::vector<std::array<double, 7>> out;
  for (const auto& p : scene.patches) {
    if (p.material != 1) continue;
    V c(0.0), n(0.0);
    for (uint32_t k = 0; k < p.corner_count; ++k) c += p.corners[k] / static_cast<double>(p.corner_count);
    for (uint32_t k = 1; k + 1 < p.corner_count; ++k) n += 0.5 * glm::cross(p.corners[k] - p.corners[0], p.corners[k + 1] - p.corners[0]);
    const double a = glm::length(n);
    n /= a;
    out.push_back({c.x, c.y, c.z, a, n.x, n.y, n.z});
  }
  std::sort(out.begin(), out.end());
  return out;
}

struct TopologyCase {
  const char* name;
  Topology (*make)();
  bool indexed;
};

class StripAndFanFeature : public ::testing::TestWithParam<TopologyCase> {};

// The test's own expansion faces +y everywhere (so that the loader is compared to a sound truth).
TEST_P(StripAndFanFeature, SpecExpansionUsedAsTruthFacesUp) {
  const Topology t = GetParam().make();
  const auto list = as_triangles(t.order, t.mode);
  double area = 0.0;
  for (size_t i = 0; i < list.size(); i += 3) {
    const V n = glm::cross(t.vertices[list[i + 1]] - t.vertices[list[i]], t.vertices[list[i + 2]] - t.vertices[list[i]]);
    EXPECT_GE(n.y, 0.0) << "triangle " << i / 3;
    EXPECT_NEAR(n.x, 0.0, 1e-12);
    EXPECT_NEAR(n.z, 0.0, 1e-12);
    area += 0.5 * glm::length(n);
  }
  EXPECT_DOUBLE_EQ(area, 4.0);
}

// The loader turns the strip or fan into the same patches as the equivalent TRIANGLES list: same
// count, same centroids, areas and facing (+y), covering the 2 x 2 floor.
TEST_P(StripAndFanFeature, LoadsTheSamePatchesAsTheEquivalentTriangleList) {
  const Topology t = GetParam().make();
  const LoadResult as_mode = load_gltf_memory(lit_floor(t, GetParam().indexed, false, true).bytes, ".");
  const LoadResult as_list = load_gltf_memory(lit_floor(t, GetParam().indexed, true, true).bytes, ".");
  ASSERT_TRUE(as_mode.document) << as_mode.error;
  ASSERT_TRUE(as_list.document) << as_list.error;
  const auto a = floor_patches(scene_of(*as_mode.document)), b = floor_patches(scene_of(*as_list.document));
  ASSERT_EQ(a.size(), b.size());
  double area = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    for (int k = 0; k < 7; ++k) EXPECT_NEAR(a[i][k], b[i][k], 1e-9) << "patch " << i << " component " << k;
    EXPECT_NEAR(a[i][5], 1.0, 1e-12) << "patch " << i << " does not face +y";
    area += a[i][3];
  }
  EXPECT_NEAR(area, 4.0, 1e-9);
  EXPECT_EQ(triangle_count(*as_mode.document), triangle_count(*as_list.document));
}

// Baked under a lamp in front of it, every output triangle of the floor faces the lamp and is lit
// (a flipped odd strip triangle would face away and stay black), the triangles cover exactly the
// floor's 4 m^2, and the light equals that of the equivalent TRIANGLES primitive.
TEST_P(StripAndFanFeature, BakesToTheFloorAreaLitLikeTheTriangleList) {
  const Topology t = GetParam().make();
  const LitFloor s = lit_floor(t, GetParam().indexed, false, true);
  const Baked mode = bake(s.bytes);
  const Baked list = bake(lit_floor(t, GetParam().indexed, true, true).bytes);
  const auto tris = all_of(baked_node(mode.out, s.floor_node));
  ASSERT_FALSE(tris.empty());
  EXPECT_NEAR(total_area(tris), 4.0, 1e-5);
  EXPECT_NEAR(area_facing(tris, V(0, 1, 0)), 4.0, 1e-5);
  for (size_t i = 0; i < tris.size(); ++i)
    for (int k = 0; k < 3; ++k) ASSERT_GT(tris[i].b[k].x, 0.0) << "triangle " << i << " vertex " << k << " is dark";
  const V lit = mean_radiosity(tris), ref = mean_radiosity(all_of(baked_node(list.out, s.floor_node)));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(lit[c] / ref[c], 1.0, 1e-3) << "channel " << c;
}

// With the lamp behind the floor (on its back side), no light reaches it: winding decides.
TEST_P(StripAndFanFeature, StaysDarkWhenTheLampIsBehindIt) {
  const LitFloor s = lit_floor(GetParam().make(), GetParam().indexed, false, false);
  const Baked b = bake(s.bytes);
  const auto tris = all_of(baked_node(b.out, s.floor_node));
  ASSERT_FALSE(tris.empty());
  EXPECT_NEAR(area_facing(tris, V(0, 1, 0)), 4.0, 1e-5);
  for (const Tri& tri : tris)
    for (int k = 0; k < 3; ++k) ASSERT_EQ(tri.b[k], V(0.0));
}

INSTANTIATE_TEST_SUITE_P(Protocol, StripAndFanFeature,
                         ::testing::Values(TopologyCase{"StripIndexed", floor_strip, true},
                                           TopologyCase{"StripUnindexed", floor_strip, false},
                                           TopologyCase{"FanIndexed", floor_fan, true},
                                           TopologyCase{"FanUnindexed", floor_fan, false}),
                         [](const auto& p) { return std::string(p.param.name); });

// FINDING (README "glTF in": "Triangle pairs that form a planar convex quad (as exporters split
// quads) become one quad patch"): the loader pairs triangles by shared vertex *indices*
// (gltf_load.cpp, by_edge/edge_key), so a non-indexed TRIANGLES primitive, where every triangle has
// vertices of its own, is never merged: a quad given as 6 unindexed vertices stays two triangle
// patches, while the same quad indexed becomes one (and an unindexed strip or fan does merge, since
// consecutive triangles share vertices by position in the sequence). Repro: this test. Bakes differ
// slightly (the unindexed fan above against the same triangles as an unindexed TRIANGLES list: 0.4%
// in the floor's mean light). Enable if pairs should also be found by equal positions (or narrow the
// README's claim to indexed primitives).
TEST(QuadMergeFeature, UnindexedTrianglePairBecomesOneQuadPatchLikeTheIndexedOne) {
  for (bool indexed : {true, false}) {
    SCOPED_TRACE(indexed ? "indexed" : "unindexed");
    Doc d;
    const std::vector<V> q = rect(0, 1, 0, 1, 0, true);
    const json prim = indexed ? d.primitive(q, {0, 1, 2, 0, 2, 3}, kTriangles, d.material(plain_material(V(0.5))))
                              : d.primitive({q[0], q[1], q[2], q[0], q[2], q[3]}, {}, kTriangles, d.material(plain_material(V(0.5))));
    d.node({{"mesh", d.mesh(json::array({prim}))}});
    const LoadResult r = load_gltf_memory(d.gltf_bytes(), ".");
    ASSERT_TRUE(r.document) << r.error;
    ASSERT_EQ(scene_of(*r.document).patches.size(), 1u);
    EXPECT_EQ(scene_of(*r.document).patches[0].corner_count, 4u);
  }
}

// A grid of square tiles sharing their vertices, each split along its diagonal as exporters write
// quads: every pair merges back into its own square. Taking a triangle's edges in order paired
// triangles of neighbouring tiles across the grid's lines instead, into slanted parallelograms two
// tiles wide.
TEST(QuadMergeFeature, TiledGridMergesBackIntoItsSquares) {
  constexpr int nx = 4, nz = 3;
  std::vector<V> points;
  for (int i = 0; i <= nx; ++i)
    for (int j = 0; j <= nz; ++j) points.emplace_back(0.5 * i, 0.0, 0.5 * j);
  auto at = [&](int i, int j) { return static_cast<uint32_t>(i * (nz + 1) + j); };
  std::vector<uint32_t> indices;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < nz; ++j) {
      // As rect(): (x0, z0), (x0, z1), (x1, z1), (x1, z0), facing up.
      const std::array<uint32_t, 4> q{at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)};
      for (int k : {0, 1, 2, 0, 2, 3}) indices.push_back(q[static_cast<size_t>(k)]);
    }
  Doc d;
  d.node({{"mesh", d.mesh(json::array({d.primitive(points, indices, kTriangles, d.material(plain_material(V(0.5))))}))}});
  const LoadResult r = load_gltf_memory(d.gltf_bytes(), ".");
  ASSERT_TRUE(r.document) << r.error;
  const auto& patches = scene_of(*r.document).patches;
  ASSERT_EQ(patches.size(), static_cast<size_t>(nx * nz));
  for (const auto& p : patches) {
    ASSERT_EQ(p.corner_count, 4u);
    for (uint32_t k = 0; k < 4; ++k) {
      const V e = p.corners[(k + 1) % 4] - p.corners[k];
      // Every edge runs along x or z and is one tile long.
      EXPECT_NEAR(std::abs(e.x) + std::abs(e.z), 0.5, 1e-6);
      EXPECT_NEAR(std::min(std::abs(e.x), std::abs(e.z)), 0.0, 1e-6);
    }
  }
}

// ---- 2. Points and lines ------------------------------------------------------------------------

// A mesh with POINTS, LINES, LINE_LOOP and LINE_STRIP primitives besides a quad: the four are skipped
// with a warning that says so, and the quad is loaded and baked alone.
TEST(PrimitiveModeFeature, PointsAndLinesAreSkippedWithAWarning) {
  Doc d;
  const int grey = d.material(plain_material(V(0.6)));
  const int lamp = d.material(lamp_material(V(4.0)));
  const std::vector<V> pts = {V(0, 0.5, 0), V(1, 0.5, 0), V(1, 0.5, 1), V(0, 0.5, 1)};
  json prims = json::array({d.primitive(pts, {}, 0, grey)});
  prims.push_back(d.primitive(pts, {0, 1, 2, 3}, 1, grey));
  prims.push_back(d.primitive(pts, {}, 2, grey));
  prims.push_back(d.primitive(pts, {0, 1, 2}, 3, grey));
  const std::vector<V> floor = rect(0, 2, 0, 2, 0, true);
  prims.push_back(d.primitive(floor, {0, 1, 2, 0, 2, 3}, kTriangles, grey));
  const int node = d.node({{"name", "mixed"}, {"mesh", d.mesh(prims)}});
  d.quad_node(rect(0.5, 1.5, 0.5, 1.5, 1.0, false), lamp);
  const Baked b = bake(d.gltf_bytes());
  ASSERT_TRUE(b.loaded.document);
  EXPECT_TRUE(mentions(b.loaded.warnings, "points") || mentions(b.loaded.warnings, "lines")) << joined(b.loaded.warnings);
  const auto& patches = scene_of(*b.loaded.document).patches;
  EXPECT_EQ(patches.size(), 2u);  // the floor and the lamp, one quad each
  const auto out = baked_node(b.out, node);
  ASSERT_EQ(out.size(), 1u);      // the quad's primitive only
  EXPECT_NEAR(total_area(out[0]), 4.0, 1e-5);
  EXPECT_GT(mean_radiosity(out[0]).x, 0.0);
}

// A file with nothing but lines loads to an error (nothing to bake), not to an empty bake.
TEST(PrimitiveModeFeature, AFileOfOnlyLinesIsRefusedAsHavingNoTriangles) {
  Doc d;
  d.node({{"mesh", d.mesh(json::array({d.primitive({V(0, 0, 0), V(1, 0, 0)}, {}, 1, d.material(plain_material(V(0.5))))}))}});
  const LoadResult r = load_gltf_memory(d.gltf_bytes(), ".");
  EXPECT_FALSE(r.document);
  EXPECT_NE(r.error.find("no triangles"), std::string::npos) << r.error;
}

// ---- 3. Mirrored transforms ---------------------------------------------------------------------

// A floor authored in x in [-2, 0] and mirrored into [0, 2] by its node (scale, a matrix, or a
// mirroring parent): its front side (by the glTF rule for negative determinants) still faces the
// lamp, so it is lit exactly like the same floor authored unmirrored in place.
struct MirrorCase {
  const char* name;
  int how;  // 0: scale (-1, 1, 1); 1: matrix diag(-1, 1, 1); 2: parent scale (-1, 1, 1), child identity
};

struct MirrorScene {
  std::vector<uint8_t> bytes;
  int floor_node = 0;
};

MirrorScene mirror_scene(int how) {
  Doc d;
  const int grey = d.material(plain_material(V(0.6)));
  const int lamp = d.material(lamp_material(V(4.0)));
  MirrorScene s;
  if (how < 0) {
    s.floor_node = d.quad_node(rect(0, 2, 0, 2, 0, true), grey, {{"name", "floor"}});
  } else {
    // Authored counter-clockwise seen from +y in its own frame: the mirror keeps that side the front.
    const std::vector<V> local = rect(-2, 0, 0, 2, 0, true);
    json n = {{"name", "floor"}};
    if (how == 0) n["scale"] = {-1.0, 1.0, 1.0};
    if (how == 1) n["matrix"] = {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    if (how == 2) {
      n["mesh"] = d.mesh(json::array({d.primitive(local, {0, 1, 2, 0, 2, 3}, kTriangles, grey)}));
      s.floor_node = d.node(n, false);
      d.node({{"name", "mirror"}, {"scale", {-1.0, 1.0, 1.0}}, {"children", {s.floor_node}}});
    } else {
      s.floor_node = d.quad_node(local, grey, n);
    }
  }
  d.quad_node(rect(0.5, 1.5, 0.5, 1.5, 1.0, false), lamp, {{"name", "lamp"}});
  s.bytes = d.gltf_bytes();
  return s;
}

class MirroredFloorFeature : public ::testing::TestWithParam<MirrorCase> {};

TEST_P(MirroredFloorFeature, IsLitLikeTheSameFloorUnmirrored) {
  const MirrorScene s = mirror_scene(GetParam().how), ref_scene = mirror_scene(-1);
  const Baked b = bake(s.bytes), ref = bake(ref_scene.bytes);
  ASSERT_TRUE(b.loaded.document);
  // The loader's patch for the floor faces +y in the world.
  for (const auto& p : scene_of(*b.loaded.document).patches)
    if (p.material == 1) {
      EXPECT_GT(glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]).y, 0.0);
    }
  const auto tris = all_of(baked_node(b.out, s.floor_node));
  ASSERT_FALSE(tris.empty());
  // The baked geometry is where the mirror puts it, and covers the floor.
  for (const Tri& t : tris)
    for (const V& p : t.p) {
      ASSERT_GE(p.x, -1e-6);
      ASSERT_LE(p.x, 2.0 + 1e-6);
    }
  EXPECT_NEAR(total_area(tris), 4.0, 1e-5);
  const V lit = mean_radiosity(tris), expected = mean_radiosity(all_of(baked_node(ref.out, ref_scene.floor_node)));
  ASSERT_GT(expected.x, 0.05);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(lit[c] / expected[c], 1.0, 1e-3) << "channel " << c;
}

// BUG (repro: this test, or: bake a floor quad wound counter-clockwise from +y in its node's frame,
// node "scale": [-1, 1, 1], lamp above; read the output triangles back and apply the node's matrix):
// write_baked_glb writes every element counter-clockwise in the *world* (the solver's front) and
// only transforms positions back into the node's frame, so under a mirroring node matrix the output
// triangles are clockwise in the node's frame and, by the glTF rule for negative determinants, their
// front faces away from the light: viewers with back-face culling hide the lit side. The loader swaps
// the winding for mirrored nodes (gltf_load.cpp, `if (mirrored) std::swap(v[1], v[2])`); the writer
// needs the same swap for nodes whose world matrix has a negative determinant. Checked: swapping
// indices 1 and 2 of every output triangle when det(mat3(doc.node_world[node])) < 0, just before the
// primitive is encoded in write_baked_glb, makes this test pass and keeps the rest of protocol_tests
// passing.
TEST_P(MirroredFloorFeature, OutputTrianglesFrontFacesTheLampByTheGltfWindingRule) {
  const MirrorScene s = mirror_scene(GetParam().how);
  const Baked b = bake(s.bytes);
  const auto tris = all_of(baked_node(b.out, s.floor_node));
  ASSERT_FALSE(tris.empty());
  EXPECT_NEAR(area_facing(tris, V(0, 1, 0)), 4.0, 1e-5);
}

INSTANTIATE_TEST_SUITE_P(Protocol, MirroredFloorFeature,
                         ::testing::Values(MirrorCase{"Scale", 0}, MirrorCase{"Matrix", 1}, MirrorCase{"Parent", 2}),
                         [](const auto& p) { return std::string(p.param.name); });

// ---- 4. Double-sided materials ----------------------------------------------------------------

// A unit quad at y = 0 between a lamp above (emitting (4, 2, 1)) and a lamp below ((1, 2, 4)):
// `sides` 2 makes it double-sided, 1 single-sided facing up, -1 single-sided facing down.
struct Sandwich {
  std::vector<uint8_t> bytes;
  int quad_node = 0, quad_material = 0;
};

Sandwich sandwich(int sides) {
  Doc d;
  Sandwich s;
  json m = plain_material(V(0.7, 0.6, 0.5), "two-faced");
  if (sides == 2) m["doubleSided"] = true;
  s.quad_material = d.material(m);
  const int above = d.material(lamp_material(V(4.0, 2.0, 1.0)));
  const int below = d.material(lamp_material(V(1.0, 2.0, 4.0)));
  s.quad_node = d.quad_node(rect(0, 1, 0, 1, 0, sides != -1), s.quad_material, {{"name", "quad"}});
  d.quad_node(rect(0, 1, 0, 1, 0.5, false), above, {{"name", "above"}});
  d.quad_node(rect(0, 1, 0, 1, -0.5, true), below, {{"name", "below"}});
  s.bytes = d.gltf_bytes();
  return s;
}

// Both sides are lit, each by its own lamp, as much as a single-sided quad facing that lamp; the
// output has a front and a back primitive (each covering the quad and facing its lamp), and no
// output material is double-sided (each side is its own primitive).
TEST(DoubleSidedFeature, BothSidesAreLitLikeSingleSidedQuadsFacingEachLamp) {
  const Sandwich two = sandwich(2), up = sandwich(1), down = sandwich(-1);
  const Baked b = bake(two.bytes), ref_up = bake(up.bytes), ref_down = bake(down.bytes);
  const auto prims = baked_node(b.out, two.quad_node);
  ASSERT_EQ(prims.size(), 2u);
  const json& out_prims = b.out.doc["meshes"][b.out.doc["nodes"][two.quad_node]["mesh"].get<int>()]["primitives"];
  for (const json& p : out_prims) EXPECT_EQ(p["material"], two.quad_material);
  for (const json& m : b.out.doc["materials"]) EXPECT_FALSE(m.value("doubleSided", false)) << m.dump();
  // Which primitive is which, by the way its triangles face.
  const bool first_up = area_facing(prims[0], V(0, 1, 0)) > 0.0;
  const std::vector<Tri>& top = prims[first_up ? 0 : 1];
  const std::vector<Tri>& bottom = prims[first_up ? 1 : 0];
  EXPECT_NEAR(area_facing(top, V(0, 1, 0)), 1.0, 1e-5);
  EXPECT_NEAR(area_facing(bottom, V(0, -1, 0)), 1.0, 1e-5);
  const V top_b = mean_radiosity(top), bottom_b = mean_radiosity(bottom);
  const V up_b = mean_radiosity(all_of(baked_node(ref_up.out, up.quad_node)));
  const V down_b = mean_radiosity(all_of(baked_node(ref_down.out, down.quad_node)));
  for (int c = 0; c < 3; ++c) {
    EXPECT_GT(top_b[c], 0.0);
    EXPECT_GT(bottom_b[c], 0.0);
    EXPECT_NEAR(top_b[c] / up_b[c], 1.0, 0.03) << "channel " << c;
    EXPECT_NEAR(bottom_b[c] / down_b[c], 1.0, 0.03) << "channel " << c;
  }
  // The lamps differ, so the sides are not interchangeable: the top is red-heavy, the bottom blue.
  EXPECT_GT(top_b.x / top_b.z, 2.0);
  EXPECT_GT(bottom_b.z / bottom_b.x, 2.0);
}

// A closed box [lo, hi] as one mesh of 12 triangles sharing its 8 corners, wound so that the
// triangles face out (or in).
int box_node(Doc& d, const V& lo, const V& hi, int mat, bool inward, json node = json::object()) {
  const std::vector<V> c = {V(lo.x, lo.y, lo.z), V(hi.x, lo.y, lo.z), V(hi.x, hi.y, lo.z), V(lo.x, hi.y, lo.z),
                            V(lo.x, lo.y, hi.z), V(hi.x, lo.y, hi.z), V(hi.x, hi.y, hi.z), V(lo.x, hi.y, hi.z)};
  // Each face's corners counter-clockwise seen from outside.
  const int faces[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {3, 7, 6, 2}, {0, 4, 7, 3}, {1, 2, 6, 5}};
  std::vector<uint32_t> idx;
  for (const auto& f : faces) {
    const std::array<uint32_t, 6> t = {uint32_t(f[0]), uint32_t(f[1]), uint32_t(f[2]), uint32_t(f[0]), uint32_t(f[2]), uint32_t(f[3])};
    for (size_t k = 0; k < 6; k += 3) {
      idx.push_back(t[k]);
      idx.push_back(inward ? t[k + 2] : t[k + 1]);
      idx.push_back(inward ? t[k + 1] : t[k + 2]);
    }
  }
  node["mesh"] = d.mesh(json::array({d.primitive(c, idx, kTriangles, mat)}));
  return d.node(node);
}

// Area of the triangles whose front faces away from point o (out) or towards it (in).
double area_facing_from(const std::vector<Tri>& tris, const V& o, bool out) {
  double a = 0.0;
  for (const Tri& t : tris)
    if ((glm::dot(t.front, (t.p[0] + t.p[1] + t.p[2]) / 3.0 - o) > 0.0) == out) a += t.area();
  return a;
}

// Blender marks every material double-sided, so a closed box comes with the faces of its inside,
// which no one outside sees; written, they showed through the outside's edges in a viewer's depth
// test as dark dots. A double-sided box (wound either way) under a lamp is written as its outside
// alone, and a double-sided floor (open) with both sides.
TEST(DoubleSidedFeature, ClosedBoxIsWrittenAsItsOutsideAndAnOpenFloorWithBothSides) {
  for (const bool inward : {false, true}) {
    Doc d;
    json m = plain_material(V(0.6), "crate");
    m["doubleSided"] = true;
    const int mat = d.material(m);
    const int floor = d.quad_node(rect(-2, 2, -2, 2, 0, true), mat, {{"name", "floor"}});
    const V lo(-0.5, 0.3, -0.5), hi(0.5, 1.3, 0.5);
    const int box = box_node(d, lo, hi, mat, inward, {{"name", "box"}});
    d.quad_node(rect(-0.5, 0.5, -0.5, 0.5, 2.5, false), d.material(lamp_material(V(4.0))), {{"name", "lamp"}});
    const Baked b = bake(d.gltf_bytes());
    const auto box_tris = all_of(baked_node(b.out, box));
    const V centre = 0.5 * (lo + hi);
    EXPECT_NEAR(area_facing_from(box_tris, centre, true), 6.0, 1e-5) << (inward ? "wound inward" : "wound outward");
    EXPECT_EQ(area_facing_from(box_tris, centre, false), 0.0) << (inward ? "wound inward" : "wound outward");
    EXPECT_GT(mean_radiosity(box_tris).x, 0.0);
    const auto floor_prims = baked_node(b.out, floor);
    ASSERT_EQ(floor_prims.size(), 2u);
    const auto floor_tris = all_of(floor_prims);
    EXPECT_NEAR(area_facing(floor_tris, V(0, 1, 0)), 16.0, 1e-5);
    EXPECT_NEAR(area_facing(floor_tris, V(0, -1, 0)), 16.0, 1e-5);
  }
}

// A room built as one closed double-sided box with its lamp (an emitting quad, or a point light)
// inside: its inside is what is seen, and is written with its outside.
TEST(DoubleSidedFeature, ClosedRoomWithItsLampInsideKeepsItsInside) {
  for (const bool punctual : {false, true}) {
    Doc d;
    json m = plain_material(V(0.6), "room");
    m["doubleSided"] = true;
    const V lo(-2, 0, -2), hi(2, 3, 2);
    const int room = box_node(d, lo, hi, d.material(m), false, {{"name", "room"}});
    if (punctual) {
      d.gltf["extensionsUsed"] = json::array({"KHR_lights_punctual"});
      d.gltf["extensions"]["KHR_lights_punctual"]["lights"] = json::array({json{{"type", "point"}, {"intensity", 20.0}}});
      d.node({{"name", "bulb"}, {"translation", {0.0, 2.0, 0.0}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
    } else {
      d.quad_node(rect(-0.5, 0.5, -0.5, 0.5, 2.9, false), d.material(lamp_material(V(4.0))), {{"name", "lamp"}});
    }
    const Baked b = bake(d.gltf_bytes());
    const auto tris = all_of(baked_node(b.out, room));
    const V centre = 0.5 * (lo + hi);
    const double faces = 2.0 * (16.0 + 12.0 + 12.0);
    EXPECT_NEAR(area_facing_from(tris, centre, false), faces, 1e-4) << (punctual ? "point light" : "lamp");
    EXPECT_NEAR(area_facing_from(tris, centre, true), faces, 1e-4) << (punctual ? "point light" : "lamp");
    std::vector<Tri> inside;
    for (const Tri& t : tris)
      if (glm::dot(t.front, (t.p[0] + t.p[1] + t.p[2]) / 3.0 - centre) < 0.0) inside.push_back(t);
    EXPECT_GT(mean_radiosity(inside).x, 0.01);
  }
}

// Whether a written triangle facing along `n` covers point x (within 1e-4 of its plane).
bool written_over(const std::vector<Tri>& tris, const V& x, const V& n) {
  for (const Tri& t : tris) {
    const V f = glm::normalize(t.front);
    if (glm::dot(f, n) < 0.99 || std::abs(glm::dot(f, x - t.p[0])) > 1e-4) continue;
    bool inside = true;
    for (int k = 0; k < 3 && inside; ++k) inside = glm::dot(glm::cross(t.p[(k + 1) % 3] - t.p[k], x - t.p[k]), f) >= -1e-9;
    if (inside) return true;
  }
  return false;
}

// Walls built as boxes, one's end pressed against the next one's face, and a block standing on the
// floor, as exporters write rooms: the faces pressed against a face that faces them (the wall end,
// the part of the next wall it covers, the floor under the block, the block's bottom) are seen from
// nowhere, and written they lay in the plane of a seen face, where a viewer's depth test showed
// them along the shared edge in dark dots. They are not written; every point of what the room
// shows stays covered.
TEST(BuriedFaceFeature, FacesPressedAgainstAFaceFacingThemAreNotWrittenAndTheRoomHasNoHole) {
  Doc d;
  const int grey = d.material(plain_material(V(0.6), "plaster"));
  const int floor = d.quad_node(rect(-2, 2, -2, 2, 0, true), grey, {{"name", "floor"}});
  const int north = box_node(d, V(-2, 0, -2.2), V(2, 2.5, -2), grey, false, {{"name", "north"}});
  const int west = box_node(d, V(-2, 0, -2), V(-1.8, 2.5, 2), grey, false, {{"name", "west"}});
  const int block = box_node(d, V(0, 0, 0), V(0.5, 0.5, 0.5), grey, false, {{"name", "block"}});
  d.quad_node(rect(-0.5, 0.5, -0.5, 0.5, 2.4, false), d.material(lamp_material(V(4.0))), {{"name", "lamp"}});
  const Baked b = bake(d.gltf_bytes());
  const auto floor_tris = all_of(baked_node(b.out, floor));
  const auto north_tris = all_of(baked_node(b.out, north));
  const auto west_tris = all_of(baked_node(b.out, west));
  const auto block_tris = all_of(baked_node(b.out, block));
  std::vector<Tri> all;
  for (const auto* t : {&floor_tris, &north_tris, &west_tris, &block_tris}) all.insert(all.end(), t->begin(), t->end());
  // The west wall's end (z = -2, facing -z) lies on the north wall's room face; its bottom and the
  // block's lie on the floor.
  EXPECT_EQ(area_facing(west_tris, V(0, 0, -1)), 0.0);
  EXPECT_EQ(area_facing(west_tris, V(0, -1, 0)), 0.0);
  EXPECT_EQ(area_facing(block_tris, V(0, -1, 0)), 0.0);
  // The north wall's room face is written but for the 0.2 m the west wall's end covers, give or take
  // the elements across the end's outline; the floor but for what the west wall and the block stand on.
  const double north_face = area_facing(north_tris, V(0, 0, 1));
  EXPECT_LE(north_face, 4.0 * 2.5 - 0.5 * 0.2 * 2.5);
  EXPECT_GE(north_face, 3.8 * 2.5);
  const double floor_area = area_facing(floor_tris, V(0, 1, 0));
  EXPECT_LE(floor_area, 16.0 - 0.5 * (0.8 + 0.25));
  EXPECT_GE(floor_area, 16.0 - 0.8 - 0.25);
  // No written triangle lies pressed against another written one that faces it.
  for (const Tri& t : all) {
    const V c = (t.p[0] + t.p[1] + t.p[2]) / 3.0;
    EXPECT_FALSE(written_over(all, c, -glm::normalize(t.front))) << "a written face lies on another at " << c.x << ", "
                                                                   << c.y << ", " << c.z;
  }
  // What the room shows is all written: seeded points on the floor, the north and west walls' room
  // faces, the block's top and a side.
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int holes = 0;
  for (int i = 0; i < 400; ++i) {
    const double a = u(rng), c = u(rng);
    const V on_floor(-1.8 + 3.8 * a, 0, -2 + 4 * c);
    if (!(on_floor.x > -1e-3 && on_floor.x < 0.501 && on_floor.z > -1e-3 && on_floor.z < 0.501))
      holes += !written_over(all, on_floor, V(0, 1, 0));
    holes += !written_over(all, V(-1.8 + 3.8 * a, 2.5 * c, -2), V(0, 0, 1));
    holes += !written_over(all, V(-1.8, 2.5 * c, -2 + 4 * a), V(1, 0, 0));
    holes += !written_over(all, V(0.5 * a, 0.5, 0.5 * c), V(0, 1, 0));
    holes += !written_over(all, V(0.5 * a, 0.5 * c, 0.5), V(0, 0, 1));
  }
  EXPECT_EQ(holes, 0);
}

// ---- 4b. Smooth shading -------------------------------------------------------------------------

// A six-sided tube (its sides 60 degrees apart, more than the solver's 30 degree crease) lit from
// one side. Written smooth-shaded, as an exporter does (one vertex with one normal where faces
// meet), its light is one surface's: every point on a vertical edge shows one value whichever face
// is drawn. Written flat (a vertex per face, with the face's normal), the faces keep their own
// values there. Without NORMAL, shared vertices say nothing (glTF shades such faces flat).
TEST(SmoothShadingFeature, SharedVerticesWithNormalsAreOneSmoothSurface) {
  constexpr double kPi = std::numbers::pi;
  auto spread_on_edges = [&](bool shared, bool normals) {
    Doc d;
    const int mat = d.material(plain_material(V(0.6), "tube"));
    std::vector<V> points, normal;
    std::vector<uint32_t> idx;
    auto ring = [&](int k, double y) { return V(0.5 * std::cos(k * kPi / 3), y, 0.5 * std::sin(k * kPi / 3)); };
    auto radial = [&](int k) { return V(std::cos(k * kPi / 3), 0.0, std::sin(k * kPi / 3)); };
    for (int k = 0; k < 6; ++k) {
      const int j = (k + 1) % 6;
      // The side between angles k and j, counter-clockwise seen from outside.
      const std::array<V, 4> c = {ring(k, 0.0), ring(k, 1.0), ring(j, 1.0), ring(j, 0.0)};
      if (shared) {
        if (k == 0)
          for (int m = 0; m < 6; ++m) {
            points.push_back(ring(m, 0.0));
            points.push_back(ring(m, 1.0));
            normal.push_back(radial(m));
            normal.push_back(radial(m));
          }
        const uint32_t a = 2 * k, b = 2 * k + 1, e = 2 * j + 1, f = 2 * j;
        idx.insert(idx.end(), {a, b, e, a, e, f});
      } else {
        const uint32_t base = static_cast<uint32_t>(points.size());
        const V n = glm::normalize(glm::cross(c[1] - c[0], c[3] - c[0]));
        for (const V& x : c) {
          points.push_back(x);
          normal.push_back(n);
        }
        idx.insert(idx.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
      }
    }
    json prim = d.primitive(points, idx, kTriangles, mat);
    if (normals) prim["attributes"]["NORMAL"] = d.positions(normal);
    const int tube = d.node({{"mesh", d.mesh(json::array({prim}))}, {"name", "tube"}});
    d.quad_node({V(2.0, -0.5, -1.0), V(2.0, -0.5, 1.0), V(2.0, 1.5, 1.0), V(2.0, 1.5, -1.0)},
                d.material(lamp_material(V(4.0))), {{"name", "lamp"}});
    const Baked b = bake(d.gltf_bytes());
    // Per point on a vertical edge (angle k * 60 degrees), the values the faces show there.
    std::map<std::array<long, 3>, std::pair<double, double>> seen;
    for (const Tri& t : all_of(baked_node(b.out, tube)))
      for (int c = 0; c < 3; ++c) {
        const V& x = t.p[c];
        const double angle = std::atan2(x.z, x.x) / (kPi / 3);
        if (std::abs(angle - std::round(angle)) > 1e-4 || std::hypot(x.x, x.z) < 0.49) continue;
        const std::array<long, 3> key = {std::lround(x.x * 1e4), std::lround(x.y * 1e4), std::lround(x.z * 1e4)};
        auto [it, fresh] = seen.try_emplace(key, t.b[c].x, t.b[c].x);
        it->second.first = std::min(it->second.first, t.b[c].x);
        it->second.second = std::max(it->second.second, t.b[c].x);
      }
    EXPECT_GE(seen.size(), 12u);
    double worst = 0.0;
    for (const auto& [key, range] : seen) worst = std::max(worst, (range.second - range.first) / std::max(range.second, 1e-12));
    return worst;
  };
  EXPECT_LT(spread_on_edges(true, true), 1e-6);
  EXPECT_GT(spread_on_edges(false, true), 0.05);
  EXPECT_GT(spread_on_edges(true, false), 0.05);
}

// ---- 5. Base colour textures --------------------------------------------------------------------

constexpr uint8_t kTexel[3] = {200, 120, 60};  // sRGB bytes

// A 4 x 4 RGBA image (row-major, 64 bytes) as PNG bytes.
std::vector<uint8_t> png_4x4(const std::vector<uint8_t>& pixels) {
  std::vector<uint8_t> png;
  stbi_write_png_to_func(
      [](void* ctx, void* data, int size) {
        auto* out = static_cast<std::vector<uint8_t>*>(ctx);
        out->insert(out->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
      },
      &png, 4, 4, 4, pixels.data(), 16);
  return png;
}

std::vector<uint8_t> uniform_png() {
  std::vector<uint8_t> pixels;
  for (int i = 0; i < 4 * 4; ++i) pixels.insert(pixels.end(), {kTexel[0], kTexel[1], kTexel[2], 255});
  return png_4x4(pixels);
}

struct TexturedScene {
  std::vector<uint8_t> bytes;
  int floor_node = 0;
};

// A floor with UVs under a lamp; its base colour from the PNG (factor 1) or from a factor alone.
TexturedScene textured_floor(bool textured, const std::vector<uint8_t>& png) {
  Doc d;
  TexturedScene s;
  json m;
  if (textured) {
    const int view = d.view(png.data(), png.size());
    d.gltf["images"] = json::array({json{{"bufferView", view}, {"mimeType", "image/png"}, {"name", "swatch"}}});
    d.gltf["samplers"] = json::array({json{{"magFilter", 9728}, {"minFilter", 9728}}});
    d.gltf["textures"] = json::array({json{{"source", 0}, {"sampler", 0}}});
    m = {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}};
  } else {
    m = plain_material(V(srgb_to_linear(kTexel[0] / 255.0), srgb_to_linear(kTexel[1] / 255.0), srgb_to_linear(kTexel[2] / 255.0)));
  }
  const int floor_mat = d.material(m);
  const int lamp = d.material(lamp_material(V(4.0)));
  s.floor_node = d.quad_node(rect(0, 2, 0, 2, 0, true), floor_mat, {{"name", "floor"}}, {UV(0, 0), UV(0, 1), UV(1, 1), UV(1, 0)});
  d.quad_node(rect(0.5, 1.5, 0.5, 1.5, 1.0, false), lamp, {{"name", "lamp"}});
  s.bytes = d.gltf_bytes();
  return s;
}

// A uniform texture reflects like the factor of its sRGB-decoded colour (the light on the floor
// agrees within 1% per channel; taking the bytes as linear would be 36% to 5 times off).
TEST(BaseColorTextureFeature, UniformTextureReflectsLikeItsDecodedColourAsAFactor) {
  const std::vector<uint8_t> png = uniform_png();
  const TexturedScene tex = textured_floor(true, png), plain = textured_floor(false, png);
  const Baked a = bake(tex.bytes), b = bake(plain.bytes);
  ASSERT_TRUE(a.loaded.document && b.loaded.document);
  const V ta = mean_radiosity(all_of(baked_node(a.out, tex.floor_node)));
  const V tb = mean_radiosity(all_of(baked_node(b.out, plain.floor_node)));
  for (int c = 0; c < 3; ++c) {
    ASSERT_GT(tb[c], 0.0);
    EXPECT_NEAR(ta[c] / tb[c], 1.0, 0.01) << "channel " << c;
  }
  // The reflectance itself, as the solver sees it.
  for (const auto& p : scene_of(*a.loaded.document).patches)
    if (p.material == 1) {
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(p.reflectance[c], srgb_to_linear(kTexel[c] / 255.0), 1e-9);
    }
}

// The output keeps the image (its bytes unchanged, in the GLB), the texture, the sampler, the
// material's reference to it, and TEXCOORD_0 on the baked primitive, plain and Draco-compressed.
TEST(BaseColorTextureFeature, OutputKeepsTheImageBytesTextureSamplerAndUvs) {
  const std::vector<uint8_t> png = uniform_png();
  const TexturedScene tex = textured_floor(true, png);
  for (bool draco : {false, true}) {
    SCOPED_TRACE(draco ? "draco" : "plain");
    const Baked b = bake(tex.bytes, draco);
    const json& g = b.out.doc;
    ASSERT_EQ(g.value("images", json::array()).size(), 1u);
    ASSERT_EQ(g.value("textures", json::array()).size(), 1u);
    ASSERT_EQ(g.value("samplers", json::array()).size(), 1u);
    EXPECT_EQ(g["textures"][0]["source"], 0);
    EXPECT_EQ(g["textures"][0]["sampler"], 0);
    EXPECT_EQ(g["samplers"][0].value("magFilter", 0), 9728);
    const json& image = g["images"][0];
    EXPECT_FALSE(image.contains("uri"));
    EXPECT_EQ(image.value("mimeType", ""), "image/png");
    ASSERT_TRUE(image.contains("bufferView"));
    const json& view = g["bufferViews"][image["bufferView"].get<int>()];
    const size_t at = view.value("byteOffset", 0), len = view["byteLength"].get<size_t>();
    ASSERT_LE(at + len, b.out.bin.size());
    EXPECT_EQ(std::vector<uint8_t>(b.out.bin.begin() + at, b.out.bin.begin() + at + len), png);
    const json& node = g["nodes"][tex.floor_node];
    const json& prim = g["meshes"][node["mesh"].get<int>()]["primitives"][0];
    EXPECT_EQ(g["materials"][prim["material"].get<int>()]["pbrMetallicRoughness"]["baseColorTexture"]["index"], 0);
    ASSERT_TRUE(prim["attributes"].contains("TEXCOORD_0"));
    const Primitive d = read_primitive(b.out, prim);
    EXPECT_EQ(d.uv.size(), d.positions.size());
  }
}

// ---- 6. Material extras -------------------------------------------------------------------------

struct PanelScene {
  std::vector<uint8_t> bytes;
  int floor_node = 0;
};

// A floor under a panel; `panel` and `floor` are the two materials.
PanelScene panel_scene(const json& floor, const json& panel) {
  Doc d;
  PanelScene s;
  const int f = d.material(floor);
  const int p = d.material(panel);
  s.floor_node = d.quad_node(rect(0, 2, 0, 2, 0, true), f, {{"name", "floor"}});
  d.quad_node(rect(0.5, 1.5, 0.5, 1.5, 1.0, false), p, {{"name", "panel"}});
  s.bytes = d.gltf_bytes();
  return s;
}

json with_extras(json m, const json& hemibake) {
  m["extras"]["hemibake"] = hemibake;
  return m;
}

// A plain, non-emissive panel with extras.hemibake.emission lights the floor exactly as the same
// emission given by emissiveFactor x emissiveStrength.
TEST(MaterialExtrasFeature, EmissionOverrideMakesAPlainMaterialALight) {
  const json floor = plain_material(V(0.6));
  const PanelScene over = panel_scene(floor, with_extras(plain_material(V(0.0), "panel"), {{"emission", {3.0, 2.0, 1.0}}}));
  const PanelScene ref = panel_scene(floor, lamp_material(V(3.0, 2.0, 1.0)));
  const Baked a = bake(over.bytes), b = bake(ref.bytes);
  const V la = mean_radiosity(all_of(baked_node(a.out, over.floor_node)));
  const V lb = mean_radiosity(all_of(baked_node(b.out, ref.floor_node)));
  for (int c = 0; c < 3; ++c) {
    ASSERT_GT(lb[c], 0.0);
    EXPECT_NEAR(la[c] / lb[c], 1.0, 0.01) << "channel " << c;
  }
}

// extras.hemibake.reflectance replaces the base colour for the bake: a white floor overridden to
// (0.2, 0.4, 0.6) is lit like a floor of that base colour.
TEST(MaterialExtrasFeature, ReflectanceOverrideReplacesTheBaseColourInTheBake) {
  const json lamp = lamp_material(V(4.0));
  const PanelScene over = panel_scene(with_extras(plain_material(V(0.9), "floor"), {{"reflectance", {0.2, 0.4, 0.6}}}), lamp);
  const PanelScene ref = panel_scene(plain_material(V(0.2, 0.4, 0.6)), lamp);
  const Baked a = bake(over.bytes), b = bake(ref.bytes);
  ASSERT_TRUE(a.loaded.document);
  for (const auto& p : scene_of(*a.loaded.document).patches)
    if (p.material == 1) {
      EXPECT_EQ(p.reflectance, V(0.2, 0.4, 0.6));
    }
  const V la = mean_radiosity(all_of(baked_node(a.out, over.floor_node)));
  const V lb = mean_radiosity(all_of(baked_node(b.out, ref.floor_node)));
  for (int c = 0; c < 3; ++c) {
    ASSERT_GT(lb[c], 0.0);
    EXPECT_NEAR(la[c] / lb[c], 1.0, 0.01) << "channel " << c;
  }
}

struct BadExtras {
  const char* name;
  const char* hemibake;  // JSON of extras.hemibake
};

class MalformedExtrasFeature : public ::testing::TestWithParam<BadExtras> {};

// A malformed override is refused, and the error names the material (index and name) and the field.
TEST_P(MalformedExtrasFeature, IsRefusedWithAnErrorNamingTheMaterial) {
  const json panel = with_extras(lamp_material(V(2.0)), json::parse(GetParam().hemibake));
  json named = panel;
  named["name"] = "glowing panel";
  const PanelScene s = panel_scene(plain_material(V(0.6)), named);
  const LoadResult r = load_gltf_memory(s.bytes, ".");
  EXPECT_FALSE(r.document);
  EXPECT_NE(r.error.find("material 1"), std::string::npos) << r.error;
  EXPECT_NE(r.error.find("glowing panel"), std::string::npos) << r.error;
  const std::string field = json::parse(GetParam().hemibake).begin().key();
  EXPECT_NE(r.error.find(field), std::string::npos) << r.error;
}

INSTANTIATE_TEST_SUITE_P(
    Protocol, MalformedExtrasFeature,
    ::testing::Values(BadExtras{"ReflectanceTooShort", R"({"reflectance": [0.5, 0.5]})"},
                      BadExtras{"ReflectanceTooLong", R"({"reflectance": [0.5, 0.5, 0.5, 1.0]})"},
                      BadExtras{"ReflectanceNotNumbers", R"({"reflectance": ["red", 0.5, 0.5]})"},
                      BadExtras{"ReflectanceNotAnArray", R"({"reflectance": 0.5})"},
                      BadExtras{"EmissionTooShort", R"({"emission": [1.0, 1.0]})"},
                      BadExtras{"EmissionTooLong", R"({"emission": [1.0, 1.0, 1.0, 1.0]})"},
                      BadExtras{"EmissionNegative", R"({"emission": [1.0, -0.5, 1.0]})"},
                      BadExtras{"EmissionNotNumbers", R"({"emission": [1.0, null, 1.0]})"}),
    [](const auto& p) { return std::string(p.param.name); });

// ---- 7. emissiveStrength as an integer; KHR_lights_punctual -------------------------------------

solver::Scene lamp_patches(const json& strength) {
  Doc d;
  json m = plain_material(V(0.5));
  m["emissiveFactor"] = {1.0, 0.5, 0.25};
  m["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] = strength;
  d.quad_node(rect(0, 1, 0, 1, 0, true), d.material(m));
  const LoadResult r = load_gltf_memory(d.gltf_bytes(), ".");
  EXPECT_TRUE(r.document) << r.error;
  return r.document ? scene_of(*r.document) : solver::Scene{};
}

// JSON has one number type: "emissiveStrength": 3 is the same as 3.0 (radiance = factor x 3, so
// the emitted exitance is pi times that).
TEST(EmissiveStrengthFeature, IntegerStrengthWorksLikeTheSameRealNumber) {
  ASSERT_EQ(json(3).dump(), "3");
  ASSERT_EQ(json(3.0).dump(), "3.0");
  const solver::Scene as_int = lamp_patches(json(3)), as_real = lamp_patches(json(3.0));
  ASSERT_EQ(as_int.patches.size(), 1u);
  ASSERT_EQ(as_real.patches.size(), 1u);
  const V exitance = std::numbers::pi * V(3.0, 1.5, 0.75);
  for (int c = 0; c < 3; ++c) {
    EXPECT_DOUBLE_EQ(as_int.patches[0].emission[c], exitance[c]);
    EXPECT_DOUBLE_EQ(as_real.patches[0].emission[c], exitance[c]);
  }
}

// Lambert's formula: the form factor from a point with unit normal n to a polygon (no occlusion).
double lambert_form_factor(const V& x, const V& n, const std::vector<V>& poly) {
  double sum = 0.0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const V a = glm::normalize(poly[i] - x), b = glm::normalize(poly[(i + 1) % poly.size()] - x);
    const V c = glm::cross(a, b);
    const double len = glm::length(c);
    if (len == 0.0) continue;
    sum += std::atan2(len, glm::dot(a, b)) * glm::dot(n, c) / len;
  }
  return std::abs(sum) / (2.0 * std::numbers::pi);
}

// KHR_lights_punctual lights are light sources: placed by their nodes, in candela and lux as
// given. Measured as a viewer shows the output: vertex radiosity interpolated over the output's
// triangles at random points.

// Points spread uniformly by area over `tris`, with the radiosity interpolated there.
std::vector<std::pair<V, V>> sample_tris(const std::vector<Tri>& tris, int count, std::mt19937_64& rng) {
  std::vector<double> cumulative;
  double total = 0.0;
  for (const Tri& t : tris) cumulative.push_back(total += t.area());
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<std::pair<V, V>> out;
  for (int i = 0; i < count && total > 0.0; ++i) {
    const size_t k = std::min(tris.size() - 1, static_cast<size_t>(std::lower_bound(cumulative.begin(), cumulative.end(), u(rng) * total) - cumulative.begin()));
    double a = u(rng), b = u(rng);
    if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b;
    const Tri& t = tris[k];
    out.emplace_back((1 - a - b) * t.p[0] + a * t.p[1] + b * t.p[2], (1 - a - b) * t.b[0] + a * t.b[1] + b * t.b[2]);
  }
  return out;
}

// Median and 90th percentile of the relative error of channel c against `truth`.
std::pair<double, double> errors_against(const std::vector<std::pair<V, V>>& samples, int c,
                                         const std::function<V(const V&)>& truth) {
  std::vector<double> err;
  for (const auto& [x, b] : samples) err.push_back(std::abs(b[c] / truth(x)[c] - 1.0));
  std::sort(err.begin(), err.end());
  return {err[err.size() / 2], err[err.size() * 9 / 10]};
}

void add_lights(Doc& d, json lights) {
  d.gltf["extensionsUsed"] = json::array({"KHR_lights_punctual"});
  d.gltf["extensionsRequired"] = json::array({"KHR_lights_punctual"});  // as Blender's exporter writes it
  d.gltf["extensions"]["KHR_lights_punctual"]["lights"] = std::move(lights);
}

json light_ref(int light) { return {{"KHR_lights_punctual", {{"light", light}}}}; }

// A point light on a child of a scaled, translated node: at the child's world position, with the
// colour times the intensity in candela (scale does not change it).
TEST(PunctualLightsFeature, PointLightOnANestedNodeLightsAnOpenFloorAsIHOverDCubed) {
  const uint64_t seed = test::test_seed();
  std::mt19937_64 rng(seed);
  Doc d;
  const double rho = 0.6, intensity = 5.0;
  const V colour(1.0, 0.5, 0.25);
  const int floor = d.quad_node(rect(-1, 1, -1, 1, 0, true), d.material(plain_material(V(rho))), {{"name", "floor"}});
  add_lights(d, json::array({json{{"type", "point"}, {"intensity", intensity}, {"color", {colour.x, colour.y, colour.z}}, {"name", "bulb"}}}));
  const int child = d.node({{"name", "bulb"}, {"translation", {0.1, 0.4, -0.1}}, {"extensions", light_ref(0)}}, false);
  d.node({{"name", "holder"}, {"translation", {0.2, 0.0, 0.0}}, {"scale", {2.0, 2.0, 2.0}}, {"children", {child}}});
  const V pos(0.4, 0.8, -0.2);
  solver::Params params;  // the defaults: the accuracy a user gets
  const Baked b = bake(d.gltf_bytes(), false, params);
  ASSERT_TRUE(b.loaded.document);
  ASSERT_EQ(scene_of(*b.loaded.document).lights.size(), 1u);
  const auto samples = sample_tris(all_of(baked_node(b.out, floor)), 3000, rng);
  auto truth = [&](const V& x) {
    const double dist = glm::length(pos - x);
    return rho * intensity * colour * pos.y / (dist * dist * dist);
  };
  for (int c = 0; c < 3; ++c) {
    const auto [median, p90] = errors_against(samples, c, truth);
    EXPECT_LE(median, 0.02) << "channel " << c << ", " << test::seed_note(seed);
    EXPECT_LE(p90, 0.05) << "channel " << c << ", " << test::seed_note(seed);
  }
  // The output bakes the light in and does not carry it (a viewer would light the floor twice).
  const json used = b.out.doc.value("extensionsUsed", json::array());
  EXPECT_EQ(std::find(used.begin(), used.end(), "KHR_lights_punctual"), used.end());
  EXPECT_NE(b.out.doc["asset"]["extras"]["hemibake"]["radiosity"].get<std::string>().find("exitance"), std::string::npos);
}

// A spot light points along its node's -Z: a node turned -90 degrees about x points it down.
TEST(PunctualLightsFeature, SpotLightPointsAlongItsNodesMinusZ) {
  Doc d;
  const double rho = 0.5;
  const int floor = d.quad_node(rect(-1.5, 1.5, -1.5, 1.5, 0, true), d.material(plain_material(V(rho))), {{"name", "floor"}});
  add_lights(d, json::array({json{{"type", "spot"}, {"intensity", 4.0}, {"spot", {{"innerConeAngle", 0.2}, {"outerConeAngle", 0.4}}}}}));
  d.node({{"translation", {0.0, 1.0, 0.0}}, {"rotation", {-std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5)}}, {"extensions", light_ref(0)}});
  const Baked b = bake(d.gltf_bytes());
  ASSERT_TRUE(b.loaded.document);
  const auto& lights = scene_of(*b.loaded.document).lights;
  ASSERT_EQ(lights.size(), 1u);
  EXPECT_NEAR(lights[0].direction.y, -1.0, 1e-9);
  // Under the light, about rho I / h^2; a metre to the side (45 degrees off the axis), dark.
  double centre = 0.0, side = 0.0;
  for (const Tri& t : all_of(baked_node(b.out, floor)))
    for (int k = 0; k < 3; ++k) {
      const double r = std::hypot(t.p[k].x, t.p[k].z);
      if (r < 0.05) centre = std::max(centre, t.b[k].x);
      if (r > 1.0) side = std::max(side, t.b[k].x);
    }
  EXPECT_NEAR(centre / (rho * 4.0), 1.0, 0.05);
  EXPECT_EQ(side, 0.0);
}

// An emissive panel of radiance L and a point light in one file: the floor gets
// rho (pi L F(x -> panel) + I cos / d^2), the two in one unit.
TEST(PunctualLightsFeature, EmissivePanelAndPointLightShareOneUnit) {
  const uint64_t seed = test::test_seed();
  std::mt19937_64 rng(seed);
  Doc d;
  const double rho = 0.5, exitance = 6.0, intensity = 1.5;
  const int floor = d.quad_node(rect(-1, 1, -1, 1, 0, true), d.material(plain_material(V(rho))), {{"name", "floor"}});
  d.quad_node(rect(-0.5, 0.5, -0.5, 0.5, 1.0, false), d.material(lamp_material(V(exitance))), {{"name", "panel"}});
  add_lights(d, json::array({json{{"type", "point"}, {"intensity", intensity}}}));
  const V pos(0.8, 0.6, 0.3);
  d.node({{"translation", {pos.x, pos.y, pos.z}}, {"extensions", light_ref(0)}});
  solver::Params params;
  const Baked b = bake(d.gltf_bytes(), false, params);
  ASSERT_TRUE(b.loaded.document);
  const std::vector<V> panel = {V(-0.5, 1, -0.5), V(0.5, 1, -0.5), V(0.5, 1, 0.5), V(-0.5, 1, 0.5)};
  auto truth = [&](const V& x) {
    const double dist = glm::length(pos - x);
    return V(rho * (exitance * lambert_form_factor(x, V(0, 1, 0), panel) + intensity * pos.y / (dist * dist * dist)));
  };
  const auto [median, p90] = errors_against(sample_tris(all_of(baked_node(b.out, floor)), 3000, rng), 0, truth);
  // The panel's own share is as accurate as the patch solver makes it; a factor pi between the
  // two would put the sum a quarter or more off.
  EXPECT_LE(median, 0.05) << test::seed_note(seed);
  EXPECT_LE(p90, 0.12) << test::seed_note(seed);
}

// An emitter with a dark base colour (lava: dark rock, glowing) is shown by its emission: its output
// material's base colour is the emissive factor's hue, and base colour x COLOR_0 is exposure x
// radiosity (through the recorded tone curve), as bright as the light it gives, brighter than the
// floor it lights.
TEST(EmitterDisplayFeature, DarkEmitterShowsItsEmissionNotItsBaseColour) {
  Doc d;
  const int floor = d.quad_node(rect(-1, 1, -1, 1, 0, true), d.material(plain_material(V(0.6))), {{"name", "floor"}});
  json lava = plain_material(V(0.05, 0.04, 0.04), "lava");
  lava["emissiveFactor"] = {1.0, 0.3, 0.05};
  lava["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] = 2.0;
  const int lava_mat = d.material(lava);
  const int lamp = d.quad_node(rect(-0.3, 0.3, -0.3, 0.3, 0.8, false), lava_mat, {{"name", "lava"}});
  const Baked b = bake(d.gltf_bytes());
  const json& mat = b.out.doc["materials"][lava_mat];
  const json factor = mat["pbrMetallicRoughness"]["baseColorFactor"];
  EXPECT_NEAR(factor[0].get<double>(), 1.0, 1e-9);
  EXPECT_NEAR(factor[1].get<double>(), 0.3, 1e-9);
  EXPECT_NEAR(factor[2].get<double>(), 0.05, 1e-9);
  const double exposure = b.out.doc["asset"]["extras"]["hemibake"]["exposure"].get<double>();
  const test::RecordedTone tone = test::recorded_tone(b.out.doc);
  auto shown = [&](int node) {
    std::vector<V> out;
    const json& n = b.out.doc["nodes"][node];
    for (const json& prim : b.out.doc["meshes"][n["mesh"].get<int>()]["primitives"]) {
      const json f = b.out.doc["materials"][prim["material"].get<int>()]["pbrMetallicRoughness"]["baseColorFactor"];
      const V base(f[0].get<double>(), f[1].get<double>(), f[2].get<double>());
      const Primitive p = read_primitive(b.out, prim);
      for (size_t i = 0; i < p.colors.size(); ++i) {
        const V v = base * p.colors[i];
        out.push_back(v);
        const V expected = base * test::documented_color(tone, exposure * p.radiosity[i] / base);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(v[c], expected[c], 2e-3) << "vertex " << i;
      }
    }
    return out;
  };
  const std::vector<V> lava_shown = shown(lamp), floor_shown = shown(floor);
  ASSERT_FALSE(lava_shown.empty());
  double floor_max = 0.0;
  for (const V& v : floor_shown) floor_max = std::max(floor_max, v.x);
  for (const V& v : lava_shown) EXPECT_GE(v.x, floor_max);  // red channel: as bright as anything lit
  EXPECT_NEAR(lava_shown[0].x, 1.0, 1e-3);                   // full red, where dark rock was 0.05
}

// COLOR_0's highlights (README, "GLB out"). A point light of known intensity over two small grey
// panels beside each other at different heights, and a floor far below: the panels' irradiance is
// I h / r^3 at their centres, 1.3 times apart, and an explicit exposure puts both far above the
// knee (the nearer at the scene's brightest), the floor below it. A third panel, lower, lies on the
// shoulder's first stretch, where no channel reaches 1.
struct HighlightScene {
  Doc d;
  int floor = -1, near = -1, far = -1, mid = -1;
  double exposure = 0.0;
  double ratio = 0.0;  ///< near panel's irradiance over the far one's, at their centres
};

HighlightScene highlight_scene() {
  HighlightScene s;
  const V light(0.0, 3.0, 0.0), colour(1.0, 0.9, 0.8);
  const double intensity = 100.0;
  const int grey = s.d.material(plain_material(V(0.8), "grey")), ground = s.d.material(plain_material(V(0.5), "ground"));
  s.floor = s.d.quad_node(rect(-2, 2, -2, 2, 0, true), ground, {{"name", "floor"}});
  s.near = s.d.quad_node(rect(-0.35, -0.25, -0.05, 0.05, 2.0, true), grey, {{"name", "near"}});
  s.far = s.d.quad_node(rect(0.25, 0.35, -0.05, 0.05, 1.84, true), grey, {{"name", "far"}});
  s.mid = s.d.quad_node(rect(-0.05, 0.05, 0.25, 0.35, 1.0, true), grey, {{"name", "mid"}});
  add_lights(s.d, json::array({json{{"type", "point"}, {"intensity", intensity}, {"color", {colour.x, colour.y, colour.z}}}}));
  s.d.node({{"translation", {light.x, light.y, light.z}}, {"extensions", light_ref(0)}});
  auto irradiance = [&](const V& x) {
    const double r = glm::length(light - x);
    return intensity * (light.y - x.y) / (r * r * r);
  };
  s.ratio = irradiance(V(-0.3, 2.0, 0.0)) / irradiance(V(0.3, 1.84, 0.0));
  // The near panel's light (mean of the channels) at its centre becomes 4, 5.7 times the knee.
  s.exposure = 4.0 / (irradiance(V(-0.3, 2.0, 0.0)) * (colour.x + colour.y + colour.z) / 3.0);
  return s;
}

// Bakes `d` with `spec` and reads the GLB back.
Baked bake_spec(const Doc& d, const JobSpec& spec) {
  Baked r;
  r.loaded = load_gltf_memory(d.gltf_bytes(), ".");
  EXPECT_TRUE(r.loaded.document) << r.loaded.error;
  if (!r.loaded.document) return r;
  const BakeOutput w = protocol::bake(*r.loaded.document, spec);
  EXPECT_EQ(w.error, "");
  const auto parts = test::split_glb(w.glb);
  EXPECT_TRUE(parts.has_value());
  if (parts) r.out = {parts->gltf, parts->bin};
  return r;
}

Baked bake_with(const HighlightScene& s, Tone tone) {
  JobSpec spec;
  spec.params = quick_params();
  spec.write.draco = false;  // uint16 COLOR_0 exactly as written
  spec.write.exposure = s.exposure;
  spec.write.tone = tone;
  return bake_spec(s.d, spec);
}

// A node's vertices: base colour, exposed light (exposure x radiosity / base) and COLOR_0.
struct Shown {
  V base, light, color;
};

std::vector<Shown> shown_vertices(const Baked& b, int node, double exposure) {
  std::vector<Shown> out;
  const json& n = b.out.doc["nodes"][node];
  for (const json& prim : b.out.doc["meshes"][n["mesh"].get<int>()]["primitives"]) {
    const json f = b.out.doc["materials"][prim["material"].get<int>()]["pbrMetallicRoughness"]["baseColorFactor"];
    const V base(f[0].get<double>(), f[1].get<double>(), f[2].get<double>());
    const Primitive p = read_primitive(b.out, prim);
    for (size_t i = 0; i < p.colors.size(); ++i) out.push_back({base, exposure * p.radiosity[i] / base, p.colors[i]});
  }
  return out;
}

V mean_of(const std::vector<Shown>& v, V Shown::*what) {
  V sum(0.0);
  for (const Shown& s : v) sum += s.*what;
  return v.empty() ? sum : sum / static_cast<double>(v.size());
}

double mean3(const V& v) { return (v.x + v.y + v.z) / 3.0; }

TEST(HighlightFeature, SurfacesLitFarAboveTheKneeStayApartInOrder) {
  const HighlightScene s = highlight_scene();
  ASSERT_GE(s.ratio, 1.3);
  const Baked b = bake_with(s, Tone::kShoulder);
  ASSERT_TRUE(b.loaded.document);
  const test::RecordedTone tone = test::recorded_tone(b.out.doc);
  ASSERT_TRUE(tone.shoulder);
  EXPECT_EQ(b.out.doc["asset"]["extras"]["hemibake"]["exposure"].get<double>(), s.exposure);  // as asked
  const auto floor = shown_vertices(b, s.floor, s.exposure), near = shown_vertices(b, s.near, s.exposure),
             far = shown_vertices(b, s.far, s.exposure), mid = shown_vertices(b, s.mid, s.exposure);
  ASSERT_FALSE(floor.empty());
  ASSERT_FALSE(mid.empty());
  ASSERT_FALSE(near.empty());
  ASSERT_FALSE(far.empty());
  // The panels' baked light is the closed form's: 1.3 times apart, both far above the knee.
  const V near_light = mean_of(near, &Shown::light), far_light = mean_of(far, &Shown::light);
  EXPECT_NEAR(mean3(near_light) / mean3(far_light), s.ratio, 0.03 * s.ratio);
  EXPECT_GT(mean3(far_light), 3.0 * tone.knee);
  // White is the brightest vertex's light (mean of the channels) on the surfaces, none of which
  // emits; it reaches 1 there.
  double brightest = 0.0;
  for (const auto* v : {&floor, &near, &far, &mid})
    for (const Shown& x : *v) brightest = std::max(brightest, mean3(x.light));
  EXPECT_NEAR(tone.white, brightest, 1e-5 * brightest);
  EXPECT_LT(tone.knee, 1.0);
  // Every COLOR_0 in [0, 1] and as the recorded curve makes it from _RADIOSITY; below the knee it
  // is the asked exposure times the light, as before the curve.
  size_t below = 0;
  for (const auto* v : {&floor, &near, &far, &mid})
    for (const Shown& x : *v) {
      const V expected = test::documented_color(tone, x.light);
      for (int c = 0; c < 3; ++c) {
        ASSERT_GE(x.color[c], 0.0);
        ASSERT_LE(x.color[c], 1.0);
        ASSERT_NEAR(x.color[c], expected[c], 1e-4);
      }
      if (mean3(x.light) < tone.knee && std::max({x.light.x, x.light.y, x.light.z}) <= 1.0) {
        ++below;
        for (int c = 0; c < 3; ++c) ASSERT_NEAR(x.color[c], x.light[c], 1e-4);
      }
    }
  EXPECT_GT(below, floor.size() / 2);
  // The nearer panel shows brighter, no channel darker, and far enough apart to see in three.js's
  // 8-bit sRGB output (base colour x COLOR_0) where the clamp showed both at the base colour.
  const V near_shown = 0.8 * mean_of(near, &Shown::color), far_shown = 0.8 * mean_of(far, &Shown::color);
  int steps = 0;
  for (int c = 0; c < 3; ++c) {
    EXPECT_GE(near_shown[c], far_shown[c]) << "channel " << c;
    steps = std::max(steps, test::srgb8(near_shown[c]) - test::srgb8(far_shown[c]));
  }
  EXPECT_GT(mean3(near_shown), mean3(far_shown));
  EXPECT_GE(steps, 2) << "near " << near_shown.x << "," << near_shown.y << "," << near_shown.z << " far " << far_shown.x
                      << "," << far_shown.y << "," << far_shown.z;
  // The recorded numbers invert COLOR_0 to the light wherever no channel is 1: on the middle
  // panel, above the knee, too.
  size_t inverted = 0;
  for (const auto* v : {&floor, &near, &far, &mid})
    for (const Shown& x : *v) {
      if (std::max({x.color.x, x.color.y, x.color.z}) >= 1.0) continue;
      const V back = test::documented_light(tone, x.color);
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(back[c], x.light[c], 2e-3 * (x.light[c] + 0.01));
      inverted += mean3(x.light) > tone.knee;
    }
  EXPECT_GE(inverted, mid.size());
}

// tone=clamp keeps the linear clip: COLOR_0 = min(1, exposure x light) per channel, which shows the
// two panels alike in the channel that clips.
TEST(HighlightFeature, ClampToneKeepsTheLinearClip) {
  const HighlightScene s = highlight_scene();
  const Baked b = bake_with(s, Tone::kClamp);
  ASSERT_TRUE(b.loaded.document);
  EXPECT_EQ(b.out.doc["asset"]["extras"]["hemibake"]["tone"]["curve"], "clamp");
  EXPECT_FALSE(test::recorded_tone(b.out.doc).shoulder);
  for (int node : {s.floor, s.near, s.far})
    for (const Shown& x : shown_vertices(b, node, s.exposure))
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(x.color[c], std::min(1.0, x.light[c]), 1e-4);
  const V near = mean_of(shown_vertices(b, s.near, s.exposure), &Shown::color),
          far = mean_of(shown_vertices(b, s.far, s.exposure), &Shown::color);
  EXPECT_EQ(near.y, 1.0);
  EXPECT_EQ(far.y, 1.0);
}

// The automatic exposure (README, "GLB out"; protocol::key_exposure).

// A square plate of side 2 h centred at c, its front facing n, two of its edges along u (u and n
// orthogonal unit vectors), corners counter-clockwise seen from the front.
std::vector<V> plate(const V& c, const V& n, const V& u, double h) {
  const V w = glm::cross(n, u);  // cross(u, w) = n
  return {c - h * u - h * w, c + h * u - h * w, c + h * u + h * w, c - h * u + h * w};
}

// An open floor under a uniform sky of radiance s receives E = pi s from every direction it sees
// (nothing else is there), so its light is the same everywhere: the exposure puts it at the key,
// kExposureKey / (pi mean(s)), and COLOR_0 is the key times the sky's hue.
TEST(ExposureFeature, UniformSkyLightMapsToTheKey) {
  Doc d;
  const V sky(0.5, 0.4, 0.3), base(0.7, 0.6, 0.5);
  const int floor = d.quad_node(rect(-1, 1, -1, 1, 0, true), d.material(plain_material(base, "floor")), {{"name", "floor"}});
  JobSpec spec;
  spec.params = quick_params();
  spec.write.draco = false;
  spec.sky = sky;
  const Baked b = bake_spec(d, spec);
  ASSERT_TRUE(b.loaded.document);
  const double expected = kExposureKey / (std::numbers::pi * mean3(sky));
  const double exposure = b.out.doc["asset"]["extras"]["hemibake"]["exposure"].get<double>();
  EXPECT_NEAR(exposure, expected, 1e-3 * expected);
  const auto shown = shown_vertices(b, floor, exposure);
  ASSERT_FALSE(shown.empty());
  for (const Shown& x : shown)
    for (int c = 0; c < 3; ++c) ASSERT_NEAR(x.color[c], kExposureKey * sky[c] / mean3(sky), 2e-3) << "channel " << c;
}

// A stand-in for a room lit through a window beside a sunlit outside, with its light in closed
// form: a sun straight down (E lux) on a ground facing it, a smaller plate tilted to cos 0.6 (a
// second sunlit value), and a "room" wall of the ground's area turned nearly edge-on, to cos 0.01,
// a hundred times dimmer. None of them sees another's lit side, so each has its direct light
// alone. The old rule put the 95th percentile, the ground, at 0.9 and the wall at 0.009; the wall
// must now be readable, COLOR_0 at least 0.08 (a white wall at sRGB 79 of 255 or more; the interiors
// reported nearly black read 0.01 to 0.05), while the two sunlit values, pushed up the shoulder,
// stay apart and in order (not clipped to one flat colour).
TEST(ExposureFeature, WallAHundredTimesDimmerThanTheSunlitGroundIsReadableAndTheSunlitStayInOrder) {
  Doc d;
  const double sun = 1000.0, dim_cos = 0.01;
  const int mat = d.material(plain_material(V(0.8), "plaster"));
  const int ground = d.quad_node(rect(-6, -2, -2, 2, 0, true), mat, {{"name", "ground"}});
  const int tilted = d.quad_node(plate(V(-10, -2, 0), V(0.8, 0.6, 0), V(-0.6, 0.8, 0), 1.0), mat, {{"name", "tilted"}});
  const double s = std::sqrt(1.0 - dim_cos * dim_cos);
  const int wall = d.quad_node(plate(V(4, -3, 0), V(s, dim_cos, 0), V(-dim_cos, s, 0), 2.0), mat, {{"name", "wall"}});
  add_lights(d, json::array({json{{"type", "directional"}, {"intensity", sun}}}));
  // -90 degrees about x takes the light's -z to -y.
  d.node({{"rotation", {-std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5)}}, {"extensions", light_ref(0)}});
  JobSpec spec;
  spec.params = quick_params();
  spec.write.draco = false;
  const Baked b = bake_spec(d, spec);
  ASSERT_TRUE(b.loaded.document);
  const double exposure = b.out.doc["asset"]["extras"]["hemibake"]["exposure"].get<double>();
  const test::RecordedTone tone = test::recorded_tone(b.out.doc);
  ASSERT_TRUE(tone.shoulder);
  const auto g = shown_vertices(b, ground, exposure), t = shown_vertices(b, tilted, exposure),
             w = shown_vertices(b, wall, exposure);
  ASSERT_FALSE(g.empty());
  ASSERT_FALSE(t.empty());
  ASSERT_FALSE(w.empty());
  // The baked light is the closed form's: E, 0.6 E and 0.01 E.
  const double gl = mean3(mean_of(g, &Shown::light)) / exposure, tl = mean3(mean_of(t, &Shown::light)) / exposure,
               wl = mean3(mean_of(w, &Shown::light)) / exposure;
  EXPECT_NEAR(gl, sun, 0.01 * sun);
  EXPECT_NEAR(tl, 0.6 * sun, 0.01 * sun);
  EXPECT_NEAR(wl, dim_cos * sun, 0.02 * dim_cos * sun);
  // The wall reads.
  for (const Shown& x : w) ASSERT_GE(mean3(x.color), 0.08);
  // The sunlit two: the tilted plate is below 1 in every channel, the ground brighter, far enough
  // apart to see in three.js's 8-bit sRGB output (base colour x COLOR_0), and each COLOR_0 as the
  // recorded curve makes it.
  const V gc = mean_of(g, &Shown::color), tc = mean_of(t, &Shown::color);
  for (int c = 0; c < 3; ++c) EXPECT_LT(tc[c], 1.0);
  EXPECT_GE(test::srgb8(0.8 * mean3(gc)) - test::srgb8(0.8 * mean3(tc)), 2) << mean3(gc) << " " << mean3(tc);
  for (const auto* v : {&g, &t, &w})
    for (const Shown& x : *v) {
      const V expected = test::documented_color(tone, x.light);
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(x.color[c], expected[c], 1e-4);
    }
}

// A light used by two nodes shines from both: twice the light of one, where they stand together.
TEST(PunctualLightsFeature, EveryNodeThatRefersToALightShines) {
  auto floor_light = [](int copies) {
    Doc d;
    const int floor = d.quad_node(rect(-1, 1, -1, 1, 0, true), d.material(plain_material(V(0.5))), {{"name", "floor"}});
    add_lights(d, json::array({json{{"type", "directional"}, {"intensity", 2.0}}}));
    for (int i = 0; i < copies; ++i)
      d.node({{"rotation", {-std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5)}}, {"extensions", light_ref(0)}});
    const Baked b = bake(d.gltf_bytes());
    return mean_radiosity(all_of(baked_node(b.out, floor))).x;
  };
  const double one = floor_light(1), two = floor_light(2);
  EXPECT_NEAR(one / (0.5 * 2.0), 1.0, 0.01);  // rho E cos 0
  EXPECT_NEAR(two / one, 2.0, 0.02);
}

// Environment lighting in a file is not read, and the warning says what to use instead.
TEST(PunctualLightsFeature, ImageBasedLightingIsNamedAsNotRead) {
  Doc d;
  d.quad_node(rect(-1, 1, -1, 1, 0, true), d.material(lamp_material(V(1.0))));
  d.gltf["extensionsUsed"] = json::array({"EXT_lights_image_based"});
  const LoadResult r = load_gltf_memory(d.gltf_bytes(), ".");
  ASSERT_TRUE(r.document) << r.error;
  EXPECT_TRUE(mentions(r.warnings, "EXT_lights_image_based")) << joined(r.warnings);
  EXPECT_TRUE(mentions(r.warnings, "sky")) << joined(r.warnings);
}

// Files from Blender's own exporter (tests/data, made by scripts/make_blender_lights.py with
// Blender 3.4): Z-up scenes turned Y-up, lights on nodes turned to point along -Z, intensities
// converted from watts by Blender's rule (point and spot: W / (4 pi) x 683 candela; sun:
// W/m^2 x 683 lux; a spot's outer cone half its size, inner outer x (1 - blend)).
TEST(BlenderExportFeature, LightsArePlacedAndScaledAsBlenderSetThem) {
  const LoadResult r = load_gltf_file(HEMIBAKE_SOURCE_DIR "/tests/data/blender-lights.glb");
  ASSERT_TRUE(r.document) << r.error;
  const solver::Scene& scene = scene_of(*r.document);
  ASSERT_EQ(scene.lights.size(), 3u);
  // Blender (x, y, z) is glTF (x, z, -y).
  auto gltf = [](const V& b) { return V(b.x, b.z, -b.y); };
  const double pi = std::numbers::pi;
  const solver::Light* point = nullptr;
  const solver::Light* sun = nullptr;
  const solver::Light* spot = nullptr;
  for (const auto& l : scene.lights)
    (l.type == solver::Light::Type::kPoint ? point : l.type == solver::Light::Type::kSpot ? spot : sun) = &l;
  ASSERT_TRUE(point && sun && spot);
  auto near = [](const V& a, const V& b, double tol) { return glm::length(a - b) < tol; };
  EXPECT_TRUE(near(point->position, gltf(V(0.5, -0.5, 1.0)), 1e-6));
  const double bulb = 100.0 / (4.0 * pi) * 683.0;
  EXPECT_TRUE(near(point->intensity, bulb * V(1.0, 0.8, 0.6), 1e-3 * bulb));
  // The sun turned by Blender's XYZ Euler angles (40, 0, 30) degrees shines along R (0, 0, -1).
  const double ax = 40.0 * pi / 180.0, az = 30.0 * pi / 180.0;
  const V rx(0.0, std::sin(ax), -std::cos(ax));
  const V sun_dir(std::cos(az) * rx.x - std::sin(az) * rx.y, std::sin(az) * rx.x + std::cos(az) * rx.y, rx.z);
  EXPECT_TRUE(near(sun->direction, gltf(sun_dir), 1e-5)) << sun->direction.x << " " << sun->direction.y << " " << sun->direction.z;
  EXPECT_NEAR(sun->intensity.x, 3.0 * 683.0, 1e-6);
  EXPECT_TRUE(near(spot->position, gltf(V(-1.0, 1.0, 2.0)), 1e-6));
  EXPECT_TRUE(near(spot->direction, V(0.0, -1.0, 0.0), 1e-6));
  EXPECT_NEAR(spot->intensity.x, 200.0 / (4.0 * pi) * 683.0, 1e-3);
  EXPECT_NEAR(spot->outer_cone, 30.0 * pi / 180.0, 1e-6);
  EXPECT_NEAR(spot->inner_cone, 30.0 * pi / 180.0 * 0.75, 1e-6);
  // The lamp's material: emission (1, 0.5, 0.2) at strength 3 is a radiance; it emits pi times it.
  bool lamp = false;
  for (const auto& p : scene.patches)
    if (p.emission != V(0.0)) {
      lamp = true;
      EXPECT_TRUE(near(p.emission, pi * 3.0 * V(1.0, 0.5, 0.2), 1e-5));
    }
  EXPECT_TRUE(lamp);
  const LoadResult dark = load_gltf_file(HEMIBAKE_SOURCE_DIR "/tests/data/blender-point.glb");
  ASSERT_TRUE(dark.document) << dark.error;
  EXPECT_EQ(bake_error(*dark.document), "");  // lit by its light alone
}

// Blender's point light over Blender's (double-sided) floor: the top is rho I h / d^3 as a viewer
// shows it; the underside is dark.
TEST(BlenderExportFeature, PointLightLightsTheFloorAsIHOverDCubed) {
  const uint64_t seed = test::test_seed();
  std::mt19937_64 rng(seed);
  std::ifstream in(HEMIBAKE_SOURCE_DIR "/tests/data/blender-point.glb", std::ios::binary);
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const Baked b = bake(bytes, true, solver::Params{});
  ASSERT_TRUE(b.loaded.document);
  const V pos(0.3, 0.8, -0.2);  // Blender's (0.3, 0.2, 0.8)
  const double intensity = 50.0 / (4.0 * std::numbers::pi) * 683.0, rho = 0.6;
  std::vector<Tri> top, bottom;
  for (const Tri& t : all_of(baked_node(b.out, 0))) (t.front.y > 0.0 ? top : bottom).push_back(t);
  ASSERT_NEAR(total_area(top), 16.0, 1e-3);  // 4 m x 4 m
  ASSERT_NEAR(total_area(bottom), 16.0, 1e-3);
  auto truth = [&](const V& x) {
    const double d = glm::length(pos - x);
    return V(rho * intensity * pos.y / (d * d * d));
  };
  const auto [median, p90] = errors_against(sample_tris(top, 3000, rng), 0, truth);
  EXPECT_LE(median, 0.02) << test::seed_note(seed);
  EXPECT_LE(p90, 0.05) << test::seed_note(seed);
  EXPECT_EQ(mean_radiosity(bottom), V(0.0));
}

// A scene with neither emitter, light nor sky is refused, and the message names all three.
TEST(PunctualLightsFeature, DarkSceneMessageNamesEmittersLightsAndSky) {
  Doc d;
  d.quad_node(rect(-1, 1, -1, 1, 0, true), d.material(plain_material(V(0.5))));
  const LoadResult r = load_gltf_memory(d.gltf_bytes(), ".");
  ASSERT_TRUE(r.document) << r.error;
  const std::string e = bake_error(*r.document);
  for (const char* word : {"emissiveFactor", "KHR_lights_punctual", "sky"}) EXPECT_NE(e.find(word), std::string::npos) << e;
  JobSpec spec;
  spec.sky = V(1.0);
  EXPECT_EQ(bake_error(*r.document, spec), "");
  spec.method = Method::kHierarchical;
  EXPECT_NE(bake_error(*r.document, spec).find("sky"), std::string::npos);
  spec.method = Method::kReference;  // its path tracer sees the sky
  EXPECT_EQ(bake_error(*r.document, spec), "");
}

struct BadLight {
  const char* name;
  const char* lights;  // JSON of the lights array
  int node_light;      // the node's light index
  const char* expect;  // in the message
};

class MalformedLightsFeature : public ::testing::TestWithParam<BadLight> {};

TEST_P(MalformedLightsFeature, IsRefusedWithAMessageNamingTheLight) {
  Doc d;
  d.quad_node(rect(-1, 1, -1, 1, 0, true), d.material(lamp_material(V(1.0))));
  add_lights(d, json::parse(GetParam().lights));
  d.node({{"translation", {0.0, 1.0, 0.0}}, {"extensions", light_ref(GetParam().node_light)}});
  const LoadResult r = load_gltf_memory(d.gltf_bytes(), ".");
  EXPECT_FALSE(r.document);
  EXPECT_NE(r.error.find("light"), std::string::npos) << r.error;
  EXPECT_NE(r.error.find(GetParam().expect), std::string::npos) << r.error;
}

INSTANTIATE_TEST_SUITE_P(
    Protocol, MalformedLightsFeature,
    ::testing::Values(
        BadLight{"IndexOutOfRange", R"([{"type": "point"}])", 3, "light 3, which does not exist"},
        BadLight{"UnknownType", R"([{"type": "area", "name": "softbox"}])", 0, "'softbox'"},
        BadLight{"NegativeIntensity", R"([{"type": "point", "intensity": -2}])", 0, "intensity"},
        BadLight{"NegativeColour", R"([{"type": "point", "color": [1, -0.5, 1]}])", 0, "color"},
        BadLight{"ShortColour", R"([{"type": "point", "color": [1, 1]}])", 0, "color"},
        BadLight{"NegativeRange", R"([{"type": "point", "range": -1}])", 0, "range"},
        BadLight{"InnerNotBelowOuter", R"([{"type": "spot", "spot": {"innerConeAngle": 0.5, "outerConeAngle": 0.5}}])", 0, "cone"},
        BadLight{"OuterPastRightAngle", R"([{"type": "spot", "spot": {"outerConeAngle": 2.0}}])", 0, "cone"}),
    [](const auto& p) { return std::string(p.param.name); });

// ---- 8. TEXCOORD_0 against the closed form ------------------------------------------------------

// A quad over x, z in [0, 2] with UVs (0,0), (1,0), (1,1), (0,1) at its corners (u = x/2, v = z/2),
// lit from close by so that it is subdivided: every output vertex's UV is (x/2, z/2) of its position
// in the node's frame, exactly in plain output and within Draco's quantization otherwise.
TEST(TexcoordFeature, OutputUvsInterpolateTheInputUvsOverSubdividedElements) {
  Doc d;
  const int floor_mat = d.material(plain_material(V(0.6)));
  const int lamp = d.material(lamp_material(V(4.0)));
  const std::vector<V> corners = {V(0, 0, 0), V(0, 0, 2), V(2, 0, 2), V(2, 0, 0)};  // faces +y
  std::vector<UV> uv;
  for (const V& c : corners) uv.emplace_back(c.x / 2.0, c.z / 2.0);
  const int floor = d.quad_node(corners, floor_mat, {{"name", "floor"}, {"translation", {3.0, 1.0, -2.0}}}, uv);
  d.quad_node(rect(3.6, 4.4, -1.4, -0.6, 1.3, false), lamp, {{"name", "lamp"}});
  const std::vector<uint8_t> bytes = d.gltf_bytes();
  for (bool draco : {false, true}) {
    SCOPED_TRACE(draco ? "draco" : "plain");
    const Baked b = bake(bytes, draco);
    const json& node = b.out.doc["nodes"][floor];
    const Primitive p = read_primitive(b.out, b.out.doc["meshes"][node["mesh"].get<int>()]["primitives"][0]);
    ASSERT_EQ(p.uv.size(), p.positions.size());
    EXPECT_GT(p.positions.size(), 16u) << "the floor was not subdivided; the check would be trivial";
    const double tol = draco ? 1e-3 : 1e-4;
    for (size_t i = 0; i < p.positions.size(); ++i) {
      ASSERT_NEAR(p.uv[i].x, p.positions[i].x / 2.0, tol) << "vertex " << i;
      ASSERT_NEAR(p.uv[i].y, p.positions[i].z / 2.0, tol) << "vertex " << i;
    }
  }
}

// A texture coordinate that is not a finite number is refused with the accessor that holds it (the
// Draco encoder crashed on such a file, exported from Blender and damaged), plain or Draco alike.
TEST(TexcoordFeature, NonFiniteTexcoordsAreRefusedByAccessor) {
  for (const double bad : {std::nan(""), std::numeric_limits<double>::infinity()}) {
    Doc d;
    const int floor_mat = d.material(plain_material(V(0.6)));
    const int lamp = d.material(lamp_material(V(4.0)));
    const std::vector<V> corners = {V(0, 0, 0), V(0, 0, 2), V(2, 0, 2), V(2, 0, 0)};
    const std::vector<UV> uv = {UV(0, 0), UV(0, 1), UV(bad, 1), UV(1, 0)};
    d.quad_node(corners, floor_mat, {{"name", "floor"}}, uv);
    d.quad_node(rect(0.6, 1.4, 0.6, 1.4, 0.3, false), lamp, {{"name", "lamp"}});
    const LoadResult r = load_gltf_memory(d.gltf_bytes(), ".");
    EXPECT_FALSE(r.document);
    EXPECT_NE(r.error.find("TEXCOORD_0"), std::string::npos) << r.error;
    EXPECT_NE(r.error.find("non-finite value at element 2"), std::string::npos) << r.error;
  }
}

// UVs that are not an affine function of position (a quad's UVs are linear over each of its two
// source triangles, not over the quad): every output vertex's UV is the barycentric interpolation of
// the corner UVs over the source triangle that holds it, as computed here.
TEST(TexcoordFeature, OutputUvsAreLinearOverEachSourceTriangleOfAQuad) {
  Doc d;
  const int floor_mat = d.material(plain_material(V(0.6)));
  const int lamp = d.material(lamp_material(V(4.0)));
  const std::vector<V> c = {V(0, 0, 0), V(0, 0, 2), V(2, 0, 2), V(2, 0, 0)};  // faces +y; triangles 012, 023
  const std::vector<UV> uv = {UV(0.0, 0.0), UV(0.1, 0.9), UV(1.0, 0.6), UV(0.7, 0.0)};
  const int floor = d.quad_node(c, floor_mat, {{"name", "floor"}}, uv);
  d.quad_node(rect(0.6, 1.4, 0.6, 1.4, 0.3, false), lamp, {{"name", "lamp"}});
  const Baked b = bake(d.gltf_bytes());
  const json& node = b.out.doc["nodes"][floor];
  const Primitive p = read_primitive(b.out, b.out.doc["meshes"][node["mesh"].get<int>()]["primitives"][0]);
  ASSERT_EQ(p.uv.size(), p.positions.size());
  EXPECT_GT(p.positions.size(), 16u);
  // In the (x, z) plane: barycentric coordinates of q in triangle (a, b, c).
  auto bary = [](const V& q, const V& a, const V& bb, const V& cc) {
    const double det = (bb.x - a.x) * (cc.z - a.z) - (cc.x - a.x) * (bb.z - a.z);
    const double l1 = ((q.x - a.x) * (cc.z - a.z) - (cc.x - a.x) * (q.z - a.z)) / det;
    const double l2 = ((bb.x - a.x) * (q.z - a.z) - (q.x - a.x) * (bb.z - a.z)) / det;
    return glm::dvec3(1.0 - l1 - l2, l1, l2);
  };
  size_t off_diagonal = 0;
  for (size_t i = 0; i < p.positions.size(); ++i) {
    const V& q = p.positions[i];
    const glm::dvec3 w1 = bary(q, c[0], c[1], c[2]), w2 = bary(q, c[0], c[2], c[3]);
    const bool first = std::min({w1.x, w1.y, w1.z}) >= std::min({w2.x, w2.y, w2.z});
    const UV expected = first ? w1.x * uv[0] + w1.y * uv[1] + w1.z * uv[2] : w2.x * uv[0] + w2.y * uv[2] + w2.z * uv[3];
    ASSERT_NEAR(p.uv[i].x, expected.x, 1e-5) << "vertex " << i << " at " << q.x << ", " << q.z;
    ASSERT_NEAR(p.uv[i].y, expected.y, 1e-5) << "vertex " << i << " at " << q.x << ", " << q.z;
    // The other triangle's plane would give a different UV off the diagonal (the check is not vacuous).
    const UV other = first ? w2.x * uv[0] + w2.y * uv[2] + w2.z * uv[3] : w1.x * uv[0] + w1.y * uv[1] + w1.z * uv[2];
    if (glm::length(other - expected) > 1e-3) ++off_diagonal;
  }
  EXPECT_GT(off_diagonal, p.positions.size() / 2);
}


// ---- 9. What exporters write: sparse accessors, morph targets, vertex colours, texture transforms

// The corners of every patch of a loaded scene, as one sorted list (independent of patch order and
// of where each corner list starts).
std::vector<std::array<double, 3>> all_corners(const solver::Scene& scene) {
  std::vector<std::array<double, 3>> out;
  for (const auto& p : scene.patches)
    for (uint32_t k = 0; k < p.corner_count; ++k) out.push_back({p.corners[k].x, p.corners[k].y, p.corners[k].z});
  std::sort(out.begin(), out.end());
  return out;
}

// A material that also emits, so that a scene of it alone can be baked (the loader's checks only
// need a scene that emits; emission changes neither corners nor reflectance).
json glowing(json m) {
  m["emissiveFactor"] = {1.0, 1.0, 1.0};
  return m;
}

std::vector<std::array<double, 3>> sorted(const std::vector<V>& points) {
  std::vector<std::array<double, 3>> out;
  for (const V& p : points) out.push_back({p.x, p.y, p.z});
  std::sort(out.begin(), out.end());
  return out;
}

// A sparse accessor of `count` VEC3 floats: zeros (no bufferView) or the elements of `base`, with
// the elements at `at` (increasing) replaced by `values` (glTF 2.0, section 3.6.2.3).
int sparse_vec3(Doc& d, size_t count, const std::vector<uint32_t>& at, const std::vector<V>& values, int base = -1) {
  std::vector<uint16_t> idx(at.begin(), at.end());
  std::vector<float> val;
  for (const V& v : values) val.insert(val.end(), {static_cast<float>(v.x), static_cast<float>(v.y), static_cast<float>(v.z)});
  json a = {{"componentType", kFloat}, {"count", count}, {"type", "VEC3"},
            {"sparse", {{"count", at.size()},
                        {"indices", {{"bufferView", d.view(idx.data(), idx.size() * 2)}, {"componentType", kUnsignedShort}}},
                        {"values", {{"bufferView", d.view(val.data(), val.size() * 4)}}}}}};
  if (base >= 0) a["bufferView"] = d.gltf["accessors"][base]["bufferView"];
  return d.accessor(a);
}

// Sparse POSITION accessors load as their dense meaning: without a bufferView the unlisted
// elements are zero; with one, the listed elements replace the stored ones.
TEST(SparseAccessorFeature, PositionsAreTheBaseWithTheListedElementsReplaced) {
  Doc d;
  const int mat = d.material(glowing(plain_material(V(0.5))));
  // Zeros, with vertices 1, 2, 3 given: the unit quad (0,0,0) (1,0,0) (1,1,0) (0,1,0).
  const int zeros = sparse_vec3(d, 4, {1, 2, 3}, {V(1, 0, 0), V(1, 1, 0), V(0, 1, 0)});
  d.node({{"mesh", d.mesh(json::array({{{"attributes", {{"POSITION", zeros}}}, {"indices", d.indices({0, 1, 2, 0, 2, 3})}, {"material", mat}}}))}});
  // A stored quad at z = 5 whose vertex 2 is replaced: (3,0,5) (4,0,5) (4.5,2,5) (3,1,5).
  const int stored = d.positions({V(3, 0, 5), V(4, 0, 5), V(9, 9, 9), V(3, 1, 5)});
  const int patched = sparse_vec3(d, 4, {2}, {V(4.5, 2, 5)}, stored);
  d.node({{"mesh", d.mesh(json::array({{{"attributes", {{"POSITION", patched}}}, {"indices", d.indices({0, 1, 2, 0, 2, 3})}, {"material", mat}}}))}});
  const LoadResult r = load_gltf_memory(d.glb_bytes(), ".");
  ASSERT_TRUE(r.document) << r.error;
  EXPECT_EQ(all_corners(scene_of(*r.document)),
            sorted({V(0, 0, 0), V(1, 0, 0), V(1, 1, 0), V(0, 1, 0), V(3, 0, 5), V(4, 0, 5), V(4.5, 2, 5), V(3, 1, 5)}));
}

// Morph targets are baked at the instance's weights (glTF 2.0, section 3.7.2.2): position = base +
// sum of weight x displacement, with the node's weights overriding the mesh's. Exporters store the
// displacements as sparse accessors, as one target is here, and an unused one as an accessor
// without a bufferView, whose elements are zeros (section 3.6.2), as the third is here.
TEST(MorphTargetFeature, PositionsAreTheBasePlusTheWeightedDisplacements) {
  Doc d;
  const int mat = d.material(glowing(plain_material(V(0.5))));
  const std::vector<V> base = {V(0, 0, 0), V(1, 0, 0), V(1, 1, 0), V(0, 1, 0)};
  const std::vector<V> up = {V(0, 0, 0), V(0, 0, 0), V(0, 2, 0), V(0, 2, 0)};  // target 0: the top edge up by 2
  const int t0 = d.positions(up);
  const int t1 = sparse_vec3(d, 4, {1, 2}, {V(4, 0, 0), V(4, 0, 0)});        // target 1: the right edge out by 4
  // Target 2: no bufferView, so zeros (gltf-transform writes an unused shape key so).
  const int t2 = d.accessor({{"componentType", kFloat}, {"count", 4}, {"type", "VEC3"}});
  json prim = {{"attributes", {{"POSITION", d.positions(base)}}}, {"indices", d.indices({0, 1, 2, 0, 2, 3})}, {"material", mat},
               {"targets", json::array({json{{"POSITION", t0}}, json{{"POSITION", t1}}, json{{"POSITION", t2}}})}};
  const int mesh = d.mesh(json::array({prim}));
  d.gltf["meshes"][mesh]["weights"] = {0.5, 0.25, 1.0};
  d.node({{"mesh", mesh}});                                                     // the mesh's weights
  d.node({{"mesh", mesh}, {"weights", {1.0, 0.0, 0.7}}, {"translation", {0.0, 0.0, 3.0}}});  // its own
  const LoadResult r = load_gltf_memory(d.glb_bytes(), ".");
  ASSERT_TRUE(r.document) << r.error;
  std::vector<V> expected;
  for (size_t i = 0; i < 4; ++i) {
    const V t1d = (i == 1 || i == 2) ? V(4, 0, 0) : V(0.0);
    expected.push_back(base[i] + 0.5 * up[i] + 0.25 * t1d);
    expected.push_back(base[i] + 1.0 * up[i] + V(0, 0, 3));
  }
  EXPECT_EQ(all_corners(scene_of(*r.document)), sorted(expected));
}

// COLOR_0 multiplies the base colour (glTF 2.0, section 3.9.2): a triangle's reflectance is the
// factor times the mean of its vertex colours (linear over the triangle), whatever the accessor's
// storage (float VEC4, normalized unsigned byte VEC3).
TEST(VertexColorFeature, ReflectanceIsTheBaseColourTimesTheMeanVertexColour) {
  Doc d;
  const V factor(0.8, 0.6, 0.5);
  const int mat = d.material(glowing(plain_material(factor)));
  // Two separate triangles (no quad is formed), each with its own colours.
  const std::vector<V> tri_a = {V(0, 0, 0), V(1, 0, 0), V(0, 1, 0)};
  const std::vector<V> tri_b = {V(3, 0, 0), V(4, 0, 0), V(3, 1, 0)};
  const float colours_a[3][4] = {{1.0f, 0.5f, 0.0f, 1.0f}, {0.5f, 0.5f, 0.25f, 0.3f}, {0.0f, 1.0f, 0.5f, 1.0f}};
  const uint8_t colours_b[3][4] = {{255, 0, 51, 0}, {0, 255, 102, 0}, {51, 51, 0, 0}};  // VEC3, padded to 4 bytes
  const int ca = d.accessor({{"bufferView", d.view(colours_a, sizeof colours_a)}, {"componentType", kFloat}, {"count", 3}, {"type", "VEC4"}});
  const int vb = d.view(colours_b, sizeof colours_b);
  d.gltf["bufferViews"][vb]["byteStride"] = 4;
  const int cb = d.accessor({{"bufferView", vb}, {"componentType", 5121}, {"normalized", true}, {"count", 3}, {"type", "VEC3"}});
  json pa = d.primitive(tri_a, {}, kTriangles, mat), pb = d.primitive(tri_b, {}, kTriangles, mat);
  pa["attributes"]["COLOR_0"] = ca;
  pb["attributes"]["COLOR_0"] = cb;
  d.node({{"mesh", d.mesh(json::array({pa, pb}))}});
  const LoadResult r = load_gltf_memory(d.glb_bytes(), ".");
  ASSERT_TRUE(r.document) << r.error;
  const auto& patches = scene_of(*r.document).patches;
  ASSERT_EQ(patches.size(), 2u);
  const V mean_a = V(1.5, 2.0, 0.75) / 3.0;
  const V mean_b = V(306.0, 306.0, 153.0) / (3.0 * 255.0);
  for (const auto& p : patches) {
    const V expected = factor * (p.corners[0].x < 2.0 ? mean_a : mean_b);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(p.reflectance[c], expected[c], 1e-6) << "channel " << c;
  }
}

// Vertex colours light the bake like the same colour given as the base colour factor; the output
// still divides by the displayed base colour (COLOR_0 replaces the input's), so base colour x the
// output's COLOR_0 is the light, as for any material.
TEST(VertexColorFeature, BakesLikeTheSameColourAsAFactor) {
  const V colour(0.9, 0.4, 0.1);
  auto scene = [&](bool as_vertex_colour) {
    Doc d;
    const int floor_mat = d.material(plain_material(as_vertex_colour ? V(1.0) : colour));
    const int lamp = d.material(lamp_material(V(4.0)));
    json p = d.primitive(rect(0, 2, 0, 2, 0, true), {0, 1, 2, 0, 2, 3}, kTriangles, floor_mat);
    if (as_vertex_colour) {
      const std::vector<float> c = {0.9f, 0.4f, 0.1f, 0.9f, 0.4f, 0.1f, 0.9f, 0.4f, 0.1f, 0.9f, 0.4f, 0.1f};
      p["attributes"]["COLOR_0"] = d.accessor({{"bufferView", d.view(c.data(), c.size() * 4)}, {"componentType", kFloat}, {"count", 4}, {"type", "VEC3"}});
    }
    d.node({{"mesh", d.mesh(json::array({p}))}, {"name", "floor"}});
    d.quad_node(rect(0.5, 1.5, 0.5, 1.5, 1.0, false), lamp, {{"name", "lamp"}});
    return d.gltf_bytes();
  };
  const Baked a = bake(scene(true)), b = bake(scene(false));
  ASSERT_TRUE(a.loaded.document && b.loaded.document);
  const V la = mean_radiosity(all_of(baked_node(a.out, 0))), lb = mean_radiosity(all_of(baked_node(b.out, 0)));
  for (int c = 0; c < 3; ++c) {
    ASSERT_GT(lb[c], 0.0);
    EXPECT_NEAR(la[c] / lb[c], 1.0, 0.01) << "channel " << c;
  }
}

// A 4 x 4 PNG: the left half (u < 0.5) kRed, the right half kBlue (sRGB bytes).
constexpr uint8_t kRed[3] = {230, 20, 20}, kBlue[3] = {20, 40, 230};

std::vector<uint8_t> halves_png() {
  std::vector<uint8_t> pixels;
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) {
      const uint8_t* c = x < 2 ? kRed : kBlue;
      pixels.insert(pixels.end(), {c[0], c[1], c[2], 255});
    }
  return png_4x4(pixels);
}

// KHR_texture_transform maps the stored UVs before sampling: uv' = T(offset) R(rotation) S(scale) uv
// with R = [[cos, sin], [-sin, cos]] (the extension's specification). Each transform below maps the
// unit square of stored UVs onto the blue half only, so the reflectance is the blue texel's decoded
// colour; without the transform (or with the rotation's sign flipped) the red half would be sampled.
TEST(TextureTransformFeature, BaseColourIsSampledWhereTheTransformMapsTheUvs) {
  const std::vector<uint8_t> png = halves_png();
  const json transforms[] = {
      {{"offset", {0.5, 0.0}}, {"scale", {0.5, 1.0}}},                                  // u' = 0.5 + 0.5 u
      {{"offset", {0.5, 0.0}}, {"scale", {1.0, 0.5}}, {"rotation", std::acos(-1.0) / 2}},  // u' = 0.5 + 0.5 v
  };
  for (const json& t : transforms) {
    SCOPED_TRACE(t.dump());
    Doc d;
    const int view = d.view(png.data(), png.size());
    d.gltf["images"] = json::array({json{{"bufferView", view}, {"mimeType", "image/png"}}});
    d.gltf["textures"] = json::array({json{{"source", 0}}});
    d.gltf["extensionsUsed"] = {"KHR_texture_transform"};
    const int mat = d.material(glowing(
        {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}, {"extensions", {{"KHR_texture_transform", t}}}}}}}}));
    d.quad_node({V(0, 0, 0), V(1, 0, 0), V(1, 1, 0), V(0, 1, 0)}, mat, json::object(), {UV(0, 0), UV(1, 0), UV(1, 1), UV(0, 1)});
    const LoadResult r = load_gltf_memory(d.glb_bytes(), ".");
    ASSERT_TRUE(r.document) << r.error;
    ASSERT_EQ(scene_of(*r.document).patches.size(), 1u);
    const V rho = scene_of(*r.document).patches[0].reflectance;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(rho[c], srgb_to_linear(kBlue[c] / 255.0), 1e-9) << "channel " << c;
  }
}

// Every extension named in an object's "extensions", anywhere in a glTF JSON document.
void extensions_in(const json& j, std::vector<std::string>& out) {
  if (j.is_object()) {
    for (const auto& [key, v] : j.items()) {
      if (key == "extensions" && v.is_object())
        for (const auto& [name, ext] : v.items()) out.push_back(name);
      extensions_in(v, out);
    }
  } else if (j.is_array()) {
    for (const json& v : j) extensions_in(v, out);
  }
}

// A Blender-style material (KHR_materials_specular and _ior, a normal and an occlusion texture, the
// base colour texture on TEXCOORD_1 with a transform) bakes into a file that keeps the glTF rules
// the validator checks: every extension an object carries is declared in extensionsUsed (glTF 2.0,
// section 3.12), and every texture a material uses finds its TEXCOORD_n on the primitive (3.9.6).
// The base colour texture's UVs are the output's TEXCOORD_0: the input's TEXCOORD_1, u = 0.25.
TEST(ExporterMaterialFeature, OutputDeclaresItsExtensionsAndHasTheUvSetsItsTexturesUse) {
  const std::vector<uint8_t> png = halves_png();
  Doc d;
  const int view = d.view(png.data(), png.size());
  d.gltf["images"] = json::array({json{{"bufferView", view}, {"mimeType", "image/png"}}});
  d.gltf["textures"] = json::array({json{{"source", 0}}});
  d.gltf["extensionsUsed"] = {"KHR_materials_specular", "KHR_materials_ior", "KHR_texture_transform"};
  json m = plain_material(V(1.0), "blender");
  m["pbrMetallicRoughness"]["baseColorTexture"] = {
      {"index", 0}, {"texCoord", 1}, {"extensions", {{"KHR_texture_transform", {{"scale", {1.0, 1.0}}}}}}};
  m["normalTexture"] = {{"index", 0}, {"texCoord", 1}};
  m["occlusionTexture"] = {{"index", 0}, {"texCoord", 2}};
  m["extensions"] = {{"KHR_materials_specular", {{"specularFactor", 0.5}}}, {"KHR_materials_ior", {{"ior", 1.45}}}};
  const int mat = d.material(m);
  const int lamp = d.material(lamp_material(V(4.0)));
  const std::vector<V> floor = rect(0, 2, 0, 2, 0, true);
  json p = d.primitive(floor, {0, 1, 2, 0, 2, 3}, kTriangles, mat, {UV(0, 0), UV(0, 1), UV(1, 1), UV(1, 0)});
  p["attributes"]["TEXCOORD_1"] = d.texcoords({UV(0.25, 0), UV(0.25, 1), UV(0.25, 1), UV(0.25, 0)});
  p["attributes"]["TEXCOORD_2"] = d.texcoords({UV(0, 0), UV(0, 0), UV(0, 0), UV(0, 0)});
  const int floor_node = d.node({{"mesh", d.mesh(json::array({p}))}});
  d.quad_node(rect(0.5, 1.5, 0.5, 1.5, 1.0, false), lamp);
  for (bool draco : {false, true}) {
    SCOPED_TRACE(draco ? "draco" : "plain");
    const Baked b = bake(d.glb_bytes(), draco);
    const json& g = b.out.doc;
    std::vector<std::string> present;
    extensions_in(g, present);
    const json used = g.value("extensionsUsed", json::array());
    for (const std::string& e : present) EXPECT_NE(std::find(used.begin(), used.end(), e), used.end()) << e << " is not declared";
    for (const json& mesh : g["meshes"])
      for (const json& prim : mesh["primitives"]) {
        const json& pm = g["materials"][prim["material"].get<int>()];
        std::vector<json> infos;
        if (pm.contains("pbrMetallicRoughness")) {
          for (const char* k : {"baseColorTexture", "metallicRoughnessTexture"})
            if (pm["pbrMetallicRoughness"].contains(k)) infos.push_back(pm["pbrMetallicRoughness"][k]);
        }
        for (const char* k : {"normalTexture", "occlusionTexture", "emissiveTexture"})
          if (pm.contains(k)) infos.push_back(pm[k]);
        for (const json& info : infos) {
          int set = info.value("texCoord", 0);
          if (info.contains("extensions") && info["extensions"].contains("KHR_texture_transform"))
            set = info["extensions"]["KHR_texture_transform"].value("texCoord", set);
          EXPECT_TRUE(prim["attributes"].contains("TEXCOORD_" + std::to_string(set))) << info.dump();
        }
      }
    const json& node = g["nodes"][floor_node];
    const Primitive out = read_primitive(b.out, g["meshes"][node["mesh"].get<int>()]["primitives"][0]);
    ASSERT_EQ(out.uv.size(), out.positions.size());
    for (size_t i = 0; i < out.uv.size(); ++i) {
      EXPECT_NEAR(out.uv[i].x, 0.25, 1e-3) << "vertex " << i;
      EXPECT_NEAR(out.uv[i].y, out.positions[i].z / 2.0, 1e-3) << "vertex " << i;  // TEXCOORD_1's v = z / 2
    }
  }
}

// alphaMode BLEND (a glass pane), MASK (a cut-out) and KHR_materials_transmission (Blender's glass)
// cannot be baked as what they are, since the solver has no transmission: the file loads, and a
// warning names each such material and says it is baked opaque; an OPAQUE material gets none.
TEST(AlphaModeFeature, BlendMaskAndTransmissionMaterialsAreReportedAsBakedOpaque) {
  Doc d;
  json glass = plain_material(V(0.9), "glass"), leaf = plain_material(V(0.3), "leaf");
  glass["alphaMode"] = "BLEND";
  leaf["alphaMode"] = "MASK";
  d.quad_node(rect(0, 1, 0, 1, 0, true), d.material(glowing(plain_material(V(0.5), "floor"))));
  d.quad_node(rect(0, 1, 0, 1, 1, false), d.material(glass));
  d.quad_node(rect(0, 1, 0, 1, 2, false), d.material(leaf));
  json blender_glass = plain_material(V(0.9), "window");
  blender_glass["extensions"]["KHR_materials_transmission"] = {{"transmissionFactor", 1.0}};
  d.gltf["extensionsUsed"] = {"KHR_materials_transmission"};
  d.quad_node(rect(0, 1, 0, 1, 3, false), d.material(blender_glass));
  const LoadResult r = load_gltf_memory(d.glb_bytes(), ".");
  ASSERT_TRUE(r.document) << r.error;
  EXPECT_TRUE(mentions(r.warnings, "material 1 ('glass') has alphaMode BLEND")) << joined(r.warnings);
  EXPECT_TRUE(mentions(r.warnings, "material 2 ('leaf') has alphaMode MASK")) << joined(r.warnings);
  EXPECT_TRUE(mentions(r.warnings, "material 3 ('window') has KHR_materials_transmission")) << joined(r.warnings);
  EXPECT_TRUE(mentions(r.warnings, "opaque")) << joined(r.warnings);
  EXPECT_FALSE(mentions(r.warnings, "floor")) << joined(r.warnings);
}

// glTF allows a zero scale; exporters flatten objects with it (a rug made of a box). A node scaled
// by (1, 0, 1) at height 0.2 puts its horizontal quad at y = 0.2 and its vertical one nowhere (all
// degenerate). The baked output keeps the node's transform, so its vertices, taken through that
// transform, must land on the flattened quad: finite, at y = 0.2, covering 2 x 2 facing up; before,
// the writer divided by the transform (NaN positions, and Draco refused to encode them).
TEST(ZeroScaleFeature, FlattenedNodeBakesOntoThePlaneItFlattensTo) {
  Doc d;
  const int rug_mat = d.material(plain_material(V(0.5)));
  const int lamp = d.material(lamp_material(V(4.0)));
  const std::vector<V> top = rect(0, 2, 0, 2, 0.5, true);
  const std::vector<V> side = {V(0, 0, 0), V(2, 0, 0), V(2, 1, 0), V(0, 1, 0)};  // faces +z; flattened away
  std::vector<V> points = top;
  points.insert(points.end(), side.begin(), side.end());
  const int rug = d.node({{"mesh", d.mesh(json::array({d.primitive(points, {0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7}, kTriangles, rug_mat)}))},
                          {"translation", {0.0, 0.2, 0.0}},
                          {"scale", {1.0, 0.0, 1.0}}});
  d.quad_node(rect(0.5, 1.5, 0.5, 1.5, 1.0, false), lamp);
  for (bool draco : {false, true}) {
    SCOPED_TRACE(draco ? "draco" : "plain");
    const Baked b = bake(d.glb_bytes(), draco);
    ASSERT_TRUE(b.loaded.document);
    const std::vector<Tri> tris = all_of(baked_node(b.out, rug));
    ASSERT_FALSE(tris.empty());
    for (const Tri& t : tris)
      for (const V& p : t.p) {
        ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
        EXPECT_NEAR(p.y, 0.2, 1e-6);
        EXPECT_GE(p.x, -1e-3);
        EXPECT_LE(p.x, 2.0 + 1e-3);
      }
    EXPECT_NEAR(area_facing(tris, V(0, 1, 0)), 4.0, 1e-3);
    EXPECT_NEAR(total_area(tris), 4.0, 1e-3);
    EXPECT_GT(mean_radiosity(tris).x, 0.0);
  }
}

// A sampler's wrap mode decides which texels UVs outside [0, 1] read (glTF 2.0, section 3.8.4):
// on the red-left, blue-right texture, u in [1.1, 1.4] reads the blue right edge under
// CLAMP_TO_EDGE and the blue 2 - u in [0.6, 0.9] under MIRRORED_REPEAT, where REPEAT would read the
// red u - 1 in [0.1, 0.4]; REPEAT (no sampler) reads blue for u in [1.6, 1.9].
TEST(TextureWrapFeature, SamplerWrapModesDecideWhichTexelsAreAveraged) {
  const std::vector<uint8_t> png = halves_png();
  constexpr int kClamp = 33071, kMirror = 33648;
  const std::pair<int, double> cases[] = {{kClamp, 1.1}, {kMirror, 1.1}, {0, 1.6}};
  for (const auto& [mode, u0] : cases) {
    SCOPED_TRACE("wrap " + std::to_string(mode));
    Doc d;
    const int view = d.view(png.data(), png.size());
    d.gltf["images"] = json::array({json{{"bufferView", view}, {"mimeType", "image/png"}}});
    d.gltf["textures"] = json::array({json{{"source", 0}}});
    if (mode != 0) {
      d.gltf["samplers"] = json::array({json{{"wrapS", mode}, {"wrapT", mode}}});
      d.gltf["textures"][0]["sampler"] = 0;
    }
    const int mat = d.material(glowing({{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}));
    const double u1 = u0 + 0.3;
    d.quad_node({V(0, 0, 0), V(1, 0, 0), V(1, 1, 0), V(0, 1, 0)}, mat, json::object(),
                {UV(u0, 0.1), UV(u1, 0.1), UV(u1, 0.9), UV(u0, 0.9)});
    const LoadResult r = load_gltf_memory(d.glb_bytes(), ".");
    ASSERT_TRUE(r.document) << r.error;
    ASSERT_EQ(scene_of(*r.document).patches.size(), 1u);
    const V rho = scene_of(*r.document).patches[0].reflectance;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(rho[c], srgb_to_linear(kBlue[c] / 255.0), 1e-9) << "channel " << c;
  }
}

// KHR_materials_pbrSpecularGlossiness (older exporters) gives the diffuse colour in place of the
// base colour (the extension's specification: diffuse = diffuseFactor x diffuseTexture). Without a
// metallic-roughness fallback the base colour would be the default white. The reflectance is the
// diffuse, and the output material shows it as its base colour (unlit, without the extension).
TEST(SpecularGlossinessFeature, DiffuseIsTheBaseColour) {
  const std::vector<uint8_t> png = halves_png();
  for (bool textured : {false, true}) {
    SCOPED_TRACE(textured ? "diffuseTexture" : "diffuseFactor");
    Doc d;
    json sg = {{"diffuseFactor", {0.7, 0.5, 0.4, 1.0}}, {"specularFactor", {0.1, 0.1, 0.1}}, {"glossinessFactor", 0.2}};
    if (textured) {
      const int view = d.view(png.data(), png.size());
      d.gltf["images"] = json::array({json{{"bufferView", view}, {"mimeType", "image/png"}}});
      d.gltf["textures"] = json::array({json{{"source", 0}}});
      sg["diffuseTexture"] = {{"index", 0}};
    }
    d.gltf["extensionsUsed"] = {"KHR_materials_pbrSpecularGlossiness"};
    d.gltf["extensionsRequired"] = {"KHR_materials_pbrSpecularGlossiness"};
    const int mat = d.material({{"name", "old"}, {"extensions", {{"KHR_materials_pbrSpecularGlossiness", sg}}}});
    const int lamp = d.material(lamp_material(V(4.0)));
    // The floor's UVs lie in the blue half (u in [0.6, 0.9]).
    const int floor = d.quad_node(rect(0, 2, 0, 2, 0, true), mat, json::object(), {UV(0.6, 0.1), UV(0.6, 0.9), UV(0.9, 0.9), UV(0.9, 0.1)});
    d.quad_node(rect(0.5, 1.5, 0.5, 1.5, 1.0, false), lamp);
    const Baked b = bake(d.glb_bytes());
    ASSERT_TRUE(b.loaded.document);
    V expected(0.7, 0.5, 0.4);
    if (textured)
      for (int c = 0; c < 3; ++c) expected[c] *= srgb_to_linear(kBlue[c] / 255.0);
    for (const auto& p : scene_of(*b.loaded.document).patches) {
      if (p.material != static_cast<uint32_t>(mat + 1)) continue;
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(p.reflectance[c], expected[c], 1e-9) << "channel " << c;
    }
    const json& g = b.out.doc;
    const json& prim = g["meshes"][g["nodes"][floor]["mesh"].get<int>()]["primitives"][0];
    const json& out_mat = g["materials"][prim["material"].get<int>()];
    EXPECT_EQ(out_mat["pbrMetallicRoughness"]["baseColorFactor"], json({0.7, 0.5, 0.4, 1.0}));
    EXPECT_EQ(out_mat["pbrMetallicRoughness"].contains("baseColorTexture"), textured);
    EXPECT_FALSE(out_mat["extensions"].contains("KHR_materials_pbrSpecularGlossiness"));
  }
}

}  // namespace
}  // namespace hemibake::protocol
