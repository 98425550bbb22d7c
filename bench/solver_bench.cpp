// The solver's benchmark: the Cornell box at the paper's settings in both form-factor modes, the
// cost of re-projecting against reusing the parent's pixels, and how the cost of one hemicube grows
// with the number of elements. Each configuration runs in a child process so that its peak memory
// is its own. Prints markdown tables (see bench/README.md).
#include "display_error.h"
#include "hemibake/baselines/reference.h"
#include "hemibake/protocol/bake.h"
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"

#include <glm/geometric.hpp>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <cstring>
#include <algorithm>
#include <atomic>
#include <map>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace hemibake::solver;
using hemibake::protocol::JobSpec;

struct Result {
  Stats stats;
  long peak_kib = 0;
};

// Runs fn() (returning a trivially copyable T) in a forked child and returns its result; the
// child's peak resident memory goes to *peak_kib.
template <typename T, typename Fn>
T isolated_value(Fn fn, long* peak_kib) {
  int fds[2];
  if (pipe(fds) != 0) std::abort();
  const pid_t pid = fork();
  if (pid == 0) {
    close(fds[0]);
    struct {
      T value;
      long peak;
    } out{fn(), 0};
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    out.peak = ru.ru_maxrss;
    if (write(fds[1], &out, sizeof out) != static_cast<ssize_t>(sizeof out)) _exit(1);
    _exit(0);
  }
  close(fds[1]);
  struct {
    T value;
    long peak;
  } in{};
  size_t got = 0;
  while (got < sizeof in) {
    const ssize_t n = read(fds[0], reinterpret_cast<char*>(&in) + got, sizeof in - got);
    if (n <= 0) break;
    got += static_cast<size_t>(n);
  }
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (got != sizeof in) {
    std::fprintf(stderr, "benchmark child failed\n");
    std::exit(1);
  }
  if (peak_kib != nullptr) *peak_kib = in.peak;
  return in.value;
}

template <typename Fn>
Result isolated(Fn fn) {
  Result r;
  r.stats = isolated_value<Stats>(fn, &r.peak_kib);
  return r;
}

// A mesh's error against the path-traced reference at its element centres (emitters left out:
// they are exact), as fractions of the reference's mean radiosity (luminance = mean of RGB).
struct Error {
  double rms = 0.0;        // RMS error
  double rms_clean = 0.0;  // with the reference's own variance subtracted
  double max = 0.0;        // largest absolute error
  double ref_se = 0.0;     // the reference's RMS standard error
  double energy = 0.0;     // sum B A / the reference's
};

Error error_of(const Scene& scene, const Mesh& mesh, uint32_t samples) {
  const hemibake::baselines::Reference reference(scene);
  std::vector<uint32_t> todo;
  for (uint32_t i = 0; i < mesh.elements.size(); ++i)
    if (scene.patches[mesh.elements[i].patch].emission == glm::dvec3(0.0)) todo.push_back(i);
  std::vector<double> ref(todo.size()), se(todo.size());
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t k; (k = next.fetch_add(1)) < todo.size();) {
      const auto& el = mesh.elements[todo[k]];
      glm::dvec3 c(0.0);
      for (uint32_t j = 0; j < el.corner_count; ++j) c += mesh.positions[el.corners[j]];
      c /= static_cast<double>(el.corner_count);
      const auto r = reference.radiosity_at(el.patch, c, samples, todo[k] + 1);
      ref[k] = (r.radiosity.x + r.radiosity.y + r.radiosity.z) / 3.0;
      se[k] = std::sqrt((r.std_error.x * r.std_error.x + r.std_error.y * r.std_error.y + r.std_error.z * r.std_error.z) / 3.0);
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 0; t < std::max(1u, std::thread::hardware_concurrency()); ++t) pool.emplace_back(work);
  for (auto& t : pool) t.join();
  double err2 = 0.0, se2 = 0.0, worst = 0.0, sum_ref = 0.0, sum_refa = 0.0, sum_ba = 0.0;
  for (size_t k = 0; k < todo.size(); ++k) {
    const auto& el = mesh.elements[todo[k]];
    const double b = (el.radiosity.x + el.radiosity.y + el.radiosity.z) / 3.0;
    err2 += (b - ref[k]) * (b - ref[k]);
    se2 += se[k] * se[k];
    worst = std::max(worst, std::abs(b - ref[k]));
    sum_ref += ref[k];
    sum_refa += ref[k] * el.area;
    sum_ba += b * el.area;
  }
  const double n = static_cast<double>(std::max<size_t>(1, todo.size())), mean = sum_ref / n;
  return {std::sqrt(err2 / n) / mean, std::sqrt(std::max(0.0, err2 - se2) / n) / mean, worst / mean,
          std::sqrt(se2 / n) / mean, sum_ba / sum_refa};
}

