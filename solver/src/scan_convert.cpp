// Solid-area scan conversion, after Figure 4 of "Anti-aliased hemicubes for performance improvement
// in radiosity solutions".
//
// The area of a polygon inside a pixel is the signed sum, over the polygon's edges, of the area
// between each edge and the pixel's bottom border, restricted to the pixel. An edge piece inside the
// pixel contributes the trapezoid (x_e - x_l)(y_e + y_l)/2 (coordinates from the pixel's lower-left
// corner); an edge piece in a pixel higher up in the same column contributes its full pixel height
// over its x-extent, which the column carry C hands down to every pixel below it. Vertical edges
// contribute nothing, so only x-extents matter.
#include "hemibake/solver/scan_convert.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdint>

namespace hemibake::solver {

double signed_area(std::span<const glm::dvec2> polygon) {
  double twice = 0.0;
  const size_t n = polygon.size();
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2& p = polygon[i];
    const glm::dvec2& q = polygon[(i + 1) % n];
    twice += (p.x - q.x) * (p.y + q.y);
  }
  return 0.5 * twice;
}

namespace {

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

// One edge walk for areas and, with Moments, first moments. For an edge piece from (x0, y0) to
// (x1, y1) inside a pixel (local coordinates), the region between it and the pixel's bottom has
// area -s * integral of y dx (the paper's s (x_e - x_l)(y_e + y_l) / 2), moments -s * integral of
// x y dx and -s * integral of y^2 / 2 dx, all exact by Simpson's rule since the integrands are at
// most quadratic. Pixels below get the full-height column: -s dx for the area, -s (x1^2 - x0^2) / 2
// and -s dx / 2 for the moments, handed down by the column carry.
template <bool Moments>
void walk(std::span<const glm::dvec2> polygon, const PixelWindow& window, std::span<double> area,
          std::span<double> moment_x, std::span<double> moment_y, ScanScratch& scratch) {
  const int w = window.width;
  const int h = window.height;
  assert(w > 0 && h > 0);
  const size_t cells = static_cast<size_t>(w) * static_cast<size_t>(h);
  assert(area.size() >= cells);
  const size_t n = polygon.size();
  const double signed_total = n >= 3 ? signed_area(polygon) : 0.0;
  if (n < 3 || cells == 1) {
    // Nothing, or a polygon inside a single pixel: its own area and centroid, no walk needed.
    std::fill_n(area.begin(), cells, 0.0);
    if constexpr (Moments) {
      std::fill_n(moment_x.begin(), cells, 0.0);
      std::fill_n(moment_y.begin(), cells, 0.0);
    }
    if (n < 3) return;
    area[0] = std::abs(signed_total);
    if constexpr (Moments) {
      if (signed_total == 0.0) return;
      double cx = 0.0, cy = 0.0;
      for (size_t i = 0; i < n; ++i) {
        const glm::dvec2 a = polygon[i] - glm::dvec2(window.x0, window.y0);
        const glm::dvec2 b = polygon[(i + 1) % n] - glm::dvec2(window.x0, window.y0);
        const double cross = a.x * b.y - b.x * a.y;
        cx += (a.x + b.x) * cross;
        cy += (a.y + b.y) * cross;
      }
      // Centroid = (cx, cy) / (6 A) with A the signed area; moments are centroid times |A|.
      const double k = std::abs(signed_total) / (6.0 * signed_total);
      moment_x[0] = cx * k;
      moment_y[0] = cy * k;
    }
    return;
  }

  // Per pixel, interleaved: own area, area carry (and own moments x, y, moment carries x, y). The
  // buffer is kept all zero between calls: the final sweep clears what it reads.
  constexpr size_t kStride = Moments ? 6 : 2;
  std::vector<double>& acc = scratch.cells;
  if (acc.size() < cells * kStride) acc.resize(cells * kStride, 0.0);

  // Orientation: the trapezoid sum is positive for counter-clockwise loops.
  const double s = signed_total >= 0.0 ? 1.0 : -1.0;
  const double fx0 = window.x0;
  const double fy0 = window.y0;

  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2 p = polygon[i];
    const glm::dvec2 q = polygon[(i + 1) % n];
    if (p.x == q.x) continue;  // vertical: no x-extent, no area
    const glm::dvec2 d = q - p;

    // Split the edge where it crosses a pixel border, so that every piece lies in one pixel: the
    // crossings of vertical and of horizontal borders each come in increasing t, and are merged
    // as the edge is walked.
    const double sx = d.x > 0.0 ? 1.0 : -1.0;
    const double inv_dx = 1.0 / d.x;
    double kx = d.x > 0.0 ? fast_floor(p.x) + 1.0 : fast_ceil(p.x) - 1.0;
    auto next_tx = [&] { return (d.x > 0.0 ? kx < q.x : kx > q.x) ? (kx - p.x) * inv_dx : 2.0; };
    double tx = next_tx();
    double ky = 0.0, sy = 0.0, inv_dy = 0.0, ty = 2.0;
    if (p.y != q.y) {
      sy = d.y > 0.0 ? 1.0 : -1.0;
      inv_dy = 1.0 / d.y;
      ky = d.y > 0.0 ? fast_floor(p.y) + 1.0 : fast_ceil(p.y) - 1.0;
    }
    auto next_ty = [&] { return sy != 0.0 && (d.y > 0.0 ? ky < q.y : ky > q.y) ? (ky - p.y) * inv_dy : 2.0; };
    ty = next_ty();

    glm::dvec2 a = p;
    for (;;) {
      const bool last = tx == 2.0 && ty == 2.0;
      glm::dvec2 b = q;
      if (!last) {
        // Vertical borders first where both fall at the same t (the second piece is empty).
        const double t = ty < tx ? ty : tx;
        b = p + d * t;
        if (ty < tx) {
          ky += sy;
          ty = next_ty();
        } else {
          kx += sx;
          tx = next_tx();
        }
      }
      if (b.x != a.x) {  // a zero-width piece (a repeated crossing) adds nothing
        const glm::dvec2 mid = 0.5 * (a + b);
        // Truncation is floor here: negative values clamp to 0 either way.
        const int col = std::clamp(static_cast<int>(mid.x - fx0), 0, w - 1);
        const int row = std::clamp(static_cast<int>(mid.y - fy0), 0, h - 1);
        const double px = fx0 + col, py = fy0 + row;
        // Entering (a) and leaving (b) coordinates relative to the pixel's lower-left corner.
        const double xe = a.x - px, xl = b.x - px;
        const double ye = std::clamp(a.y - py, 0.0, 1.0), yl = std::clamp(b.y - py, 0.0, 1.0);
        double* c = acc.data() + (static_cast<size_t>(row) * static_cast<size_t>(w) + static_cast<size_t>(col)) * kStride;
        const double dx = s * (xe - xl);
        c[0] += dx * (ye + yl) * 0.5;
        c[1] += dx;  // times the pixel height, which is 1
        if constexpr (Moments) {
          const double xm = 0.5 * (xe + xl), ym = 0.5 * (ye + yl);
          const double dx6 = dx / 6.0;  // -(x_l - x_e) / 6 with the orientation's sign
          c[2] += dx6 * (xe * ye + 4.0 * xm * ym + xl * yl);
          c[3] += dx6 * 0.5 * (ye * ye + 4.0 * ym * ym + yl * yl);
          c[4] += dx * xm;  // s (x_e^2 - x_l^2) / 2
          c[5] += 0.5 * dx;
        }
      }
      if (last) break;
      a = b;
    }
  }

