// How a shooting unit (a patch, or a cluster of small patches of one surface) breaks into pieces,
// each shooting from a hemicube of its own, and refines for near receivers.
#include "solver_impl.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>

namespace hemibake::solver {
namespace {

// A patch is cut for shooter_limit at most this many levels (4096 pieces): a sliver as long as the
// scene stays a few sliver-shaped pieces rather than millions.
constexpr int kMaxCutLevels = 6;

// A hemicube sees its shooter as a point, and an area light's penumbra as a hard shadow: the
// Cornell box's floor and back wall beside the tall block read up to 40 % off on either side of the
// shadow's edge, and a box in a lamp-lit room cast a blocky shadow. A patch emitting at least
// kStrongEmitterShare of the scene's emitted power, and left whole by shooter_limit (a lamp, not a
// glowing wall, which shooter_limit cuts already), shoots from pieces no wider than
// kStrongEmitterCut of its own diameter (4 x 4), each with its own hemicube, whose shadows fall
// apart across the penumbra. The Cornell box's p90 as displayed: 12.9 % from one hemicube, 8.1 %
// from 2 x 2 (its floor's shadow a visible staircase), 7.2 % from 4 x 4 (bench/README.md). The
// walls of a uniformly glowing box, cut so too, split at every corner and came out 2.5 % dark there.
constexpr double kStrongEmitterShare = 0.05;
constexpr double kStrongEmitterCut = 0.25;
// Each such cut (ShooterNode::extra) multiplies a piece's judge (refine.cpp judges its shot as if
// that many times as strong) by kStrongCutJudge: n pieces whose light varies together across a
// receiver add up to n times one piece's variation, and where their shadows fall apart to about
// one; the judge is sqrt(n), between the two. At 1 the pieces left lamp-lit floors coarser than one
// hemicube had (a lamp room's p90 4.9 -> 7.5 % with 2 x 2); at 2.5 a level the Cornell box took
// three times the elements.
constexpr double kStrongCutJudge = 2.0;

}  // namespace

// Shoots a piece of patch p (an element of its quadtree, or a geometric piece of a leaf) to
// `receivers`; the receivers too close for its hemicube go on to its quarters, down to
// kMaxShooterDepth levels, each quarter's unshot radiosity its own where the tree has it.
void Solver::Impl::shoot_node(uint32_t p, const ShooterNode& node, const std::vector<uint32_t>& receivers,
                              bool whole_scene) {
  const uint32_t n = patches[p].corner_count;
  Piece piece;
  piece.patch = p;
  piece.normal = prep.normal[p];
  piece.area = polygon_area(node.c, n);
  piece.dB = node.unshot;
  piece.centre = polygon_centre(node.c, n);
  if (node.element != kNone && e_child[node.element] != kNone) {
    // The hemicube stands where the piece's unshot power is: at its leaves' centres weighted by
    // their power (a point of the piece, which is convex). A floor piece half under a block, lit
    // only outside it, then shoots into the room rather than into the block.
    glm::dvec3 power(0.0), moment(0.0);
    for_leaves(node.element, [&](uint32_t e) {
      power += e_unshot[e] * e_area[e];
      moment += channel_sum(e_unshot[e]) * e_area[e] * e_centre[e];
    });
    piece.dB = power / piece.area;
    if (channel_sum(power) > 0.0) piece.centre = moment / channel_sum(power);
  } else if (node.element != kNone) {
    piece.dB = e_unshot[node.element];
  }
  if (receivers.empty()) return;
  if (channel_sum(piece.dB) <= 0.0) {
    record_broken = true;  // a replay could not know this piece
    return;
  }
  // A piece centred under a surface resting on its patch (covered) shoots from its parts; what is
  // left under that surface is not shot. A replay leaves it so too, as long as the leaf it lies in
  // has not been split since (replay): within a leaf, the pieces and their centres follow from its
  // corners alone, whatever its power. (Such shots once kept no record: in the benchmarks'
  // cluttered room 173 shots of tiles and table tops under boxes were made afresh every time.)
  if (covered(p, piece.centre)) {
    const bool is_leaf = node.element == kNone || e_child[node.element] == kNone;
    if (is_leaf && node.depth >= kMaxShooterDepth) {
      if (recording != nullptr && (recording->covered.empty() || recording->covered.back() != node.source))
        recording->covered.push_back(node.source);
      return;
    }
    for (uint32_t k = 0; k < 4; ++k) {
      ShooterNode part;
      child_corners(node.c, n, k, part.c);
      part.depth = is_leaf ? node.depth + 1 : node.depth;
      part.element = is_leaf ? kNone : e_child[node.element] + k;
      part.source = is_leaf ? node.source : part.element;
      part.unshot = piece.dB;
      part.top = node.top;
      part.extra = node.extra;
      shoot_node(p, part, receivers, whole_scene);
    }
    return;
  }
  piece.src.assign(1, node.source);
  piece.src_area = node.element != kNone ? piece.area : e_area[node.source];
  piece.up = node.c[1] - node.c[0];
  piece.diameter = polygon_diameter(node.c, n);
  piece.points.assign(node.c.begin(), node.c.begin() + n);
  piece.depth = node.depth;
  piece.judge = std::pow(kStrongCutJudge, node.extra);
  piece.power = channel_sum(piece.dB) * piece.area;
  // A piece shoots its mean unshot radiosity from its centre. Where that is uneven, the centre's
  // view is not its bright part's: a ceiling piece over a lamp hung 1 mm under it, bright only
  // above the lamp, would give the room the light that only the lamp's top sees; a lit floor piece
  // reaching under a block would give its light to the block's inside. Such pieces (strong enough
  // to refine at all) shoot from their children, each with its own unshot radiosity.
  if (node.element != kNone && e_child[node.element] != kNone && piece.power >= params.feps * emitted_power &&
      uneven_piece(node.element)) {
    for (uint32_t k = 0; k < 4; ++k) {
      const uint32_t kid = e_child[node.element] + k;
      ShooterNode part{{}, kid, glm::dvec3(0.0), node.depth, kid, node.top, node.extra};
      corners_of(kid, part.c);
      shoot_node(p, part, receivers, whole_scene);
    }
    return;
  }
  // Weak shots stay whole. A strong emitter's extra cuts count as near-field levels: its small
  // pieces refine no deeper than its whole would have (the Blender room's double-sided panel, 1 cm
  // under the ceiling: 10.4 s against 4.3 s when they did not, 3.6 s when they do).
  piece.may_refine = node.depth + node.extra < kMaxShooterDepth && piece.power >= params.feps * emitted_power;
  // A top piece that may refine holds its far receivers' light until its parts have shot (settle_far).
  defer_far = node.top && piece.may_refine;
  const std::vector<uint32_t> near = shoot_piece(piece, receivers, whole_scene);
  defer_far = false;
  std::unique_ptr<FarShare> far = std::move(far_pending);
  const double before = delivered;
  const bool is_leaf = node.element == kNone || e_child[node.element] == kNone;
  for (uint32_t k = 0; k < 4 && !near.empty(); ++k) {
    ShooterNode kid;
    child_corners(node.c, n, k, kid.c);
    kid.depth = node.depth + 1;
    kid.element = is_leaf ? kNone : e_child[node.element] + k;
    kid.source = is_leaf ? node.source : kid.element;
    kid.unshot = piece.dB;  // a geometric piece of a leaf shares the leaf's unshot radiosity
    kid.extra = node.extra;
    shoot_node(p, kid, near, false);
  }
  if (!far) return;
  const double scale =
      settle_far(*far, piece.power, delivered - before, whole_scene, !near.empty(), u_far_scale[p_unit[p]]);
  far_scale_sum += scale * piece.power;
  far_scaled_power += piece.power;
}

// Whether the children of inner element `element` depart from its mean unshot radiosity by more
// than kUnevenShare (area-weighted, channels summed), so that it shoots from them (shoot_node).
bool Solver::Impl::uneven_piece(uint32_t element) const {
  double power[4] = {0.0, 0.0, 0.0, 0.0}, area[4] = {0.0, 0.0, 0.0, 0.0}, total = 0.0, total_area = 0.0;
  for (uint32_t k = 0; k < 4; ++k) {
    for_leaves(e_child[element] + k, [&](uint32_t e) {
      power[k] += channel_sum(e_unshot[e]) * e_area[e];
      area[k] += e_area[e];
    });
    total += power[k];
    total_area += area[k];
  }
  if (total <= 0.0) return false;
  const double mean = total / total_area;
  double departure = 0.0;
  for (uint32_t k = 0; k < 4; ++k) departure += std::abs(power[k] - mean * area[k]);
  return departure > kUnevenShare * total;
}

// Shoots cluster node c to `receivers` as one piece along its mean normal, or from a whole cube (a
// volume cluster whose faces look several ways); `depth` counts the halvings from the unit's root.
void Solver::Impl::shoot_cluster(uint32_t c, const std::vector<uint32_t>& receivers, bool whole_scene, int depth) {
  if (receivers.empty()) return;
  const ClusterNode& node = c_nodes[c];
  if (node.end - node.begin == 1) {
    // One patch: it shoots for these receivers as it would alone.
    const uint32_t p = cluster_patch[node.begin];
    Corners root{};
    corners_of(p_root[p], root);
    shoot_tops(p, {{root, p_root[p], glm::dvec3(0.0), std::min(depth / 2, kMaxShooterDepth), p_root[p], depth == 0}},
               receivers, whole_scene);
    return;
  }
  Piece piece;
  piece.patch = cluster_patch[node.begin];
  piece.normal = node.normal;
  glm::dvec3 power(0.0);
  for (uint32_t i = node.begin; i < node.end; ++i)
    for_leaves(p_root[cluster_patch[i]], [&](uint32_t e) { power += e_unshot[e] * e_area[e]; });
  if (channel_sum(power) <= 0.0) {
    record_broken = true;
    return;
  }
  for (uint32_t i = node.begin; i < node.end; ++i) piece.src.push_back(p_root[cluster_patch[i]]);
  piece.src_area = node.area;
  piece.area = node.area;
  piece.dB = power / node.area;
  piece.power = channel_sum(piece.dB) * piece.area;
  piece.centre = node.centre + node.normal * node.front;
  piece.rear = node.depth;
  piece.up = node.box[1] - node.box[0];
  if (glm::length(glm::cross(piece.up, piece.normal)) < kRoundingLength * prep.diagonal) piece.up = node.box[2] - node.box[0];
  if (volume_shot(node)) {
    // Its faces look several ways: a whole cube at its centroid, always turned alike (its pixels'
    // directions are kept per level).
    piece.volume = true;
    piece.cluster = c;
    piece.centre = node.centre;
    piece.normal = glm::dvec3(0.0, 0.0, 1.0);
    piece.up = glm::dvec3(0.0, 1.0, 0.0);
  }
  piece.diameter = node.diameter;
  piece.points.assign(node.box.begin(), node.box.end());
  piece.depth = depth / 2;  // each level halves the area, every second one the width
  // A cluster stands for its patches: receivers near it always go on to its halves, down to single
  // patches, so that clustering never makes a receiver see a coarser shooter than the patches.
  piece.may_refine = true;
  // The near receivers take from its parts what those, where they stand, send their way (the floor
  // under a cluster of boxes, seen from above it): its far receivers wait for the rest (settle_far).
  defer_far = depth == 0;
  std::vector<uint32_t> near = shoot_piece(piece, receivers, whole_scene);
  defer_far = false;
  std::unique_ptr<FarShare> far = std::move(far_pending);
  const double before = delivered;
  shoot_parts(c, near, depth);
  if (far) {
    const uint32_t unit = p_unit[cluster_patch[node.begin]];
    // A volume cluster's cube settles always: its near receivers are seen from its centre, inside it.
    u_far_scale[unit] = settle_far(*far, piece.power, delivered - before, whole_scene, piece.volume || !near.empty(),
                                   u_far_scale[unit]);
  }
}

// Hands the receivers near cluster node c to its parts (shoot_cluster).
void Solver::Impl::shoot_parts(uint32_t c, const std::vector<uint32_t>& near, int depth) {
  const ClusterNode& node = c_nodes[c];
  if (near.empty()) return;
  // Near receivers go on to the quarters (the halves' halves: half as wide), as for a patch.
  for (uint32_t h = node.child; h < node.child + 2; ++h) {
    if (c_nodes[h].child == kNone) {
      shoot_cluster(h, near, false, depth + 2);
      continue;
    }
    shoot_cluster(c_nodes[h].child, near, false, depth + 2);
    shoot_cluster(c_nodes[h].child + 1, near, false, depth + 2);
  }
}

// The patch shoots from pieces no wider than shooter_limit (a leaf wider than that is cut
// geometrically; its pieces share its unshot radiosity); each piece refines further for the
// receivers near it (shoot_node).
void Solver::Impl::shoot_patch(uint32_t p, const std::vector<uint32_t>& receivers, bool whole_scene) {
  const uint32_t n = patches[p].corner_count;
  std::vector<ShooterNode> stack, tops;
  Corners root{};
  corners_of(p_root[p], root);
  stack.push_back({root, p_root[p], glm::dvec3(0.0), 0, p_root[p]});
  // A strong emitter shoots from smaller pieces, judged for refinement as if stronger (judge).
  const double emitted = channel_sum(patches[p].emission) * prep.area[p];
  const double diameter = polygon_diameter(root, n);
  const double limit = emitted > 0.0 && emitted >= kStrongEmitterShare * emitted_power && diameter <= shooter_limit
                           ? (kStrongEmitterCut + 1e-4) * diameter
                           : shooter_limit;
  while (!stack.empty()) {
    ShooterNode node = stack.back();
    stack.pop_back();
    const bool leaf = node.element == kNone || e_child[node.element] == kNone;
    if (node.element != kNone && leaf) node.unshot = e_unshot[node.element];
    if (polygon_diameter(node.c, n) <= limit || node.depth >= kMaxCutLevels) {
      node.depth = 0;  // near-field refinement counts from here
      tops.push_back(node);
      continue;
    }
    for (uint32_t k = 4; k-- > 0;) {
      ShooterNode kid;
      child_corners(node.c, n, k, kid.c);
      kid.depth = node.depth + 1;
      kid.element = leaf ? kNone : e_child[node.element] + k;
      kid.source = leaf ? node.source : kid.element;
      kid.unshot = node.unshot;
      kid.extra = node.extra + (polygon_diameter(node.c, n) <= shooter_limit ? 1 : 0);
      stack.push_back(kid);
    }
  }
  for (ShooterNode& top : tops) top.top = true;
  grow_scratch();
  shoot_tops(p, tops, receivers, whole_scene);
}

// Shoots patch p's top pieces; a whole-scene shot keeps their far scales' mean, by power, as its
// unit's (settle_far).
void Solver::Impl::shoot_tops(uint32_t p, const std::vector<ShooterNode>& tops, const std::vector<uint32_t>& receivers,
                              bool whole_scene) {
  far_scale_sum = 0.0;
  far_scaled_power = 0.0;
  for (const ShooterNode& top : tops) shoot_node(p, top, receivers, whole_scene);
  if (whole_scene && far_scaled_power > 0.0) u_far_scale[p_unit[p]] = far_scale_sum / far_scaled_power;
}

}  // namespace hemibake::solver
