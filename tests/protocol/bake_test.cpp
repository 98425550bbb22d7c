// glTF in, bake, GLB out, read back with Draco's own decoder and a GLB parser written here: the
// geometry survives, the radiosity is the closed form, COLOR_0 is in [0, 1].
#include "hemibake/protocol/bake.h"
#include "hemibake/protocol/gltf.h"
#include "hemibake/solver/solver.h"
#include "glb_reader.h"
#include "gltf_builder.h"
#include "tone_formula.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <glm/geometric.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <glm/mat4x4.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <fstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace hemibake::protocol {
namespace {

using nlohmann::json;

// A glTF document built in memory: quads (two triangles each) in one primitive per material.
struct GltfBuilder {
  json doc = json::object();
  std::vector<uint8_t> blob;
  GltfBuilder() {
    doc["asset"] = {{"version", "2.0"}};
    doc["scene"] = 0;
    doc["scenes"] = json::array({json{{"nodes", json::array()}}});
    doc["nodes"] = json::array();
    doc["meshes"] = json::array();
    doc["materials"] = json::array();
    doc["accessors"] = json::array();
    doc["bufferViews"] = json::array();
  }
  int view(const void* data, size_t size) {
    while (blob.size() % 4) blob.push_back(0);
    const size_t off = blob.size();
    blob.insert(blob.end(), static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + size);
    doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", off}, {"byteLength", size}});
    return static_cast<int>(doc["bufferViews"].size()) - 1;
  }
  // `exitance` is the emitted radiosity; glTF's emission is its radiance, exitance / pi.
  int material(const glm::dvec3& base, const glm::dvec3& exitance) {
    json m = {{"pbrMetallicRoughness", {{"baseColorFactor", {base.x, base.y, base.z, 1.0}}}}};
    const double top = std::max({exitance.x, exitance.y, exitance.z});
    if (top > 0) {
      m["emissiveFactor"] = {exitance.x / top, exitance.y / top, exitance.z / top};
      m["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] = top / std::numbers::pi;
    }
    doc["materials"].push_back(m);
    return static_cast<int>(doc["materials"].size()) - 1;
  }
  // A mesh of quads (corners counter-clockwise from the front), one material.
  int mesh(const std::vector<std::array<glm::dvec3, 4>>& quads, int material) {
    std::vector<float> pos;
    std::vector<uint16_t> idx;
    for (const auto& q : quads) {
      const auto base = static_cast<uint16_t>(pos.size() / 3);
      for (const auto& p : q)
        for (int k = 0; k < 3; ++k) pos.push_back(static_cast<float>(p[k]));
      for (int k : {0, 1, 2, 0, 2, 3}) idx.push_back(static_cast<uint16_t>(base + k));
    }
    std::vector<double> lo(3, 1e300), hi(3, -1e300);
    for (size_t i = 0; i < pos.size(); ++i) {
      lo[i % 3] = std::min(lo[i % 3], static_cast<double>(pos[i]));
      hi[i % 3] = std::max(hi[i % 3], static_cast<double>(pos[i]));
    }
    const int pv = view(pos.data(), pos.size() * 4);
    doc["accessors"].push_back({{"bufferView", pv}, {"componentType", 5126}, {"count", pos.size() / 3},
                                {"type", "VEC3"}, {"min", lo}, {"max", hi}});
    const int iv = view(idx.data(), idx.size() * 2);
    doc["accessors"].push_back({{"bufferView", iv}, {"componentType", 5123}, {"count", idx.size()}, {"type", "SCALAR"}});
    const int n = static_cast<int>(doc["accessors"].size());
    doc["meshes"].push_back({{"primitives", json::array({json{{"attributes", {{"POSITION", n - 2}}},
                                                               {"indices", n - 1}, {"material", material}}})}});
    return static_cast<int>(doc["meshes"].size()) - 1;
  }
  int node(json n, bool root = true) {
    doc["nodes"].push_back(n);
    const int i = static_cast<int>(doc["nodes"].size()) - 1;
    if (root) doc["scenes"][0]["nodes"].push_back(i);
    return i;
  }
  std::vector<uint8_t> gltf() {
    json d = doc;
    d["buffers"] = json::array({json{{"byteLength", blob.size()}, {"uri", "data:application/octet-stream;base64," + test::base64_encode(blob)}}});
    const std::string s = d.dump();
    return std::vector<uint8_t>(s.begin(), s.end());
  }
};

// The inward-facing walls of the box [0, size]^3, each split into cells x cells quads.
std::vector<std::array<glm::dvec3, 4>> box_walls(double size, int cells) {
  std::vector<std::array<glm::dvec3, 4>> quads;
  const double step = size / cells;
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      for (int i = 0; i < cells; ++i) {
        for (int j = 0; j < cells; ++j) {
          std::array<glm::dvec3, 4> q;
          const double uv[4][2] = {{i * step, j * step}, {(i + 1) * step, j * step}, {(i + 1) * step, (j + 1) * step}, {i * step, (j + 1) * step}};
          for (int c = 0; c < 4; ++c) {
            q[c][axis] = side == 0 ? 0.0 : size;
            q[c][u] = uv[c][0];
            q[c][v] = uv[c][1];
          }
          // Counter-clockwise in (u, v) faces +axis: the wall at 0 faces in, the one at size faces out.
          if (side == 1) std::swap(q[1], q[3]);
          quads.push_back(q);
        }
      }
    }
  }
  return quads;
}

