#include "pool.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <exception>

namespace hemibake::server {

void lower_thread_priority(int nice) {
  if (nice > 0) setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), nice);  // best effort
}

Pool::Pool(std::string name, unsigned threads, size_t max_waiting, int nice) : name_(std::move(name)), max_waiting_(max_waiting) {
  for (unsigned i = 0; i < std::max(1u, threads); ++i)
    threads_.emplace_back([this, nice] {
      lower_thread_priority(nice);
      loop();
    });
}

Pool::~Pool() { stop(); }

bool Pool::post(std::function<void()> work, std::function<void()> dropped) {
  {
    std::lock_guard lock(mutex_);
    // A task an idle thread is about to take does not wait.
    if (stopping_ || tasks_.size() >= max_waiting_ + idle_) return false;
    tasks_.push_back({std::move(work), std::move(dropped)});
  }
  ready_.notify_one();
  return true;
}

size_t Pool::waiting() {
  std::lock_guard lock(mutex_);
  return tasks_.size() > idle_ ? tasks_.size() - idle_ : 0;
}

void Pool::stop() {
  std::deque<Task> dropped;
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    dropped.swap(tasks_);
  }
  ready_.notify_all();
  for (auto& t : dropped) {
    try {
      if (t.dropped) t.dropped();
    } catch (const std::exception& e) {
      std::fprintf(stderr, "hemibake-server: %s pool: dropping a task failed: %s\n", name_.c_str(), e.what());
    }
  }
  for (auto& t : threads_)
    if (t.joinable() && t.get_id() != std::this_thread::get_id()) t.join();
}

void Pool::loop() {
  for (;;) {
    Task task;
    {
      std::unique_lock lock(mutex_);
      ++idle_;
      ready_.wait(lock, [&] { return stopping_ || !tasks_.empty(); });
      --idle_;
      if (tasks_.empty()) return;  // stopping, and nothing left that was taken before the stop
      task = std::move(tasks_.front());
      tasks_.pop_front();
    }
    try {
      task.work();
    } catch (const std::exception& e) {
      std::fprintf(stderr, "hemibake-server: %s pool: a task failed: %s\n", name_.c_str(), e.what());
    }
  }
}

}  // namespace hemibake::server
