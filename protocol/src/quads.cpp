// Triangle pairs merged back into the quads an exporter split.
#include "quads.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <unordered_map>

namespace hemibake::protocol {
namespace {

// Which triangles meet at each edge, with vertices identified by position.
struct Adjacency {
  std::vector<uint32_t> canon;  // per vertex: the first vertex (in triangle order) at its position
  std::unordered_map<uint64_t, std::vector<uint32_t>> triangles_of_edge;

  uint64_t edge(uint32_t a, uint32_t b) const {
    a = canon[a];
    b = canon[b];
    return (static_cast<uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
  }
};

Adjacency adjacency(std::span<const glm::dvec3> points, std::span<const std::array<uint32_t, 3>> triangles) {
  Adjacency adj;
  adj.canon.resize(points.size());
  std::unordered_map<std::string, uint32_t> first;
  for (const auto& t : triangles)
    for (uint32_t v : t) {
      std::string key(reinterpret_cast<const char*>(&points[v]), sizeof(glm::dvec3));
      adj.canon[v] = first.try_emplace(std::move(key), v).first->second;
    }
  for (uint32_t t = 0; t < triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) adj.triangles_of_edge[adj.edge(triangles[t][k], triangles[t][(k + 1) % 3])].push_back(t);
  return adj;
}

// The quad that triangle `tv` = (p, q, r) and its neighbour `uv3` across the edge q -> r (k is
// q's place in `tv`) make, if the neighbour runs r -> q -> s, no UV seam runs along the edge and
// the quad is planar and strictly convex seen along `normal`, the first triangle's.
std::optional<std::array<uint32_t, 4>> quad_of(std::span<const glm::dvec3> points, const std::vector<uint32_t>& canon,
                                               std::span<const glm::dvec2> uv, const std::array<uint32_t, 3>& tv, int k,
                                               const std::array<uint32_t, 3>& uv3, const glm::dvec3& normal) {
  const uint32_t q = tv[k], r = tv[(k + 1) % 3], p = tv[(k + 2) % 3];
  int j = -1;
  for (int i = 0; i < 3; ++i)
    if (canon[uv3[i]] == canon[r] && canon[uv3[(i + 1) % 3]] == canon[q]) j = i;
  if (j < 0) return std::nullopt;
  const uint32_t s = uv3[(j + 2) % 3];
  if (canon[s] == canon[p]) return std::nullopt;
  if (!uv.empty() && (uv[uv3[j]] != uv[r] || uv[uv3[(j + 1) % 3]] != uv[q])) return std::nullopt;
  const std::array<uint32_t, 4> quad{p, q, s, r};
  const double size = glm::length(points[s] - points[p]) + glm::length(points[r] - points[q]);
  if (std::abs(glm::dot(normal, points[s] - points[p])) > 1e-9 * size) return std::nullopt;
  for (int i = 0; i < 4; ++i) {
    const glm::dvec3 e0 = points[quad[(i + 1) % 4]] - points[quad[i]];
    const glm::dvec3 e1 = points[quad[(i + 2) % 4]] - points[quad[(i + 1) % 4]];
    if (!(glm::dot(glm::cross(e0, e1), normal) > 1e-6 * glm::length(e0) * glm::length(e1))) return std::nullopt;
  }
  return quad;
}

}  // namespace

std::vector<Outline> merge_triangle_pairs(std::span<const glm::dvec3> points,
                                          std::span<const std::array<uint32_t, 3>> triangles,
                                          std::span<const glm::dvec2> uv) {
  const Adjacency adj = adjacency(points, triangles);
  std::vector<uint8_t> used(triangles.size(), 0);
  std::vector<Outline> out;
  out.reserve(triangles.size());
  for (uint32_t t = 0; t < triangles.size(); ++t) {
    if (used[t]) continue;
    used[t] = 1;
    const auto& tv = triangles[t];
    const glm::dvec3 normal = glm::normalize(glm::cross(points[tv[1]] - points[tv[0]], points[tv[2]] - points[tv[0]]));
    Outline outline{{tv[0], tv[1], tv[2], 0}, 3, t, t};
    // The longest edge first: an exporter splits a quad along a diagonal, its triangles' longest
    // edge. Taking the edges in order paired a grid's triangles across the grid's lines instead,
    // into parallelograms two cells wide (a wall of square tiles became slanted elements, whose
    // splits along a cabinet's outline showed as a sawtooth).
    std::array<int, 3> order{0, 1, 2};
    auto length = [&](int k) { return glm::distance(points[tv[k]], points[tv[(k + 1) % 3]]); };
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return length(a) > length(b); });
    for (int k : order) {
      if (outline.count != 3) break;
      // Only an edge between exactly two triangles: elsewhere the surface branches or ends.
      const auto& sharing = adj.triangles_of_edge.at(adj.edge(tv[k], tv[(k + 1) % 3]));
      if (sharing.size() != 2) continue;
      for (uint32_t u : sharing) {
        if (u == t || used[u]) continue;
        const auto quad = quad_of(points, adj.canon, uv, tv, k, triangles[u], normal);
        if (!quad) continue;
        used[u] = 1;
        outline = {*quad, 4, t, u};
        break;
      }
    }
    out.push_back(outline);
  }
  return out;
}

}  // namespace hemibake::protocol
