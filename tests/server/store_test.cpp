// The Store contract, run against both implementations (SQLite in a directory, PostgreSQL on a
// server started for these tests), and what only the shared store promises: claims of several
// nodes never overlap, a lease that ran out gives the job to another node and fences the first one
// out, one idempotency key makes one job when nodes race. Truth about the database is read with
// psql, outside the store under test.
#include "hemibake/server/store.h"
#include "pg_server.h"

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

namespace hemibake::server {
namespace {

using namespace std::chrono_literals;

hemibake_test::PgServer& pg() {
  static hemibake_test::PgServer server;
  return server;
}

int next_db = 0;

// A store of the kind the test is parametrised with, on a fresh directory or database.
class StoreTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    if (GetParam() == "postgresql") {
      if (!pg().available()) GTEST_SKIP() << "PostgreSQL tests skipped: " << pg().why();
      db_ = "store" + std::to_string(getpid()) + "_" + std::to_string(next_db++);
      uri_ = pg().create_database(db_);
    } else {
      dir_ = (std::filesystem::temp_directory_path() / ("hemibake-store-" + std::to_string(getpid()) + "-" + std::to_string(next_db++))).string();
      std::filesystem::remove_all(dir_);
    }
    store_ = open_store();
    ASSERT_TRUE(store_);
  }
  void TearDown() override {
    store_.reset();
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
  }
  std::unique_ptr<Store> open_store(PgOptions o = fast()) {
    std::string error;
    auto s = dir_.empty() ? Store::open_postgres(uri_, o, error) : Store::open(dir_, error);
    EXPECT_TRUE(s) << error;
    return s;
  }
  static PgOptions fast() {
    PgOptions o;
    o.expiry_interval = 0;
    return o;
  }
  std::string sql(const std::string& q) { return pg().psql(db_, q); }

  std::string dir_, db_, uri_;
  std::unique_ptr<Store> store_;
};

INSTANTIATE_TEST_SUITE_P(Both, StoreTest, ::testing::Values("sqlite", "postgresql"),
                         [](const auto& p) { return p.param; });

// A job goes queued -> running -> succeeded; its events come back in order with consecutive
// sequence numbers, its scene and result come back byte for byte (zero bytes included).
TEST_P(StoreTest, JobLifecycleKeepsScenesEventsAndResultsExactly) {
  std::string scene = "glTF";
  scene += std::string("\0\x01\xff", 3);
  const Created c = store_->create(scene, "model/gltf-binary", R"({"a":1})", "cache1", "");
  ASSERT_TRUE(c.error.empty()) << c.error;
  ASSERT_FALSE(c.existed);
  auto rec = store_->get(c.id);
  ASSERT_TRUE(rec);
  EXPECT_EQ(rec->state, JobState::kQueued);
  EXPECT_EQ(rec->scene_bytes, scene.size());
  EXPECT_EQ(rec->attempts, 0);
  std::string id, got_scene, params;
  ASSERT_TRUE(store_->claim(id, got_scene, params));
  EXPECT_EQ(id, c.id);
  EXPECT_EQ(got_scene, scene);
  EXPECT_EQ(params, R"({"a":1})");
  EXPECT_FALSE(store_->claim(id, got_scene, params));  // nothing else queued
  EXPECT_EQ(store_->get(c.id)->state, JobState::kRunning);
  EXPECT_EQ(store_->get(c.id)->attempts, 1);
  EXPECT_TRUE(store_->set_progress(c.id, R"({"shots":3})"));
  EXPECT_EQ(store_->get(c.id)->progress, R"({"shots":3})");
  EXPECT_EQ(store_->add_event(c.id, "state", R"({"state":"running"})"), 1u);
  EXPECT_EQ(store_->add_event(c.id, "progress", R"({"shots":3})"), 2u);
  EXPECT_EQ(store_->add_event("nosuchjob", "progress", "{}"), 0u);
  const auto ev = store_->events_after(c.id, 0, 10);
  ASSERT_EQ(ev.size(), 2u);
  EXPECT_EQ(ev[0].seq, 1u);
  EXPECT_EQ(ev[0].type, "state");
  EXPECT_EQ(ev[1].data, R"({"shots":3})");
  EXPECT_EQ(store_->events_after(c.id, 1, 10).size(), 1u);  // resume after the first
  EXPECT_EQ(store_->get(c.id)->last_event, 2u);
  EXPECT_FALSE(store_->result(c.id));
  std::string result(1000, '\0');
  for (size_t i = 0; i < result.size(); ++i) result[i] = static_cast<char>(i * 7);
  const Change done = store_->succeed(c.id, result, "\"e\"");
  EXPECT_TRUE(done.made);
  EXPECT_EQ(done.from, JobState::kRunning);
  EXPECT_EQ(store_->result(c.id), result);
  rec = store_->get(c.id);
  EXPECT_EQ(rec->state, JobState::kSucceeded);
  EXPECT_EQ(rec->etag, "\"e\"");
  EXPECT_EQ(rec->result_bytes, result.size());
  EXPECT_GT(rec->finished, 0.0);
  const Change again = store_->succeed(c.id, "other", "\"f\"");
  EXPECT_FALSE(again.made);
  EXPECT_EQ(again.from, JobState::kSucceeded);
  EXPECT_EQ(store_->result(c.id), result);
  EXPECT_EQ(store_->find_cached("cache1"), c.id);
  EXPECT_FALSE(store_->find_cached("cache2"));
}

