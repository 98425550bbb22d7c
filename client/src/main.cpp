// The `hemibake` command line.
#include "remote.h"
#include "render.h"

#include "hemibake/baselines/hierarchical.h"
#include "hemibake/baselines/reference.h"
#include "hemibake/protocol/gltf.h"
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <unistd.h>
#include <vector>

namespace {

using hemibake::solver::Method;
using hemibake::solver::Params;

constexpr const char* kSolverOptions =
    "solver options (the paper's names):\n"
    "  --method aa|classical   form factors: anti-aliased (default) or classical hemicube\n"
    "           hr             (bake, submit) hierarchical radiosity with ray-cast visibility (baseline)\n"
    "           reference      (bake, submit) the aa mesh with path-traced radiosity at its vertices\n"
    "  --rays N                hr: visibility rays per link (default 4)\n"
    "  --samples N             reference: paths per vertex (default 256)\n"
    "  --resolution N          hemicube resolution (default 100)\n"
    "  --feps X                form-factor tolerance (default 0.001)\n"
    "  --aeps X                minimum element area / scene area (default 0.0001)\n"
    "  --beps X                radiosity tolerance (default 0.03)\n"
    "  --cluster-size X        small patches of a surface shoot together in clusters up to X times the\n"
    "                          scene's diagonal wide (default 0.15; 0: every patch shoots alone)\n"
    "  --convergence X         stop at unshot/emitted power below X (default 0.001)\n"
    "  --max-shots N           shot limit\n"
    "  --max-elements N        element limit (default 2000000)\n"
    "  --threads N             threads (default: all cores)\n"
    "  --no-reuse              re-project the scene after splits instead of reusing pixels\n"
    "  --shot-cache-mb N       memory for replaying a shooter's earlier form factors (default 256; 0: off)\n";

void usage(FILE* out) {
  std::fprintf(out,
               "usage:\n"
               "  hemibake bake IN.glb|IN.gltf -o OUT.glb [options]   bake a glTF scene\n"
               "  hemibake cornell [options]                          bake the built-in Cornell box\n"
               "  hemibake room [--patches N] [options]               bake the benchmarks' furnished room\n"
               "  hemibake bake --server URL IN -o OUT.glb [options]  bake on a hemibake-server\n"
               "  hemibake submit IN [options]                        submit to the server; prints the job id\n"
               "  hemibake status ID | watch ID | cancel ID           a job's state, live progress, cancel it\n"
               "  hemibake fetch ID -o OUT.glb                        download a job's result\n"
               "  hemibake list [--state S]                           the server's jobs, newest first\n"
               "  hemibake render IN.glb -o OUT.png [--camera ...] [--wireframe] [--flat]\n"
               "                                                      software render of a baked file\n"
               "  (the server: --server URL or HEMIBAKE_SERVER; a bearer token from HEMIBAKE_TOKEN)\n"
               "\n%s"
               "output options (bake):\n"
               "  --no-draco              write plain accessors instead of KHR_draco_mesh_compression\n"
               "  --position-bits N       Draco position quantization (default 14, 0 = lossless)\n"
               "  --texcoord-bits N       Draco texture coordinate quantization (default 12)\n"
               "  --draco-speed N         Draco encode/decode speed 0..10 (default 5)\n"
               "  --exposure X            radiosity scale for COLOR_0 (default: automatic)\n"
               "  --max-triangles N       refuse larger scenes (default 2000000)\n"
               "  --render FILE.png       also render the result (Gouraud) to a PNG\n"
               "  --wireframe FILE.png    also render the mesh (flat, element edges) to a PNG\n"
               "  --camera X,Y,Z:TX,TY,TZ the renders' camera and the point it looks at\n",
               kSolverOptions);
}

bool parse_number(const char* text, double& out) {
  char* end = nullptr;
  out = std::strtod(text, &end);
  return end != text && *end == '\0';
}

struct Options {
  Params params;
  hemibake::protocol::WriteOptions write;
  hemibake::protocol::LoadLimits limits;
  std::string input, output, render_path, wire_path, server, state;
  bool flat = false, wire_flag = false;
  std::string baseline;  // "hr" or "reference", else empty
  uint32_t rays = 4, samples = 256, patches = 6300;
  std::optional<hemibake::client::Camera> camera;
};

// Parses "x,y,z:tx,ty,tz" (camera position, then the point it looks at).
std::optional<hemibake::client::Camera> parse_camera(const std::string& text) {
  double v[6];
  char extra;
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf:%lf,%lf,%lf%c", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &extra) != 6)
    return std::nullopt;
  hemibake::client::Camera cam;
  cam.position = {v[0], v[1], v[2]};
  cam.target = {v[3], v[4], v[5]};
  if (glm::length(cam.target - cam.position) <= 0.0) return std::nullopt;
  return cam;
}

// Parses argv[first..]; returns an error message or an empty string.
std::string parse(int argc, char** argv, int first, bool bake, Options& o) {
  for (int i = first; i < argc; ++i) {
    const std::string opt = argv[i];
    if (opt == "--no-reuse") {
      o.params.reuse_visibility = false;
      continue;
    }
    if (opt == "--no-draco") {
      o.write.draco = false;
      continue;
    }
    if (opt == "--flat" || (opt == "--wireframe" && (i + 1 >= argc || argv[i + 1][0] == '-'))) {
      (opt == "--flat" ? o.flat : o.wire_flag) = true;
      continue;
    }
    if (opt.empty() || opt[0] != '-') {
      if (!bake || !o.input.empty()) return "unexpected argument '" + opt + "'";  // one positional
      o.input = opt;
      continue;
    }
    if (i + 1 >= argc) return opt + " needs a value";
    const char* val = argv[++i];
    if (opt == "-o" || opt == "--output") {
      o.output = val;
      continue;
    }
    if (opt == "--server") {
      o.server = val;
      continue;
    }
    if (opt == "--state") {
      o.state = val;
      continue;
    }
    if (opt == "--render" || opt == "--wireframe") {
      (opt == "--render" ? o.render_path : o.wire_path) = val;
      continue;
    }
    if (opt == "--camera") {
      o.camera = parse_camera(val);
      if (!o.camera) return std::string("--camera needs x,y,z:tx,ty,tz (got '") + val + "')";
      continue;
    }
    if (opt == "--method") {
      o.baseline.clear();
      if (std::strcmp(val, "aa") == 0) o.params.method = Method::kAntiAliased;
      else if (std::strcmp(val, "classical") == 0) o.params.method = Method::kClassical;
      else if (std::strcmp(val, "hr") == 0 || std::strcmp(val, "reference") == 0) o.baseline = val;
      else return std::string("--method must be aa, classical, hr or reference (got '") + val + "')";
      continue;
    }
    double x = 0.0;
    if (!parse_number(val, x)) return opt + " needs a number (got '" + val + "')";
    const bool whole = x >= 0 && x == static_cast<double>(static_cast<uint64_t>(x));
    if (opt == "--resolution" && whole) o.params.resolution = static_cast<uint32_t>(x);
    else if (opt == "--feps") o.params.feps = x;
    else if (opt == "--aeps") o.params.aeps = x;
    else if (opt == "--beps") o.params.beps = x;
    else if (opt == "--cluster-size") o.params.cluster_size = x;
    else if (opt == "--convergence") o.params.convergence = x;
    else if (opt == "--max-shots" && whole) o.params.max_shots = static_cast<uint64_t>(x);
    else if (opt == "--max-elements" && whole) o.params.max_elements = static_cast<uint64_t>(x);
    else if (opt == "--threads" && whole) o.params.threads = static_cast<uint32_t>(x);
    else if (opt == "--shot-cache-mb" && whole && x <= 1048576) o.params.shot_cache_mb = static_cast<uint32_t>(x);
    else if (opt == "--position-bits" && whole && x <= 30) o.write.position_bits = static_cast<int>(x);
    else if (opt == "--texcoord-bits" && whole && x <= 30) o.write.texcoord_bits = static_cast<int>(x);
    else if (opt == "--draco-speed" && whole && x <= 10) o.write.encode_speed = o.write.decode_speed = static_cast<int>(x);
    else if (opt == "--exposure" && x > 0) o.write.exposure = x;
    else if (opt == "--max-triangles" && whole) o.limits.max_triangles = static_cast<uint64_t>(x);
    else if (opt == "--rays" && whole && x >= 1 && x <= 1024) o.rays = static_cast<uint32_t>(x);
    else if (opt == "--samples" && whole && x >= 1 && x <= 1000000) o.samples = static_cast<uint32_t>(x);
    else if (opt == "--patches" && whole && x >= 100 && x <= 1000000) o.patches = static_cast<uint32_t>(x);
    else if (opt == "--resolution" || opt == "--max-shots" || opt == "--max-elements" || opt == "--threads" || opt == "--shot-cache-mb" ||
             opt == "--position-bits" || opt == "--texcoord-bits" || opt == "--draco-speed" ||
             opt == "--exposure" || opt == "--max-triangles" || opt == "--rays" || opt == "--samples" || opt == "--patches")
      return opt + " is out of range (got '" + val + "')";
    else return "unknown option '" + opt + "'";
  }
  return hemibake::solver::validate(o.params);
}

// Runs the solver with a progress line on a terminal.
void solve(hemibake::solver::Solver& solver) {
  const bool tty = isatty(STDERR_FILENO);
  solver.run([&](const hemibake::solver::Progress& p) {
    if (!tty) return;
    const int width = 24;
    const double done = p.unshot_fraction > 0.0 ? std::clamp(std::log10(1.0 / p.unshot_fraction) / 3.0, 0.0, 1.0) : 1.0;
    const int filled = static_cast<int>(done * width);
    std::fprintf(stderr, "\r  [%.*s%*s] shots %6llu  unshot %8.5f  elements %7llu  %6.1f s ", filled,
                 "########################", width - filled, "", static_cast<unsigned long long>(p.shots),
                 p.unshot_fraction, static_cast<unsigned long long>(p.elements), p.elapsed_seconds);
  });
  if (tty) std::fputs("\n", stderr);
}

void print_stats(const hemibake::solver::Stats& st) {
  std::printf("  %s after %.3f s: %llu shots (%llu replayed, %llu of them partly anew), %llu hemicubes, %llu elements, unshot %.5f\n",
              st.converged ? "converged" : st.cancelled ? "cancelled" : "stopped at a limit", st.seconds,
              static_cast<unsigned long long>(st.shots), static_cast<unsigned long long>(st.replayed_shots),
              static_cast<unsigned long long>(st.replays_reshot),
              static_cast<unsigned long long>(st.hemicubes),
              static_cast<unsigned long long>(st.elements), st.unshot_fraction);
  std::printf("  splits: %llu (form factor %llu, visibility %llu, gradient %llu), projections %llu of %llu elements in all, reused children %llu\n",
              static_cast<unsigned long long>(st.splits), static_cast<unsigned long long>(st.splits_form_factor),
              static_cast<unsigned long long>(st.splits_visibility), static_cast<unsigned long long>(st.splits_gradient),
              static_cast<unsigned long long>(st.projections), static_cast<unsigned long long>(st.elements_projected),
              static_cast<unsigned long long>(st.reused_children));
}

bool render_pngs(const hemibake::solver::Mesh& mesh, const Options& o, const hemibake::client::Camera& cam) {
  for (const auto& [path, wire] : {std::pair{o.render_path, false}, std::pair{o.wire_path, true}}) {
    if (path.empty()) continue;
    hemibake::client::RenderOptions ro;
    ro.gouraud = !wire;
    ro.wireframe = wire;
    const auto rgb = hemibake::client::render(mesh, cam, ro);
    if (!hemibake::client::write_png(path, rgb, ro.width, ro.height)) {
      std::fprintf(stderr, "hemibake: cannot write %s\n", path.c_str());
      return false;
    }
  }
  return true;
}

// A camera outside the scene's bounding box, looking at its centre from the -z side and above.
hemibake::client::Camera frame(const hemibake::solver::Mesh& mesh) {
  glm::dvec3 lo(1e300), hi(-1e300);
  for (const auto& p : mesh.positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const glm::dvec3 centre = 0.5 * (lo + hi);
  const double size = glm::length(hi - lo);
  hemibake::client::Camera cam;
  cam.target = centre;
  cam.position = centre + glm::dvec3(0.0, 0.25, 1.2) * size;
  cam.fov_y_degrees = 45.0;
  return cam;
}

// Solves `scene` with hierarchical radiosity (the options' FEPS, AEPS, rays and threads) and prints
// its statistics.
hemibake::solver::Mesh solve_hr(const hemibake::solver::Scene& scene, const Options& o,
                                hemibake::baselines::HierarchicalStats& hs) {
  hemibake::baselines::HierarchicalParams hp;
  hp.feps = o.params.feps;
  hp.aeps = o.params.aeps;
  hp.rays = o.rays;
  hp.threads = o.params.threads;
  auto mesh = hemibake::baselines::solve_hierarchical(scene, hp, hs);
  std::printf("  hierarchical radiosity: %.3f s (%.3f s linking), %llu links, %llu elements, %u iterations\n", hs.seconds,
              hs.seconds_linking, static_cast<unsigned long long>(hs.links), static_cast<unsigned long long>(hs.elements),
              hs.iterations);
  return mesh;
}

// Solves `scene` with the chosen method (aa, classical or hr), printing the statistics.
hemibake::solver::Mesh solve_builtin(const hemibake::solver::Scene& scene, const Options& o) {
  if (o.baseline == "hr") {
    hemibake::baselines::HierarchicalStats hs;
    return solve_hr(scene, o, hs);
  }
  hemibake::solver::Solver solver(scene, o.params);
  solve(solver);
  print_stats(solver.stats());
  return solver.mesh();
}

const char* method_name(const Options& o) {
  return o.baseline == "hr" ? "hierarchical radiosity" : o.params.method == Method::kAntiAliased ? "anti-aliased hemicube" : "classical hemicube";
}

int cornell(const Options& o) {
  const auto scene = hemibake::solver::make_cornell_box();
  std::printf("Cornell box, %s, resolution %u\n", method_name(o), o.params.resolution);
  const auto mesh = solve_builtin(scene, o);
  std::map<uint32_t, std::pair<double, double>> by_material;  // material -> (sum B*A, A)
  for (const auto& el : mesh.elements) {
    auto& [ba, a] = by_material[scene.patches[el.patch].material];
    ba += (el.radiosity.x + el.radiosity.y + el.radiosity.z) / 3.0 * el.area;
    a += el.area;
  }
  const char* names[] = {"white", "red", "green", "light"};
  for (const auto& [mat, v] : by_material)
    std::printf("  mean radiosity %-6s %.4f\n", mat < 4 ? names[mat] : "?", v.first / v.second);
  hemibake::client::Camera cam;
  cam.position = {278, 273, -800};
  cam.target = {278, 273, 0};
  cam.fov_y_degrees = 39.3;
  return render_pngs(mesh, o, o.camera.value_or(cam)) ? 0 : 1;
}

// The furnished room of the benchmarks (the paper's second scene), about `patches` patches.
int room(const Options& o) {
  const auto scene = hemibake::solver::make_furnished_room(o.patches);
  std::printf("furnished room, %zu patches, %s, resolution %u\n", scene.patches.size(), method_name(o), o.params.resolution);
  const auto mesh = solve_builtin(scene, o);
  hemibake::client::Camera cam;  // inside, from a top corner, looking at the table
  cam.position = {5.7, 2.7, 4.7};
  cam.target = {2.6, 0.5, 1.9};
  cam.fov_y_degrees = 60.0;
  return render_pngs(mesh, o, o.camera.value_or(cam)) ? 0 : 1;
}

int render_file(const Options& o) {
  if (o.input.empty() || o.output.empty()) {
    std::fputs("hemibake: render needs IN.glb -o OUT.png\n", stderr);
    return 2;
  }
  hemibake::solver::Mesh mesh;
  if (std::string err = hemibake::protocol::read_baked_mesh(o.input, mesh); !err.empty()) {
    std::fprintf(stderr, "hemibake: %s: %s\n", o.input.c_str(), err.c_str());
    return 1;
  }
  hemibake::client::RenderOptions ro;
  ro.gouraud = !o.flat;
  ro.wireframe = o.wire_flag;
  const auto rgb = hemibake::client::render(mesh, o.camera.value_or(frame(mesh)), ro);
  if (!hemibake::client::write_png(o.output, rgb, ro.width, ro.height)) {
    std::fprintf(stderr, "hemibake: cannot write %s\n", o.output.c_str());
    return 1;
  }
  std::printf("wrote %s (%zu triangles)\n", o.output.c_str(), mesh.elements.size());
  return 0;
}

int bake(const Options& o) {
  if (o.input.empty()) {
    std::fputs("hemibake: bake needs an input file\n", stderr);
    return 2;
  }
  if (o.output.empty()) {
    std::fputs("hemibake: bake needs -o OUT.glb\n", stderr);
    return 2;
  }
  const auto loaded = hemibake::protocol::load_gltf_file(o.input, o.limits);
  for (const auto& w : loaded.warnings) std::fprintf(stderr, "hemibake: warning: %s\n", w.c_str());
  if (!loaded.document) {
    std::fprintf(stderr, "hemibake: %s: %s\n", o.input.c_str(), loaded.error.c_str());
    return 1;
  }
  if (std::string e = hemibake::protocol::bake_error(*loaded.document); !e.empty()) {
    std::fprintf(stderr, "hemibake: %s: %s\n", o.input.c_str(), e.c_str());
    return 1;
  }
  const auto& scene = hemibake::protocol::scene_of(*loaded.document);
  std::printf("%s: %llu triangles, %zu patches\n", o.input.c_str(),
              static_cast<unsigned long long>(hemibake::protocol::triangle_count(*loaded.document)), scene.patches.size());
  hemibake::solver::Mesh mesh;
  hemibake::solver::Stats st;
  auto write = o.write;
  if (o.baseline == "hr") {
    hemibake::baselines::HierarchicalStats hs;
    mesh = solve_hr(scene, o, hs);
    st.elements = hs.elements;
    st.patches = scene.patches.size();
    st.seconds = hs.seconds;
    st.converged = true;
    st.unshot_fraction = 0.0;
    write.method = "hr";
  } else {
    hemibake::solver::Solver solver(scene, o.params);
    solve(solver);
    st = solver.stats();
    print_stats(st);
    mesh = solver.mesh();
    if (o.baseline == "reference") {
      // The same mesh, its vertex radiosity replaced by path-traced estimates.
      const auto rs = hemibake::baselines::apply_reference(scene, mesh, o.samples, o.params.threads);
      write.method = "reference";
      std::printf("  reference: %u paths per vertex in %.3f s, largest standard error %.4g\n", o.samples, rs.seconds,
                  rs.largest_std_error);
    }
  }
  const auto written = hemibake::protocol::write_baked_glb(*loaded.document, mesh, o.params, st, write);
  if (!written.error.empty()) {
    std::fprintf(stderr, "hemibake: %s\n", written.error.c_str());
    return 1;
  }
  std::ofstream out(o.output, std::ios::binary);
  if (!out.write(reinterpret_cast<const char*>(written.glb.data()), static_cast<std::streamsize>(written.glb.size())) ||
      !out.flush()) {
    std::fprintf(stderr, "hemibake: cannot write %s\n", o.output.c_str());
    return 1;
  }
  std::printf("  wrote %s (%zu bytes%s, exposure %.4g)\n", o.output.c_str(), written.glb.size(),
              o.write.draco ? ", Draco" : "", written.exposure);
  return render_pngs(mesh, o, o.camera.value_or(frame(mesh))) ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  // Lines as they happen, also into a pipe or a log file (a long bake's first lines would
  // otherwise wait in the buffer until it ends).
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0) {
    usage(argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  const std::string command = argv[1];
  const bool remote_command = command == "submit" || command == "status" || command == "watch" ||
                              command == "fetch" || command == "cancel" || command == "list";
  if (command != "cornell" && command != "room" && command != "bake" && command != "render" && !remote_command) {
    std::fprintf(stderr, "hemibake: unknown command '%s' (try --help)\n", argv[1]);
    return 2;
  }
  // `hemibake bake --help` asks for help, not for an option called --help.
  for (int i = 2; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      usage(stdout);
      return 0;
    }
  }
  Options o;
  if (std::string err = parse(argc, argv, 2, command != "cornell" && command != "room" && command != "list", o); !err.empty()) {
    std::fprintf(stderr, "hemibake: %s\n", err.c_str());
    return 2;
  }
  if (!o.baseline.empty() && command != "bake" && command != "submit" &&
      !(o.baseline == "hr" && (command == "cornell" || command == "room"))) {
    std::fprintf(stderr, "hemibake: --method %s is for bake and submit (hr also cornell and room) only\n", o.baseline.c_str());
    return 2;
  }
  if (command == "cornell") return cornell(o);
  if (command == "room") return room(o);
  if (command == "render") return render_file(o);
  if (command == "bake" && o.server.empty() && !std::getenv("HEMIBAKE_SERVER")) return bake(o);
  if (command == "bake" && o.server.empty()) o.server = std::getenv("HEMIBAKE_SERVER");
  // The commands that talk to a server.
  if (o.server.empty() && std::getenv("HEMIBAKE_SERVER")) o.server = std::getenv("HEMIBAKE_SERVER");
  if (o.server.empty()) {
    std::fprintf(stderr, "hemibake: %s needs a server: --server http://HOST:PORT or HEMIBAKE_SERVER\n", command.c_str());
    return 2;
  }
  hemibake::client::Remote remote;
  if (std::string err = hemibake::client::parse_server(o.server, remote); !err.empty()) {
    std::fprintf(stderr, "hemibake: %s\n", err.c_str());
    return 2;
  }
  if (const char* token = std::getenv("HEMIBAKE_TOKEN")) remote.token = token;
  hemibake::protocol::JobSpec spec;
  spec.params = o.params;
  spec.write = o.write;
  spec.write.method = o.baseline;
  spec.rays = o.rays;
  spec.samples = o.samples;
  if (command != "list" && o.input.empty()) {
    std::fprintf(stderr, "hemibake: %s needs %s\n", command.c_str(), command == "submit" || command == "bake" ? "an input file" : "a job id");
    return 2;
  }
  if (command == "bake") {
    if (o.output.empty()) {
      std::fputs("hemibake: bake needs -o OUT.glb\n", stderr);
      return 2;
    }
    return hemibake::client::remote_bake(remote, o.input, o.output, spec);
  }
  if (command == "submit") return hemibake::client::remote_submit(remote, o.input, spec);
  if (command == "status") return hemibake::client::remote_status(remote, o.input);
  if (command == "watch") return hemibake::client::remote_watch(remote, o.input);
  if (command == "cancel") return hemibake::client::remote_cancel(remote, o.input);
  if (command == "list") return hemibake::client::remote_list(remote, o.state);
  if (o.output.empty()) {
    std::fputs("hemibake: fetch needs -o OUT.glb\n", stderr);
    return 2;
  }
  return hemibake::client::remote_fetch(remote, o.input, o.output);
}
