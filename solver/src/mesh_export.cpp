// The radiosity mesh: leaf elements with shared vertices, vertex radiosity averaged per surface,
// and the hanging vertices of finer neighbours in each element's boundary loop.
#include "solver_impl.h"

#include <algorithm>
#include <functional>
#include <unordered_map>
#include <unordered_set>

namespace hemibake::solver {

Mesh Solver::mesh(bool ambient) const {
  const Impl& s = *impl_;
  Mesh m;
  // Ambient term (Cohen et al. 1988): the unshot power spread over the scene and reflected on
  // average, per channel: ambient = R * sum(dB_i A_i) / sum(A_i), R = 1 / (1 - rho_mean).
  glm::dvec3 amb(0.0);
  if (ambient) {
    glm::dvec3 unshot(0.0), rho(0.0);
    for (uint32_t e : s.leaves) unshot += s.e_unshot[e] * s.e_area[e];
    for (uint32_t p = 0; p < s.patches.size(); ++p) rho += s.patches[p].reflectance * s.prep.area[p];
    rho /= s.prep.total_area;
    amb = unshot / s.prep.total_area / (glm::dvec3(1.0) - rho);
  }

  std::vector<uint32_t> leaves = s.leaves;
  std::sort(leaves.begin(), leaves.end(), [&](uint32_t a, uint32_t b) {
    return s.e_patch[a] != s.e_patch[b] ? s.e_patch[a] < s.e_patch[b] : a < b;
  });

  // Every vertex position, to find the vertices of other surfaces on an element's edge (they are
  // the same points, computed by the same midpoint arithmetic).
  struct PosHash {
    size_t operator()(const glm::dvec3& p) const {
      return std::hash<double>()(p.x) ^ (std::hash<double>()(p.y) * 31) ^ (std::hash<double>()(p.z) * 131);
    }
  };
  std::unordered_set<glm::dvec3, PosHash> positions(s.vpos.begin(), s.vpos.end());
  m.positions = s.vpos;
  std::vector<std::array<uint32_t, 2>> lerp_from;  // for extra vertices: the edge they lie on
  std::unordered_map<uint64_t, uint32_t> extra;      // edge key -> extra vertex

  // Collects the vertices strictly inside edge (a, b), in order from a to b.
  std::function<void(uint32_t, uint32_t)> hanging = [&](uint32_t a, uint32_t b) {
    uint32_t mid = kNone;
    if (auto it = s.midpoints.find(edge_key(a, b)); it != s.midpoints.end()) {
      mid = it->second;
    } else if (auto ex = extra.find(edge_key(a, b)); ex != extra.end()) {
      mid = ex->second;
    } else {
      const glm::dvec3 pm = 0.5 * (m.positions[a] + m.positions[b]);
      if (positions.count(pm)) {
        mid = static_cast<uint32_t>(m.positions.size());
        m.positions.push_back(pm);
        lerp_from.push_back({a, b});
        extra.emplace(edge_key(a, b), mid);
      }
    }
    if (mid == kNone) return;
    hanging(a, mid);
    m.boundary.push_back(mid);
    hanging(mid, b);
  };

  std::vector<glm::dvec3> acc(s.vpos.size(), glm::dvec3(0.0));
  std::vector<double> weight(s.vpos.size(), 0.0);
  m.elements.reserve(leaves.size());
  for (uint32_t e : leaves) {
    Mesh::Element el;
    el.patch = s.e_patch[e];
    el.corner_count = s.corner_count(e);
    el.corners = s.e_corner[e];
    el.area = s.e_area[e];
    el.radiosity = s.e_b[e] + s.patches[el.patch].reflectance * amb;
    HEMIBAKE_DCHECK(el.radiosity.x >= 0.0 && el.radiosity.y >= 0.0 && el.radiosity.z >= 0.0);
    el.boundary_begin = static_cast<uint32_t>(m.boundary.size());
    for (uint32_t k = 0; k < el.corner_count; ++k) {
      const uint32_t a = el.corners[k], b = el.corners[(k + 1) % el.corner_count];
      m.boundary.push_back(a);
      hanging(a, b);
    }
    el.boundary_end = static_cast<uint32_t>(m.boundary.size());
    const glm::dvec3& rho = s.patches[el.patch].reflectance;
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const uint32_t v = m.boundary[i];
      if (v >= s.vpos.size()) continue;  // another surface's point: interpolated below
      // Gathered: the vertex's own light (gather.cpp); the lights' direct light and light from
      // covered pieces (e_gap) as the element's.
      const glm::dvec3 b = s.gather_done && v < s.v_gathered.size() && s.v_gathered[v]
                               ? s.patches[el.patch].emission + s.e_light[e] + s.e_gap[e] + rho * (s.v_irr[v] + amb)
                               : el.radiosity;
      acc[v] += b * el.area;
      weight[v] += el.area;
    }
    m.elements.push_back(el);
  }
  for (uint32_t v : m.boundary) HEMIBAKE_DCHECK(v < m.positions.size());
  m.radiosity.resize(m.positions.size(), glm::dvec3(0.0));
  for (size_t v = 0; v < s.vpos.size(); ++v)
    if (weight[v] > 0.0) m.radiosity[v] = acc[v] / weight[v];
  // Extra vertices were created in order, each from an earlier vertex pair.
  for (size_t i = 0; i < lerp_from.size(); ++i) {
    const auto [a, b] = lerp_from[i];
    m.radiosity[s.vpos.size() + i] = 0.5 * (m.radiosity[a] + m.radiosity[b]);
  }
  return m;
}

}  // namespace hemibake::solver
