#include "display_error.h"

#include "hemibake/baselines/reference.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <thread>

namespace hemibake::bench {
namespace {

double channel_sum(const glm::dvec3& v) { return v.x + v.y + v.z; }

// mark_pressed: in contact within this share of the scene's diagonal, facing the other way within
// this cosine (2.6 degrees).
constexpr double kContact = 1e-6;
constexpr double kFacing = 0.999;

// Runs fn(i) for i in [0, n) on `threads` threads (0 = all cores).
template <typename Fn>
void parallel(size_t n, uint32_t threads, Fn&& fn) {
  const uint32_t count = threads != 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
  std::atomic<size_t> next{0};
  std::vector<std::thread> pool;
  for (uint32_t t = 0; t < count; ++t)
    pool.emplace_back([&] {
      for (size_t i; (i = next.fetch_add(1)) < n;) fn(i);
    });
  for (auto& th : pool) th.join();
}

// A uniformly distributed point on a patch (a quad as its two triangles 0-1-2 and 0-2-3).
glm::dvec3 point_on(const solver::Patch& p, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  auto tri_area = [&](int a, int b, int c) {
    return 0.5 * glm::length(glm::cross(p.corners[b] - p.corners[a], p.corners[c] - p.corners[a]));
  };
  int b = 1, c = 2;
  if (p.corner_count == 4) {
    const double a0 = tri_area(0, 1, 2), a1 = tri_area(0, 2, 3);
    if (uni(rng) * (a0 + a1) >= a0) b = 2, c = 3;
  }
  double u = uni(rng), v = uni(rng);
  if (u + v > 1.0) u = 1.0 - u, v = 1.0 - v;
  return p.corners[0] + u * (p.corners[b] - p.corners[0]) + v * (p.corners[c] - p.corners[0]);
}

double patch_area(const solver::Patch& p) {
  double a = 0.0;
  for (uint32_t k = 1; k + 1 < p.corner_count; ++k)
    a += 0.5 * glm::length(glm::cross(p.corners[k] - p.corners[0], p.corners[k + 1] - p.corners[0]));
  return a;
}

}  // namespace

std::vector<SurfacePoint> reference_points(const solver::Scene& scene, const ReferenceOptions& options) {
  std::vector<double> cdf;
  std::vector<uint32_t> candidates;
  double total = 0.0;
  for (uint32_t i = 0; i < scene.patches.size(); ++i) {
    const auto& p = scene.patches[i];
    if (channel_sum(p.emission) > 0.0) continue;
    total += patch_area(p);
    cdf.push_back(total);
    candidates.push_back(i);
  }
  std::vector<SurfacePoint> points;
  if (candidates.empty()) return points;
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  for (uint32_t k = 0; k < options.points; ++k) {
    const size_t c = std::min<size_t>(std::lower_bound(cdf.begin(), cdf.end(), uni(rng) * total) - cdf.begin(),
                                      candidates.size() - 1);
    SurfacePoint sp;
    sp.patch = candidates[c];
    const auto& p = scene.patches[sp.patch];
    sp.position = point_on(p, rng);
    sp.normal = glm::normalize(glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]));
    points.push_back(sp);
  }
  trace_reference(scene, points, options);
  mark_pressed(scene, points);
  return points;
}

void trace_reference(const solver::Scene& scene, std::vector<SurfacePoint>& points, const ReferenceOptions& options) {
  // A first pass gives every point a value; the floor for dark points is 5 % of their mean.
  const baselines::Reference reference(scene);
  constexpr uint32_t kBatch = 512;
  std::vector<glm::dvec3> sum(points.size(), glm::dvec3(0.0));
  std::vector<double> var_sum(points.size(), 0.0);  // of the batch means' channel sums
  for (size_t i = 0; i < points.size(); ++i) {
    const double batches = static_cast<double>(points[i].samples / kBatch);
    sum[i] = points[i].reference * batches;
    var_sum[i] = points[i].std_error * points[i].std_error * batches * batches;
  }
  auto trace = [&](size_t i) {
    const uint64_t batch = points[i].samples / kBatch;
    const auto r = reference.radiosity_at(points[i].patch, points[i].position, kBatch,
                                          options.seed * 0x9e3779b97f4a7c15ull + i * 65537 + batch);
    sum[i] += r.radiosity;
    var_sum[i] += glm::dot(r.std_error, r.std_error);
    points[i].samples += kBatch;
    const double batches = static_cast<double>(points[i].samples / kBatch);
    points[i].reference = sum[i] / batches;
    points[i].std_error = std::sqrt(var_sum[i]) / batches;
  };
  parallel(points.size(), options.threads, [&](size_t i) {
    if (points[i].samples == 0) trace(i);
  });
  double mean = 0.0;
  for (const auto& p : points) mean += channel_sum(p.reference) / static_cast<double>(points.size());
  const double floor = 0.05 * mean;
  parallel(points.size(), options.threads, [&](size_t i) {
    while (points[i].samples < options.max_samples &&
           points[i].std_error > options.max_std_error * std::max(channel_sum(points[i].reference), floor))
      trace(i);
  });
}

