// The hemicube: projection of polygons into pixel fragments, and per-pixel visibility.
#pragma once

#include "hemibake/solver/scan_convert.h"
#include "hemibake/solver/solver.h"
#include "thread_pool.h"

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace hemibake::solver::detail {

/// One element's share of one hemicube pixel: 16 bytes, since a solve writes and reads millions
/// of them (at 32 bytes the Cornell box solved 13 % slower). The element's occlusion group is
/// looked up by element (resolve's `group_of`).
struct Fragment {
  uint32_t pixel = 0;    ///< global pixel index (top face, then the four half faces; a full cube's bottom last)
  uint32_t element = 0;  ///< the caller's id for the polygon
  float area = 0.0f;     ///< covered fraction of the pixel (classical: 1, the centre is inside)
  union {
    /// Before resolve(): 1 / distance along the face axis, at the pixel (larger is nearer).
    float inv_depth = 0.0f;
    /// After resolve(): the fraction of the pixel not taken by nearer groups.
    float trans;
  };
};
static_assert(sizeof(Fragment) == 16);

/// Set in Fragment::element for the back of a one-sided surface: an occluder that takes no light.
/// Its fragments form layers of their own (never merged with front-facing neighbours, whose
/// projections do not tile with it) and lose depth ties to front faces.
inline constexpr uint32_t kBackFace = 0x80000000u;
/// In resolve()'s cover_of: the cover is seen from its back (a one-sided surface facing the element).
inline constexpr uint32_t kBackFaceCover = 0x80000000u;
/// A back face's 1/depth is scaled by this, so that a front face at the same depth (a surface
/// lying on another's back) stays in front of it.
inline constexpr float kBackDepthScale = 1.0f - 1e-5f;

/// Pairs of occlusion groups that share an edge, and how they project where both face the eye.
/// A polygon's corners run counter-clockwise as seen from its front, so its interior lies to the
/// left of each edge. Two polygons that run their common edge in opposite directions (a
/// consistently wound surface: a room's walls, a box's outside) project to opposite sides of it
/// and tile: within a pixel their coverages add rather than occlude. Two that run it in the same
/// direction project to the same side, one folded behind the other: the inside of a double-sided
/// box (the back twin of one side) seen through the front of the face it meets. A back face's
/// polygon is projected reversed, which swaps the two cases.
class GroupAdjacency {
 public:
  struct Link {
    uint64_t key;  ///< a << 32 | b
    bool folded;   ///< every common edge runs the same way in both (see above)
  };
  /// `folded`: this common edge runs the same way in a's and b's corner order.
  void add(uint32_t a, uint32_t b, bool folded);
  void finish();  ///< call once after the last add()
  /// The link between a and b, or null when they share no edge.
  const Link* find(uint32_t a, uint32_t b) const;
  /// The links of `a`, in increasing b.
  std::span<const Link> neighbours(uint32_t a) const;
  bool empty() const { return links_.empty(); }
  /// One past the largest id with links when they are indexed by id (dense ids), else 0.
  size_t id_bound() const { return first_.empty() ? 0 : first_.size() - 1; }

  /// Surface `top` stands on surface `base` without sharing an edge with it: an edge of top lies
  /// in base's plane, within it, and all of top lies on one side of that plane (`on_front`: the
  /// side base faces). The sides of a box without a bottom on a floor; a wall standing on the seam
  /// between two floor tiles. Seen from top's side of the plane, top hides base wherever both
  /// show; seen from the other side, base hides top. In a pixel on the foot their depths, taken at
  /// the centres of their covered parts, said either, and the floor in front of a foot took the
  /// foot's share of the pixel. Pairs with an edge link keep that link's rule.
  void add_standing(uint32_t base, uint32_t top, bool on_front);
  void finish_standing();  ///< call once after the last add_standing()
  /// Which of surfaces a and b (occlusion group ids, bit 32 set for a back face: the side seen)
  /// lies in front where both show in a pixel because one stands on the other: -1 a, 1 b, 0 neither
  /// stands on the other.
  int standing_order(uint64_t a, uint64_t b) const;
  /// How many surfaces stand on a or a stands on (for choosing how to search a pixel).
  size_t standing_count(uint32_t a) const { return standing_of(a).size(); }
  /// Calls fn(other) for each surface standing on a or that a stands on.
  template <class Fn>
  void for_standing(uint32_t a, Fn fn) const {
    for (const Stand& s : standing_of(a)) fn(static_cast<uint32_t>(s.key));
  }
  bool any_standing() const { return !standing_.empty(); }

 private:
  struct Stand {
    uint64_t key;   ///< x << 32 | y
    bool x_base;    ///< x is the one stood on
    bool on_front;  ///< the other lies on the side x or y (the base) faces
  };
  std::vector<Stand> standing_;
  std::vector<uint32_t> standing_first_;  ///< per a (and one past the last): its first in standing_;
                                          ///< empty for sparse ids, which search instead
  std::span<const Stand> standing_of(uint32_t a) const;
  std::vector<Link> links_;
  std::vector<uint32_t> first_;  ///< per a (and one past the last): its first link in links_
};

/// The length of segment a-b lying in the plane of the convex polygon `base` (unit normal n: both
/// ends within `in_plane` of it) and within the polygon, its outline included (within `tol`): the
/// foot of a surface standing on `base` (GroupAdjacency::add_standing). 0 when out of the plane.
double foot_within(std::span<const glm::dvec3> base, const glm::dvec3& n, const glm::dvec3& a, const glm::dvec3& b,
                   double in_plane, double tol);

/// A rectangle of one face's pixels: columns [x0, x1), rows [y0, y1).
struct FaceWindow {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool empty() const { return x0 >= x1 || y0 >= y1; }
  /// Grows to hold `o` too.
  void widen(const FaceWindow& o) {
    if (o.empty()) return;
    *this = empty() ? o
                    : FaceWindow{std::min(x0, o.x0), std::min(y0, o.y0), std::max(x1, o.x1), std::max(y1, o.y1)};
  }
};
/// Per face of a hemicube (a full cube's six), the pixels a projection keeps to
/// (Hemicube::project).
using FaceWindows = std::array<FaceWindow, 6>;

/// A polygon being clipped: at most 4 corners plus one per clip plane.
struct ClipPolygon {
  static constexpr int kMax = 16;
  std::array<glm::dvec3, kMax> v;
  int n = 0;
};

/// Per-thread scratch for projecting polygons.
struct ProjectScratch {
  ScanScratch scan;
  ClipPolygon clip_a, clip_b;
  std::array<glm::dvec3, ClipPolygon::kMax> local;  // the polygon in the hemicube's frame
  int local_n = 0;
  std::vector<glm::dvec2> poly2, window_cut;
  std::vector<float> inv_depths;
};

class Hemicube {
 public:
  /// resolution: even, >= 2. Precomputes every pixel's exact delta form factor. `full`: a whole
  /// cube of six resolution x resolution faces around the eye (a volume cluster's view, whose
  /// pixels the caller weights), the top facing `normal` as placed.
  explicit Hemicube(uint32_t resolution, bool full = false);
  /// The top face alone, its pixels' weights each 1 / resolution^2 (no form factors computed): a
  /// parallel projection's view (lights.cpp), which maps the scene onto the top face only.
  static Hemicube top_face(uint32_t resolution);
  /// A hemicube whose pixel weights (delta_form_factors) are their solid angles, with no form
  /// factors computed: a point or spot light's view (lights.cpp), at resolutions where the exact
  /// form factors would cost more than the light's shot.
  static Hemicube solid_angles(uint32_t resolution);

  uint32_t resolution() const { return n_; }
  uint32_t pixel_count() const { return pixel_count_; }
  bool full() const { return full_; }
  /// Exact form factor of each pixel from the hemicube's centre (they sum to 1); a full cube's
  /// pixels' shares of the sphere's solid angle (they sum to 1); a solid_angles() hemicube's
  /// pixels' solid angles (they sum to 2 pi).
  const std::vector<double>& delta_form_factors() const { return dff_; }

  /// The world direction from the eye through the centre of pixel `pixel` (not unit), as placed.
  glm::dvec3 pixel_direction(uint32_t pixel) const;
  /// The solid angle pixel `pixel` subtends at the eye (they sum to 2 pi).
  double pixel_solid_angle(uint32_t pixel) const;

  /// Where a fragment's depth is taken: at its pixel's centre (true) or at the centre of the part
  /// of the pixel it covers (false, the default; see Hemicube::rasterize).
  void set_depth_at_pixel_centre(bool on) { centre_depth_ = on; }

  /// Places the hemicube at `eye` facing `normal` (unit); `up_hint` fixes the rotation about it.
  void place(const glm::dvec3& eye, const glm::dvec3& normal, const glm::dvec3& up_hint);
  const glm::dvec3& eye() const { return eye_; }

  /// Projects a planar convex polygon (world coordinates, front side facing the eye), appending
  /// its fragments in increasing pixel order. Classical: a fragment per pixel whose centre is
  /// inside; anti-aliased: a fragment per pixel it covers, with the covered area. `plane_normal`,
  /// when given, is the polygon's plane normal (any length); otherwise it is computed. `windows`,
  /// when given, keeps the fragments to those pixels: the part of the polygon inside them is scan
  /// converted, so their fragments are the whole polygon's but for rounding.
  void project(std::span<const glm::dvec3> polygon, uint32_t element, Method method,
               ProjectScratch& scratch, std::vector<Fragment>& out,
               const glm::dvec3* plane_normal = nullptr, const FaceWindows* windows = nullptr) const;
  /// Grows `windows` to hold the pixels of `fragments` (fragments of this hemicube).
  void widen_windows(std::span<const Fragment> fragments, FaceWindows& windows) const;
  /// How many pixels `windows` hold.
  uint64_t window_pixels(const FaceWindows& windows) const;

  /// Projects a polygon that lies inside a parent polygon whose resolved fragments are `parent`
  /// (sorted by pixel), appending its fragments with the parent's transmission per pixel. No other
  /// polygon is looked at: this is the reuse of the parent's visibility.
  void project_child(std::span<const glm::dvec3> polygon, uint32_t element,
                     std::span<const Fragment> parent, Method method, ProjectScratch& scratch,
                     std::vector<Fragment>& out) const;

 private:
  struct Face {
    glm::dvec3 right, up, forward;  // world axes of the face's (a, b, depth)
    double b_min = -1.0;            // -1 for the top face, 0 for the half faces
    uint32_t height = 0;            // rows
    uint32_t offset = 0;            // first global pixel index
  };
  void to_local(std::span<const glm::dvec3> polygon, ProjectScratch& scratch) const;
  // The face of a pixel, and the pixel's (a, b) square on it, a0 a1 b0 b1.
  size_t pixel_square(uint32_t pixel, std::array<double, 4>& square) const;
  // Clips to face f and maps to pixel coordinates; false when nothing is left. `inside`: every
  // corner is known to lie inside the face's frustum (only the near plane may still cut).
  bool clip_to_face(size_t face, ProjectScratch& scratch, bool inside) const;
  // The face whose frustum holds every corner of the polygon in `scratch.local`, or -1.
  int common_face(const ProjectScratch& scratch) const;
  // `keep`: scan only those pixels (a classical projection's window: see Hemicube::project).
  void rasterize(const Face& face, uint32_t element, Method method,
                 const glm::dvec3& plane_normal, double plane_offset, std::span<const Fragment> parent,
                 bool child, ProjectScratch& scratch, std::vector<Fragment>& out,
                 const FaceWindow* keep = nullptr) const;

  struct TopFaceTag {};
  Hemicube(uint32_t resolution, TopFaceTag);
  struct SolidAngleTag {};
  Hemicube(uint32_t resolution, SolidAngleTag);
  // The faces' rows, offsets and pixel count (the constructors' common part).
  void lay_out_faces();
  // Every pixel's solid angle times `scale`, into dff_ (pixel_solid_angle's corner terms computed
  // once per corner of the faces' grids).
  void fill_solid_angles(double scale);

  uint32_t n_;
  bool full_;
  bool centre_depth_ = false;
  size_t face_count_;  // 5, or 6 for a full cube
  uint32_t pixel_count_;
  std::vector<double> dff_;
  std::array<Face, 6> faces_{};
  glm::dvec3 eye_{0.0};
  glm::dvec3 frame_x_{1, 0, 0}, frame_y_{0, 1, 0}, frame_z_{0, 0, 1};
};

/// Fills `trans` of every fragment (in place of its inv_depth): classical keeps the nearest
/// fragment of each pixel (trans 1, others 0); anti-aliased orders the pixel's occlusion groups by
/// depth (nearest first) and gives group k the transmission 1 - f_{k-1}, where
/// f_k = f_{k-1} + A_k (1 - f_{k-1}) (the paper's E_k = A_k (1 - f_{k-1})). Groups that share an
/// edge are merged first (their areas add). `group_of[element]` is an element's occlusion group:
/// fragments of one group never hide each other. Back-face fragments (kBackFace) are grouped by
/// their surface too, apart from its front-facing fragments. With a `covered_bit` (0: none), that
/// bit of `group_of[element]` marks elements with a surface on them or just in front of them (a
/// box's bottom on a floor): where something nearer took part of a pixel, their surface's share of
/// it goes to its fragments that are not covered. `cover_of[element]` (empty: none known) is the
/// occlusion group of the surface that covers a covered element as seen from the element's side
/// (with kBackFaceCover: that group's back faces), or kNone: where both are in a pixel, the
/// covered element's surface lies behind it. `order` and `pixel_start` are scratch.
void resolve(std::span<Fragment> fragments, uint32_t pixel_count, Method method,
             std::span<const uint32_t> group_of, uint32_t covered_bit, std::span<const uint32_t> cover_of,
             const GroupAdjacency& adjacency, ThreadPool& pool, std::vector<uint32_t>& order,
             std::vector<uint32_t>& pixel_start);

}  // namespace hemibake::solver::detail
