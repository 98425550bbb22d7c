#include "hemibake/client/remote.h"

#include "http_call.h"

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
#include <random>
#include <thread>
#include <sstream>

namespace hemibake::client {
namespace {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;
using nlohmann::json;

using Clock = std::chrono::steady_clock;

// "5 s", "0.5 s".
std::string seconds_text(double seconds) {
  char text[32];
  std::snprintf(text, sizeof text, "%g s", std::round(seconds * 10.0) / 10.0);
  return text;
}

// Retry-After as delay-seconds (RFC 9110, section 10.2.3); -1 if absent or an HTTP-date, which
// hemibake-server never sends.
double parse_retry_after(const std::string& value) {
  if (value.empty() || !std::all_of(value.begin(), value.end(), [](unsigned char ch) { return std::isdigit(ch) != 0; })) return -1.0;
  return std::min(std::strtod(value.c_str(), nullptr), 3600.0);
}

// How a connection failed, by its error. Refused: nothing listens there (a server restarting), so
// nothing was sent. Reset, aborted, a broken pipe, or closed before a whole answer: the server (or
// a proxy) went away on the way, after the request may have arrived.
Failure failure_of(const beast::error_code& ec) {
  if (ec == net::error::connection_refused) return Failure::kRefused;
  if (ec == net::error::connection_reset || ec == net::error::connection_aborted || ec == net::error::broken_pipe ||
      ec == net::error::eof || ec == http::error::end_of_stream || ec == http::error::partial_message)
    return Failure::kCut;
  return Failure::kOther;
}

std::string failure_text(const Remote& r, Failure failure, const beast::error_code& ec) {
  if (failure == Failure::kCut)
    return "the server at " + r.host + ":" + r.port + " closed the connection before it answered (" + ec.message() + ")";
  return "cannot reach the server at " + r.host + ":" + r.port + ": " + ec.message();
}

Reply call(const Remote& r, http::verb verb, const std::string& target, const std::string& body = {},
           const std::string& content_type = {}, const std::map<std::string, std::string>& headers = {}) {
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
    for (const auto& [name, value] : headers) req.set(name, value);
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
    out.retry_after = parse_retry_after(std::string(parser.get()[http::field::retry_after]));
  } catch (const boost::system::system_error& e) {
    out.failure = failure_of(e.code());
    out.error = failure_text(r, out.failure, e.code());
  } catch (const std::exception& e) {
    out.failure = Failure::kOther;
    out.error = std::string("cannot reach the server at ") + r.host + ":" + r.port + ": " + e.what();
  }
  return out;
}

// The server's own error message in `reply`, or empty if it sent none (a proxy's page, say).
std::string server_error(const Reply& reply) {
  const json j = json::parse(reply.body, nullptr, false);
  return j.is_object() && j.contains("error") && j["error"].is_string() ? j["error"].get<std::string>() : std::string();
}

// Prints the server's error for a failed call; returns the exit status 1.
int report(const Remote& r, const Reply& reply, const Console& c) {
  const std::string gave_up =
      reply.gave_up_after > 0 ? " (still so after " + seconds_text(reply.gave_up_after) + "; --retry-seconds waits longer)" : "";
  if (!reply.error.empty()) {
    std::fprintf(c.err, "hemibake: %s%s\n", reply.error.c_str(), gave_up.c_str());
    return 1;
  }
  const std::string message = server_error(reply);
  if (message.empty()) {
    if (reply.status == 503) {  // a proxy or load balancer in front of the server says it has none to send to
      std::fprintf(c.err, "hemibake: the server at %s:%s is unavailable (503)%s\n", r.host.c_str(), r.port.c_str(), gave_up.c_str());
      return 1;
    }
    if (reply.status == 429) {  // hemibake-server says why (its queue is full); this is a proxy's rate limit
      std::fprintf(c.err, "hemibake: the server at %s:%s has too many requests (429: its queue is full, or a proxy limits the rate)%s\n",
                   r.host.c_str(), r.port.c_str(), gave_up.c_str());
      return 1;
    }
    // Not one of ours (a proxy, another web server): its page would only bury the point.
    std::fprintf(c.err, "hemibake: the server at %s:%s answered %d without a hemibake error; is it a hemibake-server?\n",
                 r.host.c_str(), r.port.c_str(), reply.status);
    return 1;
  }
  std::fprintf(c.err, "hemibake: the server answered %d: %s%s%s\n", reply.status, message.c_str(),
               reply.status == 401 ? " (set HEMIBAKE_TOKEN)" : "", gave_up.c_str());
  return 1;
}

// Waits between tries of a request, for up to Remote::retry_seconds from the first failure, saying
// on stderr what it waits for. The server may ask to be asked later: 503 (its job store is busy or
// cannot be reached, it has too much waiting, it is stopping; a proxy with no server to send to) or
// 429 (its queue is full); then it waits as Retry-After says (5 s without one). Or the connection
// may fail (refused or cut while the server restarts); then it waits 0.5 s, twice as long each
// time up to 5 s: a restart takes a second or two, and a server that stays away is not asked
// more than once per 5 s.
class Retrier {
 public:
  Retrier(const Remote& r, const Console& c, std::string what) : r_(r), c_(c), what_(std::move(what)) {}
  /// After a 503 or 429 (`why`: the server's reason): waits and returns true, or returns false
  /// once the time is up.
  bool wait(double retry_after, const std::string& why) {
    backoff_ = kFirstBackoff;  // the server answers: a later failed connection is a new outage
    return pause(retry_after >= 0.0 ? std::max(retry_after, 0.1) : 5.0, why);
  }
  /// After a failed connection (`why`: how it failed): waits and returns true, or returns false
  /// once the time is up.
  bool wait_to_reconnect(const std::string& why) {
    const double seconds = backoff_;
    backoff_ = std::min(2.0 * backoff_, kLastBackoff);
    return pause(seconds, why);
  }
  /// The request was answered: a later outage has the whole time again.
  void reset() {
    waiting_ = false;
    backoff_ = kFirstBackoff;
  }

