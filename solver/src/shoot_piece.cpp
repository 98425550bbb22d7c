// One hemicube: a shooting piece's shot, in stages. It classifies the receivers (near ones go on
// to the piece's sub-pieces), gathers what may hide the rest (shaft.cpp), places a hemicube of the
// resolution the piece's power asks for, refines the receivers a posteriori (refine.cpp), records
// the form factors for a replay (shot_cache.cpp) and distributes the piece's unshot radiosity.
#include "solver_impl.h"

#include <glm/geometric.hpp>
#include <glm/vec4.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>

namespace hemibake::solver {
namespace {

// A finer hemicube (sharp_level, sharp_resolution) has at most this resolution: pixels cost memory
// and time.
constexpr uint32_t kMaxFinerResolution = 400;
// A volume cluster's whole cube has at most this resolution per face (six faces, and per pixel a
// direction, a solid angle and a weight: 20 MB at 256): a cluster of small objects is a weak,
// distant shooter for most receivers, and at resolution 2048 its cubes would take 2 GB.
constexpr uint32_t kMaxVolumeResolution = 256;

}  // namespace

// Returns the receivers this piece's sub-pieces must serve instead (near-field): the caller's
// recursion shoots them from the quarters.
std::vector<uint32_t> Solver::Impl::shoot_piece(const Piece& piece, const std::vector<uint32_t>& receivers, bool whole_scene) {
  mark_shooting_patches(piece);
  std::vector<uint32_t> accepted, near;
  classify_receivers(piece, current_leaves(receivers), accepted, near);
  if (accepted.empty()) return near;
  // A large absorbing back face close in front of the piece (a light panel's back, hung 1 cm under
  // a ceiling piece) fills most of the hemicube at the piece's centre, while the piece's other
  // points see past it: the centre's view would sink their light into it. Everything goes to the
  // sub-pieces, whose own centres decide (on the furnished room, whose ceiling panels are such
  // backs: energy 0.984 to 0.995 of the path tracer's, RMS error 4.3 % to 3.8 %). So does a large
  // face turned to the piece close in front of it, with an opening: a double-sided wall 30 cm
  // from a sky plane, its window straight before the plane's centre, let 16 % too much light into
  // the room (a Blender export; the same room with one-sided walls has the backs above). Only for
  // pieces of at least FEPS of the emitted power, as for a patch's near receivers: a weak cluster
  // of a 159k-facet sphere resting on a floor tile, which faces it, went down to single facets,
  // each projecting the whole scene (3328 hemicubes, 124 s for one shot of 1e-4 of the power).
  if (piece.may_refine && piece.power >= params.feps * emitted_power && absorber_close(piece)) {
    near.insert(near.end(), accepted.begin(), accepted.end());
    return near;
  }

  const detail::Shaft shaft = shaft_of(piece, accepted, whole_scene);
  std::vector<uint32_t> seen;
  gather_seen(shaft, accepted, seen);
  place_hemicube(piece, seen);
  // The closed meshes the eye lies in: a volume cluster's centre, or a hair in front of the piece
  // (a piece of a mesh's inside lies on the mesh's outline, where the test could go either way).
  eye_within = enclosing(piece.volume ? piece.centre : piece.centre + piece.normal * (kEyeOffset * prep.diagonal));
  // A shot to some receivers needs only their pixels (project): a near-field piece's, a replay's.
  project(seen, whole_scene ? std::span<const uint32_t>() : std::span<const uint32_t>(accepted));
  sum_form_factors(accepted);  // the occluders' own form factors are not needed
  double seen_share = 0.0;  // of a deferred piece's light: what meets a front face (whole-scene shots)
  if (defer_far && whole_scene)
    for (const Fragment& f : frags)
      if (!(f.element & detail::kBackFace)) seen_share += static_cast<double>(f.area) * f.trans * (*pixel_weight)[f.pixel];

  const uint32_t unit = p_unit[piece.patch];
  if (u_feps_scale.size() < u_unshot.size()) u_feps_scale.resize(u_unshot.size(), 0.0);
  if (whole_scene) {
    feps_scale = interaction_scale(accepted, near, unit, piece.power);
    u_feps_scale[unit] = feps_scale;
  } else if (piece.depth == 0 || !(feps_scale > 0.0)) {
    feps_scale = u_feps_scale[unit] > 0.0 ? u_feps_scale[unit] : emitted_power;
  }
  double split_room = std::numeric_limits<double>::infinity();
  const bool settled = refine(piece, shaft, accepted, seen, split_room);
  receiver_form_factors(piece, accepted);
  HEMIBAKE_DCHECK(hemicube_share(accepted) <= 1.0 + 1e-4);
  if (!settled) record_broken = true;  // kMaxRounds still splitting: no headroom to record
  if (recording != nullptr) record_piece(piece, split_room, accepted);
  gap_share = covered_share(piece.src);
  if (defer_far) {
    defer_far = false;
    auto far = std::make_unique<FarShare>();
    far->src = piece.src;
    far->shape = shape_of(piece);
    far->dB = piece.dB;
    far->gap = gap_share;
    far->seen = seen_share;
    if (recording != nullptr && !record_broken && !recording->pieces.empty()) far->record_piece = recording->pieces.size() - 1;
    for (uint32_t e : accepted)
      if (f_recv[e] > 0.0) {
        far->recv.push_back(e);
        far->f.push_back(f_recv[e]);
        far->power += f_recv[e] * e_area[e] * channel_sum(piece.dB);
      }
    far_pending = std::move(far);
    gap_share = 0.0;
    return near;
  }
  const ShooterShape shape = shape_of(piece);
  shooter_shape = &shape;
  ++grid_shooter;
  distribute(piece.dB, accepted);
  shooter_shape = nullptr;
  gap_share = 0.0;
  return near;
}

// The piece's own patches stay out of its hemicube (a curved cluster's may stand in front of it)
// and are no absorbers in front of it (absorber_close); so do a volume cluster's faces' other sides
// (foreign_inside lets them pass through its box).
void Solver::Impl::mark_shooting_patches(const Piece& piece) {
  ++shooting_stamp;
  for (uint32_t e : piece.src) {
    p_shooting[e_patch[e]] = shooting_stamp;
    // A volume cluster's faces' other sides lie where they do, inside its cube.
    if (piece.volume && prep.twin[e_patch[e]] != kNone) p_shooting[prep.twin[e_patch[e]]] = shooting_stamp;
  }
}

// Receivers split by earlier pieces of the shot are replaced by their leaves.
std::vector<uint32_t> Solver::Impl::current_leaves(const std::vector<uint32_t>& receivers) const {
  std::vector<uint32_t> current;
  current.reserve(receivers.size());
  for (uint32_t e : receivers) for_leaves(e, [&](uint32_t leaf) { current.push_back(leaf); });
  return current;
}

// Near-field: a receiver close to the piece (a room corner, or a block standing on a lit floor,
// whose faces see only part of the piece) sees it very differently from how the hemicube at its
// centre sees the receiver. Such receivers (is_close), where the difference may matter
// (near_error), go to `near`: they take their share from the piece's sub-pieces instead, each with
// a hemicube of its own. The others, `accepted`, take it from this piece's hemicube.
void Solver::Impl::classify_receivers(const Piece& piece, const std::vector<uint32_t>& current,
                                      std::vector<uint32_t>& accepted, std::vector<uint32_t>& near) {
  std::vector<uint8_t> goes_near(current.size(), 0);
  if (piece.may_refine)
    pool.parallel_for(current.size(), [&](size_t begin, size_t end, size_t) {
      for (size_t i = begin; i < end; ++i)
        goes_near[i] = is_close(piece, current[i]) && near_error(piece, current[i]) > kNearError * b_tolerance;
    });
  for (size_t i = 0; i < current.size(); ++i) (goes_near[i] ? near : accepted).push_back(current[i]);
  HEMIBAKE_DCHECK(accepted.size() + near.size() == current.size());
}

// Whether a piece shoots from the finer hemicube whatever its level (Params::sharp_shadows). A
// large emitter's light reaches much of the scene through its near-field pieces (a glowing wall's
// quarters, for a table of boxes a few metres from it), whose hemicubes halve the resolution per
// level: there a box is a pixel or less, and a pixel's layers taken as independent light the
// crevices between boxes and leave a box's face half behind another one lit element. Tables of
// 60 to 65 boxes before a glowing wall, under a ceiling panel and beside a wall panel, against the
// path tracer at 1500 points (median as displayed): 33.7 -> 16.3 %, 8.6 -> 5.4 %, 33.0 -> 18.4 %
// (hr 13.1, 8.5, 11.3 %). Elsewhere it changes little at 1 to 1.25 times the time (the Cornell
// box's shadows split more finely), and a wall 5 cm behind a cabinet can take more of the light
// past it (bench/README.md): an option, off by default and at every preset.
bool Solver::Impl::sharp_level(const Piece& piece, double power) const {
  return params.sharp_shadows && params.method == Method::kAntiAliased && !piece.volume && power >= kSharpPower * emitted_power;
}

// The objects of the scene (p_object_size, p_object_centre): outward-facing solids and closed
// double-sided meshes, each measured by its bounding box once.
void Solver::Impl::measure_objects() {
  p_object_size.assign(patches.size(), 0.0);
  p_object_centre.assign(patches.size(), glm::dvec3(0.0));
  auto median_extent = [](const glm::dvec3& lo, const glm::dvec3& hi) {
    const glm::dvec3 d = hi - lo;
    return std::max(std::min(d.x, d.y), std::min(std::max(d.x, d.y), d.z));
  };
  for (uint32_t q = 0; q < patches.size(); ++q) {
    const uint32_t s = prep.solid[q];
    if (s == kNone) continue;
    p_object_size[q] = median_extent(prep.solid_lo[s], prep.solid_hi[s]);
    p_object_centre[q] = 0.5 * (prep.solid_lo[s] + prep.solid_hi[s]);
  }
  for (uint32_t m = 0; m < prep.closed_outside.size(); ++m)
    for (uint32_t q : prep.closed_outside[m]) {
      p_object_size[q] = median_extent(prep.closed_lo[m], prep.closed_hi[m]);
      p_object_centre[q] = 0.5 * (prep.closed_lo[m] + prep.closed_hi[m]);
    }
}

// The resolution a strong piece's hemicube needs to show each object it may see (`seen`: what it
// projects) at least kObjectPixels pixels wide: an object of size s at distance d spans s / d
// radians, a pixel at the top face's centre 2 / R. Its near-field pieces halve the resolution per
// level, since a quarter-size piece serves receivers half as far; but the objects do not shrink
// with the piece. A table of boxes of 4 to 18 cm, 3 m from a glowing wall, is shot from the wall's
// sixteenths at resolution 26, where a box is a pixel or less: light then leaks into the crevices
// between the boxes and a face half behind another stays lit (bench/README.md). 0 where it sees no
// object, for a volume cluster, or not aa's; whether the piece's level is fine enough, and whether
// the piece is strong enough to take more, is place_hemicube's to say. Walls of tiles and open
// sheets are no objects: only solids and closed meshes hide things behind them at every angle.
uint32_t Solver::Impl::sharp_resolution(const Piece& piece, const std::vector<uint32_t>& seen) {
  if (params.method != Method::kAntiAliased || piece.volume) return 0;
  // The narrowest object's angle, on the pool's threads (a whole-scene shot of the atrium sees
  // 140 000 elements).
  const double least = least_over(seen.size(), std::numeric_limits<double>::infinity(), [&](size_t i, double& angle) {
    const uint32_t q = e_patch[seen[i]];
    const double size = p_object_size[q];
    if (size > 0.0) angle = std::min(angle, size / std::max(glm::distance(piece.centre, p_object_centre[q]), size));
  });
  return std::isfinite(least) ? static_cast<uint32_t>(std::ceil(2.0 * kObjectPixels / least)) : 0;
}

// Chooses the piece's hemicube, its level's or a finer one, and places it at the piece's centre.
// Strong cluster pieces (from 0.1 % of the emitted power) once took the finer hemicube at level 0;
// measured as displayed it changed the cluttered and furnished rooms' p90 by under half a point,
// and cost the furnished room about a sixth of its time (bench/README.md). Weak pieces once took
// coarser hemicubes (half the resolution under 5 % of the emitted power, a quarter under 0.5 %), as
// long as those shot under a quarter of all the power. The hemicube's cost is mostly per element
// projected, and replays of such shots were refused once the quarter was reached: without them the
// atrium took 158 000 hemicubes rather than 201 000 (162 s against 188), the cluttered room 0.93 of
// the time, and the displayed error fell (the gallery's visible points: median 2.6 -> 2.0 %, p90
// 12.4 -> 11.5 %; bench/README.md).
// A strong piece that objects ask a finer hemicube of (sharp_resolution) takes the coarsest level's
// that is fine enough, or the finer one.
void Solver::Impl::place_hemicube(const Piece& piece, const std::vector<uint32_t>& seen) {
  const bool option = sharp_level(piece, piece.power);
  const uint32_t wanted = option ? 0 : sharp_resolution(piece, seen);
  size_t level = std::min<size_t>(static_cast<size_t>(piece.depth), cubes.size() - 1);
  objects_want_finer = wanted > cubes[level].resolution();
  const bool strong = objects_want_finer && piece.power >= kSharpPower * emitted_power;
  if (strong)
    while (level > 0 && cubes[level].resolution() < wanted) --level;
  const bool sharp = option || (strong && cubes[level].resolution() < wanted);
  ++stats.hemicubes;
  ++stamp;
  if (sharp) level = 0;
  cube = &cubes[level];
  if (piece.volume) {
    VolumeCube& v = volume_cubes[level];
    if (!v.cube) {
      v.cube = std::make_unique<detail::Hemicube>(std::min(cubes[level].resolution(), kMaxVolumeResolution), true);
      v.cube->place(glm::dvec3(0.0), piece.normal, piece.up);
      const uint32_t pixels = v.cube->pixel_count();
      v.dir.resize(pixels);
      v.omega.resize(pixels);
      for (uint32_t px = 0; px < pixels; ++px) {
        v.dir[px] = glm::normalize(v.cube->pixel_direction(px));
        v.omega[px] = v.cube->pixel_solid_angle(px);
      }
    }
    cube = v.cube.get();
    cube->place(piece.centre, piece.normal, piece.up);
    volume_weights(piece, v);
    pixel_weight = &volume_weight;
    return;
  }
  const uint32_t finer_resolution = std::max(params.resolution, std::min(2 * params.resolution, kMaxFinerResolution));
  if (sharp && finer_resolution > params.resolution) {
    // Made when first needed, and none at all where the resolution is that fine already.
    if (!finer_cube) finer_cube = std::make_unique<detail::Hemicube>(finer_resolution);
    cube = finer_cube.get();
  }
  cube->place(piece.centre, piece.normal, piece.up);
  pixel_weight = &cube->delta_form_factors();
}

// The share of a volume cluster's light that leaves through each pixel of its cube: its faces'
// areas a_i projected on the pixel's direction w, sum_i a_i max(0, n_i . w) dOmega / pi, over the
// sum of the faces' areas (the radiosity is taken as the cluster's mean, as for any cluster), so
// that a flat cluster's weights are the hemicube's delta form factors. Faces of like normal
// (within about 2 degrees) are summed first; the weights are scaled to sum to exactly 1. The
// cluster's own faces are left out of its cube: a convex object's faces look away from its
// centre, so light leaves it unhindered.
void Solver::Impl::volume_weights(const Piece& piece, const VolumeCube& v) {
  HEMIBAKE_DCHECK(piece.cluster < c_nodes.size() && v.cube->full());
  const ClusterNode& node = c_nodes[piece.cluster];
  std::map<std::array<int, 3>, glm::dvec4> by_normal;  // area times normal, and area
  for (uint32_t i = node.begin; i < node.end; ++i) {
    const uint32_t q = cluster_patch[i];
    const glm::dvec3& n = prep.normal[q];
    const std::array<int, 3> key{static_cast<int>(std::lround(n.x * 32.0)), static_cast<int>(std::lround(n.y * 32.0)),
                                 static_cast<int>(std::lround(n.z * 32.0))};
    by_normal[key] += glm::dvec4(n * prep.area[q], prep.area[q]);
  }
  std::vector<glm::dvec4> lobes;  // unit normal, area
  lobes.reserve(by_normal.size());
  for (const auto& [key, sum] : by_normal) {
    const glm::dvec3 n(sum);
    const double len = glm::length(n);
    if (len > 0.0) lobes.emplace_back(n / len, sum.w);
  }
  const uint32_t pixels = v.cube->pixel_count();
  volume_weight.resize(pixels);
  pool.parallel_for(pixels, [&](size_t begin, size_t end, size_t) {
    for (size_t px = begin; px < end; ++px) {
      double w = 0.0;
      for (const glm::dvec4& l : lobes) w += l.w * std::max(0.0, glm::dot(glm::dvec3(l), v.dir[px]));
      volume_weight[px] = w * v.omega[px];
    }
  });
  const double total = std::accumulate(volume_weight.begin(), volume_weight.end(), 0.0);
  HEMIBAKE_DCHECK(total > 0.0);
  for (double& w : volume_weight) w /= total;
}

// F(element -> piece) for every accepted receiver, visible (f_recv) and unoccluded (f_open): from
// the hemicube by reciprocity, or for a close receiver of a piece that is not refined further, from
// the exact form factor (exact_form_factor). Each receiver's on its own, so the receivers are
// shared among the threads.
void Solver::Impl::receiver_form_factors(const Piece& piece, const std::vector<uint32_t>& accepted) {
  // Receivers within a diameter of a piece that is not refined further (a weak shot, or the
  // deepest level) and less than twice its size take the exact form factor to the piece, times the
  // fraction of the receiver the hemicube found visible: reciprocity from the piece's centre errs
  // by the piece's size against the distance, the receiver's points by the receiver's.
  const bool exact_close = !piece.may_refine && piece.points.size() <= 4;
  auto near_piece = [&](uint32_t e) {
    return e_radius[e] < piece.diameter && glm::distance(piece.centre, e_centre[e]) - e_radius[e] < piece.diameter;
  };
  // front_shares: per receiving patch near the piece, once per call.
  std::vector<std::pair<uint32_t, double>> shares;
  if (exact_close) {
    for (uint32_t e : accepted)
      if (near_piece(e)) shares.emplace_back(e_patch[e], 0.0);
    std::sort(shares.begin(), shares.end());
    shares.erase(std::unique(shares.begin(), shares.end()), shares.end());
    front_shares(piece, shares);
  }
  auto share_of = [&](uint32_t q) { return std::lower_bound(shares.begin(), shares.end(), std::make_pair(q, 0.0))->second; };
  // An uneven piece (a wall piece reaching from the room into the gap behind a cabinet) gives a
  // close receiver the light of the leaves it faces most (uneven_share), not the front part's mean.
  const std::vector<ShotNode> uneven = shares.empty() ? std::vector<ShotNode>{} : uneven_tree(piece);
  pool.parallel_for(accepted.size(), [&](size_t begin, size_t end, size_t) {
    for (size_t i = begin; i < end; ++i) {
      const uint32_t e = accepted[i];
      f_recv[e] = f_open[e] = 0.0;
      if (sealed(e_patch[e], eye_within)) continue;
      const bool seen_here = projected(e);
      if (seen_here) {
        f_recv[e] = by_reciprocity(piece, e, e_ff[e]);
        f_open[e] = by_reciprocity(piece, e, e_ff_open[e]);
      }
      const double size = 2.0 * e_radius[e];
      if (exact_close && near_piece(e) && is_close(piece, e)) {
        // A receiver the hemicube did not see (the piece's centre lies behind it, though part of
        // the piece is in front: a floor piece under a block's face) is taken as unoccluded from
        // the part in front, which lies within a diameter of it. The exact form factor is to that
        // part, and the light is that part's own unshot radiosity (front_shares): the floor under a
        // block that stands on it is dark; and beside a wall box standing on a floor, the floor
        // piece reaching under the wall holds its light in front of the wall alone, where the
        // wall's foot took the piece's mean, diluted by the covered strip (a closed room of wall
        // boxes lost 3 % of the light at each of its floor's shots).
        const double f = exact_form_factor(piece, e, size < 0.5 * piece.diameter ? 1 : size < piece.diameter ? 2 : 3);
        const double share = uneven.empty() ? share_of(e_patch[e]) : uneven_share(piece, uneven, e, share_of(e_patch[e]));
        f_open[e] = std::min(1.0, f * share);
        f_recv[e] = seen_here ? f_open[e] * (e_ff[e] / e_ff_open[e]) : f_open[e];
      }
      // Visible shares are at most the unoccluded ones, and both form factors at most 1.
      HEMIBAKE_DCHECK(f_recv[e] >= 0.0 && f_recv[e] <= f_open[e] && f_open[e] <= 1.0);
    }
  });
}

// For each (q, share): the unshot radiosity of the part of `piece` in front of the plane of
// receiving patch q, as a share of the piece's mean: its leaves there, by their centres (1 for a
// piece of uniform radiosity; more where the part behind holds less, as a floor piece reaching
// under a wall box does). The piece's leaves are listed once for all the patches, which are
// shared among the threads.
void Solver::Impl::front_shares(const Piece& piece, std::vector<std::pair<uint32_t, double>>& shares) {
  if (piece.src.size() != 1 || e_child[piece.src[0]] == kNone || piece.src_area != piece.area) {
    for (auto& entry : shares) entry.second = 1.0;
    return;
  }
  struct Leaf {
    glm::dvec3 centre;
    double power, area;
  };
  std::vector<Leaf> lit;
  for_leaves(piece.src[0], [&](uint32_t x) { lit.push_back({e_centre[x], channel_sum(e_unshot[x]) * e_area[x], e_area[x]}); });
  const double mean = channel_sum(piece.dB);
  pool.parallel_for(shares.size(), [&](size_t begin, size_t end, size_t) {
    for (size_t i = begin; i < end; ++i) {
      const uint32_t q = shares[i].first;
      const glm::dvec3& nq = prep.normal[q];
      const glm::dvec3& oq = patches[q].corners[0];
      double power = 0.0, area = 0.0;
      for (const Leaf& x : lit) {
        if (glm::dot(nq, x.centre - oq) <= 0.0) continue;
        power += x.power;
        area += x.area;
      }
      shares[i].second = area > 0.0 && mean > 0.0 ? power / area / mean : 0.0;
    }
  });
}

// The element tree under a piece that is one element, cut up, whose leaves' unshot radiosity
// departs from its mean by more than kUnevenShare (summed over them by area as a share of the
// mean); empty otherwise. Each node holds its leaves' mean unshot radiosity (channels summed) as a
// share of the piece's mean; a node's children follow one another. The leaves are judged, not the
// four children (uneven_piece): a quarter of a wall whose lit strips lie on both sides of a
// bookshelf standing 2 cm before it has even halves, and the shelf's back took the lit strips'
// mean from it, two thirds of the light that reached the dark wall behind it.
std::vector<Solver::Impl::ShotNode> Solver::Impl::uneven_tree(const Piece& piece) const {
  std::vector<ShotNode> out;
  if (piece.src.size() != 1 || e_child[piece.src[0]] == kNone || piece.src_area != piece.area || piece.volume) return out;
  const double mean = channel_sum(piece.dB);
  if (!(mean > 0.0)) return out;
  // Breadth first, so that each node's four children are placed together; then the shares, from
  // the leaves up (children come after their parents).
  std::vector<uint32_t> element{piece.src[0]};
  out.push_back({e_centre[piece.src[0]], e_area[piece.src[0]], e_radius[piece.src[0]] * e_radius[piece.src[0]], 0.0, kNone});
  double departure = 0.0, total_area = 0.0;
  for (size_t i = 0; i < out.size(); ++i) {
    const uint32_t x = element[i];
    if (e_child[x] == kNone) {
      out[i].share = channel_sum(e_unshot[x]) / mean;
      departure += std::abs(out[i].share - 1.0) * out[i].area;
      total_area += out[i].area;
      continue;
    }
    out[i].first_child = static_cast<uint32_t>(out.size());
    for (uint32_t k = 0; k < 4; ++k) {
      const uint32_t c = e_child[x] + k;
      element.push_back(c);
      out.push_back({e_centre[c], e_area[c], e_radius[c] * e_radius[c], 0.0, kNone});
    }
  }
  for (size_t i = out.size(); i-- > 0;) {
    if (out[i].first_child == kNone) continue;
    double sum = 0.0, area = 0.0;
    for (uint32_t k = 0; k < 4; ++k) {
      const ShotNode& c = out[out[i].first_child + k];
      sum += c.share * c.area;
      area += c.area;
    }
    out[i].share = area > 0.0 ? sum / area : 0.0;
  }
  if (!(departure > kUnevenShare * total_area)) out.clear();
  return out;
}

// The unshot radiosity receiver e takes from an uneven piece, as a share of the piece's mean: its
// leaves' own, each weighted by its point-to-point form factor from the receiver's centre and
// corners, A cos cos' / (pi d^2), with d at least the leaf's radius (the receiver's whole view is
// the exact form factor to the piece; this only says whose light it is). Nodes of the piece's tree
// that lie further than kShareOpen radii away stand for their leaves. A cabinet's back 5 cm before
// a wall piece that reaches out of the gap behind the cabinet into the lit room took the piece's
// mean, several times the gap's own light (bench/README.md). `fallback` where it faces none.
double Solver::Impl::uneven_share(const Piece& piece, std::span<const ShotNode> nodes, uint32_t e, double fallback) const {
  constexpr double kShareOpen = 2.0;
  const glm::dvec3& nq = prep.normal[e_patch[e]];
  double weighted = 0.0, weight = 0.0;
  std::vector<uint32_t> stack;
  auto from = [&](const glm::dvec3& x) {
    stack.assign(1, 0);
    while (!stack.empty()) {
      const ShotNode& node = nodes[stack.back()];
      stack.pop_back();
      const glm::dvec3 v = node.centre - x;
      const double d2 = glm::dot(v, v);
      if (node.first_child != kNone && d2 < kShareOpen * kShareOpen * node.radius2) {
        for (uint32_t k = 0; k < 4; ++k) stack.push_back(node.first_child + k);
        continue;
      }
      const double ce = glm::dot(nq, v), cl = -glm::dot(piece.normal, v);
      if (ce <= 0.0 || cl <= 0.0) continue;
      // cos cos' / d^2 = ce cl / d^4, the distance held at the node's radius and above
      const double w = node.area * ce * cl / (d2 * std::max(d2, node.radius2));
      weighted += w * node.share;
      weight += w;
    }
  };
  from(e_centre[e]);
  for (uint32_t i = 0; i < corner_count(e); ++i) from(vpos[e_corner[e][i]]);
  return weight > 0.0 ? weighted / weight : fallback;
}

// The share of the hemicube's view that its receivers take, sum of F(piece -> receiver): at most 1
// (the pixels' delta form factors sum to 1, and the visible shares in a pixel to at most 1).
double Solver::Impl::hemicube_share(const std::vector<uint32_t>& accepted) const {
  double sum = 0.0;
  for (uint32_t e : accepted)
    if (projected(e)) sum += e_ff[e];
  return sum;
}

// Southwell step: the piece's unshot radiosity goes to the receivers that took light here.
void Solver::Impl::distribute(const glm::dvec3& dB, const std::vector<uint32_t>& accepted) {
  receive_each(accepted.size(), dB, [&](size_t i) { return accepted[i]; }, [&](size_t i) { return f_recv[accepted[i]]; }, true);
}

// A top piece's far receivers take their light once its parts have served its near ones, `given` of
// its `power`. The share N of its hemicube (or cube) that front faces took but the far receivers
// did not is what the near receivers took as seen from its centre; its parts, where they stand,
// gave them `given` instead. The difference, N P - given, leaves as the rest of the hemicube's
// light does, (1 - N) P, a share of it to the far receivers (the rest to the sky or into absorbing
// backs): their form factors are scaled by 1 + (N P - given) / ((1 - N) P), so that a shot in a
// closed room gives out all of its power, no more and no less (a volume cluster over a floor lost
// 8.4 % of its light without; a flat patch's near-field parts, which see a wall beside it better
// than its centre, gave out up to half a percent too much). Only a whole-scene shot sees all its
// far receivers: a partial one (reshoot_split) keeps the unit's `kept` scale. `parts`: whether any
// receiver went to the parts (a flat piece whose parts shot nothing keeps its hemicube's light).
// Returns the scale.
double Solver::Impl::settle_far(FarShare& far, double power, double given, bool whole_scene, bool parts, double kept) {
  double scale = kept;
  if (whole_scene) {
    const double near_share = std::max(0.0, far.seen - far.power / power);
    scale = parts && near_share < 1.0 ? std::max(0.0, 1.0 + (near_share * power - given) / ((1.0 - near_share) * power)) : 1.0;
  }
  finish_far(far, scale);
  return scale;
}

// Gives a top piece's deferred far receivers their light, their form factors times `scale` (at
// most 1), in the shot's record too. A receiver split since takes it on its leaves.
void Solver::Impl::finish_far(FarShare& far, double scale) {
  far.shape.src = far.src;
  shooter_shape = &far.shape;
  gap_share = far.gap;
  ++grid_shooter;
  // The receivers' leaves (distinct: the receivers are), each with its receiver's form factor.
  std::vector<std::pair<uint32_t, double>> leaves_f;
  leaves_f.reserve(far.recv.size());
  for (size_t i = 0; i < far.recv.size(); ++i) {
    const double f = std::min(1.0, far.f[i] * scale);
    if (f > 0.0) for_leaves(far.recv[i], [&](uint32_t leaf) { leaves_f.emplace_back(leaf, f); });
  }
  receive_each(leaves_f.size(), far.dB, [&](size_t i) { return leaves_f[i].first; }, [&](size_t i) { return leaves_f[i].second; }, true);
  shooter_shape = nullptr;
  gap_share = 0.0;
  if (recording != nullptr && !record_broken && far.record_piece < recording->pieces.size()) {
    const ShotRecord::Piece& rp = recording->pieces[far.record_piece];
    for (uint32_t k = rp.recv_begin; k < rp.recv_end; ++k)
      recording->f[k] = static_cast<float>(std::min(1.0, recording->f[k] * scale));
  }
}

}  // namespace hemibake::solver
