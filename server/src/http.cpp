#include "hemibake/server/http.h"

#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <optional>

namespace hemibake::server {
namespace {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;

// Beast reads at most this much per read, and only as much as its buffer has room for.
constexpr size_t kReadChunk = 64 * 1024;

std::chrono::steady_clock::duration seconds(double s) {
  return std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(s));
}

class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(tcp::socket&& socket, Service& service, const HttpOptions& options, std::atomic<size_t>& streams)
      : stream_(std::move(socket)), service_(service), options_(options), streams_(streams), timer_(stream_.get_executor()) {}

  void run() { net::dispatch(stream_.get_executor(), [self = shared_from_this()] { self->read(); }); }

 private:
  // Reading a request, under three limits: an idle connection closes after idle_timeout; the
  // request line and headers get header_timeout from their first byte; the body must average
  // min_rate bytes per second after header_timeout seconds of grace, and never pause for
  // idle_timeout. A slow but steady upload of any allowed size gets through; a request that misses
  // a limit once it has begun is answered 408. (One 30 s limit for the whole request dropped
  // uploads slower than 8.5 MB/s, with no answer.)
  void read() {
    head_ = false;
    timed_out_ = false;
    early_ = false;
    parser_.emplace();
    parser_->body_limit(options_.max_body_bytes);
    if (buffer_.size() > 0) return read_header();  // pipelined: the next request is here already
    stream_.expires_after(seconds(options_.idle_timeout));
    stream_.async_read_some(buffer_.prepare(1024), [self = shared_from_this()](beast::error_code ec, size_t n) {
      if (ec) return self->close();  // no request began: closed without a word
      self->buffer_.commit(n);
      self->read_header();
    });
  }

  void read_header() {
    stream_.expires_never();
    arm(std::chrono::steady_clock::now() + seconds(options_.header_timeout));
    http::async_read_header(stream_, buffer_, *parser_, [self = shared_from_this()](beast::error_code ec, size_t) {
      self->disarm();
      if (ec && self->timed_out_)
        return self->request_timeout("the request line and headers did not arrive within " + number(self->options_.header_timeout) +
                                     " s (hemibake-server --header-timeout)");
      self->on_header(ec);
    });
  }

  // The deadlines answer 408, so they are a timer of their own: the stream's expiry would close the
  // socket. A firing that comes after its read finished (its handler was queued already) is ignored.
  void arm(std::chrono::steady_clock::time_point deadline) {
    timer_.expires_at(deadline);
    timer_.async_wait([self = shared_from_this(), armed = ++armed_](beast::error_code ec) {
      if (ec || armed != self->armed_) return;
      self->timed_out_ = true;
      beast::error_code ignored;
      self->stream_.socket().cancel(ignored);
    });
  }
  void disarm() {
    ++armed_;
    timer_.cancel();
  }

  void on_header(beast::error_code header_ec) {
    if (header_ec) return on_read(header_ec);
    // Decided from the headers, before any of the body is read: how the body is framed, and
    // whether the client may send one at all (four unauthenticated 256 MB uploads held 1 GB).
    if (auto bad = framing_error()) return answer_early(*bad);
    if (parser_->is_done()) return on_read({});
    if (auto denied = service_.check_auth(header_only())) return answer_early(*denied);
    // A large body is read 64 KB at a time, not in the few hundred bytes the buffer had room for
    // after the header: for a 200 MB scene, 3 200 reads (and wake-ups of an I/O thread) instead of
    // 400 000. Small bodies leave an idle connection's buffer small.
    const auto length = parser_->content_length();
    if (!length || *length > kReadChunk / 4) buffer_.reserve(kReadChunk);
    body_start_ = std::chrono::steady_clock::now();
    received_ = 0;
    if (beast::iequals(parser_->get()[http::field::expect], "100-continue")) {
      // The client waits for this before it sends the body (RFC 9110, section 10.1.1).
      static const std::string kContinue = "HTTP/1.1 100 Continue\r\n\r\n";
      stream_.expires_after(seconds(options_.idle_timeout));
      net::async_write(stream_, net::buffer(kContinue), [self = shared_from_this()](beast::error_code ec, size_t) {
        if (ec) return self->close();
        self->stream_.expires_never();
        self->body_start_ = std::chrono::steady_clock::now();
        self->read_body();
      });
      return;
    }
    read_body();
  }

