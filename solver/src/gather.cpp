// The final gather: once the shots are done, every vertex of the mesh gathers the radiosity of what
// it sees, and elements split where the light gathered across them is not linear.
//
// Shooting leaves each element one radiosity, its mean over the element, and the mesh showed the
// mean of the elements around each vertex. A face lit only indirectly takes many weak shots, none
// of which splits it, so it stayed one flat element (a block's face turned from the light, darkening
// by a factor of three toward the floor), and a vertex on a surface's outline showed the mean of
// elements that all lie to one side of it. Here a hemicube of the solve's method is placed at each
// vertex; what it sees, with the radiosities the shots gave it, makes the vertex's irradiance
// H = sum F B (in radiosity units), and the vertex shows E + rho H. Where the sky shows through, it
// brings pi times its radiance. Punctual lights are no surfaces a hemicube can see: their direct
// light keeps the elements' mean (their own shots refine for it). So does light from covered
// surfaces (the ceiling above a lamp hung just under it: kCoverGap), which gathers see dark.
//
// Then each element large enough to split gathers at the points its split would make (its edges'
// midpoints, a quad's centre). Where one differs from the value the corners interpolate by more
// than the radiosity tolerance, it splits, and its children are checked in turn.
//
// A gather projects a cut through the element trees, not every leaf: a node that looks narrower
// than kGatherAngle from the point, and whose leaves' radiosities are alike (kGatherUneven), stands
// for its leaves with their mean radiosity (a node's polygon is the union of its children's, so
// what it hides is the same). The backs of a solid are occluders
// when the point lies in the solid's box: a point on the floor under a box standing on it sees
// nothing else (elsewhere they stay culled, as in the shots). A vertex on a surface's outline
// gathers a little inside it: at a wall's foot the floor fills half the view, but from the outline
// itself it lies edge-on. Points are gathered in parallel, each with one thread's hemicube.
#include "solver_impl.h"

#include "hemibake/solver/hemicube.h"

#include <glm/geometric.hpp>
#include <glm/vector_relational.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace hemibake::solver {
namespace {

// A node narrower than this (radians, as seen from the gathering point) is projected whole.
constexpr double kGatherAngle = 0.8;
// ... and whose leaves' radiosities lie within this factor of each other (plus the tolerance): a
// node of a ceiling straddling the outline of a lamp hung just under it, bright above the lamp and
// dim beside it, would show the bright mean around the lamp.
constexpr double kGatherUneven = 4.0;
// The gather's hemicube has this share of the solve's resolution (at least kMinResolution): each
// node it sees counts with its exact form factor, and the cube only finds the share of it in view,
// pixels partly covered counting in part, so a coarse cube sums nearly the same light. A quarter
// (26 pixels at the default 100) against a half: p90 as displayed within 0.4 points on five
// scenes, 21 to 27 % less CPU on the Cornell box and a room lit through a window, the same on
// glowing spheres, whose cost is the nodes (bench/README.md).
constexpr uint32_t kGatherResolutionDivisor = 4;
// A vertex whose elements' centroid lies farther from it than this share of its smallest
// element's radius is on the surface's outline; it gathers kOutlineStep of the scene's diagonal
// inside (a step of a tenth of the element instead: one-sided panel room alike, Cornell box p90
// 8.6 % to 8.8 %, vertices on outlines up to 5 % off the light at the vertex).
constexpr double kOutlineShare = 0.25;
constexpr double kOutlineStep = 1e-4;
// The gather projects at most this many times the nodes the shots projected (stats'
// elements_projected): on the Cornell box that is every vertex, on thousands of small patches the
// vertices of the largest elements.
constexpr double kGatherBudget = 2.0;
// The vertices of the first round take at most this share of the budget: the rest is kept for the
// splits' points, largest elements first. With every vertex of the lit yard's 16 000 elements to
// gather, the budget ran out before any element was checked, and the back of its wall, one element
// whose foot corners gather 40 times the light of its top (the ground fills half their view),
// showed that light interpolated up the whole wall: 53 times the path tracer's light there, 14
// times with this share (the foot needs splits down to centimetres; a known defect).
constexpr double kVertexShare = 0.5;
// Points gathered per step(), so that cancellation and progress come between batches.
constexpr size_t kGatherBatch = 512;
constexpr double kPi = 3.14159265358979323846;

glm::dvec3 up_hint(const glm::dvec3& n) {
  return std::abs(n.z) < 0.9 ? glm::dvec3(0.0, 0.0, 1.0) : glm::dvec3(1.0, 0.0, 0.0);
}

}  // namespace

