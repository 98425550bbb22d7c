// How exposed light becomes COLOR_0, whose values must lie in [0, 1]: linear up to a knee, then a
// shoulder that rolls the highlights off to 1 at a white point chosen from the scene, so that a pool
// of light far above the midtones keeps its shading instead of clipping to one flat colour; and the
// exposure chosen from the scene (Reinhard's key on the log-average, with a floor for the darker
// quarter), which that shoulder lets rise above what the brightest surfaces alone would allow.
#pragma once

#include <glm/vec3.hpp>

#include <cstdint>
#include <optional>
#include <span>
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

/// Where the shoulder starts, in exposed light. The automatic exposure puts the log-average of the
/// surfaces' light at kExposureKey, so most of an evenly lit room (79 % of the Cornell box's area)
/// lies below it and keeps COLOR_0 = exposure x light. A higher knee keeps more of it but leaves the
/// shoulder less room: at 0.8 two surfaces 30 % apart near the top of the Cornell box's range (white
/// 4.1) differ by about 2 steps of 8-bit sRGB on a white wall, at 0.7 by about 3.
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

/// Where the automatic exposure puts the log-average (geometric mean, by area) of the light on the
/// lit surfaces: Reinhard's photographic key (Reinhard et al. 2002, "Photographic tone reproduction
/// for digital images", equations 1-2) on light rather than on luminance. His 0.18 is a grey card's
/// luminance; COLOR_0 multiplies a base colour, and with the base colours of the test rooms (their
/// geometric mean over the lit area 0.4 to 0.8) a light key of 0.4 shows the log-average surface at
/// 0.16 to 0.32 of white. Lower keys (0.18 and 0.25, tried on the Blender files) showed white rooms
/// mid-grey; 0.5 kept the Blender kitchen as hot as the old rule (the 95th percentile of the light
/// at 0.9) did.
constexpr double kExposureKey = 0.4;

/// The least COLOR_0 the automatic exposure gives the darker quarter (by area) of the lit surfaces,
/// when the key alone would leave it below: a room lit through a window beside a sunlit outside lies
/// 6 to 7 stops below it, and the log-average, halfway between in stops, showed most of the room
/// below 0.05, nearly black (a white wall at 0.1 shows as sRGB 89 of 255). The shoulder keeps in
/// order what this pushes above the knee.
constexpr double kDarkQuarterLevel = 0.1;

/// A surface's light (the mean of the channels of radiosity / base colour) and its area.
struct LitArea {
  double light = 0.0;
  double area = 0.0;
};

/// The automatic exposure: the larger of kExposureKey / (log-average of the light) and
/// kDarkQuarterLevel / (25th percentile of the light), both by area, over the surfaces lit to at
/// least 2^-10 of their 95th percentile; 1 when none is lit. Uniform light L gives kExposureKey / L.
/// `surfaces` may hold entries with zero light or area (ignored) in any order.
double key_exposure(std::span<const LitArea> surfaces);

}  // namespace hemibake::protocol
