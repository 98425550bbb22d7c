// The shared PostgreSQL store's costs, on a PostgreSQL 15 started here on loopback (as in the tests):
//   1. claim latency: one claim() of a queued job, with 1000 queued;
//   2. store overhead per job: 1000 tiny jobs through 1, 2 and 3 nodes (each a Store of its own
//      connections, as a hemibake-server process has, with 2 workers) doing what a worker does for
//      each job: claim, a progress write, four events, the result (20 KB), while the lease thread
//      renews; the bake itself is left out, so the time is the store's alone;
//   3. event delay: an event written by node A's worker (through the store) to an SSE client of a
//      real hemibake-server, node B, via LISTEN/NOTIFY.
//   4. with --http N: N tiny bakes (the Cornell box, one shot, 8x8 hemicubes) submitted over HTTP to
//      1, 2 and 3 real hemibake-server processes (one worker each): jobs per second end to end,
//      which on a 2-core machine measures mostly the solver and the CPU, not the store.
// Usage: hemibake-nodes-bench [jobs] [--http N]   (default 1000 jobs, no HTTP run)
#include "hemibake/server/store.h"
#include "pg_server.h"
#include "server_process.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <numeric>
#include <thread>
#include <vector>

using namespace hemibake::server;
using namespace hemibake_test;
using Clock = std::chrono::steady_clock;

namespace {

double ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

double pct(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size())))];
}

