// Form factors from a point to polygons through a hemicube, outside of a solve: for checking the
// hemicube against closed forms and for benchmarks.
#pragma once

#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

#include <span>
#include <vector>

namespace hemibake::solver {

/// A convex planar polygon as a receiver. Polygons that share a `group` lie in one plane and never
/// overlap (pieces of one surface): their pixel coverages add instead of occluding each other.
struct ReceiverPolygon {
  std::vector<glm::dvec3> corners;  ///< counter-clockwise seen from its front; 3 or more
  uint32_t group = kNone;           ///< kNone: a group of its own
};

/// Form factors from a differential area at `eye` with unit normal `normal` to each polygon, with
/// the polygons occluding one another, as a hemicube of the given method and resolution computes
/// them. Polygons with a common edge (bitwise equal corners) are neighbours: where both cover a
/// pixel their coverages add, as for the patches of a scene. Polygons facing away from the eye get
/// 0. The hemicube's orientation about the normal is fixed by `up_hint` (any vector not parallel
/// to the normal). With `receivers` (indices into `polygons`), the view is kept to those polygons'
/// pixels, as a solve's shot to a few receivers keeps it: theirs are computed, the rest get 0.
std::vector<double> hemicube_form_factors(const glm::dvec3& eye, const glm::dvec3& normal,
                                          std::span<const ReceiverPolygon> polygons, Method method,
                                          uint32_t resolution,
                                          const glm::dvec3& up_hint = glm::dvec3(0.0, 0.0, 1.0),
                                          std::span<const uint32_t> receivers = {});

/// The solid angle of each polygon visible from `eye`, with the polygons occluding one another,
/// as the full cube of a volume cluster computes it (six faces of resolution x resolution pixels;
/// the top one facing `normal`, turned about it by `up_hint`). Polygons facing away get 0.
std::vector<double> cube_solid_angles(const glm::dvec3& eye, std::span<const ReceiverPolygon> polygons, Method method,
                                      uint32_t resolution, const glm::dvec3& normal = glm::dvec3(0.0, 0.0, 1.0),
                                      const glm::dvec3& up_hint = glm::dvec3(0.0, 1.0, 0.0));

/// The exact form factor from a differential area at `eye` with unit normal `normal` to a polygon
/// that lies wholly in front of it (Lambert's formula: (1 / 2pi) sum_i beta_i cos gamma_i).
double point_polygon_form_factor(const glm::dvec3& eye, const glm::dvec3& normal,
                                 std::span<const glm::dvec3> polygon);

}  // namespace hemibake::solver
