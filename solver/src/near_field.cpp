// Rules for receivers close to a shooting piece, where the hemicube at its centre sees them
// poorly: which receivers are close, when the point view's error matters, when an absorbing back
// in front of the piece spoils its centre's view, and the exact form factors that close receivers
// of an unrefined piece take instead.
#include "solver_impl.h"

#include "hemibake/solver/hemicube.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace hemibake::solver {

// Near: within kNearFactor diameters of the piece, or (a piece of a patch carrying at least
// kStraddlePower of the emitted power) on a plane that cuts through the piece: its centre may lie
// behind the receiver while part of it is in front (a face of a block that sees part of the light
// got nothing from the light's centre). Clusters are left to their quarters' own tests: planes
// cut through them everywhere in a furnished room. Only a receiver that some of the piece can see,
// and that can see some of the piece, counts.
bool Solver::Impl::is_close(const Piece& piece, uint32_t e) const {
  const uint32_t p = piece.patch;
  const glm::dvec3& centre = piece.centre;
  const double eps = kCloseFacingLength * prep.diagonal;
  const bool cut_rule = piece.points.size() <= 4 && piece.power >= kStraddlePower * emitted_power;
  const uint32_t q = e_patch[e];
  if (prep.occlusion_group[q] == prep.occlusion_group[p]) return false;
  const glm::dvec3& nq = prep.normal[q];
  const glm::dvec3& oq = patches[q].corners[0];
  // On a cluster's own curved surface, a receiver with the cluster's centroid behind its plane
  // (a convex surface: a sphere's facets) sees none of the cluster. Without this every cluster
  // of a 159k-facet sphere went down to single patches (526 659 hemicubes for 1303 shots).
  if (piece.points.size() > 4 && !piece.volume && p_surface[q] == p_surface[p] && glm::dot(nq, centre - oq) <= 0.0)
    return false;
  const bool within = glm::distance(centre, e_centre[e]) - e_radius[e] < kNearFactor * piece.diameter;
  if (!within) {
    // The piece's centre behind the receiver's plane, or just in front of it: the centre's
    // hemicube gives the receiver nothing, or a grazing, poor view.
    const double dc = glm::dot(nq, centre - oq);
    if (!cut_rule || dc > 0.1 * piece.diameter || dc < -0.5 * piece.diameter) return false;
  }
  double lo = 0.0, hi = 0.0;
  for (const glm::dvec3& x : piece.points) {
    const double d = glm::dot(nq, x - oq);
    lo = std::min(lo, d);
    hi = std::max(hi, d);
  }
  if (hi <= eps || (!within && lo >= -eps)) return false;
  if (piece.volume) return true;  // it shoots every way
  bool in_front = false;
  for (uint32_t i = 0; i < corner_count(e) && !in_front; ++i)
    in_front = glm::dot(piece.normal, vpos[e_corner[e][i]] - centre) > eps - piece.rear;
  return in_front;
}

// The point view's possible error for a close receiver (infinite where it always matters). A close
// receiver goes to the sub-pieces only where the centre's hemicube could err by more than
// kNearError of the radiosity tolerance: it gains at most rho * dB * F, with F at most
// A / (pi g^2) at a gap g between them (at most 1), and the hemicube's point view of the piece
// errs by about (D / 2g)^2 of that (D the piece's diameter). Within half a diameter the error may
// be all of the gain: F(element -> piece) is at most 1 and, by reciprocity, at most the piece's
// area over the element's, both for the hemicube's value and for the true one. That bound stops a
// weak shot's descent where the pieces become small beside the receiver (a cluster of a 159k-facet
// sphere resting on a floor tile went down to single facets for the tile: 5576 hemicubes in one
// shot).
double Solver::Impl::near_error(const Piece& piece, uint32_t e) const {
  const glm::dvec3& centre = piece.centre;
  const double gap = glm::distance(centre, e_centre[e]) - e_radius[e] - 0.5 * piece.diameter;
  if (gap <= 0.5 * piece.diameter)
    return mean(patches[e_patch[e]].reflectance * piece.dB) * std::min(1.0, piece.area / e_area[e]);
  // A receiver whose plane cuts the piece (is_close) may get nothing at all from the centre.
  if (glm::distance(centre, e_centre[e]) - e_radius[e] >= kNearFactor * piece.diameter)
    return std::numeric_limits<double>::infinity();
  const double f = std::min(1.0, piece.area / (std::numbers::pi * gap * gap));
  const double share = 0.25 * piece.diameter * piece.diameter / (gap * gap);
  return mean(patches[e_patch[e]].reflectance * piece.dB) * f * share;
}

