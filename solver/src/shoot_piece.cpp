// One hemicube: a shooting piece's receivers, what may hide them, the hemicube's resolution,
// a posteriori subdivision and the Southwell step.
#include "solver_impl.h"

#include "hemibake/solver/hemicube.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace hemibake::solver {

// How many times coarser than its depth's hemicube a shooting piece's hemicube may be. Weak shots
// carry little of the light: with fractional coverage a hemicube of half the resolution keeps its
// form factors within a few tenths of a percent, so pieces under 5 % (and again under 0.5 %) of the
// emitted power use half (a quarter of) the resolution. The classical hemicube's point sampling
// loses energy at lower resolution, so it always keeps its own. When every shot is weak (thousands
// of small patches), their errors add up: coarser hemicubes may shoot at most kCoarseShare of all the
// power shot so far (shoot_piece), which took a 1746-patch room from 7.5 % to 6.1 % RMS error.
int Solver::Impl::coarser_levels(double power) const {
  if (params.method != Method::kAntiAliased) return 0;
  return (power < 0.05 * emitted_power ? 1 : 0) + (power < 0.005 * emitted_power ? 1 : 0);
}

// Whether a shooting piece takes a hemicube of twice its level's resolution (at most 400). A
// cluster shoots for many small patches, and its receivers are the scene's many small patches, whose
// silhouettes a hemicube resolves coarsely (pixels mixing a piece of furniture and the wall behind
// it); there a hemicube's cost is mostly per projected element, so twice the resolution costs
// little more. Whole-scene cluster hemicubes carrying at least kFinePower of the emitted power take
// it: on the 6758-patch furnished room, RMS error 4.6 % to 3.8 % for 11 % more instructions (from
// 0.03 % of the power on: 3.6 % for 23 % more), where resolution 140 for every hemicube gives 3.7 %
// for about 30 % more time.
bool Solver::Impl::finer_level(const Piece& piece, double power) const {
  // Clusters at depth 0 are the whole-scene shots (step); their quarters go down the levels.
  return params.method == Method::kAntiAliased && piece.points.size() > 4 && piece.depth == 0 &&
         power >= kFinePower * emitted_power;
}

