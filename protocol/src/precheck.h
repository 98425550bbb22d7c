// Checks of a glTF file's container and JSON made before tinygltf parses it.
#pragma once

#include <cstdint>
#include <span>
#include <string>

namespace hemibake::protocol {

struct PrecheckResult {
  bool unchecked_draco = false;  ///< Draco data outside the GLB BIN chunk, not decoded here
};

/// Returns an empty string if tinygltf may parse `bytes`, else what is wrong (naming the object).
std::string precheck_gltf(std::span<const uint8_t> bytes, bool allow_external, PrecheckResult& out);

}  // namespace hemibake::protocol
