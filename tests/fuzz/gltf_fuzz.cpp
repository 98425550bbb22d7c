// libFuzzer target: the glTF/GLB loader (its pre-check, tinygltf's parse, our accessor, material and
// image checks, the patches) on untrusted bytes, with the server's kind of limits kept small so that
// the fuzzer spends its time on structure, not on large allocations.
#include "hemibake/protocol/gltf.h"

#include <cstddef>
#include <cstdint>
#include <span>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  hemibake::protocol::LoadLimits limits;
  limits.allow_external_files = false;
  limits.max_file_bytes = 4u << 20;
  limits.max_triangles = 20'000;
  limits.max_image_pixels = 256 * 256;
  limits.max_total_image_pixels = 512 * 512;
  const auto loaded = hemibake::protocol::load_gltf_memory(std::span(data, size), "", limits);
  if (loaded.document) {
    (void)hemibake::protocol::bake_error(*loaded.document);
    (void)hemibake::protocol::image_pixel_count(*loaded.document);
  }
  return 0;
}
