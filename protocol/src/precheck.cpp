// Checks a glTF file's container and JSON before tinygltf parses it. tinygltf trusts what it
// reads: it recurses on nesting, silently drops properties of the wrong type, truncates large
// indices, reads a GLB's BIN chunk up to 8 bytes past the end, and decodes Draco data with
// unchecked indices. Everything it would trip on is refused here, with a message that names the
// object at fault.
#include "precheck.h"

#include <draco/compression/decode.h>
#include <draco/core/decoder_buffer.h>
#include <nlohmann/json.hpp>

#include <cctype>
#include <cstring>
#include <set>

namespace hemibake::protocol {
namespace {

using nlohmann::json;

constexpr int kMaxDepth = 64;

uint32_t u32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

std::string shorten(std::string s) {
  if (s.size() > 200) s = s.substr(0, 200) + "...";
  return s;
}

// Deepest nesting of arrays and objects, without recursion (strings skipped).
int nesting_depth(std::string_view text) {
  int depth = 0, deepest = 0;
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      deepest = std::max(deepest, ++depth);
      if (deepest > kMaxDepth) return deepest;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return deepest;
}

struct Checker {
  const json& j;
  std::string error;

  size_t count(const char* array) const { return j.contains(array) && j[array].is_array() ? j[array].size() : 0; }

  // The top-level property `name`, if present, must be an array of objects.
  bool array_of_objects(const char* name) {
    if (!j.contains(name)) return true;
    if (!j[name].is_array()) return fail(std::string("'") + name + "' must be an array");
    for (size_t i = 0; i < j[name].size(); ++i)
      if (!j[name][i].is_object()) return fail(std::string(name) + "[" + std::to_string(i) + "] must be an object");
    return true;
  }

  bool fail(const std::string& message) {
    if (error.empty()) error = message;
    return false;
  }

  // `o[key]`, if present, must be an integer in [0, limit); `what` names it in messages.
  bool index(const json& o, const char* key, size_t limit, const std::string& what, const char* target) {
    if (!o.contains(key)) return true;
    const json& v = o[key];
    if (!whole(v)) return fail(what + "." + key + " must refer to a " + target + " by a non-negative integer (got " + shorten(v.dump()) + ")");
    if (v.get<uint64_t>() >= limit)
      return fail(what + "." + key + " refers to " + target + " " + std::to_string(v.get<uint64_t>()) + ", which does not exist");
    return true;
  }

  bool non_negative(const json& o, const char* key, const std::string& what) {
    if (!o.contains(key)) return true;
    const json& v = o[key];
    if (!whole(v)) return fail(what + "." + key + " must be a non-negative integer (got " + shorten(v.dump()) + ")");
    return true;
  }

