// The radiosity mesh: leaf elements with shared vertices, vertex radiosity averaged per surface,
// and in each element's boundary loop the hanging vertices of finer neighbours and the points of
// other surfaces that meet its edges (with its own light there).
#include "solver_impl.h"

#include <algorithm>
#include <functional>
#include <numbers>
#include <unordered_map>
#include <unordered_set>

namespace hemibake::solver {

// A vertex covered by a surface resting on its own or hung just in front of it (covered, facing
// either way: the floor under a block, the ceiling above a lamp 1 mm under it) is seen by no one,
// yet the elements around it interpolate its value into what is seen: the ceiling above a one-sided
// lamp is dark, and an element reaching from it past the lamp's outline showed a dark band 10 to
// 30 cm wide beside the lamp (above a double-sided lamp, a bright halo). So does a vertex on the
// outline of what covers it (on the loop of a covered element): the covered side's light shows only
// through the gap. Such a vertex shows the mean of the other vertices on the loops of the
// uncovered elements around it; one with none keeps its own light. Covered here means within the
// whole gap (kCoverGap), whatever the element's size: an element in the gap behind a cabinet 5 cm
// from a wall is seen only through the gap even when smaller than 5 cm, and with its size as the
// reach (gap_covered) the small elements along the cabinet's outline counted as open, and the
// wall's vertices beside them 10 to 20 cm inside the gap showed their light. `m` holds the mesh's elements
// (in the order of `leaves`) and loops, and the radiosity of the solver's own vertices.
//
// The elements covered all over keep their own light at such a vertex (the mean of theirs around
// it): the gap is seen too, past its opening at a slant. With the open side's light there, a 2 cm
// slot behind a bookshelf showed the lit wall's light fading over the 37 cm element inside its
// end, where the path tracer finds none past the first centimetres. An element reaching out of
// the gap (a shelf's back panel, its centre behind a book and its top above it) shows the open
// light as before: its open part is seen head-on. The returned side says which elements are
// covered all over and that light, per vertex (split_covered_side).
constexpr double kCornerInset = 0.02;  // corners pulled this share towards the centre

Solver::Impl::CoveredSide Solver::Impl::show_uncovered_light(const std::vector<uint32_t>& sorted, Mesh& m) const {
  const size_t n = vpos.size();
  CoveredSide side;
  std::vector<uint32_t> patch(n, kNone);
  for (uint32_t e : sorted)
    for (uint32_t k = 0; k < corner_count(e); ++k) patch[e_corner[e][k]] = e_patch[e];
  std::vector<char> hidden(n, 0), leaf_hidden(sorted.size(), 0);
  side.leaf.assign(sorted.size(), 0);
  bool any = false;
  const double gap = kCoverGap * prep.diagonal;
  for (size_t v = 0; v < n; ++v)
    if (patch[v] != kNone && covered(patch[v], vpos[v], gap, true)) hidden[v] = any = true;
  for (size_t i = 0; i < sorted.size(); ++i) {
    const uint32_t e = sorted[i];
    if (!covered(e_patch[e], e_centre[e], gap, true)) continue;
    leaf_hidden[i] = 1;
    for (uint32_t a = m.elements[i].boundary_begin; a < m.elements[i].boundary_end; ++a)
      if (m.boundary[a] < n) hidden[m.boundary[a]] = any = true;
    // Covered all over: its corners too, pulled a little towards its centre (those on the outline
    // of what covers it lie on its edge).
    bool whole = true;
    for (uint32_t k = 0; k < corner_count(e) && whole; ++k) {
      const glm::dvec3& x = vpos[e_corner[e][k]];
      whole = covered(e_patch[e], x + kCornerInset * (e_centre[e] - x), gap, true);
    }
    side.leaf[i] = whole;
  }
  if (!any) return side;
  std::vector<glm::dvec3> sum(n, glm::dvec3(0.0)), covered_sum(n, glm::dvec3(0.0));
  std::vector<uint32_t> count(n, 0);
  std::vector<double> covered_area(n, 0.0);
  for (size_t i = 0; i < sorted.size(); ++i) {
    const Mesh::Element& el = m.elements[i];
    for (uint32_t a = el.boundary_begin; a < el.boundary_end; ++a) {
      const uint32_t v = m.boundary[a];
      if (v >= n || !hidden[v]) continue;
      if (side.leaf[i]) {
        covered_sum[v] += el.radiosity * el.area;
        covered_area[v] += el.area;
      }
      if (leaf_hidden[i]) continue;
      for (uint32_t b = el.boundary_begin; b < el.boundary_end; ++b) {
        const uint32_t u = m.boundary[b];
        if (u >= n || hidden[u]) continue;
        sum[v] += m.radiosity[u];
        ++count[v];
      }
    }
  }
  for (size_t v = 0; v < n; ++v) {
    if (count[v] == 0) continue;
    if (covered_area[v] > 0.0) side.light.emplace(static_cast<uint32_t>(v), covered_sum[v] / covered_area[v]);
    m.radiosity[v] = sum[v] / static_cast<double>(count[v]);
  }
  return side;
}

// Per vertex of the solver's own: whether it lies on its surface's outline, where the angles of
// the elements around it (pi where it hangs on a larger element's edge) fall short of a full turn.
std::vector<char> Solver::Impl::outline_vertices(const Mesh& m) const {
  const size_t n = vpos.size();
  std::vector<double> turn(n, 0.0);
  for (const Mesh::Element& el : m.elements) {
    const uint32_t nc = el.corner_count;
    for (uint32_t a = el.boundary_begin; a < el.boundary_end; ++a) {
      const uint32_t v = m.boundary[a];
      if (v >= n) continue;
      uint32_t k = 0;
      while (k < nc && el.corners[k] != v) ++k;
      if (k == nc) {
        turn[v] += std::numbers::pi;  // hangs on this element's edge
        continue;
      }
      const glm::dvec3 x = m.positions[v];
      const glm::dvec3 to_prev = m.positions[el.corners[(k + nc - 1) % nc]] - x, to_next = m.positions[el.corners[(k + 1) % nc]] - x;
      turn[v] += std::acos(std::clamp(glm::dot(to_prev, to_next) / (glm::length(to_prev) * glm::length(to_next)), -1.0, 1.0));
    }
  }
  std::vector<char> out(n, 0);
  for (size_t v = 0; v < n; ++v) out[v] = turn[v] > 0.0 && turn[v] < 2.0 * std::numbers::pi - 0.1;
  return out;
}

// A vertex on a surface's outline averages only the elements on one side of it, whose centres lie
// inward: where the light changes across them, the outline showed the light half an element in (a
// lamp's pool on a wall of 12.5 cm elements: the wall's edges 12 to 15 % too bright, 5 % over the
// outer half of the wall). An element with corners both inside the surface and on its outline fits
// a linear light to its mean (at its centre) and to its inside corners' values, by least squares in
// its plane (along one direction when they lie on one line), and gives its outline corners that
// light, at least 0; an outline vertex shows the area-weighted mean of what its elements give it.
// The outline is outline_vertices'. `fixed` vertices keep their value (gathered, or beside a patch
// standing on the surface). `m` holds the elements (in the order of `sorted`), loops and vertex
// radiosity.
void Solver::Impl::extrapolate_to_outline(const std::vector<uint32_t>& sorted, const std::vector<char>& fixed,
                                          Mesh& m) const {
  const size_t n = vpos.size();
  const std::vector<char> outline = outline_vertices(m);
  auto on_outline = [&](uint32_t v) { return outline[v] != 0; };
  std::vector<glm::dvec3> sum(n, glm::dvec3(0.0));
  std::vector<double> weight(n, 0.0);
  for (size_t i = 0; i < sorted.size(); ++i) {
    const Mesh::Element& el = m.elements[i];
    const uint32_t e = sorted[i], nc = el.corner_count;
    bool outer = false;
    for (uint32_t k = 0; k < nc; ++k) outer = outer || (on_outline(el.corners[k]) && !fixed[el.corners[k]]);
    if (!outer) continue;
    // In the element's plane: axes u, w; the fit's normal equations over the inside corners.
    const glm::dvec3& normal = prep.normal[e_patch[e]];
    const glm::dvec3 u = glm::normalize(m.positions[el.corners[1]] - m.positions[el.corners[0]]);
    const glm::dvec3 w = glm::cross(normal, u);
    auto in_plane = [&](uint32_t v) {
      const glm::dvec3 d = m.positions[v] - e_centre[e];
      return glm::dvec2(glm::dot(d, u), glm::dot(d, w));
    };
    double suu = 0.0, suw = 0.0, sww = 0.0;
    glm::dvec3 ru(0.0), rw(0.0);
    uint32_t inside = 0;
    for (uint32_t k = 0; k < nc; ++k) {
      const uint32_t v = el.corners[k];
      if (on_outline(v)) continue;
      const glm::dvec2 d = in_plane(v);
      const glm::dvec3 r = m.radiosity[v] - el.radiosity;
      suu += d.x * d.x;
      suw += d.x * d.y;
      sww += d.y * d.y;
      ru += d.x * r;
      rw += d.y * r;
      ++inside;
    }
    if (inside == 0) continue;
    const double det = suu * sww - suw * suw, trace = suu + sww;
    glm::dvec3 gu(0.0), gw(0.0);
    if (det > 1e-6 * trace * trace) {
      gu = (sww * ru - suw * rw) / det;
      gw = (suu * rw - suw * ru) / det;
    } else {
      // The inside corners on one line through the centre: the slope along it alone. The sums
      // are then those of d = t * dir: ru = dir.x sum(t r), rw = dir.y sum(t r), trace = sum(t^2).
      gu = ru / trace;
      gw = rw / trace;
    }
    for (uint32_t k = 0; k < nc; ++k) {
      const uint32_t v = el.corners[k];
      if (!on_outline(v) || fixed[v]) continue;
      const glm::dvec2 d = in_plane(v);
      sum[v] += glm::max(el.radiosity + d.x * gu + d.y * gw, glm::dvec3(0.0)) * el.area;
      weight[v] += el.area;
    }
  }
  for (size_t v = 0; v < n; ++v)
    if (weight[v] > 0.0) m.radiosity[v] = sum[v] / weight[v];
}

// Per leaf (in the order of `sorted`), the one-sided patches standing on its surface across or along
// it (at most two, then kNone): an edge of theirs lies in the leaf's plane and meets it, and they
// reach in front of it (contact_crosses: the sides of a block without a bottom on a floor). A leaf
// whose centre lies behind such a patch is mostly under the block, dark and seen by no one, and the
// vertices on the open side of the patch leave it out of their mean: averaged in, it showed as a
// dark band in front of the block's foot (the floor 0.5 to 3 cm from a cabinet at 0.55 to 0.7 of
// the path tracer's light).
std::vector<std::array<uint32_t, 2>> Solver::Impl::standing_on(const std::vector<uint32_t>& sorted) const {
  std::vector<std::array<uint32_t, 2>> out(sorted.size(), {kNone, kNone});
  const double eps = kRoundingLength * prep.diagonal;
  for (size_t i = 0; i < sorted.size(); ++i) {
    const uint32_t e = sorted[i];
    const uint32_t p = e_patch[e];
    const glm::dvec3& n = prep.normal[p];
    glm::dvec3 lo, hi;
    element_box(e, lo, hi);
    auto near = [&](const glm::dvec3& blo, const glm::dvec3& bhi) { return boxes_meet(lo, hi, blo, bhi, eps); };
    uint32_t found = 0;
    find_patch(near, [&](uint32_t q) {
      if (q == p || prep.twin[q] != kNone || std::abs(glm::dot(prep.normal[q], n)) > 1.0 - 1e-6) return false;
      if (contact_length(e, q, -eps) > eps) out[i][found++] = q;
      return found == 2;
    });
  }
  return out;
}

namespace {

// Extra vertices: points of other surfaces on an element's edge, which take the light of the
// element's own surface there, linear along the edge: (1 - w) B(a) + w B(b).
struct Lerp {
  uint32_t a, b;
  double w;
};

// The covered elements (`covered_leaf`, per element of the mesh) take a copy of each vertex on
// their loops that shows the open side's light, at the same place with the covered side's light,
// and a copy of each extra vertex between such vertices, interpolated between the copies. Light
// then steps at a cover's outline, as it does across a gap's opening. `covered_light`: per vertex
// that shows the open side's light, the covered side's (show_uncovered_light). `own` is the count
// of the solver's own vertices; extra vertex own + i interpolates as lerp_from[i].
void split_covered_side(const std::vector<char>& covered_leaf, const std::unordered_map<uint32_t, glm::dvec3>& covered_light,
                        const std::vector<Lerp>& lerp_from, size_t own, Mesh& m) {
  if (covered_light.empty()) return;
  std::unordered_map<uint32_t, uint32_t> copy;
  std::function<uint32_t(uint32_t)> covered_copy = [&](uint32_t v) -> uint32_t {
    if (auto it = copy.find(v); it != copy.end()) return it->second;
    glm::dvec3 b(0.0);
    if (v < own) {
      const auto it = covered_light.find(v);
      if (it == covered_light.end()) return v;
      b = it->second;
    } else {
      const Lerp& l = lerp_from[v - own];
      const uint32_t a = covered_copy(l.a), c = covered_copy(l.b);
      if (a == l.a && c == l.b) return v;
      b = (1.0 - l.w) * m.radiosity[a] + l.w * m.radiosity[c];
    }
    const uint32_t out = static_cast<uint32_t>(m.positions.size());
    const glm::dvec3 x = m.positions[v];
    const uint8_t interpolated = m.interpolated[v];
    m.positions.push_back(x);
    m.radiosity.push_back(b);
    m.interpolated.push_back(interpolated);
    copy.emplace(v, out);
    return out;
  };
  for (size_t i = 0; i < m.elements.size(); ++i) {
    if (!covered_leaf[i]) continue;
    Mesh::Element& el = m.elements[i];
    for (uint32_t a = el.boundary_begin; a < el.boundary_end; ++a) m.boundary[a] = covered_copy(m.boundary[a]);
    for (uint32_t k = 0; k < el.corner_count; ++k) el.corners[k] = covered_copy(el.corners[k]);
  }
}

}  // namespace

// See Solver::mesh: an element's gathered corners may differ from its shot radiosity by this
// factor where the gather's budget left it unchecked for a split, by kCheckedMismatch where it
// was checked.
constexpr double kGatheredMismatch = 2.0;
constexpr double kCheckedMismatch = 4.0;

Mesh Solver::mesh(bool ambient) const {
  const Impl& s = *impl_;
  Mesh m;
  // Ambient term (Cohen et al. 1988): the unshot power spread over the scene and reflected on
  // average, per channel: ambient = R * sum(dB_i A_i) / sum(A_i), R = 1 / (1 - rho_mean).
  glm::dvec3 amb(0.0);
  if (ambient) {
    glm::dvec3 unshot(0.0), rho(0.0);
    for (uint32_t e : s.leaves) unshot += s.e_unshot[e] * s.e_area[e];
    for (uint32_t p = 0; p < s.patches.size(); ++p) rho += s.patches[p].reflectance * s.prep.area[p];
    rho /= s.prep.total_area;
    amb = unshot / s.prep.total_area / (glm::dvec3(1.0) - rho);
  }

  std::vector<uint32_t> leaves = s.leaves;
  std::sort(leaves.begin(), leaves.end(), [&](uint32_t a, uint32_t b) {
    return s.e_patch[a] != s.e_patch[b] ? s.e_patch[a] < s.e_patch[b] : a < b;
  });

  // Every vertex position, to find the vertices of other surfaces on an element's edge (they are
  // the same points, computed by the same midpoint arithmetic).
  struct PosHash {
    size_t operator()(const glm::dvec3& p) const {
      return std::hash<double>()(p.x) ^ (std::hash<double>()(p.y) * 31) ^ (std::hash<double>()(p.z) * 131);
    }
  };
  std::unordered_set<glm::dvec3, PosHash> positions(s.vpos.begin(), s.vpos.end());
  m.positions = s.vpos;
  std::vector<Lerp> lerp_from;                   // per extra vertex, in the order made
  std::unordered_map<uint64_t, uint32_t> extra;  // edge key -> extra vertex

  // Vertices of other patches on a patch's edges, per patch and edge, by distance from the edge's
  // first corner: those of its T-neighbours (PreparedScene::t_neighbours), which are vertices of its
  // own smoothing group and join its loops as they are, and those of its seam neighbours
  // (PreparedScene::seam_neighbours: a wall's foot on the floor, the other slope at a roof's ridge),
  // whose points join its loops as extra vertices with its own light, so that no triangle edge of
  // the output runs past a vertex of a surface it meets (rasterizers leave dotted gaps along such
  // an edge where the two sides are cut differently). Elements are cut by halving their own
  // edges, so along a shared line the other side's vertices fall between this patch's. Such a
  // vertex lies on its own patch's outline: each patch's outline vertices are listed once, per edge
  // and in order, and a neighbour's edge takes those within its extent by binary search (a floor
  // edged with 20 000 tiles took seconds when every pair scanned every vertex).
  const double on_edge = 1e-7 * s.prep.diagonal;
  struct EdgeVertex {
    double t;     // distance from the edge's first corner
    uint32_t v;   // a solver vertex of the other patch
    bool shared;  // of this patch's smoothing group: joins the loop itself
  };
  auto by_t = [](const EdgeVertex& x, const EdgeVertex& y) { return x.t != y.t ? x.t < y.t : x.v < y.v; };
  using EdgeList = std::vector<EdgeVertex>;
  std::vector<std::array<EdgeList, 4>> t_edges(s.patches.size());
  // Each patch edge's first corner, direction and length, and where x lies along it (distance from
  // the first corner) if within on_edge of it, else -1: on_segment without its square roots, since
  // every leaf's corners and every element's edges are tested against their patch's edges.
  struct EdgeFrame {
    glm::dvec3 origin, dir;
    double length;
  };
  std::vector<std::array<EdgeFrame, 4>> frames(s.patches.size());
  for (uint32_t p = 0; p < s.patches.size(); ++p)
    for (uint32_t k = 0; k < s.patches[p].corner_count; ++k) {
      const glm::dvec3& c0 = s.patches[p].corners[k];
      const glm::dvec3 d = s.patches[p].corners[(k + 1) % s.patches[p].corner_count] - c0;
      frames[p][k] = {c0, glm::normalize(d), glm::length(d)};
    }
  auto on_patch_edge = [&](uint32_t p, uint32_t k, const glm::dvec3& x) {
    const EdgeFrame& f = frames[p][k];
    const glm::dvec3 r = x - f.origin;
    const double t = glm::dot(r, f.dir);
    if (t < -on_edge || t > f.length + on_edge) return -1.0;
    const glm::dvec3 off = r - t * f.dir;
    return glm::dot(off, off) <= on_edge * on_edge ? std::clamp(t, 0.0, f.length) : -1.0;
  };
  {
    std::vector<std::pair<size_t, size_t>> range(s.patches.size(), {0, 0});
    for (size_t i = 0; i < leaves.size();) {
      size_t j = i;
      while (j < leaves.size() && s.e_patch[leaves[j]] == s.e_patch[leaves[i]]) ++j;
      range[s.e_patch[leaves[i]]] = {i, j};
      i = j;
    }
    std::vector<std::array<EdgeList, 4>> outline(s.patches.size());
    for (uint32_t q = 0; q < s.patches.size(); ++q) {
      if (s.prep.t_neighbours[q].empty() && s.prep.seam_neighbours[q].empty()) continue;
      for (size_t i = range[q].first; i < range[q].second; ++i)
        for (uint32_t c = 0; c < s.corner_count(leaves[i]); ++c) {
          const uint32_t v = s.e_corner[leaves[i]][c];
          for (uint32_t k = 0; k < s.patches[q].corner_count; ++k)
            if (const double t = on_patch_edge(q, k, s.vpos[v]); t >= 0.0) outline[q][k].push_back({t, v, false});
        }
      for (EdgeList& list : outline[q]) {
        std::sort(list.begin(), list.end(), by_t);
        list.erase(std::unique(list.begin(), list.end(), [](const auto& x, const auto& y) { return x.v == y.v; }), list.end());
      }
    }
    // Adds to p's edges the vertices of q's outline that lie strictly inside them.
    auto take = [&](uint32_t p, uint32_t q, bool shared) {
      const Patch& pa = s.patches[p];
      const Patch& pq = s.patches[q];
      for (uint32_t j = 0; j < pq.corner_count; ++j) {
        const EdgeList& theirs = outline[q][j];
        if (theirs.empty()) continue;
        const glm::dvec3& q0 = pq.corners[j];
        const glm::dvec3 dq = pq.corners[(j + 1) % pq.corner_count] - q0;
        const glm::dvec3 uq = dq / glm::length(dq);
        auto off_line = [&](const glm::dvec3& x) { return glm::length(x - q0 - uq * glm::dot(x - q0, uq)) > on_edge; };
        for (uint32_t k = 0; k < pa.corner_count; ++k) {
          // Edge k of p on the line of q's edge j: the part of q's list within p's edge.
          const glm::dvec3& a = pa.corners[k];
          const glm::dvec3& b = pa.corners[(k + 1) % pa.corner_count];
          if (off_line(a) || off_line(b)) continue;
          const double sa = glm::dot(a - q0, uq), sb = glm::dot(b - q0, uq);
          auto it = std::lower_bound(theirs.begin(), theirs.end(), EdgeVertex{std::min(sa, sb) - on_edge, 0, false}, by_t);
          for (; it != theirs.end() && it->t <= std::max(sa, sb) + on_edge; ++it)
            if (const double t = along_segment(s.vpos[it->v], a, b, on_edge); t > 0.0) t_edges[p][k].push_back({t, it->v, shared});
        }
      }
    };
    for (uint32_t p = 0; p < s.patches.size(); ++p) {
      for (uint32_t q : s.prep.t_neighbours[p]) take(p, q, true);
      for (uint32_t q : s.prep.seam_neighbours[p]) take(p, q, s.prep.smoothing_group[q] == s.prep.smoothing_group[p]);
      // One vertex per point: where several surfaces have a vertex (a room's corner, the two sides
      // of a double-sided wall), the first of this patch's group, or else the first.
      for (EdgeList& list : t_edges[p]) {
        std::sort(list.begin(), list.end(), by_t);
        size_t kept = 0;
        for (size_t i = 0; i < list.size();) {
          size_t j = i, pick = i;
          for (; j < list.size() && list[j].t - list[i].t <= on_edge; ++j)
            if (list[j].shared && !list[pick].shared) pick = j;
          list[kept++] = list[pick];
          i = j;
        }
        list.resize(kept);
      }
    }
  }
  // The element edge whose loop is being collected, if it lies along an edge of its patch with
  // vertices of other patches on it: that edge's list, its first corner and direction.
  const EdgeList* list_now = nullptr;
  glm::dvec3 edge_origin(0.0), edge_dir(0.0);
  auto along_patch_edge = [&](uint32_t patch, uint32_t a, uint32_t b) {
    list_now = nullptr;
    for (uint32_t k = 0; k < s.patches[patch].corner_count; ++k) {
      if (t_edges[patch][k].empty()) continue;
      if (on_patch_edge(patch, k, m.positions[a]) < 0.0 || on_patch_edge(patch, k, m.positions[b]) < 0.0) continue;
      list_now = &t_edges[patch][k];
      edge_origin = frames[patch][k].origin;
      edge_dir = frames[patch][k].dir;
      return;
    }
  };
  // The vertex of another patch strictly inside (a, b), a part of the element edge being
  // collected, nearest to a; or null.
  auto junction_on = [&](uint32_t a, uint32_t b) -> const EdgeVertex* {
    if (list_now == nullptr) return nullptr;
    const EdgeList& list = *list_now;
    const double ta = glm::dot(m.positions[a] - edge_origin, edge_dir), tb = glm::dot(m.positions[b] - edge_origin, edge_dir);
    const double lo = std::min(ta, tb) + on_edge, hi = std::max(ta, tb) - on_edge;
    if (ta < tb) {
      for (auto it = std::upper_bound(list.begin(), list.end(), EdgeVertex{lo, kNone, false}, by_t); it != list.end() && it->t < hi; ++it)
        if (it->v != a && it->v != b) return &*it;
    } else {
      auto it = std::lower_bound(list.begin(), list.end(), EdgeVertex{hi, 0, false}, by_t);
      while (it != list.begin()) {
        --it;
        if (it->t <= lo) break;
        if (it->v != a && it->v != b) return &*it;
      }
    }
    return nullptr;
  };
  // A new vertex at point x on edge (a, b), lit as the edge there.
  auto add_extra = [&](uint32_t a, uint32_t b, const glm::dvec3& x) {
    const uint32_t mid = static_cast<uint32_t>(m.positions.size());
    const glm::dvec3 d = m.positions[b] - m.positions[a];
    m.positions.push_back(x);
    lerp_from.push_back({a, b, std::clamp(glm::dot(x - m.positions[a], d) / glm::dot(d, d), 0.0, 1.0)});
    extra.emplace(edge_key(a, b), mid);
    return mid;
  };
  // Collects the vertices strictly inside edge (a, b), in order from a to b.
  std::function<void(uint32_t, uint32_t)> hanging = [&](uint32_t a, uint32_t b) {
    uint32_t mid = kNone;
    if (auto it = s.midpoints.find(edge_key(a, b)); it != s.midpoints.end()) {
      mid = it->second;
    } else if (auto ex = extra.find(edge_key(a, b)); ex != extra.end()) {
      mid = ex->second;
    } else if (const EdgeVertex* t = junction_on(a, b)) {
      mid = t->shared ? t->v : add_extra(a, b, s.vpos[t->v]);
    } else {
      const glm::dvec3 pm = 0.5 * (m.positions[a] + m.positions[b]);
      if (positions.count(pm)) mid = add_extra(a, b, pm);
    }
    if (mid == kNone) return;
    hanging(a, mid);
    m.boundary.push_back(mid);
    hanging(mid, b);
  };

  // Per vertex: the area-weighted sums of the elements around it, and of those not under a patch
  // standing on the surface (standing_on).
  std::vector<glm::dvec3> acc(s.vpos.size(), glm::dvec3(0.0));
  std::vector<glm::dvec3> acc_open = acc;
  std::vector<double> weight(s.vpos.size(), 0.0);
  std::vector<double> weight_open = weight;
  const std::vector<std::array<uint32_t, 2>> standing = s.standing_on(leaves);
  const double standing_eps = kRoundingLength * s.prep.diagonal;
  // Whether leaf i (element e) lies under a patch standing on it, as seen from its vertex v on the
  // patch's open side.
  auto under = [&](size_t i, uint32_t e, uint32_t v) {
    for (uint32_t q : standing[i]) {
      if (q == kNone) break;
      const glm::dvec3& nq = s.prep.normal[q];
      const glm::dvec3& aq = s.patches[q].corners[0];
      if (glm::dot(nq, s.e_centre[e] - aq) < 0.0 && glm::dot(nq, m.positions[v] - aq) >= -standing_eps) return true;
    }
    return false;
  };
  m.elements.reserve(leaves.size());
  // A gathered vertex shows its own light; where that misstates an element, its vertices show the
  // elements' mean instead. The shot gives each element the mean of its light; the mean of its
  // gathered corners (what the mesh shows over it, interpolated) must agree within a factor of
  // kGatheredMismatch (or the radiosity tolerance) where the gather's budget left the element
  // unchecked for a split. A wall's back standing on a ground lit behind it: the corners at its
  // foot see the ground fill half their view, the light falls off within centimetres up the wall,
  // and an element 1.6 m high showed the foot's light interpolated over itself, 14 times the path
  // tracer's light there. An element the gather checked may differ by kCheckedMismatch: at a
  // block's foot on the Cornell box the gathered corners are nearer the path tracer (a factor of
  // 2 there too: p90 8.0 % instead of 7.9 %), and at no limit Blender's lights file went from
  // p90 1.4 % to 1.9 %.
  auto gathered = [&](uint32_t v) { return s.gather_done && v < s.v_gathered.size() && s.v_gathered[v]; };
  // What gathered vertex v shows on element e: its own light (gather.cpp); the lights' direct light
  // and light from covered pieces (e_gap) as the element's.
  auto gathered_light = [&](uint32_t e, uint32_t v) {
    const Patch& patch = s.patches[s.e_patch[e]];
    return patch.emission + s.e_light[e] + s.e_gap[e] + patch.reflectance * (s.v_irr[v] + amb);
  };
  std::vector<uint8_t> keep_mean(s.vpos.size(), 0);
  if (s.gather_done)
    for (uint32_t e : leaves) {
      const double factor = e < s.e_settled.size() && s.e_settled[e] ? kCheckedMismatch : kGatheredMismatch;
      const uint32_t nc = s.corner_count(e);
      const glm::dvec3 mean_light = s.e_b[e] + s.patches[s.e_patch[e]].reflectance * amb;
      glm::dvec3 shown(0.0);
      bool any = false;
      for (uint32_t k = 0; k < nc; ++k) {
        const uint32_t v = s.e_corner[e][k];
        const bool g = gathered(v);
        any = any || g;
        shown += g ? gathered_light(e, v) : mean_light;
      }
      if (!any) continue;
      const double got = mean(shown) / nc, want = mean(mean_light);
      if (std::abs(got - want) > s.gather_tolerance &&
          (got > factor * want || want > factor * got))
        for (uint32_t k = 0; k < nc; ++k) keep_mean[s.e_corner[e][k]] = 1;
    }
  for (uint32_t e : leaves) {
    Mesh::Element el;
    el.patch = s.e_patch[e];
    el.corner_count = s.corner_count(e);
    el.corners = s.e_corner[e];
    el.area = s.e_area[e];
    el.radiosity = s.e_b[e] + s.patches[el.patch].reflectance * amb;
    el.buried = s.buried(e);
    HEMIBAKE_DCHECK(el.radiosity.x >= 0.0 && el.radiosity.y >= 0.0 && el.radiosity.z >= 0.0);
    el.boundary_begin = static_cast<uint32_t>(m.boundary.size());
    for (uint32_t k = 0; k < el.corner_count; ++k) {
      const uint32_t a = el.corners[k], b = el.corners[(k + 1) % el.corner_count];
      m.boundary.push_back(a);
      along_patch_edge(el.patch, a, b);
      hanging(a, b);
    }
    el.boundary_end = static_cast<uint32_t>(m.boundary.size());
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const uint32_t v = m.boundary[i];
      if (v >= s.vpos.size()) continue;  // another surface's point: interpolated below
      const glm::dvec3 b = gathered(v) && !keep_mean[v] ? gathered_light(e, v) : el.radiosity;
      acc[v] += b * el.area;
      weight[v] += el.area;
      if (!under(m.elements.size(), e, v)) {
        acc_open[v] += b * el.area;
        weight_open[v] += el.area;
      }
    }
    m.elements.push_back(el);
  }
  for (uint32_t v : m.boundary) HEMIBAKE_DCHECK(v < m.positions.size());
  m.radiosity.resize(m.positions.size(), glm::dvec3(0.0));
  std::vector<char> fixed(s.vpos.size(), 0);
  for (size_t v = 0; v < s.vpos.size(); ++v) {
    if (weight_open[v] > 0.0) m.radiosity[v] = acc_open[v] / weight_open[v];
    else if (weight[v] > 0.0) m.radiosity[v] = acc[v] / weight[v];
    fixed[v] = weight_open[v] != weight[v] || (gathered(static_cast<uint32_t>(v)) && !keep_mean[v]);
  }
  s.extrapolate_to_outline(leaves, fixed, m);
  const Impl::CoveredSide covered_side = s.show_uncovered_light(leaves, m);
  // Extra vertices were created in order, each from an earlier vertex pair.
  for (size_t i = 0; i < lerp_from.size(); ++i) {
    const auto [a, b, w] = lerp_from[i];
    m.radiosity[s.vpos.size() + i] = (1.0 - w) * m.radiosity[a] + w * m.radiosity[b];
  }
  m.interpolated.assign(m.positions.size(), 0);
  std::fill(m.interpolated.begin() + static_cast<std::ptrdiff_t>(s.vpos.size()), m.interpolated.end(), 1);
  split_covered_side(covered_side.leaf, covered_side.light, lerp_from, s.vpos.size(), m);
  return m;
}

}  // namespace hemibake::solver
