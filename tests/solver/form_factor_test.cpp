// Hemicube form factors (classical and the paper's anti-aliased one) against truths computed here:
// Lambert's contour formula for a differential area to a polygon (itself checked against a closed
// form), the closed forms for parallel and perpendicular rectangles (checked against the published
// values), exact polygon clipping for occlusion, and conservation (the faces of a closed box around
// the eye take all of the hemisphere; occluders only redistribute what a backdrop gets).
//
// Random inputs use a fresh seed each run, printed on failure; HEMIBAKE_TEST_SEED=N repeats a run,
// HEMIBAKE_TEST_VERBOSE=1 prints the measured errors (also recorded as test properties).
#include "test_seed.h"

#include "hemibake/solver/hemicube.h"

#include <gtest/gtest.h>

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

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

using glm::dvec3;
using Poly = std::vector<dvec3>;
constexpr double kPi = std::numbers::pi;

using test::seed_note;
using test::test_seed;

void record(const char* key, double value) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", value);
  ::testing::Test::RecordProperty(key, buf);
  if (std::getenv("HEMIBAKE_TEST_VERBOSE")) std::printf("  %s = %s\n", key, buf);
}

// --- Truth -----------------------------------------------------------------------------------

// Lambert: the form factor from a differential area at `eye` with unit normal `n` to a polygon
// wholly in front of it is (1 / 2pi) sum_i beta_i cos gamma_i, where beta_i is the angle the edge
// (p_i, p_i+1) subtends at the eye and gamma_i the angle between n and the normal of the plane
// through the eye and that edge.
double lambert(const dvec3& eye, const dvec3& n, const Poly& poly) {
  double sum = 0.0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const dvec3 r0 = poly[i] - eye;
    const dvec3 r1 = poly[(i + 1) % poly.size()] - eye;
    const dvec3 g = glm::cross(r0, r1);
    const double g_len = std::sqrt(glm::dot(g, g));
    if (g_len == 0.0) continue;
    const double beta = std::atan2(g_len, glm::dot(r0, r1));
    sum += beta * glm::dot(n, g) / g_len;
  }
  return std::abs(sum) / (2.0 * kPi);
}

// Differential area to a parallel rectangle a x b at height c whose corner is straight above it.
double corner_rectangle_closed_form(double a, double b, double c) {
  const double x = a / c, y = b / c;
  const double sx = std::sqrt(1.0 + x * x), sy = std::sqrt(1.0 + y * y);
  return (x / sx * std::atan(y / sx) + y / sy * std::atan(x / sy)) / (2.0 * kPi);
}

// Area to area: two directly opposed parallel a x b rectangles c apart.
double parallel_rectangles_closed_form(double a, double b, double c) {
  const double x = a / c, y = b / c;
  const double x2 = x * x, y2 = y * y;
  const double sx = std::sqrt(1.0 + x2), sy = std::sqrt(1.0 + y2);
  return 2.0 / (kPi * x * y) *
         (0.5 * std::log((1.0 + x2) * (1.0 + y2) / (1.0 + x2 + y2)) + x * sy * std::atan(x / sy) +
          y * sx * std::atan(y / sx) - x * std::atan(x) - y * std::atan(y));
}

// Area to area: from a w x l rectangle to an h x l rectangle at a right angle, sharing the edge of
// length l.
double perpendicular_rectangles_closed_form(double w, double h, double l) {
  const double W = w / l, H = h / l;
  const double w2 = W * W, h2 = H * H, s = w2 + h2;
  const double log_term = std::log((1.0 + w2) * (1.0 + h2) / (1.0 + s)) +
                          w2 * std::log(w2 * (1.0 + s) / ((1.0 + w2) * s)) +
                          h2 * std::log(h2 * (1.0 + s) / ((1.0 + h2) * s));
  return (W * std::atan(1.0 / W) + H * std::atan(1.0 / H) -
          std::sqrt(s) * std::atan(1.0 / std::sqrt(s)) + 0.25 * log_term) /
         (kPi * W);
}

// --- Geometry helpers ------------------------------------------------------------------------

dvec3 newell(const Poly& p) {
  dvec3 n(0.0);
  for (size_t i = 0; i < p.size(); ++i) n += glm::cross(p[i], p[(i + 1) % p.size()]);
  return n;
}

// The polygon with its corners counter-clockwise as seen from `viewer` (its front towards it).
Poly facing(Poly p, const dvec3& viewer) {
  if (glm::dot(newell(p), viewer - p[0]) < 0.0) std::reverse(p.begin(), p.end());
  return p;
}

// The part of a convex polygon where dot(n, x - o) >= 0 (Sutherland-Hodgman).
Poly clip_above(const Poly& in, const dvec3& o, const dvec3& n) {
  Poly out;
  for (size_t i = 0; i < in.size(); ++i) {
    const dvec3 a = in[(i + in.size() - 1) % in.size()], b = in[i];
    const double da = glm::dot(n, a - o), db = glm::dot(n, b - o);
    if ((da >= 0.0) != (db >= 0.0)) out.push_back(a + (b - a) * (da / (da - db)));
    if (db >= 0.0) out.push_back(b);
  }
  return out;
}

dvec3 random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  for (;;) {
    const dvec3 v(g(rng), g(rng), g(rng));
    const double len = glm::length(v);
    if (len > 1e-3) return v / len;
  }
}

// Two unit vectors completing `n` to a right-handed orthonormal frame.
void tangent_frame(const dvec3& n, dvec3& t, dvec3& b) {
  t = glm::normalize(glm::cross(std::abs(n.x) < 0.6 ? dvec3(1, 0, 0) : dvec3(0, 1, 0), n));
  b = glm::cross(n, t);
}

// A random rigid motion, to place a scene built in a convenient frame at a random pose.
struct Pose {
  dvec3 x, y, z, origin;
  dvec3 point(const dvec3& p) const { return origin + p.x * x + p.y * y + p.z * z; }
  dvec3 dir(const dvec3& v) const { return v.x * x + v.y * y + v.z * z; }
  Poly poly(const Poly& p) const {
    Poly out;
    for (const dvec3& v : p) out.push_back(point(v));
    return out;
  }
};