// F(point x with normal n -> piece): Lambert's formula over the piece cut to x's front side;
// nothing for a point behind the piece.
double Solver::Impl::point_piece_form_factor(const Piece& piece, const glm::dvec3& x, const glm::dvec3& n) {
  if (glm::dot(piece.normal, x - piece.centre) <= 0.0) return 0.0;
  uint32_t m = 0;
  std::array<glm::dvec3, 8> clipped{};
  const size_t k = piece.points.size();
  for (size_t i = 0; i < k; ++i) {
    const glm::dvec3& a = piece.points[i];
    const glm::dvec3& b = piece.points[(i + 1) % k];
    const double da = glm::dot(n, a - x), db = glm::dot(n, b - x);
    if (da > 0.0) clipped[m++] = a;
    if ((da > 0.0) != (db > 0.0)) clipped[m++] = a + (b - a) * (da / (da - db));
  }
  return m < 3 ? 0.0 : point_polygon_form_factor(x, n, std::span(clipped.data(), m));
}

// F(element -> piece): the mean over `side` x `side` points of the element (quads: cell centres
// of a bilinear grid; triangles: the centroid, or those of its four halved-edge triangles).
double Solver::Impl::element_piece_form_factor(const Piece& piece, uint32_t e, int side) const {
  const glm::dvec3& n = prep.normal[e_patch[e]];
  const Corners c = corners_of_copy(e);
  if (side <= 1) return point_piece_form_factor(piece, polygon_centre(c, corner_count(e)), n);
  double sum = 0.0;
  int count = 0;
  if (corner_count(e) == 4) {
    for (int i = 0; i < side; ++i)
      for (int j = 0; j < side; ++j, ++count) {
        const double u = (i + 0.5) / side, v = (j + 0.5) / side;
        sum += point_piece_form_factor(piece, (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3], n);
      }
  } else {
    Corners sub{};
    for (uint32_t k = 0; k < 4; ++k, ++count) {
      child_corners(c, 3, k, sub);
      sum += point_piece_form_factor(piece, (sub[0] + sub[1] + sub[2]) / 3.0, n);
    }
  }
  return sum / count;
}

// The exact F(element -> piece) (element_piece_form_factor) over 1, 4 or 9 points of the receiver
// as it is smaller than half the piece, than the piece, or larger (`side`), capped at 1; kept for
// the hemicube's later rounds (e_exact_stamp).
double Solver::Impl::exact_form_factor(const Piece& piece, uint32_t e, int side) {
  if (e_exact_stamp[e] != stamp) {
    e_exact[e] = std::min(1.0, element_piece_form_factor(piece, e, side));
    e_exact_stamp[e] = stamp;
  }
  return e_exact[e];
}

