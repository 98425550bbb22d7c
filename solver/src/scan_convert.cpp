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

// One edge walk for areas and, when moment_x is not empty, first moments. For an edge piece from
// (x0, y0) to (x1, y1) inside a pixel (local coordinates), the region between it and the pixel's
// bottom has area -s * integral of y dx (the paper's s (x_e - x_l)(y_e + y_l) / 2), moments
// -s * integral of x y dx and -s * integral of y^2 / 2 dx, all exact by Simpson's rule since the
// integrands are at most quadratic. Pixels below get the full-height column: -s dx for the area,
// -s (x1^2 - x0^2) / 2 and -s dx / 2 for the moments, handed down by the column carry.
void walk(std::span<const glm::dvec2> polygon, const PixelWindow& window, std::span<double> area,
          std::span<double> moment_x, std::span<double> moment_y, ScanScratch& scratch) {
  const int w = window.width;
  const int h = window.height;
  assert(w > 0 && h > 0);
  const size_t cells = static_cast<size_t>(w) * static_cast<size_t>(h);
  assert(area.size() >= cells);
  const bool moments = !moment_x.empty();
  std::fill_n(area.begin(), cells, 0.0);
  scratch.carry.assign(cells, 0.0);
  if (moments) {
    std::fill_n(moment_x.begin(), cells, 0.0);
    std::fill_n(moment_y.begin(), cells, 0.0);
    scratch.carry_x.assign(cells, 0.0);
    scratch.carry_y.assign(cells, 0.0);
  }
  const size_t n = polygon.size();
  if (n < 3) return;

  const double signed_total = signed_area(polygon);
  if (cells == 1) {
    // A polygon inside a single pixel: its own area and centroid, no walk needed.
    area[0] = std::abs(signed_total);
    if (moments && signed_total != 0.0) {
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

  // Orientation: the trapezoid sum is positive for counter-clockwise loops.
  const double s = signed_total >= 0.0 ? 1.0 : -1.0;
  const double fx0 = window.x0;
  const double fy0 = window.y0;

  std::vector<double>& ts = scratch.crossings;
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2 p = polygon[i];
    const glm::dvec2 q = polygon[(i + 1) % n];
    if (p.x == q.x) continue;  // vertical: no x-extent, no area
    const glm::dvec2 d = q - p;

    // Split the edge where it crosses a pixel border, so that every piece lies in one pixel.
    // Crossings of vertical and of horizontal pixel borders each come in increasing t; merge.
    ts.clear();
    ts.push_back(0.0);
    {
      std::vector<double>& ys = scratch.y_crossings;
      ys.clear();
      if (p.y != q.y) {
        if (d.y > 0.0) {
          for (double k = std::floor(p.y) + 1.0; k < q.y; k += 1.0) ys.push_back((k - p.y) / d.y);
        } else {
          for (double k = std::ceil(p.y) - 1.0; k > q.y; k -= 1.0) ys.push_back((k - p.y) / d.y);
        }
      }
      size_t yi = 0;
      auto push_x = [&](double t) {
        while (yi < ys.size() && ys[yi] < t) ts.push_back(ys[yi++]);
        ts.push_back(t);
      };
      if (d.x > 0.0) {
        for (double k = std::floor(p.x) + 1.0; k < q.x; k += 1.0) push_x((k - p.x) / d.x);
      } else {
        for (double k = std::ceil(p.x) - 1.0; k > q.x; k -= 1.0) push_x((k - p.x) / d.x);
      }
      while (yi < ys.size()) ts.push_back(ys[yi++]);
    }
    ts.push_back(1.0);

    glm::dvec2 a = p;
    for (size_t k = 1; k < ts.size(); ++k) {
      const glm::dvec2 b = (k + 1 == ts.size()) ? q : p + d * ts[k];
      if (b.x == a.x) {  // a zero-width piece (a repeated crossing): nothing to add
        a = b;
        continue;
      }
      const glm::dvec2 mid = 0.5 * (a + b);
      const int col = std::clamp(static_cast<int>(std::floor(mid.x - fx0)), 0, w - 1);
      const int row = std::clamp(static_cast<int>(std::floor(mid.y - fy0)), 0, h - 1);
      const double px = fx0 + col, py = fy0 + row;
      // Entering (a) and leaving (b) coordinates relative to the pixel's lower-left corner.
      const double xe = a.x - px, xl = b.x - px;
      const double ye = std::clamp(a.y - py, 0.0, 1.0), yl = std::clamp(b.y - py, 0.0, 1.0);
      const size_t cell = static_cast<size_t>(row) * static_cast<size_t>(w) + static_cast<size_t>(col);
      area[cell] += s * (xe - xl) * (ye + yl) * 0.5;
      scratch.carry[cell] += s * (xe - xl);  // times the pixel height, which is 1
      if (moments) {
        const double xm = 0.5 * (xe + xl), ym = 0.5 * (ye + yl);
        const double dx6 = (xe - xl) / 6.0;  // -(x_l - x_e) / 6, the sign of -s folded in below
        moment_x[cell] += s * dx6 * (xe * ye + 4.0 * xm * ym + xl * yl);
        moment_y[cell] += s * dx6 * 0.5 * (ye * ye + 4.0 * ym * ym + yl * yl);
        scratch.carry_x[cell] += s * 0.5 * (xe * xe - xl * xl);
        scratch.carry_y[cell] += s * 0.5 * (xe - xl);
      }
      a = b;
    }
  }

  // Hand each column's carry down from the top row to the rows below it.
  for (int col = 0; col < w; ++col) {
    double cc = 0.0, cx = 0.0, cy = 0.0;
    for (int row = h - 1; row >= 0; --row) {
      const size_t cell = static_cast<size_t>(row) * static_cast<size_t>(w) + static_cast<size_t>(col);
      area[cell] += cc;
      cc += scratch.carry[cell];
      if (moments) {
        moment_x[cell] += cx;
        moment_y[cell] += cy;
        cx += scratch.carry_x[cell];
        cy += scratch.carry_y[cell];
      }
    }
  }
}

}  // namespace

void scan_convert_area(std::span<const glm::dvec2> polygon, const PixelWindow& window,
                       std::span<double> area, ScanScratch& scratch) {
  walk(polygon, window, area, {}, {}, scratch);
}

void scan_convert_moments(std::span<const glm::dvec2> polygon, const PixelWindow& window,
                          std::span<double> area, std::span<double> moment_x,
                          std::span<double> moment_y, ScanScratch& scratch) {
  walk(polygon, window, area, moment_x, moment_y, scratch);
}

}  // namespace hemibake::solver
