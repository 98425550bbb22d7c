// The solver's shared state: Solver::Impl, its thresholds and its helpers. The member functions
// live in the files named for what they hold (the list is in solver.cpp); the declarations below
// are grouped by file. Private to solver/src.
#pragma once

#include "hemibake/solver/solver.h"

#include "check.h"
#include "geometry.h"
#include "hemicube_engine.h"
#include "scene_prep.h"
#include "shaft.h"
#include "thread_pool.h"

#include <glm/common.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <unordered_map>
#include <vector>

namespace hemibake::solver {

// The polygon helpers (geometry.h), unqualified in the Impl's files.
using detail::along_segment;
using detail::on_segment;
using detail::channel_sum;
using detail::child_corners;
using detail::Corners;
using detail::edge_key;
using detail::Fragment;
using detail::mean;
using detail::median_cut;
using detail::polygon_area;
using detail::polygon_centre;
using detail::polygon_diameter;
using Clock = std::chrono::steady_clock;

inline double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// Shared thresholds. Those that compare a piece's power with the emitted power are read twice: by
// the fresh shot that decides with them, and by piece_headroom, which stops a replay of that shot
// where a fresh one would decide differently. A replay reuses the recorded form factors, so it is
// exact only while both places read the same constant.

// A receiver nearer to a shooting area's centre than kNearFactor times its diameter takes its share
// from the area's quarters, down to kMaxShooterDepth levels.
constexpr double kNearFactor = 2.0;
constexpr int kMaxShooterDepth = 3;
// A near-field hemicube projects only what may hide its receivers: elements overlapping the joint
// bounding box of the piece and the receivers of one surface, at most this many boxes (shaft_of).
constexpr size_t kMaxShaftBoxes = 32;
// A close receiver is refined for only if the point view's error could exceed this share of the
// radiosity tolerance (classify_receivers, near_error).
constexpr double kNearError = 0.25;
// Two rules save work rather than decide structure, so a replay may exceed them by this factor
// (piece_headroom): a weak piece left unrefined (power under FEPS of the emitted power), and a
// close receiver left to the hemicube (point view's error under kNearError of the tolerance).
constexpr double kSavingRuleSlack = 2.0;
// Hemicubes halve their resolution per level, down to this.
constexpr uint32_t kMinResolution = 20;
// The solver keeps this many levels of hemicubes: a patch's pieces go down kMaxShooterDepth levels,
// a cluster's parts further (the deepest share the last level).
constexpr int kCubeLevels = kMaxShooterDepth + 3;
// Once the unshot power is below `convergence` of the emitted, units still holding more than
// kLocalConvergence times `convergence` of their own light shoot on, unless their unshot power is
// below kLocalFloor times `convergence` of the emitted (lagging_unit).
constexpr double kLocalConvergence = 10.0;
constexpr double kLocalFloor = 1e-3;
// pools.cpp: the first pass looks for light pools once every emitter has shot and the unshot power
// is below this share of the emitted (or at convergence): the emitters' light and its first
// reflections. An element splits there when the light its points took differs by more than
// kPoolShare of their mean and by more than kPoolFloor times the radiosity tolerance: a pool, not
// the few percent by which an evenly lit wall's points differ before the last shots even them out.
constexpr double kPoolsPass = 0.3;
// ... and once the patches the lights lit that hold at least this share of the light have shot
// (count_lit_as_emitters; at most 1 / kPoolsUnit of them).
constexpr double kPoolsUnit = 0.01;
constexpr double kPoolShare = 0.3;
constexpr double kPoolFloor = 0.05;
// Pieces carrying at least this share of the emitted power refine for receivers whose plane cuts
// through them, however far (is_close, piece_headroom).
constexpr double kStraddlePower = 0.05;
// A cluster of a curved surface shoots along its patches' mean normal, as if flat: its patches'
// normals stay within this cosine (20 degrees) of it, so a receiver's cosine at the cluster errs by
// under 6 % where it faces the cluster (build_clusters).
constexpr double kClusterCone = 0.9397;
// ... and its faces lie within this share of its width along that normal: a cluster of a
// double-sided ball's outer faces on one side and its inner faces on the other (the same normals)
// would shoot the inner faces' light out of the ball from in front of the outer ones.
constexpr double kClusterDepth = 0.5;
// A shooting piece whose absorbing backs close in front of it take at least this share of the
// light from its centre together is refined (absorber_close).
constexpr double kAbsorberShare = 0.1;
// ... also a front facing the piece within this cosine of head-on (absorber_close).
constexpr double kFacingOccluderCos = 0.7;
// A piece of a patch whose children's unshot radiosities depart from its mean by more than this,
// summed over them by area as a share of the mean, shoots from its children (uneven_piece).
constexpr double kUnevenShare = 0.5;
// Elements under AEPS split further, down to AEPS / kSharpAreaFactor (four more levels), only where
// the shot's radiosity jumps by more than kSharpJump radiosity tolerances: the outline of a lamp
// hung 1 mm under a ceiling, bright above the lamp and dark beside it, the edge of a contact shadow.
constexpr double kSharpAreaFactor = 256.0;
constexpr double kSharpJump = 10.0;
// ... and only where the light on one side is at least this many times the other's: an edge, not a
// steep but smooth falloff (a spot's cone), which graded elements would only make uneven.
constexpr double kSharpRatio = 4.0;
// A punctual light's shot splits elements under AEPS too (down to AEPS / kSharpAreaFactor) where
// an element's radius exceeds this share of its distance to the light: the light's pool on a
// surface near it is about as wide as that distance, however small the surface is in the scene.
constexpr double kLightPoolReach = 0.1;
// A punctual light's shadows are sharp: an element under AEPS that the light's view finds partly
// hidden splits, two levels further (down to AEPS / kShadowAreaFactor), where the light it would
// take unhidden exceeds kSharpJump tolerances, however small a share of it the shadow hides (a
// pillar's shadow across a platform's elements, which no corner's jump shows). Down to AEPS /
// kSharpAreaFactor, the atrium's sun took 20 % more elements and 12 % more time, for about a
// point of p90 on the study (11.6 against 12.7 %).
constexpr double kShadowAreaFactor = 16.0;
// The sun's parallel view has pixels as wide as the smallest elements a sharp outline still splits
// (min_sharp_split_area), at most this many a side (prepare_lights).
constexpr uint32_t kMaxSunResolution = 1024;
// A point or spot light's cube has pixels as wide, half the scene's diagonal from the light, as
// those elements (at most this many a side), if the light brings at least kFineLightShare of the
// emitted power (prepare_lights); weaker lights take the hemicube's resolution.
constexpr uint32_t kMaxPointResolution = 256;
constexpr double kFineLightShare = 0.01;
// With Params::sharp_shadows, pieces carrying the same share of the emitted power take the finer
// hemicube at any level (sharp_level, piece_headroom). Without it, such pieces take a finer level's
// hemicube, or the finer one, where an object they may see would be narrower than kObjectPixels
// pixels at their own level (sharp_resolution).
constexpr double kSharpPower = kFineLightShare;
constexpr double kObjectPixels = 2.0;
// Lengths under this share of the scene's diagonal are rounding. An eye that near a patch's plane
// sees it edge-on: project() leaves such patches out and projects backs beyond it, and
// absorber_close, which predicts which absorbing backs the hemicube will see, must draw the same
// line. Boxes that near meet (patches_meeting).
constexpr double kRoundingLength = 1e-9;
// How far in front of a shooting piece (a share of the scene's diagonal) its eye is tested against
// the closed meshes (enclosing): off the piece's own plane, far inside the thinnest mesh modelled.
constexpr double kEyeOffset = 1e-6;
// A receiver counts as close (is_close) only where the piece lies in front of it, and it in front
// of the piece, by more than this share of the scene's diagonal.
constexpr double kCloseFacingLength = 1e-6;
// A surface facing a point of another closer than the point's piece or element radius (at most this
// share of the scene's diagonal) covers it (gap_covered): the ceiling above a lamp hung 1 mm under
// it, 40 times brighter than the rest. Its light leaves only through the gap, at grazing angles: a
// gather would take it through the pixels along the lamp's outline instead (the anti-aliased
// hemicube takes a pixel's layers as independent), so such light reaches the mesh as the shots
// spread it (e_gap), and gathers see covered elements dark.
constexpr double kCoverGap = 0.01;
// A cover that emits nothing splits the elements along its outline this many levels under the
// smallest split (split_along_cover_outlines).
constexpr int kCoverOutlineLevels = 2;
// The elements around a point where a surface touches another at a corner alone split as far from
// it as half that surface is wide, at most this share of the scene's diagonal
// (find_point_contacts).
constexpr double kContactReach = 0.05;
// A surface standing on an element splits it (contact_crosses) where the stretch of its foot across
// the element is at least this share of the side of the smallest element an outline splits to: a
// chair's 3 cm leg does not split a cluttered room's floor.
constexpr double kContactShare = 0.5;
// A shot is repeated after splits (refine) at most this many times; one still splitting after them
// is not recorded for replays.
constexpr int kMaxRounds = 64;

// Whether boxes [alo, ahi] and [blo, bhi] meet, each widened by `slack`.
inline bool boxes_meet(const glm::dvec3& alo, const glm::dvec3& ahi, const glm::dvec3& blo, const glm::dvec3& bhi,
                       double slack) {
  for (int k = 0; k < 3; ++k)
    if (ahi[k] + slack < blo[k] || alo[k] - slack > bhi[k]) return false;
  return true;
}

// Lowers `room`, the factor by which a shot's dB may grow, to the factor at which `value` (which
// scales with dB) reaches `limit`.
inline void lower_headroom(double& room, double limit, double value) {
  if (value > 0.0) room = std::min(room, limit / value);
}

// A shooting piece as pools.cpp sees it: a polygon (a piece of one patch), or a cluster: the
// polygons of the elements `src` near it, a disc of its area further off.
struct ShooterShape {
  glm::dvec3 centre{0.0}, normal{0.0};
  double area = 0.0, diameter = 0.0;
  std::array<glm::dvec3, 4> poly{};
  uint32_t poly_n = 0;            // 0: a cluster
  std::span<const uint32_t> src;  // a cluster's elements (set where it shoots; not kept)
  // A volume cluster (no normal): its area by where it faces, along +x, -x, +y, -y, +z and -z (the
  // normals' parts), as shares that sum to 1.
  bool volume = false;
  std::array<double, 6> lobe{};
};

struct Solver::Impl {
  // What one hemicube shoots from: a piece of a patch, or a cluster of patches of one surface.
  struct Piece {
    uint32_t patch;                   // a patch of the piece: its plane and occlusion group
    glm::dvec3 normal;                // the hemicube's axis: the patch's normal, a cluster's mean
    glm::dvec3 centre, up;            // the hemicube's centre and rotation hint
    double area, diameter;
    glm::dvec3 dB;                    // unshot radiosity shot (uniform over the piece)
    double power;                     // unshot power shot: channel_sum(dB) * area
    std::vector<glm::dvec3> points;   // points whose hull holds the piece (facing tests)
    int depth;                        // hemicube level (each halves the resolution)
    double rear = 0.0;                // a cluster not flat: how far behind `centre` it reaches
    bool may_refine;                  // near receivers are left to sub-pieces
    double judge = 1.0;               // refine judges the shot as if this many times as strong
    // A volume cluster (cluster node `cluster`): a whole cube at `centre`, each pixel weighted by
    // the cluster's faces that look its way (volume_weights); `normal` only turns the cube.
    bool volume = false;
    uint32_t cluster = kNone;
    // Where dB comes from (for replays): the unshot power of the leaves under `src`, divided by
    // src_area.
    std::vector<uint32_t> src;
    double src_area;
  };
  // A piece of a patch on the way down its quadtree (shooters.cpp).
  struct ShooterNode {
    Corners c;
    uint32_t element;  // kNone: a geometric piece of a leaf
    glm::dvec3 unshot;
    int depth;
    uint32_t source;   // `element`, or for a geometric piece the leaf it was cut from
    bool top = false;  // a piece of the unit's own cut, not a near-field part (settles its far share)
    int extra = 0;     // cuts of a strong emitter below shooter_limit (shooters.cpp)
  };
  // A shot's form factors, kept for a replay (step): per piece, in the order they shot, its
  // sources and the receivers that took light with their F(element -> piece).
  struct ShotRecord {
    struct Piece {
      uint32_t src_begin, src_end, recv_begin, recv_end;
      uint32_t dark_begin, dark_end, dark_first;  // its bytes of `dark`, and its first unlit entry's index
      double src_area, area;
      glm::dvec3 dB;  // the unshot radiosity it shot when recorded
      double headroom;  // a replay may shoot up to this times dB (piece_headroom)
      ShooterShape shape;  // where its light comes from (pools.cpp)
    };
    size_t fresh_pieces = 0;  // pieces of the shot that made it (replays may add more)
    std::vector<Piece> pieces;
    // `recv`: the receivers the piece lit, with their form factors in `f`; `dark`: those it faced
    // and did not light (F = 0), which a replay needs only to know whether they were split since.
    // Most receivers of a whole-scene shot in a large scene are hidden (71 % of the atrium's), and
    // come in runs of near ids: `dark` holds each piece's as differences from the one before
    // (zigzag, 7 bits a byte; add_dark, for_dark), `dark_count` of them in all.
    std::vector<uint32_t> src, recv;
    std::vector<uint8_t> dark;
    size_t dark_count = 0;
    std::vector<float> f;
    // The leaves from which covered pieces were left unshot (shoot_node): a replay leaves them
    // too, unless one has been split since (a fresh shot would then cut it along its children).
    std::vector<uint32_t> covered;
    size_t bytes() const {
      if (pieces.capacity() + src.capacity() + recv.capacity() + dark.capacity() + f.capacity() + covered.capacity() == 0)
        return 0;  // none
      return sizeof(ShotRecord) + pieces.capacity() * sizeof(Piece) +
             (src.capacity() + recv.capacity() + covered.capacity()) * sizeof(uint32_t) + dark.capacity() +
             f.capacity() * sizeof(float);
    }
    void append(const ShotRecord& from, Piece piece, const uint8_t* skip);
    bool consistent() const;  // for HEMIBAKE_DCHECK: the pieces' ranges tile recv and dark, and lie in src
    size_t entries() const { return recv.size() + dark_count; }
    // Appends unlit receiver e to the piece being written, `last` the one before it (0 at first).
    void add_dark(uint32_t& last, uint32_t e) {
      const int64_t d = static_cast<int64_t>(e) - static_cast<int64_t>(last);
      uint64_t z = (static_cast<uint64_t>(d) << 1) ^ static_cast<uint64_t>(d >> 63);
      for (; z >= 0x80; z >>= 7) dark.push_back(static_cast<uint8_t>(z | 0x80));
      dark.push_back(static_cast<uint8_t>(z));
      last = e;
      ++dark_count;
    }
    // Calls fn(e, index) for each unlit receiver of piece p, in order; `index` counts all of the
    // record's unlit entries.
    template <typename Fn>
    void for_dark(const Piece& p, Fn&& fn) const {
      uint32_t last = 0;
      size_t index = p.dark_first;
      for (uint32_t at = p.dark_begin; at < p.dark_end; ++index) {
        uint64_t z = 0;
        for (int shift = 0;; shift += 7) {
          const uint8_t b = dark[at++];
          z |= static_cast<uint64_t>(b & 0x7f) << shift;
          if (!(b & 0x80)) break;
        }
        const int64_t d = static_cast<int64_t>(z >> 1) ^ -static_cast<int64_t>(z & 1);
        last = static_cast<uint32_t>(static_cast<int64_t>(last) + d);
        fn(last, index);
      }
    }
  };
  // A node of a cluster's binary tree over its patches (by median cuts of their centres).
  struct ClusterNode {
    uint32_t begin = 0, end = 0;  // its patches: cluster_patch[begin, end)
    uint32_t child = kNone;       // children at child and child + 1
    glm::dvec3 centre{0.0};       // area centroid
    glm::dvec3 normal{0.0};       // area-weighted mean of its patches' normals, unit
    double min_cos = 1.0;         // least cosine between a patch's normal and `normal`
    double area = 0.0, diameter = 0.0;
    std::array<glm::dvec3, 8> box{};  // corners of the bounding box of its patches' corners
    // How far in front of `centre`, along `normal`, its foremost patch corner lies (0 for a flat
    // cluster); the hemicube stands there (shoot_cluster).
    double front = 0.0;
    double depth = 0.0;  // from its rearmost patch corner to its foremost, along `normal`
    // Of a pool of faces of small objects across orientations: where its faces look several ways
    // (volume_shot), it shoots from a whole cube at its centre.
    bool volume = false;
  };
  // A node of the bounding-box tree over the patches (patch_bvh.cpp).
  struct BoxNode {
    glm::dvec3 lo, hi;
    uint32_t begin = 0, end = 0;  // its patches: tree_patch[begin, end)
    uint32_t child = kNone;       // children at child and child + 1
  };

