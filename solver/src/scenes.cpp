#include "hemibake/solver/scenes.h"

#include <glm/geometric.hpp>

#include <array>
#include <algorithm>
#include <cmath>
#include <vector>

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

Scene make_furnished_room(uint32_t target_patches) {
  using V = glm::dvec3;
  struct Box {
    V lo, hi;
    glm::dvec3 rho;
    bool floor_open;  // standing on the floor: no bottom face
  };
  const glm::dvec3 wall(0.7), floor(0.45, 0.4, 0.35), wood(0.5, 0.35, 0.2), metal(0.55, 0.55, 0.6), cloth(0.3, 0.35, 0.5);
  const V room(6.0, 3.0, 5.0);
  std::vector<Box> boxes;
  // Table (top and four legs), four chairs (seat, back, legs), a cabinet, a bench, a door frame.
  auto table = [&](V c) {
    boxes.push_back({c + V(-0.8, 0.72, -0.45), c + V(0.8, 0.76, 0.45), wood, false});
    for (double sx : {-0.72, 0.68})
      for (double sz : {-0.37, 0.33}) boxes.push_back({c + V(sx, 0.0, sz), c + V(sx + 0.04, 0.72, sz + 0.04), wood, true});
  };
  auto chair = [&](V c, double facing) {
    boxes.push_back({c + V(-0.22, 0.44, -0.22), c + V(0.22, 0.48, 0.22), cloth, false});
    const double bz = facing > 0 ? -0.22 : 0.18;
    boxes.push_back({c + V(-0.22, 0.48, bz), c + V(0.22, 0.95, bz + 0.04), cloth, false});
    for (double sx : {-0.2, 0.17})
      for (double sz : {-0.2, 0.17}) boxes.push_back({c + V(sx, 0.0, sz), c + V(sx + 0.03, 0.44, sz + 0.03), metal, true});
  };
  table(V(3.0, 0.0, 2.5));
  chair(V(2.5, 0.0, 1.7), 1.0);
  chair(V(3.5, 0.0, 1.7), 1.0);
  chair(V(2.5, 0.0, 3.3), -1.0);
  chair(V(3.5, 0.0, 3.3), -1.0);
  boxes.push_back({V(0.1, 0.0, 0.3), V(0.6, 1.9, 1.5), metal, true});    // cabinet
  boxes.push_back({V(4.6, 0.0, 4.4), V(5.8, 0.45, 4.85), wood, true});    // bench
  boxes.push_back({V(5.96, 0.0, 1.8), V(6.0, 2.1, 2.8), wood, false});     // door (on the wall)

  // Total area, to size the grid cells so that the patch count comes near the target.
  auto box_area = [](const Box& b) {
    const V d = b.hi - b.lo;
    return 2.0 * (d.x * d.y + d.y * d.z + d.z * d.x) - (b.floor_open ? d.x * d.z : 0.0);
  };
  double area = 2.0 * (room.x * room.y + room.y * room.z + room.z * room.x);
  for (const Box& b : boxes) area += box_area(b);
  const double cell = std::sqrt(area / target_patches);

  Scene s;
  // A rectangle from `o` spanned by `u` and `v` (counter-clockwise seen from the front), cut into a
  // grid of cells about `cell` wide.
  auto rect = [&](V o, V u, V v, const glm::dvec3& rho, const glm::dvec3& e, uint32_t material) {
    const int nu = std::max(1, static_cast<int>(std::lround(glm::length(u) / cell)));
    const int nv = std::max(1, static_cast<int>(std::lround(glm::length(v) / cell)));
    for (int i = 0; i < nu; ++i)
      for (int j = 0; j < nv; ++j) {
        const V a = o + u * (double(i) / nu) + v * (double(j) / nv);
        const V du = u / double(nu), dv = v / double(nv);
        add_quad(s, a, a + du, a + du + dv, a + dv, rho, e, material);
      }
  };
  const glm::dvec3 none(0.0);
  // Room, seen from inside: floor, ceiling (with light panels), four walls.
  rect(V(0, 0, 0), V(0, 0, room.z), V(room.x, 0, 0), floor, none, 1);
  rect(V(0, room.y, 0), V(room.x, 0, 0), V(0, 0, room.z), wall, none, 0);
  rect(V(0, 0, 0), V(room.x, 0, 0), V(0, room.y, 0), wall, none, 0);
  rect(V(0, 0, room.z), V(0, room.y, 0), V(room.x, 0, 0), wall, none, 0);
  rect(V(0, 0, 0), V(0, room.y, 0), V(0, 0, room.z), wall, none, 0);
  rect(V(room.x, 0, 0), V(0, 0, room.z), V(0, room.y, 0), wall, none, 0);
  // Light panels just below the ceiling, facing down.
  for (double lx : {1.5, 4.5})
    for (double lz : {1.5, 3.5})
      add_quad(s, V(lx - 0.5, room.y - 0.01, lz - 0.3), V(lx + 0.5, room.y - 0.01, lz - 0.3),
               V(lx + 0.5, room.y - 0.01, lz + 0.3), V(lx - 0.5, room.y - 0.01, lz + 0.3), glm::dvec3(0.8),
               glm::dvec3(12.0, 11.0, 9.0), 2);
  // Boxes, faces outward.
  uint32_t material = 3;
  for (const Box& b : boxes) {
    const V lo = b.lo, d = b.hi - b.lo;
    rect(V(lo.x, b.hi.y, lo.z), V(0, 0, d.z), V(d.x, 0, 0), b.rho, none, material);            // top
    if (!b.floor_open) rect(lo, V(d.x, 0, 0), V(0, 0, d.z), b.rho, none, material);            // bottom
    rect(lo, V(0, d.y, 0), V(d.x, 0, 0), b.rho, none, material);                              // -z
    rect(V(lo.x, lo.y, b.hi.z), V(d.x, 0, 0), V(0, d.y, 0), b.rho, none, material);           // +z
    rect(lo, V(0, 0, d.z), V(0, d.y, 0), b.rho, none, material);                              // -x
    rect(V(b.hi.x, lo.y, lo.z), V(0, d.y, 0), V(0, 0, d.z), b.rho, none, material);           // +x
    ++material;
  }
  return s;
}

}  // namespace hemibake::solver

