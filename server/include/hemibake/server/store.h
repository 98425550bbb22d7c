// The embedded job store: SQLite in WAL mode in a data directory. Jobs, their scenes, parameters,
// progress events and results survive a restart.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

struct sqlite3;

namespace hemibake::server {

enum class JobState { kQueued, kRunning, kSucceeded, kFailed, kCancelled };
const char* to_string(JobState s);
std::optional<JobState> job_state_from(const std::string& s);
inline bool finished(JobState s) { return s != JobState::kQueued && s != JobState::kRunning; }

/// A job's record without its large blobs.
struct JobRecord {
  std::string id;
  JobState state = JobState::kQueued;
  std::string params;       ///< JSON (protocol::params_json)
  std::string content_type; ///< of the scene
  uint64_t scene_bytes = 0;
  std::string progress;     ///< JSON, or empty
  std::string error;
  std::string etag;         ///< of the result
  uint64_t result_bytes = 0;
  int attempts = 0;
  double created = 0.0, started = 0.0, finished = 0.0;  ///< unix seconds, 0 = not yet
  uint64_t last_event = 0;  ///< id of the newest event
};

struct Event {
  uint64_t seq = 0;
  std::string type;  ///< "progress", "state"
  std::string data;  ///< JSON
};

/// Thread-safe: one connection, calls serialised by a mutex.
class Store {
 public:
  /// Opens (creating) `dir`/hemibake.db and holds an exclusive lock on `dir`/hemibake.lock while it
  /// lives. Returns null and sets `error` on failure, also when another process holds the lock.
  static std::unique_ptr<Store> open(const std::string& dir, std::string& error);
  ~Store();

  /// A new queued job. `idempotency_key` may be empty. Returns the new id, or the id of the job
  /// that already has this idempotency key (then `existed` is set).
  std::string create(const std::string& scene, const std::string& content_type, const std::string& params,
                     const std::string& cache_key, const std::string& idempotency_key, bool& existed);
  /// The job that holds this idempotency key, if any.
  std::optional<std::string> find_idempotent(const std::string& idempotency_key);
  /// The newest succeeded job with this cache key, if any.
  std::optional<std::string> find_cached(const std::string& cache_key);
  std::optional<JobRecord> get(const std::string& id);
  /// Jobs, newest first; `state` filters when set. `after` is a paging cursor (a job id) or empty.
  std::vector<JobRecord> list(std::optional<JobState> state, size_t limit, const std::string& after);
  /// Takes the oldest queued job and marks it running; returns its id, scene and params.
  bool claim(std::string& id, std::string& scene, std::string& params);
  void set_progress(const std::string& id, const std::string& progress_json);
  uint64_t add_event(const std::string& id, const std::string& type, const std::string& data);
  std::vector<Event> events_after(const std::string& id, uint64_t after, size_t limit);
  void succeed(const std::string& id, const std::string& result, const std::string& etag);
  void fail(const std::string& id, const std::string& error);
  /// Marks a queued or running job cancelled; false if it had finished already or is unknown.
  bool cancel(const std::string& id);
  /// Puts it back in the queue (a worker stopped before finishing it).
  void requeue(const std::string& id);
  std::optional<std::string> result(const std::string& id);
  /// At start: jobs left running by a crash are queued again, or failed after `max_attempts`.
  /// Returns how many were re-queued.
  int recover(int max_attempts);
  /// Deletes finished jobs older than `age_seconds`; returns how many.
  int expire(double age_seconds);
  size_t count(JobState state);

 private:
  Store(sqlite3* db, int lock_fd) : db_(db), lock_fd_(lock_fd) {}
  /// find_idempotent's query, for callers that hold mutex_.
  std::optional<std::string> idempotent_locked(const std::string& idempotency_key);
  sqlite3* db_;
  int lock_fd_;  ///< flock'ed: one server per data directory
  std::mutex mutex_;
};

double unix_now();

}  // namespace hemibake::server
