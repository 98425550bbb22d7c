// The error as displayed (bench/display_error.h) against closed forms, and bakes of emitters close
// to surfaces measured with it against the path tracer: the bright region above a lamp hung 1 mm
// under a ceiling ends at the lamp's outline, and the room's light stays the reference's.
#include "display_error.h"

#include "../solver/add_box.h"
#include "../solver/stacked_wall.h"

#include "hemibake/protocol/bake.h"
#include "hemibake/protocol/gltf.h"
#include "hemibake/solver/hemicube.h"
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

namespace hemibake::bench {
namespace {

using glm::dvec3;
using solver::Patch;
using solver::Scene;

solver::Mesh solve(const Scene& scene, bool gather = false, bool pools = false) {
  EXPECT_EQ(solver::validate(scene), "");
  solver::Params params;
  params.threads = 2;
  params.gather = gather;
  params.pools = pools;
  solver::Solver s(scene, params);
  s.run();
  EXPECT_TRUE(s.stats().converged);
  return s.mesh();
}

// A closed box with uniform emission and reflectance: B = E / (1 - rho) everywhere, so the
// measure must find no error but the reference's noise.
TEST(DisplayedError, ClosedBoxShowsItsClosedForm) {
  const Scene box = solver::make_closed_box(1.0, 3, dvec3(0.5), dvec3(1.0), true);
  const solver::Mesh mesh = solve(box);
  ReferenceOptions options;
  options.points = 100;
  const auto points = reference_points(box, options);
  ASSERT_EQ(points.size(), 0u);  // every patch emits: no point to measure
  // The same box with one patch dark: its points are measured (the dark one reflects only).
  Scene lit = box;
  lit.patches[0].emission = dvec3(0.0);
  lit.patches[0].material = 1;  // vertex radiosity is averaged within a material, not across emitters
  const auto lit_points = reference_points(lit, options);
  ASSERT_EQ(lit_points.size(), 100u);
  const DisplayError e = displayed_error(lit_points, solve(lit));
  std::printf("closed box, one patch dark: median %.4f p90 %.4f max %.4f, missed %u\n", e.median, e.p90, e.max, e.missed);
  EXPECT_EQ(e.missed, 0u);
  EXPECT_LT(e.median, 0.03);
  EXPECT_NEAR(e.mean_ratio, 1.0, 0.02);
  // Traced again, the points keep their light (a second call once read them at a fraction of it).
  auto again = lit_points;
  trace_reference(lit, again, options);
  EXPECT_NEAR(displayed_error(again, solve(lit)).mean_ratio, 1.0, 0.02);
}

Scene room_with_lamp(double gap, bool double_sided, uint32_t& ceiling);

// A box resting on the floor of a lit room presses its bottom against the floor: no viewer sees
// either there, and the path tracer finds no light at them. A box floating 2 cm over the floor and
// a double-sided plate (two patches, the same corners) press on nothing. Then the rule that leaves
// points out of what is seen, case by case.
TEST(DisplayedError, PointsPressedUnderABoxAreLeftOutOfWhatIsSeen) {
  uint32_t ceiling = 0;
  Scene scene = room_with_lamp(0.1, false, ceiling);
  const uint32_t floor = 0;  // facing up over x, z in [-2, 2]
  const uint32_t resting = static_cast<uint32_t>(scene.patches.size());
  solver::add_box(scene, dvec3(-1.5, 0.0, -1.5), dvec3(-0.5, 0.5, -0.5), dvec3(0.5), dvec3(0.0), 2);
  const uint32_t resting_bottom = resting + 1;  // add_box's second face looks down
  solver::add_box(scene, dvec3(0.5, 0.02, 0.5), dvec3(1.5, 0.5, 1.5), dvec3(0.5), dvec3(0.0), 2);
  const uint32_t plate = static_cast<uint32_t>(scene.patches.size());
  const dvec3 a(0.5, 1.0, -1.5), b(1.5, 1.0, -1.5), c(1.5, 1.0, -0.5), d(0.5, 1.0, -0.5);
  solver::add_quad(scene, a, d, c, b, dvec3(0.5), dvec3(0.0), 3);  // facing up
  solver::add_quad(scene, a, b, c, d, dvec3(0.5), dvec3(0.0), 3);  // its other side
  ASSERT_EQ(solver::validate(scene), "");

  // A 20 x 20 grid over the floor, and points on the resting box's bottom and the plate's top.
  std::vector<SurfacePoint> points;
  auto add = [&](uint32_t patch, const dvec3& x, const dvec3& n) {
    SurfacePoint sp;
    sp.patch = patch;
    sp.position = x;
    sp.normal = n;
    points.push_back(sp);
  };
  for (double x = -1.95; x < 2.0; x += 0.2)
    for (double z = -1.95; z < 2.0; z += 0.2) add(floor, dvec3(x, 0.0, z), dvec3(0.0, 1.0, 0.0));
  for (double x = -1.45; x < -0.5; x += 0.2) add(resting_bottom, dvec3(x, 0.0, -1.0), dvec3(0.0, -1.0, 0.0));
  for (double x = 0.55; x < 1.5; x += 0.2) add(plate, dvec3(x, 1.0, -1.0), dvec3(0.0, 1.0, 0.0));
  mark_pressed(scene, points);
  auto under_resting = [](const dvec3& x) { return x.x > -1.5 && x.x < -0.5 && x.z > -1.5 && x.z < -0.5; };
  uint32_t pressed = 0;
  for (const SurfacePoint& sp : points) {
    const bool expected = sp.patch == resting_bottom || (sp.patch == floor && under_resting(sp.position));
    EXPECT_EQ(sp.pressed, expected) << "patch " << sp.patch << " at " << sp.position.x << ", " << sp.position.z;
    pressed += sp.pressed;
  }
  EXPECT_EQ(pressed, 25u + 5u);  // 5 x 5 grid points under the box, 5 on its bottom

  // The path tracer sees no light at the pressed points, and light wherever no box is over them.
  ReferenceOptions options;
  options.max_samples = 4096;
  trace_reference(scene, points, options);
  auto lit = [](const SurfacePoint& sp) { return sp.reference.x + sp.reference.y + sp.reference.z > 0.0; };
  auto under_floating = [](const dvec3& x) { return x.x > 0.5 && x.x < 1.5 && x.z > 0.5 && x.z < 1.5; };
  for (const SurfacePoint& sp : points) {
    if (sp.pressed) {
      EXPECT_FALSE(lit(sp)) << "patch " << sp.patch << " at " << sp.position.x << ", " << sp.position.z;
    } else if (!under_floating(sp.position)) {
      EXPECT_TRUE(lit(sp)) << "patch " << sp.patch << " at " << sp.position.x << ", " << sp.position.z;
    }
  }

  // What is seen leaves them out; the figures over every point keep them.
  const solver::Mesh mesh = solve(scene);
  const DisplayError e = displayed_error(points, mesh);
  EXPECT_EQ(e.seen.points, points.size() - pressed);
  for (size_t i = 0; i < points.size(); ++i) EXPECT_EQ(e.hidden[i] != 0, points[i].pressed);
  EXPECT_EQ(e.missed, 0u);
  // A bake that covers nothing misses every point: those with no light are no one's to see, the
  // others are the whole of their light wrong.
  const DisplayError none = displayed_error(points, solver::Mesh{});
  EXPECT_EQ(none.missed, points.size());
  EXPECT_EQ(none.seen.points, static_cast<size_t>(std::count_if(points.begin(), points.end(), lit)));
  EXPECT_DOUBLE_EQ(none.seen.median, 1.0);

  // The rule on hand-set references, each case apart: a point is left out only with no light and
  // either pressed or covered by no triangle.
  struct Case {
    dvec3 position;
    bool pressed;
    double light;
    bool hidden;
  };
  const Case cases[] = {
      {dvec3(1.0, 0.0, -1.0), false, 0.0, false},  // on the floor, covered, no light: seen
      {dvec3(1.0, 0.0, -1.0), true, 1.0, false},   // pressed, with light (plates back to back): seen
      {dvec3(1.0, 0.0, -1.0), true, 0.0, true},    // pressed, no light
      {dvec3(0.0, 1.5, 0.0), false, 0.0, true},    // in mid-air: no triangle covers it, no light
      {dvec3(0.0, 1.5, 0.0), false, 1.0, false},   // the same with light: seen, and missed
  };
  std::vector<SurfacePoint> set;
  for (const Case& one : cases) {
    SurfacePoint sp;
    sp.patch = floor;
    sp.position = one.position;
    sp.normal = dvec3(0.0, 1.0, 0.0);
    sp.pressed = one.pressed;
    sp.reference = dvec3(one.light);
    set.push_back(sp);
  }
  const DisplayError by_hand = displayed_error(set, mesh);
  for (size_t i = 0; i < set.size(); ++i) EXPECT_EQ(by_hand.hidden[i] != 0, cases[i].hidden) << "case " << i;
  EXPECT_EQ(by_hand.missed, 2u);
  EXPECT_EQ(by_hand.seen.points, 3u);
}

// A 4 x 3 x 4 room (one-sided walls facing in) with a 1 m lamp under its ceiling, `gap` below it,
// facing down; `double_sided` adds the lamp's upward side (as exporters write a double-sided
// emissive quad), which lights the ceiling above it.
Scene room_with_lamp(double gap, bool double_sided, uint32_t& ceiling) {
  Scene s;
  const dvec3 lo(-2.0, 0.0, -2.0), hi(2.0, 3.0, 2.0), rho(0.7);
  auto quad = [&](dvec3 a, dvec3 b, dvec3 c, dvec3 d, const dvec3& r, const dvec3& e, uint32_t m) {
    solver::add_quad(s, a, b, c, d, r, e, m);
  };
  quad({lo.x, lo.y, lo.z}, {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z}, {hi.x, lo.y, lo.z}, rho, dvec3(0.0), 0);  // floor, up
  ceiling = static_cast<uint32_t>(s.patches.size());
  quad({lo.x, hi.y, lo.z}, {hi.x, hi.y, lo.z}, {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}, rho, dvec3(0.0), 0);  // ceiling, down
  quad({lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {lo.x, hi.y, lo.z}, rho, dvec3(0.0), 0);  // z = lo, +z
  quad({lo.x, lo.y, hi.z}, {lo.x, hi.y, hi.z}, {hi.x, hi.y, hi.z}, {hi.x, lo.y, hi.z}, rho, dvec3(0.0), 0);  // z = hi, -z
  quad({lo.x, lo.y, lo.z}, {lo.x, hi.y, lo.z}, {lo.x, hi.y, hi.z}, {lo.x, lo.y, hi.z}, rho, dvec3(0.0), 0);  // x = lo, +x
  quad({hi.x, lo.y, lo.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z}, {hi.x, hi.y, lo.z}, rho, dvec3(0.0), 0);  // x = hi, -x
  const double y = hi.y - gap;
  const dvec3 a(-0.5, y, -0.5), b(0.5, y, -0.5), c(0.5, y, 0.5), d(-0.5, y, 0.5), e(5.0);
  quad(a, b, c, d, dvec3(0.8), e, 1);  // facing down
  if (double_sided) quad(a, d, c, b, dvec3(0.8), e, 1);
  return s;
}

// Points on the ceiling (patch `ceiling`, facing down) at distances in [d0, d1] outside the lamp's
// outline, seeded.
std::vector<SurfacePoint> ring(uint32_t ceiling, double d0, double d1, uint32_t count) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<SurfacePoint> out;
  while (out.size() < count) {
    const double x = -0.5 - d1 + uni(rng) * (1.0 + 2.0 * d1), z = -0.5 - d1 + uni(rng) * (1.0 + 2.0 * d1);
    const double outside = std::max(std::abs(x), std::abs(z)) - 0.5;
    if (outside < d0 || outside > d1) continue;
    SurfacePoint p;
    p.patch = ceiling;
    p.position = dvec3(x, 3.0, z);
    p.normal = dvec3(0.0, -1.0, 0.0);
    out.push_back(p);
  }
  return out;
}

void expect_lamp_outline_and_room_light(double gap, bool double_sided, bool gather = false) {
  uint32_t ceiling = 0;
  const Scene scene = room_with_lamp(gap, double_sided, ceiling);
  const solver::Mesh mesh = solve(scene, gather);
  ReferenceOptions options;
  options.points = 200;
  const auto points = reference_points(scene, options);
  const DisplayError room = displayed_error(points, mesh);
  auto near = ring(ceiling, 0.01, 0.03, 60);
  trace_reference(scene, near, options);
  const DisplayError edge = displayed_error(near, mesh);
  std::printf("lamp %.4f m under the ceiling, %s%s: room median %.3f p90 %.3f, bake/reference %.3f; "
              "ceiling 1-3 cm outside the lamp: median %.3f, bake/reference %.3f\n",
              gap, double_sided ? "double-sided" : "one-sided", gather ? ", final gather" : "", room.median, room.p90, room.mean_ratio, edge.median,
              edge.mean_ratio);
  EXPECT_NEAR(room.mean_ratio, 1.0, 0.03);
  EXPECT_LT(room.median, 0.05);
  // Next to the outline the ceiling is lit by the room as the path tracer lights it: neither the
  // lamp's upward light nor the darkness above a one-sided lamp spreads past its outline (both made
  // the ceiling 1 to 3 cm outside it 13 to 40 % too dark or up to 40 times too bright).
  EXPECT_NEAR(edge.mean_ratio, 1.0, 0.1);
  EXPECT_LT(edge.median, 0.15);
}

TEST(EmitterNearSurface, DoubleSidedLampOneMillimetreUnderTheCeiling) { expect_lamp_outline_and_room_light(0.001, true); }
TEST(EmitterNearSurface, OneSidedLampOneMillimetreUnderTheCeiling) { expect_lamp_outline_and_room_light(0.001, false); }
// The lamp's top faces the ceiling 10 cm above it: a ceiling piece's centre sees the lamp head-on
// while most of the piece sees past it, so such pieces shoot from their parts (absorber_close).
// Before, the room came out 5.6 % too dark.
TEST(EmitterNearSurface, DoubleSidedLampTenCentimetresUnderTheCeiling) { expect_lamp_outline_and_room_light(0.1, true); }
// With the final gather: every vertex sees the lamp's back or top right in front of the ceiling.
TEST(EmitterNearSurface, OneSidedLampOneMillimetreUnderTheCeilingWithTheGather) {
  expect_lamp_outline_and_room_light(0.001, false, true);
}
TEST(EmitterNearSurface, DoubleSidedLampOneMillimetreUnderTheCeilingWithTheGather) {
  expect_lamp_outline_and_room_light(0.001, true, true);
}

// The mean of the points' reference light (grey: the mean of the channels).
double grey_mean_reference(const std::vector<SurfacePoint>& points) {
  double sum = 0.0;
  for (const SurfacePoint& p : points) sum += (p.reference.x + p.reference.y + p.reference.z) / 3.0;
  return sum / static_cast<double>(points.size());
}

// A 4 x 3 x 4 room with walls, floor and ceiling in `tile` tiles (0.25 m: smaller than the smallest
// split at the settings of the tests below, as in a cluttered room; 4 m: one quad each, as exporters
// write a room), four lamps 1 cm under its ceiling, and a cabinet (a box without a bottom,
// 1.2 x 1.9 x 0.5 m) standing 5 cm in front of the wall at z = 2.
// `count` points on patch `patch` (facing `normal`), uniform over the parallelogram at `corner`
// spanned by `a` and `b`, seeded.
std::vector<SurfacePoint> points_on(uint32_t patch, const dvec3& corner, const dvec3& a, const dvec3& b, const dvec3& normal,
                                    int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<SurfacePoint> out;
  for (int i = 0; i < count; ++i) {
    SurfacePoint p;
    p.patch = patch;
    const double u = uni(rng), v = uni(rng);
    p.position = corner + u * a + v * b;
    p.normal = normal;
    out.push_back(p);
  }
  return out;
}

Scene room_with_cabinet(double tile = 0.25) {
  Scene s;
  auto grid = [&](dvec3 o, dvec3 u, dvec3 v, const dvec3& rho, uint32_t m, double cell) {
    const int nu = static_cast<int>(std::ceil(glm::length(u) / cell - 1e-9)), nv = static_cast<int>(std::ceil(glm::length(v) / cell - 1e-9));
    for (int i = 0; i < nu; ++i)
      for (int j = 0; j < nv; ++j) {
        const dvec3 a = o + u * (double(i) / nu) + v * (double(j) / nv), du = u / double(nu), dv = v / double(nv);
        solver::add_quad(s, a, a + du, a + du + dv, a + dv, rho, dvec3(0.0), m);
      }
  };
  const dvec3 wall(0.7);
  grid({-2, 0, -2}, {0, 0, 4}, {4, 0, 0}, wall, 0, tile);  // floor, up
  grid({-2, 3, -2}, {4, 0, 0}, {0, 0, 4}, wall, 0, tile);  // ceiling, down
  grid({-2, 0, -2}, {4, 0, 0}, {0, 3, 0}, wall, 0, tile);  // z = -2, +z
  grid({-2, 0, 2}, {0, 3, 0}, {4, 0, 0}, wall, 0, tile);   // z = 2, -z
  grid({-2, 0, -2}, {0, 3, 0}, {0, 0, 4}, wall, 0, tile);  // x = -2, +x
  grid({2, 0, -2}, {0, 0, 4}, {0, 3, 0}, wall, 0, tile);   // x = 2, -x
  for (double lx : {-1.0, 1.0})
    for (double lz : {-1.0, 1.0})
      solver::add_quad(s, {lx - 0.3, 2.99, lz - 0.3}, {lx + 0.3, 2.99, lz - 0.3}, {lx + 0.3, 2.99, lz + 0.3},
                       {lx - 0.3, 2.99, lz + 0.3}, dvec3(0.8), dvec3(6.0), 1);
  const dvec3 lo(-0.6, 0.0, 1.45), hi(0.6, 1.9, 1.95), metal(0.55);
  const dvec3 d = hi - lo;
  const double cell = 0.5;
  grid({lo.x, hi.y, lo.z}, {0, 0, d.z}, {d.x, 0, 0}, metal, 2, cell);  // top
  grid(lo, {0, d.y, 0}, {d.x, 0, 0}, metal, 2, cell);                  // front, -z
  grid({lo.x, lo.y, hi.z}, {d.x, 0, 0}, {0, d.y, 0}, metal, 2, cell);  // back, +z: faces the wall 5 cm away
  grid(lo, {0, 0, d.z}, {0, d.y, 0}, metal, 2, cell);                  // -x
  grid({hi.x, lo.y, lo.z}, {0, d.y, 0}, {0, 0, d.z}, metal, 2, cell);  // +x
  return s;
}

// The wall behind the cabinet is lit only through the 5 cm gap, and dark a few centimetres into it.
// The wall's tiles reaching past the cabinet's sides used to show the open wall's light 25 cm and
// more into the gap (hidden vertices take their uncovered neighbours' light, so that nothing dark
// spreads past a lamp's outline): the wall behind a cabinet in a cluttered room read up to 15 times
// the path tracer's light, and the room 3 % too bright.
TEST(CoverNearSurface, WallBehindACabinetFiveCentimetresFromItStaysDark) {
  const Scene scene = room_with_cabinet();
  solver::Params params;
  params.threads = 2;
  params.aeps = 5e-4;  // the 0.25 m tiles are below the smallest split (4 aeps of the scene's area)
  solver::Solver solver(scene, params);
  solver.run();
  ASSERT_TRUE(solver.stats().converged);
  const solver::Mesh mesh = solver.mesh();
  ReferenceOptions options;
  options.points = 200;
  const auto points = reference_points(scene, options);
  const DisplayError room = displayed_error(points, mesh);
  const double mean_reference = grey_mean_reference(points);
  // Points on the wall behind the cabinet, 10 cm or more inside its outline.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<SurfacePoint> behind;
  uint32_t wall_patch = 0;
  for (uint32_t i = 0; i < scene.patches.size(); ++i)
    if (scene.patches[i].corners[0].z == 2.0 && scene.patches[i].corners[1].z == 2.0 && scene.patches[i].corners[2].z == 2.0) wall_patch = i;
  for (int i = 0; i < 60; ++i) {
    SurfacePoint p;
    p.patch = wall_patch;  // any of the wall's tiles: the reference takes its plane and reflectance, which they share
    p.position = dvec3(-0.5 + uni(rng) * 1.0, 0.1 + uni(rng) * 1.6, 2.0);
    p.normal = dvec3(0.0, 0.0, -1.0);
    behind.push_back(p);
  }
  trace_reference(scene, behind, options);
  glm::dvec3 shown(0.0);
  double abs_error = 0.0, reference = 0.0;
  for (const SurfacePoint& p : behind) {
    ASSERT_TRUE(displayed_value(mesh, p.position, p.normal, plane_slack(mesh), shown));
    const double b = (shown.x + shown.y + shown.z) / 3.0, r = (p.reference.x + p.reference.y + p.reference.z) / 3.0;
    abs_error += std::abs(b - r);
    reference += r;
  }
  abs_error /= static_cast<double>(behind.size());
  reference /= static_cast<double>(behind.size());
  std::printf("wall behind a cabinet: reference %.4f, mean error %.4f (room mean %.4f); room median %.3f, "
              "bake/reference %.3f\n",
              reference, abs_error, mean_reference, room.median, room.mean_ratio);
  EXPECT_LT(reference, 0.1 * mean_reference);  // the scene is what it says: the gap is dark
  // 23 % of the room's mean before (0.050), 11 % with the outline split alone, 6 % with both.
  EXPECT_LT(abs_error, 0.08 * mean_reference);
  EXPECT_NEAR(room.mean_ratio, 1.0, 0.03);
}

// The floor at the cabinet's foot: the cabinet has no bottom, so nothing covers the floor under it,
// but its sides stand on the floor's tiles, dark inside their outline and lit outside. A tile across
// the outline showed the dark inside spread outward and the light inside: the floor 0.5 to 3 cm in
// front of the cabinet read its tile's mean.
TEST(CoverNearSurface, FloorAtTheFootOfABottomlessCabinetIsLitToItsOutline) {
  const Scene scene = room_with_cabinet();
  solver::Params params;
  params.threads = 2;
  params.aeps = 5e-4;
  solver::Solver solver(scene, params);
  solver.run();
  ASSERT_TRUE(solver.stats().converged);
  const solver::Mesh mesh = solver.mesh();
  uint32_t floor_patch = 0;
  for (uint32_t i = 0; i < scene.patches.size(); ++i)
    if (scene.patches[i].corners[0].y == 0.0 && scene.patches[i].corners[2].y == 0.0 && scene.patches[i].reflectance.x == 0.7) floor_patch = i;
  // 0.5 to 3 cm in front of the cabinet's front (z = 1.45)
  std::vector<SurfacePoint> front = points_on(floor_patch, dvec3(-0.55, 0.0, 1.42), dvec3(1.1, 0.0, 0.0), dvec3(0.0, 0.0, 0.025),
                                              dvec3(0.0, 1.0, 0.0), 60, 13);
  ReferenceOptions options;
  trace_reference(scene, front, options);
  glm::dvec3 shown(0.0);
  double abs_error = 0.0, reference = 0.0;
  for (const SurfacePoint& p : front) {
    ASSERT_TRUE(displayed_value(mesh, p.position, p.normal, plane_slack(mesh), shown));
    abs_error += std::abs((shown.x + shown.y + shown.z) / 3.0 - (p.reference.x + p.reference.y + p.reference.z) / 3.0);
    reference += (p.reference.x + p.reference.y + p.reference.z) / 3.0;
  }
  std::printf("floor 0.5-3 cm in front of a bottomless cabinet: reference %.4f, mean error %.4f\n", reference / 60.0, abs_error / 60.0);
  EXPECT_LT(abs_error, 0.2 * reference);
}

// Mean absolute error of the displayed light at `points` against the path tracer, and their mean
// reference (grey: the mean of the channels).
std::pair<double, double> error_at(const Scene& scene, const solver::Mesh& mesh, std::vector<SurfacePoint>& points);

// The same room with its walls one quad each, at default settings. The wall's pieces reach from the
// lit room into the 5 cm gap behind the cabinet; a weak shot of such a piece (its mean from the
// room's side) gave the cabinet's back, 5 cm in front of it, that mean, and the back gave it on to
// the wall: the cabinet's back read several times the path tracer's light.
TEST(CoverNearSurface, CabinetBackFiveCentimetresFromAWholeWallStaysDark) {
  const Scene scene = room_with_cabinet(4.0);
  const solver::Mesh mesh = solve(scene);
  uint32_t back = solver::kNone;  // the cabinet's back, at z = 1.95 facing the wall
  for (uint32_t i = 0; i < scene.patches.size(); ++i)
    if (scene.patches[i].corners[0].z == 1.95 && scene.patches[i].corners[2].z == 1.95) back = i;
  ASSERT_NE(back, solver::kNone);
  // 15 cm and more inside the outline
  std::vector<SurfacePoint> points = points_on(back, dvec3(-0.45, 0.1, 1.95), dvec3(0.9, 0.0, 0.0), dvec3(0.0, 1.6, 0.0),
                                               dvec3(0.0, 0.0, 1.0), 40, 17);
  ReferenceOptions options;
  options.points = 200;
  const auto room_points = reference_points(scene, options);
  const double room_mean = grey_mean_reference(room_points);
  const auto [error, reference] = error_at(scene, mesh, points);
  std::printf("cabinet's back 5 cm from a whole wall: reference %.4f, mean error %.4f (room mean %.4f)\n", reference, error, room_mean);
  EXPECT_LT(reference, 0.1 * room_mean);  // the gap is dark
  EXPECT_LT(error, 0.05 * room_mean);
}

std::pair<double, double> error_at(const Scene& scene, const solver::Mesh& mesh, std::vector<SurfacePoint>& points) {
  ReferenceOptions options;
  trace_reference(scene, points, options);
  glm::dvec3 shown(0.0);
  double abs_error = 0.0, reference = 0.0;
  for (const SurfacePoint& p : points) {
    if (!displayed_value(mesh, p.position, p.normal, plane_slack(mesh), shown)) return {1e30, 0.0};
    abs_error += std::abs((shown.x + shown.y + shown.z) / 3.0 - (p.reference.x + p.reference.y + p.reference.z) / 3.0);
    reference += (p.reference.x + p.reference.y + p.reference.z) / 3.0;
  }
  const double n = static_cast<double>(points.size());
  return {abs_error / n, reference / n};
}

void bake_written_and_read_back(const protocol::SceneDocument& document, const protocol::JobSpec& spec,
                                const std::string& name, solver::Mesh& mesh);

// Blender's study (tests/data/blender/study.glb): a bookshelf's back panel stands 2 cm before the
// north wall, the slot between them open at its ends and top. Baked at the defaults and read back
// from the file, the wall in the slot 20 cm and more past its openings shows what the path tracer
// finds there, next to nothing. Two faults lit it: a quarter of the wall whose lit strips lay on
// both sides of the shelf had even halves, so the panel's back took the strips' mean from it and
// gave it on to the wall (uneven_tree); and the elements inside the slot's end took the open wall's
// light at their corners on the shelf's outline, which showed it fading over a whole element
// (split_covered_side): 93 where the path tracer has 0, 24 cm inside the slot.
TEST(CoverNearSurface, WallInTheStudysSlotBehindItsBookshelfStaysDark) {
  const protocol::LoadResult r = protocol::load_gltf_file(HEMIBAKE_SOURCE_DIR "/tests/data/blender/study.glb");
  ASSERT_TRUE(r.document) << r.error;
  const Scene& scene = protocol::scene_of(*r.document);
  // The wall's face towards the room: in the plane z = -4, facing +z, holding the slot.
  uint32_t wall = solver::kNone;
  for (uint32_t i = 0; i < scene.patches.size() && wall == solver::kNone; ++i) {
    const Patch& p = scene.patches[i];
    double lo_x = 1e9, hi_x = -1e9, lo_y = 1e9, hi_y = -1e9;
    bool in_plane = true;
    for (uint32_t k = 0; k < p.corner_count; ++k) {
      in_plane = in_plane && std::abs(p.corners[k].z + 4.0) < 1e-4;
      lo_x = std::min(lo_x, p.corners[k].x), hi_x = std::max(hi_x, p.corners[k].x);
      lo_y = std::min(lo_y, p.corners[k].y), hi_y = std::max(hi_y, p.corners[k].y);
    }
    const dvec3 n = glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]);
    if (in_plane && n.z > 0.0 && lo_x < 0.6 && hi_x > 2.0 && lo_y < 0.1 && hi_y > 1.9) wall = i;
  }
  ASSERT_NE(wall, solver::kNone);
  solver::Mesh baked;
  ASSERT_NO_FATAL_FAILURE(bake_written_and_read_back(*r.document, protocol::JobSpec{}, "study-default.glb", baked));
  // The slot runs over x 0.43 to 2.17, up to 2 m.
  std::vector<SurfacePoint> points = points_on(wall, dvec3(0.65, 0.1, -4.0), dvec3(1.3, 0.0, 0.0), dvec3(0.0, 1.7, 0.0),
                                               dvec3(0.0, 0.0, 1.0), 40, 23);
  ReferenceOptions options;
  options.points = 200;
  const double room_mean = grey_mean_reference(reference_points(scene, options));
  const auto [error, reference] = error_at(scene, baked, points);
  std::printf("study's wall in the slot behind the bookshelf: reference %.3f, mean error %.3f (room mean %.3f)\n", reference,
              error, room_mean);
  EXPECT_LT(reference, 0.01 * room_mean);  // the slot is dark
  EXPECT_LT(error, 0.02 * room_mean);  // 1.2 of 161; before the two fixes, 5.6
}

