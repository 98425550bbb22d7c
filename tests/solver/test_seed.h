// Fresh random seeds for tests, reproducible on demand.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <random>
#include <string>

namespace hemibake::test {

/// A fresh seed per run; HEMIBAKE_TEST_SEED=N reproduces a run.
inline uint64_t test_seed() {
  if (const char* env = std::getenv("HEMIBAKE_TEST_SEED")) return std::strtoull(env, nullptr, 10);
  std::random_device rd;
  return (static_cast<uint64_t>(rd()) << 32) | rd();
}

/// Records the seed in the test's output and returns a line to print with failures.
inline std::string seed_note(uint64_t seed) {
  ::testing::Test::RecordProperty("seed", std::to_string(seed));
  return "seed " + std::to_string(seed) + " (rerun with HEMIBAKE_TEST_SEED=" + std::to_string(seed) + ")";
}

}  // namespace hemibake::test
