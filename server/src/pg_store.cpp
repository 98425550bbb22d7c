// The shared job store on PostgreSQL (libpq), for several nodes on one database.
//
// - Claims take the oldest queued job with SELECT ... FOR UPDATE SKIP LOCKED, so two nodes never
//   take the same job and neither waits for the other's lock.
// - A claimed job holds a lease (lease_until, in the database's clock so node clocks do not matter)
//   that this node renews every third of --lease-seconds. Any node requeues jobs whose lease
//   expired (or fails them after max_attempts); that UPDATE is atomic per row, so running it on
//   several nodes at once does no harm.
// - Fencing: every write a worker makes for its job (progress, events, the result, the end state,
//   a requeue) carries the owner and attempt number it claimed with, and checks that the lease has
//   not expired. A node that was paused past its lease and comes back finds the job re-queued or
//   claimed again (owner cleared or attempt moved on), so its writes change nothing.
// - A node that could not reach the database renews, at its first renewal once it can, also the
//   leases that ran out meanwhile, unless a node took the job back first (owner cleared or attempt
//   moved on): the job was nobody else's, and the result of a bake that finished while the
//   database was away is written rather than thrown away and baked again. A node that was paused
//   instead does not know it was, and does not revive its leases.
// - LISTEN/NOTIFY on one extra connection: new jobs wake idle workers, new events wake event
//   streams on every node, a cancel reaches the owning node at once. Notifications can be lost
//   when that connection drops; after reconnecting the listener wakes every stream and worker, and
//   the lease renewal finds any job it lost meanwhile.
#include "hemibake/server/store.h"

#include <libpq-fe.h>

#include <sys/select.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

