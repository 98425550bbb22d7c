// The real server binary on loopback, spoken to over real HTTP (a Beast client written here).
#include "dark_glb.h"
#include "hemibake/server/store.h"
#include "server_process.h"

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/read_until.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstring>
#include <map>
#include <mutex>
#include <random>
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <fcntl.h>
#include <poll.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace {
using namespace hemibake_test;
using hemibake_test::Reply;
const std::map<std::string, std::string> kGltf = {{"Content-Type", "model/gltf+json"}};

TEST(Server, SubmitStreamFetchAndCacheHit) {
  ServerProcess server(temp_dir("submit"), {"--workers", "1"});
  ASSERT_NE(server.port(), 0);
  const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.05", cornell(), kGltf);
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = posted.js()["id"];
  EXPECT_EQ(posted.headers.at("location"), "/v1/jobs/" + id);
  // The stream carries the job's events in order and ends with its final state.
  const auto evs = events(server.port(), id);
  ASSERT_FALSE(evs.empty());
  for (size_t i = 1; i < evs.size(); ++i) EXPECT_EQ(std::get<0>(evs[i]), std::get<0>(evs[i - 1]) + 1);
  EXPECT_EQ(std::get<1>(evs.back()), "state");
  EXPECT_EQ(json::parse(std::get<2>(evs.back()))["state"], "succeeded");
  // Resuming after the first event replays only what came after it.
  const auto resumed = events(server.port(), id, std::get<0>(evs.front()));
  EXPECT_EQ(resumed.size(), evs.size() - 1);
  const json job = request(server.port(), http::verb::get, "/v1/jobs/" + id).js();
  EXPECT_EQ(job["state"], "succeeded");
  EXPECT_LT(job["progress"]["unshot_fraction"].get<double>(), 0.05);
  const Reply result = request(server.port(), http::verb::get, "/v1/jobs/" + id + "/result");
  ASSERT_EQ(result.status, 200);
  EXPECT_EQ(result.headers.at("content-type"), "model/gltf-binary");
  EXPECT_EQ(result.body.substr(0, 4), "glTF");
  const Reply again = request(server.port(), http::verb::get, "/v1/jobs/" + id + "/result", "",
                              {{"If-None-Match", result.headers.at("etag")}});
  EXPECT_EQ(again.status, 304);
  // The same scene and parameters: answered from the store.
  const Reply cached = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.05", cornell(), kGltf);
  EXPECT_EQ(cached.status, 200);
  EXPECT_EQ(cached.headers.at("x-hemibake-cache"), "hit");
  EXPECT_EQ(cached.js()["id"], id);
  // Listing, with the state filter.
  const json list = request(server.port(), http::verb::get, "/v1/jobs?state=succeeded").js();
  ASSERT_EQ(list["jobs"].size(), 1u);
  EXPECT_EQ(list["jobs"][0]["id"], id);
  EXPECT_EQ(request(server.port(), http::verb::get, "/openapi.json").js()["openapi"], "3.1.0");
  EXPECT_NE(request(server.port(), http::verb::get, "/metrics").body.find("hemibake_jobs{state=\"succeeded\"} 1"), std::string::npos);
}

TEST(Server, RefusesBadRequestsWithJsonErrors) {
  ServerProcess server(temp_dir("errors"), {"--workers", "1", "--max-body", "100000"});
  auto post = [&](const std::string& body, const std::string& type, const std::string& query = "") {
    return request(server.port(), http::verb::post, "/v1/jobs" + query, body, {{"Content-Type", type}});
  };
  EXPECT_EQ(post(cornell(), "text/plain").status, 415);
  EXPECT_EQ(post("{\"asset\":", "model/gltf+json").status, 422);
  EXPECT_EQ(post(cornell(), "model/gltf+json", "?resolution=7").status, 400);
  EXPECT_EQ(post(cornell(), "model/gltf+json", "?bogus=1").status, 400);
  const Reply large = post(std::string(200000, 'x'), "model/gltf-binary");
  EXPECT_EQ(large.status, 413);
  EXPECT_NE(large.js().value("error", "").find("limit of 100000 bytes"), std::string::npos) << large.body;
  const Reply long_url = request(server.port(), http::verb::get, "/v1/jobs/" + std::string(9000, 'a'));
  EXPECT_EQ(long_url.status, 431);
  EXPECT_TRUE(long_url.js().contains("error")) << long_url.body;
  const Reply bad = post("{\"asset\":{\"version\":\"2.0\"},\"scenes\":[{\"nodes\":[5]}]}", "model/gltf+json");
  EXPECT_EQ(bad.status, 422);
  EXPECT_NE(bad.js()["error"].get<std::string>().find("node 5"), std::string::npos) << bad.body;
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs/nope").status, 404);
}

TEST(Server, IdempotencyKeyMakesRetriesSafe) {
  ServerProcess server(temp_dir("idem"), {"--workers", "1"});
  const std::map<std::string, std::string> h = {{"Content-Type", "model/gltf+json"}, {"Idempotency-Key", "abc-123"}};
  const Reply a = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.3", cornell(), h);
  const Reply b = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.3", cornell(), h);
  EXPECT_EQ(a.status, 202);
  EXPECT_EQ(b.status, 200);
  EXPECT_EQ(a.js()["id"], b.js()["id"]);
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs").js()["jobs"].size(), 1u);
}

TEST(Server, BearerTokensWhenConfigured) {
  ServerProcess server(temp_dir("auth"), {"--workers", "1"}, {"HEMIBAKE_TOKENS=s3cret,other"});
  const Reply none = request(server.port(), http::verb::get, "/v1/jobs");
  EXPECT_EQ(none.status, 401);
  EXPECT_EQ(none.headers.at("www-authenticate").rfind("Bearer", 0), 0u);
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs", "", {{"Authorization", "Bearer wrong"}}).status, 401);
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs", "", {{"Authorization", "Bearer s3cret"}}).status, 200);
  EXPECT_EQ(request(server.port(), http::verb::get, "/healthz").status, 200);
}