// A double-sided rug (1.5 x 1 m, as exporters write one: a single quad of a double-sided material)
// 3 mm over the floor of the cabinet's room, its walls one quad each, at default settings: the floor
// under the rug, 5 cm and more inside its outline, is as dark as the path tracer finds it. In a
// hemicube pixel on the rug's edge, seen from across the room, the rug's mean depth (the centre of
// its part of the pixel) often lay behind the floor's (the pixel's centre): the floor took the
// whole pixel, its elements under the rug included (PixelResolver::order_covers): 5.7 % of the
// room's mean light before, 0.9 % after. The rug's outline lies on the lines of the floor's
// elements (12.5 cm), so that no element reaches from under the rug into the open: such an element
// shows its mean over both (outline splits stop at that size here), which is the mesh's error, not
// the hemicube's.
TEST(CoverNearSurface, FloorUnderARugThreeMillimetresOverItStaysDark) {
  Scene scene = room_with_cabinet(4.0);
  const double y = 0.003;
  const dvec3 a(-0.75, y, -1.25), b(-0.75, y, -0.25), c(0.75, y, -0.25), d(0.75, y, -1.25), rug(0.6, 0.3, 0.2);
  solver::add_quad(scene, a, b, c, d, rug, dvec3(0.0), 3);  // facing up
  solver::add_quad(scene, a, d, c, b, rug, dvec3(0.0), 3);  // its back, facing the floor
  const uint32_t floor = 0;  // the first tile of room_with_cabinet
  ASSERT_EQ(scene.patches[floor].corners[0], dvec3(-2.0, 0.0, -2.0));
  solver::Params params;
  params.threads = 2;
  solver::Solver solver(scene, params);
  solver.run();
  ASSERT_TRUE(solver.stats().converged);
  const solver::Mesh mesh = solver.mesh();
  std::vector<SurfacePoint> points = points_on(floor, dvec3(-0.7, 0.0, -1.2), dvec3(1.4, 0.0, 0.0), dvec3(0.0, 0.0, 0.9),
                                               dvec3(0.0, 1.0, 0.0), 60, 29);
  ReferenceOptions options;
  options.points = 200;
  const double room_mean = grey_mean_reference(reference_points(scene, options));
  const auto [error, reference] = error_at(scene, mesh, points);
  std::printf("floor under a rug 3 mm over it: reference %.4f, mean error %.4f (room mean %.4f)\n", reference, error, room_mean);
  EXPECT_LT(reference, 0.01 * room_mean);  // the scene is what it says: the floor under the rug is dark
  EXPECT_LT(error, 0.02 * room_mean);
}

