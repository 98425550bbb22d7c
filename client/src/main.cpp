// The `hemibake` command line.
#include "render.h"

#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <unistd.h>

namespace {

using hemibake::solver::Method;
using hemibake::solver::Params;

void usage(FILE* out) {
  std::fputs(
      "usage: hemibake cornell [options]\n"
      "  Bakes the built-in Cornell box and prints a summary.\n"
      "options (the paper's names):\n"
      "  --method aa|classical   form factors: anti-aliased (default) or classical hemicube\n"
      "  --resolution N          hemicube resolution (default 100)\n"
      "  --feps X                form-factor tolerance (default 0.001)\n"
      "  --aeps X                minimum element area / scene area (default 0.0001)\n"
      "  --beps X                radiosity tolerance (default 0.03)\n"
      "  --convergence X         stop at unshot/emitted power below X (default 0.001)\n"
      "  --max-shots N           shot limit\n"
      "  --max-elements N        element limit\n"
      "  --threads N             threads (default: all cores)\n"
      "  --no-reuse              re-project the scene after splits instead of reusing pixels\n"
      "  --render FILE.png       also render the result (Gouraud) to a PNG\n"
      "  --wireframe FILE.png    also render the mesh (flat, with element edges) to a PNG\n",
      out);
}

bool parse_number(const char* text, double& out) {
  char* end = nullptr;
  out = std::strtod(text, &end);
  return end != text && *end == '\0';
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0) {
    usage(argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  if (std::strcmp(argv[1], "cornell") != 0) {
    std::fprintf(stderr, "hemibake: unknown command '%s'\n", argv[1]);
    usage(stderr);
    return 2;
  }
  Params params;
  std::string render_path, wire_path;
  for (int i = 2; i < argc; ++i) {
    const std::string opt = argv[i];
    if (opt == "--no-reuse") {
      params.reuse_visibility = false;
      continue;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "hemibake: %s needs a value\n", opt.c_str());
      return 2;
    }
    const char* val = argv[++i];
    if (opt == "--render" || opt == "--wireframe") {
      (opt == "--render" ? render_path : wire_path) = val;
      continue;
    }
    if (opt == "--method") {
      if (std::strcmp(val, "aa") == 0) params.method = Method::kAntiAliased;
      else if (std::strcmp(val, "classical") == 0) params.method = Method::kClassical;
      else {
        std::fprintf(stderr, "hemibake: --method must be aa or classical (got '%s')\n", val);
        return 2;
      }
      continue;
    }
    double x = 0.0;
    if (!parse_number(val, x)) {
      std::fprintf(stderr, "hemibake: %s needs a number (got '%s')\n", opt.c_str(), val);
      return 2;
    }
    if (opt == "--resolution") params.resolution = static_cast<uint32_t>(x);
    else if (opt == "--feps") params.feps = x;
    else if (opt == "--aeps") params.aeps = x;
    else if (opt == "--beps") params.beps = x;
    else if (opt == "--convergence") params.convergence = x;
    else if (opt == "--max-shots") params.max_shots = static_cast<uint64_t>(x);
    else if (opt == "--max-elements") params.max_elements = static_cast<uint64_t>(x);
    else if (opt == "--threads") params.threads = static_cast<uint32_t>(x);
    else {
      std::fprintf(stderr, "hemibake: unknown option '%s'\n", opt.c_str());
      usage(stderr);
      return 2;
    }
  }
  if (std::string err = hemibake::solver::validate(params); !err.empty()) {
    std::fprintf(stderr, "hemibake: %s\n", err.c_str());
    return 2;
  }
  const auto scene = hemibake::solver::make_cornell_box();
  hemibake::solver::Solver solver(scene, params);
  const bool tty = isatty(STDERR_FILENO);
  const auto& st = solver.run([&](const hemibake::solver::Progress& p) {
    if (tty)
      std::fprintf(stderr, "\r  shots %6llu  unshot %8.5f  elements %7llu  %6.2f s ",
                   static_cast<unsigned long long>(p.shots), p.unshot_fraction,
                   static_cast<unsigned long long>(p.elements), p.elapsed_seconds);
  });
  if (tty) std::fputs("\n", stderr);
  const auto mesh = solver.mesh();
  std::map<uint32_t, std::pair<double, double>> by_material;  // material -> (sum B*A, A)
  for (const auto& el : mesh.elements) {
    auto& [ba, a] = by_material[scene.patches[el.patch].material];
    ba += (el.radiosity.x + el.radiosity.y + el.radiosity.z) / 3.0 * el.area;
    a += el.area;
  }
  std::printf("Cornell box, %s hemicube, resolution %u\n",
              params.method == Method::kAntiAliased ? "anti-aliased" : "classical", params.resolution);
  std::printf("  %s after %.3f s: %llu shots, %llu hemicubes, %llu elements, unshot %.5f\n",
              st.converged ? "converged" : "stopped", st.seconds,
              static_cast<unsigned long long>(st.shots), static_cast<unsigned long long>(st.hemicubes),
              static_cast<unsigned long long>(st.elements), st.unshot_fraction);
  std::printf("  splits: %llu (form factor %llu, visibility %llu, gradient %llu), projections %llu, reused children %llu\n",
              static_cast<unsigned long long>(st.splits), static_cast<unsigned long long>(st.splits_form_factor),
              static_cast<unsigned long long>(st.splits_visibility), static_cast<unsigned long long>(st.splits_gradient),
              static_cast<unsigned long long>(st.projections), static_cast<unsigned long long>(st.reused_children));
  const char* names[] = {"white", "red", "green", "light"};
  for (const auto& [mat, v] : by_material)
    std::printf("  mean radiosity %-6s %.4f\n", mat < 4 ? names[mat] : "?", v.first / v.second);
  hemibake::client::Camera cam;
  cam.position = {278, 273, -800};
  cam.target = {278, 273, 0};
  cam.fov_y_degrees = 39.3;
  for (const auto& [path, wire] : {std::pair{render_path, false}, std::pair{wire_path, true}}) {
    if (path.empty()) continue;
    hemibake::client::RenderOptions ro;
    ro.gouraud = !wire;
    ro.wireframe = wire;
    const auto rgb = hemibake::client::render(mesh, cam, ro);
    if (!hemibake::client::write_png(path, rgb, ro.width, ro.height)) {
      std::fprintf(stderr, "hemibake: cannot write %s\n", path.c_str());
      return 1;
    }
  }
  return 0;
}
