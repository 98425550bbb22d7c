// The job store: jobs, their scenes, parameters, progress events and results, kept so that they
// survive a restart. `Store` is the interface the service uses; Store::open gives the embedded
// implementation (SQLite in WAL mode in a data directory).
//
// Reads that answer status, list and event requests touch only small columns: a job's scene and
// result are read only by claim() and result(), when a worker or a client asks for them.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

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

/// What create() did.
struct Created {
  std::string id;          ///< the new job, or the one that holds the idempotency key; empty on error
  bool existed = false;    ///< the idempotency key was taken: `id` is that job
  std::string cache_key;   ///< when `existed`: that job's cache key (scene and parameters)
  std::string error;       ///< the store could not write the job (disk full, ...)
  bool full = false;       ///< ... because the disk or the store's size limit is full
  bool busy = false;       ///< ... because another connection held the store's lock too long, or the
                           ///< store could not be reached: the same write may be made when tried again
};

/// Why a read gave nothing: set when the store could not answer it, as opposed to having nothing
/// to give (no such job, no events yet). The reads take one where a caller must tell the two apart.
struct ReadError {
  std::string error;  ///< empty: the read was answered; else the cause, for a message
  bool busy = false;  ///< another connection held the store's lock too long, or the store could not
                      ///< be reached: the same read may be answered when tried again
};

/// What a state change did. Each change is one atomic step in the store that applies only from the
/// states it names, so of two that race (a cancel and the result's write) exactly one is made.
struct Change {
  bool made = false;                  ///< the job was in a state this change applies to, and now is changed
  JobState from = JobState::kQueued;  ///< when made: the state it was in before
  std::string error;                  ///< the store could not write the change (made is false)
  bool busy = false;                  ///< ... because another connection held the store's lock too
                                      ///< long, or the store could not be reached: the same change
                                      ///< may be made when tried again
};

/// What a shared store tells the service about changes made by other nodes. Called from the store's
/// own thread; none may block.
struct StoreListener {
  std::function<void()> job_queued;                      ///< a job may be waiting to be claimed
  std::function<void(const std::string& id)> event;      ///< job `id` has a new event; empty id: any job may have
  std::function<void(const std::string& id)> lost;       ///< this node no longer owns running job `id`
                                                         ///< (cancelled elsewhere, or its lease expired): stop it
  std::function<void(const std::string& id)> preview_asked;  ///< another node wants a preview of job `id`
  std::function<void(const std::string& id)> preview_ready;  ///< a preview of job `id` was stored (put_preview)
};

/// Options of the PostgreSQL store.
struct PgOptions {
  double lease_seconds = 30;     ///< a claimed job's lease; renewed every third of it
  int max_attempts = 3;          ///< a job whose lease expired this many times fails
  double expiry_interval = 300;  ///< expire() runs at most once in this many seconds across all nodes
  int connections = 4;           ///< connections for requests and workers (one more listens)
};

/// Thread-safe.
class Store {
 public:
  /// The embedded store: opens (creating) `dir`/hemibake.db and holds an exclusive lock on
  /// `dir`/hemibake.lock while it lives. A database of an older layout is converted. Returns null and
  /// sets `error` on failure, also when another process holds the lock. A write waits up to
  /// `busy_ms` for another connection's lock (a backup, an operator's sqlite3 shell), then fails
  /// with `busy` set.
  static std::unique_ptr<Store> open(const std::string& dir, std::string& error, int busy_ms = 10000);
  /// The shared store: PostgreSQL at `uri` (a libpq URI, postgresql://USER@HOST:PORT/DB), for any
  /// number of nodes. Creates or migrates the schema. Returns null and sets `error` if the URI is bad,
  /// the server cannot be reached or the schema is newer than this build.
  static std::unique_ptr<Store> open_postgres(const std::string& uri, const PgOptions& options, std::string& error);
  virtual ~Store() = default;

