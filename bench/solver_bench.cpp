// The solver's benchmark: the Cornell box at the paper's settings in both form-factor modes, the
// cost of re-projecting against reusing the parent's pixels, and how the cost of one hemicube grows
// with the number of elements. Each configuration runs in a child process so that its peak memory
// is its own. Prints markdown tables (see bench/README.md).
#include "hemibake/baselines/hierarchical.h"
#include "hemibake/baselines/reference.h"
#include "hemibake/solver/scenes.h"
#include "hemibake/solver/solver.h"

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <cstring>
#include <algorithm>
#include <string>
#include <vector>

namespace {

using namespace hemibake::solver;

struct Result {
  Stats stats;
  long peak_kib = 0;
};

// Runs fn() in a forked child and returns its stats and peak resident memory.
template <typename Fn>
Result isolated(Fn fn) {
  int fds[2];
  if (pipe(fds) != 0) std::abort();
  const pid_t pid = fork();
  if (pid == 0) {
    close(fds[0]);
    Result r;
    r.stats = fn();
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    r.peak_kib = ru.ru_maxrss;
    if (write(fds[1], &r, sizeof r) != static_cast<ssize_t>(sizeof r)) _exit(1);
    _exit(0);
  }
  close(fds[1]);
  Result r;
  const ssize_t got = read(fds[0], &r, sizeof r);
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (got != static_cast<ssize_t>(sizeof r)) {
    std::fprintf(stderr, "benchmark child failed\n");
    std::exit(1);
  }
  return r;
}

Stats solve(const Scene& scene, const Params& params) {
  Solver solver(scene, params);
  return solver.run();
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const Scene cornell = make_cornell_box();
  if (argc > 1 && std::strcmp(argv[1], "--sweep") == 0) {
    // Equal quality: each method at several tolerances, its error against the reference and its
    // time (one thread for both, so that the comparison is of the methods).
    const hemibake::baselines::Reference reference(cornell);
    auto error = [&](const Mesh& mesh) {
      double err2 = 0.0, se2 = 0.0, sum_ref = 0.0;
      uint64_t seed = 1, n = 0;
      for (const auto& el : mesh.elements) {
        if (cornell.patches[el.patch].emission.x > 0.0) continue;
        glm::dvec3 c(0.0);
        for (uint32_t k = 0; k < el.corner_count; ++k) c += mesh.positions[el.corners[k]];
        c /= static_cast<double>(el.corner_count);
        const auto r = reference.radiosity_at(el.patch, c, 512, seed++);
        const double rl = (r.radiosity.x + r.radiosity.y + r.radiosity.z) / 3.0;
        const double bl = (el.radiosity.x + el.radiosity.y + el.radiosity.z) / 3.0;
        const double se = (r.std_error.x + r.std_error.y + r.std_error.z) / 3.0;
        err2 += (bl - rl) * (bl - rl);
        se2 += se * se;
        sum_ref += rl;
        ++n;
      }
      return std::sqrt(std::max(0.0, err2 - se2) / n) / (sum_ref / n);
    };
    struct Run {
      std::string method;
      double tolerance, seconds, err;
      uint64_t elements;
    };
    std::vector<Run> runs;
    std::printf("## Equal quality (Cornell box, one thread; error = RMS against the reference, its noise removed)\n\n");
    std::printf("| method | tolerance | time (s) | elements | error |\n|---|---|---|---|---|\n");
    for (double beps : {0.1, 0.03, 0.01}) {
      Params p;
      p.threads = 1;
      p.beps = beps;
      Solver solver(cornell, p);
      const Stats& st = solver.run();
      const Mesh mesh = solver.mesh();
      runs.push_back({"aa", beps, st.seconds, error(mesh), mesh.elements.size()});
    }
    for (double feps : {0.01, 0.003, 0.001}) {
      hemibake::baselines::HierarchicalParams hp;
      hp.feps = feps;
      hemibake::baselines::HierarchicalStats hs;
      const Mesh mesh = hemibake::baselines::solve_hierarchical(cornell, hp, hs);
      runs.push_back({"hr", feps, hs.seconds, error(mesh), mesh.elements.size()});
    }
    for (const Run& r : runs)
      std::printf("| %s | %s %g | %.3f | %llu | %.4f |\n", r.method.c_str(), r.method == "aa" ? "beps" : "feps",
                  r.tolerance, r.seconds, static_cast<unsigned long long>(r.elements), r.err);
    // The smallest error both reach, and the fastest run of each that reaches it.
    double best_aa = 1e300, best_hr = 1e300;
    for (const Run& r : runs) (r.method == "aa" ? best_aa : best_hr) = std::min(r.method == "aa" ? best_aa : best_hr, r.err);
    const double target = std::max(best_aa, best_hr);
    double t_aa = 1e300, t_hr = 1e300;
    for (const Run& r : runs)
      if (r.err <= target * 1.0000001) (r.method == "aa" ? t_aa : t_hr) = std::min(r.method == "aa" ? t_aa : t_hr, r.seconds);
    std::printf("\nTo reach an error of %.4f: aa %.3f s, hr %.3f s; hr / aa = %.2f\n", target, t_aa, t_hr, t_hr / t_aa);
    return 0;
  }
  if (argc > 1 && std::strcmp(argv[1], "--chamber") == 0) {
    // The paper's second experiment: a furnished room of about 6300 patches (minutes, so on demand).
    const Scene room = make_furnished_room();
    std::printf("## Furnished room (%zu patches; resolution 100, FEPS 0.001, AEPS 0.0001, unshot < 0.001)\n\n",
                room.patches.size());
    std::printf("| method | time (s) | shots | hemicubes | elements | peak memory (MB) |\n|---|---|---|---|---|---|\n");
    for (Method m : {Method::kAntiAliased, Method::kClassical}) {
      Params p;
      p.method = m;
      const Result r = isolated([&] { return solve(room, p); });
      std::printf("| %s | %.1f | %llu | %llu | %llu | %.1f |\n", m == Method::kAntiAliased ? "aa" : "classical",
                  r.stats.seconds, static_cast<unsigned long long>(r.stats.shots),
                  static_cast<unsigned long long>(r.stats.hemicubes), static_cast<unsigned long long>(r.stats.elements),
                  r.peak_kib / 1024.0);
      std::fflush(stdout);
    }
    return 0;
  }

  std::printf("## Cornell box (resolution 100, FEPS 0.001, AEPS 0.0001, until unshot < 0.001 of emitted)\n\n");
  std::printf("| method | visibility of children | threads | time (s) | shots | hemicubes | elements | "
              "splits | repeated shots | scene projections | projecting (s) | children from parent (s) | "
              "peak memory (MB) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  struct Config {
    Method method;
    bool reuse;
    uint32_t threads;
  };
  const std::vector<Config> configs{{Method::kAntiAliased, true, 0},  {Method::kAntiAliased, true, 1},
                                    {Method::kAntiAliased, false, 0}, {Method::kClassical, true, 0},
                                    {Method::kClassical, false, 0}};
  for (const Config& c : configs) {
    Params p;
    p.method = c.method;
    p.reuse_visibility = c.reuse;
    p.threads = c.threads;
    const Result r = isolated([&] { return solve(cornell, p); });
    const Stats& s = r.stats;
    std::printf("| %s | %s | %s | %.3f | %llu | %llu | %llu | %llu | %llu | %llu | %.3f | %.3f | %.1f |\n",
                c.method == Method::kAntiAliased ? "aa" : "classical",
                c.reuse ? "reused from parent" : "re-projected", c.threads == 0 ? "all" : "1", s.seconds,
                static_cast<unsigned long long>(s.shots), static_cast<unsigned long long>(s.hemicubes),
                static_cast<unsigned long long>(s.elements), static_cast<unsigned long long>(s.splits),
                static_cast<unsigned long long>(s.rounds), static_cast<unsigned long long>(s.projections),
                s.seconds_projecting, s.seconds_reusing, r.peak_kib / 1024.0);
    std::fflush(stdout);
  }

  // Accuracy against the path-traced reference, at element centres (luminance = mean of RGB).
  {
    const uint32_t samples = quick ? 256 : 1024;
    std::printf("\n## Error against a path-traced reference (Cornell box, %u paths per element centre)\n\n", samples);
    std::printf("| method | elements | RMS error / mean radiosity | RMS error, reference noise removed | max abs error / mean | reference standard error (RMS) / mean | energy (sum B A) / reference's |\n");
    std::printf("|---|---|---|---|---|---|---|\n");
    const hemibake::baselines::Reference reference(cornell);
    auto compare = [&](const char* name, const Mesh& mesh) {
      double se2 = 0.0, err2 = 0.0, worst = 0.0, sum_ref = 0.0, sum_refa = 0.0, sum_ba = 0.0;
      uint64_t seed = 1, n = 0;
      for (const auto& el : mesh.elements) {
        if (cornell.patches[el.patch].emission.x > 0.0) continue;  // the light itself is exact
        glm::dvec3 c(0.0);
        for (uint32_t k = 0; k < el.corner_count; ++k) c += mesh.positions[el.corners[k]];
        c /= static_cast<double>(el.corner_count);
        const auto r = reference.radiosity_at(el.patch, c, samples, seed++);
        const double rl = (r.radiosity.x + r.radiosity.y + r.radiosity.z) / 3.0;
        const double bl = (el.radiosity.x + el.radiosity.y + el.radiosity.z) / 3.0;
        const double sel = std::sqrt((r.std_error.x * r.std_error.x + r.std_error.y * r.std_error.y + r.std_error.z * r.std_error.z) / 3.0);
        err2 += (bl - rl) * (bl - rl);
        se2 += sel * sel;
        worst = std::max(worst, std::abs(bl - rl));
        sum_ref += rl;
        sum_refa += rl * el.area;
        sum_ba += bl * el.area;
        ++n;
      }
      const double mean_ref = sum_ref / static_cast<double>(n);
      std::printf("| %s | %zu | %.4f | %.4f | %.4f | %.4f | %.4f |\n", name, mesh.elements.size(),
                  std::sqrt(err2 / n) / mean_ref, std::sqrt(std::max(0.0, err2 - se2) / n) / mean_ref, worst / mean_ref,
                  std::sqrt(se2 / n) / mean_ref, sum_ba / sum_refa);
      std::fflush(stdout);
    };
    for (Method m : {Method::kAntiAliased, Method::kClassical}) {
      Params p;
      p.method = m;
      Solver solver(cornell, p);
      solver.run();
      compare(m == Method::kAntiAliased ? "aa" : "classical", solver.mesh());
    }
    hemibake::baselines::HierarchicalStats hs;
    const Mesh hr = hemibake::baselines::solve_hierarchical(cornell, {}, hs);
    compare("hr", hr);
    std::printf("\nHierarchical radiosity (FEPS 0.001, AEPS 0.0001, 4 rays per link, 1 thread): %.3f s "
                "(%.3f s linking), %llu links, %llu elements, %u iterations\n",
                hs.seconds, hs.seconds_linking, static_cast<unsigned long long>(hs.links),
                static_cast<unsigned long long>(hs.elements), hs.iterations);
  }

  std::printf("\n## Cost of one hemicube against elements (closed box, no subdivision, aa, all threads)\n\n");
  std::printf("| elements | hemicubes | time per hemicube (ms) | time per hemicube per 1000 elements (ms) |\n");
  std::printf("|---|---|---|---|\n");
  for (uint32_t cells : {4u, 8u, 16u, 32u, 64u}) {
    if (quick && cells > 16) break;
    const Scene box = make_closed_box(1.0, cells, glm::dvec3(0.5), glm::dvec3(1.0), false);
    Params p;
    p.aeps = 0.5;  // nothing splits: the element count stays fixed
    p.max_shots = 40;
    p.shooter_size = 10.0;
    const Result r = isolated([&] { return solve(box, p); });
    const double per = r.stats.seconds / static_cast<double>(r.stats.hemicubes) * 1e3;
    std::printf("| %llu | %llu | %.3f | %.4f |\n", static_cast<unsigned long long>(r.stats.elements),
                static_cast<unsigned long long>(r.stats.hemicubes), per,
                per / (static_cast<double>(r.stats.elements) / 1000.0));
    std::fflush(stdout);
  }
  return 0;
}
