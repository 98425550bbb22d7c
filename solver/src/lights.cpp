// Punctual lights and a uniform sky, shot before any patch with the anti-aliased hemicube's
// machinery: the scene is projected with fractional coverage, each pixel's surfaces share it by
// depth (E_k = A_k (1 - f_{k-1}), section 2.2.1 of the paper), receivers are refined a posteriori
// by the same criteria as a patch's shot, and children reuse their parent's pixels (section 2.3).
//
// What a light gives is an irradiance, not a form factor. Over a receiver of area A, a point light
// of intensity I brings the power I * (solid angle of the receiver's visible part, seen from the
// light), since dw = cos(theta) dA / d^2: so its mean irradiance is I * sum over its pixels of
// (visible coverage x pixel solid angle) / A, from a whole cube of pixels around the light (two
// hemicubes, back to back). A spot light is the hemicube facing its axis, each pixel weighted by
// the cone falloff at its centre. A directional light of illuminance E brings E * (visible
// projected area): one parallel projection over the scene, each pixel weighted by its area.
//
// A parallel projection is a hemicube at the origin looking at a projectively mapped scene: the
// map (u, v, z) -> (u, v, 1) / w with w affine in the depth z along the light sends the parallel
// rays through the origin, keeps planes planar and depth order (w falls with z), and maps the
// scene's extent across the light onto the top face. So the clipper, scan converter, per-pixel
// resolve and child reuse are the hemicube's own.
//
// The sky of uniform radiance S is a sum of parallel projections from kSkyDirections directions
// spread evenly over the sphere (a Fibonacci lattice), each of weight S * 4 pi / kSkyDirections:
// E = S * integral of visible cos(theta) dw. Per receiver the sum is divided by the same sum with
// nothing hidden (computed from its normal) and multiplied by pi, so that an open surface gets
// exactly pi S. After splits, each direction is projected again for the new children and what may
// share their pixels (sky_seen): the directions' fragments are not kept, since their memory would
// grow with the directions.
#include "solver_impl.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

namespace hemibake::solver {
namespace {

constexpr double kPi = std::numbers::pi;
// Directions of the sky's parallel projections, and its refinement rounds (each re-projects all).
constexpr uint32_t kSkyDirections = 512;
constexpr int kSkyRounds = 8;
// Every kSkyEstimateStep-th direction estimates the sky's power before the solve, and every
// kSkyRefineStep-th decides the sky's splits.
constexpr uint32_t kSkyEstimateStep = 8;
constexpr uint32_t kSkyRefineStep = 4;
// The sky's shot projects directions for about this long per step (shoot_sky_part).
constexpr double kSkyPartSeconds = 1.0;
// A receiver that sees less than this share of its open sky sees none: the silhouette pixels of a
// closed room's walls, seen from outside, let through a few parts in ten thousand, which would
// light a closed room (and split its elements for partial visibility).
constexpr double kSkyLeak = 3e-3;

bool finite(const glm::dvec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Direction k of n, evenly spread over the sphere (unit).
glm::dvec3 fibonacci_direction(uint32_t k, uint32_t n) {
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  const double y = 1.0 - (2.0 * k + 1.0) / n;
  const double r = std::sqrt(std::max(0.0, 1.0 - y * y));
  return {r * std::cos(golden * k), y, r * std::sin(golden * k)};
}

// A unit vector perpendicular to unit `d`.
glm::dvec3 perpendicular(const glm::dvec3& d) {
  return glm::normalize(glm::cross(d, std::abs(d.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0)));
}

// KHR_lights_punctual's spot falloff for a direction at cosine `c` to the axis: t^2 with
// t = (c - cos outer) / (cos inner - cos outer), clamped to [0, 1].
double spot_falloff(const Light& light, double c) {
  const double cos_outer = std::cos(light.outer_cone);
  const double scale = 1.0 / std::max(1e-3, std::cos(light.inner_cone) - cos_outer);
  const double t = std::clamp((c - cos_outer) * scale, 0.0, 1.0);
  return t * t;
}

// KHR_lights_punctual's range window at distance `x` times the range.
double range_window(double x) { return std::clamp(1.0 - x * x * x * x, 0.0, 1.0); }

}  // namespace

// One projection of the scene for a light: a hemicube placed at a point light, or a parallel
// projection (mapped so that a hemicube at the origin sees it on its top face), with each pixel's
// weight: its solid angle (times a spot's falloff), or its area across the light.
struct Solver::Impl::LightView {
  detail::Hemicube* cube = nullptr;
  bool parallel = false;
  glm::dvec3 eye{0.0}, axis{0.0, 0.0, 1.0}, up{0.0, 1.0, 0.0};  // perspective: the placement
  glm::dvec3 centre{0.0}, t{1, 0, 0}, b{0, 1, 0}, d{0, 0, 1};   // parallel: the frame (t x b = d)
  double half = 1.0, z_max = 0.0, depth = 1.0, pixel_area = 0.0;
  std::vector<double> weight;  // perspective: per pixel
  std::vector<glm::dvec3> dirs;  // perspective with a range: per pixel, the unit direction
  std::vector<Fragment> frags;
  std::vector<uint32_t> begin, end;  // per element: its front fragments in `frags`
  std::vector<uint32_t> within;      // perspective: the closed meshes the light lies in (enclosing;
                                     // parallel: none, the light comes from outside them all)

