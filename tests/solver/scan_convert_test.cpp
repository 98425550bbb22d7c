// Solid-area scan conversion (the paper's Figure 4) against areas computed independently here:
// every pixel's value is compared with the exact area (and, for scan_convert_moments, the first
// moments) of polygon ∩ pixel square, obtained by Sutherland-Hodgman clipping of convex pieces (the
// polygon itself when convex; the fan triangles of a star-shaped polygon from a point of its kernel
// otherwise) and the shoelace formula and its moment analogue.
//
// Random inputs use a fresh seed each run, printed on failure; HEMIBAKE_TEST_SEED=N repeats a run.
#include "test_seed.h"

#include "hemibake/solver/scan_convert.h"

#include <gtest/gtest.h>

#include <glm/common.hpp>
#include <glm/vec2.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace hemibake::solver {
namespace {

using Poly = std::vector<glm::dvec2>;

using test::seed_note;
using test::test_seed;

// Twice the signed area, by the shoelace formula (positive counter-clockwise).
double shoelace2(const Poly& p) {
  double s = 0.0;
  for (size_t i = 0; i < p.size(); ++i) {
    const glm::dvec2& a = p[i];
    const glm::dvec2& b = p[(i + 1) % p.size()];
    s += a.x * b.y - b.x * a.y;
  }
  return s;
}

// Sutherland-Hodgman: the part of a convex polygon inside the axis-aligned box [lo, hi].
Poly clip_to_box(Poly poly, glm::dvec2 lo, glm::dvec2 hi) {
  // Each half-plane as (axis, bound, keep-side sign): keep sign * (p[axis] - bound) >= 0.
  const struct {
    int axis;
    double bound;
    double sign;
  } planes[4] = {{0, lo.x, 1.0}, {0, hi.x, -1.0}, {1, lo.y, 1.0}, {1, hi.y, -1.0}};
  for (const auto& pl : planes) {
    Poly out;
    const size_t n = poly.size();
    for (size_t i = 0; i < n; ++i) {
      const glm::dvec2 a = poly[(i + n - 1) % n];
      const glm::dvec2 b = poly[i];
      const double da = pl.sign * (a[pl.axis] - pl.bound);
      const double db = pl.sign * (b[pl.axis] - pl.bound);
      if ((da >= 0.0) != (db >= 0.0)) {
        glm::dvec2 x = a + (b - a) * (da / (da - db));
        x[pl.axis] = pl.bound;  // exactly on the clip line
        out.push_back(x);
      }
      if (db >= 0.0) out.push_back(b);
    }
    poly = std::move(out);
    if (poly.empty()) break;
  }
  return poly;
}

// Area and first moments (integrals of x dA and y dA, about `origin`) of a simple polygon.
struct Coverage {
  double area = 0.0, mx = 0.0, my = 0.0;
};

Coverage coverage_of(const Poly& p, glm::dvec2 origin) {
  double a2 = 0.0, cx = 0.0, cy = 0.0;
  for (size_t i = 0; i < p.size(); ++i) {
    const glm::dvec2 a = p[i] - origin, b = p[(i + 1) % p.size()] - origin;
    const double cross = a.x * b.y - b.x * a.y;
    a2 += cross;
    cx += (a.x + b.x) * cross;
    cy += (a.y + b.y) * cross;
  }
  const double sign = a2 < 0.0 ? -1.0 : 1.0;  // either orientation
  return {0.5 * sign * a2, sign * cx / 6.0, sign * cy / 6.0};
}

// The exact area and moments (about the pixel's lower-left corner `lo`) of (union of convex
// pieces) ∩ pixel square, for pieces that do not overlap.
Coverage covered(const std::vector<Poly>& convex_pieces, glm::dvec2 lo) {
  Coverage sum;
  for (const Poly& piece : convex_pieces) {
    const Poly clipped = clip_to_box(piece, lo, lo + glm::dvec2(1.0));
    if (clipped.size() < 3) continue;
    const Coverage c = coverage_of(clipped, lo);
    sum.area += c.area;
    sum.mx += c.mx;
    sum.my += c.my;
  }
  return sum;
}

// A star-shaped polygon as the fan of triangles from a point `c` of its kernel.
std::vector<Poly> fan(const Poly& p, glm::dvec2 c) {
  std::vector<Poly> tris;
  for (size_t i = 0; i < p.size(); ++i) tris.push_back({c, p[i], p[(i + 1) % p.size()]});
  return tris;
}

// Convex hull (Andrew's monotone chain), counter-clockwise, without collinear points.
Poly convex_hull(Poly pts) {
  std::sort(pts.begin(), pts.end(),
            [](glm::dvec2 a, glm::dvec2 b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
  pts.erase(std::unique(pts.begin(), pts.end()), pts.end());
  if (pts.size() < 3) return pts;
  auto cross = [](glm::dvec2 o, glm::dvec2 a, glm::dvec2 b) {
    return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
  };
  Poly h(2 * pts.size());
  size_t k = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], pts[i]) <= 0.0) --k;
    h[k++] = pts[i];
  }
  for (size_t i = pts.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(h[k - 2], h[k - 1], pts[i]) <= 0.0) --k;
    h[k++] = pts[i];
  }
  h.resize(k - 1);
  return h;
}