Pose random_pose(std::mt19937_64& rng) {
  Pose pose;
  pose.z = random_unit(rng);
  tangent_frame(pose.z, pose.x, pose.y);
  std::uniform_real_distribution<double> u(-5.0, 5.0);
  pose.origin = dvec3(u(rng), u(rng), u(rng));
  return pose;
}

// An up hint not too close to the normal, turning the hemicube's pixel grid by a random angle.
dvec3 random_up(std::mt19937_64& rng, const dvec3& normal) {
  for (;;) {
    const dvec3 up = random_unit(rng);
    if (glm::length(glm::cross(up, normal)) > 0.2) return up;
  }
}

// The paper's resolution (its figures use 100).
constexpr uint32_t kResolution = 100;

std::vector<double> hemicube(const dvec3& eye, const dvec3& normal, const std::vector<Poly>& polys,
                             Method method, const dvec3& up,
                             const std::vector<uint32_t>& groups = {},
                             uint32_t resolution = kResolution) {
  std::vector<ReceiverPolygon> rp(polys.size());
  for (size_t i = 0; i < polys.size(); ++i) {
    rp[i].corners = polys[i];
    if (!groups.empty()) rp[i].group = groups[i];
  }
  return hemicube_form_factors(eye, normal, rp, method, resolution, up);
}

// --- The truth checks itself -----------------------------------------------------------------

TEST(FormFactorTruth, LambertMatchesTheClosedFormForARectangleAboveAPoint) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.05, 5.0);
  for (int trial = 0; trial < 100; ++trial) {
    const double a = u(rng), b = u(rng), c = u(rng);
    const Poly rect{{0, 0, c}, {a, 0, c}, {a, b, c}, {0, b, c}};
    EXPECT_NEAR(lambert(dvec3(0.0), dvec3(0, 0, 1), rect), corner_rectangle_closed_form(a, b, c),
                1e-12);
    // Either orientation, and a rectangle around the point is four corner rectangles.
    const Poly around{{-a, -b, c}, {a, -b, c}, {a, b, c}, {-a, b, c}};
    EXPECT_NEAR(lambert(dvec3(0.0), dvec3(0, 0, 1), facing(around, dvec3(0.0))),
                4.0 * corner_rectangle_closed_form(a, b, c), 1e-12);
  }
}

TEST(FormFactorTruth, ClosedFormsGiveThePublishedValuesForUnitSquares) {
  // Cohen and Wallace (1993): 0.19982 for coaxial parallel unit squares 1 apart, 0.20004 for unit
  // squares at a right angle sharing an edge (both given to 5 decimals).
  EXPECT_NEAR(parallel_rectangles_closed_form(1, 1, 1), 0.19982, 5e-6);
  EXPECT_NEAR(perpendicular_rectangles_closed_form(1, 1, 1), 0.20004, 5e-6);
  // Reciprocity for unequal perpendicular rectangles: A1 F12 = A2 F21.
  EXPECT_NEAR(2.0 * perpendicular_rectangles_closed_form(2.0, 0.5, 1.0),
              0.5 * perpendicular_rectangles_closed_form(0.5, 2.0, 1.0), 1e-12);
}

// Gauss-Legendre nodes and weights on [0, 1] (Newton's method on the Legendre polynomial).
struct Node {
  double x, w;
};
std::vector<Node> gauss_legendre(int n) {
  std::vector<Node> nodes;
  for (int i = 1; i <= n; ++i) {
    double x = std::cos(kPi * (i - 0.25) / (n + 0.5)), dp = 1.0;
    for (int iter = 0; iter < 100; ++iter) {
      double p0 = 1.0, p1 = x;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = n * (x * p1 - p0) / (x * x - 1.0);
      const double dx = p1 / dp;
      x -= dx;
      if (std::abs(dx) < 1e-15) break;
    }
    nodes.push_back({0.5 * (x + 1.0), 1.0 / ((1.0 - x * x) * dp * dp)});
  }
  return nodes;
}

// The area-to-area factor from the unit square [0,1]^2 as the mean of a point factor over it, by
// an n x n Gauss-Legendre product rule. The point factor is smooth on the closed square for the
// parallel receiver; for the perpendicular one it has only a weak (d log d) singularity at the
// shared edge, so 6 x 6 nodes already give both to about 2e-8 (8 x 8: 1e-11).
constexpr int kQuadratureOrder = 6;

template <typename PointFactor>
double square_average(int n, PointFactor f) {
  const std::vector<Node> g = gauss_legendre(n);
  double sum = 0.0;
  for (const Node& a : g)
    for (const Node& b : g) sum += a.w * b.w * f(a.x, b.x);
  return sum;
}

// Unit squares: the source is [0,1]^2 in z = 0 facing +z; the receivers face the source.
const Poly kParallelReceiver =
    facing({{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}}, dvec3(0.5, 0.5, 0));
const Poly kPerpendicularReceiver =
    facing({{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}}, dvec3(0.5, 0.5, 0));

TEST(FormFactorTruth, LambertAveragedOverTheSourceGivesTheClosedForms) {
  const dvec3 n(0, 0, 1);
  EXPECT_NEAR(square_average(kQuadratureOrder, [&](double x, double y) {
                return lambert(dvec3(x, y, 0), n, kParallelReceiver);
              }),
              parallel_rectangles_closed_form(1, 1, 1), 1e-7);
  EXPECT_NEAR(square_average(kQuadratureOrder, [&](double x, double y) {
                return lambert(dvec3(x, y, 0), n, kPerpendicularReceiver);
              }),
              perpendicular_rectangles_closed_form(1, 1, 1), 1e-7);
}

// --- Random unoccluded polygons ----------------------------------------------------------------

