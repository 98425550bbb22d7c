#include "hemibake/protocol/tone.h"

#include <glm/common.hpp>

#include <algorithm>
#include <cmath>

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

}  // namespace hemibake::protocol