// One method on one scene: time, counters, error and memory.
struct Run {
  char method[24] = {};
  uint32_t threads = 0;
  double seconds = 0.0;
  uint64_t shots = 0;       // aa / classical: shots; hr: gathering iterations
  uint64_t hemicubes = 0;
  uint64_t replayed = 0;    // aa / classical: shots that replayed an earlier shot's form factors
  uint64_t elements = 0;
  uint64_t links = 0;
  Error error;
  double shown_median = 0.0, shown_p90 = 0.0, shown_max = 0.0;  // as displayed (display_error.h)
  // As displayed, per region of the points (run_method's `region`): points, median error, and the
  // bake's light over the reference's.
  static constexpr int kRegions = 8;
  uint32_t region_points[kRegions] = {};
  double region_median[kRegions] = {}, region_ratio[kRegions] = {};
  long peak_kib = 0;
};

// Which region of a bench table a point of the displayed-error measure belongs to (0 to
// Run::kRegions - 1), or -1 for none.
using RegionOf = std::function<int(const hemibake::bench::SurfacePoint&)>;

// The per-region figures of `shown` at the points a viewer sees into `out` (Run::region_*).
void region_figures(const std::vector<hemibake::bench::SurfacePoint>& points, const Mesh& mesh,
                    const hemibake::bench::DisplayError& shown, RegionOf region, Run& out) {
  std::vector<double> errors[Run::kRegions];
  double bake[Run::kRegions] = {}, ref[Run::kRegions] = {};
  const double slack = hemibake::bench::plane_slack(mesh);
  for (size_t i = 0; i < points.size(); ++i) {
    const int r = region(points[i]);
    if (r < 0 || r >= Run::kRegions || shown.hidden[i]) continue;
    glm::dvec3 v(0.0);
    hemibake::bench::displayed_value(mesh, points[i].position, points[i].normal, slack, v);
    errors[r].push_back(shown.errors[i]);
    bake[r] += v.x + v.y + v.z;
    ref[r] += points[i].reference.x + points[i].reference.y + points[i].reference.z;
  }
  for (int r = 0; r < Run::kRegions; ++r) {
    out.region_points[r] = static_cast<uint32_t>(errors[r].size());
    if (errors[r].empty()) continue;
    std::sort(errors[r].begin(), errors[r].end());
    out.region_median[r] = errors[r][errors[r].size() / 2];
    out.region_ratio[r] = ref[r] > 0.0 ? bake[r] / ref[r] : 0.0;
  }
}

// Runs `method` ("aa", "classical" or "hr") with `threads` on `scene` in a child process, through
// the bake pipeline with the settings of `base`; the error against the reference (`samples` paths
// per element) is measured after the clock stops. With `repeats` > 1 the solve runs that many times
// and the fastest counts (this machine is shared).
Run run_method(const Scene& scene, const std::string& method, uint32_t threads, uint32_t samples,
               const hemibake::protocol::JobSpec& base = {}, uint32_t repeats = 1,
               const std::vector<hemibake::bench::SurfacePoint>* points = nullptr, RegionOf region = nullptr) {
  long peak = 0;
  Run r = isolated_value<Run>(
      [&] {
        Run out;
        std::snprintf(out.method, sizeof out.method, "%s", method.c_str());
        out.threads = threads;
        hemibake::protocol::JobSpec spec = base;
        spec.method = *hemibake::protocol::method_from(method);
        spec.params.threads = threads;
        Mesh mesh;
        out.seconds = 1e300;
        for (uint32_t rep = 0; rep < std::max(1u, repeats); ++rep) {
          auto s = hemibake::protocol::solve(scene, spec);
          out.seconds = std::min(out.seconds, s.stats.seconds);
          if (spec.method == hemibake::protocol::Method::kHierarchical) {
            out.shots = s.hierarchical.iterations;
            out.links = s.hierarchical.links;
          } else {
            out.shots = s.stats.shots;
            out.hemicubes = s.stats.hemicubes;
            out.replayed = s.stats.replayed_shots;
          }
          mesh = std::move(s.mesh);
        }
        out.elements = mesh.elements.size();
        if (samples > 0) out.error = error_of(scene, mesh, samples);
        if (points != nullptr) {
          const hemibake::bench::DisplayError shown = hemibake::bench::displayed_error(*points, mesh);
          out.shown_median = shown.seen.median;
          out.shown_p90 = shown.seen.p90;
          out.shown_max = shown.seen.max;
          if (region != nullptr) region_figures(*points, mesh, shown, region, out);
        }
        return out;
      },
      &peak);
  r.peak_kib = peak;
  return r;
}

