// Progressive refinement radiosity (Cohen, Chen, Wallace and Greenberg 1988) with adaptive
// substructuring (Cohen, Greenberg, Immel and Brock 1986), form factors from the anti-aliased
// hemicube, and reuse of the parent's pixels for subdivided elements (section 2.3 of "Anti-aliased
// hemicubes for performance improvement in radiosity solutions").
//
// One shot:
//   1. The patch with the most unshot power shoots. Large patches shoot from sub-areas no wider
//      than `shooter_size` of the scene's diagonal, each with its own hemicube, so that receivers
//      near a large shooter (room corners) do not see it as a point.
//   2. Every receiver (a leaf element of a patch that faces the hemicube) is projected, and every
//      other surface as the largest elements of its quadtree that hold no receiver; each pixel's
//      fragments are resolved by depth (E_k = A_k (1 - f_{k-1})); F(shooter -> element) is the sum
//      over its pixels of its visible share times the pixel's delta form factor.
//   3. A posteriori subdivision: a leaf is too large for this interaction when (a) its form factor
//      weighted by the shooter's share of the emitted power exceeds FEPS, or (b) it is partly hidden
//      and the hidden part would have changed its radiosity by more than the radiosity tolerance
//      (beps times the scene's mean emitted radiosity), or (c) the shot's radiosity differs across
//      one of its corners by more than that tolerance. Children must be at least AEPS of the
//      scene's area. Split elements cancel the shot; it is repeated from the same shooter, and the
//      children's form factors come from their parent's pixels and per-pixel transmissions (no
//      other element is looked at again) until nothing splits.
//   4. Southwell step: every receiver gains rho * dB * F(element -> shooter), with
//      F(element -> shooter) = F(shooter -> element) * A_shooter / A_element (capped at 1).
#include "hemibake/solver/solver.h"

#include "hemibake/solver/hemicube.h"

#include "hemicube_engine.h"
#include "scene_prep.h"
#include "thread_pool.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vector_relational.hpp>

#include <algorithm>
#include <chrono>
#include <functional>
#include <memory>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <thread>
#include <unordered_map>
#include <unordered_set>

namespace hemibake::solver {
namespace {

using detail::Fragment;
using Clock = std::chrono::steady_clock;

double channel_sum(const glm::dvec3& c) { return c.x + c.y + c.z; }
double mean(const glm::dvec3& c) { return (c.x + c.y + c.z) / 3.0; }
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}
uint64_t edge_key(uint32_t a, uint32_t b) {
  if (a > b) std::swap(a, b);
  return (static_cast<uint64_t>(a) << 32) | b;
}

using Corners = std::array<glm::dvec3, 4>;

// A receiver nearer to a shooting area's centre than kNearFactor times its diameter takes its share
// from the area's quarters, down to kMaxShooterDepth levels.
constexpr double kNearFactor = 2.0;
constexpr int kMaxShooterDepth = 3;
// A near-field hemicube projects only what may hide its receivers: elements overlapping the joint
// bounding box of the piece and the receivers of one surface, at most this many boxes.
constexpr size_t kMaxShaftBoxes = 32;
// A close receiver is refined for only if the point view's error could exceed this share of the
// radiosity tolerance (shoot_piece).
constexpr double kNearError = 0.25;
constexpr uint32_t kMinResolution = 20;
// A cluster of a curved surface shoots along its patches' mean normal, as if flat: its patches'
// normals stay within this cosine (20 degrees) of it, so a receiver's cosine at the cluster errs by
// under 6 % where it faces the cluster (build_clusters).
constexpr double kClusterCone = 0.9397;
// A shooting piece with an absorbing back close in front of it that takes at least this share of
// the light from its centre is refined (absorber_close).
constexpr double kAbsorberShare = 0.1;
// Coarser hemicubes may shoot at most this share of all the power shot (see coarser_levels).
constexpr double kCoarseShare = 0.25;
// Cluster pieces carrying at least this share of the emitted power take a finer hemicube
// (finer_level).
constexpr double kFinePower = 1e-3;
// Pieces carrying at least this share of the emitted power refine for receivers whose plane cuts
// through them, however far (shoot_piece).
constexpr double kStraddlePower = 0.05;

// Child k of a quad (4 corners) or triangle (3), in the order Solver::Impl::split creates them.
// Quads split at edge midpoints and the corners' mean (the bilinear centre); triangles at edge
// midpoints, the fourth child being the middle triangle.
uint32_t child_corners(const Corners& c, uint32_t n, uint32_t k, Corners& out) {
  if (n == 4) {
    const glm::dvec3 m01 = 0.5 * (c[0] + c[1]), m12 = 0.5 * (c[1] + c[2]);
    const glm::dvec3 m23 = 0.5 * (c[2] + c[3]), m30 = 0.5 * (c[3] + c[0]);
    const glm::dvec3 ctr = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    const std::array<Corners, 4> kids{{{c[0], m01, ctr, m30}, {m01, c[1], m12, ctr},
                                       {ctr, m12, c[2], m23}, {m30, ctr, m23, c[3]}}};
    out = kids[k];
    return 4;
  }
  const glm::dvec3 m01 = 0.5 * (c[0] + c[1]), m12 = 0.5 * (c[1] + c[2]), m20 = 0.5 * (c[2] + c[0]);
  const std::array<Corners, 4> kids{{{c[0], m01, m20, {}}, {m01, c[1], m12, {}},
                                     {m20, m12, c[2], {}}, {m12, m20, m01, {}}}};
  out = kids[k];
  return 3;
}

double polygon_area(const Corners& c, uint32_t n) {
  if (n == 4) return 0.5 * glm::length(glm::cross(c[2] - c[0], c[3] - c[1]));
  return 0.5 * glm::length(glm::cross(c[1] - c[0], c[2] - c[0]));
}

double polygon_diameter(const Corners& c, uint32_t n) {
  double d = 0.0;
  for (uint32_t i = 0; i < n; ++i)
    for (uint32_t j = i + 1; j < n; ++j) d = std::max(d, glm::length(c[i] - c[j]));
  return d;
}

// Reorders ids[begin, end) around its middle (returned) by the points key(id) along the widest
// axis of their bounding box [lo, hi]: a median cut, ties broken by id so that it is deterministic.
template <typename Key>
uint32_t median_cut(std::vector<uint32_t>& ids, uint32_t begin, uint32_t end, const glm::dvec3& lo,
                    const glm::dvec3& hi, Key key) {
  const glm::dvec3 ext = hi - lo;
  const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : ext.y >= ext.z ? 1 : 2;
  const uint32_t mid = begin + (end - begin) / 2;
  std::nth_element(ids.begin() + begin, ids.begin() + mid, ids.begin() + end, [&](uint32_t a, uint32_t b) {
    const double ka = key(a)[axis], kb = key(b)[axis];
    return ka != kb ? ka < kb : a < b;
  });
  return mid;
}

glm::dvec3 polygon_centre(const Corners& c, uint32_t n) {
  if (n == 3) return (c[0] + c[1] + c[2]) / 3.0;
  // Area centroid of a convex quad: area-weighted centroids of its two triangles.
  const double a1 = 0.5 * glm::length(glm::cross(c[1] - c[0], c[2] - c[0]));
  const double a2 = 0.5 * glm::length(glm::cross(c[2] - c[0], c[3] - c[0]));
  const glm::dvec3 g1 = (c[0] + c[1] + c[2]) / 3.0, g2 = (c[0] + c[2] + c[3]) / 3.0;
  return (a1 + a2) > 0.0 ? (a1 * g1 + a2 * g2) / (a1 + a2) : 0.25 * (c[0] + c[1] + c[2] + c[3]);
}

}  // namespace

