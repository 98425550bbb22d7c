// The request handler as a function of the request: no sockets, a store in a temporary folder.
#include "hemibake/server/service.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace hemibake::server {
namespace {

using nlohmann::json;

struct Fixture {
  std::string dir;
  std::unique_ptr<Service> service;
  explicit Fixture(ServiceOptions o = {}) {
    dir = (std::filesystem::temp_directory_path() / ("hemibake-handler-" + std::to_string(getpid()))).string();
    std::filesystem::remove_all(dir);
    o.data_dir = dir;
    o.workers = 1;
    std::string error;
    service = Service::start(o, error);
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
  const Response posted = f.call("POST", "/v1/jobs?convergence=0.2", cornell(), {{"content-type", "model/gltf+json"}});
  ASSERT_EQ(posted.status, 202) << posted.body;
  const std::string id = json::parse(posted.body)["id"];
  json job;
  for (int i = 0; i < 300; ++i) {
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
