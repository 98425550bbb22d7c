// Seams between surfaces that meet along an edge at an angle (a wall's foot on the floor, a roof's
// ridge): the mesh's triangles meet vertex to vertex there, and each side keeps its own light.
// Checked against geometry computed here: every mesh vertex is tested against every edge of the
// triangles a viewer draws (each element's loop, as a fan from its centre).
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"
#include "solve_scene.h"
#include "stacked_wall.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <tuple>
#include <vector>

namespace hemibake::solver {
namespace {

double mean3(const glm::dvec3& v) { return (v.x + v.y + v.z) / 3.0; }

// Where x lies strictly inside segment (a, b): its parameter in (0, 1), more than `tol` from
// either end and within `tol` of the line; else -1.
double strictly_inside(const glm::dvec3& x, const glm::dvec3& a, const glm::dvec3& b, double tol) {
  const glm::dvec3 d = b - a;
  const double len = glm::length(d);
  if (len <= 2.0 * tol) return -1.0;
  const double t = glm::dot(x - a, d) / len;
  if (t <= tol || t >= len - tol || glm::length(x - a - d * (t / len)) > tol) return -1.0;
  return t / len;
}

struct Crack {
  uint32_t vertex;       // lies strictly inside
  uint32_t element;      // an edge of this element's loop
  glm::dvec3 position;
};

// Every vertex of a loop that lies strictly inside an edge of another loop (consecutive loop
// vertices: the outer edges of the fan a viewer draws), over the whole mesh, within 1e-9 of the
// scene's size. Vertices are bucketed in a grid; each edge looks in the cells along it.
std::vector<Crack> cracks(const Mesh& m) {
  std::vector<uint32_t> used;
  for (const auto& el : m.elements)
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) used.push_back(m.boundary[i]);
  std::sort(used.begin(), used.end());
  used.erase(std::unique(used.begin(), used.end()), used.end());
  glm::dvec3 lo(1e300), hi(-1e300);
  for (uint32_t v : used) {
    lo = glm::min(lo, m.positions[v]);
    hi = glm::max(hi, m.positions[v]);
  }
  const double size = glm::length(hi - lo), tol = 1e-9 * size, cell = size / 64.0;
  using Key = std::tuple<long, long, long>;
  auto key = [&](const glm::dvec3& x) {
    const glm::dvec3 c = glm::floor((x - lo) / cell);
    return Key(static_cast<long>(c.x), static_cast<long>(c.y), static_cast<long>(c.z));
  };
  std::map<Key, std::vector<uint32_t>> grid;
  for (uint32_t v : used) grid[key(m.positions[v])].push_back(v);
  std::vector<Crack> out;
  for (uint32_t e = 0; e < m.elements.size(); ++e) {
    const auto& el = m.elements[e];
    const uint32_t nb = el.boundary_end - el.boundary_begin;
    for (uint32_t k = 0; k < nb; ++k) {
      const uint32_t a = m.boundary[el.boundary_begin + k], b = m.boundary[el.boundary_begin + (k + 1) % nb];
      const glm::dvec3 pa = m.positions[a], pb = m.positions[b];
      const int steps = static_cast<int>(std::ceil(glm::length(pb - pa) / cell)) + 1;
      std::vector<uint32_t> seen;
      for (int s = 0; s <= steps; ++s) {
        const auto [cx, cy, cz] = key(pa + (pb - pa) * (static_cast<double>(s) / steps));
        for (long dx = -1; dx <= 1; ++dx)
          for (long dy = -1; dy <= 1; ++dy)
            for (long dz = -1; dz <= 1; ++dz) {
              const auto it = grid.find(Key(cx + dx, cy + dy, cz + dz));
              if (it == grid.end()) continue;
              for (uint32_t v : it->second) {
                if (v == a || v == b || std::find(seen.begin(), seen.end(), v) != seen.end()) continue;
                if (strictly_inside(m.positions[v], pa, pb, tol) < 0.0) continue;
                seen.push_back(v);
                out.push_back({v, e, m.positions[v]});
              }
            }
      }
    }
  }
  return out;
}

std::string describe(const Mesh& m, const std::vector<Crack>& found) {
  if (found.empty()) return {};
  char line[200];
  std::snprintf(line, sizeof line, "%zu vertices inside an edge, e.g. (%.4f, %.4f, %.4f) inside an edge of an element of patch %u",
                found.size(), found[0].position.x, found[0].position.y, found[0].position.z, m.elements[found[0].element].patch);
  return line;
}

// Pairs (vertex of `of`, element of `against`) where a corner of one of `of`'s elements lies
// strictly inside an edge between two corners of an element of `against`: the T-junctions a mesh
// would have if the loops held only the elements' corners (the need for stitching, not its result).
size_t corner_t_junctions(const Mesh& m, const std::vector<uint32_t>& of, const std::vector<uint32_t>& against) {
  std::vector<uint32_t> corners;
  for (const auto& el : m.elements)
    if (std::find(of.begin(), of.end(), el.patch) != of.end())
      corners.insert(corners.end(), el.corners.begin(), el.corners.begin() + el.corner_count);
  std::sort(corners.begin(), corners.end());
  corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
  size_t n = 0;
  for (const auto& el : m.elements) {
    if (std::find(against.begin(), against.end(), el.patch) == against.end()) continue;
    for (uint32_t k = 0; k < el.corner_count; ++k) {
      const glm::dvec3 a = m.positions[el.corners[k]], b = m.positions[el.corners[(k + 1) % el.corner_count]];
      for (uint32_t v : corners) n += strictly_inside(m.positions[v], a, b, 1e-9) >= 0.0;
    }
  }
  return n;
}

// A 4 x 3 x 4 m room (y up) whose wall at x = 0 is cut in two at z = 1.3, as a modeller cuts a wall
// around a door, and a lamp 15 cm from that wall near its foot, facing it: the wall's foot is cut
// into small elements, the floor it stands on, a darker material lit only by what the wall
// reflects, into large ones. The floor's edge along the wall runs past the wall's corners at z =
// 1.3 and past its fine elements' corners. Patches: 0 floor, 1 ceiling, 2-3 the lit wall, 4-6 the
// other walls, 7 the lamp.
Scene lit_wall_room() {
  Scene scene;
  const glm::dvec3 floor_rho(0.2), wall_rho(0.7), dark(0.0);
  add_quad(scene, {0, 0, 0}, {0, 0, 4}, {4, 0, 4}, {4, 0, 0}, floor_rho, dark, 0);
  add_quad(scene, {0, 3, 0}, {4, 3, 0}, {4, 3, 4}, {0, 3, 4}, wall_rho, dark, 1);
  add_quad(scene, {0, 0, 0}, {0, 3, 0}, {0, 3, 1.3}, {0, 0, 1.3}, wall_rho, dark, 1);
  add_quad(scene, {0, 0, 1.3}, {0, 3, 1.3}, {0, 3, 4}, {0, 0, 4}, wall_rho, dark, 1);
  add_quad(scene, {4, 0, 0}, {4, 0, 4}, {4, 3, 4}, {4, 3, 0}, wall_rho, dark, 1);
  add_quad(scene, {0, 0, 0}, {4, 0, 0}, {4, 3, 0}, {0, 3, 0}, wall_rho, dark, 1);
  add_quad(scene, {0, 0, 4}, {0, 3, 4}, {4, 3, 4}, {4, 0, 4}, wall_rho, dark, 1);
  add_quad(scene, {0.15, 0.1, 1.7}, {0.15, 0.1, 2.3}, {0.15, 0.4, 2.3}, {0.15, 0.4, 1.7}, glm::dvec3(0.0), glm::dvec3(40.0), 2);
  return scene;
}

TEST(Seams, WallFinelyLitBesideACoarseFloorMeetsItVertexToVertex) {
  const Mesh m = solve(lit_wall_room());
  // The case at hand: the floor's elements' corners alone would leave the wall's corners inside
  // the floor's edges.
  ASSERT_GT(corner_t_junctions(m, {2, 3}, {0}), 10u) << "the wall is not cut finer than the floor along its foot";
  const std::vector<Crack> found = cracks(m);
  EXPECT_TRUE(found.empty()) << describe(m, found);
}

// The vertices added to the floor's loops along the wall's foot show the floor's light there,
// linear between the ends of the floor element's edge (what the floor showed before they were
// added), not the wall's, which is many times brighter.
TEST(Seams, AddedVerticesOnTheDarkFloorTakeTheFloorsLightNotTheLitWalls) {
  const Mesh m = solve(lit_wall_room());
  ASSERT_EQ(m.interpolated.size(), m.positions.size());
  // The wall's light at each of its vertices on its foot (z, y = 0, x = 0).
  std::map<double, glm::dvec3> wall_at;
  for (const auto& el : m.elements)
    if (el.patch == 2 || el.patch == 3)
      for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
        const glm::dvec3 p = m.positions[m.boundary[i]];
        if (p.x == 0.0 && p.y == 0.0) wall_at[p.z] = m.radiosity[m.boundary[i]];
      }
  size_t added = 0, darker = 0;
  for (const auto& el : m.elements) {
    if (el.patch != 0) continue;
    const uint32_t nb = el.boundary_end - el.boundary_begin;
    const uint32_t* loop = m.boundary.data() + el.boundary_begin;
    for (uint32_t k = 0; k < nb; ++k) {
      const uint32_t v = loop[k];
      if (!m.interpolated[v]) continue;
      // The floor's own vertices before and after it along the loop end its edge.
      uint32_t before = k, after = k;
      while (m.interpolated[loop[before]]) before = (before + nb - 1) % nb;
      while (m.interpolated[loop[after]]) after = (after + 1) % nb;
      const glm::dvec3 a = m.positions[loop[before]], b = m.positions[loop[after]];
      const double t = strictly_inside(m.positions[v], a, b, 1e-9);
      ASSERT_GE(t, 0.0) << "an added vertex not on its element's edge";
      const glm::dvec3 expected = (1.0 - t) * m.radiosity[loop[before]] + t * m.radiosity[loop[after]];
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(m.radiosity[v][c], expected[c], 1e-9 * (1.0 + expected[c]));
      const glm::dvec3 p = m.positions[v];
      if (p.x != 0.0 || p.y != 0.0) continue;
      ++added;
      const auto w = wall_at.find(p.z);
      ASSERT_NE(w, wall_at.end()) << "an added vertex on the wall's foot at z = " << p.z << " is no vertex of the wall";
      darker += mean3(w->second) > 2.0 * mean3(m.radiosity[v]);
    }
  }
  EXPECT_GT(added, 10u);
  // Where the wall is much brighter than the floor, the floor stays dark.
  EXPECT_GT(darker, added / 2) << "of " << added << " added vertices on the floor along the wall";
}