namespace hemibake::solver {
namespace {

// A small deterministic generator (the same scene on every platform, unlike <random>'s
// distributions).
struct Lcg {
  uint64_t state;
  double next() {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * (1.0 / 9007199254740992.0);
  }
  double in(double lo, double hi) { return lo + (hi - lo) * next(); }
};

// A rectangle from `o` spanned by `u` and `v` (counter-clockwise seen from the front) in cells no
// wider than `cell`.
void add_grid(Scene& s, const glm::dvec3& o, const glm::dvec3& u, const glm::dvec3& v, const glm::dvec3& rho,
              const glm::dvec3& e, double cell, uint32_t material) {
  const int nu = std::max(1, static_cast<int>(std::ceil(glm::length(u) / cell - 1e-9)));
  const int nv = std::max(1, static_cast<int>(std::ceil(glm::length(v) / cell - 1e-9)));
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const glm::dvec3 a = o + u * (double(i) / nu) + v * (double(j) / nv);
      const glm::dvec3 du = u / double(nu), dv = v / double(nv);
      add_quad(s, a, a + du, a + du + dv, a + dv, rho, e, material);
    }
}

}  // namespace

Scene make_cluttered_room(uint32_t small_boxes, uint32_t seed) {
  using V = glm::dvec3;
  const V room(8.0, 3.0, 6.0);
  const glm::dvec3 wall(0.7), floor(0.45, 0.4, 0.35), wood(0.5, 0.35, 0.2), metal(0.55, 0.55, 0.6),
      cloth(0.3, 0.35, 0.5), none(0.0);
  Scene s;
  uint32_t material = 0;
  // A rectangle from `o` spanned by `u` and `v` (counter-clockwise seen from the front) in cells no
  // wider than `cell`.
  auto rect = [&](V o, V u, V v, const glm::dvec3& rho, const glm::dvec3& e, double cell) {
    add_grid(s, o, u, v, rho, e, cell, material);
  };
  // An axis-aligned box, faces outward; `open_bottom` for what stands on something.
  auto box = [&](V lo, V hi, const glm::dvec3& rho, bool open_bottom, double cell) {
    const V d = hi - lo;
    rect(V(lo.x, hi.y, lo.z), V(0, 0, d.z), V(d.x, 0, 0), rho, none, cell);
    if (!open_bottom) rect(lo, V(d.x, 0, 0), V(0, 0, d.z), rho, none, cell);
    rect(lo, V(0, d.y, 0), V(d.x, 0, 0), rho, none, cell);
    rect(V(lo.x, lo.y, hi.z), V(d.x, 0, 0), V(0, d.y, 0), rho, none, cell);
    rect(lo, V(0, 0, d.z), V(0, d.y, 0), rho, none, cell);
    rect(V(hi.x, lo.y, lo.z), V(0, d.y, 0), V(0, 0, d.z), rho, none, cell);
    ++material;
  };
  // Room, seen from inside, in 0.25 m tiles.
  const double tile = 0.25;
  rect(V(0, 0, 0), V(0, 0, room.z), V(room.x, 0, 0), floor, none, tile);
  rect(V(0, room.y, 0), V(room.x, 0, 0), V(0, 0, room.z), wall, none, tile);
  rect(V(0, 0, 0), V(room.x, 0, 0), V(0, room.y, 0), wall, none, tile);
  rect(V(0, 0, room.z), V(0, room.y, 0), V(room.x, 0, 0), wall, none, tile);
  rect(V(0, 0, 0), V(0, room.y, 0), V(0, 0, room.z), wall, none, tile);
  rect(V(room.x, 0, 0), V(0, 0, room.z), V(0, room.y, 0), wall, none, tile);
  ++material;
  // Six light panels 1 cm under the ceiling, facing down.
  for (double lx : {1.6, 4.0, 6.4})
    for (double lz : {1.8, 4.2})
      add_quad(s, V(lx - 0.5, room.y - 0.01, lz - 0.3), V(lx + 0.5, room.y - 0.01, lz - 0.3),
               V(lx + 0.5, room.y - 0.01, lz + 0.3), V(lx - 0.5, room.y - 0.01, lz + 0.3), glm::dvec3(0.8),
               glm::dvec3(12.0, 11.0, 9.0), material);
  ++material;
  // What occupies the floor (x-z boxes with a margin), so that small boxes stand in free places.
  struct Area {
    double x0, z0, x1, z1;
  };
  std::vector<Area> taken;
  const double furniture_cell = 0.5;
  // Six tables (top and four legs), each with four chairs (seat, back, four legs).
  std::vector<Area> table_tops;
  for (double tx : {1.6, 4.0, 6.4})
    for (double tz : {1.7, 4.3}) {
      const V c(tx, 0.0, tz);
      box(c + V(-0.8, 0.72, -0.45), c + V(0.8, 0.76, 0.45), wood, false, furniture_cell);
      for (double sx : {-0.72, 0.68})
        for (double sz : {-0.37, 0.33}) box(c + V(sx, 0.0, sz), c + V(sx + 0.04, 0.72, sz + 0.04), wood, true, furniture_cell);
      table_tops.push_back({tx - 0.8, tz - 0.45, tx + 0.8, tz + 0.45});
      taken.push_back({tx - 0.85, tz - 0.5, tx + 0.85, tz + 0.5});
      for (double cx : {-0.4, 0.4})
        for (double side : {-1.0, 1.0}) {
          const V k(tx + cx, 0.0, tz + side * 0.75);
          box(k + V(-0.22, 0.44, -0.22), k + V(0.22, 0.48, 0.22), cloth, false, furniture_cell);
          const double bz = side < 0 ? -0.22 : 0.18;
          box(k + V(-0.22, 0.48, bz), k + V(0.22, 0.95, bz + 0.04), cloth, false, furniture_cell);
          for (double sx : {-0.2, 0.17})
            for (double sz : {-0.2, 0.17}) box(k + V(sx, 0.0, sz), k + V(sx + 0.03, 0.44, sz + 0.03), metal, true, furniture_cell);
          taken.push_back({k.x - 0.27, k.z - 0.27, k.x + 0.27, k.z + 0.27});
        }
    }
  // Five cabinets along the walls.
  const std::array<Area, 5> cabinets{{{0.05, 0.3, 0.55, 1.3}, {0.05, 4.6, 0.55, 5.6}, {7.45, 2.5, 7.95, 3.5},
                                      {2.5, 5.45, 3.7, 5.95}, {5.0, 0.05, 6.2, 0.55}}};
  for (const Area& a : cabinets) {
    box(V(a.x0, 0.0, a.z0), V(a.x1, 1.9, a.z1), metal, true, furniture_cell);
    taken.push_back({a.x0 - 0.05, a.z0 - 0.05, a.x1 + 0.05, a.z1 + 0.05});
  }
  // Small boxes in slots of 0.2 m (so that none overlap): on the table tops, and on the free floor.
  Lcg rng{seed * 0x9E3779B97F4A7C15ull + 1};
  struct Slot {
    double x, y, z;
  };
  std::vector<Slot> slots;
  const double slot = 0.2;
  for (const Area& t : table_tops)
    for (double x = t.x0 + 0.1; x + 0.1 <= t.x1 + 1e-9; x += slot)
      for (double z = t.z0 + 0.1; z + 0.1 <= t.z1 + 1e-9; z += slot) slots.push_back({x, 0.76, z});
  for (double x = 0.2; x < room.x - 0.1; x += slot)
    for (double z = 0.2; z < room.z - 0.1; z += slot) {
      bool free = true;
      for (const Area& a : taken) free = free && !(x + 0.1 > a.x0 && x - 0.1 < a.x1 && z + 0.1 > a.z0 && z - 0.1 < a.z1);
      if (free) slots.push_back({x, 0.0, z});
    }
  // A seeded shuffle, then the first `small_boxes` slots.
  for (size_t i = slots.size(); i > 1; --i) std::swap(slots[i - 1], slots[static_cast<size_t>(rng.next() * i) % i]);
  const std::array<glm::dvec3, 4> colours{glm::dvec3(0.7, 0.2, 0.2), glm::dvec3(0.2, 0.5, 0.7), glm::dvec3(0.8, 0.7, 0.3),
                                          glm::dvec3(0.6)};
  for (uint32_t i = 0; i < std::min<size_t>(small_boxes, slots.size()); ++i) {
    const Slot& sl = slots[i];
    const double w = rng.in(0.04, 0.18), d = rng.in(0.04, 0.18), h = rng.in(0.04, 0.18);
    const double x = sl.x + rng.in(-0.5, 0.5) * (0.19 - w), z = sl.z + rng.in(-0.5, 0.5) * (0.19 - d);
    box(V(x - 0.5 * w, sl.y, z - 0.5 * d), V(x + 0.5 * w, sl.y + h, z + 0.5 * d), colours[i % 4], true, 1.0);
  }
  return s;
}

