// Checked reads of glTF accessors (glTF 2.0, section 3.6): tinygltf 2.7 checks neither offset +
// count * stride against the bufferView nor the bufferView against its buffer, and does not apply
// sparse substitution at all.
#include "accessor.h"

#include <algorithm>
#include <cstring>

namespace hemibake::protocol {
namespace {

// Accessors with more elements than this are refused before any arithmetic on their size.
constexpr uint64_t kMaxAccessorCount = 1ull << 28;
// Sparse accessors and accessors without a bufferView are made dense in memory; without a
// bufferView nothing in the file bounds their size.
constexpr uint64_t kMaxDenseBytes = 1ull << 28;

// The first of `count` elements of `element` bytes, `stride` apart, from byte `offset` of
// bufferView `view`, after checking that they lie inside it; or an error message about `name`.
std::string view_bytes(const tinygltf::Model& m, int view, uint64_t offset, uint64_t count, size_t element,
                       size_t stride, const std::string& name, const uint8_t*& data) {
  if (view < 0 || static_cast<size_t>(view) >= m.bufferViews.size()) return name + " has no valid bufferView";
  const tinygltf::BufferView& bv = m.bufferViews[view];
  if (bv.buffer < 0 || static_cast<size_t>(bv.buffer) >= m.buffers.size())
    return "bufferView " + std::to_string(view) + " refers to buffer " + std::to_string(bv.buffer) + ", which does not exist";
  const tinygltf::Buffer& buf = m.buffers[bv.buffer];
  if (bv.byteOffset > buf.data.size() || bv.byteLength > buf.data.size() - bv.byteOffset)
    return "bufferView " + std::to_string(view) + " (offset " + std::to_string(bv.byteOffset) +
           ", length " + std::to_string(bv.byteLength) + ") lies outside buffer " + std::to_string(bv.buffer) +
           " (" + std::to_string(buf.data.size()) + " bytes)";
  // Last byte used: offset + stride * (count - 1) + element, within the view (no overflow: count,
  // stride and offset are bounded above).
  const uint64_t need = offset + static_cast<uint64_t>(stride) * (count - 1) + element;
  if (offset > bv.byteLength || need > bv.byteLength)
    return name + " needs " + std::to_string(need) + " bytes but bufferView " + std::to_string(view) +
           " has " + std::to_string(bv.byteLength);
  data = buf.data.data() + bv.byteOffset + offset;
  return {};
}

// Points `out` at the elements of accessor `a` in its bufferView, after checking its stride and
// alignment (glTF 2.0, section 3.6.2.4: a stride is a multiple of the component size, at most 252).
std::string view_strided(const tinygltf::Model& m, const tinygltf::Accessor& a, size_t element, int csize,
                         const std::string& name, View& out) {
  if (static_cast<size_t>(a.bufferView) >= m.bufferViews.size()) return name + " has no valid bufferView";
  const tinygltf::BufferView& bv = m.bufferViews[a.bufferView];
  const size_t stride = bv.byteStride != 0 ? bv.byteStride : element;
  if (stride < element || stride % static_cast<size_t>(csize) != 0 || stride > 252)
    return "bufferView " + std::to_string(a.bufferView) + " has byteStride " + std::to_string(bv.byteStride) +
           ", invalid for " + name;
  if (a.byteOffset % static_cast<size_t>(csize) != 0) return name + " has a misaligned byteOffset";
  if (std::string e = view_bytes(m, a.bufferView, a.byteOffset, a.count, element, stride, name, out.data); !e.empty())
    return e;
  out.stride = stride;
  return {};
}

// Writes accessor `a`'s sparse values over the dense copy `dense` (glTF 2.0, section 3.6.2.3).
std::string apply_sparse(const tinygltf::Model& m, const tinygltf::Accessor& a, size_t element, int csize,
                         const std::string& name, std::vector<uint8_t>& dense) {
  const auto& sp = a.sparse;
  if (sp.count <= 0 || static_cast<size_t>(sp.count) > a.count)
    return name + " has sparse.count " + std::to_string(sp.count) + "; it must be 1 to count (" + std::to_string(a.count) + ")";
  View indices;
  indices.count = static_cast<size_t>(sp.count);
  indices.component_type = sp.indices.componentType;
  indices.components = 1;
  indices.stride = static_cast<size_t>(component_size(sp.indices.componentType));
  if (sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
      sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
      sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
    return name + " has sparse indices that are not unsigned byte, short or int";
  if (sp.indices.byteOffset < 0 || sp.values.byteOffset < 0 ||
      static_cast<size_t>(sp.indices.byteOffset) % indices.stride != 0 || sp.values.byteOffset % csize != 0)
    return name + " has a negative or misaligned sparse byteOffset";
  const uint8_t* values = nullptr;
  if (std::string e = view_bytes(m, sp.indices.bufferView, static_cast<uint64_t>(sp.indices.byteOffset), indices.count,
                                 indices.stride, indices.stride, name + " sparse indices", indices.data);
      !e.empty())
    return e;
  if (std::string e = view_bytes(m, sp.values.bufferView, static_cast<uint64_t>(sp.values.byteOffset), indices.count,
                                 element, element, name + " sparse values", values);
      !e.empty())
    return e;
  double previous = -1.0;
  for (size_t k = 0; k < indices.count; ++k) {
    const double i = read_component(indices, k, 0);
    // The specification requires strictly increasing indices; that also makes each one unique.
    if (i >= static_cast<double>(a.count) || i <= previous)
      return name + " has sparse index " + std::to_string(static_cast<uint64_t>(i)) + " at " + std::to_string(k) +
             ": the indices must increase and be below count (" + std::to_string(a.count) + ")";
    previous = i;
    std::memcpy(dense.data() + static_cast<size_t>(i) * element, values + k * element, element);
  }
  return {};
}

}  // namespace

int component_size(int type) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
    default: return 0;
  }
}