  void place() const {
    if (parallel) cube->place(glm::dvec3(0.0), glm::dvec3(0, 0, 1), glm::dvec3(0, 1, 0));
    else cube->place(eye, axis, up);
  }
  // A world point in the parallel projection's mapped space: w falls from 1.5 at the side the
  // light comes from to 0.5 at the far side, so 1/depth = w orders surfaces as the light meets them.
  glm::dvec3 mapped(const glm::dvec3& p) const {
    const glm::dvec3 r = p - centre;
    const double w = (z_max - glm::dot(r, d)) / depth + 0.5;
    return glm::dvec3(glm::dot(r, t) / half, glm::dot(r, b) / half, 1.0) / w;
  }
  double weight_of(uint32_t pixel) const {
    if (!parallel) return weight[pixel];
    return pixel < cube->resolution() * cube->resolution() ? pixel_area : 0.0;  // the top face
  }
};

namespace detail {

std::string validate_lights(const Scene& scene) {
  for (size_t i = 0; i < scene.lights.size(); ++i) {
    const Light& l = scene.lights[i];
    std::ostringstream err;
    err << "light " << i << ": ";
    for (int c = 0; c < 3; ++c)
      if (!(l.intensity[c] >= 0.0) || !std::isfinite(l.intensity[c])) {
        err << "intensity " << l.intensity[c] << " is negative or not finite";
        return err.str();
      }
    if (l.type != Light::Type::kDirectional && !finite(l.position)) return err.str() + "position is not finite";
    if (l.type != Light::Type::kPoint && !(finite(l.direction) && std::abs(glm::length(l.direction) - 1.0) < 1e-6))
      return err.str() + "direction is not a unit vector";
    if (!(l.range >= 0.0) || !std::isfinite(l.range)) {
      err << "range " << l.range << " is negative or not finite";
      return err.str();
    }
    if (l.type == Light::Type::kSpot &&
        !(l.inner_cone >= 0.0 && l.inner_cone < l.outer_cone && l.outer_cone <= kPi / 2)) {
      err << "cone angles inner " << l.inner_cone << " and outer " << l.outer_cone
          << " are outside 0 <= inner < outer <= pi / 2";
      return err.str();
    }
  }
  for (int c = 0; c < 3; ++c)
    if (!(scene.sky[c] >= 0.0) || !std::isfinite(scene.sky[c])) {
      std::ostringstream err;
      err << "sky radiance " << scene.sky[c] << " is negative or not finite";
      return err.str();
    }
  return {};
}

}  // namespace detail

// The parallel projection along unit `direction` over the scene's bounding box.
Solver::Impl::LightView Solver::Impl::parallel_view(const glm::dvec3& direction, uint32_t resolution) const {
  LightView v;
  v.parallel = true;
  v.d = direction;
  v.t = perpendicular(direction);
  v.b = glm::cross(direction, v.t);
  const glm::dvec3 lo = tree[0].lo, hi = tree[0].hi;
  const glm::dvec3 mid = 0.5 * (lo + hi);
  double u0 = 1e300, u1 = -1e300, w0 = 1e300, w1 = -1e300, z0 = 1e300, z1 = -1e300;
  for (int k = 0; k < 8; ++k) {
    const glm::dvec3 c((k & 1) ? hi.x : lo.x, (k & 2) ? hi.y : lo.y, (k & 4) ? hi.z : lo.z);
    const glm::dvec3 r = c - mid;
    u0 = std::min(u0, glm::dot(r, v.t));
    u1 = std::max(u1, glm::dot(r, v.t));
    w0 = std::min(w0, glm::dot(r, v.b));
    w1 = std::max(w1, glm::dot(r, v.b));
    z0 = std::min(z0, glm::dot(r, v.d));
    z1 = std::max(z1, glm::dot(r, v.d));
  }
  v.centre = mid + v.t * (0.5 * (u0 + u1)) + v.b * (0.5 * (w0 + w1));
  // A margin, so that no corner lies on the face's edge.
  v.half = std::max(0.5 * std::max(u1 - u0, w1 - w0), 1e-6 * prep.diagonal) * 1.01;
  v.z_max = z1;
  v.depth = std::max(z1 - z0, 1e-6 * prep.diagonal);
  const double side = 2.0 * v.half / resolution;
  v.pixel_area = side * side;
  return v;
}

// The views of a light, with their pixel weights.
void Solver::Impl::light_views(const Light& light, std::vector<LightView>& views, bool fine) {
  views.clear();
  if (light.type == Light::Type::kDirectional) {
    views.push_back(parallel_view(light.direction, sun_cube->resolution()));
    views.back().cube = sun_cube.get();
    return;
  }
  // A point light: two hemicubes back to back (their half faces make up the cube's side faces).
  // A spot light's cone lies within the hemicube facing its axis.
  std::vector<glm::dvec3> axes;
  if (light.type == Light::Type::kSpot) axes = {light.direction};
  else axes = {glm::dvec3(0, -1, 0), glm::dvec3(0, 1, 0)};
  for (const glm::dvec3& axis : axes) {
    LightView v;
    v.cube = fine && fine_light_cube ? fine_light_cube.get() : light_cube.get();
    v.eye = light.position;
    v.within = enclosing(light.position);
    v.axis = axis;
    v.up = perpendicular(axis);
    v.place();
    v.weight.resize(v.cube->pixel_count());
    const std::vector<double>& omega = v.cube->delta_form_factors();  // solid angles (prepare_lights)
    for (uint32_t px = 0; px < v.cube->pixel_count(); ++px) {
      double w = omega[px];
      // The spot's falloff, at the pixel's centre.
      if (light.type == Light::Type::kSpot) w *= spot_falloff(light, glm::dot(glm::normalize(v.cube->pixel_direction(px)), light.direction));
      v.weight[px] = w;
    }
    if (light.range > 0.0) {
      v.dirs.resize(v.cube->pixel_count());
      for (uint32_t px = 0; px < v.cube->pixel_count(); ++px) v.dirs[px] = glm::normalize(v.cube->pixel_direction(px));
    }
    views.push_back(std::move(v));
  }
}

// Projects `elements` (receivers and occluders alike) into the view and resolves its pixels, as
// project() does for a hemicube: backs that something else may not hide are occluders that take
// no light.
void Solver::Impl::project_light_view(LightView& v, std::span<const uint32_t> elements) {
  ++stats.light_projections;
  v.place();
  v.begin.resize(e_patch.size());
  v.end.resize(e_patch.size());
  pool.parallel_for(elements.size(), [&](size_t begin, size_t end, size_t c) {
    auto& out = chunk_frags[c];
    out.clear();
    Corners poly{};
    for (size_t i = begin; i < end; ++i) {
      const uint32_t el = elements[i];
      const uint32_t p = e_patch[el];
      v.begin[el] = v.end[el] = static_cast<uint32_t>(out.size());
      const double facing = v.parallel ? -glm::dot(prep.normal[p], v.d) * prep.diagonal
                                       : glm::dot(prep.normal[p], v.eye - patches[p].corners[0]);
      if (culled(p, facing)) continue;
      corners_of(el, poly);
      if (v.parallel)
        for (uint32_t k = 0; k < corner_count(el); ++k) poly[k] = v.mapped(poly[k]);
      if (project_side(*v.cube, el, el, poly, facing, !v.parallel, scratch[c], out)) v.end[el] = static_cast<uint32_t>(out.size());
    }
  });
  join_chunks(elements, v.begin, v.end, v.frags);
  detail::resolve(v.frags, v.cube->pixel_count(), params.method, e_group, covered_bit(), e_cover, prep.adjacency, pool,
                  order, pixel_start);
  stats.peak_fragments = std::max<uint64_t>(stats.peak_fragments, v.frags.size());
}

// The children of split `parents` take their fragments from their parent's pixels in the view,
// with the parent's transmissions (section 2.3): nothing else is projected again.
void Solver::Impl::project_light_children(LightView& v, const std::vector<uint32_t>& parents) {
  v.place();
  v.begin.resize(e_patch.size());
  v.end.resize(e_patch.size());
  const size_t n = parents.size();
  const size_t chunks = pool.chunk_count(n);
  pool.parallel_for(n, [&](size_t begin, size_t end, size_t c) {
    auto& out = chunk_frags[c];
    out.clear();
    Corners poly{};
    for (size_t i = begin; i < end; ++i) {
      const uint32_t par = parents[i];
      const std::span<const Fragment> pf(v.frags.data() + v.begin[par], v.end[par] - v.begin[par]);
      for (uint32_t k = 0; k < 4; ++k) {
        const uint32_t ch = e_child[par] + k;
        v.begin[ch] = v.end[ch] = static_cast<uint32_t>(out.size());
        if (pf.empty()) continue;
        corners_of(ch, poly);
        const uint32_t cc = corner_count(ch);
        if (v.parallel)
          for (uint32_t j = 0; j < cc; ++j) poly[j] = v.mapped(poly[j]);
        v.cube->project_child(std::span(poly.data(), cc), ch, pf, params.method, scratch[c], out);
        v.end[ch] = static_cast<uint32_t>(out.size());
      }
    }
  });
  for (size_t c = 0; c < chunks; ++c) {
    const uint32_t base = static_cast<uint32_t>(v.frags.size());
    v.frags.insert(v.frags.end(), chunk_frags[c].begin(), chunk_frags[c].end());
    for (size_t i = n * c / chunks; i < n * (c + 1) / chunks; ++i)
      for (uint32_t k = 0; k < 4; ++k) {
        v.begin[e_child[parents[i]] + k] += base;
        v.end[e_child[parents[i]] + k] += base;
      }
  }
  stats.reused_children += 4 * n;
}

// Per element, what the light's views give it, in the form refine's criteria read: f_recv (and
// f_open, with nothing hidden) is the irradiance per unit of light.intensity, e_ff (e_ff_open) the
// visible solid angle (point, spot) or projected area (directional), so that e_ff times
// channel_sum(intensity) / emitted_power is the element's share of the power, as for a patch.
void Solver::Impl::light_factors(const Light* light, const std::vector<LightView>& views,
                                 std::span<const uint32_t> elements) {
  pool.parallel_for(elements.size(), [&](size_t begin, size_t end, size_t) {
    for (size_t i = begin; i < end; ++i) {
      const uint32_t e = elements[i];
      double vis = 0.0, open = 0.0;
      // KHR_lights_punctual's range window, at the distance along each pixel's ray to the
      // element's plane (at the element's centre it would be wrong for large elements).
      const bool ranged = light != nullptr && light->type != Light::Type::kDirectional && light->range > 0.0;
      const glm::dvec3& n = prep.normal[e_patch[e]];
      const double plane = ranged ? glm::dot(n, e_centre[e] - light->position) : 0.0;
      for (const LightView& v : views)
        for (uint32_t k = sealed(e_patch[e], v.within) ? v.end[e] : v.begin[e]; k < v.end[e]; ++k) {
          const Fragment& f = v.frags[k];
          double a = static_cast<double>(f.area) * v.weight_of(f.pixel);
          if (ranged) {
            const double along = glm::dot(n, v.dirs[f.pixel]);
            const double x = along != 0.0 ? plane / along / light->range : 2.0;
            a *= range_window(x);
          }
          open += a;
          vis += a * f.trans;
        }
      e_ff[e] = vis;
      e_ff_open[e] = open;
      e_stamp[e] = stamp;
      f_recv[e] = vis / e_area[e];
      f_open[e] = open / e_area[e];
    }
  });
}

// The irradiance per unit of intensity that point or spot light `light` brings to point x of a
// surface with normal n, with nothing hidden: cos(theta) / d^2, times the spot's falloff and the
// range window (as light_views and light_factors weigh the pixels). 0 behind the light or the surface.
double Solver::Impl::light_at(const Light& light, const glm::dvec3& x, const glm::dvec3& n) const {
  HEMIBAKE_DCHECK(light.type != Light::Type::kDirectional);
  const glm::dvec3 to_light = light.position - x;
  const double d2 = glm::dot(to_light, to_light);
  if (!(d2 > 0.0)) return 0.0;
  const double d = std::sqrt(d2);
  const double cos_surface = glm::dot(n, to_light) / d;
  if (cos_surface <= 0.0) return 0.0;
  double e = cos_surface / d2;
  if (light.type == Light::Type::kSpot) e *= spot_falloff(light, glm::dot(-to_light / d, light.direction));
  if (light.range > 0.0) e *= range_window(d / light.range);
  return e;
}

// Element e takes the irradiance E of a light: rho E, radiosity and unshot radiosity alike.
void Solver::Impl::light_receive(uint32_t e, const glm::dvec3& irradiance) {
  HEMIBAKE_DCHECK(e < e_child.size() && e_child[e] == kNone);
  HEMIBAKE_DCHECK(irradiance.x >= 0.0 && irradiance.y >= 0.0 && irradiance.z >= 0.0);
  const uint32_t q = e_patch[e];
  const glm::dvec3 gain = patches[q].reflectance * irradiance;
  e_b[e] += gain;
  e_unshot[e] += gain;
  p_unshot[q] += channel_sum(gain) * e_area[e];
  u_unshot[p_unit[q]] += channel_sum(gain) * e_area[e];
}

// One light's shot: its views of every leaf, refined until no receiver is too coarse for it (the
// criteria of refine.cpp, with the children's factors from their parents' pixels), then every
// receiver takes rho E.
void Solver::Impl::shoot_light(size_t index) {
  const Light& light = lights[index];
  std::vector<LightView> views;
  light_views(light, views, index < light_power.size() && light_power[index] >= kFineLightShare * emitted_power);
  std::vector<uint32_t> accepted = leaves;
  grow_scratch();
  for (LightView& v : views) project_light_view(v, accepted);
  ++stamp;
  const glm::dvec3 dB = light.intensity;
  const double weight = channel_sum(dB) / emitted_power;
  shooting_light = &light;
  for (int round = 0; round < kMaxRounds; ++round) {
    light_factors(&light, views, accepted);
    spread_shot(dB, accepted);
    std::vector<uint32_t> to_split = too_coarse(dB, weight, accepted);
    reset_spread(accepted);
    if (to_split.empty() || !trim_to_element_limit(to_split)) break;
    ++stats.rounds;
    for (uint32_t e : to_split) split(e);
    replace_split(leaves);
    replace_split(accepted);
    grow_scratch();
    for (LightView& v : views) project_light_children(v, to_split);
  }
  shooting_light = nullptr;
  light_factors(&light, views, accepted);
  for (uint32_t e : accepted)
    if (f_recv[e] > 0.0) {
      light_receive(e, dB * f_recv[e]);
      e_light[e] += patches[e_patch[e]].reflectance * dB * f_recv[e];
    }
}

// Adds to `sums` (per element of `elements`, indexed by element: visible and open) the sky's parallel
// projections along directions first, first + step, ... (each of weight 4 pi step / kSkyDirections)
// but the multiples of `skip` (0: none), until the last or, given `seconds`, once that long has
// passed. Returns the next direction. Given `leaves_in_order` (every leaf, in the order a view of
// all projects them), `elements` are the children of a round's splits, and each view holds what of
// those leaves may share a pixel with them (sky_seen).
uint32_t Solver::Impl::add_sky_directions(uint32_t step, uint32_t skip, uint32_t first, std::span<const uint32_t> elements,
                                          std::vector<glm::dvec3>& sums, double seconds,
                                          std::span<const uint32_t> leaves_in_order) {
  const auto t0 = Clock::now();
  sums.resize(e_patch.size(), glm::dvec3(0.0));
  const double omega = 4.0 * kPi * step / kSkyDirections;
  LightView v;  // placed anew for each direction
  std::vector<uint32_t> seen;
  uint32_t k = first;
  for (; k < kSkyDirections && (seconds <= 0.0 || seconds_since(t0) < seconds); k += step) {
    if (skip != 0 && k % skip == 0) continue;
    const glm::dvec3 towards_sky = fibonacci_direction(k, kSkyDirections);
    v = parallel_view(-towards_sky, sky_cube->resolution());
    v.cube = sky_cube.get();
    if (!leaves_in_order.empty()) {
      sky_seen(v, elements, leaves_in_order, seen);
      project_light_view(v, seen);
    } else {
      project_light_view(v, elements);
    }
    pool.parallel_for(elements.size(), [&](size_t begin, size_t end_i, size_t) {
      for (size_t i = begin; i < end_i; ++i) {
        const uint32_t e = elements[i];
        // The sky lies outside every closed mesh.
        for (uint32_t j = sealed(e_patch[e], {}) ? v.end[e] : v.begin[e]; j < v.end[e]; ++j) {
          const Fragment& f = v.frags[j];
          const double a = omega * static_cast<double>(f.area) * v.pixel_area;
          sums[e].y += a;
          sums[e].x += a * f.trans;
        }
      }
    });
  }
  return k;
}

// What a sky direction's view must hold for `fresh`, the children of a round's splits: of every
// leaf (in the order of `leaves_in_order`, which holds the children), those whose bounding sphere may reach
// a pixel of a child's. A pixel's rule reads only the pixel's own fragments, in the order they were
// projected, so the children get to the bit what a view of every leaf gives them. (Occluders drawn
// as whole patches rather than their leaves, as for a near-field hemicube, differ by rounding:
// where a panel lies on a wall, the two surfaces' mean depths in a pixel tie to the last bits, and
// the pixel went to the other one; a child on the Blender room's panel got up to 11 % more or less.)
// On the atrium the rounds after the first split 70 to 221 elements of 142 000 each, and
// projecting every leaf along 128 directions per round took 15 s of its 31 s of lights and sky
// (23 s in all since).
void Solver::Impl::sky_seen(const LightView& v, std::span<const uint32_t> fresh, std::span<const uint32_t> leaves_in_order,
                            std::vector<uint32_t>& seen) {
  const int res = static_cast<int>(v.cube->resolution());
  const double cell = 2.0 * v.half / res;
  // The pixels (rows y, columns x) a sphere's projection may touch, and one more on each side
  // against rounding.
  struct Cells {
    int x0, x1, y0, y1;
  };
  auto cells_of = [&](const glm::dvec3& c, double r) {
    const glm::dvec3 d = c - v.centre;
    const double x = (glm::dot(d, v.t) + v.half) / cell, y = (glm::dot(d, v.b) + v.half) / cell, rr = r / cell;
    auto at = [&](double a) { return static_cast<int>(std::clamp(std::floor(a), 0.0, res - 1.0)); };
    return Cells{at(x - rr - 1.0), at(x + rr + 1.0), at(y - rr - 1.0), at(y + rr + 1.0)};
  };
  // The children's pixels, as a summed-area table (row-major, one row and column of zeros first).
  const size_t side = static_cast<size_t>(res) + 1;
  std::vector<uint32_t> table(side * side, 0);
  for (uint32_t e : fresh) {
    const Cells c = cells_of(e_centre[e], e_radius[e]);
    for (int y = c.y0; y <= c.y1; ++y)
      for (int x = c.x0; x <= c.x1; ++x) table[(y + 1) * side + (x + 1)] = 1;
  }
  for (size_t y = 1; y < side; ++y)
    for (size_t x = 1; x < side; ++x) table[y * side + x] += table[(y - 1) * side + x] + table[y * side + x - 1] - table[(y - 1) * side + x - 1];
  auto meets_fresh = [&](uint32_t e) {
    const Cells c = cells_of(e_centre[e], e_radius[e]);
    const size_t x0 = c.x0, x1 = c.x1 + 1, y0 = c.y0, y1 = c.y1 + 1;
    return table[y1 * side + x1] + table[y0 * side + x0] != table[y0 * side + x1] + table[y1 * side + x0];
  };
  seen.clear();
  pool.parallel_for(leaves_in_order.size(), [&](size_t begin, size_t end, size_t c) {
    std::vector<uint32_t>& out = gather_chunks[c];
    out.clear();
    for (size_t i = begin; i < end; ++i)
      if (meets_fresh(leaves_in_order[i])) out.push_back(leaves_in_order[i]);
  });
  for (size_t c = 0; c < pool.chunk_count(leaves_in_order.size()); ++c)
    seen.insert(seen.end(), gather_chunks[c].begin(), gather_chunks[c].end());
}

// The sums over every step-th direction as F(element -> sky) per element: x visible, y open.
void Solver::Impl::finish_sky_factors(uint32_t step, std::span<const uint32_t> elements, std::vector<glm::dvec3>& sums) const {
  const double omega = 4.0 * kPi * step / kSkyDirections;
  // The same quadrature over an open hemisphere, from the normal alone: pi / it corrects the
  // directions' discreteness, so that nothing hidden gives exactly pi.
  std::vector<double> open_sum(patches.size(), -1.0);
  for (uint32_t e : elements) {
    const uint32_t p = e_patch[e];
    if (open_sum[p] < 0.0) {
      double q = 0.0;
      for (uint32_t k = 0; k < kSkyDirections; k += step)
        q += omega * std::max(0.0, glm::dot(prep.normal[p], fibonacci_direction(k, kSkyDirections)));
      open_sum[p] = q;
    }
    const double norm = open_sum[p] > 0.0 ? kPi / (open_sum[p] * e_area[e]) : 0.0;
    const double visible = sums[e].x < kSkyLeak * sums[e].y ? 0.0 : sums[e].x;
    sums[e] = glm::dvec3(visible * norm, sums[e].y * norm, 0.0);
  }
}

std::vector<glm::dvec3> Solver::Impl::sky_factors(uint32_t step, std::span<const uint32_t> elements) {
  std::vector<glm::dvec3> sums;
  add_sky_directions(step, 0, 0, elements, sums, 0.0);
  finish_sky_factors(step, elements, sums);
  return sums;
}

// The sky's shot: every leaf's view of the sky, refined by the criteria of refine.cpp (at most
// kSkyRounds rounds; after the first, each direction is projected again for the new children
// alone, sky_seen). The rounds that decide splits look along every kSkyRefineStep-th direction
// only; the light is then distributed from all of them. A large scene's sky takes a quarter of a
// minute (the first round and the final pass project its 143 000 elements along 512 directions),
// so the shot goes on over several steps, each projecting directions for about
// kSkyPartSeconds, and the progress is reported between them; the sums, and so the result, do not
// depend on where a part ends. Returns whether the shot is complete.
bool Solver::Impl::shoot_sky_part() {
  SkyShot& sh = sky_shot;
  const glm::dvec3 dB = sky;
  if (!sh.started) {
    sh = SkyShot{};
    sh.started = true;
    sh.accepted = leaves;
  }
  const uint32_t step = sh.final_pass ? 1 : kSkyRefineStep;
  grow_scratch();
  const bool only_fresh = !sh.fresh.empty();  // cleared before the final pass
  sh.next = add_sky_directions(step, sh.final_pass && sh.reuse ? kSkyRefineStep : 0, sh.next,
                               only_fresh ? sh.fresh : sh.accepted, sh.sums, kSkyPartSeconds,
                               only_fresh ? std::span<const uint32_t>(sh.accepted) : std::span<const uint32_t>());
  if (sh.next < kSkyDirections) return false;
  std::vector<glm::dvec3> f = std::move(sh.sums);
  sh.sums.clear();
  sh.next = 0;
  // A round that splits nothing leaves the final pass's receivers as they are: its directions'
  // sums, a quarter of the weight each in the final pass, need not be projected again.
  std::vector<glm::dvec3> round_sums;
  if (!sh.final_pass) round_sums = f;
  finish_sky_factors(step, sh.accepted, f);
  if (sh.final_pass) {
    for (uint32_t e : sh.accepted)
      if (f[e].x > 0.0) light_receive(e, dB * f[e].x);
    sh = SkyShot{};
    return true;
  }
  std::vector<uint32_t>& accepted = sh.accepted;
  const double weight = channel_sum(dB) / emitted_power;
  ++stamp;
  for (uint32_t e : accepted) {
    f_recv[e] = f[e].x;
    f_open[e] = std::max(f[e].y, f[e].x);
    e_ff[e] = f[e].x * e_area[e];
    e_ff_open[e] = f_open[e] * e_area[e];
    e_stamp[e] = stamp;
  }
  spread_shot(dB, accepted);
  std::vector<uint32_t> to_split = too_coarse(dB, weight, accepted);
  reset_spread(accepted);
  if (to_split.empty() || !trim_to_element_limit(to_split)) {
    sh.final_pass = true;
    sh.reuse = true;
    sh.fresh.clear();
    sh.sums = std::move(round_sums);
    for (uint32_t e : sh.accepted) sh.sums[e] /= static_cast<double>(kSkyRefineStep);
    return false;
  }
  ++stats.rounds;
  for (uint32_t e : to_split) split(e);
  replace_split(leaves);
  replace_split(accepted);
  sh.fresh.clear();
  if (++sh.round >= kSkyRounds) {
    sh.final_pass = true;
    return false;
  }
  // The next round projects the children alone; the rest keep this round's sums (the same
  // directions, the same geometry).
  for (uint32_t e : to_split)
    for (uint32_t k = 0; k < 4; ++k) sh.fresh.push_back(e_child[e] + k);
  sh.sums = std::move(round_sums);  // the children, appended by split(), start from zero
  sh.sums.resize(e_patch.size(), glm::dvec3(0.0));
  return false;
}

// Before the solve: the power the lights and the sky bring to the surfaces (from unrefined views)
// counts as emitted, for convergence and the refinement thresholds, as a patch's emission does.
void Solver::Impl::prepare_lights() {
  const bool has_sky = sky != glm::dvec3(0.0);
  if (lights.empty() && !has_sky) return;
  const auto t0 = Clock::now();
  light_cube = std::make_unique<detail::Hemicube>(detail::Hemicube::solid_angles(params.resolution));
  // A sun's one parallel view spans the whole scene: at the hemicube's resolution its pixels were
  // 30 cm wide over a 30 m yard, and a pillar's shadow across a platform was lost in them. Its
  // pixels are as wide as the smallest elements a sharp outline still splits (min_sharp_split_area;
  // at most kMaxSunResolution a side). Twice as wide, the lit yard's peak memory was 54 MB rather
  // than 127, but the gallery's displayed p90 was 13.6 % rather than 12.4 (13.2 before either).
  if (std::any_of(lights.begin(), lights.end(), [](const Light& l) { return l.type == Light::Type::kDirectional; })) {
    const double pixel = std::sqrt(min_sharp_split_area());
    uint32_t resolution = params.resolution;
    if (pixel > 0.0)
      resolution = std::max(resolution, static_cast<uint32_t>(std::min<double>(kMaxSunResolution, std::ceil(prep.diagonal / pixel))) & ~1u);
    sun_cube = std::make_unique<detail::Hemicube>(detail::Hemicube::top_face(resolution));
  }
  // A point or spot light's shadows of small things (boxes on a table under a lamp 1.4 m away)
  // spread over a pixel of its cube, 2.8 cm there at resolution 100: so a strong light's cube has
  // pixels as wide as the smallest elements a sharp outline still splits, half the scene's diagonal
  // from the light (kMaxPointResolution; bench/README.md, "Crowded tables").
  const bool any_point = std::any_of(lights.begin(), lights.end(), [](const Light& l) { return l.type != Light::Type::kDirectional; });
  if (const double pixel = std::sqrt(min_sharp_split_area()); any_point && pixel > 0.0) {
    const uint32_t resolution = static_cast<uint32_t>(std::min<double>(kMaxPointResolution, std::ceil(prep.diagonal / pixel))) & ~1u;
    if (resolution > params.resolution) fine_light_cube = std::make_unique<detail::Hemicube>(detail::Hemicube::solid_angles(resolution));
  }
  // A direction of the sky is one of hundreds: its shadows are summed with the others', so half
  // the resolution serves.
  sky_cube = std::make_unique<detail::Hemicube>(detail::Hemicube::top_face(std::max(kMinResolution, ((params.resolution / 2) + 1) & ~1u)));
  grow_scratch();
  double power = 0.0;
  for (const Light& light : lights) {
    std::vector<LightView> views;
    light_views(light, views);
    for (LightView& v : views) project_light_view(v, leaves);
    light_factors(&light, views, leaves);
    double own = 0.0;
    for (uint32_t e : leaves) own += channel_sum(light.intensity) * f_recv[e] * e_area[e];
    light_power.push_back(own);
    power += own;
  }
  if (has_sky) {
    const std::vector<glm::dvec3> f = sky_factors(kSkyEstimateStep, leaves);
    for (uint32_t e : leaves) power += channel_sum(sky) * f[e].x * e_area[e];
  }
  emitted_power += power;
  // The radiosity tolerance is beps times the mean emitted radiosity per unit area: light that
  // arrives counts as emitted there.
  b_tolerance += params.beps * (power / 3.0) / prep.total_area;
  stats.emitted_power = emitted_power;
  update_unshot_total();
  stats.seconds_lights += seconds_since(t0);
}

// Shoots the next light, or the sky after the last light; false when all have shot.
bool Solver::Impl::shoot_next_light() {
  const uint32_t turns = static_cast<uint32_t>(lights.size()) + (sky != glm::dvec3(0.0) ? 1u : 0u);
  if (light_turn >= turns) return false;
  if (emitted_power <= 0.0) {
    light_turn = turns;  // nothing they light: nothing to shoot
    return false;
  }
  const auto t0 = Clock::now();
  bool shot = true;
  if (light_turn < lights.size()) shoot_light(light_turn);
  else shot = shoot_sky_part();
  stats.seconds += seconds_since(t0);
  stats.seconds_lights += seconds_since(t0);
  if (!shot) return true;  // the sky's shot goes on at the next step
  ++light_turn;
  ++stats.shots;
  ++stats.light_shots;
  update_unshot_total();
  if (first_pass && light_turn == turns) count_lit_as_emitters();
  return true;
}

// The first pass waits for every emitter to shoot (pools.cpp): the lights' light first leaves
// the patches they lit, and those holding at least kPoolsUnit of the scene's light count as
// emitters too. A gallery's sunlit floor under a skylight held 8 % of it, the roof's outside 80 %:
// once the roof had shot into the empty sky, 70 % of the light was given out and the pass ended
// before the floor's light reached the end walls, which stayed one flat element each.
void Solver::Impl::count_lit_as_emitters() {
  if (p_emitter_left.empty()) return;
  for (uint32_t q = 0; q < patches.size(); ++q)
    if (!p_emitter_left[q] && p_unshot[q] >= kPoolsUnit * emitted_power) {
      p_emitter_left[q] = 1;
      ++emitters_left;
    }
}

}  // namespace hemibake::solver
