// The final gather (Params::gather): what the mesh shows at and between its vertices, against
// closed forms computed here (Lambert's point-to-polygon form factor, a uniform sky).
#include "hemibake/solver/hemicube.h"
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"
#include "add_box.h"
#include "shown_on_floor.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <vector>

namespace hemibake::solver {
namespace {

double mean3(const glm::dvec3& v) { return (v.x + v.y + v.z) / 3.0; }

// A scene solved with the final gather: its mesh and the solve's figures.
struct Gathered {
  Mesh mesh;
  Stats stats;
};
Gathered solve_with_gather(const Scene& scene) {
  EXPECT_EQ(validate(scene), "");
  Params params;
  params.gather = true;
  Solver solver(scene, params);
  EXPECT_TRUE(solver.run().converged);
  return {solver.mesh(), solver.stats()};
}

// A floor 4 x 4 m (one patch) under a 1 x 1 m emitter 1 m up, facing down, nothing else: every
// point of the floor shows rho E F(point -> emitter). The gather puts that value at every vertex,
// on the floor's outline too, and the mesh interpolates it between them; as shown at random points
// the floor is within a few percent of the closed form.
TEST(Gather, FloorUnderALampShowsThePointFormFactor) {
  Scene scene;
  const glm::dvec3 rho(0.6), e(5.0);
  add_quad(scene, {-2, 0, -2}, {-2, 0, 2}, {2, 0, 2}, {2, 0, -2}, rho, glm::dvec3(0.0), 0);
  add_quad(scene, {-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}, glm::dvec3(0.0), e, 1);
  ASSERT_EQ(validate(scene), "");
  const std::vector<glm::dvec3> lamp{{-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}};
  auto exact = [&](double x, double z) { return rho.x * e.x * point_polygon_form_factor({x, 0, z}, {0, 1, 0}, lamp); };
  for (const bool gather : {true, false}) {
    Params params;
    params.gather = gather;
    Solver solver(scene, params);
    ASSERT_TRUE(solver.run().converged);
    const Mesh mesh = solver.mesh();
    double worst_vertex = 0.0;
    for (const Mesh::Element& el : mesh.elements) {
      if (el.patch != 0) continue;
      for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
        const glm::dvec3& q = mesh.positions[mesh.boundary[i]];
        const double want = exact(q.x, q.z);
        worst_vertex = std::max(worst_vertex, std::abs(mesh.radiosity[mesh.boundary[i]].x - want) / want);
      }
    }
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(-2.0, 2.0);
    std::vector<double> errors;
    for (int i = 0; i < 400; ++i) {
      const double x = u(rng), z = u(rng);
      const auto shown = shown_on_floor(mesh, 0, 1, x, z);
      ASSERT_TRUE(shown.has_value()) << x << " " << z;
      const double want = exact(x, z);
      errors.push_back(std::abs(shown->x - want) / want);
    }
    std::sort(errors.begin(), errors.end());
    const double median = errors[errors.size() / 2], p90 = errors[errors.size() * 9 / 10];
    std::printf("gather %d: worst vertex %.4f, shown median %.4f p90 %.4f, %zu elements\n", gather, worst_vertex, median,
                p90, mesh.elements.size());
    if (gather) {
      EXPECT_LT(worst_vertex, 0.03);
      EXPECT_LT(median, 0.01);
      EXPECT_LT(p90, 0.03);
    } else {
      // Averaging the elements around a vertex misses the falloff on the outline: the gather is
      // what makes the vertices right.
      EXPECT_GT(worst_vertex, 0.05);
    }
  }
}

// The floor under the lamp above, beside a wall of 40 x 40 black tiles (rho 0: they change no one's
// light, but every gather in front of them must project each of them). Gathering every vertex
// would cost more than the gather's budget (twice the nodes the shots projected), so the gather
// stops part way; the vertices it reached, the largest elements' first, keep what they gathered.
// Those vertices are within a few percent of the closed form, where the elements' mean is far
// off it on the floor's outline.
TEST(Gather, VerticesGatheredBeforeTheBudgetRanOutKeepTheirLight) {
  Scene scene;
  const glm::dvec3 rho(0.6), e(5.0);
  add_quad(scene, {-2, 0, -2}, {-2, 0, 2}, {2, 0, 2}, {2, 0, -2}, rho, glm::dvec3(0.0), 0);
  add_quad(scene, {-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}, glm::dvec3(0.0), e, 1);
  const double t = 0.04;  // the tiles: x in [-0.8, 0.8], y in [0.2, 1.8], at z = 2.5, facing -z
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j) {
      const double x0 = -0.8 + t * i, y0 = 0.2 + t * j;
      add_quad(scene, {x0, y0, 2.5}, {x0, y0 + t, 2.5}, {x0 + t, y0 + t, 2.5}, {x0 + t, y0, 2.5}, glm::dvec3(0.0),
               glm::dvec3(0.0), 2);
    }
  const std::vector<glm::dvec3> lamp{{-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}};
  auto exact = [&](const glm::dvec3& q) { return rho.x * e.x * point_polygon_form_factor(q, {0, 1, 0}, lamp); };
  const Gathered solved = solve_with_gather(scene);
  const Mesh& mesh = solved.mesh;
  // The vertices of the floor's largest elements (at least half the largest one's area).
  auto area = [&](const Mesh::Element& el) {
    double a = 0.0;
    const glm::dvec3& o = mesh.positions[mesh.boundary[el.boundary_begin]];
    for (uint32_t i = el.boundary_begin + 1; i + 1 < el.boundary_end; ++i)
      a += 0.5 * glm::length(
                     glm::cross(mesh.positions[mesh.boundary[i]] - o, mesh.positions[mesh.boundary[i + 1]] - o));
    return a;
  };
  double largest = 0.0;
  for (const Mesh::Element& el : mesh.elements)
    if (el.patch == 0) largest = std::max(largest, area(el));
  // Their corners: a loop also holds the corners of smaller neighbours on its edges, which lie on
  // the line between the loop's previous and next vertex and are gathered with their own elements.
  std::vector<uint32_t> vertices;
  for (const Mesh::Element& el : mesh.elements) {
    if (el.patch != 0 || area(el) < 0.5 * largest) continue;
    const uint32_t n = el.boundary_end - el.boundary_begin;
    for (uint32_t k = 0; k < n; ++k) {
      const glm::dvec3& prev = mesh.positions[mesh.boundary[el.boundary_begin + (k + n - 1) % n]];
      const glm::dvec3& at = mesh.positions[mesh.boundary[el.boundary_begin + k]];
      const glm::dvec3& next = mesh.positions[mesh.boundary[el.boundary_begin + (k + 1) % n]];
      if (glm::length(glm::cross(at - prev, next - at)) > 1e-9 * glm::length(next - prev) * glm::length(next - prev))
        vertices.push_back(mesh.boundary[el.boundary_begin + k]);
    }
  }
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  // The budget did run out: fewer points were gathered than the mesh has vertices.
  std::printf("%zu vertices in the mesh, %llu gathered; %zu corners of the floor's largest elements\n", mesh.positions.size(),
              static_cast<unsigned long long>(solved.stats.gathers), vertices.size());
  ASSERT_LT(solved.stats.gathers, mesh.positions.size() / 2);
  ASSERT_GT(vertices.size(), 8u);
  std::vector<double> errors;
  for (uint32_t v : vertices)
    errors.push_back(std::abs(mesh.radiosity[v].x - exact(mesh.positions[v])) / exact(mesh.positions[v]));
  std::sort(errors.begin(), errors.end());
  const double median = errors[errors.size() / 2], worst = errors.back();
  std::printf("those vertices: median error %.4f, worst %.4f\n", median, worst);
  EXPECT_LT(median, 0.01);
  EXPECT_LT(worst, 0.03);
}

