#include "thread_pool.h"

#include <algorithm>
#include <chrono>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

namespace hemibake::solver::detail {

namespace {
constexpr size_t kMinParallelItems = 64;

// A solve calls parallel_for thousands of times a second, often for well under a millisecond of
// work: a worker put to sleep after each loop and woken by the next costs tens of microseconds per
// call on a virtual machine. Threads spin this long for the next loop (or for the last chunk of
// this one) before they sleep.
constexpr auto kSpin = std::chrono::microseconds(200);
// Spins between looks at the clock and yields of the core: a yield is a system call, not a thing to
// do every turn.
constexpr uint32_t kSpinTurns = 64;

inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  _mm_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}

// Spins until done() or kSpin has passed; returns done(). Every kSpinTurns it yields the core, so
// that where more threads want to run than there are cores (two solves at once, a build beside a
// bake) a waiting thread gives way to one with work: two Cornell boxes solved at once on two cores
// with two threads each took 1.44 times as long as with one thread each while they only spun.
template <class Done>
bool spin_until(Done&& done) {
  const auto until = std::chrono::steady_clock::now() + kSpin;
  for (uint32_t i = 1;; ++i) {
    if (done()) return true;
    cpu_relax();
    if (i % kSpinTurns == 0) {
      if (std::chrono::steady_clock::now() > until) return done();
      std::this_thread::yield();
    }
  }
}
}  // namespace

ThreadPool::ThreadPool(unsigned threads) : threads_(std::max(1u, threads)) {
  for (unsigned i = 1; i < threads_; ++i) workers_.emplace_back([this] { worker_loop(); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
    generation_.fetch_add(1, std::memory_order_release);
  }
  wake_.notify_all();
  for (auto& w : workers_) w.join();
}

size_t ThreadPool::chunk_count(size_t n) const {
  if (n == 0) return 0;
  // A few chunks per thread balance uneven work (hemicube faces differ in size and depth); small
  // loops run on the calling thread, where waking the workers would cost more than it saves.
  if (threads_ == 1 || n < kMinParallelItems) return 1;
  return std::min(n, static_cast<size_t>(threads_) * 4);
}

void ThreadPool::run_chunks(std::unique_lock<std::mutex>& lock) {
  while (next_chunk_ < job_chunks_) {
    const size_t chunk = next_chunk_++;
    const size_t n = job_n_, chunks = job_chunks_;
    const auto* job = job_;
    lock.unlock();
    (*job)(n * chunk / chunks, n * (chunk + 1) / chunks, chunk);
    lock.lock();
    if (chunks_done_.fetch_add(1, std::memory_order_release) + 1 == job_chunks_) done_.notify_all();
  }
}

void ThreadPool::worker_loop() {
  uint64_t seen = 0;
  for (;;) {
    spin_until([&] { return generation_.load(std::memory_order_acquire) != seen; });
    std::unique_lock lock(mutex_);
    wake_.wait(lock, [&] { return stop_ || generation_.load(std::memory_order_relaxed) != seen; });
    if (stop_) return;
    seen = generation_.load(std::memory_order_relaxed);
    run_chunks(lock);
  }
}

void ThreadPool::parallel_for(size_t n, const std::function<void(size_t, size_t, size_t)>& fn) {
  const size_t chunks = chunk_count(n);
  if (chunks == 0) return;
  if (threads_ == 1 || chunks == 1) {
    for (size_t c = 0; c < chunks; ++c) fn(n * c / chunks, n * (c + 1) / chunks, c);
    return;
  }
  std::unique_lock lock(mutex_);
  job_ = &fn;
  job_n_ = n;
  job_chunks_ = chunks;
  next_chunk_ = 0;
  chunks_done_.store(0, std::memory_order_relaxed);
  generation_.fetch_add(1, std::memory_order_release);
  wake_.notify_all();
  run_chunks(lock);
  if (chunks_done_.load(std::memory_order_acquire) != chunks) {
    lock.unlock();
    spin_until([&] { return chunks_done_.load(std::memory_order_acquire) == chunks; });
    lock.lock();
    done_.wait(lock, [&] { return chunks_done_.load(std::memory_order_relaxed) == chunks; });
  }
  job_ = nullptr;
}

}  // namespace hemibake::solver::detail
