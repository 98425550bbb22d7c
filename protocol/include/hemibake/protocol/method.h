// The bake methods, by the names the command line, the wire and baked files use.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

namespace hemibake::protocol {

/// How a bake computes radiosity.
enum class Method : uint8_t {
  kAntiAliased,   ///< "aa": the paper's anti-aliased hemicube (the default)
  kClassical,     ///< "classical": the point-sampled, z-buffered hemicube
  kHierarchical,  ///< "hr": hierarchical radiosity with ray-cast visibility (a baseline)
  kReference,     ///< "reference": the aa mesh with path-traced radiosity at its vertices
};

/// "aa", "classical", "hr" or "reference".
const char* to_string(Method method);

/// The method of that name, or nullopt.
std::optional<Method> method_from(std::string_view name);

}  // namespace hemibake::protocol