struct Solver::Impl {
  Impl(const Scene& scene, const Params& p);

  // Geometry and tree.
  uint32_t corner_count(uint32_t e) const { return patches[e_patch[e]].corner_count; }
  void corners_of(uint32_t e, Corners& out) const {
    for (uint32_t i = 0; i < corner_count(e); ++i) out[i] = vpos[e_corner[e][i]];
  }
  Corners corners_of_copy(uint32_t e) const {
    Corners c{};
    corners_of(e, c);
    return c;
  }
  uint32_t midpoint(uint32_t a, uint32_t b);
  uint32_t add_element(uint32_t patch, uint32_t parent, const std::array<uint32_t, 4>& corners,
                       const glm::dvec3& b, const glm::dvec3& unshot);
  void split(uint32_t e);
  template <typename Fn>
  void for_leaves(uint32_t e, Fn&& fn) const;

  // Shooting.
  bool step();
  struct ShooterNode {
    Corners c;
    uint32_t element;  // kNone: a geometric piece of a leaf
    glm::dvec3 unshot;
    int depth;
    uint32_t source;   // `element`, or for a geometric piece the leaf it was cut from
  };
  // What one hemicube shoots from: a piece of a patch, or a cluster of patches of one surface.
  struct Piece {
    uint32_t patch;                   // a patch of the piece: its plane and occlusion group
    glm::dvec3 normal;                // the hemicube's axis: the patch's normal, a cluster's mean
    glm::dvec3 centre, up;            // the hemicube's centre and rotation hint
    double area, diameter;
    glm::dvec3 dB;                    // unshot radiosity shot (uniform over the piece)
    std::vector<glm::dvec3> points;   // points whose hull holds the piece (facing tests)
    int depth;                        // hemicube level (each halves the resolution)
    bool may_refine;                  // near receivers are left to sub-pieces
    // Where dB comes from (for replays): the unshot power of the leaves under `src`, divided by
    // src_area.
    std::vector<uint32_t> src;
    double src_area;
  };
  // A shot's form factors, kept for a replay (step): per piece, in the order they shot, its
  // sources and the receivers that took light with their F(element -> piece).
  struct ShotRecord {
    struct Piece {
      uint32_t src_begin, src_end, recv_begin, recv_end;
      double src_area, area;
      glm::dvec3 dB;  // the unshot radiosity it shot when recorded
      double headroom;  // a replay may shoot up to this times dB (shoot_piece)
      bool coarse;    // shot from a hemicube coarser than its level (kCoarseShare)
      bool extra;     // shot for children of split receivers: its power counts once, elsewhere
    };
    size_t fresh_pieces = 0;  // pieces of the shot that made it (replays may add more)
    std::vector<Piece> pieces;
    std::vector<uint32_t> src, recv;
    std::vector<float> f;
    size_t bytes() const {
      if (pieces.capacity() + src.capacity() + recv.capacity() + f.capacity() == 0) return 0;  // none
      return sizeof(ShotRecord) + pieces.capacity() * sizeof(Piece) +
             (src.capacity() + recv.capacity()) * sizeof(uint32_t) + f.capacity() * sizeof(float);
    }
  };
  bool replay(uint32_t unit);
  void keep_record(uint32_t unit, ShotRecord record);
  void receive(uint32_t e, const glm::dvec3& dB, double f);
  // A node of a cluster's binary tree over its patches (by median cuts of their centres).
  struct ClusterNode {
    uint32_t begin = 0, end = 0;  // its patches: cluster_patch[begin, end)
    uint32_t child = kNone;       // children at child and child + 1
    glm::dvec3 centre{0.0};       // area centroid
    glm::dvec3 normal{0.0};       // area-weighted mean of its patches' normals, unit
    double min_cos = 1.0;         // least cosine between a patch's normal and `normal`
    double area = 0.0, diameter = 0.0;
    std::array<glm::dvec3, 8> box{};  // corners of the bounding box of its patches' corners
  };
  void shoot_patch(uint32_t p, const std::vector<uint32_t>& receivers, bool whole_scene);
  void shoot_node(uint32_t p, const ShooterNode& node, std::vector<uint32_t> receivers, bool whole_scene);
  void shoot_cluster(uint32_t c, std::vector<uint32_t> receivers, bool whole_scene, int depth);
  std::vector<uint32_t> shoot_piece(const Piece& piece, std::vector<uint32_t> receivers, bool whole_scene);
  bool absorber_close(const Piece& piece) const;
  void build_cluster(uint32_t id, uint32_t begin, uint32_t end);
  void build_clusters();
  void build_patch_tree(uint32_t node, uint32_t begin, uint32_t end);
  void replace_split(std::vector<uint32_t>& list) const;
  void grow_scratch();
  int coarser_levels(double power) const;
  bool finer_level(const Piece& piece, double power) const;
  // Projects `elements` onto the placed hemicube, but for the patches of the shooting piece
  // (p_shooting == shooting_stamp).
  void project(std::span<const uint32_t> elements);
  void project_children(const std::vector<uint32_t>& parents);
  void sum_form_factors(std::span<const uint32_t> elements);
  void update_unshot_total();

