// A large scene for tests of the server under load, shared by the handler and server tests.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>

namespace hemibake::test {

/// `gltf` (a .gltf with embedded buffers) as a GLB whose BIN chunk is `bin_bytes` of zeros (rounded
/// up to 4) that no accessor uses: a large scene that bakes like the small one.
inline std::string glb_with_padding(const std::string& gltf, uint32_t bin_bytes, bool dark = false) {
  nlohmann::json g = nlohmann::json::parse(gltf);
  if (dark) {
    for (auto& m : g["materials"]) {
      m.erase("emissiveFactor");
      m.erase("extensions");
    }
  }
  // The BIN chunk is the buffer without a uri, and that buffer must come first.
  g["buffers"].insert(g["buffers"].begin(), nlohmann::json{{"byteLength", bin_bytes}});
  for (auto& v : g["bufferViews"]) v["buffer"] = v["buffer"].get<int>() + 1;
  std::string text = g.dump();
  text.append((4 - text.size() % 4) % 4, ' ');
  bin_bytes += (4 - bin_bytes % 4) % 4;
  std::string glb;
  glb.reserve(28 + text.size() + bin_bytes);
  auto u32 = [&](uint32_t v) { glb.append(reinterpret_cast<const char*>(&v), 4); };
  glb += "glTF";
  u32(2);
  u32(static_cast<uint32_t>(28 + text.size() + bin_bytes));
  u32(static_cast<uint32_t>(text.size()));
  glb += "JSON" + text;
  u32(bin_bytes);
  glb.append("BIN\0", 4);
  glb.append(bin_bytes, '\0');
  return glb;
}

/// glb_with_padding with the light switched off. The server reads and checks all of it (container,
/// JSON, buffers), then refuses it for having no light (422), so nothing is stored.
inline std::string dark_glb_with_padding(const std::string& gltf, uint32_t bin_bytes) {
  return glb_with_padding(gltf, bin_bytes, true);
}

}  // namespace hemibake::test