  // lights.cpp: punctual lights and the sky shoot first, each once, from projections of their own
  // (a LightView: a hemicube at a point light, or a parallel projection along a direction).
  struct LightView;
  void prepare_lights();
  bool shoot_next_light();
  void light_views(const Light& light, std::vector<LightView>& views, bool fine = false);
  LightView parallel_view(const glm::dvec3& direction, uint32_t resolution) const;
  void project_light_view(LightView& view, std::span<const uint32_t> elements);
  void project_light_children(LightView& view, const std::vector<uint32_t>& parents);
  void light_factors(const Light* light, const std::vector<LightView>& views, std::span<const uint32_t> elements);
  double light_at(const Light& light, const glm::dvec3& x, const glm::dvec3& n) const;
  void shoot_light(size_t index);  // lights[index]
  std::vector<glm::dvec3> sky_factors(uint32_t directions_step, std::span<const uint32_t> elements);
  uint32_t add_sky_directions(uint32_t step, uint32_t skip, uint32_t first, std::span<const uint32_t> elements,
                              std::vector<glm::dvec3>& sums, double seconds,
                              std::span<const uint32_t> leaves_in_order = {});
  void sky_seen(const LightView& view, std::span<const uint32_t> fresh, std::span<const uint32_t> leaves_in_order,
                std::vector<uint32_t>& seen);
  void finish_sky_factors(uint32_t step, std::span<const uint32_t> elements, std::vector<glm::dvec3>& sums) const;
  bool shoot_sky_part();
  void light_receive(uint32_t e, const glm::dvec3& irradiance);

