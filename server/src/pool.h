// A few threads for request work that may wait (parsing a scene, the store's lock), so that the
// I/O threads never do. Bounded: past `max_waiting` tasks the caller is told no and answers 503,
// instead of the queue (and the request bodies it holds) growing without end.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace hemibake::server {

/// Lowers the calling thread's scheduling priority by `nice` steps (Linux: nice is per thread, and
/// threads it starts inherit it). For CPU-bound work (bakes, scene checks), so that on a saturated
/// machine the I/O threads, which wake for moments, still get a core at once.
void lower_thread_priority(int nice);

/// Nice steps of CPU-bound threads (weight 110 against 1024 for the I/O threads).
constexpr int kBackgroundNice = 10;

class Pool {
 public:
  /// Starts `threads` threads (at least one) at `nice` steps below normal priority. `name` appears
  /// in log lines.
  Pool(std::string name, unsigned threads, size_t max_waiting, int nice = 0);
  ~Pool();
  Pool(const Pool&) = delete;
  Pool& operator=(const Pool&) = delete;

  /// Runs `work` on a pool thread. Returns false, keeping neither function, when `max_waiting`
  /// tasks wait for a busy thread already or the pool has stopped. A task the pool stops before it began gets
  /// `dropped` called instead (on the stopping thread). Neither may throw past the pool: an
  /// exception is logged and the thread goes on.
  bool post(std::function<void()> work, std::function<void()> dropped);
  /// Refuses new tasks, drops those not begun, waits for the running ones. Idempotent.
  void stop();
  /// Tasks waiting for a thread.
  size_t waiting();
  size_t max_waiting() const { return max_waiting_; }

 private:
  struct Task {
    std::function<void()> work, dropped;
  };
  void loop();

  std::string name_;
  size_t max_waiting_;
  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<Task> tasks_;
  size_t idle_ = 0;  // threads waiting for a task
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace hemibake::server