  // A non-negative integer (large unsigned values included).
  static bool whole(const json& v) {
    return v.is_number_unsigned() || (v.is_number_integer() && v.get<int64_t>() >= 0);
  }
};

// A data URI's payload: base64 must hold only its alphabet (with '=' padding at the end).
bool valid_data_uri(const std::string& uri) {
  const size_t comma = uri.find(',');
  if (comma == std::string::npos) return false;
  const std::string head = uri.substr(0, comma);
  if (head.size() < 7 || head.compare(head.size() - 7, 7, ";base64") != 0) return true;  // not base64: tinygltf refuses
  size_t pad = 0;
  for (size_t i = comma + 1; i < uri.size(); ++i) {
    const char ch = uri[i];
    if (ch == '=') {
      ++pad;
      continue;
    }
    if (pad > 0 || !(std::isalnum(static_cast<unsigned char>(ch)) || ch == '+' || ch == '/')) return false;
  }
  return pad <= 2;
}

// A buffer's or image's uri: a string; a data URI with valid base64; an external file only where
// allowed.
std::string check_uri(const json& v, const std::string& what, bool allow_external) {
  if (!v.is_string()) return what + ".uri must be a string";
  const std::string uri = v;
  if (uri.rfind("data:", 0) == 0) return valid_data_uri(uri) ? std::string() : what + "'s data URI is not valid base64";
  if (!allow_external)
    return what + " refers to an external file ('" + shorten(uri) + "'); only embedded data (GLB or data URIs) is accepted";
  return {};
}

// The JSON text of a GLB (glTF 2.0, section 4.4) and its BIN chunk, if any; or the whole file as
// JSON. Every length is checked against the file: tinygltf reads the BIN chunk up to 8 bytes past
// the end.
std::string split_container(std::span<const uint8_t> bytes, bool glb, std::string_view& text,
                            std::span<const uint8_t>& bin) {
  if (!glb) {
    text = std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    return {};
  }
  if (bytes.size() < 20) return "the GLB file is truncated (no JSON chunk)";
  const uint32_t version = u32(bytes.data() + 4), length = u32(bytes.data() + 8);
  if (version != 2) return "the GLB container is version " + std::to_string(version) + "; only version 2 exists";
  if (length != bytes.size())
    return "the GLB header says " + std::to_string(length) + " bytes but the file has " + std::to_string(bytes.size());
  const uint32_t json_len = u32(bytes.data() + 12), json_type = u32(bytes.data() + 16);
  if (json_type != 0x4E4F534Au) return "the GLB's first chunk is not JSON";
  if (json_len > bytes.size() - 20) return "the GLB's JSON chunk runs past the end of the file";
  text = std::string_view(reinterpret_cast<const char*>(bytes.data() + 20), json_len);
  const size_t bin_at = 20 + static_cast<size_t>(json_len);
  if (bin_at >= bytes.size()) return {};
  if (bytes.size() - bin_at < 8) return "the GLB's second chunk is truncated";
  const uint32_t bin_len = u32(bytes.data() + bin_at), bin_type = u32(bytes.data() + bin_at + 4);
  if (bin_len > bytes.size() - bin_at - 8) return "the GLB's BIN chunk runs past the end of the file";
  if (bin_type == 0x004E4942u) bin = bytes.subspan(bin_at + 8, bin_len);
  return {};
}

// How many of each top-level object there are (the arrays are checked to hold objects first).
struct Counts {
  size_t nodes, meshes, accessors, views, buffers, images, materials, textures, scenes;
};

// Buffers: external files only where allowed; declared sizes, which bufferViews are checked against.
std::string check_buffers(Checker& c, bool glb, std::span<const uint8_t> bin, bool allow_external, const Counts& n,
                          std::vector<uint64_t>& buffer_length) {
  buffer_length.assign(n.buffers, 0);
  for (size_t i = 0; i < n.buffers; ++i) {
    const json& b = c.j["buffers"][i];
    const std::string what = "buffer " + std::to_string(i);
    if (!c.non_negative(b, "byteLength", what)) return shorten(c.error);
    buffer_length[i] = b.value("byteLength", uint64_t{0});
    if (b.contains("uri")) {
      if (std::string e = check_uri(b["uri"], what, allow_external); !e.empty()) return e;
    } else if (!(glb && i == 0)) {
      return what + " has no uri and is not the GLB's BIN chunk";
    } else if (buffer_length[i] > bin.size()) {
      return what + " declares " + std::to_string(buffer_length[i]) + " bytes but the BIN chunk has " + std::to_string(bin.size());
    }
  }
  return {};
}

std::string check_images(Checker& c, bool allow_external, const Counts& n) {
  for (size_t i = 0; i < n.images; ++i) {
    const json& im = c.j["images"][i];
    const std::string what = "image " + std::to_string(i);
    if (!c.index(im, "bufferView", n.views, what, "bufferView")) return shorten(c.error);
    if (im.contains("uri"))
      if (std::string e = check_uri(im["uri"], what, allow_external); !e.empty()) return e;
  }
  return {};
}

std::string check_buffer_views(Checker& c, const Counts& n, const std::vector<uint64_t>& buffer_length) {
  for (size_t i = 0; i < n.views; ++i) {
    const json& v = c.j["bufferViews"][i];
    const std::string what = "bufferView " + std::to_string(i);
    if (!v.contains("buffer")) return what + " has no buffer";
    if (!c.index(v, "buffer", n.buffers, what, "buffer") || !c.non_negative(v, "byteOffset", what) ||
        !c.non_negative(v, "byteLength", what) || !c.non_negative(v, "byteStride", what))
      return shorten(c.error);
    const uint64_t off = v.value("byteOffset", uint64_t{0}), len = v.value("byteLength", uint64_t{0});
    const uint64_t blen = buffer_length[v["buffer"].get<size_t>()];
    if (off > blen || len > blen - off)
      return what + " (offset " + std::to_string(off) + ", length " + std::to_string(len) + ") lies outside buffer " +
             std::to_string(v["buffer"].get<size_t>()) + " (" + std::to_string(blen) + " bytes)";
  }
  return {};
}

// tinygltf reads a sparse accessor's numbers as int: larger ones would wrap.
std::string check_sparse(Checker& c, const json& sp, const std::string& what, const Counts& n) {
  const std::string sw = what + ".sparse";
  if (!sp.is_object() || !sp.contains("indices") || !sp.contains("values") || !sp["indices"].is_object() ||
      !sp["values"].is_object())
    return sw + " needs indices and values objects";
  if (!c.non_negative(sp, "count", sw) || !c.index(sp["indices"], "bufferView", n.views, sw + ".indices", "bufferView") ||
      !c.non_negative(sp["indices"], "byteOffset", sw + ".indices") ||
      !c.index(sp["values"], "bufferView", n.views, sw + ".values", "bufferView") ||
      !c.non_negative(sp["values"], "byteOffset", sw + ".values"))
    return shorten(c.error);
  for (const json* v : {&sp, &sp["indices"], &sp["values"]})
    for (const char* key : {"count", "byteOffset"})
      if (v->contains(key) && (*v)[key].get<uint64_t>() > 0x7fffffffu) return sw + " has a count or byteOffset too large";
  return {};
}

std::string check_accessors(Checker& c, const Counts& n) {
  for (size_t i = 0; i < n.accessors; ++i) {
    const json& a = c.j["accessors"][i];
    const std::string what = "accessor " + std::to_string(i);
    if (!c.index(a, "bufferView", n.views, what, "bufferView") || !c.non_negative(a, "byteOffset", what) ||
        !c.non_negative(a, "count", what))
      return shorten(c.error);
    // tinygltf takes any componentType from 5120 to 5130, and its Draco decoding sizes buffers by
    // the component size, which is -1 for the ones glTF does not define: a 7 KB file with 5127 on
    // a Draco primitive's accessor allocated 4 GB.
    const json& type = a.contains("componentType") ? a["componentType"] : json();
    if (!type.is_number_integer() || !std::set<int64_t>{5120, 5121, 5122, 5123, 5125, 5126}.count(type.get<int64_t>()))
      return what + ".componentType must be 5120, 5121, 5122, 5123, 5125 or 5126 (got " + shorten(type.dump()) + ")";
    if (a.contains("sparse"))
      if (std::string e = check_sparse(c, a["sparse"], what, n); !e.empty()) return e;
  }
  return {};
}

std::string check_textures(Checker& c, const Counts& n) {
  for (size_t i = 0; i < n.textures; ++i)
    if (!c.index(c.j["textures"][i], "source", n.images, "texture " + std::to_string(i), "image")) return shorten(c.error);
  return {};
}

// A primitive's KHR_draco_mesh_compression, checked by decoding it here (tinygltf's decoding
// trusts the indices). Only GLB BIN data can be decoded here; data-URI buffers are checked by
// tinygltf's own base64 decoding first and by the ranges above.
std::string check_draco(Checker& c, const json& prim, const std::string& what, bool glb, std::span<const uint8_t> bin,
                        const Counts& n, PrecheckResult& out) {
  const json& d = prim["extensions"]["KHR_draco_mesh_compression"];
  const std::string dwhat = what + " KHR_draco_mesh_compression";
  if (!d.is_object() || !d.contains("bufferView") || !d.contains("attributes") || !d["attributes"].is_object())
    return dwhat + " needs a bufferView and attributes";
  if (!c.index(d, "bufferView", n.views, dwhat, "bufferView")) return shorten(c.error);
  if (!prim.contains("attributes")) return dwhat + ": the primitive has no attributes";
  std::vector<uint32_t> ids;
  for (const auto& [name, v] : d["attributes"].items()) {
    if (!Checker::whole(v) || v.get<uint64_t>() > 1000000)
      return dwhat + " attribute " + shorten(name) + " must be a Draco attribute id";
    if (!prim["attributes"].contains(name)) return dwhat + " attribute " + shorten(name) + " is not an attribute of the primitive";
    ids.push_back(v.get<uint32_t>());
  }
  const json& view = c.j["bufferViews"][d["bufferView"].get<size_t>()];
  if (!(glb && view["buffer"].get<size_t>() == 0 && !c.j["buffers"][0].contains("uri"))) {
    out.unchecked_draco = true;
    return {};
  }
  const uint64_t off = view.value("byteOffset", uint64_t{0}), len = view.value("byteLength", uint64_t{0});
  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(bin.data() + off), len);
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) return dwhat + ": the Draco data cannot be decoded (" + shorten(decoded.status().error_msg()) + ")";
  for (uint32_t id : ids)
    if (decoded.value()->GetAttributeByUniqueId(id) == nullptr)
      return dwhat + ": Draco attribute id " + std::to_string(id) + " is not in the compressed data";
  return {};
}