  void read_body() {
    if (parser_->is_done()) return on_read({});
    const auto now = std::chrono::steady_clock::now();
    auto deadline = now + seconds(options_.idle_timeout);
    if (options_.min_rate > 0)
      deadline = std::min(deadline, body_start_ + seconds(options_.header_timeout + static_cast<double>(received_) / options_.min_rate));
    arm(deadline);
    http::async_read_some(stream_, buffer_, *parser_, [self = shared_from_this()](beast::error_code ec, size_t n) {
      self->disarm();
      if (ec && self->timed_out_)
        return self->request_timeout("the request body arrived slower than " + number(self->options_.min_rate) +
                                     " bytes per second, or paused for " + number(self->options_.idle_timeout) +
                                     " s (hemibake-server --min-rate, --idle-timeout)");
      if (ec) return self->on_read(ec);
      self->received_ += n;
      self->read_body();
    });
  }

  static std::string number(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%g", v);
    return text;
  }

  // The request so far, without its body: for the checks made before the body is read.
  Request header_only() const {
    Request req;
    req.method = std::string(parser_->get().method_string());
    req.target = std::string(parser_->get().target());
    for (const auto& f : parser_->get()) {
      std::string name(f.name_string());
      for (auto& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      req.headers[name] = std::string(f.value());
    }
    return req;
  }

  // A Transfer-Encoding other than one "chunked" (RFC 9112, sections 6.1 and 6.3). If chunked is not
  // the last coding, or comes twice, the body's end is not known, and what follows it would be read
  // as the next request (a DELETE hidden in a body ran): 400. A coding before chunked that we cannot
  // decode: 501. Chunked with a Content-Length: 400 (a reader trusting the length sees another
  // end). Each closes the connection.
  std::optional<Response> framing_error() const {
    std::vector<std::string> codings;
    bool listed = false;
    for (const auto& f : parser_->get()) {
      if (f.name() != http::field::transfer_encoding) continue;
      listed = true;
      const std::string value(f.value());
      for (size_t start = 0; start <= value.size();) {
        size_t end = value.find(',', start);
        if (end == std::string::npos) end = value.size();
        std::string c = value.substr(start, end - start);
        c = c.substr(0, c.find(';'));  // transfer parameters
        c.erase(0, c.find_first_not_of(" \t"));
        c.erase(c.find_last_not_of(" \t") + 1);
        for (auto& ch : c) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
        if (!c.empty()) codings.push_back(c);
        start = end + 1;
      }
    }
    if (!listed) return std::nullopt;
    auto refuse = [](int status, const std::string& why) {
      return Response{status, {}, "{\"error\":\"" + why + "\"}"};
    };
    if (codings.empty() || codings.back() != "chunked")
      return refuse(400, "a request's Transfer-Encoding must end with chunked (RFC 9112, section 6.3)");
    if (std::count(codings.begin(), codings.end(), "chunked") > 1)
      return refuse(400, "chunked is listed more than once in Transfer-Encoding");
    if (codings.size() > 1) return refuse(501, "the only transfer coding this server reads is chunked");
    if (parser_->get().count(http::field::content_length) > 0)
      return refuse(400, "a request may not have both Transfer-Encoding and Content-Length");
    return std::nullopt;
  }

  // An answer given before the body was read (or all of it): the connection closes after it.
  void answer_early(const Response& r) {
    keep_alive_ = false;
    early_ = true;
    send(r);
  }

  void request_timeout(const std::string& why) {
    Response r;
    r.status = 408;
    r.body = "{\"error\":\"" + why + "\"}";
    answer_early(r);
  }

  // After an early answer, the client may still be sending: its bytes are read and dropped for a
  // moment before the socket closes, since closing with unread input sends a reset, which can
  // destroy the answer before the client has read it.
  void linger() {
    beast::error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    stream_.expires_after(std::chrono::seconds(2));
    drain(0);
  }
  void drain(size_t dropped) {
    auto sink = std::make_shared<std::array<char, 16384>>();
    stream_.async_read_some(net::buffer(*sink), [self = shared_from_this(), sink, dropped](beast::error_code ec, size_t n) {
      if (ec || dropped + n > (8u << 20)) return self->close();
      self->drain(dropped + n);
    });
  }

  void on_read(beast::error_code ec) {
    if (ec == http::error::end_of_stream || ec == beast::error::timeout) return close();
    if (ec == http::error::body_limit) {
      Response r;
      r.status = 413;
      r.body = "{\"error\":\"the request body is larger than the server's limit of " + std::to_string(options_.max_body_bytes) +
               " bytes (hemibake-server --max-body)\"}";
      return answer_early(r);
    }
    if (ec == http::error::header_limit) {
      Response r;
      r.status = 431;
      r.body = R"({"error":"the request line and headers are larger than 8 KB; shorten the URL or the headers"})";
      keep_alive_ = false;
      return send(r);
    }
    if (ec) {
      // A broken request: answer 400 if we can, then drop the connection.
      Response r;
      r.status = 400;
      r.body = std::string(R"({"error":"malformed HTTP request: )") + ec.message() + "\"}";
      return answer_early(r);
    }
    auto msg = parser_->release();
    keep_alive_ = msg.keep_alive();
    // HEAD is GET without the body; a body after a HEAD response would be read as the next response.
    head_ = msg.method() == http::verb::head;
    Request req;
    req.method = head_ ? "GET" : std::string(msg.method_string());
    req.target = std::string(msg.target());
    for (const auto& f : msg) {
      std::string name(f.name_string());
      for (auto& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      req.headers[name] = std::string(f.value());
    }
    req.body = std::move(msg.body());
    const std::string job = head_ ? std::string() : Service::events_job(req);
    if (!job.empty()) return start_events(req, job);
    // The service answers when it can (a scene checked, a preview made between two shots), from
    // whichever thread; the answer comes back to this session's strand. No I/O thread waits for it,
    // and the next request on this connection is read only after this one's answer is written.
    const std::string what = req.method + " " + req.target;
    try {
      service_.handle_async(std::move(req), [self = shared_from_this(), strand = tracked()](Response r) {
        net::post(strand, [self, r = std::move(r)] { self->send(r); });
      });
    } catch (const std::exception& e) {
      std::fprintf(stderr, "hemibake-server: %s failed: %s\n", what.c_str(), e.what());
      send(Response{500, {}, R"({"error":"internal error"})"});
    }
  }

  void send(const Response& r) {
    service_.count_response(r.status);
    if (r.parts) return send_parts(r);
    auto res = std::make_shared<http::response<http::string_body>>(static_cast<http::status>(r.status), 11);
    res->set(http::field::server, "hemibake");
    if (!r.content_type.empty()) res->set(http::field::content_type, r.content_type);
    for (const auto& [k, v] : r.headers) res->insert(k, v);
    res->body() = r.body;
    res->keep_alive(keep_alive_);
    res->prepare_payload();
    if (head_) res->body().clear();  // Content-Length stays the GET's
    // A large result may go to a slow client: the time allowed grows with its size, at min_rate.
    const double transfer = options_.min_rate > 0 ? static_cast<double>(res->body().size()) / options_.min_rate : 0.0;
    stream_.expires_after(seconds(options_.idle_timeout + transfer));
    http::async_write(stream_, *res, [self = shared_from_this(), res](beast::error_code ec, size_t) {
      if (!ec && !self->keep_alive_ && self->early_) return self->linger();
      if (ec || !self->keep_alive_) return self->close();
      self->read();
    });
  }

  // A body sent in parts (a result): the header with the whole length, then one part at a time,
  // each read from the store when the previous one has gone out. The connection holds one part.
  void send_parts(const Response& r) {
    auto res = std::make_shared<http::response<http::empty_body>>(static_cast<http::status>(r.status), 11);
    res->set(http::field::server, "hemibake");
    if (!r.content_type.empty()) res->set(http::field::content_type, r.content_type);
    for (const auto& [k, v] : r.headers) res->insert(k, v);
    res->content_length(r.parts_size);
    res->keep_alive(keep_alive_);
    auto sr = std::make_shared<http::response_serializer<http::empty_body>>(*res);
    stream_.expires_after(seconds(options_.idle_timeout));
    http::async_write_header(stream_, *sr, [self = shared_from_this(), res, sr, parts = r.parts, size = r.parts_size](beast::error_code ec, size_t) {
      if (ec) return self->close();
      if (self->head_) return self->sent();
      self->send_part(parts, 0, size);
    });
  }

  static constexpr size_t kPart = 1 << 20;

  void send_part(std::function<std::optional<std::string>(uint64_t, size_t)> parts, uint64_t at, uint64_t size) {
    if (at >= size) return sent();
    auto part = std::make_shared<std::string>();
    if (auto p = parts(at, static_cast<size_t>(std::min<uint64_t>(kPart, size - at))); p && !p->empty()) *part = std::move(*p);
    else return close();  // gone (expired) or unreadable: the client sees a short body, not a wrong one
    const double transfer = options_.min_rate > 0 ? static_cast<double>(part->size()) / options_.min_rate : 0.0;
    stream_.expires_after(seconds(options_.idle_timeout + transfer));
    net::async_write(stream_, net::buffer(*part), [self = shared_from_this(), part, parts = std::move(parts), at, size](beast::error_code ec, size_t n) mutable {
      if (ec) return self->close();
      self->send_part(std::move(parts), at + n, size);
    });
  }

  // A response has gone out: the next request, or the end of the connection.
  void sent() {
    if (!keep_alive_) return close();
    read();
  }

  // Server-Sent Events: every event since Last-Event-ID, then new ones as they come, a heartbeat
  // comment when idle, and the end of the stream after the job's final event.
  // The store is read on the service's lookup pool, never on an I/O thread, and only when the job
  // has a new event (the service wakes the stream): each read's answer comes back to this
  // session's strand.
  void start_events(const Request& req, const std::string& id) {
    if (auto denied = service_.check_auth(req)) return send(*denied);
    job_ = id;
    // A Last-Event-ID that is not a whole number we could have sent (-5, text, past 2^64) cannot
    // name an event: the stream replays from the start, as for a client that never had one.
    if (auto it = req.headers.find("last-event-id"); it != req.headers.end()) {
      const std::string& v = it->second;
      errno = 0;
      const bool digits = !v.empty() && v.size() <= 20 && v.find_first_not_of("0123456789") == std::string::npos;
      const uint64_t n = digits ? std::strtoull(v.c_str(), nullptr, 10) : 0;
      last_ = digits && errno == 0 ? n : 0;
    }
    read_events(&Session::on_first_events, std::chrono::milliseconds(0));
  }

  void read_events(void (Session::*then)(EventBatch), std::chrono::milliseconds wait) {
    service_.events_async(job_, last_, wait, [self = shared_from_this(), then, strand = tracked()](EventBatch b) {
      net::post(strand, [self, then, b = std::move(b)]() mutable { ((*self).*then)(std::move(b)); });
    });
  }

  // This session's strand, counted as work of the io_context while the copy lives: an answer the
  // service still owes keeps the I/O threads running (at a stop, until the service has answered).
  net::any_io_executor tracked() { return net::prefer(stream_.get_executor(), net::execution::outstanding_work.tracked); }

  void on_first_events(EventBatch batch) {
    if (batch.status == 404) {
      keep_alive_ = true;
      return send(Response{404, {}, R"({"error":"no such job"})"});
    }
    if (batch.status != 200) {
      const std::string why = batch.error.empty() ? "the server is busy; retry later" : batch.error + "; retry in a moment";
      return send(Response{503, {{"Retry-After", "5"}}, nlohmann::json{{"error", why}}.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)});
    }
    if (streams_.fetch_add(1) >= options_.max_streams) {
      streams_.fetch_sub(1);
      Response r{503, {{"Retry-After", "5"}}, R"({"error":"too many event streams; retry later"})"};
      return send(r);
    }
    counted_ = true;
    service_.count_response(200);
    out_ = std::make_shared<std::string>(
        "HTTP/1.1 200 OK\r\nServer: hemibake\r\nContent-Type: text/event-stream\r\nCache-Control: no-cache\r\n"
        "Connection: close\r\nX-Accel-Buffering: no\r\n\r\n");
    append(*out_, batch);
    watch_peer();
    write_events();
  }

  // The batch's events as SSE, after `out`; notes the last one sent and the end of the stream.
  void append(std::string& out, const EventBatch& batch) {
    for (const auto& e : batch.events) {
      out += "id: " + std::to_string(e.seq) + "\nevent: " + e.type + "\ndata: " + e.data + "\n\n";
      last_ = e.seq;
    }
    // No such job any more (expired): nothing will follow either.
    if (batch.end || batch.status == 404) done_ = true;
  }

  // The client says nothing during a stream, so the end of its input means it went away: end the
  // stream now and free its slot, not at the next write (up to a heartbeat later for a queued job).
  void watch_peer() {
    stream_.socket().async_wait(tcp::socket::wait_read, [self = shared_from_this()](beast::error_code ec) {
      if (ec == net::error::operation_aborted) return;
      if (!ec) {
        // Readiness may be stale (another thread saw the request's bytes arrive), so look without
        // blocking: nothing there, or bytes after the request, and the client is still with us.
        char sink[512];
        self->stream_.socket().non_blocking(true, ec);
        if (!ec) self->stream_.socket().read_some(net::buffer(sink), ec);
        if (!ec || ec == net::error::would_block) return self->watch_peer();
      }
      self->gone_ = true;
      self->timer_.cancel();
      self->close();  // the slot is free now; a wait for the job's next event ends in nothing
    });
  }

  void write_events() {
    stream_.expires_after(seconds(options_.idle_timeout));
    net::async_write(stream_, net::buffer(*out_), [self = shared_from_this(), keep = out_](beast::error_code ec, size_t) {
      if (ec || self->done_) return self->close();
      self->wait_events();
    });
  }

  void wait_events() {
    if (gone_) return close();
    read_events(&Session::on_events, std::chrono::duration_cast<std::chrono::milliseconds>(seconds(options_.heartbeat)));
  }

  // Nothing new after the wait: a heartbeat. A busy server's batch (503) has nothing either: the
  // stream asks again after a pause.
  void on_events(EventBatch batch) {
    if (gone_) return close();
    if (batch.status == 503) {
      timer_.expires_after(std::chrono::seconds(1));
      timer_.async_wait([self = shared_from_this()](beast::error_code) { self->wait_events(); });
      return;
    }
    auto out = std::make_shared<std::string>();
    append(*out, batch);
    if (out->empty() && !done_) *out = ": heartbeat\n\n";
    out_ = out;
    write_events();
  }

  void close() {
    if (counted_) {
      streams_.fetch_sub(1);
      counted_ = false;
    }
    beast::error_code ec;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ec);
    stream_.socket().cancel(ec);  // the peer watch, so that the session ends
  }

  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  Service& service_;
  HttpOptions options_;
  std::atomic<size_t>& streams_;
  net::steady_timer timer_;
  bool keep_alive_ = false;
  bool head_ = false;  // the request being answered is a HEAD
  // Reading a request.
  bool timed_out_ = false;  // a deadline cancelled the read
  bool early_ = false;      // answered before its body was read: linger before closing
  uint64_t armed_ = 0;      // which deadline is current
  std::chrono::steady_clock::time_point body_start_;
  uint64_t received_ = 0;   // body bytes so far
  // Event streams.
  std::string job_;
  uint64_t last_ = 0;
  bool done_ = false;
  bool gone_ = false;  // the client closed its end
  bool counted_ = false;
  std::shared_ptr<std::string> out_;
};

}  // namespace