double scene_diagonal(const solver::Scene& scene) {
  if (scene.patches.empty()) return 0.0;
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
  for (const auto& p : scene.patches)
    for (uint32_t k = 0; k < p.corner_count; ++k) {
      lo = glm::min(lo, p.corners[k]);
      hi = glm::max(hi, p.corners[k]);
    }
  return glm::length(hi - lo);
}

void mark_pressed(const solver::Scene& scene, std::vector<SurfacePoint>& points) {
  // In contact: as close as single-precision positions of a scene's size put two faces that touch.
  const double contact = kContact * scene_diagonal(scene);
  auto same_corners = [&](const solver::Patch& a, const solver::Patch& b) {
    if (a.corner_count != b.corner_count) return false;
    for (uint32_t i = 0; i < a.corner_count; ++i) {
      bool found = false;
      for (uint32_t j = 0; j < b.corner_count && !found; ++j)
        found = glm::length(a.corners[i] - b.corners[j]) <= contact;
      if (!found) return false;
    }
    return true;
  };
  // The patch's polygon (convex, as patches are) holds x, which lies in its plane of normal n.
  auto holds = [](const solver::Patch& p, const glm::dvec3& n, const glm::dvec3& x) {
    for (uint32_t k = 0; k < p.corner_count; ++k) {
      const glm::dvec3& a = p.corners[k];
      const glm::dvec3& b = p.corners[(k + 1) % p.corner_count];
      if (glm::dot(glm::cross(b - a, x - a), n) < 0.0) return false;
    }
    return true;
  };
  parallel(points.size(), 0, [&](size_t i) {
    SurfacePoint& sp = points[i];
    sp.pressed = false;
    for (uint32_t q = 0; q < scene.patches.size() && !sp.pressed; ++q) {
      if (q == sp.patch) continue;
      const solver::Patch& p = scene.patches[q];
      glm::dvec3 n = glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]);
      const double len = glm::length(n);
      if (len <= 0.0) continue;
      n /= len;
      if (glm::dot(n, sp.normal) > -kFacing || std::abs(glm::dot(sp.position - p.corners[0], n)) > contact) continue;
      if (!holds(p, n, sp.position) || same_corners(p, scene.patches[sp.patch])) continue;
      sp.pressed = true;
    }
  });
}

double plane_slack(const solver::Mesh& baked) {
  if (baked.positions.empty()) return 0.0;
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
  for (const glm::dvec3& v : baked.positions) {
    lo = glm::min(lo, v);
    hi = glm::max(hi, v);
  }
  return 1e-4 * glm::length(hi - lo);
}

