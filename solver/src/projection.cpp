// Projection of elements onto the placed hemicube, the reuse of a parent's pixels for its
// children (section 2.3 of the paper), and the form factors summed from the resolved fragments.
#include "solver_impl.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>

namespace hemibake::solver {

// F(piece -> element) for each element, summed over its fragments: covered area times the pixel's
// delta form factor (a volume cluster's: the share of its light through the pixel), with (e_ff)
// and without (e_ff_open) the pixel's transmission.
void Solver::Impl::sum_form_factors(std::span<const uint32_t> elements) {
  const auto& dff = *pixel_weight;
  pool.parallel_for(elements.size(), [&](size_t b, size_t e, size_t) {
    for (size_t i = b; i < e; ++i) {
      const uint32_t el = elements[i];
      double ff = 0.0, open = 0.0;
      for (uint32_t k = sealed(e_patch[el], eye_within) ? f_end[el] : f_begin[el]; k < f_end[el]; ++k) {
        const Fragment& f = frags[k];
        const double a = static_cast<double>(f.area) * dff[f.pixel];
        open += a;
        ff += a * f.trans;
      }
      e_ff[el] = ff;
      e_ff_open[el] = open;
      e_stamp[el] = stamp;
    }
  });
}

// The paper culls the parent patch's back faces (section 2.2), which is exact where every back face
// lies behind a front face of the same solid. A one-sided wall seen from behind has none: culled, it
// would let light through (a room of inward-facing walls lit from outside came out lit inside). So
// such backs (PreparedScene::back_hidden) are projected as occluders that take no light: flagged,
// and outside the element's fragment range. The backs of solids and of double-sided surfaces stay
// culled: projected too, they would over-occlude at every silhouette pixel (front and back cover the
// same part of it, and E_k takes them as independent). A patch seen edge-on is left out. The final
// gather (gather.cpp) projects the backs of the solids whose bounding box holds its point: a point
// on the floor under a box standing on it sees nothing but the box's backs.
bool Solver::Impl::culled(uint32_t p, double facing) const {
  return std::abs(facing) <= kRoundingLength * prep.diagonal || (facing < 0.0 && prep.back_hidden[p]);
}

// A closed double-sided mesh's inside is seen only from within it. Seen from outside, its faces lie
// behind its outside's in every pixel, yet the layers of a pixel take each surface's coverage as
// independent of the others': where such a mesh is smaller than a pixel (a book on a shelf across
// the room, a chair's leg) its inside took a share of the pixel behind its own outside, the
// study's books 30 to 60 % of their outside's light and the insides of the walls' boxes 1 to 3 %,
// which bounced about inside and took shots to settle. For an eye outside their mesh such faces
// take no light. A light's view still projects them, to hide what they hid: left out there, the
// seam between two wall boxes under a window, where each box's outside covers part of a pixel, let
// the sun through in a line across the floor. A patch's hemicube leaves them out (project): in a
// pixel they lie folded behind their own outside, which leaves them nothing, yet each is one more
// surface in every pixel its box covers, and a room of hundreds of double-sided boxes spent a third
// of its bake layering them (bench/README.md, "Faces inside closed boxes").
std::vector<uint32_t> Solver::Impl::enclosing(const glm::dvec3& x) const {
  std::vector<uint32_t> in;
  for (uint32_t k = 0; k < prep.closed_outside.size(); ++k)
    if (detail::inside_closed(patches, prep, k, x)) in.push_back(k);
  return in;
}

bool Solver::Impl::sealed(uint32_t p, std::span<const uint32_t> open) const {
  const uint32_t s = prep.inner_solid[p];
  return s != kNone && !std::binary_search(open.begin(), open.end(), s);
}

// Projects element el (its corners in poly, as the cube sees them) into `cube`: its front, or
// (facing < 0) its back as an occluder that takes no light, reversed to run counter-clockwise as
// seen and a little farther than a front face at the same depth. `plane`: clip to the element's
// side of its plane (a perspective view). The fragments carry `id` (el, or the caller's own index);
// `windows`, when given, keeps them to those pixels. Returns whether they are the element's own.
bool Solver::Impl::project_side(detail::Hemicube& into, uint32_t el, uint32_t id, Corners& poly, double facing,
                                bool plane, detail::ProjectScratch& s, std::vector<Fragment>& out,
                                const detail::FaceWindows* windows) const {
  const uint32_t p = e_patch[el];
  const uint32_t cc = patches[p].corner_count;
  if (facing > 0.0) {
    into.project(std::span(poly.data(), cc), id, params.method, s, out, plane ? &prep.normal[p] : nullptr, windows);
    return true;
  }
  std::reverse(poly.begin(), poly.begin() + cc);
  const glm::dvec3 back = -prep.normal[p];
  const size_t first = out.size();
  into.project(std::span(poly.data(), cc), id | detail::kBackFace, params.method, s, out, plane ? &back : nullptr,
               windows);
  for (size_t k = first; k < out.size(); ++k) out[k].inv_depth *= detail::kBackDepthScale;
  return false;
}

// Joins the chunks' fragment lists (chunk_frags) into `all` in chunk order, so fragments (and ties
// in depth) come in the same order with any number of threads, and moves each element's range.
void Solver::Impl::join_chunks(std::span<const uint32_t> elements, std::vector<uint32_t>& begin,
                               std::vector<uint32_t>& end, std::vector<Fragment>& all) {
  const size_t n = elements.size();
  const size_t chunks = pool.chunk_count(n);
  all.clear();
  for (size_t c = 0; c < chunks; ++c) {
    const uint32_t base = static_cast<uint32_t>(all.size());
    all.insert(all.end(), chunk_frags[c].begin(), chunk_frags[c].end());
    for (size_t i = n * c / chunks; i < n * (c + 1) / chunks; ++i) {
      begin[elements[i]] += base;
      end[elements[i]] += base;
    }
  }
}

// Projects element el into `out`, unless it belongs to the shooting piece, is culled or is sealed
// from the eye; returns whether the fragments are its own (project_side).
bool Solver::Impl::project_element(uint32_t el, const glm::dvec3& eye, Corners& poly, detail::ProjectScratch& s,
                                   std::vector<Fragment>& out, const detail::FaceWindows* windows) const {
  const uint32_t p = e_patch[el];
  const double facing = glm::dot(prep.normal[p], eye - patches[p].corners[0]);
  if (p_shooting[p] == shooting_stamp || culled(p, facing) || sealed(p, eye_within)) return false;
  corners_of(el, poly);
  return project_side(*cube, el, el, poly, facing, true, s, out, windows);
}

// Projects the receivers first (their fragments kept in recv_frags, per receiver its chunk and
// range in recv_at), and sets `windows` to their own fragments' pixels, face by face
// (widen_windows). False when those would keep the view to half or more of the cube's pixels,
// where keeping to them saves little.
bool Solver::Impl::project_receivers(std::span<const uint32_t> receivers, detail::FaceWindows& windows) {
  const size_t chunks = pool.chunk_count(receivers.size());
  if (recv_frags.size() < chunks) recv_frags.resize(chunks);
  recv_at.resize(receivers.size());
  if (e_recv_slot.size() < e_patch.size()) e_recv_slot.resize(e_patch.size(), 0);
  std::vector<detail::FaceWindows> per_chunk(chunks);
  const glm::dvec3 eye = cube->eye();
  pool.parallel_for(receivers.size(), [&](size_t b, size_t e, size_t c) {
    auto& out = recv_frags[c];
    out.clear();
    Corners poly{};
    for (size_t i = b; i < e; ++i) {
      const size_t first = out.size();
      const bool own = project_element(receivers[i], eye, poly, scratch[c], out, nullptr);
      if (own) cube->widen_windows(std::span(out.data() + first, out.size() - first), per_chunk[c]);
      recv_at[i] = {static_cast<uint32_t>(c), static_cast<uint32_t>(first), static_cast<uint32_t>(out.size()), own};
    }
  });
  for (size_t i = 0; i < receivers.size(); ++i) e_recv_slot[receivers[i]] = static_cast<uint32_t>(i + 1);
  windows = {};
  for (const detail::FaceWindows& w : per_chunk)
    for (size_t f = 0; f < w.size(); ++f) windows[f].widen(w[f]);
  return 2 * cube->window_pixels(windows) < cube->pixel_count();
}

// Each chunk of elements projects into a fragment list of its own (join_chunks). A shot that needs
// the form factors of a few receivers only (a near-field piece's, a replay's split receivers')
// keeps the projection to their pixels: a pixel's rule reads only its own fragments, so theirs
// come out as with the whole view (but for rounding where an occluder is cut at a window's edge).
// The receivers are projected first, to find their pixels, and their fragments then take their
// place in the order of `elements` (the order breaks ties in depth). The cluttered room's
// replays drew 59 M fragments, 1.4 % of them in their receivers' pixels.
void Solver::Impl::project(std::span<const uint32_t> elements, std::span<const uint32_t> receivers) {
  const auto t0 = Clock::now();
  ++stats.projections;
  stats.elements_projected += elements.size();
  const glm::dvec3 eye = cube->eye();
  detail::FaceWindows windows{};
  const bool windowed = !receivers.empty() && project_receivers(receivers, windows);
  pool.parallel_for(elements.size(), [&](size_t b, size_t e, size_t c) {
    auto& out = chunk_frags[c];
    out.clear();
    Corners poly{};
    for (size_t i = b; i < e; ++i) {
      const uint32_t el = elements[i];
      f_begin[el] = f_end[el] = static_cast<uint32_t>(out.size());
      if (!receivers.empty() && e_recv_slot[el] != 0) {
        const RecvAt& at = recv_at[e_recv_slot[el] - 1];
        const std::vector<Fragment>& from = recv_frags[at.chunk];
        out.insert(out.end(), from.begin() + at.begin, from.begin() + at.end);
        if (at.own) f_end[el] = static_cast<uint32_t>(out.size());
        continue;
      }
      if (project_element(el, eye, poly, scratch[c], out, windowed ? &windows : nullptr))
        f_end[el] = static_cast<uint32_t>(out.size());
    }
  });
  for (uint32_t el : receivers) e_recv_slot[el] = 0;
  join_chunks(elements, f_begin, f_end, frags);
  for (uint32_t el : elements) HEMIBAKE_DCHECK(f_begin[el] <= f_end[el] && f_end[el] <= frags.size());
  detail::resolve(frags, cube->pixel_count(), params.method, e_group, covered_bit(), e_cover, prep.adjacency, pool, order,
                  pixel_start);
  stats.peak_fragments = std::max<uint64_t>(stats.peak_fragments, frags.size());
  stats.seconds_projecting += seconds_since(t0);
}

// The children of split `parents` take their fragments from their parent's pixels and
// transmissions (no other element is projected again), and their form factors from those.
void Solver::Impl::project_children(const std::vector<uint32_t>& parents) {
  const auto t0 = Clock::now();
  const size_t n = parents.size();
  const size_t chunks = pool.chunk_count(n);
  pool.parallel_for(n, [&](size_t b, size_t e, size_t c) {
    auto& out = chunk_frags[c];
    out.clear();
    Corners poly{};
    for (size_t i = b; i < e; ++i) {
      const uint32_t par = parents[i];
      const std::span<const Fragment> pf(frags.data() + f_begin[par], f_end[par] - f_begin[par]);
      for (uint32_t k = 0; k < 4; ++k) {
        const uint32_t ch = e_child[par] + k;
        f_begin[ch] = f_end[ch] = static_cast<uint32_t>(out.size());
        if (pf.empty()) continue;
        corners_of(ch, poly);
        cube->project_child(std::span(poly.data(), corner_count(ch)), ch, pf, params.method,
                           scratch[c], out);
        f_end[ch] = static_cast<uint32_t>(out.size());
      }
    }
  });
  std::vector<uint32_t> children;
  children.reserve(n * 4);
  for (size_t c = 0; c < chunks; ++c) {
    const uint32_t base = static_cast<uint32_t>(frags.size());
    frags.insert(frags.end(), chunk_frags[c].begin(), chunk_frags[c].end());
    for (size_t i = n * c / chunks; i < n * (c + 1) / chunks; ++i) {
      for (uint32_t k = 0; k < 4; ++k) {
        const uint32_t ch = e_child[parents[i]] + k;
        f_begin[ch] += base;
        f_end[ch] += base;
        children.push_back(ch);
      }
    }
  }
  for (uint32_t ch : children) HEMIBAKE_DCHECK(f_begin[ch] <= f_end[ch] && f_end[ch] <= frags.size());
  sum_form_factors(children);
  stats.reused_children += children.size();
  stats.peak_fragments = std::max<uint64_t>(stats.peak_fragments, frags.size());
  stats.seconds_reusing += seconds_since(t0);
}

}  // namespace hemibake::solver
