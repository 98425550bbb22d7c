// hemibake-accuracy SCENE.gltf BAKED.glb [BAKED2.glb ...]: the error of each bake as displayed
// (radiosity interpolated over its triangles at random surface points) against a path-traced
// reference at the same points. See display_error.h and bench/README.md.
#include "display_error.h"

#include "hemibake/protocol/gltf.h"
#include "hemibake/protocol/job.h"

#include <glm/geometric.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

namespace {

void usage() {
  std::fprintf(stderr,
               "usage: hemibake-accuracy SCENE.gltf|.glb BAKED.glb [BAKED2.glb ...] [options]\n"
               "  --points N          random surface points, area-weighted over non-emitting patches (300)\n"
               "  --seed N            their seed (1)\n"
               "  --max-se X          trace each point until its standard error is at most X of its value (0.015)\n"
               "  --reference FILE    read the reference points from FILE if it exists (they must lie on this\n"
               "                      scene's patches), else trace and write them\n"
               "  --per-point FILE    write each point's patch, position, reference, displayed value, error and\n"
               "                      whether no viewer sees it (first bake)\n"
               "  --sky R,G,B         the uniform sky the bakes had (a job parameter, not in the file; 0)\n");
}

bool read_points(const std::string& path, std::vector<hemibake::bench::SurfacePoint>& out) {
  std::ifstream in(path);
  if (!in) return false;
  hemibake::bench::SurfacePoint p;
  while (in >> p.patch >> p.position.x >> p.position.y >> p.position.z >> p.normal.x >> p.normal.y >> p.normal.z >>
         p.reference.x >> p.reference.y >> p.reference.z >> p.std_error >> p.samples)
    out.push_back(p);
  return !out.empty();
}

// Whether every point names a patch of `scene` and lies in its plane (a file traced for another
// scene, or for another reading of this one, does not).
bool fits(const hemibake::solver::Scene& scene, const std::vector<hemibake::bench::SurfacePoint>& points) {
  const double tolerance = 1e-5 * hemibake::bench::scene_diagonal(scene);
  for (const auto& sp : points) {
    if (sp.patch >= scene.patches.size()) return false;
    const auto& p = scene.patches[sp.patch];
    const glm::dvec3 n = glm::cross(p.corners[1] - p.corners[0], p.corners[2] - p.corners[0]);
    const double len = glm::length(n);
    if (len <= 0.0 || std::abs(glm::dot(sp.position - p.corners[0], n)) > tolerance * len) return false;
  }
  return true;
}

void write_points(const std::string& path, const std::vector<hemibake::bench::SurfacePoint>& points) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) return;
  for (const auto& p : points)
    std::fprintf(f, "%u %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %u\n", p.patch, p.position.x,
                 p.position.y, p.position.z, p.normal.x, p.normal.y, p.normal.z, p.reference.x, p.reference.y,
                 p.reference.z, p.std_error, p.samples);
  std::fclose(f);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace hemibake;
  std::vector<std::string> files;
  bench::ReferenceOptions options;
  std::string reference_file, per_point_file;
  glm::dvec3 sky(0.0);
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hemibake-accuracy: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--points") options.points = static_cast<uint32_t>(std::strtoul(value(), nullptr, 10));
    else if (a == "--seed") options.seed = std::strtoull(value(), nullptr, 10);
    else if (a == "--max-se") options.max_std_error = std::strtod(value(), nullptr);
    else if (a == "--reference") reference_file = value();
    else if (a == "--per-point") per_point_file = value();
    else if (a == "--sky") {
      const char* text = value();
      if (std::string e = protocol::parse_colour_value(*protocol::find_param("sky"), text, sky); !e.empty()) {
        std::fprintf(stderr, "hemibake-accuracy: --sky: %s\n", e.c_str());
        return 2;
      }
    }
    else if (a == "--help" || a == "-h") {
      usage();
      return 0;
    } else if (!a.empty() && a[0] == '-') {
      std::fprintf(stderr, "hemibake-accuracy: unknown option %s\n", a.c_str());
      usage();
      return 2;
    } else {
      files.push_back(a);
    }
  }
  if (files.size() < 2 || options.points == 0) {
    usage();
    return 2;
  }
  const protocol::LoadResult scene = protocol::load_gltf_file(files[0]);
  if (!scene.document) {
    std::fprintf(stderr, "hemibake-accuracy: %s: %s\n", files[0].c_str(), scene.error.c_str());
    return 1;
  }
  std::vector<bench::SurfacePoint> points;
  solver::Scene lit = protocol::scene_of(*scene.document);
  if (sky != glm::dvec3(0.0)) lit.sky = sky;
  if (!reference_file.empty() && read_points(reference_file, points) && !fits(lit, points)) {
    std::fprintf(stderr,
                 "hemibake-accuracy: %s: its points do not lie on %s's patches (traced for another scene?); "
                 "name another file to trace this scene's\n",
                 reference_file.c_str(), files[0].c_str());
    return 1;
  }
  if (points.empty()) {
    const auto t0 = std::chrono::steady_clock::now();
    points = bench::reference_points(lit, options);
    std::fprintf(stderr, "reference: %zu points traced in %.1f s\n", points.size(),
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    if (!reference_file.empty()) write_points(reference_file, points);
  }
  bench::mark_pressed(lit, points);  // the file keeps no such mark
  std::printf("| bake | median | p90 | max | bake/reference | missed | reference s.e. (worst) | seen | seen: median | p90 "
              "| max | bake/reference |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (size_t f = 1; f < files.size(); ++f) {
    solver::Mesh baked;
    if (std::string e = protocol::read_baked_mesh(files[f], baked); !e.empty()) {
      std::fprintf(stderr, "hemibake-accuracy: %s: %s\n", files[f].c_str(), e.c_str());
      return 1;
    }
    const bench::DisplayError err = bench::displayed_error(points, baked);
    std::printf("| %s | %.1f %% | %.1f %% | %.0f %% | %.3f | %u | %.1f %% | %u | ", files[f].c_str(), 100.0 * err.median,
                100.0 * err.p90, 100.0 * err.max, err.mean_ratio, err.missed, 100.0 * err.worst_std_error,
                err.seen.points);
    if (err.seen.points == 0)
      std::printf("- | - | - | - |\n");
    else
      std::printf("%.1f %% | %.1f %% | %.0f %% | %.3f |\n", 100.0 * err.seen.median, 100.0 * err.seen.p90,
                  100.0 * err.seen.max, err.seen.mean_ratio);
    if (f == 1 && !per_point_file.empty()) {
      std::FILE* out = std::fopen(per_point_file.c_str(), "w");
      if (out == nullptr) continue;
      const double slack = bench::plane_slack(baked);
      for (size_t i = 0; i < points.size(); ++i) {
        glm::dvec3 shown(0.0);
        bench::displayed_value(baked, points[i].position, points[i].normal, slack, shown);
        std::fprintf(out, "%u %.6g %.6g %.6g %.6g %.6g %.6g %.6g %.6g %.6g %.4f %d\n", points[i].patch,
                     points[i].position.x, points[i].position.y, points[i].position.z, points[i].reference.x,
                     points[i].reference.y, points[i].reference.z, shown.x, shown.y, shown.z, err.errors[i],
                     err.hidden[i]);
      }
      std::fclose(out);
    }
  }
  return 0;
}
