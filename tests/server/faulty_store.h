// A job store that forwards to a real one, counts its reads, and fails writes on demand: for tests
// of what the service does when the store cannot write (a full disk) or when a request lands at a
// chosen moment (a DELETE during the result's write).
#pragma once

#include "hemibake/server/store.h"

#include <atomic>
#include <functional>
#include <memory>
#include <string>

namespace hemibake::test {

using server::Change;
using server::Created;
using server::Event;
using server::JobRecord;
using server::JobState;
using server::ReadError;

class FaultyStore final : public server::Store {
 public:
  /// Called before each write with its name ("create", "add_event", "set_progress", "succeed", "fail",
  /// "cancel", "requeue") and the job's id (empty for create). A non-empty answer fails the write
  /// with that message instead of making it. Set it before the service starts.
  using Fault = std::function<std::string(const std::string& write, const std::string& id)>;

  FaultyStore(std::unique_ptr<server::Store> inner, Fault fault) : inner_(std::move(inner)), fault_(std::move(fault)) {}

  /// Reads of job records and events (get, list, events_after).
  std::atomic<uint64_t> reads{0};

  Created create(const std::string& scene, const std::string& content_type, const std::string& params,
                 const std::string& cache_key, const std::string& idempotency_key) override {
    if (std::string e = fault_("create", ""); !e.empty()) return Created{{}, false, {}, e, true};
    return inner_->create(scene, content_type, params, cache_key, idempotency_key);
  }
  std::optional<std::pair<std::string, std::string>> find_idempotent(const std::string& key) override {
    return inner_->find_idempotent(key);
  }
  std::optional<std::string> find_cached(const std::string& cache_key) override { return inner_->find_cached(cache_key); }
  std::optional<JobRecord> get(const std::string& id, ReadError* why = nullptr) override {
    ++reads;
    return inner_->get(id, why);
  }
  std::vector<JobRecord> list(std::optional<JobState> state, size_t limit, const std::string& after,
                              ReadError* why = nullptr) override {
    ++reads;
    return inner_->list(state, limit, after, why);
  }
  bool claim(std::string& id, std::string& scene, std::string& params) override { return inner_->claim(id, scene, params); }
  bool set_progress(const std::string& id, const std::string& progress_json) override {
    if (!fault_("set_progress", id).empty()) return false;
    return inner_->set_progress(id, progress_json);
  }
  uint64_t add_event(const std::string& id, const std::string& type, const std::string& data) override {
    if (!fault_("add_event", id).empty()) return 0;
    return inner_->add_event(id, type, data);
  }
  std::vector<Event> events_after(const std::string& id, uint64_t after, size_t limit, ReadError* why = nullptr) override {
    ++reads;
    return inner_->events_after(id, after, limit, why);
  }
  Change succeed(const std::string& id, const std::string& result, const std::string& etag) override {
    if (std::string e = fault_("succeed", id); !e.empty()) return Change{false, JobState::kRunning, e};
    return inner_->succeed(id, result, etag);
  }
  Change fail(const std::string& id, const std::string& error) override {
    if (std::string e = fault_("fail", id); !e.empty()) return Change{false, JobState::kRunning, e};
    return inner_->fail(id, error);
  }
  Change cancel(const std::string& id) override {
    if (std::string e = fault_("cancel", id); !e.empty()) return Change{false, JobState::kRunning, e};
    return inner_->cancel(id);
  }
  Change requeue(const std::string& id) override {
    if (std::string e = fault_("requeue", id); !e.empty()) return Change{false, JobState::kRunning, e};
    return inner_->requeue(id);
  }
  std::optional<std::string> result(const std::string& id, ReadError* why = nullptr) override { return inner_->result(id, why); }
  std::optional<std::string> result_part(const std::string& id, uint64_t offset, size_t size, ReadError* why = nullptr) override {
    return inner_->result_part(id, offset, size, why);
  }
  int recover(int max_attempts) override { return inner_->recover(max_attempts); }
  int expire(double age_seconds) override { return inner_->expire(age_seconds); }
  size_t count(JobState state, ReadError* why = nullptr) override { return inner_->count(state, why); }

 private:
  std::unique_ptr<server::Store> inner_;
  Fault fault_;
};

}  // namespace hemibake::test
