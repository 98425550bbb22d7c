// hemibake-server: the baking service.
#include "hemibake/server/http.h"
#include "hemibake/server/service.h"

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace {

void usage(FILE* out) {
  std::fputs(
      "usage: hemibake-server [options]\n"
      "  --listen HOST:PORT      address to serve on (default 127.0.0.1:8080)\n"
      "  --data DIR              data directory for the embedded job store (default ./hemibake-data)\n"
      "  --store URI             keep jobs in PostgreSQL instead, shared by any number of nodes:\n"
      "                          postgresql://USER[:PASSWORD]@HOST:PORT/DATABASE (a libpq URI)\n"
      "  --lease-seconds S       with --store: a node that has not renewed a running job's lease for S seconds\n"
      "                          loses it and the job runs again elsewhere (default 30)\n"
      "  --workers N             concurrent bakes (default: number of cores)\n"
      "  --solver-threads N      threads inside each bake (default 1)\n"
      "  --tokens FILE           bearer tokens, one per line (also HEMIBAKE_TOKENS, comma-separated);\n"
      "                          without any, no authentication\n"
      "  --max-body BYTES        largest scene accepted (default 268435456)\n"
      "  --max-queue N           queued jobs before 429 (default 100)\n"
      "  --max-streams N         concurrent event streams (default 64)\n"
      "  --idle-timeout S        close a connection idle for S seconds, or a request body paused that long (default 60)\n"
      "  --header-timeout S      408 if a request line and headers take longer than S seconds (default 10)\n"
      "  --min-rate BYTES        408 if a request body arrives slower than this many bytes per second on\n"
      "                          average, counted after --header-timeout seconds (default 16384; 0: any)\n"
      "  --check-threads N       threads that load and check submitted scenes (default: half the cores)\n"
      "  --max-checks N          submitted scenes waiting for a check thread before 503 (default 4)\n"
      "  --job-seconds S         time budget per job (default 3600)\n"
      "  --max-elements N        element budget per job (default 2000000)\n"
      "  --max-shot-cache-mb N   memory per job for replayed shots (default 256; caps the job's shot_cache_mb)\n"
      "  --max-triangles N       largest scene in triangles (default 2000000)\n"
      "  --max-job-mb N          memory a job may need (hemicubes, elements, images, shot cache, scene),\n"
      "                          estimated at submit; more is refused with 422 (default 2048)\n"
      "  --max-image-pixels N    decoded texture pixels per job, all images together (default 67108864)\n"
      "  --max-attempts N        restarts of a job interrupted by a crash (default 3)\n"
      "  --expire-hours H        delete finished jobs and results after H hours (default 168)\n",
      out);
}

}  // namespace