// A wall of stacked boxes (a lower box, a narrower one above it pressed on its top), lit by a lamp
// under the ceiling, alone and with a shelf standing on the boxes' seam: the wall within 10 cm of
// the seam, both boxes' faces, shows the path tracer's light. The faces pressed between the boxes
// stand on no seam a viewer sees, so the wall is one surface there; the shelf's bottom is seen, so
// the wall under it keeps its shadow apart from the light above.
TEST(CoverNearSurface, WallOfStackedBoxesNearTheirSeamShowsThePathTracersLight) {
  for (const bool shelf : {false, true}) {
    const solver::StackedWall w = solver::stacked_wall_room(shelf);
    const solver::Mesh mesh = solve(w.scene);
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    std::vector<SurfacePoint> near_seam;
    for (int i = 0; i < 80; ++i) {
      SurfacePoint p;
      p.position = dvec3(0.0, 0.9 + 0.2 * uni(rng), 0.1 + 2.3 * uni(rng));
      if (shelf && p.position.y > 1.0 && p.position.y < 1.04 + 1e-3 && p.position.z > 0.5 && p.position.z < 2.0) continue;
      p.patch = p.position.y < 1.0 ? w.lower_face : w.upper_face;
      p.normal = dvec3(1.0, 0.0, 0.0);
      near_seam.push_back(p);
    }
    const auto [error, reference] = error_at(w.scene, mesh, near_seam);
    std::printf("%s: wall within 10 cm of the seam: reference %.4f, mean error %.4f\n", shelf ? "shelf" : "no shelf",
                reference, error);
    EXPECT_LT(error, 0.08 * reference) << (shelf ? "with the shelf" : "without the shelf");
  }
}

