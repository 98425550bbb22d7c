// The scan converter behind scan_convert_area / scan_convert_moments, handing each pixel's result
// to a callback instead of writing arrays, so that the hemicube turns pixels into fragments as the
// final sweep reaches them.
#pragma once

#include "hemibake/solver/scan_convert.h"

#include <glm/vec2.hpp>

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

namespace hemibake::solver::detail {

// floor and ceil by truncation (std::floor is a library call or a long sequence on baseline
// x86-64); for finite |v| < 2^63, which pixel coordinates are.
inline double fast_floor(double v) {
  const double t = static_cast<double>(static_cast<int64_t>(v));
  return t > v ? t - 1.0 : t;
}
inline double fast_ceil(double v) {
  const double t = static_cast<double>(static_cast<int64_t>(v));
  return t < v ? t + 1.0 : t;
}

// Signed area and signed first moments (integrals of x and y over the loop's winding) of a closed
// loop, by the shoelace sums.
struct LoopMoments {
  double area = 0.0, mx = 0.0, my = 0.0;
};
inline LoopMoments loop_moments(const glm::dvec2* p, size_t n) {
  double a2 = 0.0, cx = 0.0, cy = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2 a = p[i];
    const glm::dvec2 b = p[i + 1 == n ? 0 : i + 1];
    const double cross = a.x * b.y - b.x * a.y;
    a2 += cross;
    cx += (a.x + b.x) * cross;
    cy += (a.y + b.y) * cross;
  }
  return {0.5 * a2, cx / 6.0, cy / 6.0};
}

// Keeps the part of a loop on one side of the line coordinate[axis] = at (below: smaller values).
// Sutherland-Hodgman: for a non-convex or self-overlapping loop the result may run along the line
// twice, which adds nothing to its signed area or moments.
inline size_t cut_loop(const glm::dvec2* in, size_t n, int axis, double at, bool below, glm::dvec2* out) {
  size_t m = 0;
  if (n == 0) return 0;
  auto inside = [&](const glm::dvec2& v) { return below ? v[axis] <= at : v[axis] >= at; };
  glm::dvec2 prev = in[n - 1];
  bool prev_in = inside(prev);
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2 cur = in[i];
    const bool cur_in = inside(cur);
    if (cur_in != prev_in) {
      const double t = (at - prev[axis]) / (cur[axis] - prev[axis]);
      glm::dvec2 x = prev + (cur - prev) * t;
      x[axis] = at;
      out[m++] = x;
    }
    if (cur_in) out[m++] = cur;
    prev = cur;
    prev_in = cur_in;
  }
  return m;
}

// One cut of n corners gives at most 3n/2 corners: 24, then 36 (scan_small_window).
inline constexpr size_t kMaxSmallCut = 16;

// Windows of at most 2 x 2 pixels (scan_walk): areas and moments of the parts left (x < 1) and below
// (y < 1) and of the part both left and below; the other pixels' by difference from the whole. Signs
// follow the loop's orientation. `local`: the polygon in window coordinates, n <= kMaxSmallCut.
template <bool Moments, class Sink>
[[gnu::always_inline]] inline void scan_small_window(const glm::dvec2* local, size_t n, int w, int h, Sink& sink) {
  const LoopMoments whole = loop_moments(local, n);
  const double s = whole.area >= 0.0 ? 1.0 : -1.0;
  std::array<glm::dvec2, 3 * kMaxSmallCut / 2> a, b;  // uninitialised: cut_loop writes what is read
  std::array<glm::dvec2, 9 * kMaxSmallCut / 4> c;
  LoopMoments left, bottom, both;
  size_t na = 0;
  if (w == 2) {
    na = cut_loop(local, n, 0, 1.0, true, a.data());
    left = loop_moments(a.data(), na);
  }
  if (h == 2) bottom = loop_moments(b.data(), cut_loop(local, n, 1, 1.0, true, b.data()));
  if (w == 2 && h == 2) both = loop_moments(c.data(), cut_loop(a.data(), na, 1, 1.0, true, c.data()));
  if (w == 1) left = whole;
  if (h == 1) bottom = whole;
  if (w == 1 || h == 1) both = w == 1 ? bottom : left;
  // Per pixel (col, row): the part's area and moments in window coordinates.
  auto emit = [&](int col, int row, double area, double mx, double my) {
    area *= s;
    if constexpr (Moments) {
      sink(col, row, area, s * mx - col * area, s * my - row * area);
    } else {
      sink(col, row, area, 0.0, 0.0);
    }
  };
  emit(0, 0, both.area, both.mx, both.my);
  if (w == 2) emit(1, 0, bottom.area - both.area, bottom.mx - both.mx, bottom.my - both.my);
  if (h == 2) {
    emit(0, 1, left.area - both.area, left.mx - both.mx, left.my - both.my);
    if (w == 2)
      emit(1, 1, whole.area - left.area - bottom.area + both.area, whole.mx - left.mx - bottom.mx + both.mx,
           whole.my - left.my - bottom.my + both.my);
  }
}