struct Shot {
  dvec3 eye, normal, up;
  Poly poly;
};

// A triangle or convex quad (or a convex polygon of `corners` corners) wholly above the tangent
// plane of an eye at the pose's origin facing its z, facing the eye, 0.5 to 4 away and spanning
// about 8 to 40 hemicube pixels; random_shot: one such at a random pose.
Poly random_polygon_above(std::mt19937_64& rng, const Pose& pose, int corners = 0) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Shot s;
  s.eye = pose.origin;
  s.normal = pose.z;
  for (;;) {
    const double cos_t = 0.1 + 0.9 * u(rng), phi = 2.0 * kPi * u(rng);
    const double sin_t = std::sqrt(1.0 - cos_t * cos_t);
    const dvec3 d = pose.dir(dvec3(sin_t * std::cos(phi), sin_t * std::sin(phi), cos_t));
    const double r = 0.5 + 3.5 * u(rng);
    const dvec3 centre = s.eye + r * d;
    dvec3 m = glm::normalize(-d + 0.8 * random_unit(rng));
    if (glm::dot(m, -d) < 0.3) continue;
    dvec3 pu, pv;
    tangent_frame(m, pu, pv);
    const double radius = r * (0.08 + 0.32 * u(rng));
    const double ex = radius * (0.4 + 0.6 * u(rng)), ey = radius * (0.4 + 0.6 * u(rng));
    const int n = corners > 0 ? corners : (u(rng) < 0.5 ? 3 : 4);
    const double phase = 2.0 * kPi * u(rng);
    Poly p;
    for (int k = 0; k < n; ++k) {  // on an ellipse, in angular order: convex
      const double a = phase + 2.0 * kPi * (k + 0.8 * u(rng)) / n;
      p.push_back(centre + ex * std::cos(a) * pu + ey * std::sin(a) * pv);
    }
    const bool above = std::all_of(p.begin(), p.end(), [&](const dvec3& v) {
      return glm::dot(s.normal, v - s.eye) > 0.02 * glm::length(v - s.eye);  // 1 degree up
    });
    if (!above) continue;
    return facing(p, s.eye);
  }
}

Shot random_shot(std::mt19937_64& rng, int corners = 0) {
  Shot s;
  const Pose pose = random_pose(rng);
  s.eye = pose.origin;
  s.normal = pose.z;
  s.up = random_up(rng, s.normal);
  s.poly = random_polygon_above(rng, pose, corners);
  return s;
}

// With exact per-pixel delta form factors and exact coverage, the anti-aliased hemicube errs only
// where the form-factor density varies across a partly covered pixel. Measured over 24000 random
// polygons 8 to 40 pixels wide: mean relative error 0.02%, the worst 0.66%; everything above 0.3%
// was within 10 degrees of the horizon, where the density (proportional to the elevation's sine)
// changes by tens of percent across one side-face pixel. The mean over 60 stayed below 0.03%.
constexpr double kAaRelativeTolerance = 1e-2;
constexpr double kAaMeanRelativeTolerance = 1e-3;

TEST(AaHemicube, FormFactorOfRandomUnoccludedPolygonsMatchesLambert) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  double worst = 0.0, mean = 0.0;
  const int trials = 60;
  for (int trial = 0; trial < trials; ++trial) {
    const Shot s = random_shot(rng);
    const double exact = lambert(s.eye, s.normal, s.poly);
    const double aa = hemicube(s.eye, s.normal, {s.poly}, Method::kAntiAliased, s.up)[0];
    const double rel = std::abs(aa - exact) / exact;
    worst = std::max(worst, rel);
    mean += rel / trials;
    EXPECT_LE(rel, kAaRelativeTolerance) << "trial " << trial << " exact " << exact << " aa " << aa;
  }
  record("aa_max_relative_error", worst);
  record("aa_mean_relative_error", mean);
  EXPECT_LE(mean, kAaMeanRelativeTolerance);
}

TEST(AaHemicube, FormFactorOfRandomPolygonsWithManyCornersMatchesLambert) {
  // Receivers may have any number of corners; long loops take a different path (a fan of
  // triangles) than triangles and quads, and must give the same answer.
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> corners(5, 40);
  double worst = 0.0;
  for (int trial = 0; trial < 20; ++trial) {
    const Shot s = random_shot(rng, corners(rng));
    const double exact = lambert(s.eye, s.normal, s.poly);
    const double aa = hemicube(s.eye, s.normal, {s.poly}, Method::kAntiAliased, s.up)[0];
    worst = std::max(worst, std::abs(aa - exact) / exact);
    EXPECT_NEAR(aa, exact, kAaRelativeTolerance * exact)
        << "trial " << trial << ", " << s.poly.size() << " corners";
  }
  record("aa_max_relative_error", worst);
}

TEST(AaHemicube, IsSeveralTimesMoreAccurateThanClassicalOnRandomPolygons) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  double aa_err = 0.0, classical_err = 0.0, aa_rel = 0.0, classical_rel = 0.0;
  double classical_worst = 0.0;
  const int trials = 60;
  for (int trial = 0; trial < trials; ++trial) {
    const Shot s = random_shot(rng);
    const double exact = lambert(s.eye, s.normal, s.poly);
    const double aa = hemicube(s.eye, s.normal, {s.poly}, Method::kAntiAliased, s.up)[0];
    const double cl = hemicube(s.eye, s.normal, {s.poly}, Method::kClassical, s.up)[0];
    aa_err += std::abs(aa - exact) / trials;
    classical_err += std::abs(cl - exact) / trials;
    aa_rel += std::abs(aa - exact) / exact / trials;
    classical_rel += std::abs(cl - exact) / exact / trials;
    classical_worst = std::max(classical_worst, std::abs(cl - exact) / exact);
  }
  record("aa_mean_abs_error", aa_err);
  record("classical_mean_abs_error", classical_err);
  record("aa_mean_relative_error", aa_rel);
  record("classical_mean_relative_error", classical_rel);
  record("classical_max_relative_error", classical_worst);
  EXPECT_LT(3.0 * aa_err, classical_err);
}