// A box without a bottom on open ground in the sun, the sun shining on its front. Its sides stand on
// the ground (the ground under the box is dark, in front of it lit), so the ground splits along its
// foot. The sun's parallel view has 20 cm pixels here. In those on the foot the thin ground piece
// in front of the foot lay nearer the sun, by the centres of their covered parts, than the front
// face's lowest centimetres, and took their light: the foot read half the path tracer's light. The
// face standing on the ground now hides the ground wherever both show. The ground in front of the
// foot still takes, in those pixels, what the face leaves times its own coverage (the paper's
// layers), a fifth too dark within 5 cm; before the splits along feet its element reached under
// the box and it read 46 % off.
TEST(CoverNearSurface, SunlitFootOfABottomlessBoxOnOpenGround) {
  Scene scene;
  solver::add_quad(scene, {-10, 0, -10}, {-10, 0, 10}, {10, 0, 10}, {10, 0, -10}, dvec3(0.5), dvec3(0.0), 0);
  const dvec3 lo(-1.0, 0.0, 0.0), hi(1.0, 1.5, 1.0), rho(0.6);
  solver::add_quad(scene, {lo.x, hi.y, lo.z}, {lo.x, hi.y, hi.z}, {hi.x, hi.y, hi.z}, {hi.x, hi.y, lo.z}, rho, dvec3(0.0), 1);  // top
  solver::add_quad(scene, {lo.x, lo.y, lo.z}, {lo.x, hi.y, lo.z}, {hi.x, hi.y, lo.z}, {hi.x, lo.y, lo.z}, rho, dvec3(0.0), 1);  // front, -z
  solver::add_quad(scene, {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}, rho, dvec3(0.0), 1);  // back
  solver::add_quad(scene, {lo.x, lo.y, lo.z}, {lo.x, lo.y, hi.z}, {lo.x, hi.y, hi.z}, {lo.x, hi.y, lo.z}, rho, dvec3(0.0), 1);  // -x
  solver::add_quad(scene, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {hi.x, hi.y, hi.z}, {hi.x, lo.y, hi.z}, rho, dvec3(0.0), 1);  // +x
  solver::Light sun;
  sun.type = solver::Light::Type::kDirectional;
  sun.direction = glm::normalize(dvec3(0.2, -1.0, 1.0));  // from above, in front of the box
  sun.intensity = dvec3(3.0);
  scene.lights.push_back(sun);
  solver::Params params;
  params.threads = 2;
  solver::Solver solver(scene, params);
  solver.run();
  ASSERT_TRUE(solver.stats().converged);
  const solver::Mesh mesh = solver.mesh();
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<SurfacePoint> face, ground;
  for (int i = 0; i < 40; ++i) {
    SurfacePoint p;
    p.patch = 2;
    p.position = dvec3(-0.9 + 1.8 * uni(rng), 0.005 + 0.05 * uni(rng), 0.0);  // the front's lowest 5 cm
    p.normal = dvec3(0.0, 0.0, -1.0);
    face.push_back(p);
    SurfacePoint q;
    q.patch = 0;
    q.position = dvec3(-0.9 + 1.8 * uni(rng), 0.0, -0.005 - 0.05 * uni(rng));  // the ground 0.5 to 5.5 cm in front
    q.normal = dvec3(0.0, 1.0, 0.0);
    ground.push_back(q);
  }
  const auto [face_error, face_reference] = error_at(scene, mesh, face);
  const auto [ground_error, ground_reference] = error_at(scene, mesh, ground);
  std::printf("sunlit front's foot: reference %.4f, mean error %.4f; ground in front: reference %.4f, mean error %.4f\n",
              face_reference, face_error, ground_reference, ground_error);
  EXPECT_LT(face_error, 0.1 * face_reference);
  EXPECT_LT(ground_error, 0.3 * ground_reference);
}

