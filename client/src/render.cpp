#include "hemibake/client/render.h"

#include <glm/geometric.hpp>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>

namespace hemibake::client {
namespace {

struct ScreenVertex {
  double x, y, inv_z;
  glm::dvec3 colour;
};

void put_u32(std::vector<uint8_t>& out, uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(static_cast<uint8_t>(v >> s));
}

}  // namespace

std::vector<uint8_t> render(const solver::Mesh& mesh, const Camera& cam, const RenderOptions& opt) {
  const uint32_t w = opt.width, h = opt.height;
  const glm::dvec3 fwd = glm::normalize(cam.target - cam.position);
  const glm::dvec3 right = glm::normalize(glm::cross(fwd, cam.up));
  const glm::dvec3 up = glm::cross(right, fwd);
  const double focal = 0.5 * h / std::tan(0.5 * cam.fov_y_degrees * 3.14159265358979 / 180.0);
  const double near = 1e-3;

  std::vector<glm::dvec3> hdr(static_cast<size_t>(w) * h, glm::dvec3(0.0));
  std::vector<double> zbuf(static_cast<size_t>(w) * h, 0.0);  // stores 1/z, larger is nearer
  std::vector<uint8_t> edge(static_cast<size_t>(w) * h, 0);

  auto to_screen = [&](const glm::dvec3& p, const glm::dvec3& c, ScreenVertex& out) {
    const glm::dvec3 d = p - cam.position;
    const double z = glm::dot(d, fwd);
    if (z < near) return false;
    out.x = 0.5 * w + focal * glm::dot(d, right) / z;
    out.y = 0.5 * h - focal * glm::dot(d, up) / z;
    out.inv_z = 1.0 / z;
    out.colour = c;
    return true;
  };

  auto draw_triangle = [&](const ScreenVertex& a, const ScreenVertex& b, const ScreenVertex& c) {
    const double area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    // Elements are counter-clockwise from their front; screen y points down, so a front face has
    // negative area here. Back faces are not drawn (a double-sided surface is two elements).
    if (area > -1e-12) return;
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({a.x, b.x, c.x}))));
    const int x1 = std::min(static_cast<int>(w) - 1, static_cast<int>(std::ceil(std::max({a.x, b.x, c.x}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({a.y, b.y, c.y}))));
    const int y1 = std::min(static_cast<int>(h) - 1, static_cast<int>(std::ceil(std::max({a.y, b.y, c.y}))));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const double px = x + 0.5, py = y + 0.5;
        const double w0 = ((b.x - px) * (c.y - py) - (b.y - py) * (c.x - px)) / area;
        const double w1 = ((c.x - px) * (a.y - py) - (c.y - py) * (a.x - px)) / area;
        const double w2 = 1.0 - w0 - w1;
        if (w0 < -1e-9 || w1 < -1e-9 || w2 < -1e-9) continue;
        const double iz = w0 * a.inv_z + w1 * b.inv_z + w2 * c.inv_z;
        const size_t i = static_cast<size_t>(y) * w + x;
        if (iz <= zbuf[i]) continue;
        zbuf[i] = iz;
        // Perspective-correct interpolation.
        hdr[i] = (w0 * a.inv_z * a.colour + w1 * b.inv_z * b.colour + w2 * c.inv_z * c.colour) / iz;
        edge[i] = 0;
        if (opt.wireframe) {
          // Distance to the element's outer edges is not known per triangle here; the fan's outer
          // edge is b-c, so mark pixels close to it.
          const double len = std::hypot(c.x - b.x, c.y - b.y);
          if (len > 0 && std::abs(w0 * area) / len < 0.6) edge[i] = 1;
        }
      }
    }
  };

  for (const auto& el : mesh.elements) {
    if (el.buried) continue;  // pressed against a face that is seen: a depth tie along its edge
    // Fan from the element's centre over its boundary loop (which includes hanging vertices); the
    // centre is the mean of the loop's own vertices, as the baked file's (Mesh::interpolated).
    glm::dvec3 centre(0.0), centre_colour(0.0);
    const uint32_t nb = el.boundary_end - el.boundary_begin;
    uint32_t own = 0;
    for (uint32_t i = el.boundary_begin; i < el.boundary_end; ++i) {
      const uint32_t v = mesh.boundary[i];
      if (v < mesh.interpolated.size() && mesh.interpolated[v]) continue;
      centre += mesh.positions[v];
      centre_colour += mesh.radiosity[v];
      ++own;
    }
    centre /= own;
    centre_colour /= own;
    ScreenVertex sc;
    if (!to_screen(centre, opt.gouraud ? centre_colour : el.radiosity, sc)) continue;
    for (uint32_t i = 0; i < nb; ++i) {
      const uint32_t va = mesh.boundary[el.boundary_begin + i];
      const uint32_t vb = mesh.boundary[el.boundary_begin + (i + 1) % nb];
      ScreenVertex sa, sb;
      if (!to_screen(mesh.positions[va], opt.gouraud ? mesh.radiosity[va] : el.radiosity, sa)) continue;
      if (!to_screen(mesh.positions[vb], opt.gouraud ? mesh.radiosity[vb] : el.radiosity, sb)) continue;
      draw_triangle(sc, sa, sb);
    }
  }

  std::vector<double> lum;
  for (size_t i = 0; i < hdr.size(); ++i)
    if (zbuf[i] > 0.0) lum.push_back((hdr[i].x + hdr[i].y + hdr[i].z) / 3.0);
  auto percentile = [&](size_t per_cent) {
    const size_t k = std::min(lum.size() - 1, lum.size() * per_cent / 100);
    std::nth_element(lum.begin(), lum.begin() + k, lum.end());
    return lum[k];
  };
  double exposure = opt.exposure;
  if (exposure <= 0.0) {
    const double p95 = lum.empty() ? 0.0 : percentile(95);
    exposure = p95 > 0.0 ? 0.8 / p95 : 1.0;
  }
  // The highlights roll off as COLOR_0's do, here to reach 1 at the 99th percentile of what is in
  // view: the render does not know which surfaces emit, and a lamp in view, usually smaller than
  // that, clips.
  const double white = opt.white > 0.0 ? opt.white : lum.empty() ? 1.0 : exposure * percentile(99);
  const protocol::ToneCurve tone = protocol::tone_curve(opt.tone, white);
  std::vector<uint8_t> rgb(static_cast<size_t>(w) * h * 3);
  for (size_t i = 0; i < hdr.size(); ++i) {
    const glm::dvec3 shown = tone.map(hdr[i] * exposure);
    for (int c = 0; c < 3; ++c) {
      double v = shown[c];
      v = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;  // sRGB
      rgb[i * 3 + c] = edge[i] ? 0 : static_cast<uint8_t>(std::lround(v * 255.0));
    }
  }
  return rgb;
}

