// Double-sided surfaces, as exporters write them (a material marked doubleSided becomes two patches
// on the same corners, facing apart): they reflect on both sides and let no light through. Truth
// comes from closed forms and from what the one-sided scene must equal.
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"
#include "solve_scene.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cstdio>
#include <utility>
#include <vector>

namespace hemibake::solver {
namespace {

using glm::dvec3;

// A box's six faces as quads, each split into cells x cells patches; `outward` faces point away
// from the box's centre, the others toward it, and `twins` adds both.
enum class Faces { kOutward, kInward, kBoth };

void add_box(Scene& scene, const dvec3& lo, const dvec3& hi, uint32_t cells, Faces faces, const dvec3& rho,
             const dvec3& emission, uint32_t material, const std::array<bool, 6>& skip = {}) {
  const dvec3 mid = 0.5 * (lo + hi);
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      if (skip[static_cast<size_t>(axis * 2 + side)]) continue;
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (uint32_t i = 0; i < cells; ++i) {
        for (uint32_t j = 0; j < cells; ++j) {
          std::array<dvec3, 4> c;
          for (int k = 0; k < 4; ++k) {
            const double fu = (i + ((k == 1 || k == 2) ? 1.0 : 0.0)) / cells;
            const double fv = (j + (k >= 2 ? 1.0 : 0.0)) / cells;
            dvec3 p;
            p[axis] = side ? hi[axis] : lo[axis];
            p[u] = lo[u] + fu * (hi[u] - lo[u]);
            p[v] = lo[v] + fv * (hi[v] - lo[v]);
            c[static_cast<size_t>(k)] = p;
          }
          const dvec3 n = glm::cross(c[1] - c[0], c[2] - c[0]);
          const bool points_out = glm::dot(n, c[0] - mid) > 0.0;
          auto add = [&](bool out) {
            if (out == points_out) add_quad(scene, c[0], c[1], c[2], c[3], rho, emission, material);
            else add_quad(scene, c[3], c[2], c[1], c[0], rho, emission, material);
          };
          if (faces != Faces::kInward) add(true);
          if (faces != Faces::kOutward) add(false);
        }
      }
    }
  }
}

// A one-sided square light facing down at height y over [x0, x1] x [z0, z1].
void add_ceiling_light(Scene& scene, double y, double x0, double x1, double z0, double z1, const dvec3& emission) {
  add_quad(scene, dvec3(x0, y, z0), dvec3(x1, y, z0), dvec3(x1, y, z1), dvec3(x0, y, z1), dvec3(0.0), emission, 9);
}

struct Sums {
  double area = 0.0, power = 0.0;
  double mean() const { return area > 0.0 ? power / area : 0.0; }
};

// Area-weighted mean red radiosity of the patches [begin, end) whose normal satisfies `pick`.
template <typename Pick>
Sums mean_over(const Scene& scene, const Mesh& mesh, uint32_t begin, uint32_t end, Pick pick) {
  Sums s;
  for (const auto& e : mesh.elements) {
    if (e.patch < begin || e.patch >= end) continue;
    const Patch& p = scene.patches[e.patch];
    if (!pick(glm::normalize(glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0])), p)) continue;
    s.area += e.area;
    s.power += e.area * e.radiosity.x;
  }
  return s;
}

// A closed furnace whose every face is double-sided, every patch emitting E with reflectance rho:
// inside, B = E / (1 - rho) everywhere; outside, the faces see nothing and B = E.
TEST(DoubleSided, FurnaceOfDoubleSidedFacesKeepsItsClosedForm) {
  Scene scene;
  const double e = 1.0, rho = 0.6;
  add_box(scene, dvec3(0.0), dvec3(1.0), 3, Faces::kBoth, dvec3(rho), dvec3(e), 0);
  const Mesh mesh = solve(scene);
  const dvec3 centre(0.5);
  const uint32_t n = static_cast<uint32_t>(scene.patches.size());
  auto inward = [&](const dvec3& nn, const Patch& p) { return glm::dot(nn, centre - p.corners[0]) > 0.0; };
  auto outward = [&](const dvec3& nn, const Patch& p) { return !inward(nn, p); };
  EXPECT_NEAR(mean_over(scene, mesh, 0, n, inward).mean(), e / (1.0 - rho), 0.01 * e / (1.0 - rho));
  EXPECT_NEAR(mean_over(scene, mesh, 0, n, outward).mean(), e, 0.005 * e);
  // Every element, not just the mean.
  for (const auto& el : mesh.elements) {
    const Patch& p = scene.patches[el.patch];
    const dvec3 nn = glm::normalize(glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]));
    const double expected = inward(nn, p) ? e / (1.0 - rho) : e;
    ASSERT_NEAR(el.radiosity.x, expected, 0.03 * expected) << "element of patch " << el.patch;
  }
}