// A lamp hung 1 cm under a tiled ceiling, seen from a wall at grazing angles: the wall's vertices
// show rho E F(point -> lamp) (the ceiling is black, so only the lamp lights the wall). Along the
// lamp's outline the gather's coarse pixels hold both the lamp and the ceiling tiles beside it,
// which do not overlap it; compared where each one's covered part lies, the ceiling beside the
// lamp's near edge was the nearer and hid part of the lamp. The gather compares them at the pixel's
// centre (Hemicube::set_depth_at_pixel_centre).
TEST(Gather, WallSeesALampHungJustUnderATiledCeilingWhole) {
  Scene scene;
  const glm::dvec3 rho(0.5), e(10.0), black(0.0);
  for (int i = 0; i < 24; ++i)  // the ceiling, 6 x 3 m in 0.25 m tiles at y = 3, facing down
    for (int j = 0; j < 12; ++j) {
      const double x0 = 0.25 * i, z0 = 0.25 * j;
      add_quad(scene, {x0, 3, z0}, {x0 + 0.25, 3, z0}, {x0 + 0.25, 3, z0 + 0.25}, {x0, 3, z0 + 0.25}, black, black, 0);
    }
  const std::vector<glm::dvec3> lamp{{2.5, 2.99, 1.2}, {3.5, 2.99, 1.2}, {3.5, 2.99, 1.8}, {2.5, 2.99, 1.8}};
  add_quad(scene, lamp[0], lamp[1], lamp[2], lamp[3], black, e, 1);
  for (int i = 0; i < 12; ++i)  // the wall at z = 0, facing +z, in 0.5 m tiles
    for (int j = 0; j < 6; ++j) {
      const double x0 = 0.5 * i, y0 = 0.5 * j;
      add_quad(scene, {x0, y0, 0}, {x0 + 0.5, y0, 0}, {x0 + 0.5, y0 + 0.5, 0}, {x0, y0 + 0.5, 0}, rho, black, 2);
    }
  const Gathered solved = solve_with_gather(scene);
  const Mesh& mesh = solved.mesh;
  std::vector<double> errors;
  for (const Mesh::Element& el : mesh.elements) {
    if (scene.patches[el.patch].material != 2) continue;
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const glm::dvec3& q = mesh.positions[mesh.boundary[i]];
      if (q.y < 1.0 || q.y > 2.8 || q.x < 1.0 || q.x > 5.0) continue;
      const double want = rho.x * e.x * point_polygon_form_factor(q, {0, 0, 1}, lamp);
      errors.push_back((mesh.radiosity[mesh.boundary[i]].x - want) / want);
    }
  }
  ASSERT_GT(errors.size(), 20u);
  double sum = 0.0;
  for (double x : errors) sum += x;
  std::sort(errors.begin(), errors.end(), [](double a, double b) { return std::abs(a) < std::abs(b); });
  const double mean = sum / static_cast<double>(errors.size());
  const double median = std::abs(errors[errors.size() / 2]), p90 = std::abs(errors[errors.size() * 9 / 10]);
  std::printf("wall under the lamp: %llu gathers, %zu vertices; %zu vertex values, mean error %+.4f, |error| median %.4f "
              "p90 %.4f\n",
              static_cast<unsigned long long>(solved.stats.gathers), mesh.positions.size(), errors.size(),
              mean, median, p90);
  // Compared where each covered part lies: mean -4.7 %, median 1.9 %, p90 13 %. Along one ray:
  // -2.2 %, 0.9 %, 8.9 %. The rest are vertices the budget does not reach (2048 of 2656 points are
  // gathered), which show the mean of the elements around them; those gathered are exact (the
  // same scene written as glTF and baked with --gather: 530 wall vertices, each within 0.3 %).
  EXPECT_LT(std::abs(mean), 0.03);
  EXPECT_LT(median, 0.01);
}

