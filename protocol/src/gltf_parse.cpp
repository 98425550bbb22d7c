// tinygltf's file-system and image callbacks: it reads only files inside the glTF file's folder,
// and only where external files are allowed; it writes none; images are decoded only after their
// size is checked. KHR_draco_mesh_compression is decoded here, after tinygltf, into plain buffers.
#include "gltf_parse.h"

#include <draco/compression/decode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/mesh/mesh.h>
#include <nlohmann/json.hpp>
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

// Whether a PNG's chunks run to their end without an empty IDAT chunk. stb_image copies an empty
// IDAT chunk's no bytes to a buffer it has not yet allocated (memcpy from a null pointer, undefined
// behaviour that a fuzzed GLB found); a PNG whose chunks overrun the data is corrupt anyway.
bool png_chunks_sound(const unsigned char* bytes, size_t size) {
  size_t at = 8;  // the signature
  while (at + 12 <= size) {
    const uint32_t length = (uint32_t{bytes[at]} << 24) | (uint32_t{bytes[at + 1]} << 16) |
                            (uint32_t{bytes[at + 2]} << 8) | uint32_t{bytes[at + 3]};
    if (length == 0 && std::memcmp(bytes + at + 4, "IDAT", 4) == 0) return false;
    if (std::memcmp(bytes + at + 4, "IEND", 4) == 0) return true;
    if (length > size - at - 12) return false;
    at += 12 + static_cast<size_t>(length);
  }
  return false;
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
  const bool png = size >= 8 && std::memcmp(bytes, "\x89PNG\r\n\x1a\n", 8) == 0;
  if ((png && !png_chunks_sound(bytes, static_cast<size_t>(size))) || !stbi_info_from_memory(bytes, size, &w, &h, &comp)) {
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

// The number of components of a glTF accessor type (SCALAR 1 ... MAT4 16), 0 for an unknown one.
int components_of(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return 1;
    case TINYGLTF_TYPE_VEC2: return 2;
    case TINYGLTF_TYPE_VEC3: return 3;
    case TINYGLTF_TYPE_VEC4: return 4;
    case TINYGLTF_TYPE_MAT2: return 4;
    case TINYGLTF_TYPE_MAT3: return 9;
    case TINYGLTF_TYPE_MAT4: return 16;
    default: return 0;
  }
}

// Appends `bytes` as a new buffer with one view over it; returns the view's index.
int add_view(tinygltf::Model& m, std::vector<unsigned char>&& bytes) {
  tinygltf::Buffer buffer;
  buffer.data = std::move(bytes);
  tinygltf::BufferView view;
  view.buffer = static_cast<int>(m.buffers.size());
  view.byteOffset = 0;
  view.byteLength = buffer.data.size();
  m.buffers.push_back(std::move(buffer));
  m.bufferViews.push_back(std::move(view));
  return static_cast<int>(m.bufferViews.size() - 1);
}

// Decodes one primitive's KHR_draco_mesh_compression and points its accessors at the decoded data:
// indices as 32-bit integers, every attribute as floats (an integer attribute that its accessor
// calls normalized becomes 0..1 or -1..1). The accessor's `normalized`, not the bitstream's, says
// how integers read: the extension defines it so, and a bitstream's flag byte is loaded by Draco
// unchecked into a C++ bool (a fuzzed file's 57 was undefined behaviour wherever it was read).
std::string expand_draco_primitive(tinygltf::Model& m, tinygltf::Primitive& prim, const std::string& what) {
  const tinygltf::Value& ext = prim.extensions.at("KHR_draco_mesh_compression");
  const tinygltf::Value& view_value = ext.Get("bufferView");
  const tinygltf::Value& attributes = ext.Get("attributes");
  if (!view_value.IsInt() || !attributes.IsObject()) return what + ": KHR_draco_mesh_compression needs a bufferView and attributes";
  const int view_index = view_value.Get<int>();
  if (view_index < 0 || static_cast<size_t>(view_index) >= m.bufferViews.size())
    return what + ": KHR_draco_mesh_compression names bufferView " + std::to_string(view_index) + ", which does not exist";
  const tinygltf::BufferView& view = m.bufferViews[static_cast<size_t>(view_index)];
  if (view.buffer < 0 || static_cast<size_t>(view.buffer) >= m.buffers.size() ||
      view.byteOffset > m.buffers[static_cast<size_t>(view.buffer)].data.size() ||
      view.byteLength > m.buffers[static_cast<size_t>(view.buffer)].data.size() - view.byteOffset)
    return what + ": the Draco data of bufferView " + std::to_string(view_index) + " lies outside its buffer";
  const auto& data = m.buffers[static_cast<size_t>(view.buffer)].data;
  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(data.data() + view.byteOffset), view.byteLength);
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) return what + ": the Draco data cannot be decoded (" + decoded.status().error_msg_string() + ")";
  draco::Mesh& mesh = *decoded.value();
  const size_t points = mesh.num_points();

  if (prim.indices >= 0) {
    if (static_cast<size_t>(prim.indices) >= m.accessors.size()) return what + ": its indices accessor does not exist";
    std::vector<unsigned char> bytes(static_cast<size_t>(mesh.num_faces()) * 3 * sizeof(uint32_t));
    for (draco::FaceIndex f(0); f < mesh.num_faces(); ++f)
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = mesh.face(f)[k].value();
        std::memcpy(bytes.data() + (static_cast<size_t>(f.value()) * 3 + k) * sizeof(uint32_t), &v, sizeof v);
      }
    tinygltf::Accessor& a = m.accessors[static_cast<size_t>(prim.indices)];
    a.bufferView = add_view(m, std::move(bytes));
    a.byteOffset = 0;
    a.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    a.normalized = false;
    a.count = static_cast<size_t>(mesh.num_faces()) * 3;
    a.sparse = {};
  }
  for (const std::string& name : attributes.Keys()) {
    const tinygltf::Value& id = attributes.Get(name);
    const auto accessor = prim.attributes.find(name);
    if (!id.IsInt() || accessor == prim.attributes.end() || accessor->second < 0 ||
        static_cast<size_t>(accessor->second) >= m.accessors.size())
      return what + ": the Draco attribute " + name + " has no accessor of the primitive";
    const int unique_id = id.Get<int>();
    const int att_id = unique_id < 0 ? -1 : mesh.GetAttributeIdByUniqueId(static_cast<uint32_t>(unique_id));
    if (att_id < 0)
      return what + ": Draco attribute id " + std::to_string(unique_id) + " (" + name + ") is not in the compressed data";
    draco::PointAttribute* att = mesh.attribute(att_id);
    tinygltf::Accessor& a = m.accessors[static_cast<size_t>(accessor->second)];
    const int n = components_of(a.type);
    if (n == 0) return what + ": the accessor of " + name + " has no valid type";
    switch (att->data_type()) {
      case draco::DT_INT8: case draco::DT_UINT8: case draco::DT_INT16: case draco::DT_UINT16:
      case draco::DT_UINT32: case draco::DT_FLOAT32: break;
      default:  // a C++ bool read from the bitstream (DT_BOOL) is undefined beyond 0 and 1
        return what + ": the Draco attribute " + name + " is stored as " + std::to_string(static_cast<int>(att->data_type())) +
               ", which is not one of glTF's component types";
    }
    att->set_normalized(a.normalized);  // written, never read, before the conversion below
    std::vector<unsigned char> bytes(points * static_cast<size_t>(n) * sizeof(float));
    std::vector<float> value(static_cast<size_t>(n));
    for (draco::PointIndex p(0); p < mesh.num_points(); ++p) {
      if (!att->ConvertValue<float>(att->mapped_index(p), static_cast<int8_t>(n), value.data()))
        return what + ": the Draco attribute " + name + " cannot be read as " + std::to_string(n) + " numbers";
      std::memcpy(bytes.data() + static_cast<size_t>(p.value()) * n * sizeof(float), value.data(), n * sizeof(float));
    }
    a.bufferView = add_view(m, std::move(bytes));
    a.byteOffset = 0;
    a.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    a.normalized = false;
    a.count = points;
    a.sparse = {};
  }
  prim.extensions.erase("KHR_draco_mesh_compression");
  return {};
}

