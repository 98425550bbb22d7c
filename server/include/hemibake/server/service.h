// The baking service: requests in, jobs queued in the store, a worker pool that bakes them.
// handle_async() is a function of the request and the store's state; it does no socket I/O, so it
// is tested without a network (through handle(), which waits for it).
#pragma once

#include "hemibake/protocol/gltf.h"
#include "hemibake/server/store.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <map>
#include <set>
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

class Pool;

struct ServiceOptions {
  std::string data_dir = "data";
  std::string store_uri;            ///< postgresql://...: the shared store; empty: SQLite in data_dir
  double lease_seconds = 30;        ///< shared store: a running job's lease, renewed every third of it
  unsigned workers = 0;             ///< bake threads; 0 = number of cores
  unsigned solver_threads = 1;      ///< threads inside each bake
  uint64_t max_body_bytes = 256ull << 20;
  size_t max_queue = 100;           ///< queued jobs before 429
  int max_attempts = 3;             ///< restarts of a job interrupted by a crash
  double job_seconds = 3600;        ///< per-job time budget
  uint64_t max_elements = 2'000'000;  ///< per-job element budget (caps the parameter)
  uint32_t max_shot_cache_mb = 256;   ///< per-job memory for replayed shots (caps the parameter)
  uint64_t max_triangles = 2'000'000;
  uint64_t max_job_bytes = 2048ull << 20;  ///< memory a job's bake may need (hemicubes, elements, images,
                                           ///< shot cache, scene); more is refused at submit (422)
  uint64_t max_image_pixels = 8192ull * 8192;  ///< decoded texture pixels per job, all images together
  unsigned check_threads = 0;       ///< threads that load and check submitted scenes; 0 = half the cores (at least 1)
  size_t max_checks = 4;            ///< submitted scenes waiting for a check thread before 503 (each
                                    ///< holds its body, up to max_body_bytes, in memory)
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
  /// A body too large to hold whole (a result), sent in parts instead of `body`: `parts(offset,
  /// size)` gives up to `size` bytes from `offset` (fewer only at the end), or nullopt if they
  /// can no longer be read (the connection is then closed short of `parts_size`).
  std::function<std::optional<std::string>(uint64_t offset, size_t size)> parts{};
  uint64_t parts_size = 0;
};

/// Takes a request's response. Called exactly once, from any thread (the caller's, a pool's, a
/// worker's); it must not block: hand the response to the connection's own executor.
using Reply = std::function<void(Response)>;

/// The next part of an event stream.
struct EventBatch {
  int status = 200;           ///< 404: no such job; 503: the server is busy or stopping, or the store
                              ///< could not be read (ask again)
  std::vector<Event> events;  ///< after the sequence number asked for, oldest first, at most 100
  bool end = false;           ///< the job has finished and no event follows these
  std::string error;          ///< with 503, when the store could not be read: the cause
};

class Service {
 public:
  /// Opens the store in options.data_dir, re-queues jobs a crash left running, starts the workers.
  static std::unique_ptr<Service> start(const ServiceOptions& options, std::string& error);
  /// The same on a store already open (options.data_dir is not used): another implementation, or
  /// one that fails on purpose in tests.
  static std::unique_ptr<Service> start(const ServiceOptions& options, std::unique_ptr<Store> store, std::string& error);
  ~Service();

  /// Answers one request (everything but event streams) through `reply`, without ever blocking
  /// the caller: what cannot wait (health, readiness, the API description, refusals) at once; a
  /// submitted scene from a bounded pool of check threads (503 and Retry-After when it is full);
  /// a preview when the job's worker makes one between two shots (no thread waits for it); the
  /// rest, which reads the store, from a small lookup pool.
  void handle_async(Request request, Reply reply);
  /// handle_async, waited for: for tests and tools without an event loop. A body sent in parts
  /// is read whole into `body`.
  Response handle(const Request& request);
  /// For event streams: the events of job `id` after sequence number `after`, read on the lookup
  /// pool and given to `reply` (which, like a Reply, must not block). If there are none yet and the
  /// job has not finished, the request waits (as an entry, not a thread) until the job's next event
  /// or until `wait` has passed, then an empty batch says that it is time for a heartbeat.
  void events_async(const std::string& id, uint64_t after, std::chrono::milliseconds wait,
                    std::function<void(EventBatch)> reply);

  /// For event streams: the job id if `request` is GET /v1/jobs/{id}/events, else empty.
  static std::string events_job(const Request& request);
  /// An error response if the request may not proceed (authentication), else nullopt.
  std::optional<Response> check_auth(const Request& request) const;

  Store& store() { return *store_; }
  /// Jobs whose end (result or failure) the store could not write yet; they show "running" until
  /// the end writer, which tries again in the background, writes it (or a restart queues them again).
  size_t unwritten();
  /// Stops the workers; jobs they were running go back to the queue. Previews asked for and
  /// requests not yet begun are answered 503; requests being answered finish first.
  void stop();
  bool ready() const { return running_.load() && store_->healthy(); }
  void count_response(int status);