// Adds the edge p -> q of the mirrored loop (orientation sign s) to the per-pixel sums `acc`
// (scan_walk's interleaved cells of a w x h window): the edge is split where it crosses a pixel
// border, so that every piece lies in one pixel. The crossings of vertical and of horizontal
// borders each come in increasing t, and are merged as the edge is walked; the piece's pixel is
// followed by counting the crossings.
template <bool Moments>
[[gnu::always_inline]] inline void walk_edge(const glm::dvec2 p, const glm::dvec2 q, int w, int h, double s, double* acc) {
  constexpr size_t kStride = Moments ? 6 : 2;
  if (p.x == q.x) return;  // vertical: no x-extent, no area
  const glm::dvec2 d = q - p;
  const bool right = d.x > 0.0;
  const int sx = right ? 1 : -1;
  const double inv_dx = 1.0 / d.x;
  int col = right ? static_cast<int>(fast_floor(p.x)) : static_cast<int>(fast_ceil(p.x)) - 1;
  double kx = right ? col + 1.0 : static_cast<double>(col);  // the next vertical border
  auto next_tx = [&] { return (right ? kx < q.x : kx > q.x) ? (kx - p.x) * inv_dx : 2.0; };
  double tx = next_tx();
  int row = 0, sy = 0;
  double ky = 0.0, inv_dy = 0.0, ty = 2.0;
  const bool up = d.y > 0.0;
  if (p.y != q.y) {
    sy = up ? 1 : -1;
    inv_dy = 1.0 / d.y;
    row = up ? static_cast<int>(fast_floor(p.y)) : static_cast<int>(fast_ceil(p.y)) - 1;
    ky = up ? row + 1.0 : static_cast<double>(row);
  } else {
    row = static_cast<int>(fast_floor(p.y));
  }
  auto next_ty = [&] { return sy != 0 && (up ? ky < q.y : ky > q.y) ? (ky - p.y) * inv_dy : 2.0; };
  ty = next_ty();

  glm::dvec2 a = p;
  for (;;) {
    const bool last = tx == 2.0 && ty == 2.0;
    glm::dvec2 b = q;
    int next_col = col, next_row = row;
    if (!last) {
      // Vertical borders first where both fall at the same t (the second piece is empty).
      if (ty < tx) {
        b = p + d * ty;
        ky += sy;
        next_row += sy;
        ty = next_ty();
      } else {
        b = p + d * tx;
        kx += sx;
        next_col += sx;
        tx = next_tx();
      }
    }
    if (b.x != a.x) {  // a zero-width piece (a repeated crossing) adds nothing
      // Rounding may put a crossing a hair outside the window: keep to its pixels.
      const int c = std::clamp(col, 0, w - 1);
      const int r = std::clamp(row, 0, h - 1);
      // Entering (a) and leaving (b) coordinates relative to the pixel's lower-left corner.
      const double xe = a.x - c, xl = b.x - c;
      const double ye = std::clamp(a.y - r, 0.0, 1.0), yl = std::clamp(b.y - r, 0.0, 1.0);
      double* cell = acc + (static_cast<size_t>(r) * static_cast<size_t>(w) + static_cast<size_t>(c)) * kStride;
      const double dx = s * (xe - xl);
      cell[0] += dx * (ye + yl) * 0.5;
      cell[1] += dx;  // times the pixel height, which is 1
      if constexpr (Moments) {
        // Moments by Simpson's rule (the integrands are at most quadratic along the piece):
        // -s * integral of x y dx and -s * integral of y^2 / 2 dx; the column below gets
        // -s (x1^2 - x0^2) / 2 and -s dx / 2.
        const double xm = 0.5 * (xe + xl), ym = 0.5 * (ye + yl);
        const double dx6 = dx / 6.0;
        cell[2] += dx6 * (xe * ye + 4.0 * xm * ym + xl * yl);
        cell[3] += dx6 * 0.5 * (ye * ye + 4.0 * ym * ym + yl * yl);
        cell[4] += dx * xm;
        cell[5] += 0.5 * dx;
      }
    }
    if (last) break;
    a = b;
    col = next_col;
    row = next_row;
  }
}