// Whether the patches in front of the piece and within one of its diameters take at least
// kAbsorberShare of the centre's light together: those whose back the centre sees (they absorb:
// not back_hidden), or that face the piece. Their share of the centre's view then differs from most
// of the piece's (shoot_piece). Summed, not one by one: a one-sided wall around a window, 30 cm
// in front of a sky plane, is four patches of about 0.04 each (0.17 together); judged one by one,
// the plane shot from its centre, which looks through the window head-on, and the room's far wall
// took 54 % too much light once it was cut into tiles (whole, it was near enough to go to the
// plane's parts).
bool Solver::Impl::absorber_close(const Piece& piece) const {
  // A volume cluster's box holds no other object's surface (foreign_inside), and its cube has no
  // front side.
  if (piece.volume) return false;
  const glm::dvec3& c = piece.centre;
  const double r = piece.diameter;
  const double eps = kRoundingLength * prep.diagonal;
  auto near = [&](const glm::dvec3& lo, const glm::dvec3& hi) {
    const glm::dvec3 gap = glm::max(lo - c, glm::max(c - hi, glm::dvec3(0.0)));
    return glm::dot(gap, gap) <= r * r;
  };
  double taken = 0.0;
  return find_patch(near, [&](uint32_t q) {
    if (p_shooting[q] == shooting_stamp) return false;
    // Its back (a light panel's, hung under a ceiling piece), or its front if it faces the piece
    // (a wall 30 cm from a sky plane, with a window in it: the centre looks through the window
    // straight on, most of the piece sees the room at a slant or not at all). A front at an angle
    // (the next wall at a room's corner) leaves the centre's view fair.
    const bool front = glm::dot(prep.normal[q], c - patches[q].corners[0]) >= -eps;
    if (front ? glm::dot(prep.normal[q], piece.normal) > -kFacingOccluderCos : prep.back_hidden[q]) return false;
    if (!near(p_lo[q], p_hi[q])) return false;
    // The form factor from the centre to the patch cut to the piece's front side: the share of
    // the centre's light it takes (a back seen edge-on takes little).
    std::array<glm::dvec3, 8> cut{};
    uint32_t m = 0;
    const uint32_t cc = patches[q].corner_count;
    for (uint32_t k = 0; k < cc; ++k) {
      const glm::dvec3& a = patches[q].corners[k];
      const glm::dvec3& b = patches[q].corners[(k + 1) % cc];
      const double da = glm::dot(piece.normal, a - c), db = glm::dot(piece.normal, b - c);
      if (da > eps) cut[m++] = a;
      if ((da > eps) != (db > eps)) cut[m++] = a + (b - a) * ((da - eps) / (da - db));
    }
    if (m < 3) return false;
    taken += point_polygon_form_factor(c, piece.normal, std::span(cut.data(), m));
    return taken >= kAbsorberShare;
  });
}

// Whether point x of patch p lies under another surface resting on p: a patch in p's plane facing
// the other way (not p's own other side) whose polygon holds x, as a block's bottom holds the floor
// under it. Light there is the mesh's error (a floor element reaching under the block got some),
// and a hemicube there would see the block's inside.
// With a `gap`, the other surface may also lie up to that far in front of x (a lamp hung just under
// a ceiling covers the ceiling above it: light there only gets out through the gap). With
// `any_facing`, a surface facing the same way as p covers it too (a one-sided lamp's back hides
// the ceiling above it from the room as well as its front would). `by` chooses whether any surface
// counts or only those that emit nothing.
bool Solver::Impl::covered(uint32_t p, const glm::dvec3& x, double gap, bool any_facing, Cover by) const {
  return cover_at(p, x, gap, any_facing, by) != kNone;
}

// covered(), naming the surface that covers x: the first patch found, or kNone.
uint32_t Solver::Impl::cover_at(uint32_t p, const glm::dvec3& x, double gap, bool any_facing, Cover by) const {
  const glm::dvec3& n = prep.normal[p];
  const double eps = kCloseFacingLength * prep.diagonal;
  const double reach = std::max(eps, gap);
  auto near = [&](const glm::dvec3& lo, const glm::dvec3& hi) {
    return !glm::any(glm::lessThan(x, lo - reach)) && !glm::any(glm::greaterThan(x, hi + reach));
  };
  uint32_t found = kNone;
  find_patch(near, [&](uint32_t q) {
    const double facing = glm::dot(prep.normal[q], n);
    if (prep.twin[q] == p || q == p || (facing > -1.0 + 1e-9 && !(any_facing && facing >= 1.0 - 1e-9))) return false;
    if (by == Cover::kNonEmitters && channel_sum(patches[q].emission) > 0.0) return false;
    const Patch& pq = patches[q];
    // The distance in front of x along x's normal (the patch's own normal may point either way).
    const double d = facing < 0.0 ? glm::dot(prep.normal[q], x - pq.corners[0]) : glm::dot(prep.normal[q], pq.corners[0] - x);
    if (d < (facing < 0.0 ? -eps : eps) || d > reach) return false;  // a surface of the same facing only in front
    for (uint32_t k = 0; k < pq.corner_count; ++k) {
      const glm::dvec3& a = pq.corners[k];
      const glm::dvec3& b = pq.corners[(k + 1) % pq.corner_count];
      if (glm::dot(glm::cross(b - a, x - a), prep.normal[q]) <= eps * glm::length(b - a)) return false;
    }
    found = q;
    return true;
  });
  return found;
}

// Whether point x of patch p, on a piece or element of this radius, is covered by a surface just
// in front of it (kCoverGap), facing either way.
bool Solver::Impl::gap_covered(uint32_t p, const glm::dvec3& x, double radius) const {
  return covered(p, x, std::min(radius, kCoverGap * prep.diagonal), true);
}