int main(int argc, char** argv) {
  hemibake::server::ServiceOptions so;
  so.data_dir = "hemibake-data";
  hemibake::server::HttpOptions ho;
  std::string tokens_file;
  for (int i = 1; i < argc; ++i) {
    const std::string opt = argv[i];
    if (opt == "--help" || opt == "-h") {
      usage(stdout);
      return 0;
    }
    static const char* const kOptions[] = {"--listen", "--data", "--workers", "--solver-threads", "--tokens", "--max-body",
                                           "--max-queue", "--max-streams", "--idle-timeout", "--header-timeout", "--min-rate", "--check-threads", "--max-checks",
                                           "--job-seconds", "--max-elements",
                                           "--max-shot-cache-mb", "--max-triangles", "--max-job-mb", "--max-image-pixels", "--max-attempts", "--expire-hours",
                                           "--store", "--lease-seconds"};
    if (std::find(std::begin(kOptions), std::end(kOptions), opt) == std::end(kOptions)) {
      std::fprintf(stderr, "hemibake-server: unknown option '%s' (try --help)\n", opt.c_str());
      return 2;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "hemibake-server: %s needs a value\n", opt.c_str());
      return 2;
    }
    const std::string val = argv[++i];
    char* end = nullptr;
    const double num = std::strtod(val.c_str(), &end);
    const bool is_num = end != val.c_str() && *end == '\0' && num >= 0;
    auto need_num = [&]() {
      if (!is_num) {
        std::fprintf(stderr, "hemibake-server: %s needs a non-negative number (got '%s')\n", opt.c_str(), val.c_str());
        std::exit(2);
      }
      return num;
    };
    // A count: a whole number up to `max` (a thread count of 1e12 would try to start them all).
    auto need_count = [&](double max) {
      if (!is_num || num != std::floor(num) || num > max) {
        std::fprintf(stderr, "hemibake-server: %s needs a whole number from 0 to %.0f (got '%s')\n", opt.c_str(), max, val.c_str());
        std::exit(2);
      }
      return num;
    };
    if (opt == "--listen") {
      const size_t colon = val.rfind(':');
      if (colon == std::string::npos) {
        std::fprintf(stderr, "hemibake-server: --listen needs HOST:PORT (got '%s')\n", val.c_str());
        return 2;
      }
      ho.host = val.substr(0, colon);
      const long port = std::strtol(val.c_str() + colon + 1, &end, 10);
      if (*end != '\0' || port < 0 || port > 65535) {
        std::fprintf(stderr, "hemibake-server: bad port in '%s'\n", val.c_str());
        return 2;
      }
      ho.port = static_cast<unsigned short>(port);
    } else if (opt == "--data") so.data_dir = val;
    else if (opt == "--store") so.store_uri = val;
    else if (opt == "--lease-seconds") {
      so.lease_seconds = need_num();
      if (so.lease_seconds < 0.3) {
        std::fprintf(stderr, "hemibake-server: --lease-seconds needs at least 0.3 (got '%s')\n", val.c_str());
        return 2;
      }
    }
    else if (opt == "--workers") so.workers = static_cast<unsigned>(need_count(1024));
    else if (opt == "--solver-threads") so.solver_threads = static_cast<unsigned>(need_count(1024));
    else if (opt == "--tokens") tokens_file = val;
    else if (opt == "--max-body") so.max_body_bytes = ho.max_body_bytes = static_cast<uint64_t>(need_count(1e15));
    else if (opt == "--max-queue") so.max_queue = static_cast<size_t>(need_count(1e9));
    else if (opt == "--max-streams") ho.max_streams = static_cast<size_t>(need_count(1e6));
    else if (opt == "--idle-timeout") ho.idle_timeout = std::max(0.001, need_num());
    else if (opt == "--header-timeout") ho.header_timeout = std::max(0.001, need_num());
    else if (opt == "--min-rate") ho.min_rate = need_num();
    else if (opt == "--check-threads") so.check_threads = static_cast<unsigned>(need_count(1024));
    else if (opt == "--max-checks") so.max_checks = static_cast<size_t>(need_count(1e6));
    else if (opt == "--job-seconds") so.job_seconds = need_num();
    else if (opt == "--max-elements") so.max_elements = static_cast<uint64_t>(need_count(1e12));
    else if (opt == "--max-shot-cache-mb") so.max_shot_cache_mb = static_cast<uint32_t>(std::min(need_num(), 1048576.0));
    else if (opt == "--max-triangles") so.max_triangles = static_cast<uint64_t>(need_count(1e12));
    else if (opt == "--max-job-mb") so.max_job_bytes = static_cast<uint64_t>(need_count(1e9)) << 20;
    else if (opt == "--max-image-pixels") so.max_image_pixels = static_cast<uint64_t>(need_count(1e15));
    else if (opt == "--max-attempts") so.max_attempts = static_cast<int>(need_count(1e6));
    else if (opt == "--expire-hours") so.expire_seconds = need_num() * 3600.0;
    else {
      std::fprintf(stderr, "hemibake-server: unknown option '%s' (try --help)\n", opt.c_str());
      return 2;
    }
  }
  if (!tokens_file.empty()) {
    std::ifstream in(tokens_file);
    if (!in) {
      std::fprintf(stderr, "hemibake-server: cannot read tokens file '%s'\n", tokens_file.c_str());
      return 2;
    }
    for (std::string line; std::getline(in, line);) {
      while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
      if (!line.empty() && line[0] != '#') so.tokens.push_back(line);
    }
  }
  if (const char* env = std::getenv("HEMIBAKE_TOKENS")) {
    std::string all = env;
    for (size_t start = 0; start <= all.size();) {
      const size_t comma = all.find(',', start);
      const std::string t = all.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      if (!t.empty()) so.tokens.push_back(t);
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
  }
  std::string error;
  auto service = hemibake::server::Service::start(so, error);
  if (!service) {
    std::fprintf(stderr, "hemibake-server: %s\n", error.c_str());
    return 1;
  }
  boost::asio::io_context io;
  auto http = hemibake::server::HttpServer::start(*service, io, ho, error);
  if (!http) {
    std::fprintf(stderr, "hemibake-server: %s\n", error.c_str());
    return 1;
  }
  const std::string where = so.store_uri.empty() ? "data in " + so.data_dir : "jobs in PostgreSQL";
  std::printf("hemibake-server: serving http://%s:%u/ (%s, %s)\n", ho.host.c_str(), http->port(),
              where.c_str(), so.tokens.empty() ? "no authentication" : "bearer tokens required");
  std::printf("  submit:  curl -sS -X POST --data-binary @scene.glb -H 'Content-Type: model/gltf-binary' "
              "http://%s:%u/v1/jobs\n", ho.host.c_str(), http->port());
  std::fflush(stdout);
  // SIGTERM/SIGINT: stop accepting, stop the workers (running jobs go back to the queue), let the
  // responses in flight finish, then leave.
  boost::asio::signal_set signals(io, SIGINT, SIGTERM);
  std::thread stopper;
  signals.async_wait([&](const boost::system::error_code&, int) {
    std::printf("hemibake-server: shutting down\n");
    std::fflush(stdout);
    http->stop();
    // Stopping the service waits for each bake to reach the end of its shot: not on an I/O thread,
    // which meanwhile writes the 503s the stop gives to what was waiting (previews, queued checks).
    stopper = std::thread([&] {
      service->stop();
      std::this_thread::sleep_for(std::chrono::milliseconds(300));  // for those last answers
      io.stop();
    });
  });
  const unsigned n = std::max(2u, std::thread::hardware_concurrency());
  std::vector<std::thread> threads;
  for (unsigned i = 1; i < n; ++i) threads.emplace_back([&io] { io.run(); });
  io.run();
  for (auto& t : threads) t.join();
  if (stopper.joinable()) stopper.join();
  return 0;
}