  Params params;
  std::vector<Patch> patches;
  detail::PreparedScene prep;
  double aeps_area = 0.0;       // smallest element area allowed
  double b_tolerance = 0.0;     // radiosity tolerance for criteria (b) and (c)
  double shooter_limit = 0.0;   // widest shooting sub-area
  double emitted_power = 0.0;   // sum over patches of channel_sum(E) * A
  double power_shot = 0.0;      // by all hemicubes so far
  double power_coarse = 0.0;    // by hemicubes coarser than their level

  // Vertices (shared within a smoothing group) and edge midpoints.
  std::vector<glm::dvec3> vpos;
  std::unordered_map<uint64_t, uint32_t> midpoints;

  // Elements, structure of arrays. Children of an element are consecutive.
  std::vector<uint32_t> e_patch, e_parent, e_child;
  std::vector<uint32_t> e_group;  // the patch's occlusion group
  std::vector<std::array<uint32_t, 4>> e_corner;
  std::vector<double> e_area;
  std::vector<glm::dvec3> e_centre;  // bounding sphere
  std::vector<double> e_radius;
  std::vector<glm::dvec3> e_b, e_unshot;
  std::vector<uint32_t> leaves;
  std::vector<uint32_t> p_root;
  std::vector<double> p_unshot;  // unshot power per patch (channel sum times area)
  // Shooters: a unit is a patch that shoots alone or a cluster of small coplanar patches that
  // shoot together (cluster trees in c_nodes; unit_node kNone for a single patch).
  std::vector<ClusterNode> c_nodes;
  std::vector<uint32_t> cluster_patch;
  std::vector<uint32_t> unit_patch, unit_node, p_unit;
  std::vector<double> u_unshot;  // unshot power per unit
  // Replays: per unit, the form factors of its last shot (replay()).
  std::vector<ShotRecord> u_record;
  size_t record_bytes = 0;
  ShotRecord* recording = nullptr;  // the shot being recorded
  bool record_broken = false;       // a piece of it was skipped (no power): not replayable

  // Bounding-box tree over the patches (median cuts), for finding what lies near a hemicube.
  struct BoxNode {
    glm::dvec3 lo, hi;
    uint32_t begin = 0, end = 0;  // its patches: tree_patch[begin, end)
    uint32_t child = kNone;       // children at child and child + 1
  };
  std::vector<BoxNode> tree;
  std::vector<uint32_t> tree_patch;
  std::vector<glm::dvec3> p_lo, p_hi;  // per patch: bounding box
  std::vector<uint64_t> p_mark;        // per patch: listed for hemicube `mark`
  std::vector<uint32_t> p_surface;     // per patch: its surface for clustering (build_clusters)
  std::vector<uint64_t> p_shooting;    // per patch: part of the piece shooting hemicube `shooting_stamp`
  uint64_t shooting_stamp = 0;

  // Per-hemicube scratch.
  // Hemicubes of halving resolution (at least kMinResolution): a quarter-size shooting area serves
  // receivers half as far, which project as large, so its hemicube needs half the resolution; weak
  // shots may use coarser ones still (coarser_levels).
  std::vector<detail::Hemicube> cubes;
  std::unique_ptr<detail::Hemicube> finer_cube;  // for strong cluster shots (finer_level)
  detail::Hemicube* cube = nullptr;  // the one in use
  detail::ThreadPool pool;
  std::vector<Fragment> frags;
  std::vector<uint32_t> f_begin, f_end;  // per element: its fragments in `frags`
  std::vector<uint64_t> e_stamp;         // per element: the hemicube its form factor belongs to
  std::vector<double> e_ff, e_ff_open;   // per element: visible and unoccluded form factor
  uint64_t stamp = 0;
  std::vector<detail::ProjectScratch> scratch;
  std::vector<std::vector<Fragment>> chunk_frags;
  std::vector<std::vector<uint32_t>> gather_chunks;  // per chunk: elements a hemicube must see
  std::vector<uint32_t> order, pixel_start;
  std::vector<double> shot_b, vmin, vmax;
  std::vector<double> f_recv, f_open;  // per accepted receiver: F(element -> piece), visible and open
  std::vector<uint64_t> e_mark;        // per element: holds a receiver of hemicube `mark`
  uint64_t mark = 0;
  std::vector<double> e_exact;         // per element: exact F(element -> piece), for stamp e_exact_stamp
  std::vector<uint64_t> e_exact_stamp;

  Stats stats;
  bool done = false;
};

Solver::Impl::Impl(const Scene& scene, const Params& p)
    : params(p),
      patches(scene.patches),
      prep(detail::prepare(scene)),

      pool(p.threads != 0 ? p.threads : std::max(1u, std::thread::hardware_concurrency())) {
  for (int d = 0; d <= kMaxShooterDepth + 2; ++d) {
    const uint32_t res = std::max(kMinResolution, ((params.resolution >> d) + 1) & ~1u);
    cubes.emplace_back(std::min(res, params.resolution));
  }
  cube = &cubes[0];
  aeps_area = params.aeps * prep.total_area;
  shooter_limit = params.shooter_size * prep.diagonal;
  vpos = prep.vertex_position;
  double emitted_mean = 0.0;
  for (uint32_t i = 0; i < patches.size(); ++i) {
    emitted_power += channel_sum(patches[i].emission) * prep.area[i];
    emitted_mean += mean(patches[i].emission) * prep.area[i];
  }
  b_tolerance = params.beps * emitted_mean / prep.total_area;
  p_root.resize(patches.size());
  p_unshot.resize(patches.size());
  for (uint32_t i = 0; i < patches.size(); ++i) {
    p_root[i] = add_element(i, kNone, prep.corner_vertex[i], patches[i].emission, patches[i].emission);
    p_unshot[i] = channel_sum(patches[i].emission) * prep.area[i];
    leaves.push_back(p_root[i]);
  }
  build_clusters();
  p_lo.resize(patches.size());
  p_hi.resize(patches.size());
  tree_patch.resize(patches.size());
  p_mark.assign(patches.size(), 0);
  p_shooting.assign(patches.size(), 0);
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
  stats.patches = patches.size();
  stats.elements = leaves.size();
  stats.emitted_power = emitted_power;
  update_unshot_total();
  const size_t chunks = std::max<size_t>(1, pool.chunk_count(std::numeric_limits<uint32_t>::max()));
  scratch.resize(chunks);
  chunk_frags.resize(chunks);
  gather_chunks.resize(chunks);
}

