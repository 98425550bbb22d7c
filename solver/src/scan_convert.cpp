// Solid-area scan conversion, after Figure 4 of "Anti-aliased hemicubes for performance improvement
// in radiosity solutions": the public entry points, writing arrays. The method is in scan_walk.h,
// which the hemicube calls directly.
#include "hemibake/solver/scan_convert.h"

#include "scan_walk.h"

#include <cassert>

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

void scan_convert_area(std::span<const glm::dvec2> polygon, const PixelWindow& window,
                       std::span<double> area, ScanScratch& scratch) {
  assert(area.size() >= static_cast<size_t>(window.width) * static_cast<size_t>(window.height));
  detail::scan_walk<false>(polygon, window, scratch, [&](int col, int row, double a, double, double) {
    area[static_cast<size_t>(row) * static_cast<size_t>(window.width) + static_cast<size_t>(col)] = a;
  });
}

void scan_convert_moments(std::span<const glm::dvec2> polygon, const PixelWindow& window,
                          std::span<double> area, std::span<double> moment_x,
                          std::span<double> moment_y, ScanScratch& scratch) {
  assert(area.size() >= static_cast<size_t>(window.width) * static_cast<size_t>(window.height));
  detail::scan_walk<true>(polygon, window, scratch, [&](int col, int row, double a, double mx, double my) {
    const size_t cell = static_cast<size_t>(row) * static_cast<size_t>(window.width) + static_cast<size_t>(col);
    area[cell] = a;
    moment_x[cell] = mx;
    moment_y[cell] = my;
  });
}

}  // namespace hemibake::solver
