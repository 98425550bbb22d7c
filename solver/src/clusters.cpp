// Clusters: small patches that shoot together, as binary trees of median cuts: patches of one
// surface (a wall in tiles), and faces of small objects across objects (boxes on a table, the
// balusters of a balustrade). Those shoot as volume clusters (Sillion 1995): one whole cube at the
// cluster's centre, each direction weighted by the faces that look that way. Where another
// object's surface passes through such a cluster (its centre could lie inside that object), its
// faces pool by orientation instead, so that each cluster shoots along one direction class from a
// hemicube in front of its faces (Smits et al. 1994 split a cluster's emission the same way).
#include "solver_impl.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <limits>
#include <map>
#include <unordered_map>
#include <numeric>

namespace hemibake::solver {
namespace {

// Hashes a point by its coordinates' bits (points that are equal bit for bit meet).
struct PointHash {
  size_t operator()(const glm::dvec3& p) const {
    size_t h = 0;
    for (int a = 0; a < 3; ++a) h = h * 1000003u ^ std::hash<double>()(p[a]);
    return h;
  }
};

// The class of a normal by its dominant axis and sign (six classes): faces of small objects
// cluster with faces of like orientation only.
int orientation_class(const glm::dvec3& n) {
  const glm::dvec3 a = glm::abs(n);
  const int axis = a.x >= a.y && a.x >= a.z ? 0 : a.y >= a.z ? 1 : 2;
  return 2 * axis + (n[axis] < 0.0 ? 1 : 0);
}

}  // namespace


// Per patch, its object: the least patch of those joined to it through common corner points (a
// box's faces, and a double-sided box's other sides too).
std::vector<uint32_t> Solver::Impl::objects() const {
  std::vector<uint32_t> object(patches.size());
  std::iota(object.begin(), object.end(), 0u);
  auto find = [&](uint32_t i) {
    while (object[i] != i) i = object[i] = object[object[i]];
    return i;
  };
  std::unordered_map<glm::dvec3, uint32_t, PointHash> first;  // per corner point: a patch there
  for (uint32_t q = 0; q < patches.size(); ++q)
    for (uint32_t k = 0; k < patches[q].corner_count; ++k) {
      const auto [it, fresh] = first.emplace(patches[q].corners[k], q);
      if (fresh) continue;
      const uint32_t a = find(q), b = find(it->second);
      if (a != b) object[std::max(a, b)] = std::min(a, b);
    }
  for (uint32_t q = 0; q < patches.size(); ++q) object[q] = find(q);
  return object;
}

// Whether patch q is the inner side of a double-sided object: it has a twin (the same points facing
// the other way) and faces its object's centroid (`centre`: the sum of the object's patches'
// centres times area, and the area). Such a side (a double-sided ball's or box's inside) sends its
// light into the object, where a volume cluster at the object's centre would send it out through
// the other side; it clusters by orientation instead. A flat double-sided sheet has no inner side.
bool Solver::Impl::inner_side(uint32_t q, const glm::dvec4& object_centre) const {
  if (prep.twin[q] == kNone) return false;
  const glm::dvec3 centre = glm::dvec3(object_centre) / object_centre.w;
  return glm::dot(prep.normal[q], centre - polygon_centre(patches[q].corners, patches[q].corner_count)) >
         kRoundingLength * prep.diagonal;
}

// A volume pool's cut: along the widest axis of the patch centres' box [lo, hi], at the widest
// gap between centres in its middle half (between objects), or else at its middle; the median
// where that leaves a side empty. Median cuts by count would halve objects: six spheres cut at the
// median part the middle ones.
uint32_t Solver::Impl::gap_cut(uint32_t begin, uint32_t end, const glm::dvec3& lo, const glm::dvec3& hi) {
  const glm::dvec3 ext = hi - lo;
  const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : ext.y >= ext.z ? 1 : 2;
  auto key = [&](uint32_t q) { return polygon_centre(patches[q].corners, patches[q].corner_count)[axis]; };
  std::vector<std::pair<double, uint32_t>> sorted;
  sorted.reserve(end - begin);
  for (uint32_t i = begin; i < end; ++i) sorted.emplace_back(key(cluster_patch[i]), cluster_patch[i]);
  std::sort(sorted.begin(), sorted.end());
  const double a = lo[axis] + 0.25 * ext[axis], b = hi[axis] - 0.25 * ext[axis];
  size_t cut = 0;
  double widest = 0.0;
  for (size_t i = 1; i < sorted.size(); ++i) {
    const double g = sorted[i].first - sorted[i - 1].first;
    if (g > widest && sorted[i].first >= a && sorted[i - 1].first <= b) {
      widest = g;
      cut = i;
    }
  }
  if (widest < 0.05 * ext[axis]) {
    // No clear gap: at the middle.
    const double m = 0.5 * (lo[axis] + hi[axis]);
    cut = static_cast<size_t>(std::lower_bound(sorted.begin(), sorted.end(), std::make_pair(m, 0u)) - sorted.begin());
  }
  if (cut == 0 || cut == sorted.size()) cut = sorted.size() / 2;
  for (size_t i = 0; i < sorted.size(); ++i) cluster_patch[begin + i] = sorted[i].second;
  return begin + static_cast<uint32_t>(cut);
}

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
  node.volume = building_volume;
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
    // A volume pool's tree is cut on its centres only: its clusters hold every orientation.
    const bool by_normals = !building_volume && spread > 1.0 && spread >= width && spread >= thick;
    // Along the normal when that is due and the centres lie at more than one depth there.
    double dlo = std::numeric_limits<double>::max(), dhi = std::numeric_limits<double>::lowest();
    if (!building_volume && !by_normals && thick > 1.0 && thick >= width)
      for (uint32_t i = begin; i < end; ++i) {
        dlo = std::min(dlo, along(cluster_patch[i]).x);
        dhi = std::max(dhi, along(cluster_patch[i]).x);
      }
    uint32_t mid;
    if (building_volume)
      mid = gap_cut(begin, end, clo, chi);
    else if (by_normals)
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
  std::map<std::array<double, 3>, std::vector<uint32_t>> volume_pooled;  // by emission
  // Per object (patches joined by common corner points): its area centroid (inner_side), for
  // volume clusters only.
  const bool volume = params.cluster_volume && params.cluster_across && limit > 0.0;
  const std::vector<uint32_t> object = volume ? objects() : std::vector<uint32_t>{};
  std::vector<glm::dvec4> object_centre(volume ? patches.size() : 0, glm::dvec4(0.0));
  for (uint32_t q = 0; volume && q < patches.size(); ++q)
    object_centre[object[q]] +=
        glm::dvec4(polygon_centre(patches[q].corners, patches[q].corner_count) * prep.area[q], prep.area[q]);
  for (const std::vector<uint32_t>& members : cluster_candidates(limit)) {
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
    for (uint32_t q : members)
      for (uint32_t k = 0; k < patches[q].corner_count; ++k) {
        lo = glm::min(lo, patches[q].corners[k]);
        hi = glm::max(hi, patches[q].corners[k]);
      }
    if (params.cluster_across && glm::distance(lo, hi) <= 0.5 * limit) {
      const glm::dvec3& e = patches[members[0]].emission;
      for (uint32_t q : members) {
        if (volume && !inner_side(q, object_centre[object[q]])) {
          volume_pooled[{e.x, e.y, e.z}].push_back(q);
          continue;
        }
        // Each patch by its own normal: a small sphere's facets go to six pools, not one.
        pooled[{orientation_class(prep.normal[q]), {e.x, e.y, e.z}}].push_back(q);
      }
      continue;
    }
    if (members.size() >= 2) cut_into_units(members, limit);
  }
  // What no volume cluster takes pools by orientation.
  for (auto& [e, members] : volume_pooled) {
    std::vector<uint32_t> left;
    cut_into_volume_units(members, limit, left);
    for (uint32_t q : left) pooled[{orientation_class(prep.normal[q]), e}].push_back(q);
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

// A volume pool's tree, cut on centres from the top until the pieces are at most `limit` wide; a
// piece that another object's surface passes through (foreign_inside) is cut further while it has
// four or more patches, else its patches go to `left`, as do single patches.
void Solver::Impl::cut_into_volume_units(const std::vector<uint32_t>& members, double limit, std::vector<uint32_t>& left) {
  if (members.size() < 2) {
    left.insert(left.end(), members.begin(), members.end());
    return;
  }
  const uint32_t begin = static_cast<uint32_t>(cluster_patch.size());
  cluster_patch.insert(cluster_patch.end(), members.begin(), members.end());
  const uint32_t root = static_cast<uint32_t>(c_nodes.size());
  c_nodes.emplace_back();
  building_volume = true;
  build_cluster(root, begin, static_cast<uint32_t>(cluster_patch.size()), limit);
  building_volume = false;
  std::vector<uint32_t> member_stamp(patches.size(), 0);
  uint32_t stamp_value = 0;
  std::vector<uint32_t> stack{root};
  while (!stack.empty()) {
    const uint32_t c = stack.back();
    stack.pop_back();
    const ClusterNode& node = c_nodes[c];
    const uint32_t count = node.end - node.begin;
    const bool wide = node.diameter > limit;
    const bool foreign = count >= 2 && !wide && foreign_inside(node, member_stamp, ++stamp_value);
    if ((wide || (foreign && count >= 4)) && node.child != kNone) {
      stack.push_back(node.child);
      stack.push_back(node.child + 1);
      continue;
    }
    if (count < 2 || wide || foreign) {
      for (uint32_t i = node.begin; i < node.end; ++i) left.push_back(cluster_patch[i]);
      continue;
    }
    const uint32_t u = static_cast<uint32_t>(unit_patch.size());
    unit_patch.push_back(kNone);
    unit_node.push_back(c);
    u_unshot.push_back(0.0);
    for (uint32_t i = node.begin; i < node.end; ++i) {
      p_unit[cluster_patch[i]] = u;
      u_unshot[u] += p_unshot[cluster_patch[i]];
    }
  }
}

// Whether a patch of another surface than the node's passes through its bounding box (shrunk by a
// hundredth of its width, so that a floor the boxes stand on or a wall they touch does not count):
// the box's centre might lie inside that surface's object, whose inner faces a cube there would
// see. (The rest of a surface the node holds part of, half a sphere's, stays behind the part's
// faces as seen from its centre.) `member_stamp` is scratch, per surface; `stamp_value` new for
// each call.
bool Solver::Impl::foreign_inside(const ClusterNode& node, std::vector<uint32_t>& member_stamp, uint32_t stamp_value) const {
  for (uint32_t i = node.begin; i < node.end; ++i) {
    const uint32_t q = cluster_patch[i];
    member_stamp[p_surface[q]] = stamp_value;
    if (prep.twin[q] != kNone) member_stamp[p_surface[prep.twin[q]]] = stamp_value;  // out of its cube too
  }
  const double margin = std::max(0.01 * node.diameter, kRoundingLength * prep.diagonal);
  const glm::dvec3 lo = node.box[0] + margin, hi = node.box[7] - margin;
  if (lo.x >= hi.x || lo.y >= hi.y || lo.z >= hi.z) return false;  // flat: nothing passes through
  auto overlaps = [&](const glm::dvec3& a, const glm::dvec3& b) {
    return a.x <= hi.x && b.x >= lo.x && a.y <= hi.y && b.y >= lo.y && a.z <= hi.z && b.z >= lo.z;
  };
  return find_patch(overlaps, [&](uint32_t q) {
    if (member_stamp[p_surface[q]] == stamp_value || !overlaps(p_lo[q], p_hi[q])) return false;
    // The patch's plane cuts the box: corners on both sides of it.
    const glm::dvec3& n = prep.normal[q];
    const double d0 = glm::dot(n, patches[q].corners[0]);
    bool below = false, above = false;
    for (int k = 0; k < 8; ++k) {
      const double d = glm::dot(n, glm::dvec3(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z)) - d0;
      below = below || d < 0.0;
      above = above || d > 0.0;
    }
    return below && above;
  });
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