struct Result {
  std::vector<double> area, mx, my;
  double sum = 0.0;
};

Result scan(const Poly& poly, const PixelWindow& win) {
  Result r;
  r.area.assign(static_cast<size_t>(win.width) * win.height, -1.0);  // must all be overwritten
  ScanScratch scratch;
  scan_convert_area(poly, win, r.area, scratch);
  for (double a : r.area) r.sum += a;
  return r;
}

// Moments are only promised for pixels that an edge crosses; the others may keep what they held.
constexpr double kUntouched = -7.0;

Result scan_moments(const Poly& poly, const PixelWindow& win) {
  Result r;
  const size_t cells = static_cast<size_t>(win.width) * win.height;
  r.area.assign(cells, -1.0);
  r.mx.assign(cells, kUntouched);
  r.my.assign(cells, kUntouched);
  ScanScratch scratch;
  scan_convert_moments(poly, win, r.area, r.mx, r.my, scratch);
  for (double a : r.area) r.sum += a;
  return r;
}

struct Errors {
  double area = 0.0, moment = 0.0;
};

// Compares every pixel of the window with the independent area (scan_convert_area) and with the
// independent area and moments (scan_convert_moments); returns the largest errors. Moments must be
// exact in every partly covered pixel (an edge crosses it); in a pixel covered wholly or not at
// all they may be left untouched, and must be exact if written.
Errors max_pixel_errors(const Poly& poly, const std::vector<Poly>& convex_pieces,
                        const PixelWindow& win) {
  const Result r = scan(poly, win);
  const Result m = scan_moments(poly, win);
  Errors worst;
  for (int row = 0; row < win.height; ++row) {
    for (int col = 0; col < win.width; ++col) {
      const Coverage expected = covered(convex_pieces, glm::dvec2(win.x0 + col, win.y0 + row));
      const size_t cell = static_cast<size_t>(row) * win.width + col;
      worst.area = std::max({worst.area, std::abs(r.area[cell] - expected.area),
                             std::abs(m.area[cell] - expected.area)});
      const bool partial = expected.area > 1e-9 && expected.area < 1.0 - 1e-9;
      const bool untouched = m.mx[cell] == kUntouched && m.my[cell] == kUntouched;
      if (partial || !untouched) {
        worst.moment = std::max({worst.moment, std::abs(m.mx[cell] - expected.mx),
                                 std::abs(m.my[cell] - expected.my)});
      }
    }
  }
  return worst;
}

double max_pixel_error(const Poly& poly, const std::vector<Poly>& convex_pieces,
                       const PixelWindow& win) {
  const Errors e = max_pixel_errors(poly, convex_pieces, win);
  return std::max(e.area, e.moment);
}

Poly reversed(Poly p) {
  std::reverse(p.begin(), p.end());
  return p;
}

std::string describe(const Poly& p, const PixelWindow& w) {
  std::string s = "window x0=" + std::to_string(w.x0) + " y0=" + std::to_string(w.y0) +
                  " w=" + std::to_string(w.width) + " h=" + std::to_string(w.height) + " polygon:";
  char buf[64];
  for (const glm::dvec2& v : p) {
    std::snprintf(buf, sizeof buf, " (%.17g, %.17g)", v.x, v.y);
    s += buf;
  }
  return s;
}