namespace hemibake::server {
namespace {

std::string random_hex(int words) {
  static thread_local std::mt19937_64 rng(std::random_device{}() ^ (static_cast<uint64_t>(std::random_device{}()) << 32));
  static const char* hex = "0123456789abcdef";
  std::string id;
  for (int i = 0; i < words; ++i) {
    uint64_t v = rng();
    for (int k = 0; k < 16; ++k, v >>= 4) id += hex[v & 15];
  }
  return id;
}

constexpr int kSchemaVersion = 1;
// Key of the advisory lock that serialises schema set-up between nodes starting together.
constexpr const char* kSchemaLock = "4242001";

constexpr const char* kSchema1 =
    "CREATE TABLE jobs ("
    "  id TEXT PRIMARY KEY, state TEXT NOT NULL, params TEXT NOT NULL, cache_key TEXT NOT NULL,"
    "  idempotency_key TEXT UNIQUE, content_type TEXT NOT NULL, scene_bytes BIGINT NOT NULL,"
    "  etag TEXT, result_bytes BIGINT NOT NULL DEFAULT 0, error TEXT, progress TEXT,"
    "  attempts INTEGER NOT NULL DEFAULT 0, created DOUBLE PRECISION NOT NULL,"
    "  started DOUBLE PRECISION NOT NULL DEFAULT 0, finished DOUBLE PRECISION NOT NULL DEFAULT 0,"
    "  event_seq BIGINT NOT NULL DEFAULT 0, owner TEXT, lease_until TIMESTAMPTZ);"
    "CREATE INDEX jobs_state ON jobs(state, created, id);"
    "CREATE INDEX jobs_cache ON jobs(cache_key, state);"
    "CREATE INDEX jobs_created ON jobs(created, id);"
    "CREATE TABLE scenes (job TEXT PRIMARY KEY, data BYTEA NOT NULL);"
    "CREATE TABLE results (job TEXT PRIMARY KEY, data BYTEA NOT NULL);"
    "ALTER TABLE results ALTER COLUMN data SET STORAGE EXTERNAL;"
    "CREATE TABLE events (job TEXT NOT NULL, seq BIGINT NOT NULL, type TEXT NOT NULL, data TEXT NOT NULL,"
    "  PRIMARY KEY (job, seq));"
    "CREATE TABLE previews (job TEXT PRIMARY KEY, data BYTEA NOT NULL);"
    "CREATE TABLE hemibake_maintenance (one BOOLEAN PRIMARY KEY DEFAULT true CHECK (one),"
    "  last_expiry TIMESTAMPTZ NOT NULL DEFAULT '-infinity');"
    "INSERT INTO hemibake_maintenance DEFAULT VALUES;";

// Results (GLB, their meshes already Draco-compressed) are kept uncompressed out of line, so that a
// part of one is read without the rest (result_part). Stores set up before this have the column's
// default (compressed); set_up changes it there, which applies to results written from then on.
constexpr const char* kResultStorage =
    "SELECT attstorage FROM pg_attribute WHERE attrelid = 'results'::regclass AND attname = 'data'";

constexpr const char* kNow = "extract(epoch from clock_timestamp())";
constexpr const char* kColumns =
    "id, state, params, content_type, scene_bytes, coalesce(progress, ''), coalesce(error, ''), coalesce(etag, ''), "
    "result_bytes, attempts, created, started, finished, event_seq";

// One parameter of a statement; binary ones are sent as bytes (bytea), the others as text.
struct Param {
  std::string value;
  bool binary = false;
  bool null = false;
};
Param text(std::string v) { return Param{std::move(v), false, false}; }
Param bytes(const std::string& v) { return Param{v, true, false}; }
Param null() { return Param{{}, false, true}; }
Param num(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.17g", v);
  return text(b);
}
Param integer(int64_t v) { return text(std::to_string(v)); }

// A result that clears itself.
class Result {
 public:
  explicit Result(PGresult* r = nullptr) : r_(r) {}
  ~Result() { PQclear(r_); }
  Result(Result&& o) noexcept : r_(o.r_), unreachable_(std::move(o.unreachable_)) { o.r_ = nullptr; }
  Result& operator=(Result&& o) noexcept {
    std::swap(r_, o.r_);
    std::swap(unreachable_, o.unreachable_);
    return *this;
  }
  bool ok() const {
    const auto s = PQresultStatus(r_);
    return r_ && (s == PGRES_TUPLES_OK || s == PGRES_COMMAND_OK);
  }
  /// The statement failed because the database could not be reached (`why`: libpq's account): the
  /// same statement may succeed once it is back.
  void set_unreachable(const std::string& why) {
    // libpq's first line is the cause; the lines after it are hints ("Is the server running ...").
    unreachable_ = why.substr(0, why.find('\n'));
    if (unreachable_.empty()) unreachable_ = "no connection to the server";
  }
  bool unreachable() const { return !unreachable_.empty(); }
  /// Why it failed, for a message.
  std::string failure() const {
    if (unreachable()) return "the job store cannot be reached (" + unreachable_ + ")";
    return "the job store could not answer: " + error();
  }
  /// Says in `why` (if given) why the statement failed, if it did. True if it did not.
  bool answered(ReadError* why) const {
    if (ok()) return true;
    // A key that is not text in the database's encoding (bytes that are not UTF-8 in a request's
    // path) names nothing that could have been stored: nothing found, not a failure.
    if (r_ && PQresultErrorField(r_, PG_DIAG_SQLSTATE) && std::strcmp(PQresultErrorField(r_, PG_DIAG_SQLSTATE), "22021") == 0)
      return true;
    if (why) {
      why->error = failure();
      why->busy = unreachable();
    }
    return false;
  }
  int rows() const { return ok() ? PQntuples(r_) : 0; }
  std::string get(int row, int col) const {
    return PQgetisnull(r_, row, col) ? std::string() : std::string(PQgetvalue(r_, row, col), static_cast<size_t>(PQgetlength(r_, row, col)));
  }
  int64_t get_int(int row, int col) const { return std::strtoll(PQgetvalue(r_, row, col), nullptr, 10); }
  double get_real(int row, int col) const { return std::strtod(PQgetvalue(r_, row, col), nullptr); }
  std::string error() const { return r_ ? PQresultErrorMessage(r_) : "no result"; }
  /// The statement failed for want of a connection rather than by the database's answer: no result
  /// at all, an error libpq made itself (no SQLSTATE: the server closed the connection, a write to
  /// it failed), a connection exception (class 08), or the server shutting down or starting (57P01
  /// to 57P03). The same statement may succeed on a new connection.
  bool lost_connection() const {
    if (r_ == nullptr) return true;
    if (ok()) return false;
    const char* state = PQresultErrorField(r_, PG_DIAG_SQLSTATE);
    if (state == nullptr) return true;
    return std::strncmp(state, "08", 2) == 0 || std::strncmp(state, "57P0", 4) == 0;
  }
  int affected() const { return std::atoi(PQcmdTuples(r_)); }

