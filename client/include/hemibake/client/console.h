// Where the `hemibake` commands write, and how they show a job's progress.
#pragma once

#include "hemibake/protocol/job.h"

#include <cstdio>
#include <string>

namespace hemibake::client {

/// Where a command writes. Results go to `out`, messages and progress to `err`.
struct Console {
  FILE* out = stdout;
  FILE* err = stderr;
  bool tty = false;  ///< err is a terminal: progress is one line redrawn in place; otherwise a
                     ///< line now and then (a log or a pipe still shows that a bake moves)
};

/// Prints a job's progress: one line redrawn in place on a terminal; elsewhere, once the job has
/// run for `interval_seconds`, a line at each change of phase and every `interval_seconds`.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(const Console& console, double interval_seconds = 5.0)
      : console_(console), interval_(interval_seconds) {}
  ~ProgressPrinter() { finish(); }
  void update(const protocol::JobProgress& progress);
  /// Ends the redrawn line (on a terminal).
  void finish();

 private:
  Console console_;
  double interval_;
  std::string phase_;
  double start_ = -1.0;  // when the first report came
  double last_ = -1e300;
  bool open_ = false;
};

}  // namespace hemibake::client