  /// Where the service hears of other nodes' changes; a store of one node never calls it.
  virtual void set_listener(StoreListener) {}
  /// False while the store cannot be reached (the service then answers 503 on /readyz).
  virtual bool healthy() { return true; }
  /// The worker of job `id` is done with it (whatever the outcome): the store stops renewing its lease.
  virtual void release(const std::string&) {}
  /// Whether running job `id` runs on this node. A store of one node: always.
  virtual bool runs_here(const std::string&) { return true; }
  /// Previews of a job running on another node: ask its node for one (false if this store cannot),
  /// which stores it (put_preview) after its next shot; then every node hears preview_ready and reads
  /// it (take_preview).
  virtual bool ask_preview(const std::string&) { return false; }
  virtual void put_preview(const std::string&, const std::string&) {}
  virtual std::optional<std::string> take_preview(const std::string&) { return std::nullopt; }

  /// A new queued job. `idempotency_key` may be empty; if another job holds it, that job is named
  /// instead (`existed`) and nothing is written.
  virtual Created create(const std::string& scene, const std::string& content_type, const std::string& params,
                         const std::string& cache_key, const std::string& idempotency_key) = 0;
  /// The job that holds this idempotency key, if any, and its cache key.
  virtual std::optional<std::pair<std::string, std::string>> find_idempotent(const std::string& idempotency_key) = 0;
  /// The newest succeeded job with this cache key, if any.
  virtual std::optional<std::string> find_cached(const std::string& cache_key) = 0;
  /// Reads that give nothing (nullopt, an empty list) when the store cannot answer them say why in
  /// `why` if it is given, and leave it as it is when they are answered.
  virtual std::optional<JobRecord> get(const std::string& id, ReadError* why = nullptr) = 0;
  /// Jobs, newest first; `state` filters when set. `after` is a paging cursor (a job id) or empty.
  virtual std::vector<JobRecord> list(std::optional<JobState> state, size_t limit, const std::string& after,
                                      ReadError* why = nullptr) = 0;
  /// Takes the oldest queued job and marks it running; returns its id, scene and params.
  virtual bool claim(std::string& id, std::string& scene, std::string& params) = 0;
  /// False if it could not be written.
  virtual bool set_progress(const std::string& id, const std::string& progress_json) = 0;
  /// The new event's sequence number; 0 if the job is unknown or the event could not be written.
  virtual uint64_t add_event(const std::string& id, const std::string& type, const std::string& data) = 0;
  virtual std::vector<Event> events_after(const std::string& id, uint64_t after, size_t limit, ReadError* why = nullptr) = 0;
  /// running -> succeeded, storing the result.
  virtual Change succeed(const std::string& id, const std::string& result, const std::string& etag) = 0;
  /// running -> failed.
  virtual Change fail(const std::string& id, const std::string& error) = 0;
  /// queued or running -> cancelled.
  virtual Change cancel(const std::string& id) = 0;
  /// running -> queued (a worker stopped before finishing it).
  virtual Change requeue(const std::string& id) = 0;
  /// The result of a succeeded job.
  virtual std::optional<std::string> result(const std::string& id, ReadError* why = nullptr) = 0;
  /// Up to `size` bytes of a succeeded job's result from byte `offset` (fewer only at its end): for
  /// answers sent in parts, so that no request holds a whole result. nullopt if the job has no
  /// result (any more) or it cannot be read (then `why` says so). This default reads the whole
  /// result each time; both stores read only the part asked for.
  virtual std::optional<std::string> result_part(const std::string& id, uint64_t offset, size_t size,
                                                 ReadError* why = nullptr) {
    auto whole = result(id, why);
    if (!whole || offset > whole->size()) return std::nullopt;
    return whole->substr(static_cast<size_t>(offset), size);
  }
  /// At start: jobs left running by a crash are queued again, or failed after `max_attempts`.
  /// Returns how many were re-queued.
  virtual int recover(int max_attempts) = 0;
  /// Deletes finished jobs older than `age_seconds`; returns how many.
  virtual int expire(double age_seconds) = 0;
  /// Jobs in `state`; 0 and `why` set if the store cannot answer.
  virtual size_t count(JobState state, ReadError* why = nullptr) = 0;
};

double unix_now();

}  // namespace hemibake::server