uint32_t Solver::Impl::midpoint(uint32_t a, uint32_t b) {
  auto [it, fresh] = midpoints.try_emplace(edge_key(a, b), static_cast<uint32_t>(vpos.size()));
  if (fresh) vpos.push_back(0.5 * (vpos[a] + vpos[b]));
  return it->second;
}

uint32_t Solver::Impl::add_element(uint32_t patch, uint32_t parent,
                                   const std::array<uint32_t, 4>& corners, const glm::dvec3& b,
                                   const glm::dvec3& unshot) {
  const uint32_t id = static_cast<uint32_t>(e_patch.size());
  e_patch.push_back(patch);
  e_group.push_back(prep.occlusion_group[patch]);
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
  e_b.push_back(b);
  e_unshot.push_back(unshot);
  f_begin.push_back(0);
  f_end.push_back(0);
  e_stamp.push_back(0);
  e_ff.push_back(0.0);
  e_ff_open.push_back(0.0);
  e_mark.push_back(0);
  e_exact.push_back(0.0);
  e_exact_stamp.push_back(0);
  return id;
}

void Solver::Impl::split(uint32_t e) {
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
  const uint32_t first = add_element(p, e, kids[0], b, u);
  for (int k = 1; k < 4; ++k) add_element(p, e, kids[k], b, u);
  e_child[e] = first;
  ++stats.splits;
}

template <typename Fn>
void Solver::Impl::for_leaves(uint32_t e, Fn&& fn) const {
  if (e_child[e] == kNone) {
    fn(e);
    return;
  }
  for (uint32_t k = 0; k < 4; ++k) for_leaves(e_child[e] + k, fn);
}

void Solver::Impl::update_unshot_total() {
  double total = 0.0;
  for (double u : p_unshot) total += u;
  stats.unshot_fraction = emitted_power > 0.0 ? total / emitted_power : 0.0;
  stats.elements = leaves.size();
}

void Solver::Impl::sum_form_factors(std::span<const uint32_t> elements) {
  const auto& dff = cube->delta_form_factors();
  pool.parallel_for(elements.size(), [&](size_t b, size_t e, size_t) {
    for (size_t i = b; i < e; ++i) {
      const uint32_t el = elements[i];
      double ff = 0.0, open = 0.0;
      for (uint32_t k = f_begin[el]; k < f_end[el]; ++k) {
        const Fragment& f = frags[k];
        const double a = static_cast<double>(f.area) * dff[f.pixel];
        open += a;
        ff += a * f.trans;
      }
      e_ff[el] = ff;
      e_ff_open[el] = open;
      e_stamp[el] = stamp;
    }
  });
}

void Solver::Impl::project(std::span<const uint32_t> elements) {
  const auto t0 = Clock::now();
  ++stats.projections;
  stats.elements_projected += elements.size();
  const glm::dvec3 eye = cube->eye();
  const double eps = 1e-9 * prep.diagonal;
  const size_t n = elements.size();
  const size_t chunks = pool.chunk_count(n);
  pool.parallel_for(n, [&](size_t b, size_t e, size_t c) {
    auto& out = chunk_frags[c];
    out.clear();
    Corners poly{};
    for (size_t i = b; i < e; ++i) {
      const uint32_t el = elements[i];
      const uint32_t p = e_patch[el];
      f_begin[el] = f_end[el] = static_cast<uint32_t>(out.size());
      const double facing = glm::dot(prep.normal[p], eye - patches[p].corners[0]);
      if (p_shooting[p] == shooting_stamp || std::abs(facing) <= eps) continue;
      // The paper culls the parent patch's back faces (section 2.2), which is exact where every
      // back face lies behind a front face of the same solid. A one-sided wall seen from behind has
      // none: culled, it would let light through (a room of inward-facing walls lit from outside
      // came out lit inside). So such backs (PreparedScene::back_hidden) are projected as occluders
      // that take no light: flagged, and outside the element's fragment range. The backs of solids
      // stay culled: projected too, they would over-occlude at every silhouette pixel (front and
      // back cover the same part of it, and E_k takes them as independent).
      if (facing < 0.0 && prep.back_hidden[p]) continue;
      corners_of(el, poly);
      const uint32_t cc = patches[p].corner_count;
      if (facing > 0.0) {
        cube->project(std::span(poly.data(), cc), el, params.method, scratch[c], out, &prep.normal[p]);
        f_end[el] = static_cast<uint32_t>(out.size());
        continue;
      }
      std::reverse(poly.begin(), poly.begin() + cc);  // its back, counter-clockwise as seen
      const glm::dvec3 back = -prep.normal[p];
      const size_t first = out.size();
      cube->project(std::span(poly.data(), cc), el | detail::kBackFace, params.method, scratch[c], out, &back);
      for (size_t k = first; k < out.size(); ++k) out[k].inv_depth *= detail::kBackDepthScale;
    }
  });
  frags.clear();
  for (size_t c = 0; c < chunks; ++c) {
    const uint32_t base = static_cast<uint32_t>(frags.size());
    frags.insert(frags.end(), chunk_frags[c].begin(), chunk_frags[c].end());
    for (size_t i = n * c / chunks; i < n * (c + 1) / chunks; ++i) {
      f_begin[elements[i]] += base;
      f_end[elements[i]] += base;
    }
  }
  detail::resolve(frags, cube->pixel_count(), params.method, e_group, prep.adjacency, pool, order, pixel_start);
  stats.peak_fragments = std::max<uint64_t>(stats.peak_fragments, frags.size());
  stats.seconds_projecting += seconds_since(t0);
}

void Solver::Impl::project_children(const std::vector<uint32_t>& parents) {
  const auto t0 = Clock::now();
  const size_t n = parents.size();
  const size_t chunks = pool.chunk_count(n);
  pool.parallel_for(n, [&](size_t b, size_t e, size_t c) {
    auto& out = chunk_frags[c];
    out.clear();
    Corners poly{};
    for (size_t i = b; i < e; ++i) {
      const uint32_t par = parents[i];
      const std::span<const Fragment> pf(frags.data() + f_begin[par], f_end[par] - f_begin[par]);
      for (uint32_t k = 0; k < 4; ++k) {
        const uint32_t ch = e_child[par] + k;
        f_begin[ch] = f_end[ch] = static_cast<uint32_t>(out.size());
        if (pf.empty()) continue;
        corners_of(ch, poly);
        cube->project_child(std::span(poly.data(), corner_count(ch)), ch, pf, params.method,
                           scratch[c], out);
        f_end[ch] = static_cast<uint32_t>(out.size());
      }
    }
  });
  std::vector<uint32_t> children;
  children.reserve(n * 4);
  for (size_t c = 0; c < chunks; ++c) {
    const uint32_t base = static_cast<uint32_t>(frags.size());
    frags.insert(frags.end(), chunk_frags[c].begin(), chunk_frags[c].end());
    for (size_t i = n * c / chunks; i < n * (c + 1) / chunks; ++i) {
      for (uint32_t k = 0; k < 4; ++k) {
        const uint32_t ch = e_child[parents[i]] + k;
        f_begin[ch] += base;
        f_end[ch] += base;
        children.push_back(ch);
      }
    }
  }
  sum_form_factors(children);
  stats.reused_children += children.size();
  stats.peak_fragments = std::max<uint64_t>(stats.peak_fragments, frags.size());
  stats.seconds_reusing += seconds_since(t0);
}

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

