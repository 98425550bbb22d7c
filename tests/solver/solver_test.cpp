// The progressive solver against closed-form radiosity, conservation laws and geometry computed
// here independently of the solver.
#include "hemibake/solver/hemicube.h"
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"
#include "add_box.h"
#include "solve_scene.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <numbers>
#include <optional>

namespace hemibake::solver {
namespace {

double mean3(const glm::dvec3& v) { return (v.x + v.y + v.z) / 3.0; }

struct BoxCase {
  bool block;
  Method method;
};

class ClosedBox : public ::testing::TestWithParam<BoxCase> {};

// In a closed environment where every surface emits E and reflects rho, B = E + rho * B (the form
// factors from any point sum to one), so B = E / (1 - rho) everywhere.
TEST_P(ClosedBox, EveryElementConvergesToEOverOneMinusRho) {
  const glm::dvec3 rho(0.5, 0.3, 0.7), e(1.0, 2.0, 0.5);
  const Scene scene = make_closed_box(2.0, 3, rho, e, GetParam().block);
  ASSERT_EQ(validate(scene), "");
  Params params;
  params.method = GetParam().method;
  params.convergence = 1e-4;
  Solver solver(scene, params);
  const Stats& st = solver.run();
  ASSERT_TRUE(st.converged);
  const glm::dvec3 expected = e / (glm::dvec3(1.0) - rho);
  const Mesh mesh = solver.mesh();
  double worst = 0.0, total_ba = 0.0, total_a = 0.0;
  for (const auto& el : mesh.elements) {
    for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(el.radiosity[c] / expected[c] - 1.0));
    total_ba += mean3(el.radiosity) * el.area;
    total_a += el.area;
  }
  // Energy: sum A B = sum A E / (1 - rho).
  EXPECT_NEAR(total_ba / total_a / mean3(expected), 1.0, 0.005);
  // Per element, what is left is the hemicube's discretisation and the shooters' finite size;
  // with rho = 0.7 in one channel an error in the form factors is amplified 2.3 times.
  // The classical hemicube's point sampling is coarser, most of all on the lower-resolution
  // hemicubes of near-field sub-shooters.
  const double tolerance = GetParam().method == Method::kAntiAliased ? 0.02 : 0.03;
  EXPECT_LT(worst, tolerance) << "elements " << mesh.elements.size();
  for (size_t v = 0; v < mesh.radiosity.size(); ++v) {
    if (mesh.radiosity[v] == glm::dvec3(0.0)) continue;  // not on any leaf
    for (int c = 0; c < 3; ++c)
      ASSERT_NEAR(mesh.radiosity[v][c] / expected[c], 1.0, tolerance) << "vertex " << v;
  }
}

// Evenly lit surfaces need no refinement: a uniform closed box is not subdivided at all.
TEST(Solver, UniformRadiosityCausesNoSubdivision) {
  const Scene scene = make_closed_box(1.0, 3, glm::dvec3(0.6), glm::dvec3(1.0), true);
  Solver solver(scene, Params{});
  solver.run();
  EXPECT_TRUE(solver.stats().converged);
  EXPECT_EQ(solver.stats().splits, 0u);
  EXPECT_EQ(solver.stats().elements, scene.patches.size());
}

// Cracks in the floor of a lit box whose floor is patch A (0 <= z <= 1) beside a strip of patches
// (1 <= z <= 2) cut at `cuts` along x, all coplanar and of one material: vertices of the floor that
// lie inside an edge of a floor element's loop without being part of it. Also whether every cut's
// corner at z = 1 lies on the loop of an element of A.
std::pair<uint32_t, bool> floor_cracks(const std::vector<double>& cuts) {
  Scene scene;
  const glm::dvec3 rho(0.6), dark(0.0);
  add_quad(scene, {0, 0, 0}, {0, 0, 1}, {3, 0, 1}, {3, 0, 0}, rho, dark, 0);  // A
  std::vector<double> xs{0.0};
  xs.insert(xs.end(), cuts.begin(), cuts.end());
  xs.push_back(3.0);
  for (size_t i = 0; i + 1 < xs.size(); ++i)
    add_quad(scene, {xs[i], 0, 1}, {xs[i], 0, 2}, {xs[i + 1], 0, 2}, {xs[i + 1], 0, 1}, rho, dark, 0);
  const uint32_t floor_end = static_cast<uint32_t>(scene.patches.size());
  add_quad(scene, {0, 2, 0}, {1, 2, 0}, {1, 2, 2}, {0, 2, 2}, rho, glm::dvec3(1.0), 2);  // lamp over one end
  add_quad(scene, {1, 2, 0}, {3, 2, 0}, {3, 2, 2}, {1, 2, 2}, rho, dark, 1);
  add_quad(scene, {0, 0, 0}, {0, 2, 0}, {0, 2, 2}, {0, 0, 2}, rho, dark, 1);
  add_quad(scene, {3, 0, 0}, {3, 0, 2}, {3, 2, 2}, {3, 2, 0}, rho, dark, 1);
  add_quad(scene, {0, 0, 0}, {3, 0, 0}, {3, 2, 0}, {0, 2, 0}, rho, dark, 1);
  add_quad(scene, {0, 0, 2}, {0, 2, 2}, {3, 2, 2}, {3, 0, 2}, rho, dark, 1);
  const Mesh mesh = solve(scene);
  std::vector<uint32_t> floor_vertices;
  for (const auto& el : mesh.elements)
    if (el.patch < floor_end)
      for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) floor_vertices.push_back(mesh.boundary[i]);
  std::sort(floor_vertices.begin(), floor_vertices.end());
  floor_vertices.erase(std::unique(floor_vertices.begin(), floor_vertices.end()), floor_vertices.end());
  uint32_t cracks = 0;
  std::vector<bool> cut_in_a(cuts.size(), false);
  for (const auto& el : mesh.elements) {
    if (el.patch >= floor_end) continue;
    const uint32_t n = el.boundary_end - el.boundary_begin;
    for (uint32_t k = 0; k < n; ++k) {
      const uint32_t u = mesh.boundary[el.boundary_begin + k], w = mesh.boundary[el.boundary_begin + (k + 1) % n];
      for (size_t c = 0; c < cuts.size(); ++c)
        if (el.patch == 0 && glm::distance(mesh.positions[u], glm::dvec3(cuts[c], 0, 1)) < 1e-9) cut_in_a[c] = true;
      const glm::dvec3 d = mesh.positions[w] - mesh.positions[u];
      for (uint32_t x : floor_vertices) {
        if (x == u || x == w) continue;
        const glm::dvec3 r = mesh.positions[x] - mesh.positions[u];
        const double t = glm::dot(r, d) / glm::dot(d, d);
        if (t > 1e-9 && t < 1.0 - 1e-9 && glm::length(r - t * d) < 1e-9) ++cracks;
      }
    }
  }
  return {cracks, std::all_of(cut_in_a.begin(), cut_in_a.end(), [](bool b) { return b; })};
}

// A floor of three coplanar patches meeting in a T-junction (one patch along one side, two along
// the other, split at x = 1.1, which no halving of the first one reaches), as a modeller cuts a
// wall around a window. The output mesh must have no cracks there. Before, the patches were
// separate surfaces whose vertices were not shared, and each showed a flat colour with a step
// where they meet.
TEST(Solver, TJunctionBetweenInputPatchesIsJoinedInTheMesh) {
  const auto [cracks, joined] = floor_cracks({1.1});
  EXPECT_EQ(cracks, 0u);
  EXPECT_TRUE(joined) << "the corner of the two patches is not on the loop of any element of A";
}

