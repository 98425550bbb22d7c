// Job parameters over the wire: every name, its range checks, and the cache-key text.
#include "hemibake/protocol/job.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace hemibake::protocol {
namespace {

TEST(JobParams, EveryNameIsAppliedAndRoundTrips) {
  JobSpec spec;
  const std::string err = apply_params({{"method", "classical"}, {"resolution", "64"}, {"feps", "0.002"}, {"aeps", "0.0005"},
                                        {"beps", "0.1"}, {"convergence", "0.01"}, {"max_shots", "500"},
                                        {"max_elements", "9000"}, {"threads", "3"}, {"reuse", "false"}, {"cluster_size", "0.3"}, {"shot_cache_mb", "64"}, {"rays", "16"},
                                        {"samples", "64"}, {"draco", "no"}, {"position_bits", "16"},
                                        {"texcoord_bits", "10"}, {"draco_speed", "3"}, {"exposure", "2.5"},
                                        {"tone", "clamp"}},
                                       spec);
  ASSERT_EQ(err, "");
  EXPECT_EQ(spec.method, Method::kClassical);
  EXPECT_EQ(solver_params(spec).method, solver::Method::kClassical);
  EXPECT_EQ(spec.params.resolution, 64u);
  EXPECT_EQ(spec.params.feps, 0.002);
  EXPECT_EQ(spec.params.aeps, 0.0005);
  EXPECT_EQ(spec.params.beps, 0.1);
  EXPECT_EQ(spec.params.convergence, 0.01);
  EXPECT_EQ(spec.params.max_shots, 500u);
  EXPECT_EQ(spec.params.max_elements, 9000u);
  EXPECT_EQ(spec.params.threads, 3u);
  EXPECT_FALSE(spec.params.reuse_visibility);
  EXPECT_EQ(spec.params.cluster_size, 0.3);
  EXPECT_EQ(spec.params.shot_cache_mb, 64u);
  EXPECT_EQ(spec.rays, 16u);
  EXPECT_EQ(spec.samples, 64u);
  EXPECT_FALSE(spec.write.draco);
  EXPECT_EQ(spec.write.position_bits, 16);
  EXPECT_EQ(spec.write.texcoord_bits, 10);
  EXPECT_EQ(spec.write.encode_speed, 3);
  EXPECT_EQ(spec.write.exposure, 2.5);
  EXPECT_EQ(spec.write.tone, Tone::kClamp);
  // What params_json writes, parse_params_json reads back to the same text.
  JobSpec again;
  ASSERT_EQ(parse_params_json(params_json(spec), again), "");
  EXPECT_EQ(params_json(again), params_json(spec));
}

TEST(JobParams, BaselineMethodsAreRecordedAndDistinct) {
  JobSpec aa, hr, reference;
  ASSERT_EQ(apply_params({{"method", "aa"}}, aa), "");
  ASSERT_EQ(apply_params({{"method", "hr"}}, hr), "");
  ASSERT_EQ(apply_params({{"method", "reference"}}, reference), "");
  EXPECT_EQ(aa.method, Method::kAntiAliased);
  EXPECT_EQ(hr.method, Method::kHierarchical);
  EXPECT_EQ(reference.method, Method::kReference);
  // A reference bakes the aa mesh first.
  EXPECT_EQ(solver_params(reference).method, solver::Method::kAntiAliased);
  // Different methods are different cache keys; a round trip keeps the method.
  EXPECT_NE(params_json(aa), params_json(hr));
  EXPECT_NE(params_json(hr), params_json(reference));
  JobSpec back;
  ASSERT_EQ(parse_params_json(params_json(hr), back), "");
  EXPECT_EQ(back.method, Method::kHierarchical);
  ASSERT_EQ(apply_params({{"method", "classical"}}, back), "");
  EXPECT_EQ(back.method, Method::kClassical);
}

TEST(JobParams, BadValuesAreRefusedByName) {
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"method", "ray"},      {"resolution", "7"},    {"resolution", "abc"}, {"feps", "nan"},
      {"max_shots", "-1"},    {"threads", "1.5"},     {"reuse", "maybe"},    {"rays", "0"},
      {"samples", "0"},       {"samples", "1e9"},     {"position_bits", "31"}, {"exposure", "-1"},
      {"convergence", "2"},   {"cluster_size", "-1"}, {"tone", "filmic"}, {"nonsense", "1"}};
  for (const auto& [key, value] : bad) {
    JobSpec spec;
    const std::string err = apply_params({{key, value}}, spec);
    EXPECT_NE(err, "") << key << "=" << value;
    EXPECT_NE(err.find(key == "resolution" && value == "7" ? "resolution" : key), std::string::npos) << err;
  }
  JobSpec spec;
  EXPECT_NE(parse_params_json("[1,2]", spec), "");
  EXPECT_NE(parse_params_json("{\"feps\":[1]}", spec).find("feps"), std::string::npos);
}

}  // namespace
}  // namespace hemibake::protocol