// Whether a patch whose back the piece's centre sees (one that absorbs: not back_hidden), in front
// of the piece and within one of its diameters, takes at least kAbsorberShare of the centre's light.
bool Solver::Impl::absorber_close(const Piece& piece) const {
  const glm::dvec3& c = piece.centre;
  const double r = piece.diameter;
  const double eps = 1e-9 * prep.diagonal;
  std::vector<uint32_t> nodes{0};
  while (!nodes.empty()) {
    const BoxNode& node = tree[nodes.back()];
    nodes.pop_back();
    const glm::dvec3 gap = glm::max(node.lo - c, glm::max(c - node.hi, glm::dvec3(0.0)));
    if (glm::dot(gap, gap) > r * r) continue;
    if (node.child != kNone) {
      nodes.push_back(node.child);
      nodes.push_back(node.child + 1);
      continue;
    }
    for (uint32_t i = node.begin; i < node.end; ++i) {
      const uint32_t q = tree_patch[i];
      if (prep.back_hidden[q] || p_shooting[q] == shooting_stamp) continue;
      if (glm::dot(prep.normal[q], c - patches[q].corners[0]) >= -eps) continue;  // not its back
      const glm::dvec3 d = glm::max(p_lo[q] - c, glm::max(c - p_hi[q], glm::dvec3(0.0)));
      const double d2 = glm::dot(d, d);
      if (d2 > r * r) continue;
      // The form factor from the centre to the patch cut to the piece's front side: the share of
      // the centre's light it takes (a back seen edge-on takes little).
      std::array<glm::dvec3, 8> cut{};
      uint32_t m = 0;
      const uint32_t cc = patches[q].corner_count;
      for (uint32_t k = 0; k < cc; ++k) {
        const glm::dvec3& a = patches[q].corners[k];
        const glm::dvec3& b = patches[q].corners[(k + 1) % cc];
        const double da = glm::dot(piece.normal, a - c), db = glm::dot(piece.normal, b - c);
        if (da > eps) cut[m++] = a;
        if ((da > eps) != (db > eps)) cut[m++] = a + (b - a) * ((da - eps) / (da - db));
      }
      if (m >= 3 && point_polygon_form_factor(c, piece.normal, std::span(cut.data(), m)) >= kAbsorberShare) return true;
    }
  }
  return false;
}

void Solver::Impl::shoot_node(uint32_t p, const ShooterNode& node, std::vector<uint32_t> receivers,
                              bool whole_scene) {
  const uint32_t n = patches[p].corner_count;
  Piece piece;
  piece.patch = p;
  piece.normal = prep.normal[p];
  piece.area = polygon_area(node.c, n);
  piece.dB = node.unshot;
  if (node.element != kNone && e_child[node.element] != kNone) {
    glm::dvec3 power(0.0);
    for_leaves(node.element, [&](uint32_t e) { power += e_unshot[e] * e_area[e]; });
    piece.dB = power / piece.area;
  } else if (node.element != kNone) {
    piece.dB = e_unshot[node.element];
  }
  if (receivers.empty()) return;
  if (channel_sum(piece.dB) <= 0.0) {
    record_broken = true;  // a replay could not know this piece
    return;
  }
  piece.src.assign(1, node.source);
  piece.src_area = node.element != kNone ? piece.area : e_area[node.source];
  piece.centre = polygon_centre(node.c, n);
  piece.up = node.c[1] - node.c[0];
  piece.diameter = polygon_diameter(node.c, n);
  piece.points.assign(node.c.begin(), node.c.begin() + n);
  piece.depth = node.depth;
  // Weak shots stay whole.
  piece.may_refine = node.depth < kMaxShooterDepth && channel_sum(piece.dB) * piece.area >= params.feps * emitted_power;
  const std::vector<uint32_t> near = shoot_piece(piece, std::move(receivers), whole_scene);
  if (near.empty()) return;
  const bool is_leaf = node.element == kNone || e_child[node.element] == kNone;
  for (uint32_t k = 0; k < 4; ++k) {
    ShooterNode kid;
    child_corners(node.c, n, k, kid.c);
    kid.depth = node.depth + 1;
    kid.element = is_leaf ? kNone : e_child[node.element] + k;
    kid.source = is_leaf ? node.source : kid.element;
    kid.unshot = piece.dB;  // a geometric piece of a leaf shares the leaf's unshot radiosity
    shoot_node(p, kid, near, false);
  }
}

