// Progressive refinement radiosity with adaptive substructuring, with form factors from the
// anti-aliased hemicube ("Anti-aliased hemicubes for performance improvement in radiosity
// solutions") or from the classical point-sampled hemicube.
//
// The library does no I/O: scenes come in as patches, results go out as a mesh with per-vertex
// radiosity. Inputs are checked by validate(); the solver itself assumes valid input.
#pragma once

#include <glm/vec3.hpp>

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace hemibake::solver {

inline constexpr uint32_t kNone = 0xffffffffu;

/// A planar input polygon: a triangle or a convex quad, front side where the corners run
/// counter-clockwise. The patch is the unit of shooting; it refines into elements (a quadtree).
struct Patch {
  std::array<glm::dvec3, 4> corners{};  ///< the first corner_count are used
  uint32_t corner_count = 4;            ///< 3 or 4
  glm::dvec3 reflectance{0.5};          ///< diffuse reflectance per RGB channel, in [0, 1)
  glm::dvec3 emission{0.0};             ///< emitted radiosity per channel, >= 0
  uint32_t material = 0;                ///< vertex radiosity is never averaged across materials
  uint32_t object = 0;                  ///< the input object it belongs to (a glTF node's primitive;
                                        ///< 0: unknown): closed meshes are found within one
  std::array<uint32_t, 4> vertex{};     ///< the input's vertex at each corner (0: unknown). Two
                                        ///< patches whose shared edge ends at the same two input
                                        ///< vertices in both are smooth across it (an exporter's
                                        ///< smooth shading) at any angle under 90 degrees
};

/// A punctual light (as glTF's KHR_lights_punctual defines them). Lights shoot before any patch,
/// each from a projection of the scene of its own: a whole cube around a point light, the
/// hemicube facing a spot light's axis, one parallel projection over the scene for a directional
/// light. A receiver at distance d, at angle theta to the light, gets the irradiance
/// E = intensity * cos(theta) / d^2 (point, spot; times the spot's cone falloff and the range
/// window) or E = intensity * cos(theta) (directional), and reflects rho * E.
struct Light {
  enum class Type : uint8_t { kPoint, kSpot, kDirectional };
  Type type = Type::kPoint;
  glm::dvec3 position{0.0};           ///< point and spot
  glm::dvec3 direction{0.0, 0.0, -1.0};  ///< spot and directional: where the light travels (unit)
  glm::dvec3 intensity{0.0};          ///< colour x intensity per channel, >= 0: candela (point,
                                      ///< spot) or lux (directional), used as given (no 683 lm/W)
  double range = 0.0;                 ///< point and spot: beyond it no light (window
                                      ///< clamp(1 - (d / range)^4, 0, 1)); 0 = unlimited
  double inner_cone = 0.0;            ///< spot: full intensity within this angle of the axis
  double outer_cone = 0.7853981633974483;  ///< spot: none beyond it; 0 <= inner < outer <= pi / 2;
                                      ///< between, t^2 with t = (cos a - cos outer) / (cos inner - cos outer)
};

/// The input: a list of patches, lights, and a uniform sky. Patches that share corners and a plane
/// form one smooth surface.
struct Scene {
  std::vector<Patch> patches;
  std::vector<Light> lights;
  /// Radiance of a uniform sky around the scene, per channel, >= 0: every direction in which a
  /// surface sees no other surface brings it this radiance (an open floor gets E = pi * sky).
  glm::dvec3 sky{0.0};
};

/// How form factors are computed.
enum class Method : uint8_t {
  kClassical,    ///< one element per pixel, sampled at the pixel centre, z-buffered (the baseline)
  kAntiAliased,  ///< fractional pixel coverage with depth-ordered visible shares (the paper's)
};

/// Solver parameters; names follow the paper where it has them.
struct Params {
  Method method = Method::kAntiAliased;
  uint32_t resolution = 100;    ///< hemicube top face is resolution x resolution pixels (even, 4..4096);
                                ///< near-field pieces use coarser ones (see README)
  double feps = 1e-3;           ///< form-factor tolerance: split when F(shooter->element) * shooter's
                                ///< share of emitted power exceeds it
  double aeps = 1e-4;           ///< minimum element area, as a fraction of the scene's total area
  double beps = 0.03;           ///< radiosity tolerance: split when a shot's radiosity differs across
                                ///< an element's corners (or its hidden part) by more than beps times
                                ///< the scene's mean emitted radiosity per unit area
  double convergence = 1e-3;    ///< stop when unshot power < convergence * emitted power and no
                                ///< shooter holds unshot power over 10 * convergence of its own
                                ///< light (those under 1e-3 * convergence of the emitted aside)
  uint64_t max_shots = 1'000'000;     ///< stop after this many shots
  uint64_t max_elements = 2'000'000;  ///< no splits past this many leaf elements
  uint32_t threads = 0;         ///< worker threads within a shot; 0 = hardware concurrency
  double shooter_size = 0.5;    ///< a patch shoots from sub-areas no wider than this fraction of the
                                ///< scene's diagonal (large shooters near receivers are not points)
  double cluster_size = 0.15;   ///< non-emitting patches narrower than half this (times the scene's
                                ///< diagonal) shoot together with their surface's neighbours, in
                                ///< clusters up to this wide; 0 = every patch shoots alone
  bool cluster_across = true;   ///< surfaces narrower than half cluster_size (faces of small
                                ///< objects) cluster with nearby faces of like orientation on other
                                ///< objects; false = only within a surface
  bool cluster_volume = true;   ///< those faces cluster whatever their orientation, and a cluster
                                ///< that faces several ways shoots from one whole cube at its
                                ///< centre, each direction weighted by the faces that look that way
                                ///< (a volume cluster); false = one cluster per orientation class
  bool reuse_visibility = true; ///< children take visibility from their parent's pixels; false
                                ///< re-projects the whole scene after every split (for comparison)
  bool gather = false;          ///< after the shots, every vertex of the mesh gathers the radiosity of
                                ///< what it sees through a hemicube of the solve's method, and
                                ///< elements split where the light gathered across them is not linear
                                ///< (see README); false: vertices average their elements
  bool pools = false;           ///< a quick first pass finds where the light pools on surfaces too
                                ///< large for any one shot to split (a floor under small lamps), and
                                ///< the solve proper starts with those elements split (see README)
  bool sharp_shadows = false;   ///< aa: pieces shooting at least a hundredth of the emitted power take
                                ///< a hemicube of twice the resolution (at most 400) at every
                                ///< near-field level, so that small objects close to a large emitter
                                ///< cast their shadows and leave their crevices dark (see README);
                                ///< false: each near-field level halves the resolution, but for
                                ///< such pieces only as far as every solid or closed mesh they may
                                ///< see stays at least two pixels wide
  uint32_t shot_cache_mb = 1024; ///< memory for the form factors of earlier shots, replayed when the
                                 ///< same shooter shoots again with no more power and an unchanged
                                 ///< mesh (see README); 0 = every shot projects anew; taken as it
                                 ///< fills (a small scene's records take a few MB)
};

/// Returns an empty string when the parameters are usable, else a message naming the bad one.
std::string validate(const Params& params);

/// Returns an empty string when the scene is usable, else a message naming the first bad patch
/// and what is wrong with it (non-finite or degenerate corners, non-planar or non-convex quads,
/// reflectance outside [0, 1), negative emission), or the first bad light (non-finite or negative
/// intensity, a direction that is not a unit vector, negative range, cone angles outside
/// 0 <= inner < outer <= pi / 2), or a negative or non-finite sky.
std::string validate(const Scene& scene);

/// Whether point x lies inside the closed surface made of `surface`'s patches (every edge met by
/// two of them), by the parity of a ray's crossings; a point on the surface may go either way.
bool encloses(std::span<const Patch> surface, const glm::dvec3& x);

/// The volume `surface`'s patches enclose (divergence theorem, about the centre of their bounding
/// box): positive when they face away from it, negative when they face into it.
double signed_volume(std::span<const Patch> surface);

/// Reported between shots.
struct Progress {
  uint64_t shots = 0;            ///< shots done (Southwell steps)
  double unshot_fraction = 1.0;  ///< unshot power / emitted power
  uint64_t elements = 0;         ///< leaf elements
  double elapsed_seconds = 0.0;
  uint32_t pass = 1, passes = 1; ///< with Params::pools: pass 1, the quick first, of 2
};
using ProgressFn = std::function<void(const Progress&)>;

/// Cancels a running solve from any thread; the solver checks it between shots.
class CancelToken {
 public:
  void cancel() { cancelled_.store(true, std::memory_order_relaxed); }
  bool cancelled() const { return cancelled_.load(std::memory_order_relaxed); }

 private:
  std::atomic<bool> cancelled_{false};
};

/// Counters and timings of a solve.
struct Stats {
  uint64_t shots = 0;            ///< patch shots (Southwell steps), light and sky shots included
  uint64_t light_shots = 0;      ///< ... of which lights' (each light once) and the sky's (once)
  uint64_t light_projections = 0;  ///< projections of the scene for lights and the sky
  double seconds_lights = 0.0;   ///< in the lights' and the sky's shots and their power estimate
  uint64_t hemicubes = 0;        ///< hemicubes placed (a patch shoots from one or more sub-areas)
  uint64_t replayed_shots = 0;   ///< shots that reused the form factors of the shooter's earlier shot
  uint64_t replays_reshot = 0;   ///< ... of which shot anew to the children of receivers split since
  uint64_t projections = 0;      ///< projections onto a hemicube (of the whole scene, or of what may hide a near piece's receivers)
  uint64_t elements_projected = 0;  ///< elements given to those projections, summed
  uint64_t rounds = 0;           ///< repeated shots after splits (the paper's cancelled shots)
  uint64_t splits = 0;           ///< elements split
  uint64_t splits_form_factor = 0;  ///< ... of which for their form factor (FEPS)
  uint64_t splits_visibility = 0;   ///< ... for partial visibility
  uint64_t splits_gradient = 0;     ///< ... for a radiosity jump at a corner
  uint64_t splits_pools = 0;     ///< elements split where the first pass's light pools (not counted in `splits`' kinds)
  uint32_t passes = 1;           ///< 2: a first pass looked for light pools (Params::pools; none where no
                                 ///< surface but emitters is large enough to split)
  double seconds_first_pass = 0.0;  ///< ... and took this long (not in `seconds`)
  uint64_t gathers = 0;          ///< hemicubes placed at points of the mesh by the final gather
  uint64_t splits_gather = 0;    ///< elements split by the final gather (not counted in `splits`' kinds)
  double seconds_gathering = 0.0;  ///< in the final gather
                                 ///< through gaps it cannot see (a lamp just under a ceiling)
  uint64_t reused_children = 0;  ///< children whose form factor came from their parent's pixels
  uint64_t elements = 0;         ///< leaf elements now
  uint64_t patches = 0;          ///< input patches
  uint64_t shooters = 0;         ///< what shoots: clusters of patches (Params::cluster_size) and patches alone
  uint64_t peak_fragments = 0;   ///< most pixel fragments held at once
  double seconds = 0.0;          ///< wall time in run()/step()
  double seconds_projecting = 0.0;  ///< in those projections (incl. resolving pixel lists)
  double seconds_reusing = 0.0;     ///< in evaluating children from their parent's pixels
  double unshot_fraction = 1.0;     ///< unshot power / emitted power
  double emitted_power = 0.0;       ///< sum over patches of emission (RGB summed) times area,
                                    ///< plus the power lights and the sky bring to the surfaces
  bool converged = false;
  bool cancelled = false;
  bool shot_limit = false;
  bool element_limit = false;
};

/// The radiosity mesh: leaf elements with shared vertices.
struct Mesh {
  struct Element {
    uint32_t patch = 0;                ///< index of the input patch it refines
    uint32_t corner_count = 4;         ///< 3 or 4
    std::array<uint32_t, 4> corners{};  ///< vertex indices, counter-clockwise
    glm::dvec3 radiosity{0.0};         ///< element radiosity (constant over the element)
    double area = 0.0;
    uint32_t boundary_begin = 0;       ///< its loop in `boundary`: corners and the vertices of
    uint32_t boundary_end = 0;         ///< finer neighbours on its edges, counter-clockwise
    /// Pressed against another surface that faces it over all of it (a wall box's end against the
    /// next wall, a floor under a block's bottom): no viewpoint sees it, and writers leave it out,
    /// since a viewer's depth test lets it through in dots along the edge it shares with a face
    /// that is seen.
    bool buried = false;
  };
  std::vector<glm::dvec3> positions;   ///< per vertex
  std::vector<glm::dvec3> radiosity;   ///< per vertex: gathered at the vertex (Params::gather, once
                                       ///< the solve has ended), else the area-weighted mean of the
                                       ///< elements around it on the same surface and material
  std::vector<Element> elements;       ///< ordered by patch
  std::vector<uint32_t> boundary;      ///< element boundary loops (see Element)
  /// Per vertex (or empty: none), 1 where the vertex was added on an element's edge for another
  /// surface's vertex there (or a neighbour's point at the edge's middle), so that triangles of the
  /// two sides meet vertex to vertex; its radiosity is then interpolated along that edge and adds
  /// nothing to what the element shows (a triangulation leaves it out of the element's centre).
  std::vector<uint8_t> interpolated;
};

/// A progressive radiosity solution that can be advanced shot by shot and read at any time.
class Solver {
 public:
  /// Precondition: validate(scene) and validate(params) return empty strings.
  Solver(const Scene& scene, const Params& params);
  ~Solver();
  Solver(const Solver&) = delete;
  Solver& operator=(const Solver&) = delete;

  /// Performs one shot (with its repeats after splits). Returns false, doing nothing, when the
  /// solution has converged or the shot limit is reached.
  bool step();

  /// Shoots until converged, a limit, or cancellation; calls `progress` after every shot.
  const Stats& run(const ProgressFn& progress = {}, const CancelToken* cancel = nullptr);

  /// The current mesh. With `ambient`, adds the ambient term of Cohen et al. 1988 (the unshot
  /// power spread evenly), which makes unconverged states displayable; it vanishes at convergence.
  Mesh mesh(bool ambient = false) const;

  const Stats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace hemibake::solver