// The same with the strip cut into 40 tiles of uneven widths: several T-junctions inside one edge
// of A's elements, met from both ends of that edge (an element's loop runs both ways along it).
TEST(Solver, ManyTJunctionsAlongOneEdgeAreJoinedInOrder) {
  std::vector<double> cuts;
  for (int i = 1; i <= 40; ++i) cuts.push_back(3.0 * std::pow(i / 41.0, 1.3));
  const auto [cracks, joined] = floor_cracks(cuts);
  EXPECT_EQ(cracks, 0u);
  EXPECT_TRUE(joined) << "a tile's corner is not on the loop of any element of A";
}

INSTANTIATE_TEST_SUITE_P(Solver, ClosedBox,
                         ::testing::Values(BoxCase{false, Method::kAntiAliased},
                                           BoxCase{true, Method::kAntiAliased},
                                           BoxCase{false, Method::kClassical},
                                           BoxCase{true, Method::kClassical}),
                         [](const auto& test) {
                           return std::string(test.param.block ? "WithBlock" : "Empty") +
                                  (test.param.method == Method::kAntiAliased ? "Aa" : "Classical");
                         });

// Two closed rooms apart, each a furnace (every patch emits E and reflects rho): B = E / (1 - rho)
// in each, whatever the other holds. The dim room emits 5e-4 of the bright one's power, under the
// global convergence test's share of 1e-3: that test alone stopped before the dim room shot at all
// (its walls read E, 0.5 of the closed form). Each room's light must converge on its own scale.
TEST(Solver, DimRoomBesideABrightOneConvergesToItsOwnClosedForm) {
  const glm::dvec3 rho(0.5), bright(1.0), dim(5e-4);
  Scene scene = make_closed_box(2.0, 3, rho, bright, false);
  const uint32_t dim_begin = static_cast<uint32_t>(scene.patches.size());
  for (Patch p : make_closed_box(2.0, 3, rho, dim, false).patches) {
    for (auto& c : p.corners) c.x += 3.0;
    p.object = 1;
    scene.patches.push_back(p);
  }
  const Mesh mesh = solve(scene);
  auto mean_radiosity = [&](bool dim_room) {
    double ba = 0.0, a = 0.0;
    for (const auto& el : mesh.elements) {
      if ((el.patch >= dim_begin) != dim_room) continue;
      ba += mean3(el.radiosity) * el.area;
      a += el.area;
    }
    return ba / a;
  };
  const double bright_room = mean_radiosity(false) / (mean3(bright) / (1.0 - rho.x));
  const double dim_room = mean_radiosity(true) / (mean3(dim) / (1.0 - rho.x));
  std::printf("mean radiosity over the closed form: bright room %.4f, dim room %.4f\n", bright_room, dim_room);
  EXPECT_NEAR(bright_room, 1.0, 0.01);
  EXPECT_NEAR(dim_room, 1.0, 0.02);
}

// Per element, the worst channel's relative error against the closed form; its largest value and
// RMS over the elements, and the energy sum A B over sum A E / (1 - rho).
struct ClosedFormError {
  double worst = 0.0, rms = 0.0, energy = 0.0;
};
ClosedFormError closed_form_error(const Mesh& mesh, const glm::dvec3& expected) {
  ClosedFormError out;
  double sum2 = 0.0, total_ba = 0.0, total_a = 0.0;
  for (const auto& el : mesh.elements) {
    double w = 0.0;
    for (int c = 0; c < 3; ++c) w = std::max(w, std::abs(el.radiosity[c] / expected[c] - 1.0));
    out.worst = std::max(out.worst, w);
    sum2 += w * w;
    total_ba += mean3(el.radiosity) * el.area;
    total_a += el.area;
  }
  out.rms = std::sqrt(sum2 / static_cast<double>(mesh.elements.size()));
  out.energy = total_ba / total_a / mean3(expected);
  return out;
}

// Many small patches per wall: they shoot in clusters (a wall's patches together, quarters of the
// cluster for receivers near it, single patches at the closest), and the closed form still holds.
// Shooting every patch alone is no better: near corners its weak shots see each small patch from
// its centre (RMS 2.8 %, worst element 9 % on this box).
TEST(Solver, ClustersOfSmallPatchesKeepTheClosedForm) {
  const glm::dvec3 rho(0.5, 0.3, 0.7), e(1.0, 2.0, 0.5);
  const glm::dvec3 expected = e / (glm::dvec3(1.0) - rho);
  for (bool block : {false, true}) {
    const Scene scene = make_closed_box(2.0, 10, rho, e, block);  // 600 patches 0.2 wide
    Params params;
    params.cluster_size = 0.25;  // clusters up to 0.87 wide, of patches up to 0.43
    Solver clustered(scene, params);
    const Stats& st = clustered.run();
    ASSERT_TRUE(st.converged);
    if (!block) {
      params.cluster_size = 0.0;
      Solver alone(scene, params);
      const Stats& st_alone = alone.run();
      // Clusters are the unit of shooting: far fewer shots than patches shooting alone.
      EXPECT_LT(st.shots * 3, st_alone.shots) << st.shots << " against " << st_alone.shots;
    }
    const ClosedFormError err = closed_form_error(clustered.mesh(), expected);
    // Energy: sum A B = sum A E / (1 - rho). The exact form factors of receivers close to a
    // small shooting piece are not reciprocal to the hemicube's, so energy holds to the per-element
    // accuracy (here +0.5 %) rather than to rounding.
    EXPECT_NEAR(err.energy, 1.0, 0.01) << (block ? "with block" : "empty");
    EXPECT_LT(err.rms, 0.025) << (block ? "with block" : "empty");
    EXPECT_LT(err.worst, 0.08) << (block ? "with block" : "empty");
  }
}

// A UV sphere of triangles (`rings` x `segments`), normals outward or inward.
void add_sphere(Scene& scene, const glm::dvec3& centre, double radius, int rings, int segments, bool inward,
                const glm::dvec3& rho, const glm::dvec3& e) {
  auto at = [&](int i, int j) {
    const double th = std::numbers::pi * i / rings, ph = 2.0 * std::numbers::pi * j / segments;
    return centre + radius * glm::dvec3(std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph));
  };
  auto tri = [&](glm::dvec3 a, glm::dvec3 b, glm::dvec3 c) {
    if (!inward) std::swap(b, c);  // (a, b, c) as listed face inward
    Patch p;
    p.corners = {a, b, c, glm::dvec3(0.0)};
    p.corner_count = 3;
    p.reflectance = rho;
    p.emission = e;
    scene.patches.push_back(p);
  };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      if (i > 0) tri(at(i, j), at(i + 1, j + 1), at(i, j + 1));
      if (i < rings - 1) tri(at(i, j), at(i + 1, j), at(i + 1, j + 1));
    }
}

