// Parsing the `hemibake` command line, and dispatching its commands.
#include "hemibake/client/cli.h"

#include "commands.h"
#include "hemibake/client/remote.h"

#include <glm/geometric.hpp>

#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <map>
#include <vector>

namespace hemibake::client {
namespace {

bool is_local_builtin(const std::string& command) { return command == "cornell" || command == "room" || command == "clutter" || command == "lava" || command == "atrium"; }

bool is_remote(const std::string& command) {
  return command == "submit" || command == "status" || command == "watch" || command == "fetch" || command == "cancel" ||
         command == "list";
}

bool known_command(const std::string& command) {
  return is_local_builtin(command) || is_remote(command) || command == "bake" || command == "render";
}

// Parses "x,y,z:tx,ty,tz" (camera position, then the point it looks at).
std::optional<Camera> parse_camera(const std::string& text) {
  double v[6];
  char extra;
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf:%lf,%lf,%lf%c", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &extra) != 6)
    return std::nullopt;
  Camera cam;
  cam.position = {v[0], v[1], v[2]};
  cam.target = {v[3], v[4], v[5]};
  if (!(glm::length(cam.target - cam.position) > 0.0)) return std::nullopt;
  return cam;
}

// A whole number in [lo, hi] for the command line's own options.
bool whole_in(const std::string& text, uint64_t lo, uint64_t hi, uint64_t& out) {
  char* end = nullptr;
  const double x = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !(x >= static_cast<double>(lo) && x <= static_cast<double>(hi)) || x != static_cast<double>(static_cast<uint64_t>(x)))
    return false;
  out = static_cast<uint64_t>(x);
  return true;
}

// The job parameter that --FLAG names (a flag that defaults off is turned on so), or --no-FLAG
// (a flag turned off), or null.
const protocol::ParamInfo* param_of_flag(const std::string& opt, bool& negated, bool& set) {
  for (const auto& p : protocol::param_table()) {
    negated = set = false;
    const bool flag = p.kind == protocol::ParamInfo::Kind::kFlag;
    if (opt == std::string("--") + p.flag) return set = flag, &p;
    if (flag && opt == std::string("--no-") + p.flag) return negated = true, &p;
  }
  return nullptr;
}

// The command line's own options (not job parameters); returns false if `opt` is none of them.
bool own_option(const std::string& opt, const std::string& val, CommandLine& o, std::string& err) {
  uint64_t n = 0;
  if (opt == "-o" || opt == "--output") o.output = val;
  else if (opt == "--server") o.server = val;
  else if (opt == "--state") o.state = val;
  else if (opt == "--render") o.render_path = val;
  else if (opt == "--wireframe") o.wire_path = val;
  else if (opt == "--camera") {
    o.camera = parse_camera(val);
    if (!o.camera) err = "--camera needs x,y,z:tx,ty,tz (got '" + val + "')";
  } else if (opt == "--max-triangles") {
    if (whole_in(val, 1, 1ull << 40, n)) o.limits.max_triangles = n;
    else err = "--max-triangles must be a whole number from 1 (got '" + val + "')";
  } else if (opt == "--retry-seconds") {
    if (whole_in(val, 0, 86400, n)) o.retry_seconds = static_cast<double>(n);
    else err = "--retry-seconds must be a whole number from 0 to 86400 (got '" + val + "')";
  } else if (opt == "--patches") {
    if (whole_in(val, 100, 1'000'000, n)) o.patches = static_cast<uint32_t>(n);
    else err = "--patches must be a whole number from 100 to 1000000 (got '" + val + "')";
  } else {
    return false;
  }
  return true;
}

}  // namespace

std::string usage() {
  return "usage:\n"
         "  hemibake bake IN.glb|IN.gltf -o OUT.glb [options]   bake a glTF scene\n"
         "  hemibake cornell [options]                          bake the built-in Cornell box\n"
         "  hemibake room [--patches N] [options]               bake the benchmarks' furnished room\n"
         "  hemibake clutter [options]                          bake the benchmarks' cluttered room\n"
         "  hemibake lava [options]                             bake a floor lit by six emissive spheres\n"
         "  hemibake atrium [options]                           bake a Sponza-like atrium (127k triangles) under a sky and a sun\n"
         "  hemibake bake --server URL IN -o OUT.glb [options]  bake on a hemibake-server\n"
         "  hemibake submit IN [options]                        submit to the server; prints the job id\n"
         "  hemibake status ID | watch ID | cancel ID           a job's state, live progress, cancel it\n"
         "  hemibake fetch ID -o OUT.glb                        download a job's result\n"
         "  hemibake list [--state S]                           the server's jobs, newest first\n"
         "  hemibake render IN.glb -o OUT.png [--camera ...] [--wireframe] [--flat]\n"
         "                                                      software render of a baked file\n"
         "  (the server: --server URL or HEMIBAKE_SERVER; a bearer token from HEMIBAKE_TOKEN)\n"
         "\n"
         "job options (the paper's names; the same names and limits as the service's parameters):\n" +
         protocol::params_usage() +
         "\n"
         "other options:\n"
         "  --max-triangles N       bake: refuse larger scenes (default 2000000)\n"
         "  --render FILE.png       bake, cornell, room: also render the result (Gouraud) to a PNG\n"
         "  --wireframe FILE.png    bake, cornell, room: also render the mesh (flat, element edges) to a PNG\n"
         "  --camera X,Y,Z:TX,TY,TZ the renders' camera and the point it looks at\n"
         "  --retry-seconds S       server commands: keep trying for up to S s while the server answers 503\n"
         "                          (its job store busy or unreachable) or 429 (its queue full), waiting as it\n"
         "                          asks, or cannot be reached (restarting) (default 60; 0: no)\n";
}