std::unique_ptr<Store> open(const std::string& uri) {
  std::string error;
  auto s = Store::open_postgres(uri, PgOptions{}, error);
  if (!s) {
    std::fprintf(stderr, "nodes-bench: %s\n", error.c_str());
    std::exit(1);
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  int jobs = 1000, http_jobs = 0;
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--http" && i + 1 < argc) http_jobs = std::atoi(argv[++i]);
    else jobs = std::atoi(argv[i]);
  }
  PgServer pg;
  if (!pg.available()) {
    std::fprintf(stderr, "nodes-bench: %s\n", pg.why().c_str());
    return 1;
  }
  const std::string scene(5000, 's'), result(20000, 'r');

  {  // 1. claim latency
    const std::string uri = pg.create_database("claims");
    auto s = open(uri);
    for (int i = 0; i < jobs; ++i) s->create(scene, "model/gltf+json", "{}", "k" + std::to_string(i), "");
    std::vector<double> t;
    std::string id, sc, params;
    for (int i = 0; i < jobs; ++i) {
      const auto t0 = Clock::now();
      if (!s->claim(id, sc, params)) break;
      t.push_back(ms(Clock::now() - t0));
      s->release(id);
    }
    std::printf("claim latency (%zu claims, %d queued at first): median %.2f ms, p90 %.2f ms, p99 %.2f ms\n", t.size(), jobs,
                pct(t, 0.5), pct(t, 0.9), pct(t, 0.99));
  }

  // 2. throughput of the store's work per job on 1, 2, 3 nodes
  for (int nodes = 1; nodes <= 3; ++nodes) {
    const std::string uri = pg.create_database("through" + std::to_string(nodes));
    std::vector<std::unique_ptr<Store>> stores;
    for (int n = 0; n < nodes; ++n) stores.push_back(open(uri));
    for (int i = 0; i < jobs; ++i) stores[0]->create(scene, "model/gltf+json", "{}", "k" + std::to_string(i), "");
    std::atomic<int> done{0};
    const auto t0 = Clock::now();
    std::vector<std::thread> workers;
    for (int n = 0; n < nodes; ++n)
      for (int w = 0; w < 2; ++w)
        workers.emplace_back([&, n] {
          Store& s = *stores[n];
          std::string id, sc, params;
          while (s.claim(id, sc, params)) {
            s.add_event(id, "state", R"({"state":"running"})");
            s.set_progress(id, R"({"shots":1})");
            s.add_event(id, "progress", R"({"shots":1})");
            s.add_event(id, "progress", R"({"shots":2})");
            if (s.succeed(id, result, "\"e\"").made) ++done;
            s.add_event(id, "state", R"({"state":"succeeded"})");
            s.release(id);
          }
        });
    for (auto& w : workers) w.join();
    const double total = ms(Clock::now() - t0);
    std::printf("%d node%s x 2 workers: %d jobs in %.0f ms: %.0f jobs/s, %.2f ms of store work per job per worker "
                "(%.2f ms wall per job)\n",
                nodes, nodes > 1 ? "s" : " ", done.load(), total, done * 1000.0 / total, total * nodes * 2 / done, total / done);
  }

  {  // 3. event delay from node A's worker to an SSE client on node B
    const std::string uri = pg.create_database("events");
    auto a = open(uri);
    // A's worker holds the job before B starts (B's workers would claim it).
    const Created c = a->create(scene, "model/gltf+json", R"({})", "k", "");
    std::string id, sc, params;
    if (!a->claim(id, sc, params) || id != c.id) {
      std::fprintf(stderr, "nodes-bench: could not claim the event job\n");
      return 1;
    }
    ServerProcess b(temp_dir("nodes-bench"), {"--store", uri, "--workers", "1"});
    net::io_context io;
    beast::tcp_stream stream(io);
    stream.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), b.port()));
    const std::string req = "GET /v1/jobs/" + id + "/events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
    net::write(stream, net::buffer(req));
    std::this_thread::sleep_for(300ms);
    std::vector<double> delays;
    std::string buffer;
    char buf[4096];
    for (int i = 0; i < 100; ++i) {
      const std::string marker = "\"n\":" + std::to_string(i) + "}";
      const auto t0 = Clock::now();
      a->add_event(id, "progress", "{" + marker);
      while (buffer.find(marker) == std::string::npos) {
        beast::error_code ec;
        stream.expires_after(5s);
        const size_t n = stream.read_some(net::buffer(buf), ec);
        if (ec) {
          std::fprintf(stderr, "nodes-bench: the stream ended: %s\n", ec.message().c_str());
          return 1;
        }
        buffer.append(buf, n);
      }
      delays.push_back(ms(Clock::now() - t0));
      std::this_thread::sleep_for(5ms);
    }
    std::printf("event delay, node A's worker to an SSE client on node B (100 events): median %.2f ms, p90 %.2f ms, max %.2f ms\n",
                pct(delays, 0.5), pct(delays, 0.9), pct(delays, 1.0));
  }
  // 4. tiny bakes end to end on 1, 2, 3 nodes
  for (int nodes = 1; nodes <= 3 && http_jobs > 0; ++nodes) {
    const std::string uri = pg.create_database("http" + std::to_string(nodes));
    std::vector<std::unique_ptr<ServerProcess>> servers;
    for (int n = 0; n < nodes; ++n)
      servers.push_back(std::make_unique<ServerProcess>(temp_dir("nodes-bench-http" + std::to_string(n)),
                                                        std::vector<std::string>{"--store", uri, "--workers", "1", "--max-queue", "100000"}));
    const auto t0 = Clock::now();
    std::vector<std::string> ids;
    for (int i = 0; i < http_jobs; ++i) {
      const Reply r = request(servers[i % nodes]->port(), http::verb::post,
                              "/v1/jobs?max_shots=1&resolution=8&max_elements=100&convergence=" + std::to_string(0.1 + 0.0001 * i),
                              cornell(), {{"Content-Type", "model/gltf+json"}});
      if (r.status != 202) {
        std::fprintf(stderr, "nodes-bench: submit answered %d: %s\n", r.status, r.body.c_str());
        return 1;
      }
      ids.push_back(r.js()["id"]);
    }
    int ok = 0;
    for (const auto& id : ids) ok += wait_finished(servers[0]->port(), id, 600s)["state"] == "succeeded";
    const double total = ms(Clock::now() - t0);
    std::printf("HTTP, %d node%s x 1 worker: %d of %d tiny bakes succeeded in %.0f ms: %.1f jobs/s\n", nodes, nodes > 1 ? "s" : "",
                ok, http_jobs, total, ok * 1000.0 / total);
  }
  return 0;
}