uint32_t read_u32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

void append_u32(std::vector<uint8_t>& out, uint32_t v) {
  const auto* p = reinterpret_cast<const uint8_t*>(&v);
  out.insert(out.end(), p, p + sizeof v);
}

// tinygltf refuses an indices accessor without a bufferView, which is what a Draco primitive's
// indices accessor rightly has. Such accessors are pointed at the Draco bufferView for tinygltf's
// sake; expand_draco points them at the decoded indices afterwards. Returns the bytes to parse:
// `bytes` itself when nothing needs changing, else `rewritten` (a GLB keeps its BIN chunk as is).
std::span<const uint8_t> draco_indices_with_views(std::span<const uint8_t> bytes, bool glb, std::vector<uint8_t>& rewritten) {
  std::string_view text;
  size_t json_end = bytes.size();
  if (glb) {
    if (bytes.size() < 20) return bytes;
    const uint32_t json_len = read_u32(bytes.data() + 12);
    if (json_len > bytes.size() - 20) return bytes;
    text = std::string_view(reinterpret_cast<const char*>(bytes.data() + 20), json_len);
    json_end = 20 + json_len;
  } else {
    text = std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  }
  if (text.find("KHR_draco_mesh_compression") == std::string_view::npos) return bytes;
  nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (!j.is_object() || !j.contains("meshes") || !j["meshes"].is_array() || !j.contains("accessors") ||
      !j["accessors"].is_array())
    return bytes;
  bool changed = false;
  for (auto& mesh : j["meshes"]) {
    if (!mesh.is_object() || !mesh.contains("primitives") || !mesh["primitives"].is_array()) continue;
    for (auto& prim : mesh["primitives"]) {
      if (!prim.is_object() || !prim.contains("extensions") || !prim["extensions"].is_object() ||
          !prim["extensions"].contains("KHR_draco_mesh_compression") || !prim.contains("indices"))
        continue;
      const auto& ext = prim["extensions"]["KHR_draco_mesh_compression"];
      if (!ext.is_object() || !ext.contains("bufferView") || !ext["bufferView"].is_number_unsigned() ||
          !prim["indices"].is_number_unsigned())
        continue;
      const auto index = prim["indices"].get<uint64_t>();
      if (index >= j["accessors"].size() || !j["accessors"][index].is_object() || j["accessors"][index].contains("bufferView"))
        continue;
      j["accessors"][index]["bufferView"] = ext["bufferView"];
      changed = true;
    }
  }
  if (!changed) return bytes;
  std::string json_text = j.dump();
  if (!glb) {
    rewritten.assign(json_text.begin(), json_text.end());
    return rewritten;
  }
  while (json_text.size() % 4) json_text.push_back(' ');
  const size_t rest = bytes.size() - json_end;  // the BIN chunk, header included, if any
  rewritten.clear();
  rewritten.reserve(20 + json_text.size() + rest);
  append_u32(rewritten, read_u32(bytes.data()));      // magic
  append_u32(rewritten, read_u32(bytes.data() + 4));  // version
  append_u32(rewritten, static_cast<uint32_t>(20 + json_text.size() + rest));
  append_u32(rewritten, static_cast<uint32_t>(json_text.size()));
  append_u32(rewritten, read_u32(bytes.data() + 16));  // "JSON"
  rewritten.insert(rewritten.end(), json_text.begin(), json_text.end());
  rewritten.insert(rewritten.end(), bytes.begin() + static_cast<std::ptrdiff_t>(json_end), bytes.end());
  return rewritten;
}

