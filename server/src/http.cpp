#include "hemibake/server/http.h"

#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>

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
  void read() {
    head_ = false;
    parser_.emplace();
    parser_->body_limit(options_.max_body_bytes);
    stream_.expires_after(seconds(options_.read_timeout));  // for the header and the body together
    http::async_read_header(stream_, buffer_, *parser_, [self = shared_from_this()](beast::error_code ec, size_t) { self->on_header(ec); });
  }

  void on_header(beast::error_code header_ec) {
    if (header_ec || parser_->is_done()) return on_read(header_ec);
    // A large body is read 64 KB at a time, not in the few hundred bytes the buffer had room for
    // after the header: for a 200 MB scene, 3 200 reads (and wake-ups of an I/O thread) instead of
    // 400 000. Small bodies leave an idle connection's buffer small.
    const auto length = parser_->content_length();
    if (!length || *length > kReadChunk / 4) buffer_.reserve(kReadChunk);
    http::async_read(stream_, buffer_, *parser_, [self = shared_from_this()](beast::error_code ec, size_t) { self->on_read(ec); });
  }

  void on_read(beast::error_code ec) {
    if (ec == http::error::end_of_stream || ec == beast::error::timeout) return close();
    if (ec == http::error::body_limit) {
      Response r;
      r.status = 413;
      r.body = "{\"error\":\"the request body is larger than the server's limit of " + std::to_string(options_.max_body_bytes) +
               " bytes (hemibake-server --max-body)\"}";
      keep_alive_ = false;
      return send(r);
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
      keep_alive_ = false;
      return send(r);
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
    auto res = std::make_shared<http::response<http::string_body>>(static_cast<http::status>(r.status), 11);
    res->set(http::field::server, "hemibake");
    if (!r.content_type.empty()) res->set(http::field::content_type, r.content_type);
    for (const auto& [k, v] : r.headers) res->insert(k, v);
    res->body() = r.body;
    res->keep_alive(keep_alive_);
    res->prepare_payload();
    if (head_) res->body().clear();  // Content-Length stays the GET's
    stream_.expires_after(seconds(options_.read_timeout));
    http::async_write(stream_, *res, [self = shared_from_this(), res](beast::error_code ec, size_t) {
      if (ec || !self->keep_alive_) return self->close();
      self->read();
    });
  }

  // Server-Sent Events: every event since Last-Event-ID, then new ones as they come, a heartbeat
  // comment when idle, and the end of the stream after the job's final event.
  // The store is read on the service's lookup pool, never on an I/O thread, and only when the job
  // has a new event (the service wakes the stream): each read's answer comes back to this
  // session's strand.
  void start_events(const Request& req, const std::string& id) {
    if (auto denied = service_.check_auth(req)) return send(*denied);
    job_ = id;
    if (auto it = req.headers.find("last-event-id"); it != req.headers.end()) last_ = std::strtoull(it->second.c_str(), nullptr, 10);
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
    if (batch.status != 200) return send(Response{503, {{"Retry-After", "5"}}, R"({"error":"the server is busy; retry later"})"});
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
    stream_.expires_after(seconds(options_.read_timeout));
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
