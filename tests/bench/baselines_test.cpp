// The baselines against closed forms: the path-traced reference and hierarchical radiosity.
#include "hemibake/baselines/hierarchical.h"
#include "hemibake/baselines/reference.h"
#include "hemibake/solver/hemicube.h"
#include "hemibake/solver/scenes.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace hemibake::baselines {
namespace {

// In a closed box of uniform emission E and reflectance rho, B = E / (1 - rho) everywhere: the
// reference must find it within its own standard error.
TEST(Reference, ClosedBoxRadiosityWithinItsStandardError) {
  const glm::dvec3 rho(0.5, 0.3, 0.7), e(1.0, 2.0, 0.5);
  const solver::Scene scene = solver::make_closed_box(2.0, 2, rho, e, true);
  const Reference reference(scene);
  const glm::dvec3 expected = e / (glm::dvec3(1.0) - rho);
  for (uint32_t p = 0; p < scene.patches.size(); p += 5) {
    const auto& patch = scene.patches[p];
    const glm::dvec3 x = 0.25 * (patch.corners[0] + patch.corners[1] + patch.corners[2] + patch.corners[3]);
    const ReferencePoint r = reference.radiosity_at(p, x, 4000, 17 + p);
    for (int c = 0; c < 3; ++c) {
      EXPECT_GT(r.std_error[c], 0.0);
      EXPECT_NEAR(r.radiosity[c], expected[c], 4.0 * r.std_error[c] + 1e-9) << "patch " << p << " channel " << c;
    }
  }
}

// Radiosity from one small emitter onto a large parallel floor far below: at the floor's centre,
// B = rho * E * F(point -> emitter), with F for a small square A at height h straight above:
// F = A / (pi h^2) (to first order in A / h^2).
TEST(Reference, DirectLightMatchesThePointFormFactor) {
  solver::Scene scene;
  const glm::dvec3 none(0.0);
  solver::add_quad(scene, {-50, 0, -50}, {-50, 0, 50}, {50, 0, 50}, {50, 0, -50}, glm::dvec3(0.5), none, 0);
  solver::add_quad(scene, {-0.05, 10, -0.05}, {0.05, 10, -0.05}, {0.05, 10, 0.05}, {-0.05, 10, 0.05}, glm::dvec3(0.0),
                   glm::dvec3(100.0), 1);
  const Reference reference(scene);
  const ReferencePoint r = reference.radiosity_at(0, {0, 0, 0}, 4000, 3);
  const double expected = 0.5 * 100.0 * 0.01 / (M_PI * 100.0);
  EXPECT_NEAR(r.radiosity.x, expected, 0.01 * expected);
}

// A ceiling beside a lamp that faces it, 30 cm below: the ceiling sees the lamp at grazing angles,
// down to 10 degrees above its plane, and B = rho * E * F(point -> lamp) with Lambert's exact form
// factor. (The shadow rays aimed from the lifted point at the unlifted lamp met the lamp's own
// plane short of it: 1 m outside the lamp's edge the reference found nothing, 0.5 m outside a
// third too little.)
TEST(Reference, DirectLightAtGrazingAnglesMatchesTheExactFormFactor) {
  solver::Scene scene;
  const glm::dvec3 none(0.0);
  const double y = 2.7;
  solver::add_quad(scene, {-2, 3, -2}, {2, 3, -2}, {2, 3, 2}, {-2, 3, 2}, glm::dvec3(0.7), none, 0);  // facing down
  const std::array<glm::dvec3, 4> lamp = {glm::dvec3(-0.5, y, -0.5), glm::dvec3(-0.5, y, 0.5), glm::dvec3(0.5, y, 0.5),
                                          glm::dvec3(0.5, y, -0.5)};
  solver::add_quad(scene, lamp[0], lamp[1], lamp[2], lamp[3], none, glm::dvec3(5.0), 1);  // facing up
  const Reference reference(scene);
  for (double x : {-1.5, -1.0, -0.75}) {
    const glm::dvec3 point(x, 3.0, 0.0);
    const double expected = 0.7 * 5.0 * solver::point_polygon_form_factor(point, glm::dvec3(0.0, -1.0, 0.0), lamp);
    const ReferencePoint r = reference.radiosity_at(0, point, 20000, 11);
    EXPECT_NEAR(r.radiosity.x, expected, 4.0 * r.std_error.x) << "x = " << x;
  }
}

// Punctual lights over a lone floor (nothing else reflects, so B = rho * E with the irradiance
// E of KHR_lights_punctual's definitions, written out here from the specification): a point light
// at height h gives I h / d^3; a spot light the same times t^2, t = (cos a - cos outer) / (cos
// inner - cos outer) clamped to [0, 1]; a range r the window clamp(1 - (d / r)^4, 0, 1); a
// directional light I cos(theta). A black plate casts a shadow from each.
TEST(Reference, PunctualLightsMatchTheirClosedForms) {
  const glm::dvec3 none(0.0), rho(0.5, 0.4, 0.3), intensity(10.0, 20.0, 5.0);
  const double h = 2.0;
  auto floor_scene = [&] {
    solver::Scene scene;
    solver::add_quad(scene, {-50, 0, -50}, {-50, 0, 50}, {50, 0, 50}, {50, 0, -50}, rho, none, 0);
    // A black plate 1 m up over x in [3, 5], facing down: it hides the light from floor points
    // under it and reflects nothing.
    solver::add_quad(scene, {3, 1, -1}, {5, 1, -1}, {5, 1, 1}, {3, 1, 1}, none, none, 1);
    return scene;
  };
  auto at = [](const solver::Scene& scene, double x, double z) {
    const Reference reference(scene);
    return reference.radiosity_at(0, {x, 0.0, z}, 8, 5).radiosity;
  };
  auto expect = [](const glm::dvec3& got, const glm::dvec3& want, const char* what) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], want[c], 1e-9 + 1e-6 * want[c]) << what << " channel " << c;
  };
  {
    solver::Scene scene = floor_scene();
    solver::Light l;
    l.position = {0, h, 0};
    l.intensity = intensity;
    scene.lights.push_back(l);
    for (double x : {0.0, 1.0, 2.5}) {
      const double d = std::hypot(x, h);
      expect(at(scene, x, 0.0), rho * intensity * (h / (d * d * d)), "point");
    }
    expect(at(scene, 8.0, 0.0), none, "point, shadowed");  // the ray crosses y = 1 at x = 4
    scene.lights[0].range = 3.0;
    const double d = std::hypot(2.0, h);
    expect(at(scene, 2.0, 0.0), rho * intensity * (h / (d * d * d)) * (1.0 - std::pow(d / 3.0, 4.0)), "point with range");
    expect(at(scene, 2.5, 0.0), none, "point, beyond its range");
  }
  {
    solver::Scene scene = floor_scene();
    solver::Light l;
    l.type = solver::Light::Type::kSpot;
    l.position = {0, h, 0};
    l.direction = {0, -1, 0};
    l.inner_cone = 0.3;
    l.outer_cone = 0.6;
    l.intensity = intensity;
    scene.lights.push_back(l);
    for (double x : {0.5, 0.9, 1.2, 1.5}) {
      const double d = std::hypot(x, h), cos_a = h / d;
      const double t = std::clamp((cos_a - std::cos(0.6)) / (std::cos(0.3) - std::cos(0.6)), 0.0, 1.0);
      expect(at(scene, 0.0, x), rho * intensity * (h / (d * d * d)) * (t * t), "spot");
    }
  }
  {
    solver::Scene scene = floor_scene();
    solver::Light l;
    l.type = solver::Light::Type::kDirectional;
    l.direction = glm::normalize(glm::dvec3(-1.0, -std::sqrt(3.0), 0.0));  // 30 degrees from the vertical
    l.intensity = intensity;
    scene.lights.push_back(l);
    expect(at(scene, 0.0, 0.0), rho * intensity * (std::sqrt(3.0) / 2.0), "directional");
    expect(at(scene, 3.2, 0.0), none, "directional, shadowed");  // the plate's shadow moves 1 / sqrt 3 m
  }
}