// Pixel areas (and moments, which are at most 1 about the pixel's corner) are sums of a few
// products of coordinates of magnitude < 100 relative to pixels: rounding is ~1e-13.
constexpr double kAreaTolerance = 1e-9;

struct RandomCase {
  PixelWindow win;
  glm::dvec2 lo, hi;  // a box inside the window for the polygon
};

RandomCase random_case(std::mt19937_64& rng, int max_size = 12) {
  std::uniform_int_distribution<int> origin(-60, 60), size(1, max_size);
  RandomCase c;
  c.win = {origin(rng), origin(rng), size(rng), size(rng)};
  // A sub-box of the window, sometimes the whole window (polygon touching the window's border).
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const glm::dvec2 w0(c.win.x0, c.win.y0), ext(c.win.width, c.win.height);
  if (u(rng) < 0.2) {
    c.lo = w0;
    c.hi = w0 + ext;
  } else {
    glm::dvec2 a(u(rng), u(rng)), b(u(rng), u(rng));
    c.lo = w0 + ext * glm::min(a, b);
    c.hi = w0 + ext * glm::max(a, b);
  }
  return c;
}

// A random convex polygon (3 to 12 points' hull) in the case's box; a third snap to a
// quarter-pixel grid (vertices on pixel corners and borders, edges along borders), odd trials run
// clockwise. Empty when the hull is degenerate.
Poly random_convex(std::mt19937_64& rng, const RandomCase& c, int trial) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::uniform_int_distribution<int> count(3, 12);
  Poly pts;
  const int n = count(rng);
  for (int i = 0; i < n; ++i) pts.push_back(c.lo + (c.hi - c.lo) * glm::dvec2(u(rng), u(rng)));
  if (trial % 3 == 0) {
    for (glm::dvec2& p : pts) p = glm::round(p * 4.0) / 4.0;
  }
  Poly hull = convex_hull(pts);
  if (hull.size() < 3 || std::abs(shoelace2(hull)) < 1e-6) return {};
  if (trial % 2 == 1) hull = reversed(hull);
  return hull;
}

// A random star polygon (`min_n` to 24 vertices, min_n >= 4, at increasing angles around a kernel
// point, random radii) scaled into the case's box, and its kernel point; odd trials run clockwise.
// Empty when the box is too thin.
std::pair<Poly, glm::dvec2> random_star(std::mt19937_64& rng, const RandomCase& c, int trial, int min_n = 5) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::uniform_int_distribution<int> count(min_n, 24);
  // Consecutive angles differ by less than 1.9 / n turns, under pi from 4 vertices on, so the origin
  // is in the kernel and the fan from it tiles the polygon.
  const int n = count(rng);
  Poly star;
  for (int i = 0; i < n; ++i) {
    const double angle = 2.0 * std::numbers::pi * (i + 0.9 * u(rng)) / n;
    const double radius = 0.05 + 0.95 * u(rng);
    star.push_back(radius * glm::dvec2(std::cos(angle), std::sin(angle)));
  }
  // An axis-aligned scale and shift into the box: lines stay lines, the kernel point moves along,
  // so the fan still tiles the polygon.
  glm::dvec2 bmin(1e300), bmax(-1e300);
  for (const glm::dvec2& p : star) {
    bmin = glm::min(bmin, p);
    bmax = glm::max(bmax, p);
  }
  const glm::dvec2 scale = (c.hi - c.lo) / (bmax - bmin);
  if (std::min(scale.x, scale.y) < 1e-3) return {};
  for (glm::dvec2& p : star) p = c.lo + (p - bmin) * scale;
  const glm::dvec2 kernel = c.lo - bmin * scale;
  if (trial % 2 == 1) star = reversed(star);
  return {star, kernel};
}

// Areas and moments of every pixel, and the area sum, against the exact ones.
void expect_exact(const Poly& poly, const std::vector<Poly>& convex_pieces, const PixelWindow& win) {
  SCOPED_TRACE(describe(poly, win));
  const Errors e = max_pixel_errors(poly, convex_pieces, win);
  EXPECT_LE(e.area, kAreaTolerance);
  EXPECT_LE(e.moment, kAreaTolerance);
  EXPECT_NEAR(scan(poly, win).sum, 0.5 * std::abs(shoelace2(poly)), kAreaTolerance);
}