// A wall standing on an emitting floor (E uniform, 2 x 2 m) and nothing else: a point of the wall
// at height y shows rho E F(point -> floor), half of rho E at its foot. The wall is one patch; what
// it shows must follow the falloff up the wall.
TEST(Gather, WallOnAGlowingFloorFollowsTheFalloff) {
  Scene scene;
  const glm::dvec3 rho(0.5), e(1.0);
  add_quad(scene, {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, glm::dvec3(0.0), e, 0);
  // The wall: along the floor's edge z = -1, facing +z, 2 m wide and 2 m high.
  add_quad(scene, {-1, 0, -1}, {1, 0, -1}, {1, 2, -1}, {-1, 2, -1}, rho, glm::dvec3(0.0), 1);
  const std::vector<glm::dvec3> floor{{-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}};
  const Gathered solved = solve_with_gather(scene);
  const Mesh& mesh = solved.mesh;
  double worst = 0.0;
  size_t checked = 0;
  for (const Mesh::Element& el : mesh.elements) {
    if (el.patch != 1) continue;
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const glm::dvec3 q = mesh.positions[mesh.boundary[i]];
      // At the wall's two lower corners the light has no one value (it depends on the way one
      // comes to them): they are left out.
      if (q.y == 0.0 && std::abs(q.x) == 1.0) continue;
      // On the foot itself the floor lies edge-on; just above it, it fills half the view.
      const glm::dvec3 at(q.x, std::max(q.y, 1e-7), q.z);
      const double want = rho.x * e.x * point_polygon_form_factor(at, {0, 0, 1}, floor);
      const double err = std::abs(mesh.radiosity[mesh.boundary[i]].x - want) / want;
      worst = std::max(worst, err);
      ++checked;
    }
  }
  std::printf("wall: %zu vertex values, worst %.4f\n", checked, worst);
  EXPECT_GT(checked, 8u);
  EXPECT_LT(worst, 0.03);
}