// A gabled roof like tests/data/blender/wedge.glb (6 x 5 m, ridge 1.2 m up, y up) over a floor,
// with its north slope in two patches cut at x = 2.3 and a lamp close under the south slope: the
// two slopes meet at the ridge at an angle, cut differently, and the gables meet both.
// Patches: 0 floor, 1 south slope, 2-3 north slope, 4-5 gables, 6 lamp.
Scene roof_ridge() {
  Scene scene;
  const glm::dvec3 rho(0.6), dark(0.0);
  add_quad(scene, {0, 0, 0}, {6, 0, 0}, {6, 0, -5}, {0, 0, -5}, rho, dark, 0);
  add_quad(scene, {0, 0, 0}, {0, 1.2, -2.5}, {6, 1.2, -2.5}, {6, 0, 0}, rho, dark, 0);
  add_quad(scene, {0, 0, -5}, {2.3, 0, -5}, {2.3, 1.2, -2.5}, {0, 1.2, -2.5}, rho, dark, 0);
  add_quad(scene, {2.3, 0, -5}, {6, 0, -5}, {6, 1.2, -2.5}, {2.3, 1.2, -2.5}, rho, dark, 0);
  Patch gable;
  gable.corner_count = 3;
  gable.reflectance = rho;
  gable.corners = {glm::dvec3(0, 0, 0), glm::dvec3(0, 0, -5), glm::dvec3(0, 1.2, -2.5), glm::dvec3(0.0)};
  scene.patches.push_back(gable);
  gable.corners = {glm::dvec3(6, 0, 0), glm::dvec3(6, 1.2, -2.5), glm::dvec3(6, 0, -5), glm::dvec3(0.0)};
  scene.patches.push_back(gable);
  // Facing the south slope from 10 cm under it, near the ridge.
  const glm::dvec3 n = glm::normalize(glm::dvec3(0.0, -2.5, -1.2));  // the south slope's normal, inward
  const glm::dvec3 c = glm::dvec3(3.0, 0.96, -2.0) + 0.1 * n, u(0.2, 0.0, 0.0);
  const glm::dvec3 v = 0.2 * glm::normalize(glm::dvec3(0.0, 1.2, -2.5));
  add_quad(scene, c - u - v, c + u - v, c + u + v, c - u + v, glm::dvec3(0.0), glm::dvec3(60.0), 1);
  return scene;
}