// A GLB read back with this file's own parser.
struct Glb {
  json doc;
  std::vector<uint8_t> bin;
};

Glb parse_glb(const std::vector<uint8_t>& bytes) {
  Glb g;
  EXPECT_GE(bytes.size(), 20u);
  uint32_t magic, version, length, json_len, json_type;
  std::memcpy(&magic, bytes.data(), 4);
  std::memcpy(&version, bytes.data() + 4, 4);
  std::memcpy(&length, bytes.data() + 8, 4);
  EXPECT_EQ(magic, 0x46546C67u);
  EXPECT_EQ(version, 2u);
  EXPECT_EQ(length, bytes.size());
  std::memcpy(&json_len, bytes.data() + 12, 4);
  std::memcpy(&json_type, bytes.data() + 16, 4);
  EXPECT_EQ(json_type, 0x4E4F534Au);
  g.doc = json::parse(bytes.begin() + 20, bytes.begin() + 20 + json_len);
  const size_t bin_at = 20 + json_len;
  if (bin_at + 8 <= bytes.size()) {
    uint32_t bin_len;
    std::memcpy(&bin_len, bytes.data() + bin_at, 4);
    g.bin.assign(bytes.begin() + bin_at + 8, bytes.begin() + bin_at + 8 + bin_len);
  }
  return g;
}

using test::Decoded;

Decoded read_primitive(const Glb& g, const json& prim) { return test::read_primitive(g.doc, g.bin, prim); }

glm::dmat4 node_matrix(const json& n) {
  glm::dmat4 m(1.0);
  if (n.contains("matrix")) {
    for (int i = 0; i < 16; ++i) glm::value_ptr(m)[i] = n["matrix"][i].get<double>();
  } else if (n.contains("translation")) {
    m[3] = glm::dvec4(n["translation"][0].get<double>(), n["translation"][1].get<double>(), n["translation"][2].get<double>(), 1.0);
  }
  return m;
}

struct Baked {
  std::vector<uint8_t> glb;
  double exposure = 0.0;
};

Baked bake(const std::vector<uint8_t>& gltf, bool draco, solver::Params params = {}) {
  const LoadResult loaded = load_gltf_memory(gltf, ".", {});
  EXPECT_TRUE(loaded.document) << loaded.error;
  if (!loaded.document) return {};
  JobSpec spec;
  spec.params = params;
  spec.write.draco = draco;
  const BakeOutput written = protocol::bake(*loaded.document, spec);
  EXPECT_EQ(written.error, "");
  return {written.glb, written.exposure};
}

class ClosedBoxGltf : public ::testing::TestWithParam<bool> {};

