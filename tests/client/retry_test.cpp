// The server commands against a scripted HTTP server on loopback (plain POSIX sockets, written
// here, so that what the client sent is read by code other than the client's): what they ask again
// (429 and 503 as Retry-After says; a refused connection; a cut one when the request is safe to
// repeat), what they do not (a POST without an Idempotency-Key once it may have arrived), and what
// they say meanwhile.
#include "captured.h"
#include "hemibake/client/cli.h"
#include "http_call.h"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace hemibake::client {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

const std::string kScene = HEMIBAKE_SOURCE_DIR "/data/cornell-box.gltf";

// One request as the server read it.
struct Seen {
  std::string method;
  std::string target;
  std::map<std::string, std::string> headers;  // names in lower case
  size_t body_bytes = 0;
  std::string header(const std::string& name) const {
    const auto it = headers.find(name);
    return it == headers.end() ? std::string() : it->second;
  }
};

// What the server does with one connection once it has read its request.
struct Step {
  enum class Kind { kAnswer, kClose, kReset } kind = Kind::kAnswer;
  std::string response;                   // kAnswer: all that is sent before the server closes
  std::chrono::milliseconds down_for{0};  // then it stops listening this long (a restart)
};

Step answer(int status, const std::string& json_body, const std::string& more_headers = "") {
  return {Step::Kind::kAnswer,
          "HTTP/1.1 " + std::to_string(status) + " Whatever\r\nContent-Type: application/json\r\nContent-Length: " +
              std::to_string(json_body.size()) + "\r\nConnection: close\r\n" + more_headers + "\r\n" + json_body};
}

// An event stream's start and `events`, after which the server closes it (the stream cut).
Step events(const std::string& events) {
  return {Step::Kind::kAnswer, "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-cache\r\n\r\n" + events};
}

// Closed without a word, as a server that stops after reading the request (end of stream).
Step closed_unanswered() { return {Step::Kind::kClose, {}}; }

// Reset after reading the request, as a server killed with it.
Step reset_unanswered() { return {Step::Kind::kReset, {}}; }

Step then_down(Step step, std::chrono::milliseconds gap) {
  step.down_for = gap;
  return step;
}

// A server on 127.0.0.1 that reads one request per connection and treats the n-th connection as the
// n-th step of its script says (the last step repeats). Until `listen_after` has passed, its port is
// bound but not listening: connections to it are refused, as while a server restarts.
class ScriptedServer {
 public:
  explicit ScriptedServer(std::vector<Step> script, std::chrono::milliseconds listen_after = 0ms) : script_(std::move(script)) {
    listener_ = bound_socket(0);
    sockaddr_in addr{};
    socklen_t size = sizeof addr;
    ::getsockname(listener_, reinterpret_cast<sockaddr*>(&addr), &size);
    port_ = ntohs(addr.sin_port);
    if (listen_after == 0ms) ::listen(listener_, 16);
    thread_ = std::thread([this, listen_after] {
      if (listen_after > 0ms) {
        pause(listen_after);
        ::listen(listener_, 16);
      }
      serve();
    });
  }
  ~ScriptedServer() {
    stop_ = true;
    thread_.join();
    if (listener_ >= 0) ::close(listener_);
  }
  ScriptedServer(const ScriptedServer&) = delete;
  ScriptedServer& operator=(const ScriptedServer&) = delete;

  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
  std::vector<Seen> seen() {
    std::lock_guard lock(mutex_);
    return seen_;
  }

 private:
  static int bound_socket(unsigned short port) {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    const int on = 1;
    ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    addr.sin_port = htons(port);
    if (::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) ADD_FAILURE() << "bind: " << std::strerror(errno);
    return fd;
  }

  // Sleeps for `time`, or less if the server is being destroyed.
  void pause(std::chrono::milliseconds time) {
    for (const auto until = Clock::now() + time; !stop_ && Clock::now() < until;) std::this_thread::sleep_for(20ms);
  }

