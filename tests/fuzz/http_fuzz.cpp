// libFuzzer target: HTTP request handling without sockets. The input is what a client sends on a
// connection: Beast's parser reads requests from it (with the server's header and body limits),
// and each one it accepts is answered by Service::handle on a service with its store in a
// temporary folder. Every answer must be a real status with a JSON body for errors.
#include "hemibake/server/service.h"

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <unistd.h>

namespace {

namespace http = boost::beast::http;
std::unique_ptr<hemibake::server::Service> service;

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  hemibake::server::ServiceOptions o;
  o.data_dir = (std::filesystem::temp_directory_path() / ("hemibake-http-fuzz-" + std::to_string(getpid()))).string();
  std::filesystem::remove_all(o.data_dir);
  o.workers = 1;
  o.check_threads = 1;
  o.max_queue = 0;  // every scene is checked, none is baked: each input costs the same
  o.max_body_bytes = 1u << 20;
  o.max_triangles = 20'000;
  std::string error;
  service = hemibake::server::Service::start(o, error);
  if (!service) {
    std::fprintf(stderr, "cannot start the service: %s\n", error.c_str());
    std::abort();
  }
  std::atexit([] {
    const std::string dir = (std::filesystem::temp_directory_path() / ("hemibake-http-fuzz-" + std::to_string(getpid()))).string();
    service.reset();
    std::filesystem::remove_all(dir);
  });
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  boost::asio::const_buffer rest(data, size);
  for (int n = 0; n < 4 && rest.size() > 0; ++n) {
    http::request_parser<http::string_body> parser;
    parser.eager(true);
    parser.header_limit(8 * 1024);
    parser.body_limit(1u << 20);
    boost::beast::error_code ec;
    const size_t used = parser.put(rest, ec);
    if (ec || !parser.is_done()) {
      if (!ec) parser.put_eof(ec);
      if (ec || !parser.is_done()) return 0;
    }
    rest += used;
    const auto& msg = parser.get();
    hemibake::server::Request req;
    req.method = std::string(msg.method_string());
    req.target = std::string(msg.target());
    for (const auto& f : msg) {
      std::string name(f.name_string());
      for (auto& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      req.headers[name] = std::string(f.value());
    }
    req.body = msg.body();
    const hemibake::server::Response r = service->handle(req);
    if (r.status < 100 || r.status > 599) std::abort();
    if (r.status >= 400 && !nlohmann::json::accept(r.body)) {
      std::fprintf(stderr, "status %d without a JSON body: %s\n", r.status, r.body.c_str());
      std::abort();
    }
  }
  return 0;
}
