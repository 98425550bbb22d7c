// The bake pipeline: the one place that runs a job's method. `hemibake bake`, the server's
// workers, the built-in scenes and the benchmarks all come through here, so a method is chosen,
// parameterised and reported the same way everywhere.
#pragma once

#include "hemibake/baselines/hierarchical.h"
#include "hemibake/baselines/reference.h"
#include "hemibake/protocol/gltf.h"
#include "hemibake/protocol/job.h"
#include "hemibake/solver/solver.h"

#include <cstdint>
#include <functional>
#include <vector>

namespace hemibake::protocol {

/// What a caller hears from a running bake. Every member may be empty or null. All are called on
/// the thread that runs the bake.
struct BakeHooks {
  /// After every shot (aa, classical), about every 0.1 s while hr links and gathers or a reference
  /// traces paths, and once with phase "done".
  std::function<void(const JobProgress&)> progress;
  /// Asked between shots: whether a preview of the current state is wanted now.
  std::function<bool()> preview_wanted;
  /// A preview: the unconverged state with the ambient term, as a baked GLB, or the writer's
  /// error (bake() only).
  std::function<void(std::vector<uint8_t> glb, const std::string& error)> preview;
  /// Called with false when the bake enters a phase without a displayable state (hr throughout, a
  /// reference while it traces), so that preview requests can be answered at once.
  std::function<void(bool possible)> previews_possible;
  /// Checked between shots (and by the baselines about every 0.1 s).
  const solver::CancelToken* cancel = nullptr;
};

/// A solved scene: the radiosity mesh and how it was made.
struct Solution {
  solver::Mesh mesh;
  solver::Stats stats;                      ///< hr: elements, patches, seconds and the end state
  baselines::HierarchicalStats hierarchical;  ///< hr only
  baselines::ReferenceBakeStats reference;    ///< reference only
  bool cancelled() const { return stats.cancelled; }
};

/// Empty when `spec` can bake the document: something gives light (an emitting surface, a light,
/// or the spec's sky), and lights or a sky come with a method that bakes them (aa or classical;
/// the baselines hr and reference know only emitting surfaces). Otherwise a message for the user.
std::string bake_error(const SceneDocument& document, const JobSpec& spec);

/// The scene a spec bakes: the document's, with the spec's sky.
solver::Scene scene_with(const solver::Scene& scene, const JobSpec& spec);

/// Solves `scene` (validate(scene) must be empty) with the spec's method and parameters
/// (apply_params() has accepted them). Cancellation leaves a partial solution with
/// stats.cancelled set.
Solution solve(const solver::Scene& scene, const JobSpec& spec, const BakeHooks& hooks = {});

/// A baked file.
struct BakeOutput {
  Solution solution;
  std::vector<uint8_t> glb;  ///< empty when cancelled or on error
  std::string error;         ///< the writer's, for the user
  double exposure = 0.0;     ///< the exposure COLOR_0 was written with
  ToneCurve tone;            ///< and its tone curve
};

/// Solves scene_of(document) and writes the baked GLB. Previews, when asked for through the
/// hooks, are written the same way from the unconverged state.
BakeOutput bake(const SceneDocument& document, const JobSpec& spec, const BakeHooks& hooks = {});

}  // namespace hemibake::protocol