// The sky of radiance S: an open floor gets B = rho pi S; beside a black wall, rho pi S (1 - F)
// with F the exact form factor from the point to the wall.
TEST(Reference, SkyLightsWhatSeesItWithItsOpenShare) {
  const glm::dvec3 none(0.0), rho(0.6), sky(0.5, 1.0, 2.0);
  solver::Scene scene;
  solver::add_quad(scene, {-50, 0, -50}, {-50, 0, 50}, {50, 0, 50}, {50, 0, -50}, rho, none, 0);
  const std::array<glm::dvec3, 4> wall = {glm::dvec3(1, 0, -2), glm::dvec3(1, 3, -2), glm::dvec3(1, 3, 2), glm::dvec3(1, 0, 2)};
  solver::add_quad(scene, wall[0], wall[1], wall[2], wall[3], none, none, 1);  // facing -x
  scene.sky = sky;
  const Reference reference(scene);
  const ReferencePoint far = reference.radiosity_at(0, {-40, 0, 0}, 64, 3);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(far.radiosity[c], rho[c] * M_PI * sky[c], 1e-9) << "open floor, channel " << c;
  for (double x : {0.0, 0.7}) {
    const glm::dvec3 point(x, 0, 0);
    const double f = solver::point_polygon_form_factor(point, glm::dvec3(0, 1, 0), wall);
    const ReferencePoint r = reference.radiosity_at(0, point, 20000, 7);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(r.radiosity[c], rho[c] * M_PI * sky[c] * (1.0 - f), 4.0 * r.std_error[c]) << "x = " << x << " channel " << c;
  }
}

