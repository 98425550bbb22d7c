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
    const int nu = std::max(1, static_cast<int>(std::ceil(glm::length(u) / cell - 1e-9)));
    const int nv = std::max(1, static_cast<int>(std::ceil(glm::length(v) / cell - 1e-9)));
    for (int i = 0; i < nu; ++i)
      for (int j = 0; j < nv; ++j) {
        const V a = o + u * (double(i) / nu) + v * (double(j) / nv);
        const V du = u / double(nu), dv = v / double(nv);
        add_quad(s, a, a + du, a + du + dv, a + dv, rho, e, material);
      }
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

namespace {

// A UV sphere of triangles, facing outward, `rings` x `segments`.
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

}  // namespace

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

}  // namespace hemibake::solver