TEST(ScanConvert, PixelAreasAndMomentsEqualThoseOfRandomConvexPolygonsClippedToEachPixel) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  int tested = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const RandomCase c = random_case(rng);
    const Poly hull = random_convex(rng, c, trial);
    if (hull.empty()) continue;
    ++tested;
    expect_exact(hull, {hull}, c.win);
    if (HasFailure()) return;
  }
  EXPECT_GT(tested, 2000);
}

TEST(ScanConvert, PixelAreasAndMomentsEqualThoseOfRandomNonConvexStarPolygonsClippedToEachPixel) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  for (int trial = 0; trial < 3000; ++trial) {
    const RandomCase c = random_case(rng);
    const auto [star, kernel] = random_star(rng, c, trial);
    if (star.empty()) continue;
    expect_exact(star, fan(star, kernel), c.win);
    if (HasFailure()) return;
  }
}

// Windows of up to 2 x 2 pixels are cut at the pixel borders rather than walked edge by edge (and
// polygons of more than 16 corners are walked even there): both ways against the exact areas.
TEST(ScanConvert, WindowsOfUpToTwoByTwoPixelsGiveExactAreasAndMoments) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  int tested = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    const RandomCase c = random_case(rng, 2);
    if (trial % 2 == 0) {
      const Poly hull = random_convex(rng, c, trial / 2);
      if (hull.empty()) continue;
      expect_exact(hull, {hull}, c.win);
    } else {
      const auto [star, kernel] = random_star(rng, c, trial / 2, 4);
      if (star.empty()) continue;
      expect_exact(star, fan(star, kernel), c.win);
    }
    ++tested;
    if (HasFailure()) return;
  }
  EXPECT_GT(tested, 3000);
}

TEST(ScanConvert, OneScratchReusedAcrossWindowsAndModesGivesTheResultsOfFreshOnes) {
  // The scratch keeps its per-pixel sums between calls (cleared by each call's last sweep): a
  // scratch used by calls of both kinds over windows of changing size must change nothing.
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  ScanScratch shared;
  int tested = 0;
  for (int trial = 0; trial < 500; ++trial) {
    const RandomCase c = random_case(rng);
    Poly pts;
    for (int i = 0; i < 6; ++i) pts.push_back(c.lo + (c.hi - c.lo) * glm::dvec2(u(rng), u(rng)));
    const Poly hull = convex_hull(pts);
    if (hull.size() < 3) continue;
    ++tested;
    const size_t cells = static_cast<size_t>(c.win.width) * c.win.height;
    std::vector<double> area(cells), mx(cells), my(cells);
    if (trial % 2 == 0) {
      scan_convert_area(hull, c.win, area, shared);
      EXPECT_EQ(area, scan(hull, c.win).area);
    } else {
      scan_convert_moments(hull, c.win, area, mx, my, shared);
      const Result fresh = scan_moments(hull, c.win);
      EXPECT_EQ(area, fresh.area);
      EXPECT_EQ(mx, fresh.mx);
      EXPECT_EQ(my, fresh.my);
    }
    if (HasFailure()) return;
  }
  EXPECT_GT(tested, 400);
}

TEST(ScanConvert, SignedAreaIsTheShoelaceAreaWithCounterClockwisePositive) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  for (int trial = 0; trial < 200; ++trial) {
    Poly pts;
    for (int i = 0; i < 8; ++i) pts.emplace_back(u(rng), u(rng));
    const Poly hull = convex_hull(pts);
    const double area = 0.5 * shoelace2(hull);
    ASSERT_GT(area, 0.0);
    EXPECT_NEAR(signed_area(hull), area, 1e-9 * area);
    EXPECT_NEAR(signed_area(reversed(hull)), -area, 1e-9 * area);
  }
}

TEST(ScanConvert, RectangleOnPixelBordersCoversWholePixelsOnly) {
  const PixelWindow win{0, 0, 6, 5};
  const Poly rect{{1, 2}, {4, 2}, {4, 3}, {1, 3}};
  for (const Poly& p : {rect, reversed(rect)}) {
    const Result r = scan(p, win);
    for (int row = 0; row < win.height; ++row) {
      for (int col = 0; col < win.width; ++col) {
        const double expected = (row == 2 && col >= 1 && col < 4) ? 1.0 : 0.0;
        EXPECT_NEAR(r.area[row * win.width + col], expected, kAreaTolerance)
            << "col " << col << " row " << row;
      }
    }
    EXPECT_LE(max_pixel_error(p, {rect}, win), kAreaTolerance);  // moments too
  }
}

