// Input checks and the one-off analysis of a scene: which patches form one surface.
#include "scene_prep.h"

#include "geometry.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <glm/vector_relational.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <sstream>
#include <tuple>
#include <unordered_map>

namespace hemibake::solver {
namespace {

// Patches meeting at less than this angle are one smooth surface for vertex averaging (and at
// under 90 degrees where the input's vertices there are one: same_input_vertices).
constexpr double kCreaseCos = 0.866;  // 30 degrees

bool finite(const glm::dvec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

glm::dvec3 polygon_normal(const Patch& p) {
  glm::dvec3 n(0.0);
  for (uint32_t i = 0; i < p.corner_count; ++i) {
    const glm::dvec3& a = p.corners[i];
    const glm::dvec3& b = p.corners[(i + 1) % p.corner_count];
    n += glm::cross(a, b);
  }
  return 0.5 * n;  // length is the area
}

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  }
  void unite(uint32_t a, uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

struct PositionHash {
  size_t operator()(const glm::dvec3& p) const {
    uint64_t h = 1469598103934665603ull;
    for (int i = 0; i < 3; ++i) {
      uint64_t bits;
      const double v = p[i] == 0.0 ? 0.0 : p[i];  // -0 and +0 are one position
      std::memcpy(&bits, &v, sizeof bits);
      h = (h ^ bits) * 1099511628211ull;
    }
    return static_cast<size_t>(h);
  }
};

// Patches that touch: an edge of one overlaps an edge of the other along a line.
struct Touch {
  uint32_t a, b;       ///< a < b
  bool folded;         ///< the edges run the same way (GroupAdjacency)
  glm::dvec3 p, q;     ///< where they overlap
};

std::vector<Touch> touching_patches(const Scene& scene, double diagonal) {
  struct Edge {
    glm::dvec3 p, q;
    uint32_t patch;
  };
  std::vector<Edge> edges;
  for (uint32_t i = 0; i < scene.patches.size(); ++i) {
    const Patch& pa = scene.patches[i];
    for (uint32_t c = 0; c < pa.corner_count; ++c)
      edges.push_back({pa.corners[c], pa.corners[(c + 1) % pa.corner_count], i});
  }
  const double tol = 1e-7 * diagonal;
  // Whether f lies on e's line and overlaps it, and where (`from`, `to`).
  auto overlap = [tol](const Edge& e, const Edge& f, glm::dvec3& from, glm::dvec3& to) {
    const glm::dvec3 d = e.q - e.p;
    const double len = glm::length(d);
    if (len <= tol) return false;
    const glm::dvec3 u = d / len;
    for (const glm::dvec3& x : {f.p, f.q}) {
      const glm::dvec3 r = x - e.p;
      if (glm::length(r - u * glm::dot(r, u)) > tol) return false;
    }
    const double t0 = glm::dot(f.p - e.p, u), t1 = glm::dot(f.q - e.p, u);
    const double lo = std::max(std::min(t0, t1), 0.0), hi = std::min(std::max(t0, t1), len);
    from = e.p + u * lo;
    to = e.p + u * hi;
    return hi - lo > tol;
  };
  // A uniform grid over the scene, its cells twice as wide as the shorter edges (the lower quartile
  // of their lengths): an edge is listed in the cells along it, piece by piece, so that a long edge
  // does not fill its bounding box's cells, and a cell holds few edges even where thousands of
  // small patches crowd one strip (a floor edged with 20 000 tiles: a cell a cube root of the edge
  // count wide held thousands there, and the tests within cells took seconds). An edge crossing more
  // than kMaxSteps cells is tested against all edges instead.
  constexpr size_t kMaxSteps = 4096;
  glm::dvec3 lo(std::numeric_limits<double>::max());
  std::vector<double> lengths;
  lengths.reserve(edges.size());
  for (const Edge& e : edges) {
    lo = glm::min(lo, glm::min(e.p, e.q));
    lengths.push_back(glm::distance(e.p, e.q));
  }
  double cell = diagonal;
  if (!lengths.empty()) {
    std::nth_element(lengths.begin(), lengths.begin() + lengths.size() / 4, lengths.end());
    cell = 2.0 * lengths[lengths.size() / 4];
  }
  cell = std::clamp(cell, std::max(tol * 16, diagonal / 4096), std::max(diagonal, tol * 16));
  // Long edges among many short ones (a fan of thin triangles) would list each edge in thousands of
  // cells: wider cells until the listings are at most kListings per edge on average.
  constexpr double kListings = 64.0;
  for (;;) {
    double listed = 0.0;
    for (const Edge& e : edges) listed += std::min(static_cast<double>(kMaxSteps), glm::distance(e.p, e.q) / cell + 1.0);
    if (listed <= kListings * static_cast<double>(edges.size()) + 1024.0 || cell >= diagonal) break;
    cell *= 2.0;
  }
  constexpr int64_t kAxis = (int64_t{1} << 21) - 1;
  using I64Vec3 = glm::vec<3, int64_t>;
  auto cell_of = [&](const glm::dvec3& x) {
    return glm::clamp(I64Vec3(glm::floor((x - lo) / cell)), I64Vec3(0), I64Vec3(kAxis));
  };
  std::unordered_map<uint64_t, std::vector<uint32_t>> cells;
  std::vector<uint32_t> big;
  std::vector<uint64_t> keys;
  for (uint32_t i = 0; i < edges.size(); ++i) {
    const glm::dvec3 d = edges[i].q - edges[i].p;
    const size_t steps = static_cast<size_t>(std::ceil(glm::length(d) / cell)) + 1;
    if (steps > kMaxSteps) {
      big.push_back(i);
      continue;
    }
    keys.clear();
    for (size_t k = 0; k < steps; ++k) {
      const glm::dvec3 x0 = edges[i].p + d * (static_cast<double>(k) / steps);
      const glm::dvec3 x1 = edges[i].p + d * (static_cast<double>(k + 1) / steps);
      const I64Vec3 a = cell_of(glm::min(x0, x1) - tol), b = cell_of(glm::max(x0, x1) + tol);
      for (int64_t x = a.x; x <= b.x; ++x)
        for (int64_t y = a.y; y <= b.y; ++y)
          for (int64_t z = a.z; z <= b.z; ++z)
            keys.push_back((static_cast<uint64_t>(x) << 42) | (static_cast<uint64_t>(y) << 21) | static_cast<uint64_t>(z));
    }
    std::sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    for (uint64_t key : keys) cells[key].push_back(i);
  }
  std::vector<Touch> pairs;
  auto test = [&](uint32_t i, uint32_t j) {
    const Edge& e = edges[i];
    const Edge& f = edges[j];
    if (e.patch == f.patch) return;
    glm::dvec3 from, to;
    if (overlap(e, f, from, to) || overlap(f, e, from, to))
      pairs.push_back({std::min(e.patch, f.patch), std::max(e.patch, f.patch), glm::dot(e.q - e.p, f.q - f.p) > 0.0, from, to});
  };
  for (const auto& [key, list] : cells)
    for (size_t x = 0; x < list.size(); ++x)
      for (size_t y = x + 1; y < list.size(); ++y) test(list[x], list[y]);
  for (uint32_t i : big)
    for (uint32_t j = 0; j < edges.size(); ++j)
      if (j != i) test(i, j);
  auto tuple = [](const Touch& t) { return std::tuple(t.a, t.b, t.folded); };
  std::sort(pairs.begin(), pairs.end(), [&](const Touch& x, const Touch& y) { return tuple(x) < tuple(y); });
  pairs.erase(std::unique(pairs.begin(), pairs.end(), [&](const Touch& x, const Touch& y) { return tuple(x) == tuple(y); }),
              pairs.end());
  return pairs;
}

}  // namespace

std::string validate(const Params& p) {
  std::ostringstream err;
  if (p.resolution < 4 || p.resolution > 4096 || p.resolution % 2 != 0)
    err << "resolution must be an even number from 4 to 4096 (got " << p.resolution << ")";
  else if (!(p.feps > 0.0) || !std::isfinite(p.feps))
    err << "feps must be a positive number (got " << p.feps << ")";
  else if (!(p.aeps > 0.0 && p.aeps < 1.0))
    err << "aeps must lie between 0 and 1 (got " << p.aeps << ")";
  else if (!(p.beps > 0.0) || !std::isfinite(p.beps))
    err << "beps must be a positive number (got " << p.beps << ")";
  else if (!(p.convergence > 0.0 && p.convergence < 1.0))
    err << "convergence must lie between 0 and 1 (got " << p.convergence << ")";
  else if (p.max_elements < 1)
    err << "max_elements must be at least 1";
  else if (p.threads > 1024)
    err << "threads must be at most 1024 (got " << p.threads << ")";
  else if (!(p.shooter_size > 0.0) || !std::isfinite(p.shooter_size))
    err << "shooter_size must be a positive number (got " << p.shooter_size << ")";
  else if (!(p.cluster_size >= 0.0) || !std::isfinite(p.cluster_size))
    err << "cluster_size must be 0 or a positive number (got " << p.cluster_size << ")";
  return err.str();
}

std::string validate(const Scene& scene) {
  std::ostringstream err;
  if (scene.patches.empty()) return "the scene has no patches";
  if (scene.patches.size() >= kNone / 8) return "the scene has too many patches";
  for (size_t i = 0; i < scene.patches.size(); ++i) {
    const Patch& p = scene.patches[i];
    err << "patch " << i << ": ";
    if (p.corner_count != 3 && p.corner_count != 4) {
      err << "has " << p.corner_count << " corners; only triangles and quads are supported";
      return err.str();
    }
    double size = 0.0;
    for (uint32_t c = 0; c < p.corner_count; ++c) {
      if (!finite(p.corners[c])) {
        err << "corner " << c << " is not a finite point";
        return err.str();
      }
      size = std::max(size, glm::length(p.corners[c] - p.corners[(c + 1) % p.corner_count]));
    }
    const glm::dvec3 n = polygon_normal(p);
    const double area = glm::length(n);
    if (!(size > 0.0) || !(area > 1e-12 * size * size)) {
      err << "is degenerate (zero area)";
      return err.str();
    }
    const glm::dvec3 unit = n / area;
    for (uint32_t c = 0; c < p.corner_count; ++c) {
      if (std::abs(glm::dot(unit, p.corners[c] - p.corners[0])) > 1e-4 * size) {
        err << "is not planar (corner " << c << " lies off the plane of the others)";
        return err.str();
      }
      const glm::dvec3& a = p.corners[c];
      const glm::dvec3& b = p.corners[(c + 1) % p.corner_count];
      const glm::dvec3& d = p.corners[(c + 2) % p.corner_count];
      if (glm::dot(glm::cross(b - a, d - b), unit) <= 0.0) {
        err << "is not convex (or has repeated corners)";
        return err.str();
      }
    }
    for (int ch = 0; ch < 3; ++ch) {
      if (!(p.reflectance[ch] >= 0.0 && p.reflectance[ch] < 1.0)) {
        err << "reflectance " << p.reflectance[ch] << " is outside [0, 1)";
        return err.str();
      }
      if (!(p.emission[ch] >= 0.0) || !std::isfinite(p.emission[ch])) {
        err << "emission " << p.emission[ch] << " is negative or not finite";
        return err.str();
      }
    }
    err.str("");
  }
  return detail::validate_lights(scene);  // lights.cpp
}

namespace detail {
namespace {

// Corners of a patch: the ids of their points.
using PointIds = std::vector<std::array<uint32_t, 4>>;
// Per edge (its two point ids as a key), the patches that have it.
using EdgePatches = std::unordered_map<uint64_t, std::vector<uint32_t>>;

// Normals, areas, total area and the bounding box's diagonal.
void measure(const Scene& scene, PreparedScene& out) {
  const size_t n = scene.patches.size();
  out.normal.resize(n);
  out.area.resize(n);
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
  for (size_t i = 0; i < n; ++i) {
    const Patch& p = scene.patches[i];
    const glm::dvec3 nn = polygon_normal(p);
    out.area[i] = glm::length(nn);
    out.normal[i] = nn / out.area[i];
    out.total_area += out.area[i];
    for (uint32_t c = 0; c < p.corner_count; ++c) {
      lo = glm::min(lo, p.corners[c]);
      hi = glm::max(hi, p.corners[c]);
    }
  }
  out.diagonal = glm::length(hi - lo);
}

// Corners with bitwise equal positions are one point; edges between such points are shared.
PointIds point_ids(const Scene& scene) {
  const size_t n = scene.patches.size();
  std::unordered_map<glm::dvec3, uint32_t, PositionHash> point_id;
  PointIds point_of(n);
  for (size_t i = 0; i < n; ++i) {
    const Patch& p = scene.patches[i];
    for (uint32_t c = 0; c < p.corner_count; ++c) {
      glm::dvec3 key = p.corners[c];
      for (int k = 0; k < 3; ++k)
        if (key[k] == 0.0) key[k] = 0.0;
      point_of[i][c] = point_id.try_emplace(key, static_cast<uint32_t>(point_id.size())).first->second;
    }
  }
  return point_of;
}

EdgePatches patches_by_edge(const Scene& scene, const PointIds& point_of) {
  EdgePatches edge_patches;
  for (size_t i = 0; i < scene.patches.size(); ++i) {
    const uint32_t cc = scene.patches[i].corner_count;
    for (uint32_t c = 0; c < cc; ++c) {
      uint32_t a = point_of[i][c], b = point_of[i][(c + 1) % cc];
      if (a > b) std::swap(a, b);
      edge_patches[(static_cast<uint64_t>(a) << 32) | b].push_back(static_cast<uint32_t>(i));
    }
  }
  return edge_patches;
}

// Whether patches a and b have the same input vertex (Patch::vertex, known) at both ends of their
// common edge `key`: the exporter wrote one vertex, one normal, for both faces there.
bool same_input_vertices(const Scene& scene, const PointIds& point_of, uint32_t a, uint32_t b, uint64_t key) {
  for (const uint32_t point : {static_cast<uint32_t>(key >> 32), static_cast<uint32_t>(key & 0xffffffffu)}) {
    uint32_t va = 0, vb = 0;
    for (uint32_t c = 0; c < scene.patches[a].corner_count; ++c)
      if (point_of[a][c] == point) va = scene.patches[a].vertex[c];
    for (uint32_t c = 0; c < scene.patches[b].corner_count; ++c)
      if (point_of[b][c] == point) vb = scene.patches[b].vertex[c];
    if (va == 0 || va != vb) return false;
  }
  return true;
}

// Smoothing groups, occlusion groups and the occlusion groups' adjacency; `t_pairs` gets the
// coplanar patches of one material that touch along an edge (for find_t_neighbours), `touch_pairs`
// every pair of patches that touch along an edge, once (a < b; for find_seam_neighbours).
void find_groups(const Scene& scene, const PointIds& point_of, const EdgePatches& edge_patches, PreparedScene& out,
                 std::vector<std::pair<uint32_t, uint32_t>>& t_pairs, std::vector<std::pair<uint32_t, uint32_t>>& touch_pairs) {
  const size_t n = scene.patches.size();
  UnionFind occl(n), smooth(n);
  std::vector<Touch> neighbours;
  // Whether b lies in a's plane: facing the same way (coplanar), or either way (same_plane: a
  // double-sided surface's twins lie in one plane).
  auto in_plane = [&](uint32_t a, uint32_t b, bool either_way) {
    const double d = glm::dot(out.normal[a], out.normal[b]);
    if ((either_way ? std::abs(d) : d) < 1.0 - 1e-9) return false;
    const Patch& pa = scene.patches[a];
    const Patch& pb = scene.patches[b];
    for (uint32_t c = 0; c < pb.corner_count; ++c)
      if (std::abs(glm::dot(out.normal[a], pb.corners[c] - pa.corners[0])) > 1e-9 * out.diagonal)
        return false;
    return true;
  };
  auto coplanar = [&](uint32_t a, uint32_t b) { return in_plane(a, b, false); };
  auto same_plane = [&](uint32_t a, uint32_t b) { return in_plane(a, b, true); };
  // Whether patches z and f, both on the line through p along unit u, lie on the same side of it
  // (a box's bottom and the top of the box it stands on, both reaching into the wall; not a shelf
  // reaching into the room from a line where a bottom reaching into the wall also ends).
  auto same_side = [&](uint32_t z, uint32_t f, const glm::dvec3& p, const glm::dvec3& u) {
    auto off = [&](uint32_t q) {
      const Patch& pq = scene.patches[q];
      glm::dvec3 c(0.0);
      for (uint32_t k = 0; k < pq.corner_count; ++k) c += pq.corners[k];
      const glm::dvec3 r = c / static_cast<double>(pq.corner_count) - p;
      return r - u * glm::dot(r, u);
    };
    return glm::dot(off(z), off(f)) > 0.0;
  };
  // Whether z and f face each other in one plane, within the touches' tolerance (1e-7 of the
  // diagonal): two boxes an exporter stacked lie 6e-8 m apart in single precision (the Blender
  // house's wall under its window), more than coplanar's 1e-9.
  auto facing_in_plane = [&](uint32_t z, uint32_t f) {
    if (glm::dot(out.normal[z], out.normal[f]) > -1.0 + 1e-6) return false;
    const Patch& pz = scene.patches[z];
    const Patch& pf = scene.patches[f];
    for (uint32_t c = 0; c < pf.corner_count; ++c)
      if (std::abs(glm::dot(out.normal[z], pf.corners[c] - pz.corners[0])) > 1e-7 * out.diagonal) return false;
    return true;
  };
  // Twins: the two sides of one double-sided face (the same points, facing the other way).
  auto twins = [&](uint32_t a, uint32_t b) {
    const uint32_t count = scene.patches[a].corner_count;
    if (count != scene.patches[b].corner_count) return false;
    for (uint32_t i = 0; i < count; ++i) {
      bool found = false;
      for (uint32_t j = 0; j < count; ++j) found = found || point_of[a][i] == point_of[b][j];
      if (!found) return false;
    }
    return true;
  };
  // Whether z, standing on the line through p along unit u, is pressed there against f: they face
  // each other in one plane and reach to the same side of the line, and are not one plate's sides.
  auto pressed_against = [&](uint32_t z, uint32_t f, const glm::dvec3& p, const glm::dvec3& u) {
    return facing_in_plane(z, f) && !twins(z, f) && same_side(z, f, p, u);
  };
  // A junction: a surface of another plane stands on the edge between two patches (a wall on the
  // line between two rooms' floors, a shelf on a seam of the wall behind it). Light differs on its
  // two sides, so the patches are neither one smooth surface (their vertices would average across
  // the wall) nor one occlusion group (whose pieces never hide each other: the floor behind the
  // wall would be lit with the floor in front of it).
  // Patches sharing a whole edge (same two points) may share vertices: one smooth surface, unless
  // a patch in neither's plane stands on the edge between them (a junction: for coplanar patches,
  // any patch of another plane there, such as a room's ceiling under the gable that continues its
  // wall, whose vertices on that line averaged the attic's light with the room's).
  for (const auto& [key, list] : edge_patches) {
    // A named reference: clang before 16 cannot capture a structured binding in a lambda.
    const std::vector<uint32_t>& on_edge = list;
    const uint64_t edge = key;
    // A patch pressed against another that faces it, in its plane, on this edge (two stacked wall
    // boxes of one width) is no junction (see the T-junctions' rule below).
    auto junction = [&](uint32_t a, uint32_t b) {
      glm::dvec3 ends[2] = {glm::dvec3(0.0), glm::dvec3(0.0)};
      for (uint32_t c = 0; c < scene.patches[a].corner_count; ++c) {
        if (point_of[a][c] == static_cast<uint32_t>(edge >> 32)) ends[0] = scene.patches[a].corners[c];
        if (point_of[a][c] == static_cast<uint32_t>(edge & 0xffffffffu)) ends[1] = scene.patches[a].corners[c];
      }
      const glm::dvec3 u = glm::normalize(ends[1] - ends[0]);
      for (uint32_t z : on_edge) {
        if (same_plane(z, a) || same_plane(z, b)) continue;
        bool pressed = false;
        for (uint32_t f : on_edge)
          pressed = pressed || pressed_against(z, f, ends[0], u);
        if (!pressed) return true;
      }
      return false;
    };
    for (size_t x = 0; x < list.size(); ++x) {
      for (size_t y = x + 1; y < list.size(); ++y) {
        const uint32_t a = list[x], b = list[y];
        if (junction(a, b)) continue;
        const double cos_ab = glm::dot(out.normal[a], out.normal[b]);
        if (scene.patches[a].material == scene.patches[b].material &&
            (cos_ab > kCreaseCos || (cos_ab > 0.0 && same_input_vertices(scene, point_of, a, b, key))))
          smooth.unite(a, b);
      }
    }
  }
  // Patches whose edges overlap on a line (shared edges and T-junctions alike) touch: coplanar
  // ones are one occlusion group, the others are adjacent groups.
  neighbours = touching_patches(scene, out.diagonal);
  for (const Touch& t : neighbours)
    if (touch_pairs.empty() || touch_pairs.back() != std::pair(t.a, t.b)) touch_pairs.emplace_back(t.a, t.b);
  std::vector<std::vector<uint32_t>> touches(n);
  for (uint32_t i = 0; i < neighbours.size(); ++i) {
    touches[neighbours[i].a].push_back(i);
    touches[neighbours[i].b].push_back(i);
  }
  const double tol = 1e-7 * out.diagonal;
  // Whether a patch of another plane than coplanar a and b touches a along their common edge, and
  // is seen there: a patch pressed against another that faces it, in its plane, all along the part
  // of the edge it touches, is no junction. Two wall boxes stacked under a window (the top of the
  // one below pressed against the bottom of the one above) keep their room faces one surface: with
  // the faces between them as a junction, each box's face showed its own light, with steps across
  // the wall where the boxes meet (the Blender house's south wall in three.js). The two sides of a
  // double-sided plate are no such pair: the plate parts the light on its two sides. A patch
  // touching one of them along the common edge touches the other there too: the one with fewer
  // touches is searched (a floor edged with 20 000 tiles has 20 000).
  auto junction = [&](const Touch& t) {
    const glm::dvec3 d = t.q - t.p;
    const double len = glm::length(d);
    const bool by_a = touches[t.a].size() <= touches[t.b].size();
    const uint32_t self = by_a ? t.a : t.b, other = by_a ? t.b : t.a;
    // The patches of other planes on the common edge, and the part of it each touches.
    struct Standing {
      uint32_t patch;
      double from, to;
    };
    std::vector<Standing> standing;
    for (uint32_t i : touches[self]) {
      const Touch& u = neighbours[i];
      const uint32_t c = u.a == self ? u.b : u.a;
      if (c == other || same_plane(t.a, c)) continue;
      const double s0 = glm::dot(u.p - t.p, d) / len, s1 = glm::dot(u.q - t.p, d) / len;
      const bool on_line = glm::length(glm::cross(u.p - t.p, d)) / len <= tol && glm::length(glm::cross(u.q - t.p, d)) / len <= tol;
      const double from = std::max(std::min(s0, s1), 0.0), to = std::min(std::max(s0, s1), len);
      if (on_line && to - from > tol) standing.push_back({c, from, to});
    }
    for (const Standing& c : standing) {
      bool pressed = false;
      for (const Standing& f : standing)
        pressed = pressed || (f.from <= c.from + tol && f.to >= c.to - tol && pressed_against(c.patch, f.patch, t.p, d / len));
      if (!pressed) return true;
    }
    return false;
  };
  // Coplanar patches split by a junction are not neighbours either: seen from one side, the far one
  // lies behind the junction's surface, which tiles with the near one, and neighbours would join
  // all three in one layer.
  std::vector<uint8_t> split(neighbours.size(), 0);
  for (size_t i = 0; i < neighbours.size(); ++i) {
    const Touch& t = neighbours[i];
    if (!coplanar(t.a, t.b)) continue;
    if (junction(t)) {
      split[i] = 1;
      continue;
    }
    occl.unite(t.a, t.b);
    // Coplanar patches of one material meeting along a part of an edge (a T-junction) are one
    // smooth surface too: a wall cut around a window, whose pieces showed a flat colour each,
    // with steps where they meet (mesh_export.cpp joins them through out.t_neighbours).
    if (!t.folded && scene.patches[t.a].material == scene.patches[t.b].material) {
      smooth.unite(t.a, t.b);
      t_pairs.emplace_back(t.a, t.b);
    }
  }
  out.occlusion_group.resize(n);
  out.smoothing_group.resize(n);
  for (uint32_t i = 0; i < n; ++i) {
    out.occlusion_group[i] = occl.find(i);
    out.smoothing_group[i] = smooth.find(i);
  }
  for (size_t i = 0; i < neighbours.size(); ++i)
    if (!split[i])
      out.adjacency.add(out.occlusion_group[neighbours[i].a], out.occlusion_group[neighbours[i].b], neighbours[i].folded);
  out.adjacency.finish();
}

// Backs that need no projection (PreparedScene::back_hidden), first kind. Twins: the same points,
// facing the other way (sorted point ids, kNone-padded, are the key).
void hide_twin_backs(const Scene& scene, const PointIds& point_of, PreparedScene& out) {
  struct KeyHash {
    size_t operator()(const std::array<uint32_t, 4>& k) const {
      uint64_t h = 0;
      for (uint32_t v : k) h = (h ^ v) * 0x100000001b3ull;
      return static_cast<size_t>(h);
    }
  };
  std::unordered_map<std::array<uint32_t, 4>, std::vector<uint32_t>, KeyHash> by_points;
  for (size_t i = 0; i < scene.patches.size(); ++i) {
    std::array<uint32_t, 4> key{kNone, kNone, kNone, kNone};
    std::copy_n(point_of[i].begin(), scene.patches[i].corner_count, key.begin());
    std::sort(key.begin(), key.end());
    by_points[key].push_back(static_cast<uint32_t>(i));
  }
  // Where two objects' double-sided faces touch (books packed on a shelf), four patches share the
  // points: each is paired with its own object's other side first.
  for (const auto& [key, list] : by_points)
    for (const bool same_object : {true, false})
      for (size_t x = 0; x < list.size(); ++x)
        for (size_t y = x + 1; y < list.size(); ++y) {
          const uint32_t a = list[x], b = list[y];
          if (glm::dot(out.normal[a], out.normal[b]) >= 0.0 || out.twin[a] != kNone || out.twin[b] != kNone) continue;
          if (same_object && scene.patches[a].object != scene.patches[b].object) continue;
          out.back_hidden[a] = out.back_hidden[b] = 1;
          out.twin[a] = b;
          out.twin[b] = a;
        }
}

// Second kind: outward-facing solids. The signed volume of an edge-connected set of patches
// (divergence theorem, sum of (c - o) . n A / 3, o the set's box centre) is positive when its
// normals point away from what it encloses; an open box (a block with no bottom) still comes out
// positive.
void hide_solid_backs(const Scene& scene, const EdgePatches& edge_patches, PreparedScene& out) {
  const size_t n = scene.patches.size();
  UnionFind part(n);
  for (const auto& [key, list] : edge_patches)
    for (size_t x = 1; x < list.size(); ++x) part.unite(list[0], list[x]);
  std::vector<glm::dvec3> box_lo(n, glm::dvec3(std::numeric_limits<double>::max())),
      box_hi(n, glm::dvec3(std::numeric_limits<double>::lowest()));
  for (uint32_t i = 0; i < n; ++i) {
    const Patch& p = scene.patches[i];
    const uint32_t r = part.find(i);
    for (uint32_t c = 0; c < p.corner_count; ++c) {
      box_lo[r] = glm::min(box_lo[r], p.corners[c]);
      box_hi[r] = glm::max(box_hi[r], p.corners[c]);
    }
  }
  std::vector<double> volume(n, 0.0);
  for (uint32_t i = 0; i < n; ++i) {
    const Patch& p = scene.patches[i];
    const uint32_t r = part.find(i);
    glm::dvec3 c(0.0);
    for (uint32_t k = 0; k < p.corner_count; ++k) c += p.corners[k];
    c /= static_cast<double>(p.corner_count);
    volume[r] += glm::dot(c - 0.5 * (box_lo[r] + box_hi[r]), out.normal[i]) * out.area[i] / 3.0;
  }
  const double tiny = 1e-9 * out.diagonal * out.diagonal * out.diagonal;
  std::vector<uint32_t> solid_of(n, kNone);
  out.solid.assign(n, kNone);
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t r = part.find(i);
    if (volume[r] <= tiny) continue;
    out.back_hidden[i] = 1;
    if (solid_of[r] == kNone) {
      solid_of[r] = static_cast<uint32_t>(out.solid_lo.size());
      out.solid_lo.push_back(box_lo[r]);
      out.solid_hi.push_back(box_hi[r]);
    }
    out.solid[i] = solid_of[r];
  }
}

// Solver vertices: one per (point, smoothing group), so radiosity is averaged within a surface.
void make_vertices(const Scene& scene, const PointIds& point_of, PreparedScene& out) {
  std::unordered_map<uint64_t, uint32_t> vertex_id;
  out.corner_vertex.resize(scene.patches.size());
  for (size_t i = 0; i < scene.patches.size(); ++i) {
    const Patch& p = scene.patches[i];
    for (uint32_t c = 0; c < 4; ++c) {
      if (c >= p.corner_count) {
        out.corner_vertex[i][c] = kNone;
        continue;
      }
      const uint64_t key = (static_cast<uint64_t>(out.smoothing_group[i]) << 32) | point_of[i][c];
      auto [it, fresh] = vertex_id.try_emplace(key, static_cast<uint32_t>(out.vertex_position.size()));
      if (fresh) out.vertex_position.push_back(p.corners[c]);
      out.corner_vertex[i][c] = it->second;
    }
  }
}

// PreparedScene::t_neighbours: patches touching along an edge in one smoothing group where a
// corner of one lies strictly inside an edge of the other.
void find_t_neighbours(const Scene& scene, const std::vector<std::pair<uint32_t, uint32_t>>& t_pairs,
                       PreparedScene& out) {
  out.t_neighbours.assign(scene.patches.size(), {});
  const double tol = 1e-7 * out.diagonal;
  auto corner_inside = [&](uint32_t a, uint32_t b) {  // a corner of b inside an edge of a
    const Patch& pa = scene.patches[a];
    const Patch& pb = scene.patches[b];
    for (uint32_t c = 0; c < pb.corner_count; ++c)
      for (uint32_t k = 0; k < pa.corner_count; ++k)
        if (along_segment(pb.corners[c], pa.corners[k], pa.corners[(k + 1) % pa.corner_count], tol) > 0.0) return true;
    return false;
  };
  for (const auto& [a, b] : t_pairs) {
    if (out.smoothing_group[a] != out.smoothing_group[b]) continue;
    if (!corner_inside(a, b) && !corner_inside(b, a)) continue;
    out.t_neighbours[a].push_back(b);
    out.t_neighbours[b].push_back(a);
  }
}

// PreparedScene::seam_neighbours: of the patches touching along an edge, those whose vertices
// there are not already joined into each other's loops: T-neighbours are, and so are patches of one
// smoothing group sharing a whole edge (the same vertices, split at the same midpoints).
void find_seam_neighbours(const Scene& scene, const PointIds& point_of, const EdgePatches& edge_patches,
                          const std::vector<std::pair<uint32_t, uint32_t>>& touch_pairs, PreparedScene& out) {
  out.seam_neighbours.assign(scene.patches.size(), {});
  auto share_edge = [&](uint32_t a, uint32_t b) {
    const uint32_t cc = scene.patches[a].corner_count;
    for (uint32_t c = 0; c < cc; ++c) {
      const uint32_t x = point_of[a][c], y = point_of[a][(c + 1) % cc];
      const auto it = edge_patches.find((static_cast<uint64_t>(std::min(x, y)) << 32) | std::max(x, y));
      if (it != edge_patches.end() && std::find(it->second.begin(), it->second.end(), b) != it->second.end()) return true;
    }
    return false;
  };
  for (const auto& [a, b] : touch_pairs) {
    // T-neighbours are listed both ways: the shorter list is searched (a floor edged with 20 000
    // tiles has 20 000).
    const bool by_a = out.t_neighbours[a].size() <= out.t_neighbours[b].size();
    const std::vector<uint32_t>& listed = out.t_neighbours[by_a ? a : b];
    if (std::find(listed.begin(), listed.end(), by_a ? b : a) != listed.end()) continue;
    if (out.smoothing_group[a] == out.smoothing_group[b] && share_edge(a, b)) continue;
    out.seam_neighbours[a].push_back(b);
    out.seam_neighbours[b].push_back(a);
  }
}

// How many times the ray from x along a fixed direction crosses the patch (a fan of triangles from
// its first corner; Moller-Trumbore). The direction is one along which no modeller's edge runs.
int ray_crossings(const Patch& patch, const glm::dvec3& x) {
  const glm::dvec3 dir = glm::normalize(glm::dvec3(0.5377, 0.6123, 0.5799));
  int crossings = 0;
  for (uint32_t k = 1; k + 1 < patch.corner_count; ++k) {
    const glm::dvec3 a = patch.corners[0], e1 = patch.corners[k] - a, e2 = patch.corners[k + 1] - a;
    const glm::dvec3 pv = glm::cross(dir, e2);
    const double det = glm::dot(e1, pv);
    if (det == 0.0) continue;
    const glm::dvec3 tv = x - a;
    const double u = glm::dot(tv, pv) / det;
    if (u < 0.0 || u > 1.0) continue;
    const glm::dvec3 qv = glm::cross(tv, e1);
    const double v = glm::dot(dir, qv) / det;
    if (v < 0.0 || u + v > 1.0) continue;
    if (glm::dot(e2, qv) / det > 0.0) ++crossings;
  }
  return crossings;
}

// PreparedScene::inner_solid: closed double-sided meshes. Each side of such a mesh is a sheet of
// patches each meeting, along each edge, exactly one patch of its object (Patch::object) and of the
// same sheet (running the edge the other way) besides its own twin; a sheet whose every edge does
// so is closed (books packed on a shelf share edges, each book is an object of its own).
// Of the two sheets of one mesh, the one enclosing a positive signed volume is the outside, and its
// twins face the inside. A mesh of more than kMaxClosedPatches patches is left out (a point's test
// against it walks all of its outside).
constexpr size_t kMaxClosedPatches = 4096;

void find_closed_meshes(const Scene& scene, const PointIds& point_of, const EdgePatches& edge_patches,
                        PreparedScene& out) {
  const size_t n = scene.patches.size();
  out.inner_solid.assign(n, kNone);
  UnionFind sheet(n);
  std::vector<uint8_t> open(n, 0);
  // Whether patch q runs the edge from point a to point b.
  auto runs = [&](uint32_t q, uint32_t a, uint32_t b) {
    const uint32_t cc = scene.patches[q].corner_count;
    for (uint32_t k = 0; k < cc; ++k)
      if (point_of[q][k] == a && point_of[q][(k + 1) % cc] == b) return true;
    return false;
  };
  for (uint32_t p = 0; p < n; ++p) {
    if (out.twin[p] == kNone || scene.patches[out.twin[p]].object != scene.patches[p].object) {
      open[p] = 1;
      continue;
    }
    const uint32_t cc = scene.patches[p].corner_count;
    for (uint32_t k = 0; k < cc && !open[p]; ++k) {
      const uint32_t a = point_of[p][k], b = point_of[p][(k + 1) % cc];
      const auto it = edge_patches.find((static_cast<uint64_t>(std::min(a, b)) << 32) | std::max(a, b));
      uint32_t partner = kNone, partners = 0;
      if (it != edge_patches.end())
        for (uint32_t q : it->second)
          if (q != p && q != out.twin[p] && out.twin[q] != kNone && scene.patches[q].object == scene.patches[p].object &&
              runs(q, b, a))
            partner = q, ++partners;
      if (partners == 1) sheet.unite(p, partner);
      else open[p] = 1;
    }
  }
  std::vector<std::vector<uint32_t>> members(n);
  for (uint32_t p = 0; p < n; ++p) members[sheet.find(p)].push_back(p);
  for (uint32_t r = 0; r < n; ++r) {
    const std::vector<uint32_t>& m = members[r];
    if (m.size() < 4 || m.size() > kMaxClosedPatches) continue;
    bool closed = true;
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
    for (uint32_t p : m) {
      closed = closed && !open[p];
      for (uint32_t c = 0; c < scene.patches[p].corner_count; ++c) {
        lo = glm::min(lo, scene.patches[p].corners[c]);
        hi = glm::max(hi, scene.patches[p].corners[c]);
      }
    }
    if (!closed) continue;
    std::vector<Patch> sheet_patches;
    sheet_patches.reserve(m.size());
    for (uint32_t p : m) sheet_patches.push_back(scene.patches[p]);
    // The inside sheet, or flat: not the outside.
    if (signed_volume(sheet_patches) <= 1e-9 * std::pow(glm::length(hi - lo), 3.0)) continue;
    const uint32_t id = static_cast<uint32_t>(out.closed_outside.size());
    out.closed_outside.push_back(m);
    out.closed_lo.push_back(lo);
    out.closed_hi.push_back(hi);
    for (uint32_t p : m) out.inner_solid[out.twin[p]] = id;
  }
}

}  // namespace

bool inside_closed(const std::vector<Patch>& patches, const PreparedScene& prep, uint32_t closed, const glm::dvec3& x) {
  if (glm::any(glm::lessThan(x, prep.closed_lo[closed])) || glm::any(glm::greaterThan(x, prep.closed_hi[closed])))
    return false;
  int crossings = 0;
  for (uint32_t p : prep.closed_outside[closed]) crossings += ray_crossings(patches[p], x);
  return crossings % 2 == 1;
}

PreparedScene prepare(const Scene& scene) {
  PreparedScene out;
  measure(scene, out);
  const PointIds point_of = point_ids(scene);
  const EdgePatches edge_patches = patches_by_edge(scene, point_of);
  std::vector<std::pair<uint32_t, uint32_t>> t_pairs, touch_pairs;
  find_groups(scene, point_of, edge_patches, out, t_pairs, touch_pairs);
  out.back_hidden.assign(scene.patches.size(), 0);
  out.twin.assign(scene.patches.size(), kNone);
  hide_twin_backs(scene, point_of, out);
  hide_solid_backs(scene, edge_patches, out);
  find_closed_meshes(scene, point_of, edge_patches, out);
  make_vertices(scene, point_of, out);
  find_t_neighbours(scene, t_pairs, out);
  find_seam_neighbours(scene, point_of, edge_patches, touch_pairs, out);
  return out;
}

}  // namespace detail

double signed_volume(std::span<const Patch> surface) {
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
  for (const Patch& p : surface)
    for (uint32_t k = 0; k < p.corner_count; ++k) {
      lo = glm::min(lo, p.corners[k]);
      hi = glm::max(hi, p.corners[k]);
    }
  // The sum over the faces of (c - o) . n A / 3, with n A the Newell area vector.
  const glm::dvec3 o = 0.5 * (lo + hi);
  double volume = 0.0;
  for (const Patch& p : surface) {
    glm::dvec3 area(0.0), centre(0.0);
    for (uint32_t k = 0; k < p.corner_count; ++k) {
      area += 0.5 * glm::cross(p.corners[k] - o, p.corners[(k + 1) % p.corner_count] - o);
      centre += p.corners[k] / static_cast<double>(p.corner_count);
    }
    volume += glm::dot(centre - o, area) / 3.0;
  }
  return volume;
}

bool encloses(std::span<const Patch> surface, const glm::dvec3& x) {
  int crossings = 0;
  for (const Patch& p : surface) crossings += detail::ray_crossings(p, x);
  return crossings % 2 == 1;
}

}  // namespace hemibake::solver