// One batch of the final gather. Returns false when there is nothing (more) to do.
bool Solver::Impl::gather_step() {
  if (!params.gather || gather_done) return false;
  const auto t0 = Clock::now();
  // Light that leaves covered surfaces through a gap (e_gap: a double-sided lamp's top, 1 mm under
  // a ceiling) was once thought beyond the gather, which sees the gap at grazing angles: such
  // scenes kept the mean (a Blender room came out 10 % too dark with the gather). That was the
  // ceiling hiding part of the lamp in the gather's coarse pixels (Hemicube::set_depth_at_pixel_centre);
  // since, the room measures 0.2 % / 3.7 % with the gather against 0.2 % / 4.5 % without.
  if (!gather_started) start_gather();
  if (gather_spent >= gather_budget) {
    // Out of budget: what is not gathered keeps its elements' mean. The points gathered so far
    // keep what they gathered: vertices (the largest elements' first), and the splits' points of
    // the elements all of whose points were gathered, which split as in any round.
    gather_pending.resize(gather_next);
    gather_round();
    gather_done = true;
    gather_pending.clear();
    gather_workers.clear();
  } else if (gather_phase == 0 && gather_next < gather_pending.size() &&
             gather_spent >= static_cast<uint64_t>(kVertexShare * static_cast<double>(gather_budget))) {
    // The vertices' share is spent: the elements whose corners are gathered go on to be checked.
    gather_pending.resize(gather_next);
    gather_round();
  } else if (gather_next < gather_pending.size()) {
    const size_t end = std::min(gather_pending.size(), gather_next + kGatherBatch);
    std::vector<GatherPoint> batch(gather_pending.begin() + static_cast<std::ptrdiff_t>(gather_next),
                                   gather_pending.begin() + static_cast<std::ptrdiff_t>(end));
    gather_points(batch);
    std::copy(batch.begin(), batch.end(), gather_pending.begin() + static_cast<std::ptrdiff_t>(gather_next));
    gather_next = end;
  } else {
    gather_round();
  }
  stats.seconds_gathering += seconds_since(t0);
  stats.seconds += seconds_since(t0);
  return true;
}