  // solver.cpp: set-up, and the Southwell step that picks the shooter.
  // `first`: a first pass over the same scene whose light pools this pass's elements start split
  // for (find_pools); such a pass looks for no pools.
  // `solve`: this is the first pass, a draft (p) of that solve, which looks for light pools.
  Impl(const Scene& scene, const Params& p, const Impl* first = nullptr, const Params* solve = nullptr);
  // The second pass of a solve whose first found light pools (pools.cpp): a new solve of the same
  // scene on the first's elements, with the first's counts of work added to its statistics.
  static std::unique_ptr<Impl> next_pass(Impl& first);
  bool step();
  uint32_t strongest_unit() const;
  uint32_t lagging_unit() const;
  // Element e's light: radiosity (channels summed) times area.
  double light_of(uint32_t e) const { return channel_sum(e_b[e]) * e_area[e]; }
  double interaction_scale(const std::vector<uint32_t>& accepted, const std::vector<uint32_t>& near, uint32_t unit,
                           double piece_power) const;
  void fresh_shot(uint32_t unit);
  void clear_unshot(uint32_t unit);
  void receive(uint32_t e, const glm::dvec3& dB, double f);
  // receive() in two parts: what is element e's own (its radiosity, its grid points), which
  // threads may do for different elements at once, and the sums over its patch and unit.
  glm::dvec3 gain_of(uint32_t e, const glm::dvec3& dB, double f) const {
    return patches[e_patch[e]].reflectance * dB * f;
  }
  void take_light(uint32_t e, const glm::dvec3& dB, const glm::dvec3& gain);
  void count_light(uint32_t e, const glm::dvec3& gain);
  // receive() for n distinct leaves at once: leaf(i) takes form factor f(i) (nothing where it is
  // not above 0); with `deliver`, the shot's delivered power counts it. Each leaf's own light is
  // handed out on the pool's threads, the sums over patches and units follow in the leaves'
  // order, as n calls of receive() would make them.
  template <typename Leaf, typename FormFactor>
  void receive_each(size_t n, const glm::dvec3& dB, Leaf&& leaf, FormFactor&& f, bool deliver);
  // The least of `start` and what lower(i, room) leaves in `room` for i in [0, n), on the pool's
  // threads (each thread's share first; a minimum does not depend on the order).
  template <typename Lower>
  double least_over(size_t n, double start, Lower&& lower);

