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
//
// This file picks the shooter (step) and holds the public API. shooters.cpp cuts a shooter into
// pieces (1); shoot_piece.cpp shoots one piece in stages, with shaft.cpp (what may hide the
// receivers) and projection.cpp (2), refine.cpp (3) and shot_cache.cpp (records for replays);
// near_field.cpp decides which receivers are too close to a piece for its hemicube. lights.cpp
// shoots the punctual lights and the sky, once each, before the first patch; gather.cpp gathers
// at the mesh's vertices after the last.
// element_tree.cpp, patch_bvh.cpp and clusters.cpp hold what they walk; mesh_export.cpp the result.
#include "solver_impl.h"

#include <glm/common.hpp>

#include <algorithm>
#include <limits>
#include <thread>

namespace hemibake::solver {

Solver::Impl::Impl(const Scene& scene, const Params& p, const Impl* first, const Params* solve_params)
    : params(p),
      patches(scene.patches),
      prep(detail::prepare(scene)),

      pool(p.threads != 0 ? p.threads : std::max(1u, std::thread::hardware_concurrency())) {
  for (int d = 0; d < kCubeLevels; ++d) {
    const uint32_t res = std::max(kMinResolution, ((params.resolution >> d) + 1) & ~1u);
    cubes.emplace_back(std::min(res, params.resolution));
  }
  cube = &cubes[0];
  pixel_weight = &cube->delta_form_factors();
  volume_cubes.resize(cubes.size());
  aeps_area = params.aeps * prep.total_area;
  shooter_limit = params.shooter_size * prep.diagonal;
  vpos = prep.vertex_position;
  double emitted_mean = 0.0;
  for (uint32_t i = 0; i < patches.size(); ++i) {
    emitted_power += channel_sum(patches[i].emission) * prep.area[i];
    emitted_mean += mean(patches[i].emission) * prep.area[i];
  }
  b_tolerance = params.beps * emitted_mean / prep.total_area;
  gather_tolerance = b_tolerance;
  p_root.resize(patches.size());
  p_unshot.resize(patches.size());
  for (uint32_t i = 0; i < patches.size(); ++i) {
    p_root[i] = add_element(i, kNone, prep.corner_vertex[i], patches[i].emission, patches[i].emission);
    p_unshot[i] = channel_sum(patches[i].emission) * prep.area[i];
    leaves.push_back(p_root[i]);
  }
  build_patch_bvh();  // clusters look for other objects' surfaces passing through them
  measure_objects();
  find_standing();
  mark_covered();
  build_clusters();
  u_far_scale.assign(unit_node.size(), 1.0);
  source = scene;
  first_pass = solve_params != nullptr;
  solve = first_pass ? *solve_params : params;
  pool_tolerance = solve.beps * emitted_mean / prep.total_area;
  if (first_pass) {
    build_light_grids();
    p_emitter_left.assign(patches.size(), 0);
    for (uint32_t q = 0; q < patches.size(); ++q)
      if (channel_sum(patches[q].emission) > 0.0) {
        p_emitter_left[q] = 1;
        ++emitters_left;
      }
  } else {
    p_grid_n.assign(patches.size(), 0);
    pools_looked = true;
  }
  if (!first_pass) grid_light.clear();
  p_mark.assign(patches.size(), 0);
  p_shooting.assign(patches.size(), 0);
  stats.patches = patches.size();
  stats.shooters = unit_patch.size();
  stats.elements = leaves.size();
  stats.emitted_power = emitted_power;
  update_unshot_total();
  const size_t chunks = std::max<size_t>(1, pool.chunk_count(std::numeric_limits<uint32_t>::max()));
  scratch.resize(chunks);
  chunk_frags.resize(chunks);
  gather_chunks.resize(chunks);
  lights = scene.lights;
  sky = scene.sky;
  prepare_lights();
  split_along_cover_outlines();
  if (first != nullptr) {
    // The first pass's splits that lead to its light pools' elements, in its order; the
    // constructor's own splits came first in both passes and alike. The rest of the first pass's
    // refinement this pass makes for itself.
    std::vector<uint8_t> wanted(first->e_patch.size(), 0);
    for (uint32_t e : first->pool_splits)
      for (uint32_t x = e; x != kNone && !wanted[x]; x = first->e_parent[x]) wanted[x] = 1;
    std::vector<uint32_t> here(first->e_patch.size(), kNone);  // first pass's element -> this one's
    for (uint32_t e = 0; e < e_patch.size(); ++e) here[e] = e;
    for (size_t i = split_log.size(); i < first->split_log.size(); ++i) {
      const uint32_t e = first->split_log[i];
      if (!wanted[e] || here[e] == kNone || e_child[here[e]] != kNone) continue;
      split(here[e]);
      for (uint32_t k = 0; k < 4; ++k) here[first->e_child[e] + k] = e_child[here[e]] + k;
    }
    replace_split(leaves);
    stats.elements = leaves.size();
    grow_scratch();
  }
}

std::unique_ptr<Solver::Impl> Solver::Impl::next_pass(Impl& first) {
  auto next = std::make_unique<Impl>(first.source, first.solve, &first);
  Stats& s = next->stats;
  s.passes = first.stats.shots > 0 ? first.stats.passes + 1 : first.stats.passes;  // (one that made no shot is none)
  s.seconds_first_pass = first.stats.seconds;
  s.seconds = first.stats.seconds;  // this pass adds its own
  s.splits_pools = first.stats.splits_pools;
  return next;
}

// Element e takes rho dB F of a shot: radiosity and unshot radiosity alike, and the unshot power of
// its patch and unit, which pick the next shooter. The shooting unit's own patches (faces of boxes
// in one cluster light one another) hold their unshot gain until the shot is over: the shot reads
// their unshot radiosity as it was and clears it at its end (clear_unshot), which lost the gain
// (1.2 % of the light in a room of 100 boxes clustered across them).
void Solver::Impl::receive(uint32_t e, const glm::dvec3& dB, double f) {
  // Light goes to leaves only, and only adds: unshot power and radiosity stay non-negative.
  HEMIBAKE_DCHECK(e < e_child.size() && e_child[e] == kNone);
  HEMIBAKE_DCHECK(f > 0.0 && f <= 1.0);
  HEMIBAKE_DCHECK(dB.x >= 0.0 && dB.y >= 0.0 && dB.z >= 0.0);
  const glm::dvec3 gain = gain_of(e, dB, f);
  take_light(e, dB, gain);
  count_light(e, gain);
}

void Solver::Impl::take_light(uint32_t e, const glm::dvec3& dB, const glm::dvec3& gain) {
  const uint32_t q = e_patch[e];
  e_b[e] += gain;
  e_gap[e] += gap_share * gain;
  // (find_pools reads the points of leaves too small to split through their ancestors)
  if (shooter_shape != nullptr && p_grid_n[q] != 0)
    take_on_grid(e, mean(patches[q].reflectance * dB));
  if (p_unit[q] != shooting_unit) e_unshot[e] += gain;
}

void Solver::Impl::count_light(uint32_t e, const glm::dvec3& gain) {
  const uint32_t q = e_patch[e];
  if (p_unit[q] == shooting_unit) {
    held.emplace_back(e, gain);  // the shooting unit's own: unshot once it has shot (clear_unshot)
    return;
  }
  p_unshot[q] += channel_sum(gain) * e_area[e];
  u_unshot[p_unit[q]] += channel_sum(gain) * e_area[e];
}

// One Southwell step: the unit with the most unshot power shoots it all, from its record when a
// replay is exact, else afresh.
bool Solver::Impl::step() {
  if (done) return false;
  // The first pass ends before its first shot when no surface holds a grid (none large enough to
  // split): it would find nothing.
  if (first_pass && grid_light.empty()) {
    pools_looked = true;
    restart = true;
    return true;
  }
  // Lights and the sky shoot first, each once (lights.cpp).
  if (stats.shots < params.max_shots && shoot_next_light()) return true;
  // Once the shots are done, the final gather (gather.cpp), in batches.
  // The first pass, once every emitter has shot and most of their light has been given out: where
  // it pools (pools.cpp); then the solve proper starts on those elements (Solver::step).
  if (first_pass && ((emitters_left == 0 && stats.unshot_fraction < kPoolsPass) ||
                     stats.unshot_fraction < params.convergence || stats.shots >= params.max_shots ||
                     emitted_power <= 0.0)) {
    const auto t0 = Clock::now();
    find_pools();
    stats.seconds += seconds_since(t0);
    restart = true;
    return true;
  }
  uint32_t best = kNone;
  if (stats.unshot_fraction < params.convergence || emitted_power <= 0.0) {
    if (emitted_power > 0.0 && stats.shots < params.max_shots) best = lagging_unit();
    if (best == kNone) {
      if (gather_step()) return true;
      stats.converged = true;
      done = true;
      return false;
    }
  }
  if (stats.shots >= params.max_shots) {
    if (gather_step()) return true;
    stats.shot_limit = true;
    done = true;
    return false;
  }
  const auto t0 = Clock::now();
  if (best == kNone) best = strongest_unit();
  shooting_unit = best;
  if (replay(best)) {
    ++stats.replayed_shots;
  } else {
    fresh_shot(best);
  }
  clear_unshot(best);
  ++stats.shots;
  update_unshot_total();
  stats.seconds += seconds_since(t0);
  return true;
}

// The unit with the most unshot power (the first of equals).
uint32_t Solver::Impl::strongest_unit() const {
  uint32_t best = 0;
  for (uint32_t u = 1; u < u_unshot.size(); ++u)
    if (u_unshot[u] > u_unshot[best]) best = u;
  for (double u : u_unshot) HEMIBAKE_DCHECK(u >= 0.0);
  return best;
}

// Once the unshot power is below `convergence` of the emitted, the unit with the most unshot power
// among those still holding more than kLocalConvergence times `convergence` of their own light
// (radiosity times area), or kNone. The global test alone weighs every surface by the scene's
// power: an attic room lit by an 80 W spot, beside an outside lit by the sun, stopped with 191 of
// the scene's 411 shooters holding over 1 % of their own light unshot, the room's floor and walls
// 0.88 to 0.97 of the path tracer's light (0.97 to 1.04 with the convergence ten times finer,
// 0.96 to 1.02 with this test). Units holding under kLocalFloor times `convergence` of the emitted
// power are left: their light is too dim to matter anywhere.
uint32_t Solver::Impl::lagging_unit() const {
  if (first_pass) return kNone;
  std::vector<double> light(u_unshot.size(), 0.0);
  for (uint32_t e : leaves) light[p_unit[e_patch[e]]] += light_of(e);
  const double floor = kLocalFloor * params.convergence * emitted_power;
  uint32_t best = kNone;
  for (uint32_t u = 0; u < u_unshot.size(); ++u) {
    if (u_unshot[u] <= floor || u_unshot[u] <= kLocalConvergence * params.convergence * light[u]) continue;
    if (best == kNone || u_unshot[u] > u_unshot[best]) best = u;
  }
  return best;
}

// A fresh shot of the unit to every leaf, recorded for a replay while the cache has room (in place
// of the unit's record, which could not be replayed).
void Solver::Impl::fresh_shot(uint32_t unit) {
  ShotRecord record;
  keep_record(unit, {});
  recording = params.shot_cache_mb > 0 ? &record : nullptr;
  record_broken = false;
  const std::vector<uint32_t> receivers = leaves;  // the shot splits leaves as it goes
  if (unit_node[unit] == kNone) {
    shoot_patch(unit_patch[unit], receivers, true);
  } else {
    grow_scratch();
    shoot_cluster(unit_node[unit], receivers, true, 0);
  }
  recording = nullptr;
  if (params.shot_cache_mb > 0 && !record_broken) {
    record.fresh_pieces = record.pieces.size();
    HEMIBAKE_DCHECK(record.consistent());
    keep_record(unit, std::move(record));
  }
}

// The unit has shot all its unshot power.
void Solver::Impl::clear_unshot(uint32_t unit) {
  auto emitted = [&](uint32_t q) {
    if (p_emitter_left.empty() || !p_emitter_left[q]) return;
    p_emitter_left[q] = 0;
    --emitters_left;
  };
  if (unit_node[unit] != kNone) {
    const ClusterNode& c = c_nodes[unit_node[unit]];
    for (uint32_t i = c.begin; i < c.end; ++i) {
      const uint32_t q = cluster_patch[i];
      emitted(q);
      for_leaves(p_root[q], [&](uint32_t e) { e_unshot[e] = glm::dvec3(0.0); });
      p_unshot[q] = 0.0;
    }
  } else {
    const uint32_t p = unit_patch[unit];
    emitted(p);
    for_leaves(p_root[p], [&](uint32_t e) { e_unshot[e] = glm::dvec3(0.0); });
    p_unshot[p] = 0.0;
  }
  u_unshot[unit] = 0.0;
  // What the unit's patches took from one another during its shot (faces of boxes in one cluster)
  // is theirs to shoot next: it was held back from what the shot read and clears.
  for (const std::pair<uint32_t, glm::dvec3>& h : held)
    for_leaves(h.first, [&, gain = h.second](uint32_t leaf) {
      const uint32_t q = e_patch[leaf];
      e_unshot[leaf] += gain;
      p_unshot[q] += channel_sum(gain) * e_area[leaf];
      u_unshot[unit] += channel_sum(gain) * e_area[leaf];
    });
  held.clear();
  shooting_unit = kNone;
}

namespace {

// The first pass's draft of a solve: enough to see where the light goes (pools.cpp).
Params first_pass_params(const Params& p) {
  Params d = p;
  d.resolution = std::min(p.resolution, 50u);
  d.feps = std::max(p.feps, 3e-3);
  d.beps = std::max(p.beps, 0.1);
  d.gather = false;
  return d;
}

}  // namespace

Solver::Solver(const Scene& scene, const Params& params)
    : impl_(params.pools ? std::make_unique<Impl>(scene, first_pass_params(params), nullptr, &params)
                         : std::make_unique<Impl>(scene, params)) {}
Solver::~Solver() = default;

bool Solver::step() {
  const bool more = impl_->step();
  if (impl_->restart) impl_ = Impl::next_pass(*impl_);
  return more;
}

const Stats& Solver::stats() const { return impl_->stats; }

const Stats& Solver::run(const ProgressFn& progress, const CancelToken* cancel) {
  const auto t0 = Clock::now();
  while (true) {
    if (cancel && cancel->cancelled()) {
      impl_->stats.cancelled = true;
      break;
    }
    if (!step()) break;
    if (progress) {
      Progress pr;
      pr.shots = impl_->stats.shots;
      pr.unshot_fraction = impl_->stats.unshot_fraction;
      pr.elements = impl_->stats.elements;
      pr.elapsed_seconds = seconds_since(t0);
      pr.pass = impl_->first_pass ? 1 : impl_->stats.passes;
      pr.passes = impl_->first_pass ? 2 : impl_->stats.passes;
      progress(pr);
    }
  }
  return impl_->stats;
}

}  // namespace hemibake::solver