// A job that this node's claim made running is this node's from the moment anyone can read it as
// running: a preview asked for in between was sent to "another node" that never answered (the
// handler test waited 30 s for it once, on a loaded machine). A reader follows the claims job by job.
TEST_P(StoreTest, JobReadAsRunningRunsHereAtOnce) {
  std::vector<std::string> ids;
  for (int i = 0; i < 200; ++i) ids.push_back(store_->create("s", "t", "{}", "k" + std::to_string(i), "").id);
  std::atomic<bool> done{false};
  std::thread claimer([&] {
    std::string id, scene, params;
    while (store_->claim(id, scene, params)) {
    }
    done = true;
  });
  int seen = 0, elsewhere = 0;
  for (size_t i = 0; i < ids.size();) {
    // Read the flag before the job: a job read as queued after the claimer had finished is a
    // lost claim, but one read as queued before it finished may have been claimed since.
    const bool claimer_finished = done;
    const auto rec = store_->get(ids[i]);
    ASSERT_TRUE(rec);
    if (rec->state == JobState::kRunning) {
      if (!store_->runs_here(ids[i])) ++elsewhere;
      ++seen;
      ++i;
    } else if (claimer_finished) {
      break;
    }
  }
  claimer.join();
  EXPECT_EQ(seen, 200);
  EXPECT_EQ(elsewhere, 0);
}

TEST_P(StoreTest, IdempotencyKeyNamesTheJobThatHoldsIt) {
  const Created a = store_->create("s", "t", "{}", "k1", "key");
  const Created b = store_->create("s2", "t", "{}", "k2", "key");
  EXPECT_FALSE(a.existed);
  EXPECT_TRUE(b.existed);
  EXPECT_EQ(b.id, a.id);
  EXPECT_EQ(b.cache_key, "k1");
  EXPECT_EQ(store_->count(JobState::kQueued), 1u);
  EXPECT_EQ(store_->find_idempotent("key")->first, a.id);
  EXPECT_FALSE(store_->find_idempotent("other"));
}

// Of cancel, fail and requeue, each applies only from the states it names.
TEST_P(StoreTest, StateChangesApplyOnlyFromTheirStates) {
  const Created q = store_->create("s", "t", "{}", "k", "");
  const Change c1 = store_->cancel(q.id);
  EXPECT_TRUE(c1.made);
  EXPECT_EQ(c1.from, JobState::kQueued);
  EXPECT_FALSE(store_->cancel(q.id).made);
  EXPECT_FALSE(store_->requeue(q.id).made);
  EXPECT_FALSE(store_->cancel("nosuchjob").made);
  const Created r = store_->create("s", "t", "{}", "k", "");
  std::string id, scene, params;
  ASSERT_TRUE(store_->claim(id, scene, params));
  EXPECT_TRUE(store_->requeue(id).made);
  EXPECT_EQ(store_->get(id)->state, JobState::kQueued);
  ASSERT_TRUE(store_->claim(id, scene, params));
  EXPECT_EQ(store_->get(id)->attempts, 2);
  const Change f = store_->fail(id, "broken");
  EXPECT_TRUE(f.made);
  EXPECT_EQ(store_->get(id)->error, "broken");
  EXPECT_FALSE(store_->succeed(id, "x", "\"x\"").made);
  EXPECT_FALSE(store_->result(id));
  EXPECT_EQ(store_->count(JobState::kFailed), 1u);
  EXPECT_EQ(store_->count(JobState::kCancelled), 1u);
}