// Whether covered leaf e reaches past its cover's outline into the open, where the cover emits
// nothing: the end of a wall box pressed against the next wall covers that wall's elements along
// the room's corner, and the one straddling the end's outline is lit on its open side. A gather at
// the corner sees that side (start_gather); left out, the corner saw through it into the dark
// inside of the wall box. Elements across a lamp's outline stay out: their light is the lamp's.
bool Solver::Impl::partly_open(uint32_t e) const {
  const double reach = std::min(kCoverGap * prep.diagonal, e_radius[e]);
  return covered(e_patch[e], e_centre[e], reach, true, Cover::kNonEmitters) && corner_covered_unlike(e, reach, Cover::kAny, true);
}

// Whether element e lies pressed against a surface facing it (in contact, kCloseFacingLength) at
// its centre and at each of its corners pulled a little towards the centre (Mesh::Element::buried).
// Only elements covered at their centre within the cover gap (their kCoveredBit) are looked at.
bool Solver::Impl::buried(uint32_t e) const {
  if ((e_group[e] & kCoveredBit) == 0 || !covered(e_patch[e], e_centre[e])) return false;
  return !corner_covered_unlike(e, 0.0, Cover::kAny, true, false);
}

// Whether one of element e's corners, pulled a little towards its centre, is covered (within
// `reach`, by `by`; facing either way with `any_facing`, else only by surfaces facing it) where
// `centre` says the centre is not, or the other way round.
bool Solver::Impl::corner_covered_unlike(uint32_t e, double reach, Cover by, bool centre, bool any_facing) const {
  const Corners c = corners_of_copy(e);
  for (uint32_t k = 0; k < corner_count(e); ++k)
    if (covered(e_patch[e], c[k] + 0.02 * (e_centre[e] - c[k]), reach, any_facing, by) != centre) return true;
  return false;
}

// Whether element e is covered (gap_covered at its centre), once per element.
bool Solver::Impl::leaf_covered(uint32_t e) {
  if (e_cov[e] < 0) e_cov[e] = gap_covered(e_patch[e], e_centre[e], e_radius[e]) ? 1 : 0;
  return e_cov[e] == 1;
}

// The share of the unshot power under `sources` (elements) that covered leaves hold: the part of a
// shot that is light leaving through a gap (e_gap).
double Solver::Impl::covered_share(std::span<const uint32_t> sources) {
  if (!params.gather) return 0.0;
  double all = 0.0, hidden = 0.0;
  for (uint32_t s : sources)
    for_leaves(s, [&](uint32_t e) {
      const double power = channel_sum(e_unshot[e]) * e_area[e];
      all += power;
      if (power > 0.0 && leaf_covered(e)) hidden += power;
    });
  return all > 0.0 ? hidden / all : 0.0;
}

// Elements that a surface hung just in front of them (kCoverGap) covers in part split before any
// shot: no single shot sees the jump at the cover's outline, and an element reaching past it spread
// the covered side's light over the open side, or the other way round (show_uncovered_light). Above
// a lamp 1 mm under a ceiling the ceiling is lit 40 times brighter than beside it (a double-sided
// lamp's top) or not at all (a one-sided lamp's back); an emitter's outline splits down to the
// smallest split. Behind a cabinet 5 cm from a wall the wall is dark: its elements were larger than
// the smallest split in a cluttered room (0.25 m tiles), and the tile reaching past the cabinet's
// side showed the open wall's light 25 cm into the gap (the room 3 % too bright, points behind
// cabinets 10 times). Other covers' outlines split kCoverOutlineLevels further (the reach shrinks
// with the element, so a wider gap stops sooner). Each element's corners, pulled a little towards
// its centre, and the centre are tested: covered and uncovered samples together split it.
void Solver::Impl::split_along_cover_outlines() {
  find_point_contacts();
  std::vector<uint32_t> queue = leaves;
  bool any = false;
  const double gap = kCoverGap * prep.diagonal;
  const double other_limit = min_split_area() / std::pow(4.0, kCoverOutlineLevels);
  while (!queue.empty()) {
    const uint32_t e = queue.back();
    queue.pop_back();
    if (e_area[e] < other_limit || leaves.size() > params.max_elements) continue;
    if (e_area[e] >= 2.0 * min_split_area() && point_contact_near(e)) {
      split(e);
      any = true;
      for (uint32_t k = 0; k < 4; ++k) queue.push_back(e_child[e] + k);
      continue;
    }
    if (channel_sum(patches[e_patch[e]].emission) > 0.0) continue;
    const double reach = std::min(gap, e_radius[e]);
    const Cover by = e_area[e] >= min_split_area() ? Cover::kAny : Cover::kNonEmitters;
    if (!corner_covered_unlike(e, reach, by, covered(e_patch[e], e_centre[e], reach, true, by)) && !contact_crosses(e))
      continue;
    split(e);
    any = true;
    for (uint32_t k = 0; k < 4; ++k) queue.push_back(e_child[e] + k);
  }
  if (!any) return;
  replace_split(leaves);
  grow_scratch();
  update_unshot_total();
}

