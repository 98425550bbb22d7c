// Solid-area scan conversion: the fractional pixel coverage of a polygon (the paper's Figure 4).
#pragma once

#include <glm/vec2.hpp>

#include <span>
#include <vector>

namespace hemibake::solver {

/// A window of pixels with unit size: pixel (col, row) spans [x0 + col, x0 + col + 1] x
/// [y0 + row, y0 + row + 1]. Row 0 is the bottom row.
struct PixelWindow {
  int x0 = 0;      ///< x of the window's left edge, in pixels
  int y0 = 0;      ///< y of the window's bottom edge, in pixels
  int width = 0;   ///< columns
  int height = 0;  ///< rows
};

/// Scratch space for scan_convert_area and scan_convert_moments, reusable across calls so that hot
/// loops allocate nothing.
struct ScanScratch {
  /// Per pixel: the edge pieces' own sums and the paper's column carry C (areas, then moments);
  /// all zero between calls.
  std::vector<double> cells;
  std::vector<double> carry;        ///< the column carries of one sweep
  std::vector<glm::dvec2> local;    ///< the polygon in window coordinates
};

/// Writes into `area` (width * height values, row-major from the bottom row) the area of every
/// pixel of `window` that lies inside `polygon`, in units of pixel area (0 to 1, exact to rounding).
/// The polygon is a closed loop of at least three points in either orientation, convex or not,
/// simple or not (areas of a self-overlapping loop add with the winding number's sign); it must lie
/// inside the window. `area` must hold window.width * window.height values; they are overwritten.
/// Implements the signed-edge trapezoids plus column carry of Figure 4.
void scan_convert_area(std::span<const glm::dvec2> polygon, const PixelWindow& window,
                       std::span<double> area, ScanScratch& scratch);

/// As scan_convert_area, and also the first moments of the covered part of each pixel about the
/// pixel's lower-left corner (integral of x dA into `moment_x`, of y dA into `moment_y`), so that
/// the covered part's centroid is (moment_x / area, moment_y / area). Both spans are sized like
/// `area`. The moments use the same edge walk and column carry as the areas.
void scan_convert_moments(std::span<const glm::dvec2> polygon, const PixelWindow& window,
                          std::span<double> area, std::span<double> moment_x,
                          std::span<double> moment_y, ScanScratch& scratch);

/// The signed area of a closed polygon (positive for counter-clockwise loops).
double signed_area(std::span<const glm::dvec2> polygon);

}  // namespace hemibake::solver