// A closed double-sided box in a lit room: its outside is lit, its inside stays dark (the light
// would reach it only through its walls). Standing on the floor, and floating.
void expect_dark_inside(bool on_floor) {
  Scene scene;
  add_box(scene, dvec3(-2.0, 0.0, -2.0), dvec3(2.0, 3.0, 2.0), 2, Faces::kInward, dvec3(0.6), dvec3(0.0), 0);
  add_ceiling_light(scene, 2.99, -0.5, 0.5, -0.5, 0.5, dvec3(10.0));
  const uint32_t first = static_cast<uint32_t>(scene.patches.size());
  const double y0 = on_floor ? 0.0 : 0.6;
  add_box(scene, dvec3(-0.3, y0, 0.2), dvec3(0.5, y0 + 0.7, 0.9), 1, Faces::kBoth, dvec3(0.6), dvec3(0.0), 1);
  const uint32_t end = static_cast<uint32_t>(scene.patches.size());
  const Mesh mesh = solve(scene);
  const dvec3 centre(0.1, y0 + 0.35, 0.55);
  const Sums in = mean_over(scene, mesh, first, end, [&](const dvec3& n, const Patch& p) { return glm::dot(n, centre - p.corners[0]) > 0.0; });
  const Sums out = mean_over(scene, mesh, first, end, [&](const dvec3& n, const Patch& p) { return glm::dot(n, centre - p.corners[0]) < 0.0; });
  std::printf("box %s: outside %.5f, inside %.6f\n", on_floor ? "on the floor" : "floating", out.mean(), in.mean());
  EXPECT_GT(out.mean(), 0.01);
  EXPECT_LT(in.mean(), 0.02 * out.mean());  // the edge pixels of its outline let a trace through
}

TEST(DoubleSided, ClosedBoxFloatingInALitRoomIsDarkInside) { expect_dark_inside(false); }
TEST(DoubleSided, ClosedBoxStandingOnTheFloorIsDarkInside) { expect_dark_inside(true); }

// Small closed double-sided boxes in a lit room, as a Blender shelf of books or a chair's legs: a
// row of 2 cm thick books packed side by side on the floor, and a grid of 3 cm cubes floating
// apart. Seen from across the room such a box is smaller than a pixel, where the anti-aliased
// hemicube's layers take each face's coverage as independent of the others': the inside's far
// faces took a share of the pixel behind the near outside faces of the same box (the study's
// books 30 to 60 % of their outside's light inside, chair legs 5 %).
TEST(DoubleSided, SmallClosedBoxesAreDarkInside) {
  Scene scene;
  add_box(scene, dvec3(-2.0, 0.0, -2.0), dvec3(2.0, 3.0, 2.0), 2, Faces::kInward, dvec3(0.6), dvec3(0.0), 0);
  add_ceiling_light(scene, 2.99, -0.5, 0.5, -0.5, 0.5, dvec3(10.0));
  const uint32_t first = static_cast<uint32_t>(scene.patches.size());
  std::vector<dvec3> centres;
  // Each box an object of its own, as a glTF node's mesh is.
  auto add_object = [&](const dvec3& lo, const dvec3& hi, uint32_t material) {
    const size_t from = scene.patches.size();
    add_box(scene, lo, hi, 1, Faces::kBoth, dvec3(0.6), dvec3(0.0), material);
    for (size_t k = from; k < scene.patches.size(); ++k) scene.patches[k].object = static_cast<uint32_t>(centres.size() + 1);
    centres.push_back(0.5 * (lo + hi));
  };
  for (int i = 0; i < 12; ++i) {  // books: 2 x 22 x 15 cm, touching
    const dvec3 lo(-1.2 + 0.02 * i, 0.0, -1.8);
    add_object(lo, lo + dvec3(0.02, 0.22, 0.15), 1);
  }
  for (int i = 0; i < 5; ++i)  // cubes: 3 cm, 30 cm apart, 1 m up
    for (int j = 0; j < 5; ++j) {
      const dvec3 lo(0.3 * i - 0.6, 1.0, 0.3 * j - 0.6);
      add_object(lo, lo + dvec3(0.03), 2);
    }
  const Mesh mesh = solve(scene);
  // Each box's six outside and six inside faces, in the order added.
  Sums in, out;
  for (size_t b = 0; b < centres.size(); ++b) {
    const uint32_t begin = first + static_cast<uint32_t>(12 * b), end = begin + 12;
    const dvec3 c = centres[b];
    const Sums i = mean_over(scene, mesh, begin, end, [&](const dvec3& n, const Patch& p) { return glm::dot(n, c - p.corners[0]) > 0.0; });
    const Sums o = mean_over(scene, mesh, begin, end, [&](const dvec3& n, const Patch& p) { return glm::dot(n, c - p.corners[0]) < 0.0; });
    in.area += i.area;
    in.power += i.power;
    out.area += o.area;
    out.power += o.power;
  }
  std::printf("small boxes: outside %.5f, inside %.6f\n", out.mean(), in.mean());
  EXPECT_GT(out.mean(), 0.01);
  EXPECT_LT(in.mean(), 0.01 * out.mean());
}