  // Hand each column's carry down from the top row to the rows below it.
  for (int col = 0; col < w; ++col) {
    double cc = 0.0, cx = 0.0, cy = 0.0;
    for (int row = h - 1; row >= 0; --row) {
      const size_t cell = static_cast<size_t>(row) * static_cast<size_t>(w) + static_cast<size_t>(col);
      double* c = acc.data() + cell * kStride;
      area[cell] = c[0] + cc;
      cc += c[1];
      if constexpr (Moments) {
        moment_x[cell] = c[2] + cx;
        moment_y[cell] = c[3] + cy;
        cx += c[4];
        cy += c[5];
      }
      for (size_t k = 0; k < kStride; ++k) c[k] = 0.0;
    }
  }
}

}  // namespace

void scan_convert_area(std::span<const glm::dvec2> polygon, const PixelWindow& window,
                       std::span<double> area, ScanScratch& scratch) {
  walk<false>(polygon, window, area, {}, {}, scratch);
}

void scan_convert_moments(std::span<const glm::dvec2> polygon, const PixelWindow& window,
                          std::span<double> area, std::span<double> moment_x,
                          std::span<double> moment_y, ScanScratch& scratch) {
  walk<true>(polygon, window, area, moment_x, moment_y, scratch);
}

}  // namespace hemibake::solver