// The elements' mean radiosities, the vertices' normals (area-weighted over the patches around
// them) and outlines, and every leaf to check.
void Solver::Impl::start_gather() {
  gather_started = true;
  // Children come after their parents: a backward sweep meets every node after its children.
  e_hidden.assign(e_patch.size(), 0);
  e_settled.assign(e_patch.size(), 0);
  // Per node: the light and area of its uncovered leaves.
  std::vector<glm::dvec3> open_light(e_patch.size(), glm::dvec3(0.0));
  std::vector<double> open_area(e_patch.size(), 0.0);
  for (size_t i = e_patch.size(); i-- > 0;) {
    if (e_child[i] == kNone) {
      if (leaf_covered(static_cast<uint32_t>(i))) continue;
      open_light[i] = e_b[i] * e_area[i];
      open_area[i] = e_area[i];
      continue;
    }
    for (uint32_t k = 0; k < 4; ++k) {
      open_light[i] += open_light[e_child[i] + k];
      open_area[i] += open_area[e_child[i] + k];
    }
  }
  for (size_t i = e_patch.size(); i-- > 0;) {
    if (e_child[i] == kNone) {
      // A leaf covered by a surface just in front of it shows its light to no gather (kCoverGap).
      // One reaching past its cover's outline (partly_open) shows the light of the uncovered
      // leaves of its nearest node that has any: the shots gave it little (resolve hands a
      // covered element's share of a pixel to its surface's uncovered ones).
      const uint32_t e = static_cast<uint32_t>(i);
      const bool cov = leaf_covered(e);
      const bool open = cov && partly_open(e);
      uint32_t up = e;
      while (open && open_area[up] <= 0.0 && e_parent[up] != kNone) up = e_parent[up];
      e_mean[i] = !cov ? e_b[i] : open && open_area[up] > 0.0 ? open_light[up] / open_area[up] : glm::dvec3(0.0);
      e_hidden[i] = cov && !open ? 1 : 0;
      e_low[i] = e_high[i] = mean(e_mean[i]);
      continue;
    }
    e_hidden[i] = 1;
    for (uint32_t k = 0; k < 4; ++k) e_hidden[i] &= e_hidden[e_child[i] + k];
    glm::dvec3 sum(0.0);
    double a = 0.0;
    e_low[i] = std::numeric_limits<double>::max();
    e_high[i] = 0.0;
    for (uint32_t k = 0; k < 4; ++k) {
      const uint32_t ch = e_child[i] + k;
      sum += e_mean[ch] * e_area[ch];
      a += e_area[ch];
      e_low[i] = std::min(e_low[i], e_low[ch]);
      e_high[i] = std::max(e_high[i], e_high[ch]);
    }
    e_mean[i] = a > 0.0 ? sum / a : e_b[i];
  }
  v_normal.assign(vpos.size(), glm::dvec3(0.0));
  v_inward.assign(vpos.size(), glm::dvec3(0.0));
  std::vector<double> v_area(vpos.size(), 0.0), v_size(vpos.size(), 0.0);
  for (uint32_t e : leaves)
    for (uint32_t k = 0; k < corner_count(e); ++k) {
      const uint32_t v = e_corner[e][k];
      v_normal[v] += prep.normal[e_patch[e]] * e_area[e];
      v_inward[v] += e_centre[e] * e_area[e];
      v_area[v] += e_area[e];
      v_size[v] = v_size[v] > 0.0 ? std::min(v_size[v], e_radius[e]) : e_radius[e];
    }
  for (size_t v = 0; v < vpos.size(); ++v) {
    const double len = glm::length(v_normal[v]);
    if (len > 0.0) v_normal[v] /= len;
    const glm::dvec3 in = v_area[v] > 0.0 ? v_inward[v] / v_area[v] - vpos[v] : glm::dvec3(0.0);
    v_inward[v] = glm::length(in) > kOutlineShare * v_size[v] ? kOutlineStep * prep.diagonal * glm::normalize(in) : glm::dvec3(0.0);
  }
  v_irr.assign(vpos.size(), glm::dvec3(0.0));
  v_gathered.assign(vpos.size(), 0);
  gather_queue = leaves;
  gather_phase = 0;
  gather_pending.clear();
  gather_next = 0;
  // Phase 0 of the first round: every vertex of the mesh, those of the largest elements first.
  std::vector<double> largest(vpos.size(), 0.0);
  for (uint32_t e : leaves)
    for (uint32_t k = 0; k < corner_count(e); ++k) largest[e_corner[e][k]] = std::max(largest[e_corner[e][k]], e_area[e]);
  std::vector<uint32_t> by_size;
  for (uint32_t v = 0; v < vpos.size(); ++v)
    if (v_area[v] > 0.0) by_size.push_back(v);
  std::stable_sort(by_size.begin(), by_size.end(), [&](uint32_t a, uint32_t b) { return largest[a] > largest[b]; });
  for (uint32_t v : by_size) gather_pending.push_back({GatherPoint::Kind::kVertex, v, 0, vpos[v], v_normal[v], v_inward[v]});
  gather_budget = static_cast<uint64_t>(kGatherBudget * static_cast<double>(stats.elements_projected));
}

