// A Monte Carlo reference for radiosity, independent of any hemicube: path tracing of the diffuse
// scene with Embree's ray casting.
#pragma once

#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

#include <cstdint>
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

}  // namespace hemibake::baselines