void add_uv_sphere(Scene& s, const glm::dvec3& centre, double radius, int rings, int segments,
                   const glm::dvec3& rho, const glm::dvec3& e, uint32_t material) {
  auto at = [&](int i, int j) {
    const double th = 3.14159265358979323846 * i / rings, ph = 2.0 * 3.14159265358979323846 * j / segments;
    return centre + radius * glm::dvec3(std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph));
  };
  auto tri = [&](const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
    Patch p;
    p.corners = {a, c, b, glm::dvec3(0.0)};  // (a, b, c) run clockwise seen from outside
    p.corner_count = 3;
    p.reflectance = rho;
    p.emission = e;
    p.material = material;
    s.patches.push_back(p);
  };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      if (i > 0) tri(at(i, j), at(i + 1, j + 1), at(i, j + 1));
      if (i < rings - 1) tri(at(i, j), at(i + 1, j), at(i + 1, j + 1));
    }
}

Scene make_lava_field() {
  using V = glm::dvec3;
  Scene s;
  const glm::dvec3 ground(0.5, 0.45, 0.4), none(0.0);
  add_quad(s, V(-10, 0, -10), V(-10, 0, 10), V(10, 0, 10), V(10, 0, -10), ground, none, 0);
  Lcg rng{7};
  uint32_t material = 1;
  // 36 objects on a jittered 6 x 6 grid: spheres of 16 x 24 (720 triangles) and boxes whose five
  // faces are 4 x 4 grids.
  for (int i = 0; i < 6; ++i)
    for (int k = 0; k < 6; ++k) {
      const double x = -8.0 + 3.2 * i + rng.in(-0.6, 0.6), z = -8.0 + 3.2 * k + rng.in(-0.6, 0.6);
      const glm::dvec3 rho(rng.in(0.3, 0.8), rng.in(0.3, 0.8), rng.in(0.3, 0.8));
      if ((i + k) % 2 == 0) {
        const double r = rng.in(0.3, 0.8);
        add_uv_sphere(s, V(x, r, z), r, 16, 24, rho, none, material++);
      } else {
        const double w = rng.in(0.4, 1.2), h = rng.in(0.4, 1.5);
        const V lo(x - w / 2, 0.0, z - w / 2), hi(x + w / 2, h, z + w / 2), d = hi - lo;
        auto rect = [&](V o, V u, V v) {
          for (int a = 0; a < 4; ++a)
            for (int b = 0; b < 4; ++b) {
              const V c = o + u * (a / 4.0) + v * (b / 4.0);
              add_quad(s, c, c + u / 4.0, c + u / 4.0 + v / 4.0, c + v / 4.0, rho, none, material);
            }
        };
        rect(V(lo.x, hi.y, lo.z), V(0, 0, d.z), V(d.x, 0, 0));
        rect(lo, V(0, d.y, 0), V(d.x, 0, 0));
        rect(V(lo.x, lo.y, hi.z), V(d.x, 0, 0), V(0, d.y, 0));
        rect(lo, V(0, 0, d.z), V(0, d.y, 0));
        rect(V(hi.x, lo.y, lo.z), V(0, d.y, 0), V(0, 0, d.z));
        ++material;
      }
    }
  // Six lava spheres between the objects, 0.4 m, 24 x 24 (1104 triangles each).
  for (int n = 0; n < 6; ++n) {
    const double x = -6.4 + 3.2 * (n % 3) * 2.0 + 1.6, z = n < 3 ? -3.2 : 3.2;
    add_uv_sphere(s, V(x, 0.45, z), 0.4, 24, 24, glm::dvec3(0.2), glm::dvec3(20.0, 6.0, 1.0), material++);
  }
  return s;
}

