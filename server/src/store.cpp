#include "hemibake/server/store.h"

#include <sqlite3.h>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <random>

namespace hemibake::server {
namespace {

// A prepared statement that finalizes itself.
class Stmt {
 public:
  Stmt(sqlite3* db, const char* sql) { sqlite3_prepare_v2(db, sql, -1, &s_, nullptr); }
  ~Stmt() { sqlite3_finalize(s_); }
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;
  Stmt& text(int i, const std::string& v) {
    sqlite3_bind_text(s_, i, v.data(), static_cast<int>(v.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Stmt& blob(int i, const std::string& v) {
    sqlite3_bind_blob64(s_, i, v.data(), v.size(), SQLITE_STATIC);  // bound only while `v` lives
    return *this;
  }
  Stmt& real(int i, double v) {
    sqlite3_bind_double(s_, i, v);
    return *this;
  }
  Stmt& integer(int i, int64_t v) {
    sqlite3_bind_int64(s_, i, v);
    return *this;
  }
  Stmt& null(int i) {
    sqlite3_bind_null(s_, i);
    return *this;
  }
  bool row() { return (code_ = sqlite3_step(s_)) == SQLITE_ROW; }
  /// Runs a statement that returns no rows; true if it succeeded.
  bool run() { return (code_ = sqlite3_step(s_)) == SQLITE_DONE; }
  /// The last step failed (rather than found no row, or no more).
  bool failed() const { return code_ != SQLITE_ROW && code_ != SQLITE_DONE; }
  int code() const { return code_; }
  std::string col_text(int i) {
    const auto* p = sqlite3_column_text(s_, i);
    return p ? std::string(reinterpret_cast<const char*>(p), static_cast<size_t>(sqlite3_column_bytes(s_, i))) : std::string();
  }
  std::string col_blob(int i) {
    const auto* p = static_cast<const char*>(sqlite3_column_blob(s_, i));
    return p ? std::string(p, static_cast<size_t>(sqlite3_column_bytes(s_, i))) : std::string();
  }
  double col_real(int i) { return sqlite3_column_double(s_, i); }
  int64_t col_int(int i) { return sqlite3_column_int64(s_, i); }

 private:
  sqlite3_stmt* s_ = nullptr;
  int code_ = SQLITE_OK;
};

std::string new_id() {
  static thread_local std::mt19937_64 rng(std::random_device{}() ^ (static_cast<uint64_t>(std::random_device{}()) << 32));
  static const char* hex = "0123456789abcdef";
  std::string id;
  for (int i = 0; i < 2; ++i) {
    uint64_t v = rng();
    for (int k = 0; k < 16; ++k, v >>= 4) id += hex[v & 15];
  }
  return id;
}

// The job table holds only small columns; scenes and results have tables of their own. In one row,
// a column after a large blob is reached by walking the blob's chain of overflow pages, so a status
// read of a job with a 36 MB scene read 36 MB (layout 1, before user_version 2).
constexpr int kLayout = 2;
constexpr const char* kTables =
    "CREATE TABLE IF NOT EXISTS jobs ("
    "  id TEXT PRIMARY KEY, state TEXT NOT NULL, params TEXT NOT NULL, cache_key TEXT NOT NULL,"
    "  idempotency_key TEXT UNIQUE, content_type TEXT NOT NULL, scene_bytes INTEGER NOT NULL,"
    "  etag TEXT, result_bytes INTEGER NOT NULL DEFAULT 0, error TEXT, progress TEXT,"
    "  attempts INTEGER NOT NULL DEFAULT 0, created REAL NOT NULL, started REAL NOT NULL DEFAULT 0,"
    "  finished REAL NOT NULL DEFAULT 0, event_seq INTEGER NOT NULL DEFAULT 0);"
    "CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state, created);"
    "CREATE INDEX IF NOT EXISTS jobs_cache ON jobs(cache_key, state);"
    "CREATE TABLE IF NOT EXISTS scenes (job TEXT PRIMARY KEY, data BLOB NOT NULL);"
    "CREATE TABLE IF NOT EXISTS results (job TEXT PRIMARY KEY, data BLOB NOT NULL);"
    "CREATE TABLE IF NOT EXISTS events (job TEXT NOT NULL, seq INTEGER NOT NULL, type TEXT NOT NULL,"
    "  data TEXT NOT NULL, PRIMARY KEY (job, seq));";

// Layout 1 kept the scene and the result in the job's row: they move to their own tables.
constexpr const char* kFromLayout1 =
    "ALTER TABLE jobs RENAME TO jobs_layout1;"
    "DROP INDEX IF EXISTS jobs_state;"
    "DROP INDEX IF EXISTS jobs_cache;";
constexpr const char* kCopyLayout1 =
    "INSERT INTO jobs (id, state, params, cache_key, idempotency_key, content_type, scene_bytes, etag, result_bytes,"
    "                  error, progress, attempts, created, started, finished, event_seq)"
    "  SELECT id, state, params, cache_key, idempotency_key, content_type, length(scene), etag,"
    "         coalesce(length(result), 0), error, progress, attempts, created, started, finished, event_seq"
    "  FROM jobs_layout1;"
    "INSERT INTO scenes (job, data) SELECT id, scene FROM jobs_layout1;"
    "INSERT INTO results (job, data) SELECT id, result FROM jobs_layout1 WHERE result IS NOT NULL;"
    "DROP TABLE jobs_layout1;";

constexpr const char* kColumns =
    "id, state, params, content_type, scene_bytes, progress, error, etag, result_bytes, attempts, "
    "created, started, finished, event_seq";

JobRecord read_record(Stmt& s) {
  JobRecord r;
  r.id = s.col_text(0);
  r.state = job_state_from(s.col_text(1)).value_or(JobState::kFailed);
  r.params = s.col_text(2);
  r.content_type = s.col_text(3);
  r.scene_bytes = static_cast<uint64_t>(s.col_int(4));
  r.progress = s.col_text(5);
  r.error = s.col_text(6);
  r.etag = s.col_text(7);
  r.result_bytes = static_cast<uint64_t>(s.col_int(8));
  r.attempts = static_cast<int>(s.col_int(9));
  r.created = s.col_real(10);
  r.started = s.col_real(11);
  r.finished = s.col_real(12);
  r.last_event = static_cast<uint64_t>(s.col_int(13));
  return r;
}

bool is_busy(int code) { return (code & 0xff) == SQLITE_BUSY || (code & 0xff) == SQLITE_LOCKED; }

// Says in `why` (if given) why statement `s` on `db` could not be read, if it could not. True if
// it could.
bool read_ok(sqlite3* db, const Stmt& s, ReadError* why) {
  if (!s.failed()) return true;
  if (why) {
    why->busy = is_busy(s.code());
    why->error = why->busy ? std::string("the job store is busy (another program holds its lock: ") + sqlite3_errmsg(db) + ")"
                           : std::string("the job store could not be read: ") + sqlite3_errmsg(db);
  }
  return false;
}

bool exec(sqlite3* db, const char* sql, std::string& error) {
  char* msg = nullptr;
  if (sqlite3_exec(db, sql, nullptr, nullptr, &msg) == SQLITE_OK) return true;
  error = msg ? msg : sqlite3_errmsg(db);
  sqlite3_free(msg);
  return false;
}

// SQLite in WAL mode; one connection, calls serialised by a mutex. Parts of results are read
// through a second, read-only connection with a mutex of its own: in WAL mode a reader never waits
// for the writer, so a download goes on while a bake's result or a scene is written.
class SqliteStore final : public Store {
 public:
  SqliteStore(sqlite3* db, sqlite3* reader, int lock_fd) : db_(db), reader_(reader), lock_fd_(lock_fd) {}
  ~SqliteStore() override {
    sqlite3_close(reader_);
    sqlite3_close(db_);
    ::close(lock_fd_);
  }

  Created create(const std::string& scene, const std::string& content_type, const std::string& params,
                 const std::string& cache_key, const std::string& idempotency_key) override {
    std::lock_guard lock(mutex_);
    Created c;
    if (!idempotency_key.empty()) {
      if (auto held = idempotent_locked(idempotency_key)) {
        c.existed = true;
        c.id = held->first;
        c.cache_key = held->second;
        return c;
      }
    }
    const std::string id = new_id();
    Transaction t(*this);
    Stmt s(db_,
           "INSERT INTO jobs (id, state, params, cache_key, idempotency_key, content_type, scene_bytes, created)"
           " VALUES (?, 'queued', ?, ?, ?, ?, ?, ?)");
    s.text(1, id).text(2, params).text(3, cache_key);
    if (idempotency_key.empty()) s.null(4);
    else s.text(4, idempotency_key);
    s.text(5, content_type).integer(6, static_cast<int64_t>(scene.size())).real(7, unix_now());
    bool ok = t.ok() && s.run();
    if (ok) {
      Stmt d(db_, "INSERT INTO scenes (job, data) VALUES (?, ?)");
      ok = d.text(1, id).blob(2, scene).run();
    }
    if (!ok || !t.commit()) {
      c.error = t.error();
      c.full = t.full();
      c.busy = t.busy();
      return c;
    }
    c.id = id;
    return c;
  }

  std::optional<std::pair<std::string, std::string>> find_idempotent(const std::string& idempotency_key) override {
    std::lock_guard lock(mutex_);
    return idempotent_locked(idempotency_key);
  }

  std::optional<std::string> find_cached(const std::string& cache_key) override {
    std::lock_guard lock(mutex_);
    Stmt s(db_, "SELECT id FROM jobs WHERE cache_key = ? AND state = 'succeeded' ORDER BY finished DESC LIMIT 1");
    s.text(1, cache_key);
    if (s.row()) return s.col_text(0);
    return std::nullopt;
  }

  std::optional<JobRecord> get(const std::string& id, ReadError* why) override {
    std::lock_guard lock(mutex_);
    Stmt s(db_, (std::string("SELECT ") + kColumns + " FROM jobs WHERE id = ?").c_str());
    s.text(1, id);
    if (!s.row()) {
      read_ok(db_, s, why);
      return std::nullopt;
    }
    return read_record(s);
  }

  std::vector<JobRecord> list(std::optional<JobState> state, size_t limit, const std::string& after, ReadError* why) override {
    std::lock_guard lock(mutex_);
    // Newest first; the cursor is the last id of the previous page (its creation time orders).
    std::string sql = std::string("SELECT ") + kColumns + " FROM jobs WHERE (?1 IS NULL OR state = ?1)"
                      " AND (?2 IS NULL OR created < (SELECT created FROM jobs WHERE id = ?2)"
                      "      OR (created = (SELECT created FROM jobs WHERE id = ?2) AND id < ?2))"
                      " ORDER BY created DESC, id DESC LIMIT ?3";
    Stmt s(db_, sql.c_str());
    if (state) s.text(1, to_string(*state));
    else s.null(1);
    if (after.empty()) s.null(2);
    else s.text(2, after);
    s.integer(3, static_cast<int64_t>(limit));
    std::vector<JobRecord> out;
    while (s.row()) out.push_back(read_record(s));
    if (!read_ok(db_, s, why)) out.clear();
    return out;
  }

  bool claim(std::string& id, std::string& scene, std::string& params) override {
    std::lock_guard lock(mutex_);
    Stmt s(db_,
           "UPDATE jobs SET state = 'running', started = ?, attempts = attempts + 1"
           " WHERE id = (SELECT id FROM jobs WHERE state = 'queued' ORDER BY created, id LIMIT 1)"
           " RETURNING id, params");
    s.real(1, unix_now());
    if (!s.row()) return false;
    id = s.col_text(0);
    params = s.col_text(1);
    s.row();  // completes the update
    Stmt d(db_, "SELECT data FROM scenes WHERE job = ?");
    d.text(1, id);
    scene = d.row() ? d.col_blob(0) : std::string();
    return true;
  }

  bool set_progress(const std::string& id, const std::string& progress_json) override {
    std::lock_guard lock(mutex_);
    Stmt s(db_, "UPDATE jobs SET progress = ? WHERE id = ?");
    return s.text(1, progress_json).text(2, id).run();
  }

  uint64_t add_event(const std::string& id, const std::string& type, const std::string& data) override {
    std::lock_guard lock(mutex_);
    Transaction t(*this);
    if (!t.ok()) return 0;
    int64_t seq = 0;
    {
      Stmt u(db_, "UPDATE jobs SET event_seq = event_seq + 1 WHERE id = ? RETURNING event_seq");
      u.text(1, id);
      if (!u.row()) return 0;
      seq = u.col_int(0);
    }
    Stmt s(db_, "INSERT INTO events (job, seq, type, data) VALUES (?, ?, ?, ?)");
    if (!s.text(1, id).integer(2, seq).text(3, type).text(4, data).run() || !t.commit()) return 0;
    return static_cast<uint64_t>(seq);
  }

  std::vector<Event> events_after(const std::string& id, uint64_t after, size_t limit, ReadError* why) override {
    std::lock_guard lock(mutex_);
    Stmt s(db_, "SELECT seq, type, data FROM events WHERE job = ? AND seq > ? ORDER BY seq LIMIT ?");
    s.text(1, id).integer(2, static_cast<int64_t>(after)).integer(3, static_cast<int64_t>(limit));
    std::vector<Event> out;
    while (s.row()) out.push_back({static_cast<uint64_t>(s.col_int(0)), s.col_text(1), s.col_text(2)});
    if (!read_ok(db_, s, why)) out.clear();
    return out;
  }

  Change succeed(const std::string& id, const std::string& result, const std::string& etag) override {
    std::lock_guard lock(mutex_);
    Transaction t(*this);
    Change c = change_locked(t, id, "state = 'succeeded', etag = ?2, result_bytes = ?3, finished = ?4", "('running')",
                             [&](Stmt& s) { s.text(2, etag).integer(3, static_cast<int64_t>(result.size())).real(4, unix_now()); });
    if (!c.made) return c;
    Stmt d(db_, "INSERT OR REPLACE INTO results (job, data) VALUES (?, ?)");
    if (!d.text(1, id).blob(2, result).run() || !t.commit()) return unmade(t, c.from);
    return c;
  }

  Change fail(const std::string& id, const std::string& error) override {
    std::lock_guard lock(mutex_);
    Transaction t(*this);
    Change c = change_locked(t, id, "state = 'failed', error = ?2, finished = ?3", "('running')",
                             [&](Stmt& s) { s.text(2, error).real(3, unix_now()); });
    return c.made && !t.commit() ? unmade(t, c.from) : c;
  }

  Change cancel(const std::string& id) override {
    std::lock_guard lock(mutex_);
    Transaction t(*this);
    Change c = change_locked(t, id, "state = 'cancelled', finished = ?2", "('queued', 'running')",
                             [&](Stmt& s) { s.real(2, unix_now()); });
    return c.made && !t.commit() ? unmade(t, c.from) : c;
  }

  Change requeue(const std::string& id) override {
    std::lock_guard lock(mutex_);
    Transaction t(*this);
    Change c = change_locked(t, id, "state = 'queued'", "('running')", [](Stmt&) {});
    return c.made && !t.commit() ? unmade(t, c.from) : c;
  }

  std::optional<std::string> result_part(const std::string& id, uint64_t offset, size_t size, ReadError* why) override {
    std::lock_guard lock(reader_mutex_);
    // The row and its length first (length() of a blob reads its header, not its pages); then
    // the part through incremental blob I/O, which reads only the pages that hold it. One short
    // read transaction per part: a slow download does not hold back the WAL's checkpoints.
    int64_t rowid = 0, bytes = 0;
    {
      Stmt s(reader_, "SELECT r.rowid, length(r.data) FROM results r JOIN jobs j ON j.id = r.job"
                      " WHERE r.job = ? AND j.state = 'succeeded'");
      s.text(1, id);
      if (!s.row()) {
        read_ok(reader_, s, why);
        return std::nullopt;
      }
      rowid = s.col_int(0);
      bytes = s.col_int(1);
    }
    if (offset > static_cast<uint64_t>(bytes)) return std::nullopt;
    const auto n = static_cast<int>(std::min<uint64_t>(size, static_cast<uint64_t>(bytes) - offset));
    std::string part(static_cast<size_t>(n), '\0');
    if (n == 0) return part;
    sqlite3_blob* blob = nullptr;
    int code = sqlite3_blob_open(reader_, "main", "results", "data", rowid, 0, &blob);
    if (code == SQLITE_OK) code = sqlite3_blob_read(blob, part.data(), n, static_cast<int>(offset));
    if (code != SQLITE_OK && why) {
      why->busy = is_busy(code);
      why->error = std::string("the job store could not read the result: ") + sqlite3_errmsg(reader_);
    }
    sqlite3_blob_close(blob);
    if (code != SQLITE_OK) return std::nullopt;
    return part;
  }

  std::optional<std::string> result(const std::string& id, ReadError* why) override {
    std::lock_guard lock(mutex_);
    Stmt s(db_, "SELECT r.data FROM results r JOIN jobs j ON j.id = r.job WHERE r.job = ? AND j.state = 'succeeded'");
    s.text(1, id);
    if (!s.row()) {
      read_ok(db_, s, why);
      return std::nullopt;
    }
    return s.col_blob(0);
  }

  int recover(int max_attempts) override {
    std::lock_guard lock(mutex_);
    Stmt f(db_, "UPDATE jobs SET state = 'failed', finished = ?, error = 'the server stopped during each of its ' || attempts || ' attempts' WHERE state = 'running' AND attempts >= ?");
    f.real(1, unix_now()).integer(2, max_attempts).run();
    Stmt q(db_, "UPDATE jobs SET state = 'queued' WHERE state = 'running'");
    q.run();
    return sqlite3_changes(db_);
  }

  int expire(double age_seconds) override {
    std::lock_guard lock(mutex_);
    const double cutoff = unix_now() - age_seconds;
    Transaction t(*this);
    if (!t.ok()) return 0;
    const char* old = "(SELECT id FROM jobs WHERE state IN ('succeeded', 'failed', 'cancelled') AND finished < ?)";
    for (const char* table : {"events", "scenes", "results"}) {
      Stmt e(db_, (std::string("DELETE FROM ") + table + " WHERE job IN " + old).c_str());
      e.real(1, cutoff).run();
    }
    Stmt s(db_, "DELETE FROM jobs WHERE state IN ('succeeded', 'failed', 'cancelled') AND finished < ?");
    s.real(1, cutoff).run();
    const int n = sqlite3_changes(db_);
    return t.commit() ? n : 0;
  }

  size_t count(JobState state, ReadError* why) override {
    std::lock_guard lock(mutex_);
    Stmt s(db_, "SELECT count(*) FROM jobs WHERE state = ?");
    s.text(1, to_string(state));
    if (s.row()) return static_cast<size_t>(s.col_int(0));
    read_ok(db_, s, why);
    return 0;
  }

 private:
  // A write transaction, rolled back unless committed. Callers hold mutex_.
  class Transaction {
   public:
    explicit Transaction(SqliteStore& s) : db_(s.db_) { ok_ = sqlite3_exec(db_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) == SQLITE_OK; note(); }
    ~Transaction() {
      // After some errors (a full disk among them) SQLite has rolled back already.
      if (ok_ && !committed_ && !sqlite3_get_autocommit(db_)) sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    }
    bool ok() const { return ok_; }
    bool commit() {
      committed_ = ok_ && sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr) == SQLITE_OK;
      return committed_;
    }
    /// Why the last statement failed, for a message.
    std::string error() {
      note();
      if (busy_) return "the job store is busy (another program holds its lock: " + error_ + ")";
      return error_.empty() ? "the job store could not write" : "the job store could not write: " + error_;
    }
    bool full() {
      note();
      return full_;
    }
    bool busy() {
      note();
      return busy_;
    }

   private:
    void note() {
      const int code = sqlite3_errcode(db_);
      if (code != SQLITE_OK && code != SQLITE_DONE && code != SQLITE_ROW) {
        error_ = sqlite3_errmsg(db_);
        full_ = full_ || code == SQLITE_FULL;
        busy_ = is_busy(code);
      }
    }
    sqlite3* db_;
    bool ok_ = false, committed_ = false, full_ = false, busy_ = false;
    std::string error_;
  };

  // A change that could not be written, and why.
  static Change unmade(Transaction& t, JobState from) {
    Change c{false, from, t.error()};
    c.busy = t.busy();
    return c;
  }

  // Sets `set` on job `id` if its state is one of `from` (an SQL list), in transaction `t`; ?1 is
  // the id, `bind` binds the rest. The read of the state before and the update are one step.
  template <typename Bind>
  Change change_locked(Transaction& t, const std::string& id, const char* set, const char* from, Bind bind) {
    Change c;
    if (!t.ok()) return unmade(t, c.from);
    Stmt q(db_, "SELECT state FROM jobs WHERE id = ?");
    q.text(1, id);
    if (!q.row()) return c;
    c.from = job_state_from(q.col_text(0)).value_or(JobState::kFailed);
    Stmt s(db_, (std::string("UPDATE jobs SET ") + set + " WHERE id = ?1 AND state IN " + from).c_str());
    s.text(1, id);
    bind(s);
    if (!s.run()) return unmade(t, c.from);
    c.made = sqlite3_changes(db_) > 0;
    return c;
  }

  std::optional<std::pair<std::string, std::string>> idempotent_locked(const std::string& idempotency_key) {
    Stmt s(db_, "SELECT id, cache_key FROM jobs WHERE idempotency_key = ?");
    s.text(1, idempotency_key);
    if (s.row()) return std::make_pair(s.col_text(0), s.col_text(1));
    return std::nullopt;
  }

  sqlite3* db_;
  sqlite3* reader_;  ///< read-only, for parts of results
  int lock_fd_;  ///< flock'ed: one server per data directory
  std::mutex mutex_;
  std::mutex reader_mutex_;
};

}  // namespace

double unix_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

const char* to_string(JobState s) {
  switch (s) {
    case JobState::kQueued: return "queued";
    case JobState::kRunning: return "running";
    case JobState::kSucceeded: return "succeeded";
    case JobState::kFailed: return "failed";
    case JobState::kCancelled: return "cancelled";
  }
  return "failed";
}

std::optional<JobState> job_state_from(const std::string& s) {
  for (JobState st : {JobState::kQueued, JobState::kRunning, JobState::kSucceeded, JobState::kFailed, JobState::kCancelled})
    if (s == to_string(st)) return st;
  return std::nullopt;
}

std::unique_ptr<Store> Store::open(const std::string& dir, std::string& error, int busy_ms) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    error = "cannot create data directory '" + dir + "': " + ec.message();
    return nullptr;
  }
  // One server per data directory: a second one would re-queue the first one's running jobs at
  // its start (recover) and bake them twice. The lock dies with the process, even on SIGKILL.
  const std::string lock_path = (std::filesystem::path(dir) / "hemibake.lock").string();
  const int lock_fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (lock_fd < 0) {
    error = "cannot open " + lock_path + ": " + std::strerror(errno);
    return nullptr;
  }
  if (::flock(lock_fd, LOCK_EX | LOCK_NB) != 0) {
    error = errno == EWOULDBLOCK ? "the data directory '" + dir + "' is in use by another hemibake-server; stop it or give --data another directory"
                                 : "cannot lock " + lock_path + ": " + std::strerror(errno);
    ::close(lock_fd);
    return nullptr;
  }
  const std::string path = (std::filesystem::path(dir) / "hemibake.db").string();
  sqlite3* db = nullptr;
  auto fail = [&](const std::string& what) {
    error = what;
    sqlite3_close(db);
    ::close(lock_fd);
    return nullptr;
  };
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX, nullptr) != SQLITE_OK)
    return fail("cannot open " + path + ": " + (db ? sqlite3_errmsg(db) : "out of memory"));
  // WAL: readers never wait for the writer; synchronous=FULL: a committed job survives power loss.
  std::string why;
  if (sqlite3_busy_timeout(db, busy_ms) != SQLITE_OK || !exec(db, "PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL;", why))
    return fail("cannot set up the job store " + path + ": " + why);
  int layout = 0;
  bool layout1 = false;
  {
    Stmt v(db, "PRAGMA user_version");
    if (v.row()) layout = static_cast<int>(v.col_int(0));
    Stmt c(db, "SELECT 1 FROM pragma_table_info('jobs') WHERE name = 'scene'");
    layout1 = c.row();
  }
  if (layout > kLayout) return fail("the job store " + path + " was written by a newer hemibake-server (layout " + std::to_string(layout) + ")");
  // One transaction: a crash during the conversion leaves layout 1 as it was.
  const std::string setup = std::string("BEGIN IMMEDIATE;") + (layout1 ? kFromLayout1 : "") + kTables +
                            (layout1 ? kCopyLayout1 : "") + "PRAGMA user_version = " + std::to_string(kLayout) + "; COMMIT;";
  if (!exec(db, setup.c_str(), why)) {
    sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr);
    return fail("cannot set up the job store " + path + ": " + why);
  }
  if (layout1) exec(db, "VACUUM", why);  // the old rows' space back; not needed to go on
  sqlite3* reader = nullptr;
  if (sqlite3_open_v2(path.c_str(), &reader, SQLITE_OPEN_READONLY | SQLITE_OPEN_FULLMUTEX, nullptr) != SQLITE_OK ||
      sqlite3_busy_timeout(reader, busy_ms) != SQLITE_OK) {
    const std::string what = "cannot open " + path + " for reading: " + (reader ? sqlite3_errmsg(reader) : "out of memory");
    sqlite3_close(reader);
    return fail(what);
  }
  return std::make_unique<SqliteStore>(db, reader, lock_fd);
}

}  // namespace hemibake::server
