#include "hemibake/client/remote.h"

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <nlohmann/json.hpp>


#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace hemibake::client {
namespace {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;
using nlohmann::json;

struct Reply {
  int status = 0;
  std::string body;
  std::map<std::string, std::string> headers;
  std::string error;  ///< a transport failure
};

Reply call(const Remote& r, http::verb verb, const std::string& target, const std::string& body = {},
           const std::string& content_type = {}) {
  Reply out;
  try {
    net::io_context io;
    tcp::resolver resolver(io);
    beast::tcp_stream stream(io);
    stream.expires_after(std::chrono::seconds(300));
    stream.connect(resolver.resolve(r.host, r.port));
    http::request<http::string_body> req(verb, target, 11);
    req.set(http::field::host, r.host);
    req.set(http::field::user_agent, "hemibake");
    if (!r.token.empty()) req.set(http::field::authorization, "Bearer " + r.token);
    if (!content_type.empty()) req.set(http::field::content_type, content_type);
    req.body() = body;
    req.prepare_payload();
    http::write(stream, req);
    beast::flat_buffer buffer;
    http::response_parser<http::string_body> parser;
    parser.body_limit(4ull << 30);
    http::read(stream, buffer, parser);
    out.status = static_cast<int>(parser.get().result_int());
    out.body = parser.get().body();
    for (const auto& f : parser.get()) out.headers[std::string(f.name_string())] = std::string(f.value());
  } catch (const boost::system::system_error& e) {
    out.error = "cannot reach the server at " + r.host + ":" + r.port + ": " + e.code().message();
  } catch (const std::exception& e) {
    out.error = std::string("cannot reach the server at ") + r.host + ":" + r.port + ": " + e.what();
  }
  return out;
}

// Prints the server's error for a failed call; returns the exit status 1.
int report(const Remote& r, const Reply& reply, const Console& c) {
  if (!reply.error.empty()) {
    std::fprintf(c.err, "hemibake: %s\n", reply.error.c_str());
    return 1;
  }
  const json j = json::parse(reply.body, nullptr, false);
  if (!j.is_object() || !j.contains("error") || !j["error"].is_string()) {
    // Not one of ours (a proxy, another web server): its page would only bury the point.
    std::fprintf(c.err, "hemibake: the server at %s:%s answered %d without a hemibake error; is it a hemibake-server?\n",
                 r.host.c_str(), r.port.c_str(), reply.status);
    return 1;
  }
  std::fprintf(c.err, "hemibake: the server answered %d: %s%s\n", reply.status, j["error"].get<std::string>().c_str(),
               reply.status == 401 ? " (set HEMIBAKE_TOKEN)" : "");
  return 1;
}

// A 200 answer's JSON object, or null after saying that the server is not a hemibake-server.
json answer_json(const Remote& r, const Reply& reply, const Console& c) {
  json j = json::parse(reply.body, nullptr, false);
  if (j.is_object()) return j;
  std::fprintf(c.err, "hemibake: the server at %s:%s did not answer with JSON; is it a hemibake-server?\n", r.host.c_str(),
               r.port.c_str());
  return nullptr;
}

// A job id as a path segment: whatever the user typed stays one segment of a valid request line.
std::string job_path(const std::string& id) {
  static const char* hex = "0123456789ABCDEF";
  std::string out = "/v1/jobs/";
  for (const unsigned char c : id) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~') {
      out += static_cast<char>(c);
    } else {
      out += '%';
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  return out;
}

std::string query_of(const protocol::JobSpec& spec) {
  const json j = json::parse(protocol::params_json(spec));
  std::string q;
  for (const auto& [k, v] : j.items()) {
    q += q.empty() ? "?" : "&";
    q += k + "=" + (v.is_string() ? v.get<std::string>() : v.is_boolean() ? (v.get<bool>() ? "true" : "false") : v.dump());
  }
  return q;
}

}  // namespace

