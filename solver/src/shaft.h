// What may hide a near-field hemicube's receivers. What hides a receiver lies between the piece's
// centre and the receiver, so within the convex hull of the piece and the receiver, and so within
// their joint bounding box. The receivers are boxed by surface (occlusion group), each box joined
// with the piece's: an element overlapping none of the boxes hides nothing from any receiver.
#pragma once

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <limits>
#include <vector>

namespace hemibake::solver::detail {

struct Box {
  glm::dvec3 lo{std::numeric_limits<double>::max()}, hi{std::numeric_limits<double>::lowest()};
  void add(const glm::dvec3& x) { lo = glm::min(lo, x); hi = glm::max(hi, x); }
  void add(const Box& b) { lo = glm::min(lo, b.lo); hi = glm::max(hi, b.hi); }
};

struct Shaft {
  bool whole_scene = true;  ///< a whole-scene hemicube sees everything: no boxes
  std::vector<Box> boxes;

  /// Whether the sphere (centre c, radius r) overlaps a box.
  bool overlaps(const glm::dvec3& c, double r) const {
    if (whole_scene) return true;
    const double r2 = r * r;
    for (const Box& b : boxes) {
      const glm::dvec3 d = glm::max(b.lo - c, glm::max(c - b.hi, glm::dvec3(0.0)));
      if (glm::dot(d, d) <= r2) return true;
    }
    return false;
  }

  /// Whether the box [lo, hi], widened by `slack`, meets a box.
  bool meets(const glm::dvec3& lo, const glm::dvec3& hi, double slack) const {
    for (const Box& b : boxes)
      if (lo.x <= b.hi.x + slack && lo.y <= b.hi.y + slack && lo.z <= b.hi.z + slack && hi.x + slack >= b.lo.x &&
          hi.y + slack >= b.lo.y && hi.z + slack >= b.lo.z)
        return true;
    return false;
  }
};

}  // namespace hemibake::solver::detail
