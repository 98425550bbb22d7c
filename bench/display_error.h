// The error of a bake as a viewer displays it: radiosity interpolated over the baked triangles at
// random points on the scene's surfaces, against a path-traced reference at the same points.
// Element centres are not enough: a face left as one flat element has its mean near its centre.
#pragma once

#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace hemibake::bench {

/// A point on an input patch's front side with its reference radiosity.
struct SurfacePoint {
  uint32_t patch = 0;
  glm::dvec3 position{0.0};
  glm::dvec3 normal{0.0};
  glm::dvec3 reference{0.0};  ///< path-traced radiosity
  double std_error = 0.0;     ///< of the reference's channel sum
  uint32_t samples = 0;       ///< paths traced for it
  bool pressed = false;       ///< against a surface that faces it (mark_pressed)
};

struct ReferenceOptions {
  uint32_t points = 300;
  uint64_t seed = 1;
  double max_std_error = 0.015;  ///< trace until the standard error is at most this share of the value
                                 ///< (of a floor of 5 % of the points' mean for dark points)
  uint32_t max_samples = 1u << 17;
  uint32_t threads = 0;          ///< 0 = all cores
};

/// `points` places area-weighted (seeded) on the patches that emit nothing, each traced until its
/// standard error meets `max_std_error` or `max_samples` paths.
std::vector<SurfacePoint> reference_points(const solver::Scene& scene, const ReferenceOptions& options);

/// Traces the reference at `points` (patch, position and normal set) as reference_points does.
/// Points already traced go on from their samples: a second call only traces those whose standard
/// error is still above the options' (before, it restarted their sums but not their sample counts,
/// and read them at a fraction of their light).
void trace_reference(const solver::Scene& scene, std::vector<SurfacePoint>& points, const ReferenceOptions& options);

/// The length of the diagonal of the box around every patch's corners (0 for no patch).
double scene_diagonal(const solver::Scene& scene);

/// Marks the points pressed against a surface that faces them: in contact, within 1e-6 of the
/// scene's diagonal, with another patch facing the other way (within 2.6 degrees) whose polygon
/// holds the point (a box's bottom on a floor, a ceiling over a wall box's top, the floor under a
/// wall box). The other side of a double-sided patch (the same corners) is no such surface. Two
/// one-sided plates back to back look the same here; displayed_error tells them apart by the
/// reference's light. reference_points calls it; points read back from a file need it again. Every
/// point against every patch: about 40 M pairs for the atrium at 400 points.
/// Points must name a patch of `scene`.
void mark_pressed(const solver::Scene& scene, std::vector<SurfacePoint>& points);

/// The error over some of the points (all zero when there are none).
struct ErrorSummary {
  uint32_t points = 0;      ///< how many points it is over
  double median = 0.0;      ///< of the points' relative errors (DisplayError::errors)
  double p90 = 0.0;         ///< 90th percentile of them
  double max = 0.0;         ///< the largest
  double mean_ratio = 0.0;  ///< sum of bake / sum of reference over them
};

struct DisplayError {
  double median = 0.0;   ///< relative error of the channel sum, |bake - reference| / max(reference, floor)
  double p90 = 0.0;
  double max = 0.0;
  double mean_ratio = 0.0;  ///< sum of bake / sum of reference over the points (overall brightness)
  double worst_std_error = 0.0;  ///< largest relative standard error of the reference
  uint32_t missed = 0;   ///< points no baked triangle covers (shown as 0: an unwritten closed mesh's inside)
  double missed_light = 0.0;  ///< the reference's light on those, as a share of its light on all points
  /// Over the points a viewer can see: all but those with no light at all in the reference that
  /// are pressed against a surface (SurfacePoint::pressed, set by mark_pressed) or that no baked
  /// triangle covers (the inside of a closed mesh, which the writer leaves out). The fields above
  /// count every point; the points no one sees pull their median toward 0, and a bake that lights
  /// them gets errors no one sees. "No light" is the reference's exact 0: a point whose first 512
  /// paths find none is traced no further, so a dim point at the edge of a contact can be left out.
  ErrorSummary seen;
  std::vector<double> errors;  ///< per point, in the order of the points
  std::vector<uint8_t> hidden;  ///< per point: left out of `seen`
};

/// The error of `baked` (triangles in world space with per-vertex radiosity, as read_baked_mesh
/// gives, or any mesh whose element loops are its displayed polygons) at `points`. The floor of the
/// relative error is 5 % of the points' mean reference, so points in an umbra do not dominate.
DisplayError displayed_error(const std::vector<SurfacePoint>& points, const solver::Mesh& baked);

/// How far off a triangle's plane a point may lie and still be on it, besides 1e-3 of the
/// triangle's size: 1e-4 of the extent of `baked` (written positions are quantized: Draco's 14 bits
/// move small elements off their plane by up to 3e-5 of the extent).
double plane_slack(const solver::Mesh& baked);

/// The value `baked` displays at a point, interpolated barycentrically over the triangle that
/// contains it on the side facing `normal` (within `slack`, plane_slack(baked)); false if none
/// does. An element loop of more than three vertices (a solver mesh) is shown as the writer shows
/// it: a fan from its centre.
bool displayed_value(const solver::Mesh& baked, const glm::dvec3& position, const glm::dvec3& normal, double slack,
                     glm::dvec3& out);

}  // namespace hemibake::bench