// Points where a surface touches another at one corner, with none of its edges lying on it: the
// foot of a ball resting on a floor, a box balanced on a corner. Light changes fast around such a
// point (the object's contact shadow, and the light the two trade in the crevice between them), yet
// no edge marks it, and one shot of a large light never sees it on an element reaching far past it:
// a ball on a floor under a large ceiling light left the floor lit up to its foot (2 to 70 times the
// path tracer's light within 30 cm of it) and its underside 13 times too bright, through floor
// elements 1.5 m wide meeting at the foot. The elements around such a point split down to the
// smallest split before any shot (point_contact_near); a corner within kCloseFacingLength (of the
// scene's diagonal) of the plane touches it. The split reaches as far from the point as half the touching surface is wide (its
// smoothing group's box: a ball's shadow on the floor is about as wide as the ball), at most
// kContactReach of the scene's diagonal.
void Solver::Impl::find_point_contacts() {
  const uint32_t n = static_cast<uint32_t>(patches.size());
  const double eps = kCloseFacingLength * prep.diagonal;
  std::vector<glm::dvec3> group_lo(n, glm::dvec3(std::numeric_limits<double>::max()));
  std::vector<glm::dvec3> group_hi(n, glm::dvec3(std::numeric_limits<double>::lowest()));
  for (uint32_t q = 0; q < n; ++q) {
    const uint32_t g = prep.smoothing_group[q];
    group_lo[g] = glm::min(group_lo[g], p_lo[q]);
    group_hi[g] = glm::max(group_hi[g], p_hi[q]);
  }
  struct Found {
    uint32_t p;
    glm::dvec4 point;  // the point, and how far the split reaches from it
  };
  std::vector<std::vector<Found>> per_chunk(pool.chunk_count(n));
  pool.parallel_for(n, [&](size_t begin, size_t end, size_t chunk) {
    std::vector<Found>& found = per_chunk[chunk];
    for (uint32_t q = static_cast<uint32_t>(begin); q < end; ++q) {
      const Patch& pq = patches[q];
      for (uint32_t k = 0; k < pq.corner_count; ++k) {
        const glm::dvec3& v = pq.corners[k];
        auto near = [&](const glm::dvec3& lo, const glm::dvec3& hi) {
          return !glm::any(glm::lessThan(v, lo - eps)) && !glm::any(glm::greaterThan(v, hi + eps));
        };
        find_patch(near, [&](uint32_t p) {
          if (p == q || prep.twin[p] == q || prep.occlusion_group[p] == prep.occlusion_group[q] || !near(p_lo[p], p_hi[p]))
            return false;
          const glm::dvec3& np = prep.normal[p];
          const glm::dvec3& op = patches[p].corners[0];
          if (std::abs(glm::dot(np, v - op)) > eps) return false;
          // q reaches in front of p, and neither of its edges at v lies in p's plane.
          const double before = glm::dot(np, pq.corners[(k + pq.corner_count - 1) % pq.corner_count] - op);
          const double after = glm::dot(np, pq.corners[(k + 1) % pq.corner_count] - op);
          if (before <= eps || after <= eps) return false;
          // v within p's polygon.
          const Patch& pp = patches[p];
          for (uint32_t j = 0; j < pp.corner_count; ++j) {
            const glm::dvec3 m = glm::cross(np, pp.corners[(j + 1) % pp.corner_count] - pp.corners[j]);
            if (glm::dot(m, v - pp.corners[j]) < -eps * glm::length(m)) return false;
          }
          const glm::dvec3 size = group_hi[prep.smoothing_group[q]] - group_lo[prep.smoothing_group[q]];
          const double reach = std::min(0.5 * std::max({size.x, size.y, size.z}), kContactReach * prep.diagonal);
          found.push_back({p, glm::dvec4(v, reach)});
          return false;
        });
      }
    }
  });
  std::vector<Found> found;
  for (const std::vector<Found>& part : per_chunk) found.insert(found.end(), part.begin(), part.end());
  std::stable_sort(found.begin(), found.end(), [](const Found& a, const Found& b) { return a.p < b.p; });
  p_contact_begin.assign(n + 1, 0);
  contact_points.clear();
  for (const Found& f : found) {
    ++p_contact_begin[f.p + 1];
    contact_points.push_back(f.point);
  }
  for (uint32_t p = 0; p < n; ++p) p_contact_begin[p + 1] += p_contact_begin[p];
}