std::string check_primitive(Checker& c, const json& prim, const std::string& what, bool glb, std::span<const uint8_t> bin,
                            const Counts& n, PrecheckResult& out) {
  if (!prim.is_object()) return what + " must be an object";
  if (!c.index(prim, "indices", n.accessors, what, "accessor") || !c.index(prim, "material", n.materials, what, "material") ||
      !c.non_negative(prim, "mode", what))
    return shorten(c.error);
  if (prim.contains("attributes")) {
    if (!prim["attributes"].is_object()) return what + ".attributes must be an object";
    for (const auto& [name, v] : prim["attributes"].items())
      if (!Checker::whole(v) || v.get<uint64_t>() >= n.accessors)
        return what + " attribute " + shorten(name) + " refers to accessor " + shorten(v.dump()) + ", which does not exist";
  }
  if (!prim.contains("extensions") || !prim["extensions"].is_object() ||
      !prim["extensions"].contains("KHR_draco_mesh_compression"))
    return {};
  return check_draco(c, prim, what, glb, bin, n, out);
}

std::string check_meshes(Checker& c, bool glb, std::span<const uint8_t> bin, const Counts& n, PrecheckResult& out) {
  for (size_t m = 0; m < n.meshes; ++m) {
    const json& mesh = c.j["meshes"][m];
    if (!mesh.contains("primitives") || !mesh["primitives"].is_array()) return "mesh " + std::to_string(m) + " has no primitives array";
    for (size_t p = 0; p < mesh["primitives"].size(); ++p) {
      const std::string what = "mesh " + std::to_string(m) + " primitive " + std::to_string(p);
      if (std::string e = check_primitive(c, mesh["primitives"][p], what, glb, bin, n, out); !e.empty()) return e;
    }
  }
  return {};
}

