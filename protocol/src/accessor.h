// Checked reads of glTF accessors. tinygltf checks none of an accessor's ranges; everything here is
// checked against the buffers before a byte is read, and a fault comes back as a message that names
// the accessor and what it was read for.
#pragma once

#include <tiny_gltf.h>

#include <glm/vec3.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace hemibake::protocol {

/// A checked view of an accessor's elements.
struct View {
  const uint8_t* data = nullptr;  ///< first element
  size_t stride = 0;
  size_t count = 0;
  int component_type = 0;
  int components = 0;
  bool normalized = false;
  std::shared_ptr<const std::vector<uint8_t>> owned;  ///< a sparse accessor's elements, made dense
};

/// Bytes of one component of glTF componentType `type`; 0 for an unknown type.
int component_size(int type);

/// Components per element of glTF accessor type `type` (SCALAR 1 ... MAT4 16); 0 for an unknown type.
int component_count(int type);

/// Component `c` of element `i` as a double (normalized integers mapped to [0, 1] or [-1, 1]).
/// Precondition: `i` < v.count and `c` < v.components.
double read_component(const View& v, size_t i, int c);

/// Components 0, 1 and 2 of element `i`. Precondition: v.components >= 3.
glm::dvec3 read_vec3(const View& v, size_t i);

/// Checks accessor `index` for use as `what` ("POSITION of mesh 0 primitive 1") and returns a view
/// of it, or an error message. An accessor without a bufferView is zeros (glTF 2.0, section 3.6.2);
/// a sparse accessor (3.6.2.3) is those or its bufferView's elements, with the elements at
/// `sparse.indices` replaced by `sparse.values`. Either is made dense in a copy that the view owns.
std::string view_accessor(const tinygltf::Model& m, int index, const std::string& what, View& out);

}  // namespace hemibake::protocol
