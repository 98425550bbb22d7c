// Light pools (Params::pools, solver/src/pools.cpp): a large floor (one patch) under small
// emitters is refined where their light pools, without the final gather. The truth is Lambert's
// point-to-polygon form factor; the floor is judged as a viewer sees it, at random points, with the
// error measured as the bench measures it (relative to the exact value, or to 5 % of the mean
// where the exact value is smaller). Without pools these floors stay one element or nearly
// (median errors of 60 % and more).
#include "hemibake/solver/hemicube.h"
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"
#include "shown_on_floor.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <numeric>
#include <random>
#include <vector>

namespace hemibake::solver {
namespace {

struct Shown {
  double median = 0.0, p90 = 0.0;
  size_t elements = 0;
};

// A 12 x 12 m floor as one patch (rho 0.6) under a square lamp of side `side` at `height`, facing
// down, cut into n x n patches. With `far_light`, an 8 x 8 m emitter under the floor, facing away
// from it, holds most of the scene's power (the lamp is one light among many, as a lamp is in a
// lit building). Bakes with `params` and compares what the floor shows at 400 random points within
// `radius` of the lamp's foot with rho E F(point -> lamp).
Shown floor_under_lamp(double side, double height, int n, bool far_light, double radius, const Params& params) {
  Scene scene;
  const glm::dvec3 rho(0.6), e(40.0);
  add_quad(scene, {-6, 0, -6}, {-6, 0, 6}, {6, 0, 6}, {6, 0, -6}, rho, glm::dvec3(0.0), 0);
  if (far_light) add_quad(scene, {-4, -1, -4}, {4, -1, -4}, {4, -1, 4}, {-4, -1, 4}, glm::dvec3(0.0), e, 2);
  const double h = side / 2.0, step = side / n;
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < n; ++k) {
      const double x0 = -h + i * step, z0 = -h + k * step;
      add_quad(scene, {x0, height, z0}, {x0 + step, height, z0}, {x0 + step, height, z0 + step}, {x0, height, z0 + step},
               glm::dvec3(0.0), e, 1);
    }
  EXPECT_EQ(validate(scene), "");
  const std::vector<glm::dvec3> lamp{{-h, height, -h}, {h, height, -h}, {h, height, h}, {-h, height, h}};
  auto exact = [&](double x, double z) { return rho.x * e.x * point_polygon_form_factor({x, 0, z}, {0, 1, 0}, lamp); };
  Solver solver(scene, params);
  EXPECT_TRUE(solver.run().converged);
  const Mesh mesh = solver.mesh();
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-radius, radius);
  std::vector<glm::dvec2> points;
  double mean_exact = 0.0;
  while (points.size() < 400) {
    const double x = u(rng), z = u(rng);
    if (x * x + z * z > radius * radius) continue;
    points.emplace_back(x, z);
    mean_exact += exact(x, z) / 400.0;
  }
  std::vector<double> errors;
  for (const glm::dvec2& p : points) {
    const auto shown = shown_on_floor(mesh, 0, 1, p.x, p.y);
    EXPECT_TRUE(shown.has_value()) << p.x << " " << p.y;
    if (!shown) continue;
    const double want = exact(p.x, p.y);
    errors.push_back(std::abs(shown->x - want) / std::max(want, 0.05 * mean_exact));
  }
  std::sort(errors.begin(), errors.end());
  Shown s;
  if (errors.empty()) return s;
  s.median = errors[errors.size() / 2];
  s.p90 = errors[errors.size() * 9 / 10];
  s.elements = mesh.elements.size();
  return s;
}