  // element_tree.cpp: the elements' quadtree.
  uint32_t corner_count(uint32_t e) const { return patches[e_patch[e]].corner_count; }
  void corners_of(uint32_t e, Corners& out) const {
    for (uint32_t i = 0; i < corner_count(e); ++i) out[i] = vpos[e_corner[e][i]];
  }
  Corners corners_of_copy(uint32_t e) const {
    Corners c{};
    corners_of(e, c);
    return c;
  }
  // The bounding box of element e's corners.
  void element_box(uint32_t e, glm::dvec3& lo, glm::dvec3& hi) const {
    const Corners c = corners_of_copy(e);
    lo = hi = c[0];
    for (uint32_t k = 1; k < corner_count(e); ++k) {
      lo = glm::min(lo, c[k]);
      hi = glm::max(hi, c[k]);
    }
  }
  uint32_t midpoint(uint32_t a, uint32_t b);
  uint32_t add_element(uint32_t patch, uint32_t parent, const std::array<uint32_t, 4>& corners,
                       const glm::dvec3& b, const glm::dvec3& unshot);
  void split(uint32_t e);
  template <typename Fn>
  void for_leaves(uint32_t e, Fn&& fn) const;
  // Calls found(q) for the patches of the patch tree's leaves whose boxes pass near(lo, hi), until
  // found returns true; returns whether it did.
  template <typename Near, typename Found>
  bool find_patch(Near&& near, Found&& found) const;
  void replace_split(std::vector<uint32_t>& list) const;
  void grow_scratch();
  void update_unshot_total();

  // patch_bvh.cpp, clusters.cpp: built once.
  void build_patch_bvh();
  void find_standing();
  uint32_t under_foot(uint32_t e) const;
  uint32_t cover_at_centre(uint32_t e) const;
  void mark_covered();
  void build_patch_tree(uint32_t node, uint32_t begin, uint32_t end);
  void patches_meeting(const detail::Shaft& shaft, std::vector<uint32_t>& out);
  void build_clusters();
  void find_surfaces();
  std::vector<std::vector<uint32_t>> cluster_candidates(double limit) const;
  void cut_into_units(const std::vector<uint32_t>& members, double limit);
  void cut_into_volume_units(const std::vector<uint32_t>& members, double limit, std::vector<uint32_t>& left);
  void build_cluster(uint32_t id, uint32_t begin, uint32_t end, double limit);
  uint32_t gap_cut(uint32_t begin, uint32_t end, const glm::dvec3& lo, const glm::dvec3& hi);
  std::vector<uint32_t> objects() const;
  bool inner_side(uint32_t q, const glm::dvec4& object_centre) const;
  static bool cluster_unfit(const ClusterNode& node, double limit);
  static bool volume_shot(const ClusterNode& node) {
    return node.volume && (node.min_cos < kClusterCone || node.depth > kClusterDepth * node.diameter);
  }
  bool foreign_inside(const ClusterNode& node, std::vector<uint32_t>& member_stamp, uint32_t stamp_value) const;

  // shooters.cpp: a unit breaks into pieces, each of which shoot_piece shoots.
  void shoot_patch(uint32_t p, const std::vector<uint32_t>& receivers, bool whole_scene);
  void shoot_node(uint32_t p, const ShooterNode& node, const std::vector<uint32_t>& receivers, bool whole_scene);
  void shoot_tops(uint32_t p, const std::vector<ShooterNode>& tops, const std::vector<uint32_t>& receivers,
                  bool whole_scene);
  void shoot_cluster(uint32_t c, const std::vector<uint32_t>& receivers, bool whole_scene, int depth);
  void shoot_parts(uint32_t c, const std::vector<uint32_t>& near, int depth);

