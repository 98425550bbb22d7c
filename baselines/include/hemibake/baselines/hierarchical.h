// Hierarchical radiosity (Hanrahan, Salzman and Aupperle 1991), the baseline the paper compares
// against: quadtree elements, links refined by a form-factor oracle (FEPS) down to AEPS, visibility
// by ray casting (Embree) with a number of rays per link, Jacobi gathering with push-pull.
#pragma once

#include "hemibake/solver/solver.h"

#include <cstdint>

namespace hemibake::baselines {

struct HierarchicalParams {
  double feps = 1e-3;        ///< refine a link while its estimated form factor exceeds this
  double aeps = 1e-4;        ///< smallest element area, as a fraction of the scene's area
  uint32_t rays = 4;         ///< visibility rays per link
  double tolerance = 1e-4;   ///< stop when no element's radiosity changes by more than this
                             ///< fraction of the largest radiosity
  uint32_t max_iterations = 100;
};

struct HierarchicalStats {
  uint64_t links = 0;
  uint64_t elements = 0;     ///< leaves
  uint32_t iterations = 0;
  double seconds = 0.0;
  double seconds_linking = 0.0;
};

/// Solves `scene` and returns its leaves as a mesh (vertices shared by position; no hanging
/// vertices in the loops). Precondition: validate(scene) is empty.
solver::Mesh solve_hierarchical(const solver::Scene& scene, const HierarchicalParams& params, HierarchicalStats& stats);

}  // namespace hemibake::baselines