 private:
  static constexpr double kFirstBackoff = 0.5;
  static constexpr double kLastBackoff = 5.0;

  bool pause(double seconds, const std::string& why) {
    const auto now = Clock::now();
    if (!waiting_) start_ = now;
    waiting_ = true;
    const double left = r_.retry_seconds - std::chrono::duration<double>(now - start_).count();
    if (left <= 0.0) return false;
    seconds = std::min(seconds, left);
    std::fprintf(c_.err, "hemibake: %s: %s; trying again in %s\n", what_.c_str(), why.c_str(), seconds_text(seconds).c_str());
    std::fflush(c_.err);
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    return true;
  }

  const Remote& r_;
  const Console& c_;
  std::string what_;
  bool waiting_ = false;
  Clock::time_point start_;
  double backoff_ = kFirstBackoff;
};

// Whether the server asks to be asked again later.
bool come_back_later(const Reply& reply) { return reply.status == 503 || reply.status == 429; }

// Why the server asks to be asked later, for the wait's message.
std::string busy_reason(const Reply& reply) {
  const std::string message = server_error(reply);
  return (reply.status == 429 ? "the server is busy (429" : "the server is unavailable (503") +
         (message.empty() ? std::string() : ": " + message) + ")";
}

// Whether a request may be sent again after a try that may have reached the server: the
// idempotent methods (RFC 9110, section 9.2.2; a DELETE of a job already cancelled is answered
// 409, see remote_cancel), and a request with an Idempotency-Key (the server answers its repeat with
// the job the first try made).
bool repeatable(http::verb verb, const std::map<std::string, std::string>& headers) {
  if (verb == http::verb::get || verb == http::verb::head || verb == http::verb::put || verb == http::verb::delete_ ||
      verb == http::verb::options)
    return true;
  return std::any_of(headers.begin(), headers.end(),
                     [](const auto& h) { return beast::iequals(h.first, "Idempotency-Key") && !h.second.empty(); });
}

// A fresh Idempotency-Key: a submission tried again after a lost answer names the job it made.
std::string new_idempotency_key() {
  std::random_device random;
  static const char* hex = "0123456789abcdef";
  std::string key;
  for (int i = 0; i < 32; ++i) key += hex[random() & 15];
  return key;
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

Reply call_retrying(const Remote& r, const Console& c, const std::string& what, const std::string& method,
                    const std::string& target, const std::string& body, const std::string& content_type,
                    const std::map<std::string, std::string>& headers) {
  const http::verb verb = http::string_to_verb(method);
  Retrier retry(r, c, what);
  for (bool cut_before = false;;) {
    Reply reply = call(r, verb, target, body, content_type, headers);
    reply.earlier_try_cut = cut_before;
    bool again = false;
    if (come_back_later(reply)) {
      again = retry.wait(reply.retry_after, busy_reason(reply));
    } else if (reply.failure == Failure::kRefused || (reply.failure == Failure::kCut && repeatable(verb, headers))) {
      again = retry.wait_to_reconnect(reply.error);
    } else {
      if (reply.failure == Failure::kCut) reply.error += "; not tried again, since the server may have acted on it";
      return reply;
    }
    if (!again) {
      reply.gave_up_after = r.retry_seconds;
      return reply;
    }
    cut_before = cut_before || reply.failure == Failure::kCut;
  }
}

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
  // One key for every try: a try whose answer was lost made the job, and the next one is answered
  // with that job instead of making a second.
  const Reply reply = call_retrying(r, c, "submitting " + path, "POST", "/v1/jobs" + query_of(spec), bytes,
                                    glb ? "model/gltf-binary" : "model/gltf+json", {{"Idempotency-Key", new_idempotency_key()}});
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
  const Reply reply = call_retrying(r, c, "reading the status of job " + id, "GET", job_path(id));
  if (reply.status != 200) return report(r, reply, c);
  const json j = answer_json(r, reply, c);
  if (j.is_null()) return 1;
  std::fprintf(c.out, "%s\n", j.dump(2).c_str());
  return 0;
}

namespace {

// One connection to job `id`'s event stream, from after event `last_event`, read until the server
// closes it. Progress goes to `printer`; `last_event` follows the events read; `ended` is set once a
// state event names a final state. Returns the server's answer if it did not open the stream (its
// status is 0 if it did).
Reply follow_events(const Remote& r, const std::string& id, uint64_t& last_event, ProgressPrinter& printer, const Console& c,
                    bool& ended) {
  net::io_context io;
  tcp::resolver resolver(io);
  beast::tcp_stream stream(io);
  stream.connect(resolver.resolve(r.host, r.port));
  std::string req = "GET " + job_path(id) + "/events HTTP/1.1\r\nHost: " + r.host + "\r\nAccept: text/event-stream\r\n";
  if (!r.token.empty()) req += "Authorization: Bearer " + r.token + "\r\n";
  if (last_event > 0) req += "Last-Event-ID: " + std::to_string(last_event) + "\r\n";
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
          Reply refused;
          refused.status = std::atoi(pending.c_str() + 9);
          std::string head = pending.substr(0, end);
          std::transform(head.begin(), head.end(), head.begin(), [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
          // The error's body may come after the head: read it to its Content-Length.
          if (const size_t at = head.find("\r\ncontent-length:"); at != std::string::npos) {
            const size_t length = std::strtoull(head.c_str() + at + 17, nullptr, 10);
            while (!ec && length <= (64u << 10) && pending.size() < end + 4 + length) {
              const size_t more = stream.read_some(net::buffer(buf), ec);
              pending.append(buf, more);
            }
          }
          refused.body = pending.substr(end + 4);
          if (const size_t at = head.find("\r\nretry-after:"); at != std::string::npos) {
            std::string value = head.substr(at + 14, head.find('\r', at + 14) - (at + 14));
            value.erase(0, value.find_first_not_of(' '));
            value.erase(value.find_last_not_of(' ') + 1);
            refused.retry_after = parse_retry_after(value);
          }
          return refused;
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
        else if (line.rfind("id: ", 0) == 0) last_event = std::strtoull(line.c_str() + 4, nullptr, 10);
      }
      const json j = json::parse(data, nullptr, false);
      if (type == "progress") {
        if (const auto p = protocol::parse_progress_json(data)) printer.update(*p);
      }
      if (type == "state" && j.is_object()) {
        const std::string state = j.value("state", "");
        ended = ended || state == "succeeded" || state == "failed" || state == "cancelled";
        if (state == "failed") {
          printer.finish();
          std::fprintf(c.err, "hemibake: the bake failed: %s\n", j.value("error", "").c_str());
        }
      }
    }
    // A final state is the stream's last event: the server closes it then, and a server that kept
    // it open until its next heartbeat (15 s, before 2026-11-27) is not waited for.
    if (ec || ended) break;
  }
  return {};
}

}  // namespace

