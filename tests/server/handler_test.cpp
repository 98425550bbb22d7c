// The request handler as a function of the request: no sockets, a store in a temporary folder.
#include "hemibake/server/service.h"

#include "dark_glb.h"
#include "faulty_store.h"
#include "pg_server.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sqlite3.h>
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>
#include <sstream>
#include <thread>
#include <sys/resource.h>
#include <unistd.h>
#include <vector>

namespace hemibake::server {
namespace {

using nlohmann::json;

// HEMIBAKE_TEST_STORE=postgresql runs these tests on the shared store (a PostgreSQL started for
// them, a fresh database per fixture); CTest does that as handler_tests_postgresql.
bool on_postgres() {
  const char* e = std::getenv("HEMIBAKE_TEST_STORE");
  return e && std::string(e) == "postgresql";
}
hemibake_test::PgServer& postgres() {
  static hemibake_test::PgServer server;
  return server;
}
std::string postgres_database() {
  static int n = 0;
  return postgres().create_database("handler" + std::to_string(getpid()) + "_" + std::to_string(n++));
}
// Without PostgreSQL's binaries every test skips, saying why.
class PostgresEnvironment : public ::testing::Environment {
 public:
  void SetUp() override {
    if (!postgres().available()) GTEST_SKIP() << "PostgreSQL tests skipped: " << postgres().why();
  }
};
[[maybe_unused]] ::testing::Environment* const postgres_environment =
    on_postgres() ? ::testing::AddGlobalTestEnvironment(new PostgresEnvironment) : nullptr;

struct Fixture {
  std::string dir;
  std::unique_ptr<Service> service;
  test::FaultyStore* store = nullptr;  // with a `fault`: the service's store
  explicit Fixture(ServiceOptions o = {}, test::FaultyStore::Fault fault = nullptr, int busy_ms = 10000) {
    dir = (std::filesystem::temp_directory_path() / ("hemibake-handler-" + std::to_string(getpid()))).string();
    std::filesystem::remove_all(dir);
    o.data_dir = dir;
    o.workers = 1;
    if (on_postgres()) o.store_uri = postgres_database();
    std::string error;
    if (fault) {
      auto real = o.store_uri.empty() ? Store::open(dir, error, busy_ms) : Store::open_postgres(o.store_uri, PgOptions{}, error);
      EXPECT_TRUE(real) << error;
      auto faulty = std::make_unique<test::FaultyStore>(std::move(real), std::move(fault));
      store = faulty.get();
      service = Service::start(o, std::move(faulty), error);
    } else {
      service = Service::start(o, error);
    }
    EXPECT_TRUE(service) << error;
  }
  ~Fixture() {
    service.reset();
    std::filesystem::remove_all(dir);
  }
  Response call(const std::string& method, const std::string& target, const std::string& body = {},
                std::map<std::string, std::string> headers = {}) {
    Request r;
    r.method = method;
    r.target = target;
    r.body = body;
    r.headers = std::move(headers);
    return service->handle(r);
  }
};

std::string cornell() {
  std::ifstream in(HEMIBAKE_SOURCE_DIR "/data/cornell-box.gltf");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The API description names every job parameter with its limits, and the server refuses each whole
// number just past the maximum it gives, naming the parameter.
TEST(Handler, ApiDescriptionGivesTheLimitsTheServerEnforces) {
  Fixture f;
  const json doc = json::parse(f.call("GET", "/openapi.json").body);
  std::vector<json> params;
  for (const auto& p : doc["paths"]["/v1/jobs"]["post"]["parameters"])
    if (p["in"] == "query") params.push_back(p);
  ASSERT_GE(params.size(), 20u);
  const std::string scene = cornell();
  const std::map<std::string, std::string> gltf = {{"content-type", "model/gltf+json"}};
  for (const auto& p : params) {
    const std::string name = p["name"];
    const json& schema = p["schema"];
    if (schema["type"] != "integer") continue;
    // max_shots=0 and the like are valid requests that bake nothing useful: only ask the parser.
    const uint64_t max = schema["maximum"];
    const Response past = f.call("POST", "/v1/jobs?" + name + "=" + std::to_string(max + 1), scene, gltf);
    EXPECT_EQ(past.status, 400) << name;
    EXPECT_NE(past.body.find(name), std::string::npos) << past.body;
  }
  const Response method = f.call("POST", "/v1/jobs?method=ray", scene, gltf);
  EXPECT_EQ(method.status, 400);
  EXPECT_NE(method.body.find("aa, classical, hr or reference"), std::string::npos) << method.body;
}

TEST(Handler, AnswersWithoutANetwork) {
  Fixture f;
  EXPECT_EQ(f.call("GET", "/healthz").status, 200);
  EXPECT_EQ(f.call("GET", "/readyz").status, 200);
  EXPECT_EQ(f.call("GET", "/nowhere").status, 404);
  const Response put = f.call("PUT", "/v1/jobs");
  EXPECT_EQ(put.status, 405);
  ASSERT_EQ(put.headers.size(), 1u);
  EXPECT_EQ(put.headers[0], std::make_pair(std::string("Allow"), std::string("GET, HEAD, POST")));
  EXPECT_EQ(f.call("FROB", "/healthz").status, 405);
  EXPECT_EQ(f.call("POST", "/metrics").status, 405);
  EXPECT_EQ(f.call("GET", "/v1/jobs?state=bogus").status, 400);
  EXPECT_EQ(f.call("GET", "/v1/jobs?limit=0").status, 400);
  const Response posted = f.call("POST", "/v1/jobs?pools=false&convergence=0.2", cornell(), {{"content-type", "model/gltf+json"}});
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = json::parse(posted.body)["id"];
  json job;
  // 120 s: instrumented, beside another test on a slow day, this small bake once took over 15 s.
  for (int i = 0; i < 2400; ++i) {
    job = json::parse(f.call("GET", "/v1/jobs/" + id).body);
    if (job["state"] == "succeeded") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_EQ(job["state"], "succeeded");
  const Response result = f.call("GET", "/v1/jobs/" + id + "/result");
  EXPECT_EQ(result.status, 200);
  EXPECT_EQ(result.content_type, "model/gltf-binary");
  // Query strings are decoded: a percent-encoded parameter name is still checked (7 is odd: refused).
  EXPECT_EQ(f.call("POST", "/v1/jobs?resolut%69on=7", cornell(), {{"content-type", "model/gltf+json"}}).status, 400);
  // A parameter given twice is refused, not decided by its last value.
  const Response twice = f.call("POST", "/v1/jobs?resolution=abc&resolut%69on=200", cornell(), {{"content-type", "model/gltf+json"}});
  EXPECT_EQ(twice.status, 400);
  EXPECT_EQ(json::parse(twice.body)["error"], "parameter resolution is given twice");
  // A paging cursor naming no job is an error, not an empty last page.
  EXPECT_EQ(f.call("GET", "/v1/jobs?after=" + id).status, 200);
  EXPECT_EQ(f.call("GET", "/v1/jobs?after=nosuchjob").status, 400);
  EXPECT_EQ(f.call("POST", "/v1/jobs/" + id + "/events").status, 405);
  EXPECT_EQ(f.call("DELETE", "/v1/jobs/" + id + "/result").status, 405);
}

// A scene in which nothing emits would bake black: it is refused before it is queued, saying why.
TEST(Handler, SceneWithoutLightIsRefused) {
  Fixture f;
  json gltf = json::parse(cornell());
  for (auto& m : gltf["materials"]) {
    m.erase("emissiveFactor");
    m.erase("extensions");
  }
  const Response r = f.call("POST", "/v1/jobs", gltf.dump(), {{"content-type", "model/gltf+json"}});
  EXPECT_EQ(r.status, 422) << r.body;
  EXPECT_NE(json::parse(r.body)["error"].get<std::string>().find("emits no light"), std::string::npos) << r.body;
  EXPECT_TRUE(json::parse(f.call("GET", "/v1/jobs").body)["jobs"].empty());
}

std::string lit_yard() {
  std::ifstream in(HEMIBAKE_SOURCE_DIR "/data/lit-yard.gltf");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The job's final state, polled.
json finished(Fixture& f, const std::string& id) {
  json job;
  for (int i = 0; i < 2400; ++i) {  // 120 s: instrumented on a loaded machine the sky job took 31 s
    job = json::parse(f.call("GET", "/v1/jobs/" + id).body);
    if (job["state"] != "queued" && job["state"] != "running") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return job;
}

// A file with KHR_lights_punctual lights (and nothing else emitting but a small lamp) is baked; a
// bad light is refused before it is queued, with a message that names it.
TEST(Handler, FileWithLightsBakesAndABadLightIsNamed) {
  Fixture f;
  const std::map<std::string, std::string> type = {{"content-type", "model/gltf+json"}};
  const Response posted = f.call("POST", "/v1/jobs?pools=false&convergence=0.01", lit_yard(), type);
  ASSERT_EQ(posted.status, 202) << posted.body;
  EXPECT_EQ(finished(f, json::parse(posted.body)["id"])["state"], "succeeded");
  json bad = json::parse(lit_yard());
  bad["nodes"][1]["extensions"]["KHR_lights_punctual"]["light"] = 7;
  const Response r = f.call("POST", "/v1/jobs", bad.dump(), type);
  EXPECT_EQ(r.status, 422) << r.body;
  EXPECT_NE(json::parse(r.body)["error"].get<std::string>().find("light 7"), std::string::npos) << r.body;
  bad = json::parse(lit_yard());
  bad["extensions"]["KHR_lights_punctual"]["lights"][2]["spot"]["innerConeAngle"] = 0.5;
  const Response cone = f.call("POST", "/v1/jobs", bad.dump(), type);
  EXPECT_EQ(cone.status, 422) << cone.body;
  EXPECT_NE(json::parse(cone.body)["error"].get<std::string>().find("light 2 ('Spot')"), std::string::npos) << cone.body;
}

// The sky is a job parameter: an open yard with no light of its own is refused without it and
// baked with it; a bad sky value is a bad parameter.
TEST(Handler, JobWithASkyBakesAnUnlitScene) {
  Fixture f;
  json dark = json::parse(lit_yard());
  dark.erase("extensions");
  dark.erase("extensionsRequired");
  dark["extensionsUsed"] = json::array();
  for (auto& n : dark["nodes"]) n.erase("extensions");
  for (auto& m : dark["materials"]) {
    m.erase("emissiveFactor");
    m.erase("extensions");
  }
  const std::map<std::string, std::string> type = {{"content-type", "model/gltf+json"}};
  const Response refused = f.call("POST", "/v1/jobs", dark.dump(), type);
  EXPECT_EQ(refused.status, 422) << refused.body;
  const std::string why = json::parse(refused.body)["error"];
  for (const char* word : {"emissive", "KHR_lights_punctual", "sky"}) EXPECT_NE(why.find(word), std::string::npos) << why;
  const Response posted = f.call("POST", "/v1/jobs?pools=false&sky=0.2,0.3,0.5&convergence=0.01", dark.dump(), type);
  ASSERT_EQ(posted.status, 202) << posted.body;
  const json job = finished(f, json::parse(posted.body)["id"]);
  EXPECT_EQ(job["state"], "succeeded");
  EXPECT_EQ(job["params"]["sky"], "0.2,0.3,0.5");
  for (const char* bad : {"-1", "1,2", "a,b,c", "1,2,3,4"}) {
    const Response r = f.call("POST", std::string("/v1/jobs?sky=") + bad, dark.dump(), type);
    EXPECT_EQ(r.status, 400) << bad << ": " << r.body;
    EXPECT_NE(r.body.find("sky"), std::string::npos) << r.body;
  }
  // Lights and the sky are not baked by the baselines: refused, not silently left out.
  const Response hr = f.call("POST", "/v1/jobs?sky=1&method=hr", dark.dump(), type);
  EXPECT_EQ(hr.status, 422) << hr.body;
}

TEST(Handler, TokensProtectEverythingButHealthChecks) {
  ServiceOptions o;
  o.tokens = {"t0ken"};
  Fixture f(o);
  EXPECT_EQ(f.call("GET", "/healthz").status, 200);
  const Response denied = f.call("GET", "/v1/jobs");
  EXPECT_EQ(denied.status, 401);
  EXPECT_EQ(f.call("GET", "/v1/jobs", "", {{"authorization", "Bearer t0ke"}}).status, 401);
  EXPECT_EQ(f.call("GET", "/v1/jobs", "", {{"authorization", "Bearer t0ken"}}).status, 200);
  EXPECT_EQ(f.call("GET", "/metrics", "", {{"authorization", "Bearer t0ken"}}).status, 200);
}

// A form part for a multipart/form-data body with boundary "b".
std::string form_part(const std::string& name, const std::string& data) {
  return "--b\r\nContent-Disposition: form-data; name=\"" + name + "\"; filename=\"f\"\r\n\r\n" + data + "\r\n";
}

// Two scenes (or two parameter sets) in one form: refused, not one of them silently dropped.
TEST(Handler, FormWithARepeatedPartIsRefused) {
  Fixture f;
  const std::map<std::string, std::string> form = {{"content-type", "multipart/form-data; boundary=b"}};
  const Response one = f.call("POST", "/v1/jobs", form_part("scene", cornell()) + "--b--\r\n", form);
  EXPECT_EQ(one.status, 202) << one.body;
  const Response two = f.call("POST", "/v1/jobs", form_part("scene", cornell()) + form_part("scene", "{}") + "--b--\r\n", form);
  EXPECT_EQ(two.status, 400) << two.body;
  EXPECT_EQ(json::parse(two.body)["error"], "the form has more than one 'scene' part");
  const Response params = f.call("POST", "/v1/jobs",
                                 form_part("scene", cornell()) + form_part("params", R"({"resolution":200})") +
                                     form_part("params", R"({"resolution":50})") + "--b--\r\n",
                                 form);
  EXPECT_EQ(params.status, 400) << params.body;
  const Response empty = f.call("POST", "/v1/jobs", "----\r\n", {{"content-type", "multipart/form-data; boundary="}});
  EXPECT_EQ(empty.status, 400) << empty.body;
}

// A second server on the same data directory would re-queue the first one's running jobs at its
// start and bake them twice: it is refused, and the directory is free again once the first stops.
TEST(Handler, SecondServiceOnTheSameDataDirectoryIsRefused) {
  Fixture f;
  ServiceOptions o;
  o.data_dir = f.dir;
  o.workers = 1;
  std::string error;
  EXPECT_FALSE(Service::start(o, error));
  EXPECT_NE(error.find("in use by another hemibake-server"), std::string::npos) << error;
  f.service.reset();
  error.clear();
  EXPECT_TRUE(Service::start(o, error)) << error;
}

// Threads of this process.
size_t thread_count() {
  size_t n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator("/proc/self/task")) ++n;
  return n;
}

// Responses given through handle_async, gathered for a test to wait on.
struct Answers {
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<Response> got;
  Reply reply() {
    return [this](Response r) {
      std::lock_guard lock(mutex);
      got.push_back(std::move(r));
      changed.notify_all();
    };
  }
  bool wait_for(size_t n, std::chrono::seconds limit) {
    std::unique_lock lock(mutex);
    return changed.wait_for(lock, limit, [&] { return got.size() >= n; });
  }
};

Request get(const std::string& target) {
  Request r;
  r.method = "GET";
  r.target = target;
  return r;
}

// A job whose shots take a few tenths of a second each (1024² hemicubes, none replayed), running.
std::string start_slow_job(Fixture& f) {
  const Response posted = f.call("POST", "/v1/jobs?resolution=1024&reuse=false&convergence=0.00001", cornell(),
                                 {{"content-type", "model/gltf+json"}});
  EXPECT_EQ(posted.status, 202) << posted.body;
  const std::string id = json::parse(posted.body)["id"];
  for (int i = 0; i < 200 && json::parse(f.call("GET", "/v1/jobs/" + id).body)["state"] != "running"; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(json::parse(f.call("GET", "/v1/jobs/" + id).body)["state"], "running");
  return id;
}

// Previews asked for wait as entries, not threads: 32 of them add no thread, and the worker's next
// shot answers them all with a GLB.
TEST(Handler, WaitingPreviewsHoldNoThreadAndOneShotAnswersThemAll) {
  Fixture f;
  const std::string id = start_slow_job(f);
  const size_t before = thread_count();
  Answers answers;
  for (int i = 0; i < 32; ++i) f.service->handle_async(get("/v1/jobs/" + id + "/preview"), answers.reply());
  EXPECT_EQ(thread_count(), before);
  ASSERT_TRUE(answers.wait_for(32, std::chrono::seconds(60)));
  for (const Response& r : answers.got) {
    EXPECT_EQ(r.status, 200) << r.body;
    EXPECT_EQ(r.body.substr(0, 4), "glTF");
  }
  f.call("DELETE", "/v1/jobs/" + id);
}

// Stopping the service answers every preview still waiting (503, to be asked again), and a
// request after the stop is answered at once.
TEST(Handler, StopAnswersWaitingPreviews) {
  Fixture f;
  const std::string id = start_slow_job(f);
  Answers answers;
  for (int i = 0; i < 8; ++i) f.service->handle_async(get("/v1/jobs/" + id + "/preview"), answers.reply());
  f.service->stop();
  ASSERT_TRUE(answers.wait_for(8, std::chrono::seconds(10)));
  for (const Response& r : answers.got) EXPECT_TRUE(r.status == 503 || r.status == 200) << r.status << " " << r.body;
  const Response after = f.call("GET", "/v1/jobs/" + id + "/preview");
  EXPECT_EQ(after.status, 503) << after.body;
}

// Scenes wait for a check thread in a bounded queue: past it, 503 with Retry-After at once.
TEST(Handler, FullCheckQueueAnswers503WithRetryAfter) {
  ServiceOptions o;
  o.check_threads = 1;
  o.max_checks = 1;
  Fixture f(o);
  const std::string scene = test::dark_glb_with_padding(cornell(), 32u << 20);
  Answers answers;
  // The requests are made first, so that all four arrive within microseconds: copying a 32 MB body
  // between two of them leaves the check thread time to finish the first, and the test failed once
  // on a loaded machine.
  std::vector<Request> requests(4);
  for (Request& r : requests) {
    r.method = "POST";
    r.target = "/v1/jobs";
    r.headers = {{"content-type", "model/gltf-binary"}};
    r.body = scene;
  }
  for (Request& r : requests) f.service->handle_async(std::move(r), answers.reply());
  ASSERT_TRUE(answers.wait_for(4, std::chrono::seconds(120)));
  int checked = 0, refused = 0;
  for (const Response& r : answers.got) {
    if (r.status == 422) ++checked;
    if (r.status == 503) {
      ++refused;
      EXPECT_NE(json::parse(r.body)["error"].get<std::string>().find("waiting to be checked"), std::string::npos) << r.body;
      ASSERT_EQ(r.headers.size(), 1u);
      EXPECT_EQ(r.headers[0].first, "Retry-After");
    }
  }
  // One being checked, one waiting; the other two refused.
  EXPECT_GE(checked, 1);
  EXPECT_GE(refused, 1);
  EXPECT_EQ(checked + refused, 4);
}

// Bytes that are not UTF-8 in a path, a query or a Content-Type are named in a JSON error with the
// status the request deserves (each was a 500: the JSON writer threw on them).
TEST(Handler, InvalidUtf8InARequestGetsItsProperStatus) {
  Fixture f;
  const Response path = f.call("GET", "/v1/jobs/\xff\xfe");
  EXPECT_EQ(path.status, 404);
  EXPECT_TRUE(json::parse(path.body, nullptr, false).is_object()) << path.body;
  const Response query = f.call("POST", "/v1/jobs?\xff=1", cornell(), {{"content-type", "model/gltf+json"}});
  EXPECT_EQ(query.status, 400);
  EXPECT_TRUE(json::parse(query.body, nullptr, false).is_object()) << query.body;
  const Response type = f.call("POST", "/v1/jobs", cornell(), {{"content-type", "text/\xc3\x28"}});
  EXPECT_EQ(type.status, 415);
  EXPECT_TRUE(json::parse(type.body, nullptr, false).is_object()) << type.body;
}

// Never fails a write: for tests that only count reads.
std::string no_fault(const std::string&, const std::string&) { return {}; }

// Streams of a job with nothing new wait for its next event without reading the store (they read
// it five times a second each), and that event reaches all of them at once.
TEST(Handler, WaitingEventStreamsReadTheStoreOnlyWhenAnEventComes) {
  Fixture f({}, no_fault);
  const std::string slow = start_slow_job(f);
  const Response posted = f.call("POST", "/v1/jobs?pools=false&convergence=0.3", cornell(), {{"content-type", "model/gltf+json"}});
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = json::parse(posted.body)["id"];
  ASSERT_EQ(json::parse(posted.body)["state"], "queued");
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<EventBatch> batches;
  for (int i = 0; i < 16; ++i)
    f.service->events_async(id, 0, std::chrono::milliseconds(30'000), [&](EventBatch b) {
      std::lock_guard lock(mutex);
      batches.push_back(std::move(b));
      changed.notify_all();
    });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // each has read once, and waits
  const uint64_t before = f.store->reads.load();
  std::this_thread::sleep_for(std::chrono::seconds(1));
  EXPECT_EQ(f.store->reads.load(), before) << "waiting streams read the store";
  {
    std::lock_guard lock(mutex);
    EXPECT_TRUE(batches.empty());
  }
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(f.call("DELETE", "/v1/jobs/" + id).status, 200);
  std::unique_lock lock(mutex);
  ASSERT_TRUE(changed.wait_for(lock, std::chrono::seconds(10), [&] { return batches.size() == 16; }));
  std::printf("16 waiting streams had the event %.1f ms after the DELETE was sent\n",
              std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  for (const EventBatch& b : batches) {
    EXPECT_EQ(b.status, 200);
    ASSERT_EQ(b.events.size(), 1u);
    EXPECT_EQ(json::parse(b.events[0].data)["state"], "cancelled");
  }
  lock.unlock();
  f.call("DELETE", "/v1/jobs/" + slow);
}

// A job's event stream read to its end (or for `limit`), as a stream client reads it.
std::vector<Event> read_stream(Service& service, const std::string& id, std::chrono::seconds limit, bool* ended) {
  std::vector<Event> all;
  *ended = false;
  const auto until = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < until) {
    std::promise<EventBatch> got;
    service.events_async(id, all.empty() ? 0 : all.back().seq, std::chrono::milliseconds(1000),
                         [&got](EventBatch b) { got.set_value(std::move(b)); });
    EventBatch b = got.get_future().get();
    all.insert(all.end(), b.events.begin(), b.events.end());
    if (b.end || b.status == 404) {
      *ended = b.end;
      break;
    }
  }
  return all;
}

// The state named by the last state event.
std::string last_state(const std::vector<Event>& events) {
  std::string state;
  for (const Event& e : events)
    if (e.type == "state") state = json::parse(e.data)["state"];
  return state;
}

// A stream ends with its job's final state event. A stream that read that event while the worker
// still had the job registered waited for a next event, which never comes: the stream ended only at
// the next heartbeat (15 s), and `hemibake bake --server` took 16 s for a job of 1 s. Here every
// wait is 10 minutes long, so a stream that waits for a heartbeat fails the test's 2 minutes.
TEST(Handler, EventStreamEndsWithItsJobsFinalEventNotAHeartbeatLater) {
  Fixture f({}, no_fault);
  const Response posted = f.call("POST", "/v1/jobs?pools=false&convergence=0.3", cornell(), {{"content-type", "model/gltf+json"}});
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = json::parse(posted.body)["id"];
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(2);
  std::vector<Event> all;
  bool ended = false;
  while (!ended) {
    auto got = std::make_shared<std::promise<EventBatch>>();
    auto next = got->get_future();
    f.service->events_async(id, all.empty() ? 0 : all.back().seq, std::chrono::minutes(10),
                            [got](EventBatch b) { got->set_value(std::move(b)); });
    ASSERT_EQ(next.wait_until(deadline), std::future_status::ready)
        << "the stream still waited 2 minutes in; events so far end in state " << last_state(all);
    EventBatch b = next.get();
    ASSERT_EQ(b.status, 200);
    all.insert(all.end(), b.events.begin(), b.events.end());
    ended = b.end;
  }
  EXPECT_EQ(last_state(all), "succeeded");
}

// A result the store cannot write (a full disk) fails the job with the reason: it does not stay
// running for ever. Its stream ends, and its worker takes the next job, which succeeds once the
// store can write again.
TEST(Handler, ResultThatCannotBeStoredFailsTheJob) {
  std::atomic<bool> full{true};
  Fixture f({}, [&](const std::string& write, const std::string&) {
    return full && write == "succeed" ? std::string("database or disk is full") : std::string();
  });
  const std::map<std::string, std::string> gltf = {{"content-type", "model/gltf+json"}};
  const Response posted = f.call("POST", "/v1/jobs?pools=false&convergence=0.2", cornell(), gltf);
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = json::parse(posted.body)["id"];
  bool ended = false;
  const auto events = read_stream(*f.service, id, std::chrono::seconds(60), &ended);
  EXPECT_TRUE(ended) << "the stream did not end";
  EXPECT_EQ(last_state(events), "failed");
  const json job = json::parse(f.call("GET", "/v1/jobs/" + id).body);
  EXPECT_EQ(job["state"], "failed");
  EXPECT_NE(job.value("error", "").find("database or disk is full"), std::string::npos) << job.dump();
  EXPECT_NE(job.value("error", "").find("result could not be stored"), std::string::npos) << job.dump();
  full = false;
  const Response next = f.call("POST", "/v1/jobs?pools=false&convergence=0.21", cornell(), gltf);
  ASSERT_EQ(next.status, 202) << next.body;
  EXPECT_EQ(finished(f, json::parse(next.body)["id"])["state"], "succeeded");
}

// The end of a job that the store cannot write at all (neither the result nor the failure): the
// worker does not wait for the store (the next job bakes), and the job ends, failed with the
// reason, once the store writes again. It used to stay "running" until the server restarted.
TEST(Handler, EndThatCannotBeWrittenIsWrittenWhenTheStoreIsBack) {
  std::atomic<bool> broken{true};
  std::mutex m;
  std::string first;  // the first job to reach its end
  Fixture f({}, [&](const std::string& write, const std::string& id) {
    if (write != "succeed" && write != "fail") return std::string();
    std::lock_guard lock(m);
    if (first.empty()) first = id;
    return broken && id == first ? std::string("disk I/O error") : std::string();
  });
  const std::map<std::string, std::string> gltf = {{"content-type", "model/gltf+json"}};
  const Response a = f.call("POST", "/v1/jobs?pools=false&convergence=0.2", cornell(), gltf);
  ASSERT_EQ(a.status, 202) << a.body;
  const std::string id = json::parse(a.body)["id"];
  // The next job takes the only worker and succeeds while the first one's end is still unwritten.
  const Response b = f.call("POST", "/v1/jobs?pools=false&convergence=0.21", cornell(), gltf);
  ASSERT_EQ(b.status, 202) << b.body;
  EXPECT_EQ(finished(f, json::parse(b.body)["id"])["state"], "succeeded");
  {
    std::lock_guard lock(m);
    ASSERT_EQ(first, id);
  }
  EXPECT_EQ(json::parse(f.call("GET", "/v1/jobs/" + id).body)["state"], "running");
  broken = false;
  bool ended = false;
  const auto events = read_stream(*f.service, id, std::chrono::seconds(30), &ended);
  EXPECT_TRUE(ended) << "the stream did not end";
  EXPECT_EQ(last_state(events), "failed");
  const json job = json::parse(f.call("GET", "/v1/jobs/" + id).body);
  EXPECT_EQ(job["state"], "failed");
  EXPECT_NE(job.value("error", "").find("result could not be stored: disk I/O error"), std::string::npos) << job.dump();
}

// An end the store refused for a while is written within seconds of the store writing again, also
// while the only worker is busy with a long bake: it is tried again in the background with backoff,
// not only when a worker is about to claim a job (the job stayed "running", its stream open, until
// the long bake ended).
TEST(Handler, EndThatCannotBeWrittenIsWrittenWhileTheWorkersAreBusy) {
  std::atomic<bool> broken{true};
  std::mutex m;
  std::string first;  // the first job to reach its end
  Fixture f({}, [&](const std::string& write, const std::string& id) {
    if (write != "succeed" && write != "fail") return std::string();
    std::lock_guard lock(m);
    if (first.empty()) first = id;
    return broken && id == first ? std::string("disk I/O error") : std::string();
  });
  const std::map<std::string, std::string> gltf = {{"content-type", "model/gltf+json"}};
  const Response a = f.call("POST", "/v1/jobs?pools=false&convergence=0.2", cornell(), gltf);
  ASSERT_EQ(a.status, 202) << a.body;
  const std::string id = json::parse(a.body)["id"];
  // Minutes of path tracing, stopped within 16 vertices by a DELETE.
  const Response b = f.call("POST", "/v1/jobs?pools=false&method=reference&samples=65536&convergence=0.2", cornell(), gltf);
  ASSERT_EQ(b.status, 202) << b.body;
  const std::string slow = json::parse(b.body)["id"];
  // The only worker left the first job's end unwritten and took the long one.
  std::string slow_state;
  for (int i = 0; i < 1200 && slow_state != "running"; ++i) {
    if (i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    slow_state = json::parse(f.call("GET", "/v1/jobs/" + slow).body)["state"];
  }
  ASSERT_EQ(slow_state, "running");
  {
    std::lock_guard lock(m);
    ASSERT_EQ(first, id);
  }
  EXPECT_EQ(json::parse(f.call("GET", "/v1/jobs/" + id).body)["state"], "running");
  std::this_thread::sleep_for(std::chrono::seconds(2));  // refused for a while: tried again meanwhile
  broken = false;
  const auto t0 = std::chrono::steady_clock::now();
  bool ended = false;
  const auto events = read_stream(*f.service, id, std::chrono::seconds(20), &ended);
  const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_TRUE(ended) << "the stream did not end within 20 s of the store's return";
  EXPECT_EQ(last_state(events), "failed");
  EXPECT_LT(waited, 10.0);
  const json job = json::parse(f.call("GET", "/v1/jobs/" + id).body);
  EXPECT_EQ(job["state"], "failed");
  EXPECT_NE(job.value("error", "").find("result could not be stored: disk I/O error"), std::string::npos) << job.dump();
  EXPECT_EQ(json::parse(f.call("GET", "/v1/jobs/" + slow).body)["state"], "running") << "the long bake ended first";
  EXPECT_EQ(f.call("DELETE", "/v1/jobs/" + slow).status, 200);
}

// Another program holding the store's write lock (an operator's sqlite3 shell, a backup) past the
// store's busy timeout: a submission gets 503 with Retry-After, and a bake that ends meanwhile is
// written once the lock is gone, succeeded, not failed and not lost.
TEST(Handler, StoreThatAnswersBusyFailsAndLosesNoJob) {
  struct WriteLock {  // a second connection's open write transaction
    sqlite3* db = nullptr;
    bool held = false;
    explicit WriteLock(const std::string& dir) {
      sqlite3_open((dir + "/hemibake.db").c_str(), &db);
      // The service's own short writes (its start, a worker's progress) may hold the lock for a
      // moment: wait for them as any well-behaved second program would.
      sqlite3_busy_timeout(db, 5000);
      held = sqlite3_exec(db, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) == SQLITE_OK;
    }
    ~WriteLock() {
      sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr);
      sqlite3_close(db);
    }
  };
  std::string dir;
  std::atomic<int> locks{0};
  std::thread holder;
  Fixture f({}, [&](const std::string& write, const std::string&) {
    // At the first result's write: the lock for 3 s, far past the store's 100 ms.
    if (write == "succeed" && locks.fetch_add(1) == 0) {
      std::promise<bool> taken;
      auto held = taken.get_future();
      holder = std::thread([&dir, &taken] {
        WriteLock lock(dir);
        taken.set_value(lock.held);
        std::this_thread::sleep_for(std::chrono::seconds(3));
      });
      EXPECT_TRUE(held.get());
    }
    return std::string();
  }, 100);
  dir = f.dir;
  const std::map<std::string, std::string> gltf = {{"content-type", "model/gltf+json"}};
  {
    WriteLock lock(dir);
    ASSERT_TRUE(lock.held);
    const Response refused = f.call("POST", "/v1/jobs?pools=false&convergence=0.2", cornell(), gltf);
    EXPECT_EQ(refused.status, 503) << refused.body;
    EXPECT_TRUE(std::any_of(refused.headers.begin(), refused.headers.end(), [](const auto& h) { return h.first == "Retry-After"; }));
  }
  const Response posted = f.call("POST", "/v1/jobs?pools=false&convergence=0.2", cornell(), gltf);
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = json::parse(posted.body)["id"];
  bool ended = false;
  const auto events = read_stream(*f.service, id, std::chrono::seconds(60), &ended);
  holder.join();
  EXPECT_GE(locks.load(), 2) << "the result's write met the lock and was tried again";
  EXPECT_TRUE(ended) << "the stream did not end";
  EXPECT_EQ(last_state(events), "succeeded");
  const json job = json::parse(f.call("GET", "/v1/jobs/" + id).body);
  EXPECT_EQ(job["state"], "succeeded") << job.dump();
  EXPECT_EQ(job["attempts"], 1);
  const Response result = f.call("GET", "/v1/jobs/" + id + "/result");
  EXPECT_EQ(result.status, 200);
  EXPECT_EQ(result.body.substr(0, 4), "glTF");
}

// A DELETE that lands while the result is written: one of the two wins, and the job's state, its
// stream and its result all say the same (the state said cancelled while the stream said succeeded).
TEST(Handler, CancelDuringTheResultWriteEndsTheJobOneWay) {
  Fixture* fixture = nullptr;
  std::atomic<int> deleted{0};
  Fixture f({}, [&](const std::string& write, const std::string& id) {
    if (write == "succeed" && deleted == 0) deleted = fixture->call("DELETE", "/v1/jobs/" + id).status;
    return std::string();
  });
  fixture = &f;
  const Response posted = f.call("POST", "/v1/jobs?pools=false&convergence=0.2", cornell(), {{"content-type", "model/gltf+json"}});
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = json::parse(posted.body)["id"];
  bool ended = false;
  const auto events = read_stream(*f.service, id, std::chrono::seconds(60), &ended);
  EXPECT_TRUE(ended);
  const json job = json::parse(f.call("GET", "/v1/jobs/" + id).body);
  const int result = f.call("GET", "/v1/jobs/" + id + "/result").status;
  EXPECT_EQ(last_state(events), job["state"]) << "the stream and the job disagree";
  if (job["state"] == "cancelled") {
    EXPECT_EQ(deleted.load(), 200);
    EXPECT_EQ(result, 409);
  } else {
    EXPECT_EQ(job["state"], "succeeded");
    EXPECT_EQ(deleted.load(), 409);
    EXPECT_EQ(result, 200);
  }
}

// A data directory of the older layout (the scene and the result in the job's row) is converted at
// start: the jobs, their scenes, results and events are all still there.
TEST(Handler, StoreOfTheOlderLayoutIsConverted) {
  const std::string dir = (std::filesystem::temp_directory_path() / ("hemibake-layout1-" + std::to_string(getpid()))).string();
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((dir + "/hemibake.db").c_str(), &db), SQLITE_OK);
    const char* layout1 =
        "PRAGMA journal_mode=WAL;"
        "CREATE TABLE jobs (id TEXT PRIMARY KEY, state TEXT NOT NULL, params TEXT NOT NULL, cache_key TEXT NOT NULL,"
        "  idempotency_key TEXT UNIQUE, scene BLOB NOT NULL, content_type TEXT NOT NULL,"
        "  result BLOB, etag TEXT, error TEXT, progress TEXT, attempts INTEGER NOT NULL DEFAULT 0,"
        "  created REAL NOT NULL, started REAL NOT NULL DEFAULT 0, finished REAL NOT NULL DEFAULT 0,"
        "  event_seq INTEGER NOT NULL DEFAULT 0);"
        "CREATE INDEX jobs_state ON jobs(state, created);"
        "CREATE INDEX jobs_cache ON jobs(cache_key, state);"
        "CREATE TABLE events (job TEXT NOT NULL, seq INTEGER NOT NULL, type TEXT NOT NULL,"
        "  data TEXT NOT NULL, PRIMARY KEY (job, seq));"
        "INSERT INTO jobs (id, state, params, cache_key, idempotency_key, scene, content_type, result, etag, created,"
        "  finished, event_seq) VALUES ('done', 'succeeded', '{}', 'k1', 'key', x'0102030405', 'model/gltf-binary',"
        "  x'0a0b0c', '\"e\"', 1, 2, 1);"
        "INSERT INTO jobs (id, state, params, cache_key, scene, content_type, created)"
        "  VALUES ('waiting', 'queued', '{\"resolution\":64}', 'k2', x'0607', 'model/gltf+json', 3);"
        "INSERT INTO events VALUES ('done', 1, 'state', '{\"state\":\"succeeded\"}');";
    ASSERT_EQ(sqlite3_exec(db, layout1, nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
    sqlite3_close(db);
  }
  std::string error;
  auto store = Store::open(dir, error);
  ASSERT_TRUE(store) << error;
  const auto done = store->get("done");
  ASSERT_TRUE(done);
  EXPECT_EQ(done->state, JobState::kSucceeded);
  EXPECT_EQ(done->scene_bytes, 5u);
  EXPECT_EQ(done->result_bytes, 3u);
  EXPECT_EQ(done->etag, "\"e\"");
  EXPECT_EQ(done->last_event, 1u);
  EXPECT_EQ(store->result("done"), std::string("\x0a\x0b\x0c"));
  EXPECT_EQ(store->events_after("done", 0, 10).size(), 1u);
  EXPECT_EQ(store->find_idempotent("key")->first, "done");
  EXPECT_EQ(store->find_cached("k1"), std::string("done"));
  std::string id, scene, params;
  ASSERT_TRUE(store->claim(id, scene, params));
  EXPECT_EQ(id, "waiting");
  EXPECT_EQ(scene, std::string("\x06\x07"));
  EXPECT_EQ(params, "{\"resolution\":64}");
  store.reset();
  ASSERT_TRUE(Store::open(dir, error)) << error;  // converted once; the new layout opens as it is
  std::filesystem::remove_all(dir);
}

// An Idempotency-Key names one submission: the same key with another scene or other parameters is
// refused with 422 (as the IETF Idempotency-Key draft asks), not answered with the first job.
TEST(Handler, IdempotencyKeyReusedForAnotherSubmissionIsRefused) {
  Fixture f;
  const std::map<std::string, std::string> h = {{"content-type", "model/gltf+json"}, {"idempotency-key", "k-1"}};
  const Response first = f.call("POST", "/v1/jobs?pools=false&convergence=0.3", cornell(), h);
  ASSERT_EQ(first.status, 202) << first.body;
  const Response again = f.call("POST", "/v1/jobs?pools=false&convergence=0.3", cornell(), h);
  EXPECT_EQ(again.status, 200) << again.body;
  EXPECT_EQ(json::parse(again.body)["id"], json::parse(first.body)["id"]);
  const Response params = f.call("POST", "/v1/jobs?pools=false&convergence=0.25", cornell(), h);
  EXPECT_EQ(params.status, 422) << params.body;
  EXPECT_NE(json::parse(params.body)["error"].get<std::string>().find("Idempotency-Key"), std::string::npos) << params.body;
  json other = json::parse(cornell());
  other["materials"][0]["name"] = "another";
  const Response scene = f.call("POST", "/v1/jobs?pools=false&convergence=0.3", other.dump(), h);
  EXPECT_EQ(scene.status, 422) << scene.body;
}

// A PNG of w x h grey pixels as a data URI.
std::string png_uri(int w, int h) {
  std::vector<unsigned char> pixels(static_cast<size_t>(w) * h * 3, 128);
  std::string png;
  stbi_write_png_to_func([](void* out, void* data, int size) { static_cast<std::string*>(out)->append(static_cast<char*>(data), size); },
                         &png, w, h, 3, pixels.data(), w * 3);
  static const char* abc = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string b64;
  for (size_t i = 0; i < png.size(); i += 3) {
    uint32_t v = static_cast<unsigned char>(png[i]) << 16;
    if (i + 1 < png.size()) v |= static_cast<unsigned char>(png[i + 1]) << 8;
    if (i + 2 < png.size()) v |= static_cast<unsigned char>(png[i + 2]);
    b64 += abc[(v >> 18) & 63];
    b64 += abc[(v >> 12) & 63];
    b64 += i + 1 < png.size() ? abc[(v >> 6) & 63] : '=';
    b64 += i + 2 < png.size() ? abc[v & 63] : '=';
  }
  return "data:image/png;base64," + b64;
}

// Memory a job asks for is budgeted at submit, naming the limit: a 4096² hemicube (3.7 GB) is
// refused by default, a small job under a small budget is not; the decoded pixels of all images
// together are limited (the limit was per image).
TEST(Handler, JobsThatNeedMoreMemoryThanTheBudgetAreRefusedAtSubmit) {
  const std::map<std::string, std::string> gltf = {{"content-type", "model/gltf+json"}};
  {
    Fixture f;
    const Response huge = f.call("POST", "/v1/jobs?resolution=4096", cornell(), gltf);
    EXPECT_EQ(huge.status, 422) << huge.body;
    EXPECT_NE(huge.body.find("limit of 2048 MB per job (hemibake-server --max-job-mb)"), std::string::npos) << huge.body;
    EXPECT_NE(huge.body.find("hemicubes at resolution 4096"), std::string::npos) << huge.body;
  }
  ServiceOptions o;
  o.max_job_bytes = 64u << 20;
  o.max_image_pixels = 100;
  Fixture f(o);
  const Response big = f.call("POST", "/v1/jobs?resolution=1024&shot_cache_mb=0", cornell(), gltf);
  EXPECT_EQ(big.status, 422) << big.body;
  EXPECT_NE(big.body.find("limit of 64 MB"), std::string::npos) << big.body;
  const Response cache = f.call("POST", "/v1/jobs?shot_cache_mb=200", cornell(), gltf);
  EXPECT_EQ(cache.status, 422) << cache.body;
  EXPECT_EQ(f.call("POST", "/v1/jobs?pools=false&resolution=100&shot_cache_mb=0&aeps=0.002&convergence=0.3", cornell(), gltf).status, 202);
  json scene = json::parse(cornell());
  scene["images"] = json::array({{{"uri", png_uri(8, 8)}}});
  EXPECT_EQ(f.call("POST", "/v1/jobs?pools=false&shot_cache_mb=0&aeps=0.002&convergence=0.31", scene.dump(), gltf).status, 202);
  scene["images"].push_back({{"uri", png_uri(8, 8)}});
  const Response images = f.call("POST", "/v1/jobs?pools=false&shot_cache_mb=0&aeps=0.002&convergence=0.32", scene.dump(), gltf);
  EXPECT_EQ(images.status, 422) << images.body;
  EXPECT_NE(images.body.find("more than 100 pixels in all"), std::string::npos) << images.body;
}

// Found by gltf_fuzz: a baked GLB (7 KB) whose Draco primitive has an accessor of componentType
// 5127, which glTF does not define. tinygltf sized the decoded buffer by a component size of -1
// and allocated 4 GB for the submission. It is refused from the JSON, with the accessor named.
TEST(Handler, UndefinedComponentTypeIsRefusedBeforeDracoDecoding) {
  Fixture f;
  std::ifstream in(HEMIBAKE_SOURCE_DIR "/tests/fuzz/corpus/gltf/draco-bad-component-type.glb", std::ios::binary);
  const std::string glb((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(glb.size(), 6796u);
  rusage before{};
  getrusage(RUSAGE_SELF, &before);
  const Response r = f.call("POST", "/v1/jobs", glb, {{"content-type", "model/gltf-binary"}});
  rusage after{};
  getrusage(RUSAGE_SELF, &after);
  EXPECT_EQ(r.status, 422) << r.body;
  EXPECT_NE(r.body.find("accessor 4.componentType must be"), std::string::npos) << r.body;
  EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 512 * 1024) << "peak memory grew by " << (after.ru_maxrss - before.ru_maxrss) << " KB";
}

TEST(Handler, QueryStringsDecode) {
  const auto q = parse_query("a=1&b=x%20y&c=&d&e=%2F%2f+z");
  EXPECT_EQ(q.at("a"), "1");
  EXPECT_EQ(q.at("b"), "x y");
  EXPECT_EQ(q.at("c"), "");
  EXPECT_EQ(q.at("d"), "");
  EXPECT_EQ(q.at("e"), "// z");
}

}  // namespace
}  // namespace hemibake::server