TEST_P(StoreTest, ListPagesNewestFirstAndFilters) {
  std::vector<std::string> ids;
  for (int i = 0; i < 5; ++i) {
    ids.push_back(store_->create("s", "t", "{}", "k", "").id);
    std::this_thread::sleep_for(2ms);
  }
  ASSERT_TRUE(store_->cancel(ids[1]).made);
  const auto first = store_->list(std::nullopt, 2, "");
  ASSERT_EQ(first.size(), 2u);
  EXPECT_EQ(first[0].id, ids[4]);
  EXPECT_EQ(first[1].id, ids[3]);
  const auto second = store_->list(std::nullopt, 10, first[1].id);
  ASSERT_EQ(second.size(), 3u);
  EXPECT_EQ(second[0].id, ids[2]);
  EXPECT_EQ(second[2].id, ids[0]);
  const auto cancelled = store_->list(JobState::kCancelled, 10, "");
  ASSERT_EQ(cancelled.size(), 1u);
  EXPECT_EQ(cancelled[0].id, ids[1]);
}

TEST_P(StoreTest, ExpireDeletesOnlyOldFinishedJobs) {
  const Created old = store_->create("s", "t", "{}", "k", "");
  const Created queued = store_->create("s", "t", "{}", "k", "");
  ASSERT_TRUE(store_->cancel(old.id).made);
  store_->add_event(old.id, "state", "{}");
  EXPECT_EQ(store_->expire(3600), 0);  // not old enough
  std::this_thread::sleep_for(20ms);
  EXPECT_EQ(store_->expire(0.001), 1);
  EXPECT_FALSE(store_->get(old.id));
  EXPECT_TRUE(store_->events_after(old.id, 0, 10).empty());
  EXPECT_TRUE(store_->get(queued.id));
}

// A result read in parts, as a download sends it, comes back byte for byte: parts that start
// anywhere, the last one short, an empty part at the very end, nothing past it.
TEST_P(StoreTest, ResultPartsComeBackByteForByte) {
  const Created c = store_->create("s", "t", "{}", "k", "");
  std::string id, scene, params;
  ASSERT_TRUE(store_->claim(id, scene, params));
  std::string result(3 * (1 << 20) + 123, '\0');
  uint64_t x = 88172645463325252ull;  // xorshift: bytes that do not compress
  for (char& b : result) {
    x ^= x << 13, x ^= x >> 7, x ^= x << 17;
    b = static_cast<char>(x >> 56);
  }
  ASSERT_TRUE(store_->succeed(id, result, "\"e\"").made);
  ReadError why;
  std::string joined;
  for (uint64_t at = 0; at < result.size(); at += 1 << 20) {
    const auto part = store_->result_part(id, at, 1 << 20, &why);
    ASSERT_TRUE(part) << at << " " << why.error;
    joined += *part;
  }
  EXPECT_TRUE(joined == result);
  EXPECT_EQ(store_->result_part(id, 1, 7), result.substr(1, 7));
  EXPECT_EQ(store_->result_part(id, (1 << 20) - 3, 10), result.substr((1 << 20) - 3, 10));
  EXPECT_EQ(store_->result_part(id, result.size() - 5, 100), result.substr(result.size() - 5));
  EXPECT_EQ(store_->result_part(id, result.size(), 100), std::string());
  EXPECT_FALSE(store_->result_part(id, result.size() + 1, 100));
  EXPECT_EQ(store_->result_part(id, 0, 0), std::string());
  EXPECT_EQ(why.error, "");
}

// Reads that find nothing (no such job, no events, no result yet) say nothing went wrong: only a
// read the store could not answer sets ReadError. An id that is not UTF-8 (from a request's path)
// names no job either.
TEST_P(StoreTest, ReadsThatFindNothingAreNotFailures) {
  const Created c = store_->create("s", "t", "{}", "k", "");
  ReadError why;
  EXPECT_FALSE(store_->get("nosuchjob", &why));
  EXPECT_FALSE(store_->get("\xff\xfe", &why));
  EXPECT_TRUE(store_->events_after("\xff\xfe", 0, 10, &why).empty());
  EXPECT_TRUE(store_->events_after(c.id, 0, 10, &why).empty());
  EXPECT_TRUE(store_->list(JobState::kFailed, 10, "", &why).empty());
  EXPECT_FALSE(store_->result(c.id, &why));
  EXPECT_FALSE(store_->result_part(c.id, 0, 10, &why));
  EXPECT_TRUE(store_->get(c.id, &why));
  EXPECT_EQ(why.error, "");
  EXPECT_FALSE(why.busy);
}