// Every KHR_draco_mesh_compression primitive, decoded; an error names the first that cannot be.
std::string expand_draco(tinygltf::Model& m) {
  for (size_t i = 0; i < m.meshes.size(); ++i)
    for (size_t k = 0; k < m.meshes[i].primitives.size(); ++k) {
      tinygltf::Primitive& prim = m.meshes[i].primitives[k];
      if (prim.extensions.count("KHR_draco_mesh_compression") == 0) continue;
      const std::string what = "mesh " + std::to_string(i) + " primitive " + std::to_string(k);
      if (std::string e = expand_draco_primitive(m, prim, what); !e.empty()) return e;
    }
  return {};
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
  std::vector<uint8_t> rewritten;
  bytes = draco_indices_with_views(bytes, binary, rewritten);
  const auto size = static_cast<unsigned int>(bytes.size());
  const bool ok = binary ? loader.LoadBinaryFromMemory(&doc.model, &err, &warn, bytes.data(), size, options.base_dir)
                          : loader.LoadASCIIFromString(&doc.model, &err, &warn, reinterpret_cast<const char*>(bytes.data()),
                                                       size, options.base_dir);
  if (!ctx.fatal.empty()) {
    err = ctx.fatal;
    return false;
  }
  if (!ok) return false;
  err = expand_draco(doc.model);
  return err.empty();
}

}  // namespace hemibake::protocol