// Whether element e reaches within the split's reach of a point where another surface touches its
// patch at a corner (find_point_contacts).
bool Solver::Impl::point_contact_near(uint32_t e) const {
  const uint32_t p = e_patch[e];
  if (p_contact_begin.empty()) return false;
  for (uint32_t i = p_contact_begin[p]; i < p_contact_begin[p + 1]; ++i) {
    const glm::dvec4& c = contact_points[i];
    if (glm::distance(glm::dvec3(c), e_centre[e]) - e_radius[e] < c.w) return true;
  }
  return false;
}

// How long a stretch of patch q's outline lies in element e's plane within e (its edges moved in by
// `inset`; a negative inset takes the outline too), if q stands on e's surface: at an angle to it
// and reaching in front of it. 0 otherwise.
double Solver::Impl::contact_length(uint32_t e, uint32_t q, double inset) const {
  const glm::dvec3& n = prep.normal[e_patch[e]];
  const Corners c = corners_of_copy(e);
  const uint32_t nc = corner_count(e);
  // An edge within this of the plane lies in it (written positions are rounded).
  const double eps = kCloseFacingLength * prep.diagonal;
  const Patch& pq = patches[q];
  bool in_front = false;
  for (uint32_t k = 0; k < pq.corner_count; ++k) in_front = in_front || glm::dot(n, pq.corners[k] - c[0]) > eps;
  if (!in_front) return 0.0;
  double longest = 0.0;
  for (uint32_t k = 0; k < pq.corner_count; ++k) {
    const glm::dvec3& a = pq.corners[k];
    const glm::dvec3& b = pq.corners[(k + 1) % pq.corner_count];
    if (std::abs(glm::dot(n, a - c[0])) > eps || std::abs(glm::dot(n, b - c[0])) > eps) continue;
    double t0 = 0.0, t1 = 1.0;
    for (uint32_t j = 0; j < nc && t0 < t1; ++j) {
      const glm::dvec3 m = glm::normalize(glm::cross(n, c[(j + 1) % nc] - c[j]));
      const double da = glm::dot(m, a - c[j]) - inset, db = glm::dot(m, b - c[j]) - inset;
      if (da < 0.0 && db < 0.0) t1 = -1.0;
      else if (da < 0.0) t0 = std::max(t0, da / (da - db));
      else if (db < 0.0) t1 = std::min(t1, da / (da - db));
    }
    longest = std::max(longest, (t1 - t0) * glm::length(b - a));
  }
  return longest;
}

// Whether a surface standing on element e's patch crosses e's interior (contact_length): the foot
// of a block without a bottom on a floor. The floor is dark on one side of such a line and lit on
// the other; an element across it showed the light under the block and the dark outside it.
bool Solver::Impl::contact_crosses(uint32_t e) const {
  const uint32_t p = e_patch[e];
  const glm::dvec3& n = prep.normal[p];
  const double eps = kRoundingLength * prep.diagonal;
  glm::dvec3 lo, hi;
  element_box(e, lo, hi);
  auto near = [&](const glm::dvec3& blo, const glm::dvec3& bhi) { return boxes_meet(lo, hi, blo, bhi, eps); };
  const double shortest = std::max(eps, kContactShare * std::sqrt(min_split_area() / std::pow(4.0, kCoverOutlineLevels)));
  return find_patch(near, [&](uint32_t q) {
    return q != p && prep.twin[q] != p && std::abs(glm::dot(prep.normal[q], n)) <= 1.0 - 1e-6 && contact_length(e, q, eps) > shortest;
  });
}

}  // namespace hemibake::solver
