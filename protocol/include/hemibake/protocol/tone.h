// How exposed light becomes COLOR_0, whose values must lie in [0, 1]: linear up to a knee, then a
// shoulder that rolls the highlights off to 1 at a white point chosen from the scene, so that a pool
// of light far above the midtones keeps its shading instead of clipping to one flat colour.
#pragma once

#include <glm/vec3.hpp>

#include <cstdint>
#include <optional>
#include <string_view>

namespace hemibake::protocol {

/// What happens to light above the knee (the job parameter `tone`).
enum class Tone : uint8_t {
  kShoulder,  ///< "shoulder": the roll-off of ToneCurve (the default)
  kClamp,     ///< "clamp": linear, each channel clipped at 1
};

/// "shoulder" or "clamp".
const char* to_string(Tone tone);

/// The tone of that name, or nullopt.
std::optional<Tone> tone_from(std::string_view name);

/// Where the shoulder starts, in exposed light. The automatic exposure puts the 95th percentile of
/// the surfaces' light at 0.9, so most of a room (86 % of the Cornell box's area) lies below it and
/// keeps COLOR_0 = exposure x light. A higher knee keeps more of it but leaves the shoulder less
/// room: at 0.8 two surfaces 30 % apart near the top of the Cornell box's range (white 3.5) differ
/// by about 2 steps of 8-bit sRGB on a white wall, at 0.7 by about 3.
constexpr double kToneKnee = 0.7;

/// The curve f that takes the mean m of the three channels of exposed light L to the mean shown:
///
///   f(m) = m                                       for m <= knee
///        = knee + scale * ln(1 + (m - knee) / scale) for knee < m < white
///        = 1                                       for m >= white
///
/// and the colour shown is L * f(m) / m, each channel clipped to [0, 1] (hue kept until a channel
/// reaches 1). The shoulder's slope is 1 at the knee (no kink where the midtones end) and falls as
/// scale / (scale + m - knee): a logarithm well above the knee, so each doubling of the light gets
/// between scale x ln 2 and twice that of the output however far up it lies (a rational curve such
/// as Reinhard's gives the far highlights less and less, and a pool 50 times the midtones flattens
/// again). `scale` is the one number that makes f(white) = 1. With white <= 1 nothing lit needs a
/// shoulder, and the curve is the identity up to 1 (knee = white = 1, scale = 0).
struct ToneCurve {
  Tone tone = Tone::kShoulder;
  double knee = 1.0;   ///< f is the identity below it
  double white = 1.0;  ///< f reaches 1 here
  double scale = 0.0;  ///< the shoulder's width (0: no shoulder)

  /// f(m) for m >= 0 (kClamp: min(m, 1)).
  double curve(double m) const;

  /// The inverse of f on [0, 1): the m with f(m) = y (kClamp: y).
  double invert(double y) const;

  /// The colour shown for exposed light `light` (every channel >= 0): kShoulder: light * f(m) / m
  /// with m the mean of its channels; kClamp: the light itself; then each channel clipped to [0, 1].
  glm::dvec3 map(const glm::dvec3& light) const;
};

/// The shoulder from `knee` (in (0, 1)) that reaches 1 at `white`, the brightest exposed light
/// (mean of the channels) on a surface that does not emit; white <= 1 gives the identity up to 1.
ToneCurve shoulder_curve(double white, double knee = kToneKnee);

/// The curve of `tone`: shoulder_curve(white), or the plain clamp (knee = white = 1).
ToneCurve tone_curve(Tone tone, double white);

}  // namespace hemibake::protocol
