// A small software renderer for looking at radiosity meshes: perspective, z-buffer, Gouraud or
// flat shading, optional wireframe.
#pragma once

#include "hemibake/protocol/tone.h"
#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace hemibake::client {

struct Camera {
  glm::dvec3 position{0.0};
  glm::dvec3 target{0.0, 0.0, 1.0};
  glm::dvec3 up{0.0, 1.0, 0.0};
  double fov_y_degrees = 40.0;
};

struct RenderOptions {
  uint32_t width = 512;
  uint32_t height = 512;
  bool gouraud = true;    ///< vertex radiosity interpolated; false: flat element radiosity
  bool wireframe = false; ///< element edges drawn in black
  double exposure = 0.0;  ///< radiosity to [0, 1] scale below the knee; 0 picks one from the image
  protocol::Tone tone = protocol::Tone::kShoulder;  ///< highlights as COLOR_0's (protocol/tone.h)
  double white = 0.0;     ///< exposed radiosity (mean of the channels) shown as 1; 0 picks it from
                          ///< the image
};

/// 8-bit sRGB pixels, row-major from the top row.
std::vector<uint8_t> render(const solver::Mesh& mesh, const Camera& camera, const RenderOptions& options);

/// Writes RGB pixels as a PNG file (uncompressed deflate blocks). Returns false on I/O failure.
bool write_png(const std::string& path, const std::vector<uint8_t>& rgb, uint32_t width, uint32_t height);

}  // namespace hemibake::client