// A box (one-sided faces, outward, no bottom) standing on a floor of 8 x 8 patches, under a lamp:
// the floor's vertices inside the box's footprint see only the box's backs and stay dark.
TEST(Gather, FloorUnderABoxStaysDark) {
  Scene scene;
  const glm::dvec3 rho(0.6), e(5.0);
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j) {
      const double x0 = -2 + 0.5 * i, z0 = -2 + 0.5 * j;
      add_quad(scene, {x0, 0, z0}, {x0, 0, z0 + 0.5}, {x0 + 0.5, 0, z0 + 0.5}, {x0 + 0.5, 0, z0}, rho, glm::dvec3(0.0), 0);
    }
  const uint32_t floor_end = static_cast<uint32_t>(scene.patches.size());
  // The box [-0.6, 0.6] x [0, 0.5] x [-0.6, 0.6]: its footprint holds the floor's vertices at
  // x, z in {-0.5, 0, 0.5}.
  const double a = 0.6, h = 0.5;
  add_quad(scene, {-a, h, -a}, {-a, h, a}, {a, h, a}, {a, h, -a}, rho, glm::dvec3(0.0), 0);   // top
  add_quad(scene, {-a, 0, a}, {a, 0, a}, {a, h, a}, {-a, h, a}, rho, glm::dvec3(0.0), 0);     // +z
  add_quad(scene, {a, 0, -a}, {-a, 0, -a}, {-a, h, -a}, {a, h, -a}, rho, glm::dvec3(0.0), 0); // -z
  add_quad(scene, {a, 0, a}, {a, 0, -a}, {a, h, -a}, {a, h, a}, rho, glm::dvec3(0.0), 0);     // +x
  add_quad(scene, {-a, 0, -a}, {-a, 0, a}, {-a, h, a}, {-a, h, -a}, rho, glm::dvec3(0.0), 0); // -x
  add_quad(scene, {-0.5, 2, -0.5}, {0.5, 2, -0.5}, {0.5, 2, 0.5}, {-0.5, 2, 0.5}, glm::dvec3(0.0), e, 1);
  const Gathered solved = solve_with_gather(scene);
  const Mesh& mesh = solved.mesh;
  double inside = 0.0, outside = 0.0;
  size_t n_inside = 0;
  for (const Mesh::Element& el : mesh.elements) {
    if (el.patch >= floor_end) continue;
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const glm::dvec3& q = mesh.positions[mesh.boundary[i]];
      const double b = mean3(mesh.radiosity[mesh.boundary[i]]);
      if (std::abs(q.x) < a - 0.05 && std::abs(q.z) < a - 0.05) {
        inside = std::max(inside, b);
        ++n_inside;
      } else if (std::abs(q.x) > a + 0.3 || std::abs(q.z) > a + 0.3) {
        outside = std::max(outside, b);
      }
    }
  }
  std::printf("under the box: %zu vertex values, brightest %.5f; outside, brightest %.5f\n", n_inside, inside, outside);
  EXPECT_GT(n_inside, 8u);
  EXPECT_GT(outside, 0.0);
  EXPECT_LT(inside, 0.01 * outside);
}