 private:
  PGresult* r_;
  std::string unreachable_;
};

Result run(PGconn* c, const std::string& sql, const std::vector<Param>& params = {}, bool binary_result = false) {
  std::vector<const char*> values;
  std::vector<int> lengths, formats;
  for (const auto& p : params) {
    values.push_back(p.null ? nullptr : p.value.data());
    lengths.push_back(static_cast<int>(p.value.size()));
    formats.push_back(p.binary ? 1 : 0);
  }
  return Result(PQexecParams(c, sql.c_str(), static_cast<int>(params.size()), nullptr, values.data(), lengths.data(),
                             formats.data(), binary_result ? 1 : 0));
}

JobRecord read_record(const Result& r, int row) {
  JobRecord j;
  j.id = r.get(row, 0);
  j.state = job_state_from(r.get(row, 1)).value_or(JobState::kFailed);
  j.params = r.get(row, 2);
  j.content_type = r.get(row, 3);
  j.scene_bytes = static_cast<uint64_t>(r.get_int(row, 4));
  j.progress = r.get(row, 5);
  j.error = r.get(row, 6);
  j.etag = r.get(row, 7);
  j.result_bytes = static_cast<uint64_t>(r.get_int(row, 8));
  j.attempts = static_cast<int>(r.get_int(row, 9));
  j.created = r.get_real(row, 10);
  j.started = r.get_real(row, 11);
  j.finished = r.get_real(row, 12);
  j.last_event = static_cast<uint64_t>(r.get_int(row, 13));
  return j;
}

PGconn* connect(const std::string& uri, std::string& error) {
  // connect_timeout: a database that does not answer is reported in seconds, not minutes.
  const char* keys[] = {"dbname", "connect_timeout", "application_name", nullptr};
  const char* values[] = {uri.c_str(), "5", "hemibake-server", nullptr};
  PGconn* c = PQconnectdbParams(keys, values, 1);
  if (!c || PQstatus(c) != CONNECTION_OK) {
    error = c ? PQerrorMessage(c) : "out of memory";
    while (!error.empty() && (error.back() == '\n' || error.back() == ' ')) error.pop_back();
    PQfinish(c);
    return nullptr;
  }
  // Notices (CREATE ... IF NOT EXISTS and the like) are not for the server's log.
  PQsetNoticeProcessor(c, [](void*, const char*) {}, nullptr);
  return c;
}

class PgStore final : public Store {
 public:
  PgStore(std::string uri, PgOptions o, std::vector<PGconn*> conns)
      : uri_(std::move(uri)), options_(o), node_(random_hex(1)) {
    for (PGconn* c : conns) free_.push_back(c);
    all_ = conns;
    listener_thread_ = std::thread([this] { listen_loop(); });
    lease_thread_ = std::thread([this] { lease_loop(); });
  }
  ~PgStore() override {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    stop_wake_.notify_all();
    listener_thread_.join();
    lease_thread_.join();
    for (PGconn* c : all_) PQfinish(c);
  }

  void set_listener(StoreListener l) override {
    std::lock_guard lock(listener_mutex_);
    listener_ = std::move(l);
  }
  bool healthy() override { return healthy_.load(); }
  void release(const std::string& id) override {
    std::lock_guard lock(mutex_);
    owned_.erase(id);
  }

  // A job reads as running from the moment its claim's update commits, before the claim names it in
  // owned_: a job not named there waits for a claim under way to name it.
  bool runs_here(const std::string& id) override {
    {
      std::lock_guard lock(mutex_);
      if (owned_.count(id) > 0) return true;
    }
    std::lock_guard claiming(claim_mutex_);
    std::lock_guard lock(mutex_);
    return owned_.count(id) > 0;
  }
  bool ask_preview(const std::string& id) override {
    return exec("SELECT pg_notify('hemibake_preview_ask', $1)", {text(id)}).ok();
  }
  void put_preview(const std::string& id, const std::string& glb) override {
    exec("WITH p AS (INSERT INTO previews (job, data) VALUES ($1, $2) ON CONFLICT (job) DO UPDATE SET data = EXCLUDED.data"
         " RETURNING job) SELECT pg_notify('hemibake_preview', job) FROM p",
         {text(id), bytes(glb)});
  }
  std::optional<std::string> take_preview(const std::string& id) override {
    Result r = exec("SELECT data FROM previews WHERE job = $1", {text(id)}, true);
    if (r.rows() == 0) return std::nullopt;
    return r.get(0, 0);
  }

  Created create(const std::string& scene, const std::string& content_type, const std::string& params,
                 const std::string& cache_key, const std::string& idempotency_key) override {
    Created c;
    const std::string id = random_hex(2);
    // The unique idempotency key decides between two nodes that insert the same key at once: one
    // row is made, the other insert does nothing (after waiting for the first to commit) and the
    // select that follows names the first one's job.
    Result r = exec(std::string("WITH j AS (INSERT INTO jobs (id, state, params, cache_key, idempotency_key, content_type,"
                                " scene_bytes, created) VALUES ($1, 'queued', $2, $3, $4, $5, $6, ") + kNow +
                        ") ON CONFLICT (idempotency_key) DO NOTHING RETURNING id),"
                        " s AS (INSERT INTO scenes (job, data) SELECT id, $7 FROM j)"
                        " SELECT id, pg_notify('hemibake_job', '') FROM j",
                    {text(id), text(params), text(cache_key), idempotency_key.empty() ? null() : text(idempotency_key),
                     text(content_type), integer(static_cast<int64_t>(scene.size())), bytes(scene)});
    if (!r.ok()) {
      c.error = r.unreachable() ? r.failure() : "the job store could not write: " + r.error();
      c.full = c.error.find("No space left") != std::string::npos || c.error.find("disk full") != std::string::npos;
      c.busy = r.unreachable();
      return c;
    }
    if (r.rows() == 1) {
      c.id = id;
      return c;
    }
    if (auto held = find_idempotent(idempotency_key)) {
      c.existed = true;
      c.id = held->first;
      c.cache_key = held->second;
      return c;
    }
    c.error = "the job store could not write: the idempotency key's job vanished; retry";
    return c;
  }

