// Small glTF 2.0 assets built in code for the protocol tests: a JSON document plus one binary
// buffer, packed either as a .gltf with a base64 data URI or as a GLB container. Written from the
// glTF 2.0 specification (section 4.4 "Binary glTF Layout"), independently of the loader.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <cstring>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace hemibake::test {

using nlohmann::json;

inline constexpr uint32_t kGlbMagic = 0x46546C67;      // "glTF"
inline constexpr uint32_t kChunkJson = 0x4E4F534A;     // "JSON"
inline constexpr uint32_t kChunkBin = 0x004E4942;      // "BIN\0"

/// RFC 4648 base64 with padding.
inline std::string base64_encode(std::span<const uint8_t> bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const uint32_t v = (uint32_t{bytes[i]} << 16) | (uint32_t{bytes[i + 1]} << 8) | bytes[i + 2];
    for (int s = 18; s >= 0; s -= 6) out += kAlphabet[(v >> s) & 63];
  }
  if (const size_t rest = bytes.size() - i; rest > 0) {
    const uint32_t v = (uint32_t{bytes[i]} << 16) | (rest == 2 ? uint32_t{bytes[i + 1]} << 8 : 0);
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += rest == 2 ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

inline void put_u32(std::vector<uint8_t>& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<uint8_t>(v >> (8 * i)));  // little endian
}

inline uint32_t get_u32(std::span<const uint8_t> bytes, size_t at) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | bytes[at + static_cast<size_t>(i)];
  return v;
}

/// A GLB: 12-byte header, a JSON chunk padded with spaces to 4 bytes, then (if `bin` is not empty)
/// a BIN chunk padded with zeros.
inline std::vector<uint8_t> make_glb(const json& gltf, std::span<const uint8_t> bin) {
  std::string text = gltf.dump();
  while (text.size() % 4 != 0) text += ' ';
  std::vector<uint8_t> body(bin.begin(), bin.end());
  while (body.size() % 4 != 0) body.push_back(0);
  std::vector<uint8_t> out;
  const size_t total = 12 + 8 + text.size() + (body.empty() ? 0 : 8 + body.size());
  out.reserve(total);
  put_u32(out, kGlbMagic);
  put_u32(out, 2);
  put_u32(out, static_cast<uint32_t>(total));
  put_u32(out, static_cast<uint32_t>(text.size()));
  put_u32(out, kChunkJson);
  out.insert(out.end(), text.begin(), text.end());
  if (!body.empty()) {
    put_u32(out, static_cast<uint32_t>(body.size()));
    put_u32(out, kChunkBin);
    out.insert(out.end(), body.begin(), body.end());
  }
  return out;
}

/// The layout of a well-formed GLB made by make_glb (offsets of its parts).
struct GlbLayout {
  size_t json_begin = 20, json_end = 0;  ///< the JSON chunk's data
  size_t bin_header = 0;                 ///< the BIN chunk's 8-byte header (== size if none)
  size_t bin_begin = 0, bin_end = 0;     ///< the BIN chunk's data
};

/// Splits a GLB into its JSON and BIN chunk data; nullopt unless it is a well-formed GLB 2.
struct GlbParts {
  json gltf;
  std::vector<uint8_t> bin;
  GlbLayout layout;
};
inline std::optional<GlbParts> split_glb(std::span<const uint8_t> glb) {
  if (glb.size() < 20 || get_u32(glb, 0) != kGlbMagic || get_u32(glb, 4) != 2 || get_u32(glb, 8) != glb.size())
    return std::nullopt;
  const size_t json_length = get_u32(glb, 12);
  if (get_u32(glb, 16) != kChunkJson || 20 + json_length > glb.size()) return std::nullopt;
  GlbParts parts;
  parts.layout.json_end = 20 + json_length;
  parts.layout.bin_header = parts.layout.json_end;
  parts.gltf = json::parse(glb.begin() + 20, glb.begin() + static_cast<ptrdiff_t>(parts.layout.json_end), nullptr, false);
  if (parts.gltf.is_discarded()) return std::nullopt;
  if (parts.layout.json_end + 8 <= glb.size()) {
    const size_t bin_length = get_u32(glb, parts.layout.json_end);
    if (get_u32(glb, parts.layout.json_end + 4) != kChunkBin || parts.layout.json_end + 8 + bin_length > glb.size())
      return std::nullopt;
    parts.layout.bin_begin = parts.layout.json_end + 8;
    parts.layout.bin_end = parts.layout.bin_begin + bin_length;
    parts.bin.assign(glb.begin() + static_cast<ptrdiff_t>(parts.layout.bin_begin),
                     glb.begin() + static_cast<ptrdiff_t>(parts.layout.bin_end));
  }
  return parts;
}

