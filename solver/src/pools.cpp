// Light pools (Params::pools): where the light an element takes varies across it. The hemicube
// gives each receiver one number per shot, its mean; a floor that is one element under a small
// lamp, or under the facets of a glowing sphere, has four corners that agree and stays one flat
// element however bright the pool under the lamp. A criterion that split wherever one shot varies
// would split the walls of every evenly lit room, whose light is even only in sum.
//
// So a first pass, a draft of the solve, keeps a grid of points in the (u, v) of every patch large
// enough to split, and every shot adds to the points of the receivers it lights rho dB times the
// unoccluded form factor from the point to the shooting piece (Lambert's formula within a
// diameter of it, a disc further off): the sum of the shots, with visibility element by element.
// Once every emitter has shot and 70 % of the light is given out (kPoolsPass), find_pools splits
// the leaves whose points differ by more than kPoolShare of their mean (and kPoolFloor times the
// solve's radiosity tolerance), and their children likewise, down to the smallest element that may
// split. The pass used to go on to 2 % unshot: 0.5 to 2 s on rooms of a few thousand patches, as
// much as the solve proper. Ended once the emitters alone have shot, it found the pools under
// lamps, windows and glowing objects but not those of their first reflections (the ceiling over a
// lamp's pool on the floor, a block's faces turned from the lamp: lamp room p90 21.9 %, Cornell box
// 32.1 %); at 30 % unshot it finds those (4.9 %, 12.9 %; at 2 %, 5.5 % and 11.1 %) for a third of
// the cost.
// The solve proper then starts on the scene with those splits made (Impl::next_pass), so that the
// hemicube gives every shot's light to the finer elements.
#include "solver_impl.h"

#include "hemibake/solver/hemicube.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <numbers>