// One lamp patch 0.5 m over the floor, one shot, with a small share of the scene's power. Weighed
// by the scene's power its form factor to the floor mattered little, and the floor's four
// corners, 6 m away, see almost nothing of it, so no criterion of a shot split the floor; the
// light pools' pass refined it (the error as shown fell to a quarter at the median, a half at
// p90). FEPS now weighs the lamp's shot against the light of what it reaches, at least the lamp's
// own power, and the shot itself refines the pool: both ways the floor within 2 m shows the
// closed form (median 3.4 %, p90 9.8 % with pools and 11.5 % without).
TEST(Refine, FloorUnderASmallLampIsRefinedWhereItsLightPools) {
  // The smallest element (AEPS of the scene's 208 m^2) must be small beside the pool, 1 m wide.
  Params params;
  params.aeps = 1e-5;
  const Shown without = floor_under_lamp(0.3, 0.5, 1, true, 2.0, params);
  params.pools = true;
  const Shown with = floor_under_lamp(0.3, 0.5, 1, true, 2.0, params);
  std::printf("one lamp patch: median %.3f, p90 %.3f, %zu elements (without pools %.3f, %.3f, %zu)\n", with.median,
              with.p90, with.elements, without.median, without.p90, without.elements);
  EXPECT_LT(with.median, 0.05);
  EXPECT_LT(with.p90, 0.12);
  EXPECT_LT(without.median, 0.05);
  EXPECT_LT(without.p90, 0.15);
}

// The same lamp as 8 x 8 patches shooting one by one (no clusters): each shot alone varies across
// the floor by little, their sum by as much as the single lamp's. The floor is refined as finely.
TEST(Refine, LightOfManySmallShootersAddsUpAcrossAnElement) {
  Params params;
  params.cluster_size = 0.0;
  params.pools = true;
  const Shown s = floor_under_lamp(0.3, 1.5, 8, false, 4.0, params);
  std::printf("8 x 8 lamp patches: median %.3f, p90 %.3f, %zu elements\n", s.median, s.p90, s.elements);
  EXPECT_LT(s.median, 0.06);
  EXPECT_LT(s.p90, 0.20);
}

// A glowing sphere (r 0.4 m, 24 x 24 triangles) 5 cm above a 20 x 20 m floor, one patch: each of
// its 1 104 faces shoots too little to split the floor alone, and the first pass, which had split
// the floor under the sphere finely for its own shots, found the pool in none of those small
// elements, so the solve proper kept four 2.5 m elements under the sphere (the floor 2 to 3 m
// from it shown at 5.8 times its light). Truth: rho E times the sum of the faces' point-to-polygon
// form factors (the sphere is convex: a face is seen wherever it faces the point); the error as
// the bench measures it, at 400 random points within 2 m of the sphere's foot: median 2.5 %, p90
// 7.7 % (79 % and 235 % before; 5.7 % and 9.5 % with the pool held to AEPS, 0.45 m elements
// against a pool about 1 m wide).
TEST(Refine, FloorUnderAGlowingSphereJustAboveItIsRefined) {
  Scene scene;
  const glm::dvec3 rho(0.5), e(10.0);
  add_quad(scene, {-10, 0, -10}, {-10, 0, 10}, {10, 0, 10}, {10, 0, -10}, rho, glm::dvec3(0.0), 0);
  add_uv_sphere(scene, {0.0, 0.45, 0.0}, 0.4, 24, 24, glm::dvec3(0.0), e, 1);
  EXPECT_EQ(validate(scene), "");
  auto exact = [&](double x, double z) {
    const glm::dvec3 at(x, 0.0, z);
    double f = 0.0;
    for (size_t p = 1; p < scene.patches.size(); ++p) {
      const Patch& t = scene.patches[p];
      const glm::dvec3 n = glm::cross(t.corners[1] - t.corners[0], t.corners[2] - t.corners[0]);
      if (glm::dot(n, at - t.corners[0]) <= 0.0) continue;
      f += point_polygon_form_factor(at, {0, 1, 0}, std::vector<glm::dvec3>(t.corners.begin(), t.corners.begin() + 3));
    }
    return rho.x * e.x * f;
  };
  Params params;
  params.pools = true;
  params.threads = 2;
  Solver solver(scene, params);
  EXPECT_TRUE(solver.run().converged);
  const Mesh mesh = solver.mesh();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  std::vector<glm::dvec3> points;  // x, z, exact
  double mean_exact = 0.0;
  while (points.size() < 400) {
    const double x = u(rng), z = u(rng);
    if (x * x + z * z > 4.0) continue;
    points.emplace_back(x, z, exact(x, z));
    mean_exact += points.back().z / 400.0;
  }
  std::vector<double> errors;
  for (const glm::dvec3& p : points) {
    const auto shown = shown_on_floor(mesh, 0, 1, p.x, p.y);
    ASSERT_TRUE(shown.has_value()) << p.x << " " << p.y;
    errors.push_back(std::abs(shown->x - p.z) / std::max(p.z, 0.05 * mean_exact));
  }
  std::sort(errors.begin(), errors.end());
  std::printf("floor under a glowing sphere: median %.3f, p90 %.3f, %zu elements\n", errors[200], errors[360],
              mesh.elements.size());
  EXPECT_LT(errors[200], 0.045);
  EXPECT_LT(errors[360], 0.12);
}

