// The element quadtree: vertices, elements as structure of arrays, splits, and the per-element
// scratch that grows with them.
#include "solver_impl.h"

#include <limits>

namespace hemibake::solver {

// The vertex halfway along edge (a, b), made once: the elements on both sides of the edge share
// it, so a finer neighbour's vertex lies on a coarser element's edge, not off it.
uint32_t Solver::Impl::midpoint(uint32_t a, uint32_t b) {
  auto [it, fresh] = midpoints.try_emplace(edge_key(a, b), static_cast<uint32_t>(vpos.size()));
  if (fresh) vpos.push_back(0.5 * (vpos[a] + vpos[b]));
  return it->second;
}

// Appends an element to every per-element array (the scratch ones too, so that no shot has to
// check their sizes).
uint32_t Solver::Impl::add_element(uint32_t patch, uint32_t parent,
                                   const std::array<uint32_t, 4>& corners, const glm::dvec3& b,
                                   const glm::dvec3& unshot) {
  const uint32_t id = static_cast<uint32_t>(e_patch.size());
  HEMIBAKE_DCHECK(patch < patches.size());
  HEMIBAKE_DCHECK(parent == kNone || (parent < id && e_patch[parent] == patch));
  for (uint32_t i = 0; i < patches[patch].corner_count; ++i) HEMIBAKE_DCHECK(corners[i] < vpos.size());
  e_patch.push_back(patch);
  HEMIBAKE_DCHECK(prep.occlusion_group[patch] < kCoveredBit);
  e_group.push_back(prep.occlusion_group[patch]);
  e_cover.push_back(kNone);
  e_parent.push_back(parent);
  e_child.push_back(kNone);
  e_corner.push_back(corners);
  Corners c{};
  corners_of(id, c);
  const uint32_t nc = patches[patch].corner_count;
  e_area.push_back(polygon_area(c, nc));
  const glm::dvec3 centre = polygon_centre(c, nc);
  double radius = 0.0;
  for (uint32_t i = 0; i < nc; ++i) radius = std::max(radius, glm::distance(centre, c[i]));
  e_centre.push_back(centre);
  e_radius.push_back(radius);
  e_under.push_back(under_foot(id));
  set_covered(id, cover_at_centre(id));
  e_b.push_back(b);
  e_unshot.push_back(unshot);
  f_begin.push_back(0);
  f_end.push_back(0);
  e_stamp.push_back(0);
  e_ff.push_back(0.0);
  e_ff_open.push_back(0.0);
  if (parent == kNone && patches[patch].corner_count == 4)
    e_uv.push_back({glm::dvec2(0, 0), glm::dvec2(1, 0), glm::dvec2(1, 1), glm::dvec2(0, 1)});
  else if (parent == kNone)
    e_uv.push_back({glm::dvec2(0, 0), glm::dvec2(1, 0), glm::dvec2(0, 1), glm::dvec2(0, 0)});
  else
    e_uv.push_back({});  // set by split()
  e_mark.push_back(0);
  e_exact.push_back(0.0);
  e_exact_stamp.push_back(0);
  e_light.push_back(parent != kNone ? e_light[parent] : glm::dvec3(0.0));
  e_gap.push_back(parent != kNone ? e_gap[parent] : glm::dvec3(0.0));
  e_cov.push_back(-1);
  e_mean.push_back(b);
  e_low.push_back(mean(b));
  e_high.push_back(mean(b));
  return id;
}

// Splits leaf e into four consecutive children, in child_corners' order.
void Solver::Impl::split(uint32_t e) {
  HEMIBAKE_DCHECK(e < e_child.size() && e_child[e] == kNone);  // only leaves split
  const std::array<uint32_t, 4> c = e_corner[e];
  const uint32_t p = e_patch[e];
  // Children start with the parent's radiosity and unshot radiosity: energy carries over.
  const glm::dvec3 b = e_b[e], u = e_unshot[e];
  std::array<std::array<uint32_t, 4>, 4> kids;
  if (patches[p].corner_count == 4) {
    const uint32_t m01 = midpoint(c[0], c[1]), m12 = midpoint(c[1], c[2]);
    const uint32_t m23 = midpoint(c[2], c[3]), m30 = midpoint(c[3], c[0]);
    const uint32_t ctr = static_cast<uint32_t>(vpos.size());
    vpos.push_back(0.25 * (vpos[c[0]] + vpos[c[1]] + vpos[c[2]] + vpos[c[3]]));
    kids = {{{c[0], m01, ctr, m30}, {m01, c[1], m12, ctr}, {ctr, m12, c[2], m23}, {m30, ctr, m23, c[3]}}};
  } else {
    const uint32_t m01 = midpoint(c[0], c[1]), m12 = midpoint(c[1], c[2]), m20 = midpoint(c[2], c[0]);
    kids = {{{c[0], m01, m20, kNone}, {m01, c[1], m12, kNone}, {m20, m12, c[2], kNone},
             {m12, m20, m01, kNone}}};
  }
  split_log.push_back(e);
  const uint32_t first = add_element(p, e, kids[0], b, u);
  for (int k = 1; k < 4; ++k) add_element(p, e, kids[k], b, u);
  e_child[e] = first;
  // The children's corners in the patch's (u, v), split as their positions are.
  const std::array<glm::dvec2, 4> t = e_uv[e];
  if (patches[p].corner_count == 4) {
    const glm::dvec2 m01 = 0.5 * (t[0] + t[1]), m12 = 0.5 * (t[1] + t[2]), m23 = 0.5 * (t[2] + t[3]),
                     m30 = 0.5 * (t[3] + t[0]), ctr = 0.25 * (t[0] + t[1] + t[2] + t[3]);
    e_uv[first] = {t[0], m01, ctr, m30};
    e_uv[first + 1] = {m01, t[1], m12, ctr};
    e_uv[first + 2] = {ctr, m12, t[2], m23};
    e_uv[first + 3] = {m30, ctr, m23, t[3]};
  } else {
    const glm::dvec2 m01 = 0.5 * (t[0] + t[1]), m12 = 0.5 * (t[1] + t[2]), m20 = 0.5 * (t[2] + t[0]);
    e_uv[first] = {t[0], m01, m20, {}};
    e_uv[first + 1] = {m01, t[1], m12, {}};
    e_uv[first + 2] = {m20, m12, t[2], {}};
    e_uv[first + 3] = {m12, m20, m01, {}};
  }
  HEMIBAKE_DCHECK(first + 3 < e_parent.size() && e_parent[first] == e && e_parent[first + 3] == e);
  ++stats.splits;
}

// The progress figures read between shots.
void Solver::Impl::update_unshot_total() {
  double total = 0.0;
  for (double u : p_unshot) total += u;
  for (double u : p_unshot) HEMIBAKE_DCHECK(u >= 0.0);
  // Every patch is a root, and every split turns a leaf into four.
  HEMIBAKE_DCHECK(leaves.size() == patches.size() + 3 * stats.splits);
  stats.unshot_fraction = emitted_power > 0.0 ? total / emitted_power : 0.0;
  stats.elements = leaves.size();
}

// Split elements (now inner nodes) are replaced by their leaves, in place of the parent: the list
// keeps its order, and with it the order of everything summed or projected from it.
void Solver::Impl::replace_split(std::vector<uint32_t>& list) const {
  bool any = false;
  for (uint32_t e : list) any = any || e_child[e] != kNone;
  if (!any) return;
  std::vector<uint32_t> out;
  out.reserve(list.size() + 16);
  for (uint32_t e : list) for_leaves(e, [&](uint32_t leaf) { out.push_back(leaf); });
  list.swap(out);
  for (uint32_t e : list) HEMIBAKE_DCHECK(e_child[e] == kNone);
}

// Per-receiver and per-vertex scratch of a shot, grown after splits and new vertices; vmin and vmax
// start empty (refine resets the entries it touched).
void Solver::Impl::grow_scratch() {
  shot_b.resize(e_patch.size());
  f_recv.resize(e_patch.size());
  f_open.resize(e_patch.size());
  vmin.resize(vpos.size(), std::numeric_limits<double>::max());
  vmax.resize(vpos.size(), std::numeric_limits<double>::lowest());
}

}  // namespace hemibake::solver
