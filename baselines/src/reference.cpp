// Path-traced radiosity: B(x) = E(x) + rho(x) * integral over surfaces y of B(y) cos cos' V / (pi r^2).
// At every path vertex the emitters are sampled directly (a point on an emitting triangle, chosen by
// emitted power, and a shadow ray: next-event estimation); the path goes on in a cosine-weighted
// direction, counting only reflected light where it lands (emission there was already sampled), and
// ends by Russian roulette on the reflectance.
//
// Punctual lights (KHR_lights_punctual) and the uniform sky follow the solver's definitions in
// solver.h, evaluated here by rays instead of projections. At every path vertex each light is
// checked with one shadow ray: a point or spot light at distance d and cosine cos_x brings the
// irradiance I cos_x / d^2 (times the spot's falloff t^2 and the range window), a directional
// light I cos_x when nothing lies toward it. A path direction that meets no surface sees the sky:
// the cosine-weighted estimate of its irradiance is pi S.
#include "hemibake/baselines/reference.h"

#include "shadow_ray.h"

#include <embree3/rtcore.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <thread>

namespace hemibake::baselines {

namespace {

// twin[p] = the patch with p's corners facing the other way, or p when there is none.
void find_twins(const solver::Scene& scene, const std::vector<glm::dvec3>& normal, std::vector<uint32_t>& twin) {
  std::map<std::vector<double>, std::vector<uint32_t>> by_corners;
  for (uint32_t p = 0; p < scene.patches.size(); ++p) {
    const auto& patch = scene.patches[p];
    std::vector<std::array<double, 3>> c;
    for (uint32_t k = 0; k < patch.corner_count; ++k) c.push_back({patch.corners[k].x, patch.corners[k].y, patch.corners[k].z});
    std::sort(c.begin(), c.end());
    std::vector<double> key;
    for (const auto& v : c) key.insert(key.end(), v.begin(), v.end());
    by_corners[key].push_back(p);
  }
  twin.resize(scene.patches.size());
  for (uint32_t p = 0; p < twin.size(); ++p) twin[p] = p;
  for (const auto& [key, list] : by_corners)
    for (uint32_t a : list)
      for (uint32_t b : list)
        if (glm::dot(normal[a], normal[b]) < 0.0) twin[a] = b;
}

}  // namespace

struct Reference::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::vector<uint32_t> tri_patch;  // triangle -> patch
  std::vector<glm::dvec3> normal;   // per patch
  // A double-sided surface is two patches on the same corners facing apart; a ray meets both at
  // one distance and Embree may report either. twin[q] is q's other side (or q itself).
  std::vector<uint32_t> twin;
  const solver::Scene* input = nullptr;
  double eps = 1e-6;
  // Emitting triangles: corners, patch, and the cumulative distribution of their emitted power.
  struct Emitter {
    glm::dvec3 a, b, c;
    uint32_t patch;
    double area;
  };
  std::vector<Emitter> emitters;
  std::vector<double> cdf;
  double total_power = 0.0;
  // The irradiance the punctual lights bring to x (normal n), each seen through a shadow ray.
  glm::dvec3 light_irradiance(const glm::dvec3& x, const glm::dvec3& n) const;
};