void Solver::Impl::shoot_cluster(uint32_t c, std::vector<uint32_t> receivers, bool whole_scene, int depth) {
  if (receivers.empty()) return;
  const ClusterNode& node = c_nodes[c];
  if (node.end - node.begin == 1) {
    // One patch: it shoots for these receivers as it would alone.
    const uint32_t p = cluster_patch[node.begin];
    Corners root{};
    corners_of(p_root[p], root);
    shoot_node(p, {root, p_root[p], glm::dvec3(0.0), std::min(depth / 2, kMaxShooterDepth), p_root[p]},
               std::move(receivers), whole_scene);
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
  piece.centre = node.centre;
  piece.up = node.box[1] - node.box[0];
  if (glm::length(glm::cross(piece.up, piece.normal)) < 1e-9 * prep.diagonal) piece.up = node.box[2] - node.box[0];
  piece.diameter = node.diameter;
  piece.points.assign(node.box.begin(), node.box.end());
  piece.depth = depth / 2;  // each level halves the area, every second one the width
  // A cluster stands for its patches: receivers near it always go on to its halves, down to single
  // patches, so that clustering never makes a receiver see a coarser shooter than the patches.
  piece.may_refine = true;
  const std::vector<uint32_t> near = shoot_piece(piece, std::move(receivers), whole_scene);
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

void Solver::Impl::build_cluster(uint32_t id, uint32_t begin, uint32_t end) {
  ClusterNode node;
  node.begin = begin;
  node.end = end;
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
  glm::dvec3 clo = lo, chi = hi;  // of the patch centres
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
  }
  node.centre /= node.area;
  const double nl = glm::length(node.normal);
  node.normal = nl > 0.0 ? node.normal / nl : prep.normal[cluster_patch[begin]];
  node.min_cos = nl > 0.0 ? 1.0 : -1.0;
  for (uint32_t i = begin; i < end; ++i) node.min_cos = std::min(node.min_cos, glm::dot(node.normal, prep.normal[cluster_patch[i]]));
  for (int k = 0; k < 8; ++k) node.box[k] = glm::dvec3(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z);
  for (uint32_t i = begin; i < end; ++i) {
    const Patch& patch = patches[cluster_patch[i]];
    for (uint32_t k = 0; k < patch.corner_count; ++k)
      node.diameter = std::max(node.diameter, 2.0 * glm::distance(node.centre, patch.corners[k]));
  }
  if (end - begin > 1) {
    // Median cut of the patch centres across their widest extent.
    const uint32_t mid = median_cut(cluster_patch, begin, end, clo, chi, [&](uint32_t q) {
      return polygon_centre(patches[q].corners, patches[q].corner_count);
    });
    node.child = static_cast<uint32_t>(c_nodes.size());
    c_nodes.resize(c_nodes.size() + 2);
    build_cluster(node.child, begin, mid);
    build_cluster(node.child + 1, mid, end);
  }
  c_nodes[id] = node;
}

void Solver::Impl::build_clusters() {
  // Small patches of one surface (an occlusion group: coplanar and edge-connected) with the same
  // emission shoot together: each surface's tree is cut into clusters no wider than cluster_size
  // of the scene's diagonal. Larger patches shoot alone.
  const double limit = params.cluster_size * prep.diagonal;
  // A surface: coplanar edge-connected patches (an occlusion group) joined with smoothly curved
  // ones (a smoothing group: same material, creases under 30 degrees). Group ids are patch ids.
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
  std::map<std::pair<uint32_t, std::array<double, 3>>, std::vector<uint32_t>> groups;
  p_unit.assign(patches.size(), kNone);
  for (uint32_t p = 0; p < patches.size(); ++p) {
    Corners c{};
    corners_of(p_root[p], c);
    if (limit <= 0.0 || polygon_diameter(c, patches[p].corner_count) > 0.5 * limit) continue;
    const glm::dvec3& e = patches[p].emission;
    groups[{find(p), {e.x, e.y, e.z}}].push_back(p);
  }
  std::vector<std::vector<uint32_t>> by_group;
  for (auto& [key, members] : groups) by_group.push_back(std::move(members));
  for (auto& members : by_group) {
    if (members.size() < 2) continue;
    const uint32_t begin = static_cast<uint32_t>(cluster_patch.size());
    cluster_patch.insert(cluster_patch.end(), members.begin(), members.end());
    // Cut from the top until the pieces are narrow enough.
    const uint32_t root = static_cast<uint32_t>(c_nodes.size());
    c_nodes.emplace_back();
    build_cluster(root, begin, static_cast<uint32_t>(cluster_patch.size()));
    std::vector<uint32_t> stack{root};
    while (!stack.empty()) {
      const uint32_t c = stack.back();
      stack.pop_back();
      if ((c_nodes[c].diameter > limit || c_nodes[c].min_cos < kClusterCone) && c_nodes[c].child != kNone) {
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
  for (uint32_t p = 0; p < patches.size(); ++p) {
    if (p_unit[p] != kNone) continue;
    p_unit[p] = static_cast<uint32_t>(unit_patch.size());
    unit_patch.push_back(p);
    unit_node.push_back(kNone);
    u_unshot.push_back(p_unshot[p]);
  }
}

void Solver::Impl::build_patch_tree(uint32_t id, uint32_t begin, uint32_t end) {
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

void Solver::Impl::replace_split(std::vector<uint32_t>& list) const {
  // Split elements (now inner nodes) are replaced by their children, in place of the parent.
  bool any = false;
  for (uint32_t e : list) any = any || e_child[e] != kNone;
  if (!any) return;
  std::vector<uint32_t> out;
  out.reserve(list.size() + 16);
  for (uint32_t e : list) for_leaves(e, [&](uint32_t leaf) { out.push_back(leaf); });
  list.swap(out);
}

void Solver::Impl::grow_scratch() {
  shot_b.resize(e_patch.size());
  f_recv.resize(e_patch.size());
  f_open.resize(e_patch.size());
  vmin.resize(vpos.size(), std::numeric_limits<double>::max());
  vmax.resize(vpos.size(), std::numeric_limits<double>::lowest());
}

void Solver::Impl::shoot_patch(uint32_t p, const std::vector<uint32_t>& receivers, bool whole_scene) {
  const uint32_t n = patches[p].corner_count;
  // The patch shoots from pieces no wider than shooter_limit (a leaf wider than that is cut
  // geometrically; its pieces share its unshot radiosity); each piece refines further for the
  // receivers near it (shoot_node).
  std::vector<ShooterNode> stack, tops;
  Corners root{};
  corners_of(p_root[p], root);
  stack.push_back({root, p_root[p], glm::dvec3(0.0), 0, p_root[p]});
  while (!stack.empty()) {
    ShooterNode node = stack.back();
    stack.pop_back();
    const bool leaf = node.element == kNone || e_child[node.element] == kNone;
    if (node.element != kNone && leaf) node.unshot = e_unshot[node.element];
    if (polygon_diameter(node.c, n) <= shooter_limit || node.depth >= 6) {
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
      stack.push_back(kid);
    }
  }
  grow_scratch();
  for (const ShooterNode& top : tops) shoot_node(p, top, receivers, whole_scene);
}

// A shooter that shoots again (its patches received light since) places the same hemicubes and, as
// long as none of its receivers has been split since, finds the same form factors: a split
// occluder's children hide exactly what it hid. A replay takes them from the last shot's record and
// only recomputes each piece's unshot radiosity. Every piece must shoot no more than when it was
// recorded, in every channel: the refinement near the shooter, the hemicubes' resolution and the
// subdivision criteria all ask less of a weaker shot, so it would have placed coarser hemicubes and
// split nothing more (the recorded shot ended with a round that split nothing).
bool Solver::Impl::replay(uint32_t unit) {
  if (u_record.empty()) return false;
  ShotRecord& r = u_record[unit];
  if (r.pieces.empty()) return false;
  auto drop = [&] {
    keep_record(unit, {});
    return false;
  };
  // Receivers split since need form factors for their children. When they are few, the rest is
  // replayed and the children are shot anew from the same shooter, its hemicubes seeing only what
  // may hide them (as near-field hemicubes do); otherwise the whole shot is made anew. A shot that
  // split a receiver recorded it in its earlier pieces and its children in later ones: the children
  // are shot anew from the whole shooter, so none of their entries replays either.
  std::vector<uint8_t> stale(r.recv.size(), 0);
  size_t stale_count = 0;
  ++mark;
  for (size_t k = 0; k < r.recv.size(); ++k)
    if (e_child[r.recv[k]] != kNone) stale[k] = 1, ++stale_count, e_mark[r.recv[k]] = mark;
  if (stale_count > 0)
    for (size_t k = 0; k < r.recv.size(); ++k)
      for (uint32_t x = e_parent[r.recv[k]]; x != kNone && !stale[k]; x = e_parent[x])
        if (e_mark[x] == mark) stale[k] = 1, ++stale_count;
  if (stale_count * 4 > r.recv.size()) return drop();  // splits are for good: it never replays again
  std::vector<glm::dvec3> dBs(r.pieces.size());
  double total = 0.0, coarse = 0.0;
  for (size_t i = 0; i < r.pieces.size(); ++i) {
    const ShotRecord::Piece& rp = r.pieces[i];
    glm::dvec3 power(0.0);
    for (uint32_t k = rp.src_begin; k < rp.src_end; ++k)
      for_leaves(r.src[k], [&](uint32_t e) { power += e_unshot[e] * e_area[e]; });
    dBs[i] = power / rp.src_area;
    // The most any channel grew: every decision of the shot is a sum of channels with non-negative
    // weights, so it grew by at most this factor.
    double growth = 0.0;
    for (int c = 0; c < 3; ++c) {
      if (dBs[i][c] <= 0.0) continue;
      growth = rp.dB[c] > 0.0 ? std::max(growth, dBs[i][c] / rp.dB[c]) : std::numeric_limits<double>::infinity();
    }
    if (std::isinf(growth) || growth > rp.headroom) return false;
    if (rp.extra) continue;
    const double shot = channel_sum(dBs[i]) * rp.area;
    total += shot;
    if (rp.coarse) coarse += shot;
  }
  // Coarser hemicubes may not shoot more than their share (coarser_levels): shoot anew instead.
  if (coarse > 0.0 && power_coarse + coarse > kCoarseShare * (power_shot + total)) return false;
  power_shot += total;
  power_coarse += coarse;
  for (size_t i = 0; i < r.pieces.size(); ++i) {
    const ShotRecord::Piece& rp = r.pieces[i];
    for (uint32_t k = rp.recv_begin; k < rp.recv_end; ++k)
      if (!stale[k] && r.f[k] > 0.0f) receive(r.recv[k], dBs[i], r.f[k]);
  }
  if (stale_count == 0) return true;

  // The split receivers, each once and none below another (the shot expands them to their leaves).
  std::vector<uint32_t> redo;
  for (size_t k = 0; k < r.recv.size(); ++k) {
    if (e_mark[r.recv[k]] != mark) continue;
    bool below = false;
    for (uint32_t x = e_parent[r.recv[k]]; x != kNone && !below; x = e_parent[x]) below = e_mark[x] == mark;
    if (!below) redo.push_back(r.recv[k]);
  }
  std::sort(redo.begin(), redo.end());
  redo.erase(std::unique(redo.begin(), redo.end()), redo.end());
  ShotRecord part;
  // The unit's power is counted above already; the partial shot's pieces do not count again.
  const double shot_before = power_shot, coarse_before = power_coarse;
  recording = &part;
  record_broken = false;
  grow_scratch();
  if (unit_node[unit] == kNone) shoot_patch(unit_patch[unit], redo, false);
  else shoot_cluster(unit_node[unit], redo, false, 0);
  recording = nullptr;
  power_shot = shot_before;
  power_coarse = coarse_before;
  ++stats.replays_reshot;

  // The record now holds the replayed receivers and the partial shot's pieces. Each partial shot
  // adds pieces (with the sources of the shooter's own): past four times the fresh shot's, the
  // record is dropped, and the next shot makes a compact one.
  if (record_broken || r.pieces.size() + part.pieces.size() > 4 * r.fresh_pieces) {
    drop();
    return true;
  }
  ShotRecord merged;
  merged.fresh_pieces = r.fresh_pieces;
  auto add = [&](const ShotRecord& from, ShotRecord::Piece np, bool extra, const uint8_t* skip) {
    const uint32_t src_begin = np.src_begin, src_end = np.src_end, recv_begin = np.recv_begin, recv_end = np.recv_end;
    np.recv_begin = static_cast<uint32_t>(merged.recv.size());
    for (uint32_t k = recv_begin; k < recv_end; ++k) {
      if (skip != nullptr && skip[k]) continue;
      merged.recv.push_back(from.recv[k]);
      merged.f.push_back(from.f[k]);
    }
    np.recv_end = static_cast<uint32_t>(merged.recv.size());
    if (np.recv_end == np.recv_begin) return;
    np.src_begin = static_cast<uint32_t>(merged.src.size());
    merged.src.insert(merged.src.end(), from.src.begin() + src_begin, from.src.begin() + src_end);
    np.src_end = static_cast<uint32_t>(merged.src.size());
    np.extra = np.extra || extra;
    merged.pieces.push_back(np);
  };
  for (const ShotRecord::Piece& rp : r.pieces) add(r, rp, false, stale.data());
  for (const ShotRecord::Piece& rp : part.pieces) add(part, rp, true, nullptr);
  keep_record(unit, std::move(merged));
  return true;
}

// Puts `record` in place of the unit's record, if the records' memory allows.
void Solver::Impl::keep_record(uint32_t unit, ShotRecord record) {
  if (!u_record.empty()) {
    record_bytes -= u_record[unit].bytes();
    u_record[unit] = ShotRecord{};
  }
  if (record.pieces.empty()) return;
  record.pieces.shrink_to_fit();
  record.src.shrink_to_fit();
  record.recv.shrink_to_fit();
  record.f.shrink_to_fit();
  if (record_bytes + record.bytes() > static_cast<size_t>(params.shot_cache_mb) << 20) return;
  if (u_record.empty()) u_record.resize(unit_node.size());
  record_bytes += record.bytes();
  u_record[unit] = std::move(record);
}

void Solver::Impl::receive(uint32_t e, const glm::dvec3& dB, double f) {
  const uint32_t q = e_patch[e];
  const glm::dvec3 gain = patches[q].reflectance * dB * f;
  e_b[e] += gain;
  e_unshot[e] += gain;
  p_unshot[q] += channel_sum(gain) * e_area[e];
  u_unshot[p_unit[q]] += channel_sum(gain) * e_area[e];
}

bool Solver::Impl::step() {
  if (done) return false;
  if (stats.unshot_fraction < params.convergence || emitted_power <= 0.0) {
    stats.converged = true;
    done = true;
    return false;
  }
  if (stats.shots >= params.max_shots) {
    stats.shot_limit = true;
    done = true;
    return false;
  }
  const auto t0 = Clock::now();
  uint32_t best = 0;
  for (uint32_t u = 1; u < u_unshot.size(); ++u)
    if (u_unshot[u] > u_unshot[best]) best = u;
  if (replay(best)) {
    ++stats.replayed_shots;
  } else {
    // A fresh shot, recorded for a replay while the cache has room (in place of the unit's
    // record, which could not be replayed).
    ShotRecord record;
    keep_record(best, {});
    recording = params.shot_cache_mb > 0 ? &record : nullptr;
    record_broken = false;
    if (unit_node[best] == kNone) {
      shoot_patch(unit_patch[best], leaves, true);
    } else {
      grow_scratch();
      shoot_cluster(unit_node[best], leaves, true, 0);
    }
    recording = nullptr;
    if (params.shot_cache_mb > 0 && !record_broken) {
      record.fresh_pieces = record.pieces.size();
      keep_record(best, std::move(record));
    }
  }
  if (unit_node[best] != kNone) {
    const ClusterNode& c = c_nodes[unit_node[best]];
    for (uint32_t i = c.begin; i < c.end; ++i) {
      const uint32_t q = cluster_patch[i];
      for_leaves(p_root[q], [&](uint32_t e) { e_unshot[e] = glm::dvec3(0.0); });
      p_unshot[q] = 0.0;
    }
  } else {
    const uint32_t p = unit_patch[best];
    for_leaves(p_root[p], [&](uint32_t e) { e_unshot[e] = glm::dvec3(0.0); });
    p_unshot[p] = 0.0;
  }
  u_unshot[best] = 0.0;
  ++stats.shots;
  update_unshot_total();
  stats.seconds += seconds_since(t0);
  return true;
}

Solver::Solver(const Scene& scene, const Params& params)
    : impl_(std::make_unique<Impl>(scene, params)) {}
Solver::~Solver() = default;

bool Solver::step() { return impl_->step(); }

const Stats& Solver::stats() const { return impl_->stats; }

const Stats& Solver::run(const ProgressFn& progress, const CancelToken* cancel) {
  const auto t0 = Clock::now();
  while (true) {
    if (cancel && cancel->cancelled()) {
      impl_->stats.cancelled = true;
      break;
    }
    if (!impl_->step()) break;
    if (progress) {
      Progress pr;
      pr.shots = impl_->stats.shots;
      pr.unshot_fraction = impl_->stats.unshot_fraction;
      pr.elements = impl_->stats.elements;
      pr.elapsed_seconds = seconds_since(t0);
      progress(pr);
    }
  }
  return impl_->stats;
}

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
  std::vector<std::array<uint32_t, 2>> lerp_from;  // for extra vertices: the edge they lie on
  std::unordered_map<uint64_t, uint32_t> extra;      // edge key -> extra vertex

  // Collects the vertices strictly inside edge (a, b), in order from a to b.
  std::function<void(uint32_t, uint32_t)> hanging = [&](uint32_t a, uint32_t b) {
    uint32_t mid = kNone;
    if (auto it = s.midpoints.find(edge_key(a, b)); it != s.midpoints.end()) {
      mid = it->second;
    } else if (auto ex = extra.find(edge_key(a, b)); ex != extra.end()) {
      mid = ex->second;
    } else {
      const glm::dvec3 pm = 0.5 * (m.positions[a] + m.positions[b]);
      if (positions.count(pm)) {
        mid = static_cast<uint32_t>(m.positions.size());
        m.positions.push_back(pm);
        lerp_from.push_back({a, b});
        extra.emplace(edge_key(a, b), mid);
      }
    }
    if (mid == kNone) return;
    hanging(a, mid);
    m.boundary.push_back(mid);
    hanging(mid, b);
  };

  std::vector<glm::dvec3> acc(s.vpos.size(), glm::dvec3(0.0));
  std::vector<double> weight(s.vpos.size(), 0.0);
  m.elements.reserve(leaves.size());
  for (uint32_t e : leaves) {
    Mesh::Element el;
    el.patch = s.e_patch[e];
    el.corner_count = s.corner_count(e);
    el.corners = s.e_corner[e];
    el.area = s.e_area[e];
    el.radiosity = s.e_b[e] + s.patches[el.patch].reflectance * amb;
    el.boundary_begin = static_cast<uint32_t>(m.boundary.size());
    for (uint32_t k = 0; k < el.corner_count; ++k) {
      const uint32_t a = el.corners[k], b = el.corners[(k + 1) % el.corner_count];
      m.boundary.push_back(a);
      hanging(a, b);
    }
    el.boundary_end = static_cast<uint32_t>(m.boundary.size());
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const uint32_t v = m.boundary[i];
      if (v >= s.vpos.size()) continue;  // another surface's point: interpolated below
      acc[v] += el.radiosity * el.area;
      weight[v] += el.area;
    }
    m.elements.push_back(el);
  }
  m.radiosity.resize(m.positions.size(), glm::dvec3(0.0));
  for (size_t v = 0; v < s.vpos.size(); ++v)
    if (weight[v] > 0.0) m.radiosity[v] = acc[v] / weight[v];
  // Extra vertices were created in order, each from an earlier vertex pair.
  for (size_t i = 0; i < lerp_from.size(); ++i) {
    const auto [a, b] = lerp_from[i];
    m.radiosity[s.vpos.size() + i] = 0.5 * (m.radiosity[a] + m.radiosity[b]);
  }
  return m;
}

}  // namespace hemibake::solver