namespace hemibake::solver {

namespace {

// Points a side of a patch's grid: 2^m + 1, spaced about half the side of the smallest element
// that may split, 3 to 129.
constexpr uint32_t kMinGridLevels = 1, kMaxGridLevels = 7;
// How far in front of its surface a point looks from, times the scene's diagonal.
constexpr double kGridLift = 1e-4;
// ... and how far towards its patch's centre, as a share of the way.
constexpr double kGridInset = 1e-3;

// The form factor from a point (normal n) to the part of polygon `poly` in front of its plane.
double clipped_form_factor(const glm::dvec3& x, const glm::dvec3& n, const std::array<glm::dvec3, 4>& poly,
                           uint32_t count) {
  std::array<glm::dvec3, 5> in;
  uint32_t kept = 0;
  constexpr double kAbove = 1e-9;
  for (uint32_t i = 0; i < count; ++i) {
    const glm::dvec3& a = poly[i];
    const glm::dvec3& b = poly[(i + 1) % count];
    const double da = glm::dot(n, a - x) - kAbove, db = glm::dot(n, b - x) - kAbove;
    if (da >= 0.0 && kept < in.size()) in[kept++] = a;
    if ((da >= 0.0) != (db >= 0.0) && kept < in.size()) in[kept++] = a + (b - a) * (da / (da - db));
  }
  if (kept < 3) return 0.0;
  return point_polygon_form_factor(x, n, std::span<const glm::dvec3>(in.data(), kept));
}

}  // namespace

void Solver::Impl::build_light_grids() {
  p_grid_n.assign(patches.size(), 0);
  p_grid_begin.assign(patches.size(), 0);
  const double spacing = 0.5 * std::sqrt(min_split_area());
  size_t points = 0;
  for (uint32_t p = 0; p < patches.size(); ++p) {
    // An emitter shows its own light, to which what it reflects adds little. The ceiling panels
    // were the only patches large enough for a grid in the benchmarks' furnished and cluttered
    // rooms, where the pass then found nothing and took 1 s of 4.6 s and 2 s of 16 s.
    if (!(prep.area[p] >= 4.0 * min_split_area()) || channel_sum(patches[p].emission) > 0.0) continue;
    const double extent = polygon_diameter(corners_of_copy(p_root[p]), corner_count(p_root[p]));
    uint32_t levels = kMinGridLevels;
    while (levels < kMaxGridLevels && extent / static_cast<double>(1u << levels) > spacing) ++levels;
    p_grid_n[p] = (1u << levels) + 1;
    p_grid_begin[p] = static_cast<uint32_t>(points);
    points += static_cast<size_t>(p_grid_n[p]) * p_grid_n[p];
  }
  grid_light.assign(points, 0.0f);
  grid_stamp.assign(points, 0);
}

// The shooter's unoccluded light at x (normal n), as a form factor: Lambert's formula for the
// part of its polygons in front of x within two diameters of its centre, a disc of its area further.
double Solver::Impl::shooter_light(const ShooterShape& s, const glm::dvec3& x, const glm::dvec3& n) const {
  const glm::dvec3 d = s.centre - x;
  const double r2 = glm::dot(d, d);
  const bool near = r2 < s.diameter * s.diameter;
  if (near && s.poly_n >= 3) {
    if (glm::dot(s.normal, s.poly[0] - x) >= 0.0) return 0.0;  // x behind its plane
    return clipped_form_factor(x, n, s.poly, s.poly_n);
  }
  if (near && !s.src.empty()) {
    double f = 0.0;
    std::array<glm::dvec3, 4> poly;
    for (uint32_t e : s.src) {
      Corners c;
      corners_of(e, c);
      const uint32_t count = corner_count(e);
      std::copy(c.begin(), c.begin() + count, poly.begin());
      if (glm::dot(prep.normal[e_patch[e]], poly[0] - x) >= 0.0) continue;
      f += clipped_form_factor(x, n, poly, count);
    }
    return f;
  }
  const double r = std::sqrt(r2);
  if (s.volume) {
    // The cluster's area facing x, as a share (its lobe along -d), stands for cos_s.
    const glm::dvec3 w = -d / r;
    double facing = 0.0;
    for (int a = 0; a < 3; ++a) facing += w[a] > 0.0 ? s.lobe[2 * a] * w[a] : -s.lobe[2 * a + 1] * w[a];
    const double cos_r = glm::dot(n, d) / r;
    if (!(cos_r > 0.0 && facing > 0.0)) return 0.0;
    return s.area * cos_r * facing / (std::numbers::pi * r2 + s.area);
  }
  if (glm::dot(s.normal, d) >= 0.0) return 0.0;
  const double cos_r = glm::dot(n, d) / r, cos_s = -glm::dot(s.normal, d) / r;
  if (!(cos_r > 0.0 && cos_s > 0.0)) return 0.0;
  return s.area * cos_r * cos_s / (std::numbers::pi * r2 + s.area);
}

ShooterShape Solver::Impl::shape_of(const Piece& piece) const {
  ShooterShape s;
  s.centre = piece.centre;
  s.normal = piece.normal;
  s.area = piece.area;
  s.diameter = piece.diameter;
  // A piece of one patch is its polygon; a cluster (more points, or reaching behind its centre) a disc.
  if (piece.rear == 0.0 && piece.points.size() >= 3 && piece.points.size() <= 4) {
    s.poly_n = static_cast<uint32_t>(piece.points.size());
    std::copy(piece.points.begin(), piece.points.end(), s.poly.begin());
  } else {
    s.src = piece.src;
  }
  if (piece.volume) {
    s.volume = true;
    const ClusterNode& node = c_nodes[piece.cluster];
    double sum = 0.0;
    for (uint32_t i = node.begin; i < node.end; ++i) {
      const uint32_t q = cluster_patch[i];
      for (int a = 0; a < 3; ++a) {
        const double part = prep.normal[q][a] * prep.area[q];
        s.lobe[2 * a + (part < 0.0 ? 1 : 0)] += std::abs(part);
        sum += std::abs(part);
      }
    }
    if (sum > 0.0)
      for (double& x : s.lobe) x /= sum;
  }
  return s;
}

// Calls fn(index into grid_light, position) for the grid points of element e's patch that e
// owns: every point of the patch belongs to exactly one leaf (a point on an outline to the one
// it falls in when moved a hair towards the patch's middle and then in a direction along no
// outline), so that no point takes a shooter's light twice from two receivers served by
// different pieces of it.
template <typename Fn>
void Solver::Impl::for_grid_points(uint32_t e, Fn&& fn) const {
  const uint32_t p = e_patch[e];
  const uint32_t g = p_grid_n[p];
  if (g == 0) return;
  const std::array<glm::dvec2, 4>& t = e_uv[e];
  const bool quad = corner_count(e) == 4;
  const uint32_t n = quad ? 4 : 3;
  glm::dvec2 lo(1.0), hi(0.0);
  for (uint32_t i = 0; i < n; ++i) {
    lo = glm::min(lo, t[i]);
    hi = glm::max(hi, t[i]);
  }
  const glm::dvec2 middle = quad ? glm::dvec2(0.5) : glm::dvec2(1.0 / 3.0);
  const double steps = static_cast<double>(g - 1);
  constexpr double kEps = 1e-9;
  const auto first = [&](double v) { return static_cast<uint32_t>(std::max(0.0, std::ceil(v * steps - kEps))); };
  const auto last = [&](double v) { return static_cast<uint32_t>(std::min(steps, std::floor(v * steps + kEps))); };
  Corners c;
  corners_of(p_root[p], c);
  for (uint32_t j = first(lo.y); j <= last(hi.y); ++j)
    for (uint32_t i = first(lo.x); i <= last(hi.x); ++i) {
      const glm::dvec2 uv(i / steps, j / steps);
      const glm::dvec2 q = uv + 1e-7 * (middle - uv) + glm::dvec2(3.7e-11, 7.1e-11);
      bool inside = true;
      for (uint32_t k = 0; k < n && inside; ++k) {
        const glm::dvec2 a = t[k], b = t[(k + 1) % n];
        inside = (b.x - a.x) * (q.y - a.y) - (b.y - a.y) * (q.x - a.x) > 0.0;
      }
      if (!inside) continue;
      const glm::dvec3 x = quad ? (1 - uv.x) * (1 - uv.y) * c[0] + uv.x * (1 - uv.y) * c[1] + uv.x * uv.y * c[2] +
                                      (1 - uv.x) * uv.y * c[3]
                                : c[0] + uv.x * (c[1] - c[0]) + uv.y * (c[2] - c[0]);
      fn(p_grid_begin[p] + j * g + i, x);
    }
}

// Element e's points take the current shooter's light: `radiosity` (rho dB, mean over channels,
// times the share of the shooter the hemicube found visible from e) times the unoccluded form
// factor from each point to the shooter. A point on the outline of two receivers takes it once.
void Solver::Impl::take_on_grid(uint32_t e, double radiosity) {
  const uint32_t p = e_patch[e];
  const glm::dvec3 normal = prep.normal[p];
  // Points on an outline shared with a surface at an angle (a room's corner) lie in its plane and
  // would see it edge-on: they look from a little inside their patch and in front of it instead.
  const glm::dvec3 centre = e_centre[p_root[p]];
  const glm::dvec3 lift = normal * (kGridLift * prep.diagonal);
  for_grid_points(e, [&](uint32_t i, const glm::dvec3& x) {
    // A point shared by elements that threads hand light to at once (distribute) is taken by the
    // first: each shooter lights it once, with the same radiosity from any of them.
    std::atomic_ref<uint32_t> claim(grid_stamp[i]);
    uint32_t was = claim.load(std::memory_order_relaxed);
    if (was == grid_shooter || !claim.compare_exchange_strong(was, grid_shooter, std::memory_order_relaxed)) return;
    const glm::dvec3 at = x + kGridInset * (centre - x) + lift;
    grid_light[i] += static_cast<float>(radiosity * shooter_light(*shooter_shape, at, normal));
  });
}

// Whether an emitting patch lies within e_radius[e] / kLightPoolReach of element e's centre: its
// pool on e's surface is then about as narrow as e (a glowing sphere 5 cm over a floor lights it
// 1 to 2 m around, where elements at AEPS of the scene's area were 0.45 m).
bool Solver::Impl::near_emitter(uint32_t e) const {
  const double reach = e_radius[e] / kLightPoolReach;
  const glm::dvec3 lo = e_centre[e] - reach, hi = e_centre[e] + reach;
  auto near = [&](const glm::dvec3& a, const glm::dvec3& b) { return boxes_meet(lo, hi, a, b, 0.0); };
  return find_patch(near, [&](uint32_t q) {
    if (channel_sum(patches[q].emission) <= 0.0) return false;
    const glm::dvec3 closest = glm::clamp(e_centre[e], p_lo[q], p_hi[q]);
    return glm::distance(closest, e_centre[e]) < reach;
  });
}

// Splits the elements whose grid points differ by more than the radiosity tolerance, and their
// children likewise, down to the smallest element that may split; from each surface's root down,
// so that an element this pass split for another reason is noted too (pool_splits: the solve
// proper makes only those splits). Walked from the leaves, a pool that this pass had split
// finely for its own shots was found in none of its small leaves, and the solve proper started
// without it: a floor under a glowing sphere 5 cm above it kept four 2.5 m elements under the
// sphere, each shot of the sphere's 1 104 faces too weak alone to split them. Returns whether
// anything split.
bool Solver::Impl::find_pools() {
  pools_looked = true;
  std::vector<uint32_t> todo;
  for (uint32_t p = 0; p < patches.size(); ++p)
    if (p_grid_n[p] != 0) todo.push_back(p_root[p]);
  bool any = false;
  while (!todo.empty()) {
    const uint32_t e = todo.back();
    todo.pop_back();
    // Under AEPS, near an emitter (kLightPoolReach), one level further: as far as the grid sees.
    if (e_area[e] < min_split_area() && (e_area[e] < 4.0 * min_sharp_split_area() || !near_emitter(e))) continue;
    double lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
    uint32_t count = 0;
    double sum = 0.0;
    for_grid_points(e, [&](uint32_t i, const glm::dvec3&) {
      lo = std::min(lo, static_cast<double>(grid_light[i]));
      hi = std::max(hi, static_cast<double>(grid_light[i]));
      sum += grid_light[i];
      ++count;
    });
    if (count < 4 || hi - lo <= kPoolFloor * pool_tolerance || hi - lo <= kPoolShare * sum / count) continue;
    if (e_child[e] == kNone) {
      if (patches.size() + 3 * (stats.splits + 1) > params.max_elements) {
        stats.element_limit = true;
        break;
      }
      split(e);  // `leaves` holds it or an ancestor: replace_split below expands them
      any = true;
    }
    pool_splits.push_back(e);
    ++stats.splits_pools;
    for (uint32_t k = 0; k < 4; ++k) todo.push_back(e_child[e] + k);
  }
  if (any) {
    replace_split(leaves);
    stats.elements = leaves.size();
  }
  return any;
}

}  // namespace hemibake::solver
