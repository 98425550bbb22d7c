// What a viewer shows on a floor: shared by the solver's tests that compare it with closed forms.
#pragma once

#include "hemibake/solver/solver.h"

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

namespace hemibake::solver {

// What a viewer shows at (x, 0, z) on a floor facing +y: the element holding the point, its loop
// drawn as one triangle or as a fan from its centre (the mean of its loop), values interpolated
// barycentrically. Empty when no element of `patches` holds the point.
inline std::optional<glm::dvec3> shown_on_floor(const Mesh& mesh, uint32_t first_patch, uint32_t end_patch, double x, double z) {
  auto cross2 = [](const glm::dvec2& a, const glm::dvec2& b) { return a.x * b.y - a.y * b.x; };
  const glm::dvec2 p(x, z);
  for (const Mesh::Element& el : mesh.elements) {
    if (el.patch < first_patch || el.patch >= end_patch) continue;
    std::vector<glm::dvec2> loop;
    std::vector<glm::dvec3> value;
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const glm::dvec3& q = mesh.positions[mesh.boundary[i]];
      loop.emplace_back(q.x, q.z);
      value.push_back(mesh.radiosity[mesh.boundary[i]]);
    }
    glm::dvec2 c(0.0);
    glm::dvec3 vc(0.0);
    for (size_t k = 0; k < loop.size(); ++k) {
      c += loop[k];
      vc += value[k];
    }
    c /= static_cast<double>(loop.size());
    vc /= static_cast<double>(loop.size());
    // Triangles (a, b, d) with values; a loop of three is itself the triangle.
    auto inside = [&](const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& d, const glm::dvec3& va,
                      const glm::dvec3& vb, const glm::dvec3& vd) -> std::optional<glm::dvec3> {
      const double area = cross2(b - a, d - a);
      if (std::abs(area) < 1e-15) return std::nullopt;
      const double wa = cross2(b - p, d - p) / area, wb = cross2(d - p, a - p) / area, wd = cross2(a - p, b - p) / area;
      if (wa < -1e-12 || wb < -1e-12 || wd < -1e-12) return std::nullopt;
      return wa * va + wb * vb + wd * vd;
    };
    if (loop.size() == 3) {
      if (auto v = inside(loop[0], loop[1], loop[2], value[0], value[1], value[2])) return v;
      continue;
    }
    for (size_t k = 0; k < loop.size(); ++k) {
      const size_t j = (k + 1) % loop.size();
      if (auto v = inside(c, loop[k], loop[j], vc, value[k], value[j])) return v;
    }
  }
  return std::nullopt;
}

}  // namespace hemibake::solver