// A closed box, every wall emitting E and reflecting rho: _RADIOSITY = E / (1 - rho) everywhere,
// as read back by Draco's decoder (or from plain accessors); COLOR_0 lies in [0, 1] and is the
// recorded tone curve's map of exposure * radiosity / base colour (an emitter's: its emission's
// hue), which with no surface that does not emit is that light itself (nothing needs a shoulder);
// the triangles cover the walls exactly.
TEST_P(ClosedBoxGltf, BakesToEOverOneMinusRhoReadBackIndependently) {
  const glm::dvec3 rho(0.5, 0.6, 0.4), e(0.3, 0.2, 0.1);
  GltfBuilder b;
  const int mat = b.material(rho, e);
  b.node({{"name", "room"}, {"mesh", b.mesh(box_walls(2.0, 2), mat)}, {"translation", {1.0, -2.0, 0.5}}});
  const Baked baked = bake(b.gltf(), GetParam());
  ASSERT_FALSE(baked.glb.empty());
  const Glb g = parse_glb(baked.glb);
  ASSERT_EQ(g.doc["nodes"].size(), 1u);
  EXPECT_EQ(g.doc["nodes"][0]["name"], "room");
  EXPECT_NEAR(g.doc["asset"]["extras"]["hemibake"]["exposure"].get<double>(), baked.exposure, 1e-12);
  const glm::dvec3 expected = e / (glm::dvec3(1.0) - rho);
  const json& prim = g.doc["meshes"][g.doc["nodes"][0]["mesh"].get<int>()]["primitives"][0];
  const Decoded d = read_primitive(g, prim);
  ASSERT_GT(d.positions.size(), 0u);
  ASSERT_EQ(d.radiosity.size(), d.positions.size());
  // Every wall emits, so the walls are shown by their emission: the base colour is the emission's
  // hue (e over its largest channel), and COLOR_0 the brightness on it.
  const json& base = g.doc["materials"][prim["material"].get<int>()]["pbrMetallicRoughness"]["baseColorFactor"];
  const glm::dvec3 hue = e / std::max({e.x, e.y, e.z});
  for (int c = 0; c < 3; ++c) ASSERT_NEAR(base[c].get<double>(), hue[c], 1e-9);
  const test::RecordedTone tone = test::recorded_tone(g.doc);
  EXPECT_TRUE(tone.shoulder);
  EXPECT_EQ(tone.scale, 0.0);
  for (size_t i = 0; i < d.radiosity.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      ASSERT_NEAR(d.radiosity[i][c] / expected[c], 1.0, 0.02) << "vertex " << i;
      ASSERT_GE(d.colors[i][c], 0.0);
      ASSERT_LE(d.colors[i][c], 1.0);
      ASSERT_NEAR(d.colors[i][c], test::documented_color(tone, baked.exposure * d.radiosity[i] / hue)[c], 2e-3);
      ASSERT_NEAR(d.colors[i][c], baked.exposure * d.radiosity[i][c] / hue[c], 2e-3);
    }
  }
  // Node-local positions: the node's translation still applies, and the box is where it was.
  const glm::dmat4 world = node_matrix(g.doc["nodes"][0]);
  double area = 0.0;
  const double q = GetParam() ? 1e-3 : 1e-6;  // Draco quantizes positions (14 bits over 2 m)
  for (size_t t = 0; t + 2 < d.indices.size(); t += 3) {
    glm::dvec3 p[3];
    for (int k = 0; k < 3; ++k) {
      p[k] = glm::dvec3(world * glm::dvec4(d.positions[d.indices[t + k]], 1.0)) - glm::dvec3(1.0, -2.0, 0.5);
      for (int c = 0; c < 3; ++c) {
        ASSERT_GE(p[k][c], -q);
        ASSERT_LE(p[k][c], 2.0 + q);
      }
    }
    area += 0.5 * glm::length(glm::cross(p[1] - p[0], p[2] - p[0]));
  }
  EXPECT_NEAR(area, 24.0, 24.0 * 1e-3);  // six 2 x 2 walls, no gaps, no overlaps
  // KHR_materials_unlit on every material, Draco required when used.
  for (const auto& m : g.doc["materials"]) EXPECT_TRUE(m["extensions"].contains("KHR_materials_unlit"));
  const auto& required = g.doc.value("extensionsRequired", json::array());
  EXPECT_EQ(std::find(required.begin(), required.end(), "KHR_draco_mesh_compression") != required.end(), GetParam());
}