// Small patches of a smoothly curved surface shoot together too, in clusters whose normals stay
// within 20 degrees of their mean (a tessellated sphere is no occlusion group: no two of its
// triangles are coplanar). Closed environments with uniform E and rho give B = E / (1 - rho)
// everywhere: the inside of a sphere (concave: its patches light each other, also within a
// cluster) and a sphere inside a closed box (convex).
TEST(Solver, CurvedSurfacesShootInClustersAndKeepTheClosedForm) {
  const glm::dvec3 rho(0.5, 0.3, 0.7), e(1.0, 2.0, 0.5);
  const glm::dvec3 expected = e / (glm::dvec3(1.0) - rho);
  for (const bool inside : {true, false}) {
    Scene scene;
    if (inside) {
      add_sphere(scene, glm::dvec3(0.0), 1.0, 16, 32, true, rho, e);
    } else {
      scene = make_closed_box(4.0, 4, rho, e, false);
      add_sphere(scene, glm::dvec3(2.0), 0.8, 16, 32, false, rho, e);
    }
    ASSERT_EQ(validate(scene), "");
    const char* what = inside ? "inside a sphere" : "sphere in a box";
    Params params;
    Solver clustered(scene, params);
    const Stats& st = clustered.run();
    ASSERT_TRUE(st.converged) << what;
    params.cluster_size = 0.0;
    Solver alone(scene, params);
    // At least a third fewer shots than patches alone (inside the sphere, with clusters of
    // coplanar patches only, there were 3906 against 5306; with curved ones 2728; in the box 868
    // against 3291: a concave cluster hands its own patches, which see it, down to its halves).
    EXPECT_LT(st.shots * 3, alone.run().shots * 2) << what;
    const ClosedFormError err = closed_form_error(clustered.mesh(), expected);
    EXPECT_NEAR(err.energy, 1.0, 0.01) << what;
    EXPECT_LT(err.rms, 0.025) << what;
    EXPECT_LT(err.worst, 0.08) << what;
  }
}

// A receiver far below a square light, on a plane through the light's centre: it sees half the
// light, though the light's centre is on its horizon (the hemicube there gives it nothing). Its
// radiosity must be rho E F(receiver -> the half in front), F by Lambert's formula over its area.
// Solves the scene with default parameters; the area-weighted mean red radiosity of the patch.
double solved_mean_red(const Scene& scene, uint32_t patch) {
  Solver solver(scene, {});
  solver.run();
  double ba = 0.0, a = 0.0;
  for (const auto& el : solver.mesh().elements)
    if (el.patch == patch) {
      ba += el.radiosity.x * el.area;
      a += el.area;
    }
  return ba / a;
}

TEST(Solver, ReceiverWhosePlaneCutsTheLightSeesItsHalf) {
  Scene scene;
  const glm::dvec3 e(10.0), rho(0.5);
  // Light: y = 2, facing down, x and z in [-0.5, 0.5]. Receiver: the plane x = 0, facing +x.
  add_quad(scene, {-0.5, 2, -0.5}, {0.5, 2, -0.5}, {0.5, 2, 0.5}, {-0.5, 2, 0.5}, glm::dvec3(0.0), e, 1);
  add_quad(scene, {0, -4, -0.5}, {0, -4, 0.5}, {0, -3, 0.5}, {0, -3, -0.5}, rho, glm::dvec3(0.0), 0);
  ASSERT_EQ(validate(scene), "");
  const double b = solved_mean_red(scene, 1);
  const std::vector<glm::dvec3> half{{0, 2, -0.5}, {0.5, 2, -0.5}, {0.5, 2, 0.5}, {0, 2, 0.5}};
  double f = 0.0;
  constexpr int kGrid = 32;
  for (int i = 0; i < kGrid; ++i)
    for (int j = 0; j < kGrid; ++j)
      f += point_polygon_form_factor({0, -4 + (i + 0.5) / kGrid, -0.5 + (j + 0.5) / kGrid}, {1, 0, 0}, half);
  f /= kGrid * kGrid;
  ASSERT_GT(f, 0.0);
  EXPECT_NEAR(b, rho.x * e.x * f, 0.05 * rho.x * e.x * f);
}

TEST(Solver, ReceiverCrossingTheLightsPlaneIsLitOnlyInFrontOfIt) {
  Scene scene;
  const glm::dvec3 e(10.0), rho(0.5);
  // Light: y = 2, facing down, x and z in [-0.5, 0.5]. Receiver: the plane x = 0.6, facing the
  // light (-x), y in [1.8, 2.2]: its upper half lies behind the light, which gives it nothing.
  add_quad(scene, {-0.5, 2, -0.5}, {0.5, 2, -0.5}, {0.5, 2, 0.5}, {-0.5, 2, 0.5}, glm::dvec3(0.0), e, 1);
  add_quad(scene, {0.6, 1.8, -0.5}, {0.6, 1.8, 0.5}, {0.6, 2.2, 0.5}, {0.6, 2.2, -0.5}, rho, glm::dvec3(0.0), 0);
  ASSERT_EQ(validate(scene), "");
  const double b = solved_mean_red(scene, 1);
  const std::vector<glm::dvec3> light{{-0.5, 2, -0.5}, {0.5, 2, -0.5}, {0.5, 2, 0.5}, {-0.5, 2, 0.5}};
  double f = 0.0;  // mean over the receiver of F(point -> light), nothing above y = 2
  constexpr int kGrid = 64;
  for (int i = 0; i < kGrid; ++i)
    for (int j = 0; j < kGrid; ++j) {
      const double y = 1.8 + 0.4 * (i + 0.5) / kGrid;
      if (y < 2.0) f += point_polygon_form_factor({0.6, y, -0.5 + (j + 0.5) / kGrid}, {-1, 0, 0}, light);
    }
  f /= kGrid * kGrid;
  ASSERT_GT(f, 0.0);
  EXPECT_NEAR(b, rho.x * e.x * f, 0.03 * rho.x * e.x * f);
}

// A one-sided surface is opaque from behind too. A room of inward-facing walls (as exporters write
// rooms) lit from outside: every wall shows the light its back, and nothing gets in. Culling backs,
// as the paper's hemicube does, lit the whole inside.
TEST(Solver, InwardFacingRoomKeepsTheLightOutside) {
  Scene scene = make_closed_box(2.0, 3, glm::dvec3(0.7), glm::dvec3(0.0), false);
  const uint32_t light = static_cast<uint32_t>(scene.patches.size());
  // Above the roof (y = 2), facing down onto it, inside its outline.
  add_quad(scene, {0.5, 3, 0.5}, {1.5, 3, 0.5}, {1.5, 3, 1.5}, {0.5, 3, 1.5}, glm::dvec3(0.0), glm::dvec3(10.0), 1);
  ASSERT_EQ(validate(scene), "");
  Solver solver(scene, {});
  EXPECT_TRUE(solver.run().converged);
  // The truth is no light at all. What gets through is the anti-aliased pixel rule's share in the
  // pixels where a wall's top edge meets the roof's outline (the wall lies wholly behind it there;
  // a pixel knows only its surfaces' coverages): 1.5e-5 of the emitted power when this was
  // written. With backs culled the inside reflected about 0.8 of it.
  double inside = 0.0;
  for (const auto& el : solver.mesh().elements)
    if (el.patch != light) inside += mean3(el.radiosity) * el.area;
  EXPECT_LT(inside, 1e-3 * 10.0 * 1.0) << "power reflected inside, of 10 emitted";
}