  // shoot_piece.cpp: one hemicube, stage by stage.
  std::vector<uint32_t> shoot_piece(const Piece& piece, const std::vector<uint32_t>& receivers, bool whole_scene);
  void mark_shooting_patches(const Piece& piece);
  std::vector<uint32_t> current_leaves(const std::vector<uint32_t>& receivers) const;
  void classify_receivers(const Piece& piece, const std::vector<uint32_t>& current,
                          std::vector<uint32_t>& accepted, std::vector<uint32_t>& near);
  bool sharp_level(const Piece& piece, double power) const;
  void measure_objects();
  uint32_t sharp_resolution(const Piece& piece, const std::vector<uint32_t>& seen);
  void place_hemicube(const Piece& piece, const std::vector<uint32_t>& seen);
  struct VolumeCube;
  void volume_weights(const Piece& piece, const VolumeCube& v);
  void receiver_form_factors(const Piece& piece, const std::vector<uint32_t>& accepted);
  void distribute(const glm::dvec3& dB, const std::vector<uint32_t>& accepted);
  // A shot's top piece gives its far receivers what its parts did not give its near ones
  // (settle_far): deferred until they have shot.
  struct FarShare {
    std::vector<uint32_t> recv, src;
    std::vector<double> f;
    glm::dvec3 dB{0.0};
    ShooterShape shape;
    double gap = 0.0, power = 0.0;  // gap_share; the power the receivers take at f
    double seen = 0.0;  // the share of the cube that front faces take (the rest: the sky, backs)
    size_t record_piece = static_cast<size_t>(-1);  // its piece in the shot's record
  };
  void finish_far(FarShare& far, double scale);
  double settle_far(FarShare& far, double power, double given, bool whole_scene, bool parts, double kept);
  double hemicube_share(const std::vector<uint32_t>& accepted) const;
  bool defer_far = false;                // shoot_piece keeps the piece's far light in far_pending
  std::unique_ptr<FarShare> far_pending;
  double delivered = 0.0;                // power given out by shots so far (channels summed)
  std::vector<double> u_far_scale;       // per unit: its last whole-scene shot's far scale
  double far_scaled_power = 0.0, far_scale_sum = 0.0;  // shoot_tops: its tops' scales, by power
  // Whether element e has form factors from the hemicube in use.
  bool projected(uint32_t e) const { return e_stamp[e] == stamp && e_ff_open[e] > 0.0; }
  // F(element -> piece) from F(piece -> element) = ff, by reciprocity (capped at 1).
  double by_reciprocity(const Piece& piece, uint32_t e, double ff) const {
    return std::min(1.0, ff * piece.area / e_area[e]);
  }
  // The radiosity element e gains from a shot of dB with F(element -> piece) = f (channels' mean).
  double shot_radiosity(uint32_t e, const glm::dvec3& dB, double f) const {
    return mean(patches[e_patch[e]].reflectance * dB) * f;
  }

  // near_field.cpp: receivers close to the piece.
  bool is_close(const Piece& piece, uint32_t e) const;
  double near_error(const Piece& piece, uint32_t e) const;
  bool absorber_close(const Piece& piece) const;
  bool uneven_piece(uint32_t element) const;
  void front_shares(const Piece& piece, std::vector<std::pair<uint32_t, double>>& shares);
  // A node of an uneven piece's element tree (uneven_tree).
  struct ShotNode {
    glm::dvec3 centre;
    double area, radius2;
    double share;          // its leaves' mean unshot radiosity over the piece's
    uint32_t first_child;  // kNone: a leaf
  };
  std::vector<ShotNode> uneven_tree(const Piece& piece) const;
  double uneven_share(const Piece& piece, std::span<const ShotNode> nodes, uint32_t e, double fallback) const;
  // Which surfaces may cover a point (covered): any, or only those that emit nothing.
  enum class Cover : uint8_t { kAny, kNonEmitters };
  bool covered(uint32_t p, const glm::dvec3& x, double gap = 0.0, bool any_facing = false,
               Cover by = Cover::kAny) const;
  uint32_t cover_at(uint32_t p, const glm::dvec3& x, double gap, bool any_facing, Cover by) const;
  void split_along_cover_outlines();
  bool contact_crosses(uint32_t e) const;
  void find_point_contacts();
  bool point_contact_near(uint32_t e) const;
  double contact_length(uint32_t e, uint32_t q, double inset) const;

  // pools.cpp: where the light an element took varies across it. Each patch large enough to split
  // holds a grid of points; every shot adds to the points of its receivers the light it gave them,
  // spread as the shooter's unoccluded light varies across each one. Once the shots are done,
  // leaves whose points differ by more than the radiosity tolerance split, their light shared out
  // as the points say.
  void build_light_grids();
  void count_lit_as_emitters();
  ShooterShape shape_of(const Piece& piece) const;
  double shooter_light(const ShooterShape& s, const glm::dvec3& x, const glm::dvec3& n) const;
  void take_on_grid(uint32_t e, double radiosity);
  template <typename Fn>
  void for_grid_points(uint32_t e, Fn&& fn) const;
  bool find_pools();
  bool near_emitter(uint32_t e) const;
  bool gap_covered(uint32_t p, const glm::dvec3& x, double radius) const;
  // mesh_export.cpp: covered vertices show the light of their uncovered neighbours; the covered
  // elements around a vertex that does so keep their own light there (CoveredSide).
  struct CoveredSide {
    std::vector<char> leaf;  // per element of the mesh: covered
    std::unordered_map<uint32_t, glm::dvec3> light;  // vertex -> the covered elements' mean light
  };
  CoveredSide show_uncovered_light(const std::vector<uint32_t>& leaves, Mesh& m) const;
  std::vector<char> outline_vertices(const Mesh& m) const;
  void extrapolate_to_outline(const std::vector<uint32_t>& leaves, const std::vector<char>& fixed, Mesh& m) const;
  std::vector<std::array<uint32_t, 2>> standing_on(const std::vector<uint32_t>& leaves) const;
  bool leaf_covered(uint32_t e);
  bool partly_open(uint32_t e) const;
  bool buried(uint32_t e) const;
  bool corner_covered_unlike(uint32_t e, double reach, Cover by, bool centre, bool any_facing = true) const;
  double covered_share(std::span<const uint32_t> sources);
  static double point_piece_form_factor(const Piece& piece, const glm::dvec3& x, const glm::dvec3& n);
  double element_piece_form_factor(const Piece& piece, uint32_t e, int side) const;
  double exact_form_factor(const Piece& piece, uint32_t e, int side);

  // shaft.cpp: what the hemicube must see.
  detail::Shaft shaft_of(const Piece& piece, const std::vector<uint32_t>& accepted, bool whole_scene) const;
  void gather_seen(const detail::Shaft& shaft, const std::vector<uint32_t>& accepted, std::vector<uint32_t>& seen);