TEST(Hierarchical, ClosedBoxConvergesToEOverOneMinusRho) {
  const glm::dvec3 rho(0.5, 0.3, 0.7), e(1.0, 2.0, 0.5);
  const solver::Scene scene = solver::make_closed_box(2.0, 2, rho, e, true);
  HierarchicalParams params;
  params.feps = 3e-3;
  HierarchicalStats stats;
  const solver::Mesh mesh = solve_hierarchical(scene, params, stats);
  EXPECT_GT(stats.links, 0u);
  const glm::dvec3 expected = e / (glm::dvec3(1.0) - rho);
  double ba = 0.0, a = 0.0;
  for (const auto& el : mesh.elements) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(el.radiosity[c] / expected[c], 1.0, 0.08);
    ba += (el.radiosity.x + el.radiosity.y + el.radiosity.z) * el.area;
    a += el.area;
  }
  EXPECT_NEAR(ba / a / (expected.x + expected.y + expected.z), 1.0, 0.02);
}

// The links are refined on several threads; the solution must not depend on how many.
TEST(Hierarchical, SameResultOnOneAndThreeThreads) {
  const solver::Scene scene = solver::make_cornell_box();
  HierarchicalParams params;
  params.feps = 0.01;
  HierarchicalStats one_stats, three_stats;
  params.threads = 1;
  const solver::Mesh one = solve_hierarchical(scene, params, one_stats);
  params.threads = 3;
  const solver::Mesh three = solve_hierarchical(scene, params, three_stats);
  EXPECT_EQ(one_stats.links, three_stats.links);
  ASSERT_EQ(one.elements.size(), three.elements.size());
  ASSERT_GT(one.elements.size(), scene.patches.size());  // it did subdivide
  for (size_t i = 0; i < one.elements.size(); ++i) {
    EXPECT_EQ(one.elements[i].patch, three.elements[i].patch);
    EXPECT_EQ(one.elements[i].radiosity, three.elements[i].radiosity) << "element " << i;
  }
  EXPECT_EQ(one.radiosity, three.radiosity);
}

// A cancelled solve stops and says so; progress is reported while linking.
TEST(Hierarchical, CancelStopsLinking) {
  const solver::Scene scene = solver::make_cornell_box();
  solver::CancelToken cancel;
  uint32_t reports = 0;
  HierarchicalParams params;
  params.feps = 1e-5;  // far more linking work than the time the test waits
  params.aeps = 1e-6;
  HierarchicalStats stats;
  const solver::Mesh mesh = solve_hierarchical(
      scene, params, stats,
      [&](const HierarchicalProgress& p) {
        ++reports;
        EXPECT_TRUE(p.linking);
        EXPECT_GE(p.fraction, 0.0);
        EXPECT_LE(p.fraction, 1.0);
        cancel.cancel();
      },
      &cancel);
  EXPECT_TRUE(stats.cancelled);
  EXPECT_TRUE(mesh.elements.empty());
  EXPECT_GE(reports, 1u);
}

}  // namespace
}  // namespace hemibake::baselines
