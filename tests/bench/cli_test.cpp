// The baselines through the command line and the same output path as the hemicube methods.
#include "hemibake/protocol/gltf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <unistd.h>

namespace {

std::string read_all(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

class BaselineBake : public ::testing::TestWithParam<const char*> {};

TEST_P(BaselineBake, WritesALitGlbRecordingTheMethod) {
  const std::string method = GetParam();
  const std::string out = (std::filesystem::temp_directory_path() /
                           ("hemibake-" + method + "-" + std::to_string(getpid()) + ".glb")).string();
  const std::string command = std::string(HEMIBAKE_CLIENT) + " bake " HEMIBAKE_SOURCE_DIR "/data/cornell-box.gltf -o " + out +
                              " --method " + method + " --samples 16 --convergence 0.05 --aeps 0.001 > /dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  const std::string glb = read_all(out);
  EXPECT_NE(glb.find("\"method\":\"" + method + "\""), std::string::npos);
  hemibake::solver::Mesh mesh;
  ASSERT_EQ(hemibake::protocol::read_baked_mesh(out, mesh), "");
  std::filesystem::remove(out);
  double lit = 0.0;
  for (const auto& b : mesh.radiosity) {
    ASSERT_TRUE(std::isfinite(b.x) && b.x >= 0.0);
    lit += b.x;
  }
  EXPECT_GT(lit / static_cast<double>(mesh.radiosity.size()), 0.01);
}

INSTANTIATE_TEST_SUITE_P(Cli, BaselineBake, ::testing::Values("hr", "reference"));

}  // namespace