namespace {

constexpr double kPi = 3.14159265358979323846;

// A surface of revolution around the vertical through `base`: `profile` lists (radius, height)
// from the bottom up, each ring cut into `segments` planar quads facing outward (a ring of radius 0
// closes the top or bottom).
void add_lathe(Scene& s, const glm::dvec3& base, const std::vector<std::array<double, 2>>& profile, int segments,
               const glm::dvec3& rho, uint32_t material) {
  auto at = [&](size_t i, int j) {
    const double a = 2.0 * kPi * j / segments;
    return base + glm::dvec3(profile[i][0] * std::cos(a), profile[i][1], -profile[i][0] * std::sin(a));
  };
  for (size_t i = 0; i + 1 < profile.size(); ++i)
    for (int j = 0; j < segments; ++j) {
      const glm::dvec3 a = at(i, j), b = at(i, j + 1), c = at(i + 1, j + 1), d = at(i + 1, j);
      Patch p;
      p.reflectance = rho;
      p.material = material;
      if (profile[i][0] == 0.0 || profile[i + 1][0] == 0.0) {  // a cone's tip: one triangle
        p.corner_count = 3;
        p.corners = profile[i][0] == 0.0 ? std::array<glm::dvec3, 4>{a, c, d, glm::dvec3(0.0)}
                                         : std::array<glm::dvec3, 4>{a, b, c, glm::dvec3(0.0)};
        s.patches.push_back(p);
      } else {
        add_quad(s, a, b, c, d, rho, glm::dvec3(0.0), material);
      }
    }
}

}  // namespace

