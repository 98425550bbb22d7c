// Hierarchical radiosity after Hanrahan, Salzman and Aupperle (1991). For every pair of patches that
// face each other, Refine(p, q) estimates the form factor of the interaction both ways with the
// disk approximation F = A cos cos' / (pi r^2 + A); while the larger exceeds FEPS, the larger
// element (if it may still be split under AEPS) is subdivided and the children are refined
// against the other; otherwise a link is made, its visibility the fraction of `rays` unoccluded
// rays between random points of the two elements. Solving alternates gathering over the links
// (B_gathered = rho * sum F V B_source) with push-pull down and up the quadtrees.
#include "hemibake/baselines/hierarchical.h"

#include <embree3/rtcore.h>
#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <chrono>
#include <functional>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <vector>

namespace hemibake::baselines {
namespace {

using Corners = std::array<glm::dvec3, 4>;

struct Link {
  uint32_t source;
  double ff;  // F(receiver -> source) * visibility
};

struct Node {
  Corners c{};
  uint32_t n = 4;
  uint32_t patch = 0;
  double area = 0.0;
  glm::dvec3 centre{0.0};
  uint32_t first_child = UINT32_MAX;
  std::vector<Link> links;
  glm::dvec3 b{0.0}, gathered{0.0};
};

Corners child(const Corners& c, uint32_t n, uint32_t k) {
  Corners out{};
  if (n == 4) {
    const glm::dvec3 m01 = 0.5 * (c[0] + c[1]), m12 = 0.5 * (c[1] + c[2]), m23 = 0.5 * (c[2] + c[3]), m30 = 0.5 * (c[3] + c[0]);
    const glm::dvec3 ctr = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    const std::array<Corners, 4> kids{{{c[0], m01, ctr, m30}, {m01, c[1], m12, ctr}, {ctr, m12, c[2], m23}, {m30, ctr, m23, c[3]}}};
    return kids[k];
  }
  const glm::dvec3 m01 = 0.5 * (c[0] + c[1]), m12 = 0.5 * (c[1] + c[2]), m20 = 0.5 * (c[2] + c[0]);
  const std::array<Corners, 4> kids{{{c[0], m01, m20, {}}, {m01, c[1], m12, {}}, {m20, m12, c[2], {}}, {m12, m20, m01, {}}}};
  out = kids[k];
  return out;
}

double area_of(const Corners& c, uint32_t n) {
  if (n == 4) return 0.5 * glm::length(glm::cross(c[2] - c[0], c[3] - c[1]));
  return 0.5 * glm::length(glm::cross(c[1] - c[0], c[2] - c[0]));
}

class Solver {
 public:
  Solver(const solver::Scene& scene, const HierarchicalParams& p) : scene_(scene), params_(p), rng_(12345) {
    device_ = rtcNewDevice(nullptr);
    rtc_ = rtcNewScene(device_);
    std::vector<float> v;
    std::vector<uint32_t> idx;
    for (uint32_t i = 0; i < scene.patches.size(); ++i) {
      const auto& patch = scene.patches[i];
      const uint32_t base = static_cast<uint32_t>(v.size() / 3);
      for (uint32_t k = 0; k < patch.corner_count; ++k)
        for (int a = 0; a < 3; ++a) v.push_back(static_cast<float>(patch.corners[k][a]));
      for (uint32_t t = 1; t + 1 < patch.corner_count; ++t) idx.insert(idx.end(), {base, base + t, base + t + 1});
      normal_.push_back(glm::normalize(glm::cross(patch.corners[1] - patch.corners[0], patch.corners[2] - patch.corners[0])));
      Node root;
      root.n = patch.corner_count;
      root.c = patch.corners;
      root.patch = i;
      root.area = area_of(root.c, root.n);
      for (uint32_t k = 0; k < root.n; ++k) root.centre += root.c[k] / static_cast<double>(root.n);
      total_area_ += root.area;
      nodes_.push_back(root);
      for (uint32_t k = 0; k < root.n; ++k) {
        lo_ = glm::min(lo_, root.c[k]);
        hi_ = glm::max(hi_, root.c[k]);
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

  void link_all(HierarchicalStats& st) {
    const uint32_t n = static_cast<uint32_t>(scene_.patches.size());
    for (uint32_t p = 0; p < n; ++p)
      for (uint32_t q = p + 1; q < n; ++q)
        if (faces(p, q)) refine(p, q);
    st.links = links_;
  }

  uint32_t solve() {
    uint32_t it = 0;
    for (; it < params_.max_iterations; ++it) {
      for (auto& node : nodes_) {
        glm::dvec3 g(0.0);
        for (const Link& l : node.links) g += l.ff * nodes_[l.source].b;
        node.gathered = scene_.patches[node.patch].reflectance * g;
      }
      double change = 0.0, top = 0.0;
      for (uint32_t p = 0; p < scene_.patches.size(); ++p) push_pull(p, glm::dvec3(0.0), change, top);
      if (change <= params_.tolerance * std::max(top, 1e-300)) {
        ++it;
        break;
      }
    }
    return it;
  }

  solver::Mesh mesh() const {
    // Leaves, with vertices shared by position; each element's loop also holds the corners of finer
    // neighbours on its edges (their midpoints are computed with the same arithmetic), so the
    // output has no T-junctions.
    solver::Mesh m;
    std::map<std::array<double, 3>, uint32_t> vid;
    auto key = [](const glm::dvec3& p) { return std::array<double, 3>{p.x, p.y, p.z}; };
    std::vector<uint32_t> leaves, stack;
    for (uint32_t p = 0; p < scene_.patches.size(); ++p) {
      stack.push_back(p);
      while (!stack.empty()) {
        const uint32_t i = stack.back();
        stack.pop_back();
        const Node& node = nodes_[i];
        if (node.first_child != UINT32_MAX) {
          for (uint32_t k = 0; k < 4; ++k) stack.push_back(node.first_child + k);
          continue;
        }
        leaves.push_back(i);
        for (uint32_t k = 0; k < node.n; ++k) {
          auto [it, fresh] = vid.try_emplace(key(node.c[k]), static_cast<uint32_t>(m.positions.size()));
          if (fresh) m.positions.push_back(node.c[k]);
        }
      }
    }
    std::vector<double> weight(m.positions.size(), 0.0);
    m.radiosity.assign(m.positions.size(), glm::dvec3(0.0));
    std::function<void(const glm::dvec3&, const glm::dvec3&)> hanging = [&](const glm::dvec3& a, const glm::dvec3& b) {
      const glm::dvec3 mid = 0.5 * (a + b);
      const auto it = vid.find(key(mid));
      if (it == vid.end()) return;
      hanging(a, mid);
      m.boundary.push_back(it->second);
      hanging(mid, b);
    };
    for (uint32_t i : leaves) {
      const Node& node = nodes_[i];
      solver::Mesh::Element el;
      el.patch = node.patch;
      el.corner_count = node.n;
      el.radiosity = node.b;
      el.area = node.area;
      el.boundary_begin = static_cast<uint32_t>(m.boundary.size());
      for (uint32_t k = 0; k < node.n; ++k) {
        el.corners[k] = vid.at(key(node.c[k]));
        m.boundary.push_back(el.corners[k]);
        hanging(node.c[k], node.c[(k + 1) % node.n]);
      }
      el.boundary_end = static_cast<uint32_t>(m.boundary.size());
      for (uint32_t j = el.boundary_begin; j < el.boundary_end; ++j) {
        m.radiosity[m.boundary[j]] += node.b * node.area;
        weight[m.boundary[j]] += node.area;
      }
      m.elements.push_back(el);
    }
    for (size_t v = 0; v < m.radiosity.size(); ++v)
      if (weight[v] > 0.0) m.radiosity[v] /= weight[v];
    return m;
  }

 private:
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

  // Disk estimate of F(p -> q) between element centres.
  double estimate(uint32_t p, uint32_t q) const {
    const Node& a = nodes_[p];
    const Node& b = nodes_[q];
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

  void split(uint32_t i) {
    if (nodes_[i].first_child != UINT32_MAX) return;
    const uint32_t first = static_cast<uint32_t>(nodes_.size());
    for (uint32_t k = 0; k < 4; ++k) {
      Node c;
      c.n = nodes_[i].n;
      c.c = child(nodes_[i].c, c.n, k);
      c.patch = nodes_[i].patch;
      c.area = area_of(c.c, c.n);
      for (uint32_t j = 0; j < c.n; ++j) c.centre += c.c[j] / static_cast<double>(c.n);
      nodes_.push_back(c);
    }
    nodes_[i].first_child = first;
  }

  glm::dvec3 random_point(const Node& node) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    double s = u(rng_), t = u(rng_);
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

  double visibility(uint32_t p, uint32_t q) {
    uint32_t seen = 0;
    for (uint32_t r = 0; r < params_.rays; ++r) {
      const glm::dvec3 a = random_point(nodes_[p]) + normal_[nodes_[p].patch] * eps_;
      const glm::dvec3 b = random_point(nodes_[q]) + normal_[nodes_[q].patch] * eps_;
      const glm::dvec3 d = b - a;
      const double len = glm::length(d);
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      RTCRay ray{};
      ray.org_x = static_cast<float>(a.x);
      ray.org_y = static_cast<float>(a.y);
      ray.org_z = static_cast<float>(a.z);
      ray.dir_x = static_cast<float>(d.x / len);
      ray.dir_y = static_cast<float>(d.y / len);
      ray.dir_z = static_cast<float>(d.z / len);
      ray.tnear = 0.0f;
      ray.tfar = static_cast<float>(len * (1.0 - 1e-4));
      ray.mask = 0xffffffffu;
      rtcOccluded1(rtc_, &ctx, &ray);
      seen += ray.tfar >= 0.0f;
    }
    return static_cast<double>(seen) / params_.rays;
  }

  void refine(uint32_t p, uint32_t q) {
    const double fpq = estimate(p, q), fqp = estimate(q, p);
    if (fpq <= 0.0 && fqp <= 0.0) return;
    const bool split_p = nodes_[p].area >= 4.0 * min_area_, split_q = nodes_[q].area >= 4.0 * min_area_;
    if (std::max(fpq, fqp) > params_.feps && (split_p || split_q)) {
      // Split the one whose view of the other is worse (the larger form factor).
      if ((fqp >= fpq && split_q) || !split_p) {
        split(q);
        for (uint32_t k = 0; k < 4; ++k) refine(p, nodes_[q].first_child + k);
      } else {
        split(p);
        for (uint32_t k = 0; k < 4; ++k) refine(nodes_[p].first_child + k, q);
      }
      return;
    }
    const double v = visibility(p, q);
    if (v <= 0.0) return;
    nodes_[p].links.push_back({q, std::min(1.0, fpq) * v});
    nodes_[q].links.push_back({p, std::min(1.0, fqp) * v});
    links_ += 2;
  }

  // Push the radiosity gathered above down to the leaves and pull area averages back up.
  glm::dvec3 push_pull(uint32_t i, const glm::dvec3& down, double& change, double& top) {
    Node& node = nodes_[i];
    const glm::dvec3 here = down + node.gathered;
    glm::dvec3 b;
    if (node.first_child == UINT32_MAX) {
      b = scene_.patches[node.patch].emission + here;
    } else {
      b = glm::dvec3(0.0);
      double a = 0.0;
      for (uint32_t k = 0; k < 4; ++k) {
        const uint32_t ch = node.first_child + k;
        b += push_pull(ch, here, change, top) * nodes_[ch].area;
        a += nodes_[ch].area;
      }
      b /= a;
    }
    const glm::dvec3 diff = glm::abs(b - node.b);
    change = std::max({change, diff.x, diff.y, diff.z});
    top = std::max({top, b.x, b.y, b.z});
    node.b = b;
    return b;
  }

  const solver::Scene& scene_;
  HierarchicalParams params_;
  std::mt19937_64 rng_;
  RTCDevice device_ = nullptr;
  RTCScene rtc_ = nullptr;
  std::vector<Node> nodes_;
  std::vector<glm::dvec3> normal_;
  glm::dvec3 lo_{1e300}, hi_{-1e300};
  double total_area_ = 0.0, min_area_ = 0.0, eps_ = 0.0;
  uint64_t links_ = 0;
};

}  // namespace

solver::Mesh solve_hierarchical(const solver::Scene& scene, const HierarchicalParams& params, HierarchicalStats& stats) {
  const auto t0 = std::chrono::steady_clock::now();
  Solver s(scene, params);
  s.link_all(stats);
  const auto t1 = std::chrono::steady_clock::now();
  stats.iterations = s.solve();
  solver::Mesh m = s.mesh();
  stats.elements = m.elements.size();
  stats.seconds_linking = std::chrono::duration<double>(t1 - t0).count();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return m;
}

}  // namespace hemibake::baselines
