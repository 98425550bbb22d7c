// A Monte Carlo reference for radiosity, independent of any hemicube: path tracing of the diffuse
// scene with Embree's ray casting. Emitting patches, punctual lights and the sky all light it.
#pragma once

#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

namespace hemibake::baselines {

struct ReferencePoint {
  glm::dvec3 radiosity{0.0};  ///< estimate
  glm::dvec3 std_error{0.0};  ///< its standard error per channel
};

class Reference {
 public:
  explicit Reference(const solver::Scene& scene);
  ~Reference();
  /// Radiosity leaving patch `patch` at point `x` (on it), from `samples` cosine-weighted paths
  /// (Russian roulette on reflectance). Deterministic for a given `seed`.
  ReferencePoint radiosity_at(uint32_t patch, const glm::dvec3& x, uint32_t samples, uint64_t seed) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct ReferenceBakeStats {
  double largest_std_error = 0.0;  ///< over vertices, mean of the channels
  double seconds = 0.0;
  bool cancelled = false;
};

/// Replaces the vertex radiosity of `mesh` (a solution of `scene`) by path-traced estimates from
/// `samples` paths each (a vertex is traced from the patch of an element it bounds), and each
/// element's radiosity by the mean of its corners. Runs on `threads` threads (0 = all cores);
/// the result does not depend on their number. `progress(fraction of vertices done)` is called
/// from the calling thread about every 0.1 s; a cancelled run leaves `mesh` partly updated and
/// sets `cancelled`.
ReferenceBakeStats apply_reference(const solver::Scene& scene, solver::Mesh& mesh, uint32_t samples, uint32_t threads,
                                   const std::function<void(double)>& progress = {},
                                   const solver::CancelToken* cancel = nullptr);

}  // namespace hemibake::baselines
