// hemibake bake (local), cornell, room and render, and the progress they show.
#include "commands.h"

#include "hemibake/protocol/bake.h"
#include "hemibake/solver/scenes.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <map>

namespace hemibake::client {
namespace {

using protocol::Method;

double now_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void print_stats(const Console& c, const solver::Stats& st) {
  std::fprintf(c.out, "  %s after %.3f s: %llu shots of %llu shooters (%llu replayed, %llu of them partly anew), %llu hemicubes, %llu elements, unshot %.5f\n",
               st.converged ? "converged" : st.cancelled ? "cancelled" : "stopped at a limit", st.seconds,
               static_cast<unsigned long long>(st.shots), static_cast<unsigned long long>(st.shooters), static_cast<unsigned long long>(st.replayed_shots),
               static_cast<unsigned long long>(st.replays_reshot), static_cast<unsigned long long>(st.hemicubes),
               static_cast<unsigned long long>(st.elements), st.unshot_fraction);
  if (st.passes > 1)
    std::fprintf(c.out, "  first pass: %.3f s, %llu elements split where the light pools\n", st.seconds_first_pass,
                 static_cast<unsigned long long>(st.splits_pools));
  std::fprintf(c.out, "  splits: %llu (form factor %llu, visibility %llu, gradient %llu, light pools %llu), projections %llu of %llu elements in all, reused children %llu\n",
               static_cast<unsigned long long>(st.splits), static_cast<unsigned long long>(st.splits_form_factor),
               static_cast<unsigned long long>(st.splits_visibility), static_cast<unsigned long long>(st.splits_gradient),
               static_cast<unsigned long long>(st.splits_pools),
               static_cast<unsigned long long>(st.projections), static_cast<unsigned long long>(st.elements_projected),
               static_cast<unsigned long long>(st.reused_children));
  if (st.gathers > 0)
    std::fprintf(c.out, "  final gather: %llu hemicubes, %llu splits, %.3f s\n", static_cast<unsigned long long>(st.gathers),
                 static_cast<unsigned long long>(st.splits_gather), st.seconds_gathering);
  if (st.light_shots > 0)
    std::fprintf(c.out, "  lights and sky: %llu shots, %llu projections, %.3f s\n", static_cast<unsigned long long>(st.light_shots),
                 static_cast<unsigned long long>(st.light_projections), st.seconds_lights);
}

// What the solve reports after it ends: the hemicube statistics or hr's.
void print_solution(const Console& c, const protocol::JobSpec& spec, const protocol::Solution& s) {
  if (spec.method == Method::kHierarchical) {
    const auto& hs = s.hierarchical;
    std::fprintf(c.out, "  hierarchical radiosity: %.3f s (%.3f s linking), %llu links, %llu elements, %u iterations\n", hs.seconds,
                 hs.seconds_linking, static_cast<unsigned long long>(hs.links), static_cast<unsigned long long>(hs.elements),
                 hs.iterations);
    return;
  }
  print_stats(c, s.stats);
  if (spec.method == Method::kReference)
    std::fprintf(c.out, "  reference: %u paths per vertex in %.3f s, largest standard error %.4g\n", spec.samples,
                 s.reference.seconds, s.reference.largest_std_error);
}

const char* method_title(Method m) {
  switch (m) {
    case Method::kHierarchical: return "hierarchical radiosity";
    case Method::kClassical: return "classical hemicube";
    case Method::kReference: return "path-traced reference";
    case Method::kAntiAliased: break;
  }
  return "anti-aliased hemicube";
}

bool render_pngs(const solver::Mesh& mesh, const CommandLine& o, const Camera& cam, const Console& c) {
  for (const auto& [path, wire] : {std::pair{o.render_path, false}, std::pair{o.wire_path, true}}) {
    if (path.empty()) continue;
    RenderOptions ro;
    ro.gouraud = !wire;
    ro.wireframe = wire;
    ro.tone = o.spec.write.tone;
    const auto rgb = render(mesh, cam, ro);
    if (!write_png(path, rgb, ro.width, ro.height)) {
      std::fprintf(c.err, "hemibake: cannot write %s\n", path.c_str());
      return false;
    }
  }
  return true;
}

// A camera outside the scene's bounding box, looking at its centre from the -z side and above.
Camera frame(const solver::Mesh& mesh) {
  glm::dvec3 lo(1e300), hi(-1e300);
  for (const auto& p : mesh.positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const glm::dvec3 centre = 0.5 * (lo + hi);
  const double size = glm::length(hi - lo);
  Camera cam;
  cam.target = centre;
  cam.position = centre + glm::dvec3(0.0, 0.25, 1.2) * size;
  cam.fov_y_degrees = 45.0;
  return cam;
}

protocol::BakeHooks progress_hooks(ProgressPrinter& printer) {
  protocol::BakeHooks hooks;
  hooks.progress = [&printer](const protocol::JobProgress& p) { printer.update(p); };
  return hooks;
}

// A built-in scene through the pipeline, with progress and statistics.
protocol::Solution solve_builtin(const solver::Scene& scene, const CommandLine& o, const Console& c) {
  // A built-in scene keeps its own sky (the atrium's) unless --sky gives one: the job's sky, 0 by
  // default, would otherwise take its place.
  protocol::JobSpec spec = o.spec;
  if (spec.sky == glm::dvec3(0.0)) spec.sky = scene.sky;
  protocol::Solution s;
  {
    ProgressPrinter printer(c);
    s = protocol::solve(scene, spec, progress_hooks(printer));
  }
  print_solution(c, spec, s);
  return s;
}

}  // namespace

void ProgressPrinter::update(const protocol::JobProgress& p) {
  if (p.phase == "done" || p.phase == "cancelled") return finish();
  const bool shooting = p.phase == "shooting";
  // The first shots say little about the time left.
  const double eta = p.elapsed_seconds >= 1.0 ? p.eta_seconds : -1.0;
  if (!console_.tty) {
    // A line every `interval_` seconds and when a phase starts, once the bake has taken that long:
    // a log shows a long bake moving, a short one stays quiet.
    const double now = now_seconds();
    if (start_ < 0.0) start_ = now;
    if (now - start_ < interval_ || (p.phase == phase_ && now - last_ < interval_)) return;
    phase_ = p.phase;
    last_ = now;
    if (shooting)
      std::fprintf(console_.err, "  shooting: %llu shots, unshot %.5f, %llu elements, %.1f s%s\n",
                   static_cast<unsigned long long>(p.shots), p.unshot_fraction, static_cast<unsigned long long>(p.elements),
                   p.elapsed_seconds, eta >= 0 ? (", about " + std::to_string(static_cast<long>(eta)) + " s left").c_str() : "");
    else
      std::fprintf(console_.err, "  %s: %.1f %%, %.1f s\n", p.phase.c_str(), 100.0 * std::clamp(p.fraction, 0.0, 1.0), p.elapsed_seconds);
    std::fflush(console_.err);
    return;
  }
  open_ = true;
  const double done = std::clamp(p.fraction, 0.0, 1.0);
  const int width = 24, filled = static_cast<int>(done * width);
  if (!shooting) {
    std::fprintf(console_.err, "\r  [%.*s%*s] %-9s %5.1f %%  %6.1f s%40s", filled, "########################", width - filled, "",
                 p.phase.c_str(), 100.0 * done, p.elapsed_seconds, "");
    return;
  }
  std::fprintf(console_.err, "\r  [%.*s%*s] shots %6llu  unshot %8.5f  elements %7llu  %6.1f s%s", filled,
               "########################", width - filled, "", static_cast<unsigned long long>(p.shots), p.unshot_fraction,
               static_cast<unsigned long long>(p.elements), p.elapsed_seconds,
               eta >= 0 ? ("  ~" + std::to_string(static_cast<long>(eta)) + " s left ").c_str() : "          ");
}

void ProgressPrinter::finish() {
  if (!open_) return;
  open_ = false;
  std::fputs("\n", console_.err);
}

int run_cornell(const CommandLine& o, const Console& c) {
  const auto scene = solver::make_cornell_box();
  std::fprintf(c.out, "Cornell box, %s, resolution %u\n", method_title(o.spec.method), o.spec.params.resolution);
  const auto solution = solve_builtin(scene, o, c);
  std::map<uint32_t, std::pair<double, double>> by_material;  // material -> (sum B*A, A)
  for (const auto& el : solution.mesh.elements) {
    auto& [ba, a] = by_material[scene.patches[el.patch].material];
    ba += (el.radiosity.x + el.radiosity.y + el.radiosity.z) / 3.0 * el.area;
    a += el.area;
  }
  const char* names[] = {"white", "red", "green", "light"};
  for (const auto& [mat, v] : by_material)
    std::fprintf(c.out, "  mean radiosity %-6s %.4f\n", mat < 4 ? names[mat] : "?", v.first / v.second);
  Camera cam;
  cam.position = {278, 273, -800};
  cam.target = {278, 273, 0};
  cam.fov_y_degrees = 39.3;
  return render_pngs(solution.mesh, o, o.camera.value_or(cam), c) ? 0 : 1;
}

// A built-in scene: its size, the solve, and renders from `cam` unless --camera says otherwise.
int run_builtin(const char* title, const solver::Scene& scene, const Camera& cam, const CommandLine& o, const Console& c) {
  std::fprintf(c.out, "%s, %zu patches, %s, resolution %u\n", title, scene.patches.size(), method_title(o.spec.method),
               o.spec.params.resolution);
  const auto solution = solve_builtin(scene, o, c);
  return render_pngs(solution.mesh, o, o.camera.value_or(cam), c) ? 0 : 1;
}

Camera camera_at(const glm::dvec3& position, const glm::dvec3& target) {
  Camera cam;
  cam.position = position;
  cam.target = target;
  cam.fov_y_degrees = 60.0;
  return cam;
}

// The furnished room of the benchmarks (the paper's second scene), about `patches` patches.
int run_room(const CommandLine& o, const Console& c) {
  // Inside, from a top corner, looking at the table.
  return run_builtin("furnished room", solver::make_furnished_room(o.patches), camera_at({5.7, 2.7, 4.7}, {2.6, 0.5, 1.9}), o, c);
}

// The cluttered room of the benchmarks: furniture with legs and about 390 small boxes.
int run_clutter(const CommandLine& o, const Console& c) {
  // Inside, from a top corner, looking over the tables.
  return run_builtin("cluttered room", solver::make_cluttered_room(), camera_at({7.7, 2.7, 5.7}, {3.5, 0.5, 2.5}), o, c);
}

// Many small emitters: lava spheres lighting a floor and 36 objects.
int run_lava(const CommandLine& o, const Console& c) {
  return run_builtin("lava field", solver::make_lava_field(), camera_at({12.0, 8.0, 12.0}, {0.0, 0.0, 0.0}), o, c);
}

// A big input: a Sponza-like atrium under the sky and a sun.
int run_atrium(const CommandLine& o, const Console& c) {
  return run_builtin("atrium", solver::make_atrium(), camera_at({-10.0, 6.5, -3.5}, {6.0, 3.0, 3.0}), o, c);
}

int run_render(const CommandLine& o, const Console& c) {
  if (o.input.empty() || o.output.empty()) {
    std::fputs("hemibake: render needs IN.glb -o OUT.png\n", c.err);
    return 2;
  }
  solver::Mesh mesh;
  if (std::string err = protocol::read_baked_mesh(o.input, mesh); !err.empty()) {
    std::fprintf(c.err, "hemibake: %s: %s\n", o.input.c_str(), err.c_str());
    return 1;
  }
  RenderOptions ro;
  ro.gouraud = !o.flat;
  ro.wireframe = o.wireframe;
  ro.tone = o.spec.write.tone;
  const auto rgb = render(mesh, o.camera.value_or(frame(mesh)), ro);
  if (!write_png(o.output, rgb, ro.width, ro.height)) {
    std::fprintf(c.err, "hemibake: cannot write %s\n", o.output.c_str());
    return 1;
  }
  std::fprintf(c.out, "wrote %s (%zu triangles)\n", o.output.c_str(), mesh.elements.size());
  return 0;
}

int run_bake(const CommandLine& o, const Console& c) {
  if (o.input.empty()) {
    std::fputs("hemibake: bake needs an input file\n", c.err);
    return 2;
  }
  if (o.output.empty()) {
    std::fputs("hemibake: bake needs -o OUT.glb\n", c.err);
    return 2;
  }
  const auto loaded = protocol::load_gltf_file(o.input, o.limits);
  for (const auto& w : loaded.warnings) std::fprintf(c.err, "hemibake: warning: %s\n", w.c_str());
  if (!loaded.document) {
    std::fprintf(c.err, "hemibake: %s: %s\n", o.input.c_str(), loaded.error.c_str());
    return 1;
  }
  if (std::string e = protocol::bake_error(*loaded.document, o.spec); !e.empty()) {
    std::fprintf(c.err, "hemibake: %s: %s\n", o.input.c_str(), e.c_str());
    return 1;
  }
  std::fprintf(c.out, "%s: %llu triangles, %zu patches\n", o.input.c_str(),
               static_cast<unsigned long long>(protocol::triangle_count(*loaded.document)),
               protocol::scene_of(*loaded.document).patches.size());
  protocol::BakeOutput baked;
  {
    ProgressPrinter printer(c);
    baked = protocol::bake(*loaded.document, o.spec, progress_hooks(printer));
  }
  print_solution(c, o.spec, baked.solution);
  if (!baked.error.empty()) {
    std::fprintf(c.err, "hemibake: %s\n", baked.error.c_str());
    return 1;
  }
  std::ofstream out(o.output, std::ios::binary);
  if (!out.write(reinterpret_cast<const char*>(baked.glb.data()), static_cast<std::streamsize>(baked.glb.size())) ||
      !out.flush()) {
    std::fprintf(c.err, "hemibake: cannot write %s\n", o.output.c_str());
    return 1;
  }
  std::fprintf(c.out, "  wrote %s (%zu bytes%s, exposure %.4g", o.output.c_str(), baked.glb.size(),
               o.spec.write.draco ? ", Draco" : "", baked.exposure);
  // How far above the clip point the brightest lit surface lies.
  if (baked.tone.scale > 0.0)
    std::fprintf(c.out, ", highlights rolled off from %.2g to 1 at %.4g", baked.tone.knee, baked.tone.white);
  std::fprintf(c.out, ")\n");
  return render_pngs(baked.solution.mesh, o, o.camera.value_or(frame(baked.solution.mesh)), c) ? 0 : 1;
}

}  // namespace hemibake::client
