// Triangle pairs merged back into quads (protocol/src/quads.cpp), against what the geometry says:
// two triangles that share an edge and lie in one plane as a convex quad are one quad, with the
// shared edge as its diagonal; a bent, concave or UV-seamed pair, or a pair on an edge that a third
// triangle shares, is not.
#include "quads.h"

#include <gtest/gtest.h>

#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <vector>

namespace hemibake::protocol {
namespace {

using V = glm::dvec3;
using T = std::array<uint32_t, 3>;

// Twice the signed area of an outline seen from +z: positive when counter-clockwise.
double signed_area_z(const std::vector<V>& p, const Outline& o) {
  double a = 0.0;
  for (uint32_t k = 0; k < o.count; ++k) {
    const V& u = p[o.v[k]];
    const V& w = p[o.v[(k + 1) % o.count]];
    a += u.x * w.y - w.x * u.y;
  }
  return a;
}

TEST(TrianglePairs, SquareSplitAlongADiagonalIsOneQuadWithThatDiagonal) {
  const std::vector<V> p{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  const std::vector<T> t{{0, 1, 2}, {0, 2, 3}};
  const std::vector<Outline> out = merge_triangle_pairs(p, t, {});
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].count, 4u);
  EXPECT_EQ(std::min(out[0].v[1], out[0].v[3]), 0u);
  EXPECT_EQ(std::max(out[0].v[1], out[0].v[3]), 2u);
  std::array<uint32_t, 4> corners = out[0].v;
  std::sort(corners.begin(), corners.end());
  EXPECT_EQ(corners, (std::array<uint32_t, 4>{0, 1, 2, 3}));
  EXPECT_DOUBLE_EQ(signed_area_z(p, out[0]), 2.0);  // the unit square, counter-clockwise
  EXPECT_EQ(out[0].first, 0u);
  EXPECT_EQ(out[0].second, 1u);
}

TEST(TrianglePairs, UnindexedTrianglesPairUpByPosition) {
  const std::vector<V> p{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  const std::vector<T> t{{0, 1, 2}, {3, 4, 5}};
  const std::vector<Outline> out = merge_triangle_pairs(p, t, {});
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].count, 4u);
  EXPECT_DOUBLE_EQ(signed_area_z(p, out[0]), 2.0);
}

TEST(TrianglePairs, BentPairStaysTwoTriangles) {
  const std::vector<V> p{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0.1}};
  const std::vector<T> t{{0, 1, 2}, {0, 2, 3}};
  const std::vector<Outline> out = merge_triangle_pairs(p, t, {});
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].count, 3u);
  EXPECT_EQ(out[1].count, 3u);
}

TEST(TrianglePairs, ConcavePairStaysTwoTriangles) {
  // (0, 0) (1, 1) (3, 1) (0, 2) turns clockwise at (1, 1): an arrowhead.
  const std::vector<V> p{{0, 0, 0}, {1, 1, 0}, {0, 2, 0}, {3, 1, 0}};
  const std::vector<T> t{{0, 1, 2}, {2, 1, 3}};
  const std::vector<Outline> out = merge_triangle_pairs(p, t, {});
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].count, 3u);
  EXPECT_EQ(out[1].count, 3u);
}

TEST(TrianglePairs, UvSeamAlongTheSharedEdgeKeepsTwoTriangles) {
  const std::vector<V> p{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  const std::vector<T> t{{0, 1, 2}, {3, 4, 5}};
  std::vector<glm::dvec2> uv{{0, 0}, {1, 0}, {1, 1}, {0, 0}, {1, 1}, {0, 1}};
  EXPECT_EQ(merge_triangle_pairs(p, t, uv).size(), 1u);  // one UV per position: no seam
  uv[4] = {0.5, 1.0};
  EXPECT_EQ(merge_triangle_pairs(p, t, uv).size(), 2u);
}

TEST(TrianglePairs, EdgeOfThreeTrianglesJoinsNone) {
  // Two coplanar triangles and a fin standing on their shared edge.
  const std::vector<V> p{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5, 0.5, 1}};
  const std::vector<T> t{{0, 1, 2}, {0, 2, 3}, {2, 0, 4}};
  const std::vector<Outline> out = merge_triangle_pairs(p, t, {});
  ASSERT_EQ(out.size(), 3u);
  for (const Outline& o : out) EXPECT_EQ(o.count, 3u);
}

}  // namespace
}  // namespace hemibake::protocol