std::string check_nodes(Checker& c, const Counts& n) {
  for (size_t i = 0; i < n.nodes; ++i) {
    const json& node = c.j["nodes"][i];
    const std::string what = "node " + std::to_string(i);
    if (!c.index(node, "mesh", n.meshes, what, "mesh")) return shorten(c.error);
    if (!node.contains("children")) continue;
    if (!node["children"].is_array()) return what + ".children must be an array";
    for (const json& ch : node["children"])
      if (!Checker::whole(ch) || ch.get<uint64_t>() >= n.nodes)
        return what + " has child " + shorten(ch.dump()) + ", which is not an existing node";
  }
  return {};
}

// No cycles anywhere in the node graph, not just in the scene used: an iterative depth-first
// search with colours (0 unvisited, 1 on the path, 2 done).
std::string check_cycles(const json& j, size_t nodes) {
  std::vector<uint8_t> colour(nodes, 0);
  for (size_t start = 0; start < nodes; ++start) {
    if (colour[start]) continue;
    std::vector<std::pair<size_t, size_t>> stack{{start, 0}};
    colour[start] = 1;
    while (!stack.empty()) {
      auto& [n, k] = stack.back();
      const json& ch = j["nodes"][n].contains("children") ? j["nodes"][n]["children"] : json::array();
      if (k >= ch.size()) {
        colour[n] = 2;
        stack.pop_back();
        continue;
      }
      const size_t next = ch[k++].get<size_t>();
      if (colour[next] == 1) return "node " + std::to_string(next) + " is its own ancestor (the node hierarchy has a cycle)";
      if (colour[next] == 0) {
        colour[next] = 1;
        stack.emplace_back(next, 0);
      }
    }
  }
  return {};
}

