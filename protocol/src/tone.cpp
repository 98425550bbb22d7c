#include "hemibake/protocol/tone.h"

#include <glm/common.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

namespace hemibake::protocol {

const char* to_string(Tone tone) { return tone == Tone::kClamp ? "clamp" : "shoulder"; }

std::optional<Tone> tone_from(std::string_view name) {
  for (Tone t : {Tone::kShoulder, Tone::kClamp})
    if (name == to_string(t)) return t;
  return std::nullopt;
}

double ToneCurve::curve(double m) const {
  if (tone == Tone::kClamp || scale <= 0.0) return std::min(m, 1.0);
  if (m <= knee) return m;
  if (m >= white) return 1.0;
  return std::min(1.0, knee + scale * std::log1p((m - knee) / scale));
}

double ToneCurve::invert(double y) const {
  if (tone == Tone::kClamp || scale <= 0.0 || y <= knee) return y;
  return knee + scale * std::expm1((y - knee) / scale);
}

glm::dvec3 ToneCurve::map(const glm::dvec3& light) const {
  glm::dvec3 out = light;
  if (tone == Tone::kShoulder) {
    const double m = (light.x + light.y + light.z) / 3.0;
    if (m > knee) out *= curve(m) / m;
  }
  return glm::clamp(out, 0.0, 1.0);
}

ToneCurve shoulder_curve(double white, double knee) {
  ToneCurve c;
  // The shoulder spends the headroom h = 1 - knee over the span d = white - knee:
  // g(scale) = scale * ln(1 + d / scale) = h. g rises from 0 to d as scale grows, so a root exists
  // when d > h (white > 1); as white comes down to 1 the root runs off to infinity and the shoulder
  // straightens into the identity, which is what white <= 1 gets.
  const double h = 1.0 - knee, d = white - knee;
  if (!(knee > 0.0 && knee < 1.0) || !(d > h * (1.0 + 1e-9)) || !std::isfinite(white)) return c;
  auto g = [&](double s) { return s * std::log1p(d / s); };
  double lo = 1e-300, hi = h;
  while (g(hi) < h) hi *= 2.0;  // g(h) > h * ln 2; the doubling ends because g -> d > h
  // Bisection on log(scale): g is monotonic, and 200 halvings of a span of at most 2^1100 leave it
  // at the last bit.
  for (int i = 0; i < 200 && hi > lo * (1.0 + 1e-15); ++i) {
    const double mid = std::sqrt(lo * hi);
    (g(mid) < h ? lo : hi) = mid;
  }
  c.knee = knee;
  c.white = white;
  c.scale = hi;
  return c;
}

ToneCurve tone_curve(Tone tone, double white) {
  if (tone == Tone::kClamp) {
    ToneCurve c;
    c.tone = Tone::kClamp;
    return c;
  }
  return shoulder_curve(white);
}

double key_exposure(std::span<const LitArea> surfaces) {
  std::vector<LitArea> lit;
  lit.reserve(surfaces.size());
  for (const LitArea& s : surfaces)
    if (s.light > 0.0 && s.area > 0.0) lit.push_back(s);
  std::sort(lit.begin(), lit.end(), [](const LitArea& a, const LitArea& b) { return a.light < b.light; });
  // The light below which the fraction q of the area lies.
  auto percentile = [&lit](double q) {
    double total = 0.0, acc = 0.0;
    for (const LitArea& s : lit) total += s.area;
    for (const LitArea& s : lit)
      if ((acc += s.area) >= q * total) return s.light;
    return lit.back().light;
  };
  if (lit.empty()) return 1.0;
  // Surfaces lit more than 2^10 times less than the brightest twentieth show black at any exposure
  // that keeps those off the shoulder's top, and they are mostly faces no one sees: the underside of
  // a ground plane, which a little stray light reaches, is half the area of an outdoor scene, and
  // counted it pulled the log-average down by 5 stops. (A small epsilon added to the light, as
  // Reinhard adds to luminance, still counts them at its logarithm.)
  const double floor = std::ldexp(percentile(0.95), -10);
  std::erase_if(lit, [floor](const LitArea& s) { return s.light < floor; });
  double area = 0.0, log_sum = 0.0;
  for (const LitArea& s : lit) {
    area += s.area;
    log_sum += s.area * std::log(s.light);
  }
  const double log_average = std::exp(log_sum / area);
  return std::max(kExposureKey / log_average, kDarkQuarterLevel / percentile(0.25));
}

}  // namespace hemibake::protocol
