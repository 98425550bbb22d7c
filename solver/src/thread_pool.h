// A fixed pool of worker threads for data-parallel loops inside one shot.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace hemibake::solver::detail {

class ThreadPool {
 public:
  /// `threads` >= 1 counts the calling thread: a pool of 1 runs everything inline.
  explicit ThreadPool(unsigned threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  unsigned size() const { return threads_; }

  /// How many chunks parallel_for splits `n` items into; fixed for a given n and pool size, so
  /// per-chunk outputs concatenated in chunk order are deterministic.
  size_t chunk_count(size_t n) const;

  /// Calls fn(begin, end, chunk) for consecutive ranges covering [0, n), in parallel; returns when
  /// all are done. fn must not throw.
  void parallel_for(size_t n, const std::function<void(size_t, size_t, size_t)>& fn);

 private:
  void worker_loop();
  void run_chunks(std::unique_lock<std::mutex>& lock);

  unsigned threads_;
  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable done_;
  const std::function<void(size_t, size_t, size_t)>* job_ = nullptr;
  size_t job_n_ = 0;
  size_t job_chunks_ = 0;
  size_t next_chunk_ = 0;
  std::atomic<size_t> chunks_done_{0};
  std::atomic<uint64_t> generation_{0};
  bool stop_ = false;
};

}  // namespace hemibake::solver::detail