glm::dvec3 Reference::Impl::light_irradiance(const glm::dvec3& x, const glm::dvec3& n) const {
  glm::dvec3 sum(0.0);
  const glm::dvec3 from = x + n * eps;
  for (const solver::Light& l : input->lights) {
    if (l.type == solver::Light::Type::kDirectional) {
      const glm::dvec3 to_light = -glm::normalize(l.direction);
      const double cos_x = glm::dot(n, to_light);
      if (cos_x > 0.0 && detail::unoccluded(scene, from, to_light, std::numeric_limits<double>::infinity()))
        sum += l.intensity * cos_x;
      continue;
    }
    // The light's geometry is x's own; only the shadow ray leaves from the lifted point.
    const glm::dvec3 to = l.position - x;
    const double d2 = glm::dot(to, to);
    if (!(d2 > 0.0)) continue;
    const double d = std::sqrt(d2);
    const glm::dvec3 dir = to / d;
    const double cos_x = glm::dot(n, dir);
    if (cos_x <= 0.0) continue;
    double scale = cos_x / d2;
    if (l.range > 0.0) scale *= std::clamp(1.0 - std::pow(d / l.range, 4.0), 0.0, 1.0);
    if (l.type == solver::Light::Type::kSpot) {
      const double cos_outer = std::cos(l.outer_cone), cos_inner = std::cos(l.inner_cone);
      const double t = std::clamp((glm::dot(-dir, glm::normalize(l.direction)) - cos_outer) / std::max(1e-12, cos_inner - cos_outer), 0.0, 1.0);
      scale *= t * t;
    }
    if (scale <= 0.0) continue;
    const glm::dvec3 ray = l.position - from;
    const double length = glm::length(ray);
    if (detail::unoccluded(scene, from, ray / length, length * (1.0 - 1e-6))) sum += l.intensity * scale;
  }
  return sum;
}

Reference::Reference(const solver::Scene& scene) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.input = &scene;
  s.device = rtcNewDevice(nullptr);
  s.scene = rtcNewScene(s.device);
  std::vector<float> vertices;
  std::vector<uint32_t> indices;
  glm::dvec3 lo(1e300), hi(-1e300);
  for (uint32_t p = 0; p < scene.patches.size(); ++p) {
    const auto& patch = scene.patches[p];
    const uint32_t base = static_cast<uint32_t>(vertices.size() / 3);
    for (uint32_t c = 0; c < patch.corner_count; ++c) {
      for (int k = 0; k < 3; ++k) vertices.push_back(static_cast<float>(patch.corners[c][k]));
      lo = glm::min(lo, patch.corners[c]);
      hi = glm::max(hi, patch.corners[c]);
    }
    for (uint32_t t = 1; t + 1 < patch.corner_count; ++t) {
      indices.insert(indices.end(), {base, base + t, base + t + 1});
      s.tri_patch.push_back(p);
      const double power = (patch.emission.x + patch.emission.y + patch.emission.z);
      if (power > 0.0) {
        const double area = 0.5 * glm::length(glm::cross(patch.corners[t] - patch.corners[0], patch.corners[t + 1] - patch.corners[0]));
        s.emitters.push_back({patch.corners[0], patch.corners[t], patch.corners[t + 1], p, area});
        s.total_power += power * area;
        s.cdf.push_back(s.total_power);
      }
    }
    const glm::dvec3 n = glm::cross(patch.corners[1] - patch.corners[0], patch.corners[2] - patch.corners[0]);
    s.normal.push_back(glm::normalize(n));
  }
  s.eps = 1e-5 * glm::length(hi - lo);
  find_twins(scene, s.normal, s.twin);
  RTCGeometry geom = rtcNewGeometry(s.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                         3 * sizeof(float), vertices.size() / 3));
  std::copy(vertices.begin(), vertices.end(), vb);
  auto* ib = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                            3 * sizeof(uint32_t), indices.size() / 3));
  std::copy(indices.begin(), indices.end(), ib);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(s.scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(s.scene);
}

Reference::~Reference() {
  rtcReleaseScene(impl_->scene);
  rtcReleaseDevice(impl_->device);
}

namespace {

// The emitter sampling's density, per solid angle, of a point of an emitting patch with emission
// `e` at squared distance r2 seen at cosine cos_y: the patch is chosen by power, the point by area.
double light_pdf(double total_power, const glm::dvec3& e, double r2, double cos_y) {
  return cos_y > 0.0 ? (e.x + e.y + e.z) * r2 / (total_power * cos_y) : 0.0;
}

// The power heuristic (Veach): the weight of a sample drawn with density a, where b also draws it.
double mis_weight(double a, double b) { return a * a / (a * a + b * b); }

}  // namespace