TEST(Server, CancelStopsARunningJob) {
  ServerProcess server(temp_dir("cancel"), {"--workers", "1"});
  const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?convergence=0.000001&aeps=0.00002", cornell(), kGltf);
  const std::string id = posted.js()["id"];
  for (int i = 0; i < 100 && request(server.port(), http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
    std::this_thread::sleep_for(50ms);
  const Reply cancelled = request(server.port(), http::verb::delete_, "/v1/jobs/" + id);
  EXPECT_EQ(cancelled.status, 200);
  EXPECT_EQ(cancelled.js()["state"], "cancelled");
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs/" + id + "/result").status, 409);
  EXPECT_EQ(request(server.port(), http::verb::delete_, "/v1/jobs/" + id).status, 409);
  // The worker is free again: a new job runs to the end.
  const Reply next = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.2", cornell(), kGltf);
  EXPECT_EQ(wait_finished(server.port(), next.js()["id"])["state"], "succeeded");
}

// A cancelled bake says so in its status and in its stream, with the progress where it stopped
// (it used to report the phase "done" with the whole phase done).
TEST(Server, CancelledJobReportsWhereItStopped) {
  ServerProcess server(temp_dir("cancel-progress"), {"--workers", "1"});
  const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?convergence=0.000001&aeps=0.00002", cornell(), kGltf);
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = posted.js()["id"];
  json before;
  for (int i = 0; i < 600; ++i) {
    before = request(server.port(), http::verb::get, "/v1/jobs/" + id).js();
    if (before.contains("progress") && before["progress"].value("shots", 0) > 0) break;
    std::this_thread::sleep_for(50ms);
  }
  ASSERT_TRUE(before.contains("progress")) << before.dump();
  ASSERT_EQ(before["state"], "running") << before.dump();
  ASSERT_EQ(request(server.port(), http::verb::delete_, "/v1/jobs/" + id).status, 200);
  // The stream ends after the worker's last word: no progress event claims the bake was done; the
  // last one says where it stopped, before the final state.
  const auto all = events(server.port(), id);
  ASSERT_FALSE(all.empty());
  std::string last_progress = "{}";
  for (const auto& [eid, type, data] : all) {
    if (type != "progress") continue;
    EXPECT_NE(json::parse(data).value("phase", ""), "done") << "a cancelled bake reported: " << data;
    last_progress = data;
  }
  EXPECT_EQ(json::parse(last_progress).value("phase", ""), "cancelled") << last_progress;
  // The status says the same.
  const json after = request(server.port(), http::verb::get, "/v1/jobs/" + id).js();
  ASSERT_EQ(after["state"], "cancelled") << after.dump();
  ASSERT_TRUE(after.contains("progress")) << after.dump();
  const json& p = after["progress"];
  EXPECT_EQ(p.value("phase", ""), "cancelled") << after.dump();
  EXPECT_LT(p.value("fraction", 1.0), 1.0) << after.dump();
  EXPECT_GE(p.value("shots", 0), before["progress"].value("shots", 0)) << after.dump();
  EXPECT_GT(p.value("unshot_fraction", 0.0), 0.000001) << "the bake was stopped short of its convergence: " << after.dump();
  EXPECT_EQ(std::get<1>(all.back()), "state");
  EXPECT_EQ(json::parse(std::get<2>(all.back())).value("state", ""), "cancelled");
}

TEST(Server, QueueLimitAnswers429WithRetryAfter) {
  ServerProcess server(temp_dir("queue"), {"--workers", "1", "--max-queue", "1"});
  std::vector<std::string> ids;
  int refused = 0;
  for (int i = 0; i < 5; ++i) {
    const Reply r = request(server.port(), http::verb::post,
                            "/v1/jobs?convergence=0.000001&aeps=0.00002&max_shots=" + std::to_string(100000 + i), cornell(), kGltf);
    if (r.status == 429) {
      ++refused;
      EXPECT_TRUE(r.headers.count("retry-after"));
    } else {
      ASSERT_EQ(r.status, 202) << r.body;
      ids.push_back(r.js()["id"]);
    }
  }
  EXPECT_GE(refused, 2);
  // A fresh Idempotency-Key per request is no way past the limit (it used to be: with a limit of 2,
  // 20 jobs with distinct keys were accepted); a retry of an accepted one still gets its job.
  int refused_with_keys = 0;
  std::string first_key;
  for (int i = 0; i < 5; ++i) {
    const std::string key = "key-" + std::to_string(i);
    const Reply r = request(server.port(), http::verb::post,
                            "/v1/jobs?convergence=0.000001&aeps=0.00002&max_shots=" + std::to_string(200000 + i), cornell(),
                            {{"Content-Type", "model/gltf+json"}, {"Idempotency-Key", key}});
    if (r.status == 429) {
      ++refused_with_keys;
    } else {
      ASSERT_EQ(r.status, 202) << r.body;
      ids.push_back(r.js()["id"]);
      if (first_key.empty()) first_key = key;
    }
  }
  EXPECT_GE(refused_with_keys, 3);
  if (!first_key.empty()) {
    const Reply again = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.3", cornell(),
                                {{"Content-Type", "model/gltf+json"}, {"Idempotency-Key", first_key}});
    EXPECT_EQ(again.status, 200) << again.body;
  }
  for (const auto& id : ids) request(server.port(), http::verb::delete_, "/v1/jobs/" + id);
}

// A material name is copied into a Warning header as a quoted string: a name with CR LF cannot add
// a header (a crafted file used to set a cookie this way).
TEST(Server, WarningHeadersCannotBeSplitByMaterialNames) {
  ServerProcess server(temp_dir("split"), {"--workers", "1"});
  json scene = json::parse(cornell());
  ASSERT_TRUE(scene.contains("materials"));
  scene["materials"][0]["name"] = "wall\r\nSet-Cookie: stolen=1\r\n\r\nHTTP/1.1 200 OK";
  scene["materials"][0]["alphaMode"] = "BLEND";  // baked opaque, with a warning naming the material
  const Reply r = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.3", scene.dump(), kGltf);
  ASSERT_EQ(r.status, 202) << r.body;
  EXPECT_EQ(r.headers.count("set-cookie"), 0u);
  ASSERT_TRUE(r.headers.count("warning"));
  const std::string w = r.headers.at("warning");
  EXPECT_EQ(w.find('\r'), std::string::npos);
  EXPECT_EQ(w.find('\n'), std::string::npos);
  EXPECT_NE(w.find("Set-Cookie: stolen=1"), std::string::npos) << w;  // kept, as text inside the quotes
  request(server.port(), http::verb::delete_, "/v1/jobs/" + r.js()["id"].get<std::string>());
}

// An accepted job is never lost: SIGKILL while it runs, start again on the same data directory,
// and it completes.
TEST(Server, JobSurvivesSigkillAndCompletesAfterRestart) {
  const std::string dir = temp_dir("crash");
  std::string id;
  {
    ServerProcess server(dir, {"--workers", "1"});
    const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?convergence=0.0001", cornell(), kGltf);
    ASSERT_EQ(posted.status, 202);
    id = posted.js()["id"];
    for (int i = 0; i < 100 && request(server.port(), http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
      std::this_thread::sleep_for(20ms);
    std::this_thread::sleep_for(300ms);
    ASSERT_EQ(request(server.port(), http::verb::get, "/v1/jobs/" + id).js()["state"], "running");
    server.stop(SIGKILL);
  }
  ServerProcess again(dir, {"--workers", "1"});
  const json done = wait_finished(again.port(), id);
  EXPECT_EQ(done["state"], "succeeded") << done.dump();
  EXPECT_EQ(done["attempts"].get<int>(), 2);  // killed in its first run, finished in the second
  const Reply result = request(again.port(), http::verb::get, "/v1/jobs/" + id + "/result");
  EXPECT_EQ(result.status, 200);
  EXPECT_EQ(result.body.substr(0, 4), "glTF");
}

// While a job runs, /preview gives its current state as a GLB; before and after, 409.
TEST(Server, PreviewOfARunningJob) {
  ServerProcess server(temp_dir("preview"), {"--workers", "1"});
  const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?convergence=0.00001&aeps=0.00002", cornell(), kGltf);
  const std::string id = posted.js()["id"];
  for (int i = 0; i < 100 && request(server.port(), http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
    std::this_thread::sleep_for(20ms);
  const auto asked = std::chrono::steady_clock::now();
  const Reply preview = request(server.port(), http::verb::get, "/v1/jobs/" + id + "/preview");
  const double round_trip_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - asked).count();
  ASSERT_EQ(preview.status, 200) << preview.body;
  EXPECT_EQ(preview.headers.at("content-type"), "model/gltf-binary");
  EXPECT_EQ(preview.body.substr(0, 4), "glTF");
  // The worker's writing time, which a page paces its requests by: part of the request's time.
  ASSERT_TRUE(preview.headers.count("server-timing"));
  const std::string timing = preview.headers.at("server-timing");
  ASSERT_EQ(timing.rfind("write;dur=", 0), 0u) << timing;
  const double write_ms = std::stod(timing.substr(10));
  EXPECT_GE(write_ms, 0.0);
  EXPECT_LE(write_ms, round_trip_ms + 1.0) << timing;
  request(server.port(), http::verb::delete_, "/v1/jobs/" + id);
  EXPECT_EQ(wait_finished(server.port(), id)["state"], "cancelled");
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs/" + id + "/preview").status, 409);
}

// The GLB's JSON chunk.
json glb_json(const std::string& glb) {
  if (glb.size() < 20 || glb.substr(0, 4) != "glTF") return json();
  uint32_t length = 0;
  std::memcpy(&length, glb.data() + 12, 4);
  return json::parse(glb.substr(20, length), nullptr, false);
}

// The baselines run as jobs too, with their own phases in the progress events.
TEST(Server, HierarchicalAndReferenceJobs) {
  ServerProcess server(temp_dir("baselines"), {"--workers", "1"});
  for (const std::string method : {"hr", "reference"}) {
    const std::string query = method == "hr" ? "?method=hr&feps=0.01&rays=2" : "?method=reference&samples=8&convergence=0.05";
    const Reply posted = request(server.port(), http::verb::post, "/v1/jobs" + query, cornell(), kGltf);
    ASSERT_EQ(posted.status, 202) << posted.body;
    const std::string id = posted.js()["id"];
    const auto evs = events(server.port(), id);
    ASSERT_FALSE(evs.empty());
    EXPECT_EQ(json::parse(std::get<2>(evs.back()))["state"], "succeeded") << method;
    std::set<std::string> phases;
    for (const auto& e : evs)
      if (std::get<1>(e) == "progress") phases.insert(json::parse(std::get<2>(e)).value("phase", ""));
    EXPECT_TRUE(phases.count("done")) << method;
    const json job = request(server.port(), http::verb::get, "/v1/jobs/" + id).js();
    EXPECT_EQ(job["params"]["method"], method);
    const Reply result = request(server.port(), http::verb::get, "/v1/jobs/" + id + "/result");
    ASSERT_EQ(result.status, 200);
    const json doc = glb_json(result.body);
    ASSERT_TRUE(doc.is_object()) << method;
    EXPECT_EQ(doc["asset"]["extras"]["hemibake"]["parameters"]["method"], method);
    // Both subdivide the 26 input patches.
    EXPECT_GT(doc["asset"]["extras"]["hemibake"]["statistics"]["elements"].get<double>(), 100.0) << method;
  }
  // A long hr job: no preview while it links, and cancelling stops it.
  const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?method=hr&feps=0.00001&aeps=0.000001", cornell(), kGltf);
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = posted.js()["id"];
  for (int i = 0; i < 200 && request(server.port(), http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
    std::this_thread::sleep_for(20ms);
  std::this_thread::sleep_for(300ms);
  const Reply preview = request(server.port(), http::verb::get, "/v1/jobs/" + id + "/preview");
  EXPECT_EQ(preview.status, 409) << preview.body;
  const auto t0 = std::chrono::steady_clock::now();
  request(server.port(), http::verb::delete_, "/v1/jobs/" + id);
  EXPECT_EQ(wait_finished(server.port(), id)["state"], "cancelled");
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 10s);
}

// SIGTERM: the running job goes back to the queue and completes after the restart.
TEST(Server, SigtermRequeuesTheRunningJob) {
  const std::string dir = temp_dir("term");
  std::string id;
  {
    ServerProcess server(dir, {"--workers", "1"});
    id = request(server.port(), http::verb::post, "/v1/jobs?convergence=0.0001", cornell(), kGltf).js()["id"];
    for (int i = 0; i < 100 && request(server.port(), http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
      std::this_thread::sleep_for(20ms);
    std::this_thread::sleep_for(200ms);
    ASSERT_EQ(request(server.port(), http::verb::get, "/v1/jobs/" + id).js()["state"], "running");
    server.stop(SIGTERM);
  }
  ServerProcess again(dir, {"--workers", "1"});
  const json done = wait_finished(again.port(), id);
  EXPECT_EQ(done["state"], "succeeded") << done.dump();
  EXPECT_EQ(done["attempts"].get<int>(), 2);
}

// SIGTERM while clients wait for previews: each gets an answer (503 to ask again, or the preview if
// a shot ended first), not a dropped connection.
TEST(Server, SigtermAnswersWaitingPreviews) {
  ServerProcess server(temp_dir("term-previews"), {"--workers", "1"});
  // 2048² hemicubes: shots of seconds, so the previews are still waiting when the signal comes
  // (in one pass: light pools' first pass shoots at a draft's resolution).
  const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?resolution=2048&reuse=false&convergence=0.00001&pools=false", cornell(), kGltf);
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = posted.js()["id"];
  for (int i = 0; i < 200 && request(server.port(), http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
    std::this_thread::sleep_for(20ms);
  std::vector<int> statuses(3, 0);
  std::vector<std::thread> waiting;
  for (size_t c = 0; c < statuses.size(); ++c) {
    waiting.emplace_back([&, c] {
      try {
        statuses[c] = request(server.port(), http::verb::get, "/v1/jobs/" + id + "/preview").status;
      } catch (const std::exception&) {
        statuses[c] = -1;
      }
    });
  }
  std::this_thread::sleep_for(300ms);
  server.stop(SIGTERM);
  for (auto& t : waiting) t.join();
  int stopped = 0;
  for (int s : statuses) {
    EXPECT_TRUE(s == 503 || s == 200) << s;
    stopped += s == 503;
  }
  EXPECT_GE(stopped, 1);
}

// The hemibake command against the server: bake --server submits, follows and downloads; the
// other subcommands report the server's errors with a non-zero exit status.
TEST(Client, BakesOnTheServerAndReportsErrors) {
  ServerProcess server(temp_dir("client"), {"--workers", "1"});
  const std::string url = "http://127.0.0.1:" + std::to_string(server.port());
  const std::string out = temp_dir("client-out", ".glb");
  const std::string bake = std::string(HEMIBAKE_CLIENT) + " bake --server " + url + " " HEMIBAKE_SOURCE_DIR
                           "/data/cornell-box.gltf -o " + out + " --convergence 0.05 2>/dev/null >/dev/null";
  ASSERT_EQ(std::system(bake.c_str()), 0) << bake;
  EXPECT_EQ(read_file(out).substr(0, 4), "glTF");
  std::filesystem::remove(out);
  const std::string missing = std::string(HEMIBAKE_CLIENT) + " status nope --server " + url + " 2>/dev/null";
  EXPECT_NE(std::system(missing.c_str()), 0);
  const std::string unreachable = std::string(HEMIBAKE_CLIENT) + " list --server http://127.0.0.1:1 --retry-seconds 0 2>/dev/null";
  EXPECT_NE(std::system(unreachable.c_str()), 0);
}

// What arrives on `socket` until the peer closes it or `limit` has passed (then `timed_out` is set).
// Beast's stream timeouts do not apply to blocking reads, so this waits with poll().
std::string read_until_closed(tcp::socket& socket, std::chrono::seconds limit, bool* timed_out) {
  const auto until = std::chrono::steady_clock::now() + limit;
  std::string all;
  char buf[4096];
  if (timed_out) *timed_out = false;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now()).count();
    pollfd p{socket.native_handle(), POLLIN, 0};
    if (left <= 0 || poll(&p, 1, static_cast<int>(left)) == 0) {
      if (timed_out) *timed_out = true;
      return all;
    }
    const ssize_t n = ::recv(socket.native_handle(), buf, sizeof buf, 0);
    if (n <= 0) return all;
    all.append(buf, static_cast<size_t>(n));
  }
}

// Everything the server sends on one connection for `raw` requests, until it closes (or `limit`
// has passed: then `timed_out` is set, if given).
std::string exchange(unsigned short port, const std::string& raw, std::chrono::seconds limit = 30s, bool* timed_out = nullptr) {
  net::io_context io;
  tcp::socket socket(io);
  socket.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
  net::write(socket, net::buffer(raw));
  return read_until_closed(socket, limit, timed_out);
}

// How many responses `all` holds (status lines; bodies here are JSON, without "HTTP/1.1 ").
size_t responses(const std::string& all) {
  size_t n = 0;
  for (size_t at = all.find("HTTP/1.1 "); at != std::string::npos; at = all.find("HTTP/1.1 ", at + 1)) ++n;
  return n;
}

// A HEAD response has the GET's headers and no body, so a request pipelined after it is answered
// in its own response.
TEST(Server, HeadAnswersWithoutABody) {
  ServerProcess server(temp_dir("head"), {"--workers", "1"});
  const std::string all = exchange(server.port(),
                                   "HEAD /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
                                   "GET /readyz HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n");
  const size_t second = all.find("HTTP/1.1", 1);
  ASSERT_NE(second, std::string::npos) << all;
  const std::string head = all.substr(0, second);
  EXPECT_EQ(head.rfind("HTTP/1.1 200 OK\r\n", 0), 0u) << head;
  EXPECT_NE(head.find("Content-Length: 15\r\n"), std::string::npos) << head;  // that of {"status":"ok"}
  EXPECT_EQ(head.substr(head.size() - 4), "\r\n\r\n") << head;
  EXPECT_EQ(all.substr(all.size() - 18), R"({"status":"ready"})") << all;
}

// The status line of an event stream request, read from a fresh connection that is then closed.
std::string stream_status(unsigned short port, const std::string& id) {
  net::io_context io;
  tcp::socket socket(io);
  socket.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
  const std::string req = "GET /v1/jobs/" + id + "/events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
  net::write(socket, net::buffer(req));
  char buf[64] = {0};
  beast::error_code ec;
  const size_t n = socket.read_some(net::buffer(buf, sizeof buf - 1), ec);
  return std::string(buf, n).substr(0, std::string(buf, n).find('\r'));
}

// A client that leaves an event stream frees its slot at once, also while the job waits in the
// queue and nothing is written to it.
TEST(Server, EventStreamSlotIsFreedWhenTheClientLeaves) {
  ServerProcess server(temp_dir("streams"), {"--workers", "1", "--max-streams", "1"});
  const std::string busy = request(server.port(), http::verb::post, "/v1/jobs?method=hr&feps=0.00001&aeps=0.000001", cornell(), kGltf).js()["id"];
  const std::string queued = request(server.port(), http::verb::post, "/v1/jobs?method=hr&feps=0.00001&aeps=0.000002", cornell(), kGltf).js()["id"];
  ASSERT_EQ(request(server.port(), http::verb::get, "/v1/jobs/" + queued).js()["state"], "queued");
  ASSERT_EQ(stream_status(server.port(), queued), "HTTP/1.1 200 OK");
  std::string status;
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 20 && (status = stream_status(server.port(), queued)) != "HTTP/1.1 200 OK"; ++i) std::this_thread::sleep_for(100ms);
  EXPECT_EQ(status, "HTTP/1.1 200 OK");
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s);
  request(server.port(), http::verb::delete_, "/v1/jobs/" + queued);
  request(server.port(), http::verb::delete_, "/v1/jobs/" + busy);
}

// CPU time (user + system) a process has used, in clock ticks.
long cpu_ticks(pid_t pid) {
  std::istringstream stat(read_file("/proc/" + std::to_string(pid) + "/stat"));
  std::string field;
  std::getline(stat, field, ')');  // pid and (comm), which may hold spaces
  std::vector<std::string> rest;
  while (stat >> field) rest.push_back(field);
  return rest.size() > 12 ? std::stol(rest[11]) + std::stol(rest[12]) : -1;
}

// More connections than file descriptors: the server does not spin on the failing accept, and
// serves again once connections close.
// gcc says __SANITIZE_ADDRESS__, clang __has_feature(address_sanitizer).
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define HEMIBAKE_TEST_ASAN 1
#endif
#endif
TEST(Server, RunningOutOfFileDescriptorsDoesNotSpin) {
#if defined(__SANITIZE_ADDRESS__) || defined(HEMIBAKE_TEST_ASAN)
  // UndefinedBehaviorSanitizer's vptr check needs a file descriptor of its own: with none left it
  // reports any valid object as having an invalid vptr (as a ten-line program out of descriptors
  // shows), and the server aborts.
  GTEST_SKIP() << "needs file descriptors that a sanitized server cannot do without";
#endif
  ServerProcess server(temp_dir("fds"), {"--workers", "1"}, {}, 48);
  ASSERT_NE(server.port(), 0);
  net::io_context io;
  std::vector<tcp::socket> idle;
  for (int i = 0; i < 80; ++i) {
    idle.emplace_back(io);
    idle.back().connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), server.port()));
  }
  std::this_thread::sleep_for(300ms);
  const long before = cpu_ticks(server.pid());
  std::this_thread::sleep_for(2s);
  const long used = cpu_ticks(server.pid()) - before;
  EXPECT_LT(used, sysconf(_SC_CLK_TCK) / 4) << "clock ticks in 2 s with descriptors exhausted";
  idle.clear();
  EXPECT_EQ(request(server.port(), http::verb::get, "/healthz").status, 200);
}

// A web server that is not hemibake-server: every request gets 200 and an HTML page.
class NotHemibake {
 public:
  NotHemibake() : acceptor_(io_, tcp::endpoint(net::ip::make_address("127.0.0.1"), 0)) {
    accept();
    thread_ = std::thread([this] { io_.run_for(60s); });
  }
  ~NotHemibake() {
    io_.stop();
    thread_.join();
  }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(acceptor_.local_endpoint().port()); }

 private:
  void accept() {
    acceptor_.async_accept([this](beast::error_code ec, tcp::socket socket) {
      if (ec) return;
      auto s = std::make_shared<tcp::socket>(std::move(socket));
      auto buf = std::make_shared<std::string>();
      net::async_read_until(*s, net::dynamic_buffer(*buf), "\r\n\r\n", [s, buf](beast::error_code, size_t) {
        static const std::string page = "<html>hello</html>";
        auto res = std::make_shared<std::string>("HTTP/1.1 200 OK\r\nContent-Type: text/html\r\nContent-Length: " +
                                                 std::to_string(page.size()) + "\r\nConnection: close\r\n\r\n" + page);
        net::async_write(*s, net::buffer(*res), [s, res](beast::error_code, size_t) {});
      });
      accept();
    });
  }
  net::io_context io_;
  tcp::acceptor acceptor_;
  std::thread thread_;
};

// --server pointing at some other web server: a clear message and exit status 1, not a crash.
TEST(Client, ServerThatIsNotHemibakeIsReportedClearly) {
  NotHemibake other;
  const std::string glb = temp_dir("not-hemibake", ".glb");
  for (const std::string& command : std::vector<std::string>{"status abc", "list", "watch abc", "cancel abc", "fetch abc -o " + glb}) {
    const auto [status, out] = run(std::string(HEMIBAKE_CLIENT) + " " + command + " --server " + other.url());
    EXPECT_EQ(status, 1) << command << ": " << out;
    EXPECT_NE(out.find("is it a hemibake-server?"), std::string::npos) << command << ": " << out;
    EXPECT_EQ(out.find("<html>"), std::string::npos) << command << ": " << out;
  }
  EXPECT_FALSE(std::filesystem::exists(glb));
  // A job id the user mistyped with a space stays one path segment: the server says it has no such job.
  ServerProcess server(temp_dir("client-id"), {"--workers", "1"});
  const auto [status, out] = run(std::string(HEMIBAKE_CLIENT) + " status 'a b' --server http://127.0.0.1:" + std::to_string(server.port()));
  EXPECT_EQ(status, 1);
  EXPECT_NE(out.find("404: no job"), std::string::npos) << out;
}

// A proxy in front of a server that loses the server's answers to submissions, as a load balancer
// whose upstream timed out after the server had acted: each request is forwarded, and the answers
// to the first `lose` POSTs are replaced by 503 with Retry-After: 1. It records the
// Idempotency-Key each POST carried.
class LossyProxy {
 public:
  LossyProxy(unsigned short upstream, int lose)
      : upstream_(upstream), lose_(lose), acceptor_(io_, tcp::endpoint(net::ip::make_address("127.0.0.1"), 0)) {
    thread_ = std::thread([this] { serve(); });
  }
  ~LossyProxy() {
    stop_ = true;
    beast::error_code ec;
    tcp::socket wake(io_);
    wake.connect(acceptor_.local_endpoint(), ec);  // ends the blocking accept
    thread_.join();
  }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(acceptor_.local_endpoint().port()); }
  std::vector<std::string> keys() {
    std::lock_guard lock(mutex_);
    return keys_;
  }

 private:
  void serve() {
    while (!stop_) {
      beast::error_code ec;
      tcp::socket socket(io_);
      acceptor_.accept(socket, ec);
      if (ec || stop_) continue;
      beast::tcp_stream stream(std::move(socket));
      stream.expires_after(60s);
      beast::flat_buffer buffer;
      http::request<http::string_body> req;
      http::read(stream, buffer, req, ec);
      if (ec) continue;
      std::map<std::string, std::string> headers;
      for (const auto& f : req) headers[std::string(f.name_string())] = std::string(f.value());
      const Reply up = request(upstream_, req.method(), std::string(req.target()), req.body(), headers);
      http::response<http::string_body> res;
      res.version(11);
      res.keep_alive(false);
      bool lost = false;
      if (req.method() == http::verb::post) {
        std::lock_guard lock(mutex_);
        keys_.push_back(std::string(req["Idempotency-Key"]));
        lost = static_cast<int>(keys_.size()) <= lose_;
      }
      if (lost) {
        res.result(503);
        res.set(http::field::retry_after, "1");
        res.set(http::field::content_type, "application/json");
        res.body() = R"({"error":"the upstream did not answer in time"})";
      } else {
        res.result(up.status);
        for (const auto& [k, v] : up.headers)
          if (k != "content-length" && k != "connection") res.set(k, v);
        res.body() = up.body;
      }
      res.prepare_payload();
      http::write(stream, res, ec);
      stream.socket().shutdown(tcp::socket::shutdown_both, ec);
    }
  }
  unsigned short upstream_;
  int lose_;
  net::io_context io_;
  tcp::acceptor acceptor_;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::vector<std::string> keys_;
  std::thread thread_;
};