  void serve() {
    for (size_t n = 0; !stop_;) {
      pollfd p{listener_, POLLIN, 0};
      if (::poll(&p, 1, 50) != 1) continue;
      const int fd = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) continue;
      const Step& step = script_[std::min(n++, script_.size() - 1)];
      const bool read = read_request(fd);
      if (read && step.kind == Step::Kind::kAnswer) {
        for (size_t at = 0; at < step.response.size();) {
          const ssize_t w = ::send(fd, step.response.data() + at, step.response.size() - at, MSG_NOSIGNAL);
          if (w <= 0) break;
          at += static_cast<size_t>(w);
        }
      }
      if (step.kind == Step::Kind::kReset) {
        const linger abort{1, 0};  // close() sends RST instead of FIN
        ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &abort, sizeof abort);
      }
      ::close(fd);
      if (step.down_for > 0ms) {
        ::close(listener_);
        pause(step.down_for);
        listener_ = bound_socket(port_);
        ::listen(listener_, 16);
      }
    }
  }

  // Reads the head and the Content-Length body and records them; false if the client went away.
  bool read_request(int fd) {
    std::string data;
    char buf[65536];
    size_t head_end = std::string::npos, need = 0;
    const auto until = Clock::now() + 20s;
    while (Clock::now() < until) {
      if (head_end == std::string::npos && (head_end = data.find("\r\n\r\n")) != std::string::npos) {
        Seen s;
        std::string lower = data.substr(0, head_end);
        std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
        const size_t line_end = data.find("\r\n");
        const std::string line = data.substr(0, line_end);
        s.method = line.substr(0, line.find(' '));
        s.target = line.substr(s.method.size() + 1, line.rfind(' ') - s.method.size() - 1);
        for (size_t at = line_end + 2; at < head_end;) {
          const size_t end = data.find("\r\n", at);
          const size_t colon = data.find(':', at);
          if (colon < end) s.headers[lower.substr(at, colon - at)] = data.substr(colon + 2, end - colon - 2);
          at = end + 2;
        }
        need = head_end + 4 + std::strtoull(s.header("content-length").c_str(), nullptr, 10);
        s.body_bytes = need - head_end - 4;
        std::lock_guard lock(mutex_);
        seen_.push_back(s);
      }
      if (head_end != std::string::npos && data.size() >= need) return true;
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 100) != 1) continue;
      const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      if (n <= 0) return false;
      data.append(buf, static_cast<size_t>(n));
    }
    return false;
  }

  std::vector<Step> script_;
  int listener_ = -1;
  unsigned short port_ = 0;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::vector<Seen> seen_;
  std::thread thread_;
};

// A command line run through the library, and what it printed.
struct Ran {
  int status = -1;
  std::string out, err;
  double seconds = 0.0;
};