  std::optional<std::pair<std::string, std::string>> find_idempotent(const std::string& key) override {
    Result r = exec("SELECT id, cache_key FROM jobs WHERE idempotency_key = $1", {text(key)});
    if (r.rows() == 0) return std::nullopt;
    return std::make_pair(r.get(0, 0), r.get(0, 1));
  }

  std::optional<std::string> find_cached(const std::string& cache_key) override {
    Result r = exec("SELECT id FROM jobs WHERE cache_key = $1 AND state = 'succeeded' ORDER BY finished DESC LIMIT 1",
                    {text(cache_key)});
    if (r.rows() == 0) return std::nullopt;
    return r.get(0, 0);
  }

  std::optional<JobRecord> get(const std::string& id, ReadError* why) override {
    Result r = exec(std::string("SELECT ") + kColumns + " FROM jobs WHERE id = $1", {text(id)});
    if (!r.answered(why) || r.rows() == 0) return std::nullopt;
    return read_record(r, 0);
  }

  std::vector<JobRecord> list(std::optional<JobState> state, size_t limit, const std::string& after, ReadError* why) override {
    Result r = exec(std::string("SELECT ") + kColumns +
                        " FROM jobs WHERE ($1::text IS NULL OR state = $1)"
                        " AND ($2::text IS NULL OR (created, id) < (SELECT created, id FROM jobs WHERE id = $2))"
                        " ORDER BY created DESC, id DESC LIMIT $3",
                    {state ? text(to_string(*state)) : null(), after.empty() ? null() : text(after),
                     integer(static_cast<int64_t>(limit))});
    r.answered(why);
    std::vector<JobRecord> out;
    for (int i = 0; i < r.rows(); ++i) out.push_back(read_record(r, i));
    return out;
  }

  bool claim(std::string& id, std::string& scene, std::string& params) override {
    // Not a job this node still holds: one whose lease it lost and whose old run has not yet
    // stopped (its fence and its entry in owned_ belong to that run).
    std::string held = "{";
    {
      std::lock_guard lock(mutex_);
      for (const auto& [job, attempt] : owned_) held += (held.size() > 1 ? "," : "") + job;
    }
    held += "}";
    std::unique_lock claiming(claim_mutex_);
    Result r = exec(std::string("WITH c AS (SELECT id FROM jobs WHERE state = 'queued' AND NOT (id = ANY($3::text[]))"
                                " ORDER BY created, id LIMIT 1 FOR UPDATE SKIP LOCKED)"
                                " UPDATE jobs j SET state = 'running', owner = $1, attempts = j.attempts + 1, started = ") + kNow +
                        ", lease_until = clock_timestamp() + $2 * interval '1 second'"
                        " FROM c WHERE j.id = c.id RETURNING j.id, j.params, j.attempts",
                    {text(node_), num(options_.lease_seconds), text(held)});
    if (r.rows() == 0) return false;
    id = r.get(0, 0);
    params = r.get(0, 1);
    const int attempt = static_cast<int>(r.get_int(0, 2));
    {
      std::lock_guard lock(mutex_);
      owned_[id] = attempt;
    }
    claiming.unlock();
    Result s = exec("SELECT data FROM scenes WHERE job = $1", {text(id)}, true);
    scene = s.rows() == 1 ? s.get(0, 0) : std::string();
    if (!s.ok()) {
      // Claimed but the scene could not be read (the connection dropped): the lease runs out and
      // the job is claimed again.
      release(id);
      return false;
    }
    return true;
  }

  bool set_progress(const std::string& id, const std::string& progress_json) override {
    auto [fence, args] = fence_for(id, 3);
    Result r = exec("UPDATE jobs SET progress = $2 WHERE id = $1" + fence, join({text(id), text(progress_json)}, args));
    return r.ok() && r.affected() == 1;
  }

  uint64_t add_event(const std::string& id, const std::string& type, const std::string& data) override {
    auto [fence, args] = fence_for(id, 4);
    // The row lock of the job's UPDATE orders the sequence numbers of concurrent writers.
    Result r = exec("WITH u AS (UPDATE jobs SET event_seq = event_seq + 1 WHERE id = $1" + fence +
                        " RETURNING event_seq),"
                        " i AS (INSERT INTO events (job, seq, type, data) SELECT $1, event_seq, $2, $3 FROM u)"
                        " SELECT event_seq, pg_notify('hemibake_event', $1) FROM u",
                    join({text(id), text(type), text(data)}, args));
    return r.rows() == 1 ? static_cast<uint64_t>(r.get_int(0, 0)) : 0;
  }

