// Scene analysis done once before solving: surfaces, groups and shared vertices.
#pragma once

#include "hemibake/solver/solver.h"
#include "hemicube_engine.h"

#include <glm/vec3.hpp>

#include <array>
#include <string>
#include <vector>

namespace hemibake::solver::detail {

struct PreparedScene {
  std::vector<glm::dvec3> normal;             ///< unit normal per patch
  std::vector<double> area;                   ///< per patch
  std::vector<uint32_t> occlusion_group;      ///< per patch: coplanar, edge-connected patches
  std::vector<uint32_t> smoothing_group;      ///< per patch: edge-connected (whole edges, or a part
                                              ///< of one: a T-junction), same material, no crease
  GroupAdjacency adjacency;                   ///< occlusion groups that share an edge
  std::vector<glm::dvec3> vertex_position;    ///< corner vertices, shared within a smoothing group
  std::vector<std::array<uint32_t, 4>> corner_vertex;  ///< per patch
  /// Per patch: the patches of its smoothing group that meet it along a part of an edge only
  /// (T-junctions: a wall piece beside a window, whose edge holds the corners of the pieces above
  /// and below it); their vertices on its edges are joined into its elements' loops (mesh_export).
  std::vector<std::vector<uint32_t>> t_neighbours;
  /// Per patch: the other patches that touch it along a part of an edge (collinear, overlapping
  /// edges) whose vertices there are not its own: other smoothing groups, whatever their plane and
  /// material (a wall's foot on a floor, a roof's ridge), and patches of its group met other than
  /// along a whole shared edge or in a T-junction. Their vertices on its edges become vertices of
  /// its elements' loops, with its own light (mesh_export), so the output has no T-junctions there.
  std::vector<std::vector<uint32_t>> seam_neighbours;
  /// Per patch: its back needs no projection, since something else always hides what it would:
  /// another patch with the same corners in reverse order (the other side of a double-sided
  /// surface), or the front faces of the outward-facing solid it belongs to (edge-connected
  /// patches enclosing a positive signed volume). Open sheets and inward-facing shells (a room's
  /// walls seen from outside) need their backs projected as occluders.
  std::vector<uint8_t> back_hidden;
  /// Per patch: the outward-facing solid whose front faces hide its back (index into solid_lo and
  /// solid_hi, the solid's bounding box), or kNone.
  std::vector<uint32_t> solid;
  std::vector<glm::dvec3> solid_lo, solid_hi;
  std::vector<uint32_t> twin;                 ///< per patch: its other side (the same points facing
                                              ///< the other way: a double-sided surface), or kNone
  /// Closed double-sided meshes (a Blender cube: every edge met by one other face of each side):
  /// per patch, the mesh whose inside it faces, or kNone; per mesh, its bounding box and the
  /// patches of its outside (inside_closed tests points against them). Only what is in a mesh
  /// sees its inside (Solver::Impl::sealed).
  std::vector<uint32_t> inner_solid;
  std::vector<glm::dvec3> closed_lo, closed_hi;
  std::vector<std::vector<uint32_t>> closed_outside;
  double total_area = 0.0;
  double diagonal = 0.0;                      ///< of the scene's bounding box
};

/// Precondition: validate(scene) is empty.
PreparedScene prepare(const Scene& scene);

/// Whether point x lies inside closed double-sided mesh `closed` (PreparedScene::closed_outside):
/// within its box, and a ray from x crosses its outside an odd number of times.
bool inside_closed(const std::vector<Patch>& patches, const PreparedScene& prep, uint32_t closed, const glm::dvec3& x);

/// The lights' and the sky's part of validate(scene) (lights.cpp).
std::string validate_lights(const Scene& scene);

}  // namespace hemibake::solver::detail
