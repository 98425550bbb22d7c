#include "hemibake/solver/scenes.h"

#include <glm/geometric.hpp>

#include <array>
#include <cmath>

namespace hemibake::solver {

void add_quad(Scene& scene, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c,
              const glm::dvec3& d, const glm::dvec3& reflectance, const glm::dvec3& emission,
              uint32_t material) {
  const glm::dvec3 n = glm::normalize(glm::cross(b - a, c - a));
  const double size = std::max(glm::length(c - a), glm::length(d - b));
  Patch p;
  p.reflectance = reflectance;
  p.emission = emission;
  p.material = material;
  if (std::abs(glm::dot(n, d - a)) <= 1e-6 * size) {
    p.corners = {a, b, c, d};
    p.corner_count = 4;
    scene.patches.push_back(p);
    return;
  }
  p.corner_count = 3;
  p.corners = {a, b, c, glm::dvec3(0.0)};
  scene.patches.push_back(p);
  p.corners = {a, c, d, glm::dvec3(0.0)};
  scene.patches.push_back(p);
}

Scene make_cornell_box() {
  Scene s;
  const glm::dvec3 white(0.755, 0.748, 0.751), red(0.443, 0.061, 0.062), green(0.136, 0.406, 0.107);
  const glm::dvec3 light_emission(15.94, 11.65, 5.12), light_reflectance(0.78);
  const glm::dvec3 none(0.0);
  using V = glm::dvec3;
  // Floor, back wall, red (left) wall, green (right) wall.
  add_quad(s, V(552.8, 0, 0), V(0, 0, 0), V(0, 0, 559.2), V(549.6, 0, 559.2), white, none, kCornellWhite);
  add_quad(s, V(549.6, 0, 559.2), V(0, 0, 559.2), V(0, 548.8, 559.2), V(556, 548.8, 559.2), white, none,
           kCornellWhite);
  add_quad(s, V(552.8, 0, 0), V(549.6, 0, 559.2), V(556, 548.8, 559.2), V(556, 548.8, 0), red, none,
           kCornellRed);
  add_quad(s, V(0, 0, 559.2), V(0, 0, 0), V(0, 548.8, 0), V(0, 548.8, 559.2), green, none, kCornellGreen);
  // Ceiling (facing down) in a 3 x 3 grid whose middle cell is the light.
  const std::array<double, 4> xs{0, 213, 343, 556}, zs{0, 227, 332, 559.2};
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < 3; ++k) {
      const bool light = i == 1 && k == 1;
      add_quad(s, V(xs[i], 548.8, zs[k]), V(xs[i + 1], 548.8, zs[k]), V(xs[i + 1], 548.8, zs[k + 1]),
               V(xs[i], 548.8, zs[k + 1]), light ? light_reflectance : white,
               light ? light_emission : none, light ? kCornellLight : kCornellWhite);
    }
  }
  // Blocks: top (counter-clockwise from above) and four sides down to the floor, facing outward.
  auto block = [&](const std::array<V, 4>& top) {
    add_quad(s, top[0], top[1], top[2], top[3], white, none, kCornellWhite);
    V centre(0.0);
    for (const V& t : top) centre += 0.25 * t;
    for (int i = 0; i < 4; ++i) {
      const V a = top[i], b = top[(i + 1) % 4];
      V qa(a.x, 0, a.z), qb(b.x, 0, b.z);
      // Order the side so its normal points away from the block's axis.
      const glm::dvec3 n = glm::cross(qa - a, qb - qa);
      const glm::dvec3 out(0.5 * (a.x + b.x) - centre.x, 0, 0.5 * (a.z + b.z) - centre.z);
      if (glm::dot(n, out) > 0)
        add_quad(s, a, qa, qb, b, white, none, kCornellWhite);
      else
        add_quad(s, b, qb, qa, a, white, none, kCornellWhite);
    }
  };
  block({V(130, 165, 65), V(82, 165, 225), V(240, 165, 272), V(290, 165, 114)});
  block({V(423, 330, 247), V(265, 330, 296), V(314, 330, 456), V(472, 330, 406)});
  return s;
}

Scene make_closed_box(double size, uint32_t cells, const glm::dvec3& reflectance,
                      const glm::dvec3& emission, bool block) {
  Scene s;
  // Six faces of an axis-aligned cube [lo, hi]^3; `inward` picks the side the normals face.
  auto cube = [&](double lo, double hi, uint32_t n, bool inward) {
    const double step = (hi - lo) / n;
    for (int axis = 0; axis < 3; ++axis) {
      for (int side = 0; side < 2; ++side) {
        const int u = (axis + 1) % 3, v = (axis + 2) % 3;
        const double w = side == 0 ? lo : hi;
        // The face at `lo` faces +axis from inside the cube, the face at `hi` faces -axis.
        const bool faces_plus = (side == 0) == inward;
        for (uint32_t i = 0; i < n; ++i) {
          for (uint32_t j = 0; j < n; ++j) {
            std::array<glm::dvec3, 4> q;
            const double u0 = lo + i * step, u1 = lo + (i + 1) * step;
            const double v0 = lo + j * step, v1 = lo + (j + 1) * step;
            const std::array<std::array<double, 2>, 4> uv{{{u0, v0}, {u1, v0}, {u1, v1}, {u0, v1}}};
            for (int c = 0; c < 4; ++c) {
              q[c][axis] = w;
              q[c][u] = uv[c][0];
              q[c][v] = uv[c][1];
            }
            // (u, v, axis) is right-handed: counter-clockwise in (u, v) faces +axis.
            if (faces_plus)
              add_quad(s, q[0], q[1], q[2], q[3], reflectance, emission, 0);
            else
              add_quad(s, q[3], q[2], q[1], q[0], reflectance, emission, 0);
          }
        }
      }
    }
  };
  cube(0.0, size, cells, true);
  if (block) cube(0.3 * size, 0.6 * size, 1, false);
  return s;
}

}  // namespace hemibake::solver