// Ends the phase whose points are all gathered, and starts the next: the splits' points of this
// round's elements, or (after them) the splits, whose children make the next round.
void Solver::Impl::gather_round() {
  if (gather_phase == 0) {
    for (const GatherPoint& g : gather_pending) {
      v_irr[g.id] = g.irr;
      v_gathered[g.id] = 1;
    }
    // Only elements whose corners are all gathered may split.
    std::erase_if(gather_queue, [&](uint32_t e) {
      for (uint32_t k = 0; k < corner_count(e); ++k)
        if (!v_gathered[e_corner[e][k]]) return true;
      return false;
    });
    // The points each element's split would make, where it may split at all: the largest
    // elements' first, for a budget that may not reach them all.
    std::stable_sort(gather_queue.begin(), gather_queue.end(),
                     [&](uint32_t a, uint32_t b) { return e_area[a] > e_area[b]; });
    gather_pending.clear();
    std::unordered_map<uint64_t, uint32_t> edge_seen;  // a midpoint is gathered once
    for (uint32_t e : gather_queue) {
      if (e_area[e] < min_split_area()) continue;
      const uint32_t nc = corner_count(e);
      const glm::dvec3& n = prep.normal[e_patch[e]];
      for (uint32_t k = 0; k < nc; ++k) {
        const uint32_t a = e_corner[e][k], b = e_corner[e][(k + 1) % nc];
        if (auto it = midpoints.find(edge_key(a, b)); it != midpoints.end() && v_gathered[it->second]) continue;
        if (!edge_seen.emplace(edge_key(a, b), e).second) continue;
        const glm::dvec3 mid = 0.5 * (vpos[a] + vpos[b]);
        gather_pending.push_back({GatherPoint::Kind::kMidpoint, e, k, mid, n, kOutlineStep * prep.diagonal * glm::normalize(e_centre[e] - mid)});
      }
      if (nc == 4) gather_pending.push_back({GatherPoint::Kind::kCentre, e, 0, e_centre[e], n, glm::dvec3(0.0)});
    }
    gather_phase = 1;
    gather_next = 0;
    return;
  }
  // Phase 1 done: what was gathered, by edge and by centre.
  std::unordered_map<uint64_t, glm::dvec3> at_edge;
  std::unordered_map<uint32_t, glm::dvec3> at_centre;
  for (const GatherPoint& g : gather_pending) {
    if (g.kind == GatherPoint::Kind::kCentre) {
      at_centre.emplace(g.id, g.irr);
    } else {
      const uint32_t nc = corner_count(g.id);
      at_edge.emplace(edge_key(e_corner[g.id][g.edge], e_corner[g.id][(g.edge + 1) % nc]), g.irr);
    }
  }
  std::vector<uint32_t> next;
  for (uint32_t e : gather_queue) {
    // Settled: too small to split, at the element limit, covered, or compared below.
    if (e_area[e] < min_split_area() || leaves.size() + 3 * (1 + next.size() / 4) > params.max_elements) {
      e_settled[e] = 1;
      continue;
    }
    if (leaf_covered(e)) {  // covered: seen by no one, or through its open part only
      e_settled[e] = 1;
      continue;
    }
    const uint32_t nc = corner_count(e);
    const std::array<uint32_t, 4> c = e_corner[e];
    const glm::dvec3& rho = patches[e_patch[e]].reflectance;
    // The light at the new points, as gathered and as the corners interpolate it (an element
    // whose points the budget did not reach stays as it is).
    std::array<glm::dvec3, 5> got{}, lerp{};
    bool all = true;
    for (uint32_t k = 0; k < nc && all; ++k) {
      const uint64_t key = edge_key(c[k], c[(k + 1) % nc]);
      lerp[k] = 0.5 * (v_irr[c[k]] + v_irr[c[(k + 1) % nc]]);
      if (auto it = midpoints.find(key); it != midpoints.end() && v_gathered[it->second]) {
        got[k] = v_irr[it->second];
      } else if (auto at = at_edge.find(key); at != at_edge.end()) {
        got[k] = at->second;
      } else {
        all = false;
      }
    }
    const uint32_t points = nc == 4 ? 5 : 3;
    if (nc == 4 && all) {
      const auto at = at_centre.find(e);
      all = at != at_centre.end();
      if (all) got[4] = at->second;
      lerp[4] = 0.25 * (v_irr[c[0]] + v_irr[c[1]] + v_irr[c[2]] + v_irr[c[3]]);
    }
    if (!all) continue;
    e_settled[e] = 1;
    double worst = 0.0;
    for (uint32_t k = 0; k < points; ++k) worst = std::max(worst, mean(rho * glm::abs(got[k] - lerp[k])));
    if (worst <= gather_tolerance) continue;
    split(e);
    ++stats.splits_gather;
    // The split made the midpoints and the centre: they keep what was gathered there.
    v_normal.resize(vpos.size(), glm::dvec3(0.0));
    v_inward.resize(vpos.size(), glm::dvec3(0.0));
    v_irr.resize(vpos.size(), glm::dvec3(0.0));
    v_gathered.resize(vpos.size(), 0);
    for (uint32_t k = 0; k < nc; ++k) {
      const uint32_t m = midpoints.at(edge_key(c[k], c[(k + 1) % nc]));
      if (v_gathered[m]) continue;
      v_normal[m] = prep.normal[e_patch[e]];
      v_irr[m] = got[k];
      v_gathered[m] = 1;
    }
    if (nc == 4) {
      const uint32_t ctr = e_corner[e_child[e]][2];  // child 0 is {c0, m01, centre, m30}
      v_normal[ctr] = prep.normal[e_patch[e]];
      v_irr[ctr] = got[4];
      v_gathered[ctr] = 1;
    }
    e_hidden.resize(e_patch.size(), 0);
    e_settled.resize(e_patch.size(), 0);
    for (uint32_t k = 0; k < 4; ++k) {
      e_mean[e_child[e] + k] = e_b[e];
      e_low[e_child[e] + k] = e_high[e_child[e] + k] = mean(e_b[e]);
      next.push_back(e_child[e] + k);
    }
  }
  replace_split(leaves);
  grow_scratch();
  update_unshot_total();
  // The children's corners are all gathered: the next round starts with its splits' points.
  gather_queue.swap(next);
  gather_pending.clear();
  gather_next = 0;
  gather_phase = 0;
  if (gather_queue.empty()) {
    gather_done = true;
    gather_workers.clear();
  }
}