// The shared store alone.
class PgStoreTest : public StoreTest {};
INSTANTIATE_TEST_SUITE_P(Shared, PgStoreTest, ::testing::Values("postgresql"), [](const auto& p) { return p.param; });

// While the database is down, reads give nothing and say why (it cannot be reached; the same read
// may be answered later), and writes fail the same way; once it is back, the same reads find the
// job, its events and its result.
TEST_P(PgStoreTest, ReadsAndWritesWhileTheDatabaseIsDownSayItCannotBeReached) {
  const Created c = store_->create("s", "t", "{}", "k", "");
  std::string id, scene, params;
  ASSERT_TRUE(store_->claim(id, scene, params));
  ASSERT_EQ(store_->add_event(id, "state", "{}"), 1u);
  ASSERT_TRUE(store_->succeed(id, "result", "\"e\"").made);
  pg().stop();
  struct Restart {  // the other tests need the database, whatever happens here
    bool up = false;
    ~Restart() {
      if (!up) pg().start();
    }
  } restart;
  auto unreachable = [](const ReadError& why) {
    return why.busy && why.error.find("the job store cannot be reached") != std::string::npos;
  };
  ReadError get, list, events, result, part;
  EXPECT_FALSE(store_->get(id, &get));
  EXPECT_TRUE(unreachable(get)) << get.error;
  EXPECT_TRUE(store_->list(std::nullopt, 10, "", &list).empty());
  EXPECT_TRUE(unreachable(list)) << list.error;
  EXPECT_TRUE(store_->events_after(id, 0, 10, &events).empty());
  EXPECT_TRUE(unreachable(events)) << events.error;
  EXPECT_FALSE(store_->result(id, &result));
  EXPECT_TRUE(unreachable(result)) << result.error;
  EXPECT_FALSE(store_->result_part(id, 0, 3, &part));
  EXPECT_TRUE(unreachable(part)) << part.error;
  const Created refused = store_->create("s", "t", "{}", "k2", "");
  EXPECT_TRUE(refused.id.empty());
  EXPECT_TRUE(refused.busy) << refused.error;
  const Change cancel = store_->cancel(c.id);
  EXPECT_FALSE(cancel.made);
  EXPECT_TRUE(cancel.busy) << cancel.error;
  ASSERT_TRUE(restart.up = pg().start());
  ReadError why;
  const auto rec = store_->get(id, &why);
  ASSERT_TRUE(rec) << why.error;
  EXPECT_EQ(rec->state, JobState::kSucceeded);
  EXPECT_EQ(store_->events_after(id, 0, 10, &why).size(), 1u);
  EXPECT_EQ(store_->result_part(id, 0, 3, &why), std::string("res"));
  EXPECT_EQ(store_->list(std::nullopt, 10, "", &why).size(), 1u);
  EXPECT_EQ(why.error, "");
}

// Results are kept uncompressed out of line, where PostgreSQL reads a substring from only the
// chunks that hold it: a download in parts reads a result once, not once per part. A store set up
// before this (the column's default, compressed) is changed when a node opens it, and the results
// it already holds, compressed, still read in parts.
TEST_P(PgStoreTest, ResultsAreStoredSoThatAPartIsReadAlone) {
  const std::string storage = "SELECT attstorage FROM pg_attribute WHERE attrelid = 'results'::regclass AND attname = 'data'";
  EXPECT_EQ(sql(storage), "e");
  ASSERT_EQ(sql("ALTER TABLE results ALTER COLUMN data SET STORAGE EXTENDED"), "");
  ASSERT_EQ(sql(storage), "x");
  const Created c = store_->create("s", "t", "{}", "k", "");
  std::string id, scene, params;
  ASSERT_TRUE(store_->claim(id, scene, params));
  std::string result;
  for (int i = 0; i < 200000; ++i) result += "part " + std::to_string(i) + ";";  // compresses
  ASSERT_TRUE(store_->succeed(id, result, "\"e\"").made);
  store_.reset();
  store_ = open_store();
  ASSERT_TRUE(store_);
  EXPECT_EQ(sql(storage), "e");
  EXPECT_EQ(store_->result_part(id, 500000, 1000), result.substr(500000, 1000));
  EXPECT_EQ(store_->result_part(id, result.size() - 10, 1000), result.substr(result.size() - 10));
}