int component_count(int type) {
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

double read_component(const View& v, size_t i, int c) {
  const uint8_t* p = v.data + v.stride * i + static_cast<size_t>(c) * component_size(v.component_type);
  switch (v.component_type) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float f;
      std::memcpy(&f, p, 4);
      return f;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return v.normalized ? p[0] / 255.0 : p[0];
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      const double x = static_cast<int8_t>(p[0]);
      return v.normalized ? std::max(x / 127.0, -1.0) : x;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      uint16_t s;
      std::memcpy(&s, p, 2);
      return v.normalized ? s / 65535.0 : s;
    }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t s;
      std::memcpy(&s, p, 2);
      return v.normalized ? std::max(s / 32767.0, -1.0) : s;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      uint32_t u;
      std::memcpy(&u, p, 4);
      return u;
    }
    default: return 0.0;
  }
}

glm::dvec3 read_vec3(const View& v, size_t i) {
  return glm::dvec3(read_component(v, i, 0), read_component(v, i, 1), read_component(v, i, 2));
}

std::string view_accessor(const tinygltf::Model& m, int index, const std::string& what, View& out) {
  const std::string name = "accessor " + std::to_string(index) + " (" + what + ")";
  if (index < 0 || static_cast<size_t>(index) >= m.accessors.size())
    return what + " refers to accessor " + std::to_string(index) + ", which does not exist";
  const tinygltf::Accessor& a = m.accessors[index];
  const int csize = component_size(a.componentType);
  const int ncomp = component_count(a.type);
  if (csize == 0 || ncomp == 0) return name + " has an invalid componentType or type";
  if (a.count == 0) return name + " has no elements";
  if (a.count > kMaxAccessorCount) return name + " has too many elements (" + std::to_string(a.count) + ")";
  const size_t element = static_cast<size_t>(csize) * static_cast<size_t>(ncomp);
  out = View();
  out.count = a.count;
  out.component_type = a.componentType;
  out.components = ncomp;
  out.normalized = a.normalized;
  if (a.bufferView >= 0) {
    if (std::string e = view_strided(m, a, element, csize, name, out); !e.empty()) return e;
    if (!a.sparse.isSparse) return {};
  }

  // Without a bufferView the elements are zeros (exporters write an unused morph target so).
  if (a.count * element > kMaxDenseBytes) return name + " is too large to expand (" + std::to_string(a.count) + " elements)";
  auto dense = std::make_shared<std::vector<uint8_t>>(a.count * element, uint8_t{0});
  if (out.data)
    for (size_t i = 0; i < a.count; ++i) std::memcpy(dense->data() + i * element, out.data + i * out.stride, element);
  if (a.sparse.isSparse)
    if (std::string e = apply_sparse(m, a, element, csize, name, *dense); !e.empty()) return e;
  out.data = dense->data();
  out.stride = element;
  out.owned = std::move(dense);
  return {};
}

}  // namespace hemibake::protocol