// The server made the job but its answer was lost (503 from a proxy): the client waits as
// Retry-After says, says so, and submits again with the same Idempotency-Key, so the server has
// one job, and the id printed is that job's. (The bake is long, so that no retry is answered from
// the cache of succeeded jobs instead.)
TEST(Client, SubmitWhoseAnswerWasLostIsRetriedIntoOneJob) {
  ServerProcess server(temp_dir("client-lost"), {"--workers", "1"});
  LossyProxy proxy(server.port(), 1);
  const auto [status, out] = run(std::string(HEMIBAKE_CLIENT) + " submit " HEMIBAKE_SOURCE_DIR
                                 "/data/cornell-box.gltf --convergence 0.000001 --aeps 0.00002 --server " + proxy.url());
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("503"), std::string::npos) << "the wait is not explained: " << out;
  const auto keys = proxy.keys();
  ASSERT_EQ(keys.size(), 2u) << out;
  EXPECT_FALSE(keys[0].empty()) << "the submission carried no Idempotency-Key";
  EXPECT_EQ(keys[0], keys[1]) << "the retry carried another key";
  const json jobs = request(server.port(), http::verb::get, "/v1/jobs").js()["jobs"];
  ASSERT_EQ(jobs.size(), 1u) << jobs.dump();
  EXPECT_NE(out.find(jobs[0]["id"].get<std::string>()), std::string::npos) << out;
}