// Two rooms side by side, 2 m high and deep, the left one x 0..left_end, the right one
// right_start..4 (inward faces); each lacks the wall toward the other, which the caller builds
// between them. Returns the right room's patches, [first, second).
std::pair<uint32_t, uint32_t> add_two_rooms(Scene& scene, double left_end, double right_start) {
  add_box(scene, dvec3(0.0), dvec3(left_end, 2.0, 2.0), 2, Faces::kInward, dvec3(0.7), dvec3(0.0), 0,
          {false, true, false, false, false, false});
  const uint32_t right_begin = static_cast<uint32_t>(scene.patches.size());
  add_box(scene, dvec3(right_start, 0.0, 0.0), dvec3(4.0, 2.0, 2.0), 2, Faces::kInward, dvec3(0.7), dvec3(0.0), 0,
          {true, false, false, false, false, false});
  return {right_begin, static_cast<uint32_t>(scene.patches.size())};
}

// Two rooms side by side, their common wall one double-sided quad (its twins face either room),
// the light in the left one: the right room gets no light through the wall.
TEST(DoubleSided, WallBetweenALitAndADarkRoomLetsNoLightThrough) {
  Scene scene;
  const auto [right_begin, right_end] = add_two_rooms(scene, 2.0, 2.0);
  // The common wall x = 2, double-sided.
  add_box(scene, dvec3(2.0, 0.0, 0.0), dvec3(2.0, 2.0, 2.0), 2, Faces::kBoth, dvec3(0.7), dvec3(0.0), 0,
          {false, true, true, true, true, true});
  const uint32_t wall_end = static_cast<uint32_t>(scene.patches.size());
  add_ceiling_light(scene, 1.99, 0.7, 1.3, 0.7, 1.3, dvec3(10.0));
  const Mesh mesh = solve(scene);
  auto any = [](const dvec3&, const Patch&) { return true; };
  const Sums left = mean_over(scene, mesh, 0, right_begin, any);
  const Sums right = mean_over(scene, mesh, right_begin, right_end, any);
  const Sums wall_right = mean_over(scene, mesh, right_end, wall_end, [](const dvec3& n, const Patch&) { return n.x > 0.0; });
  std::printf("left room %.5f, right room %.7f, the wall's right side %.7f\n", left.mean(), right.mean(), wall_right.mean());
  EXPECT_GT(left.mean(), 0.05);
  EXPECT_LT(right.mean(), 1e-4 * left.mean());
  EXPECT_LT(wall_right.mean(), 1e-4 * left.mean());
}

// The same two rooms, their common wall 20 cm thick and built of two closed double-sided boxes
// stacked one on the other, as a modeller lays a wall out of blocks: along the seam where they meet,
// a pixel holds part of each box's face, and the layers' rule (each coverage independent of the
// other's) lets a share of it through. What passes is a trace along a line (1e-5 of the left
// room's light where patches' hemicubes leave the boxes' insides out; none where they project
// them and the insides hide the seam a second time); the right room stays dark against the left.
TEST(DoubleSided, WallOfTwoBoxesBetweenALitAndADarkRoomLetsAlmostNoLightThrough) {
  Scene scene;
  const auto [right_begin, right_end] = add_two_rooms(scene, 1.9, 2.1);
  for (uint32_t k = 0; k < right_end; ++k) scene.patches[k].object = 1;
  // The wall: two boxes of 1 m, one over the other (their seam at y = 1), each an object.
  for (uint32_t b = 0; b < 2; ++b) {
    const size_t from = scene.patches.size();
    add_box(scene, dvec3(1.9, b, 0.0), dvec3(2.1, b + 1.0, 2.0), 1, Faces::kBoth, dvec3(0.7), dvec3(0.0), 0);
    for (size_t k = from; k < scene.patches.size(); ++k) scene.patches[k].object = 2 + b;
  }
  add_ceiling_light(scene, 1.99, 0.6, 1.2, 0.7, 1.3, dvec3(10.0));
  scene.patches.back().object = 4;
  const Mesh mesh = solve(scene);
  auto any = [](const dvec3&, const Patch&) { return true; };
  const Sums left = mean_over(scene, mesh, 0, right_begin, any);
  const Sums right = mean_over(scene, mesh, right_begin, right_end, any);
  std::printf("left room %.5f, right room %.7f (%.2e of the left)\n", left.mean(), right.mean(), right.mean() / left.mean());
  EXPECT_GT(left.mean(), 0.05);
  EXPECT_LT(right.mean(), 1e-4 * left.mean());
}