TEST(ScanConvert, PolygonFillingTheWholeWindowCoversEveryPixel) {
  const PixelWindow win{-3, 7, 4, 3};
  const Poly rect{{-3, 7}, {1, 7}, {1, 10}, {-3, 10}};
  for (const Poly& p : {rect, reversed(rect)}) {
    const Result r = scan(p, win);
    for (double a : r.area) EXPECT_NEAR(a, 1.0, kAreaTolerance);
    EXPECT_LE(max_pixel_error(p, {rect}, win), kAreaTolerance);  // moments too
  }
}

TEST(ScanConvert, SinglePixelWindowHoldsTheAreaOfAPolygonInside) {
  const PixelWindow win{5, -2, 1, 1};
  const Poly tri{{5.25, -1.5}, {5.75, -1.75}, {5.5, -1.125}};
  for (const Poly& p : {tri, reversed(tri)}) {
    EXPECT_NEAR(scan(p, win).area[0], 0.5 * std::abs(shoelace2(tri)), kAreaTolerance);
    EXPECT_LE(max_pixel_error(p, {tri}, win), kAreaTolerance);  // moments too
  }
}

TEST(ScanConvert, PolygonSmallerThanAPixelPutsItsAreaInThatPixelOnly) {
  const PixelWindow win{0, 0, 3, 3};
  const Poly tri{{1.2, 1.3}, {1.5, 1.35}, {1.4, 1.6}};
  const double exact = 0.5 * std::abs(shoelace2(tri));
  for (const Poly& p : {tri, reversed(tri)}) {
    const Result r = scan(p, win);
    for (int cell = 0; cell < 9; ++cell) {
      EXPECT_NEAR(r.area[cell], cell == 4 ? exact : 0.0, 1e-12) << "cell " << cell;
    }
    // The covered part's centroid, moment / area, is the triangle's centroid (1.3667, 1.4167)
    // relative to the pixel's corner (1, 1).
    const Result m = scan_moments(p, win);
    EXPECT_NEAR(m.mx[4] / m.area[4], (1.2 + 1.5 + 1.4) / 3.0 - 1.0, 1e-9);
    EXPECT_NEAR(m.my[4] / m.area[4], (1.3 + 1.35 + 1.6) / 3.0 - 1.0, 1e-9);
  }
}

TEST(ScanConvert, TinyPolygonAroundAPixelCornerSplitsIntoFourQuarters) {
  // A 0.02-wide square centred on the corner (2, 2): a quarter of its area in each pixel around it.
  const PixelWindow win{0, 0, 4, 4};
  const Poly sq{{1.99, 1.99}, {2.01, 1.99}, {2.01, 2.01}, {1.99, 2.01}};
  for (const Poly& p : {sq, reversed(sq)}) {
    const Result r = scan(p, win);
    for (int row = 0; row < 4; ++row) {
      for (int col = 0; col < 4; ++col) {
        const bool touched = (row == 1 || row == 2) && (col == 1 || col == 2);
        EXPECT_NEAR(r.area[row * 4 + col], touched ? 1e-4 : 0.0, 1e-13)
            << "col " << col << " row " << row;
      }
    }
    EXPECT_LE(max_pixel_error(p, {sq}, win), 1e-13);  // moments too
  }
}

TEST(ScanConvert, DiamondWithVerticesOnPixelCornersCoversHalvesAndWholes) {
  // Vertices on pixel corners, edges along pixel diagonals: the 8 pixels the edges cross are half
  // covered, the 4 inner pixels fully, the 4 corner pixels (touched at one point) not at all.
  const PixelWindow win{0, 0, 4, 4};
  const Poly diamond{{2, 0}, {4, 2}, {2, 4}, {0, 2}};
  for (const Poly& p : {diamond, reversed(diamond)}) {
    const Result r = scan(p, win);
    for (int row = 0; row < 4; ++row) {
      for (int col = 0; col < 4; ++col) {
        const bool inner_row = row == 1 || row == 2, inner_col = col == 1 || col == 2;
        const double expected = inner_row && inner_col ? 1.0 : (inner_row || inner_col ? 0.5 : 0.0);
        EXPECT_NEAR(r.area[row * 4 + col], expected, kAreaTolerance)
            << "col " << col << " row " << row;
      }
    }
    EXPECT_NEAR(r.sum, 8.0, kAreaTolerance);
    EXPECT_LE(max_pixel_error(p, {diamond}, win), kAreaTolerance);  // moments too
  }
}