// An area lamp's penumbra. A square lamp (side 0.4 m, 2 m over a floor, facing down) is half
// covered, as seen from the floor under its middle, by a black plate 1 m over the floor whose edge
// runs under the lamp's middle (x = 0): a floor point at x sees the part of the lamp with x' > -x,
// so the floor goes from dark to fully lit across x in [-0.2, 0.2]. Truth: rho E times the
// point-to-polygon form factor of that part. Error: as a share of the unoccluded lamp's light, at
// random points of the 0.6 m square around the lamp's foot, two thirds of them in the penumbra.
// A hemicube at the lamp's centre alone casts the plate's shadow as a point light does, a step at
// x = 0, a mean error of about 1/4 over the penumbra's ramp and 1/6 over the square. The lamp, a
// strong emitter, shoots from 4 x 4 pieces (shooters.cpp), which cast four steps a tenth apart: a
// quarter of that error (1/24 over the square); 2 x 2 pieces would leave half of it (1/12).
TEST(Refine, AreaLampCastsAPenumbraAcrossAnEdge) {
  Scene scene;
  const glm::dvec3 rho(0.6), e(10.0), black(0.0), none(0.0);
  // The floor in 0.2 m tiles: one 4 m patch would be near the lamp for the near-field rule
  // (near_field.cpp) and take its light from the lamp's sixteenths, until its first split.
  for (int i = 0; i < 20; ++i)
    for (int k = 0; k < 20; ++k) {
      const double x0 = -2 + 0.2 * i, z0 = -2 + 0.2 * k;
      add_quad(scene, {x0, 0, z0}, {x0, 0, z0 + 0.2}, {x0 + 0.2, 0, z0 + 0.2}, {x0 + 0.2, 0, z0}, rho, none, 0);
    }
  add_quad(scene, {-2, 1, -2}, {-2, 1, 2}, {0, 1, 2}, {0, 1, -2}, black, none, 1);  // plate, up
  add_quad(scene, {-2, 1, -2}, {0, 1, -2}, {0, 1, 2}, {-2, 1, 2}, black, none, 1);  // plate, down
  const double h = 0.2;
  add_quad(scene, {-h, 2, -h}, {h, 2, -h}, {h, 2, h}, {-h, 2, h}, black, e, 2);            // lamp, down
  ASSERT_EQ(validate(scene), "");
  // What the part of the lamp with x' >= cut gives the floor at (x, 0, z).
  auto part = [&](double x, double z, double cut) {
    if (cut >= h) return 0.0;
    const std::vector<glm::dvec3> seen{{cut, 2, -h}, {h, 2, -h}, {h, 2, h}, {cut, 2, h}};
    return rho.x * e.x * point_polygon_form_factor({x, 0, z}, {0, 1, 0}, seen);
  };
  auto exact = [&](double x, double z) { return part(x, z, std::clamp(-x, -h, h)); };
  Solver solver(scene, Params{});
  ASSERT_TRUE(solver.run().converged);
  const Mesh mesh = solver.mesh();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  std::vector<double> errors;
  for (int i = 0; i < 400; ++i) {
    const double x = u(rng), z = u(rng);
    const auto shown = shown_on_floor(mesh, 0, 400, x, z);
    ASSERT_TRUE(shown.has_value()) << x << " " << z;
    errors.push_back(std::abs(shown->x - exact(x, z)) / part(x, z, -h));
  }
  std::sort(errors.begin(), errors.end());
  const double mean = std::accumulate(errors.begin(), errors.end(), 0.0) / errors.size();
  std::printf("penumbra: error / unoccluded light: mean %.3f, p90 %.3f, max %.3f\n", mean, errors[360], errors.back());
  EXPECT_LT(mean, 0.065);
  EXPECT_LT(errors[360], 0.15);  // one step 0.4, two steps 0.2
}

