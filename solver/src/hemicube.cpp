// The hemicube of Cohen and Greenberg (1985) with the anti-aliasing of "Anti-aliased hemicubes for
// performance improvement in radiosity solutions": polygons are clipped to the five faces and
// scan-converted with fractional coverage (Figure 4); each pixel's fragments are ordered by depth
// and share the pixel as E_0 = A_0, E_k = A_k (1 - f_{k-1}) (section 2.2.1).
#include "hemicube_engine.h"

#include "hemibake/solver/hemicube.h"
#include "check.h"
#include "scan_walk.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <stdexcept>

namespace hemibake::solver {
namespace detail {
namespace {

// A corner nearer to the eye than this share of the polygon's extent does not give a trustworthy
// 1/depth: the polygon is clipped there. clip_to_face's fast path and its clipper must agree, or
// a polygon's fragments would depend on which path it took.
constexpr double kNearPlane = 1e-9;
// A pixel covered by less than this fraction gets no fragment (rounding of the scan converter).
constexpr double kMinCoverage = 1e-9;

// Axes of the faces in the hemicube's own frame (x, y tangent, z the normal): the top, the four
// side faces (halves of them, but for a full cube), and a full cube's bottom.
struct LocalFace {
  glm::dvec3 right, up, forward;
  bool top;
};
constexpr std::array<LocalFace, 6> kLocalFaces{{
    {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, true},
    {{0, 1, 0}, {0, 0, 1}, {1, 0, 0}, false},
    {{0, -1, 0}, {0, 0, 1}, {-1, 0, 0}, false},
    {{-1, 0, 0}, {0, 0, 1}, {0, 1, 0}, false},
    {{1, 0, 0}, {0, 0, 1}, {0, -1, 0}, false},
    {{1, 0, 0}, {0, -1, 0}, {0, 0, -1}, true},
}};

// Keeps the part of `in` where dist(q) >= 0 (Sutherland-Hodgman against one plane). A convex
// polygon gains at most one vertex per plane.
template <typename Dist>
void clip_plane(const ClipPolygon& in, ClipPolygon& out, Dist dist) {
  out.n = 0;
  const int n = in.n;
  if (n == 0) return;
  glm::dvec3 prev = in.v[n - 1];
  double dprev = dist(prev);
  for (int i = 0; i < n; ++i) {
    const glm::dvec3& cur = in.v[i];
    const double dcur = dist(cur);
    if ((dprev >= 0.0) != (dcur >= 0.0) && out.n < ClipPolygon::kMax) {
      const double t = dprev / (dprev - dcur);
      out.v[out.n++] = prev + (cur - prev) * t;
    }
    if (dcur >= 0.0 && out.n < ClipPolygon::kMax) out.v[out.n++] = cur;
    prev = cur;
    dprev = dcur;
  }
  if (out.n < 3) out.n = 0;
}

// A point of the hemicube's frame in face f's (right, up, forward) (see kLocalFaces).
inline glm::dvec3 to_face(size_t f, const glm::dvec3& l) {
  switch (f) {
    case 0: return l;
    case 1: return glm::dvec3(l.y, l.z, l.x);
    case 2: return glm::dvec3(-l.y, l.z, -l.x);
    case 3: return glm::dvec3(-l.x, l.z, l.y);
    case 4: return glm::dvec3(l.x, l.z, -l.y);
    default: return glm::dvec3(l.x, -l.y, -l.z);
  }
}

glm::dvec3 newell_normal(std::span<const glm::dvec3> p) {
  glm::dvec3 n(0.0);
  for (size_t i = 0; i < p.size(); ++i) {
    const glm::dvec3& a = p[i];
    const glm::dvec3& b = p[(i + 1) % p.size()];
    n.x += (a.y - b.y) * (a.z + b.z);
    n.y += (a.z - b.z) * (a.x + b.x);
    n.z += (a.x - b.x) * (a.y + b.y);
  }
  return n;
}

}  // namespace

namespace {

// Pair lists keyed (a << 32) | b: sorts `pairs` by key, keeps one entry per key, and drops a key
// whose entries disagree (`agree`).
template <class T, class Agree>
void sort_and_drop_disagreeing(std::vector<T>& pairs, Agree agree) {
  std::sort(pairs.begin(), pairs.end(), [](const T& x, const T& y) { return x.key < y.key; });
  size_t out = 0;
  bool disagree = false;  // the entries merged into pairs[out - 1] disagree
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (out > 0 && pairs[out - 1].key == pairs[i].key) {
      disagree = disagree || !agree(pairs[out - 1], pairs[i]);
      continue;
    }
    if (disagree) --out;
    disagree = false;
    pairs[out++] = pairs[i];
  }
  if (disagree) --out;
  pairs.resize(out);
}

// Where each a's entries start in sorted `pairs`, so that a pixel's resolve looks them up by index
// instead of searching; left empty where ids are sparse (a caller's own, from 2^31 on).
template <class T>
void index_by_first(const std::vector<T>& pairs, std::vector<uint32_t>& first) {
  first.clear();
  const size_t ids = pairs.empty() ? 0 : static_cast<size_t>(pairs.back().key >> 32) + 1;
  if (ids > 16 * pairs.size() + 65536) return;
  first.assign(ids + 1, 0);
  for (const T& x : pairs) ++first[static_cast<size_t>(x.key >> 32) + 1];
  for (size_t a = 1; a < first.size(); ++a) first[a] += first[a - 1];
}

// a's entries in sorted `pairs`: by the index where there is one, else by search.
template <class T>
std::span<const T> entries_of(const std::vector<T>& pairs, const std::vector<uint32_t>& first, uint32_t a) {
  if (!first.empty()) {
    if (static_cast<size_t>(a) + 1 >= first.size()) return {};
    return {pairs.data() + first[a], static_cast<size_t>(first[a + 1] - first[a])};
  }
  const uint64_t lo = static_cast<uint64_t>(a) << 32;
  auto below = [](const T& x, uint64_t k) { return x.key < k; };
  const auto b = std::lower_bound(pairs.begin(), pairs.end(), lo, below);
  const auto e = std::lower_bound(b, pairs.end(), lo + (uint64_t{1} << 32), below);
  return {pairs.data() + (b - pairs.begin()), static_cast<size_t>(e - b)};
}

}  // namespace

void GroupAdjacency::add(uint32_t a, uint32_t b, bool folded) {
  if (a == b) return;
  links_.push_back({(static_cast<uint64_t>(a) << 32) | b, folded});
  links_.push_back({(static_cast<uint64_t>(b) << 32) | a, folded});
}

// Groups whose common edges disagree (a wall standing on the line between two floor tiles of one
// group, one tile on each side, where the floor goes on around the wall's end) are not linked: they
// are ordered by depth like any two surfaces. Counted as tiling, the wall and the floor behind it
// shared every pixel where both showed, half each: a wall on such a floor took two thirds of its
// sky, and light went through it to the floor beyond.
void GroupAdjacency::finish() {
  sort_and_drop_disagreeing(links_, [](const Link& x, const Link& y) { return x.folded == y.folded; });
  index_by_first(links_, first_);
}

const GroupAdjacency::Link* GroupAdjacency::find(uint32_t a, uint32_t b) const {
  const std::span<const Link> of_a = neighbours(a);
  const uint64_t key = (static_cast<uint64_t>(a) << 32) | b;
  const auto it = std::lower_bound(of_a.begin(), of_a.end(), key, [](const Link& l, uint64_t k) { return l.key < k; });
  return it != of_a.end() && it->key == key ? &*it : nullptr;
}

std::span<const GroupAdjacency::Link> GroupAdjacency::neighbours(uint32_t a) const {
  return entries_of(links_, first_, a);
}

void GroupAdjacency::add_standing(uint32_t base, uint32_t top, bool on_front) {
  if (base == top) return;
  standing_.push_back({(static_cast<uint64_t>(base) << 32) | top, true, on_front});
  standing_.push_back({(static_cast<uint64_t>(top) << 32) | base, false, on_front});
}

// Sorted for standing_order's search; a pair listed twice in disagreement (each standing on the
// other, or on both sides) is dropped, and so is a pair with an edge link.
void GroupAdjacency::finish_standing() {
  sort_and_drop_disagreeing(standing_, [](const Stand& x, const Stand& y) {
    return x.x_base == y.x_base && x.on_front == y.on_front;
  });
  std::erase_if(standing_, [&](const Stand& s) {
    return find(static_cast<uint32_t>(s.key >> 32), static_cast<uint32_t>(s.key)) != nullptr;
  });
  index_by_first(standing_, standing_first_);
}

std::span<const GroupAdjacency::Stand> GroupAdjacency::standing_of(uint32_t a) const {
  return entries_of(standing_, standing_first_, a);
}

double foot_within(std::span<const glm::dvec3> base, const glm::dvec3& n, const glm::dvec3& a, const glm::dvec3& b,
                   double in_plane, double tol) {
  if (std::abs(glm::dot(n, a - base[0])) > in_plane || std::abs(glm::dot(n, b - base[0])) > in_plane) return 0.0;
  double t0 = 0.0, t1 = 1.0;
  for (size_t j = 0; j < base.size() && t0 < t1; ++j) {
    const glm::dvec3& c = base[j];
    const glm::dvec3 m = glm::normalize(glm::cross(n, base[(j + 1) % base.size()] - c));  // inward
    const double da = glm::dot(m, a - c) + tol, db = glm::dot(m, b - c) + tol;
    if (da < 0.0 && db < 0.0) return 0.0;
    if (da < 0.0) t0 = std::max(t0, da / (da - db));
    else if (db < 0.0) t1 = std::min(t1, da / (da - db));
  }
  return std::max(0.0, t1 - t0) * glm::distance(a, b);
}

int GroupAdjacency::standing_order(uint64_t a, uint64_t b) const {
  const std::span<const Stand> of_a = standing_of(static_cast<uint32_t>(a));
  if (of_a.empty()) return 0;
  const uint64_t key = (a << 32) | (b & 0xffffffffu);
  const auto it = std::lower_bound(of_a.begin(), of_a.end(), key, [](const Stand& s, uint64_t k) { return s.key < k; });
  if (it == of_a.end() || it->key != key) return 0;
  // The base seen from its front (no back-face bit) has the eye on the side it faces: the top
  // hides it when the top stands on that side.
  const uint64_t base = it->x_base ? a : b;
  const bool base_front_seen = (base >> 32) == 0;
  const bool top_first = base_front_seen == it->on_front;
  return top_first == it->x_base ? 1 : -1;
}

void Hemicube::lay_out_faces() {
  const uint32_t half = n_ / 2;
  pixel_count_ = full_ ? 6 * n_ * n_ : n_ * n_ + 4 * n_ * half;
  uint32_t offset = 0;
  for (size_t f = 0; f < face_count_; ++f) {
    const bool whole = kLocalFaces[f].top || full_;
    faces_[f].b_min = whole ? -1.0 : 0.0;
    faces_[f].height = whole ? n_ : half;
    faces_[f].offset = offset;
    offset += faces_[f].height * n_;
  }
  HEMIBAKE_DCHECK(offset == pixel_count_);
}

Hemicube::Hemicube(uint32_t resolution, bool full) : n_(resolution), full_(full), face_count_(full ? 6 : 5) {
  assert(resolution >= 2 && resolution % 2 == 0);
  lay_out_faces();
  dff_.resize(pixel_count_);
  const double step = 2.0 / n_;
  for (size_t f = 0; f < face_count_ && !full; ++f) {
    const LocalFace& lf = kLocalFaces[f];
    for (uint32_t row = 0; row < faces_[f].height; ++row) {
      for (uint32_t col = 0; col < n_; ++col) {
        // The exact form factor of the pixel (Lambert) rather than the classical centre-point
        // value: the pixels' factors then sum to 1 and edge pixels are not biased.
        const double a0 = -1.0 + col * step, a1 = a0 + step;
        const double b0 = faces_[f].b_min + row * step, b1 = b0 + step;
        const std::array<glm::dvec3, 4> corners{
            lf.right * a0 + lf.up * b0 + lf.forward, lf.right * a1 + lf.up * b0 + lf.forward,
            lf.right * a1 + lf.up * b1 + lf.forward, lf.right * a0 + lf.up * b1 + lf.forward};
        dff_[faces_[f].offset + row * n_ + col] = point_polygon_form_factor(glm::dvec3(0.0), glm::dvec3(0, 0, 1), corners);
      }
    }
  }
  // A full cube's pixels tile the sphere: each one's share of it.
  if (full) fill_solid_angles(1.0 / (4.0 * std::numbers::pi));
  // The pixels tile the hemisphere (the sphere): their exact form factors (shares) sum to 1.
  HEMIBAKE_DCHECK(std::abs(std::accumulate(dff_.begin(), dff_.end(), 0.0) - 1.0) < 1e-6);
  place(glm::dvec3(0.0), glm::dvec3(0, 0, 1), glm::dvec3(0, 1, 0));
}

Hemicube::Hemicube(uint32_t resolution, SolidAngleTag) : n_(resolution), full_(false), face_count_(5) {
  assert(resolution >= 2 && resolution % 2 == 0);
  lay_out_faces();
  dff_.resize(pixel_count_);
  fill_solid_angles(1.0);
  // The pixels tile the hemisphere: 2 pi steradians.
  HEMIBAKE_DCHECK(std::abs(std::accumulate(dff_.begin(), dff_.end(), 0.0) - 2.0 * std::numbers::pi) < 1e-5);
  place(glm::dvec3(0.0), glm::dvec3(0, 0, 1), glm::dvec3(0, 1, 0));
}

void Hemicube::fill_solid_angles(double scale) {
  // pixel_solid_angle's corner terms, once per corner of the faces' grids rather than four times
  // per pixel (a 256 light cube has 196 608 pixels).
  const double step = 2.0 / n_;
  const uint32_t w = n_ + 1;
  std::vector<double> corner;
  for (size_t f = 0; f < face_count_; ++f) {
    const Face& face = faces_[f];
    corner.resize(static_cast<size_t>(w) * (face.height + 1));
    for (uint32_t row = 0; row <= face.height; ++row)
      for (uint32_t col = 0; col <= n_; ++col) {
        const double a = -1.0 + col * step, b = face.b_min + row * step;
        corner[row * w + col] = std::atan(a * b / std::sqrt(1.0 + a * a + b * b));
      }
    for (uint32_t row = 0; row < face.height; ++row)
      for (uint32_t col = 0; col < n_; ++col)
        dff_[face.offset + row * n_ + col] = scale * (corner[(row + 1) * w + col + 1] - corner[(row + 1) * w + col] -
                                                      corner[row * w + col + 1] + corner[row * w + col]);
  }
  HEMIBAKE_DCHECK(std::abs(dff_[pixel_count_ / 3] - scale * pixel_solid_angle(pixel_count_ / 3)) < 1e-12);
}

Hemicube Hemicube::solid_angles(uint32_t resolution) { return Hemicube(resolution, SolidAngleTag{}); }

Hemicube::Hemicube(uint32_t resolution, TopFaceTag) : n_(resolution), full_(false), face_count_(1) {
  assert(resolution >= 2 && resolution % 2 == 0);
  pixel_count_ = n_ * n_;
  dff_.assign(pixel_count_, 1.0 / pixel_count_);
  faces_[0].b_min = -1.0;
  faces_[0].height = n_;
  faces_[0].offset = 0;
  place(glm::dvec3(0.0), glm::dvec3(0, 0, 1), glm::dvec3(0, 1, 0));
}

Hemicube Hemicube::top_face(uint32_t resolution) { return Hemicube(resolution, TopFaceTag{}); }

void Hemicube::place(const glm::dvec3& eye, const glm::dvec3& normal, const glm::dvec3& up_hint) {
  eye_ = eye;
  glm::dvec3 t = glm::cross(up_hint, normal);
  if (glm::dot(t, t) < 1e-12) t = glm::cross(std::abs(normal.x) < 0.9 ? glm::dvec3(1, 0, 0)
                                                                     : glm::dvec3(0, 1, 0),
                                             normal);
  t = glm::normalize(t);
  const glm::dvec3 b = glm::cross(normal, t);
  frame_x_ = t;
  frame_y_ = b;
  frame_z_ = normal;
  auto to_world = [&](const glm::dvec3& v) { return v.x * t + v.y * b + v.z * normal; };
  for (size_t f = 0; f < face_count_; ++f) {
    faces_[f].right = to_world(kLocalFaces[f].right);
    faces_[f].up = to_world(kLocalFaces[f].up);
    faces_[f].forward = to_world(kLocalFaces[f].forward);
  }
}

size_t Hemicube::pixel_square(uint32_t pixel, std::array<double, 4>& square) const {
  size_t f = 0;
  while (f + 1 < face_count_ && pixel >= faces_[f + 1].offset) ++f;
  const uint32_t local = pixel - faces_[f].offset;
  const double step = 2.0 / n_;
  const double a0 = -1.0 + (local % n_) * step, b0 = faces_[f].b_min + (local / n_) * step;
  square = {a0, a0 + step, b0, b0 + step};
  return f;
}

glm::dvec3 Hemicube::pixel_direction(uint32_t pixel) const {
  std::array<double, 4> sq;
  const Face& face = faces_[pixel_square(pixel, sq)];
  return face.right * (0.5 * (sq[0] + sq[1])) + face.up * (0.5 * (sq[2] + sq[3])) + face.forward;
}

double Hemicube::pixel_solid_angle(uint32_t pixel) const {
  std::array<double, 4> sq;
  pixel_square(pixel, sq);
  // The solid angle of the rectangle [0, a] x [0, b] on the plane at distance 1, seen from a
  // corner's foot, is atan(a b / sqrt(1 + a^2 + b^2)); a pixel is four such corners' difference.
  auto corner = [](double a, double b) { return std::atan(a * b / std::sqrt(1.0 + a * a + b * b)); };
  return corner(sq[1], sq[3]) - corner(sq[0], sq[3]) - corner(sq[1], sq[2]) + corner(sq[0], sq[2]);
}

void Hemicube::to_local(std::span<const glm::dvec3> polygon, ProjectScratch& s) const {
  s.local_n = 0;
  for (const glm::dvec3& p : polygon) {
    const glm::dvec3 d = p - eye_;
    s.local[s.local_n++] = glm::dvec3(glm::dot(d, frame_x_), glm::dot(d, frame_y_), glm::dot(d, frame_z_));
  }
}

int Hemicube::common_face(const ProjectScratch& s) const {
  int face = -1;
  for (int i = 0; i < s.local_n; ++i) {
    const glm::dvec3& l = s.local[i];
    const double ax = std::abs(l.x), ay = std::abs(l.y);
    int f;
    if (full_) {
      // Each face's frustum is where its axis dominates (strictly).
      const double az = std::abs(l.z);
      if (az > ax && az > ay) f = l.z > 0.0 ? 0 : 5;
      else if (ax > ay && ax > az) f = l.x > 0.0 ? 1 : 2;
      else if (ay > ax && ay > az) f = l.y > 0.0 ? 3 : 4;
      else return -1;  // on a face boundary
    } else if (l.z > ax && l.z > ay) {
      f = 0;
    } else if (l.z > 0.0 && ax > ay && ax > l.z) {
      f = l.x > 0.0 ? 1 : 2;
    } else if (l.z > 0.0 && ay > ax && ay > l.z) {
      f = l.y > 0.0 ? 3 : 4;
    } else {
      return -1;  // on a face boundary or below the base
    }
    if (face >= 0 && f != face) return -1;
    face = f;
  }
  return face;
}

bool Hemicube::clip_to_face(size_t f, ProjectScratch& s, bool inside) const {
  const Face& face = faces_[f];
  if (inside) {
    // Every corner lies strictly inside the face's frustum (common_face): nothing to clip, unless
    // a corner is so near the eye that 1/depth is not to be trusted.
    const double half_n = 0.5 * n_;
    double scale = 0.0;
    for (int i = 0; i < s.local_n; ++i) {
      const glm::dvec3& l = s.local[i];
      scale = std::max(scale, std::abs(l.x) + std::abs(l.y) + std::abs(l.z));
    }
    s.poly2.clear();
    s.inv_depths.clear();
    bool near = false;
    for (int i = 0; i < s.local_n && !near; ++i) {
      const glm::dvec3 q = to_face(f, s.local[i]);
      near = q.z < kNearPlane * scale;
      const double inv_z = 1.0 / q.z;
      const double x = std::clamp((q.x * inv_z + 1.0) * half_n, 0.0, static_cast<double>(n_));
      const double y = std::clamp((q.y * inv_z - face.b_min) * half_n, 0.0, static_cast<double>(face.height));
      if (!s.poly2.empty() && s.poly2.back() == glm::dvec2(x, y)) continue;
      s.poly2.emplace_back(x, y);
      s.inv_depths.push_back(static_cast<float>(inv_z));
    }
    if (!near) {
      while (s.poly2.size() > 1 && s.poly2.back() == s.poly2.front()) {
        s.poly2.pop_back();
        s.inv_depths.pop_back();
      }
      return s.poly2.size() >= 3;
    }
  }
  ClipPolygon& a = s.clip_a;
  ClipPolygon& b = s.clip_b;
  a.n = 0;
  b.n = 0;
  double scale = 0.0;
  // Outcodes against the face's frustum: a polygon wholly outside one plane is not on this face.
  unsigned all_out = 0x1f, any_out = 0;
  for (int i = 0; i < s.local_n; ++i) {
    const glm::dvec3& l = s.local[i];
    const glm::dvec3 q = to_face(f, l);
    scale = std::max(scale, std::abs(q.x) + std::abs(q.y) + std::abs(q.z));
    unsigned out = 0;
    out |= (q.z - q.x < 0.0) ? 1u : 0u;
    out |= (q.z + q.x < 0.0) ? 2u : 0u;
    out |= (q.z - q.y < 0.0) ? 4u : 0u;
    out |= ((face.b_min < 0.0 ? q.z + q.y : q.y) < 0.0) ? 8u : 0u;
    out |= (q.z <= 0.0) ? 16u : 0u;
    all_out &= out;
    any_out |= out;
    a.v[a.n++] = q;
  }
  if (all_out != 0) return false;
  // The face's frustum: |a| <= depth, b within [b_min * depth, depth], and in front of the eye.
  // Only the planes that some corner lies outside of cut anything.
  ClipPolygon* in = &a;
  ClipPolygon* out = &b;
  auto clip = [&](auto dist) {
    clip_plane(*in, *out, dist);
    std::swap(in, out);
  };
  if (any_out & 1u) clip([](const glm::dvec3& q) { return q.z - q.x; });
  if (any_out & 2u) clip([](const glm::dvec3& q) { return q.z + q.x; });
  if (any_out & 4u) clip([](const glm::dvec3& q) { return q.z - q.y; });
  if (any_out & 8u) {
    if (face.b_min < 0.0) {
      clip([](const glm::dvec3& q) { return q.z + q.y; });
    } else {
      clip([](const glm::dvec3& q) { return q.y; });
    }
  }
  const double near = kNearPlane * scale;
  bool near_cut = false;
  for (int i = 0; i < in->n && !near_cut; ++i) near_cut = in->v[i].z < near;
  if (near_cut) clip([near](const glm::dvec3& q) { return q.z - near; });
  if (in->n == 0) return false;
  const ClipPolygon& clipped = *in;

  const double half_n = 0.5 * n_;
  s.poly2.clear();
  s.inv_depths.clear();
  for (int i = 0; i < clipped.n; ++i) {
    const glm::dvec3& q = clipped.v[i];
    const double x = std::clamp((q.x / q.z + 1.0) * half_n, 0.0, static_cast<double>(n_));
    const double y = std::clamp((q.y / q.z - face.b_min) * half_n, 0.0,
                                static_cast<double>(face.height));
    // Clipping at a corner that lies on a clip plane repeats it: drop repeats, which would
    // otherwise be zero-length edges.
    if (!s.poly2.empty() && s.poly2.back() == glm::dvec2(x, y)) continue;
    s.poly2.emplace_back(x, y);
    s.inv_depths.push_back(static_cast<float>(1.0 / q.z));
  }
  while (s.poly2.size() > 1 && s.poly2.back() == s.poly2.front()) {
    s.poly2.pop_back();
    s.inv_depths.pop_back();
  }
  return s.poly2.size() >= 3;
}

namespace {

// The bounding box of a polygon in a face's pixel coordinates: x min, x max, y min, y max.
std::array<double, 4> bounds_of(const std::vector<glm::dvec2>& poly) {
  std::array<double, 4> b{poly[0].x, poly[0].x, poly[0].y, poly[0].y};
  for (const glm::dvec2& p : poly) {
    b[0] = std::min(b[0], p.x);
    b[1] = std::max(b[1], p.x);
    b[2] = std::min(b[2], p.y);
    b[3] = std::max(b[3], p.y);
  }
  return b;
}

}  // namespace

void Hemicube::rasterize(const Face& face, uint32_t element, Method method,
                         const glm::dvec3& plane_normal, double plane_offset,
                         std::span<const Fragment> parent, bool child, ProjectScratch& s,
                         std::vector<Fragment>& out, const FaceWindow* keep) const {
  const auto [xmin, xmax, ymin, ymax] = bounds_of(s.poly2);
  PixelWindow win;
  win.x0 = std::clamp(static_cast<int>(std::floor(xmin)), 0, static_cast<int>(n_) - 1);
  win.y0 = std::clamp(static_cast<int>(std::floor(ymin)), 0, static_cast<int>(face.height) - 1);
  const int x1 = std::clamp(static_cast<int>(std::ceil(xmax)), win.x0 + 1, static_cast<int>(n_));
  const int y1 =
      std::clamp(static_cast<int>(std::ceil(ymax)), win.y0 + 1, static_cast<int>(face.height));
  win.width = x1 - win.x0;
  win.height = y1 - win.y0;
  if (keep != nullptr) {
    const int kx0 = std::max(win.x0, keep->x0), ky0 = std::max(win.y0, keep->y0);
    const int kx1 = std::min(win.x0 + win.width, keep->x1), ky1 = std::min(win.y0 + win.height, keep->y1);
    if (kx0 >= kx1 || ky0 >= ky1) return;
    win = {kx0, ky0, kx1 - kx0, ky1 - ky0};
  }

  // Depth: 1/depth is affine in the face's (a, b) for a planar polygon, so it is evaluated from the
  // plane, by default at the centre of the part of the pixel the polygon covers, clamped to the
  // polygon's own range against rounding. Two faces that meet at an edge and project to the same
  // side of it (a double-sided box's outside and its inside seen past it) are so compared on the
  // side both cover; at the pixel's centre, which may lie on the other side, their order flips
  // (with it, light reached the inside of Blender's double-sided crate). A gather's hemicube
  // (set_depth_at_pixel_centre) compares every fragment of a pixel at its centre, along one ray:
  // compared where each one's covered part lies, a lamp hung 1 cm under a ceiling and seen at a
  // grazing angle lay behind the ceiling beside its near edge (that part of the ceiling is nearer
  // than the part of the lamp beside it), and along the lamp's outline the ceiling hid part of it
  // (an empty room's upper walls, gathered at a quarter of the solve's resolution, 10 % dark).
  // The centre lies within one pixel of the covered part, so the value leaves the polygon's range
  // by at most one pixel's step; it is clamped to that against rounding. Where the plane's horizon
  // crosses the pixel (the centre's ray misses the plane), the covered part's centre serves.
  float inv_lo = s.inv_depths[0], inv_hi = inv_lo;
  for (float v : s.inv_depths) {
    inv_lo = std::min(inv_lo, v);
    inv_hi = std::max(inv_hi, v);
  }
  const glm::dvec3 m(glm::dot(plane_normal, face.right), glm::dot(plane_normal, face.up),
                     glm::dot(plane_normal, face.forward));
  const double inv_h = plane_offset != 0.0 ? 1.0 / plane_offset : 0.0;
  const double step = 2.0 / n_;
  // 1/depth at face pixel coordinates (x, y), a = -1 + x step and b = b_min + y step on the face:
  // (m.x a + m.y b + m.z) / h, affine in (x, y); here in the window's coordinates.
  const double depth_x = m.x * step * inv_h, depth_y = m.y * step * inv_h;
  const double depth_0 = (m.x * (-1.0 + win.x0 * step) + m.y * (face.b_min + win.y0 * step) + m.z) * inv_h;
  const float pixel_step = static_cast<float>(std::abs(depth_x) + std::abs(depth_y));
  // The window's lower-left pixel; pixel (col, row) of the window is base + row n + col.
  const uint32_t base = face.offset + static_cast<uint32_t>(win.y0) * n_ + static_cast<uint32_t>(win.x0);

  // For children: walk the parent's fragments (sorted by pixel) alongside. Fragments go out in
  // increasing pixel order (the scan converter's sweep meets rows upwards).
  size_t pj = 0;
  // `cx`, `cy`: where in the pixel (0..1) the polygon's covered part is centred.
  auto emit = [&](int col, int row, float area, double cx, double cy) __attribute__((always_inline)) {
    Fragment fr;
    fr.pixel = base + static_cast<uint32_t>(row) * n_ + static_cast<uint32_t>(col);
    fr.element = element;
    fr.area = area;
    if (child) {
      while (pj < parent.size() && parent[pj].pixel < fr.pixel) ++pj;
      // Only rounding puts a child outside its parent's pixels.
      if (pj == parent.size() || parent[pj].pixel != fr.pixel) return;
      fr.trans = parent[pj].trans;
    } else {
      double v = depth_0 + depth_x * (col + cx) + depth_y * (row + cy);
      float lo = inv_lo, hi = inv_hi;
      if (centre_depth_) {
        if (const double at_centre = depth_0 + depth_x * (col + 0.5) + depth_y * (row + 0.5); at_centre > 0.0) {
          v = at_centre;
          lo -= pixel_step;
          hi += pixel_step;
        }
      }
      fr.inv_depth = std::clamp(static_cast<float>(v), lo, hi);
    }
    out.push_back(fr);
  };

  if (method == Method::kAntiAliased) {
    if (child) {
      detail::scan_walk<false>(s.poly2, win, s.scan, [&](int col, int row, double a, double, double) __attribute__((always_inline)) {
        if (a > kMinCoverage) emit(col, row, static_cast<float>(std::min(a, 1.0)), 0.5, 0.5);
      });
    } else {
      // The depth that orders a partly covered pixel is the polygon's mean depth over the part it
      // covers (1/depth is affine, so its mean is its value at that part's centroid). The pixel
      // centre would misorder surfaces that meet inside a pixel, such as a block standing on a
      // floor.
      detail::scan_walk<true>(s.poly2, win, s.scan, [&](int col, int row, double a, double mx, double my) __attribute__((always_inline)) {
        if (a <= kMinCoverage) return;
        emit(col, row, static_cast<float>(std::min(a, 1.0)), std::clamp(mx / a, 0.0, 1.0),
             std::clamp(my / a, 0.0, 1.0));
      });
    }
    return;
  }

  // Classical: the pixel belongs to the polygon when its centre is inside (top-left rule on
  // edges, so that a centre on an edge shared by two elements goes to exactly one of them).
  if (signed_area(s.poly2) < 0.0) std::reverse(s.poly2.begin(), s.poly2.end());
  const size_t nv = s.poly2.size();
  for (int row = 0; row < win.height; ++row) {
    const double cy = win.y0 + row + 0.5;
    for (int col = 0; col < win.width; ++col) {
      const double cx = win.x0 + col + 0.5;
      bool inside = true;
      for (size_t i = 0; i < nv && inside; ++i) {
        const glm::dvec2 p = s.poly2[i];
        const glm::dvec2 d = s.poly2[(i + 1) % nv] - p;
        if (d.x == 0.0 && d.y == 0.0) continue;
        const double e = d.x * (cy - p.y) - d.y * (cx - p.x);
        inside = e > 0.0 || (e == 0.0 && (d.y < 0.0 || (d.y == 0.0 && d.x < 0.0)));
      }
      if (inside) emit(col, row, 1.0f, 0.5, 0.5);
    }
  }
}

namespace {

// Keeps the part of the polygon in s.poly2 (a face's pixel coordinates) that lies in window w;
// false when none does. s.inv_depths keeps the whole polygon's corners: rasterize takes only their
// range from them, to clamp rounding. `cut_it`: cut the polygon at the window's edges (anti-aliased);
// otherwise only whether it meets the window is told, and rasterize keeps to the window's pixels
// (classical: a cut edge, a hair off the original, would flip the tie-break of pixel centres
// lying on a shared edge, giving the pixel to both neighbours or to neither).
bool keep_to_window(const FaceWindow& w, ProjectScratch& s, bool cut_it) {
  const auto [xmin, xmax, ymin, ymax] = bounds_of(s.poly2);
  if (xmax <= w.x0 || xmin >= w.x1 || ymax <= w.y0 || ymin >= w.y1) return false;
  if (!cut_it) return true;
  auto cut = [&s](int axis, double at, bool below) {
    s.window_cut.resize(2 * s.poly2.size() + 2);
    s.window_cut.resize(cut_loop(s.poly2.data(), s.poly2.size(), axis, at, below, s.window_cut.data()));
    std::swap(s.poly2, s.window_cut);
  };
  if (xmin < w.x0) cut(0, w.x0, false);
  if (xmax > w.x1) cut(0, w.x1, true);
  if (ymin < w.y0) cut(1, w.y0, false);
  if (ymax > w.y1) cut(1, w.y1, true);
  return s.poly2.size() >= 3;
}

}  // namespace

void Hemicube::widen_windows(std::span<const Fragment> fragments, FaceWindows& windows) const {
  for (const Fragment& fr : fragments) {
    size_t f = 0;
    while (f + 1 < face_count_ && fr.pixel >= faces_[f + 1].offset) ++f;
    const uint32_t local = fr.pixel - faces_[f].offset;
    const int x = static_cast<int>(local % n_), y = static_cast<int>(local / n_);
    windows[f].widen({x, y, x + 1, y + 1});
  }
}

uint64_t Hemicube::window_pixels(const FaceWindows& windows) const {
  uint64_t pixels = 0;
  for (size_t f = 0; f < face_count_; ++f)
    if (!windows[f].empty())
      pixels += static_cast<uint64_t>(windows[f].x1 - windows[f].x0) * static_cast<uint64_t>(windows[f].y1 - windows[f].y0);
  return pixels;
}

void Hemicube::project(std::span<const glm::dvec3> polygon, uint32_t element, Method method,
                       ProjectScratch& scratch, std::vector<Fragment>& out,
                       const glm::dvec3* plane_normal, const FaceWindows* windows) const {
  to_local(polygon, scratch);
  bool any_in_front = full_;
  for (int i = 0; i < scratch.local_n; ++i) any_in_front = any_in_front || scratch.local[i].z > 0.0;
  if (!any_in_front) return;  // wholly below the hemicube's base
  const glm::dvec3 normal = plane_normal != nullptr ? *plane_normal : newell_normal(polygon);
  const double offset = glm::dot(normal, polygon[0] - eye_);
  // The faces' frusta are convex cones, so a convex polygon whose corners all lie in one face's
  // frustum lies wholly on that face: the other four need not be looked at.
  const int single = common_face(scratch);
  for (size_t f = 0; f < face_count_; ++f) {
    if (single >= 0 && static_cast<int>(f) != single) continue;
    if (windows != nullptr && (*windows)[f].empty()) continue;
    if (!clip_to_face(f, scratch, single >= 0)) continue;
    const bool cut = method == Method::kAntiAliased;
    if (windows != nullptr && !keep_to_window((*windows)[f], scratch, cut)) continue;
    rasterize(faces_[f], element, method, normal, offset, {}, false, scratch, out,
              windows != nullptr && !cut ? &(*windows)[f] : nullptr);
  }
}

void Hemicube::project_child(std::span<const glm::dvec3> polygon, uint32_t element,
                             std::span<const Fragment> parent, Method method,
                             ProjectScratch& scratch, std::vector<Fragment>& out) const {
  if (parent.empty()) return;
  to_local(polygon, scratch);
  size_t begin = 0;
  for (size_t f = 0; f < face_count_; ++f) {
    const Face& face = faces_[f];
    // The parent's fragments on this face (they are sorted by pixel, faces in order).
    const uint32_t end_pixel = face.offset + face.height * n_;
    size_t end = begin;
    while (end < parent.size() && parent[end].pixel < end_pixel) ++end;
    if (end > begin && clip_to_face(f, scratch, false)) {
      rasterize(face, element, method, glm::dvec3(0.0), 0.0, parent.subspan(begin, end - begin),
                true, scratch, out);
    }
    begin = end;
  }
}

namespace {

// A pixel's fragments of one surface, summed (PixelResolver::layers).
struct GroupSum {
  uint64_t group;
  uint32_t root;
  double area;
  double depth_sum;  // the fragments' 1/depth times their coverage
  float inv_depth;   // depth_sum / area: the surface's 1/depth at the centre of what it covers
  float trans;
};

// A surface's 1/depth in a pixel: the mean of its fragments' by coverage, which (1/depth being
// affine over a plane) is its value at the centre of the part the surface covers, however the
// surface is cut into elements there. The nearest fragment's, as before, moved a finely cut
// surface forward by up to a pixel's depth: a rug 3 mm over a floor, both cut finely under a
// sun whose 7 cm pixels span 10 cm of depth along the floor, lost the sun in stripes to the
// floor under it.
float mean_depth(double depth_sum, double area) {
  return static_cast<float>(area > 0.0 ? depth_sum / area : 0.0);
}

// The side (bit 32 of a pixel's surface id) on which a neighbour across `link` of a surface on
// side `side` is folded behind it, or tiles with it (a back face is projected reversed, so a
// different side flips the link's case).
uint64_t fold_side(uint64_t side, const GroupAdjacency::Link& link) {
  return link.folded ? side : side ^ (uint64_t{1} << 32);
}
uint64_t tile_side(uint64_t side, const GroupAdjacency::Link& link) {
  return link.folded ? side ^ (uint64_t{1} << 32) : side;
}

// One thread's share of resolve(): the rule for one pixel's fragments, with the lists it reuses
// from pixel to pixel. A pixel's fragments are fragments[order[lo]] .. fragments[order[hi - 1]].
class PixelResolver {
 public:
  PixelResolver(std::span<Fragment> fragments, std::span<const uint32_t> order,
                std::span<const uint32_t> group_of, uint32_t covered_bit, std::span<const uint32_t> cover_of,
                const GroupAdjacency& adjacency)
      : fragments_(fragments), order_(order), group_of_(group_of), cover_of_(cover_of), covered_bit_(covered_bit),
        group_mask_(~covered_bit), adjacency_(adjacency) {
    thread_local std::vector<Slot> slots;
    thread_local uint32_t stamp = 0;
    if (slots.size() < adjacency.id_bound()) slots.resize(adjacency.id_bound());
    slots_ = slots.data();
    slot_count_ = adjacency.id_bound();
    stamp_ = &stamp;
  }