// A server that stays unavailable: the client gives up after --retry-seconds with exit status 1 and
// the server's reason; its attempts still made one job.
TEST(Client, GivesUpOnAServerThatStaysUnavailable) {
  ServerProcess server(temp_dir("client-gives-up"), {"--workers", "1"});
  LossyProxy proxy(server.port(), 1000);
  const auto t0 = std::chrono::steady_clock::now();
  const auto [status, out] = run(std::string(HEMIBAKE_CLIENT) + " submit " HEMIBAKE_SOURCE_DIR
                                 "/data/cornell-box.gltf --convergence 0.000001 --aeps 0.00002 --retry-seconds 3 --server " +
                                 proxy.url());
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(status, 1) << out;
  EXPECT_NE(out.find("the upstream did not answer in time"), std::string::npos) << out;
  EXPECT_NE(out.find("3 s"), std::string::npos) << "the message does not say how long it waited: " << out;
  EXPECT_GE(seconds, 2.5) << out;
  EXPECT_LT(seconds, 15.0) << out;
  EXPECT_GE(proxy.keys().size(), 3u) << out;
  const json jobs = request(server.port(), http::verb::get, "/v1/jobs").js()["jobs"];
  EXPECT_EQ(jobs.size(), 1u) << jobs.dump();
}

