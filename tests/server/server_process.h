// Helpers of the tests that run the real server binary: a hemibake-server process on a free loopback
// port, a small Beast HTTP client, an event stream reader.
#pragma once

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/read_until.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <thread>
#include <tuple>
#include <vector>

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

namespace hemibake_test {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;
using nlohmann::json;
using namespace std::chrono_literals;

inline std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// A hemibake-server process on a free loopback port.
class ServerProcess {
 public:
  // `max_files` > 0 sets the server's limit of open file descriptors. `prefix` runs the server
  // through another program (which ends by executing it); `errors` receives its stderr.
  ServerProcess(const std::string& data_dir, std::vector<std::string> extra = {}, std::vector<std::string> env = {},
                rlim_t max_files = 0, std::vector<std::string> prefix = {}, const std::string& errors = {}) {
    int fds[2];
    if (pipe(fds) != 0) std::abort();
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], STDOUT_FILENO);
      close(fds[0]);
      if (!errors.empty()) {
        const int fd = ::open(errors.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(fd, STDERR_FILENO);
      }
      if (max_files > 0) {
        const rlimit limit{max_files, max_files};
        setrlimit(RLIMIT_NOFILE, &limit);
      }
      for (const auto& e : env) putenv(const_cast<char*>(e.c_str()));
      // HEMIBAKE_TEST_SERVER runs the tests against another build of the server (an older one, to see a
      // regression test fail).
      const char* binary = std::getenv("HEMIBAKE_TEST_SERVER") ? std::getenv("HEMIBAKE_TEST_SERVER") : HEMIBAKE_SERVER;
      std::vector<std::string> args = prefix;
      for (const std::string& a : {std::string(binary), std::string("--listen"), std::string("127.0.0.1:0"), std::string("--data"), data_dir})
        args.push_back(a);
      args.insert(args.end(), extra.begin(), extra.end());
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(fds[1]);
    // The first line names the port: "hemibake-server: serving http://127.0.0.1:PORT/ ...".
    FILE* out = fdopen(fds[0], "r");
    char line[512] = {0};
    if (fgets(line, sizeof line, out)) {
      const char* p = std::strstr(line, "127.0.0.1:");
      if (p) port_ = static_cast<unsigned short>(std::atoi(p + 10));
    }
    out_ = out;
  }
  ~ServerProcess() { stop(SIGTERM); }
  unsigned short port() const { return port_; }
  pid_t pid() const { return pid_; }
  void stop(int sig) {
    if (pid_ <= 0) return;
    kill(pid_, sig);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    if (out_) fclose(out_);
    out_ = nullptr;
  }

 private:
  pid_t pid_ = -1;
  unsigned short port_ = 0;
  FILE* out_ = nullptr;
};

struct Reply {
  int status = 0;
  std::map<std::string, std::string> headers;
  std::string body;
  json js() const { return json::parse(body, nullptr, false); }
};

inline Reply request(unsigned short port, http::verb method, const std::string& target, const std::string& body = {},
              std::map<std::string, std::string> headers = {}) {
  net::io_context io;
  beast::tcp_stream stream(io);
  stream.expires_after(30s);
  stream.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
  http::request<http::string_body> req(method, target, 11);
  req.set(http::field::host, "127.0.0.1");
  for (const auto& [k, v] : headers) req.set(k, v);
  req.body() = body;
  req.prepare_payload();
  http::write(stream, req);
  beast::flat_buffer buffer;
  http::response_parser<http::string_body> parser;
  parser.body_limit(1ull << 30);
  parser.skip(method == http::verb::head);  // the GET's Content-Length, and no body
  http::read(stream, buffer, parser);
  Reply r;
  r.status = static_cast<int>(parser.get().result_int());
  for (const auto& f : parser.get()) {
    std::string name(f.name_string());
    for (auto& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    r.headers[name] = std::string(f.value());
  }
  r.body = parser.get().body();
  return r;
}

// Reads an event stream until it ends; returns (id, event, data) triples.
inline std::vector<std::tuple<uint64_t, std::string, std::string>> events(unsigned short port, const std::string& id,
                                                                   uint64_t last = 0) {
  net::io_context io;
  beast::tcp_stream stream(io);
  stream.expires_after(120s);
  stream.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
  std::string req = "GET /v1/jobs/" + id + "/events HTTP/1.1\r\nHost: 127.0.0.1\r\n";
  if (last) req += "Last-Event-ID: " + std::to_string(last) + "\r\n";
  req += "\r\n";
  net::write(stream, net::buffer(req));
  std::string all;
  beast::error_code ec;
  char buf[4096];
  for (;;) {
    const size_t n = stream.read_some(net::buffer(buf), ec);
    all.append(buf, n);
    if (ec) break;
  }
  std::vector<std::tuple<uint64_t, std::string, std::string>> out;
  const size_t body = all.find("\r\n\r\n");
  std::istringstream lines(all.substr(body == std::string::npos ? all.size() : body + 4));
  uint64_t eid = 0;
  std::string type, data;
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("id: ", 0) == 0) eid = std::stoull(line.substr(4));
    else if (line.rfind("event: ", 0) == 0) type = line.substr(7);
    else if (line.rfind("data: ", 0) == 0) data = line.substr(6);
    else if (line.empty() && !type.empty()) {
      out.emplace_back(eid, type, data);
      type.clear();
    }
  }
  return out;
}

// Runs a command; returns its exit status (-1 if it did not exit normally, as on an abort) and
// what it wrote to stdout and stderr.
inline std::pair<int, std::string> run(const std::string& command) {
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  std::string out;
  char buf[512];
  while (size_t n = fread(buf, 1, sizeof buf, p)) out.append(buf, n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

// The directories temp_dir handed out, removed when the test program exits.
struct TempDirs {
  std::vector<std::filesystem::path> paths;
  ~TempDirs() {
    std::error_code ec;
    for (const auto& p : paths) std::filesystem::remove_all(p, ec);
  }
};

// A fresh path under the temporary directory (nothing there yet), ending in `suffix`, removed with
// whatever the test put there when the test program exits.
inline std::string temp_dir(const std::string& name, const std::string& suffix = "") {
  static TempDirs dirs;
  const auto d =
      std::filesystem::temp_directory_path() / ("hemibake-" + name + "-" + std::to_string(getpid()) + suffix);
  std::filesystem::remove_all(d);
  dirs.paths.push_back(d);
  return d.string();
}

inline const std::string& cornell() {
  static const std::string scene = read_file(HEMIBAKE_SOURCE_DIR "/data/cornell-box.gltf");
  return scene;
}

inline json wait_finished(unsigned short port, const std::string& id, std::chrono::seconds limit = 120s) {
  const auto until = std::chrono::steady_clock::now() + limit;
  json j;
  while (std::chrono::steady_clock::now() < until) {
    j = request(port, http::verb::get, "/v1/jobs/" + id).js();
    const std::string s = j.value("state", "");
    if (s == "succeeded" || s == "failed" || s == "cancelled") return j;
    std::this_thread::sleep_for(100ms);
  }
  return j;
}


}  // namespace hemibake_test