Scene make_atrium() {
  using V = glm::dvec3;
  Scene s;
  const glm::dvec3 stone(0.62, 0.58, 0.5), paving(0.45, 0.42, 0.38), plaster(0.7, 0.66, 0.58), wood(0.42, 0.3, 0.2),
      terracotta(0.6, 0.32, 0.2), leaves(0.15, 0.35, 0.1), none(0.0);
  const std::array<glm::dvec3, 3> cloth{glm::dvec3(0.6, 0.12, 0.1), glm::dvec3(0.12, 0.3, 0.55), glm::dvec3(0.2, 0.45, 0.2)};
  uint32_t material = 0;
  // A rectangle from `o` spanned by `u` and `v` (counter-clockwise seen from the front) in cells no
  // wider than `cell`.
  auto rect = [&](V o, V u, V v, const glm::dvec3& rho, double cell) { add_grid(s, o, u, v, rho, none, cell, material); };
  // An axis-aligned box, faces outward (no bottom).
  auto box = [&](V lo, V hi, const glm::dvec3& rho, double cell) {
    const V d = hi - lo;
    rect(V(lo.x, hi.y, lo.z), V(0, 0, d.z), V(d.x, 0, 0), rho, cell);
    rect(lo, V(0, d.y, 0), V(d.x, 0, 0), rho, cell);
    rect(V(lo.x, lo.y, hi.z), V(d.x, 0, 0), V(0, d.y, 0), rho, cell);
    rect(lo, V(0, 0, d.z), V(0, d.y, 0), rho, cell);
    rect(V(hi.x, lo.y, lo.z), V(0, d.y, 0), V(0, 0, d.z), rho, cell);
  };
  // The court is x in [-12, 12], z in [-5, 5], open to the sky; galleries of two storeys (floors at
  // 0 and 5 m, roofs at 10 m) run along both long sides to back walls at z = +-8; end walls at
  // x = +-12 and the back walls rise to 12 m.
  const double X = 12.0, court = 5.0, back = 8.0, top = 12.0, wall = 0.5;
  rect(V(-X, 0, -back), V(0, 0, 2 * back), V(2 * X, 0, 0), paving, 1.0);
  ++material;
  rect(V(-X, 0, -back), V(2 * X, 0, 0), V(0, top, 0), plaster, 1.0);          // back wall z = -8
  rect(V(-X, 0, back), V(0, top, 0), V(2 * X, 0, 0), plaster, 1.0);           // back wall z = +8
  rect(V(-X, 0, -back), V(0, top, 0), V(0, 0, 2 * back), plaster, 1.0);       // end wall x = -12
  rect(V(X, 0, -back), V(0, 0, 2 * back), V(0, top, 0), plaster, 1.0);        // end wall x = +12
  ++material;
  // Per side (sz = -1, +1): for each storey an arcade of ten columns and nine arches on the court's
  // edge, the gallery's ceiling slab over it, and the parapet above the roof.
  const int bays = 10;
  const double bay = 2 * X / bays, column_r = 0.22;
  for (double sz : {-1.0, 1.0}) {
    const double zf = sz * court, zb = sz * (court + wall);  // the arcade wall's court and gallery faces
    for (int storey = 0; storey < 2; ++storey) {
      const double y0 = 5.0 * storey, spring = y0 + 3.0, y1 = y0 + 4.7, slab = y0 + 5.0;
      // Columns: base, a shaft with entasis (10 rings, 24 sides), a capital.
      for (int k = 1; k < bays; ++k) {
        const double x = -X + bay * k;
        const V c(x, y0, sz * (court + 0.5 * wall));
        box(c + V(-0.32, 0.0, -0.32), c + V(0.32, 0.25, 0.32), stone, 1.0);
        std::vector<std::array<double, 2>> shaft;
        for (int i = 0; i <= 10; ++i) shaft.push_back({column_r * (1.0 + 0.12 * std::sin(kPi * i / 10.0) - 0.06 * i / 10.0), 0.25 + 2.5 * i / 10.0});
        add_lathe(s, c, shaft, 24, stone, material);
        box(c + V(-0.3, 2.75, -0.3), c + V(0.3, 3.0, 0.3), stone, 1.0);
      }
      ++material;
      // The arcade wall over the arches, from the springing to the slab: per bay a semicircular
      // opening between the capitals, its soffit, and the spandrels on both faces.
      for (int k = 0; k < bays; ++k) {
        const double x0 = -X + bay * k, xc = x0 + 0.5 * bay, r = 0.5 * bay - 0.3;
        const int n = 12;
        auto arc = [&](int i, double z) { const double a = kPi * (1.0 - double(i) / n); return V(xc + r * std::cos(a), spring + r * std::sin(a), z); };
        for (int i = 0; i < n; ++i) {
          // Spandrel strips from the arc up to the top of the wall, on both faces.
          const V a = arc(i, zf), b = arc(i + 1, zf);
          const V ta(a.x, y1, zf), tb(b.x, y1, zf);
          const V a2 = arc(i, zb), b2 = arc(i + 1, zb);
          const V ta2(a2.x, y1, zb), tb2(b2.x, y1, zb);
          if (sz > 0) {
            add_quad(s, b, a, ta, tb, stone, none, material);      // court face looks to -z
            add_quad(s, a2, b2, tb2, ta2, stone, none, material);  // gallery face looks to +z
            add_quad(s, a, b, b2, a2, stone, none, material);      // soffit looks into the opening
          } else {
            add_quad(s, a, b, tb, ta, stone, none, material);
            add_quad(s, b2, a2, ta2, tb2, stone, none, material);
            add_quad(s, a2, b2, b, a, stone, none, material);
          }
        }
        // The piers' parts beside the arch (x0 .. xc - r and xc + r .. x0 + bay), both faces.
        for (double px : {x0, xc + r}) {
          const double w = 0.3;
          if (sz < 0) {
            add_quad(s, V(px, spring, zf), V(px + w, spring, zf), V(px + w, y1, zf), V(px, y1, zf), stone, none, material);
            add_quad(s, V(px + w, spring, zb), V(px, spring, zb), V(px, y1, zb), V(px + w, y1, zb), stone, none, material);
          } else {
            add_quad(s, V(px + w, spring, zf), V(px, spring, zf), V(px, y1, zf), V(px + w, y1, zf), stone, none, material);
            add_quad(s, V(px, spring, zb), V(px + w, spring, zb), V(px + w, y1, zb), V(px, y1, zb), stone, none, material);
          }
        }
      }
      ++material;
      // The slab over the gallery: its underside, its edge on the court and its top (the next
      // storey's floor or the roof), 1 m tiles.
      const double z0 = sz > 0 ? court : -back, z1 = sz > 0 ? back : -court;
      rect(V(-X, y1, z0), V(2 * X, 0, 0), V(0, 0, z1 - z0), plaster, 1.0);
      rect(V(-X, slab, z0), V(0, 0, z1 - z0), V(2 * X, 0, 0), paving, 1.0);
      if (sz < 0) rect(V(-X, y1, zf), V(2 * X, 0, 0), V(0, slab - y1, 0), stone, 1.0);
      else rect(V(-X, y1, zf), V(0, slab - y1, 0), V(2 * X, 0, 0), stone, 1.0);
      ++material;
      // A balustrade along the slab's edge above (the upper gallery's and the roof's): rails and
      // vase-shaped balusters (8 sides, 8 rings) every 0.2 m.
      const double by = slab, bz = sz * (court + 0.25);
      for (int k = 0; k < bays; ++k) {
        const double xa = -X + bay * k + 0.4, xb = -X + bay * (k + 1) - 0.4;
        box(V(xa, by + 0.85, bz - 0.12), V(xb, by + 0.95, bz + 0.12), stone, 1.0);
        for (double x = xa + 0.1; x < xb - 0.05; x += 0.2)
          add_lathe(s, V(x, by, bz), {{0.06, 0.0}, {0.06, 0.1}, {0.035, 0.18}, {0.07, 0.4}, {0.07, 0.5},
                                        {0.035, 0.68}, {0.05, 0.78}, {0.05, 0.85}, {0.0, 0.85}},
                    8, stone, material);
      }
      ++material;
    }
    // Curtains hung behind the upper arches (every other bay): wavy sheets, both sides, 1.9 x 2.6 m
    // in 40 x 30 cells.
    for (int k = 0; k < bays; k += 2) {
      const double x0 = -X + bay * k + 0.35, w = bay - 0.7, y0 = 5.3, h = 2.5, zc = sz * (court + wall + 0.3);
      const int nu = 40, nv = 30;
      auto at = [&](int i, int j) {
        const double x = x0 + w * i / nu, y = y0 + h * j / nv;
        return V(x, y, zc + 0.07 * std::sin(2.0 * kPi * 6.0 * i / nu) * (0.4 + 0.6 * (1.0 - double(j) / nv)));
      };
      const glm::dvec3 rho = cloth[static_cast<size_t>(k / 2) % cloth.size()];
      for (int i = 0; i < nu; ++i)
        for (int j = 0; j < nv; ++j) {
          const V a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
          add_quad(s, a, b, c, d, rho, none, material);  // the side towards -z
          add_quad(s, a, d, c, b, rho, none, material);  // the side towards +z
        }
      ++material;
    }
    // Benches along the lower gallery's back wall.
    for (int k = 0; k < bays; ++k) {
      const double xc = -X + bay * (k + 0.5), zc = sz * (back - 0.45);
      box(V(xc - 0.8, 0.42, zc - 0.2), V(xc + 0.8, 0.47, zc + 0.2), wood, 1.0);
      for (double lx : {-0.75, 0.7})
        for (double lz : {-0.18, 0.14}) box(V(xc + lx, 0.0, zc + lz), V(xc + lx + 0.05, 0.42, zc + lz + 0.04), wood, 1.0);
    }
    ++material;
  }
  // The court: a fountain (a basin and a column of tiers) and 24 planters with round shrubs.
  add_lathe(s, V(0, 0, 0), {{1.6, 0.0}, {1.6, 0.5}, {1.4, 0.5}, {1.4, 0.25}, {0.3, 0.25}, {0.25, 1.2}, {0.8, 1.3},
                            {0.8, 1.4}, {0.2, 1.45}, {0.15, 2.1}, {0.45, 2.2}, {0.45, 2.3}, {0.0, 2.35}},
            48, stone, material++);
  Lcg rng{11};
  for (int i = 0; i < 12; ++i)
    for (double sz : {-1.0, 1.0}) {
      const double x = -X + 1.0 + i * (2 * X - 2.0) / 11.0, z = sz * (court - 1.2);
      if (std::abs(x) < 2.5) continue;
      add_lathe(s, V(x, 0, z), {{0.25, 0.0}, {0.32, 0.1}, {0.38, 0.45}, {0.42, 0.55}, {0.36, 0.55}, {0.36, 0.5}, {0.0, 0.5}},
                20, terracotta, material);
      add_uv_sphere(s, V(x, 0.5 + 0.35, z), rng.in(0.3, 0.42), 12, 18, leaves, none, material + 1);
    }
  material += 2;
  // Lit by the sky through the open roof and a low sun.
  s.sky = glm::dvec3(0.55, 0.65, 0.9);
  Light sun;
  sun.type = Light::Type::kDirectional;
  sun.direction = glm::normalize(glm::dvec3(0.35, -0.8, 0.45));
  sun.intensity = glm::dvec3(9.0, 8.4, 7.2);
  s.lights.push_back(sun);
  return s;
}