// Bad options: exit status 2 and one line naming the problem, before anything starts.
TEST(Server, BadOptionsAreRefusedClearly) {
  const std::string dir = temp_dir("options");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--bogus", "unknown option '--bogus'"},
      {"--workers", "--workers needs a value"},
      {"--workers 1e12", "--workers needs a whole number"},
      {"--workers 0.5", "--workers needs a whole number"},
      {"--max-streams -1", "--max-streams needs a whole number"}};
  for (const auto& [options, message] : cases) {
    const auto [status, out] = run("timeout 10 " + std::string(HEMIBAKE_SERVER) + " --listen 127.0.0.1:0 --data " + dir + " " + options);
    EXPECT_EQ(status, 2) << options << ": " << out;
    EXPECT_NE(out.find(message), std::string::npos) << options << ": " << out;
  }
}

// Many clients at once, bounded in number and time: every request answered, no error.
TEST(Server, ManyConcurrentClientsAndStreams) {
  ServerProcess server(temp_dir("load"), {"--workers", "2"});
  const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.01", cornell(), kGltf);
  const std::string id = posted.js()["id"];
  std::atomic<int> failures{0};
  std::vector<std::thread> clients;
  for (int c = 0; c < 16; ++c) {
    clients.emplace_back([&, c] {
      try {
        if (c % 4 == 0) {
          const auto evs = events(server.port(), id);
          if (evs.empty() || json::parse(std::get<2>(evs.back()))["state"] != "succeeded") ++failures;
          return;
        }
        for (int i = 0; i < 20; ++i) {
          const Reply r = request(server.port(), http::verb::get, i % 2 ? "/v1/jobs" : "/v1/jobs/" + id);
          if (r.status != 200) ++failures;
        }
      } catch (const std::exception&) {
        ++failures;
      }
    });
  }
  for (auto& t : clients) t.join();
  EXPECT_EQ(failures.load(), 0);
}