// A single one-sided sheet turned away from a light still casts its shadow: a receiver that sees
// the light only through it stays dark; with the sheet turned towards the light, the same.
TEST(Solver, OneSidedSheetShadowsFromEitherSide) {
  for (const bool facing_light : {false, true}) {
    Scene scene;
    // Light: y = 2, facing down, x and z in [-0.5, 0.5]. Receiver: y = 0, facing up, the same
    // square. Sheet: y = 1, x and z in [-2, 2]; every segment from light to receiver crosses it.
    add_quad(scene, {-0.5, 2, -0.5}, {0.5, 2, -0.5}, {0.5, 2, 0.5}, {-0.5, 2, 0.5}, glm::dvec3(0.0), glm::dvec3(10.0), 1);
    add_quad(scene, {-0.5, 0, -0.5}, {-0.5, 0, 0.5}, {0.5, 0, 0.5}, {0.5, 0, -0.5}, glm::dvec3(0.5), glm::dvec3(0.0), 0);
    if (facing_light)
      add_quad(scene, {-2, 1, -2}, {-2, 1, 2}, {2, 1, 2}, {2, 1, -2}, glm::dvec3(0.5), glm::dvec3(0.0), 0);
    else
      add_quad(scene, {-2, 1, -2}, {2, 1, -2}, {2, 1, 2}, {-2, 1, 2}, glm::dvec3(0.5), glm::dvec3(0.0), 0);
    ASSERT_EQ(validate(scene), "");
    EXPECT_EQ(solved_mean_red(scene, 1), 0.0) << (facing_light ? "sheet facing the light" : "sheet's back to the light");
  }
}

// Whether segment p->q hits a convex planar polygon (independent of the solver's hemicube).
bool segment_hits(const glm::dvec3& p, const glm::dvec3& q, const Patch& patch) {
  const glm::dvec3 n = glm::cross(patch.corners[1] - patch.corners[0], patch.corners[2] - patch.corners[0]);
  const double dp = glm::dot(n, p - patch.corners[0]), dq = glm::dot(n, q - patch.corners[0]);
  if ((dp > 0) == (dq > 0) || dp == dq) return false;
  const glm::dvec3 x = p + (q - p) * (dp / (dp - dq));
  for (uint32_t i = 0; i < patch.corner_count; ++i) {
    const glm::dvec3& a = patch.corners[i];
    const glm::dvec3& b = patch.corners[(i + 1) % patch.corner_count];
    if (glm::dot(glm::cross(b - a, x - a), n) < 0) return false;
  }
  return true;
}

// Fraction of the Cornell light visible from point x, by sampling the light on a grid.
double light_visibility(const Scene& scene, const glm::dvec3& x) {
  int seen = 0, total = 0;
  for (int i = 0; i < 12; ++i) {
    for (int k = 0; k < 12; ++k) {
      const glm::dvec3 l(213 + 130 * (i + 0.5) / 12, 548.7, 227 + 105 * (k + 0.5) / 12);
      bool blocked = false;
      for (const Patch& p : scene.patches)
        if (p.material == kCornellWhite && p.corners[0].y < 500 && segment_hits(x, l, p)) blocked = true;
      seen += !blocked;
      ++total;
    }
  }
  return static_cast<double>(seen) / total;
}

class CornellBox : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new Scene(make_cornell_box());
    solver_ = new Solver(*scene_, Params{});
    solver_->run();
  }
  static void TearDownTestSuite() {
    delete solver_;
    delete scene_;
  }
  static Scene* scene_;
  static Solver* solver_;
};
Scene* CornellBox::scene_ = nullptr;
Solver* CornellBox::solver_ = nullptr;

TEST_F(CornellBox, ConvergesWithFiniteNonNegativeRadiosity) {
  const Stats& st = solver_->stats();
  EXPECT_TRUE(st.converged);
  EXPECT_LT(st.unshot_fraction, 1e-3);
  const Mesh mesh = solver_->mesh();
  for (const auto& el : mesh.elements)
    for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(el.radiosity[c]) && el.radiosity[c] >= 0.0);
  // Power balance of an open box: everything emitted is absorbed inside or escapes through the
  // open front, so the power absorbed, sum (1 - rho) (B - E) A / rho ... is bounded by the
  // emitted power. Radiosity reflected, sum (B - E) A, is at most rho_max / (1 - rho_max) times
  // the emitted power.
  double reflected = 0.0, emitted = 0.0;
  for (const auto& el : mesh.elements) {
    const Patch& p = scene_->patches[el.patch];
    reflected += mean3(el.radiosity - p.emission) * el.area;
    emitted += mean3(p.emission) * el.area;
  }
  EXPECT_GT(reflected, 0.0);
  EXPECT_LT(reflected, emitted * 0.78 / (1.0 - 0.78));
}

// Substructuring refines where the light is partly hidden (the blocks' shadow boundaries on the
// floor), and leaves the evenly lit middle of the ceiling coarse.
TEST_F(CornellBox, RefinesShadowBoundariesAndNotTheEvenCeiling) {
  const Mesh mesh = solver_->mesh();
  double penumbra_area = 0.0, ceiling_area = 0.0;
  int penumbra_n = 0, ceiling_n = 0;
  for (const auto& el : mesh.elements) {
    glm::dvec3 c(0.0);
    for (uint32_t i = 0; i < el.corner_count; ++i) c += mesh.positions[el.corners[i]];
    c /= static_cast<double>(el.corner_count);
    if (c.y < 1.0) {  // floor
      const double v = light_visibility(*scene_, c + glm::dvec3(0, 0.01, 0));
      if (v > 0.1 && v < 0.9) {
        penumbra_area += el.area;
        ++penumbra_n;
      }
    } else if (c.y > 548 && scene_->patches[el.patch].material == kCornellWhite &&
               c.x > 100 && c.x < 456 && c.z > 100 && c.z < 459 &&
               !(c.x > 180 && c.x < 376 && c.z > 190 && c.z < 370)) {
      // The ceiling away from the walls and the light's rim.
      ceiling_area += el.area;
      ++ceiling_n;
    }
  }
  ASSERT_GT(penumbra_n, 20);
  ASSERT_GT(ceiling_n, 0);
  const double penumbra_mean = penumbra_area / penumbra_n, ceiling_mean = ceiling_area / ceiling_n;
  EXPECT_GT(ceiling_mean, 8.0 * penumbra_mean)
      << "penumbra elements " << penumbra_n << " of mean area " << penumbra_mean
      << ", ceiling elements " << ceiling_n << " of mean area " << ceiling_mean;
}

// Every vertex of the mesh that lies inside an element's edge is part of that element's boundary
// loop: triangulating the loops leaves no T-junctions. Checked by brute force over positions.
TEST(SolverMesh, BoundaryLoopsContainEveryVertexOnTheirEdges) {
  Scene scene = make_closed_box(1.0, 1, glm::dvec3(0.6), glm::dvec3(0.0), true);
  scene.patches[0].emission = glm::dvec3(5.0);  // one emitting wall: uneven light, uneven mesh
  Params params;
  params.aeps = 2e-3;
  Solver solver(scene, params);
  solver.run();
  const Mesh mesh = solver.mesh();
  ASSERT_GT(mesh.elements.size(), 100u);
  std::vector<uint32_t> used;
  for (const auto& el : mesh.elements)
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) used.push_back(mesh.boundary[i]);
  std::sort(used.begin(), used.end());
  used.erase(std::unique(used.begin(), used.end()), used.end());
  size_t checked = 0;
  for (const auto& el : mesh.elements) {
    const std::vector<uint32_t> loop(mesh.boundary.begin() + el.boundary_begin,
                                     mesh.boundary.begin() + el.boundary_end);
    for (uint32_t k = 0; k < el.corner_count; ++k) {
      const glm::dvec3 a = mesh.positions[el.corners[k]];
      const glm::dvec3 b = mesh.positions[el.corners[(k + 1) % el.corner_count]];
      const double len = glm::length(b - a);
      for (uint32_t v : used) {
        const glm::dvec3 p = mesh.positions[v];
        const double t = glm::dot(p - a, b - a) / (len * len);
        if (t <= 1e-9 || t >= 1 - 1e-9) continue;
        if (glm::length(a + (b - a) * t - p) > 1e-9 * len) continue;
        ++checked;
        const bool in_loop = std::any_of(loop.begin(), loop.end(),
                                         [&](uint32_t u) { return mesh.positions[u] == p; });
        ASSERT_TRUE(in_loop) << "a vertex on an edge of an element of patch " << el.patch
                             << " is missing from its boundary loop";
      }
    }
  }
  EXPECT_GT(checked, 0u);
}

