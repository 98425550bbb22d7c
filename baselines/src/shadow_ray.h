// One shadow ray through Embree, shared by the baselines.
#pragma once

#include <embree3/rtcore.h>
#include <glm/vec3.hpp>

#include <cmath>
#include <limits>

namespace hemibake::baselines::detail {

// True when no surface of `scene` lies within `length` of `from` along the unit `dir` (`length`
// may be infinite).
inline bool unoccluded(RTCScene scene, const glm::dvec3& from, const glm::dvec3& dir, double length) {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r{};
  r.org_x = static_cast<float>(from.x);
  r.org_y = static_cast<float>(from.y);
  r.org_z = static_cast<float>(from.z);
  r.dir_x = static_cast<float>(dir.x);
  r.dir_y = static_cast<float>(dir.y);
  r.dir_z = static_cast<float>(dir.z);
  r.tnear = 0.0f;
  r.tfar = std::isfinite(length) ? static_cast<float>(length) : std::numeric_limits<float>::infinity();
  r.mask = 0xffffffffu;
  rtcOccluded1(scene, &ctx, &r);
  return r.tfar >= 0.0f;
}

}  // namespace hemibake::baselines::detail
