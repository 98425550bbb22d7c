// The `hemibake` commands that talk to a hemibake-server.
#pragma once

#include "hemibake/client/console.h"
#include "hemibake/protocol/job.h"

#include <map>
#include <string>

namespace hemibake::client {

struct Remote {
  std::string host;
  std::string port;
  std::string token;  ///< bearer token, or empty
  /// How long a command keeps trying a request the server answers 503 (its job store busy or
  /// unreachable, too much waiting, stopping) or 429 (its queue full), waiting as Retry-After says,
  /// or whose connection fails (a server restarting; see below); 0: not at all.
  double retry_seconds = 60.0;
};

/// Parses http://HOST[:PORT][/] into `out`; returns an error message or an empty string.
std::string parse_server(const std::string& url, Remote& out);

// Each command returns its exit status: 0 done, 1 failed (the reason is on console.err). A 503 or
// 429 is tried again for up to Remote::retry_seconds (see there), saying so on console.err, and so
// is a refused connection, or one cut before the answer: every command's requests may be repeated
// (GETs, the cancel's DELETE), and a submission carries an Idempotency-Key, fresh for each
// submission and the same on its every try, so that a try whose answer was lost does not make a
// second job.

/// hemibake submit: prints the job id (or stores it in *id_out instead).
int remote_submit(const Remote& r, const std::string& path, const protocol::JobSpec& spec, const Console& console,
                  std::string* id_out = nullptr);
/// The job's JSON, indented.
int remote_status(const Remote& r, const std::string& id, const Console& console);
/// Follows the job's event stream with its progress; 0 if it succeeded.
int remote_watch(const Remote& r, const std::string& id, const Console& console);
int remote_fetch(const Remote& r, const std::string& id, const std::string& out_path, const Console& console);
/// A 409 (the job has ended) counts as done if the job is cancelled and an earlier try was cut
/// after it was sent (that try may have cancelled it).
int remote_cancel(const Remote& r, const std::string& id, const Console& console);
/// The newest 100 jobs, one line each (`state` empty: all).
int remote_list(const Remote& r, const std::string& state, const Console& console);
/// submit + watch + fetch.
int remote_bake(const Remote& r, const std::string& in, const std::string& out, const protocol::JobSpec& spec,
                const Console& console);

}  // namespace hemibake::client