// A lamp standing on a wall's face (touching it along its edge, facing into the room): the wall
// next to it is lit as the path tracer lights it.
TEST(EmitterNearSurface, LampTouchingAWall) {
  uint32_t ceiling = 0;
  Scene scene = room_with_lamp(0.5, false, ceiling);
  // Move the lamp so that one edge lies on the wall x = -2.
  for (auto& p : scene.patches)
    if (p.emission.x > 0.0)
      for (auto& c : p.corners) c.x -= 1.5;
  const solver::Mesh mesh = solve(scene);
  ReferenceOptions options;
  options.points = 200;
  const auto points = reference_points(scene, options);
  const DisplayError room = displayed_error(points, mesh);
  std::printf("lamp touching a wall: median %.3f p90 %.3f, bake/reference %.3f\n", room.median, room.p90,
              room.mean_ratio);
  EXPECT_NEAR(room.mean_ratio, 1.0, 0.03);
  EXPECT_LT(room.median, 0.05);
}

// Bakes `document` as a user gets it (the GLB the service writes), writes it to a file and reads
// the mesh back from that file.
void bake_written_and_read_back(const protocol::SceneDocument& document, const protocol::JobSpec& spec,
                                const std::string& name, solver::Mesh& mesh) {
  const protocol::BakeOutput baked = protocol::bake(document, spec);
  ASSERT_FALSE(baked.glb.empty()) << baked.error;
  const std::string path = ::testing::TempDir() + "/" + name;
  {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    ASSERT_EQ(std::fwrite(baked.glb.data(), 1, baked.glb.size(), f), baked.glb.size());
    std::fclose(f);
  }
  ASSERT_EQ(protocol::read_baked_mesh(path, mesh), "");
  std::remove(path.c_str());
}