// Hands each column's carry down from the top (mirrored) row of `acc` (scan_walk): that is the
// window's bottom row first, so the sink sees rows in increasing order. Clears what it reads.
template <bool Moments, class Sink>
[[gnu::always_inline]] inline void sweep_carry(double* acc, int w, int h, std::vector<double>& carry, Sink& sink) {
  constexpr size_t kStride = Moments ? 6 : 2;
  carry.assign(static_cast<size_t>(w) * (Moments ? 3 : 1), 0.0);
  for (int r = h - 1; r >= 0; --r) {
    const int out_row = h - 1 - r;
    double* cell = acc + static_cast<size_t>(r) * static_cast<size_t>(w) * kStride;
    for (int col = 0; col < w; ++col, cell += kStride) {
      const double area = cell[0] + carry[col];
      carry[col] += cell[1];
      if constexpr (Moments) {
        // Mirrored back: the moment of y about the pixel's bottom is area - moment of y'.
        const double mx = cell[2] + carry[w + col];
        const double my_mirrored = cell[3] + carry[2 * w + col];
        carry[w + col] += cell[4];
        carry[2 * w + col] += cell[5];
        for (size_t k = 0; k < kStride; ++k) cell[k] = 0.0;
        sink(col, out_row, area, mx, area - my_mirrored);
      } else {
        cell[0] = cell[1] = 0.0;
        sink(col, out_row, area, 0.0, 0.0);
      }
    }
  }
}

// Calls sink(col, row, area, moment_x, moment_y) once for every pixel of the window, in increasing
// row and, within a row, increasing column, with the covered area (pixel units) and, with Moments,
// its first moments about the pixel's lower-left corner (zero without). Semantics as
// scan_convert_moments; `local` is scratch for the polygon in window coordinates.
//
// Windows of one pixel take the polygon's own area and centroid; windows of at most 2 x 2 pixels cut
// the polygon at the inner pixel borders (one pixel's share is then the whole minus the others').
// Larger windows walk the edges: the area of a polygon inside a pixel is the signed sum, over its
// edges, of the area between each edge and the pixel's bottom border, restricted to the pixel. An
// edge piece inside the pixel contributes the trapezoid (x_e - x_l)(y_e + y_l)/2 (coordinates from
// the pixel's lower-left corner); an edge piece in a pixel higher up in the same column contributes
// its full pixel height over its x-extent, which the column carry C hands down to every pixel below
// it. Vertical edges contribute nothing. The walk runs on the polygon mirrored top to bottom, so
// that the final sweep, which must go from the top row down to hand on the carry, meets the rows in
// increasing order.
template <bool Moments, class Sink>
void scan_walk(std::span<const glm::dvec2> polygon, const PixelWindow& window, ScanScratch& scratch,
               Sink&& sink) {
  const int w = window.width;
  const int h = window.height;
  assert(w > 0 && h > 0);
  const size_t n = polygon.size();
  if (n < 3) {
    for (int row = 0; row < h; ++row)
      for (int col = 0; col < w; ++col) sink(col, row, 0.0, 0.0, 0.0);
    return;
  }
  // The polygon in window coordinates (origin at the window's lower-left corner).
  std::vector<glm::dvec2>& local = scratch.local;
  local.resize(n);
  const glm::dvec2 origin(window.x0, window.y0);
  for (size_t i = 0; i < n; ++i) local[i] = polygon[i] - origin;

  if (w <= 2 && h <= 2 && n <= kMaxSmallCut) {
    scan_small_window<Moments>(local.data(), n, w, h, sink);
    return;
  }

  // Per pixel, interleaved: own area, area carry (and own moments x, y, moment carries x, y). The
  // buffer is kept all zero between calls: the final sweep clears what it reads.
  constexpr size_t kStride = Moments ? 6 : 2;
  const size_t cells = static_cast<size_t>(w) * static_cast<size_t>(h);
  std::vector<double>& acc = scratch.cells;
  if (acc.size() < cells * kStride) acc.resize(cells * kStride, 0.0);
  // Mirror top to bottom: y' = h - y (the loop's orientation flips with it).
  for (glm::dvec2& v : local) v.y = h - v.y;
  // Orientation: the trapezoid sum is positive for counter-clockwise loops.
  double twice = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2& p = local[i];
    const glm::dvec2& q = local[i + 1 == n ? 0 : i + 1];
    twice += (p.x - q.x) * (p.y + q.y);
  }
  const double s = twice >= 0.0 ? 1.0 : -1.0;
  for (size_t i = 0; i < n; ++i) walk_edge<Moments>(local[i], local[i + 1 == n ? 0 : i + 1], w, h, s, acc.data());
  sweep_carry<Moments>(acc.data(), w, h, scratch.carry, sink);
}

}  // namespace hemibake::solver::detail