// A double-sided plate floating under a light, over a floor, in a room whose other walls are black:
// its top is lit as a one-sided plate's top is, and its bottom as a one-sided plate's bottom (only
// by what the floor sends up, in the plate's shadow). A double-sided plate is those two, so each
// side must match the scene that has only that side.
TEST(DoubleSided, FloatingPlateIsLitOnTopAndOnlyByTheFloorBelow) {
  enum Sides { kTop = 1, kBottom = 2 };
  auto build = [](int sides, uint32_t& plate_begin) {
    Scene scene;
    add_box(scene, dvec3(-2.0, 0.0, -2.0), dvec3(2.0, 3.0, 2.0), 2, Faces::kInward, dvec3(0.0), dvec3(0.0), 0);
    for (auto& p : scene.patches) {
      const dvec3 n = glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]);
      if (n.y > 0.0) p.reflectance = dvec3(0.5);  // the floor reflects
    }
    add_ceiling_light(scene, 2.99, -0.5, 0.5, -0.5, 0.5, dvec3(10.0));
    plate_begin = static_cast<uint32_t>(scene.patches.size());
    const dvec3 a(-0.6, 1.0, -0.6), b(0.6, 1.0, -0.6), c(0.6, 1.0, 0.6), d(-0.6, 1.0, 0.6);
    if (sides & kTop) add_quad(scene, a, d, c, b, dvec3(0.5), dvec3(0.0), 1);
    if (sides & kBottom) add_quad(scene, a, b, c, d, dvec3(0.5), dvec3(0.0), 1);
    return scene;
  };
  auto side_mean = [&](int sides, bool top) {
    uint32_t begin = 0;
    const Scene scene = build(sides, begin);
    const Mesh mesh = solve(scene);
    return mean_over(scene, mesh, begin, static_cast<uint32_t>(scene.patches.size()),
                     [&](const dvec3& n, const Patch&) { return top ? n.y > 0.5 : n.y < -0.5; })
        .mean();
  };
  const double top2 = side_mean(kTop | kBottom, true), bottom2 = side_mean(kTop | kBottom, false);
  const double top1 = side_mean(kTop, true), bottom1 = side_mean(kBottom, false);
  std::printf("double-sided plate: top %.5f bottom %.5f; one side alone: top %.5f bottom %.5f\n", top2, bottom2,
              top1, bottom1);
  EXPECT_GT(top2, 0.1);
  EXPECT_NEAR(top2, top1, 0.03 * top1);
  EXPECT_NEAR(bottom2, bottom1, 0.03 * bottom1 + 0.003 * top1);
  EXPECT_LT(bottom2, 0.2 * top2);  // only what the floor sends up
}

// A room under a lit attic, as Blender's attic export has them: the room a closed box of inward
// faces, the attic another on top of it, its floor the twin of the room's ceiling. Each wall of the
// room and the attic wall above it lie in one plane, of one material, and share their whole edge,
// on which the ceiling and the attic's floor stand. The room is closed and holds no light, so it is
// dark, and a viewer must show it dark up to that edge: the vertices there once averaged the attic
// wall's light with the room wall's (the attic's gables read 0.91 of the path tracer's light over
// their lowest 15 cm, and the room's walls were lit along their top).
TEST(DoubleSided, RoomUnderALitAtticIsShownDarkUpToTheWallThatContinuesAbove) {
  Scene scene;
  add_box(scene, dvec3(0.0), dvec3(2.0, 1.0, 2.0), 1, Faces::kInward, dvec3(0.7), dvec3(0.0), 0);
  const uint32_t room_end = static_cast<uint32_t>(scene.patches.size());
  add_box(scene, dvec3(0.0, 1.0, 0.0), dvec3(2.0, 2.0, 2.0), 1, Faces::kInward, dvec3(0.7), dvec3(0.0), 0);
  const uint32_t attic_end = static_cast<uint32_t>(scene.patches.size());
  add_ceiling_light(scene, 1.99, 0.7, 1.3, 0.7, 1.3, dvec3(10.0));
  const Mesh mesh = solve(scene);
  auto any = [](const dvec3&, const Patch&) { return true; };
  const double attic = mean_over(scene, mesh, room_end, attic_end, any).mean();
  double room_vertex = 0.0;  // the brightest vertex of the room's elements
  for (const auto& e : mesh.elements)
    if (e.patch < room_end)
      for (uint32_t k = 0; k < e.corner_count; ++k) room_vertex = std::max(room_vertex, mesh.radiosity[e.corners[k]].x);
  std::printf("attic %.5f, the room's brightest vertex %.7f\n", attic, room_vertex);
  EXPECT_GT(attic, 0.05);
  EXPECT_LT(room_vertex, 1e-4 * attic);
}

}  // namespace
}  // namespace hemibake::solver