bool displayed_value(const solver::Mesh& baked, const glm::dvec3& x, const glm::dvec3& normal, double slack,
                     glm::dvec3& out) {
  // The triangle containing x on the side facing `normal`, nearest to x's plane (within 1e-3 of its
  // size plus `slack`).
  double best = std::numeric_limits<double>::max();
  bool found = false;
  auto consider = [&](const glm::dvec3& pa, const glm::dvec3& pb, const glm::dvec3& pc, const glm::dvec3& ba,
                      const glm::dvec3& bb, const glm::dvec3& bc) {
    const glm::dvec3 n = glm::cross(pb - pa, pc - pa);
    const double n2 = glm::dot(n, n);
    if (n2 <= 0.0) return;
    const double len = std::sqrt(n2);
    if (glm::dot(n, normal) < 0.99 * len) return;
    const double dist = std::abs(glm::dot(x - pa, n)) / len;
    const double size = std::max({glm::length(pb - pa), glm::length(pc - pa), glm::length(pc - pb)});
    if (dist > 1e-3 * size + slack + 1e-9 || dist >= best) return;
    // Barycentric coordinates of x projected onto the plane.
    const glm::dvec3 q = x - pa;
    const double wb = glm::dot(glm::cross(q, pc - pa), n) / n2;
    const double wc = glm::dot(glm::cross(pb - pa, q), n) / n2;
    const double wa = 1.0 - wb - wc;
    constexpr double kSlack = -1e-7;
    if (wa < kSlack || wb < kSlack || wc < kSlack) return;
    best = dist;
    found = true;
    out = wa * ba + wb * bb + wc * bc;
  };
  const auto& p = baked.positions;
  const auto& b = baked.radiosity;
  for (const auto& el : baked.elements) {
    const uint32_t nb = el.boundary_end - el.boundary_begin;
    if (nb == 3 || nb == 0) {
      const auto& c = el.corners;
      consider(p[c[0]], p[c[1]], p[c[2]], b[c[0]], b[c[1]], b[c[2]]);
      continue;
    }
    // As the writer shows a loop of more than three vertices: a fan from its centre, which takes
    // the mean of the loop's own (not interpolated) vertices.
    const uint32_t* loop = baked.boundary.data() + el.boundary_begin;
    glm::dvec3 centre(0.0), value(0.0);
    uint32_t own = 0;
    for (uint32_t k = 0; k < nb; ++k) {
      if (loop[k] < baked.interpolated.size() && baked.interpolated[loop[k]]) continue;
      centre += p[loop[k]];
      value += b[loop[k]];
      ++own;
    }
    centre /= static_cast<double>(own);
    value /= static_cast<double>(own);
    for (uint32_t k = 0; k < nb; ++k)
      consider(centre, p[loop[k]], p[loop[(k + 1) % nb]], value, b[loop[k]], b[loop[(k + 1) % nb]]);
  }
  return found;
}

DisplayError displayed_error(const std::vector<SurfacePoint>& points, const solver::Mesh& baked) {
  DisplayError out;
  if (points.empty()) return out;
  double mean = 0.0;
  for (const auto& p : points) mean += channel_sum(p.reference) / static_cast<double>(points.size());
  const double floor = 0.05 * mean;
  out.errors.assign(points.size(), 0.0);
  std::vector<glm::dvec3> shown(points.size(), glm::dvec3(0.0));
  std::vector<uint8_t> hit(points.size(), 0);
  const double slack = plane_slack(baked);
  parallel(points.size(), 0,
           [&](size_t i) { hit[i] = displayed_value(baked, points[i].position, points[i].normal, slack, shown[i]); });
  double ref_sum = 0.0;
  for (size_t i = 0; i < points.size(); ++i) {
    const double ref = channel_sum(points[i].reference), denom = std::max(ref, floor);
    out.worst_std_error = std::max(out.worst_std_error, points[i].std_error / denom);
    ref_sum += ref;
    // A point no baked triangle covers shows nothing: the writer leaves out the insides of closed
    // meshes, which no one outside them sees (their reference is dark); anywhere else it is the
    // whole reference wrong.
    if (!hit[i]) {
      ++out.missed;
      out.missed_light += ref;
    }
    out.errors[i] = std::abs(channel_sum(shown[i]) - ref) / denom;
  }
  auto summary = [&](auto&& take) {
    ErrorSummary s;
    std::vector<double> sorted;
    double bake = 0.0, ref = 0.0;
    for (size_t i = 0; i < points.size(); ++i) {
      if (!take(i)) continue;
      sorted.push_back(out.errors[i]);
      bake += channel_sum(shown[i]);
      ref += channel_sum(points[i].reference);
    }
    if (sorted.empty()) return s;
    std::sort(sorted.begin(), sorted.end());
    auto quantile = [&](double q) {
      return sorted[std::min(sorted.size() - 1, static_cast<size_t>(q * sorted.size()))];
    };
    s.points = static_cast<uint32_t>(sorted.size());
    s.median = quantile(0.5);
    s.p90 = quantile(0.9);
    s.max = sorted.back();
    s.mean_ratio = ref > 0.0 ? bake / ref : 0.0;
    return s;
  };
  const ErrorSummary all = summary([](size_t) { return true; });
  out.median = all.median;
  out.p90 = all.p90;
  out.max = all.max;
  out.mean_ratio = all.mean_ratio;
  out.missed_light = ref_sum > 0.0 ? out.missed_light / ref_sum : 0.0;
  out.hidden.assign(points.size(), 0);
  for (size_t i = 0; i < points.size(); ++i)
    out.hidden[i] = channel_sum(points[i].reference) == 0.0 && (points[i].pressed || !hit[i]);
  out.seen = summary([&](size_t i) { return !out.hidden[i]; });
  return out;
}

}  // namespace hemibake::bench