// Blender's export of two small glowing spheres over a 12 m floor that is one quad (double-sided
// materials, as Blender writes them; scripts/make_blender_pools.py). Without light pools the floor
// stays nearly one element and shows the wrong light almost everywhere; with them it shows the
// path tracer's pools: as a user gets it, baked at the default settings (light pools on) and
// read back from the GLB written.
TEST(LightPools, BlenderFloorUnderGlowingSpheresShowsThePathTracersPools) {
  const protocol::LoadResult r = protocol::load_gltf_file(HEMIBAKE_SOURCE_DIR "/tests/data/blender/glowing-spheres.glb");
  ASSERT_TRUE(r.document) << r.error;
  const Scene& scene = protocol::scene_of(*r.document);
  ReferenceOptions options;
  options.points = 200;
  const auto points = reference_points(scene, options);
  ASSERT_EQ(points.size(), 200u);
  const DisplayError without = displayed_error(points, solve(scene, false, false));
  solver::Mesh baked;
  ASSERT_NO_FATAL_FAILURE(bake_written_and_read_back(*r.document, protocol::JobSpec{}, "glowing-spheres-default.glb", baked));
  const DisplayError with = displayed_error(points, baked);
  std::printf("glowing spheres: without pools median %.4f p90 %.4f, ratio %.3f; with %.4f %.4f, ratio %.3f\n",
              without.median, without.p90, without.mean_ratio, with.median, with.p90, with.mean_ratio);
  EXPECT_LT(with.missed_light, 1e-3);  // the written file leaves out only the dark insides of closed meshes
  EXPECT_LT(with.median, 0.05);
  EXPECT_LT(with.p90, 0.25);
  EXPECT_NEAR(with.mean_ratio, 1.0, 0.05);
  EXPECT_LT(with.p90, without.p90 / 4.0);
}

// Blender's export of a room lit through a window by a sky plane 30 cm outside it, every material
// double-sided (scripts/make_blender_scenes.py). The plane's centre looks through the window
// straight on, while most of the plane sees the room at a slant past the wall's edges or not at
// all: shot from its centre alone, the room took 9 % too much light (16 % with the plane
// one-sided).
TEST(EmitterNearSurface, SkyPlaneBeforeADoubleSidedWindowWallLightsTheRoomAsThePathTracerDoes) {
  const protocol::LoadResult r = protocol::load_gltf_file(HEMIBAKE_SOURCE_DIR "/tests/data/blender/room-window.glb");
  ASSERT_TRUE(r.document) << r.error;
  const Scene& scene = protocol::scene_of(*r.document);
  ReferenceOptions options;
  options.points = 200;
  const auto points = reference_points(scene, options);
  const DisplayError e = displayed_error(points, solve(scene));
  std::printf("window room, double-sided: median %.4f p90 %.4f, bake/reference %.3f\n", e.median, e.p90, e.mean_ratio);
  EXPECT_EQ(e.missed, 0u);
  EXPECT_NEAR(e.mean_ratio, 1.0, 0.04);
}

// The same room with one-sided walls, its far wall (facing the window, 4.3 m from the plane) cut
// into 0.5 m tiles as a modeller's subdivided wall is. Whole, that wall was close enough to the plane
// to take its light from the plane's parts; as tiles, each was far and took the view of the plane's
// centre, which looks through the window head-on: the wall 54 % too bright and the room 22 %
// (the one-sided wall around the window, 30 cm before the plane, is four patches that were each
// too small a share of the centre's view to count).
TEST(EmitterNearSurface, SkyPlaneBeforeAOneSidedWindowWallLightsATiledFarWallAsThePathTracerDoes) {
  const protocol::LoadResult r = protocol::load_gltf_file(HEMIBAKE_SOURCE_DIR "/tests/data/blender/room-window-single.glb");
  ASSERT_TRUE(r.document) << r.error;
  Scene scene = protocol::scene_of(*r.document);
  constexpr int kAcross = 8, kUp = 6;
  size_t wall = scene.patches.size();
  for (size_t i = 0; i < scene.patches.size(); ++i) {
    const Patch& p = scene.patches[i];
    const dvec3 n = glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]);
    if (p.corner_count == 4 && n.x > 0.0 && std::abs(n.y) + std::abs(n.z) < 1e-6 * n.x && p.corners[0].x < -1.9) wall = i;
  }
  ASSERT_LT(wall, scene.patches.size());
  const Patch whole = scene.patches[wall];
  scene.patches.erase(scene.patches.begin() + static_cast<std::ptrdiff_t>(wall));
  auto at = [&](double u, double v) {
    return (1 - u) * (1 - v) * whole.corners[0] + u * (1 - v) * whole.corners[1] + u * v * whole.corners[2] +
           (1 - u) * v * whole.corners[3];
  };
  for (int i = 0; i < kAcross; ++i)
    for (int j = 0; j < kUp; ++j) {
      Patch tile = whole;
      const double u0 = double(i) / kAcross, u1 = double(i + 1) / kAcross, v0 = double(j) / kUp, v1 = double(j + 1) / kUp;
      tile.corners = {at(u0, v0), at(u1, v0), at(u1, v1), at(u0, v1)};
      scene.patches.push_back(tile);
    }
  ReferenceOptions options;
  options.points = 200;
  const auto points = reference_points(scene, options);
  const DisplayError e = displayed_error(points, solve(scene));
  std::printf("window room, one-sided, far wall tiled: median %.4f p90 %.4f, bake/reference %.3f\n", e.median, e.p90,
              e.mean_ratio);
  EXPECT_EQ(e.missed, 0u);
  EXPECT_NEAR(e.mean_ratio, 1.0, 0.04);
}


// Blender's export of a floor and a crate lit by a point light, a spot, a sun and an emissive lamp
// (scripts/make_blender_lights.py), baked and written as a user gets it (a Draco GLB with
// quantized positions) and read back: the lights' pools and the crate's shadow show the path
// tracer's light. The written file's small elements sit up to 3e-5 of the extent off their
// planes; the measure still finds every point on them.
TEST(PunctualLights, BlenderLightsShowThePathTracersLightInTheWrittenBake) {
  const protocol::LoadResult r = protocol::load_gltf_file(HEMIBAKE_SOURCE_DIR "/tests/data/blender-lights.glb");
  ASSERT_TRUE(r.document) << r.error;
  const Scene& scene = protocol::scene_of(*r.document);
  ASSERT_EQ(scene.lights.size(), 3u);
  protocol::JobSpec spec;
  spec.params.threads = 2;
  solver::Mesh mesh;
  ASSERT_NO_FATAL_FAILURE(bake_written_and_read_back(*r.document, spec, "blender-lights-baked.glb", mesh));
  ReferenceOptions options;
  options.points = 300;
  // The floor's underside (a double-sided material) takes about half of the points, dark in both;
  // they are left out so that the figures speak of the lit surfaces.
  std::vector<SurfacePoint> points;
  for (const SurfacePoint& p : reference_points(scene, options))
    if (p.reference.x + p.reference.y + p.reference.z > 0.0) points.push_back(p);
  ASSERT_GT(points.size(), 80u);
  const DisplayError e = displayed_error(points, mesh);
  std::printf("Blender lights, written bake, %zu lit points: median %.4f p90 %.4f max %.4f, bake/reference %.3f, missed %u\n",
              points.size(), e.median, e.p90, e.max, e.mean_ratio, e.missed);
  EXPECT_LT(e.missed_light, 1e-3);  // the written file leaves out only the dark insides of closed meshes
  EXPECT_LT(e.median, 0.03);
  EXPECT_LT(e.p90, 0.10);
  EXPECT_NEAR(e.mean_ratio, 1.0, 0.03);
}