/// A glTF document with one binary buffer (buffers[0]), editable before packing.
struct Asset {
  json gltf;
  std::vector<uint8_t> bin;

  void put_f32(size_t at, float v) { std::memcpy(&bin.at(at + 3) - 3, &v, 4); }
  void put_f32_bits(size_t at, uint32_t bits) { std::memcpy(&bin.at(at + 3) - 3, &bits, 4); }
  void put_u16(size_t at, uint16_t v) { std::memcpy(&bin.at(at + 1) - 1, &v, 2); }
  void put_u32_at(size_t at, uint32_t v) { std::memcpy(&bin.at(at + 3) - 3, &v, 4); }

  /// As a .gltf: buffers[0] without a uri gets `bin` as a data URI.
  std::vector<uint8_t> gltf_bytes() const {
    json j = gltf;
    if (j.contains("buffers") && j["buffers"].is_array() && !j["buffers"].empty() && j["buffers"][0].is_object() &&
        !j["buffers"][0].contains("uri"))
      j["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64_encode(bin);
    const std::string text = j.dump();
    return {text.begin(), text.end()};
  }
  /// As a GLB: `bin` is the BIN chunk (buffers[0] must have no uri to use it).
  std::vector<uint8_t> glb_bytes() const { return make_glb(gltf, bin); }
};

/// The unit quad (0,0,0) (1,0,0) (1,1,0) (0,1,0), facing +z, as two indexed triangles.
/// Buffer layout: POSITION (accessor 0, bufferView 0) 4 x VEC3 float at bytes 0..47;
/// indices (accessor 1, bufferView 1) 6 x unsigned short at bytes 48..59. One node (0) with
/// mesh 0, scene 0 = [node 0], material 0 grey and emissive.
inline constexpr size_t kQuadPositionsOffset = 0;
inline constexpr size_t kQuadIndicesOffset = 48;
inline constexpr size_t kQuadBufferBytes = 60;

inline Asset quad_asset() {
  Asset a;
  a.bin.resize(kQuadBufferBytes);
  const float positions[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  for (size_t v = 0; v < 4; ++v)
    for (size_t c = 0; c < 3; ++c) a.put_f32(kQuadPositionsOffset + 12 * v + 4 * c, positions[v][c]);
  const uint16_t indices[6] = {0, 1, 2, 0, 2, 3};
  for (size_t i = 0; i < 6; ++i) a.put_u16(kQuadIndicesOffset + 2 * i, indices[i]);
  a.gltf = {
      {"asset", {{"version", "2.0"}, {"generator", "hemibake tests"}}},
      {"scene", 0},
      {"scenes", json::array({{{"nodes", {0}}}})},
      {"nodes", json::array({{{"mesh", 0}}})},
      {"meshes", json::array({{{"primitives", json::array({{{"attributes", {{"POSITION", 0}}},
                                                             {"indices", 1},
                                                             {"material", 0},
                                                             {"mode", 4}}})}}})},
      {"materials", json::array({{{"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}},
                                  {"emissiveFactor", {1.0, 1.0, 1.0}}}})},
      {"accessors", json::array({{{"bufferView", 0},
                                  {"componentType", 5126},
                                  {"count", 4},
                                  {"type", "VEC3"},
                                  {"min", {0.0, 0.0, 0.0}},
                                  {"max", {1.0, 1.0, 0.0}}},
                                 {{"bufferView", 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}})},
      {"bufferViews", json::array({{{"buffer", 0}, {"byteOffset", kQuadPositionsOffset}, {"byteLength", 48}, {"target", 34962}},
                                   {{"buffer", 0}, {"byteOffset", kQuadIndicesOffset}, {"byteLength", 12}, {"target", 34963}}})},
      {"buffers", json::array({{{"byteLength", kQuadBufferBytes}}})},
  };
  return a;
}

}  // namespace hemibake::test