ReferencePoint Reference::radiosity_at(uint32_t patch, const glm::dvec3& x0, uint32_t samples, uint64_t seed) const {
  const Impl& s = *impl_;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  glm::dvec3 sum(0.0), sum2(0.0);
  const auto& p0 = s.input->patches[patch];
  for (uint32_t i = 0; i < samples; ++i) {
    // One path: the light reaching x0's surface, weighted by the reflectances along the way.
    glm::dvec3 value(0.0), weight = p0.reflectance;
    glm::dvec3 x = x0;
    glm::dvec3 n = s.normal[patch];
    for (int bounce = 0; bounce < 64; ++bounce) {
      if (!s.input->lights.empty()) value += weight * s.light_irradiance(x, n);
      // Direct light: a point on an emitter, chosen by power, seen through a shadow ray.
      if (!s.emitters.empty()) {
        const double pick = uni(rng) * s.total_power;
        const size_t k = std::min<size_t>(std::lower_bound(s.cdf.begin(), s.cdf.end(), pick) - s.cdf.begin(), s.emitters.size() - 1);
        const auto& em = s.emitters[k];
        double u = uni(rng), v = uni(rng);
        if (u + v > 1.0) {
          u = 1.0 - u;
          v = 1.0 - v;
        }
        const glm::dvec3 y = em.a + u * (em.b - em.a) + v * (em.c - em.a);
        const glm::dvec3 to = y - x;
        const double r2 = glm::dot(to, to);
        const glm::dvec3 dir = to / std::sqrt(r2);
        const double cos_x = glm::dot(n, dir), cos_y = -glm::dot(s.normal[em.patch], dir);
        if (cos_x > 0.0 && cos_y > 0.0) {
          // The shadow ray runs between the two points lifted off their surfaces by eps, so that
          // it stays in front of both planes. (Lifting only x and aiming along x -> y made the
          // ray meet the emitter's plane eps / cos_y short of y: at grazing angles every sample was
          // occluded by the emitter itself, and a ceiling 1 m beside a lamp facing it got none of
          // its direct light.)
          const glm::dvec3 from = x + n * s.eps, target = y + s.normal[em.patch] * s.eps;
          const glm::dvec3 seg = target - from;
          const double seg_len = glm::length(seg);
          if (detail::unoccluded(s.scene, from, seg / seg_len, seg_len * (1.0 - 1e-4))) {
            const auto& pe = s.input->patches[em.patch];
            const double power = (pe.emission.x + pe.emission.y + pe.emission.z) * em.area;
            const double prob = power / s.total_power;  // of choosing this triangle
            const double w = mis_weight(light_pdf(s.total_power, pe.emission, r2, cos_y), cos_x / std::numbers::pi);
            value += weight * pe.emission * (w * cos_x * cos_y * em.area / (std::numbers::pi * r2 * prob));
          }
        }
      }
      // Cosine-weighted direction about n.
      const double r1 = uni(rng), r2 = uni(rng);
      const double phi = 2.0 * std::numbers::pi * r1, r = std::sqrt(r2);
      const glm::dvec3 t = glm::normalize(std::abs(n.x) < 0.9 ? glm::cross(n, glm::dvec3(1, 0, 0)) : glm::cross(n, glm::dvec3(0, 1, 0)));
      const glm::dvec3 b = glm::cross(n, t);
      const glm::dvec3 d = r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(1.0 - r2) * n;
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      RTCRayHit rh{};
      rh.ray.org_x = static_cast<float>(x.x + n.x * s.eps);
      rh.ray.org_y = static_cast<float>(x.y + n.y * s.eps);
      rh.ray.org_z = static_cast<float>(x.z + n.z * s.eps);
      rh.ray.dir_x = static_cast<float>(d.x);
      rh.ray.dir_y = static_cast<float>(d.y);
      rh.ray.dir_z = static_cast<float>(d.z);
      rh.ray.tnear = 0.0f;
      rh.ray.tfar = std::numeric_limits<float>::infinity();
      rh.ray.mask = 0xffffffffu;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(s.scene, &ctx, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {  // escaped: the sky
        value += weight * (std::numbers::pi * s.input->sky);
        break;
      }
      uint32_t q = s.tri_patch[rh.hit.primID];
      if (glm::dot(s.normal[q], d) >= 0.0) q = s.twin[q];
      const glm::dvec3 nq = s.normal[q];
      if (glm::dot(nq, d) >= 0.0) break;  // the back of a one-sided surface: black
      const auto& pq = s.input->patches[q];
      // An emitter met by the cosine-weighted direction counts too, weighted against the emitter
      // sampling above: close to a lamp (a ceiling 1 mm over it) only this finds its light.
      if (pq.emission != glm::dvec3(0.0)) {
        const double dist = static_cast<double>(rh.ray.tfar) + s.eps;
        const double w = mis_weight(glm::dot(n, d) / std::numbers::pi,
                                    light_pdf(s.total_power, pq.emission, dist * dist, -glm::dot(nq, d)));
        value += weight * pq.emission * w;
      }
      // Russian roulette on the reflectance's mean keeps the estimate unbiased.
      const double keep = std::min(0.95, (pq.reflectance.x + pq.reflectance.y + pq.reflectance.z) / 3.0);
      if (keep <= 0.0 || uni(rng) >= keep) break;
      weight *= pq.reflectance / keep;
      x = x + d * static_cast<double>(rh.ray.tfar);
      n = nq;
    }
    sum += value;
    sum2 += value * value;
  }
  ReferencePoint out;
  const double ns = samples;
  const glm::dvec3 mean = sum / ns;
  out.radiosity = p0.emission + mean;
  const glm::dvec3 var = glm::max(sum2 / ns - mean * mean, glm::dvec3(0.0));
  out.std_error = glm::sqrt(var / ns);
  return out;
}

ReferenceBakeStats apply_reference(const solver::Scene& scene, solver::Mesh& mesh, uint32_t samples, uint32_t threads,
                                   const std::function<void(double)>& progress, const solver::CancelToken* cancel) {
  const auto t0 = std::chrono::steady_clock::now();
  ReferenceBakeStats stats;
  const Reference reference(scene);
  // Every vertex gets its own light, those added on an edge for another surface's point too.
  mesh.interpolated.clear();
  std::vector<uint32_t> patch_of(mesh.positions.size(), UINT32_MAX);
  for (const auto& el : mesh.elements)
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) patch_of[mesh.boundary[i]] = el.patch;
  std::vector<double> std_error(mesh.positions.size(), 0.0);
  const size_t count = mesh.positions.size();
  constexpr size_t kChunk = 16;
  std::atomic<size_t> next{0}, done{0};
  std::atomic<bool> stop{false};
  auto work = [&] {
    for (size_t begin; !stop.load(std::memory_order_relaxed) && (begin = next.fetch_add(kChunk)) < count;) {
      const size_t end = std::min(count, begin + kChunk);
      for (size_t v = begin; v < end; ++v) {
        if (patch_of[v] == UINT32_MAX) continue;
        const ReferencePoint r = reference.radiosity_at(patch_of[v], mesh.positions[v], samples, v + 1);
        mesh.radiosity[v] = r.radiosity;
        std_error[v] = (r.std_error.x + r.std_error.y + r.std_error.z) / 3.0;
      }
      done.fetch_add(end - begin);
    }
  };
  const uint32_t n = threads != 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> pool;
  for (uint32_t t = 0; t < n; ++t) pool.emplace_back(work);
  auto last = std::chrono::steady_clock::now();
  while (done.load() < count && !stop.load()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (cancel != nullptr && cancel->cancelled()) stop.store(true);
    if (progress && std::chrono::steady_clock::now() - last > std::chrono::milliseconds(100)) {
      last = std::chrono::steady_clock::now();
      progress(static_cast<double>(done.load()) / static_cast<double>(count));
    }
  }
  for (auto& th : pool) th.join();
  stats.cancelled = stop.load();
  for (auto& el : mesh.elements) {
    el.radiosity = glm::dvec3(0.0);
    for (uint32_t k = 0; k < el.corner_count; ++k) el.radiosity += mesh.radiosity[el.corners[k]] / static_cast<double>(el.corner_count);
  }
  for (double se : std_error) stats.largest_std_error = std::max(stats.largest_std_error, se);
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return stats;
}

}  // namespace hemibake::baselines