std::string parse_server(const std::string& url, Remote& out) {
  std::string rest = url;
  if (rest.rfind("http://", 0) == 0) rest = rest.substr(7);
  else if (rest.rfind("https://", 0) == 0) return "https is not supported; put hemibake-server behind a TLS proxy and use its http address";
  while (!rest.empty() && rest.back() == '/') rest.pop_back();
  if (rest.empty() || rest.find('/') != std::string::npos) return "the server must be given as http://HOST:PORT (got '" + url + "')";
  const size_t colon = rest.rfind(':');
  out.host = colon == std::string::npos ? rest : rest.substr(0, colon);
  out.port = colon == std::string::npos ? "80" : rest.substr(colon + 1);
  if (out.host.empty() || out.port.empty() || !std::all_of(out.port.begin(), out.port.end(), ::isdigit))
    return "the server must be given as http://HOST:PORT (got '" + url + "')";
  return {};
}

int remote_submit(const Remote& r, const std::string& path, const protocol::JobSpec& spec, const Console& c,
                  std::string* id_out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::fprintf(c.err, "hemibake: cannot read %s\n", path.c_str());
    return 1;
  }
  std::ostringstream data;
  data << in.rdbuf();
  const std::string bytes = data.str();
  const bool glb = bytes.size() >= 4 && bytes.compare(0, 4, "glTF") == 0;
  const Reply reply = call(r, http::verb::post, "/v1/jobs" + query_of(spec), bytes, glb ? "model/gltf-binary" : "model/gltf+json");
  if (reply.status != 202 && reply.status != 200) return report(r, reply, c);
  const json j = answer_json(r, reply, c);
  if (j.is_null()) return 1;
  const std::string id = j.value("id", "");
  if (id_out) *id_out = id;
  else std::fprintf(c.out, "%s\n", id.c_str());
  if (reply.headers.count("X-Hemibake-Cache")) std::fprintf(c.err, "hemibake: answered from the server's cache\n");
  return 0;
}

int remote_status(const Remote& r, const std::string& id, const Console& c) {
  const Reply reply = call(r, http::verb::get, job_path(id));
  if (reply.status != 200) return report(r, reply, c);
  const json j = answer_json(r, reply, c);
  if (j.is_null()) return 1;
  std::fprintf(c.out, "%s\n", j.dump(2).c_str());
  return 0;
}

int remote_watch(const Remote& r, const std::string& id, const Console& c) {
  ProgressPrinter printer(c);
  std::string state;
  try {
    net::io_context io;
    tcp::resolver resolver(io);
    beast::tcp_stream stream(io);
    stream.connect(resolver.resolve(r.host, r.port));
    std::string req = "GET " + job_path(id) + "/events HTTP/1.1\r\nHost: " + r.host + "\r\nAccept: text/event-stream\r\n";
    if (!r.token.empty()) req += "Authorization: Bearer " + r.token + "\r\n";
    req += "\r\n";
    net::write(stream, net::buffer(req));
    std::string pending;
    bool header_done = false;
    char buf[4096];
    for (;;) {
      stream.expires_after(std::chrono::seconds(60));  // the server sends a heartbeat every 15 s
      beast::error_code ec;
      const size_t n = stream.read_some(net::buffer(buf), ec);
      pending.append(buf, n);
      if (!header_done) {
        const size_t end = pending.find("\r\n\r\n");
        if (end != std::string::npos) {
          if (pending.compare(0, 12, "HTTP/1.1 200") != 0) {
            const size_t body = end + 4;
            Reply reply;
            reply.status = std::atoi(pending.c_str() + 9);
            reply.body = pending.substr(body);
            return report(r, reply, c);
          }
          pending = pending.substr(end + 4);
          header_done = true;
        }
      }
      size_t blank;
      while (header_done && (blank = pending.find("\n\n")) != std::string::npos) {
        std::istringstream lines(pending.substr(0, blank));
        pending = pending.substr(blank + 2);
        std::string type, data;
        for (std::string line; std::getline(lines, line);) {
          if (line.rfind("event: ", 0) == 0) type = line.substr(7);
          else if (line.rfind("data: ", 0) == 0) data = line.substr(6);
        }
        const json j = json::parse(data, nullptr, false);
        if (type == "progress") {
          if (const auto p = protocol::parse_progress_json(data)) printer.update(*p);
        }
        if (type == "state" && j.is_object()) {
          state = j.value("state", "");
          if (state == "failed") {
            printer.finish();
            std::fprintf(c.err, "hemibake: the bake failed: %s\n", j.value("error", "").c_str());
          }
        }
      }
      if (ec) break;
    }
  } catch (const boost::system::system_error& e) {
    std::fprintf(c.err, "hemibake: cannot reach the server at %s:%s: %s\n", r.host.c_str(), r.port.c_str(),
                 e.code().message().c_str());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(c.err, "hemibake: cannot follow job %s: %s\n", id.c_str(), e.what());
    return 1;
  }
  printer.finish();
  // The stream ends after the final state; read it back to be sure of it.
  const Reply reply = call(r, http::verb::get, job_path(id));
  if (reply.status != 200) return report(r, reply, c);
  const json j = answer_json(r, reply, c);
  if (j.is_null()) return 1;
  state = j.value("state", "");
  std::fprintf(c.err, "hemibake: job %s %s\n", id.c_str(), state.c_str());
  return state == "succeeded" ? 0 : 1;
}