// Gathers at every point, in parallel: each chunk of the pool with a hemicube of its own.
void Solver::Impl::gather_points(std::vector<GatherPoint>& points) {
  const size_t chunks = pool.chunk_count(points.size());
  const uint32_t res = std::max(kMinResolution, (params.resolution / kGatherResolutionDivisor + 1) & ~1u);
  while (gather_workers.size() < chunks) gather_workers.push_back(std::make_unique<GatherWorker>(res));
  pool.parallel_for(points.size(), [&](size_t begin, size_t end, size_t c) {
    for (size_t i = begin; i < end; ++i) points[i].irr = gather_at(points[i], *gather_workers[c], points[i].cost);
  });
  stats.gathers += points.size();
  for (const GatherPoint& g : points) gather_spent += g.cost;
}

// The irradiance at a point, in radiosity units (sum over what it sees of F B): from a hemicube at
// the point over a cut through the element trees, plus the sky where nothing is seen.
glm::dvec3 Solver::Impl::gather_at(const GatherPoint& point, GatherWorker& w, uint32_t& cost) const {
  const glm::dvec3& n = point.n;
  if (glm::dot(n, n) == 0.0) return glm::dvec3(0.0);
  const glm::dvec3 x = point.x + point.inward;
  // The cut, over the patches with a corner in front of the point's plane.
  const double ahead = kRoundingLength * prep.diagonal;
  w.list.clear();
  find_patch(
      [&](const glm::dvec3& lo, const glm::dvec3& hi) {
        const glm::dvec3 far(n.x > 0.0 ? hi.x : lo.x, n.y > 0.0 ? hi.y : lo.y, n.z > 0.0 ? hi.z : lo.z);
        return glm::dot(n, far - x) > ahead;
      },
      [&](uint32_t q) {
        bool front = false;
        for (uint32_t k = 0; k < patches[q].corner_count && !front; ++k)
          front = glm::dot(n, patches[q].corners[k] - x) > ahead;
        if (!front) return false;
        w.stack.push_back(p_root[q]);
        while (!w.stack.empty()) {
          const uint32_t k = w.stack.back();
          w.stack.pop_back();
          // Covered pieces lie right behind the surface that covers them (a ceiling above a lamp
          // hung 1 mm under it): hidden from every point but through the gap, they are left out,
          // and so is their depth, which at a grazing view competed pixel by pixel with the lamp's.
          if (e_hidden[k]) continue;
          if (e_child[k] == kNone ||
              (2.0 * e_radius[k] < kGatherAngle * (glm::distance(x, e_centre[k]) - e_radius[k]) &&
               e_high[k] <= kGatherUneven * e_low[k] + gather_tolerance)) {
            w.list.push_back(k);
          } else {
            for (uint32_t j = 0; j < 4; ++j) w.stack.push_back(e_child[k] + j);
          }
        }
        return false;
      });
  cost = static_cast<uint32_t>(w.list.size());
  if (w.list.empty()) return kPi * sky;
  w.inside.resize(prep.solid_lo.size());
  for (size_t k = 0; k < prep.solid_lo.size(); ++k)
    w.inside[k] = glm::all(glm::greaterThanEqual(x, prep.solid_lo[k] - ahead)) &&
                  glm::all(glm::lessThanEqual(x, prep.solid_hi[k] + ahead));
  w.cube.place(x, n, up_hint(n));
  // The insides of closed meshes the point lies outside of are left out, as in a shot's hemicube
  // (projection.cpp, enclosing): they hold no light for it and lie behind their own outside. The
  // test is a hair in front of the surface, as a shot's eye is: on a closed mesh's own face (a room
  // modelled as one double-sided box) it could go either way.
  const std::vector<uint32_t> within =
      prep.closed_outside.empty() ? std::vector<uint32_t>{} : enclosing(x + n * (kEyeOffset * prep.diagonal));
  // Fragments carry the node's place in the list.
  w.frags.clear();
  w.group_of.resize(w.list.size());
  w.cover_of.resize(w.list.size());
  Corners poly{};
  for (uint32_t i = 0; i < w.list.size(); ++i) {
    const uint32_t el = w.list[i];
    const uint32_t p = e_patch[el];
    w.group_of[i] = e_group[el];
    w.cover_of[i] = e_cover[el];
    const double facing = glm::dot(prep.normal[p], x - patches[p].corners[0]);
    const bool solid_seen_inside = prep.solid[p] != kNone && w.inside[prep.solid[p]];
    if (std::abs(facing) <= ahead || (facing < 0.0 && prep.back_hidden[p] && !solid_seen_inside)) continue;
    if (sealed(p, within)) continue;
    corners_of(el, poly);
    project_side(w.cube, el, i, poly, facing, true, w.scratch, w.frags);
  }
  detail::resolve(w.frags, w.cube.pixel_count(), params.method, w.group_of, covered_bit(), w.cover_of, prep.adjacency,
                  w.inline_pool, w.order, w.pixel_start);
  const auto& dff = w.cube.delta_form_factors();
  w.seen.assign(w.list.size(), 0.0);
  w.open.assign(w.list.size(), 0.0);
  double covered = 0.0;  // whatever is seen, backs too, hides the sky
  for (const Fragment& f : w.frags) {
    const double a = static_cast<double>(f.area) * dff[f.pixel];
    covered += a * f.trans;
    if ((f.element & detail::kBackFace) != 0) continue;
    w.seen[f.element] += a * f.trans;
    w.open[f.element] += a;
  }
  // Each node's exact form factor from the point (its part in front of the point's plane), times
  // the share of it the hemicube found visible: pixels' delta form factors misweigh a node seen
  // at a grazing angle (a lamp under the ceiling, from the wall's top) at this resolution.
  glm::dvec3 h(0.0);
  std::array<glm::dvec3, 8> cut{};
  for (uint32_t i = 0; i < w.list.size(); ++i) {
    if (w.open[i] <= 0.0) continue;
    const uint32_t el = w.list[i];
    corners_of(el, poly);
    const uint32_t cc = corner_count(el);
    size_t m = 0;
    for (uint32_t k = 0; k < cc; ++k) {
      const glm::dvec3& a = poly[k];
      const glm::dvec3& b = poly[(k + 1) % cc];
      const double da = glm::dot(n, a - x), db = glm::dot(n, b - x);
      if (da > 0.0) cut[m++] = a;
      if ((da > 0.0) != (db > 0.0)) cut[m++] = a + (b - a) * (da / (da - db));
    }
    if (m < 3) continue;
    const double f = point_polygon_form_factor(x, n, std::span(cut.data(), m));
    h += f * (w.seen[i] / w.open[i]) * e_mean[el];
  }
  return h + kPi * sky * std::max(0.0, 1.0 - covered);
}

}  // namespace hemibake::solver
