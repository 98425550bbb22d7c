// A closed box of six quads: shared by the solver's tests that build rooms and furniture from boxes.
#pragma once

#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

#include <cstdint>

namespace hemibake::solver {

// A closed box from lo to hi, its six faces looking out, one patch each.
inline void add_box(Scene& scene, const glm::dvec3& lo, const glm::dvec3& hi, const glm::dvec3& rho,
                    const glm::dvec3& e, uint32_t material) {
  using V = glm::dvec3;
  add_quad(scene, V(lo.x, hi.y, lo.z), V(lo.x, hi.y, hi.z), V(hi.x, hi.y, hi.z), V(hi.x, hi.y, lo.z), rho, e, material);
  add_quad(scene, V(lo.x, lo.y, lo.z), V(hi.x, lo.y, lo.z), V(hi.x, lo.y, hi.z), V(lo.x, lo.y, hi.z), rho, e, material);
  add_quad(scene, V(lo.x, lo.y, lo.z), V(lo.x, hi.y, lo.z), V(hi.x, hi.y, lo.z), V(hi.x, lo.y, lo.z), rho, e, material);
  add_quad(scene, V(lo.x, lo.y, hi.z), V(hi.x, lo.y, hi.z), V(hi.x, hi.y, hi.z), V(lo.x, hi.y, hi.z), rho, e, material);
  add_quad(scene, V(lo.x, lo.y, lo.z), V(lo.x, lo.y, hi.z), V(lo.x, hi.y, hi.z), V(lo.x, hi.y, lo.z), rho, e, material);
  add_quad(scene, V(hi.x, lo.y, lo.z), V(hi.x, hi.y, lo.z), V(hi.x, hi.y, hi.z), V(hi.x, lo.y, hi.z), rho, e, material);
}

}  // namespace hemibake::solver
