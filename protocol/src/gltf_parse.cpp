// tinygltf's file-system and image callbacks: it reads only files inside the glTF file's folder,
// and only where external files are allowed; it writes none; images are decoded only after their
// size is checked.
#include "gltf_parse.h"

#include <stb_image.h>

#include <cstring>
#include <filesystem>
#include <fstream>

namespace hemibake::protocol {
namespace {

namespace fs = std::filesystem;

// What tinygltf's callbacks see.
struct LoaderContext {
  std::string base_dir;
  bool allow_external = false;
  uint64_t max_bytes = 0;
  uint32_t max_image_pixels = 0;
  uint64_t max_total_image_pixels = 0;
  uint64_t total_image_pixels = 0;  // decoded so far
  std::string fatal;                // an error that ends the load
  SceneDocument* doc = nullptr;
  std::vector<std::string>* warnings = nullptr;
};

// Whether `path` lies inside the folder of the glTF file.
bool inside_base(const LoaderContext& ctx, const std::string& path) {
  std::error_code ec;
  const fs::path base = fs::weakly_canonical(ctx.base_dir.empty() ? fs::path(".") : fs::path(ctx.base_dir), ec);
  const fs::path target = fs::weakly_canonical(fs::path(path), ec);
  const auto rel = target.lexically_relative(base);
  return !ec && !rel.empty() && *rel.begin() != "..";
}

bool fs_exists(const std::string& path, void* user) {
  // Only files that may be read exist: the answer must not reveal anything else on the machine.
  const auto& ctx = *static_cast<const LoaderContext*>(user);
  if (!ctx.allow_external || !inside_base(ctx, path)) return false;
  std::error_code ec;
  return fs::exists(path, ec);
}
std::string fs_expand(const std::string& path, void*) { return path; }
bool fs_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err = "writing files is not allowed while loading";
  return false;
}
bool fs_read(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
  const auto* ctx = static_cast<const LoaderContext*>(user);
  if (!ctx->allow_external) {
    if (err) *err = "external file '" + path + "' is not allowed here: embed buffers and images (GLB or data URIs)";
    return false;
  }
  // The file must lie inside the folder of the .gltf file.
  std::error_code ec;
  if (!inside_base(*ctx, path)) {
    if (err) *err = "an external file lies outside the folder of the glTF file";
    return false;
  }
  const fs::path target = fs::weakly_canonical(fs::path(path), ec);
  const auto size = fs::file_size(target, ec);
  if (ec) {
    if (err) *err = "cannot read external file '" + path + "'";
    return false;
  }
  if (size > ctx->max_bytes) {
    if (err) *err = "external file '" + path + "' is larger than the limit";
    return false;
  }
  std::ifstream in(target, std::ios::binary);
  out->resize(size);
  if (!in.read(reinterpret_cast<char*>(out->data()), static_cast<std::streamsize>(size))) {
    if (err) *err = "cannot read external file '" + path + "'";
    return false;
  }
  return true;
}

// Keeps each image's encoded bytes (for the output) and decodes it to 8-bit RGBA after checking
// its size. An image that cannot be decoded is a warning: its texture counts as white.
bool load_image(tinygltf::Image* image, const int index, std::string*, std::string*, int, int,
                const unsigned char* bytes, int size, void* user) {
  auto* ctx = static_cast<LoaderContext*>(user);
  auto& doc = *ctx->doc;
  if (index >= 0) {
    if (doc.image_bytes.size() <= static_cast<size_t>(index)) {
      doc.image_bytes.resize(index + 1);
      doc.image_mime.resize(index + 1);
    }
    doc.image_bytes[index].assign(bytes, bytes + size);
    const bool png = size >= 8 && std::memcmp(bytes, "\x89PNG", 4) == 0;
    const bool jpeg = size >= 3 && bytes[0] == 0xff && bytes[1] == 0xd8;
    doc.image_mime[index] = png ? "image/png" : jpeg ? "image/jpeg" : image->mimeType;
  }
  int w = 0, h = 0, comp = 0;
  if (!stbi_info_from_memory(bytes, size, &w, &h, &comp)) {
    ctx->warnings->push_back("image " + std::to_string(index) + " cannot be decoded; its texture counts as white");
    return true;
  }
  if (w <= 0 || h <= 0 || static_cast<uint64_t>(w) * static_cast<uint64_t>(h) > ctx->max_image_pixels) {
    ctx->warnings->push_back("image " + std::to_string(index) + " (" + std::to_string(w) + " x " +
                             std::to_string(h) + ") is larger than the limit; its texture counts as white");
    return true;
  }
  // Decoded images take 4 bytes a pixel: all of them together are limited, checked before the
  // decoding (eight 8192² PNGs in a 2 MB file decoded to 2 GB, and a bake of 4.2 GB).
  ctx->total_image_pixels += static_cast<uint64_t>(w) * static_cast<uint64_t>(h);
  if (ctx->total_image_pixels > ctx->max_total_image_pixels) {
    ctx->fatal = std::string(kTooManyImagePixels) + std::to_string(ctx->max_total_image_pixels) +
                 " pixels in all (image " + std::to_string(index) + " is " + std::to_string(w) + " x " + std::to_string(h) +
                 "): that is the limit; use smaller textures";
    return false;
  }
  unsigned char* pixels = stbi_load_from_memory(bytes, size, &w, &h, &comp, 4);
  if (!pixels) {
    ctx->warnings->push_back("image " + std::to_string(index) + " cannot be decoded; its texture counts as white");
    return true;
  }
  image->width = w;
  image->height = h;
  image->component = 4;
  image->bits = 8;
  image->pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
  image->image.assign(pixels, pixels + static_cast<size_t>(w) * h * 4);
  stbi_image_free(pixels);
  return true;
}

}  // namespace

bool parse_gltf(std::span<const uint8_t> bytes, const ParseOptions& options, SceneDocument& doc,
                std::vector<std::string>& warnings, std::string& err) {
  LoaderContext ctx;
  ctx.base_dir = options.base_dir;
  ctx.allow_external = options.allow_external;
  ctx.max_bytes = options.max_bytes;
  ctx.max_image_pixels = options.max_image_pixels;
  ctx.max_total_image_pixels = options.max_total_image_pixels;
  ctx.doc = &doc;
  ctx.warnings = &warnings;
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks(tinygltf::FsCallbacks{&fs_exists, &fs_expand, &fs_read, &fs_write, &ctx});
  loader.SetImageLoader(&load_image, &ctx);
  std::string warn;
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  const auto size = static_cast<unsigned int>(bytes.size());
  const bool ok = binary ? loader.LoadBinaryFromMemory(&doc.model, &err, &warn, bytes.data(), size, options.base_dir)
                          : loader.LoadASCIIFromString(&doc.model, &err, &warn, reinterpret_cast<const char*>(bytes.data()),
                                                       size, options.base_dir);
  if (!ctx.fatal.empty()) {
    err = ctx.fatal;
    return false;
  }
  return ok;
}

}  // namespace hemibake::protocol