// The lit yard (data/lit-yard.gltf) with the final gather: the back of its wall sees only the dark
// strip of ground behind the wall and the black sky. Its foot corners gather forty times the
// light of its top (the ground fills half their view), and the yard's 16 000 small elements take
// the gather's whole budget, so no split followed and that light was shown interpolated up the
// whole wall, 53 times the path tracer's. Part of the budget is now kept for the largest
// elements to split, and an element whose gathered corners misstate its light shows the mean.
TEST(GatherBudget, BackOfTheLitYardsWallStaysAsDarkAsThePathTracerSeesIt) {
  const protocol::LoadResult r = protocol::load_gltf_file(HEMIBAKE_SOURCE_DIR "/data/lit-yard.gltf");
  ASSERT_TRUE(r.document) << r.error;
  const Scene& scene = protocol::scene_of(*r.document);
  // The wall's back: the patch facing -z at z = -2.6.
  uint32_t back = UINT32_MAX;
  for (uint32_t i = 0; i < scene.patches.size(); ++i) {
    const solver::Patch& p = scene.patches[i];
    const glm::dvec3 n = glm::normalize(glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]));
    bool on = n.z < -0.99;
    for (uint32_t k = 0; k < p.corner_count; ++k) on = on && std::abs(p.corners[k].z + 2.6) < 1e-4;
    if (on) back = i;
  }
  ASSERT_NE(back, UINT32_MAX);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> ux(-2.45, 2.45), uy(0.02, 1.58);
  std::vector<SurfacePoint> points(60);
  for (SurfacePoint& p : points) {
    p.patch = back;
    p.position = glm::dvec3(ux(rng), uy(rng), -2.6);
    p.normal = glm::dvec3(0.0, 0.0, -1.0);
  }
  ReferenceOptions options;
  options.max_std_error = 0.05;
  trace_reference(scene, points, options);
  protocol::JobSpec spec;
  spec.params.threads = 2;
  spec.params.gather = true;
  solver::Mesh mesh;
  ASSERT_NO_FATAL_FAILURE(bake_written_and_read_back(*r.document, spec, "lit-yard-gathered.glb", mesh));
  const DisplayError e = displayed_error(points, mesh);
  std::printf("back of the lit yard's wall, %zu points: median %.4f p90 %.4f, bake/reference %.3f, worst s.e. %.3f\n",
              points.size(), e.median, e.p90, e.mean_ratio, e.worst_std_error);
  EXPECT_LT(e.missed_light, 1e-3);  // the written file leaves out only the dark insides of closed meshes
  // 53 times the path tracer's light when the vertices took the whole budget, 14 times with half
  // of it kept for splits (the foot's light needs splits down to centimetres). Where an element's
  // gathered corners misstate its light, its vertices now show the elements' mean, as without the
  // gather: 1.7 times (the shots' own error on this dark face, whose light is a small part of the
  // yard's).
  EXPECT_LT(e.mean_ratio, 2.5);
}

// A table of 60 boxes (4 to 18 cm, one seed) 3 m from a glowing wall 3 x 2.5 m that holds all the
// light: the wall shoots from quarters and, for the table within their near field, from their
// quarters, whose hemicubes at their levels' resolutions (50, then 26) see a box as a pixel or
// less. Shadows between the boxes then leaked (a pixel's layers are taken as independent) and a box
// face half behind another stayed one lit element: 0.288 / 6.49 median / p90 against the path
// tracer. Strong pieces now take the resolution that shows each box at least two pixels wide
// (0.155 / 2.73).
Scene boxes_on_a_table() {
  Scene s;
  auto box = [&](double cx, double cz, double sx, double sy, double sz, double base, const dvec3& rho, uint32_t m) {
    const double x0 = cx - sx / 2, x1 = cx + sx / 2, z0 = cz - sz / 2, z1 = cz + sz / 2, y0 = base, y1 = base + sy;
    const dvec3 none(0.0);
    solver::add_quad(s, {x0, y1, z1}, {x1, y1, z1}, {x1, y1, z0}, {x0, y1, z0}, rho, none, m);  // top
    solver::add_quad(s, {x0, y0, z1}, {x0, y1, z1}, {x0, y1, z0}, {x0, y0, z0}, rho, none, m);  // -x
    solver::add_quad(s, {x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1}, rho, none, m);  // +x
    solver::add_quad(s, {x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}, rho, none, m);  // +z
    solver::add_quad(s, {x1, y0, z0}, {x0, y0, z0}, {x0, y1, z0}, {x1, y1, z0}, rho, none, m);  // -z
    solver::add_quad(s, {x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1}, rho, none, m);  // bottom
  };
  const double top = 0.75;
  box(0.0, 0.0, 1.2, 0.03, 0.8, top - 0.03, dvec3(0.7), 0);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> size(0.04, 0.18), unit(0.0, 1.0);
  std::vector<std::array<double, 4>> placed;  // centre x, z and size x, z
  for (int attempt = 0; placed.size() < 60 && attempt < 100000; ++attempt) {
    const double sx = size(rng), sy = size(rng), sz = size(rng);
    const double cx = -0.6 + sx / 2 + unit(rng) * (1.2 - sx), cz = -0.4 + sz / 2 + unit(rng) * (0.8 - sz);
    bool clear = true;
    for (const auto& [px, pz, psx, psz] : placed)
      clear = clear && !(std::abs(cx - px) < (sx + psx) / 2 + 0.005 && std::abs(cz - pz) < (sz + psz) / 2 + 0.005);
    if (!clear) continue;
    placed.push_back({cx, cz, sx, sz});
    box(cx, cz, sx, sy, sz, top, dvec3(0.6, 0.5, 0.4), 1);
  }
  solver::add_quad(s, {-3, 2.5, -1.5}, {-3, 2.5, 1.5}, {-3, 0, 1.5}, {-3, 0, -1.5}, dvec3(0.0), dvec3(1.0), 2);  // wall, +x
  return s;
}

TEST(SmallObjects, BoxesOnATableBeforeAGlowingWallShowThePathTracersShadowsByDefault) {
  const Scene scene = boxes_on_a_table();
  ASSERT_EQ(solver::validate(scene), "");
  ASSERT_EQ(scene.patches.size(), 6u * 61 + 1);  // the table, 60 boxes and the wall
  ReferenceOptions options;
  options.points = 400;
  const auto points = reference_points(scene, options);
  ASSERT_EQ(points.size(), 400u);
  auto bake = [&](bool sharp) {
    solver::Params params;
    params.threads = 2;
    params.pools = true;  // as the default preset
    params.sharp_shadows = sharp;
    solver::Solver solver(scene, params);
    EXPECT_TRUE(solver.run().converged);
    return displayed_error(points, solver.mesh());
  };
  const DisplayError by_default = bake(false), sharp = bake(true);
  std::printf("boxes on a table: by default median %.3f p90 %.3f ratio %.3f; with sharp shadows %.3f %.3f %.3f\n",
              by_default.median, by_default.p90, by_default.mean_ratio, sharp.median, sharp.p90, sharp.mean_ratio);
  // Half the p90 and 0.7 of the median of the levels' resolutions (above).
  EXPECT_LT(by_default.median, 0.2);
  EXPECT_LT(by_default.p90, 3.25);
  // Converged, this scene bakes about 7 % brighter than the path tracer (before every shooter's own
  // light had to converge, 1.012 at the default convergence and 1.067 at 1e-4: the light left
  // unshot had hidden it; bench/README.md).
  EXPECT_NEAR(by_default.mean_ratio, 1.0, 0.09);
  // The option asks the same of every strong piece, whatever it sees: here no less.
  EXPECT_LT(sharp.median, 0.2);
  EXPECT_LT(sharp.p90, 3.25);
}