INSTANTIATE_TEST_SUITE_P(Protocol, ClosedBoxGltf, ::testing::Values(true, false),
                         [](const auto& p) { return std::string(p.param ? "Draco" : "Plain"); });

// Each instance of a mesh (nodes sharing it, nested transforms) gets a mesh of its own, in the
// node's local frame.
TEST(BakedGlb, InstancesGetTheirOwnMeshesInTheirNodesFrames) {
  GltfBuilder b;
  const int white = b.material(glm::dvec3(0.7), glm::dvec3(0.0));
  const int lamp = b.material(glm::dvec3(0.5), glm::dvec3(5.0));
  // A floor, a lamp above it, and a small panel used twice (two nodes, one nested).
  using Q = std::array<glm::dvec3, 4>;
  using V = glm::dvec3;
  const int floor_mesh = b.mesh({Q{V(0, 0, 0), V(0, 0, 4), V(4, 0, 4), V(4, 0, 0)}}, white);
  const int lamp_mesh = b.mesh({Q{V(1, 3, 1), V(3, 3, 1), V(3, 3, 3), V(1, 3, 3)}}, lamp);
  b.node({{"name", "floor"}, {"mesh", floor_mesh}});
  b.node({{"name", "lamp"}, {"mesh", lamp_mesh}});
  const int panel = b.mesh({Q{V(0, 0, 0), V(1, 0, 0), V(1, 1, 0), V(0, 1, 0)}}, white);
  b.node({{"name", "panel a"}, {"mesh", panel}, {"translation", {0.5, 0.5, 0.5}}});
  const int child = b.node({{"name", "panel b"}, {"mesh", panel}, {"translation", {0.0, 0.0, 1.0}}}, false);
  b.node({{"name", "group"}, {"children", {child}}, {"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 2, 0.5, 1, 1}}});
  const Baked baked = bake(b.gltf(), true);
  const Glb g = parse_glb(baked.glb);
  const json& nodes = g.doc["nodes"];
  ASSERT_EQ(nodes.size(), 5u);
  EXPECT_NE(nodes[2]["mesh"], nodes[3]["mesh"]);
  // Panel b's world = group matrix * its translation: z from 2 (1 + 1), x from 2 to 3.
  const Decoded d = read_primitive(g, g.doc["meshes"][nodes[3]["mesh"].get<int>()]["primitives"][0]);
  const glm::dmat4 world = node_matrix(nodes[4]) * node_matrix(nodes[3]);
  for (const auto& p : d.positions) {
    const glm::dvec3 w(world * glm::dvec4(p, 1.0));
    EXPECT_NEAR(w.z, 2.0, 1e-3);
    EXPECT_GE(w.x, 2.0 - 1e-3);
    EXPECT_LE(w.x, 3.0 + 1e-3);
  }
  // The panels face +z, away from the lamp's light from above: only indirect light from the
  // floor reaches them, and the floor under the lamp is lit.
  const Decoded floor = read_primitive(g, g.doc["meshes"][nodes[0]["mesh"].get<int>()]["primitives"][0]);
  double brightest = 0.0;
  for (const auto& r : floor.radiosity) brightest = std::max(brightest, r.x);
  EXPECT_GT(brightest, 0.1);
}

// A baked file reads back as world-space triangles with their radiosity (what `hemibake render`
// draws): the closed box's walls, all at E / (1 - rho).
TEST(BakedGlb, ReadsBackAsTrianglesWithRadiosity) {
  const glm::dvec3 rho(0.5), e(0.4);
  GltfBuilder b;
  b.node({{"name", "room"}, {"mesh", b.mesh(box_walls(2.0, 1), b.material(rho, e))}, {"translation", {5.0, 0.0, 0.0}}});
  const Baked baked = bake(b.gltf(), true);
  const auto path = std::filesystem::temp_directory_path() / ("hemibake-read-" + std::to_string(getpid()) + ".glb");
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(baked.glb.data()),
                                              static_cast<std::streamsize>(baked.glb.size()));
  solver::Mesh m;
  ASSERT_EQ(read_baked_mesh(path.string(), m), "");
  std::filesystem::remove(path);
  double area = 0.0;
  for (const auto& el : m.elements) {
    const glm::dvec3 a = m.positions[el.corners[0]], p1 = m.positions[el.corners[1]], p2 = m.positions[el.corners[2]];
    area += 0.5 * glm::length(glm::cross(p1 - a, p2 - a));
    for (uint32_t k = 0; k < 3; ++k) {
      EXPECT_NEAR(m.positions[el.corners[k]].x, 6.0, 1.0 + 1e-3);  // the node's translation applied
      EXPECT_NEAR(m.radiosity[el.corners[k]].x, 0.8, 0.8 * 0.02);
    }
  }
  EXPECT_NEAR(area, 24.0, 0.03);
  solver::Mesh none;
  EXPECT_NE(read_baked_mesh("/nonexistent.glb", none), "");
}

// Two independent decoders agree on the baked file: Draco's own C++ decoder (read here) and
// gltf-transform with draco3d under node (tests/e2e/decode.mjs) give the same vertices, colours and
// radiosity.
TEST(BakedGlb, DracoDecoderAndGltfTransformAgree) {
  GltfBuilder b;
  const int lamp = b.material(glm::dvec3(0.5), glm::dvec3(4.0, 3.0, 2.0));
  const int wall = b.material(glm::dvec3(0.6, 0.5, 0.4), glm::dvec3(0.0));
  b.node({{"name", "room"}, {"mesh", b.mesh(box_walls(1.0, 2), wall)}});
  using Q = std::array<glm::dvec3, 4>;
  using V = glm::dvec3;
  b.node({{"name", "lamp"}, {"mesh", b.mesh({Q{V(0.4, 0.99, 0.4), V(0.6, 0.99, 0.4), V(0.6, 0.99, 0.6), V(0.4, 0.99, 0.6)}}, lamp)}});
  const Baked baked = bake(b.gltf(), true);
  ASSERT_FALSE(baked.glb.empty());
  const auto dir = std::filesystem::temp_directory_path() / ("hemibake-agree-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const auto glb_path = dir / "baked.glb", json_path = dir / "decoded.json";
  std::ofstream(glb_path, std::ios::binary).write(reinterpret_cast<const char*>(baked.glb.data()),
                                                  static_cast<std::streamsize>(baked.glb.size()));
  const std::string command = "node " HEMIBAKE_SOURCE_DIR "/tests/e2e/decode.mjs " + glb_path.string() + " " +
                              json_path.string();
  ASSERT_EQ(std::system(command.c_str()), 0) << command << " (run `npm ci` in tests/e2e; test.sh does)";
  std::ifstream in(json_path);
  const json node_side = json::parse(in);
  std::filesystem::remove_all(dir);

  const Glb g = parse_glb(baked.glb);
  size_t compared = 0;
  for (const json& p : node_side["primitives"]) {
    const json& prim = g.doc["meshes"][p["mesh"].get<int>()]["primitives"][p["primitive"].get<int>()];
    const Decoded d = read_primitive(g, prim);
    const json& attrs = p["attributes"];
    ASSERT_EQ(attrs["POSITION"]["count"].get<size_t>(), d.positions.size());
    const auto& pos = attrs["POSITION"]["array"];
    const auto& col = attrs["COLOR_0"]["array"];
    const auto& rad = attrs["_RADIOSITY"]["array"];
    const double col_scale = attrs["COLOR_0"]["normalized"].get<bool>() ? 65535.0 : 1.0;
    for (size_t i = 0; i < d.positions.size(); ++i) {
      for (int k = 0; k < 3; ++k) {
        ASSERT_NEAR(pos[3 * i + k].get<double>(), d.positions[i][k], 1e-6) << "vertex " << i;
        ASSERT_NEAR(col[3 * i + k].get<double>() / col_scale, d.colors[i][k], 1e-6) << "vertex " << i;
        ASSERT_NEAR(rad[3 * i + k].get<double>(), d.radiosity[i][k], 1e-6 * (1.0 + d.radiosity[i][k])) << "vertex " << i;
      }
    }
    ASSERT_EQ(p["indices"].size(), d.indices.size());
    for (size_t i = 0; i < d.indices.size(); ++i) ASSERT_EQ(p["indices"][i].get<uint32_t>(), d.indices[i]);
    compared += d.positions.size();
  }
  EXPECT_GT(compared, 20u);
}

// Seams in a baked file read back as world-space triangles (read_baked_mesh; Draco decoded): an
// edge used by one triangle of its primitive is a surface's outline, and no vertex on an outline
// may lie strictly inside such an edge of another surface (or of another primitive), where
// rasterizers leave dotted gaps. Returns how many do, within 1e-6 of the scene's size (the file's
// floats), and one of them.
size_t seam_cracks(const solver::Mesh& m, glm::dvec3& example) {
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  for (const auto& el : m.elements)
    for (uint32_t k = 0; k < 3; ++k) {
      const uint32_t a = el.corners[k], b = el.corners[(k + 1) % 3];
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
  std::vector<std::pair<uint32_t, uint32_t>> open;
  std::vector<uint32_t> outline;
  for (const auto& [edge, n] : uses)
    if (n == 1) {
      open.push_back(edge);
      outline.push_back(edge.first);
      outline.push_back(edge.second);
    }
  std::sort(outline.begin(), outline.end());
  outline.erase(std::unique(outline.begin(), outline.end()), outline.end());
  glm::dvec3 lo(1e300), hi(-1e300);
  for (const glm::dvec3& p : m.positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const double tol = 1e-6 * glm::length(hi - lo);
  size_t found = 0;
  for (const auto& [a, b] : open) {
    const glm::dvec3 pa = m.positions[a], d = m.positions[b] - pa;
    const double len = glm::length(d);
    if (len <= 2.0 * tol) continue;
    for (uint32_t v : outline) {
      const glm::dvec3 r = m.positions[v] - pa;
      const double t = glm::dot(r, d) / len;
      if (t <= tol || t >= len - tol || glm::length(r - d * (t / len)) > tol) continue;
      if (found++ == 0) example = m.positions[v];
    }
  }
  return found;
}

class BlenderSeams : public ::testing::TestWithParam<const char*> {};

// Blender's wedge (two roof slopes, gables and a floor, each its own node) and window room (a wall
// cut around a window, standing on the floor), baked at the draft preset: the slopes, gables,
// floor and the window wall's pieces are cut differently where they meet, and the output has no
// vertex inside another surface's triangle edge there, with Draco (whose grid the primitives that
// meet share) and without.
TEST_P(BlenderSeams, BakedFileHasNoVertexInsideAnotherSurfacesEdge) {
  const LoadResult loaded = load_gltf_file(std::string(HEMIBAKE_SOURCE_DIR "/tests/data/blender/") + GetParam());
  ASSERT_TRUE(loaded.document) << loaded.error;
  JobSpec spec;
  spec.params.resolution = 50;
  spec.params.feps = 3e-3;
  spec.params.beps = 0.1;
  spec.params.convergence = 0.01;
  spec.params.pools = false;
  spec.params.threads = 2;
  const Solution solution = solve(scene_of(*loaded.document), spec);
  for (const bool draco : {true, false}) {
    WriteOptions options;
    options.draco = draco;
    const WriteResult written = write_baked_glb(*loaded.document, solution.mesh, spec.method, solver_params(spec), solution.stats, options);
    ASSERT_EQ(written.error, "");
    const auto path = std::filesystem::temp_directory_path() / ("hemibake-seams-" + std::to_string(getpid()) + ".glb");
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(written.glb.data()),
                                                static_cast<std::streamsize>(written.glb.size()));
    solver::Mesh m;
    ASSERT_EQ(read_baked_mesh(path.string(), m), "");
    std::filesystem::remove(path);
    ASSERT_GT(m.elements.size(), 1000u);
    glm::dvec3 at(0.0);
    EXPECT_EQ(seam_cracks(m, at), 0u) << (draco ? "Draco" : "plain") << ": e.g. a vertex at (" << at.x << ", " << at.y << ", " << at.z << ")";
  }
}

INSTANTIATE_TEST_SUITE_P(BakedGlb, BlenderSeams, ::testing::Values("wedge.glb", "room-window.glb"));

}  // namespace
}  // namespace hemibake::protocol