// A room lit only by a sun through a skylight: most of the sun falls on the roof's outside and
// leaves into the empty sky when the roof shoots, the sun's patch on the floor holds the light
// that reaches the end walls. The first pass waits for the patches the lights lit to shoot (those
// holding at least a hundredth of the light): the end wall, lit only by that floor's light and
// brighter in the middle than at its sides, is refined where that light varies. When the pass
// ended on 70 % of all the light given out, it ended before the floor shot, and the end wall
// stayed one flat element (a Blender gallery's, 18 % median error).
TEST(Refine, EndWallOfARoomLitThroughASkylightIsRefined) {
  Scene scene;
  const glm::dvec3 rho(0.7), none(0.0);
  const double w = 8.0, h = 3.0, d = 4.0, t = 0.2;
  add_quad(scene, {0, 0, 0}, {0, 0, d}, {w, 0, d}, {w, 0, 0}, rho, none, 0);   // floor, up
  add_quad(scene, {0, 0, 0}, {0, h, 0}, {0, h, d}, {0, 0, d}, rho, none, 0);   // x = 0, +x: the end wall
  add_quad(scene, {w, 0, 0}, {w, 0, d}, {w, h, d}, {w, h, 0}, rho, none, 0);   // x = w, -x
  add_quad(scene, {0, 0, 0}, {w, 0, 0}, {w, h, 0}, {0, h, 0}, rho, none, 0);   // z = 0, +z
  add_quad(scene, {0, 0, d}, {0, h, d}, {w, h, d}, {w, 0, d}, rho, none, 0);   // z = d, -z
  // The ceiling (facing down) and the roof's top (facing up) around an opening x 3..5, z 1.5..2.5,
  // with its four jambs.
  const double x0 = 3.0, x1 = 5.0, z0 = 1.5, z1 = 2.5;
  auto ring = [&](double y, bool up) {
    auto q = [&](double ax, double az, double bx, double bz) {
      if (up) add_quad(scene, {ax, y, az}, {ax, y, bz}, {bx, y, bz}, {bx, y, az}, rho, none, 0);
      else add_quad(scene, {ax, y, az}, {bx, y, az}, {bx, y, bz}, {ax, y, bz}, rho, none, 0);
    };
    q(0, 0, x0, d);
    q(x1, 0, w, d);
    q(x0, 0, x1, z0);
    q(x0, z1, x1, d);
  };
  ring(h, false);
  ring(h + t, true);
  add_quad(scene, {x0, h, z0}, {x0, h + t, z0}, {x0, h + t, z1}, {x0, h, z1}, rho, none, 0);  // jambs, facing in
  add_quad(scene, {x1, h, z0}, {x1, h, z1}, {x1, h + t, z1}, {x1, h + t, z0}, rho, none, 0);
  add_quad(scene, {x0, h, z0}, {x1, h, z0}, {x1, h + t, z0}, {x0, h + t, z0}, rho, none, 0);
  add_quad(scene, {x0, h, z1}, {x0, h + t, z1}, {x1, h + t, z1}, {x1, h, z1}, rho, none, 0);
  Light sun;
  sun.type = Light::Type::kDirectional;
  sun.direction = glm::normalize(glm::dvec3(0.2, -1.0, 0.1));
  sun.intensity = glm::dvec3(3.0);
  scene.lights.push_back(sun);
  ASSERT_EQ(validate(scene), "");
  Params params;
  params.pools = true;
  Solver solver(scene, params);
  ASSERT_TRUE(solver.run().converged);
  const Mesh mesh = solver.mesh();
  size_t end_wall = 0;
  for (const auto& el : mesh.elements) end_wall += el.patch == 1;
  EXPECT_GT(end_wall, 4u);
}