// Request handling never holds an I/O thread: while four clients wait for previews of a job with
// long shots and a 200 MB scene arrives and is checked, /healthz answers each time within 100 ms.
TEST(Server, HealthzAnswersWhilePreviewsWaitAndALargeSceneIsChecked) {
  ServerProcess server(temp_dir("busy"), {"--workers", "1"});
  ASSERT_NE(server.port(), 0);
  const unsigned short port = server.port();
  // 1024² hemicubes, none replayed: every shot takes a few tenths of a second or more (for minutes),
  // and a preview waits for one.
  const Reply posted = request(port, http::verb::post, "/v1/jobs?resolution=1024&reuse=false&convergence=0.00001", cornell(), kGltf);
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = posted.js()["id"];
  for (int i = 0; i < 200 && request(port, http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
    std::this_thread::sleep_for(20ms);
  ASSERT_EQ(request(port, http::verb::get, "/v1/jobs/" + id).js()["state"], "running");

  std::atomic<bool> stop{false};
  std::atomic<int> previews{0}, preview_failures{0};
  std::mutex failure_mutex;
  std::string first_failure;
  std::vector<std::thread> waiting;
  for (int c = 0; c < 4; ++c) {
    waiting.emplace_back([&] {
      while (!stop) {
        std::string failure;
        try {
          const Reply r = request(port, http::verb::get, "/v1/jobs/" + id + "/preview");
          if (r.status == 200 && r.body.substr(0, 4) == "glTF") ++previews;
          else failure = std::to_string(r.status) + " " + r.body;
        } catch (const std::exception& e) {
          failure = e.what();
        }
        if (!failure.empty()) {
          ++preview_failures;
          std::lock_guard lock(failure_mutex);
          if (first_failure.empty()) first_failure = failure;
        }
      }
    });
  }
  std::this_thread::sleep_for(300ms);  // the previews are asked for and wait for a shot

  std::atomic<bool> sent{false}, answered{false};
  std::chrono::steady_clock::time_point sent_at, answered_at;  // written before the flags are set
  Reply large;
  std::thread poster([&, body = hemibake::test::dark_glb_with_padding(cornell(), 200u << 20)]() mutable {
    // This client's bulk upload yields to its own health probes: their latency is the server's.
    setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 10);
    try {
      net::io_context io;
      beast::tcp_stream stream(io);
      stream.expires_after(180s);
      stream.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
      http::request<http::string_body> req(http::verb::post, "/v1/jobs", 11);
      req.set(http::field::host, "127.0.0.1");
      req.set(http::field::content_type, "model/gltf-binary");
      req.body() = std::move(body);
      req.prepare_payload();
      http::write(stream, req);
      sent_at = std::chrono::steady_clock::now();
      sent = true;
      beast::flat_buffer buffer;
      http::response<http::string_body> res;
      http::read(stream, buffer, res);
      large.status = static_cast<int>(res.result_int());
      large.body = res.body();
    } catch (const std::exception& e) {
      large.body = e.what();
    }
    answered_at = std::chrono::steady_clock::now();
    answered = true;
  });

  // Round trips on fresh connections, from the start of the upload until the scene's answer: the
  // slowest while the body arrived, and while it was checked (after the client had sent it all).
  double slowest_upload = 0.0, slowest_check = 0.0;
  int during_upload = 0, during_check = 0;
  while (!answered) {
    const bool checking = sent;
    const auto t0 = std::chrono::steady_clock::now();
    const Reply h = request(port, http::verb::get, "/healthz");
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(h.status, 200);
    if (checking && !answered) {
      slowest_check = std::max(slowest_check, ms);
      ++during_check;
    } else if (!checking) {
      slowest_upload = std::max(slowest_upload, ms);
      ++during_upload;
    }
    std::this_thread::sleep_for(20ms);
  }
  poster.join();
  stop = true;
  for (auto& t : waiting) t.join();
  std::printf("healthz: slowest %.1f ms of %d round trips while the body arrived, %.1f ms of %d while it was checked; "
              "%d previews made\n",
              slowest_upload, during_upload, slowest_check, during_check, previews.load());
  // A health check that waited for the scene's check would take about as long as the check: the
  // slowest stays under half of it (or 100 ms, whichever is more; 101.8 ms once on a loaded machine
  // for a check of several hundred ms).
  const double check_ms = sent ? std::chrono::duration<double, std::milli>(answered_at - sent_at).count() : 0.0;
  std::printf("the scene's check took %.0f ms\n", check_ms);
  EXPECT_LT(slowest_upload, 100.0);
  EXPECT_LT(slowest_check, std::max(100.0, 0.5 * check_ms));
  EXPECT_GE(during_check, 3) << "too few round trips while the scene was checked to show anything";
  EXPECT_EQ(large.status, 422) << large.body;
  EXPECT_NE(large.body.find("emits no light"), std::string::npos) << large.body;
  EXPECT_GE(previews.load(), 4);
  EXPECT_EQ(preview_failures.load(), 0) << "the first: " << first_failure;
  request(port, http::verb::delete_, "/v1/jobs/" + id);
}

// Bytes a process has read through read calls (files and pipes), from /proc/PID/io.
uint64_t bytes_read(pid_t pid) {
  std::istringstream io(read_file("/proc/" + std::to_string(pid) + "/io"));
  for (std::string key; io >> key;) {
    uint64_t value = 0;
    io >> value;
    if (key == "rchar:") return value;
  }
  return 0;
}

// A running job with long shots (1024² hemicubes, none replayed), so that the next one stays queued.
std::string start_slow_job(unsigned short port) {
  const Reply posted = request(port, http::verb::post, "/v1/jobs?resolution=1024&reuse=false&convergence=0.00001", cornell(), kGltf);
  EXPECT_EQ(posted.status, 202) << posted.body;
  const std::string id = posted.js()["id"];
  for (int i = 0; i < 200 && request(port, http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
    std::this_thread::sleep_for(20ms);
  return id;
}

// Status reads, lists and event streams touch only a job's small columns: with 16 streams watching
// a job whose scene is 48 MB, and status and list requests for it, the server reads next to
// nothing from its store (it read the whole scene for each, 5 times a second per stream).
TEST(Server, StatusListsAndStreamsDoNotReadScenes) {
  ServerProcess server(temp_dir("small-reads"), {"--workers", "1"});
  ASSERT_NE(server.port(), 0);
  const unsigned short port = server.port();
  const std::string slow = start_slow_job(port);
  const Reply big = request(port, http::verb::post, "/v1/jobs", hemibake::test::glb_with_padding(cornell(), 48u << 20),
                            {{"Content-Type", "model/gltf-binary"}});
  ASSERT_EQ(big.status, 202) << big.body;
  const std::string id = big.js()["id"];
  ASSERT_EQ(big.js()["state"], "queued");
  net::io_context io;
  std::vector<tcp::socket> streams;
  for (int i = 0; i < 16; ++i) {
    streams.emplace_back(io);
    streams.back().connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
    net::write(streams.back(), net::buffer("GET /v1/jobs/" + id + "/events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"));
  }
  std::this_thread::sleep_for(500ms);
  const uint64_t before = bytes_read(server.pid());
  for (int i = 0; i < 10; ++i) EXPECT_EQ(request(port, http::verb::get, "/v1/jobs/" + id).js()["scene_bytes"].get<uint64_t>() >> 20, 48u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(request(port, http::verb::get, "/v1/jobs").status, 200);
  std::this_thread::sleep_for(2s);
  const uint64_t read = bytes_read(server.pid()) - before;
  std::printf("read %.1f MB in 2 s with 16 streams, 10 status and 3 list requests\n", read / 1e6);
  EXPECT_LT(read, 4u << 20);
  streams.clear();
  request(port, http::verb::delete_, "/v1/jobs/" + id);
  request(port, http::verb::delete_, "/v1/jobs/" + slow);
}

// A Transfer-Encoding whose last coding is not chunked, or that names chunked twice, leaves the
// body's length unknown to one reader and known to another (RFC 9112, section 6.3): refused with
// 400 and the connection closed, so that a request hidden in the body never runs (a DELETE did).
// A coding before chunked that the server cannot decode is 501.
TEST(Server, TransferEncodingsThatHideARequestAreRefused) {
  ServerProcess server(temp_dir("smuggle"), {"--workers", "1"});
  ASSERT_NE(server.port(), 0);
  const std::string slow = start_slow_job(server.port());
  ASSERT_EQ(request(server.port(), http::verb::get, "/v1/jobs/" + slow).js()["state"], "running");
  const std::string hidden = "DELETE /v1/jobs/" + slow + " HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"Transfer-Encoding: gzip\r\n", "400"},
      {"Transfer-Encoding: chunked, chunked\r\n", "400"},
      {"Transfer-Encoding: chunked\r\nTransfer-Encoding: chunked\r\n", "400"},
      {"Transfer-Encoding: chunked, identity\r\n", "400"},
      {"Transfer-Encoding: CHUNKED , gzip\r\n", "400"},
      {"Transfer-Encoding: gzip, chunked\r\n", "501"},
  };
  for (const auto& [te, status] : cases) {
    bool timed_out = false;
    const std::string all = exchange(server.port(),
                                     "POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: model/gltf+json\r\n" + te +
                                         "\r\n" + hidden,
                                     10s, &timed_out);
    EXPECT_EQ(all.rfind("HTTP/1.1 " + status, 0), 0u) << te << all;
    EXPECT_EQ(responses(all), 1u) << te << all;
    EXPECT_FALSE(timed_out) << te << ": the connection stayed open";
    EXPECT_NE(all.find("Connection: close"), std::string::npos) << te << all;
  }
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs/" + slow).js()["state"], "running");
  // Chunked alone is a body like any other.
  const std::string chunked = exchange(server.port(),
                                       "POST /v1/jobs?pools=false&convergence=0.3 HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: model/gltf+json\r\n"
                                       "Transfer-Encoding: chunked\r\nConnection: close\r\n\r\n" +
                                           [] {
                                             std::ostringstream hex;
                                             hex << std::hex << cornell().size();
                                             return hex.str();
                                           }() + "\r\n" + cornell() + "\r\n0\r\n\r\n",
                                       10s);
  EXPECT_EQ(chunked.rfind("HTTP/1.1 202", 0), 0u) << chunked;
  request(server.port(), http::verb::delete_, "/v1/jobs/" + slow);
}

// The token is checked from the headers: a request without one gets 401 at once and the
// connection is closed, before any of its body is read (four unauthenticated 256 MB uploads held
// 1 GB of memory).
TEST(Server, TokenIsCheckedBeforeTheBodyIsRead) {
  ServerProcess server(temp_dir("auth-first"), {"--workers", "1"}, {"HEMIBAKE_TOKENS=s3cret"});
  ASSERT_NE(server.port(), 0);
  bool timed_out = false;
  const auto t0 = std::chrono::steady_clock::now();
  const std::string all = exchange(server.port(),
                                   "POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: model/gltf-binary\r\n"
                                   "Content-Length: 200000000\r\n\r\nglTF",
                                   10s, &timed_out);
  EXPECT_FALSE(timed_out) << "no answer before the body";
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 5s);
  EXPECT_EQ(all.rfind("HTTP/1.1 401", 0), 0u) << all;
  EXPECT_NE(all.find("WWW-Authenticate: Bearer"), std::string::npos) << all;
  // With the token, the same headers wait for the body.
  const std::string allowed = exchange(server.port(),
                                       "POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: model/gltf-binary\r\n"
                                       "Authorization: Bearer s3cret\r\nContent-Length: 200000000\r\n\r\nglTF",
                                       2s, &timed_out);
  EXPECT_TRUE(timed_out) << allowed;
  EXPECT_EQ(allowed, "");
}

// Sends `body` after `head` at `rate` bytes per second (what is due every 50 ms, so that a late
// wake-up on a busy machine does not slow it), stopping early if an answer comes; then reads the
// answer.
std::string upload_slowly(unsigned short port, const std::string& head, const std::string& body, double rate) {
  net::io_context io;
  tcp::socket socket(io);
  socket.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
  net::write(socket, net::buffer(head));
  const auto t0 = std::chrono::steady_clock::now();
  beast::error_code ec;
  for (size_t sent = 0; sent < body.size() && !ec;) {
    std::this_thread::sleep_for(50ms);
    pollfd p{socket.native_handle(), POLLIN, 0};
    if (poll(&p, 1, 0) > 0) break;  // answered already
    const double due = rate * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const size_t target = std::min(body.size(), static_cast<size_t>(due));
    if (target <= sent) continue;
    net::write(socket, net::buffer(body.data() + sent, target - sent), ec);
    sent = target;
  }
  return read_until_closed(socket, 60s, nullptr);
}

// Timeouts: an idle connection is closed, headers that do not arrive in time and a body that
// arrives too slowly are answered 408; a slow but steady upload that takes longer than 30 s (once
// the limit for a whole request) is accepted.
TEST(Server, SlowButSteadyUploadsSucceedAndTooSlowOnesGet408) {
  ServerProcess strict(temp_dir("timeouts"), {"--workers", "1", "--idle-timeout", "1", "--header-timeout", "1",
                                              "--min-rate", "20000"});
  ASSERT_NE(strict.port(), 0);
  bool timed_out = false;
  auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(exchange(strict.port(), "", 10s, &timed_out), "");  // idle: closed without a word
  EXPECT_FALSE(timed_out);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s);
  t0 = std::chrono::steady_clock::now();
  const std::string header = exchange(strict.port(), "GET /healthz HTTP/1.1\r\nHo", 10s, &timed_out);
  EXPECT_EQ(header.rfind("HTTP/1.1 408", 0), 0u) << header;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s);
  const std::string scene = hemibake::test::glb_with_padding(cornell(), 600'000);
  const std::string head = "POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\nContent-Type: model/gltf-binary\r\nContent-Length: " +
                           std::to_string(scene.size()) + "\r\n\r\n";
  t0 = std::chrono::steady_clock::now();
  const std::string slow = upload_slowly(strict.port(), head, scene, 10'000);
  EXPECT_EQ(slow.rfind("HTTP/1.1 408", 0), 0u) << slow;
  EXPECT_NE(slow.find("20000 bytes per second"), std::string::npos) << slow;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 10s);

  // The defaults (at least 16 KB/s on average): 600 KB at 19 KB/s, for more than 30 s.
  ServerProcess server(temp_dir("steady"), {"--workers", "1"});
  t0 = std::chrono::steady_clock::now();
  const std::string steady = upload_slowly(server.port(), head, scene, 19'000);
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("%zu bytes uploaded in %.1f s\n", scene.size(), took);
  EXPECT_GT(took, 30.0);
  EXPECT_EQ(steady.rfind("HTTP/1.1 202", 0), 0u) << steady;
}

// Smaller things from a probe: Expect: 100-continue is answered before the body is sent; HEAD on
// an event stream has the GET's status and type; the Bearer scheme is matched in any case
// (RFC 9110, section 11.1); a Last-Event-ID that is not a whole number replays from the start.
TEST(Server, ContinueHeadOnEventsBearerCaseAndBadLastEventId) {
  ServerProcess server(temp_dir("small"), {"--workers", "1"}, {"HEMIBAKE_TOKENS=s3cret"});
  ASSERT_NE(server.port(), 0);
  const std::map<std::string, std::string> auth = {{"Authorization", "bearer s3cret"}};
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs", "", auth).status, 200);
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs", "", {{"Authorization", "BEARER   s3cret"}}).status, 200);
  EXPECT_EQ(request(server.port(), http::verb::get, "/v1/jobs", "", {{"Authorization", "Basic s3cret"}}).status, 401);

  bool timed_out = false;
  const std::string cont = exchange(server.port(),
                                    "POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: model/gltf+json\r\n"
                                    "Authorization: Bearer s3cret\r\nExpect: 100-continue\r\nContent-Length: 5618\r\n\r\n",
                                    3s, &timed_out);
  EXPECT_EQ(cont, "HTTP/1.1 100 Continue\r\n\r\n");
  // Refused from the headers: no 100, the final answer at once.
  const std::string refused = exchange(server.port(),
                                       "POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: model/gltf+json\r\n"
                                       "Expect: 100-continue\r\nContent-Length: 5618\r\n\r\n",
                                       3s, &timed_out);
  EXPECT_EQ(refused.rfind("HTTP/1.1 401", 0), 0u) << refused;

  const Reply posted = request(server.port(), http::verb::post, "/v1/jobs?pools=false&convergence=0.3", cornell(),
                               {{"Content-Type", "model/gltf+json"}, {"Authorization", "Bearer s3cret"}});
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = posted.js()["id"];
  const Reply head = request(server.port(), http::verb::head, "/v1/jobs/" + id + "/events", "", auth);
  EXPECT_EQ(head.status, 200);
  EXPECT_EQ(head.headers.count("content-type") ? head.headers.at("content-type") : "", "text/event-stream");
  EXPECT_EQ(request(server.port(), http::verb::head, "/v1/jobs/nope/events", "", auth).status, 404);

  for (int i = 0; i < 200 && request(server.port(), http::verb::get, "/v1/jobs/" + id, "", auth).js()["state"] != "succeeded"; ++i)
    std::this_thread::sleep_for(50ms);
  auto first_id = [&](const std::string& last) {
    const std::string all = exchange(server.port(), "GET /v1/jobs/" + id + "/events HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                     "Authorization: Bearer s3cret\r\nLast-Event-ID: " + last + "\r\n\r\n", 10s);
    const size_t at = all.find("\nid: ");
    return at == std::string::npos ? std::string("none") : all.substr(at + 5, all.find('\n', at + 5) - at - 5);
  };
  EXPECT_EQ(first_id("-5"), "1");
  EXPECT_EQ(first_id("abc"), "1");
  EXPECT_EQ(first_id("99999999999999999999999"), "1");
  EXPECT_EQ(first_id("1"), "2");
}

// A real full disk: the data directory on an 8 MB tmpfs of the server's own (a user and mount
// namespace, so no privilege is needed), filled up while a job bakes. The result cannot be
// written: once space is back, the job is failed with the reason (not left running), its stream
// has ended, and the next job succeeds.
TEST(Server, FullDiskDuringABakeFailsTheJobAndTheServerRecovers) {
  if (std::system("unshare -rm sh -c 'mount -t tmpfs -o size=1m tmpfs /tmp' 2>/dev/null") != 0)
    GTEST_SKIP() << "no user and mount namespaces here (unshare -rm)";
  const std::string dir = temp_dir("full-disk");
  std::filesystem::create_directories(dir);
  const std::string errors = temp_dir("full-disk", "-stderr.log");
  ServerProcess server(dir, {"--workers", "1"}, {}, 0,
                       {"/usr/bin/unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=8m tmpfs \"$4\" && exec \"$0\" \"$@\""}, errors);
  ASSERT_NE(server.port(), 0) << read_file(errors);
  const unsigned short port = server.port();
  // The server's view of its data directory (its mount namespace).
  const std::string inside = "/proc/" + std::to_string(server.pid()) + "/root" + dir;
  ASSERT_TRUE(std::filesystem::exists(inside + "/hemibake.db"));
  const std::string id = request(port, http::verb::post, "/v1/jobs?resolution=512&reuse=false&max_shots=3&pools=false", cornell(), kGltf).js()["id"];
  // The waits below are bounds on liveness, generous for an instrumented build on a loaded machine
  // (this test once failed there at 104 s; alone it takes 48 s).
  for (int i = 0; i < 3000 && request(port, http::verb::get, "/v1/jobs/" + id).js()["state"] != "running"; ++i)
    std::this_thread::sleep_for(20ms);
  {
    std::ofstream ballast(inside + "/ballast", std::ios::binary);
    const std::string mb(1 << 20, 'x');
    for (int i = 0; i < 16 && ballast.write(mb.data(), static_cast<std::streamsize>(mb.size())); ++i) {}
  }
  // Full: a submission is refused cleanly, with nothing queued.
  const Reply refused = request(port, http::verb::post, "/v1/jobs?pools=false&convergence=0.3", cornell(), kGltf);
  EXPECT_EQ(refused.status, 500) << refused.body;
  EXPECT_TRUE(refused.js().contains("error")) << refused.body;
  // Space comes back once the worker has found that the result cannot be written.
  bool seen = false;
  for (int i = 0; i < 1500 && !(seen = read_file(errors).find("the result of " + id + " could not be stored") != std::string::npos); ++i)
    std::this_thread::sleep_for(100ms);
  EXPECT_TRUE(seen) << read_file(errors);
  std::filesystem::remove(inside + "/ballast");
  const json job = wait_finished(port, id, 60s);
  EXPECT_EQ(job["state"], "failed") << job.dump() << "\n" << read_file(errors);
  EXPECT_NE(job.value("error", "").find("the result could not be stored"), std::string::npos) << job.dump();
  EXPECT_NE(job.value("error", "").find("full"), std::string::npos) << job.dump();
  const auto evs = events(port, id);  // returns only once the stream has ended
  ASSERT_FALSE(evs.empty());
  EXPECT_EQ(json::parse(std::get<2>(evs.back())).value("state", ""), "failed");
  const Reply next = request(port, http::verb::post, "/v1/jobs?pools=false&convergence=0.2", cornell(), kGltf);
  ASSERT_EQ(next.status, 202) << next.body;
  EXPECT_EQ(wait_finished(port, next.js()["id"])["state"], "succeeded");
}

}  // namespace

namespace {

// A field of /proc/PID/status in KiB: VmRSS (resident now) or VmHWM (its peak).
uint64_t status_kib(pid_t pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind(field + ":", 0) == 0) return std::stoull(line.substr(field.size() + 1));
  return 0;
}
uint64_t rss_kib(pid_t pid) { return status_kib(pid, "VmRSS"); }

}  // namespace

// A result is read from the store in parts as the connection takes them, never whole: eight
// clients that start downloading a 64 MB result and then stall hold the server's memory (its RSS,
// read from the kernel) by far less than one result; read whole, each held it (and a copy). Each
// download, finished, has every byte that was stored.
TEST(Server, ResultsAreStreamedFromTheStoreNotHeldWhole) {
  const std::string dir = temp_dir("stream");
  std::string result(64u << 20, '\0');
  std::mt19937_64 rng(7);
  for (size_t i = 0; i + 8 <= result.size(); i += 8) {
    const uint64_t v = rng();
    std::memcpy(result.data() + i, &v, 8);
  }
  std::string id;
  {
    std::string error;
    auto store = hemibake::server::Store::open(dir, error);
    ASSERT_TRUE(store) << error;
    id = store->create("{}", "model/gltf+json", "{}", "key", "").id;
    std::string claimed, scene, params;
    ASSERT_TRUE(store->claim(claimed, scene, params));
    ASSERT_TRUE(store->succeed(id, result, "\"e\"").made);
  }
  ServerProcess server(dir, {"--workers", "1"});
  ASSERT_NE(server.port(), 0);
  ASSERT_EQ(request(server.port(), http::verb::get, "/healthz").status, 200);
  const uint64_t before = rss_kib(server.pid());
  // Eight downloads that read the response's head and a little, then stop reading.
  net::io_context io;
  std::vector<std::unique_ptr<tcp::socket>> clients;
  const std::string get = "GET /v1/jobs/" + id + "/result HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
  std::vector<std::string> heads;
  for (int c = 0; c < 8; ++c) {
    auto s = std::make_unique<tcp::socket>(io);
    s->connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), server.port()));
    s->set_option(net::socket_base::receive_buffer_size(64 << 10));
    net::write(*s, net::buffer(get));
    std::string got(64 << 10, '\0');
    got.resize(net::read(*s, net::buffer(got), net::transfer_exactly(got.size())));
    heads.push_back(got);
    clients.push_back(std::move(s));
  }
  std::this_thread::sleep_for(1s);  // the server sends what the sockets take, then waits
  const uint64_t during = rss_kib(server.pid());
  std::printf("server RSS %.1f MB before, %.1f MB with 8 stalled downloads of a %zu MB result\n", before / 1024.0,
              during / 1024.0, result.size() >> 20);
  EXPECT_LT(during, before + (result.size() >> 10)) << "the stalled downloads hold whole results";
  // Now each download is read to its end and compared with what was stored.
  for (int c = 0; c < 8; ++c) {
    std::string body = heads[c];
    const size_t head_end = body.find("\r\n\r\n");
    ASSERT_NE(head_end, std::string::npos);
    EXPECT_NE(body.find("Content-Length: " + std::to_string(result.size())), std::string::npos) << body.substr(0, head_end);
    body.erase(0, head_end + 4);
    std::string rest(result.size() - body.size(), '\0');
    beast::error_code ec;
    const size_t n = net::read(*clients[c], net::buffer(rest), net::transfer_exactly(rest.size()), ec);
    body.append(rest, 0, n);
    EXPECT_EQ(body.size(), result.size()) << ec.message();
    EXPECT_TRUE(body == result) << "download " << c << " differs from the stored result";
  }
}

