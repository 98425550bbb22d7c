// The tone curve's contract (protocol/tone.h), checked on the curve's defining properties: it is
// the identity up to the knee, leaves it with slope 1 (a finite difference here), climbs without
// ever falling, reaches 1 exactly at the white point, and its stated inverse undoes it. Knees and
// white points are drawn at random (the seed is printed) besides the default's. The automatic
// exposure against log-averages and percentiles known in closed form.
#include "tone_formula.h"
#include "../solver/test_seed.h"

#include "hemibake/protocol/tone.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <utility>
#include <vector>

namespace hemibake::protocol {
namespace {

using V = glm::dvec3;

std::vector<std::pair<double, double>> knees_and_whites(uint64_t seed) {
  std::vector<std::pair<double, double>> out = {{kToneKnee, 1.01}, {kToneKnee, 3.5}, {kToneKnee, 80.0}, {kToneKnee, 1e6}};
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> knee(0.3, 0.95), log_white(std::log(1.02), std::log(1e4));
  for (int i = 0; i < 40; ++i) out.emplace_back(knee(rng), std::exp(log_white(rng)));
  return out;
}

TEST(ToneCurve, ShoulderLeavesTheKneeWithSlopeOneAndReachesOneAtWhite) {
  const uint64_t seed = test::test_seed();
  for (const auto& [knee, white] : knees_and_whites(seed)) {
    const ToneCurve t = shoulder_curve(white, knee);
    SCOPED_TRACE("knee " + std::to_string(knee) + ", white " + std::to_string(white) + ", " + test::seed_note(seed));
    ASSERT_GT(t.scale, 0.0);
    EXPECT_EQ(t.knee, knee);
    EXPECT_EQ(t.white, white);
    for (double m : {0.0, 0.25 * knee, 0.5 * knee, knee}) EXPECT_EQ(t.curve(m), m);
    // Slope 1 on both sides of the knee: the difference quotient over h is 1 - O(h / scale).
    const double h = 1e-7 * std::min(1.0, t.scale);
    EXPECT_NEAR((t.curve(knee + h) - t.curve(knee)) / h, 1.0, 1e-5);
    EXPECT_NEAR((t.curve(knee) - t.curve(knee - h)) / h, 1.0, 1e-5);
    EXPECT_NEAR(t.curve(white), 1.0, 1e-12);
    EXPECT_EQ(t.curve(2.0 * white), 1.0);
    // Strictly rising from the knee to white (geometric steps: the shoulder spans decades), below 1
    // short of white, and the inverse takes each value back.
    double last = t.curve(knee);
    for (double m = knee * 1.01; m < white; m *= 1.01) {
      const double y = t.curve(m);
      ASSERT_GT(y, last) << "at " << m;
      ASSERT_LT(y, 1.0) << "at " << m;
      ASSERT_NEAR(t.invert(y), m, 1e-9 * m + 1e-12 / t.scale) << "at " << m;
      last = y;
    }
  }
}

// Nothing lit reaches 1: the curve is the identity up to 1, as the plain clamp was.
TEST(ToneCurve, WhiteAtOrBelowOneNeedsNoShoulder) {
  for (double white : {0.0, 0.5, 0.99, 1.0}) {
    const ToneCurve t = shoulder_curve(white);
    EXPECT_EQ(t.scale, 0.0) << white;
    for (double m : {0.0, 0.3, 0.7, 0.99}) EXPECT_EQ(t.curve(m), m) << white;
    EXPECT_EQ(t.map(V(0.2, 0.5, 0.9)), V(0.2, 0.5, 0.9)) << white;
  }
  // Just above 1 the shoulder is nearly straight: no jump between the two cases.
  const ToneCurve barely = shoulder_curve(1.0 + 1e-6);
  EXPECT_NEAR(barely.curve(0.9), 0.9, 1e-6);
}

// The colour is scaled as a whole (hue kept) by f(mean) / mean, a channel past 1 is clipped, and
// more of the same light never shows darker in any channel.
TEST(ToneCurve, MapKeepsTheHueAndRisesWithTheLight) {
  const ToneCurve t = shoulder_curve(20.0);
  const V hue(1.0, 0.8, 0.5);
  V last(0.0);
  for (double s = 0.05; s < 40.0; s *= 1.05) {
    const V light = s * hue / ((hue.x + hue.y + hue.z) / 3.0);  // mean s
    const V c = t.map(light);
    for (int k = 0; k < 3; ++k) {
      ASSERT_GE(c[k], 0.0);
      ASSERT_LE(c[k], 1.0);
      ASSERT_GE(c[k], last[k] - 1e-12) << "mean light " << s << ", channel " << k;  // flat above white
    }
    if (c.x < 1.0) {
      EXPECT_NEAR(c.y / c.x, hue.y / hue.x, 1e-12) << "mean light " << s;
    }
    if (s <= kToneKnee) {
      EXPECT_EQ(c, light);
    }
    last = c;
  }
  // The clamp curve is the plain clip of each channel.
  const ToneCurve clamp = tone_curve(Tone::kClamp, 20.0);
  EXPECT_EQ(clamp.map(V(0.5, 1.7, 3.0)), V(0.5, 1.0, 1.0));
}

// The README's formula (tests/protocol/tone_formula.h, written from the text) and the code agree.
TEST(ToneCurve, DocumentedFormulaIsWhatTheCodeComputes) {
  const uint64_t seed = test::test_seed();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> channel(0.0, 1.0), log_mean(std::log(0.01), std::log(100.0));
  for (const auto& [knee, white] : knees_and_whites(seed)) {
    const ToneCurve t = shoulder_curve(white, knee);
    const test::RecordedTone r{true, t.knee, t.white, t.scale};
    for (int i = 0; i < 50; ++i) {
      V light(channel(rng), channel(rng), channel(rng));
      light *= std::exp(log_mean(rng)) / std::max(1e-9, (light.x + light.y + light.z) / 3.0);
      const V c = t.map(light), d = test::documented_color(r, light);
      for (int k = 0; k < 3; ++k) ASSERT_NEAR(c[k], d[k], 1e-12) << test::seed_note(seed);
    }
  }
}

// The automatic exposure (protocol::key_exposure) on lists of surfaces whose log-average and
// percentiles are known in closed form.

// Light the same everywhere: its log-average and every percentile are that light, so the key sets
// the exposure whatever the areas, and unlit or empty entries change nothing.
TEST(KeyExposure, UniformLightMapsToTheKey) {
  const uint64_t seed = test::test_seed();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> log_light(std::log(1e-3), std::log(1e4)), area(0.01, 10.0);
  for (int i = 0; i < 20; ++i) {
    const double light = std::exp(log_light(rng));
    std::vector<LitArea> s;
    for (int k = 0; k < 50; ++k) s.push_back({light, area(rng)});
    s.push_back({0.0, area(rng)});
    s.push_back({light, 0.0});
    std::shuffle(s.begin(), s.end(), rng);
    EXPECT_NEAR(key_exposure(s), kExposureKey / light, 1e-12 * kExposureKey / light) << test::seed_note(seed);
  }
}

// Two lights a hundred times apart on equal areas: the log-average is their geometric mean, a
// tenth of the brighter, and the key alone would show the dim half at a tenth of the key; the
// darker quarter lies in the dim half, so the exposure shows it at kDarkQuarterLevel instead.
TEST(KeyExposure, DimHalfAHundredTimesBelowIsRaisedToTheDarkQuarterLevel) {
  const double bright = 2000.0, dim = bright / 100.0;
  const std::vector<LitArea> s = {{bright, 5.0}, {dim, 3.0}, {dim, 2.0}};
  const double key_alone = kExposureKey / std::sqrt(bright * dim);
  EXPECT_LT(key_alone * dim, kDarkQuarterLevel);
  EXPECT_NEAR(key_exposure(s), kDarkQuarterLevel / dim, 1e-12 / dim);
  // A dim tenth of the area is not a quarter: the key decides, on the log-average
  // bright^0.9 dim^0.1.
  const std::vector<LitArea> t = {{bright, 9.0}, {dim, 1.0}};
  const double log_average = std::pow(bright, 0.9) * std::pow(dim, 0.1);
  EXPECT_NEAR(key_exposure(t), kExposureKey / log_average, 1e-12 * kExposureKey / log_average);
}

// Faces lit more than 2^10 times below the brightest twentieth (an unseen underside) are left out:
// half the area at 1e-5 of the rest leaves the exposure as if it were not there, and nothing lit at
// all gives 1.
TEST(KeyExposure, FacesFarBelowTheBrightestTwentiethAreLeftOut) {
  const double light = 700.0;
  const std::vector<LitArea> s = {{light, 10.0}, {1e-5 * light, 10.0}};
  EXPECT_NEAR(key_exposure(s), kExposureKey / light, 1e-12 * kExposureKey / light);
  EXPECT_EQ(key_exposure(std::vector<LitArea>{{0.0, 3.0}}), 1.0);
  EXPECT_EQ(key_exposure(std::vector<LitArea>{}), 1.0);
}

TEST(ToneNames, AreShoulderAndClamp) {
  EXPECT_STREQ(to_string(Tone::kShoulder), "shoulder");
  EXPECT_STREQ(to_string(Tone::kClamp), "clamp");
  EXPECT_EQ(tone_from("clamp"), Tone::kClamp);
  EXPECT_EQ(tone_from("shoulder"), Tone::kShoulder);
  EXPECT_FALSE(tone_from("filmic").has_value());
}

}  // namespace
}  // namespace hemibake::protocol
