// A room whose wall is built of stacked boxes, as exporters write walls around a window: shared by
// the seam tests (one light across the boxes' seam) and the displayed-error tests (against the path
// tracer, with a shelf on the seam).
#pragma once

#include "add_box.h"

#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

#include <cstdint>

namespace hemibake::solver {

// A 4 x 2.5 x 4 m room whose wall at x = 0 is built of boxes, as exporters write walls around a
// window: a box up to 1 m, a narrower one above it up to the ceiling (z 0 to 2.5), and a lintel
// over the window (z 2.5 to 4, from 1.8 m); the lower box's top is pressed against the upper one's
// bottom, and is the window's sill beyond it. A lamp under the ceiling lights the wall, brighter
// above. With `shelf`, a shelf box 0.3 m deep stands on the wall at the 1 m seam (z 0.5 to 2),
// shading the wall under it. Patches: 0 floor, 1 ceiling, 2-4 the other walls, 5 the lamp, then
// the boxes' six faces each (add_box: +y, -y, -z, +z, -x, +x), lower, upper, lintel, shelf.
struct StackedWall {
  Scene scene;
  uint32_t lower_face, upper_face;
};
inline StackedWall stacked_wall_room(bool shelf) {
  StackedWall w;
  Scene& scene = w.scene;
  const glm::dvec3 rho(0.6), dark(0.0);
  add_quad(scene, {0, 0, 0}, {0, 0, 4}, {4, 0, 4}, {4, 0, 0}, rho, dark, 0);
  add_quad(scene, {0, 2.5, 0}, {4, 2.5, 0}, {4, 2.5, 4}, {0, 2.5, 4}, rho, dark, 0);
  add_quad(scene, {4, 0, 0}, {4, 0, 4}, {4, 2.5, 4}, {4, 2.5, 0}, rho, dark, 0);
  add_quad(scene, {0, 0, 0}, {4, 0, 0}, {4, 2.5, 0}, {0, 2.5, 0}, rho, dark, 0);
  add_quad(scene, {0, 0, 4}, {0, 2.5, 4}, {4, 2.5, 4}, {4, 0, 4}, rho, dark, 0);
  add_quad(scene, {0.8, 2.45, 0.8}, {1.4, 2.45, 0.8}, {1.4, 2.45, 1.6}, {0.8, 2.45, 1.6}, glm::dvec3(0.0), glm::dvec3(30.0), 1);
  const uint32_t boxes = static_cast<uint32_t>(scene.patches.size());
  add_box(scene, {-0.2, 0, 0}, {0, 1, 4}, rho, dark, 0);
  add_box(scene, {-0.2, 1, 0}, {0, 2.5, 2.5}, rho, dark, 0);
  add_box(scene, {-0.2, 1.8, 2.5}, {0, 2.5, 4}, rho, dark, 0);
  if (shelf) add_box(scene, {0, 1, 0.5}, {0.3, 1.04, 2.0}, rho, dark, 0);
  w.lower_face = boxes + 5;
  w.upper_face = boxes + 6 + 5;
  return w;
}

}  // namespace hemibake::solver