// The memory budget per job holds in a running bake, not only in the estimate at submit: under a
// --max-job-mb equal to the job's own estimate (read from the 422 of a server with a 1 MB budget,
// rounded up), the job is accepted and the server's peak RSS (VmHWM, the kernel's) grows by less
// than the budget over its RSS before the submission; its elements stay within the count the estimate
// allowed; the same scene with hemicubes twice as wide is refused with 422. The Blender room with a
// ceiling panel at a 16 MB shot cache and AEPS 3e-4: its sharp splits along the panel's outline
// take it to about twice 1/aeps elements (6110), which the estimate once took for a bound (38 MB
// estimated, 46 MB used at AEPS 1e-4); it bakes in about 3 s (Release).
void bake_stays_within_its_memory_budget(const std::string& path) {
  const std::string scene = read_file(path);
  const std::map<std::string, std::string> glb = {{"Content-Type", "model/gltf-binary"}};
  const std::string job = "/v1/jobs?shot_cache_mb=16&max_elements=12000&aeps=0.0003";
  uint64_t budget_mb = 0, element_limit = 0;
  {
    ServerProcess probe(temp_dir("budget-probe"), {"--workers", "1", "--max-job-mb", "1"});
    const Reply r = request(probe.port(), http::verb::post, job, scene, glb);
    ASSERT_EQ(r.status, 422) << r.body;
    const std::string e = r.js().value("error", "");
    ASSERT_EQ(std::sscanf(e.c_str(), "the job would need about %" SCNu64 " MB", &budget_mb), 1) << e;
    const size_t up_to = e.find("; up to ");
    ASSERT_NE(up_to, std::string::npos) << e;
    element_limit = std::stoull(e.substr(up_to + 8));
  }
  ASSERT_GT(budget_mb, 16u);
  EXPECT_LE(element_limit, 12000u);
  ++budget_mb;  // the message rounds the estimate to the nearest MB
  ServerProcess server(temp_dir("budget"), {"--workers", "1", "--max-job-mb", std::to_string(budget_mb)});
  ASSERT_EQ(request(server.port(), http::verb::get, "/healthz").status, 200);
  const uint64_t before = rss_kib(server.pid());
  const Reply wider = request(server.port(), http::verb::post, job + "&resolution=200", scene, glb);
  EXPECT_EQ(wider.status, 422) << wider.body;
  EXPECT_NE(wider.body.find("limit of " + std::to_string(budget_mb) + " MB per job"), std::string::npos) << wider.body;
  const Reply posted = request(server.port(), http::verb::post, job, scene, glb);
  ASSERT_EQ(posted.status, 202) << posted.body;
#if defined(__SANITIZE_ADDRESS__) || defined(HEMIBAKE_TEST_ASAN)
  // AddressSanitizer's redzones, quarantine and shadow memory inflate the RSS several times over,
  // and its bake of this room takes minutes: the running bake is measured in the Release build.
  GTEST_SKIP() << "the RSS of a server built with AddressSanitizer is not its memory";
#endif
  const json done = wait_finished(server.port(), posted.js()["id"]);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  EXPECT_LE(done["progress"]["elements"].get<uint64_t>(), element_limit);
  const uint64_t peak = status_kib(server.pid(), "VmHWM");
  std::printf("budget %" PRIu64 " MB (the job's estimate), %" PRIu64 " elements of %" PRIu64 " allowed; RSS %.1f MB before, peak %.1f MB: grew by %.1f MB\n",
              budget_mb, done["progress"]["elements"].get<uint64_t>(), element_limit, before / 1024.0, peak / 1024.0,
              (peak - before) / 1024.0);
  EXPECT_LT(peak - before, budget_mb << 10) << "the bake's peak memory passed its budget";
}