  std::vector<Event> events_after(const std::string& id, uint64_t after, size_t limit, ReadError* why) override {
    Result r = exec("SELECT seq, type, data FROM events WHERE job = $1 AND seq > $2 ORDER BY seq LIMIT $3",
                    {text(id), integer(static_cast<int64_t>(after)), integer(static_cast<int64_t>(limit))});
    r.answered(why);
    std::vector<Event> out;
    for (int i = 0; i < r.rows(); ++i) out.push_back({static_cast<uint64_t>(r.get_int(i, 0)), r.get(i, 1), r.get(i, 2)});
    return out;
  }

  Change succeed(const std::string& id, const std::string& result, const std::string& etag) override {
    auto [fence, args] = fence_for(id, 5);
    return change(
                  std::string("UPDATE jobs SET state = 'succeeded', etag = $2, result_bytes = $3, finished = ") + kNow +
                      " WHERE id = $1 AND state = 'running'" + fence + " RETURNING id",
                  " , r AS (INSERT INTO results (job, data) SELECT id, $4 FROM u ON CONFLICT (job) DO UPDATE SET data = EXCLUDED.data)",
                  join({text(id), text(etag), integer(static_cast<int64_t>(result.size())), bytes(result)}, args));
  }

  Change fail(const std::string& id, const std::string& error) override {
    auto [fence, args] = fence_for(id, 3);
    return change(
                  std::string("UPDATE jobs SET state = 'failed', error = $2, finished = ") + kNow +
                      " WHERE id = $1 AND state = 'running'" + fence + " RETURNING id",
                  "", join({text(id), text(error)}, args));
  }

  Change cancel(const std::string& id) override {
    // Not fenced: any node may cancel. The notification reaches the owning node, which stops.
    return change(
                  std::string("UPDATE jobs SET state = 'cancelled', finished = ") + kNow +
                      " WHERE id = $1 AND state IN ('queued', 'running') RETURNING id, pg_notify('hemibake_cancel', id)",
                  "", {text(id)});
  }

  Change requeue(const std::string& id) override {
    auto [fence, args] = fence_for(id, 2);
    Change c = change(
                      "UPDATE jobs SET state = 'queued', owner = NULL, lease_until = NULL WHERE id = $1 AND state = 'running'" +
                          fence + " RETURNING id, pg_notify('hemibake_job', '')",
                      "", join({text(id)}, args));
    release(id);
    return c;
  }

  std::optional<std::string> result(const std::string& id, ReadError* why) override {
    Result r = exec("SELECT r.data FROM results r JOIN jobs j ON j.id = r.job WHERE r.job = $1 AND j.state = 'succeeded'",
                    {text(id)}, true);
    if (!r.answered(why) || r.rows() == 0) return std::nullopt;
    return r.get(0, 0);
  }

  // Only the part asked for: results are stored uncompressed out of line (kResultStorage), so
  // substring() reads only the TOAST chunks that hold the part, and a download of a large result in
  // parts reads it once, not once per part.
  std::optional<std::string> result_part(const std::string& id, uint64_t offset, size_t size, ReadError* why) override {
    if (offset >= static_cast<uint64_t>(std::numeric_limits<int32_t>::max()))
      return std::nullopt;  // beyond any bytea (at most 1 GB)
    const auto n = static_cast<int64_t>(std::min<uint64_t>(size, static_cast<uint64_t>(std::numeric_limits<int32_t>::max())));
    Result r = exec("SELECT substring(r.data FROM $2::integer FOR $3::integer), length(r.data) >= $2::integer - 1"
                    " FROM results r JOIN jobs j ON j.id = r.job WHERE r.job = $1 AND j.state = 'succeeded'",
                    {text(id), integer(static_cast<int64_t>(offset) + 1), integer(n)}, true);
    if (!r.answered(why) || r.rows() == 0) return std::nullopt;
    const std::string within = r.get(0, 1);  // binary boolean: one byte
    if (within.size() != 1 || within[0] == 0) return std::nullopt;  // the offset lies past the end
    return r.get(0, 0);
  }

  // Shared by all nodes: only jobs whose lease has expired are taken back (a node that starts must
  // not take the jobs other nodes are running).
  int recover(int max_attempts) override {
    Result r = exec(std::string("UPDATE jobs SET owner = NULL, lease_until = NULL,"
                                " state = CASE WHEN attempts >= $1 THEN 'failed' ELSE 'queued' END,"
                                " finished = CASE WHEN attempts >= $1 THEN ") + kNow + " ELSE finished END,"
                        " error = CASE WHEN attempts >= $1 THEN 'the node running it stopped or lost its lease during each of its '"
                        "   || attempts || ' attempts' ELSE error END"
                        " WHERE state = 'running' AND lease_until < clock_timestamp()"
                        " RETURNING state, pg_notify(CASE WHEN state = 'queued' THEN 'hemibake_job' ELSE 'hemibake_event' END,"
                        "   CASE WHEN state = 'queued' THEN '' ELSE id END)",
                    {integer(max_attempts)});
    int queued = 0;
    for (int i = 0; i < r.rows(); ++i) queued += r.get(i, 0) == "queued";
    return queued;
  }

