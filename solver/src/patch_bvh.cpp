// The bounding-box tree over the patches (median cuts), for finding what lies near a hemicube.
#include "solver_impl.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <limits>
#include <numeric>

namespace hemibake::solver {

// Per patch its bounding box, and the tree over them.
void Solver::Impl::build_patch_bvh() {
  p_lo.resize(patches.size());
  p_hi.resize(patches.size());
  tree_patch.resize(patches.size());
  for (uint32_t q = 0; q < patches.size(); ++q) {
    tree_patch[q] = q;
    p_lo[q] = p_hi[q] = patches[q].corners[0];
    for (uint32_t k = 1; k < patches[q].corner_count; ++k) {
      p_lo[q] = glm::min(p_lo[q], patches[q].corners[k]);
      p_hi[q] = glm::max(p_hi[q], patches[q].corners[k]);
    }
  }
  tree.emplace_back();
  if (!patches.empty()) build_patch_tree(0, 0, static_cast<uint32_t>(patches.size()));
}

// Surfaces standing on others (GroupAdjacency::add_standing): an edge of patch q lies in the plane
// of patch p of another plane, overlapping p, and all of q's occlusion group lies on one side of
// that plane. The feet (q's edges on p) are kept per p, and p's elements under a one-sided one are
// marked (e_under).
void Solver::Impl::find_standing() {
  const double in_plane = kCloseFacingLength * prep.diagonal;  // written positions are rounded
  const double tol = 1e-7 * prep.diagonal;
  struct Contact {
    uint64_t key;  // base group << 32 | top group
    bool front;    // the top on the base's front side
    uint32_t base_patch, top;
    glm::dvec3 a, b;  // the top's edge
  };
  std::vector<Contact> contacts;
  for (uint32_t q = 0; q < patches.size(); ++q) {
    const Patch& pq = patches[q];
    for (uint32_t k = 0; k < pq.corner_count; ++k) {
      const glm::dvec3& a = pq.corners[k];
      const glm::dvec3& b = pq.corners[(k + 1) % pq.corner_count];
      const glm::dvec3 lo = glm::min(a, b), hi = glm::max(a, b);
      auto near = [&](const glm::dvec3& blo, const glm::dvec3& bhi) { return boxes_meet(lo, hi, blo, bhi, in_plane); };
      find_patch(near, [&](uint32_t p) {
        const glm::dvec3& n = prep.normal[p];
        if (p == q || prep.occlusion_group[p] == prep.occlusion_group[q] ||
            std::abs(glm::dot(n, prep.normal[q])) > 1.0 - 1e-6)
          return false;
        const Patch& pp = patches[p];
        if (detail::foot_within({pp.corners.data(), pp.corner_count}, n, a, b, in_plane, tol) <= tol) return false;
        double reach = 0.0;  // q's farthest corner from p's plane, signed
        for (uint32_t c = 0; c < pq.corner_count; ++c) {
          const double d = glm::dot(n, pq.corners[c] - pp.corners[0]);
          if (std::abs(d) > std::abs(reach)) reach = d;
        }
        if (std::abs(reach) > in_plane)
          contacts.push_back({(static_cast<uint64_t>(prep.occlusion_group[p]) << 32) | prep.occlusion_group[q], reach > 0.0, p, q, a, b});
        return false;
      });
    }
  }
  if (contacts.empty()) return;
  std::sort(contacts.begin(), contacts.end(), [](const Contact& x, const Contact& y) {
    return x.key != y.key ? x.key < y.key : x.front < y.front;
  });
  // The patches of each group, to check that the whole top lies on one side of the base's plane.
  std::vector<uint32_t> by_group(patches.size());
  std::iota(by_group.begin(), by_group.end(), 0u);
  std::sort(by_group.begin(), by_group.end(), [&](uint32_t x, uint32_t y) {
    return prep.occlusion_group[x] != prep.occlusion_group[y] ? prep.occlusion_group[x] < prep.occlusion_group[y] : x < y;
  });
  for (size_t first = 0, last = 0; first < contacts.size(); first = last) {
    while (last < contacts.size() && contacts[last].key == contacts[first].key && contacts[last].front == contacts[first].front) ++last;
    const uint64_t key = contacts[first].key;
    const bool front = contacts[first].front;
    const uint32_t base = static_cast<uint32_t>(key >> 32), top = static_cast<uint32_t>(key);
    const glm::dvec3& n = prep.normal[base];  // a group's root is one of its patches
    const glm::dvec3& origin = patches[base].corners[0];
    auto it = std::lower_bound(by_group.begin(), by_group.end(), top,
                               [&](uint32_t x, uint32_t g) { return prep.occlusion_group[x] < g; });
    bool one_side = true;
    for (; it != by_group.end() && prep.occlusion_group[*it] == top && one_side; ++it)
      for (uint32_t c = 0; c < patches[*it].corner_count; ++c) {
        const double d = glm::dot(n, patches[*it].corners[c] - origin);
        one_side = one_side && (front ? d >= -in_plane : d <= in_plane);
      }
    // Surfaces that share an edge keep that edge's rule (GroupAdjacency::finish_standing).
    if (!one_side || prep.adjacency.find(base, top) != nullptr) continue;
    prep.adjacency.add_standing(base, top, front);
    if (p_feet.empty()) p_feet.resize(patches.size());
    for (size_t c = first; c < last; ++c) p_feet[contacts[c].base_patch].push_back({contacts[c].a, contacts[c].b, contacts[c].top});
  }
  prep.adjacency.finish_standing();
  for (uint32_t e = 0; e < e_patch.size(); ++e) e_under[e] = under_foot(e);
}

// Whether a surface lies on element e or just in front of it, over its centre (gap_covered): 0
// before the patch tree is built (mark_covered marks the first elements).
// The surface covering element e at its centre (gap_covered), or kNone.
uint32_t Solver::Impl::cover_at_centre(uint32_t e) const {
  if (tree.empty()) return kNone;
  return cover_at(e_patch[e], e_centre[e], std::min(e_radius[e], kCoverGap * prep.diagonal), true, Cover::kAny);
}

// Cover patch q of a point on patch p, as the hemicubes on p's side see it: its occlusion group,
// or its other side's when it faces p (a double-sided rug's underside over a floor: the rug's top
// is what they see), or its back face's (detail::kBackFaceCover) when it has none.
uint32_t Solver::Impl::seen_cover(uint32_t p, uint32_t q) const {
  if (glm::dot(prep.normal[q], prep.normal[p]) > 0.0) return prep.occlusion_group[q];
  if (prep.twin[q] != kNone) return prep.occlusion_group[prep.twin[q]];
  return prep.occlusion_group[q] | detail::kBackFaceCover;
}

void Solver::Impl::mark_covered() {
  any_covered = false;
  for (uint32_t e = 0; e < e_patch.size(); ++e) set_covered(e, cover_at_centre(e));
}

// The one-sided surface standing on element e's patch (find_standing) that e lies under: the
// surface's foot meets e, its outline included, and e's centre lies behind the surface; or kNone.
uint32_t Solver::Impl::under_foot(uint32_t e) const {
  if (p_feet.empty() || p_feet[e_patch[e]].empty()) return kNone;
  const double in_plane = kCloseFacingLength * prep.diagonal;
  const double tol = 1e-7 * prep.diagonal;
  const Corners c = corners_of_copy(e);
  const uint32_t nc = corner_count(e);
  glm::dvec3 lo, hi;
  element_box(e, lo, hi);
  for (const Foot& foot : p_feet[e_patch[e]]) {
    if (prep.twin[foot.top] != kNone || glm::dot(prep.normal[foot.top], e_centre[e] - patches[foot.top].corners[0]) >= 0.0) continue;
    const glm::dvec3 &a = foot.a, &b = foot.b;
    if (!boxes_meet(glm::min(a, b), glm::max(a, b), lo, hi, in_plane)) continue;
    if (detail::foot_within({c.data(), nc}, prep.normal[e_patch[e]], a, b, in_plane, tol) > tol) return foot.top;
  }
  return kNone;
}

// Tree node `id` over tree_patch[begin, end), and its subtree: leaves hold at most four patches.
void Solver::Impl::build_patch_tree(uint32_t id, uint32_t begin, uint32_t end) {
  HEMIBAKE_DCHECK(begin < end && end <= tree_patch.size() && id < tree.size());
  BoxNode node;
  node.begin = begin;
  node.end = end;
  node.lo = glm::dvec3(std::numeric_limits<double>::max());
  node.hi = glm::dvec3(std::numeric_limits<double>::lowest());
  glm::dvec3 clo = node.lo, chi = node.hi;  // of the boxes' centres (doubled)
  for (uint32_t i = begin; i < end; ++i) {
    const uint32_t q = tree_patch[i];
    node.lo = glm::min(node.lo, p_lo[q]);
    node.hi = glm::max(node.hi, p_hi[q]);
    clo = glm::min(clo, p_lo[q] + p_hi[q]);
    chi = glm::max(chi, p_lo[q] + p_hi[q]);
  }
  if (end - begin > 4) {
    const uint32_t mid =
        median_cut(tree_patch, begin, end, clo, chi, [&](uint32_t q) { return p_lo[q] + p_hi[q]; });
    node.child = static_cast<uint32_t>(tree.size());
    tree.resize(tree.size() + 2);
    build_patch_tree(node.child, begin, mid);
    build_patch_tree(node.child + 1, mid, end);
  }
  tree[id] = node;
}

// Appends the patches whose boxes meet the shaft's to `out` and marks them (p_mark = mark), in
// the tree's order: the hemicube projects in this order, and ties in depth keep it.
void Solver::Impl::patches_meeting(const detail::Shaft& shaft, std::vector<uint32_t>& out) {
  const double slack = kRoundingLength * prep.diagonal;
  std::vector<uint32_t> nodes{0};
  while (!nodes.empty()) {
    const BoxNode& node = tree[nodes.back()];
    nodes.pop_back();
    if (!shaft.meets(node.lo, node.hi, slack)) continue;
    if (node.child != kNone) {
      nodes.push_back(node.child + 1);
      nodes.push_back(node.child);
      continue;
    }
    for (uint32_t i = node.begin; i < node.end; ++i) {
      const uint32_t q = tree_patch[i];
      if (shaft.meets(p_lo[q], p_hi[q], slack)) {
        out.push_back(q);
        p_mark[q] = mark;
      }
    }
  }
}

}  // namespace hemibake::solver