namespace hemibake::protocol {
namespace {

// A value of `p` other than the default's, inside its range.
std::string other_value(const ParamInfo& p, const JobSpec& defaults) {
  const double v = p.get(defaults);
  switch (p.kind) {
    case ParamInfo::Kind::kMethod: return v == 0.0 ? "classical" : "aa";
    case ParamInfo::Kind::kQuality: return v == 2.0 ? "draft" : "high";
    case ParamInfo::Kind::kTone: return v == 0.0 ? "clamp" : "shoulder";
    case ParamInfo::Kind::kFlag: return v != 0.0 ? "false" : "true";
    case ParamInfo::Kind::kWhole: return std::to_string(static_cast<uint64_t>(v == p.max ? v - 2 : v + 2));
    case ParamInfo::Kind::kNumber: return std::to_string(v == 0.0 ? 0.25 : v * 0.5);
    case ParamInfo::Kind::kColour: return v == 0.0 ? "0.5,0.25,1" : "0";
  }
  return {};
}

// The cache key is params_json: a job that asks for anything else must not get another's result.
TEST(JobParams, EveryParameterChangesTheCacheKey) {
  const JobSpec defaults;
  for (const ParamInfo& p : param_table()) {
    JobSpec changed;
    const std::string value = other_value(p, defaults);
    ASSERT_EQ(apply_params({{p.name, value}}, changed), "") << p.name << "=" << value;
    EXPECT_NE(params_json(changed), params_json(defaults)) << p.name;
    JobSpec back;
    ASSERT_EQ(parse_params_json(params_json(changed), back), "") << p.name;
    EXPECT_EQ(params_json(back), params_json(changed)) << p.name;
  }
  // The two that were once left out of the key.
  JobSpec a, b;
  b.params.shooter_size = 0.25;
  EXPECT_NE(params_json(a), params_json(b));
  JobSpec c;
  c.write.color_bits = 8;
  EXPECT_NE(params_json(a), params_json(c));
}

// A quality preset sets the settings it names; a parameter given with it overrides it whichever
// comes first; the preset is kept with the job and reads back the same.
TEST(JobParams, QualityPresetIsOverriddenByTheParametersGivenWithIt) {
  const JobSpec defaults;
  JobSpec high;
  ASSERT_EQ(apply_params({{"quality", "high"}}, high), "");
  EXPECT_TRUE(high.params.gather);
  EXPECT_EQ(high.params.beps, defaults.params.beps);
  // Light pools: looked for by default and at high, not at draft.
  EXPECT_TRUE(defaults.params.pools);
  EXPECT_TRUE(high.params.pools);
  // Sharp shadows (finer hemicubes for the strongest pieces): asked for alone, in no preset.
  EXPECT_FALSE(defaults.params.sharp_shadows);
  EXPECT_FALSE(high.params.sharp_shadows);
  JobSpec draft;
  ASSERT_EQ(apply_params({{"quality", "draft"}}, draft), "");
  EXPECT_FALSE(draft.params.gather);
  EXPECT_FALSE(draft.params.pools);
  EXPECT_FALSE(draft.params.sharp_shadows);
  EXPECT_LT(draft.params.resolution, defaults.params.resolution);
  EXPECT_GT(draft.params.beps, defaults.params.beps);
  EXPECT_GT(draft.params.convergence, defaults.params.convergence);
  // "beps" sorts before "quality" and "resolution" after it: both override the preset.
  JobSpec mixed;
  ASSERT_EQ(apply_params({{"beps", "0.01"}, {"quality", "draft"}, {"resolution", "80"}, {"gather", "true"}}, mixed), "");
  EXPECT_EQ(mixed.params.beps, 0.01);
  EXPECT_EQ(mixed.params.resolution, 80u);
  EXPECT_TRUE(mixed.params.gather);
  EXPECT_EQ(mixed.params.convergence, draft.params.convergence);
  JobSpec back;
  ASSERT_EQ(parse_params_json(params_json(mixed), back), "");
  EXPECT_EQ(params_json(back), params_json(mixed));
  JobSpec bad;
  const std::string e = apply_params({{"quality", "best"}}, bad);
  EXPECT_NE(e.find("quality"), std::string::npos) << e;
  EXPECT_NE(e.find("draft, default or high"), std::string::npos) << e;
}

// Each parameter is accepted at both ends of its range and refused just past them, with a message
// that names it.
TEST(JobParams, RangesAreEnforcedAtTheirBounds) {
  for (const ParamInfo& p : param_table()) {
    if (p.kind != ParamInfo::Kind::kWhole) continue;
    for (const double inside : {p.min, p.max}) {
      JobSpec spec;
      const std::string text = std::to_string(static_cast<uint64_t>(inside));
      EXPECT_EQ(apply_params({{p.name, text}}, spec), "") << p.name << "=" << text;
    }
    JobSpec spec;
    const std::string past = std::to_string(static_cast<uint64_t>(p.max) + 1);
    const std::string err = apply_params({{p.name, past}}, spec);
    EXPECT_NE(err.find(p.name), std::string::npos) << p.name << "=" << past << ": " << err;
  }
  // Where the command line and the wire used to disagree: 2^20 samples, and exposure 0 (automatic).
  JobSpec spec;
  EXPECT_EQ(apply_params({{"samples", "1048576"}, {"exposure", "0"}}, spec), "");
  EXPECT_EQ(spec.samples, 1048576u);
  EXPECT_EQ(spec.write.exposure, 0.0);
}

// The API description's parameters are the table's, with the defaults a JobSpec starts from and
// ranges that apply_params enforces.
TEST(JobParams, OpenApiListsEveryParameterWithItsDefaultAndRange) {
  const nlohmann::json list = nlohmann::json::parse(params_openapi_json());
  ASSERT_TRUE(list.is_array());
  ASSERT_EQ(list.size(), param_table().size());
  const nlohmann::json defaults = nlohmann::json::parse(params_json(JobSpec{}));
  for (const auto& p : list) {
    const std::string name = p.at("name");
    EXPECT_EQ(p.at("in"), "query");
    EXPECT_EQ(p.at("schema").at("default"), defaults.at(name)) << name;
    if (p.at("schema").contains("maximum") && p.at("schema").at("type") == "integer") {
      JobSpec spec;
      const uint64_t max = p.at("schema").at("maximum");
      EXPECT_NE(apply_params({{name, std::to_string(max + 1)}}, spec), "") << name;
    }
  }
}

// The sky is a colour: "R,G,B" or one number for grey on the command line and in query strings,
// also [r, g, b] in a JSON body; negative, non-numeric or two-channel values are refused by name.
TEST(JobParams, SkyTakesAColourInEveryForm) {
  JobSpec a, b, c;
  ASSERT_EQ(apply_params({{"sky", "0.5,1,2.25"}}, a), "");
  EXPECT_EQ(a.sky, glm::dvec3(0.5, 1.0, 2.25));
  ASSERT_EQ(apply_params({{"sky", "3"}}, b), "");
  EXPECT_EQ(b.sky, glm::dvec3(3.0));
  ASSERT_EQ(parse_params_json(R"({"sky": [0.5, 1, 2.25]})", c), "");
  EXPECT_EQ(c.sky, a.sky);
  EXPECT_EQ(params_json(c), params_json(a));
  JobSpec back;
  ASSERT_EQ(parse_params_json(params_json(a), back), "");
  EXPECT_EQ(back.sky, a.sky);
  for (const char* bad : {"-1", "1,2", "1,2,3,4", "1,x,2", "", "1,,2", "inf"}) {
    JobSpec s;
    const std::string e = apply_params({{"sky", bad}}, s);
    EXPECT_NE(e.find("sky"), std::string::npos) << "'" << bad << "': " << e;
  }
  JobSpec s;
  EXPECT_NE(parse_params_json(R"({"sky": [1, 2]})", s), "");
  EXPECT_NE(parse_params_json(R"({"sky": [1, -2, 3]})", s).find("sky"), std::string::npos);
}

TEST(JobProgressJson, RoundTrips) {
  JobProgress p;
  p.phase = "gathering";
  p.fraction = 0.25;
  p.links = 1234;
  p.iterations = 3;
  p.hierarchical = true;
  p.elapsed_seconds = 2.5;
  const auto back = parse_progress_json(progress_json(p));
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->phase, "gathering");
  EXPECT_EQ(back->fraction, 0.25);
  EXPECT_EQ(back->links, 1234u);
  EXPECT_EQ(back->iterations, 3u);
  EXPECT_TRUE(back->hierarchical);
  EXPECT_EQ(back->elapsed_seconds, 2.5);
  EXPECT_FALSE(parse_progress_json("[]").has_value());
  // Members of another type are left at their defaults instead of throwing.
  const auto odd = parse_progress_json(R"({"phase":3,"shots":"x"})");
  ASSERT_TRUE(odd.has_value());
  EXPECT_EQ(odd->phase, "shooting");
  EXPECT_EQ(odd->shots, 0u);
}

}  // namespace
}  // namespace hemibake::protocol