  // projection.cpp: onto the placed hemicube. Projects `elements`, but for the patches of the
  // shooting piece (p_shooting == shooting_stamp); with `receivers`, only within their pixels.
  void project(std::span<const uint32_t> elements, std::span<const uint32_t> receivers = {});
  bool project_receivers(std::span<const uint32_t> receivers, detail::FaceWindows& windows);
  struct RecvAt {
    uint32_t chunk, begin, end;
    bool own;  // the fragments are the receiver's own (not its back, as an occluder)
  };
  std::vector<std::vector<Fragment>> recv_frags;  // project_receivers: per chunk
  std::vector<RecvAt> recv_at;                    // ... per receiver: where its fragments are
  std::vector<uint32_t> e_recv_slot;              // ... per element: its receiver's index + 1, or 0
  bool project_element(uint32_t el, const glm::dvec3& eye, Corners& poly, detail::ProjectScratch& s,
                       std::vector<Fragment>& out, const detail::FaceWindows* windows) const;
  bool culled(uint32_t p, double facing) const;
  // The closed double-sided meshes a point lies in (PreparedScene::inner_solid), sorted; and
  // whether patch p faces the inside of one that the eye (in those of `open`) lies outside of.
  std::vector<uint32_t> enclosing(const glm::dvec3& x) const;
  bool sealed(uint32_t p, std::span<const uint32_t> open) const;
  bool project_side(detail::Hemicube& into, uint32_t el, uint32_t id, Corners& poly, double facing, bool plane,
                    detail::ProjectScratch& s, std::vector<Fragment>& out,
                    const detail::FaceWindows* windows = nullptr) const;
  void join_chunks(std::span<const uint32_t> elements, std::vector<uint32_t>& begin, std::vector<uint32_t>& end,
                   std::vector<Fragment>& all);
  void project_children(const std::vector<uint32_t>& parents);
  void sum_form_factors(std::span<const uint32_t> elements);

  // refine.cpp: a posteriori subdivision.
  bool refine(const Piece& piece, const detail::Shaft& shaft, std::vector<uint32_t>& accepted,
              std::vector<uint32_t>& seen, double& split_room);
  void spread_shot(const glm::dvec3& dB, const std::vector<uint32_t>& accepted);
  void reset_spread(const std::vector<uint32_t>& accepted);
  std::vector<uint32_t> too_coarse(const glm::dvec3& dB, double weight, const std::vector<uint32_t>& accepted);
  double split_headroom(const glm::dvec3& dB, double weight, const std::vector<uint32_t>& accepted);
  bool covered_emitter(uint32_t e);
  bool in_light_pool(uint32_t e) const;
  const Light* shooting_light = nullptr;  // shoot_light's light while it refines
  bool emits(uint32_t e) const { return channel_sum(patches[e_patch[e]].emission) > 0.0; }
  bool trim_to_element_limit(std::vector<uint32_t>& to_split);
  void split_receivers(const std::vector<uint32_t>& to_split, const detail::Shaft& shaft,
                       std::vector<uint32_t>& accepted, std::vector<uint32_t>& seen);
  // A split makes four children, none smaller than aeps_area.
  double min_split_area() const { return 4.0 * aeps_area; }
  // The classical hemicube's point samples make every small element's light jump (aliasing), so
  // only the anti-aliased one refines edges under AEPS.
  double min_sharp_split_area() const {
    return params.method == Method::kAntiAliased ? min_split_area() / kSharpAreaFactor : min_split_area();
  }

  // gather.cpp: the final gather at the mesh's vertices, once the shots are done.
  struct GatherPoint;
  struct GatherWorker;
  bool gather_step();
  void start_gather();
  void gather_round();
  void gather_points(std::vector<GatherPoint>& points);
  glm::dvec3 gather_at(const GatherPoint& point, GatherWorker& w, uint32_t& cost) const;

  // shot_cache.cpp: records and replays.
  bool replay(uint32_t unit);
  size_t mark_stale(const ShotRecord& r, std::vector<uint8_t>& stale);
  bool replayed_radiosities(const ShotRecord& r, std::vector<glm::dvec3>& dBs);
  ShotRecord reshoot_split(uint32_t unit, const ShotRecord& r);
  void keep_record(uint32_t unit, ShotRecord record);
  void record_piece(const Piece& piece, double split_room, const std::vector<uint32_t>& accepted);
  double piece_headroom(const Piece& piece, double split_room, const std::vector<uint32_t>& accepted);

  Params params;
  std::vector<Patch> patches;
  detail::PreparedScene prep;
  double aeps_area = 0.0;       // smallest element area allowed
  double b_tolerance = 0.0;     // radiosity tolerance for criteria (b) and (c)
  double gather_tolerance = 0.0;  // ... for the final gather's splits
  double shooter_limit = 0.0;   // widest shooting sub-area
  double emitted_power = 0.0;   // sum over patches of channel_sum(E) * A

  // Vertices (shared within a smoothing group) and edge midpoints.
  std::vector<glm::dvec3> vpos;
  std::unordered_map<uint64_t, uint32_t> midpoints;

