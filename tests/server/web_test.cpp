// The web page's files as the service answers them (no sockets): the bytes npm installed, their
// types, validators and encodings, and no token needed for them while the API keeps needing one.
#include "hemibake/server/service.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <unistd.h>

namespace hemibake::server {
namespace {

struct WebFixture {
  std::string dir;
  std::unique_ptr<Service> service;
  explicit WebFixture(ServiceOptions o = {}) {
    dir = (std::filesystem::temp_directory_path() / ("hemibake-web-" + std::to_string(getpid()))).string();
    std::filesystem::remove_all(dir);
    o.data_dir = dir;
    o.workers = 1;
    std::string error;
    service = Service::start(o, error);
    EXPECT_TRUE(service) << error;
  }
  ~WebFixture() {
    service.reset();
    std::filesystem::remove_all(dir);
  }
  Response get(const std::string& target, std::map<std::string, std::string> headers = {}, const std::string& method = "GET") {
    Request r;
    r.method = method;
    r.target = target;
    r.headers = std::move(headers);
    return service->handle(r);
  }
};

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string header(const Response& r, const std::string& name) {
  for (const auto& [k, v] : r.headers)
    if (k == name) return v;
  return {};
}

std::string gunzip(const std::string& data) {
  z_stream z{};
  EXPECT_EQ(inflateInit2(&z, 16 + MAX_WBITS), Z_OK);
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = static_cast<uInt>(data.size());
  std::string out;
  char buffer[1 << 16];
  int status = Z_OK;
  while (status == Z_OK) {
    z.next_out = reinterpret_cast<Bytef*>(buffer);
    z.avail_out = sizeof(buffer);
    status = inflate(&z, Z_NO_FLUSH);
    out.append(buffer, sizeof(buffer) - z.avail_out);
  }
  EXPECT_EQ(status, Z_STREAM_END);
  inflateEnd(&z);
  return out;
}

TEST(WebPage, IsServedWithoutATokenWhileTheApiNeedsOne) {
  ServiceOptions o;
  o.tokens = {"t0ken"};
  WebFixture f(o);
  const Response page = f.get("/");
  EXPECT_EQ(page.status, 200);
  EXPECT_EQ(page.content_type, "text/html; charset=utf-8");
  EXPECT_EQ(page.body, read_file(HEMIBAKE_SOURCE_DIR "/web/src/index.html"));
  EXPECT_NE(header(page, "Content-Security-Policy").find("default-src 'self'"), std::string::npos);
  EXPECT_EQ(f.get("/index.html").body, page.body);
  EXPECT_EQ(f.get("/assets/app.js").status, 200);
  EXPECT_EQ(f.get("/v1/jobs").status, 401);
  EXPECT_EQ(f.get("/openapi.json").status, 401);
  EXPECT_EQ(f.get("/nowhere").status, 401);
}

// three.js is the file npm installed, byte for byte, with the type a browser needs for a module
// and for WebAssembly (a wrong type makes the browser refuse both).
TEST(WebPage, ServesThreeAsInstalledWithItsTypes) {
  WebFixture f;
  const std::string three = HEMIBAKE_SOURCE_DIR "/web/node_modules/three/";
  const struct {
    const char* path;
    const char* file;
    const char* type;
  } files[] = {
      {"/assets/three/build/three.module.js", "build/three.module.js", "text/javascript; charset=utf-8"},
      {"/assets/three/build/three.core.js", "build/three.core.js", "text/javascript; charset=utf-8"},
      {"/assets/three/examples/jsm/loaders/GLTFLoader.js", "examples/jsm/loaders/GLTFLoader.js", "text/javascript; charset=utf-8"},
      {"/assets/three/examples/jsm/loaders/DRACOLoader.js", "examples/jsm/loaders/DRACOLoader.js", "text/javascript; charset=utf-8"},
      {"/assets/three/examples/jsm/libs/draco/draco_decoder.wasm", "examples/jsm/libs/draco/draco_decoder.wasm", "application/wasm"},
      {"/assets/three/examples/jsm/libs/draco/draco_wasm_wrapper.js", "examples/jsm/libs/draco/draco_wasm_wrapper.js",
       "text/javascript; charset=utf-8"},
  };
  for (const auto& file : files) {
    const Response r = f.get(file.path);
    EXPECT_EQ(r.status, 200) << file.path;
    EXPECT_EQ(r.content_type, file.type) << file.path;
    EXPECT_EQ(r.body, read_file(three + file.file)) << file.path;
    EXPECT_EQ(header(r, "Content-Encoding"), "") << file.path;
  }
  EXPECT_EQ(f.get("/assets/app.css").content_type, "text/css; charset=utf-8");
  EXPECT_EQ(f.get("/assets/icon.svg").content_type, "image/svg+xml");
}

TEST(WebPage, RevalidatesWithETagsAndCompressesWhenAsked) {
  WebFixture f;
  const Response plain = f.get("/assets/three/build/three.core.js");
  const std::string etag = header(plain, "ETag");
  ASSERT_GE(etag.size(), 3u);
  EXPECT_EQ(etag.front(), '"');
  EXPECT_EQ(header(plain, "Cache-Control"), "no-cache");
  EXPECT_EQ(header(plain, "Vary"), "Accept-Encoding");

  const Response again = f.get("/assets/three/build/three.core.js", {{"if-none-match", etag}});
  EXPECT_EQ(again.status, 304);
  EXPECT_TRUE(again.body.empty());
  EXPECT_EQ(header(again, "ETag"), etag);
  EXPECT_EQ(f.get("/assets/three/build/three.core.js", {{"if-none-match", "\"other\""}}).status, 200);

  const Response gz = f.get("/assets/three/build/three.core.js", {{"accept-encoding", "br, GZIP;q=0.8"}});
  EXPECT_EQ(gz.status, 200);
  EXPECT_EQ(header(gz, "Content-Encoding"), "gzip");
  EXPECT_LT(gz.body.size(), plain.body.size() / 2);
  EXPECT_EQ(gunzip(gz.body), plain.body);
  EXPECT_NE(header(gz, "ETag"), etag);  // another representation, another validator
  EXPECT_EQ(f.get("/assets/three/build/three.core.js", {{"accept-encoding", "gzip;q=0"}}).body, plain.body);
  EXPECT_EQ(f.get("/assets/three/build/three.core.js", {{"accept-encoding", "gzip"}, {"if-none-match", header(gz, "ETag")}}).status, 304);
}

TEST(WebPage, UnknownFilesAndOtherMethodsAreRefused) {
  WebFixture f;
  const Response missing = f.get("/assets/nothing.js");
  EXPECT_EQ(missing.status, 404);
  EXPECT_EQ(missing.content_type, "application/json");
  EXPECT_NE(missing.body.find("\"error\""), std::string::npos);
  EXPECT_EQ(f.get("/assets/three/package.json").status, 404);  // only the files the page uses
  EXPECT_EQ(f.get("/assets/../server/src/main.cpp").status, 404);
  const Response odd = f.get("/assets/\xff\"\x01.js");
  EXPECT_EQ(odd.status, 404);
  EXPECT_EQ(odd.body, "{\"error\":\"no such file: /assets/\xef\xbf\xbd\\\"\\u0001.js\"}");
  const Response post = f.get("/", {}, "POST");
  EXPECT_EQ(post.status, 405);
  EXPECT_EQ(header(post, "Allow"), "GET, HEAD");
  EXPECT_EQ(f.get("/assets/app.js", {}, "DELETE").status, 405);
}

}  // namespace
}  // namespace hemibake::server
