// A posteriori subdivision of a hemicube's receivers (step 3 of the shot in solver.cpp): a leaf is
// too large for this interaction when (a) its form factor weighted by the shooter's share of the
// emitted power exceeds FEPS, or (b) it is partly hidden and the hidden part would have changed its
// radiosity by more than the radiosity tolerance, or (c) the shot's radiosity differs across one of
// its corners by more than that tolerance, or (d) a point or spot light's light varies across it by
// more than that tolerance. Split elements cancel the shot; it is repeated with
// their children, whose form factors come from their parent's pixels.
#include "solver_impl.h"

#include <algorithm>
#include <limits>

namespace hemibake::solver {

// Repeats the piece's shot until a round splits nothing, at most kMaxRounds times. Returns whether
// the last round split nothing (or could not: the element limit). While recording, `split_room`
// is by how much the piece's dB could grow before that round would have split something.
bool Solver::Impl::refine(const Piece& piece, const detail::Shaft& shaft, std::vector<uint32_t>& accepted,
                          std::vector<uint32_t>& seen, double& split_room) {
  // This piece's share of the light its shot acts on (feps_scale): how much the interaction matters
  // (criterion a). A strong emitter's piece (shooters.cpp) weighs as all n of them, judge squared
  // times its own (they see a receiver alike: the Cornell box's p90 7.2 -> 6.8 %); the other
  // criteria judge dB times the judge (sqrt(n)).
  const double weight = piece.judge * piece.judge * piece.power / feps_scale;
  const glm::dvec3 judged = piece.judge * piece.dB;
  for (int round = 0; round < kMaxRounds; ++round) {
    receiver_form_factors(piece, accepted);
    spread_shot(judged, accepted);
    std::vector<uint32_t> to_split = too_coarse(judged, weight, accepted);
    if (recording != nullptr) split_room = split_headroom(judged, weight, accepted);
    reset_spread(accepted);
    if (to_split.empty()) {
      // Nothing passed a criterion, so dB may grow by at least 1 before anything does.
      HEMIBAKE_DCHECK(recording == nullptr || split_room >= 1.0);
      return true;
    }
    if (!trim_to_element_limit(to_split)) {
      split_room = std::numeric_limits<double>::infinity();  // no split is possible any more
      return true;
    }
    // The shot is cancelled and repeated with the split elements.
    ++stats.rounds;
    split_receivers(to_split, shaft, accepted, seen);
  }
  return false;
}

// The power that FEPS is a share of for a whole-scene shot of `unit`: the light (radiosity times
// area) of the receivers it reaches (the hemicube's visible `accepted`, and the `near` ones its
// parts serve), at least the unit's unshot power and at most the emitted power. The paper's FEPS weighs
// every interaction by the whole scene's emitted power; a room lit far more dimly than the rest (an
// interior the sun enters through a window, beside a sunlit outside that holds most of the power)
// then stayed coarse: the Blender house's sunlit room 15.2 % median and 34.1 % p90 error as
// displayed (bench/README.md, "FEPS against the light in view"). In a room that holds the light
// the receivers hold the emitted power or more, and little changes; a lamp's first shot, into
// receivers still dark, is weighed against its own power, the emitted power where it lights the
// room alone. A shot's near-field parts keep its scale, and a partial shot (reshoot_split) takes
// the unit's last whole-scene one.
double Solver::Impl::interaction_scale(const std::vector<uint32_t>& accepted, const std::vector<uint32_t>& near,
                                       uint32_t unit, double piece_power) const {
  double light = 0.0;
  for (uint32_t e : accepted)
    if (projected(e) && e_ff[e] > 0.0) light += light_of(e);
  for (uint32_t e : near) light += light_of(e);
  return std::min(emitted_power, std::max({light, u_unshot[unit], piece_power}));
}

// This shot's radiosity at every accepted receiver (shot_b), and its spread around every vertex
// (vmin, vmax). Elements under a surface standing on them (e_under) are left out of the spread: no
// one sees them, the foot is split along before any shot (contact_crosses), and the mesh leaves them
// out of the vertices on the foot (Solver::mesh). Counted, the light in front of a sunlit foot
// against the dark under it split the ground along every foot down to the smallest elements (the
// lit yard: 5777 splits for the gradient against 3430; the Cornell box 1218 against 999).
void Solver::Impl::spread_shot(const glm::dvec3& dB, const std::vector<uint32_t>& accepted) {
  for (uint32_t e : accepted) {
    const double v = shot_radiosity(e, dB, f_recv[e]);
    shot_b[e] = v;
    if (e_under[e] != kNone) continue;
    for (uint32_t k = 0; k < corner_count(e); ++k) {
      const uint32_t vert = e_corner[e][k];
      vmin[vert] = std::min(vmin[vert], v);
      vmax[vert] = std::max(vmax[vert], v);
    }
  }
}

// Resets the vertex spreads for the next round (only the touched vertices).
void Solver::Impl::reset_spread(const std::vector<uint32_t>& accepted) {
  for (uint32_t e : accepted)
    for (uint32_t k = 0; k < corner_count(e); ++k) {
      vmin[e_corner[e][k]] = std::numeric_limits<double>::max();
      vmax[e_corner[e][k]] = std::numeric_limits<double>::lowest();
    }
}

// The receivers too coarse for this interaction (criteria a-c), counted by criterion in stats.
// Each receiver is judged on its own, so the receivers are shared among the threads; their lists
// are joined in order, as one thread would have made them.
std::vector<uint32_t> Solver::Impl::too_coarse(const glm::dvec3& dB, double weight,
                                               const std::vector<uint32_t>& accepted) {
  struct Part {
    std::vector<uint32_t> split;
    uint64_t form_factor = 0, visibility = 0, gradient = 0;
  };
  std::vector<Part> parts(pool.chunk_count(accepted.size()));
  const bool point_light = shooting_light != nullptr && shooting_light->type != Light::Type::kDirectional;
  pool.parallel_for(accepted.size(), [&](size_t begin, size_t end, size_t c) {
    Part& part = parts[c];
    for (size_t i = begin; i < end; ++i) {
      const uint32_t e = accepted[i];
      if (e_area[e] < min_sharp_split_area() || covered_emitter(e)) continue;
      // Under AEPS only a sharp edge of light splits (kSharpJump), but near a punctual light.
      const bool sharp_only = e_area[e] < min_split_area() && !in_light_pool(e);
      const double tolerance = sharp_only ? kSharpJump * b_tolerance : b_tolerance;
      bool split_it = false;
      if (projected(e)) {
        // (a) too coarse for this interaction.
        split_it = !sharp_only && e_ff[e] * weight > params.feps;
        part.form_factor += split_it;
        // (b) partly hidden, and the hidden part matters. Under AEPS (kShadowAreaFactor), a
        // punctual light's shadow is an edge across the element, a jump of its whole unhidden
        // light (kSharpJump), whatever share of the element it hides; both parts must matter (an
        // element in the shadow keeps rounding's crumbs of light).
        if (!split_it && (!sharp_only || shooting_light != nullptr) && e_ff[e] > 0.0 && e_ff[e] < e_ff_open[e]) {
          const double open = shot_radiosity(e, dB, f_open[e]);
          split_it = sharp_only ? e_area[e] >= min_split_area() / kShadowAreaFactor && open > tolerance &&
                                      shot_b[e] > b_tolerance && open - shot_b[e] > b_tolerance
                                : open - shot_b[e] > tolerance;
          part.visibility += split_it;
        }
      }
      // (c) the shot's radiosity jumps across one of its corners.
      for (uint32_t k = 0; k < corner_count(e) && !split_it; ++k) {
        const uint32_t vert = e_corner[e][k];
        split_it = vmax[vert] - vmin[vert] > tolerance && (!sharp_only || vmax[vert] > kSharpRatio * vmin[vert]);
        part.gradient += split_it;
      }
      // (d) A point or spot light's light varies across the element by more than the tolerance.
      // The corners' spread (c) compares an element with its neighbours, so an element alone on
      // its surface never splits by it: a picture's canvas under a spot light stayed one flat
      // element while the path tracer's light fell by half across it. Taken from the light's
      // formula at the element's corners and centre (pixel coverage would add its own noise),
      // scaled by the share of the element the light sees.
      if (!split_it && !sharp_only && point_light && f_recv[e] > 0.0 && f_open[e] > 0.0) {
        const glm::dvec3& n = prep.normal[e_patch[e]];
        double lo = light_at(*shooting_light, e_centre[e], n), hi = lo;
        for (uint32_t k = 0; k < corner_count(e); ++k) {
          const double v = light_at(*shooting_light, vpos[e_corner[e][k]], n);
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
        split_it = shot_radiosity(e, dB, hi - lo) * (f_recv[e] / f_open[e]) > tolerance;
        part.gradient += split_it;
      }
      if (split_it) part.split.push_back(e);
    }
  });
  std::vector<uint32_t> to_split;
  for (const Part& part : parts) {
    to_split.insert(to_split.end(), part.split.begin(), part.split.end());
    stats.splits_form_factor += part.form_factor;
    stats.splits_visibility += part.visibility;
    stats.splits_gradient += part.gradient;
  }
  return to_split;
}

// For a replay: by how much dB could grow before this round would split something. The criteria
// scale with dB, so each gives limit / value; the same tests as too_coarse (but a punctual light's
// shadows under AEPS: lights shoot once, and record nothing). The least over the receivers, each
// thread's share first.
double Solver::Impl::split_headroom(const glm::dvec3& dB, double weight, const std::vector<uint32_t>& accepted) {
  HEMIBAKE_DCHECK(shooting_light == nullptr);
  return least_over(accepted.size(), std::numeric_limits<double>::infinity(), [&](size_t i, double& room) {
    const uint32_t e = accepted[i];
    // too_coarse has noted e_cov for the emitters' elements.
    if (e_area[e] < min_sharp_split_area() || (e_cov[e] == 1 && emits(e))) return;
    const bool sharp_only = e_area[e] < min_split_area() && !in_light_pool(e);
    const double tolerance = sharp_only ? kSharpJump * b_tolerance : b_tolerance;
    if (projected(e)) {
      if (!sharp_only) lower_headroom(room, params.feps, e_ff[e] * weight);
      if (!sharp_only && e_ff[e] > 0.0 && e_ff[e] < e_ff_open[e])
        lower_headroom(room, tolerance, shot_radiosity(e, dB, f_open[e]) - shot_b[e]);
    }
    for (uint32_t k = 0; k < corner_count(e); ++k)
      if (!sharp_only || vmax[e_corner[e][k]] > kSharpRatio * vmin[e_corner[e][k]])
        lower_headroom(room, tolerance, vmax[e_corner[e][k]] - vmin[e_corner[e][k]]);
  });
}

// Whether element e is the side of an emitter that a surface just in front of it covers (the top of
// a lamp hung 1 mm under a ceiling): no one sees it, and each shot of the ceiling over it lights
// only the part right under the shooting piece, a pattern the shots add up to a flat light. Split
// for it, the Blender room with a panel 1 mm under its ceiling cut the panel into 8000 elements.
bool Solver::Impl::covered_emitter(uint32_t e) { return emits(e) && leaf_covered(e); }

// Whether element e lies in the pool of the punctual light being shot, close enough to it for its
// light's fall-off across e to need elements under AEPS (kLightPoolReach): a desk lamp 60 cm from
// a wall lit it through 35 to 50 cm elements (a room of wall boxes, whose outsides and hidden
// insides hold most of its area), its peak 28 % low.
bool Solver::Impl::in_light_pool(uint32_t e) const {
  if (shooting_light == nullptr || shooting_light->type == Light::Type::kDirectional) return false;
  return e_radius[e] > kLightPoolReach * glm::distance(shooting_light->position, e_centre[e]);
}

// Keeps to the element limit (params.max_elements; a split adds three leaves): trims `to_split`
// to what it allows. Returns false when nothing may split any more.
bool Solver::Impl::trim_to_element_limit(std::vector<uint32_t>& to_split) {
  const uint64_t room = params.max_elements > leaves.size() ? (params.max_elements - leaves.size()) / 3 : 0;
  if (to_split.size() <= room) return true;
  stats.element_limit = true;
  to_split.resize(room);
  return !to_split.empty();
}

// Splits the receivers and gives their children form factors: from their parent's pixels (no
// other element is looked at again), or with reuse_visibility off, from a new projection.
void Solver::Impl::split_receivers(const std::vector<uint32_t>& to_split, const detail::Shaft& shaft,
                                   std::vector<uint32_t>& accepted, std::vector<uint32_t>& seen) {
  for (uint32_t e : to_split) split(e);
  replace_split(leaves);
  replace_split(accepted);
  HEMIBAKE_DCHECK(leaves.size() == patches.size() + 3 * stats.splits);
  grow_scratch();
  if (params.reuse_visibility) {
    project_children(to_split);
  } else {
    gather_seen(shaft, accepted, seen);
    project(seen, shaft.whole_scene ? std::span<const uint32_t>() : std::span<const uint32_t>(accepted));
    sum_form_factors(accepted);
  }
}

}  // namespace hemibake::solver
