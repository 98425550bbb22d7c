// The command line through its library: parsing against the wire's parameter rules, a local bake
// read back by the independent baked-file reader, and the progress a log sees.
#include "captured.h"
#include "hemibake/client/cli.h"
#include "hemibake/protocol/gltf.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace hemibake::client {
namespace {

std::string parse(std::vector<std::string> args, CommandLine& out) { return parse_command_line(args, out); }

// The message for a command line parsed on its own.
std::string error_of(std::vector<std::string> args) {
  CommandLine fresh;
  return parse_command_line(args, fresh);
}

TEST(CommandLine, OptionsSetTheSameFieldsAsTheWireNames) {
  CommandLine cl;
  ASSERT_EQ(parse({"bake", "in.gltf", "-o", "out.glb", "--method", "hr", "--rays", "8", "--no-draco", "--max-shots", "10",
                   "--shooter-size", "0.25", "--color-bits", "8", "--exposure", "0", "--no-reuse"},
                  cl),
            "");
  protocol::JobSpec wire;
  ASSERT_EQ(protocol::apply_params({{"method", "hr"}, {"rays", "8"}, {"draco", "false"}, {"max_shots", "10"},
                                    {"shooter_size", "0.25"}, {"color_bits", "8"}, {"exposure", "0"}, {"reuse", "no"}},
                                   wire),
            "");
  EXPECT_EQ(protocol::params_json(cl.spec), protocol::params_json(wire));
  EXPECT_EQ(cl.input, "in.gltf");
  EXPECT_EQ(cl.output, "out.glb");
}

// Every job parameter is an option, and the command line accepts and refuses exactly what the
// wire does, at both ends of each range.
TEST(CommandLine, EveryParameterHasTheWiresLimits) {
  for (const auto& p : protocol::param_table()) {
    std::vector<std::string> values;
    if (p.kind == protocol::ParamInfo::Kind::kWhole || p.kind == protocol::ParamInfo::Kind::kNumber) {
      values = {std::to_string(p.min), std::to_string(p.min - 1)};
      if (p.max < 1e300) {
        values.push_back(std::to_string(p.max));
        values.push_back(std::to_string(p.max + 1));
      }
      values.push_back("abc");
    } else if (p.kind == protocol::ParamInfo::Kind::kMethod) {
      values = {"aa", "classical", "hr", "reference", "ray"};
    } else if (p.kind == protocol::ParamInfo::Kind::kQuality) {
      values = {"draft", "default", "high", "best"};
    } else if (p.kind == protocol::ParamInfo::Kind::kTone) {
      values = {"shoulder", "clamp", "filmic"};
    } else {
      continue;  // flags: --no-FLAG, checked below
    }
    for (const std::string& v : values) {
      protocol::JobSpec wire;
      const bool wire_ok = protocol::apply_params({{p.name, v}}, wire).empty();
      CommandLine cl;
      const std::string err = parse({"bake", "in.gltf", std::string("--") + p.flag, v}, cl);
      EXPECT_EQ(err.empty(), wire_ok) << "--" << p.flag << " " << v << ": " << err;
      if (!err.empty() && err.find("--method") == std::string::npos) {
        EXPECT_TRUE(err.find(p.flag) != std::string::npos || err.find(p.name) != std::string::npos)
            << "the message names the option: " << err;
      }
    }
  }
  for (const auto& p : protocol::param_table()) {
    if (p.kind != protocol::ParamInfo::Kind::kFlag) continue;
    CommandLine cl;
    ASSERT_EQ(parse({"bake", "in.gltf", std::string("--no-") + p.flag}, cl), "") << p.flag;
    EXPECT_EQ(p.get(cl.spec), 0.0) << p.flag;
  }
}

TEST(CommandLine, BadUsageIsNamed) {
  EXPECT_NE(error_of({"frobnicate"}).find("unknown command 'frobnicate'"), std::string::npos);
  EXPECT_NE(error_of({"bake", "in.gltf", "--bogus"}).find("unknown option '--bogus'"), std::string::npos);
  EXPECT_NE(error_of({"bake", "in.gltf", "--resolution"}).find("--resolution needs a value"), std::string::npos);
  EXPECT_NE(error_of({"bake", "a.gltf", "b.gltf"}).find("unexpected argument 'b.gltf'"), std::string::npos);
  EXPECT_NE(error_of({"cornell", "--resolution", "7"}).find("resolution must be an even number"), std::string::npos);
  EXPECT_NE(error_of({"cornell", "--method", "reference"}).find("is for bake and submit"), std::string::npos);
  EXPECT_NE(error_of({"bake", "in.gltf", "--camera", "1,2,3"}).find("--camera"), std::string::npos);
  CommandLine help;
  EXPECT_EQ(parse({"bake", "--resolution", "--help"}, help), "");
  EXPECT_TRUE(help.help);
}

TEST(CommandLine, HelpListsEveryParameterWithItsDefault) {
  const std::string text = usage();
  const protocol::JobSpec defaults;
  for (const auto& p : protocol::param_table()) {
    // A flag is named the way it changes the default: --no-FLAG when on, --FLAG when off.
    const bool on_flag = p.kind == protocol::ParamInfo::Kind::kFlag && p.get(defaults) != 0.0;
    EXPECT_NE(text.find(std::string("--") + (on_flag ? "no-" : "") + p.flag + " "), std::string::npos) << p.flag;
  }
  EXPECT_NE(text.find("(default 100)"), std::string::npos);  // the resolution's
}

// A flag that defaults off is turned on by --FLAG, one that defaults on off by --no-FLAG.
TEST(CommandLine, FlagsTurnOnAndOff) {
  CommandLine cl;
  ASSERT_EQ(parse({"bake", "in.glb", "-o", "out.glb", "--gather", "--no-reuse"}, cl), "");
  EXPECT_TRUE(cl.spec.params.gather);
  EXPECT_FALSE(cl.spec.params.reuse_visibility);
  CommandLine plain;
  ASSERT_EQ(parse({"bake", "in.glb", "-o", "out.glb"}, plain), "");
  EXPECT_FALSE(plain.spec.params.gather);
  EXPECT_TRUE(plain.spec.params.reuse_visibility);
}

// A local bake through the library, read back by the baked-file reader: lit, finite, and the
// method recorded.
TEST(LocalBake, WritesALitFileThatReadsBack) {
  const std::string out = (std::filesystem::temp_directory_path() / ("hemibake-client-" + std::to_string(getpid()) + ".glb")).string();
  CommandLine cl;
  ASSERT_EQ(parse({"bake", HEMIBAKE_SOURCE_DIR "/data/cornell-box.gltf", "-o", out, "--method", "classical", "--convergence",
                   "0.05", "--aeps", "0.001", "--resolution", "32"},
                  cl),
            "");
  Captured io;
  EXPECT_EQ(run(cl, io.console), 0) << io.err();
  EXPECT_NE(io.out().find("wrote " + out), std::string::npos) << io.out();
  solver::Mesh mesh;
  ASSERT_EQ(protocol::read_baked_mesh(out, mesh), "");
  double lit = 0.0;
  for (const auto& b : mesh.radiosity) {
    ASSERT_TRUE(std::isfinite(b.x) && b.x >= 0.0);
    lit += b.x;
  }
  EXPECT_GT(lit / static_cast<double>(mesh.radiosity.size()), 0.01);
  FILE* f = std::fopen(out.c_str(), "rb");
  ASSERT_NE(f, nullptr);
  std::string bytes(4096, '\0');
  bytes.resize(std::fread(bytes.data(), 1, bytes.size(), f));
  std::fclose(f);
  EXPECT_NE(bytes.find("\"method\":\"classical\""), std::string::npos);
  std::filesystem::remove(out);
}

TEST(LocalBake, RefusesASceneWithoutLightAndAMissingFile) {
  CommandLine cl;
  ASSERT_EQ(parse({"bake", "/nonexistent/scene.gltf", "-o", "/tmp/x.glb"}, cl), "");
  Captured io;
  EXPECT_EQ(run(cl, io.console), 1);
  EXPECT_NE(io.err().find("/nonexistent/scene.gltf"), std::string::npos) << io.err();
  CommandLine no_out;
  ASSERT_EQ(parse({"bake", "in.gltf"}, no_out), "");
  Captured io2;
  EXPECT_EQ(run(no_out, io2.console), 2);
  EXPECT_NE(io2.err().find("-o OUT.glb"), std::string::npos);
}

// A file whose node refers to a light that does not exist: exit status 1, and the message names
// the light; a sky that is not three numbers is bad usage naming --sky.
TEST(LocalBake, BadLightExitsOneAndBadSkyIsNamed) {
  std::ifstream in(HEMIBAKE_SOURCE_DIR "/data/lit-yard.gltf");
  std::stringstream text;
  text << in.rdbuf();
  std::string gltf = text.str();
  const std::string ref = "\"light\": 1\n";  // the bulb's node
  const size_t at = gltf.find(ref);
  ASSERT_NE(at, std::string::npos);
  gltf.replace(at, ref.size(), "\"light\": 9\n");
  const std::string path = (std::filesystem::temp_directory_path() / ("hemibake-badlight-" + std::to_string(getpid()) + ".gltf")).string();
  std::ofstream(path) << gltf;
  CommandLine cl;
  ASSERT_EQ(parse({"bake", path, "-o", "/tmp/never-written.glb"}, cl), "");
  Captured io;
  EXPECT_EQ(run(cl, io.console), 1);
  EXPECT_NE(io.err().find("light 9, which does not exist"), std::string::npos) << io.err();
  std::filesystem::remove(path);
  EXPECT_NE(error_of({"bake", "in.gltf", "-o", "x.glb", "--sky", "1,2"}).find("--sky"), std::string::npos);
  CommandLine sky;
  ASSERT_EQ(parse({"bake", "in.gltf", "-o", "x.glb", "--sky", "0.5,1,2"}, sky), "");
  EXPECT_EQ(sky.spec.sky, glm::dvec3(0.5, 1.0, 2.0));
}

// Not on a terminal, a long job still shows progress as whole lines; on a terminal, one line is
// redrawn in place and ended once.
TEST(Progress, LinesForALogAndOneRedrawnLineForATerminal) {
  protocol::JobProgress p;
  p.shots = 7;
  p.unshot_fraction = 0.5;
  p.elapsed_seconds = 2.0;
  p.eta_seconds = 3.0;
  {
    Captured io;
    {
      ProgressPrinter printer(io.console, 0.0);
      printer.update(p);
      p.phase = "tracing";
      printer.update(p);
      p.phase = "done";
      printer.update(p);
    }
    const std::string err = io.err();
    EXPECT_NE(err.find("shooting: 7 shots, unshot 0.50000"), std::string::npos) << err;
    EXPECT_NE(err.find("about 3 s left"), std::string::npos) << err;
    EXPECT_NE(err.find("tracing"), std::string::npos) << err;
    EXPECT_EQ(err.find('\r'), std::string::npos) << err;
  }
  {
    Captured io;
    io.console.tty = true;
    p.phase = "shooting";
    {
      ProgressPrinter printer(io.console, 0.0);
      printer.update(p);
      printer.update(p);
    }
    const std::string err = io.err();
    EXPECT_EQ(std::count(err.begin(), err.end(), '\r'), 2) << err;
    EXPECT_EQ(err.back(), '\n');
  }
  {
    // A job shorter than the interval prints nothing to a log.
    Captured io;
    {
      ProgressPrinter printer(io.console, 60.0);
      p.phase = "shooting";
      printer.update(p);
    }
    EXPECT_EQ(io.err(), "");
  }
}

}  // namespace
}  // namespace hemibake::client
