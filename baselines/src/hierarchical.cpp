// Hierarchical radiosity after Hanrahan, Salzman and Aupperle (1991). For every pair of patches that
// face each other, Refine(p, q) estimates the form factor of the interaction both ways with the
// disk approximation F = A cos cos' / (pi r^2 + A); while the larger exceeds FEPS, the larger
// element (if it may still be split under AEPS) is subdivided and the children are refined
// against the other; otherwise a link is made, its visibility the fraction of `rays` unoccluded
// rays between random points of the two elements. Solving alternates gathering over the links
// (B_gathered = rho * sum F V B_source) with push-pull down and up the quadtrees.
//
// Threads: patch pairs are refined in parallel. A node's children are made once, under a lock,
// and published through an atomic pointer; links are added under a lock per node. Whether a node
// splits depends only on geometry and each top-level pair draws its visibility rays from its own
// random stream, so after each node's links are sorted by source the solution does not depend on
// the number of threads or on scheduling.
#include "hemibake/baselines/hierarchical.h"

#include "shadow_ray.h"

#include <embree3/rtcore.h>
#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <thread>
#include <vector>

namespace hemibake::baselines {
namespace {

using Corners = std::array<glm::dvec3, 4>;
using Clock = std::chrono::steady_clock;

struct Node;

struct Link {
  const Node* source;
  double ff;  // F(receiver -> source) * visibility
};

struct Node {
  Corners c{};
  uint32_t n = 4;
  uint32_t patch = 0;
  uint32_t id = 0;  // depth-first order, assigned after linking
  double area = 0.0;
  glm::dvec3 centre{0.0};
  std::atomic<Node*> kids{nullptr};  // four children, or null
  std::unique_ptr<Node[]> own_kids;
  std::vector<Link> links;
  glm::dvec3 b{0.0}, gathered{0.0};