// A room modelled as builders model walls: six closed boxes 25 cm thick, lit by a panel 1 cm under
// the ceiling. The west and east walls' ends press against the south and north walls' faces, which
// run on past the corners: each corner of the room has a wall's end covering the next wall's face
// from the corner outward. The quadtree cannot cut that face at the corner, and along it an element
// is left that reaches from under the end into the room. Its centre covered, the shots gave it
// little (its covered share of each pixel went to its open neighbours), and the final gather left
// it out: a vertex at the corner saw through it into the wall box's dark inside. The Blender
// study's corners read up to 35 % dark with the gather where the shots alone were within 3 %, and
// `--quality high` was worse than the default there. A gather now sees such an element with its
// open neighbours' light.
TEST(CoverNearSurface, CornersOfAbuttingWallBoxesAreLitWithTheGather) {
  const double w = 4.0, h = 2.5, d = 3.0, t = 0.25;
  const dvec3 rho(0.6), none(0.0);
  Scene scene;
  solver::add_box(scene, {-t, 0, 0}, {0, h, d}, rho, none, 0);          // west: patches 0-5, its face 5
  solver::add_box(scene, {w, 0, 0}, {w + t, h, d}, rho, none, 0);       // east: 6-11, its face 10
  solver::add_box(scene, {-t, 0, -t}, {w + t, h, 0}, rho, none, 0);     // south: 12-17, its face 15
  solver::add_box(scene, {-t, 0, d}, {w + t, h, d + t}, rho, none, 0);  // north: 18-23, its face 20
  solver::add_box(scene, {-t, -t, -t}, {w + t, 0, d + t}, rho, none, 0);
  solver::add_box(scene, {-t, h, -t}, {w + t, h + t, d + t}, rho, none, 0);
  const double y = h - 0.01;
  solver::add_quad(scene, {1.4, y, 0.9}, {2.6, y, 0.9}, {2.6, y, 2.1}, {1.4, y, 2.1}, dvec3(0.8), dvec3(5.0), 1);
  ASSERT_EQ(solver::validate(scene), "");
  // Points 3 mm to 8 cm from each vertical corner of the room, on both walls, seeded.
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> away(0.003, 0.08), up(0.3, 2.2);
  std::vector<SurfacePoint> points;
  for (const double cx : {0.0, w})
    for (const double cz : {0.0, d})
      for (int i = 0; i < 8; ++i) {
        const double a = away(rng), b = away(rng), ya = up(rng), yb = up(rng);
        SurfacePoint on_x;  // on the west or east face
        on_x.patch = cx == 0.0 ? 5 : 10;
        on_x.position = dvec3(cx, ya, cz == 0.0 ? a : d - a);
        on_x.normal = dvec3(cx == 0.0 ? 1.0 : -1.0, 0.0, 0.0);
        SurfacePoint on_z;  // on the south or north face
        on_z.patch = cz == 0.0 ? 15 : 20;
        on_z.position = dvec3(cx == 0.0 ? b : w - b, yb, cz);
        on_z.normal = dvec3(0.0, 0.0, cz == 0.0 ? 1.0 : -1.0);
        points.push_back(on_x);
        points.push_back(on_z);
      }
  for (const SurfacePoint& p : points) {  // each point lies on its patch, facing its way
    const Patch& q = scene.patches[p.patch];
    ASSERT_GT(glm::dot(glm::normalize(glm::cross(q.corners[1] - q.corners[0], q.corners[2] - q.corners[0])), p.normal), 0.999);
    ASSERT_NEAR(glm::dot(p.normal, q.corners[0] - p.position), 0.0, 1e-12);
  }
  const solver::Mesh shot = solve(scene), gathered = solve(scene, true);
  const auto [shot_error, reference] = error_at(scene, shot, points);
  const double gathered_error = error_at(scene, gathered, points).first;
  std::printf("corners of abutting wall boxes: reference %.4f; mean error %.4f shot, %.4f gathered\n", reference, shot_error,
              gathered_error);
  // 0.07 of the reference with the shots alone and with the gather when written, 0.17 with the
  // gather before (the points next to the corner on the south and north faces are still a fifth
  // too dark, the shots' error there, and those 2 to 7 cm from it up to a sixth too bright).
  EXPECT_LT(gathered_error, 0.1 * reference);
  EXPECT_LT(gathered_error, shot_error + 0.01 * reference);  // the gather does no worse than the shots
}

}  // namespace
}  // namespace hemibake::bench



namespace hemibake::bench {
namespace {

// A small lamp 60 cm over the floor of a closed room with black walls, beside a closed room that
// glows 10 000 times as strongly: the dim room's floor shows rho E F(x -> lamp) exactly (Lambert's
// formula; nothing else lights it). The lamp's shot splits the floor by its form factors against
// the light of what it sees (at least its own power), not against the whole scene's power: weighed
// by the bright room's power, the pool stayed coarse (median error 44 %, p90 71 % as displayed;
// 0.4 % and 0.9 % now).
TEST(LocalTolerance, LampPoolInADimRoomBesideABrightOneIsResolved) {
  Scene scene = solver::make_closed_box(2.0, 2, dvec3(0.5), dvec3(1.0), false);  // 24 units of power
  const dvec3 o(4.0, 0.0, 0.0), black(0.0), none(0.0);
  // The dim room, 2 x 1 x 2 m, faces looking in; its floor the only reflector.
  const dvec3 a = o, b = o + dvec3(2, 0, 0), c = o + dvec3(2, 0, 2), d = o + dvec3(0, 0, 2);
  const dvec3 up(0, 1, 0);
  solver::add_quad(scene, a, d, c, b, dvec3(0.5), none, 1);                             // floor
  solver::add_quad(scene, a + up, b + up, c + up, d + up, black, none, 2);             // ceiling
  solver::add_quad(scene, a, b, b + up, a + up, black, none, 2);                       // z = 0
  solver::add_quad(scene, d, d + up, c + up, c, black, none, 2);                       // z = 2
  solver::add_quad(scene, a, a + up, d + up, d, black, none, 2);                       // x = 4
  solver::add_quad(scene, b, c, c + up, b + up, black, none, 2);                       // x = 6
  const double h = 0.6, s = 0.15;
  const std::array<dvec3, 4> lamp{o + dvec3(1 - s, h, 1 - s), o + dvec3(1 + s, h, 1 - s), o + dvec3(1 + s, h, 1 + s),
                                   o + dvec3(1 - s, h, 1 + s)};
  const double e = 24.0 * 1e-4 / (4 * s * s);
  solver::add_quad(scene, lamp[0], lamp[1], lamp[2], lamp[3], black, dvec3(e), 3);  // faces down
  ASSERT_EQ(solver::validate(scene), "");
  const solver::Mesh mesh = solve(scene, false, true);
  const double slack = plane_slack(mesh);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<double> errors;
  while (errors.size() < 300) {
    const dvec3 x = o + dvec3(0.4 + 1.2 * unit(rng), 0.0, 0.4 + 1.2 * unit(rng));  // within 60 cm of the pool's centre
    const double truth = 0.5 * e * solver::point_polygon_form_factor(x, up, lamp);
    dvec3 shown(0.0);
    ASSERT_TRUE(displayed_value(mesh, x, up, slack, shown));
    errors.push_back(std::abs(shown.x - truth) / truth);
  }
  std::sort(errors.begin(), errors.end());
  const double median = errors[errors.size() / 2], p90 = errors[errors.size() * 9 / 10];
  std::printf("dim room's lamp pool as displayed: median %.3f p90 %.3f\n", median, p90);
  EXPECT_LT(median, 0.05);
  EXPECT_LT(p90, 0.15);
}

}  // namespace
}  // namespace hemibake::bench