TEST(AaHemicube, PolygonCrossingTheTangentPlaneGetsTheFactorOfItsPartAbove) {
  // The hemicube sees only the half space in front of the eye: a polygon straddling the tangent
  // plane counts with its part above it (clipped here independently). The classical hemicube's
  // clipping is checked by the closed box below, whose faces the tangent plane cuts; its error on
  // the thin slivers left above the plane here is too large to say more. Every polygon here reaches
  // the horizon, where the anti-aliased error is largest (see kAaRelativeTolerance): measured up
  // to 0.73% over 7200 polygons, hence 1.5%.
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double worst = 0.0;
  for (int trial = 0; trial < 20; ++trial) {
    const Pose pose = random_pose(rng);
    const dvec3 up = random_up(rng, pose.z);
    // A square standing on the local x axis at distance 1..3, tilted towards the eye, from
    // z = -h0 to z = h1.
    const double dist = 1.0 + 2.0 * u(rng), h0 = 0.2 + 0.8 * u(rng), h1 = 0.3 + u(rng);
    const double tilt = 0.5 * u(rng), half = 0.3 + u(rng);
    const Poly local{{dist + tilt * h0, -half, -h0}, {dist - tilt * h1, -half, h1},
                     {dist - tilt * h1, half, h1}, {dist + tilt * h0, half, -h0}};
    const Poly poly = facing(pose.poly(local), pose.origin);
    const double exact = lambert(pose.origin, pose.z, clip_above(poly, pose.origin, pose.z));
    const double aa = hemicube(pose.origin, pose.z, {poly}, Method::kAntiAliased, up)[0];
    EXPECT_NEAR(aa, exact, 1.5e-2 * exact) << "trial " << trial;
    worst = std::max(worst, std::abs(aa - exact) / exact);
  }
  record("aa_max_relative_error", worst);
}

TEST(Hemicube, PolygonFacingAwayGetsNothing) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  for (int trial = 0; trial < 5; ++trial) {
    Shot s = random_shot(rng);
    std::reverse(s.poly.begin(), s.poly.end());
    EXPECT_EQ(hemicube(s.eye, s.normal, {s.poly}, Method::kAntiAliased, s.up)[0], 0.0);
    EXPECT_EQ(hemicube(s.eye, s.normal, {s.poly}, Method::kClassical, s.up)[0], 0.0);
  }
}

TEST(AaHemicube, ErrorFallsWithTheSquareOfThePixelSize) {
  // The anti-aliased error comes from the density's variation inside partly covered pixels, so it
  // is second order: doubling the resolution divides it by about 4 (the mean over 30 polygons
  // fell by 3.4 to 5.6 times over 100 runs). An error of first order (an offset in the
  // projection, coverage given to the wrong pixel) would show as a ratio near 2, a wrong pixel
  // factor as a ratio near 1.
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  double err100 = 0.0, err200 = 0.0;
  for (int trial = 0; trial < 30; ++trial) {
    const Shot s = random_shot(rng);
    const double exact = lambert(s.eye, s.normal, s.poly);
    err100 += std::abs(hemicube(s.eye, s.normal, {s.poly}, Method::kAntiAliased, s.up, {}, 100)[0] -
                       exact) / exact;
    err200 += std::abs(hemicube(s.eye, s.normal, {s.poly}, Method::kAntiAliased, s.up, {}, 200)[0] -
                       exact) / exact;
  }
  record("error_ratio_100_to_200", err100 / err200);
  EXPECT_GT(err100 / err200, 2.5);
}

// --- Closed forms for unit squares -------------------------------------------------------------

// The area factor as the Gauss-Legendre mean of hemicube point factors over the source square.
double hemicube_square_average(const Poly& receiver, Method method, const dvec3& up) {
  return square_average(kQuadratureOrder, [&](double x, double y) {
    return hemicube(dvec3(x, y, 0), dvec3(0, 0, 1), {receiver}, method, up)[0];
  });
}

// The quadrature is exact to 1e-7 (checked above), so what remains is the hemicube's own error,
// measured over 60 runs (random hemicube rotations) at up to 1.2e-4 relative for the parallel
// squares and 3e-5 for the perpendicular ones.
constexpr double kAaSquaresRelativeTolerance = 5e-4;
// The classical hemicube's errors at the 36 points partly cancel in the mean, but how much depends
// on the hemicube's rotation: over 600 runs (random rotations) up to 1.4 % (0.42 % over the first
// 60; a 1 % bound failed about once in 300 runs, seed 18194689156291024500).
constexpr double kClassicalSquaresRelativeTolerance = 2.5e-2;

// Both hemicubes' mean form factor from the source square to `receiver` against `exact`, with the
// hemicube turned about its normal at random.
void expect_squares_match(const Poly& receiver, double exact) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  const dvec3 up = random_up(rng, dvec3(0, 0, 1));
  const double aa = hemicube_square_average(receiver, Method::kAntiAliased, up);
  const double cl = hemicube_square_average(receiver, Method::kClassical, up);
  record("aa_relative_error", (aa - exact) / exact);
  record("classical_relative_error", (cl - exact) / exact);
  EXPECT_NEAR(aa, exact, kAaSquaresRelativeTolerance * exact);
  EXPECT_NEAR(cl, exact, kClassicalSquaresRelativeTolerance * exact);
}

TEST(Hemicube, FormFactorOfParallelUnitSquaresMatchesClosedForm) {
  expect_squares_match(kParallelReceiver, parallel_rectangles_closed_form(1, 1, 1));  // 0.19982
}

TEST(Hemicube, FormFactorOfPerpendicularUnitSquaresMatchesClosedForm) {
  expect_squares_match(kPerpendicularReceiver, perpendicular_rectangles_closed_form(1, 1, 1));  // 0.20004
}

// --- Occlusion ---------------------------------------------------------------------------------

