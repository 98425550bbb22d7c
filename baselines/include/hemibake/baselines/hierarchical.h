// Hierarchical radiosity (Hanrahan, Salzman and Aupperle 1991), the baseline the paper compares
// against: quadtree elements, links refined by a form-factor oracle (FEPS) down to AEPS, visibility
// by ray casting (Embree) with a number of rays per link, Jacobi gathering with push-pull.
#pragma once

#include "hemibake/solver/solver.h"

#include <cstdint>
#include <functional>

namespace hemibake::baselines {

struct HierarchicalParams {
  double feps = 1e-3;        ///< refine a link while its estimated form factor exceeds this
  double aeps = 1e-4;        ///< smallest element area, as a fraction of the scene's area
  uint32_t rays = 4;         ///< visibility rays per link
  double tolerance = 1e-4;   ///< stop when no element's radiosity changes by more than this
                             ///< fraction of the largest radiosity
  uint32_t max_iterations = 100;
  uint32_t threads = 0;      ///< 0 = hardware concurrency; results do not depend on it
};

struct HierarchicalStats {
  uint64_t links = 0;
  uint64_t elements = 0;     ///< leaves
  uint32_t iterations = 0;
  double seconds = 0.0;
  double seconds_linking = 0.0;
  bool cancelled = false;
};

/// Reported while linking (fraction of patch pairs done) and after each gathering iteration.
struct HierarchicalProgress {
  bool linking = true;
  double fraction = 0.0;     ///< linking: patch pairs refined / all; solving: iterations / max
  uint64_t links = 0;
  uint32_t iterations = 0;
  double elapsed_seconds = 0.0;
};
using HierarchicalProgressFn = std::function<void(const HierarchicalProgress&)>;

/// Solves `scene` and returns its leaves as a mesh (vertices shared by position; no hanging
/// vertices in the loops). Precondition: validate(scene) is empty. `progress` is called from the
/// calling thread about every 0.1 s; `cancel` is checked as often, and a cancelled solve returns an
/// empty mesh with stats.cancelled set.
solver::Mesh solve_hierarchical(const solver::Scene& scene, const HierarchicalParams& params, HierarchicalStats& stats,
                                const HierarchicalProgressFn& progress = {}, const solver::CancelToken* cancel = nullptr);

}  // namespace hemibake::baselines
