// tinygltf behind a fence: the file system it may read, and the images it decodes.
#pragma once

#include "document.h"

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace hemibake::protocol {

struct ParseOptions {
  std::string base_dir;           ///< the folder of a .gltf file: external files must lie inside it
  bool allow_external = false;    ///< false: only embedded data (GLB or data URIs) is read
  uint64_t max_bytes = 0;         ///< per external file
  uint32_t max_image_pixels = 0;  ///< a larger image is not decoded (its texture counts as white)
  uint64_t max_total_image_pixels = ~0ull;  ///< decoded pixels of all images together; past it, an error
};

/// How the error of a scene whose images hold more pixels than max_total_image_pixels begins.
inline constexpr const char* kTooManyImagePixels = "the scene's images hold more than ";

/// Parses `bytes` (GLB or glTF JSON, told apart by the GLB magic) into doc.model with tinygltf.
/// Images keep their encoded bytes in doc.image_bytes and doc.image_mime and are decoded to 8-bit
/// RGBA; one that cannot be decoded or is too large is a warning, not an error. Returns false with
/// tinygltf's message in `err`. The bytes must have passed precheck_gltf: tinygltf trusts them.
bool parse_gltf(std::span<const uint8_t> bytes, const ParseOptions& options, SceneDocument& doc,
                std::vector<std::string>& warnings, std::string& err);

}  // namespace hemibake::protocol