TEST(Hemicube, PolygonWhollyBehindALargerOneGetsNothing) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  for (int trial = 0; trial < 10; ++trial) {
    const Pose pose = random_pose(rng);
    const dvec3 eye = pose.origin, n = pose.z, up = random_up(rng, n);
    // In the local frame the front square spans tangents +-0.5, the back one at most +-0.45: at
    // least 2.5 pixels of the front square surround the back one on the top face.
    const double sx = u(rng), sy = u(rng);
    const Poly front =
        facing(pose.poly({{-1, -1, 2}, {1, -1, 2}, {1, 1, 2}, {-1, 1, 2}}), eye);
    const Poly back = facing(pose.poly({{sx - 1.2, sy - 1.2, 4},
                                        {sx + 1.2, sy - 1.2, 4},
                                        {sx + 1.2, sy + 1.2, 4},
                                        {sx - 1.2, sy + 1.2, 4}}),
                             eye);
    const double back_alone = lambert(eye, n, back);
    for (const Method method : {Method::kAntiAliased, Method::kClassical}) {
      // Either order of the input: occlusion must not depend on it.
      const std::vector<double> ff = hemicube(eye, n, {back, front}, method, up);
      const std::vector<double> ff2 = hemicube(eye, n, {front, back}, method, up);
      // Fully covered pixels have coverage 1 to float rounding (6e-8).
      EXPECT_LE(ff[0], 1e-6 * back_alone) << "method " << static_cast<int>(method);
      EXPECT_LE(ff2[1], 1e-6 * back_alone) << "method " << static_cast<int>(method);
    }
    const double aa_front = hemicube(eye, n, {back, front}, Method::kAntiAliased, up)[1];
    EXPECT_NEAR(aa_front, lambert(eye, n, front), kAaRelativeTolerance * lambert(eye, n, front));
  }
}

TEST(AaHemicube, PartlyCoveredPolygonGetsTheFactorOfItsUncoveredPart) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    const Pose pose = random_pose(rng);
    const dvec3 eye = pose.origin, n = pose.z, up = random_up(rng, n);
    // Back square [-1,1]^2 at height 4; an occluder at height 2 whose edge x = t/2 projects onto
    // the back square's line x = t, and which overhangs the back square everywhere else.
    const double t = -0.6 + 1.2 * u(rng);
    const Poly back = facing(pose.poly({{-1, -1, 4}, {1, -1, 4}, {1, 1, 4}, {-1, 1, 4}}), eye);
    const Poly occluder = facing(
        pose.poly({{-1.5, -1.5, 2}, {t / 2, -1.5, 2}, {t / 2, 1.5, 2}, {-1.5, 1.5, 2}}), eye);
    const Poly uncovered = facing(pose.poly({{t, -1, 4}, {1, -1, 4}, {1, 1, 4}, {t, 1, 4}}), eye);
    const double exact = lambert(eye, n, uncovered);
    const std::vector<double> ff = hemicube(eye, n, {back, occluder}, Method::kAntiAliased, up);
    EXPECT_NEAR(ff[0], exact, kAaRelativeTolerance * exact) << "trial " << trial << " t " << t;
    EXPECT_NEAR(ff[1], lambert(eye, n, occluder), kAaRelativeTolerance * lambert(eye, n, occluder));
  }
}

// A view kept to a receiver's pixels (as a solve's shot to a few split receivers keeps it) gives
// the receiver what the whole view does, though the occluder reaches far beyond those pixels and is
// cut at their edge: here a small square partly hidden by a large occluder, before a large
// backdrop, gets the factor of its uncovered part; the others get nothing.
TEST(AaHemicube, ViewKeptToAReceiverGivesItTheFactorOfItsUncoveredPart) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    const Pose pose = random_pose(rng);
    const dvec3 eye = pose.origin, n = pose.z, up = random_up(rng, n);
    // The receiver [0.4, 1.4] x [-0.25, 0.25] at height 4; the occluder at height 2 reaches from
    // x = -3 to t / 2, whose line projects onto x = t on the receiver, and 3 either side in y. The
    // uncovered strip is 0.3 to 0.9 wide, 4 to 11 pixels at the top face's centre: narrower, the
    // hemicube's own error at its two edges passed 1 %, kept view or not.
    const double t = 0.5 + 0.6 * u(rng);
    std::vector<ReceiverPolygon> polys(2);
    polys[0].corners = facing(pose.poly({{0.4, -0.25, 4}, {1.4, -0.25, 4}, {1.4, 0.25, 4}, {0.4, 0.25, 4}}), eye);
    polys[1].corners = facing(pose.poly({{-3, -3, 2}, {t / 2, -3, 2}, {t / 2, 3, 2}, {-3, 3, 2}}), eye);
    polys.push_back({facing(pose.poly({{-20, -20, 6}, {20, -20, 6}, {20, 20, 6}, {-20, 20, 6}}), eye)});
    const Poly uncovered = facing(pose.poly({{t, -0.25, 4}, {1.4, -0.25, 4}, {1.4, 0.25, 4}, {t, 0.25, 4}}), eye);
    const double exact = lambert(eye, n, uncovered);
    const std::vector<uint32_t> receivers{0};
    const std::vector<double> ff = hemicube_form_factors(eye, n, polys, Method::kAntiAliased, kResolution, up, receivers);
    const double whole = hemicube_form_factors(eye, n, polys, Method::kAntiAliased, kResolution, up)[0];
    EXPECT_NEAR(ff[0], exact, kAaRelativeTolerance * exact) << "trial " << trial << " t " << t;
    EXPECT_NEAR(ff[0], whole, 1e-6 * whole) << "trial " << trial << " t " << t;
    for (size_t k = 1; k < ff.size(); ++k) EXPECT_EQ(ff[k], 0.0) << "trial " << trial << " polygon " << k;
  }
}