TEST(Solver, SameThreadCountGivesIdenticalResults) {
  const Scene scene = make_cornell_box();
  Params params;
  params.threads = 2;
  params.convergence = 0.05;
  Solver a(scene, params), b(scene, params);
  a.run();
  b.run();
  const Mesh ma = a.mesh(), mb = b.mesh();
  ASSERT_EQ(ma.elements.size(), mb.elements.size());
  for (size_t v = 0; v < ma.radiosity.size(); ++v) ASSERT_EQ(ma.radiosity[v], mb.radiosity[v]);
}

// Reusing the parent's pixels for its children is the paper's saving; it must give the same
// form factors as projecting the whole scene again.
TEST(Solver, ReusingParentVisibilityMatchesReprojection) {
  const Scene scene = make_cornell_box();
  Params params;
  params.convergence = 0.3;
  Params again = params;
  again.reuse_visibility = false;
  Solver reuse(scene, params), reproject(scene, again);
  reuse.run();
  reproject.run();
  EXPECT_GT(reuse.stats().reused_children, 0u);
  EXPECT_EQ(reproject.stats().reused_children, 0u);
  EXPECT_GT(reproject.stats().projections, reuse.stats().projections);
  // The two runs may create elements in a different order: match them by patch and corners.
  auto by_place = [](const Mesh& m) {
    std::map<std::pair<uint32_t, std::array<double, 3>>, glm::dvec3> out;
    for (const auto& el : m.elements) {
      glm::dvec3 c(0.0);
      for (uint32_t i = 0; i < el.corner_count; ++i) c += m.positions[el.corners[i]];
      out[{el.patch, {c.x, c.y, c.z}}] = el.radiosity;
    }
    return out;
  };
  const auto a = by_place(reuse.mesh()), b = by_place(reproject.mesh());
  ASSERT_EQ(a.size(), b.size());
  for (const auto& [key, radiosity] : a) {
    const auto it = b.find(key);
    ASSERT_NE(it, b.end()) << "an element of patch " << key.first << " exists in only one run";
    for (int c = 0; c < 3; ++c)
      ASSERT_NEAR(radiosity[c], it->second[c], 1e-6 * (1e-3 + it->second[c]))
          << "element of patch " << key.first << " at " << key.second[0] << ", " << key.second[1]
          << ", " << key.second[2];
  }
}

// A shooter that shoots again takes its earlier shot's form factors (a replay) while the mesh is
// unchanged. In a closed box of small patches nothing is ever split, so every cluster's later shots
// replay; the closed form must hold as well as it does with every shot projected anew.
TEST(Solver, ReplayedShotsKeepTheClosedForm) {
  const glm::dvec3 rho(0.5, 0.3, 0.7), e(1.0, 2.0, 0.5);
  const glm::dvec3 expected = e / (glm::dvec3(1.0) - rho);
  const Scene scene = make_closed_box(2.0, 6, rho, e, true);
  Params params;
  params.cluster_size = 0.25;
  Params fresh = params;
  fresh.shot_cache_mb = 0;
  Solver replaying(scene, params), projecting(scene, fresh);
  ASSERT_TRUE(replaying.run().converged);
  ASSERT_TRUE(projecting.run().converged);
  EXPECT_EQ(projecting.stats().replayed_shots, 0u);
  // Most shots are repeats of a few dozen clusters.
  EXPECT_GT(replaying.stats().replayed_shots * 2, replaying.stats().shots);
  EXPECT_LT(replaying.stats().hemicubes, projecting.stats().hemicubes);
  auto rms_error = [&](const Mesh& mesh) {
    double sum2 = 0.0;
    for (const auto& el : mesh.elements)
      for (int c = 0; c < 3; ++c) sum2 += std::pow(el.radiosity[c] / expected[c] - 1.0, 2) / 3.0;
    return std::sqrt(sum2 / mesh.elements.size());
  };
  const double with = rms_error(replaying.mesh()), without = rms_error(projecting.mesh());
  EXPECT_LT(with, 0.01);
  EXPECT_LT(with, without * 1.1 + 1e-3) << "replayed " << with << ", projected " << without;
}

// Splits change what a shooter sees: no shot may be replayed across them. On the Cornell box,
// which is split during its early shots, the replaying solve must give the mesh and the surfaces'
// radiosities of the solve that projects every shot.
TEST(Solver, ReplaysAfterSplitsMatchFreshShots) {
  const Scene scene = make_cornell_box();
  Params params;
  Params fresh = params;
  fresh.shot_cache_mb = 0;
  Solver replaying(scene, params), projecting(scene, fresh);
  replaying.run();
  projecting.run();
  EXPECT_GT(replaying.stats().replayed_shots, 0u);
  EXPECT_GT(replaying.stats().splits, 0u);
  const double elements = static_cast<double>(projecting.stats().elements);
  EXPECT_NEAR(static_cast<double>(replaying.stats().elements) / elements, 1.0, 0.05);
  auto per_patch = [&](const Mesh& mesh) {
    std::vector<glm::dvec3> ba(scene.patches.size(), glm::dvec3(0.0));
    std::vector<double> a(scene.patches.size(), 0.0);
    for (const auto& el : mesh.elements) {
      ba[el.patch] += el.radiosity * el.area;
      a[el.patch] += el.area;
    }
    for (size_t p = 0; p < ba.size(); ++p) ba[p] /= a[p];
    return ba;
  };
  const auto x = per_patch(replaying.mesh()), y = per_patch(projecting.mesh());
  // Replays carry the refinement of the stronger shot they were recorded from; per surface that
  // moves the radiosity by about 1 % here.
  for (size_t p = 0; p < x.size(); ++p) EXPECT_NEAR(mean3(x[p]) / mean3(y[p]), 1.0, 0.025) << "patch " << p;
}

// In a closed box of uniform reflectance rho, whatever emits where, sum A B = sum A E / (1 - rho)
// (the form factors from every element sum to one). With one light the block's shadows are split
// shot after shot, so replays meet receivers split since they were recorded: their children must
// be shot anew, once (handing their light to the split elements lost 1.4 % of it; shooting a
// child both from the record and anew added 0.8 %).
TEST(Solver, ReplaysAcrossSplitsKeepTheEnergyOfAClosedBox) {
  const double rho = 0.6;
  Scene scene = make_closed_box(2.0, 4, glm::dvec3(rho), glm::dvec3(0.0), true);
  double emitted = 0.0;
  for (Patch& p : scene.patches) {
    const glm::dvec3 n = glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]);
    const double a = 0.5 * glm::length(n) + 0.5 * glm::length(glm::cross(p.corners[2] - p.corners[0], p.corners[3] - p.corners[0]));
    // One ceiling patch (facing down, at the top) is the light.
    const glm::dvec3 c = 0.25 * (p.corners[0] + p.corners[1] + p.corners[2] + p.corners[3]);
    if (n.y < 0.0 && c.y > 1.9 && emitted == 0.0) {
      p.emission = glm::dvec3(10.0);
      emitted += 10.0 * a;
    }
  }
  ASSERT_GT(emitted, 0.0);
  ASSERT_EQ(validate(scene), "");
  Params params;
  params.convergence = 1e-4;
  Params fresh = params;
  fresh.shot_cache_mb = 0;
  auto energy = [&](const Params& p, Stats& st) {
    Solver solver(scene, p);
    st = solver.run();
    double ba = 0.0;
    for (const auto& el : solver.mesh().elements) ba += mean3(el.radiosity) * el.area;
    return ba / (emitted / (1.0 - rho));
  };
  Stats replaying, projecting;
  const double with = energy(params, replaying), without = energy(fresh, projecting);
  ASSERT_TRUE(replaying.converged);
  EXPECT_GT(replaying.splits, 0u);
  EXPECT_GT(replaying.replayed_shots, 0u);
  EXPECT_GT(replaying.replays_reshot, 0u);  // replays whose split receivers were shot anew
  // The solver holds the closed form to 1.2 % here, with replays or without.
  EXPECT_NEAR(with, 1.0, 0.02);
  EXPECT_NEAR(with / without, 1.0, 0.003) << "with replays " << with << ", without " << without;
}

