#include "hemibake/server/store.h"

#include <sqlite3.h>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
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
    sqlite3_bind_blob64(s_, i, v.data(), v.size(), SQLITE_TRANSIENT);
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
  bool row() { return sqlite3_step(s_) == SQLITE_ROW; }
  int run() { return sqlite3_step(s_); }
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
  bool ok() const { return s_ != nullptr; }

 private:
  sqlite3_stmt* s_ = nullptr;
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

constexpr const char* kColumns =
    "id, state, params, content_type, length(scene), progress, error, etag, length(result), attempts, "
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

std::unique_ptr<Store> Store::open(const std::string& dir, std::string& error) {
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
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX, nullptr) != SQLITE_OK) {
    error = "cannot open " + path + ": " + (db ? sqlite3_errmsg(db) : "out of memory");
    sqlite3_close(db);
    ::close(lock_fd);
    return nullptr;
  }
  // WAL: readers never wait for the writer; synchronous=FULL: a committed job survives power loss.
  const char* schema =
      "PRAGMA journal_mode=WAL;"
      "PRAGMA synchronous=FULL;"
      "PRAGMA busy_timeout=10000;"
      "CREATE TABLE IF NOT EXISTS jobs ("
      "  id TEXT PRIMARY KEY, state TEXT NOT NULL, params TEXT NOT NULL, cache_key TEXT NOT NULL,"
      "  idempotency_key TEXT UNIQUE, scene BLOB NOT NULL, content_type TEXT NOT NULL,"
      "  result BLOB, etag TEXT, error TEXT, progress TEXT, attempts INTEGER NOT NULL DEFAULT 0,"
      "  created REAL NOT NULL, started REAL NOT NULL DEFAULT 0, finished REAL NOT NULL DEFAULT 0,"
      "  event_seq INTEGER NOT NULL DEFAULT 0);"
      "CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state, created);"
      "CREATE INDEX IF NOT EXISTS jobs_cache ON jobs(cache_key, state);"
      "CREATE TABLE IF NOT EXISTS events (job TEXT NOT NULL, seq INTEGER NOT NULL, type TEXT NOT NULL,"
      "  data TEXT NOT NULL, PRIMARY KEY (job, seq));";
  char* msg = nullptr;
  if (sqlite3_exec(db, schema, nullptr, nullptr, &msg) != SQLITE_OK) {
    error = "cannot set up the job store " + path + ": " + (msg ? msg : "?");
    sqlite3_free(msg);
    sqlite3_close(db);
    ::close(lock_fd);
    return nullptr;
  }
  return std::unique_ptr<Store>(new Store(db, lock_fd));
}

Store::~Store() {
  sqlite3_close(db_);
  ::close(lock_fd_);
}

std::string Store::create(const std::string& scene, const std::string& content_type, const std::string& params,
                          const std::string& cache_key, const std::string& idempotency_key, bool& existed) {
  std::lock_guard lock(mutex_);
  existed = false;
  if (!idempotency_key.empty()) {
    if (auto id = idempotent_locked(idempotency_key)) {
      existed = true;
      return *id;
    }
  }
  const std::string id = new_id();
  Stmt s(db_,
         "INSERT INTO jobs (id, state, params, cache_key, idempotency_key, scene, content_type, created)"
         " VALUES (?, 'queued', ?, ?, ?, ?, ?, ?)");
  s.text(1, id).text(2, params).text(3, cache_key);
  if (idempotency_key.empty()) s.null(4);
  else s.text(4, idempotency_key);
  s.blob(5, scene).text(6, content_type).real(7, unix_now());
  if (s.run() != SQLITE_DONE) return {};
  return id;
}

std::optional<std::string> Store::idempotent_locked(const std::string& idempotency_key) {
  Stmt s(db_, "SELECT id FROM jobs WHERE idempotency_key = ?");
  s.text(1, idempotency_key);
  if (s.row()) return s.col_text(0);
  return std::nullopt;
}

std::optional<std::string> Store::find_idempotent(const std::string& idempotency_key) {
  std::lock_guard lock(mutex_);
  return idempotent_locked(idempotency_key);
}

std::optional<std::string> Store::find_cached(const std::string& cache_key) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "SELECT id FROM jobs WHERE cache_key = ? AND state = 'succeeded' ORDER BY finished DESC LIMIT 1");
  s.text(1, cache_key);
  if (s.row()) return s.col_text(0);
  return std::nullopt;
}

std::optional<JobRecord> Store::get(const std::string& id) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, (std::string("SELECT ") + kColumns + " FROM jobs WHERE id = ?").c_str());
  s.text(1, id);
  if (!s.row()) return std::nullopt;
  return read_record(s);
}