  // Once per expiry_interval across all nodes: the conditional update of the one maintenance row
  // lets one node through; the others see last_expiry moved on and delete nothing.
  int expire(double age_seconds) override {
    Result r = exec(std::string("WITH go AS (UPDATE hemibake_maintenance SET last_expiry = clock_timestamp()"
                                "   WHERE last_expiry < clock_timestamp() - $2 * interval '1 second' RETURNING 1),"
                                " old AS (SELECT id FROM jobs WHERE EXISTS (SELECT 1 FROM go)"
                                "   AND state IN ('succeeded', 'failed', 'cancelled') AND finished < ") + kNow + " - $1),"
                        " e AS (DELETE FROM events WHERE job IN (SELECT id FROM old)),"
                        " s AS (DELETE FROM scenes WHERE job IN (SELECT id FROM old)),"
                        " r AS (DELETE FROM results WHERE job IN (SELECT id FROM old)),"
                        " p AS (DELETE FROM previews WHERE job IN (SELECT id FROM old)),"
                        " j AS (DELETE FROM jobs WHERE id IN (SELECT id FROM old) RETURNING 1)"
                        " SELECT count(*) FROM j",
                    {num(age_seconds), num(options_.expiry_interval)});
    return r.rows() == 1 ? static_cast<int>(r.get_int(0, 0)) : 0;
  }

  size_t count(JobState state, ReadError* why) override {
    Result r = exec("SELECT count(*) FROM jobs WHERE state = $1", {text(to_string(state))});
    if (!r.answered(why)) return 0;
    return r.rows() == 1 ? static_cast<size_t>(r.get_int(0, 0)) : 0;
  }

 private:
  // The fence of a write for job `id`: if this node claimed it, the write applies only while the
  // job is still this node's, at the same attempt, within its lease. Parameters from $first on.
  std::pair<std::string, std::vector<Param>> fence_for(const std::string& id, int first) {
    std::lock_guard lock(mutex_);
    const auto it = owned_.find(id);
    if (it == owned_.end()) return {};
    return {" AND owner = $" + std::to_string(first) + " AND attempts = $" + std::to_string(first + 1) +
                " AND lease_until > clock_timestamp()",
            {text(node_), integer(it->second)}};
  }
  static std::vector<Param> join(std::vector<Param> a, const std::vector<Param>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
  }

  // A state change: `update` (RETURNING a row when made) with `more` CTEs after it, and the state
  // before, in one statement.
  Change change(const std::string& update, const std::string& more, const std::vector<Param>& params) {
    Change c;
    Result r = exec("WITH prev AS (SELECT state FROM jobs WHERE id = $1), u AS (" + update + ")" + more +
                        " SELECT (SELECT state FROM prev), (SELECT count(*) FROM u)",
                    params);
    if (!r.ok()) {
      c.error = r.unreachable() ? r.failure() : "the job store could not write: " + r.error();
      c.busy = r.unreachable();
      return c;
    }
    if (r.rows() == 0 || r.get(0, 0).empty()) return c;
    c.from = job_state_from(r.get(0, 0)).value_or(JobState::kFailed);
    c.made = r.get_int(0, 1) > 0;
    return c;
  }

  // Runs a statement on a pooled connection. A broken connection is reset once (the statement is
  // not repeated: the caller sees the error, as with any failed write); while the database is away
  // the store reports itself unhealthy and the lease thread reconnects with backoff.
  Result exec(const std::string& sql, const std::vector<Param>& params, bool binary_result = false) {
    PGconn* c = acquire();
    if (PQstatus(c) != CONNECTION_OK) {
      PQreset(c);
      if (PQstatus(c) != CONNECTION_OK) {
        healthy_ = false;
        Result lost;
        lost.set_unreachable(PQerrorMessage(c));
        give_back(c);
        return lost;
      }
    }
    Result r = run(c, sql, params, binary_result);
    // libpq does not always mark a connection bad when the server closed it under a statement (a
    // failed write of the statement is reported, the status can stay "ok"): the result says so too.
    auto lost = [&] { return !r.ok() && (PQstatus(c) != CONNECTION_OK || r.lost_connection()); };
    if (lost()) {
      // The server restarted or the connection dropped since this connection's last use: once
      // more on a new connection. Writes are safe to repeat: each is conditional on the state (and
      // fence) it changes from, or inserts a key that cannot be inserted twice.
      PQreset(c);
      if (PQstatus(c) == CONNECTION_OK) r = run(c, sql, params, binary_result);
      if (lost()) {
        healthy_ = false;
        r.set_unreachable(PQstatus(c) != CONNECTION_OK ? PQerrorMessage(c) : r.error());
      }
    }
    give_back(c);
    return r;
  }
  PGconn* acquire() {
    std::unique_lock lock(pool_mutex_);
    pool_wake_.wait(lock, [&] { return !free_.empty(); });
    PGconn* c = free_.back();
    free_.pop_back();
    return c;
  }
  void give_back(PGconn* c) {
    {
      std::lock_guard lock(pool_mutex_);
      free_.push_back(c);
    }
    pool_wake_.notify_one();
  }

