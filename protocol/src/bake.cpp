#include "hemibake/protocol/bake.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace hemibake::protocol {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

void tell(const BakeHooks& hooks, const JobProgress& p) {
  if (hooks.progress) hooks.progress(p);
}

// The shooting phase's progress. Unshot power falls roughly geometrically, so the fraction done is
// log(u) / log(target), and the time left elapsed * log(u / target) / log(1 / u). The quick first
// pass of a solve that looks for light pools (solver::Params::pools) counts as its first tenth.
JobProgress shooting_progress(const solver::Progress& p, double target) {
  JobProgress out;
  out.phase = "shooting";
  out.shots = p.shots;
  out.unshot_fraction = p.unshot_fraction;
  out.elements = p.elements;
  out.elapsed_seconds = p.elapsed_seconds;
  constexpr double kFirstPassShare = 0.1, kFirstPassTarget = 0.02;
  const bool first = p.passes > 1 && p.pass == 1;
  const double goal = first ? std::max(target, kFirstPassTarget) : target;
  const double done = p.unshot_fraction >= 1.0 ? 0.0
                      : p.unshot_fraction <= goal ? 1.0
                                                  : std::log(p.unshot_fraction) / std::log(goal);
  if (first) {
    out.fraction = kFirstPassShare * done;
    return out;  // no time left to tell yet
  }
  if (p.unshot_fraction > target && p.unshot_fraction < 1.0)
    out.eta_seconds = p.elapsed_seconds * std::log(p.unshot_fraction / target) / std::log(1.0 / p.unshot_fraction);
  out.fraction = p.passes > 1 ? kFirstPassShare + (1.0 - kFirstPassShare) * done : done;
  return out;
}

Solution solve_hierarchical(const solver::Scene& scene, const JobSpec& spec, const BakeHooks& hooks, Clock::time_point t0) {
  if (hooks.previews_possible) hooks.previews_possible(false);
  baselines::HierarchicalParams hp;
  hp.feps = spec.params.feps;
  hp.aeps = spec.params.aeps;
  hp.rays = spec.rays;
  hp.threads = spec.params.threads;
  Solution s;
  s.mesh = baselines::solve_hierarchical(
      scene, hp, s.hierarchical,
      [&](const baselines::HierarchicalProgress& p) {
        JobProgress out;
        out.phase = p.linking ? "linking" : "gathering";
        out.fraction = p.fraction;
        out.unshot_fraction = p.linking ? 1.0 : 0.0;
        out.links = p.links;
        out.iterations = p.iterations;
        out.hierarchical = true;
        out.elapsed_seconds = seconds_since(t0);
        tell(hooks, out);
      },
      hooks.cancel);
  // hr has no shots: its statistics are the mesh's and the end state.
  s.stats.cancelled = s.hierarchical.cancelled;
  s.stats.converged = !s.hierarchical.cancelled;
  s.stats.unshot_fraction = 0.0;
  s.stats.elements = s.hierarchical.elements;
  s.stats.patches = scene.patches.size();
  s.stats.seconds = s.hierarchical.seconds;
  return s;
}

// aa and classical, and the aa solve under a reference. `document` (may be null) is what previews
// are written from.
Solution solve_hemicube(const solver::Scene& scene, const JobSpec& spec, const BakeHooks& hooks,
                        const SceneDocument* document) {
  const solver::Params params = solver_params(spec);
  solver::Solver solver(scene, params);
  solver.run(
      [&](const solver::Progress& p) {
        if (document != nullptr && hooks.preview && hooks.preview_wanted && hooks.preview_wanted()) {
          // The current state with the ambient term, so that it is displayable.
          auto written = write_baked_glb(*document, solver.mesh(true), spec.method, params, solver.stats(), spec.write);
          hooks.preview(std::move(written.glb), written.error);
        }
        tell(hooks, shooting_progress(p, params.convergence));
      },
      hooks.cancel);
  Solution s;
  s.stats = solver.stats();
  s.mesh = solver.mesh();
  return s;
}

// Replaces the aa solution's vertex radiosity by path-traced estimates.
void trace_reference(const solver::Scene& scene, const JobSpec& spec, const BakeHooks& hooks, Clock::time_point t0,
                     Solution& s) {
  if (hooks.previews_possible) hooks.previews_possible(false);
  s.reference = baselines::apply_reference(
      scene, s.mesh, spec.samples, spec.params.threads,
      [&](double fraction) {
        JobProgress out;
        out.phase = "tracing";
        out.fraction = fraction;
        out.shots = s.stats.shots;
        out.unshot_fraction = 0.0;
        out.elements = s.stats.elements;
        out.elapsed_seconds = seconds_since(t0);
        tell(hooks, out);
      },
      hooks.cancel);
  s.stats.cancelled = s.reference.cancelled;
}

Solution solve_with(const solver::Scene& scene, const JobSpec& spec, const BakeHooks& hooks, const SceneDocument* document) {
  const auto t0 = Clock::now();
  Solution s;
  if (spec.method == Method::kHierarchical) {
    s = solve_hierarchical(scene, spec, hooks, t0);
  } else {
    s = solve_hemicube(scene, spec, hooks, document);
    if (spec.method == Method::kReference && !s.stats.cancelled) trace_reference(scene, spec, hooks, t0, s);
  }
  JobProgress done;
  done.phase = "done";
  done.fraction = 1.0;
  done.shots = s.stats.shots;
  done.unshot_fraction = s.stats.unshot_fraction;
  done.elements = s.stats.elements;
  done.eta_seconds = 0.0;
  done.elapsed_seconds = seconds_since(t0);
  tell(hooks, done);
  return s;
}

}  // namespace

std::string bake_error(const SceneDocument& document, const JobSpec& spec) {
  const solver::Scene& scene = scene_of(document);
  if (spec.method == Method::kHierarchical && (!scene.lights.empty() || spec.sky != glm::dvec3(0.0)))
    return std::string("method ") + to_string(spec.method) +
           " bakes emitting surfaces only; KHR_lights_punctual lights and the sky are baked by aa, classical and reference";
  if (spec.sky != glm::dvec3(0.0)) return {};
  return bake_error(document);
}

solver::Scene scene_with(const solver::Scene& scene, const JobSpec& spec) {
  solver::Scene out = scene;
  out.sky = spec.sky;
  return out;
}

Solution solve(const solver::Scene& scene, const JobSpec& spec, const BakeHooks& hooks) {
  if (spec.sky != scene.sky) return solve_with(scene_with(scene, spec), spec, hooks, nullptr);
  return solve_with(scene, spec, hooks, nullptr);
}

BakeOutput bake(const SceneDocument& document, const JobSpec& spec, const BakeHooks& hooks) {
  BakeOutput out;
  if (spec.sky != scene_of(document).sky) out.solution = solve_with(scene_with(scene_of(document), spec), spec, hooks, &document);
  else out.solution = solve_with(scene_of(document), spec, hooks, &document);
  if (out.solution.cancelled()) return out;
  auto written = write_baked_glb(document, out.solution.mesh, spec.method, solver_params(spec), out.solution.stats, spec.write);
  out.glb = std::move(written.glb);
  out.error = std::move(written.error);
  out.exposure = written.exposure;
  out.tone = written.tone;
  return out;
}

}  // namespace hemibake::protocol