// Evenly lit surfaces have no pools: a uniform closed box (every patch emitting E, reflectance
// rho) is not subdivided with pools either, and keeps B = E / (1 - rho). Its patches all emit, so
// none holds a grid and there is no first pass.
TEST(Refine, UniformClosedBoxHasNoPools) {
  const Scene scene = make_closed_box(1.0, 3, glm::dvec3(0.6), glm::dvec3(1.0), true);
  Params params;
  params.pools = true;
  Solver solver(scene, params);
  const Stats& st = solver.run();
  ASSERT_TRUE(st.converged);
  EXPECT_EQ(st.passes, 1u);
  EXPECT_EQ(st.splits, 0u);
  EXPECT_EQ(st.elements, scene.patches.size());
  for (const Mesh::Element& el : solver.mesh().elements) EXPECT_NEAR(el.radiosity.x, 2.5, 0.05);
}

// The same box emitting nowhere but one wall, which does not count as lit evenly: a 3 x 3 grid of
// 1/3 m cells (each large enough to split) is looked at in a first pass.
TEST(Refine, BoxLitByOneWallHasAFirstPass) {
  Scene scene = make_closed_box(1.0, 3, glm::dvec3(0.6), glm::dvec3(0.0), false);
  for (uint32_t q = 0; q < 9; ++q) scene.patches[q].emission = glm::dvec3(1.0);
  Params params;
  params.pools = true;
  params.max_shots = 2;  // enough to tell
  Solver solver(scene, params);
  EXPECT_EQ(solver.run().passes, 2u);
}

// A floor of small tiles (none large enough for a grid: room for four of the smallest elements
// that may split, each of four times AEPS of the scene's area)
// under a large lamp panel: the only patch a grid could cover is the lamp, which shows its own
// light. No first pass is made, and the bake is the one-pass solve's, element for element.
TEST(Refine, NoFirstPassWhereOnlyEmittersAreLargeEnoughToSplit) {
  Scene scene;
  const int n = 24;
  const double step = 1.0 / n;
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < n; ++k) {
      const double x = i * step, z = k * step;
      add_quad(scene, {x, 0, z}, {x, 0, z + step}, {x + step, 0, z + step}, {x + step, 0, z}, glm::dvec3(0.6),
               glm::dvec3(0.0), 0);
    }
  add_quad(scene, {0.2, 0.5, 0.2}, {0.8, 0.5, 0.2}, {0.8, 0.5, 0.8}, {0.2, 0.5, 0.8}, glm::dvec3(0.5), glm::dvec3(10.0),
           1);
  ASSERT_EQ(validate(scene), "");
  Params params;
  params.pools = true;
  ASSERT_LT(step * step, 16.0 * params.aeps * (1.0 + 0.36));  // the floor and the lamp
  Solver with(scene, params);
  const Stats& st = with.run();
  ASSERT_TRUE(st.converged);
  EXPECT_EQ(st.passes, 1u);
  EXPECT_EQ(st.splits_pools, 0u);
  params.pools = false;
  Solver without(scene, params);
  ASSERT_TRUE(without.run().converged);
  const Mesh a = with.mesh(), b = without.mesh();
  ASSERT_EQ(a.elements.size(), b.elements.size());
  ASSERT_EQ(a.radiosity.size(), b.radiosity.size());
  for (size_t v = 0; v < a.radiosity.size(); ++v) ASSERT_EQ(a.radiosity[v], b.radiosity[v]);
}