bool write_png(const std::string& path, const std::vector<uint8_t>& rgb, uint32_t w, uint32_t h) {
  // Scanlines with the Sub filter (each byte minus the one a pixel to its left), deflated by zlib.
  std::vector<uint8_t> raw;
  raw.reserve((static_cast<size_t>(w) * 3 + 1) * h);
  for (uint32_t y = 0; y < h; ++y) {
    raw.push_back(1);
    const uint8_t* row = rgb.data() + static_cast<size_t>(y) * w * 3;
    for (uint32_t x = 0; x < w * 3; ++x) raw.push_back(static_cast<uint8_t>(row[x] - (x >= 3 ? row[x - 3] : 0)));
  }
  uLongf zlen = compressBound(static_cast<uLong>(raw.size()));
  std::vector<uint8_t> z(zlen);
  if (compress2(z.data(), &zlen, raw.data(), static_cast<uLong>(raw.size()), 9) != Z_OK) return false;
  z.resize(zlen);

  std::vector<uint8_t> png{0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  auto chunk = [&](const char* type, const std::vector<uint8_t>& data) {
    put_u32(png, static_cast<uint32_t>(data.size()));
    const size_t start = png.size();
    png.insert(png.end(), type, type + 4);
    png.insert(png.end(), data.begin(), data.end());
    put_u32(png, static_cast<uint32_t>(::crc32(0L, png.data() + start, static_cast<uInt>(png.size() - start))));
  };
  std::vector<uint8_t> ihdr;
  put_u32(ihdr, w);
  put_u32(ihdr, h);
  ihdr.insert(ihdr.end(), {8, 2, 0, 0, 0});
  chunk("IHDR", ihdr);
  chunk("IDAT", z);
  chunk("IEND", {});
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return false;
  const bool ok = std::fwrite(png.data(), 1, png.size(), f) == png.size();
  return std::fclose(f) == 0 && ok;
}

}  // namespace hemibake::client
