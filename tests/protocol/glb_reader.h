// Reading a baked primitive back from a GLB's JSON and BIN chunk, independently of hemibake's
// writer: Draco-compressed primitives through Draco's own decoder, plain ones from their accessors.
#pragma once

#include <draco/compression/decode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/mesh/mesh.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <cstdint>
#include <cstring>
#include <vector>

namespace hemibake::test {

/// A primitive's vertices (in the node's frame) and triangles.
struct Decoded {
  std::vector<glm::dvec3> positions, colors, radiosity;
  std::vector<glm::dvec2> uv;  ///< empty without TEXCOORD_0
  std::vector<uint32_t> indices;
};

inline Decoded read_primitive(const nlohmann::json& doc, const std::vector<uint8_t>& bin, const nlohmann::json& prim) {
  Decoded d;
  const nlohmann::json& acc = doc["accessors"];
  const nlohmann::json& attrs = prim["attributes"];
  if (prim.contains("extensions") && prim["extensions"].contains("KHR_draco_mesh_compression")) {
    const nlohmann::json& ext = prim["extensions"]["KHR_draco_mesh_compression"];
    const nlohmann::json& view = doc["bufferViews"][ext["bufferView"].get<int>()];
    draco::DecoderBuffer buffer;
    buffer.Init(reinterpret_cast<const char*>(bin.data()) + view.value("byteOffset", 0), view["byteLength"].get<size_t>());
    draco::Decoder decoder;
    auto mesh = decoder.DecodeMeshFromBuffer(&buffer);
    EXPECT_TRUE(mesh.ok());
    if (!mesh.ok()) return d;
    const draco::Mesh& m = *mesh.value();
    auto read = [&](const char* name, int n, auto&& put) {
      if (!ext["attributes"].contains(name)) return;
      const auto* att = m.GetAttributeByUniqueId(ext["attributes"][name].get<uint32_t>());
      ASSERT_NE(att, nullptr) << name;
      for (draco::PointIndex p(0); p < m.num_points(); ++p) {
        float v[3] = {0, 0, 0};
        ASSERT_TRUE(att->ConvertValue<float>(att->mapped_index(p), static_cast<int8_t>(n), v));
        put(v);
      }
    };
    read("POSITION", 3, [&](const float* v) { d.positions.emplace_back(v[0], v[1], v[2]); });
    read("COLOR_0", 3, [&](const float* v) { d.colors.emplace_back(v[0], v[1], v[2]); });
    read("_RADIOSITY", 3, [&](const float* v) { d.radiosity.emplace_back(v[0], v[1], v[2]); });
    read("TEXCOORD_0", 2, [&](const float* v) { d.uv.emplace_back(v[0], v[1]); });
    for (draco::FaceIndex f(0); f < m.num_faces(); ++f)
      for (int k = 0; k < 3; ++k) d.indices.push_back(m.face(f)[k].value());
    // The fallback accessors describe the decoded data.
    EXPECT_EQ(acc[attrs["POSITION"].get<int>()]["count"].get<size_t>(), d.positions.size());
    EXPECT_EQ(acc[prim["indices"].get<int>()]["count"].get<size_t>(), d.indices.size());
    return d;
  }
  // Float or normalized unsigned short components, with the view's stride.
  auto read = [&](const char* name, int n, auto&& put) {
    if (!attrs.contains(name)) return;
    const nlohmann::json& ac = acc[attrs[name].get<int>()];
    const nlohmann::json& view = doc["bufferViews"][ac["bufferView"].get<int>()];
    const size_t base = view.value("byteOffset", 0) + ac.value("byteOffset", 0);
    const int ct = ac["componentType"];
    const size_t csize = ct == 5126 ? 4 : 2;
    const size_t stride = view.value("byteStride", n * csize);
    for (size_t i = 0; i < ac["count"].get<size_t>(); ++i) {
      double v[3] = {0, 0, 0};
      for (int k = 0; k < n; ++k) {
        const uint8_t* p = bin.data() + base + i * stride + k * csize;
        if (ct == 5126) {
          float f;
          std::memcpy(&f, p, 4);
          v[k] = f;
        } else {
          uint16_t s;
          std::memcpy(&s, p, 2);
          v[k] = s / 65535.0;
        }
      }
      put(v);
    }
  };
  read("POSITION", 3, [&](const double* v) { d.positions.emplace_back(v[0], v[1], v[2]); });
  read("COLOR_0", 3, [&](const double* v) { d.colors.emplace_back(v[0], v[1], v[2]); });
  read("_RADIOSITY", 3, [&](const double* v) { d.radiosity.emplace_back(v[0], v[1], v[2]); });
  read("TEXCOORD_0", 2, [&](const double* v) { d.uv.emplace_back(v[0], v[1]); });
  const nlohmann::json& ia = acc[prim["indices"].get<int>()];
  const nlohmann::json& iview = doc["bufferViews"][ia["bufferView"].get<int>()];
  const size_t at = iview.value("byteOffset", 0) + ia.value("byteOffset", 0);
  for (size_t i = 0; i < ia["count"].get<size_t>(); ++i) {
    if (ia["componentType"] == 5123) {
      uint16_t s;
      std::memcpy(&s, bin.data() + at + 2 * i, 2);
      d.indices.push_back(s);
    } else {
      EXPECT_EQ(ia["componentType"], 5125);
      uint32_t u;
      std::memcpy(&u, bin.data() + at + 4 * i, 4);
      d.indices.push_back(u);
    }
  }
  return d;
}

}  // namespace hemibake::test