std::vector<JobRecord> Store::list(std::optional<JobState> state, size_t limit, const std::string& after) {
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
  return out;
}

bool Store::claim(std::string& id, std::string& scene, std::string& params) {
  std::lock_guard lock(mutex_);
  Stmt s(db_,
         "UPDATE jobs SET state = 'running', started = ?, attempts = attempts + 1"
         " WHERE id = (SELECT id FROM jobs WHERE state = 'queued' ORDER BY created, id LIMIT 1)"
         " RETURNING id, scene, params");
  s.real(1, unix_now());
  if (!s.row()) return false;
  id = s.col_text(0);
  scene = s.col_blob(1);
  params = s.col_text(2);
  return true;
}

void Store::set_progress(const std::string& id, const std::string& progress_json) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "UPDATE jobs SET progress = ? WHERE id = ?");
  s.text(1, progress_json).text(2, id).run();
}

uint64_t Store::add_event(const std::string& id, const std::string& type, const std::string& data) {
  std::lock_guard lock(mutex_);
  Stmt u(db_, "UPDATE jobs SET event_seq = event_seq + 1 WHERE id = ? RETURNING event_seq");
  u.text(1, id);
  if (!u.row()) return 0;
  const int64_t seq = u.col_int(0);
  Stmt s(db_, "INSERT INTO events (job, seq, type, data) VALUES (?, ?, ?, ?)");
  s.text(1, id).integer(2, seq).text(3, type).text(4, data).run();
  return static_cast<uint64_t>(seq);
}

std::vector<Event> Store::events_after(const std::string& id, uint64_t after, size_t limit) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "SELECT seq, type, data FROM events WHERE job = ? AND seq > ? ORDER BY seq LIMIT ?");
  s.text(1, id).integer(2, static_cast<int64_t>(after)).integer(3, static_cast<int64_t>(limit));
  std::vector<Event> out;
  while (s.row()) out.push_back({static_cast<uint64_t>(s.col_int(0)), s.col_text(1), s.col_text(2)});
  return out;
}

void Store::succeed(const std::string& id, const std::string& result, const std::string& etag) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "UPDATE jobs SET state = 'succeeded', result = ?, etag = ?, finished = ? WHERE id = ? AND state = 'running'");
  s.blob(1, result).text(2, etag).real(3, unix_now()).text(4, id).run();
}

void Store::fail(const std::string& id, const std::string& error) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "UPDATE jobs SET state = 'failed', error = ?, finished = ? WHERE id = ? AND state = 'running'");
  s.text(1, error).real(2, unix_now()).text(3, id).run();
}

bool Store::cancel(const std::string& id) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "UPDATE jobs SET state = 'cancelled', finished = ? WHERE id = ? AND state IN ('queued', 'running')");
  s.real(1, unix_now()).text(2, id).run();
  return sqlite3_changes(db_) > 0;
}

void Store::requeue(const std::string& id) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "UPDATE jobs SET state = 'queued' WHERE id = ? AND state = 'running'");
  s.text(1, id).run();
}

std::optional<std::string> Store::result(const std::string& id) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "SELECT result FROM jobs WHERE id = ? AND state = 'succeeded'");
  s.text(1, id);
  if (!s.row()) return std::nullopt;
  return s.col_blob(0);
}

int Store::recover(int max_attempts) {
  std::lock_guard lock(mutex_);
  Stmt f(db_, "UPDATE jobs SET state = 'failed', finished = ?, error = 'the server stopped during each of its ' || attempts || ' attempts' WHERE state = 'running' AND attempts >= ?");
  f.real(1, unix_now()).integer(2, max_attempts).run();
  Stmt q(db_, "UPDATE jobs SET state = 'queued' WHERE state = 'running'");
  q.run();
  return sqlite3_changes(db_);
}

int Store::expire(double age_seconds) {
  std::lock_guard lock(mutex_);
  const double cutoff = unix_now() - age_seconds;
  Stmt e(db_, "DELETE FROM events WHERE job IN (SELECT id FROM jobs WHERE state IN ('succeeded', 'failed', 'cancelled') AND finished < ?)");
  e.real(1, cutoff).run();
  Stmt s(db_, "DELETE FROM jobs WHERE state IN ('succeeded', 'failed', 'cancelled') AND finished < ?");
  s.real(1, cutoff).run();
  return sqlite3_changes(db_);
}

size_t Store::count(JobState state) {
  std::lock_guard lock(mutex_);
  Stmt s(db_, "SELECT count(*) FROM jobs WHERE state = ?");
  s.text(1, to_string(state));
  return s.row() ? static_cast<size_t>(s.col_int(0)) : 0;
}

}  // namespace hemibake::server
