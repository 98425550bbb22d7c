// COLOR_0 as README ("GLB out") and asset.extras.hemibake.colors state it, written out here from the
// documented formula and the numbers the file records, without hemibake's own curve code: a file's
// COLOR_0 must follow from its _RADIOSITY, its base colours and its record alone.
#pragma once

#include <nlohmann/json.hpp>

#include <glm/vec3.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace hemibake::test {

/// The curve recorded in asset.extras.hemibake.tone.
struct RecordedTone {
  bool shoulder = false;  ///< curve "shoulder"; else "clamp"
  double knee = 1.0, white = 1.0, scale = 0.0;
};

inline RecordedTone recorded_tone(const nlohmann::json& doc) {
  const nlohmann::json& t = doc["asset"]["extras"]["hemibake"]["tone"];
  RecordedTone r;
  r.shoulder = t.at("curve").get<std::string>() == "shoulder";
  if (r.shoulder) {
    r.knee = t.at("knee").get<double>();
    r.white = t.at("white").get<double>();
    r.scale = t.at("scale").get<double>();
  }
  return r;
}

/// f(m): m up to the knee, knee + scale ln(1 + (m - knee) / scale) up to white, 1 above; scale 0:
/// min(m, 1).
inline double documented_curve(const RecordedTone& t, double m) {
  if (t.scale <= 0.0) return std::min(m, 1.0);
  if (m <= t.knee) return m;
  if (m >= t.white) return 1.0;
  return t.knee + t.scale * std::log(1.0 + (m - t.knee) / t.scale);
}

/// COLOR_0 for exposed light L = exposure x radiosity / base colour: shoulder: L f(m) / m with m the
/// mean of L's channels, clamp: L; each channel then clipped to [0, 1].
inline glm::dvec3 documented_color(const RecordedTone& t, const glm::dvec3& light) {
  glm::dvec3 c = light;
  const double m = (light.x + light.y + light.z) / 3.0;
  if (t.shoulder && m > 0.0) c *= documented_curve(t, m) / m;
  for (int k = 0; k < 3; ++k) c[k] = std::clamp(c[k], 0.0, 1.0);
  return c;
}

/// The exposed light back from COLOR_0 where no channel is 1: y = mean(COLOR_0), m = y up to the
/// knee, else knee + scale (e^((y - knee) / scale) - 1); L = COLOR_0 m / y.
inline glm::dvec3 documented_light(const RecordedTone& t, const glm::dvec3& color) {
  const double y = (color.x + color.y + color.z) / 3.0;
  if (!t.shoulder || t.scale <= 0.0 || y <= t.knee) return color;
  const double m = t.knee + t.scale * (std::exp((y - t.knee) / t.scale) - 1.0);
  return color * (m / y);
}

/// 8-bit sRGB as three.js writes its output (linear to sRGB, then rounded), for "visibly different".
inline int srgb8(double linear) {
  const double v = std::clamp(linear, 0.0, 1.0);
  const double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
  return static_cast<int>(std::lround(s * 255.0));
}

}  // namespace hemibake::test