int remote_watch(const Remote& r, const std::string& id, const Console& c) {
  ProgressPrinter printer(c);
  Retrier retry(r, c, "following job " + id);
  uint64_t last_event = 0;
  for (bool ended = false; !ended;) {
    Reply refused;
    const uint64_t before = last_event;
    try {
      refused = follow_events(r, id, last_event, printer, c, ended);
    } catch (const boost::system::system_error& e) {
      // Opening the stream failed. Refused or cut (a server restarting): asking again is safe.
      printer.finish();
      Reply lost;
      lost.failure = failure_of(e.code());
      lost.error = failure_text(r, lost.failure, e.code());
      if (lost.failure != Failure::kRefused && lost.failure != Failure::kCut) return report(r, lost, c);
      if (retry.wait_to_reconnect(lost.error)) continue;
      lost.gave_up_after = r.retry_seconds;
      return report(r, lost, c);
    } catch (const std::exception& e) {
      printer.finish();
      std::fprintf(c.err, "hemibake: cannot follow job %s: %s\n", id.c_str(), e.what());
      return 1;
    }
    if (ended) break;
    if (come_back_later(refused)) {
      printer.finish();
      if (!retry.wait(refused.retry_after, busy_reason(refused))) {
        refused.gave_up_after = r.retry_seconds;
        return report(r, refused, c);
      }
      continue;
    }
    if (refused.status != 0) {
      printer.finish();
      return report(r, refused, c);
    }
    // The stream closed before a final state: the job may have ended without one (a restart that
    // failed it after its last attempt), or the connection was cut (a server restarting, a proxy's
    // timeout). Its state says which; if it still runs, the stream is followed again from the last
    // event read.
    if (last_event > before) retry.reset();  // it had got going: a new cut has the whole time again
    printer.finish();
    const Reply reply = call_retrying(r, c, "reading the status of job " + id, "GET", job_path(id));
    if (reply.status != 200) return report(r, reply, c);
    const json j = answer_json(r, reply, c);
    if (j.is_null()) return 1;
    const std::string state = j.value("state", "");
    if (state != "queued" && state != "running") break;
    if (!retry.wait(1.0, "the event stream ended before the job did")) {
      std::fprintf(c.err, "hemibake: the event stream of job %s kept ending before the job did; gave up after %s\n", id.c_str(),
                   seconds_text(r.retry_seconds).c_str());
      return 1;
    }
  }
  printer.finish();
  // The stream ends after the final state; read it back to be sure of it.
  const Reply reply = call_retrying(r, c, "reading the status of job " + id, "GET", job_path(id));
  if (reply.status != 200) return report(r, reply, c);
  const json j = answer_json(r, reply, c);
  if (j.is_null()) return 1;
  const std::string state = j.value("state", "");
  std::fprintf(c.err, "hemibake: job %s %s\n", id.c_str(), state.c_str());
  return state == "succeeded" ? 0 : 1;
}