  // Elements, structure of arrays. Children of an element are consecutive.
  std::vector<uint32_t> e_patch, e_parent, e_child;
  std::vector<uint32_t> e_group;  // the patch's occlusion group, and kCoveredBit (set_covered)
  // Per patch: the feet of the surfaces standing on it (find_standing); empty if there are none.
  struct Foot {
    glm::dvec3 a, b;  // an edge of `top` in the patch's plane
    uint32_t top;
  };
  std::vector<std::vector<Foot>> p_feet;
  // Per element: the one-sided surface standing on it that it lies under (the surface's foot meets
  // it and its centre lies behind the surface: the floor inside a box without a bottom), or kNone.
  std::vector<uint32_t> e_under;
  // Per element: whether a surface lies on it or just in front of it over its centre (gap_covered: a
  // box's bottom on a floor, a wall box's end against another wall's face, a lamp hung 1 mm under a
  // ceiling, a rug over a floor), and whether any does. Where something nearer shares a pixel with
  // them, hemicubes give their share of it to their surface's uncovered elements (resolve).
  // The flag is kept in e_group, as resolve() reads it. e_cover: the surface that covers it as
  // hemicubes on its side see it (detail::resolve's cover_of), or kNone.
  static constexpr uint32_t kCoveredBit = 1u << 30;
  bool any_covered = false;
  std::vector<uint32_t> e_cover;
  void set_covered(uint32_t e, uint32_t cover_patch) {
    const bool is_covered = cover_patch != kNone;
    e_group[e] = is_covered ? e_group[e] | kCoveredBit : e_group[e] & ~kCoveredBit;
    e_cover[e] = is_covered ? seen_cover(e_patch[e], cover_patch) : kNone;
    any_covered = any_covered || is_covered;
  }
  uint32_t seen_cover(uint32_t p, uint32_t cover_patch) const;
  uint32_t covered_bit() const { return any_covered ? kCoveredBit : 0u; }
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
  bool building_volume = false;  // build_cluster: a volume pool's tree (cut on centres only)
  std::vector<uint32_t> unit_patch, unit_node, p_unit;
  std::vector<double> u_unshot;  // unshot power per unit
  // The power FEPS weighs the current shot's interactions against (interaction_scale), and per
  // unit its last whole-scene shot's (0: none yet).
  double feps_scale = 0.0;
  std::vector<double> u_feps_scale;
  // Replays: per unit, the form factors of its last shot (replay()).
  std::vector<ShotRecord> u_record;
  size_t record_bytes = 0;
  // The unit shooting (step): its patches' own gains are held until it has shot (receive).
  uint32_t shooting_unit = kNone;
  std::vector<std::pair<uint32_t, glm::dvec3>> held;
  ShotRecord* recording = nullptr;  // the shot being recorded
  bool record_broken = false;       // a piece of it was skipped (no power): not replayable

  // Bounding-box tree over the patches (patch_bvh.cpp), for finding what lies near a hemicube.
  std::vector<BoxNode> tree;
  std::vector<uint32_t> tree_patch;
  std::vector<glm::dvec3> p_lo, p_hi;  // per patch: bounding box
  std::vector<uint64_t> p_mark;        // per patch: listed for hemicube `mark`
  std::vector<uint32_t> p_surface;     // per patch: its surface for clustering (build_clusters)
  std::vector<uint64_t> p_shooting;    // per patch: part of the piece shooting hemicube `shooting_stamp`
  std::vector<uint32_t> eye_within;    // the closed meshes the placed hemicube's eye lies in (enclosing)
  // Per patch: the size (the median of its box's three extents) and the centre of the object it
  // belongs to, an outward-facing solid or a closed double-sided mesh; size 0 for none (a wall of
  // tiles, an open sheet). sharp_resolution finds the objects a hemicube would show too small.
  std::vector<double> p_object_size;
  std::vector<glm::dvec3> p_object_centre;
  // Whether the placed hemicube's objects asked for more than its level's resolution, whatever the
  // piece's power (piece_headroom: a stronger replay would place a finer one).
  bool objects_want_finer = false;
  uint64_t shooting_stamp = 0;

  // Per-hemicube scratch.
  // Hemicubes of halving resolution (at least kMinResolution): a quarter-size shooting area serves
  // receivers half as far, which project as large, so its hemicube needs half the resolution; small
  // objects do not shrink with it (sharp_resolution).
  std::vector<detail::Hemicube> cubes;
  std::unique_ptr<detail::Hemicube> finer_cube;  // for strong pieces that small objects ask it of
  // Whole cubes for volume clusters, per level as `cubes` (made when first needed), with each
  // pixel's unit direction and solid angle, and the weights of the one in use.
  struct VolumeCube {
    std::unique_ptr<detail::Hemicube> cube;
    std::vector<glm::dvec3> dir;
    std::vector<double> omega;
  };
  std::vector<VolumeCube> volume_cubes;
  std::vector<double> volume_weight;
  detail::Hemicube* cube = nullptr;  // the one in use
  const std::vector<double>* pixel_weight = nullptr;  // its pixels' delta form factors, or volume_weight
  detail::ThreadPool pool;
  std::vector<Fragment> frags;
  std::vector<uint32_t> f_begin, f_end;  // per element: its fragments in `frags`
  std::vector<uint64_t> e_stamp;         // per element: the hemicube its form factor belongs to
  std::vector<double> e_ff, e_ff_open;   // per element: visible and unoccluded form factor
  // Per patch: the points where another surface touches it at a corner alone (find_point_contacts),
  // and all of them, each patch's in a run.
  std::vector<uint32_t> p_contact_begin;
  std::vector<glm::dvec4> contact_points;  // the point, and the split's reach from it
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

  // Lights and the sky (lights.cpp): turn k < lights.size() shoots light k, the next the sky.
  std::vector<Light> lights;
  glm::dvec3 sky{0.0};
  uint32_t light_turn = 0;
  // The sky's shot under way (shoot_sky_part): its refinement round, whether this is the pass that
  // distributes the light, the next direction, its receivers and the sums so far.
  struct SkyShot {
    bool started = false, final_pass = false;
    int round = 0;
    uint32_t next = 0;
    std::vector<uint32_t> accepted;
    std::vector<glm::dvec3> sums;
    // A round after splits: the children just made (the rest keep their sums from the round
    // before; shoot_sky_part). Empty: every receiver is projected.
    std::vector<uint32_t> fresh;
    bool reuse = false;  // the final pass starts from the last round's directions (it split nothing)
  };
  SkyShot sky_shot;
  std::unique_ptr<detail::Hemicube> light_cube;  // at params.resolution, for lights' views
  std::unique_ptr<detail::Hemicube> fine_light_cube;  // for strong point and spot lights (or none)
  std::vector<double> light_power;  // per light: the power it brings (prepare_lights' estimate)
  std::unique_ptr<detail::Hemicube> sun_cube;    // finer, for directional lights (prepare_lights)
  std::unique_ptr<detail::Hemicube> sky_cube;    // coarser, for the sky's many directions

