// Clusters: small patches that shoot together, as binary trees of median cuts: patches of one
// surface (a wall in tiles), and faces of small objects across objects (boxes on a table), pooled by
// orientation so that each cluster shoots along one direction class (Sillion 1995 and Smits et al.
// 1994 split a volume cluster's emission the same way, by where it faces).
#include "solver_impl.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <limits>
#include <map>
#include <numeric>

namespace hemibake::solver {
namespace {

// The class of a normal by its dominant axis and sign (six classes): faces of small objects
// cluster with faces of like orientation only.
int orientation_class(const glm::dvec3& n) {
  const glm::dvec3 a = glm::abs(n);
  const int axis = a.x >= a.y && a.x >= a.z ? 0 : a.y >= a.z ? 1 : 2;
  return 2 * axis + (n[axis] < 0.0 ? 1 : 0);
}

}  // namespace


// Whether a cluster node is too wide (`limit`), its normals too spread (kClusterCone) or its faces
// too far apart along its normal (kClusterDepth) to shoot as one piece.
bool Solver::Impl::cluster_unfit(const ClusterNode& node, double limit) {
  return node.diameter > limit || node.min_cos < kClusterCone || node.depth > kClusterDepth * node.diameter;
}

// Cluster node `id` over cluster_patch[begin, end), and its subtree. A node is cut at the median
// of its patches' centres; or of their normals where the normals' spread exceeds kClusterCone by
// more than the node's width exceeds `limit`, so that a curved surface's facets (a column's, a wavy
// curtain's) part by where they face, into clusters that span the surface, instead of into slices
// that each hold every orientation until they are down to a facet or two; or along its normal where
// its faces lie deeper than kClusterDepth of its width (the outer and inner faces of a double-sided
// ball, which look the same way from opposite sides).
void Solver::Impl::build_cluster(uint32_t id, uint32_t begin, uint32_t end, double limit) {
  HEMIBAKE_DCHECK(begin < end && end <= cluster_patch.size() && id < c_nodes.size());
  ClusterNode node;
  node.begin = begin;
  node.end = end;
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
  glm::dvec3 clo = lo, chi = hi;  // of the patch centres
  glm::dvec3 nlo = lo, nhi = hi;  // of the patch normals
  for (uint32_t i = begin; i < end; ++i) {
    const uint32_t q = cluster_patch[i];
    const Patch& patch = patches[q];
    for (uint32_t k = 0; k < patch.corner_count; ++k) {
      lo = glm::min(lo, patch.corners[k]);
      hi = glm::max(hi, patch.corners[k]);
    }
    const glm::dvec3 pc = polygon_centre(patch.corners, patch.corner_count);
    node.centre += pc * prep.area[q];
    node.normal += prep.normal[q] * prep.area[q];
    node.area += prep.area[q];
    clo = glm::min(clo, pc);
    chi = glm::max(chi, pc);
    nlo = glm::min(nlo, prep.normal[q]);
    nhi = glm::max(nhi, prep.normal[q]);
  }
  node.centre /= node.area;
  const double nl = glm::length(node.normal);
  node.normal = nl > 0.0 ? node.normal / nl : prep.normal[cluster_patch[begin]];
  node.min_cos = nl > 0.0 ? 1.0 : -1.0;
  for (uint32_t i = begin; i < end; ++i) node.min_cos = std::min(node.min_cos, glm::dot(node.normal, prep.normal[cluster_patch[i]]));
  for (int k = 0; k < 8; ++k) node.box[k] = glm::dvec3(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z);
  // Its faces lie at different depths along its normal (box tops of several heights across
  // objects; the crests and troughs of a wavy curtain): its centroid may lie inside a box, whose
  // inner faces are absorbing backs, or behind its own surface's crests. Its hemicube stands in
  // front of all of its patches instead (shoot_cluster).
  double back = 0.0;
  for (uint32_t i = begin; i < end; ++i) {
    const Patch& patch = patches[cluster_patch[i]];
    for (uint32_t k = 0; k < patch.corner_count; ++k) {
      node.diameter = std::max(node.diameter, 2.0 * glm::distance(node.centre, patch.corners[k]));
      const double d = glm::dot(node.normal, patch.corners[k] - node.centre);
      node.front = std::max(node.front, d);
      back = std::max(back, -d);
    }
  }
  node.depth = node.front + back;
  if (node.depth <= kRoundingLength * prep.diagonal) node.front = node.depth = 0.0;  // flat
  if (end - begin > 1) {
    // Cut where the node is furthest from a unit (cluster_unfit): on the normals, along the mean
    // normal (a double-sided object's outer and inner faces that look the same way), or on the
    // centres.
    const double spread = (1.0 - node.min_cos) / (1.0 - kClusterCone);
    const double width = limit > 0.0 ? node.diameter / limit : 0.0;
    const double thick = node.diameter > 0.0 ? node.depth / (kClusterDepth * node.diameter) : 0.0;
    const glm::dvec3 axis = node.normal;
    auto along = [&](uint32_t q) {
      return glm::dvec3(glm::dot(axis, polygon_centre(patches[q].corners, patches[q].corner_count)), 0.0, 0.0);
    };
    const bool by_normals = spread > 1.0 && spread >= width && spread >= thick;
    // Along the normal when that is due and the centres lie at more than one depth there.
    double dlo = std::numeric_limits<double>::max(), dhi = std::numeric_limits<double>::lowest();
    if (!by_normals && thick > 1.0 && thick >= width)
      for (uint32_t i = begin; i < end; ++i) {
        dlo = std::min(dlo, along(cluster_patch[i]).x);
        dhi = std::max(dhi, along(cluster_patch[i]).x);
      }
    uint32_t mid;
    if (by_normals)
      mid = median_cut(cluster_patch, begin, end, nlo, nhi, [&](uint32_t q) { return prep.normal[q]; });
    else if (dhi > dlo)
      mid = median_cut(cluster_patch, begin, end, glm::dvec3(dlo, 0, 0), glm::dvec3(dhi, 0, 0), along);
    else
      mid = median_cut(cluster_patch, begin, end, clo, chi, [&](uint32_t q) {
        return polygon_centre(patches[q].corners, patches[q].corner_count);
      });
    node.child = static_cast<uint32_t>(c_nodes.size());
    c_nodes.resize(c_nodes.size() + 2);
    build_cluster(node.child, begin, mid, limit);
    build_cluster(node.child + 1, mid, end, limit);
  }
  c_nodes[id] = node;
}

// Small patches of one surface with the same emission shoot together: each surface's tree is cut
// into clusters no wider than cluster_size of the scene's diagonal (units). Larger patches, and
// patches left alone by the cuts, are units of their own.
void Solver::Impl::build_clusters() {
  const double limit = params.cluster_size * prep.diagonal;
  find_surfaces();
  p_unit.assign(patches.size(), kNone);
  // Surfaces no wider than half the limit (the faces of small boxes, chair legs) cluster across
  // objects, pooled by orientation class and emission; wider ones (a wall in tiles) among their
  // own patches.
  std::map<std::pair<int, std::array<double, 3>>, std::vector<uint32_t>> pooled;
  for (const std::vector<uint32_t>& members : cluster_candidates(limit)) {
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
    for (uint32_t q : members)
      for (uint32_t k = 0; k < patches[q].corner_count; ++k) {
        lo = glm::min(lo, patches[q].corners[k]);
        hi = glm::max(hi, patches[q].corners[k]);
      }
    if (params.cluster_across && glm::distance(lo, hi) <= 0.5 * limit) {
      // Each patch by its own normal: a small sphere's facets go to six pools, not one.
      const glm::dvec3& e = patches[members[0]].emission;
      for (uint32_t q : members) pooled[{orientation_class(prep.normal[q]), {e.x, e.y, e.z}}].push_back(q);
      continue;
    }
    if (members.size() >= 2) cut_into_units(members, limit);
  }
  for (auto& [key, members] : pooled)
    if (members.size() >= 2) cut_into_units(members, limit);
  for (uint32_t p = 0; p < patches.size(); ++p) {
    if (p_unit[p] != kNone) continue;
    p_unit[p] = static_cast<uint32_t>(unit_patch.size());
    unit_patch.push_back(p);
    unit_node.push_back(kNone);
    u_unshot.push_back(p_unshot[p]);
  }
  HEMIBAKE_DCHECK(unit_patch.size() == unit_node.size() && unit_node.size() == u_unshot.size());
  for (uint32_t p = 0; p < patches.size(); ++p) HEMIBAKE_DCHECK(p_unit[p] < unit_patch.size());
}

// A surface (p_surface): coplanar edge-connected patches (an occlusion group) joined with smoothly
// curved ones (a smoothing group: same material, creases under 30 degrees). Group ids are patch
// ids; a surface's id is its least patch's.
void Solver::Impl::find_surfaces() {
  std::vector<uint32_t> surface(patches.size());
  std::iota(surface.begin(), surface.end(), 0u);
  auto find = [&](uint32_t i) {
    while (surface[i] != i) i = surface[i] = surface[surface[i]];
    return i;
  };
  for (uint32_t p = 0; p < patches.size(); ++p)
    for (uint32_t g : {prep.occlusion_group[p], prep.smoothing_group[p]}) {
      const uint32_t a = find(p), b = find(g);
      if (a != b) surface[std::max(a, b)] = std::min(a, b);
    }
  p_surface.resize(patches.size());
  for (uint32_t p = 0; p < patches.size(); ++p) p_surface[p] = find(p);
}

// The patches narrower than half the cluster limit, grouped by surface and emission (in the order
// of surface, then emission).
std::vector<std::vector<uint32_t>> Solver::Impl::cluster_candidates(double limit) const {
  std::map<std::pair<uint32_t, std::array<double, 3>>, std::vector<uint32_t>> groups;
  for (uint32_t p = 0; p < patches.size(); ++p) {
    Corners c{};
    corners_of(p_root[p], c);
    if (limit <= 0.0 || polygon_diameter(c, patches[p].corner_count) > 0.5 * limit) continue;
    const glm::dvec3& e = patches[p].emission;
    groups[{p_surface[p], {e.x, e.y, e.z}}].push_back(p);
  }
  std::vector<std::vector<uint32_t>> by_group;
  for (auto& [key, members] : groups) by_group.push_back(std::move(members));
  return by_group;
}

// Builds the cluster tree over `members` and cuts it from the top until the pieces fit
// (cluster_unfit); each piece of two or more patches becomes a unit.
void Solver::Impl::cut_into_units(const std::vector<uint32_t>& members, double limit) {
  const uint32_t begin = static_cast<uint32_t>(cluster_patch.size());
  cluster_patch.insert(cluster_patch.end(), members.begin(), members.end());
  const uint32_t root = static_cast<uint32_t>(c_nodes.size());
  c_nodes.emplace_back();
  build_cluster(root, begin, static_cast<uint32_t>(cluster_patch.size()), limit);
  std::vector<uint32_t> stack{root};
  while (!stack.empty()) {
    const uint32_t c = stack.back();
    stack.pop_back();
    if (cluster_unfit(c_nodes[c], limit) && c_nodes[c].child != kNone) {
      stack.push_back(c_nodes[c].child);
      stack.push_back(c_nodes[c].child + 1);
      continue;
    }
    if (c_nodes[c].end - c_nodes[c].begin < 2) continue;  // one patch: it shoots alone
    const uint32_t u = static_cast<uint32_t>(unit_patch.size());
    unit_patch.push_back(kNone);
    unit_node.push_back(c);
    u_unshot.push_back(0.0);
    for (uint32_t i = c_nodes[c].begin; i < c_nodes[c].end; ++i) {
      p_unit[cluster_patch[i]] = u;
      u_unshot[u] += p_unshot[cluster_patch[i]];
    }
  }
}

}  // namespace hemibake::solver
