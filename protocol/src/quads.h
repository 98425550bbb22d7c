// Exporters split quads into triangle pairs. Pairs that form a planar convex quad become one quad
// patch again: its elements are then quads, and its light is not cut along the diagonal.
#pragma once

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace hemibake::protocol {

/// A patch's outline: one triangle of the input, or two that share an edge, merged into a quad.
struct Outline {
  std::array<uint32_t, 4> v{};  ///< vertex indices, counter-clockwise, the first `count`; a quad's
                                ///< diagonal v[1]-v[3] is the edge its triangles shared
  uint32_t count = 3;           ///< 3 or 4
  uint32_t first = 0;           ///< the triangle it starts from
  uint32_t second = 0;          ///< a quad's other triangle (a triangle's: `first`)
};

/// Pairs triangles (counter-clockwise vertex triples into `points`) across edges that exactly two of
/// them share into planar, strictly convex quads, greedily in triangle order; the rest stay
/// triangles. Vertices are matched by position (bitwise), so unindexed triangle lists pair up too.
/// With texture coordinates (`uv`, per vertex, or empty) they must agree along the shared edge, so
/// no UV seam runs inside a quad. Returns one outline per patch, in the order of each one's first
/// triangle.
std::vector<Outline> merge_triangle_pairs(std::span<const glm::dvec3> points,
                                          std::span<const std::array<uint32_t, 3>> triangles,
                                          std::span<const glm::dvec2> uv);

}  // namespace hemibake::protocol