void print_runs_header() {
  std::printf("| method | threads | time (s) | shots (hr: iterations) | replayed shots | hemicubes | elements | links | "
              "shown: median error | shown: p90 | shown: max | centres: RMS error | centres: RMS, reference noise removed | "
              "centres: max error | energy / reference's | peak memory (MB) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
}

void print_run(const Run& r) {
  std::printf("| %s | %s | %.3f | %llu | %llu | %llu | %llu | %llu | %.1f %% | %.1f %% | %.0f %% | %.4f | %.4f | %.4f | %.4f | %.1f |\n",
              r.method, r.threads == 0 ? "all" : std::to_string(r.threads).c_str(),
              r.seconds, static_cast<unsigned long long>(r.shots), static_cast<unsigned long long>(r.replayed),
              static_cast<unsigned long long>(r.hemicubes),
              static_cast<unsigned long long>(r.elements), static_cast<unsigned long long>(r.links),
              100.0 * r.shown_median, 100.0 * r.shown_p90, 100.0 * r.shown_max, r.error.rms,
              r.error.rms_clean, r.error.max, r.error.energy, r.peak_kib / 1024.0);
  std::fflush(stdout);
}

Stats solve_stats(const Scene& scene, const JobSpec& spec) { return hemibake::protocol::solve(scene, spec).stats; }

// Equal quality: each method at several settings, its error as displayed (p90 over the points,
// display_error.h) and its time; prints the time each needs to reach the best p90 that aa and hr
// both reach, and their ratio.
void sweep(const Scene& scene, const char* title, const std::vector<hemibake::bench::SurfacePoint>& points,
           const std::vector<std::pair<std::string, std::vector<JobSpec>>>& methods,
           const std::vector<std::string>& labels, uint32_t repeats) {
  std::printf("## Time against error as displayed (%s; all threads; %zu random surface points)\n\n", title,
              points.size());
  std::printf("| method | setting | time (s) | elements | links | median error | p90 error | max error |\n"
              "|---|---|---|---|---|---|---|---|\n");
  std::vector<Run> runs;
  size_t label = 0;
  for (const auto& [method, specs] : methods) {
    for (const JobSpec& spec : specs) {
      runs.push_back(run_method(scene, method, 0, 0, spec, repeats, &points));
      const Run& r = runs.back();
      std::printf("| %s | %s | %.3f | %llu | %llu | %.1f %% | %.1f %% | %.0f %% |\n", method.c_str(),
                  labels[label++].c_str(), r.seconds, static_cast<unsigned long long>(r.elements),
                  static_cast<unsigned long long>(r.links), 100.0 * r.shown_median, 100.0 * r.shown_p90,
                  100.0 * r.shown_max);
      std::fflush(stdout);
    }
  }
  auto best = [&](const char* m) {
    double b = 1e300;
    for (const Run& r : runs)
      if (std::strcmp(r.method, m) == 0) b = std::min(b, r.shown_p90);
    return b;
  };
  const double target = std::max(best("aa"), best("hr"));
  auto time_to = [&](const char* m) {
    double t = 1e300;
    for (const Run& r : runs)
      if (std::strcmp(r.method, m) == 0 && r.shown_p90 <= target * 1.01) t = std::min(t, r.seconds);
    return t;
  };
  std::printf("\nTo reach a p90 error of %.1f %% (within 1 %%): aa %.3f s, hr %.3f s; hr / aa = %.2f\n\n",
              100.0 * target, time_to("aa"), time_to("hr"), time_to("hr") / time_to("aa"));
}

// The points of the displayed-error measure and their reference, once per scene; the tables give
// the error over the points a viewer can see (DisplayError::seen).
std::vector<hemibake::bench::SurfacePoint> points_of(const Scene& scene, uint32_t count) {
  hemibake::bench::ReferenceOptions options;
  options.points = count;
  return hemibake::bench::reference_points(scene, options);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  const bool quick = mode == "--quick";
  if (!mode.empty() && !quick && mode != "--sweep" && mode != "--sweep-room" && mode != "--chamber" && mode != "--scaling" && mode != "--lights" &&
      mode != "--cluttered" && mode != "--lava" && mode != "--big") {
    std::fprintf(stderr, "usage: hemibake-bench [--quick | --sweep | --sweep-room | --chamber | --scaling | --lights | --cluttered | --lava | --big]\n");
    return 2;
  }
  const Scene cornell = make_cornell_box();
  if (mode == "--sweep" || mode == "--sweep-room") {
    // Cornell box: aa's radiosity tolerance against hr's FEPS. On the furnished room at the paper's
    // AEPS neither method subdivides (its patches are below 4 x AEPS), so what sets their accuracy
    // is aa's hemicube resolution and hr's visibility rays per link.
    const bool room = mode == "--sweep-room";
    std::vector<std::pair<std::string, std::vector<JobSpec>>> methods{{"aa", {}}, {"classical", {}}, {"hr", {}}};
    std::vector<std::string> labels;
    auto label = [&](const char* format, double v) {
      char text[64];
      std::snprintf(text, sizeof text, format, v);
      labels.emplace_back(text);
    };
    for (int m = 0; m < 2; ++m) {
      for (const double v : room ? std::vector<double>{50, 100, 140, 200} : std::vector<double>{0.1, 0.03, 0.01, 0.003}) {
        methods[m].second.emplace_back();
        if (room) methods[m].second.back().params.resolution = static_cast<uint32_t>(v);
        else methods[m].second.back().params.beps = v;
        label(room ? "resolution %g" : "beps %g", v);
      }
      if (m != 0) continue;
      // aa with the final gather (off by default), for what it gives.
      for (const double v : room ? std::vector<double>{100} : std::vector<double>{0.03, 0.003}) {
        methods[0].second.emplace_back();
        methods[0].second.back().params.gather = true;
        if (room) methods[0].second.back().params.resolution = static_cast<uint32_t>(v);
        else methods[0].second.back().params.beps = v;
        label(room ? "resolution %g, gather" : "beps %g, gather", v);
      }
    }
    for (const double v : room ? std::vector<double>{1, 4, 8, 16} : std::vector<double>{0.01, 0.003, 0.001, 0.0003}) {
      methods[2].second.emplace_back();
      if (room) methods[2].second.back().rays = static_cast<uint32_t>(v);
      else methods[2].second.back().params.feps = v;
      label(room ? "%g rays per link" : "FEPS %g", v);
    }
    const Scene scene = room ? make_furnished_room() : cornell;
    const auto points = points_of(scene, room ? 200 : 300);
    sweep(scene, room ? "furnished room, 6758 patches" : "Cornell box", points, methods, labels, room ? 1 : 3);
    return 0;
  }
  if (mode == "--lights") {
    // What lights and a sky cost on the furnished room, next to the same room lit by its panels.
    // Sun and sky only reach the inside with the ceiling open, so the room is also baked roofless.
    std::printf("## Lights on the furnished room (resolution 100, FEPS 0.001, AEPS 0.0001, unshot < 0.001, all threads)\n\n");
    std::printf("| scene | light | time (s) | of which lights (s) | shots | light shots | light projections | elements | peak memory (MB) |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|\n");
    const Scene room = make_furnished_room();
    double top = -1e300;
    for (const Patch& p : room.patches)
      for (uint32_t k = 0; k < p.corner_count; ++k) top = std::max(top, p.corners[k].y);
    Scene dark = room, open = room;
    for (Patch& p : dark.patches) p.emission = glm::dvec3(0.0);
    open.patches.clear();
    for (const Patch& p : dark.patches) {
      bool ceiling = true;
      for (uint32_t k = 0; k < p.corner_count; ++k) ceiling = ceiling && p.corners[k].y > top - 1e-9;
      if (!ceiling) open.patches.push_back(p);
    }
    Light bulb;
    bulb.type = Light::Type::kPoint;
    bulb.position = glm::dvec3(3.0, 2.5, 2.5);
    bulb.intensity = glm::dvec3(20.0);
    Light sun;
    sun.type = Light::Type::kDirectional;
    sun.direction = glm::normalize(glm::dvec3(0.4, -1.0, 0.3));
    sun.intensity = glm::dvec3(50.0);
    struct Case {
      const char* scene;
      const char* light;
      Scene s;
    };
    std::vector<Case> cases;
    cases.push_back({"furnished room", "its ceiling panels", room});
    Scene with_bulb = dark;
    with_bulb.lights.push_back(bulb);
    cases.push_back({"furnished room, panels off", "a point light", with_bulb});
    Scene with_sun = open;
    with_sun.lights.push_back(sun);
    cases.push_back({"roofless room, panels off", "a sun", with_sun});
    Scene with_sky = open;
    with_sky.sky = glm::dvec3(5.0);
    cases.push_back({"roofless room, panels off", "a sky", with_sky});
    for (const Case& c : cases) {
      long peak = 0;
      const Stats st = isolated_value<Stats>(
          [&] {
            Params params;
            Solver solver(c.s, params);
            return solver.run();
          },
          &peak);
      std::printf("| %s (%zu patches) | %s | %.2f | %.2f | %llu | %llu | %llu | %llu | %.0f |\n", c.scene, c.s.patches.size(), c.light,
                  st.seconds, st.seconds_lights, static_cast<unsigned long long>(st.shots), static_cast<unsigned long long>(st.light_shots),
                  static_cast<unsigned long long>(st.light_projections), static_cast<unsigned long long>(st.elements),
                  peak / 1024.0);
    }
    std::printf("\n");
    return 0;
  }
  if (mode == "--chamber") {
    // The paper's second experiment: a furnished room of about 6300 patches (minutes, so on demand).
    const Scene room = make_furnished_room();
    std::printf("## Furnished room (%zu patches; resolution 100, FEPS 0.001, AEPS 0.0001, unshot < 0.001; "
                "reference 256 paths per element centre)\n\n",
                room.patches.size());
    const auto points = points_of(room, 200);
    print_runs_header();
    for (const char* m : {"aa", "classical", "hr"}) print_run(run_method(room, m, 0, 256, {}, 1, &points));
    JobSpec fresh;
    fresh.params.shot_cache_mb = 0;
    Run r = run_method(room, "aa", 0, 256, fresh);
    std::snprintf(r.method, sizeof r.method, "aa, no replays");
    print_run(r);
    JobSpec alone;
    alone.params.cluster_size = 0.0;
    r = run_method(room, "aa", 0, 256, alone);
    std::snprintf(r.method, sizeof r.method, "aa, no clusters");
    print_run(r);
    std::printf("\n");
    return 0;
  }
  if (mode == "--cluttered") {
    // Many small objects: the cluttered room (tiles, furniture with legs, ~390 small boxes) and the
    // furnished room, aa (volume clusters, clusters by orientation, clusters within surfaces only)
    // against hr, error as displayed (200 points).
    for (int which = 0; which < 2; ++which) {
      const Scene room = which == 0 ? make_cluttered_room() : make_furnished_room();
      std::printf("## %s (%zu patches; resolution 100, FEPS 0.001, AEPS 0.0001, unshot < 0.001; one run each)\n\n",
                  which == 0 ? "Cluttered room" : "Furnished room", room.patches.size());
      const auto points = points_of(room, 200);
      print_runs_header();
      print_run(run_method(room, "aa", 0, 0, {}, 1, &points));
      JobSpec by_orientation;
      by_orientation.params.cluster_volume = false;
      Run r = run_method(room, "aa", 0, 0, by_orientation, 1, &points);
      std::snprintf(r.method, sizeof r.method, "aa, no volume clusters");
      print_run(r);
      JobSpec within;
      within.params.cluster_across = false;
      r = run_method(room, "aa", 0, 0, within, 1, &points);
      std::snprintf(r.method, sizeof r.method, "aa, within surfaces");
      print_run(r);
      print_run(run_method(room, "hr", 0, 0, {}, 1, &points));
      std::printf("\n");
    }
    return 0;
  }
  if (mode == "--lava") {
    // Many small emitters (issue 18, item 4): the lava field's six glowing spheres light a 20 x 20 m
    // floor among 36 objects. Error as displayed at 600 points, and on the floor by distance from
    // the nearest lava sphere's foot: its light pools.
    const Scene field = make_lava_field();
    const auto points = points_of(field, 600);
    // The lava spheres' feet: the mean corner of each emitting material's patches, on the floor.
    std::map<uint32_t, std::pair<glm::dvec3, double>> lava;
    for (const Patch& p : field.patches)
      if (p.emission.x > 0.0)
        for (uint32_t k = 0; k < p.corner_count; ++k) {
          lava[p.material].first += p.corners[k];
          lava[p.material].second += 1.0;
        }
    std::vector<glm::dvec3> feet;
    for (const auto& [material, sum] : lava) feet.push_back(sum.first / sum.second);
    auto region = [feet](const hemibake::bench::SurfacePoint& p) {
      if (p.normal.y < 0.99 || std::abs(p.position.y) > 1e-6) return 5;  // the objects
      double d = 1e300;
      for (const glm::dvec3& f : feet) d = std::min(d, std::hypot(p.position.x - f.x, p.position.z - f.z));
      return d < 1.0 ? 0 : d < 2.0 ? 1 : d < 3.0 ? 2 : d < 5.0 ? 3 : 4;
    };
    std::printf("## Lava field (%zu patches, six emissive spheres; default settings; one run each; 600 points)\n\n",
                field.patches.size());
    print_runs_header();
    std::vector<Run> runs;
    runs.push_back(run_method(field, "aa", 0, 0, {}, 1, &points, region));
    print_run(runs.back());
    JobSpec high;
    if (const std::string e = hemibake::protocol::apply_params({{"quality", "high"}}, high); !e.empty()) {
      std::fprintf(stderr, "hemibake-bench: %s\n", e.c_str());
      return 1;
    }
    runs.push_back(run_method(field, "aa", 0, 0, high, 1, &points, region));
    std::snprintf(runs.back().method, sizeof runs.back().method, "aa, --quality high");
    print_run(runs.back());
    runs.push_back(run_method(field, "hr", 0, 0, {}, 1, &points, region));
    print_run(runs.back());
    const char* names[] = {"floor, 0-1 m from a lava sphere", "floor, 1-2 m", "floor, 2-3 m", "floor, 3-5 m",
                           "floor, further", "the objects"};
    std::printf("\n| region | points | aa: median as displayed | aa: bake / reference | aa high: median | aa high: bake / reference | hr: median | hr: bake / reference |\n");
    std::printf("|---|---|---|---|---|---|---|---|\n");
    for (int r = 0; r < 6; ++r)
      std::printf("| %s | %u | %.1f %% | %.3f | %.1f %% | %.3f | %.1f %% | %.3f |\n", names[r], runs[0].region_points[r],
                  100.0 * runs[0].region_median[r], runs[0].region_ratio[r], 100.0 * runs[1].region_median[r],
                  runs[1].region_ratio[r], 100.0 * runs[2].region_median[r], runs[2].region_ratio[r]);
    std::printf("\n");
    return 0;
  }
  if (mode == "--big") {
    // Big inputs at default settings, each given the three minutes: how far they get, the
    // memory they take, and the longest single shot (progress is reported between shots).
    struct Big {
      const char* name;
      Scene scene;
    };
    std::vector<Big> bigs;
    bigs.push_back({"atrium (sky and sun)", make_atrium()});
    bigs.push_back({"sphere room (ceiling panel)", make_sphere_room()});
    const double budget = argc > 2 ? std::atof(argv[2]) : 180.0;
    std::printf("## Big inputs (default settings, all threads, at most %.0f s each)\n\n", budget);
    std::printf("| scene | triangles | patches | shooters | time (s) | converged | unshot | shots | replayed | hemicubes | elements | longest shot (s) | peak memory (MB) |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    struct Out {
      Stats st;
      double longest;
    };
    const std::string only = argc > 3 ? argv[3] : "";  // a scene whose name holds this, alone
    for (const Big& b : bigs) {
      if (std::string(b.name).find(only) == std::string::npos) continue;
      uint64_t triangles = 0;
      for (const Patch& p : b.scene.patches) triangles += p.corner_count == 4 ? 2 : 1;
      long peak = 0;
      const Out o = isolated_value<Out>(
          [&] {
            Solver solver(b.scene, hemibake::protocol::default_solver_params());
            double longest = 0.0, last = 0.0;
            uint64_t hemicubes = 0, elements = 0, rounds = 0;
            while (solver.stats().seconds < budget && solver.step()) {
              const Stats& st = solver.stats();
              if (st.seconds - last > 5.0)
                std::fprintf(stderr, "%s: shot %llu took %.1f s (%llu hemicubes, %llu rounds, %llu -> %llu elements)\n", b.name,
                             static_cast<unsigned long long>(st.shots), st.seconds - last,
                             static_cast<unsigned long long>(st.hemicubes - hemicubes), static_cast<unsigned long long>(st.rounds - rounds),
                             static_cast<unsigned long long>(elements), static_cast<unsigned long long>(st.elements));
              longest = std::max(longest, st.seconds - last);
              last = st.seconds;
              hemicubes = st.hemicubes, elements = st.elements, rounds = st.rounds;
            }
            return Out{solver.stats(), longest};
          },
          &peak);
      std::printf("| %s | %llu | %zu | %llu | %.1f | %s | %.4f | %llu | %llu | %llu | %llu | %.2f | %.0f |\n", b.name,
                  static_cast<unsigned long long>(triangles), b.scene.patches.size(),
                  static_cast<unsigned long long>(o.st.shooters), o.st.seconds, o.st.converged ? "yes" : "no",
                  o.st.unshot_fraction, static_cast<unsigned long long>(o.st.shots), static_cast<unsigned long long>(o.st.replayed_shots),
                  static_cast<unsigned long long>(o.st.hemicubes), static_cast<unsigned long long>(o.st.elements), o.longest, peak / 1024.0);
      std::fflush(stdout);
    }
    std::printf("\n");
    return 0;
  }
  if (mode == "--scaling") {
    // How cost grows with the number of input patches: the furnished room cut finer and finer.
    std::printf("## Scaling: the furnished room at several patch counts (paper's settings, all threads)\n\n");
    std::printf("| input patches | aa time (s) | aa shots | aa replayed shots | aa elements | aa time per shot (ms) | aa time per shot per 1000 elements (ms) | aa peak memory (MB) | hr time (s) | hr links | hr elements | hr links per patch | hr peak memory (MB) |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (uint32_t target : {400u, 800u, 1600u, 3200u, 6300u, 12600u, 25200u}) {
      const Scene room = make_furnished_room(target);
      const Run aa = run_method(room, "aa", 0, 0);
      const Run hr = run_method(room, "hr", 0, 0);
      const double per_shot = aa.seconds / static_cast<double>(std::max<uint64_t>(1, aa.shots)) * 1e3;
      std::printf("| %zu | %.2f | %llu | %llu | %llu | %.3f | %.4f | %.1f | %.2f | %llu | %llu | %.0f | %.1f |\n",
                  room.patches.size(), aa.seconds, static_cast<unsigned long long>(aa.shots),
                  static_cast<unsigned long long>(aa.replayed), static_cast<unsigned long long>(aa.elements),
                  per_shot, per_shot / (static_cast<double>(aa.elements) / 1000.0), aa.peak_kib / 1024.0, hr.seconds,
                  static_cast<unsigned long long>(hr.links), static_cast<unsigned long long>(hr.elements),
                  static_cast<double>(hr.links) / static_cast<double>(room.patches.size()), hr.peak_kib / 1024.0);
      std::fflush(stdout);
    }
    std::printf("\n");
    return 0;
  }

  std::printf("## Cornell box (resolution 100, FEPS 0.001, AEPS 0.0001, until unshot < 0.001 of emitted)\n\n");
  std::printf("| method | visibility of children | threads | time (s) | shots | replayed shots | hemicubes | elements | "
              "splits | repeated shots | scene projections | projecting (s) | children from parent (s) | "
              "peak memory (MB) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  struct Config {
    hemibake::protocol::Method method;
    bool reuse;
    uint32_t threads;
  };
  using hemibake::protocol::Method;
  const std::vector<Config> configs{{Method::kAntiAliased, true, 0},  {Method::kAntiAliased, true, 1},
                                    {Method::kAntiAliased, false, 0}, {Method::kClassical, true, 0},
                                    {Method::kClassical, false, 0}};
  for (const Config& c : configs) {
    JobSpec spec;
    spec.method = c.method;
    spec.params.reuse_visibility = c.reuse;
    spec.params.threads = c.threads;
    const Result r = isolated([&] { return solve_stats(cornell, spec); });
    const Stats& s = r.stats;
    std::printf("| %s | %s | %s | %.3f | %llu | %llu | %llu | %llu | %llu | %llu | %llu | %.3f | %.3f | %.1f |\n",
                to_string(c.method),
                c.reuse ? "reused from parent" : "re-projected", c.threads == 0 ? "all" : "1", s.seconds,
                static_cast<unsigned long long>(s.shots), static_cast<unsigned long long>(s.replayed_shots),
                static_cast<unsigned long long>(s.hemicubes),
                static_cast<unsigned long long>(s.elements), static_cast<unsigned long long>(s.splits),
                static_cast<unsigned long long>(s.rounds), static_cast<unsigned long long>(s.projections),
                s.seconds_projecting, s.seconds_reusing, r.peak_kib / 1024.0);
    std::fflush(stdout);
  }

  // Every method against the path-traced reference, at element centres.
  const uint32_t samples = quick ? 256 : 1024;
  std::printf("\n## Methods side by side (Cornell box, paper's settings; error against a path-traced reference, "
              "%u paths per element centre, as fractions of its mean radiosity)\n\n",
              samples);
  const auto points = points_of(cornell, 300);
  print_runs_header();
  const uint32_t repeats = quick ? 1 : 3;
  print_run(run_method(cornell, "aa", 0, samples, {}, repeats, &points));
  print_run(run_method(cornell, "aa", 1, samples, {}, repeats, &points));
  print_run(run_method(cornell, "classical", 0, samples, {}, repeats, &points));
  print_run(run_method(cornell, "hr", 0, samples, {}, repeats, &points));
  print_run(run_method(cornell, "hr", 1, samples, {}, repeats, &points));

  std::printf("\n## Cost of one hemicube against elements (closed box, no subdivision, aa, all threads)\n\n");
  std::printf("| elements | hemicubes | time per hemicube (ms) | time per hemicube per 1000 elements (ms) |\n");
  std::printf("|---|---|---|---|\n");
  for (uint32_t cells : {4u, 8u, 16u, 32u, 64u}) {
    if (quick && cells > 16) break;
    const Scene box = make_closed_box(1.0, cells, glm::dvec3(0.5), glm::dvec3(1.0), false);
    JobSpec spec;
    spec.params.aeps = 0.5;  // nothing splits: the element count stays fixed
    spec.params.cluster_size = 0.0;  // every patch shoots alone: one whole-scene hemicube per shot
    spec.params.max_shots = 40;
    spec.params.shooter_size = 10.0;
    spec.params.shot_cache_mb = 0;  // every shot projects
    const Result r = isolated([&] { return solve_stats(box, spec); });
    const double per = r.stats.seconds / static_cast<double>(r.stats.hemicubes) * 1e3;
    std::printf("| %llu | %llu | %.3f | %.4f |\n", static_cast<unsigned long long>(r.stats.elements),
                static_cast<unsigned long long>(r.stats.hemicubes), per,
                per / (static_cast<double>(r.stats.elements) / 1000.0));
    std::fflush(stdout);
  }
  return 0;
}