Scene make_sphere_room(int rings, int segments) {
  using V = glm::dvec3;
  Scene s;
  const glm::dvec3 wall(0.7), floor(0.5, 0.45, 0.4), none(0.0);
  // A 4 x 3 x 5 m room seen from inside, 0.5 m tiles, with a 1 x 1 m ceiling panel.
  auto rect = [&](V o, V u, V v, const glm::dvec3& rho, uint32_t material) { add_grid(s, o, u, v, rho, none, 0.5, material); };
  rect(V(0, 0, 0), V(0, 0, 5), V(4, 0, 0), floor, 0);
  rect(V(0, 3, 0), V(4, 0, 0), V(0, 0, 5), wall, 1);
  rect(V(0, 0, 0), V(4, 0, 0), V(0, 3, 0), wall, 1);
  rect(V(0, 0, 5), V(0, 3, 0), V(4, 0, 0), wall, 1);
  rect(V(0, 0, 0), V(0, 3, 0), V(0, 0, 5), wall, 1);
  rect(V(4, 0, 0), V(0, 0, 5), V(0, 3, 0), wall, 1);
  add_quad(s, V(1.5, 2.99, 2.0), V(2.5, 2.99, 2.0), V(2.5, 2.99, 3.0), V(1.5, 2.99, 3.0), glm::dvec3(0.8), glm::dvec3(10.0), 2);
  add_uv_sphere(s, V(2.0, 0.8, 2.5), 0.8, rings, segments, glm::dvec3(0.6, 0.4, 0.3), none, 3);
  return s;
}

}  // namespace hemibake::solver
