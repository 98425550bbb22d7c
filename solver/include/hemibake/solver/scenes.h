// Built-in scenes: the Cornell box and analytic test boxes.
#pragma once

#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

namespace hemibake::solver {

/// Material ids used by make_cornell_box().
enum CornellMaterial : uint32_t { kCornellWhite = 0, kCornellRed = 1, kCornellGreen = 2, kCornellLight = 3 };

/// The Cornell box from the Cornell University Program of Computer Graphics' published
/// measurements (millimetres, RGB reduction of the measured spectra), open at the front (z = 0).
/// The ceiling is cut into eight quads around the light so that nothing overlaps; the slightly
/// twisted walls are split into two triangles each.
Scene make_cornell_box();

/// An axis-aligned closed box [0, size]^3 seen from inside, each wall a grid of `cells` x `cells`
/// quads, every patch with the same reflectance and emission. With `block`, a smaller closed box
/// (faces outward, same material) floats in the middle. Radiosity is E / (1 - rho) everywhere.
Scene make_closed_box(double size, uint32_t cells, const glm::dvec3& reflectance,
                      const glm::dvec3& emission, bool block);

/// A furnished room like the paper's interrogation chamber (its Figure 10): a 6 x 3 x 5 m room
/// with a table, chairs, a cabinet, a bench and a door, lit by ceiling panels; every face is a grid
/// of small patches, about `target_patches` in all (the paper's had 6276). Deterministic.
Scene make_furnished_room(uint32_t target_patches = 6300);

/// A cluttered room built the way a user's export is: a 8 x 3 x 6 m room whose walls, floor and
/// ceiling are 0.25 m tiles, lit by six ceiling panels; six tables and 24 chairs with legs, five
/// cabinets, and `small_boxes` boxes 4 to 18 cm wide on the tables and the floor (each face one
/// patch). Deterministic (its own generator, seed `seed`).
Scene make_cluttered_room(uint32_t small_boxes = 390, uint32_t seed = 1);

/// Many small emitters, like an engine's example scene lit by lava spheres: a 20 x 20 m floor (one
/// quad), 36 objects (tessellated spheres and boxes) and six emissive spheres, about 20 000 patches
/// in all, open to the sky (nothing else emits). Deterministic.
Scene make_lava_field();

/// A Sponza-like atrium, for big inputs: a 24 x 10 m court open to the sky between two storeys of
/// arcades (columns, arches, balustrades of turned balusters, curtains hung behind the upper
/// arches), galleries with benches, a fountain and planters with shrubs; lit by a uniform sky and a
/// sun (a directional light). 126 816 triangles. Deterministic.
Scene make_atrium();

/// A finely tessellated object in a small room: a 4 x 3 x 5 m room (0.5 m tiles) lit by a ceiling
/// panel, with a UV sphere of `rings` x `segments` (200 x 400: 159 200 triangles) on its floor.
Scene make_sphere_room(int rings = 200, int segments = 400);

/// Appends a quad (counter-clockwise seen from the front) as one patch, or as two triangles when
/// its corners are not coplanar.
void add_quad(Scene& scene, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c,
              const glm::dvec3& d, const glm::dvec3& reflectance, const glm::dvec3& emission,
              uint32_t material);

/// Appends a UV sphere of `rings` x `segments` triangles facing outward, one patch each.
void add_uv_sphere(Scene& scene, const glm::dvec3& centre, double radius, int rings, int segments,
                   const glm::dvec3& reflectance, const glm::dvec3& emission, uint32_t material);

}  // namespace hemibake::solver