// A black ball resting on a floor (one 6 x 6 m patch, rho 0.5) under a 6 x 6 m light 3 m above it:
// the floor around its foot lies in its shadow, down to no light at the foot itself. The truth is
// rho E F(point -> light) with the ball hiding part of the light: a quadrature over the light with
// each of its points tested against the sphere. The ball touches the floor at one corner, so no
// edge marks the spot, and the floor elements meeting there were 1.5 m wide: the floor showed the
// open floor's light up to the foot (a viewer saw no contact shadow: 2 to 70 times the path
// tracer's light within 30 cm of the foot, the ball's underside 13 times, when the ball reflects).
TEST(Refine, BallRestingOnAFloorUnderALargeLightCastsItsContactShadow) {
  Scene scene;
  const double rho = 0.5, e = 1.0, radius = 0.5;
  add_quad(scene, {-3, 0, -3}, {-3, 0, 3}, {3, 0, 3}, {3, 0, -3}, glm::dvec3(rho), glm::dvec3(0.0), 0);
  add_quad(scene, {-3, 3, -3}, {3, 3, -3}, {3, 3, 3}, {-3, 3, 3}, glm::dvec3(0.0), glm::dvec3(e), 1);
  const glm::dvec3 centre(0.0, radius, 0.0);
  add_uv_sphere(scene, centre, radius, 16, 24, glm::dvec3(0.0), glm::dvec3(0.0), 2);
  EXPECT_EQ(validate(scene), "");
  auto exact = [&](double x, double z) {
    const glm::dvec3 p(x, 0.0, z);
    constexpr int kSteps = 240;
    double f = 0.0;
    const double da = (6.0 / kSteps) * (6.0 / kSteps);
    for (int i = 0; i < kSteps; ++i)
      for (int k = 0; k < kSteps; ++k) {
        const glm::dvec3 q(-3.0 + (i + 0.5) * 6.0 / kSteps, 3.0, -3.0 + (k + 0.5) * 6.0 / kSteps);
        const glm::dvec3 d = q - p;
        const double len2 = glm::dot(d, d);
        // The segment p -> q meets the sphere: its nearest point to the centre lies within it.
        const double t = std::clamp(glm::dot(centre - p, d) / len2, 0.0, 1.0);
        if (glm::distance(p + t * d, centre) < radius) continue;
        const double cos = d.y / std::sqrt(len2);  // at the floor and at the light alike (parallel)
        f += cos * cos / (std::numbers::pi * len2) * da;
      }
    return rho * e * f;
  };
  Params params;
  params.threads = 2;
  Solver solver(scene, params);
  EXPECT_TRUE(solver.run().converged);
  const Mesh mesh = solver.mesh();
  const double open = exact(2.0, 0.0);
  for (const double d : {0.3, 0.4, 0.5}) {
    double shown_sum = 0.0, exact_sum = 0.0;
    for (int a = 0; a < 8; ++a) {
      const double phi = 2.0 * std::numbers::pi * (a + 0.5) / 8.0, x = d * std::cos(phi), z = d * std::sin(phi);
      const auto shown = shown_on_floor(mesh, 0, 1, x, z);
      ASSERT_TRUE(shown.has_value());
      shown_sum += shown->x / 8.0;
      exact_sum += exact(x, z) / 8.0;
    }
    std::printf("%.2f m from the foot: shown %.4f, exact %.4f (open floor %.4f)\n", d, shown_sum, exact_sum, open);
    EXPECT_NEAR(shown_sum, exact_sum, 0.2 * open) << d << " m from the foot";
  }
}

}  // namespace
}  // namespace hemibake::solver