  // Calls the service under listener_mutex_, so that once set_listener({}) has returned (the
  // service stopping) no call is still running into it.
  template <typename F>
  void tell(F f) {
    std::lock_guard lock(listener_mutex_);
    f(listener_);
  }

  bool sleep_for(double seconds) {
    std::unique_lock lock(mutex_);
    return !stop_wake_.wait_for(lock, std::chrono::duration<double>(seconds), [&] { return stopping_; });
  }

  // Renews this node's leases every third of the lease; takes back expired ones; reconnects.
  void lease_loop() {
    double backoff = 0.1;
    while (sleep_for(healthy_ ? std::min(options_.lease_seconds / 3.0, 1.0) : backoff)) {
      std::vector<std::pair<std::string, int>> mine;
      {
        std::lock_guard lock(mutex_);
        mine.assign(owned_.begin(), owned_.end());
      }
      std::string ids = "{", attempts = "{";
      for (size_t i = 0; i < mine.size(); ++i) {
        if (i) {
          ids += ',';
          attempts += ',';
        }
        ids += mine[i].first;
        attempts += std::to_string(mine[i].second);
      }
      ids += "}";
      attempts += "}";
      // Back from an outage: leases that ran out meanwhile are renewed too (see the top of the file).
      const bool was_away = !healthy_;
      Result r = exec("UPDATE jobs SET lease_until = clock_timestamp() + $3 * interval '1 second'"
                      " FROM unnest($1::text[], $2::int[]) AS o(id, attempt)"
                      " WHERE jobs.id = o.id AND jobs.attempts = o.attempt AND jobs.owner = $4 AND jobs.state = 'running'"
                      "   AND (jobs.lease_until > clock_timestamp() OR $5::boolean)"
                      " RETURNING jobs.id",
                      {text(ids), text(attempts), num(options_.lease_seconds), text(node_), text(was_away ? "true" : "false")});
      if (!r.ok()) {
        healthy_ = false;
        backoff = std::min(backoff * 2, 5.0);
        continue;
      }
      healthy_ = true;
      backoff = 0.1;
      // Jobs not renewed are no longer this node's: cancelled, or their lease ran out.
      std::vector<std::string> lost;
      for (const auto& [id, attempt] : mine) {
        bool renewed = false;
        for (int i = 0; i < r.rows() && !renewed; ++i) renewed = r.get(i, 0) == id;
        if (!renewed) lost.push_back(id);
      }
      // The entries stay until the worker releases them: its writes meanwhile are refused.
      tell([&](const StoreListener& l) {
        for (const auto& id : lost)
          if (l.lost) l.lost(id);
      });
      if (recover(options_.max_attempts) > 0) tell([](const StoreListener& l) { if (l.job_queued) l.job_queued(); });
    }
  }

  // LISTEN on a connection of its own; on a drop, reconnects with backoff and then wakes everyone,
  // as notifications sent meanwhile are lost.
  void listen_loop() {
    PGconn* c = nullptr;
    double backoff = 0.1;
    while (true) {
      {
        std::lock_guard lock(mutex_);
        if (stopping_) break;
      }
      if (!c) {
        std::string error;
        c = connect(uri_, error);
        if (c) {
          Result r(PQexec(c, "LISTEN hemibake_job; LISTEN hemibake_event; LISTEN hemibake_cancel;"
                              " LISTEN hemibake_preview_ask; LISTEN hemibake_preview"));
          if (!r.ok()) {
            PQfinish(c);
            c = nullptr;
          }
        }
        if (!c) {
          if (!sleep_for(backoff)) break;
          backoff = std::min(backoff * 2, 5.0);
          continue;
        }
        backoff = 0.1;
        tell([](const StoreListener& l) {
          if (l.event) l.event("");
          if (l.job_queued) l.job_queued();
        });
      }
      const int fd = PQsocket(c);
      fd_set set;
      FD_ZERO(&set);
      FD_SET(fd, &set);
      timeval tv{0, 200000};  // to see stopping_
      if (::select(fd + 1, &set, nullptr, nullptr, &tv) < 0) continue;
      if (!PQconsumeInput(c) || PQstatus(c) != CONNECTION_OK) {
        PQfinish(c);
        c = nullptr;
        continue;
      }
      while (PGnotify* n = PQnotifies(c)) {
        const std::string channel = n->relname, payload = n->extra;
        PQfreemem(n);
        const bool mine = (channel == "hemibake_cancel" || channel == "hemibake_preview_ask") && runs_here(payload);
        tell([&](const StoreListener& l) {
          if (channel == "hemibake_job" && l.job_queued) l.job_queued();
          else if (channel == "hemibake_event" && l.event) l.event(payload);
          else if (channel == "hemibake_cancel" && mine && l.lost) l.lost(payload);
          else if (channel == "hemibake_preview_ask" && mine && l.preview_asked) l.preview_asked(payload);
          else if (channel == "hemibake_preview" && l.preview_ready) l.preview_ready(payload);
        });
      }
    }
    PQfinish(c);
  }