struct HttpServer::Impl {
  Impl(Service& s, net::io_context& ctx, const HttpOptions& o)
      : service(s), io(ctx), options(o), acceptor(net::make_strand(ctx)), retry(acceptor.get_executor()) {}
  void accept() {
    acceptor.async_accept(net::make_strand(io), [this](beast::error_code ec, tcp::socket socket) {
      if (!acceptor.is_open()) return;
      if (ec) {
        // Out of file descriptors (or another transient failure): the pending connection stays in
        // the backlog, so accepting again at once would spin a core. Wait until connections close.
        if (!failing) std::fprintf(stderr, "hemibake-server: cannot accept connections: %s\n", ec.message().c_str());
        failing = true;
        retry.expires_after(std::chrono::milliseconds(100));
        retry.async_wait([this](beast::error_code) { accept(); });
        return;
      }
      failing = false;
      std::make_shared<Session>(std::move(socket), service, options, streams)->run();
      accept();
    });
  }
  Service& service;
  net::io_context& io;
  HttpOptions options;
  tcp::acceptor acceptor;
  net::steady_timer retry;
  bool failing = false;  // log a run of accept failures once
  std::atomic<size_t> streams{0};
};

HttpServer::HttpServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
HttpServer::~HttpServer() { stop(); }

std::unique_ptr<HttpServer> HttpServer::start(Service& service, net::io_context& io, const HttpOptions& options,
                                              std::string& error) {
  auto impl = std::make_unique<Impl>(service, io, options);
  beast::error_code ec;
  const auto address = net::ip::make_address(options.host, ec);
  if (ec) {
    error = "bad listen address '" + options.host + "': " + ec.message();
    return nullptr;
  }
  const tcp::endpoint endpoint(address, options.port);
  impl->acceptor.open(endpoint.protocol(), ec);
  if (!ec) impl->acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) impl->acceptor.bind(endpoint, ec);
  if (!ec) impl->acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) {
    error = "cannot listen on " + options.host + ":" + std::to_string(options.port) + ": " + ec.message();
    return nullptr;
  }
  impl->accept();
  return std::unique_ptr<HttpServer>(new HttpServer(std::move(impl)));
}

unsigned short HttpServer::port() const { return impl_->acceptor.local_endpoint().port(); }

void HttpServer::stop() {
  if (!impl_) return;
  net::dispatch(impl_->acceptor.get_executor(), [impl = impl_.get()] {
    beast::error_code ec;
    impl->acceptor.close(ec);
    impl->retry.cancel();
  });
}

}  // namespace hemibake::server