TEST(Server, BakeStaysWithinItsMemoryBudget) {
  bake_stays_within_its_memory_budget(HEMIBAKE_SOURCE_DIR "/tests/data/blender/room-panel.glb");
}

// The same for a room lit by a point light, whose shot projects onto a finer cube (256 a side, two
// hemicubes back to back) than the job's hemicubes, which the estimate counts (111 MB estimated,
// 58 MB used when written; 72 MB estimated without the cube, still above what it used).
TEST(Server, PointLitBakeStaysWithinItsMemoryBudget) {
  bake_stays_within_its_memory_budget(HEMIBAKE_SOURCE_DIR "/tests/data/blender-point.glb");
}

// SIGKILL at random moments while clients submit and cancel jobs, over HEMIBAKE_KILL_RUNS runs on
// one data directory (4 by default; the test labelled slow runs 100): every job whose submission
// was acknowledged is still there after the restarts and ends; no job both cancelled and
// succeeded (by its state, its stream and its result); a cancellation acknowledged is kept; a job
// fails only by being killed during each of its attempts.
TEST(Server, RandomSigkillsLoseNoAcknowledgedJob) {
  const int runs = std::getenv("HEMIBAKE_KILL_RUNS") ? std::atoi(std::getenv("HEMIBAKE_KILL_RUNS")) : 4;
  const unsigned seed = std::random_device{}();
  std::printf("seed %u, %d runs\n", seed, runs);
  std::mt19937 rng(seed);
  const std::string dir = temp_dir("kills");
  std::mutex m;
  std::vector<std::string> acked;          // submissions answered 202 or 200
  std::set<std::string> cancel_acked;      // DELETEs answered 200 with the state cancelled
  int submitted = 0;
  for (int run = 0; run < runs; ++run) {
    ServerProcess server(dir, {"--workers", "2"});
    ASSERT_NE(server.port(), 0) << "run " << run;
    const unsigned short port = server.port();
    std::atomic<bool> stop{false};
    std::vector<std::thread> clients;
    for (int c = 0; c < 2; ++c) {
      clients.emplace_back([&, c, client_seed = static_cast<unsigned>(rng())] {
        std::mt19937 r(client_seed);
        while (!stop) {
          try {
            // Parameters that differ each time, so that no submission is a cache hit of another; small
            // bakes (a coarse hemicube, a few shots), so that the sanitizer build finishes the ~100
            // jobs of 4 runs well within the test's time on a loaded machine.
            const double convergence = 0.2 + std::uniform_real_distribution<double>(0, 0.3)(r);
            const Reply posted = request(port, http::verb::post,
                                         "/v1/jobs?pools=false&resolution=32&max_shots=30&convergence=" + std::to_string(convergence),
                                         cornell(), kGltf);
            std::string id;
            if (posted.status == 202 || posted.status == 200) {
              id = posted.js().value("id", "");
              std::lock_guard lock(m);
              acked.push_back(id);
              ++submitted;
            }
            if (c == 1 && !id.empty() && r() % 3 == 0) {
              const Reply d = request(port, http::verb::delete_, "/v1/jobs/" + id);
              if (d.status == 200 && d.js().value("state", "") == "cancelled") {
                std::lock_guard lock(m);
                cancel_acked.insert(id);
              }
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(20 + r() % 80));
          } catch (const std::exception&) {
            std::this_thread::sleep_for(10ms);  // killed: the next run's server is another port
          }
        }
      });
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(std::uniform_int_distribution<int>(50, 1500)(rng)));
    server.stop(SIGKILL);
    stop = true;
    for (auto& t : clients) t.join();
  }
  ServerProcess server(dir, {"--workers", "2"});
  const unsigned short port = server.port();
  std::map<std::string, int> ends;
  int lost = 0, both = 0, unkept = 0;
  for (const std::string& id : acked) {
    const Reply got = request(port, http::verb::get, "/v1/jobs/" + id);
    if (got.status != 200) {
      ++lost;
      ADD_FAILURE() << "acknowledged job " << id << " is lost (" << got.status << ")";
      continue;
    }
    const json job = wait_finished(port, id, 300s);
    const std::string state = job.value("state", "");
    ++ends[state];
    // The one way to fail here: killed during each of its --max-attempts runs.
    if (state == "failed") {
      EXPECT_NE(job.value("error", "").find("the server stopped during each of its"), std::string::npos)
          << "job " << id << " failed: " << job.value("error", "");
    }
    bool succeeded = false, cancelled = false;
    for (const auto& [eid, type, data] : events(port, id)) {
      if (type != "state") continue;
      const std::string s = json::parse(data).value("state", "");
      succeeded = succeeded || s == "succeeded";
      cancelled = cancelled || s == "cancelled";
    }
    const int result = request(port, http::verb::get, "/v1/jobs/" + id + "/result").status;
    if ((succeeded && cancelled) || (state == "cancelled" && (succeeded || result == 200)) ||
        (state == "succeeded" && (cancelled || result != 200))) {
      ++both;
      ADD_FAILURE() << "job " << id << " is " << state << " with events succeeded=" << succeeded
                    << " cancelled=" << cancelled << " and its result " << result;
    }
    if (cancel_acked.count(id) && state != "cancelled") {
      ++unkept;
      ADD_FAILURE() << "job " << id << " was cancelled (200) and is now " << state;
    }
  }
  std::printf("%d runs, %d submissions acknowledged, %zu cancellations acknowledged; lost %d, both %d, cancellation not kept %d; ends:",
              runs, submitted, cancel_acked.size(), lost, both, unkept);
  for (const auto& [s, n] : ends) std::printf(" %s %d", s.c_str(), n);
  std::printf("\n");
  EXPECT_GT(submitted, runs);  // the runs were not all refused before the kill
}