  const std::string uri_;
  const PgOptions options_;
  const std::string node_;  ///< this process's owner name on the jobs it claims
  std::mutex mutex_;
  std::condition_variable stop_wake_;
  bool stopping_ = false;
  std::map<std::string, int> owned_;  ///< jobs this node claimed, with their attempt numbers
  std::mutex claim_mutex_;            ///< held by a claim from its update until owned_ names the job
  std::mutex pool_mutex_;
  std::condition_variable pool_wake_;
  std::vector<PGconn*> free_, all_;
  std::atomic<bool> healthy_{true};
  std::mutex listener_mutex_;
  StoreListener listener_;
  std::thread listener_thread_, lease_thread_;
};

}  // namespace

std::unique_ptr<Store> Store::open_postgres(const std::string& uri, const PgOptions& options, std::string& error) {
  if (uri.rfind("postgresql://", 0) != 0 && uri.rfind("postgres://", 0) != 0) {
    error = "--store must be a PostgreSQL URI, postgresql://USER@HOST:PORT/DATABASE (got '" + uri + "')";
    return nullptr;
  }
  {
    char* why = nullptr;
    PQconninfoOption* parsed = PQconninfoParse(uri.c_str(), &why);
    if (!parsed) {
      error = "bad --store URI '" + uri + "': " + (why ? why : "out of memory");
      PQfreemem(why);
      return nullptr;
    }
    PQconninfoFree(parsed);
  }
  std::vector<PGconn*> conns;
  auto fail = [&](const std::string& what) {
    error = what;
    for (PGconn* c : conns) PQfinish(c);
    return nullptr;
  };
  for (int i = 0; i < std::max(1, options.connections); ++i) {
    std::string why;
    PGconn* c = connect(uri, why);
    if (!c) return fail("cannot connect to the job store at " + uri + ": " + why);
    conns.push_back(c);
  }
  // Schema: created or migrated in one transaction, under an advisory lock so that nodes starting
  // together do it once.
  PGconn* c = conns[0];
  Result b(PQexec(c, (std::string("BEGIN; SELECT pg_advisory_xact_lock(") + kSchemaLock +
                      "); CREATE TABLE IF NOT EXISTS hemibake_schema (version INTEGER NOT NULL)").c_str()));
  if (!b.ok()) return fail("cannot set up the job store at " + uri + ": " + b.error());
  Result v(PQexec(c, "SELECT coalesce(max(version), 0) FROM hemibake_schema"));
  if (!v.ok()) return fail("cannot set up the job store at " + uri + ": " + v.error());
  const int version = static_cast<int>(v.get_int(0, 0));
  if (version > kSchemaVersion) {
    Result(PQexec(c, "ROLLBACK"));
    return fail("the job store at " + uri + " was written by a newer hemibake-server (schema " + std::to_string(version) + ")");
  }
  if (version < 1) {
    Result m(PQexec(c, kSchema1));
    if (!m.ok()) {
      Result(PQexec(c, "ROLLBACK"));
      return fail("cannot set up the job store at " + uri + ": " + m.error());
    }
  }
  Result storage(PQexec(c, kResultStorage));
  if (storage.ok() && storage.rows() == 1 && storage.get(0, 0) != "e") {
    Result a(PQexec(c, "ALTER TABLE results ALTER COLUMN data SET STORAGE EXTERNAL"));
    if (!a.ok()) {
      Result(PQexec(c, "ROLLBACK"));
      return fail("cannot set up the job store at " + uri + ": " + a.error());
    }
  }
  Result s(PQexec(c, ("DELETE FROM hemibake_schema; INSERT INTO hemibake_schema VALUES (" + std::to_string(kSchemaVersion) +
                      "); COMMIT").c_str()));
  if (!s.ok()) {
    Result(PQexec(c, "ROLLBACK"));
    return fail("cannot set up the job store at " + uri + ": " + s.error());
  }
  return std::make_unique<PgStore>(uri, options, std::move(conns));
}

}  // namespace hemibake::server