TEST(ScanConvert, NonConvexPolygonWithEdgesOnPixelBordersCoversExactlyItsPixels) {
  // A U shape in whole pixels, offset window: the notch (col 1, rows 1..2) stays empty.
  const PixelWindow win{-10, 20, 3, 3};
  const Poly u{{-10, 20}, {-7, 20}, {-7, 23}, {-8, 23}, {-8, 21}, {-9, 21}, {-9, 23}, {-10, 23}};
  for (const Poly& p : {u, reversed(u)}) {
    const Result r = scan(p, win);
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) {
        const bool notch = col == 1 && row >= 1;
        EXPECT_NEAR(r.area[row * 3 + col], notch ? 0.0 : 1.0, kAreaTolerance)
            << "col " << col << " row " << row;
      }
    }
    const std::vector<Poly> pieces{{{-10, 20}, {-9, 20}, {-9, 23}, {-10, 23}},
                                   {{-9, 20}, {-8, 20}, {-8, 21}, {-9, 21}},
                                   {{-8, 20}, {-7, 20}, {-7, 23}, {-8, 23}}};
    EXPECT_LE(max_pixel_error(p, pieces, win), kAreaTolerance);  // moments too
  }
}

TEST(ScanConvert, CollinearVerticesDoNotChangeTheAreas) {
  // A triangle with extra vertices along its edges, some of them on pixel borders.
  const PixelWindow win{3, 4, 5, 4};
  const Poly tri{{3.2, 4.1}, {7.9, 4.6}, {4.0, 7.7}};
  Poly dense;
  for (size_t i = 0; i < tri.size(); ++i) {
    const glm::dvec2 a = tri[i], b = tri[(i + 1) % tri.size()];
    for (double t : {0.0, 0.25, 0.5, 0.75}) dense.push_back(a + (b - a) * t);
  }
  EXPECT_LE(max_pixel_error(dense, {tri}, win), kAreaTolerance);
  EXPECT_LE(max_pixel_error(reversed(dense), {tri}, win), kAreaTolerance);
}

TEST(ScanConvert, OffsetWindowGivesTheSameAreasAsTheShiftedPolygonAtTheOrigin) {
  // Negative and positive window origins with polygons far from zero: areas depend only on the
  // polygon's position relative to the window, and match the independent clip.
  const Poly tri{{0.3, 0.2}, {4.7, 1.1}, {2.2, 3.9}};
  const PixelWindow origin{0, 0, 5, 4};
  const Result base = scan(tri, origin);
  for (const glm::ivec2 off : {glm::ivec2(-37, 12), glm::ivec2(1000, -2000), glm::ivec2(-1, -1)}) {
    PixelWindow win{off.x, off.y, 5, 4};
    Poly moved = tri;
    for (glm::dvec2& p : moved) p += glm::dvec2(off);
    SCOPED_TRACE(describe(moved, win));
    EXPECT_LE(max_pixel_error(moved, {moved}, win), kAreaTolerance);
    const Result r = scan(moved, win);
    for (size_t i = 0; i < r.area.size(); ++i) EXPECT_NEAR(r.area[i], base.area[i], kAreaTolerance);
  }
}

TEST(ScanConvert, DegenerateLoopsCoverNothing) {
  // Fewer than three points, and a loop folded onto a line, have no area.
  const PixelWindow win{0, 0, 3, 3};
  EXPECT_EQ(scan(Poly{{0.5, 0.5}, {2.5, 2.5}}, win).sum, 0.0);
  const Result r = scan(Poly{{0.5, 0.5}, {2.5, 2.5}, {1.5, 1.5}}, win);
  for (double a : r.area) EXPECT_NEAR(a, 0.0, kAreaTolerance);
}

}  // namespace
}  // namespace hemibake::solver