std::vector<uint32_t> Solver::Impl::shoot_piece(const Piece& piece, std::vector<uint32_t> receivers, bool whole_scene) {
  const uint32_t p = piece.patch;
  const glm::dvec3& dB = piece.dB;
  const double area = piece.area;
  const double power = channel_sum(dB) * area;
  const glm::dvec3& centre = piece.centre;

  // The piece's own patches: they stay out of its hemicube (a curved cluster's may stand in front
  // of it) and are no absorbers in front of it (absorber_close).
  ++shooting_stamp;
  for (uint32_t e : piece.src) p_shooting[e_patch[e]] = shooting_stamp;

  // Receivers split by earlier pieces are replaced by their leaves.
  std::vector<uint32_t> current;
  current.reserve(receivers.size());
  for (uint32_t e : receivers) for_leaves(e, [&](uint32_t leaf) { current.push_back(leaf); });

  // Near-field: a receiver close to the piece (a room corner, or a block standing on a lit floor,
  // whose faces see only part of the piece) sees it very differently from how the hemicube at its
  // centre sees the receiver. Such receivers take their share from the piece's sub-pieces instead
  // (the caller's recursion), each with a hemicube of its own.
  std::vector<uint32_t> accepted, near;
  const double eps = 1e-6 * prep.diagonal;
  const glm::dvec3& normal = piece.normal;
  // Near: within kNearFactor diameters of the piece, or (a piece of a patch carrying at least
  // kStraddlePower of the emitted power) on a plane that cuts through the piece: its centre may lie
  // behind the receiver while part of it is in front (a face of a block that sees part of the light
  // got nothing from the light's centre). Clusters are left to their quarters' own tests: planes
  // cut through them everywhere in a furnished room.
  const bool cut_rule = piece.points.size() <= 4 && power >= kStraddlePower * emitted_power;
  auto is_close = [&](uint32_t e) {
    const uint32_t q = e_patch[e];
    if (prep.occlusion_group[q] == prep.occlusion_group[p]) return false;
    const glm::dvec3& nq = prep.normal[q];
    const glm::dvec3& oq = patches[q].corners[0];
    // On a cluster's own curved surface, a receiver with the cluster's centroid behind its plane
    // (a convex surface: a sphere's facets) sees none of the cluster. Without this every cluster
    // of a 159k-facet sphere went down to single patches (526 659 hemicubes for 1303 shots).
    if (piece.points.size() > 4 && p_surface[q] == p_surface[p] && glm::dot(nq, centre - oq) <= 0.0) return false;
    const bool within = glm::distance(centre, e_centre[e]) - e_radius[e] < kNearFactor * piece.diameter;
    if (!within) {
      // The piece's centre behind the receiver's plane, or just in front of it: the centre's
      // hemicube gives the receiver nothing, or a grazing, poor view.
      const double dc = glm::dot(nq, centre - oq);
      if (!cut_rule || dc > 0.1 * piece.diameter || dc < -0.5 * piece.diameter) return false;
    }
    // Only a receiver that some of the piece can see, and that can see some of the piece, counts.
    double lo = 0.0, hi = 0.0;
    for (const glm::dvec3& x : piece.points) {
      const double d = glm::dot(nq, x - oq);
      lo = std::min(lo, d);
      hi = std::max(hi, d);
    }
    if (hi <= eps || (!within && lo >= -eps)) return false;
    bool in_front = false;
    for (uint32_t i = 0; i < corner_count(e) && !in_front; ++i)
      in_front = glm::dot(normal, vpos[e_corner[e][i]] - centre) > eps;
    return in_front;
  };
  // A close receiver goes to the sub-pieces only where the centre's hemicube could err by more than
  // kNearError of the radiosity tolerance: it gains at most rho * dB * F, with F at most
  // A / (pi g^2) at a gap g between them (at most 1), and the hemicube's point view of the piece
  // errs by about (D / 2g)^2 of that (D the piece's diameter); within half a diameter, always.
  // The point view's possible error for a close receiver (infinite where it always matters).
  auto near_error = [&](uint32_t e) {
    const double gap = glm::distance(centre, e_centre[e]) - e_radius[e] - 0.5 * piece.diameter;
    if (gap <= 0.5 * piece.diameter) return std::numeric_limits<double>::infinity();
    // A receiver whose plane cuts the piece (the rule above) may get nothing at all from the centre.
    if (glm::distance(centre, e_centre[e]) - e_radius[e] >= kNearFactor * piece.diameter)
      return std::numeric_limits<double>::infinity();
    const double f = std::min(1.0, area / (std::numbers::pi * gap * gap));
    const double share = 0.25 * piece.diameter * piece.diameter / (gap * gap);
    return mean(patches[e_patch[e]].reflectance * dB) * f * share;
  };
  auto may_matter = [&](uint32_t e) { return near_error(e) > kNearError * b_tolerance; };
  std::vector<uint8_t> goes_near(current.size(), 0);
  if (piece.may_refine)
    pool.parallel_for(current.size(), [&](size_t begin, size_t end, size_t) {
      for (size_t i = begin; i < end; ++i) goes_near[i] = is_close(current[i]) && may_matter(current[i]);
    });
  for (size_t i = 0; i < current.size(); ++i) (goes_near[i] ? near : accepted).push_back(current[i]);
  if (accepted.empty()) return near;
  // A large absorbing back face close in front of the piece (a light panel's back, hung 1 cm under
  // a ceiling piece) fills most of the hemicube at the piece's centre, while the piece's other
  // points see past it: the centre's view would sink their light into it. Everything goes to the
  // sub-pieces, whose own centres decide (on the furnished room, whose ceiling panels are such
  // backs: energy 0.984 to 0.995 of the path tracer's, RMS error 4.3 % to 3.8 %).
  if (piece.may_refine && absorber_close(piece)) {
    near.insert(near.end(), accepted.begin(), accepted.end());
    return near;
  }

  // What the hemicube must see: every accepted receiver, and whatever may stand between one and
  // the piece. What may hide a receiver lies between the piece's centre and the receiver, so within the
  // convex hull of the piece and the receiver, and so within their joint bounding box. The
  // receivers are boxed by surface (occlusion group), each box joined with the piece's: an element
  // overlapping none of them hides nothing from any receiver. Too many surfaces are merged into
  // fewer boxes (still conservative). A whole-scene hemicube sees everything.
  struct Box {
    glm::dvec3 lo{std::numeric_limits<double>::max()}, hi{std::numeric_limits<double>::lowest()};
    void add(const glm::dvec3& x) { lo = glm::min(lo, x); hi = glm::max(hi, x); }
    void add(const Box& b) { lo = glm::min(lo, b.lo); hi = glm::max(hi, b.hi); }
  };
  std::vector<Box> boxes;
  if (!whole_scene) {
    Box piece_box;
    for (const glm::dvec3& x : piece.points) piece_box.add(x);
    std::vector<std::pair<uint32_t, uint32_t>> by_group;  // (surface, receiver)
    by_group.reserve(accepted.size());
    for (uint32_t e : accepted) by_group.emplace_back(prep.occlusion_group[e_patch[e]], e);
    std::sort(by_group.begin(), by_group.end());
    for (size_t i = 0; i < by_group.size(); ++i) {
      if (i == 0 || by_group[i].first != by_group[i - 1].first) boxes.push_back(piece_box);
      const uint32_t e = by_group[i].second;
      for (uint32_t k = 0; k < corner_count(e); ++k) boxes.back().add(vpos[e_corner[e][k]]);
    }
    while (boxes.size() > kMaxShaftBoxes) {
      for (size_t i = 0; i + 1 < boxes.size(); i += 2) boxes[i / 2] = [&] { Box b = boxes[i]; b.add(boxes[i + 1]); return b; }();
      if (boxes.size() % 2) boxes[boxes.size() / 2] = boxes.back();
      boxes.resize((boxes.size() + 1) / 2);
    }
  }
  auto overlaps = [&](uint32_t e) {
    if (whole_scene) return true;
    const glm::dvec3& c = e_centre[e];
    const double r2 = e_radius[e] * e_radius[e];
    for (const Box& b : boxes) {
      const glm::dvec3 d = glm::max(b.lo - c, glm::max(c - b.hi, glm::dvec3(0.0)));
      if (glm::dot(d, d) <= r2) return true;
    }
    return false;
  };
  // What the hemicube projects: the receivers, and as occluders, of everything overlapping the
  // boxes, the largest elements that hold no receiver (the leaves of a subdivided patch tile it, so
  // one polygon hides what they hide, and a pixel gets one fragment where it got many).
  std::vector<uint32_t> seen;
  auto gather_seen = [&] {
    seen.clear();
    ++mark;
    for (uint32_t e : accepted)
      for (uint32_t x = e; x != kNone && e_mark[x] != mark; x = e_parent[x]) e_mark[x] = mark;
    // The patches whose boxes meet the receivers' boxes (all of them for a whole-scene hemicube).
    std::vector<uint32_t> near_patches;
    if (!whole_scene) {
      const double slack = 1e-9 * prep.diagonal;
      auto meets = [&](const glm::dvec3& lo, const glm::dvec3& hi) {
        for (const Box& b : boxes)
          if (lo.x <= b.hi.x + slack && lo.y <= b.hi.y + slack && lo.z <= b.hi.z + slack && hi.x + slack >= b.lo.x &&
              hi.y + slack >= b.lo.y && hi.z + slack >= b.lo.z)
            return true;
        return false;
      };
      std::vector<uint32_t> nodes{0};
      while (!nodes.empty()) {
        const BoxNode& node = tree[nodes.back()];
        nodes.pop_back();
        if (!meets(node.lo, node.hi)) continue;
        if (node.child != kNone) {
          nodes.push_back(node.child + 1);
          nodes.push_back(node.child);
          continue;
        }
        for (uint32_t i = node.begin; i < node.end; ++i) {
          const uint32_t q = tree_patch[i];
          if (meets(p_lo[q], p_hi[q])) {
            near_patches.push_back(q);
            p_mark[q] = mark;
          }
        }
      }
      // The receivers' patches always count (rounding of shared vertices must not lose one).
      for (uint32_t e : accepted) {
        const uint32_t q = e_patch[e];
        if (p_mark[q] != mark) {
          near_patches.push_back(q);
          p_mark[q] = mark;
        }
      }
    }
    // Each patch's quadtree on its own, so the patches are shared among the threads (their lists
    // joined in order).
    const std::vector<uint32_t>& patch_list = whole_scene ? tree_patch : near_patches;
    pool.parallel_for(patch_list.size(), [&](size_t begin, size_t end, size_t c) {
      std::vector<uint32_t>& out = gather_chunks[c];
      out.clear();
      std::vector<uint32_t> stack;
      for (size_t i = begin; i < end; ++i) {
        stack.push_back(p_root[patch_list[i]]);
        while (!stack.empty()) {
          const uint32_t x = stack.back();
          stack.pop_back();
          if (e_mark[x] != mark) {
            if (overlaps(x)) out.push_back(x);
          } else if (e_child[x] == kNone) {
            out.push_back(x);  // a receiver
          } else {
            for (uint32_t k = 4; k-- > 0;) stack.push_back(e_child[x] + k);
          }
        }
      }
    });
    for (size_t c = 0; c < pool.chunk_count(patch_list.size()); ++c)
      seen.insert(seen.end(), gather_chunks[c].begin(), gather_chunks[c].end());
  };
  gather_seen();

  // Coarser hemicubes for weak pieces, as long as what they shot stays a small part of all shot.
  // Strong cluster pieces finer instead (finer_level).
  const bool finer = finer_level(piece, power);
  int coarser = finer ? 0 : coarser_levels(power);
  if (coarser > 0 && power_coarse + power > kCoarseShare * (power_shot + power)) coarser = 0;
  power_shot += power;
  if (coarser > 0) power_coarse += power;
  ++stats.hemicubes;
  ++stamp;
  const size_t level = std::min<size_t>(static_cast<size_t>(piece.depth) + coarser, cubes.size() - 1);
  cube = &cubes[level];
  const uint32_t finer_resolution = std::max(params.resolution, std::min(2 * params.resolution, 400u));
  if (finer && finer_resolution > params.resolution) {
    // Made when first needed; at most 400 (pixels cost memory and time), and none at all where the
    // resolution is that fine already.
    if (!finer_cube) finer_cube = std::make_unique<detail::Hemicube>(finer_resolution);
    cube = finer_cube.get();
  }
  cube->place(centre, normal, piece.up);
  project(seen);
  sum_form_factors(accepted);  // the occluders' own form factors are not needed

  // This piece's share of the emitted power: how much the interaction matters (criterion a).
  const double weight = power / emitted_power;
  auto received = [&](uint32_t e, double ff) {
    return std::min(1.0, ff * area / e_area[e]);  // F(element -> shooter) by reciprocity
  };

  // Receivers within a diameter of a piece that is not refined further (a weak shot, or the
  // deepest level) and less than twice its size take the exact form factor to the piece (Lambert's
  // formula, the piece cut to the receiver's front side), averaged over 1, 4 or 9 points of the
  // receiver as it is smaller than half the piece, than the piece, or larger, times the fraction of
  // the receiver the hemicube found visible: reciprocity from the piece's centre errs by the
  // piece's size against the distance, the receiver's points by the receiver's.
  const bool exact_close = !piece.may_refine && piece.points.size() <= 4;
  // F(point x with normal n -> piece): Lambert over the piece cut to x's front side; nothing for a
  // point behind the piece.
  auto point_to_piece = [&](const glm::dvec3& x, const glm::dvec3& n) {
    if (glm::dot(normal, x - centre) <= 0.0) return 0.0;
    uint32_t m = 0;
    std::array<glm::dvec3, 8> clipped{};
    const size_t k = piece.points.size();
    for (size_t i = 0; i < k; ++i) {
      const glm::dvec3& a = piece.points[i];
      const glm::dvec3& b = piece.points[(i + 1) % k];
      const double da = glm::dot(n, a - x), db = glm::dot(n, b - x);
      if (da > 0.0) clipped[m++] = a;
      if ((da > 0.0) != (db > 0.0)) clipped[m++] = a + (b - a) * (da / (da - db));
    }
    return m < 3 ? 0.0 : point_polygon_form_factor(x, n, std::span(clipped.data(), m));
  };
  // F(element -> piece): the mean over `side` x `side` points of the element (quads: cell centres
  // of a bilinear grid; triangles: the centroid, or those of its four halved-edge triangles).
  auto exact_uncached = [&](uint32_t e, int side) {
    const glm::dvec3& n = prep.normal[e_patch[e]];
    const Corners c = corners_of_copy(e);
    if (side <= 1) return point_to_piece(polygon_centre(c, corner_count(e)), n);
    double sum = 0.0;
    int count = 0;
    if (corner_count(e) == 4) {
      for (int i = 0; i < side; ++i)
        for (int j = 0; j < side; ++j, ++count) {
          const double u = (i + 0.5) / side, v = (j + 0.5) / side;
          sum += point_to_piece((1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3], n);
        }
    } else {
      Corners sub{};
      for (uint32_t k = 0; k < 4; ++k, ++count) {
        child_corners(c, 3, k, sub);
        sum += point_to_piece((sub[0] + sub[1] + sub[2]) / 3.0, n);
      }
    }
    return sum / count;
  };
  auto exact = [&](uint32_t e, int side) {
    if (e_exact_stamp[e] != stamp) {
      e_exact[e] = std::min(1.0, exact_uncached(e, side));
      e_exact_stamp[e] = stamp;
    }
    return e_exact[e];
  };
  // Each receiver's on its own, so the receivers are shared among the threads.
  auto form_factors = [&] {
    pool.parallel_for(accepted.size(), [&](size_t begin, size_t end, size_t) {
      for (size_t i = begin; i < end; ++i) {
        const uint32_t e = accepted[i];
        f_recv[e] = f_open[e] = 0.0;
        const bool projected = e_stamp[e] == stamp && e_ff_open[e] > 0.0;
        if (projected) {
          f_recv[e] = received(e, e_ff[e]);
          f_open[e] = received(e, e_ff_open[e]);
        }
        const double size = 2.0 * e_radius[e];
        if (exact_close && size < 2.0 * piece.diameter &&
            glm::distance(centre, e_centre[e]) - e_radius[e] < piece.diameter && is_close(e)) {
          // A receiver the hemicube did not see (the piece's centre lies behind it, though part of
          // the piece is in front: a floor piece under a block's face) is taken as unoccluded from
          // the part in front, which lies within a diameter of it.
          const double f = exact(e, size < 0.5 * piece.diameter ? 1 : size < piece.diameter ? 2 : 3);
          f_recv[e] = projected ? f * (e_ff[e] / e_ff_open[e]) : f;
          f_open[e] = f;
        }
      }
    });
  };

  // For a replay (step): by how much this piece's dB could grow before its last round would have
  // split something. The criteria scale with dB, so each gives limit / value.
  double split_room = std::numeric_limits<double>::infinity();
  auto within = [](double& room, double limit, double value) {
    if (value > 0.0) room = std::min(room, limit / value);
  };
  bool settled = false;  // the last round split nothing (or could not: the element limit)
  for (int round = 0; round < 64; ++round) {
    form_factors();
    // This shot's radiosity at every accepted receiver, and its spread around every vertex.
    for (uint32_t e : accepted) {
      const double v = mean(patches[e_patch[e]].reflectance * dB) * f_recv[e];
      shot_b[e] = v;
      for (uint32_t k = 0; k < corner_count(e); ++k) {
        const uint32_t vert = e_corner[e][k];
        vmin[vert] = std::min(vmin[vert], v);
        vmax[vert] = std::max(vmax[vert], v);
      }
    }
    std::vector<uint32_t> to_split;
    const double min_parent_area = 4.0 * aeps_area;
    for (uint32_t e : accepted) {
      if (e_area[e] < min_parent_area) continue;
      bool split_it = false;
      if (e_stamp[e] == stamp && e_ff_open[e] > 0.0) {
        // (a) too coarse for this interaction.
        split_it = e_ff[e] * weight > params.feps;
        stats.splits_form_factor += split_it;
        // (b) partly hidden, and the hidden part matters.
        if (!split_it && e_ff[e] > 0.0 && e_ff[e] < e_ff_open[e]) {
          const double open = mean(patches[e_patch[e]].reflectance * dB) * f_open[e];
          split_it = open - shot_b[e] > b_tolerance;
          stats.splits_visibility += split_it;
        }
      }
      // (c) the shot's radiosity jumps across one of its corners.
      for (uint32_t k = 0; k < corner_count(e) && !split_it; ++k) {
        const uint32_t vert = e_corner[e][k];
        split_it = vmax[vert] - vmin[vert] > b_tolerance;
        stats.splits_gradient += split_it;
      }
      if (split_it) to_split.push_back(e);
    }
    if (recording != nullptr) {
      split_room = std::numeric_limits<double>::infinity();
      for (uint32_t e : accepted) {
        if (e_area[e] < min_parent_area) continue;
        if (e_stamp[e] == stamp && e_ff_open[e] > 0.0) {
          within(split_room, params.feps, e_ff[e] * weight);
          if (e_ff[e] > 0.0 && e_ff[e] < e_ff_open[e])
            within(split_room, b_tolerance, mean(patches[e_patch[e]].reflectance * dB) * f_open[e] - shot_b[e]);
        }
        for (uint32_t k = 0; k < corner_count(e); ++k)
          within(split_room, b_tolerance, vmax[e_corner[e][k]] - vmin[e_corner[e][k]]);
      }
    }
    // Reset the vertex spreads for the next round (only the touched vertices).
    for (uint32_t e : accepted)
      for (uint32_t k = 0; k < corner_count(e); ++k) {
        vmin[e_corner[e][k]] = std::numeric_limits<double>::max();
        vmax[e_corner[e][k]] = std::numeric_limits<double>::lowest();
      }
    if (to_split.empty()) {
      settled = true;
      break;
    }
    const uint64_t room = params.max_elements > leaves.size() ? (params.max_elements - leaves.size()) / 3 : 0;
    if (to_split.size() > room) {
      stats.element_limit = true;
      to_split.resize(room);
      if (to_split.empty()) {
        settled = true;
        split_room = std::numeric_limits<double>::infinity();  // no split is possible any more
        break;
      }
    }
    // The shot is cancelled and repeated with the split elements.
    ++stats.rounds;
    for (uint32_t e : to_split) split(e);
    replace_split(leaves);
    replace_split(accepted);
    grow_scratch();
    if (params.reuse_visibility) {
      project_children(to_split);
    } else {
      gather_seen();
      project(seen);
      sum_form_factors(accepted);
    }
  }

  // Southwell step: distribute this piece's unshot radiosity to the receivers that took it here.
  form_factors();
  if (!settled) record_broken = true;  // 64 rounds still splitting: no headroom to record
  if (recording != nullptr) {
    ShotRecord& r = *recording;
    ShotRecord::Piece rp;
    rp.src_begin = static_cast<uint32_t>(r.src.size());
    r.src.insert(r.src.end(), piece.src.begin(), piece.src.end());
    rp.src_end = static_cast<uint32_t>(r.src.size());
    rp.recv_begin = static_cast<uint32_t>(r.recv.size());
    // Unlit receivers too: once split, their children may be lit (a near receiver's exact form
    // factor, a different route to the sub-pieces), so a replay must know to shoot them anew.
    for (uint32_t e : accepted) {
      r.recv.push_back(e);
      r.f.push_back(static_cast<float>(std::max(0.0, f_recv[e])));
    }
    rp.recv_end = static_cast<uint32_t>(r.recv.size());
    rp.src_area = piece.src_area;
    rp.area = area;
    rp.dB = dB;
    // Headroom: the least factor on dB at which a fresh shot of this piece would decide anything
    // differently from this one. Power thresholds: refinement of weak pieces, the straddle rule,
    // coarser and finer hemicubes (stronger shots get finer ones); the split criteria; and the
    // close receivers left to this hemicube because the point view's error seemed small.
    double headroom = split_room;
    const bool patch_piece = piece.points.size() <= 4;
    // Two rules save work rather than decide structure, and a replay may exceed them by up to
    // twice: a weak piece that was not refined (its close receivers took exact form factors) stays
    // so up to twice FEPS of the emitted power, and a close receiver left to this hemicube because
    // its point view errs by under a quarter of the radiosity tolerance stays so until half of it.
    if (patch_piece && !piece.may_refine && piece.depth < kMaxShooterDepth)
      within(headroom, 2.0 * params.feps * emitted_power, power);
    if (patch_piece && power < kStraddlePower * emitted_power) within(headroom, kStraddlePower * emitted_power, power);
    if (params.method == Method::kAntiAliased) {
      if (power < 0.005 * emitted_power) within(headroom, 0.005 * emitted_power, power);
      else if (power < 0.05 * emitted_power) within(headroom, 0.05 * emitted_power, power);
      if (!patch_piece && piece.depth == 0 && power < kFinePower * emitted_power) within(headroom, kFinePower * emitted_power, power);
    }
    if (piece.may_refine)
      for (uint32_t e : accepted)
        if (is_close(e)) within(headroom, 2.0 * kNearError * b_tolerance, near_error(e));
    rp.headroom = headroom;
    rp.coarse = coarser > 0;
    rp.extra = false;
    r.pieces.push_back(rp);
  }
  for (uint32_t e : accepted)
    if (f_recv[e] > 0.0) receive(e, dB, f_recv[e]);
  return near;
}

}  // namespace hemibake::solver