  // The final gather (gather.cpp), in rounds: each gathers at the corners of the elements in
  // gather_queue, then at the points their splits would make, then splits those where the light is
  // not linear; their children make the next round. Per element: the radiosity punctual lights
  // gave it directly (e_light, which a hemicube cannot see) and the mean radiosity of its leaves
  // (e_mean). Per vertex: its normal, the way into its surface where it lies on the outline
  // (v_inward), and the irradiance gathered there (v_irr, in radiosity units: sum of F B), valid
  // where v_gathered.
  std::vector<glm::dvec3> e_light, e_mean;
  // Per element: the radiosity that covered elements' unshot power gave it (gap_covered: the
  // ceiling above a lamp hung just under it), light that leaves through the gap, where no gather
  // sees it; like e_light, the mesh shows it as the elements' mean. e_cov caches gap_covered per
  // element (-1: not known yet); gap_share is the covered part of the shot under way.
  std::vector<glm::dvec3> e_gap;
  std::vector<int8_t> e_cov;
  double gap_share = 0.0;
  std::vector<uint8_t> e_hidden;  // per element: all its leaves covered (leaf_covered), for the gather
  std::vector<uint8_t> e_settled;  // per element: the gather checked it for a split (or it cannot split)
  std::vector<double> e_low, e_high;  // per element: the least and greatest mean(B) of its leaves
  std::vector<glm::dvec3> v_normal, v_inward, v_irr;
  std::vector<uint8_t> v_gathered;
  std::vector<uint32_t> gather_queue;
  std::vector<GatherPoint> gather_pending;  // points of this round's phase still to gather
  size_t gather_next = 0;                   // ... from here on
  int gather_phase = 0;                     // 0: corners, 1: the splits' points
  bool gather_started = false, gather_done = false;
  uint64_t gather_budget = 0, gather_spent = 0;  // nodes the gather may project, and has
  std::vector<std::unique_ptr<GatherWorker>> gather_workers;  // per chunk of the pool

  Stats stats;
  bool done = false;
  // pools.cpp: the shooter whose light receive() is giving out (null: none to follow), a count of
  // the shooters, per patch its grid's points a side (0: none) and first point, per point the
  // light taken and the shooter that last gave it, per element its corners in its patch's (u, v).
  const ShooterShape* shooter_shape = nullptr;
  // Emitting patches that have not shot yet (the first pass looks for pools once all have).
  std::vector<uint8_t> p_emitter_left;
  uint32_t emitters_left = 0;
  uint32_t grid_shooter = 0;
  std::vector<uint32_t> p_grid_n, p_grid_begin;
  std::vector<float> grid_light;
  std::vector<uint32_t> grid_stamp;
  std::vector<std::array<glm::dvec2, 4>> e_uv;
  bool pools_looked = false;  // find_pools ran (or this pass does not look)
  bool first_pass = false;    // a draft that looks for pools; `solve` is the solve proper
  Params solve;
  double pool_tolerance = 0.0;  // the solve proper's radiosity tolerance
  bool restart = false;       // find_pools split: the solve starts again on the new elements
  // The scene (for a second pass), and every split in order (element ids follow from it).
  Scene source;
  std::vector<uint32_t> split_log;
  std::vector<uint32_t> pool_splits;  // the elements find_pools split
};

// A point the final gather gathers at, and what it is for.
struct Solver::Impl::GatherPoint {
  enum class Kind : uint8_t { kVertex, kMidpoint, kCentre };
  Kind kind;
  uint32_t id;             // the vertex; the element whose edge (k) or centre it is
  uint32_t edge;           // kMidpoint: which edge of the element
  glm::dvec3 x, n, inward;  // gathers at x + inward (a point on a surface's outline: inside it)
  glm::dvec3 irr{0.0};     // the result
  uint32_t cost = 0;       // nodes projected for it
};

// One thread's hemicube and scratch for the final gather.
struct Solver::Impl::GatherWorker {
  explicit GatherWorker(uint32_t resolution) : cube(resolution), inline_pool(1) {
    cube.set_depth_at_pixel_centre(true);
  }
  detail::Hemicube cube;
  detail::ThreadPool inline_pool;
  detail::ProjectScratch scratch;
  std::vector<Fragment> frags;
  std::vector<uint32_t> list, stack, group_of, cover_of, order, pixel_start;
  std::vector<uint8_t> inside;  // per solid: its box holds the point
  std::vector<double> seen, open;  // per listed node: visible and unoccluded share of the view
};

template <typename Near, typename Found>
bool Solver::Impl::find_patch(Near&& near, Found&& found) const {
  std::vector<uint32_t> nodes{0};
  while (!nodes.empty()) {
    const BoxNode& node = tree[nodes.back()];
    nodes.pop_back();
    if (!near(node.lo, node.hi)) continue;
    if (node.child != kNone) {
      nodes.push_back(node.child);
      nodes.push_back(node.child + 1);
      continue;
    }
    for (uint32_t i = node.begin; i < node.end; ++i)
      if (found(tree_patch[i])) return true;
  }
  return false;
}

template <typename Lower>
double Solver::Impl::least_over(size_t n, double start, Lower&& lower) {
  std::vector<double> rooms(pool.chunk_count(n), start);
  pool.parallel_for(n, [&](size_t begin, size_t end, size_t c) {
    for (size_t i = begin; i < end; ++i) lower(i, rooms[c]);
  });
  for (double room : rooms) start = std::min(start, room);
  return start;
}

template <typename Leaf, typename FormFactor>
void Solver::Impl::receive_each(size_t n, const glm::dvec3& dB, Leaf&& leaf, FormFactor&& f, bool deliver) {
  HEMIBAKE_DCHECK(dB.x >= 0.0 && dB.y >= 0.0 && dB.z >= 0.0);
  pool.parallel_for(n, [&](size_t begin, size_t end, size_t) {
    for (size_t i = begin; i < end; ++i) {
      const double fi = f(i);
      if (!(fi > 0.0)) continue;
      const uint32_t e = leaf(i);
      HEMIBAKE_DCHECK(e < e_child.size() && e_child[e] == kNone && fi <= 1.0);
      take_light(e, dB, gain_of(e, dB, fi));
    }
  });
  for (size_t i = 0; i < n; ++i) {
    const double fi = f(i);
    if (!(fi > 0.0)) continue;
    const uint32_t e = leaf(i);
    count_light(e, gain_of(e, dB, fi));
    if (deliver) delivered += fi * e_area[e] * channel_sum(dB);
  }
}

template <typename Fn>
void Solver::Impl::for_leaves(uint32_t e, Fn&& fn) const {
  HEMIBAKE_DCHECK(e < e_child.size());
  if (e_child[e] == kNone) {
    fn(e);
    return;
  }
  for (uint32_t k = 0; k < 4; ++k) for_leaves(e_child[e] + k, fn);
}

}  // namespace hemibake::solver