  // Classical: the nearest fragment takes the pixel.
  void nearest(uint32_t lo, uint32_t hi);
  // One or two surfaces (most shared pixels: inside a subdivided patch, along an edge where two
  // meet, one in front of another): the rule of layers() without lists or sorting. False, doing
  // nothing, when the pixel holds more.
  bool two_surfaces(uint32_t lo, uint32_t hi);
  // The nearest surface covers the pixel by itself and shares no edge with another of the pixel's
  // surfaces (a wall in front of a room's clutter): it takes the pixel and the rest nothing, as in
  // layers(), without lists or sorting. False, doing nothing, otherwise.
  bool front_covers(uint32_t lo, uint32_t hi);
  // Any number of surfaces: E_k = A_k (1 - f_{k-1}) over the pixel's layers, nearest first.
  void layers(uint32_t lo, uint32_t hi);
  // After one of the rules above: where a nearer layer took part of the pixel, a surface's fragments
  // that a surface on or just in front of it covers take none of its share, which goes to its
  // uncovered fragments (each at most its whole coverage).
  void open_share(uint32_t lo, uint32_t hi);

 private:
  // A fragment's surface: its occlusion group, with the back faces of a group apart (bit 32).
  uint64_t surface_of(uint32_t element) const {
    if (element & kBackFace) return (uint64_t{1} << 32) | (group_of_[element & ~kBackFace] & group_mask_);
    return group_of_[element] & group_mask_;
  }
  // surface_of, noting a covered fragment for open_share (each rule's first pass over the pixel
  // meets every fragment).
  uint64_t surface_noting(uint32_t element) {
    if (element & kBackFace) return (uint64_t{1} << 32) | (group_of_[element & ~kBackFace] & group_mask_);
    const uint32_t g = group_of_[element];
    saw_covered_ = saw_covered_ || (g & covered_bit_) != 0;
    return g & group_mask_;
  }
  enum class Meet : uint8_t { kApart, kTile, kFold };
  void pair_neighbours();
  Meet meet(uint64_t a, uint64_t b);
  int standing_order(uint64_t a, uint64_t b);
  void order_standing();
  void sum_groups(uint32_t lo, uint32_t hi);
  bool merge_neighbours();
  void order_layers(bool any_back, uint32_t lo, uint32_t hi);
  void order_covers(uint32_t lo, uint32_t hi);
  void share_pixel(bool any_back);
  uint32_t root(uint32_t i) {
    while (groups_[i].root != i) i = groups_[i].root = groups_[groups_[i].root].root;
    return i;
  }
  // A surface's place among the pixel's (sorted) surfaces, or -1.
  int64_t index_of(uint64_t id) const {
    const uint32_t low = static_cast<uint32_t>(id);
    if (low < slot_count_) {
      const Slot& slot = slots_[low];
      return slot.stamp == *stamp_ ? slot.at[id >> 32] : -1;
    }
    const auto it = std::lower_bound(groups_.begin(), groups_.end(), id,
                                     [](const GroupSum& g, uint64_t v) { return g.group < v; });
    return it != groups_.end() && it->group == id ? it - groups_.begin() : -1;
  }

