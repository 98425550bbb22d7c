// Job parameters over the wire: every name, its range checks, and the cache-key text.
#include "hemibake/protocol/job.h"

#include <gtest/gtest.h>

namespace hemibake::protocol {
namespace {

TEST(JobParams, EveryNameIsAppliedAndRoundTrips) {
  JobSpec spec;
  const std::string err = apply_params({{"method", "classical"}, {"resolution", "64"}, {"feps", "0.002"}, {"aeps", "0.0005"},
                                        {"beps", "0.1"}, {"convergence", "0.01"}, {"max_shots", "500"},
                                        {"max_elements", "9000"}, {"threads", "3"}, {"reuse", "false"}, {"cluster_size", "0.3"}, {"shot_cache_mb", "64"}, {"rays", "16"},
                                        {"samples", "64"}, {"draco", "no"}, {"position_bits", "16"},
                                        {"texcoord_bits", "10"}, {"draco_speed", "3"}, {"exposure", "2.5"}},
                                       spec);
  ASSERT_EQ(err, "");
  EXPECT_EQ(spec.params.method, solver::Method::kClassical);
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
  EXPECT_EQ(aa.write.method, "");
  EXPECT_EQ(hr.write.method, "hr");
  EXPECT_EQ(reference.write.method, "reference");
  // Different methods are different cache keys; a round trip keeps the method.
  EXPECT_NE(params_json(aa), params_json(hr));
  EXPECT_NE(params_json(hr), params_json(reference));
  JobSpec back;
  ASSERT_EQ(parse_params_json(params_json(hr), back), "");
  EXPECT_EQ(back.write.method, "hr");
  // Switching back to a solver method clears it.
  ASSERT_EQ(apply_params({{"method", "classical"}}, back), "");
  EXPECT_EQ(back.write.method, "");
}

TEST(JobParams, BadValuesAreRefusedByName) {
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"method", "ray"},      {"resolution", "7"},    {"resolution", "abc"}, {"feps", "nan"},
      {"max_shots", "-1"},    {"threads", "1.5"},     {"reuse", "maybe"},    {"rays", "0"},
      {"samples", "0"},       {"samples", "1e9"},     {"position_bits", "31"}, {"exposure", "-1"},
      {"convergence", "2"},   {"cluster_size", "-1"}, {"nonsense", "1"}};
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