std::string parse_command_line(std::span<const std::string> args, CommandLine& o) {
  if (args.empty()) return "a command is needed (try --help)";
  o.command = args[0];
  for (const std::string& a : args) o.help = o.help || a == "--help" || a == "-h";
  if (o.help) return {};  // `hemibake bake --help` asks for help, not for an option called --help
  if (!known_command(o.command)) return "unknown command '" + o.command + "' (try --help)";
  const bool takes_positional = !is_local_builtin(o.command) && o.command != "list";
  std::map<std::string, std::string> values;  // job parameters by wire name, the last given wins
  for (size_t i = 1; i < args.size(); ++i) {
    const std::string& opt = args[i];
    const bool next_is_value = i + 1 < args.size() && (args[i + 1].empty() || args[i + 1][0] != '-');
    if (opt == "--flat" || (opt == "--wireframe" && !next_is_value)) {
      (opt == "--flat" ? o.flat : o.wireframe) = true;
      continue;
    }
    bool negated = false;
    bool set = false;
    const protocol::ParamInfo* param = param_of_flag(opt, negated, set);
    if (param != nullptr && (negated || set)) {
      values[param->name] = negated ? "false" : "true";
      continue;
    }
    if (opt.empty() || opt[0] != '-') {
      if (!takes_positional || !o.input.empty()) return "unexpected argument '" + opt + "'";
      o.input = opt;
      continue;
    }
    if (param == nullptr && opt != "-o" && opt.rfind("--", 0) != 0) return "unknown option '" + opt + "'";
    if (i + 1 >= args.size()) {
      std::string ignored;
      CommandLine scratch;
      if (param == nullptr && !own_option(opt, "", scratch, ignored)) return "unknown option '" + opt + "'";
      return opt + " needs a value";
    }
    const std::string& val = args[++i];
    if (param != nullptr) {
      double v = 0.0;
      if (std::string e = protocol::parse_param_value(*param, val, v); !e.empty()) return opt + " " + e;
      values[param->name] = val;
      continue;
    }
    std::string err;
    if (!own_option(opt, val, o, err)) return "unknown option '" + opt + "'";
    if (!err.empty()) return err;
  }
  if (std::string e = protocol::apply_params(values, o.spec); !e.empty()) return e;
  const auto method = o.spec.method;
  const bool baseline = method == protocol::Method::kHierarchical || method == protocol::Method::kReference;
  if (baseline && o.command != "bake" && o.command != "submit" &&
      !(method == protocol::Method::kHierarchical && is_local_builtin(o.command)))
    return std::string("--method ") + protocol::to_string(method) + " is for bake and submit (hr also cornell and room) only";
  return {};
}

int run(const CommandLine& o, const Console& console) {
  if (o.help) {
    std::fputs(usage().c_str(), console.out);
    return 0;
  }
  if (o.command == "cornell") return run_cornell(o, console);
  if (o.command == "room") return run_room(o, console);
  if (o.command == "clutter") return run_clutter(o, console);
  if (o.command == "lava") return run_lava(o, console);
  if (o.command == "atrium") return run_atrium(o, console);
  if (o.command == "render") return run_render(o, console);
  if (o.command == "bake" && o.server.empty()) return run_bake(o, console);
  // The commands that talk to a server.
  if (o.server.empty()) {
    std::fprintf(console.err, "hemibake: %s needs a server: --server http://HOST:PORT or HEMIBAKE_SERVER\n", o.command.c_str());
    return 2;
  }
  Remote remote;
  if (std::string err = parse_server(o.server, remote); !err.empty()) {
    std::fprintf(console.err, "hemibake: %s\n", err.c_str());
    return 2;
  }
  remote.token = o.token;
  remote.retry_seconds = o.retry_seconds;
  if (o.command != "list" && o.input.empty()) {
    std::fprintf(console.err, "hemibake: %s needs %s\n", o.command.c_str(),
                 o.command == "submit" || o.command == "bake" ? "an input file" : "a job id");
    return 2;
  }
  if (o.command == "bake") {
    if (o.output.empty()) {
      std::fputs("hemibake: bake needs -o OUT.glb\n", console.err);
      return 2;
    }
    return remote_bake(remote, o.input, o.output, o.spec, console);
  }
  if (o.command == "submit") return remote_submit(remote, o.input, o.spec, console);
  if (o.command == "status") return remote_status(remote, o.input, console);
  if (o.command == "watch") return remote_watch(remote, o.input, console);
  if (o.command == "cancel") return remote_cancel(remote, o.input, console);
  if (o.command == "list") return remote_list(remote, o.state, console);
  if (o.output.empty()) {
    std::fputs("hemibake: fetch needs -o OUT.glb\n", console.err);
    return 2;
  }
  return remote_fetch(remote, o.input, o.output, console);
}

int run_main(int argc, char** argv) {
  Console console;
  console.tty = isatty(STDERR_FILENO) != 0;
  if (argc < 2) {
    std::fputs(usage().c_str(), stderr);
    return 2;
  }
  const std::vector<std::string> args(argv + 1, argv + argc);
  CommandLine o;
  if (std::string err = parse_command_line(args, o); !err.empty()) {
    std::fprintf(stderr, "hemibake: %s\n", err.c_str());
    return 2;
  }
  if (o.server.empty())
    if (const char* s = std::getenv("HEMIBAKE_SERVER")) o.server = s;
  if (const char* token = std::getenv("HEMIBAKE_TOKEN")) o.token = token;
  return run(o, console);
}

}  // namespace hemibake::client
