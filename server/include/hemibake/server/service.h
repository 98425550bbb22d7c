// The baking service: requests in, jobs queued in the store, a worker pool that bakes them.
// handle() is a function of the request and the store's state; it does no socket I/O, so it is
// tested without a network.
#pragma once

#include "hemibake/server/store.h"

#include <atomic>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace hemibake::solver {
class CancelToken;
}

namespace hemibake::server {

struct ServiceOptions {
  std::string data_dir = "data";
  unsigned workers = 0;             ///< bake threads; 0 = number of cores
  unsigned solver_threads = 1;      ///< threads inside each bake
  uint64_t max_body_bytes = 256ull << 20;
  size_t max_queue = 100;           ///< queued jobs before 429
  int max_attempts = 3;             ///< restarts of a job interrupted by a crash
  double job_seconds = 3600;        ///< per-job time budget
  uint64_t max_elements = 2'000'000;  ///< per-job element budget (caps the parameter)
  uint32_t max_shot_cache_mb = 256;   ///< per-job memory for replayed shots (caps the parameter)
  uint64_t max_triangles = 2'000'000;
  double expire_seconds = 7 * 24 * 3600.0;  ///< finished jobs and results are deleted after this
  std::vector<std::string> tokens;  ///< bearer tokens; empty: no authentication
};

struct Request {
  std::string method;
  std::string target;                          ///< path and query
  std::map<std::string, std::string> headers;  ///< names in lower case
  std::string body;
};

struct Response {
  int status = 200;
  std::vector<std::pair<std::string, std::string>> headers;
  std::string body;
  std::string content_type = "application/json";
};

class Service {
 public:
  /// Opens the store in options.data_dir, re-queues jobs a crash left running, starts the workers.
  static std::unique_ptr<Service> start(const ServiceOptions& options, std::string& error);
  ~Service();

  /// Answers one request (everything but event streams).
  Response handle(const Request& request);

  /// For event streams: the job id if `request` is GET /v1/jobs/{id}/events, else empty.
  static std::string events_job(const Request& request);
  /// An error response if the request may not proceed (authentication), else nullopt.
  std::optional<Response> check_auth(const Request& request) const;

  Store& store() { return *store_; }
  /// Stops the workers; jobs they were running go back to the queue.
  void stop();
  bool ready() const { return running_.load(); }
  void count_response(int status);

 private:
  explicit Service(const ServiceOptions& o) : options_(o) {}
  void worker_loop();
  void bake(const std::string& id, const std::string& scene, const std::string& params);
  Response submit(const Request& request, const std::string& query);
  Response job_json(const JobRecord& r, int status);
  Response metrics();
  Response preview(const std::string& id);

  ServiceOptions options_;
  std::unique_ptr<Store> store_;
  std::vector<std::thread> workers_;
  std::atomic<bool> running_{false};
  std::mutex mutex_;
  std::condition_variable wake_;
  // A running job: its cancellation token, and previews asked for and made between its shots.
  struct Active {
    solver::CancelToken* token = nullptr;
    bool previews = true;  // false while no displayable solution exists (hr, reference tracing)
    bool preview_wanted = false;
    uint64_t preview_serial = 0;
    std::string preview;  // GLB
  };
  std::map<std::string, Active> active_;
  std::condition_variable preview_ready_;
  std::atomic<double> last_expiry_{0.0};
  // Metrics.
  std::mutex metrics_mutex_;
  std::map<int, uint64_t> responses_;
  std::vector<double> bake_seconds_buckets_{1, 5, 15, 60, 300, 1800, 7200};
  std::vector<uint64_t> bake_seconds_counts_ = std::vector<uint64_t>(8, 0);
  double bake_seconds_sum_ = 0.0;
  uint64_t bakes_ = 0, shots_ = 0;
  double shot_seconds_ = 0.0;
};

/// Splits "a=1&b=x%20y" into decoded pairs.
std::map<std::string, std::string> parse_query(const std::string& query);

}  // namespace hemibake::server
