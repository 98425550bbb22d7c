// The HTTP front of the service (Boost.Beast): sessions on strands, a body limit and a timeout on
// every read, Server-Sent Events for job progress.
#pragma once

#include "hemibake/server/service.h"

#include <boost/asio/io_context.hpp>

#include <atomic>
#include <memory>
#include <string>

namespace hemibake::server {

struct HttpOptions {
  std::string host = "127.0.0.1";
  unsigned short port = 8080;     ///< 0 picks a free port
  size_t max_streams = 64;        ///< concurrent event streams
  double idle_timeout = 60.0;     ///< seconds a connection may wait for its next request, or a body pause
  double header_timeout = 10.0;   ///< seconds for a request line and headers from their first byte (then 408);
                                  ///< also a body's grace before min_rate counts
  double min_rate = 16384.0;      ///< bytes per second a request body must average (below: 408); 0 = any
  double heartbeat = 15.0;        ///< seconds between event-stream heartbeats
  uint64_t max_body_bytes = 256ull << 20;  ///< larger request bodies get 413
};

class HttpServer {
 public:
  /// Binds and starts accepting on `io`. Returns null and sets `error` on failure.
  static std::unique_ptr<HttpServer> start(Service& service, boost::asio::io_context& io, const HttpOptions& options,
                                           std::string& error);
  ~HttpServer();
  unsigned short port() const;
  /// Stops accepting new connections; requests in flight finish.
  void stop();

 private:
  struct Impl;
  explicit HttpServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace hemibake::server