// A room modelled as one closed double-sided box, as a modeller's flipped cube is exported: every
// face emits E and reflects rho on both sides, so inside B = E / (1 - rho) everywhere and outside,
// where the faces see nothing, B = E. A vertex lies on the box itself, where whether it is inside
// the box could go either way; taken as outside, it left the room's faces out of its gather and
// showed E (the attic's ceiling, bench/README.md, seventeenth session).
TEST(Gather, RoomOfOneDoubleSidedBoxShowsItsFurnace) {
  Scene scene;
  const glm::dvec3 rho(0.6), e(1.0);
  add_box(scene, glm::dvec3(0.0), glm::dvec3(4.0, 2.5, 3.0), rho, e, 0);
  for (uint32_t k = 0; k < 6; ++k) {
    const auto& c = scene.patches[k].corners;
    add_quad(scene, c[3], c[2], c[1], c[0], rho, e, 0);
  }
  for (Patch& p : scene.patches) p.object = 1;
  const Gathered solved = solve_with_gather(scene);
  const Mesh& mesh = solved.mesh;
  const double inside = e.x / (1.0 - rho.x);
  double worst_in = 0.0, worst_out = 0.0;
  size_t n_in = 0;
  for (const Mesh::Element& el : mesh.elements) {
    const bool faces_in = el.patch >= 6;  // the reversed quads look into the room
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const double b = mesh.radiosity[mesh.boundary[i]].x;
      if (faces_in) {
        worst_in = std::max(worst_in, std::abs(b - inside) / inside);
        ++n_in;
      } else {
        worst_out = std::max(worst_out, std::abs(b - e.x) / e.x);
      }
    }
  }
  std::printf("room of one double-sided box: %zu vertex values inside, worst %.4f; outside worst %.4f\n", n_in, worst_in,
              worst_out);
  EXPECT_GE(n_in, 24u);
  EXPECT_LT(worst_in, 0.03);
  EXPECT_LT(worst_out, 0.03);
}

// An open floor under a uniform sky of radiance L: E = pi L everywhere, so every vertex shows
// rho pi L.
TEST(Gather, OpenFloorUnderTheSky) {
  Scene scene;
  const glm::dvec3 rho(0.4, 0.5, 0.6);
  for (int i = 0; i < 3; ++i)
    add_quad(scene, {i, 0, 0}, {i, 0, 1}, {i + 1.0, 0, 1}, {i + 1.0, 0, 0}, rho, glm::dvec3(0.0), 0);
  scene.sky = glm::dvec3(0.2, 0.3, 0.1);
  const Gathered solved = solve_with_gather(scene);
  const Mesh& mesh = solved.mesh;
  EXPECT_GT(solved.stats.gathers, 0u);
  const glm::dvec3 want = rho * std::numbers::pi * scene.sky;
  for (uint32_t v : mesh.boundary)
    for (int c = 0; c < 3; ++c) ASSERT_NEAR(mesh.radiosity[v][c], want[c], 0.01 * want[c]) << "vertex " << v;
}

}  // namespace
}  // namespace hemibake::solver