Ran run_command(const std::vector<std::string>& args) {
  CommandLine cl;
  EXPECT_EQ(parse_command_line(args, cl), "");
  Captured io;
  const auto t0 = Clock::now();
  Ran ran;
  ran.status = run(cl, io.console);
  ran.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  ran.out = io.out();
  ran.err = io.err();
  return ran;
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

const std::string kQueueFull = R"({"error":"the queue is full (1 jobs); retry later"})";
const std::string kQueued = R"({"id":"j1","state":"queued"})";

// The server's queue is full (429, Retry-After: 1), then it takes the job: the submission waits as
// asked, says why, and is accepted, with the same Idempotency-Key both times.
TEST(Retries, QueueFullIsAskedAgainAfterRetryAfterAndTheSubmitIsAccepted) {
  ScriptedServer server({answer(429, kQueueFull, "Retry-After: 1\r\n"), answer(202, kQueued)});
  const Ran ran = run_command({"submit", kScene, "--server", server.url(), "--retry-seconds", "20"});
  EXPECT_EQ(ran.status, 0) << ran.err;
  EXPECT_EQ(ran.out, "j1\n");
  EXPECT_TRUE(has(ran.err, "429: the queue is full")) << "the wait is not explained: " << ran.err;
  EXPECT_TRUE(has(ran.err, "trying again in 1 s")) << ran.err;
  EXPECT_GE(ran.seconds, 0.9);
  const auto seen = server.seen();
  ASSERT_EQ(seen.size(), 2u) << ran.err;
  EXPECT_EQ(seen[0].method, "POST");
  EXPECT_FALSE(seen[0].header("idempotency-key").empty());
  EXPECT_EQ(seen[0].header("idempotency-key"), seen[1].header("idempotency-key"));
}

// A queue that stays full: asked again until --retry-seconds is up, then exit status 1 with the
// server's reason and how long it was tried.
TEST(Retries, QueueThatStaysFullFailsNamingItAfterRetrySeconds) {
  ScriptedServer server({answer(429, kQueueFull, "Retry-After: 1\r\n")});
  const Ran ran = run_command({"submit", kScene, "--server", server.url(), "--retry-seconds", "2"});
  EXPECT_EQ(ran.status, 1) << ran.err;
  const std::string last = ran.err.substr(ran.err.rfind('\n', ran.err.size() - 2) + 1);
  EXPECT_TRUE(has(last, "the queue is full")) << ran.err;
  EXPECT_TRUE(has(last, "still so after 2 s")) << ran.err;
  EXPECT_GE(server.seen().size(), 2u) << ran.err;
  EXPECT_GE(ran.seconds, 1.5);
  EXPECT_LT(ran.seconds, 10.0);
}

// The first connection is closed after the request, unanswered (a server stopping): a GET is safe
// to repeat and is asked again after a short pause.
TEST(Retries, StatusIsAskedAgainWhenTheConnectionClosesUnanswered) {
  ScriptedServer server({closed_unanswered(), answer(200, R"({"id":"j1","state":"running"})")});
  const Ran ran = run_command({"status", "j1", "--server", server.url(), "--retry-seconds", "20"});
  EXPECT_EQ(ran.status, 0) << ran.err;
  EXPECT_TRUE(has(ran.out, R"("state": "running")")) << ran.out;
  EXPECT_TRUE(has(ran.err, "closed the connection")) << ran.err;
  EXPECT_TRUE(has(ran.err, "trying again in 0.5 s")) << ran.err;
  const auto seen = server.seen();
  ASSERT_EQ(seen.size(), 2u) << ran.err;
  for (const Seen& s : seen) EXPECT_EQ(s.method + " " + s.target, "GET /v1/jobs/j1");
}

// The first submission is reset after the server read it (it may have made the job): the submission
// carries an Idempotency-Key, so it is sent again with the same key and the same scene. Another
// submission has a key of its own.
TEST(Retries, SubmitCutAfterSendingIsSentAgainWithTheSameIdempotencyKey) {
  ScriptedServer server({reset_unanswered(), answer(202, kQueued)});
  const Ran ran = run_command({"submit", kScene, "--server", server.url(), "--retry-seconds", "20"});
  EXPECT_EQ(ran.status, 0) << ran.err;
  EXPECT_EQ(ran.out, "j1\n");
  auto seen = server.seen();
  ASSERT_EQ(seen.size(), 2u) << ran.err;
  const std::string key = seen[0].header("idempotency-key");
  EXPECT_GE(key.size(), 16u) << "the submission carried no Idempotency-Key";
  EXPECT_EQ(seen[1].header("idempotency-key"), key) << "the retry carried another key";
  EXPECT_EQ(seen[1].target, seen[0].target);
  EXPECT_GT(seen[0].body_bytes, 0u);
  EXPECT_EQ(seen[1].body_bytes, seen[0].body_bytes);
  const Ran again = run_command({"submit", kScene, "--server", server.url(), "--retry-seconds", "20"});
  EXPECT_EQ(again.status, 0) << again.err;
  seen = server.seen();
  ASSERT_EQ(seen.size(), 3u) << again.err;
  EXPECT_NE(seen[2].header("idempotency-key"), key) << "two submissions shared a key";
}

// A POST without an Idempotency-Key whose connection is cut after it was sent may have been acted
// on: it is not sent again, and the error says so.
TEST(Retries, PostWithoutAKeyIsNotSentAgainOnceItMayHaveArrived) {
  ScriptedServer server({closed_unanswered(), answer(202, kQueued)});
  Remote remote;
  ASSERT_EQ(parse_server(server.url(), remote), "");
  remote.retry_seconds = 20;
  Captured io;
  const Reply reply = call_retrying(remote, io.console, "posting", "POST", "/v1/jobs", "{}", "model/gltf+json");
  EXPECT_EQ(reply.status, 0);
  EXPECT_EQ(reply.failure, Failure::kCut) << reply.error;
  EXPECT_TRUE(has(reply.error, "not tried again")) << reply.error;
  std::this_thread::sleep_for(1s);  // longer than the first pause: a retry would have come by now
  EXPECT_EQ(server.seen().size(), 1u) << io.err();
}

// Nothing listens yet (a server restarting): the request was never sent, so even a POST without a
// key is sent once the server listens; `list` waits likewise, saying so.
TEST(Retries, RefusedConnectionsAreTriedAgainUntilTheServerListens) {
  {
    ScriptedServer server({answer(200, R"({"jobs":[{"id":"j1","state":"queued"}]})")}, 1500ms);
    const Ran ran = run_command({"list", "--server", server.url(), "--retry-seconds", "20"});
    EXPECT_EQ(ran.status, 0) << ran.err;
    EXPECT_TRUE(has(ran.out, "j1")) << ran.out;
    EXPECT_TRUE(has(ran.err, "Connection refused")) << ran.err;
    EXPECT_TRUE(has(ran.err, "trying again in 0.5 s")) << ran.err;
    EXPECT_TRUE(has(ran.err, "trying again in 1 s")) << "the pause does not grow: " << ran.err;
    EXPECT_GE(ran.seconds, 1.4);
  }
  {
    ScriptedServer server({answer(202, kQueued)}, 1000ms);
    Remote remote;
    ASSERT_EQ(parse_server(server.url(), remote), "");
    remote.retry_seconds = 20;
    Captured io;
    const Reply reply = call_retrying(remote, io.console, "posting", "POST", "/v1/jobs", "{}", "model/gltf+json");
    EXPECT_EQ(reply.status, 202) << reply.error;
    EXPECT_EQ(server.seen().size(), 1u);
  }
}

// The budget is shared: a server that keeps refusing is given up on after --retry-seconds, with
// the reason and how long; --retry-seconds 0 reports at once.
TEST(Retries, ServerThatNeverListensIsGivenUpOnAfterRetrySeconds) {
  ScriptedServer server({answer(200, "{}")}, 60s);
  const Ran ran = run_command({"status", "j1", "--server", server.url(), "--retry-seconds", "2"});
  EXPECT_EQ(ran.status, 1);
  EXPECT_TRUE(has(ran.err, "Connection refused (still so after 2 s")) << ran.err;
  EXPECT_GE(ran.seconds, 1.5);
  EXPECT_LT(ran.seconds, 10.0);
  const Ran at_once = run_command({"status", "j1", "--server", server.url(), "--retry-seconds", "0"});
  EXPECT_EQ(at_once.status, 1);
  EXPECT_FALSE(has(at_once.err, "trying again")) << at_once.err;
  EXPECT_LT(at_once.seconds, 1.0);
}

// The DELETE's connection was cut after it was sent, and the retry is told that the job is already
// cancelled (409): the first try may have been the one that cancelled it, and the job's state says
// it is cancelled, so the cancel is done.
TEST(Retries, CancelCutAfterSendingIsDoneWhenTheJobIsCancelled) {
  ScriptedServer server({closed_unanswered(), answer(409, R"({"error":"the job is already cancelled"})"),
                         answer(200, R"({"id":"j1","state":"cancelled"})")});
  const Ran ran = run_command({"cancel", "j1", "--server", server.url(), "--retry-seconds", "20"});
  EXPECT_EQ(ran.status, 0) << ran.err;
  EXPECT_EQ(ran.out, "job j1 cancelled\n");
  const auto seen = server.seen();
  ASSERT_EQ(seen.size(), 3u) << ran.err;
  EXPECT_EQ(seen[0].method, "DELETE");
  EXPECT_EQ(seen[1].method, "DELETE");
  EXPECT_EQ(seen[2].method + " " + seen[2].target, "GET /v1/jobs/j1");
}

// A 409 to a cancel is still a failure when no try was cut (the job had ended before), and when
// one was but the job ended otherwise.
TEST(Retries, CancelOfAJobThatEndedOtherwiseStillFails) {
  {
    ScriptedServer server({answer(409, R"({"error":"the job is already cancelled"})")});
    const Ran ran = run_command({"cancel", "j1", "--server", server.url(), "--retry-seconds", "20"});
    EXPECT_EQ(ran.status, 1);
    EXPECT_TRUE(has(ran.err, "409: the job is already cancelled")) << ran.err;
    EXPECT_EQ(server.seen().size(), 1u);
  }
  {
    ScriptedServer server({closed_unanswered(), answer(409, R"({"error":"the job has already succeeded"})"),
                           answer(200, R"({"id":"j1","state":"succeeded"})")});
    const Ran ran = run_command({"cancel", "j1", "--server", server.url(), "--retry-seconds", "20"});
    EXPECT_EQ(ran.status, 1);
    EXPECT_TRUE(has(ran.err, "409: the job has already succeeded")) << ran.err;
  }
}

// The event stream is cut, and when `watch` follows it again the server is restarting (refused
// connections): it waits, follows again from the last event read (Last-Event-ID), and ends with
// the job.
TEST(Retries, WatchFollowsAgainAcrossARestart) {
  ScriptedServer server({events("id: 1\nevent: state\ndata: {\"state\":\"running\"}\n\n"),
                         then_down(answer(200, R"({"id":"j1","state":"running"})"), 3s),
                         events("id: 2\nevent: state\ndata: {\"state\":\"succeeded\"}\n\n"),
                         answer(200, R"({"id":"j1","state":"succeeded"})")});
  const Ran ran = run_command({"watch", "j1", "--server", server.url(), "--retry-seconds", "20"});
  EXPECT_EQ(ran.status, 0) << ran.err;
  EXPECT_TRUE(has(ran.err, "Connection refused")) << "the restart was not seen: " << ran.err;
  EXPECT_TRUE(has(ran.err, "job j1 succeeded")) << ran.err;
  const auto seen = server.seen();
  ASSERT_EQ(seen.size(), 4u) << ran.err;
  EXPECT_EQ(seen[2].target, "/v1/jobs/j1/events");
  EXPECT_EQ(seen[2].header("last-event-id"), "1");
}

}  // namespace
}  // namespace hemibake::client