  void set(const Corners& corners, uint32_t count, uint32_t p) {
    c = corners;
    n = count;
    patch = p;
    area = n == 4 ? 0.5 * glm::length(glm::cross(c[2] - c[0], c[3] - c[1]))
                  : 0.5 * glm::length(glm::cross(c[1] - c[0], c[2] - c[0]));
    centre = glm::dvec3(0.0);
    for (uint32_t k = 0; k < n; ++k) centre += c[k] / static_cast<double>(n);
  }
  Node* children() const { return kids.load(std::memory_order_acquire); }
};

Corners child(const Corners& c, uint32_t n, uint32_t k) {
  if (n == 4) {
    const glm::dvec3 m01 = 0.5 * (c[0] + c[1]), m12 = 0.5 * (c[1] + c[2]), m23 = 0.5 * (c[2] + c[3]), m30 = 0.5 * (c[3] + c[0]);
    const glm::dvec3 ctr = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    const std::array<Corners, 4> kids{{{c[0], m01, ctr, m30}, {m01, c[1], m12, ctr}, {ctr, m12, c[2], m23}, {m30, ctr, m23, c[3]}}};
    return kids[k];
  }
  const glm::dvec3 m01 = 0.5 * (c[0] + c[1]), m12 = 0.5 * (c[1] + c[2]), m20 = 0.5 * (c[2] + c[0]);
  const std::array<Corners, 4> kids{{{c[0], m01, m20, {}}, {m01, c[1], m12, {}}, {m20, m12, c[2], {}}, {m12, m20, m01, {}}}};
  return kids[k];
}

// splitmix64: a small, fast random stream per patch pair.
struct Random {
  uint64_t state;
  double uniform() {
    uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    z ^= z >> 31;
    return static_cast<double>(z >> 11) * 0x1.0p-53;
  }
};

// Runs fn(i, thread) for i in [0, count) on `threads` threads, handing out indices in chunks.
void parallel_for(uint32_t threads, size_t count, size_t chunk, const std::function<void(size_t, uint32_t)>& fn) {
  std::atomic<size_t> next{0};
  auto work = [&](uint32_t t) {
    for (size_t begin; (begin = next.fetch_add(chunk)) < count;)
      for (size_t i = begin; i < std::min(count, begin + chunk); ++i) fn(i, t);
  };
  std::vector<std::thread> pool;
  for (uint32_t t = 1; t < threads; ++t) pool.emplace_back(work, t);
  work(0);
  for (auto& th : pool) th.join();
}

class Solver {
 public:
  Solver(const solver::Scene& scene, const HierarchicalParams& p) : scene_(scene), params_(p) {
    threads_ = p.threads != 0 ? p.threads : std::max(1u, std::thread::hardware_concurrency());
    device_ = rtcNewDevice(nullptr);
    rtc_ = rtcNewScene(device_);
    const uint32_t n = static_cast<uint32_t>(scene.patches.size());
    roots_ = std::make_unique<Node[]>(n);
    std::vector<float> v;
    std::vector<uint32_t> idx;
    for (uint32_t i = 0; i < n; ++i) {
      const auto& patch = scene.patches[i];
      const uint32_t base = static_cast<uint32_t>(v.size() / 3);
      for (uint32_t k = 0; k < patch.corner_count; ++k)
        for (int a = 0; a < 3; ++a) v.push_back(static_cast<float>(patch.corners[k][a]));
      for (uint32_t t = 1; t + 1 < patch.corner_count; ++t) idx.insert(idx.end(), {base, base + t, base + t + 1});
      normal_.push_back(glm::normalize(glm::cross(patch.corners[1] - patch.corners[0], patch.corners[2] - patch.corners[0])));
      roots_[i].set(patch.corners, patch.corner_count, i);
      total_area_ += roots_[i].area;
      for (uint32_t k = 0; k < patch.corner_count; ++k) {
        lo_ = glm::min(lo_, patch.corners[k]);
        hi_ = glm::max(hi_, patch.corners[k]);
      }
    }
    RTCGeometry g = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, v.size() / 3));
    std::copy(v.begin(), v.end(), vb);
    auto* ib = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, idx.size() / 3));
    std::copy(idx.begin(), idx.end(), ib);
    rtcCommitGeometry(g);
    rtcAttachGeometry(rtc_, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(rtc_);
    eps_ = 1e-5 * glm::length(hi_ - lo_);
    min_area_ = params_.aeps * total_area_;
  }
  ~Solver() {
    rtcReleaseScene(rtc_);
    rtcReleaseDevice(device_);
  }
  Solver(const Solver&) = delete;
  Solver& operator=(const Solver&) = delete;

  // Refines every facing pair of patches; false when cancelled.
  bool link_all(HierarchicalStats& st, const HierarchicalProgressFn& progress, const solver::CancelToken* cancel,
                Clock::time_point t0) {
    const uint32_t n = static_cast<uint32_t>(scene_.patches.size());
    const uint64_t all_pairs = static_cast<uint64_t>(n) * (n - (n > 0 ? 1 : 0)) / 2;
    std::atomic<uint64_t> pairs_done{0};
    std::atomic<uint32_t> next{0};
    auto work = [&] {
      for (uint32_t p; !stop_.load(std::memory_order_relaxed) && (p = next.fetch_add(1)) < n;) {
        for (uint32_t q = p + 1; q < n; ++q)
          if (faces(p, q)) {
            Random rng{(static_cast<uint64_t>(p) << 32 | q) * 0x2545f4914f6cdd1dull};
            refine(roots_[p], roots_[q], rng);
          }
        pairs_done.fetch_add(n - 1 - p, std::memory_order_relaxed);
      }
    };
    std::vector<std::thread> pool;
    for (uint32_t t = 0; t < threads_; ++t) pool.emplace_back(work);
    while (pairs_done.load() < all_pairs && !stop_.load()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      if (cancel != nullptr && cancel->cancelled()) stop_.store(true);
      if (progress && Clock::now() - last_report_ > std::chrono::milliseconds(100)) {
        last_report_ = Clock::now();
        progress({true, all_pairs ? static_cast<double>(pairs_done.load()) / all_pairs : 1.0, links_.load(), 0,
                  std::chrono::duration<double>(last_report_ - t0).count()});
      }
    }
    for (auto& th : pool) th.join();
    st.links = links_.load();
    if (stop_.load()) return false;
    // Number the nodes depth first and sort each node's links by source, so that gathering adds
    // them in an order independent of scheduling.
    for (uint32_t p = 0; p < n; ++p) number(roots_[p]);
    parallel_for(threads_, all_.size(), 256, [&](size_t i, uint32_t) {
      auto& links = all_[i]->links;
      std::sort(links.begin(), links.end(), [](const Link& a, const Link& b) { return a.source->id < b.source->id; });
      links.shrink_to_fit();
    });
    return true;
  }

  // Jacobi gathering with push-pull until nothing changes by more than the tolerance; returns the
  // number of iterations (cancelled() tells whether it was stopped).
  uint32_t solve(const HierarchicalProgressFn& progress, const solver::CancelToken* cancel, Clock::time_point t0) {
    const uint32_t n = static_cast<uint32_t>(scene_.patches.size());
    std::vector<double> change(threads_), top(threads_);
    uint32_t it = 0;
    while (it < params_.max_iterations) {
      if (cancel != nullptr && cancel->cancelled()) {
        cancelled_ = true;
        break;
      }
      parallel_for(threads_, all_.size(), 512, [&](size_t i, uint32_t) {
        Node& node = *all_[i];
        glm::dvec3 g(0.0);
        for (const Link& l : node.links) g += l.ff * l.source->b;
        node.gathered = scene_.patches[node.patch].reflectance * g;
      });
      std::fill(change.begin(), change.end(), 0.0);
      std::fill(top.begin(), top.end(), 0.0);
      parallel_for(threads_, n, 16, [&](size_t p, uint32_t t) { push_pull(roots_[p], glm::dvec3(0.0), change[t], top[t]); });
      ++it;
      if (progress)
        progress({false, static_cast<double>(it) / params_.max_iterations, links_.load(), it,
                  std::chrono::duration<double>(Clock::now() - t0).count()});
      if (*std::max_element(change.begin(), change.end()) <= params_.tolerance * std::max(*std::max_element(top.begin(), top.end()), 1e-300))
        break;
    }
    return it;
  }

  bool cancelled() const { return cancelled_; }

  solver::Mesh mesh() const {
    // Leaves, with vertices shared by position within a surface (same material, same plane
    // direction: radiosity is not averaged across creases or materials, as in the solver's output);
    // each element's loop also holds the corners of finer neighbours on its edges (their midpoints
    // are computed with the same arithmetic), so the output has no T-junctions.
    solver::Mesh m;
    using Key = std::array<double, 7>;
    std::map<Key, uint32_t> vid;
    auto key = [&](const glm::dvec3& p, uint32_t patch) {
      const glm::dvec3 n = glm::round(normal_[patch] * 1e6);
      return Key{p.x, p.y, p.z, static_cast<double>(scene_.patches[patch].material), n.x, n.y, n.z};
    };
    std::vector<const Node*> leaves;
    for (const Node* node : all_) {
      if (node->children() != nullptr) continue;
      leaves.push_back(node);
      for (uint32_t k = 0; k < node->n; ++k) {
        auto [it, fresh] = vid.try_emplace(key(node->c[k], node->patch), static_cast<uint32_t>(m.positions.size()));
        if (fresh) m.positions.push_back(node->c[k]);
      }
    }
    std::vector<double> weight(m.positions.size(), 0.0);
    m.radiosity.assign(m.positions.size(), glm::dvec3(0.0));
    uint32_t surface_patch = 0;
    std::function<void(const glm::dvec3&, const glm::dvec3&)> hanging = [&](const glm::dvec3& a, const glm::dvec3& b) {
      const glm::dvec3 mid = 0.5 * (a + b);
      const auto it = vid.find(key(mid, surface_patch));
      if (it == vid.end()) return;
      hanging(a, mid);
      m.boundary.push_back(it->second);
      hanging(mid, b);
    };
    for (const Node* node : leaves) {
      solver::Mesh::Element el;
      el.patch = node->patch;
      el.corner_count = node->n;
      el.radiosity = node->b;
      el.area = node->area;
      el.boundary_begin = static_cast<uint32_t>(m.boundary.size());
      surface_patch = node->patch;
      for (uint32_t k = 0; k < node->n; ++k) {
        el.corners[k] = vid.at(key(node->c[k], node->patch));
        m.boundary.push_back(el.corners[k]);
        hanging(node->c[k], node->c[(k + 1) % node->n]);
      }
      el.boundary_end = static_cast<uint32_t>(m.boundary.size());
      for (uint32_t j = el.boundary_begin; j < el.boundary_end; ++j) {
        m.radiosity[m.boundary[j]] += node->b * node->area;
        weight[m.boundary[j]] += node->area;
      }
      m.elements.push_back(el);
    }
    for (size_t v = 0; v < m.radiosity.size(); ++v)
      if (weight[v] > 0.0) m.radiosity[v] /= weight[v];
    return m;
  }


 private:
  void number(Node& node) {
    node.id = static_cast<uint32_t>(all_.size());
    all_.push_back(&node);
    if (Node* kids = node.children())
      for (uint32_t k = 0; k < 4; ++k) number(kids[k]);
  }

  bool faces(uint32_t p, uint32_t q) const {
    // Some corner of each lies in front of the other.
    auto front = [&](uint32_t a, uint32_t b) {
      const auto& pa = scene_.patches[a];
      const auto& pb = scene_.patches[b];
      for (uint32_t k = 0; k < pb.corner_count; ++k)
        if (glm::dot(normal_[a], pb.corners[k] - pa.corners[0]) > eps_) return true;
      return false;
    };
    return front(p, q) && front(q, p);
  }

  // Disk estimate of F(a -> b) between element centres.
  double estimate(const Node& a, const Node& b) const {
    const glm::dvec3 d = b.centre - a.centre;
    const double r2 = glm::dot(d, d);
    if (r2 <= 0.0) return 1.0;
    const glm::dvec3 u = d / std::sqrt(r2);
    const double ca = glm::dot(normal_[a.patch], u), cb = -glm::dot(normal_[b.patch], u);
    if (ca <= 0.0 || cb <= 0.0) {
      // The centres do not see each other; if some corners do (the elements straddle each other's
      // planes), be conservative so that they get split, else there is no interaction.
      auto some_in_front = [&](const Node& x, const Node& y) {
        for (uint32_t k = 0; k < y.n; ++k)
          if (glm::dot(normal_[x.patch], y.c[k] - x.centre) > eps_) return true;
        return false;
      };
      if (!some_in_front(a, b) || !some_in_front(b, a)) return 0.0;
      return std::min(1.0, b.area / (std::numbers::pi * r2 + b.area));
    }
    return ca * cb * b.area / (std::numbers::pi * r2 + b.area);
  }

  Node* split(Node& node) {
    if (Node* kids = node.children()) return kids;
    std::lock_guard lock(split_locks_[node.patch % split_locks_.size()]);
    if (Node* kids = node.kids.load(std::memory_order_relaxed)) return kids;
    auto kids = std::make_unique<Node[]>(4);
    for (uint32_t k = 0; k < 4; ++k) kids[k].set(child(node.c, node.n, k), node.n, node.patch);
    node.own_kids = std::move(kids);
    node.kids.store(node.own_kids.get(), std::memory_order_release);
    return node.own_kids.get();
  }

  glm::dvec3 random_point(const Node& node, Random& rng) const {
    double s = rng.uniform(), t = rng.uniform();
    if (node.n == 4) {
      const glm::dvec3 a = node.c[0] + s * (node.c[1] - node.c[0]);
      const glm::dvec3 b = node.c[3] + s * (node.c[2] - node.c[3]);
      return a + t * (b - a);
    }
    if (s + t > 1.0) {
      s = 1.0 - s;
      t = 1.0 - t;
    }
    return node.c[0] + s * (node.c[1] - node.c[0]) + t * (node.c[2] - node.c[0]);
  }

  double visibility(const Node& p, const Node& q, Random& rng) const {
    uint32_t seen = 0;
    for (uint32_t r = 0; r < params_.rays; ++r) {
      const glm::dvec3 a = random_point(p, rng) + normal_[p.patch] * eps_;
      const glm::dvec3 b = random_point(q, rng) + normal_[q.patch] * eps_;
      const glm::dvec3 d = b - a;
      const double len = glm::length(d);
      seen += detail::unoccluded(rtc_, a, d / len, len * (1.0 - 1e-4));
    }
    return static_cast<double>(seen) / params_.rays;
  }

  void add_link(Node& receiver, const Node& source, double ff) {
    std::lock_guard lock(link_locks_[(reinterpret_cast<uintptr_t>(&receiver) >> 7) % link_locks_.size()]);
    receiver.links.push_back({&source, ff});
  }

  void refine(Node& p, Node& q, Random& rng) {
    if (stop_.load(std::memory_order_relaxed)) return;
    const double fpq = estimate(p, q), fqp = estimate(q, p);
    if (fpq <= 0.0 && fqp <= 0.0) return;
    const bool split_p = p.area >= 4.0 * min_area_, split_q = q.area >= 4.0 * min_area_;
    if (std::max(fpq, fqp) > params_.feps && (split_p || split_q)) {
      // Split the one whose view of the other is worse (the larger form factor).
      if ((fqp >= fpq && split_q) || !split_p) {
        Node* kids = split(q);
        for (uint32_t k = 0; k < 4; ++k) refine(p, kids[k], rng);
      } else {
        Node* kids = split(p);
        for (uint32_t k = 0; k < 4; ++k) refine(kids[k], q, rng);
      }
      return;
    }
    const double v = visibility(p, q, rng);
    if (v <= 0.0) return;
    add_link(p, q, std::min(1.0, fpq) * v);
    add_link(q, p, std::min(1.0, fqp) * v);
    links_.fetch_add(2, std::memory_order_relaxed);
  }

  // Push the radiosity gathered above down to the leaves and pull area averages back up.
  glm::dvec3 push_pull(Node& node, const glm::dvec3& down, double& change, double& top) {
    const glm::dvec3 here = down + node.gathered;
    glm::dvec3 b;
    if (Node* kids = node.children()) {
      b = glm::dvec3(0.0);
      double a = 0.0;
      for (uint32_t k = 0; k < 4; ++k) {
        b += push_pull(kids[k], here, change, top) * kids[k].area;
        a += kids[k].area;
      }
      b /= a;
    } else {
      b = scene_.patches[node.patch].emission + here;
    }
    const glm::dvec3 diff = glm::abs(b - node.b);
    change = std::max({change, diff.x, diff.y, diff.z});
    top = std::max({top, b.x, b.y, b.z});
    node.b = b;
    return b;
  }

  const solver::Scene& scene_;
  HierarchicalParams params_;
  uint32_t threads_ = 1;
  RTCDevice device_ = nullptr;
  RTCScene rtc_ = nullptr;
  std::unique_ptr<Node[]> roots_;
  std::vector<Node*> all_;
  std::vector<glm::dvec3> normal_;
  glm::dvec3 lo_{1e300}, hi_{-1e300};
  double total_area_ = 0.0, min_area_ = 0.0, eps_ = 0.0;
  std::atomic<uint64_t> links_{0};
  std::atomic<bool> stop_{false};  // cancelled while linking
  std::array<std::mutex, 64> split_locks_;
  std::array<std::mutex, 1024> link_locks_;
  Clock::time_point last_report_{};
  bool cancelled_ = false;
};

}  // namespace

solver::Mesh solve_hierarchical(const solver::Scene& scene, const HierarchicalParams& params, HierarchicalStats& stats,
                                const HierarchicalProgressFn& progress, const solver::CancelToken* cancel) {
  const auto t0 = Clock::now();
  Solver s(scene, params);
  const bool linked = s.link_all(stats, progress, cancel, t0);
  const auto t1 = Clock::now();
  stats.seconds_linking = std::chrono::duration<double>(t1 - t0).count();
  stats.iterations = linked ? s.solve(progress, cancel, t0) : 0;
  if (!linked || s.cancelled()) {
    stats.cancelled = true;
    stats.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    return {};
  }
  solver::Mesh m = s.mesh();
  stats.elements = m.elements.size();
  stats.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return m;
}

}  // namespace hemibake::baselines