TEST(Seams, RoofSlopesCutDifferentlyMeetVertexToVertexAtTheRidgeAndGables) {
  const Scene scene = roof_ridge();
  ASSERT_EQ(validate(scene), "");
  const auto& lamp = scene.patches[6].corners;
  ASSERT_GT(glm::dot(glm::cross(lamp[1] - lamp[0], lamp[2] - lamp[1]), glm::dvec3(0.0, 2.5, 1.2)), 0.0)
      << "the lamp does not face the south slope";
  const Mesh m = solve(scene);
  // The slopes are cut differently along the ridge (north's corners inside south's edges or the
  // other way), and the gables differently from the slopes.
  ASSERT_GT(corner_t_junctions(m, {2, 3}, {1}) + corner_t_junctions(m, {1}, {2, 3}), 0u);
  ASSERT_GT(corner_t_junctions(m, {1, 2, 3}, {4, 5}) + corner_t_junctions(m, {4, 5}, {1, 2, 3}), 0u);
  const std::vector<Crack> found = cracks(m);
  EXPECT_TRUE(found.empty()) << describe(m, found);
}

// The light `face`'s elements show at their loops' points on the 1 m seam (x = 0, y = 1), by z.
std::map<double, glm::dvec3> light_on_seam(const Mesh& m, uint32_t face) {
  std::map<double, glm::dvec3> out;
  for (const auto& el : m.elements) {
    if (el.patch != face) continue;
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const glm::dvec3& p = m.positions[m.boundary[i]];
      if (std::abs(p.x) < 1e-9 && std::abs(p.y - 1.0) < 1e-9) out[p.z] = m.radiosity[m.boundary[i]];
    }
  }
  return out;
}

// Nothing stands on the seam between the two boxes' room faces where the boxes press together: the
// wall shows one light across it, as the path tracer sees a wall with no seam. Before, the faces
// pressed between the boxes parted them, and each face's vertices showed its own light, a step
// across the wall (the Blender house's south wall in three.js).
TEST(Seams, WallOfStackedBoxesShowsOneLightAcrossTheirSeam) {
  const StackedWall w = stacked_wall_room(false);
  const Mesh m = solve(w.scene);
  const auto below = light_on_seam(m, w.lower_face), above = light_on_seam(m, w.upper_face);
  size_t matched = 0;
  double worst = 0.0;
  for (const auto& [z, b] : above) {
    const auto it = below.find(z);
    if (it == below.end() || z < 0.05 || z > 2.45) continue;
    ++matched;
    worst = std::max(worst, std::abs(mean3(it->second) - mean3(b)) / mean3(b));
  }
  std::printf("%zu points on the seam in both faces' loops, largest difference %.4f\n", matched, worst);
  EXPECT_GT(matched, 4u);
  EXPECT_LT(worst, 0.01);
}

}  // namespace
}  // namespace hemibake::solver