 private:
  explicit Service(const ServiceOptions& o);
  void worker_loop();
  void clock_loop();
  void bake(const std::string& id, const std::string& scene, const std::string& params);
  /// How submitted scenes are loaded and checked (the same at submit and in the worker).
  protocol::LoadLimits load_limits() const;
  /// Ends running job `id`: succeeded with `result`, or failed with `failure` if there is none.
  bool end_job(const std::string& id, const std::string* result, std::string failure);
  /// A job's end that the store could not write yet: its result (kept while the store is busy or
  /// cannot be reached), or the failure.
  struct Unwritten {
    std::optional<std::string> result;
    std::string failure;
  };
  Change write_end(const std::string& id, Unwritten& end);
  /// Tells job `id`'s stream "cancelled" if the store says so; returns whether it did.
  bool note_cancelled(const std::string& id);
  /// Whether job `id`'s end was left to the end writer, which then holds its claim.
  bool end_unwritten(const std::string& id);
  /// Tries the ends not written yet again (the end writer).
  void write_unwritten();
  /// The end writer's thread: write_unwritten() with backoff while any end is unwritten.
  void end_writer_loop();
  /// Stores an event of job `id` and wakes the streams that wait for one.
  void emit(const std::string& id, const std::string& type, const std::string& data);
  bool final_event_written(const JobRecord& r);
  /// Wakes the streams that wait for an event of job `id` (of any job if `id` is empty).
  void wake_streams(const std::string& id);
  /// events_async's work on a lookup thread: reads, and waits if there is nothing to read.
  void read_events(const std::string& id, uint64_t after, std::chrono::steady_clock::time_point until,
                   std::function<void(EventBatch)> reply);
  std::optional<Response> answer_at_once(const Request& request, const std::string& path) const;
  Response route(const Request& request, const std::string& path, const std::string& query);
  Response submit(const Request& request, const std::string& query);
  Response job_json(const JobRecord& r, int status);
  Response metrics();
  void preview(const std::string& id, const Reply& reply);
  // The running job's side of previews (called by its worker).
  bool register_job(const std::string& id, solver::CancelToken* token);
  void unregister_job(const std::string& id);
  void set_previews(const std::string& id, bool on);
  bool take_preview_request(const std::string& id);
  void give_preview(const std::string& id, const std::vector<uint8_t>& glb, const std::string& error);

  ServiceOptions options_;
  std::unique_ptr<Store> store_;
  std::vector<std::thread> workers_;
  std::atomic<bool> running_{false};
  std::mutex mutex_;
  std::condition_variable wake_;
  // A preview asked for: answered by the job's worker after its next shot, or by the clock at
  // `until`. Entries, not sleeping threads: any number of clients wait at no cost.
  struct PreviewWait {
    std::chrono::steady_clock::time_point until;
    Reply reply;
  };
  // A running job: its cancellation token, and previews asked for and made between its shots.
  struct Active {
    solver::CancelToken* token = nullptr;
    bool previews = true;  // false while no displayable solution exists (hr, reference tracing)
    bool preview_wanted = false;
    std::chrono::steady_clock::time_point preview_taken;  // when the worker began writing one
    bool remote_wanted = false;  // another node asked (a shared store): the preview goes to the store
    std::vector<PreviewWait> waits;
  };
  // Previews of jobs that run on another node (a shared store): answered when that node has stored
  // one (the store's preview_ready), or by the clock.
  std::map<std::string, std::vector<PreviewWait>> remote_previews_;
  std::map<std::string, Active> active_;
  // Event streams with nothing to send, waiting for their job's next event, or for `until` (then
  // the clock answers them with an empty batch, for a heartbeat).
  struct EventWait {
    std::chrono::steady_clock::time_point until;
    uint64_t after = 0;
    std::function<void(EventBatch)> reply;
  };
  std::map<std::string, std::vector<EventWait>> event_waits_;
  uint64_t events_written_ = 0;  // events stored so far (under mutex_): a wait set up after a read
                                 // checks that none came between the two
  // Previews of jobs claimed by a worker that has not registered them yet.
  std::map<std::string, std::vector<PreviewWait>> unregistered_;
  // Another node's asks for a preview of a job of this node that has not registered yet: taken up
  // by register_job, or dropped by the clock after kRegisterWait.
  std::map<std::string, std::chrono::steady_clock::time_point> remote_asks_;
  std::condition_variable clock_wake_;  // a new deadline, or the stop
  std::thread clock_;                   // answers previews whose time is up
  std::unique_ptr<Pool> checks_;        // loads and checks submitted scenes
  std::mutex unwritten_mutex_;
  std::map<std::string, Unwritten> unwritten_;
  std::set<std::string> claims_kept_;  // jobs whose ends wait in unwritten_: their claims are kept
  std::condition_variable ends_wake_;  // an end left unwritten, or the stop (with unwritten_mutex_)
  std::thread end_writer_;
  std::unique_ptr<Pool> lookups_;       // requests that read or write the store
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

/// The parts of a multipart/form-data body by field name: (content type in lower case, data).
/// `repeated` is set to the name of a field given twice (the last one is kept).
std::map<std::string, std::pair<std::string, std::string>> parse_multipart(const std::string& body, const std::string& boundary,
                                                                           std::string& repeated);

}  // namespace hemibake::server
