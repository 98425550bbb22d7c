// The `hemibake` command line as a library: parsing, the commands, and how they report. main()
// is one call to run_main(); tests call parse_command_line() and run() without a process.
#pragma once

#include "hemibake/client/console.h"
#include "hemibake/client/render.h"
#include "hemibake/protocol/gltf.h"
#include "hemibake/protocol/job.h"

#include <cstdint>
#include <cstdio>
#include <optional>
#include <span>
#include <string>

namespace hemibake::client {

/// A parsed command line.
struct CommandLine {
  std::string command;  ///< bake, cornell, room, render, submit, status, watch, fetch, cancel, list
  bool help = false;    ///< --help anywhere: print the usage, exit 0
  protocol::JobSpec spec;           ///< the job parameters (protocol::param_table's options)
  protocol::LoadLimits limits;      ///< --max-triangles
  std::string input;                ///< the one positional argument: a file or a job id
  std::string output;               ///< -o
  std::string render_path;          ///< --render FILE.png
  std::string wire_path;            ///< --wireframe FILE.png (render: --wireframe alone draws edges)
  bool wireframe = false;           ///< render: element edges
  bool flat = false;                ///< render: flat element radiosity instead of Gouraud
  std::string server;               ///< --server URL (else HEMIBAKE_SERVER, filled by run_main)
  std::string token;                ///< bearer token (HEMIBAKE_TOKEN, filled by run_main)
  std::string state;                ///< list: --state
  double retry_seconds = 60.0;      ///< --retry-seconds: how long to keep trying a server that answers 503
                                    ///< or 429 or cannot be reached
  uint32_t patches = 6300;          ///< room: about this many patches
  std::optional<Camera> camera;     ///< --camera X,Y,Z:TX,TY,TZ
};

/// The usage text.
std::string usage();

/// Parses the arguments after the program name. Returns an empty string, or the message for an
/// unknown command, option or bad value (exit status 2).
std::string parse_command_line(std::span<const std::string> args, CommandLine& out);

/// Runs a parsed command; returns the exit status (0 done, 1 failed, 2 bad usage).
int run(const CommandLine& command, const Console& console);

/// What main() does: parse argv, take HEMIBAKE_SERVER and HEMIBAKE_TOKEN from the environment,
/// run on stdout and stderr.
int run_main(int argc, char** argv);

}  // namespace hemibake::client
