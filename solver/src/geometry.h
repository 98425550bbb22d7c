// Polygon helpers shared by the solver's sources: areas, centres and the quadtree's children of
// the triangles and convex quads that patches and elements are.
#pragma once

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

namespace hemibake::solver::detail {

inline double channel_sum(const glm::dvec3& c) { return c.x + c.y + c.z; }
// How far along segment (a, b) point x lies, in [0, |b - a|], if it lies on the segment, ends
// included (within tol of its line and of its extent); else -1.
inline double on_segment(const glm::dvec3& x, const glm::dvec3& a, const glm::dvec3& b, double tol) {
  const glm::dvec3 d = b - a;
  const double len = glm::length(d);
  if (len <= 2.0 * tol) return -1.0;
  const glm::dvec3 r = x - a;
  const double t = glm::dot(r, d) / len;
  return t >= -tol && t <= len + tol && glm::length(r - d * (t / len)) <= tol ? std::clamp(t, 0.0, len) : -1.0;
}
// The same strictly between the ends (more than tol from either); else -1. T-junctions: a corner
// of one patch inside another's edge.
inline double along_segment(const glm::dvec3& x, const glm::dvec3& a, const glm::dvec3& b, double tol) {
  const double t = on_segment(x, a, b, tol);
  return t > tol && t < glm::length(b - a) - tol ? t : -1.0;
}
inline double mean(const glm::dvec3& c) { return (c.x + c.y + c.z) / 3.0; }
// Key of the undirected edge (a, b).
inline uint64_t edge_key(uint32_t a, uint32_t b) {
  if (a > b) std::swap(a, b);
  return (static_cast<uint64_t>(a) << 32) | b;
}

using Corners = std::array<glm::dvec3, 4>;

// Child k of a quad (4 corners) or triangle (3), in the order Solver::Impl::split creates them.
// Quads split at edge midpoints and the corners' mean (the bilinear centre); triangles at edge
// midpoints, the fourth child being the middle triangle.
inline uint32_t child_corners(const Corners& c, uint32_t n, uint32_t k, Corners& out) {
  if (n == 4) {
    const glm::dvec3 m01 = 0.5 * (c[0] + c[1]), m12 = 0.5 * (c[1] + c[2]);
    const glm::dvec3 m23 = 0.5 * (c[2] + c[3]), m30 = 0.5 * (c[3] + c[0]);
    const glm::dvec3 ctr = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    const std::array<Corners, 4> kids{{{c[0], m01, ctr, m30}, {m01, c[1], m12, ctr},
                                       {ctr, m12, c[2], m23}, {m30, ctr, m23, c[3]}}};
    out = kids[k];
    return 4;
  }
  const glm::dvec3 m01 = 0.5 * (c[0] + c[1]), m12 = 0.5 * (c[1] + c[2]), m20 = 0.5 * (c[2] + c[0]);
  const std::array<Corners, 4> kids{{{c[0], m01, m20, {}}, {m01, c[1], m12, {}},
                                     {m20, m12, c[2], {}}, {m12, m20, m01, {}}}};
  out = kids[k];
  return 3;
}

inline double polygon_area(const Corners& c, uint32_t n) {
  if (n == 4) return 0.5 * glm::length(glm::cross(c[2] - c[0], c[3] - c[1]));
  return 0.5 * glm::length(glm::cross(c[1] - c[0], c[2] - c[0]));
}

inline double polygon_diameter(const Corners& c, uint32_t n) {
  double d = 0.0;
  for (uint32_t i = 0; i < n; ++i)
    for (uint32_t j = i + 1; j < n; ++j) d = std::max(d, glm::length(c[i] - c[j]));
  return d;
}

// Reorders ids[begin, end) around its middle (returned) by the points key(id) along the widest
// axis of their bounding box [lo, hi]: a median cut, ties broken by id so that it is deterministic.
template <typename Key>
inline uint32_t median_cut(std::vector<uint32_t>& ids, uint32_t begin, uint32_t end, const glm::dvec3& lo,
                    const glm::dvec3& hi, Key key) {
  const glm::dvec3 ext = hi - lo;
  const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : ext.y >= ext.z ? 1 : 2;
  const uint32_t mid = begin + (end - begin) / 2;
  std::nth_element(ids.begin() + begin, ids.begin() + mid, ids.begin() + end, [&](uint32_t a, uint32_t b) {
    const double ka = key(a)[axis], kb = key(b)[axis];
    return ka != kb ? ka < kb : a < b;
  });
  return mid;
}

inline glm::dvec3 polygon_centre(const Corners& c, uint32_t n) {
  if (n == 3) return (c[0] + c[1] + c[2]) / 3.0;
  // Area centroid of a convex quad: area-weighted centroids of its two triangles.
  const double a1 = 0.5 * glm::length(glm::cross(c[1] - c[0], c[2] - c[0]));
  const double a2 = 0.5 * glm::length(glm::cross(c[2] - c[0], c[3] - c[0]));
  const glm::dvec3 g1 = (c[0] + c[1] + c[2]) / 3.0, g2 = (c[0] + c[2] + c[3]) / 3.0;
  return (a1 + a2) > 0.0 ? (a1 * g1 + a2 * g2) / (a1 + a2) : 0.25 * (c[0] + c[1] + c[2] + c[3]);
}

}  // namespace hemibake::solver::detail