std::string check_scenes(const json& j, const Counts& n) {
  for (size_t s = 0; s < n.scenes; ++s) {
    const json& sc = j["scenes"][s];
    if (!sc.contains("nodes")) continue;
    if (!sc["nodes"].is_array()) return "scene " + std::to_string(s) + ".nodes must be an array";
    for (const json& node : sc["nodes"])
      if (!Checker::whole(node) || node.get<uint64_t>() >= n.nodes)
        return "scene " + std::to_string(s) + " refers to node " + shorten(node.dump()) + ", which does not exist";
  }
  if (j.contains("scene") && (!Checker::whole(j["scene"]) || j["scene"].get<uint64_t>() >= n.scenes))
    return "the default scene " + shorten(j["scene"].dump()) + " does not exist";
  return {};
}

}  // namespace

std::string precheck_gltf(std::span<const uint8_t> bytes, bool allow_external, PrecheckResult& out) {
  const bool glb = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  std::string_view text;
  std::span<const uint8_t> bin;
  if (std::string e = split_container(bytes, glb, text, bin); !e.empty()) return e;
  if (nesting_depth(text) > kMaxDepth) return "the JSON is nested more than " + std::to_string(kMaxDepth) + " levels deep";
  const json j = json::parse(text.begin(), text.end(), nullptr, false);
  if (j.is_discarded()) return "the JSON cannot be parsed";
  if (!j.is_object()) return "the JSON is not an object";

  Checker c{j, {}};
  for (const char* a : {"nodes", "meshes", "accessors", "bufferViews", "buffers", "scenes", "images", "materials",
                        "textures", "samplers", "cameras", "skins", "animations"})
    if (!c.array_of_objects(a)) return shorten(c.error);
  const Counts n{c.count("nodes"),   c.count("meshes"), c.count("accessors"), c.count("bufferViews"), c.count("buffers"),
                 c.count("images"), c.count("materials"), c.count("textures"), c.count("scenes")};
  std::vector<uint64_t> buffer_length;
  // In the order of references: what a check reads has been checked before it.
  if (std::string e = check_buffers(c, glb, bin, allow_external, n, buffer_length); !e.empty()) return e;
  if (std::string e = check_images(c, allow_external, n); !e.empty()) return e;
  if (std::string e = check_buffer_views(c, n, buffer_length); !e.empty()) return e;
  if (std::string e = check_accessors(c, n); !e.empty()) return e;
  if (std::string e = check_textures(c, n); !e.empty()) return e;
  if (std::string e = check_meshes(c, glb, bin, n, out); !e.empty()) return e;
  if (std::string e = check_nodes(c, n); !e.empty()) return e;
  if (std::string e = check_cycles(j, n.nodes); !e.empty()) return e;
  return check_scenes(j, n);
}

}  // namespace hemibake::protocol