  bool covered(uint32_t element) const {
    return !(element & kBackFace) && (group_of_[element] & covered_bit_) != 0;
  }
  // The surface id (as surface_of) of covered element's cover (cover_of), or kNoSurface.
  static constexpr uint64_t kNoSurface = ~uint64_t{0};
  uint64_t cover_surface(uint32_t element) const {
    const uint32_t cover = cover_of_[element];
    if (cover == kNone) return kNoSurface;
    return (cover & kBackFaceCover) ? (uint64_t{1} << 32) | (cover & ~kBackFaceCover) : cover;
  }
  int cover_order(uint32_t lo, uint32_t hi, uint64_t g0, uint64_t g1) const;
  bool covered_by_another(uint32_t lo, uint32_t hi, uint64_t surface) const;

  std::span<Fragment> fragments_;
  std::span<const uint32_t> order_;
  std::span<const uint32_t> group_of_;
  std::span<const uint32_t> cover_of_;
  uint32_t covered_bit_, group_mask_;
  bool saw_covered_ = false;  // a rule's pass over this pixel met a covered fragment
  const GroupAdjacency& adjacency_;
  // open_share: per surface of the pixel, its share and its uncovered coverage.
  struct OpenShare {
    uint64_t surface;
    double share, area, open;
  };
  std::vector<OpenShare> open_;
  // Neighbouring pixels mostly ask about the same two surfaces: the last answer is kept.
  uint64_t asked_a_ = 0, asked_b_ = 0;
  Meet asked_answer_ = Meet::kApart;
  bool asked_any_ = false;
  uint64_t stood_a_ = 0, stood_b_ = 0;
  int stood_answer_ = 0;
  bool stood_any_ = false;
  std::vector<std::pair<uint64_t, uint32_t>> by_group_;  // (surface, fragment's place in the pixel)
  std::vector<uint32_t> group_at_;  // per fragment of the pixel, in order: its group
  std::vector<GroupSum> groups_;
  std::vector<uint32_t> layers_;
  std::vector<uint32_t> rank_;  // per group root: its place in `layers_`
  std::vector<double> fold_cap_;  // per group root: the most a fold leaves it (share_pixel)
  std::vector<float> behind_cover_;  // order_covers: per group root, the farthest cover's 1/depth
  std::vector<std::pair<uint32_t, uint32_t>> folds_;  // pairs of the pixel's groups folded one behind the other
  std::vector<std::pair<uint32_t, uint32_t>> tiles_;  // pairs of the pixel's groups side by side
  std::vector<uint64_t> fold_mask_;  // merge_neighbours: per root, the roots folded against it
  std::vector<std::pair<uint32_t, uint32_t>> met_;    // pair_neighbours: (surface id, group)
  // Per thread, per surface id of the adjacency's: where the surface's two sides sit among the
  // pixel's groups, valid while `stamp` is the pixel's (sum_groups), so that index_of looks
  // neighbours up directly (a binary search per neighbour was 14 % of a 127k-triangle bake).
  struct Slot {
    uint32_t stamp = 0;
    std::array<int32_t, 2> at{-1, -1};
  };
  Slot* slots_ = nullptr;
  size_t slot_count_ = 0;
  uint32_t* stamp_ = nullptr;
};

// The pixel's groups that share an edge with another of its groups: folds_ holds the pairs (i, j)
// where j lies folded behind i, tiles_ those where j tiles with i (fold_side, tile_side), each
// ordered by i and then by j's surface id. By i's links when it has few; by the pixel's groups
// when it has more (a floor shares edges with much that stands on it, and a pixel holds a few
// surfaces). One pass over the links for both kinds, where a pass per kind (and a third for
// share_pixel) made merge_neighbours a seventh of a cluttered room's samples.
void PixelResolver::pair_neighbours() {
  folds_.clear();
  tiles_.clear();
  bool met_sorted = false;
  for (uint32_t i = 0; i < groups_.size(); ++i) {
    const uint64_t side = groups_[i].group & ~uint64_t{0xffffffffu};
    const uint32_t id = static_cast<uint32_t>(groups_[i].group);
    const std::span<const GroupAdjacency::Link> links = adjacency_.neighbours(id);
    if (links.size() <= 2 * groups_.size()) {
      for (const GroupAdjacency::Link& link : links) {
        const uint64_t other = link.key & 0xffffffffu;
        if (const int64_t j = index_of(fold_side(side, link) | other); j >= 0) folds_.emplace_back(i, static_cast<uint32_t>(j));
        if (const int64_t j = index_of(tile_side(side, link) | other); j >= 0) tiles_.emplace_back(i, static_cast<uint32_t>(j));
      }
      continue;
    }
    if (!met_sorted) {
      // groups_ runs by surface id over the front sides, then over the back sides: the two runs
      // merged.
      met_.clear();
      uint32_t backs = 0;
      while (backs < groups_.size() && (groups_[backs].group >> 32) == 0) ++backs;
      for (uint32_t a = 0, b = backs; a < backs || b < groups_.size();) {
        const bool take_a = b == groups_.size() ||
                            (a < backs && static_cast<uint32_t>(groups_[a].group) <= static_cast<uint32_t>(groups_[b].group));
        const uint32_t j = take_a ? a++ : b++;
        met_.emplace_back(static_cast<uint32_t>(groups_[j].group), j);
      }
      met_sorted = true;
    }
    for (const auto& [other, j] : met_) {
      const GroupAdjacency::Link* link = adjacency_.find(id, other);
      if (link == nullptr) continue;
      const uint64_t j_side = groups_[j].group & ~uint64_t{0xffffffffu};
      if (j_side == fold_side(side, *link)) folds_.emplace_back(i, j);
      if (j_side == tile_side(side, *link)) tiles_.emplace_back(i, j);
    }
  }
}

// How two surfaces (with their side bits) meet in a pixel: apart, side by side, or one folded
// behind the other (GroupAdjacency; a back face is projected reversed, so a different side flips
// the link's case).
PixelResolver::Meet PixelResolver::meet(uint64_t a, uint64_t b) {
  if (!asked_any_ || a != asked_a_ || b != asked_b_) {
    asked_a_ = a;
    asked_b_ = b;
    asked_any_ = true;
    const GroupAdjacency::Link* link = adjacency_.find(static_cast<uint32_t>(a), static_cast<uint32_t>(b));
    const bool sides_differ = (a >> 32) != (b >> 32);
    asked_answer_ = link == nullptr ? Meet::kApart : link->folded != sides_differ ? Meet::kFold : Meet::kTile;
  }
  return asked_answer_;
}

// GroupAdjacency::standing_order, the last answer kept as in meet().
int PixelResolver::standing_order(uint64_t a, uint64_t b) {
  if (!adjacency_.any_standing()) return 0;
  if (!stood_any_ || a != stood_a_ || b != stood_b_) {
    stood_a_ = a;
    stood_b_ = b;
    stood_any_ = true;
    stood_answer_ = adjacency_.standing_order(a, b);
  }
  return stood_answer_;
}

void PixelResolver::nearest(uint32_t lo, uint32_t hi) {
  uint32_t best = order_[lo];
  for (uint32_t k = lo + 1; k < hi; ++k) {
    const Fragment& f = fragments_[order_[k]];
    const Fragment& b = fragments_[best];
    if (f.inv_depth > b.inv_depth || (f.inv_depth == b.inv_depth && f.element < b.element))
      best = order_[k];
  }
  for (uint32_t k = lo; k < hi; ++k) fragments_[order_[k]].trans = order_[k] == best ? 1.0f : 0.0f;
}

bool PixelResolver::two_surfaces(uint32_t lo, uint32_t hi) {
  // Scalars rather than arrays indexed by the fragment's surface: no store-to-load chain.
  const uint64_t g0 = surface_of(fragments_[order_[lo]].element);
  uint64_t g1 = g0;
  double sum0 = 0.0, sum1 = 0.0, depth_sum0 = 0.0, depth_sum1 = 0.0;
  for (uint32_t k = lo; k < hi; ++k) {
    const Fragment& f = fragments_[order_[k]];
    const uint64_t g = surface_noting(f.element);
    if (g == g0) {
      sum0 += f.area;
      depth_sum0 += static_cast<double>(f.area) * f.inv_depth;
      continue;
    }
    if (g1 != g0 && g != g1) return false;
    g1 = g;
    sum1 += f.area;
    depth_sum1 += static_cast<double>(f.area) * f.inv_depth;
  }
  // A covered fragment's cover may lie behind its surface's mean depth (order_covers).
  const int cover_first = saw_covered_ && g1 != g0 && !cover_of_.empty() ? cover_order(lo, hi, g0, g1) : 0;
  const float depth0 = mean_depth(depth_sum0, sum0), depth1 = mean_depth(depth_sum1, sum1);
  float trans0, trans1;
  const Meet how = g1 == g0 ? Meet::kTile : meet(g0, g1);
  if (how == Meet::kTile) {
    const double total = sum0 + sum1;
    trans0 = trans1 = static_cast<float>(total > 1.0 ? 1.0 / total : 1.0);
  } else {
    // Nearest first; ties go to the lower id (a back face's is higher: front faces win). One
    // standing on the other goes by that (GroupAdjacency::add_standing).
    const int stand = how == Meet::kApart ? standing_order(g0, g1) : 0;
    const bool first_near = cover_first != 0 ? cover_first < 0
                            : stand != 0     ? stand < 0
                            : depth0 != depth1 ? depth0 > depth1
                                               : g0 < g1;
    const double near_sum = first_near ? sum0 : sum1, far_sum = first_near ? sum1 : sum0;
    const float near_trans = static_cast<float>(near_sum > 1.0 ? 1.0 / near_sum : 1.0);
    double t = 1.0 - std::min(near_sum, 1.0);
    // Two surfaces with a common edge that project to the same side of it, the far one folded
    // behind the near one (a wall's back seen past the edge of the roof it meets; the inside of
    // a double-sided box seen through its top): in a pixel on that edge the far one shows only
    // where it reaches past the near one.
    if (how == Meet::kFold && far_sum > 0.0)
      t = std::min(t, std::max(0.0, far_sum - near_sum) / far_sum);
    const float far_trans = static_cast<float>(far_sum > 1.0 ? t / far_sum : t);
    trans0 = first_near ? near_trans : far_trans;
    trans1 = first_near ? far_trans : near_trans;
  }
  for (uint32_t k = lo; k < hi; ++k) {
    Fragment& f = fragments_[order_[k]];
    f.trans = surface_of(f.element) == g0 ? trans0 : trans1;
  }
  return true;
}

bool PixelResolver::front_covers(uint32_t lo, uint32_t hi) {
  // The candidate: the surface of the nearest fragment (ties to the lower id, as in order_layers).
  uint64_t front = surface_noting(fragments_[order_[lo]].element);
  float depth = fragments_[order_[lo]].inv_depth;
  for (uint32_t k = lo + 1; k < hi; ++k) {
    const Fragment& f = fragments_[order_[k]];
    const uint64_t g = surface_noting(f.element);
    if (f.inv_depth > depth || (f.inv_depth == depth && g < front)) {
      front = g;
      depth = f.inv_depth;
    }
  }
  // order_covers may move it behind its fragments' cover.
  if (saw_covered_ && !cover_of_.empty() && covered_by_another(lo, hi, front)) return false;
  // Its coverage and mean depth, summed in the order sum_groups sums them.
  double area = 0.0, depth_sum = 0.0;
  for (uint32_t k = lo; k < hi; ++k) {
    const Fragment& f = fragments_[order_[k]];
    if (surface_of(f.element) != front) continue;
    area += f.area;
    depth_sum += static_cast<double>(f.area) * f.inv_depth;
  }
  if (area < 1.0) return false;
  // It is the nearest surface (as order_layers orders them, by mean depth) if every other
  // fragment lies behind its mean: another surface's mean is no nearer than its nearest fragment.
  const float mean = mean_depth(depth_sum, area);
  for (uint32_t k = lo; k < hi; ++k) {
    const Fragment& f = fragments_[order_[k]];
    const uint64_t g = surface_of(f.element);
    if (g != front && (f.inv_depth > mean || (f.inv_depth == mean && g < front))) return false;
  }
  // A surface standing on it may lie in front of it (order_standing): left to layers().
  if (adjacency_.any_standing()) {
    uint64_t asked = front;
    for (uint32_t k = lo; k < hi; ++k) {
      const uint64_t g = surface_of(fragments_[order_[k]].element);
      if (g == front || g == asked) continue;
      asked = g;
      if (standing_order(front, g) > 0) return false;
    }
  }
  // A neighbour in the pixel may join its layer (merge_neighbours): left to layers().
  for (const GroupAdjacency::Link& link : adjacency_.neighbours(static_cast<uint32_t>(front))) {
    const uint32_t other = static_cast<uint32_t>(link.key & 0xffffffffu);
    for (uint32_t k = lo; k < hi; ++k)
      if (static_cast<uint32_t>(surface_of(fragments_[order_[k]].element)) == other) return false;
  }
  const float trans = static_cast<float>(area > 1.0 ? 1.0 / area : 1.0);
  for (uint32_t k = lo; k < hi; ++k) {
    Fragment& f = fragments_[order_[k]];
    f.trans = surface_of(f.element) == front ? trans : 0.0f;
  }
  return true;
}

// The floor along the foot of a wall box standing on it: in a pixel on the foot, seen from the
// room, the wall hides the strip of floor under it and the floor shows beside it. The layers'
// rule takes them as independent, and gave the covered strip part of the floor's share, light
// that no one sees and that its elements shot into the box (a closed room built of wall boxes
// kept 0.965 of its light, of a closed form, a Blender room 0.96 of the path tracer's), and the
// visible floor beside the foot that much less. Likewise the ceiling beside a lamp hung 1 mm
// under it, seen past the lamp's outline (14 % dark 1 to 3 cm outside it). The surface's share
// is kept, and given to its uncovered fragments alone; not where nothing lies in front of it (the
// lamp's top lighting the ceiling above it).
void PixelResolver::open_share(uint32_t lo, uint32_t hi) {
  if (!saw_covered_) return;
  saw_covered_ = false;
  open_.clear();
  size_t last = 0;  // fragments of one surface mostly come together
  auto entry = [&](uint64_t surface) -> OpenShare& {
    if (last < open_.size() && open_[last].surface == surface) return open_[last];
    for (last = 0; last < open_.size(); ++last)
      if (open_[last].surface == surface) return open_[last];
    open_.push_back({surface, 0.0, 0.0, 0.0});
    return open_.back();
  };
  for (uint32_t k = lo; k < hi; ++k) {
    const Fragment& f = fragments_[order_[k]];
    OpenShare& o = entry(surface_of(f.element));
    o.share += static_cast<double>(f.area) * f.trans;
    o.area += f.area;
    if (!covered(f.element)) o.open += f.area;
  }
  for (uint32_t k = lo; k < hi; ++k) {
    Fragment& f = fragments_[order_[k]];
    const OpenShare& o = entry(surface_of(f.element));
    // Nothing nearer took any of the pixel: the surface keeps all it covers. Nothing of it here is
    // uncovered (the floor under a box seen through the gap under its bottom): as it is.
    if (o.share >= std::min(o.area, 1.0) * (1.0 - 1e-6) || o.open <= 0.0) continue;
    f.trans = covered(f.element) ? 0.0f : static_cast<float>(std::min(1.0, o.share / o.open));
  }
}

void PixelResolver::layers(uint32_t lo, uint32_t hi) {
  sum_groups(lo, hi);
  const bool any_fold = merge_neighbours();
  order_layers(any_fold, lo, hi);
  share_pixel(any_fold);
  for (uint32_t i = 0; i < groups_.size(); ++i) groups_[i].trans = groups_[root(i)].trans;
  for (uint32_t k = lo; k < hi; ++k) fragments_[order_[k]].trans = groups_[group_at_[k - lo]].trans;
}

// Sums the coverage of each occlusion group: pieces of one surface never hide each other.
// The groups come out in increasing surface id, each summed over its fragments in the pixel's
// order (increasing fragment index). A pixel mostly holds a few surfaces, each cut into many
// fragments where it is cut finely (a box's face under a lamp, in sixteen elements within one
// pixel): each fragment's surface is looked up among the few met so far rather than sorting the
// fragments. Past kFewSurfaces (a pixel of a coarse near-field hemicube over a tessellated sphere's
// facets), the fragments are sorted.
void PixelResolver::sum_groups(uint32_t lo, uint32_t hi) {
  constexpr size_t kFewSurfaces = 16;
  groups_.clear();
  group_at_.resize(hi - lo);
  uint32_t at = 0;
  bool few = true;
  for (uint32_t k = lo; k < hi && few; ++k) {
    const Fragment& f = fragments_[order_[k]];
    const uint64_t g = surface_noting(f.element);
    if (groups_.empty() || groups_[at].group != g) {
      at = 0;
      while (at < groups_.size() && groups_[at].group != g) ++at;
      if (at == groups_.size()) {
        few = groups_.size() < kFewSurfaces;
        groups_.push_back({g, at, 0.0, 0.0, 0.0f, 1.0f});
      }
    }
    groups_[at].area += f.area;
    groups_[at].depth_sum += static_cast<double>(f.area) * f.inv_depth;
    group_at_[k - lo] = at;
  }
  if (few) {
    // Into increasing surface id; group_at_ follows.
    bool sorted = true;
    for (size_t j = 1; j < groups_.size(); ++j) sorted = sorted && groups_[j - 1].group < groups_[j].group;
    if (!sorted) {
      std::sort(groups_.begin(), groups_.end(), [](const GroupSum& a, const GroupSum& b) { return a.group < b.group; });
      std::array<uint32_t, kFewSurfaces> moved{};
      for (uint32_t j = 0; j < groups_.size(); ++j) {
        moved[groups_[j].root] = j;
        groups_[j].root = j;
      }
      for (uint32_t& g : group_at_) g = moved[g];
    }
  } else {
    by_group_.clear();
    for (uint32_t k = lo; k < hi; ++k) by_group_.emplace_back(surface_of(fragments_[order_[k]].element), k - lo);
    for (uint32_t k = lo; k < hi && !saw_covered_; ++k) surface_noting(fragments_[order_[k]].element);
    std::sort(by_group_.begin(), by_group_.end());
    groups_.clear();
    for (const auto& [g, i] : by_group_) {
      const Fragment& f = fragments_[order_[lo + i]];
      if (groups_.empty() || groups_.back().group != g)
        groups_.push_back({g, static_cast<uint32_t>(groups_.size()), 0.0, 0.0, 0.0f, 1.0f});
      groups_.back().area += f.area;
      groups_.back().depth_sum += static_cast<double>(f.area) * f.inv_depth;
      group_at_[i] = static_cast<uint32_t>(groups_.size() - 1);
    }
  }
  for (GroupSum& g : groups_) g.inv_depth = mean_depth(g.depth_sum, g.area);
  if (slot_count_ == 0) return;
  if (++*stamp_ == 0) {  // wrapped: no slot may look current
    for (size_t i = 0; i < slot_count_; ++i) slots_[i].stamp = 0;
    *stamp_ = 1;
  }
  for (uint32_t j = 0; j < groups_.size(); ++j) {
    const uint32_t low = static_cast<uint32_t>(groups_[j].group);
    if (low >= slot_count_) continue;
    Slot& slot = slots_[low];
    if (slot.stamp != *stamp_) slot = {*stamp_, {-1, -1}};
    slot.at[groups_[j].group >> 32] = static_cast<int32_t>(j);
  }
}

// Merges groups that project side by side (GroupAdjacency). A surface's neighbours are looked up
// among the pixel's (sorted) surfaces: linear in the surfaces, where testing every pair was
// quadratic (a pixel of a coarse near-field hemicube can hold hundreds of a finely tessellated
// sphere's facets). Returns whether any two of them are folded one behind the other.
bool PixelResolver::merge_neighbours() {
  if (adjacency_.empty() || groups_.size() <= 1) return false;
  // Folded pairs first: two surfaces folded one behind the other never join one layer, even
  // through neighbours that tile with both (the floors of two rooms meet under the wall between
  // them, and each tiles with the wall's side that faces its room).
  pair_neighbours();
  if (folds_.empty()) {
    for (const auto& [i, j] : tiles_) {
      const uint32_t ri = root(i), rj = root(j);
      if (ri != rj) groups_[std::max(ri, rj)].root = std::min(ri, rj);
    }
    return false;
  }
  // Up to 64 groups, per root a mask of the roots it is folded against, joined as roots join;
  // past that, the folded pairs are searched.
  const bool masks = groups_.size() <= 64;
  if (masks) {
    fold_mask_.assign(groups_.size(), 0);
    for (const auto& [x, y] : folds_) {
      fold_mask_[x] |= uint64_t{1} << y;
      fold_mask_[y] |= uint64_t{1} << x;
    }
  }
  for (const auto& [i, j] : tiles_) {
    const uint32_t ri = root(i), rj = root(j);
    if (ri == rj) continue;
    bool apart = false;
    if (masks) {
      apart = (fold_mask_[ri] >> rj) & 1;
    } else {
      for (const auto& [x, y] : folds_) {
        const uint32_t rx = root(x), ry = root(y);
        apart = apart || (rx == ri && ry == rj) || (rx == rj && ry == ri);
      }
    }
    if (apart) continue;
    const uint32_t keep = std::min(ri, rj), gone = std::max(ri, rj);
    groups_[gone].root = keep;
    if (masks && fold_mask_[gone] != 0) {
      // Whoever was folded against `gone` is folded against `keep`.
      const uint64_t against = fold_mask_[gone];
      fold_mask_[keep] |= against;
      fold_mask_[gone] = 0;
      for (uint64_t m = against; m != 0; m &= m - 1) {
        const int k = std::countr_zero(m);
        fold_mask_[k] = (fold_mask_[k] & ~(uint64_t{1} << gone)) | (uint64_t{1} << keep);
      }
    }
  }
  return true;
}

// The merged groups' roots as layers, nearest first; ties go to the lower group id so the order is
// deterministic.
void PixelResolver::order_layers(bool any_fold, uint32_t lo, uint32_t hi) {
  layers_.clear();
  for (uint32_t i = 0; i < groups_.size(); ++i) {
    const uint32_t r = root(i);
    if (r != i) {
      groups_[r].area += groups_[i].area;
      groups_[r].depth_sum += groups_[i].depth_sum;
      groups_[r].inv_depth = mean_depth(groups_[r].depth_sum, groups_[r].area);
    } else {
      layers_.push_back(i);
    }
  }
  if (adjacency_.any_standing()) order_standing();
  if (saw_covered_ && !cover_of_.empty()) order_covers(lo, hi);
  std::sort(layers_.begin(), layers_.end(), [&](uint32_t a, uint32_t b) {
    if (groups_[a].inv_depth != groups_[b].inv_depth) return groups_[a].inv_depth > groups_[b].inv_depth;
    return groups_[a].group < groups_[b].group;
  });
  if (any_fold) {
    rank_.assign(groups_.size(), 0);
    for (uint32_t li = 0; li < layers_.size(); ++li) rank_[layers_[li]] = li;
  }
}

// Of two surfaces in the pixel where one stands on the other (GroupAdjacency::add_standing), the
// one behind is moved just behind the other's layer. Searched by a surface's standing partners
// when it has few, by the pixel's surfaces when it has more (a floor under hundreds of boxes).
// In a pixel on the foot, seen from the standing one's side, the base keeps the layers' rule: it
// takes what the standing one leaves times its own coverage, which leaves the floor just in front
// of a foot dark where the pixel is coarse (bench/README.md, "Surfaces standing on others").
void PixelResolver::order_standing() {
  auto settle = [&](uint32_t i, uint32_t j) {
    const int o = standing_order(groups_[i].group, groups_[j].group);
    if (o == 0) return;
    const uint32_t first = root(o < 0 ? i : j), second = root(o < 0 ? j : i);
    if (first == second) return;
    const float behind = std::nextafter(groups_[first].inv_depth, std::numeric_limits<float>::lowest());
    groups_[second].inv_depth = std::min(groups_[second].inv_depth, behind);
  };
  for (uint32_t i = 0; i < groups_.size(); ++i) {
    const uint32_t id = static_cast<uint32_t>(groups_[i].group);
    if (adjacency_.standing_count(id) <= 2 * groups_.size()) {
      adjacency_.for_standing(id, [&](uint32_t other) {
        for (uint64_t side : {uint64_t{0}, uint64_t{1} << 32}) {
          const int64_t j = index_of(side | other);
          if (j > static_cast<int64_t>(i)) settle(i, static_cast<uint32_t>(j));  // each pair once
        }
      });
    } else {
      for (uint32_t j = i + 1; j < groups_.size(); ++j) settle(i, j);
    }
  }
}

// A surface's fragments covered by a surface just in front of them (kCoverGap) lie behind that
// cover, whatever the two surfaces' mean depths say: in a pixel on a rug's edge, 3 mm over a floor
// and seen from across the room, the floor's mean is the pixel's centre and the rug's the centre of
// its part, often farther. Put in front, the floor took the whole pixel, its elements under the
// rug included (lit 15 where the path tracer has 0), and the rug none of it. So a surface goes just
// behind the farthest of its covered fragments' covers in the pixel; open_share then gives its
// share to its uncovered fragments. Only the cover itself: a surface that merely lies near in
// depth (the far inner side of a box standing on a table, over the table's covered part) is none.
// Of a pixel's two surfaces: 1 where g1 covers fragments of g0 (g1 goes first), -1 the other way
// round, else 0.
int PixelResolver::cover_order(uint32_t lo, uint32_t hi, uint64_t g0, uint64_t g1) const {
  for (uint32_t k = lo; k < hi; ++k) {
    const uint32_t e = fragments_[order_[k]].element;
    if (!covered(e)) continue;
    const uint64_t s = surface_of(e), c = cover_surface(e);
    if (s == g0 && c == g1) return 1;
    if (s == g1 && c == g0) return -1;
  }
  return 0;
}

// Whether a covered fragment of `surface` has its cover in the pixel.
bool PixelResolver::covered_by_another(uint32_t lo, uint32_t hi, uint64_t surface) const {
  uint64_t asked = kNoSurface;
  for (uint32_t k = lo; k < hi; ++k) {
    const uint32_t e = fragments_[order_[k]].element;
    if (!covered(e) || surface_of(e) != surface) continue;
    const uint64_t c = cover_surface(e);
    if (c == kNoSurface || c == asked) continue;
    asked = c;
    for (uint32_t j = lo; j < hi; ++j)
      if (surface_of(fragments_[order_[j]].element) == c) return true;
  }
  return false;
}

void PixelResolver::order_covers(uint32_t lo, uint32_t hi) {
  constexpr float kNoCover = std::numeric_limits<float>::max();
  behind_cover_.assign(groups_.size(), kNoCover);
  uint64_t asked = kNoSurface;
  int64_t at = -1;
  for (uint32_t k = lo; k < hi; ++k) {
    const Fragment& f = fragments_[order_[k]];
    if (!covered(f.element)) continue;
    const uint64_t cover = cover_surface(f.element);
    if (cover == kNoSurface) continue;
    if (cover != asked) {
      asked = cover;
      at = index_of(cover);
    }
    if (at < 0) continue;
    const uint32_t s = root(group_at_[k - lo]), r = root(static_cast<uint32_t>(at));
    if (r != s) behind_cover_[s] = std::min(behind_cover_[s], groups_[r].inv_depth);
  }
  for (uint32_t s : layers_)
    if (behind_cover_[s] != kNoCover && groups_[s].inv_depth >= behind_cover_[s])
      groups_[s].inv_depth = std::nextafter(behind_cover_[s], std::numeric_limits<float>::lowest());
}

// Each layer's transmission: what nearer layers left of the pixel (the paper's 1 - f_{k-1}).
void PixelResolver::share_pixel(bool any_fold) {
  // A layer folded behind a nearer one that shares an edge with it (two_surfaces) shows only where
  // it reaches past that one. Any surface merged into the layer may share the edge: the insides of a
  // double-sided box tile one layer, which only the faces meeting the near side's edges touch.
  if (any_fold) {
    fold_cap_.assign(groups_.size(), 1.0);
    for (const auto& [i, j] : folds_) {  // merge_neighbours's pairs
      const uint32_t ri = root(i), rj = root(j);
      if (groups_[ri].area > 0.0 && rank_[rj] < rank_[ri])
        fold_cap_[ri] = std::min(fold_cap_[ri], std::max(0.0, groups_[ri].area - groups_[rj].area) / groups_[ri].area);
    }
  }
  double f = 0.0;  // the paper's f_{k-1}: the pixel's fraction taken by nearer layers
  for (size_t li = 0; li < layers_.size(); ++li) {
    GroupSum& g = groups_[layers_[li]];
    double t = 1.0 - f;
    if (any_fold) t = std::min(t, fold_cap_[layers_[li]]);
    // Overlapping pieces of one layer (sum > 1) share the pixel in proportion.
    g.trans = static_cast<float>(g.area > 1.0 ? t / g.area : t);
    f += std::min(g.area, 1.0) * t;
  }
}

}  // namespace

void resolve(std::span<Fragment> fragments, uint32_t pixel_count, Method method,
             std::span<const uint32_t> group_of, uint32_t covered_bit, std::span<const uint32_t> cover_of,
             const GroupAdjacency& adjacency, ThreadPool& pool, std::vector<uint32_t>& order,
             std::vector<uint32_t>& pixel_start) {
  // Counting sort of fragment indices by pixel (stable: ties keep projection order).
  pixel_start.assign(static_cast<size_t>(pixel_count) + 1, 0);
  for (const Fragment& f : fragments) ++pixel_start[f.pixel + 1];
  for (uint32_t p = 0; p < pixel_count; ++p) pixel_start[p + 1] += pixel_start[p];
  order.resize(fragments.size());
  {
    std::vector<uint32_t> cursor(pixel_start.begin(), pixel_start.end() - 1);
    for (uint32_t i = 0; i < fragments.size(); ++i) order[cursor[fragments[i].pixel]++] = i;
  }
  pool.parallel_for(pixel_count, [&](size_t begin, size_t end, size_t) {
    PixelResolver pixel(fragments, order, group_of, covered_bit, covered_bit != 0 ? cover_of : std::span<const uint32_t>{},
                        adjacency);
    for (size_t p = begin; p < end; ++p) {
      const uint32_t lo = pixel_start[p], hi = pixel_start[p + 1];
      if (lo == hi) continue;
      if (method == Method::kClassical) {
        pixel.nearest(lo, hi);
        continue;
      }
      if (hi - lo == 1) {
        fragments[order[lo]].trans = 1.0f;  // alone: nothing nearer
        continue;
      }
      if (!pixel.two_surfaces(lo, hi) && !pixel.front_covers(lo, hi)) pixel.layers(lo, hi);
      pixel.open_share(lo, hi);
    }
  });
  // A fragment sees at most all of its pixel share, and nearer layers take at most all of it.
  for (const Fragment& f : fragments) HEMIBAKE_DCHECK(f.trans >= 0.0f && f.trans <= 1.0f);
}

}  // namespace detail