// Three nodes claim 60 jobs from six threads at once: each job is claimed exactly once.
TEST_P(PgStoreTest, ClaimsOfSeveralNodesNeverOverlap) {
  std::vector<std::unique_ptr<Store>> nodes;
  for (int i = 0; i < 3; ++i) nodes.push_back(open_store());
  std::set<std::string> created;
  for (int i = 0; i < 60; ++i) created.insert(store_->create("s", "t", "{}", "k", "").id);
  std::mutex m;
  std::multiset<std::string> claimed;
  std::vector<std::thread> threads;
  for (int t = 0; t < 6; ++t)
    threads.emplace_back([&, t] {
      std::string id, scene, params;
      while (nodes[t % 3]->claim(id, scene, params)) {
        std::lock_guard lock(m);
        claimed.insert(id);
      }
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(claimed.size(), 60u);
  EXPECT_EQ(std::set<std::string>(claimed.begin(), claimed.end()), created);
  EXPECT_EQ(sql("SELECT count(*) FROM jobs WHERE state = 'running' AND attempts = 1"), "60");
}

// Nodes that submit with one idempotency key at the same moment make one job.
TEST_P(PgStoreTest, RacingIdempotencyKeysMakeOneJob) {
  std::vector<std::unique_ptr<Store>> nodes;
  for (int i = 0; i < 3; ++i) nodes.push_back(open_store());
  for (int round = 0; round < 10; ++round) {
    const std::string key = "race" + std::to_string(round);
    std::mutex m;
    std::set<std::string> ids;
    int made = 0;
    std::atomic<bool> go{false};
    std::vector<std::thread> threads;
    for (int t = 0; t < 6; ++t)
      threads.emplace_back([&, t] {
        while (!go) std::this_thread::yield();
        const Created c = nodes[t % 3]->create("s", "t", "{}", "k", key);
        std::lock_guard lock(m);
        EXPECT_TRUE(c.error.empty()) << c.error;
        ids.insert(c.id);
        made += !c.existed;
      });
    go = true;
    for (auto& t : threads) t.join();
    EXPECT_EQ(ids.size(), 1u);
    EXPECT_EQ(made, 1);
    EXPECT_EQ(sql("SELECT count(*) FROM jobs WHERE idempotency_key = '" + key + "'"), "1");
  }
}

// A node whose lease ran out (paused, cut off) is fenced out: once the job has gone back to the
// queue, and after another node claimed it, none of its writes for the job apply.
TEST_P(PgStoreTest, WritesAfterTheLeaseRanOutAreRefused) {
  PgOptions slow = fast();
  slow.lease_seconds = 60;
  auto a = open_store(slow);
  auto b = open_store(slow);
  const Created c = store_->create("s", "t", "{}", "k", "");
  std::string id, scene, params;
  ASSERT_TRUE(a->claim(id, scene, params));
  EXPECT_EQ(a->add_event(id, "state", R"({"by":"a"})"), 1u);
  // As if node a had been paused for longer than its lease.
  ASSERT_EQ(sql("UPDATE jobs SET lease_until = now() - interval '1 second' WHERE id = '" + id + "'"), "");
  EXPECT_FALSE(a->set_progress(id, R"({"by":"a"})"));   // expired, not yet taken back
  EXPECT_EQ(a->add_event(id, "progress", R"({"by":"a"})"), 0u);
  EXPECT_EQ(b->recover(3), 1);
  EXPECT_FALSE(a->succeed(id, "stale", "\"a\"").made);  // back in the queue
  ASSERT_TRUE(b->claim(id, scene, params));
  EXPECT_EQ(id, c.id);
  EXPECT_EQ(sql("SELECT attempts FROM jobs WHERE id = '" + id + "'"), "2");
  EXPECT_FALSE(a->set_progress(id, R"({"by":"a"})"));
  EXPECT_EQ(a->add_event(id, "progress", R"({"by":"a"})"), 0u);
  const Change stale = a->succeed(id, "stale", "\"a\"");
  EXPECT_FALSE(stale.made);
  EXPECT_EQ(stale.from, JobState::kRunning);
  EXPECT_FALSE(a->fail(id, "stale").made);
  EXPECT_FALSE(a->requeue(id).made);
  EXPECT_TRUE(b->set_progress(id, R"({"by":"b"})"));
  EXPECT_EQ(b->add_event(id, "state", R"({"by":"b"})"), 2u);
  EXPECT_TRUE(b->succeed(id, "fresh", "\"b\"").made);
  EXPECT_EQ(sql("SELECT convert_from(data, 'UTF8') FROM results WHERE job = '" + id + "'"), "fresh");
  EXPECT_EQ(sql("SELECT string_agg(data, ' ' ORDER BY seq) FROM events WHERE job = '" + id + "'"), R"({"by":"a"} {"by":"b"})");
  EXPECT_EQ(sql("SELECT progress FROM jobs WHERE id = '" + id + "'"), R"({"by":"b"})");
}

// A node that dies stops renewing: its job goes back to the queue after the lease, is claimed
// again, and fails once max_attempts runs have been cut short.
TEST_P(PgStoreTest, JobOfADeadNodeRunsAgainThenFailsAfterMaxAttempts) {
  PgOptions o = fast();
  o.lease_seconds = 0.6;
  o.max_attempts = 2;
  auto survivor = open_store(o);
  const Created c = store_->create("s", "t", "{}", "k", "");
  std::string id, scene, params;
  for (int attempt = 1; attempt <= 2; ++attempt) {
    {
      auto doomed = open_store(o);
      const auto t0 = std::chrono::steady_clock::now();
      ASSERT_TRUE(doomed->claim(id, scene, params));
      // Renewed while its node lives (several leases long).
      std::this_thread::sleep_for(1500ms);
      ASSERT_EQ(sql("SELECT state || ' ' || attempts FROM jobs WHERE id = '" + c.id + "'"), "running " + std::to_string(attempt))
          << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }  // the node is gone without a word (no requeue)
    const auto t0 = std::chrono::steady_clock::now();
    std::string state;
    while (std::chrono::steady_clock::now() - t0 < 5s) {
      state = sql("SELECT state FROM jobs WHERE id = '" + c.id + "'");
      if (state != "running") break;
      std::this_thread::sleep_for(50ms);
    }
    EXPECT_EQ(state, attempt == 1 ? "queued" : "failed");
  }
  EXPECT_NE(sql("SELECT error FROM jobs WHERE id = '" + c.id + "'").find("2 attempts"), std::string::npos);
}

// Expiry runs once per interval across all nodes, not once per node.
TEST_P(PgStoreTest, ExpiryRunsOnceAcrossNodes) {
  PgOptions o;
  o.expiry_interval = 3600;
  auto a = open_store(o);
  auto b = open_store(o);
  const Created j1 = store_->create("s", "t", "{}", "k", "");
  ASSERT_TRUE(store_->cancel(j1.id).made);
  std::this_thread::sleep_for(10ms);
  EXPECT_EQ(a->expire(0.001), 1);
  const Created j2 = store_->create("s", "t", "{}", "k", "");
  ASSERT_TRUE(store_->cancel(j2.id).made);
  std::this_thread::sleep_for(10ms);
  EXPECT_EQ(b->expire(0.001), 0);  // a ran it within the interval
  EXPECT_EQ(sql("SELECT count(*) FROM jobs"), "1");
}

TEST_P(PgStoreTest, SchemaHasAVersionAndANewerOneIsRefused) {
  EXPECT_EQ(sql("SELECT version FROM hemibake_schema"), "1");
  auto again = open_store();  // opening a set-up database changes nothing
  ASSERT_TRUE(again);
  EXPECT_EQ(sql("SELECT count(*) FROM hemibake_schema"), "1");
  again.reset();
  sql("UPDATE hemibake_schema SET version = 99");
  std::string error;
  EXPECT_FALSE(Store::open_postgres(uri_, fast(), error));
  EXPECT_NE(error.find("newer"), std::string::npos) << error;
}

TEST(PgStoreOpen, BadUriAndUnreachableServerAreReportedClearly) {
  std::string error;
  EXPECT_FALSE(Store::open_postgres("mysql://x@y/z", PgOptions{}, error));
  EXPECT_NE(error.find("postgresql://"), std::string::npos) << error;
  error.clear();
  EXPECT_FALSE(Store::open_postgres("postgresql://u@127.0.0.1:1/db", PgOptions{}, error));
  EXPECT_NE(error.find("cannot connect"), std::string::npos) << error;
  EXPECT_NE(error.find("127.0.0.1"), std::string::npos) << error;
}

}  // namespace
}  // namespace hemibake::server
