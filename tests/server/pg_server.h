// A PostgreSQL server of Debian's packages (postgresql-15) for tests, on loopback and in a temporary
// directory: initdb, pg_ctl start on a free port, and everything removed at the end. PostgreSQL
// refuses to run as root, so when the tests run as root the server runs as the `postgres` user
// (runuser). available() is false, with the reason in why(), when the binaries are not installed.
#pragma once

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include <netinet/in.h>
#include <pwd.h>
#include <sys/socket.h>
#include <unistd.h>

namespace hemibake_test {

class PgServer {
 public:
  PgServer() {
    const char* env = std::getenv("HEMIBAKE_PG_BIN");
    bin_ = env ? env : "/usr/lib/postgresql/15/bin";
    if (!std::filesystem::exists(bin_ + "/initdb") || !std::filesystem::exists(bin_ + "/pg_ctl")) {
      why_ = "PostgreSQL 15 is not installed (no " + bin_ + "/initdb; scripts/setup.sh --test installs postgresql-15)";
      return;
    }
    if (geteuid() == 0) {
      if (!getpwnam("postgres")) {
        why_ = "running as root and there is no 'postgres' user to run PostgreSQL as";
        return;
      }
      as_ = "runuser -u postgres -- ";
    }
    char tmpl[] = "/tmp/hemibake-pg-XXXXXX";
    if (!mkdtemp(tmpl)) {
      why_ = "cannot make a temporary directory";
      return;
    }
    dir_ = tmpl;
    if (geteuid() == 0) sh("chown postgres " + dir_);
    port_ = free_port();
    if (sh(as_ + bin_ + "/initdb -D " + dir_ + "/db -A trust -U postgres --no-sync >" + dir_ + "/initdb.log 2>&1") != 0) {
      why_ = "initdb failed; see " + dir_ + "/initdb.log";
      return;
    }
    if (!start()) {
      why_ = "pg_ctl start failed; see " + dir_ + "/log";
      return;
    }
    ok_ = true;
  }
  ~PgServer() {
    if (!dir_.empty()) {
      stop();
      std::filesystem::remove_all(dir_);
    }
  }
  PgServer(const PgServer&) = delete;
  PgServer& operator=(const PgServer&) = delete;

  bool available() const { return ok_; }
  const std::string& why() const { return why_; }
  unsigned short port() const { return port_; }
  /// A fresh database for one test (so tests do not see each other's jobs).
  std::string create_database(const std::string& name) {
    psql("postgres", "DROP DATABASE IF EXISTS " + name);
    psql("postgres", "CREATE DATABASE " + name);
    return uri(name);
  }
  std::string uri(const std::string& db = "postgres") const {
    return "postgresql://postgres@127.0.0.1:" + std::to_string(port_) + "/" + db;
  }
  /// Runs one SQL statement with psql; its output (unaligned, tuples only), or "ERROR" if it failed.
  std::string psql(const std::string& db, const std::string& sql) const {
    const std::string cmd = bin_ + "/psql -X -q -A -t -h 127.0.0.1 -p " + std::to_string(port_) + " -U postgres -d " + db +
                            " -v ON_ERROR_STOP=1 -c \"" + sql + "\" 2>&1";
    std::string out;
    FILE* p = popen(cmd.c_str(), "r");
    if (!p) return "ERROR";
    char buf[4096];
    while (size_t n = fread(buf, 1, sizeof buf, p)) out.append(buf, n);
    const int rc = pclose(p);
    while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
    return rc == 0 ? out : "ERROR " + out;
  }
  bool start() {
    return sh(as_ + bin_ + "/pg_ctl -D " + dir_ + "/db -l " + dir_ + "/log -w -t 30 -o \"-c listen_addresses=127.0.0.1 -p " +
              std::to_string(port_) + " -k " + dir_ + " -c fsync=off -c max_connections=200\" start >/dev/null") == 0;
  }
  /// Stops the server at once (connections are cut, as when it crashes or the network drops).
  void stop() { sh(as_ + bin_ + "/pg_ctl -D " + dir_ + "/db -m immediate -w stop >/dev/null 2>&1"); }

 private:
  static int sh(const std::string& cmd) { return std::system(cmd.c_str()); }
  static unsigned short free_port() {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    ::close(fd);
    return ntohs(a.sin_port);
  }

  std::string bin_, as_, dir_, why_;
  unsigned short port_ = 0;
  bool ok_ = false;
};

}  // namespace hemibake_test