double point_polygon_form_factor(const glm::dvec3& eye, const glm::dvec3& normal,
                                 std::span<const glm::dvec3> polygon) {
  double sum = 0.0;
  const size_t n = polygon.size();
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec3 a = glm::normalize(polygon[i] - eye);
    const glm::dvec3 b = glm::normalize(polygon[(i + 1) % n] - eye);
    const glm::dvec3 c = glm::cross(a, b);
    const double len = glm::length(c);
    if (len == 0.0) continue;
    const double angle = std::atan2(len, glm::dot(a, b));
    sum += angle * glm::dot(normal, c) / len;
  }
  return std::abs(sum) / (2.0 * std::numbers::pi);
}

namespace {

// Projects polygon i of `polygons` into `frags`, unless it faces away from the eye.
void project_polygon(const detail::Hemicube& cube, const glm::dvec3& eye, std::span<const ReceiverPolygon> polygons,
                     uint32_t i, Method method, detail::ProjectScratch& scratch, std::vector<detail::Fragment>& frags,
                     const detail::FaceWindows* windows) {
  const auto& poly = polygons[i].corners;
  if (poly.size() < 3) return;
  const glm::dvec3 pn = detail::newell_normal(poly);
  if (glm::dot(pn, eye - poly[0]) <= 0.0) return;  // facing away
  // Long loops are cut into a fan of triangles: the clipper holds a bounded number of corners.
  if (poly.size() <= 8) {
    cube.project(poly, i, method, scratch, frags, nullptr, windows);
    return;
  }
  for (size_t k = 1; k + 1 < poly.size(); ++k) {
    const std::array<glm::dvec3, 3> tri{poly[0], poly[k], poly[k + 1]};
    cube.project(tri, i, method, scratch, frags, nullptr, windows);
  }
}

// Each polygon's visible share of the placed cube's view: its fragments' coverage times their
// transmission, summed with the pixels' delta form factors (a full cube's: shares of the sphere).
// With `receivers`, the view is kept to their pixels and only theirs are summed.
std::vector<double> visible_shares(const detail::Hemicube& cube, const glm::dvec3& eye,
                                   std::span<const ReceiverPolygon> polygons, Method method,
                                   std::span<const uint32_t> receivers = {}) {
  detail::ProjectScratch scratch;
  std::vector<detail::Fragment> frags;
  std::vector<uint32_t> group_of(polygons.size());
  for (uint32_t i = 0; i < polygons.size(); ++i)
    group_of[i] = polygons[i].group != kNone ? polygons[i].group : 0x80000000u + i;
  detail::FaceWindows windows{};
  for (uint32_t i : receivers) {
    if (i >= polygons.size()) throw std::invalid_argument("hemicube_form_factors: receiver index out of range");
    project_polygon(cube, eye, polygons, i, method, scratch, frags, nullptr);
    cube.widen_windows(frags, windows);
    frags.clear();
  }
  for (uint32_t i = 0; i < polygons.size(); ++i)
    project_polygon(cube, eye, polygons, i, method, scratch, frags, receivers.empty() ? nullptr : &windows);
  // Polygons with a common edge (the same two corner points) are neighbours, as in a solve.
  detail::GroupAdjacency adjacency;
  {
    // (polygon, whether it runs the edge from the smaller corner to the larger) per edge.
    std::map<std::pair<std::array<double, 3>, std::array<double, 3>>, std::vector<std::pair<uint32_t, bool>>> edges;
    for (uint32_t i = 0; i < polygons.size(); ++i) {
      const auto& poly = polygons[i].corners;
      for (size_t k = 0; k < poly.size() && poly.size() >= 3; ++k) {
        std::array<double, 3> a{poly[k].x, poly[k].y, poly[k].z};
        const glm::dvec3& q = poly[(k + 1) % poly.size()];
        std::array<double, 3> b{q.x, q.y, q.z};
        const bool forward = a < b;
        if (!forward) std::swap(a, b);
        edges[{a, b}].emplace_back(i, forward);
      }
    }
    for (const auto& [edge, list] : edges)
      for (size_t x = 0; x < list.size(); ++x)
        for (size_t y = x + 1; y < list.size(); ++y)
          adjacency.add(group_of[list[x].first], group_of[list[y].first], list[x].second == list[y].second);
    adjacency.finish();
    // Polygons standing on others (an edge in another's plane, within it), as in a solve; the whole
    // group of the one standing lies on one side of the plane.
    std::vector<glm::dvec3> normals(polygons.size());
    double extent = 0.0;
    for (uint32_t i = 0; i < polygons.size(); ++i) {
      if (polygons[i].corners.size() >= 3) normals[i] = glm::normalize(detail::newell_normal(polygons[i].corners));
      for (const glm::dvec3& c : polygons[i].corners) extent = std::max(extent, glm::length(c - eye));
    }
    const double in_plane = 1e-9 * extent, tol = 1e-9 * extent;
    for (uint32_t q = 0; q < polygons.size(); ++q)
      for (uint32_t p = 0; p < polygons.size(); ++p) {
        const auto& base = polygons[p].corners;
        const auto& top = polygons[q].corners;
        if (group_of[p] == group_of[q] || base.size() < 3 || top.size() < 3 ||
            std::abs(glm::dot(normals[p], normals[q])) > 1.0 - 1e-9)
          continue;
        double foot = 0.0;
        for (size_t k = 0; k < top.size(); ++k)
          foot = std::max(foot, detail::foot_within(base, normals[p], top[k], top[(k + 1) % top.size()], in_plane, tol));
        if (foot <= tol) continue;
        double lo = 0.0, hi = 0.0;  // the top's group's reach behind and in front of the plane
        for (uint32_t r = 0; r < polygons.size(); ++r)
          if (group_of[r] == group_of[q])
            for (const glm::dvec3& c : polygons[r].corners) {
              lo = std::min(lo, glm::dot(normals[p], c - base[0]));
              hi = std::max(hi, glm::dot(normals[p], c - base[0]));
            }
        if ((lo < -in_plane) != (hi > in_plane)) adjacency.add_standing(group_of[p], group_of[q], hi > in_plane);
      }
    adjacency.finish_standing();
  }
  detail::ThreadPool pool(1);
  std::vector<uint32_t> order, starts;
  detail::resolve(frags, cube.pixel_count(), method, group_of, 0, {}, adjacency, pool, order, starts);
  std::vector<double> ff(polygons.size(), 0.0);
  const auto& dff = cube.delta_form_factors();
  for (const auto& f : frags) ff[f.element] += static_cast<double>(f.area) * f.trans * dff[f.pixel];
  if (!receivers.empty()) {
    std::vector<double> kept(polygons.size(), 0.0);
    for (uint32_t i : receivers) kept[i] = ff[i];
    ff = std::move(kept);
  }
  return ff;
}

}  // namespace

std::vector<double> hemicube_form_factors(const glm::dvec3& eye, const glm::dvec3& normal,
                                          std::span<const ReceiverPolygon> polygons, Method method,
                                          uint32_t resolution, const glm::dvec3& up_hint,
                                          std::span<const uint32_t> receivers) {
  detail::Hemicube cube(resolution);
  cube.place(eye, glm::normalize(normal), up_hint);
  return visible_shares(cube, eye, polygons, method, receivers);
}

std::vector<double> cube_solid_angles(const glm::dvec3& eye, std::span<const ReceiverPolygon> polygons, Method method,
                                      uint32_t resolution, const glm::dvec3& normal, const glm::dvec3& up_hint) {
  detail::Hemicube cube(resolution, true);
  cube.place(eye, glm::normalize(normal), up_hint);
  std::vector<double> shares = visible_shares(cube, eye, polygons, method);
  for (double& x : shares) x *= 4.0 * std::numbers::pi;
  return shares;
}

}  // namespace hemibake::solver