int remote_fetch(const Remote& r, const std::string& id, const std::string& out_path, const Console& c) {
  const Reply reply = call(r, http::verb::get, job_path(id) + "/result");
  if (reply.status != 200) return report(r, reply, c);
  if (reply.body.compare(0, 4, "glTF") != 0) {
    std::fprintf(c.err, "hemibake: the server at %s:%s did not answer with a GLB; is it a hemibake-server?\n", r.host.c_str(),
                 r.port.c_str());
    return 1;
  }
  std::ofstream out(out_path, std::ios::binary);
  if (!out.write(reply.body.data(), static_cast<std::streamsize>(reply.body.size())) || !out.flush()) {
    std::fprintf(c.err, "hemibake: cannot write %s\n", out_path.c_str());
    return 1;
  }
  std::fprintf(c.out, "wrote %s (%zu bytes)\n", out_path.c_str(), reply.body.size());
  return 0;
}

int remote_cancel(const Remote& r, const std::string& id, const Console& c) {
  const Reply reply = call(r, http::verb::delete_, job_path(id));
  if (reply.status != 200) return report(r, reply, c);
  if (answer_json(r, reply, c).is_null()) return 1;
  std::fprintf(c.out, "job %s cancelled\n", id.c_str());
  return 0;
}

int remote_list(const Remote& r, const std::string& state, const Console& c) {
  std::string target = "/v1/jobs?limit=100" + (state.empty() ? std::string() : "&state=" + state);
  const Reply reply = call(r, http::verb::get, target);
  if (reply.status != 200) return report(r, reply, c);
  const json j = answer_json(r, reply, c);
  if (j.is_null()) return 1;
  if (!j.contains("jobs") || !j["jobs"].is_array()) return report(r, reply, c);
  for (const auto& job : j["jobs"]) {
    const double u = job.contains("progress") ? job["progress"].value("unshot_fraction", 1.0) : 1.0;
    std::fprintf(c.out, "%s  %-9s  unshot %.5f  %s\n", job["id"].get<std::string>().c_str(), job["state"].get<std::string>().c_str(),
                u, job.value("error", "").c_str());
  }
  return 0;
}

int remote_bake(const Remote& r, const std::string& in, const std::string& out, const protocol::JobSpec& spec,
                const Console& c) {
  std::string id;
  if (int rc = remote_submit(r, in, spec, c, &id); rc != 0) return rc;
  std::fprintf(c.err, "hemibake: job %s\n", id.c_str());
  if (int rc = remote_watch(r, id, c); rc != 0) return rc;
  return remote_fetch(r, id, out, c);
}

}  // namespace hemibake::client