// Boxes resting on a floor cover parts of it, which shoot nothing (shoot_node): a shooter with such
// parts replays like any other. In a closed room glowing evenly everywhere, with boxes standing on
// its floor, each shooter shoots afresh once and replays after, and every surface in view keeps
// B = E / (1 - rho). (The floor patches under the boxes are left out: an emitter is not split
// along a cover's outline, so such a patch takes light on its covered part too.)
TEST(Solver, ShootersPartlyUnderBoxesReplay) {
  const glm::dvec3 rho(0.5), e(1.0);
  Scene scene = make_closed_box(2.0, 4, rho, e, false);
  // Boxes half as wide as a floor patch (0.5 m), each on the middle of one.
  const std::array<glm::dvec3, 4> at{glm::dvec3(0.25, 0.0, 0.25), glm::dvec3(1.25, 0.0, 0.25), glm::dvec3(0.75, 0.0, 1.25),
                                      glm::dvec3(1.75, 0.0, 1.75)};
  const double half = 0.125;
  for (size_t i = 0; i < at.size(); ++i)
    add_box(scene, at[i] - glm::dvec3(half, 0.0, half), at[i] + glm::dvec3(half, 0.1 + 0.05 * i, half), rho, e, 1);
  ASSERT_EQ(validate(scene), "");
  Params params;
  params.convergence = 1e-4;
  Params fresh = params;
  fresh.shot_cache_mb = 0;
  Solver replaying(scene, params), projecting(scene, fresh);
  ASSERT_TRUE(replaying.run().converged);
  ASSERT_TRUE(projecting.run().converged);
  const Stats& st = replaying.stats();
  EXPECT_GT(st.replayed_shots, 0u);
  EXPECT_LE(st.shots - st.replayed_shots, st.shooters) << st.shots << " shots, " << st.replayed_shots << " replayed";
  const double expected = mean3(e / (glm::dvec3(1.0) - rho));
  auto under_a_box = [&](const glm::dvec3& x) {
    for (const glm::dvec3& c : at)
      if (x.y < 1e-9 && std::abs(x.x - c.x) < half && std::abs(x.z - c.z) < half) return true;
    return false;
  };
  auto worst = [&](const Mesh& mesh) {
    double w = 0.0;
    size_t seen = 0;
    for (const auto& el : mesh.elements) {
      glm::dvec3 centre(0.0);
      for (uint32_t i = 0; i < el.corner_count; ++i) centre += mesh.positions[el.corners[i]];
      if (under_a_box(centre / static_cast<double>(el.corner_count))) continue;
      w = std::max(w, std::abs(mean3(el.radiosity) / expected - 1.0));
      ++seen;
    }
    EXPECT_GT(seen, 96u);
    return w;
  };
  // Box faces at the floor read up to 2.3 % dark with every shot projected too (their form factors
  // to the floor beside them). Replays keep the near-field pieces of the first, strongest shot,
  // where a weaker fresh shot takes exact form factors: at those faces the two differ by a few
  // tenths of a per cent.
  const double with = worst(replaying.mesh()), without = worst(projecting.mesh());
  EXPECT_LT(with, 0.03) << "with replays";
  EXPECT_LT(without, 0.03) << "every shot projected";
}

TEST(Solver, CancellationStopsBetweenShots) {
  const Scene scene = make_cornell_box();
  Solver solver(scene, Params{});
  CancelToken token;
  uint64_t last = 0;
  const Stats& st = solver.run(
      [&](const Progress& p) {
        EXPECT_EQ(p.shots, last + 1);
        last = p.shots;
        if (p.shots == 3) token.cancel();
      },
      &token);
  EXPECT_TRUE(st.cancelled);
  EXPECT_FALSE(st.converged);
  EXPECT_EQ(st.shots, 3u);
}

TEST(Solver, UnshotPowerNeverGrows) {
  const Scene scene = make_cornell_box();
  Solver solver(scene, Params{});
  double last = 1.0;
  solver.run([&](const Progress& p) {
    EXPECT_LE(p.unshot_fraction, last + 1e-12);
    last = p.unshot_fraction;
  });
  EXPECT_LT(last, 1e-3);
}

// The ambient term makes an unconverged state displayable and vanishes at convergence.
TEST(Solver, AmbientTermBringsEarlyStatesToTheConvergedEnergy) {
  const glm::dvec3 rho(0.6), e(1.0);
  const Scene scene = make_closed_box(1.0, 2, rho, e, false);
  Solver solver(scene, Params{});
  for (int i = 0; i < 3; ++i) solver.step();
  auto mean_b = [](const Mesh& m) {
    double ba = 0.0, a = 0.0;
    for (const auto& el : m.elements) {
      ba += mean3(el.radiosity) * el.area;
      a += el.area;
    }
    return ba / a;
  };
  const double plain = mean_b(solver.mesh(false)), with_ambient = mean_b(solver.mesh(true));
  const double exact = 1.0 / (1.0 - 0.6);
  EXPECT_LT(plain, 0.9 * exact);
  EXPECT_NEAR(with_ambient / exact, 1.0, 0.02);
}

TEST(Validate, RejectsBadPatchesWithAMessageNamingThem) {
  Scene scene = make_closed_box(1.0, 1, glm::dvec3(0.5), glm::dvec3(1.0), false);
  EXPECT_EQ(validate(scene), "");
  Scene bad = scene;
  bad.patches[2].corners[1].x = std::nan("");
  EXPECT_NE(validate(bad).find("patch 2"), std::string::npos);
  bad = scene;
  bad.patches[3].corners[2] = bad.patches[3].corners[1];
  EXPECT_NE(validate(bad).find("patch 3"), std::string::npos);
  bad = scene;
  bad.patches[4].reflectance.y = 1.0;
  EXPECT_NE(validate(bad).find("reflectance"), std::string::npos);
  bad = scene;
  bad.patches[1].corners[3] += glm::dvec3(0.3, 0.3, 0.3);
  EXPECT_NE(validate(bad), "");
  bad = scene;
  bad.patches[0].emission.x = -1.0;
  EXPECT_NE(validate(bad).find("emission"), std::string::npos);
  EXPECT_NE(validate(Scene{}), "");
  Params params;
  params.resolution = 101;
  EXPECT_NE(validate(params).find("resolution"), std::string::npos);
  params = Params{};
  params.aeps = 0.0;
  EXPECT_NE(validate(params).find("aeps"), std::string::npos);
}