// Crowds of random polygons hiding one another: a view kept to a few of them gives those what the
// whole view gives them, but for rounding where an occluder is cut at the edge of their pixels.
TEST(Hemicube, ViewKeptToReceiversGivesThemTheWholeViewsFactors) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  size_t hidden = 0;  // receivers that something partly hides
  for (const Method method : {Method::kAntiAliased, Method::kClassical}) {
    for (int trial = 0; trial < 20; ++trial) {
      const Pose pose = random_pose(rng);
      const dvec3 up = random_up(rng, pose.z);
      std::vector<ReceiverPolygon> polys;
      for (int k = 0; k < 40; ++k) polys.push_back({random_polygon_above(rng, pose)});
      const std::vector<uint32_t> receivers{static_cast<uint32_t>(rng() % 40), static_cast<uint32_t>(rng() % 40)};
      const std::vector<double> whole = hemicube_form_factors(pose.origin, pose.z, polys, method, kResolution, up);
      const std::vector<double> kept =
          hemicube_form_factors(pose.origin, pose.z, polys, method, kResolution, up, receivers);
      for (uint32_t r : receivers) {
        EXPECT_NEAR(kept[r], whole[r], 1e-6 * whole[r] + 1e-12) << "trial " << trial << " receiver " << r;
        if (whole[r] < 0.99 * lambert(pose.origin, pose.z, polys[r].corners)) ++hidden;
      }
      for (uint32_t k = 0; k < kept.size(); ++k) {
        if (std::find(receivers.begin(), receivers.end(), k) == receivers.end()) {
          EXPECT_EQ(kept[k], 0.0);
        }
      }
    }
  }
  EXPECT_GE(hidden, 10u) << "too few receivers were partly hidden for the test to mean much";
}

// A wall standing on a floor, seen from low in front: in a pixel on its foot the wall's covered part
// (up the wall) lies farther from the eye than the floor strip in front of the foot, so by depth
// the strip came first and the wall lost the strip's share of every foot pixel. Standing on the
// floor, the wall hides it wherever both show from the floor's side, and keeps its whole form
// factor. The wall runs across the whole floor and rises above the eye, so the floor behind it is
// hidden and the floor's pieces (one surface) together take the form factor of the floor in front.
TEST(AaHemicube, WallStandingOnAFloorKeepsItsWholeFormFactorAtItsFoot) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    const Pose pose = random_pose(rng);
    // Local frame: the floor is y = 0, the wall z = 0 (y in [0, h]); the eye in front of the wall, a
    // little above the floor.
    const double h = 0.5 + u(rng), strip = 0.01 + 0.1 * u(rng);
    // The hemicube faces the wall; the floor starts in front of the eye (closed forms need the
    // polygons wholly in front of its plane).
    const double ez = -1.5 - u(rng);
    const dvec3 eye = pose.point({0.3 * (u(rng) - 0.5), 0.05 + 0.2 * u(rng), ez});
    const dvec3 n = pose.z, up = pose.y;
    const Poly wall = facing(pose.poly({{-3, 0, 0}, {3, 0, 0}, {3, h, 0}, {-3, h, 0}}), eye);
    const Poly in_front = facing(pose.poly({{-3, 0, ez / 2}, {3, 0, ez / 2}, {3, 0, -strip}, {-3, 0, -strip}}), eye);
    const Poly at_foot = facing(pose.poly({{-3, 0, -strip}, {3, 0, -strip}, {3, 0, 0}, {-3, 0, 0}}), eye);
    const Poly behind = facing(pose.poly({{-3, 0, 0}, {3, 0, 0}, {3, 0, 3}, {-3, 0, 3}}), eye);
    const std::vector<double> ff =
        hemicube(eye, n, {in_front, at_foot, behind, wall}, Method::kAntiAliased, up, {7, 7, 7, kNone});
    const double exact = lambert(eye, n, wall);
    EXPECT_NEAR(ff[3], exact, kAaRelativeTolerance * exact) << "trial " << trial;
    // The floor seen at a grazing angle has an error of its own: the floor alone (no wall, nothing
    // behind) shows it. In the foot's pixels the floor takes what the wall's coverage leaves, both
    // estimated along the same line from either side (within 5 % of the floor's small share at
    // this resolution, 9 % at 40 pixels); ordered by depth, the wall's loss went to the floor.
    const double floor_exact = lambert(eye, n, in_front) + lambert(eye, n, at_foot);
    const std::vector<double> alone = hemicube(eye, n, {in_front, at_foot}, Method::kAntiAliased, up, {7, 7});
    const double own_error = std::abs(alone[0] + alone[1] - floor_exact);
    EXPECT_LE(std::abs(ff[0] + ff[1] + ff[2] - floor_exact), own_error + 0.05 * floor_exact) << "trial " << trial;
  }
}

