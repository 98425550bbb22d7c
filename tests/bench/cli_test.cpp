// The baselines through the command line and the same output path as the hemicube methods.
#include "hemibake/protocol/gltf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <sys/wait.h>
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

// The benchmarks' furnished room from the command line, with each method, renders a PNG; a bad
// patch count is refused with a message.
TEST(Cli, RoomRendersWithEveryMethod) {
  for (const std::string method : {"aa", "classical", "hr"}) {
    const std::string png = (std::filesystem::temp_directory_path() /
                             ("hemibake-room-" + method + "-" + std::to_string(getpid()) + ".png")).string();
    const std::string command = std::string(HEMIBAKE_CLIENT) + " room --patches 300 --convergence 0.05 --no-pools --method " + method +
                                " --render " + png + " > /dev/null";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    const std::string bytes = read_all(png);
    std::filesystem::remove(png);
    ASSERT_GT(bytes.size(), 1000u) << method;
    EXPECT_EQ(bytes.substr(1, 3), "PNG") << method;
  }
  const std::string bad = std::string(HEMIBAKE_CLIENT) + " room --patches 5 2> /dev/null";
  EXPECT_EQ(WEXITSTATUS(std::system(bad.c_str())), 2);
}

}  // namespace

// Every command answers --help with the usage text on standard output and status 0, as the
// top-level --help does (it used to take --help for an option wanting a value).
TEST(Cli, EveryCommandAnswersHelp) {
  for (const std::string command : {"bake", "cornell", "room", "render", "submit", "status", "fetch", "list"}) {
    const std::string out = (std::filesystem::temp_directory_path() /
                             ("hemibake-help-" + command + "-" + std::to_string(getpid()) + ".txt")).string();
    const std::string line = std::string(HEMIBAKE_CLIENT) + " " + command + " --help > " + out + " 2>&1";
    EXPECT_EQ(std::system(line.c_str()), 0) << line;
    const std::string text = read_all(out);
    std::filesystem::remove(out);
    EXPECT_NE(text.find("usage:"), std::string::npos) << command << ": " << text;
    EXPECT_NE(text.find("--resolution"), std::string::npos) << command;
  }
}