// A closed 4 m room (walls in 0.5 m cells) with `count` small closed boxes (4 to 18 cm, all six
// faces) on a jittered grid, standing 1 cm above the floor or floating. With `furnace`, every
// surface emits e and reflects rho; otherwise a 1 m ceiling panel is the only emitter.
Scene small_boxes_room(uint32_t count, bool furnace, const glm::dvec3& rho, const glm::dvec3& e) {
  Scene scene = make_closed_box(4.0, 8, rho, furnace ? e : glm::dvec3(0.0), false);
  if (!furnace)
    add_quad(scene, glm::dvec3(1.5, 3.99, 1.5), glm::dvec3(2.5, 3.99, 1.5), glm::dvec3(2.5, 3.99, 2.5),
             glm::dvec3(1.5, 3.99, 2.5), rho, e, 1);
  uint64_t state = 12345;
  auto next = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * (1.0 / 9007199254740992.0);
  };
  const glm::dvec3 box_e = furnace ? e : glm::dvec3(0.0);
  for (uint32_t i = 0; i < count; ++i) {
    // 20 x 20 slots of 0.19 m over the floor, in two layers: on the floor and at 1.2 m.
    const uint32_t slot = i % 200, layer = i / 200;
    const double x = 0.1 + 0.19 * (slot % 20) + 0.005, z = 0.1 + 0.19 * (slot / 20) + 0.005;
    const double w = 0.04 + 0.14 * next(), d = 0.04 + 0.14 * next(), h = 0.04 + 0.14 * next();
    const glm::dvec3 lo(x, layer == 0 ? 0.01 : 1.2 + 0.3 * next(), z), hi = lo + glm::dvec3(w, h, d);
    add_box(scene, lo, hi, rho, box_e, 2);
  }
  return scene;
}

// Faces of small boxes, each alone on its surface, shoot in clusters across boxes (one per
// orientation class). In a furnace of 100 closed boxes the closed form B = E / (1 - rho) holds for
// the total within 0.5 %, with fewer shots than clusters within surfaces only. (With 400 boxes:
// energy within 0.5 % too, but the two solves take minutes.)
TEST(Solver, ClustersAcrossSmallObjectsKeepTheFurnaceClosedForm) {
  const glm::dvec3 rho(0.5, 0.3, 0.7), e(1.0, 2.0, 0.5);
  const glm::dvec3 expected = e / (glm::dvec3(1.0) - rho);
  const Scene scene = small_boxes_room(100, true, rho, e);
  ASSERT_EQ(validate(scene), "");
  Params params;
  Solver across(scene, params);
  const Stats& st = across.run();
  ASSERT_TRUE(st.converged);
  params.cluster_across = false;
  Solver within(scene, params);
  const Stats& st_within = within.run();
  // 3397 shots against 5609 when written.
  EXPECT_LT(st.shots * 4, st_within.shots * 3) << st.shots << " against " << st_within.shots;
  const ClosedFormError err = closed_form_error(across.mesh(), expected);
  const ClosedFormError err_within = closed_form_error(within.mesh(), expected);
  std::printf("shots %llu across, %llu within; energy %.5f / %.5f; rms %.4f / %.4f; worst %.3f / %.3f\n",
              static_cast<unsigned long long>(st.shots), static_cast<unsigned long long>(st_within.shots), err.energy,
              err_within.energy, err.rms, err_within.rms, err.worst, err_within.worst);
  EXPECT_NEAR(err.energy, 1.0, 0.005);
  // Per element the boxes' bottoms 1 cm over the floor, and the floor under them, are the near
  // field's hard case with or without clusters across objects (RMS 12.6 % against 13.5 % when
  // written): clusters across objects must not make it worse.
  EXPECT_LT(err.rms, err_within.rms + 0.005);
}

// The same room of 100 boxes lit by a ceiling panel. In a closed room of one reflectance all the
// surfaces together reflect rho / (1 - rho) of the emitted power (a little less here: the panel's
// back, 1 cm under the ceiling, absorbs the little that reaches it). That holds within 0.5 % with
// clusters across the boxes and with every face shooting alone, and the two agree within 0.5 %.
// When written, 0.9985 and 0.9976 of the closed form (0.9997 and 0.9990 at resolution 100). Two
// defects failed it: a shot gave the light that a cluster's faces traded among themselves to faces
// whose unshot light it then cleared (clusters across objects lost up to 1.2 %), and a flat patch's
// near receivers took from its parts more than its hemicube had left them, on top of the far
// receivers' full share (every face alone gave out 1.3 % too much; before the fixes 1.0089 and
// 1.0117 here). With 400 boxes at resolution 100 (HEMIBAKE_TEST_BOXES=400 and this resolution set
// to 100, a minute): 0.9993 and 0.9966, 3179 shots against 13 529.
TEST(Solver, ClustersAcrossSmallObjectsReflectTheClosedFormsLight) {
  const uint32_t boxes = std::getenv("HEMIBAKE_TEST_BOXES") ? std::atoi(std::getenv("HEMIBAKE_TEST_BOXES")) : 100;
  const Scene scene = small_boxes_room(boxes, false, glm::dvec3(0.6), glm::dvec3(10.0));
  ASSERT_EQ(validate(scene), "");
  Params params;
  params.resolution = 50;  // the sums of form factors do not depend on it; the time does
  Solver across(scene, params);
  const Stats& st = across.run();
  ASSERT_TRUE(st.converged);
  params.cluster_size = 0.0;
  Solver alone(scene, params);
  const Stats& st_alone = alone.run();
  ASSERT_TRUE(st_alone.converged);
  // The quads' areas from two edges: they are rectangles.
  double emitted = 0.0;
  for (const auto& p : scene.patches)
    emitted += mean3(p.emission) * glm::length(glm::cross(p.corners[1] - p.corners[0], p.corners[3] - p.corners[0]));
  auto reflected = [&](const Mesh& mesh) {
    double sum = 0.0;
    for (const auto& el : mesh.elements) sum += (mean3(el.radiosity) - mean3(scene.patches[el.patch].emission)) * el.area;
    return sum;
  };
  const double closed = 0.6 / 0.4 * emitted;
  const double across_share = reflected(across.mesh()) / closed, alone_share = reflected(alone.mesh()) / closed;
  std::printf("shots %llu across objects, %llu alone; reflected / closed form %.5f across, %.5f alone\n",
              static_cast<unsigned long long>(st.shots), static_cast<unsigned long long>(st_alone.shots), across_share,
              alone_share);
  for (double share : {across_share, alone_share}) {
    EXPECT_GT(share, 0.995);
    EXPECT_LT(share, 1.002);  // no more than the closed form, but for the hemicubes' rounding
  }
  EXPECT_NEAR(across_share / alone_share, 1.0, 0.005);
  EXPECT_LT(st.shots * 4, st_alone.shots * 3);
}

// Area-weighted mean radiosity (RGB mean) of the elements of `material`'s patches.
double mean_radiosity(const Scene& scene, const Mesh& mesh, uint32_t material) {
  double ba = 0.0, a = 0.0;
  for (const auto& el : mesh.elements)
    if (scene.patches[el.patch].material == material) {
      ba += (el.radiosity.x + el.radiosity.y + el.radiosity.z) / 3.0 * el.area;
      a += el.area;
    }
  return ba / a;
}