TEST(AaHemicube, OverlappingOccludersOnlyRedistributeTheFormFactorOfABackdrop) {
  // Random polygons at random depths overlap one another in front of a backdrop that fills every
  // pixel they touch. Whatever the depth order and the paper's estimate E_k = A_k (1 - f_{k-1})
  // make of pixels with several partial layers, each such pixel ends fully taken (f = 1 once the
  // backdrop's A = 1 is reached), so the factors of all polygons add up to the backdrop's alone.
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double worst = 0.0;
  for (int trial = 0; trial < 5; ++trial) {
    const Pose pose = random_pose(rng);
    const dvec3 eye = pose.origin, n = pose.z, up = random_up(rng, n);
    // The backdrop: a plane at height 1 reaching 1e4 out, so it fills every hemicube pixel but
    // those within 1e-4 radians of the horizon, where no occluder comes (elevations above 0.14).
    std::vector<Poly> polys{facing(
        pose.poly({{-1e4, -1e4, 1}, {1e4, -1e4, 1}, {1e4, 1e4, 1}, {-1e4, 1e4, 1}}), eye)};
    while (polys.size() < 13) {
      // A triangle or quad of radius 0.1 to 0.4 in a random plane, between heights 0.3 and 0.9.
      const dvec3 c(-1.2 + 2.4 * u(rng), -1.2 + 2.4 * u(rng), 0.4 + 0.4 * u(rng));
      dvec3 a, b;
      tangent_frame(random_unit(rng), a, b);
      const double r = 0.1 + 0.3 * u(rng);
      const int corners = polys.size() % 2 == 0 ? 3 : 4;
      Poly p;
      for (int i = 0; i < corners; ++i) {
        const double angle = 2.0 * kPi * (i + 0.5 * u(rng)) / corners;
        p.push_back(c + r * (std::cos(angle) * a + std::sin(angle) * b));
      }
      if (std::all_of(p.begin(), p.end(), [](const dvec3& v) { return v.z > 0.3 && v.z < 0.9; }))
        polys.push_back(facing(pose.poly(p), eye));
    }
    const std::vector<double> ff = hemicube(eye, n, polys, Method::kAntiAliased, up);
    double total = 0.0;
    for (double f : ff) total += f;
    const double backdrop_alone = hemicube(eye, n, {polys[0]}, Method::kAntiAliased, up)[0];
    worst = std::max(worst, std::abs(total - backdrop_alone));
    EXPECT_NEAR(total, backdrop_alone, 1e-6) << "trial " << trial;
    const double exact = lambert(eye, n, polys[0]);
    EXPECT_NEAR(backdrop_alone, exact, kAaMeanRelativeTolerance * exact);
  }
  record("worst_total_difference", worst);
}

// --- Slipping through the cracks (the paper's Figure 2) ------------------------------------------

TEST(AaHemicube, NoSmallElementOfAFarGridSlipsThroughTheCracks) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Pose pose = random_pose(rng);
  const dvec3 eye = pose.origin, n = pose.z, up = random_up(rng, n);
  // A 2 x 2 grid of 40 x 40 squares at height 10, within 16 degrees of the normal (on the top
  // face, tangents up to 0.28): each element spans 0.005 tangent units, a quarter of a pixel (0.02
  // at resolution 100), about 1/16 of its area. All are pieces of one plane: one occlusion group.
  const int m = 40;
  const double cx = u(rng), cy = u(rng), side = 2.0 / m;
  std::vector<Poly> elements;
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < m; ++j) {
      const double x0 = cx - 1.0 + i * side, y0 = cy - 1.0 + j * side;
      elements.push_back(facing(pose.poly({{x0, y0, 10},
                                           {x0 + side, y0, 10},
                                           {x0 + side, y0 + side, 10},
                                           {x0, y0 + side, 10}}),
                                eye));
    }
  }
  const Poly outline = facing(pose.poly({{cx - 1, cy - 1, 10},
                                         {cx + 1, cy - 1, 10},
                                         {cx + 1, cy + 1, 10},
                                         {cx - 1, cy + 1, 10}}),
                              eye);
  const double exact_total = lambert(eye, n, outline);
  const std::vector<uint32_t> groups(elements.size(), 7);

  const std::vector<double> classical =
      hemicube(eye, n, elements, Method::kClassical, up, groups);
  const std::vector<double> aa = hemicube(eye, n, elements, Method::kAntiAliased, up, groups);

  // Classical: an element gets a pixel only if it holds the pixel's centre; about 100 centres fall
  // on the grid, so most of its 1600 visible elements get nothing.
  const auto zeros = std::count(classical.begin(), classical.end(), 0.0);
  record("classical_zero_elements", static_cast<double>(zeros));
  EXPECT_GT(zeros, static_cast<long>(elements.size() / 2));

  // Anti-aliased: every element gets its share, near its own exact factor, and together they get
  // the whole grid's. An element's error is the density's variation between the element and the
  // centre of its pixel: relative gradient 4t / (1 + t^2) per tangent unit, at most 1.1 per unit
  // here, over at most 0.71 pixel (0.014): about 1.5%; measured up to 0.9%.
  double total = 0.0, worst = 0.0;
  for (size_t e = 0; e < elements.size(); ++e) {
    const double exact = lambert(eye, n, elements[e]);
    EXPECT_GT(aa[e], 0.0) << "element " << e;
    worst = std::max(worst, std::abs(aa[e] - exact) / exact);
    total += aa[e];
  }
  record("aa_worst_element_relative_error", worst);
  record("aa_total_relative_error", (total - exact_total) / exact_total);
  EXPECT_LE(worst, 0.02);
  EXPECT_NEAR(total, exact_total, 1e-2 * exact_total);
  // Pieces of one surface add up exactly: the grid gets what its outline alone would get.
  const double outline_aa = hemicube(eye, n, {outline}, Method::kAntiAliased, up)[0];
  EXPECT_NEAR(total, outline_aa, 1e-6 * outline_aa);
}

// --- Conservation --------------------------------------------------------------------------------

// A random box (0.5 to 3 m a side) with an eye inside it, a random normal and up hint for the
// cube at the eye, and the box's six faces turned to face the eye.
struct BoxAroundEye {
  dvec3 eye, normal, up;
  std::vector<Poly> faces;
};
BoxAroundEye random_box_around_eye(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  BoxAroundEye b;
  const dvec3 size(0.5 + 2.5 * u(rng), 0.5 + 2.5 * u(rng), 0.5 + 2.5 * u(rng));
  b.eye = size * dvec3(0.05 + 0.9 * u(rng), 0.05 + 0.9 * u(rng), 0.05 + 0.9 * u(rng));
  b.normal = random_unit(rng);
  b.up = random_up(rng, b.normal);
  const double X = size.x, Y = size.y, Z = size.z;
  b.faces = {
      {{0, 0, 0}, {X, 0, 0}, {X, Y, 0}, {0, Y, 0}}, {{0, 0, Z}, {X, 0, Z}, {X, Y, Z}, {0, Y, Z}},
      {{0, 0, 0}, {X, 0, 0}, {X, 0, Z}, {0, 0, Z}}, {{0, Y, 0}, {X, Y, 0}, {X, Y, Z}, {0, Y, Z}},
      {{0, 0, 0}, {0, Y, 0}, {0, Y, Z}, {0, 0, Z}}, {{X, 0, 0}, {X, Y, 0}, {X, Y, Z}, {X, 0, Z}},
  };
  for (Poly& f : b.faces) f = facing(f, b.eye);
  return b;
}