int remote_fetch(const Remote& r, const std::string& id, const std::string& out_path, const Console& c) {
  const Reply reply = call_retrying(r, c, "fetching the result of job " + id, "GET", job_path(id) + "/result");
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
  const Reply reply = call_retrying(r, c, "cancelling job " + id, "DELETE", job_path(id));
  if (reply.status == 409 && reply.earlier_try_cut) {
    // The server answers a DELETE of a job that has ended with 409. An earlier try was cut after
    // it was sent, and may have been the one that cancelled the job: if the job is cancelled now,
    // the cancel is done (also if someone else cancelled it meanwhile: it is cancelled either way).
    // Ended otherwise, the 409 stands.
    const Reply now = call_retrying(r, c, "reading the status of job " + id, "GET", job_path(id));
    const json j = now.status == 200 ? json::parse(now.body, nullptr, false) : json();
    if (j.is_object() && j.value("state", "") == "cancelled") {
      std::fprintf(c.out, "job %s cancelled\n", id.c_str());
      return 0;
    }
  }
  if (reply.status != 200) return report(r, reply, c);
  if (answer_json(r, reply, c).is_null()) return 1;
  std::fprintf(c.out, "job %s cancelled\n", id.c_str());
  return 0;
}

int remote_list(const Remote& r, const std::string& state, const Console& c) {
  std::string target = "/v1/jobs?limit=100" + (state.empty() ? std::string() : "&state=" + state);
  const Reply reply = call_retrying(r, c, "listing jobs", "GET", target);
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