// Glowing boxes (6 to 18 cm, floating in a 4 m room, nothing else emits) pool into volume clusters: boxes
// near one another shoot together from one whole cube whatever way their faces look. The light the
// room's walls and the boxes take stays that of every face shooting alone within 1.5 %, with at most
// half the shooters of clusters by orientation class.
TEST(Solver, VolumeClustersOfGlowingBoxesLightTheRoomAsTheirFacesAlone) {
  Scene scene = make_closed_box(4.0, 8, glm::dvec3(0.6), glm::dvec3(0.0), false);
  uint64_t state = 777;
  auto next = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * (1.0 / 9007199254740992.0);
  };
  using V = glm::dvec3;
  const V rho(0.5), e(4.0, 3.0, 2.0);
  for (int i = 0; i < 48; ++i) {
    // A 4 x 3 x 4 grid of 0.5 m (jittered by 5 cm) in the room's middle, floating.
    const V centre(1.25 + 0.5 * (i % 4) + 0.1 * (next() - 0.5), 0.8 + 0.5 * ((i / 4) % 3) + 0.1 * (next() - 0.5),
                   1.25 + 0.5 * (i / 12) + 0.1 * (next() - 0.5));
    const V half(0.03 + 0.06 * next(), 0.03 + 0.06 * next(), 0.03 + 0.06 * next());
    const V lo = centre - half, hi = centre + half;
    add_box(scene, lo, hi, rho, e, 2);
  }
  ASSERT_EQ(validate(scene), "");
  Params params;
  params.resolution = 50;  // the shares of light do not depend on it; the time does
  Solver volume(scene, params);
  ASSERT_TRUE(volume.run().converged);
  Params by_orientation = params;
  by_orientation.cluster_volume = false;
  const Solver oriented(scene, by_orientation);
  Params alone_params = params;
  alone_params.cluster_size = 0.0;
  Solver alone(scene, alone_params);
  ASSERT_TRUE(alone.run().converged);
  // The boxes' shooters: what the room adds to those of the empty room.
  const Solver empty(make_closed_box(4.0, 8, glm::dvec3(0.6), glm::dvec3(0.0), false), {});
  const uint64_t room = empty.stats().shooters;
  std::printf("the boxes' shooters: volume %llu, by orientation %llu, alone %llu\n",
              static_cast<unsigned long long>(volume.stats().shooters - room),
              static_cast<unsigned long long>(oriented.stats().shooters - room),
              static_cast<unsigned long long>(alone.stats().shooters - room));
  EXPECT_LE(2 * (volume.stats().shooters - room), oriented.stats().shooters - room);
  for (uint32_t material : {0u, 2u}) {
    const double ratio = mean_radiosity(scene, volume.mesh(), material) / mean_radiosity(scene, alone.mesh(), material);
    std::printf("material %u: volume / alone %.4f\n", material, ratio);
    EXPECT_NEAR(ratio, 1.0, 0.015) << material;
  }
}

// A tessellated sphere resting on a floor tile, in a room lit by a ceiling panel: the sphere's
// clusters shoot weak light (under FEPS of the emitted power), and the tile under the sphere faces
// the bottom cluster within a diameter. Weak cluster pieces no longer hand all their receivers to
// their halves for such a face (a 159k-facet sphere's went down to single facets: 3328 hemicubes
// for one shot; bench/README.md, big inputs); the light the sphere and the floor take stays that
// of the same solve with every patch shooting alone, within 1 %.
TEST(Solver, ClustersOfASphereRestingOnAFloorLightItAsItsFacetsAlone) {
  const Scene scene = make_sphere_room(12, 24);
  ASSERT_EQ(validate(scene), "");
  Params params;
  params.resolution = 50;  // the shares of light do not depend on it; the time does
  Solver clustered(scene, params);
  ASSERT_TRUE(clustered.run().converged);
  Params alone_params = params;
  alone_params.cluster_size = 0.0;
  Solver alone(scene, alone_params);
  ASSERT_TRUE(alone.run().converged);
  // The sphere's facets (material 3) and the floor (material 0).
  for (uint32_t material : {0u, 3u})
    EXPECT_NEAR(mean_radiosity(scene, clustered.mesh(), material) / mean_radiosity(scene, alone.mesh(), material), 1.0, 0.01)
        << material;
}

// Curved surfaces (a wavy double-sided curtain, a column of 16 sides) cluster by where their facets
// face: the tree cuts on normals while they spread wider than a cluster's cone, so a cluster spans
// the surface. Cut on positions alone, every slice held all orientations until it was a facet or
// two (the atrium's curtains shot as clusters of 7 triangles: bench/README.md, big inputs). Fewer
// shooters, and the light each surface takes stays that of every patch shooting alone, within 1 %
// (the curtain's side towards the wall took 5 % less when a cluster's hemicube stood at its
// centroid, behind the crests of its own waves: it now stands in front of its foremost corner).
TEST(Solver, CurvedSurfacesClusterByOrientationAndLightAsTheirFacetsAlone) {
  using V = glm::dvec3;
  Scene scene = make_sphere_room(12, 24);
  const V none(0.0);
  // The curtain: 3 x 2.2 m in 24 x 10 cells before the far wall, three waves of 10 cm (facets up
  // to 32 degrees from the mean).
  const int nu = 24, nv = 10;
  auto at = [&](int i, int j) {
    return V(0.5 + 3.0 * i / nu, 0.3 + 2.2 * j / nv, 4.5 + 0.1 * std::sin(2.0 * std::numbers::pi * 3.0 * i / nu));
  };
  const uint32_t patches_before = static_cast<uint32_t>(scene.patches.size());
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      add_quad(scene, at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1), V(0.6, 0.2, 0.2), none, 4);
      add_quad(scene, at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j), V(0.2, 0.2, 0.6), none, 5);
    }
  // The column: radius 0.15 m, 16 sides, floor to ceiling in 4 rings.
  const int sides = 16, rings = 4;
  auto rim = [&](int k, int r) {
    const double a = 2.0 * std::numbers::pi * k / sides;
    return V(0.6 + 0.15 * std::cos(a), 3.0 * r / rings, 0.6 + 0.15 * std::sin(a));
  };
  for (int k = 0; k < sides; ++k)
    for (int r = 0; r < rings; ++r)
      add_quad(scene, rim(k, r), rim(k, r + 1), rim(k + 1, r + 1), rim(k + 1, r), V(0.5), none, 6);
  const uint32_t curved = static_cast<uint32_t>(scene.patches.size()) - patches_before;
  ASSERT_EQ(validate(scene), "");
  Params params;  // clusters up to 0.15 of the room's diagonal (1.06 m)
  params.resolution = 50;  // the shares of light do not depend on it; the time does
  Solver clustered(scene, params);
  ASSERT_TRUE(clustered.run().converged);
  Params alone_params = params;
  alone_params.cluster_size = 0.0;
  Solver alone(scene, alone_params);
  ASSERT_TRUE(alone.run().converged);
  // Every patch alone is a shooter; clustered, the curved surfaces' facets add a shooter per three
  // or more of them to the room's (clusters no wider than 1.06 m cut the 3 m curtain and column; cut
  // on positions alone they added one per 2.5).
  EXPECT_EQ(alone.stats().shooters, scene.patches.size());
  const Solver room_only(make_sphere_room(12, 24), params);
  ASSERT_GT(clustered.stats().shooters, room_only.stats().shooters);
  EXPECT_LE(clustered.stats().shooters - room_only.stats().shooters, curved / 3);
  for (uint32_t material : {0u, 1u, 3u, 4u, 5u, 6u})
    EXPECT_NEAR(mean_radiosity(scene, clustered.mesh(), material) / mean_radiosity(scene, alone.mesh(), material), 1.0, 0.01)
        << material;
}

}  // namespace
}  // namespace hemibake::solver