// The six faces of a random box around the eye, facing it: every direction of the hemisphere
// meets exactly one face, so their form factors sum to 1 whatever the normal (faces behind the
// tangent plane are clipped away by the hemicube). The hemicube's pixel factors are exact and sum
// to 1, so only rounding remains: float coverages and transmissions (6e-8) in the anti-aliased sum.
// Faces meet along the box's edges, and a pixel an edge crosses is shared by two faces side by
// side: for the sum to be 1 their coverages must add there (as the solver's adjacent occlusion
// groups do), not shadow each other as depth layers would (a1 + a2 (1 - a1) < 1).
void expect_box_form_factors_sum_to_one(Method method) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  double worst = 0.0;
  for (int trial = 0; trial < 10; ++trial) {
    const BoxAroundEye box = random_box_around_eye(rng);
    const dvec3 &eye = box.eye, &n = box.normal, &up = box.up;
    const std::vector<Poly>& faces = box.faces;
    const std::vector<double> ff = hemicube(eye, n, faces, method, up);
    double sum = 0.0;
    for (double f : ff) sum += f;
    worst = std::max(worst, std::abs(sum - 1.0));
    EXPECT_NEAR(sum, 1.0, 1e-6) << "trial " << trial;
  }
  record("worst_sum_error", worst);
}

TEST(ClassicalHemicube, FormFactorsOfTheFacesOfABoxAroundTheEyeSumToOne) {
  expect_box_form_factors_sum_to_one(Method::kClassical);
}

TEST(AaHemicube, FormFactorsOfTheFacesOfABoxAroundTheEyeSumToOne) {
  expect_box_form_factors_sum_to_one(Method::kAntiAliased);
}

// --- The full cube of a volume cluster -----------------------------------------------------------

// The exact solid angle of a convex polygon seen from `eye` (Van Oosterom and Strackee's formula
// for each triangle of a fan).
double exact_solid_angle(const dvec3& eye, const Poly& p) {
  double sum = 0.0;
  for (size_t k = 1; k + 1 < p.size(); ++k) {
    const dvec3 a = p[0] - eye, b = p[k] - eye, c = p[k + 1] - eye;
    const double la = glm::length(a), lb = glm::length(b), lc = glm::length(c);
    const double num = std::abs(glm::dot(a, glm::cross(b, c)));
    const double den = la * lb * lc + glm::dot(a, b) * lc + glm::dot(a, c) * lb + glm::dot(b, c) * la;
    sum += 2.0 * std::atan2(num, den);
  }
  return sum;
}

std::vector<double> full_cube(const dvec3& eye, const std::vector<Poly>& polys, const dvec3& normal, const dvec3& up,
                              uint32_t resolution = kResolution) {
  std::vector<ReceiverPolygon> receivers;
  for (const Poly& p : polys) receivers.push_back({p, kNone});
  return cube_solid_angles(eye, receivers, Method::kAntiAliased, resolution, normal, up);
}

// The six faces of a random box around the eye, the cube turned at random: together they take the
// whole sphere (4 pi), and each face its own exact solid angle, wherever it lies, below the
// cube's top face as well as above.
TEST(FullCube, FacesOfABoxAroundTheEyeTakeTheirExactSolidAngles) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  double worst = 0.0;
  for (int trial = 0; trial < 10; ++trial) {
    const BoxAroundEye box = random_box_around_eye(rng);
    const dvec3 &eye = box.eye, &n = box.normal, &up = box.up;
    const std::vector<Poly>& faces = box.faces;
    const std::vector<double> omega = full_cube(eye, faces, n, up);
    double sum = 0.0;
    for (size_t i = 0; i < faces.size(); ++i) {
      const double exact = exact_solid_angle(eye, faces[i]);
      worst = std::max(worst, std::abs(omega[i] - exact) / exact);
      EXPECT_NEAR(omega[i], exact, 1e-2 * exact) << "trial " << trial << " face " << i;
      sum += omega[i];
    }
    EXPECT_NEAR(sum, 4.0 * kPi, 1e-5) << "trial " << trial;
  }
  record("full_cube_worst_face_relative_error", worst);
}

// A random polygon in any direction from the eye, with one in front of it half hiding it: the
// front one takes its exact solid angle, and the back one loses what the front one covers.
TEST(FullCube, NearerPolygonHidesWhatItCoversInAnyDirection) {
  const uint64_t seed = test_seed();
  SCOPED_TRACE(seed_note(seed));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const dvec3 eye(u(rng), u(rng), u(rng));
    const dvec3 d = random_unit(rng);
    const dvec3 t = glm::normalize(glm::cross(d, random_up(rng, d))), b = glm::cross(d, t);
    // A square 2 m across at 3 m, and before it at 1.5 m a square 0.5 m across over its middle:
    // it hides as much of the back square as its own solid angle.
    auto square = [&](double dist, double half) {
      const dvec3 c = eye + d * dist;
      return facing(Poly{c - t * half - b * half, c + t * half - b * half, c + t * half + b * half, c - t * half + b * half}, eye);
    };
    const Poly back = square(3.0, 1.0), front = square(1.5, 0.25);
    const dvec3 n = random_unit(rng);
    const std::vector<double> omega = full_cube(eye, {back, front}, n, random_up(rng, n));
    const double w_back = exact_solid_angle(eye, back), w_front = exact_solid_angle(eye, front);
    EXPECT_NEAR(omega[1], w_front, 1e-2 * w_front) << "trial " << trial;
    EXPECT_NEAR(omega[0], w_back - w_front, 1e-2 * (w_back - w_front)) << "trial " << trial;
  }
}

}  // namespace
}  // namespace hemibake::solver
