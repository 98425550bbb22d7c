#include "hemibake/server/service.h"

#include "hemibake/protocol/bake.h"
#include "hemibake/protocol/gltf.h"
#include "hemibake/protocol/job.h"
#include "hemibake/solver/solver.h"
#include "openapi.h"
#include "pool.h"
#include "web_assets.h"

#include <nlohmann/json.hpp>
#include <openssl/evp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <future>
#include <set>
#include <sstream>

namespace hemibake::server {
namespace {

using nlohmann::json;

// Text from requests (ids, parameter names, content types quoted in messages) may be invalid
// UTF-8, which json::dump refuses with an exception, and the request was answered 500. Such bytes
// become U+FFFD instead.
constexpr auto kReplaceInvalid = json::error_handler_t::replace;

std::string sha256_hex(const std::string& data) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_Digest(data.data(), data.size(), digest, &len, EVP_sha256(), nullptr);
  static const char* hex = "0123456789abcdef";
  std::string out;
  for (unsigned i = 0; i < len; ++i) {
    out += hex[digest[i] >> 4];
    out += hex[digest[i] & 15];
  }
  return out;
}

// The API description with the job parameters from their table, made once.
const std::string& openapi_document() {
  static const std::string text = [] {
    json doc = json::parse(kOpenApi);
    auto& parameters = doc["paths"]["/v1/jobs"]["post"]["parameters"];
    for (const auto& p : json::parse(protocol::params_openapi_json())) parameters.push_back(p);
    return doc.dump(-1, ' ', false, kReplaceInvalid);
  }();
  return text;
}

// `text` as an HTTP quoted-string (RFC 9110, section 5.6.4) for a header value. The text comes from
// the uploaded file (material names in warnings): a CR or LF copied through would end the header and
// let the file add headers or a whole response, so control characters and bytes outside ASCII
// become '?', and quotes and backslashes are escaped.
std::string quoted_string(const std::string& text) {
  std::string out = "\"";
  for (const char ch : text) {
    const auto c = static_cast<unsigned char>(ch);
    if (c == '"' || c == '\\') out += '\\';
    out += c < 0x20 || c >= 0x7f ? '?' : ch;
  }
  return out + "\"";
}

Response error(int status, const std::string& message) {
  Response r;
  r.status = status;
  r.body = json{{"error", message}}.dump(-1, ' ', false, kReplaceInvalid);
  return r;
}

// 503: the request was not begun (a pool is full, or the server is stopping); it may be sent again.
Response unavailable(const std::string& message, int retry_after) {
  Response r = error(503, message);
  r.headers.emplace_back("Retry-After", std::to_string(retry_after));
  return r;
}

Response stopping() { return unavailable("the server is stopping; retry in a moment", 5); }

// A store that could not answer a read or make a write: 503 while it is busy or cannot be reached
// (the same request may be answered in a moment), 500 for anything else; both name the cause. A
// read that failed is never answered as if it had found nothing (404, an empty list).
Response store_failed(const std::string& cause, bool busy) {
  if (busy) return unavailable(cause + "; retry in a moment", 5);
  return error(500, cause);
}
Response store_failed(const ReadError& why) { return store_failed(why.error, why.busy); }

// How long a preview waits for the worker's next shot, and for a claimed job to be registered.
constexpr auto kPreviewWait = std::chrono::seconds(30);
constexpr auto kRegisterWait = std::chrono::seconds(5);
// The lookup pool: store reads and small writes. Its threads mostly wait for the store's lock, so
// a few are enough; its queue holds requests, not scenes, so it may be long.
constexpr unsigned kLookupThreads = 2;
constexpr size_t kMaxLookups = 1024;

// What a job's bake may hold in memory, by part, in bytes: the growth of a server's peak RSS over
// its RSS before the job (`hemibake-server --workers 1`, one solver thread, Release; the figures in
// README under "Limits and failure behaviour"), with a margin over the largest seen.
// - Hemicubes: 233-273 bytes per pixel of the top face (resolution 400 and 1024), per solver thread.
// - Elements and patches: the solver's per-element arrays, the output mesh and the GLB written
//   from it, and per patch its clusters and shooters: about 1.3 KB per element and 1.45 KB per
//   patch (fitted to the cluttered room's 38 605 elements of 6136 patches and the sphere room's
//   164 695 of 159 466). Leaves of at least aeps of the scene's area number at most 1/aeps besides
//   patches that are smaller, but an aa bake splits further along sharp edges of light, down to
//   aeps / 256 (aa only): the atrium under the sun had 4.75/aeps elements past its patches after 600 shots
//   (most of them from its first shots), the cluttered room 3.25/aeps. So the count has no bound
//   from aeps alone, and the worker caps it (max_elements) at kSharpSplits/aeps past the patches,
//   about twice the most seen: the estimate's count is a limit the bake keeps.
// - The shot cache: the records kept are at most its size by their capacity, and the record of the
//   shot under way is dropped once it would outgrow the size on its own; seen 1.05-1.13 times the
//   size (the cluttered room, lava field, atrium and sphere room at 64 and 256 MB).
// - The scene as stored, as loaded and as written; images decoded at 4 bytes a pixel.
// - Fixed: the worker's allocator arenas and thread stacks, the job's own records.
// hr's links and the reference tracer's paths are not counted.
struct JobMemory {
  uint64_t hemicubes = 0, elements = 0, element_count = 0, patches = 0, patch_count = 0, images = 0, shot_cache = 0,
           scene = 0, fixed = 0;
  uint64_t total() const { return hemicubes + elements + patches + images + shot_cache + scene + fixed; }
};

constexpr double kSharpSplits = 8.0;

JobMemory job_memory(const protocol::JobSpec& spec, const protocol::SceneDocument& document, uint64_t scene_bytes,
                     unsigned threads) {
  constexpr uint64_t kCubeBytesPerPixel = 300, kVolumeCubeBytesPerPixel = 420, kElementBytes = 1600, kPatchBytes = 1600,
                     kFixedBytes = 16u << 20;
  constexpr uint64_t kFinerResolution = 400;  // shoot_piece's finer hemicube, for low resolutions
  JobMemory m;
  const uint64_t n = spec.params.resolution;
  const uint64_t finer = std::min(2 * n, kFinerResolution);
  m.hemicubes = kCubeBytesPerPixel * (n * n + (finer > n ? finer * finer : 0)) * std::max(1u, threads);
  // Volume clusters' whole cubes, one per level: six faces of n x n pixels (n at most 256), each
  // with its delta form factor, direction, solid angle, weight and list start (52 bytes), the
  // coarser levels a third more: 420 bytes per top-face pixel (counted from the solver's arrays,
  // not measured).
  if (spec.params.cluster_volume && spec.params.cluster_across && spec.params.cluster_size > 0.0 &&
      (spec.method == protocol::Method::kAntiAliased || spec.method == protocol::Method::kClassical ||
       spec.method == protocol::Method::kReference))
    m.hemicubes += kVolumeCubeBytesPerPixel * std::min<uint64_t>(n, 256) * std::min<uint64_t>(n, 256);
  const solver::Scene& scene = protocol::scene_of(document);
  m.patch_count = scene.patches.size();
  // A point or spot light's finer cube while it shoots (the solver's kMaxPointResolution, 256 a
  // side): two hemicubes back to back, as the hemicubes above per top-face pixel; aa and classical
  // bake the lights (a reference job's mesh is an aa solve's).
  constexpr uint64_t kPointResolution = 256;
  if (kPointResolution > n && spec.method != protocol::Method::kHierarchical &&
      std::any_of(scene.lights.begin(), scene.lights.end(),
                  [](const solver::Light& l) { return l.type != solver::Light::Type::kDirectional; }))
    m.hemicubes += kCubeBytesPerPixel * 2 * kPointResolution * kPointResolution;
  // Only the anti-aliased hemicube splits under aeps (a reference job's mesh is an aa solve's).
  const bool sharp = spec.method == protocol::Method::kAntiAliased || spec.method == protocol::Method::kReference;
  const double by_area = spec.params.aeps > 0 ? std::ceil((sharp ? kSharpSplits : 1.0) / spec.params.aeps) : 1e18;
  // Never fewer than the patches: each is an element from the start.
  m.element_count = std::max<uint64_t>(
      m.patch_count, std::min<uint64_t>(spec.params.max_elements, static_cast<uint64_t>(std::min(by_area, 1e18)) + m.patch_count));
  m.elements = kElementBytes * m.element_count;
  m.patches = kPatchBytes * m.patch_count;
  m.images = 4 * protocol::image_pixel_count(document);
  m.shot_cache = (static_cast<uint64_t>(spec.params.shot_cache_mb) << 20) * 5 / 4;
  m.scene = 3 * scene_bytes;  // as stored, as loaded, as written
  m.fixed = kFixedBytes;
  return m;
}

std::string megabytes(uint64_t bytes) { return std::to_string((bytes + (1u << 19)) >> 20) + " MB"; }

Response preview_missed() {
  Response r = error(409, "the job finished (or is between long shots) before a preview was made; ask again or fetch the result");
  r.headers.emplace_back("Retry-After", "1");
  return r;
}

Response no_preview_in_phase() {
  Response r = error(409, "no preview in this phase: hr has no solution until it has linked and gathered, and a reference job "
                          "has none while it traces paths; follow its events and fetch the result");
  r.headers.emplace_back("Retry-After", "5");
  return r;
}

Response not_running(const std::optional<JobRecord>& rec) {
  Response r = error(409, std::string("the job is ") + (rec ? to_string(rec->state) : "unknown") +
                              "; previews exist while it runs (a finished job has its result)");
  if (rec && rec->state == JobState::kQueued) r.headers.emplace_back("Retry-After", "5");
  return r;
}

// Calls `make` and replies with its response; the unexpected becomes 500 and a log line.
void answer(const Request& req, const Reply& reply, const std::function<Response()>& make) {
  Response r;
  try {
    r = make();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "hemibake-server: %s %s failed: %s\n", req.method.c_str(), req.target.c_str(), e.what());
    r = Response{500, {}, R"({"error":"internal error"})"};
  }
  reply(std::move(r));
}

Response not_allowed(const std::string& allow) {
  Response r = error(405, "use " + allow + " here");
  r.headers.emplace_back("Allow", allow);
  return r;
}

std::string percent_decode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '+') {
      out += ' ';
    } else if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
               std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
      out += static_cast<char>(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

// The first parameter named twice in a query string, or empty.
std::string repeated_name(const std::string& query) {
  std::set<std::string> seen;
  size_t start = 0;
  while (start < query.size()) {
    size_t end = query.find('&', start);
    if (end == std::string::npos) end = query.size();
    const std::string pair = query.substr(start, end - start);
    const std::string name = percent_decode(pair.substr(0, pair.find('=')));
    if (!pair.empty() && !seen.insert(name).second) return name;
    start = end + 1;
  }
  return {};
}

// Constant-time comparison, so that response timing does not reveal how much of a token matched.
bool same(const std::string& a, const std::string& b) {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  const size_t n = std::max(a.size(), b.size());
  for (size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    diff |= static_cast<unsigned char>(x ^ y);
  }
  return diff == 0;
}

}  // namespace

std::map<std::string, std::string> parse_query(const std::string& query) {
  std::map<std::string, std::string> out;
  size_t start = 0;
  while (start < query.size()) {
    size_t end = query.find('&', start);
    if (end == std::string::npos) end = query.size();
    const std::string pair = query.substr(start, end - start);
    const size_t eq = pair.find('=');
    if (!pair.empty()) out[percent_decode(pair.substr(0, eq))] = eq == std::string::npos ? "" : percent_decode(pair.substr(eq + 1));
    start = end + 1;
  }
  return out;
}

std::map<std::string, std::pair<std::string, std::string>> parse_multipart(const std::string& body, const std::string& boundary,
                                                                           std::string& repeated) {
  std::map<std::string, std::pair<std::string, std::string>> parts;
  const std::string delim = "--" + boundary;
  size_t pos = body.find(delim);
  while (pos != std::string::npos) {
    pos += delim.size();
    if (body.compare(pos, 2, "--") == 0) break;
    if (body.compare(pos, 2, "\r\n") == 0) pos += 2;
    const size_t head_end = body.find("\r\n\r\n", pos);
    if (head_end == std::string::npos) break;
    const std::string head = body.substr(pos, head_end - pos);
    const size_t next = body.find("\r\n" + delim, head_end + 4);
    if (next == std::string::npos) break;
    std::string name, type;
    std::istringstream lines(head);
    std::string line;
    while (std::getline(lines, line)) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      std::string lower = line;
      std::transform(lower.begin(), lower.end(), lower.begin(), ::tolower);
      if (lower.rfind("content-disposition:", 0) == 0) {
        const size_t n = lower.find("name=\"");
        if (n != std::string::npos) name = line.substr(n + 6, line.find('"', n + 6) - (n + 6));
      } else if (lower.rfind("content-type:", 0) == 0) {
        type = lower.substr(13);
        type.erase(0, type.find_first_not_of(' '));
      }
    }
    if (parts.count(name) && repeated.empty()) repeated = name;
    parts[name] = {type, body.substr(head_end + 4, next - (head_end + 4))};
    pos = next + 2;
  }
  return parts;
}

Service::Service(const ServiceOptions& o) : options_(o) {}

std::unique_ptr<Service> Service::start(const ServiceOptions& options, std::string& err) {
  std::unique_ptr<Store> store;
  if (!options.store_uri.empty()) {
    PgOptions po;
    po.lease_seconds = options.lease_seconds;
    po.max_attempts = options.max_attempts;
    store = Store::open_postgres(options.store_uri, po, err);
  } else {
    store = Store::open(options.data_dir, err);
  }
  if (!store) return nullptr;
  return start(options, std::move(store), err);
}

std::unique_ptr<Service> Service::start(const ServiceOptions& options, std::unique_ptr<Store> store, std::string&) {
  std::unique_ptr<Service> s(new Service(options));
  s->store_ = std::move(store);
  // Other nodes' changes (a shared store): new jobs wake the workers, new events the streams, and a
  // job this node lost (cancelled elsewhere, or its lease expired) stops at its next shot.
  StoreListener listener;
  listener.job_queued = [p = s.get()] { p->wake_.notify_all(); };
  listener.event = [p = s.get()](const std::string& id) { p->wake_streams(id); };
  listener.lost = [p = s.get()](const std::string& id) {
    std::lock_guard lock(p->mutex_);
    if (auto it = p->active_.find(id); it != p->active_.end()) it->second.token->cancel();
  };
  listener.preview_asked = [p = s.get()](const std::string& id) {
    std::lock_guard lock(p->mutex_);
    if (auto it = p->active_.find(id); it != p->active_.end()) {
      it->second.preview_wanted = true;
      it->second.remote_wanted = true;
    } else {
      p->remote_asks_[id] = std::chrono::steady_clock::now() + kRegisterWait;
      p->clock_wake_.notify_one();
    }
  };
  listener.preview_ready = [p = s.get()](const std::string& id) {
    std::vector<PreviewWait> waits;
    {
      std::lock_guard lock(p->mutex_);
      auto it = p->remote_previews_.find(id);
      if (it == p->remote_previews_.end()) return;
      waits = std::move(it->second);
      p->remote_previews_.erase(it);
    }
    auto work = [p, id, waits] {
      const auto glb = p->store_->take_preview(id);
      Response r;
      if (!glb) {
        r = error(503, "the preview could not be read from the job store; retry");
      } else {
        r.body = *glb;
        r.content_type = "model/gltf-binary";
        r.headers.emplace_back("Cache-Control", "no-store");
      }
      for (auto& w : waits) w.reply(r);
    };
    if (!p->lookups_->post(std::move(work), [waits] { for (auto& w : waits) w.reply(stopping()); }))
      for (auto& w : waits) w.reply(stopping());
  };
  s->store_->set_listener(std::move(listener));
  // An accepted job is never lost: what a crash left running runs again (up to max_attempts).
  s->store_->recover(options.max_attempts);
  s->store_->expire(options.expire_seconds);
  // Checking a scene is CPU work of up to seconds: half the cores, leaving the rest to the bakes.
  const unsigned checkers = options.check_threads != 0 ? options.check_threads
                                                       : std::max(1u, std::thread::hardware_concurrency() / 2);
  s->checks_ = std::make_unique<Pool>("check", checkers, options.max_checks, kBackgroundNice);
  s->lookups_ = std::make_unique<Pool>("lookup", kLookupThreads, kMaxLookups);
  s->running_ = true;
  s->clock_ = std::thread([p = s.get()] { p->clock_loop(); });
  s->end_writer_ = std::thread([p = s.get()] { p->end_writer_loop(); });
  const unsigned n = options.workers != 0 ? options.workers : std::max(1u, std::thread::hardware_concurrency());
  for (unsigned i = 0; i < n; ++i) s->workers_.emplace_back([p = s.get()] { p->worker_loop(); });
  return s;
}

Service::~Service() { stop(); }

void Service::stop() {
  if (store_) store_->set_listener({});  // returns once no call from the store runs into this service
  std::vector<Reply> waiting;
  std::vector<std::function<void(EventBatch)>> streams;
  {
    std::lock_guard lock(mutex_);
    if (!running_) return;
    running_ = false;
    for (auto& [id, a] : active_) {
      a.token->cancel();
      for (auto& w : a.waits) waiting.push_back(std::move(w.reply));
      a.waits.clear();
    }
    for (auto& [id, waits] : unregistered_)
      for (auto& w : waits) waiting.push_back(std::move(w.reply));
    unregistered_.clear();
    remote_asks_.clear();
    for (auto& [id, waits] : remote_previews_)
      for (auto& w : waits) waiting.push_back(std::move(w.reply));
    remote_previews_.clear();
    for (auto& [id, waits] : event_waits_)
      for (auto& w : waits) streams.push_back(std::move(w.reply));
    event_waits_.clear();
  }
  for (auto& reply : waiting) reply(stopping());
  for (auto& reply : streams) reply(EventBatch{503, {}, false, {}});
  wake_.notify_all();
  clock_wake_.notify_all();
  if (clock_.joinable()) clock_.join();
  {
    std::lock_guard lock(unwritten_mutex_);  // the end writer is waiting, or sees running_ false
  }
  ends_wake_.notify_all();
  if (end_writer_.joinable()) end_writer_.join();
  // Requests not begun are answered 503; those being answered finish (a preview asked for now is
  // refused, as running_ is false).
  checks_->stop();
  lookups_->stop();
  for (auto& w : workers_) w.join();
  workers_.clear();
}

// Answers the previews whose time is up: one thread for all of them, asleep until the earliest.
void Service::clock_loop() {
  std::unique_lock lock(mutex_);
  while (running_) {
    const auto now = std::chrono::steady_clock::now();
    auto next = std::chrono::steady_clock::time_point::max();
    std::vector<std::pair<Reply, Response>> due;
    auto sweep = [&](std::vector<PreviewWait>& waits, const std::function<Response()>& timeout) {
      for (auto it = waits.begin(); it != waits.end();) {
        if (it->until <= now) {
          due.emplace_back(std::move(it->reply), timeout());
          it = waits.erase(it);
        } else {
          next = std::min(next, it->until);
          ++it;
        }
      }
    };
    for (auto& [id, a] : active_) sweep(a.waits, preview_missed);
    for (auto it = remote_previews_.begin(); it != remote_previews_.end();) {
      sweep(it->second, preview_missed);
      it = it->second.empty() ? remote_previews_.erase(it) : std::next(it);
    }
    // Not registered in time: the job is taken to have ended (its state was read as running).
    for (auto it = unregistered_.begin(); it != unregistered_.end();) {
      sweep(it->second, [] {
        JobRecord running;
        running.state = JobState::kRunning;
        return not_running(running);
      });
      it = it->second.empty() ? unregistered_.erase(it) : std::next(it);
    }
    for (auto it = remote_asks_.begin(); it != remote_asks_.end();) {
      if (it->second <= now) {
        it = remote_asks_.erase(it);
      } else {
        next = std::min(next, it->second);
        ++it;
      }
    }
    // Event streams that waited long enough: time for a heartbeat.
    std::vector<std::function<void(EventBatch)>> heartbeats;
    for (auto it = event_waits_.begin(); it != event_waits_.end();) {
      auto& waits = it->second;
      for (auto w = waits.begin(); w != waits.end();) {
        if (w->until <= now) {
          heartbeats.push_back(std::move(w->reply));
          w = waits.erase(w);
        } else {
          next = std::min(next, w->until);
          ++w;
        }
      }
      it = waits.empty() ? event_waits_.erase(it) : std::next(it);
    }
    if (!due.empty() || !heartbeats.empty()) {
      lock.unlock();
      for (auto& [reply, response] : due) reply(std::move(response));
      for (auto& reply : heartbeats) reply(EventBatch{});
      lock.lock();
      continue;
    }
    if (next == std::chrono::steady_clock::time_point::max()) clock_wake_.wait(lock);
    else clock_wake_.wait_until(lock, next);
  }
}

void Service::count_response(int status) {
  std::lock_guard lock(metrics_mutex_);
  ++responses_[status];
}

void Service::worker_loop() {
  lower_thread_priority(kBackgroundNice);  // a bake never delays a request's answer
  while (running_) {
    std::string id, scene, params;
    if (!store_->claim(id, scene, params)) {
      // Idle: now and then, delete finished jobs past their time.
      const double now = unix_now();
      double last = last_expiry_.load();
      if (now - last > 600.0 && last_expiry_.compare_exchange_strong(last, now)) store_->expire(options_.expire_seconds);
      std::unique_lock lock(mutex_);
      wake_.wait_for(lock, std::chrono::milliseconds(250), [&] { return !running_; });
      continue;
    }
    bake(id, scene, params);
  }
}

void Service::bake(const std::string& id, const std::string& scene, const std::string& params) {
  const auto t0 = std::chrono::steady_clock::now();
  // Registered from the start: a cancellation or a preview request may come while it loads.
  solver::CancelToken token;
  if (!register_job(id, &token)) {
    store_->requeue(id);
    store_->release(id);
    return;
  }
  struct Unregister {
    Service* s;
    const std::string& id;
    ~Unregister() {
      s->unregister_job(id);
      // An end left to the end writer keeps the job's claim, so that its write stays fenced (the
      // writer releases it once the end is written or refused).
      if (!s->end_unwritten(id)) s->store_->release(id);
    }
  } unregister{this, id};
  if (const auto rec = store_->get(id); rec && rec->state == JobState::kCancelled) {
    // Cancelled between the claim and the registration, when no token could be reached.
    emit(id, "state", json{{"state", "cancelled"}}.dump(-1, ' ', false, kReplaceInvalid));
    return;
  }
  emit(id, "state", json{{"state", "running"}}.dump(-1, ' ', false, kReplaceInvalid));
  protocol::JobSpec spec;
  if (std::string e = protocol::parse_params_json(params, spec); !e.empty()) {
    end_job(id, nullptr, e);
    return;
  }
  spec.params.threads = options_.solver_threads;
  spec.params.max_elements = std::min<uint64_t>(spec.params.max_elements, options_.max_elements);
  spec.params.shot_cache_mb = std::min(spec.params.shot_cache_mb, options_.max_shot_cache_mb);
  const protocol::LoadLimits limits = load_limits();
  const auto loaded = protocol::load_gltf_memory(
      std::span(reinterpret_cast<const uint8_t*>(scene.data()), scene.size()), "", limits);
  if (!loaded.document) {
    end_job(id, nullptr, loaded.error);
    return;
  }
  // The element count the memory estimate allowed at submit is a limit the bake keeps (job_memory).
  spec.params.max_elements = job_memory(spec, *loaded.document, scene.size(), options_.solver_threads).element_count;
  bool over_budget = false;
  double last_report = -1.0;
  protocol::JobProgress last;  // the newest progress, stored or not: where a stopped bake stopped
  protocol::BakeHooks hooks;
  hooks.cancel = &token;
  // Stores a progress record (at most every 0.5 s, and the last one) and checks the time budget.
  hooks.progress = [&](const protocol::JobProgress& p) {
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (elapsed > options_.job_seconds) {
      over_budget = true;
      token.cancel();
    }
    // The bake reports "done" when it stops, also when it was stopped: that end is written below.
    if (p.phase == "done" && token.cancelled()) return;
    last = p;
    last.elapsed_seconds = elapsed;  // since the job started, loading included
    if (p.phase != "done" && elapsed - last_report < 0.5) return;
    last_report = elapsed;
    const std::string text = protocol::progress_json(last);
    store_->set_progress(id, text);
    emit(id, "progress", text);
  };
  hooks.previews_possible = [&](bool on) { set_previews(id, on); };
  hooks.preview_wanted = [&] { return take_preview_request(id); };
  hooks.preview = [&](std::vector<uint8_t> glb, const std::string& error) { give_preview(id, glb, error); };
  auto baked = protocol::bake(*loaded.document, spec, hooks);
  const solver::Stats& st = baked.solution.stats;
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Stopped by a DELETE (here or on another node: the store says cancelled already, as a DELETE
  // stores the cancel before it stops the bake; a job this node lost to an expired lease is fenced
  // off and nothing is written): the progress says so, with the fraction, shots and elements where
  // the bake stopped, before the stream is told.
  if (token.cancelled() && !over_budget && running_) {
    last.phase = "cancelled";
    last.eta_seconds = -1.0;
    last.elapsed_seconds = seconds;
    const std::string text = protocol::progress_json(last);
    store_->set_progress(id, text);
    emit(id, "progress", text);
  }
  if (st.cancelled) {
    if (over_budget) {
      end_job(id, nullptr, "the bake exceeded its time budget of " + std::to_string(options_.job_seconds) + " s");
    } else if (!running_) {
      store_->requeue(id);  // shutting down: the job runs again after the restart
    } else {
      emit(id, "state", json{{"state", "cancelled"}}.dump(-1, ' ', false, kReplaceInvalid));
    }
    return;
  }
  if (!baked.error.empty()) {
    end_job(id, nullptr, baked.error);
    return;
  }
  const std::string glb(baked.glb.begin(), baked.glb.end());
  if (!end_job(id, &glb, {})) return;
  std::lock_guard lock(metrics_mutex_);
  ++bakes_;
  bake_seconds_sum_ += seconds;
  size_t b = 0;
  while (b < bake_seconds_buckets_.size() && seconds > bake_seconds_buckets_[b]) ++b;
  ++bake_seconds_counts_[b];
  if (spec.method != protocol::Method::kHierarchical) {  // a reference job's shots are its aa solve's
    shots_ += st.shots;
    shot_seconds_ += st.seconds;
  }
}

// The end of running job `id`: succeeded with `result` when it is given, else failed with `failure`.
// The store's change is one atomic step from "running", so a DELETE that came first wins: the
// stream is then told "cancelled" (the DELETE of a running job leaves that to the worker), and the
// result is dropped. A result the store cannot write (a full disk) fails the job with the reason.
// A store that is busy (another program holds its lock) is tried again for a few seconds. If the
// end still cannot be written, the worker leaves it to the end writer (end_writer_loop), which tries
// again in the background, and takes the next job: no worker waits on a broken store, and the job
// ends (its stream too) within seconds of the store writing again, whatever the workers are doing.
// Returns true if the job succeeded.
bool Service::end_job(const std::string& id, const std::string* result, std::string failure) {
  Unwritten end{result ? std::optional<std::string>(*result) : std::nullopt, std::move(failure)};
  Change c;
  for (int attempt = 0;; ++attempt) {
    // A shared store that cannot be reached is not tried: back, it refuses the writes of a lease
    // that ran out until this node has renewed it (which it does first thing), and the end writer
    // waits for that.
    if (!store_->healthy()) {
      c.error = "the job store cannot be reached";
      break;
    }
    c = write_end(id, end);
    if (c.made || c.error.empty()) return c.made && end.result;
    // Only a lock is waited for here: a shared store that cannot be reached (busy too) is not, and
    // the end is left for write_unwritten().
    if (!c.busy || !store_->healthy() || attempt == 2) break;
    std::unique_lock lock(mutex_);
    if (wake_.wait_for(lock, std::chrono::seconds(1 << attempt), [&] { return !running_.load(); })) break;
  }
  if (end.result)
    std::fprintf(stderr, "hemibake-server: the result of job %s could not be stored yet (%s); it is kept and stored when the store writes again\n",
                 id.c_str(), c.error.c_str());
  else
    std::fprintf(stderr, "hemibake-server: the end of job %s could not be stored (%s); it is stored when the store writes again\n",
                 id.c_str(), end.failure.c_str());
  {
    std::lock_guard lock(unwritten_mutex_);
    unwritten_[id] = std::move(end);
    claims_kept_.insert(id);
  }
  ends_wake_.notify_one();
  return false;
}

// One try at writing a job's end. A result that cannot be written for any reason but a busy store
// becomes a failure with that reason, tried at once. Events go out for what was made.
Change Service::write_end(const std::string& id, Unwritten& end) {
  auto state_event = [](const char* state, const std::string& why) {
    json j = {{"state", state}};
    if (!why.empty()) j["error"] = why;
    return j.dump(-1, ' ', false, kReplaceInvalid);
  };
  Change c;
  if (end.result) {
    const std::string etag = "\"" + sha256_hex(*end.result) + "\"";
    c = store_->succeed(id, *end.result, etag);
    // A shared store that cannot be reached: the result is kept, not turned into a failure, and
    // written by the end writer once the store is back. The worker does not wait for it: it could
    // claim nothing meanwhile, and once the store is back it should be baking. The job stays this
    // node's (its claim is kept, the lease is renewed as soon as the store answers, also past its
    // expiry unless another node took the job back first), so the write is fenced as any other.
    if (c.made) {
      emit(id, "state", state_event("succeeded", {}));
      return c;
    }
    // Busy, or a shared store still away: the result is kept for a later try (end_job).
    if (c.error.empty() || c.busy || !store_->healthy()) {
      if (c.error.empty() && !note_cancelled(id))
        std::fprintf(stderr, "hemibake-server: the result of job %s was not stored: the job is no longer this node's "
                             "(its lease ran out and another node took it back; that run makes the result)\n",
                     id.c_str());
      return c;
    }
    std::fprintf(stderr, "hemibake-server: the result of %s could not be stored: %s\n", id.c_str(), c.error.c_str());
    end.failure = "the result could not be stored: " + c.error;
    end.result.reset();
  }
  c = store_->fail(id, end.failure);
  if (c.made) emit(id, "state", state_event("failed", end.failure));
  else if (c.error.empty()) note_cancelled(id);
  return c;
}

// A job's end found it no longer running: a DELETE came first, and its stream is told so.
bool Service::note_cancelled(const std::string& id) {
  const auto rec = store_->get(id);
  if (!rec || rec->state != JobState::kCancelled) return false;
  emit(id, "state", json{{"state", "cancelled"}}.dump(-1, ' ', false, kReplaceInvalid));
  return true;
}

bool Service::end_unwritten(const std::string& id) {
  std::lock_guard lock(unwritten_mutex_);
  return claims_kept_.count(id) > 0;
}

void Service::write_unwritten() {
  // A shared store is healthy again once this node has renewed its leases, also those that ran out
  // while it was away (unless another node took the job back): only then is a result's write fenced
  // by a lease that holds.
  if (!store_->healthy()) return;
  std::map<std::string, Unwritten> ends;
  {
    std::lock_guard lock(unwritten_mutex_);
    if (unwritten_.empty()) return;
    ends.swap(unwritten_);
  }
  for (auto it = ends.begin(); it != ends.end();) {
    const Change c = write_end(it->first, it->second);
    if (c.made || c.error.empty()) {
      {
        std::lock_guard lock(unwritten_mutex_);
        claims_kept_.erase(it->first);
      }
      store_->release(it->first);  // the claim its worker kept (bake's Unregister)
      it = ends.erase(it);
    } else {
      it = std::next(it);
    }
  }
  std::lock_guard lock(unwritten_mutex_);
  ends.merge(unwritten_);
  unwritten_.swap(ends);
}

// The ends the store refused, tried again in the background: 0.25 s after one is left here, then
// twice as long after each round the store refuses, up to every 5 s, for as long as the store
// refuses (a job's end is never dropped while the service runs; a restart queues the job again).
// The ends used to be tried only before a worker's next claim, so a job whose end was refused
// showed "running" for as long as every worker was busy with a long bake.
void Service::end_writer_loop() {
  constexpr auto kFirst = std::chrono::milliseconds(250), kLongest = std::chrono::milliseconds(5000);
  auto pause = kFirst;
  std::unique_lock lock(unwritten_mutex_);
  while (running_) {
    if (unwritten_.empty()) {
      pause = kFirst;
      ends_wake_.wait(lock, [&] { return !running_ || !unwritten_.empty(); });
      continue;
    }
    if (ends_wake_.wait_for(lock, pause, [&] { return !running_; })) break;
    lock.unlock();
    write_unwritten();
    lock.lock();
    pause = std::min(pause * 2, kLongest);
  }
}

size_t Service::unwritten() {
  std::lock_guard lock(unwritten_mutex_);
  return unwritten_.size();
}

protocol::LoadLimits Service::load_limits() const {
  protocol::LoadLimits limits;
  limits.allow_external_files = false;
  limits.max_file_bytes = options_.max_body_bytes;
  limits.max_triangles = options_.max_triangles;
  limits.max_image_pixels = static_cast<uint32_t>(std::min<uint64_t>(options_.max_image_pixels, 0xffffffffu));
  limits.max_total_image_pixels = options_.max_image_pixels;
  return limits;
}

std::optional<Response> Service::check_auth(const Request& request) const {
  if (options_.tokens.empty()) return std::nullopt;
  const std::string path = request.target.substr(0, request.target.find('?'));
  if (path == "/healthz" || path == "/readyz") return std::nullopt;
  // "Bearer" in any case, then one or more spaces (RFC 9110, section 11.1; RFC 6750, section 2.1).
  const auto it = request.headers.find("authorization");
  std::string given;
  if (it != request.headers.end()) {
    const std::string& value = it->second;
    const size_t space = value.find(' ');
    std::string scheme = value.substr(0, space);
    std::transform(scheme.begin(), scheme.end(), scheme.begin(), ::tolower);
    if (space != std::string::npos && scheme == "bearer") {
      given = value.substr(std::min(value.size(), value.find_first_not_of(' ', space)));
      given.erase(given.find_last_not_of(' ') + 1);
    }
  }
  bool ok = false;
  for (const auto& t : options_.tokens) ok = same(given, t) || ok;  // no early exit
  if (ok) return std::nullopt;
  Response r = error(401, given.empty() ? "a bearer token is required" : "the bearer token is not valid");
  r.headers.emplace_back("WWW-Authenticate", "Bearer realm=\"hemibake\"");
  return r;
}

std::string Service::events_job(const Request& request) {
  const std::string path = request.target.substr(0, request.target.find('?'));
  const std::string prefix = "/v1/jobs/", suffix = "/events";
  if (request.method != "GET" || path.rfind(prefix, 0) != 0 || path.size() <= prefix.size() + suffix.size() ||
      path.compare(path.size() - suffix.size(), suffix.size(), suffix) != 0)
    return {};
  const std::string id = path.substr(prefix.size(), path.size() - prefix.size() - suffix.size());
  return id.find('/') == std::string::npos ? id : std::string();
}

Response Service::job_json(const JobRecord& r, int status) {
  json j = {{"id", r.id},
            {"state", to_string(r.state)},
            {"params", json::parse(r.params, nullptr, false)},
            {"scene_bytes", r.scene_bytes},
            {"attempts", r.attempts},
            {"created", r.created},
            {"links", {{"self", "/v1/jobs/" + r.id}, {"events", "/v1/jobs/" + r.id + "/events"},
                       {"result", "/v1/jobs/" + r.id + "/result"}}}};
  if (!r.progress.empty()) j["progress"] = json::parse(r.progress, nullptr, false);
  if (r.started > 0) j["started"] = r.started;
  if (r.finished > 0) j["finished"] = r.finished;
  if (r.started > 0 && r.finished > 0) j["seconds"] = r.finished - r.started;
  if (!r.error.empty()) j["error"] = r.error;
  if (r.state == JobState::kSucceeded) j["result_bytes"] = r.result_bytes;
  Response resp;
  resp.status = status;
  resp.body = j.dump(-1, ' ', false, kReplaceInvalid);
  return resp;
}

Response Service::submit(const Request& req, const std::string& query) {
  protocol::JobSpec spec;
  // Which of two values was meant is not ours to guess.
  if (const std::string twice = repeated_name(query); !twice.empty()) return error(400, "parameter " + twice + " is given twice");
  std::map<std::string, std::string> values = parse_query(query);
  std::string scene, content_type;
  const auto ct_it = req.headers.find("content-type");
  std::string ct = ct_it == req.headers.end() ? "" : ct_it->second;
  std::string ct_lower = ct;
  std::transform(ct_lower.begin(), ct_lower.end(), ct_lower.begin(), ::tolower);
  const std::string media = ct_lower.substr(0, ct_lower.find(';'));
  if (media == "multipart/form-data") {
    const size_t b = ct_lower.find("boundary=");
    if (b == std::string::npos) return error(400, "multipart/form-data needs a boundary");
    std::string boundary = ct.substr(b + 9);
    if (!boundary.empty() && boundary.front() == '"') boundary = boundary.substr(1, boundary.find('"', 1) - 1);
    boundary = boundary.substr(0, boundary.find(';'));
    if (boundary.empty()) return error(400, "multipart/form-data needs a boundary");
    std::string repeated;
    const auto parts = parse_multipart(req.body, boundary, repeated);
    // Which of two scenes (or parameter sets) was meant is not ours to guess.
    if (!repeated.empty()) return error(400, "the form has more than one '" + repeated + "' part");
    const auto s = parts.find("scene");
    if (s == parts.end()) return error(400, "the form has no 'scene' file part");
    scene = s->second.second;
    content_type = s->second.first;
    if (const auto p = parts.find("params"); p != parts.end()) {
      const json j = json::parse(p->second.second, nullptr, false);
      if (j.is_discarded() || !j.is_object()) return error(400, "the 'params' part must be a JSON object");
      for (const auto& [k, v] : j.items())
        if (!values.count(k)) values[k] = v.is_string() ? v.get<std::string>() : v.dump(-1, ' ', false, kReplaceInvalid);
    }
  } else if (media == "model/gltf-binary" || media == "model/gltf+json" || media == "application/octet-stream") {
    scene = req.body;
    content_type = media;
  } else {
    Response r = error(415, "send the scene as model/gltf-binary, model/gltf+json or multipart/form-data (got '" + ct + "')");
    return r;
  }
  if (scene.empty()) return error(400, "the scene is empty");
  if (scene.size() > options_.max_body_bytes) return error(413, "the scene is larger than " + std::to_string(options_.max_body_bytes) + " bytes");
  if (std::string e = protocol::apply_params(values, spec); !e.empty()) return error(400, e);
  // The scene is checked before it is accepted: a bad file is refused now, not in the queue.
  const auto loaded = protocol::load_gltf_memory(std::span(reinterpret_cast<const uint8_t*>(scene.data()), scene.size()), "",
                                                 load_limits());
  if (!loaded.document) return error(422, loaded.error);
  if (std::string e = protocol::bake_error(*loaded.document, spec); !e.empty()) return error(422, e);
  // The memory the bake will ask for, with the server's caps applied as the worker applies them.
  {
    protocol::JobSpec capped = spec;
    capped.params.max_elements = std::min<uint64_t>(capped.params.max_elements, options_.max_elements);
    capped.params.shot_cache_mb = std::min(capped.params.shot_cache_mb, options_.max_shot_cache_mb);
    const JobMemory m = job_memory(capped, *loaded.document, scene.size(), options_.solver_threads);
    if (m.total() > options_.max_job_bytes)
      return error(422, "the job would need about " + megabytes(m.total()) + " of memory (hemicubes at resolution " +
                            std::to_string(capped.params.resolution) + ": " + megabytes(m.hemicubes) + "; up to " +
                            std::to_string(m.element_count) + " elements: " + megabytes(m.elements) + "; " +
                            std::to_string(m.patch_count) + " patches: " + megabytes(m.patches) + "; images: " +
                            megabytes(m.images) + "; shot cache: " + megabytes(m.shot_cache) + "; scene: " + megabytes(m.scene) +
                            "; the worker: " + megabytes(m.fixed) + "), more than the server's limit of " + megabytes(options_.max_job_bytes) +
                            " per job (hemibake-server --max-job-mb); lower resolution, max_elements or shot_cache_mb, or raise aeps");
  }
  const std::string params = protocol::params_json(spec);
  const std::string cache_key = sha256_hex(scene) + ":" + sha256_hex(params);
  const auto key_it = req.headers.find("idempotency-key");
  const std::string idem = key_it == req.headers.end() ? "" : key_it->second;
  if (idem.size() > 200) return error(400, "the Idempotency-Key is longer than 200 characters");
  // A key names one submission: the same key with another scene or other parameters is a client's
  // mistake, not a retry (IETF draft-ietf-httpapi-idempotency-key-header, section 2.7).
  auto reused = [&](const std::string& job) {
    return error(422, "the Idempotency-Key was sent before with another scene or other parameters (job " + job +
                          "); a new submission needs a new key");
  };
  const auto held = idem.empty() ? std::nullopt : store_->find_idempotent(idem);
  if (held && held->second != cache_key) return reused(held->first);
  // The same scene and parameters as a finished job: its answer at once.
  if (auto cached = store_->find_cached(cache_key)) {
    auto rec = store_->get(*cached);
    if (rec) {
      Response r = job_json(*rec, 200);
      r.headers.emplace_back("Location", "/v1/jobs/" + rec->id);
      r.headers.emplace_back("X-Hemibake-Cache", "hit");
      return r;
    }
  }
  // A retry of an accepted submission gets its job even when the queue has filled since; any other
  // submission counts against the queue, with a key or without (a fresh key per request used to
  // skip the limit).
  const bool retry = held.has_value();
  if (!retry && store_->count(JobState::kQueued) >= options_.max_queue) {
    Response r = error(429, "the queue is full (" + std::to_string(options_.max_queue) + " jobs); retry later");
    r.headers.emplace_back("Retry-After", "30");
    return r;
  }
  const Created created = store_->create(scene, content_type, params, cache_key, idem);
  if (created.id.empty()) {
    std::fprintf(stderr, "hemibake-server: a job could not be stored: %s\n", created.error.c_str());
    if (created.busy) return store_failed(created.error, true);
    return error(500, "the job could not be stored");
  }
  if (created.existed && created.cache_key != cache_key) return reused(created.id);  // taken meanwhile
  const std::string& id = created.id;
  wake_.notify_one();
  auto rec = store_->get(id);
  if (!rec) return error(500, "the job could not be read back");
  Response r = job_json(*rec, created.existed ? 200 : 202);
  r.headers.emplace_back("Location", "/v1/jobs/" + id);
  for (const auto& w : loaded.warnings) r.headers.emplace_back("Warning", "199 hemibake " + quoted_string(w));
  return r;
}

Response Service::metrics() {
  std::ostringstream m;
  // Job counts come from the store. While it cannot answer they are left out, not given as 0 (a
  // dashboard would show an empty queue and no running jobs), and hemibake_store_up is 0, as the
  // exporters of databases do (pg_up, mysql_up). The answer is still 200 with this node's own
  // metrics: Prometheus's `up` keeps meaning that the node answers, and an alert on
  // hemibake_store_up == 0 (or on absent(hemibake_jobs)) tells the store's outage apart.
  ReadError why;
  std::vector<std::pair<JobState, size_t>> counts;
  for (JobState s : {JobState::kQueued, JobState::kRunning, JobState::kSucceeded, JobState::kFailed, JobState::kCancelled}) {
    const size_t n = store_->count(s, &why);
    if (!why.error.empty()) break;
    counts.emplace_back(s, n);
  }
  const bool store_up = why.error.empty();
  m << "# HELP hemibake_store_up Whether the job store answered this scrape (0: it is busy or cannot be reached, and the job "
       "counts are left out).\n# TYPE hemibake_store_up gauge\n";
  m << "hemibake_store_up " << (store_up ? 1 : 0) << "\n";
  if (store_up) {
    m << "# HELP hemibake_jobs Jobs in the store by state.\n# TYPE hemibake_jobs gauge\n";
    for (const auto& [state, n] : counts) m << "hemibake_jobs{state=\"" << to_string(state) << "\"} " << n << "\n";
    m << "# HELP hemibake_queue_depth Jobs waiting for a worker.\n# TYPE hemibake_queue_depth gauge\n";
    m << "hemibake_queue_depth " << counts.front().second << "\n";
  }
  m << "# HELP hemibake_job_ends_unwritten Jobs whose end (result or failure) the store could not write yet; tried again "
       "in the background.\n# TYPE hemibake_job_ends_unwritten gauge\n";
  m << "hemibake_job_ends_unwritten " << unwritten() << "\n";
  m << "# HELP hemibake_checks_waiting Submitted scenes waiting for a check thread.\n# TYPE hemibake_checks_waiting gauge\n";
  m << "hemibake_checks_waiting " << checks_->waiting() << "\n";
  {
    std::lock_guard lock(mutex_);
    size_t previews = 0;
    for (const auto& [id, a] : active_) previews += a.waits.size();
    for (const auto& [id, waits] : unregistered_) previews += waits.size();
    m << "# HELP hemibake_previews_waiting Preview requests waiting for their job's next shot.\n"
         "# TYPE hemibake_previews_waiting gauge\n";
    m << "hemibake_previews_waiting " << previews << "\n";
  }
  std::lock_guard lock(metrics_mutex_);
  m << "# HELP hemibake_bake_seconds Time to bake a job.\n# TYPE hemibake_bake_seconds histogram\n";
  uint64_t cum = 0;
  for (size_t i = 0; i < bake_seconds_buckets_.size(); ++i) {
    cum += bake_seconds_counts_[i];
    m << "hemibake_bake_seconds_bucket{le=\"" << bake_seconds_buckets_[i] << "\"} " << cum << "\n";
  }
  cum += bake_seconds_counts_.back();
  m << "hemibake_bake_seconds_bucket{le=\"+Inf\"} " << cum << "\n";
  m << "hemibake_bake_seconds_sum " << bake_seconds_sum_ << "\nhemibake_bake_seconds_count " << bakes_ << "\n";
  m << "# HELP hemibake_shots_per_second Shots per second of solver time, over all bakes.\n"
       "# TYPE hemibake_shots_per_second gauge\n";
  m << "hemibake_shots_per_second " << (shot_seconds_ > 0 ? static_cast<double>(shots_) / shot_seconds_ : 0.0) << "\n";
  m << "# HELP hemibake_http_responses HTTP responses by status code.\n# TYPE hemibake_http_responses counter\n";
  for (const auto& [status, n] : responses_) m << "hemibake_http_responses{code=\"" << status << "\"} " << n << "\n";
  Response r;
  r.body = m.str();
  r.content_type = "text/plain; version=0.0.4";
  return r;
}

// The running job's current state as GLB, made by its worker between two shots. Nothing waits
// here: the request becomes an entry that the worker completes after its next shot, or the clock
// when the time is up.
void Service::preview(const std::string& id, const Reply& reply) {
  ReadError why;
  const auto state = store_->get(id, &why);
  if (!why.error.empty()) return reply(store_failed(why));
  if (!state) return reply(error(404, "no job " + id));
  // Running on another node (a shared store): that node makes it after its next shot.
  const bool elsewhere = state->state == JobState::kRunning && !store_->runs_here(id);
  std::unique_lock lock(mutex_);
  if (!running_) {
    lock.unlock();
    return reply(stopping());
  }
  const auto now = std::chrono::steady_clock::now();
  if (elsewhere) {
    remote_previews_[id].push_back({now + kPreviewWait, reply});
    lock.unlock();
    clock_wake_.notify_one();
    store_->ask_preview(id);
    return;
  }
  auto it = active_.find(id);
  if (it == active_.end() && state->state == JobState::kRunning) {
    // Claimed by a worker that has not registered it yet: it waits a moment for that.
    unregistered_[id].push_back({now + kRegisterWait, reply});
    lock.unlock();
    clock_wake_.notify_one();
    return;
  }
  if (it != active_.end() && !it->second.previews) {
    lock.unlock();
    return reply(no_preview_in_phase());
  }
  if (it == active_.end() || state->state != JobState::kRunning) {
    lock.unlock();
    return reply(not_running(state));
  }
  it->second.waits.push_back({now + kPreviewWait, reply});
  it->second.preview_wanted = true;
  lock.unlock();
  clock_wake_.notify_one();
}

bool Service::register_job(const std::string& id, solver::CancelToken* token) {
  {
    std::lock_guard lock(mutex_);
    if (!running_) return false;
    Active& a = active_[id];
    a.token = token;
    // Previews asked for between the claim and now: from here on they wait for a shot.
    if (auto u = unregistered_.find(id); u != unregistered_.end()) {
      const auto until = std::chrono::steady_clock::now() + kPreviewWait;
      for (auto& w : u->second) a.waits.push_back({until, std::move(w.reply)});
      unregistered_.erase(u);
      a.preview_wanted = !a.waits.empty();
    }
    // Asked for by another node meanwhile: made after the first shot, for the store.
    if (auto r = remote_asks_.find(id); r != remote_asks_.end()) {
      a.preview_wanted = a.remote_wanted = true;
      remote_asks_.erase(r);
    }
  }
  clock_wake_.notify_one();
  return true;
}

// The job's event streams are woken once more: a stream that read the final state event while the
// job was still registered here could not end there (final_event_written), and waited for a next
// event that never comes, a heartbeat (15 s) late: `hemibake bake --server` took 16 s for a job of 1 s.
void Service::unregister_job(const std::string& id) {
  std::vector<PreviewWait> waits;
  {
    std::lock_guard lock(mutex_);
    if (auto it = active_.find(id); it != active_.end()) {
      waits = std::move(it->second.waits);
      active_.erase(it);
    }
  }
  for (auto& w : waits) w.reply(preview_missed());
  wake_streams(id);
}

// Off while no displayable solution exists (hr, reference tracing): who waits is told so.
void Service::set_previews(const std::string& id, bool on) {
  std::vector<PreviewWait> waits;
  {
    std::lock_guard lock(mutex_);
    auto it = active_.find(id);
    if (it == active_.end()) return;
    it->second.previews = on;
    if (!on) {
      waits = std::move(it->second.waits);
      it->second.waits.clear();
      it->second.preview_wanted = false;
    }
  }
  for (auto& w : waits) w.reply(no_preview_in_phase());
}

bool Service::take_preview_request(const std::string& id) {
  std::lock_guard lock(mutex_);
  auto it = active_.find(id);
  if (it == active_.end() || !it->second.preview_wanted) return false;
  it->second.preview_wanted = false;
  it->second.preview_taken = std::chrono::steady_clock::now();
  return true;
}

// Every preview waiting gets this one, also those asked for while it was written (it is at most
// one shot older than they are).
void Service::give_preview(const std::string& id, const std::vector<uint8_t>& glb, const std::string& failure) {
  std::vector<PreviewWait> waits;
  bool remote = false;
  std::chrono::steady_clock::duration writing{};
  {
    std::lock_guard lock(mutex_);
    auto it = active_.find(id);
    if (it == active_.end()) return;
    writing = std::chrono::steady_clock::now() - it->second.preview_taken;
    waits = std::move(it->second.waits);
    it->second.waits.clear();
    it->second.preview_wanted = false;
    remote = it->second.remote_wanted;
    it->second.remote_wanted = false;
  }
  if (remote && !glb.empty()) store_->put_preview(id, std::string(glb.begin(), glb.end()));
  if (waits.empty()) return;
  Response r;
  if (glb.empty()) {
    std::fprintf(stderr, "hemibake-server: the preview of %s could not be written: %s\n", id.c_str(), failure.c_str());
    r = error(500, "the preview could not be written: " + failure);
  } else {
    r.body.assign(glb.begin(), glb.end());
    r.content_type = "model/gltf-binary";
    r.headers.emplace_back("Cache-Control", "no-store");
    // What the preview cost the worker, apart from the wait for its shot: a page paces its
    // requests by it.
    const double ms = std::chrono::duration<double, std::milli>(writing).count();
    r.headers.emplace_back("Server-Timing", "write;dur=" + std::to_string(std::lround(ms)));
  }
  for (auto& w : waits) w.reply(r);
}

// What never waits, answered on the caller's (I/O) thread; nullopt for the rest.
std::optional<Response> Service::answer_at_once(const Request& req, const std::string& path) const {
  // The web page and its files, from memory and without a token (its API requests carry one).
  if (auto page = web::answer(req, path)) return page;
  if (auto denied = check_auth(req)) return denied;
  const bool get = req.method == "GET";
  if ((path == "/healthz" || path == "/readyz" || path == "/metrics" || path == "/openapi.json") && !get) return not_allowed("GET, HEAD");
  if (path == "/healthz") return Response{200, {}, R"({"status":"ok"})"};
  if (path == "/readyz") {
    if (!running_) return error(503, "not ready");
    if (!store_->healthy()) return error(503, "the job store cannot be reached; reconnecting");
    return Response{200, {}, R"({"status":"ready"})"};
  }
  if (path == "/openapi.json") return Response{200, {}, openapi_document()};
  return std::nullopt;
}

void Service::handle_async(Request req, Reply reply) {
  const size_t q = req.target.find('?');
  const std::string path = req.target.substr(0, q);
  std::string query = q == std::string::npos ? "" : req.target.substr(q + 1);
  if (auto now = answer_at_once(req, path)) return reply(std::move(*now));
  if (path == "/v1/jobs" && req.method == "POST") {
    // Loading and checking a scene is seconds of CPU for a large one: on the check pool, bounded.
    const size_t limit = checks_->max_waiting();
    auto work = [this, req = std::move(req), query = std::move(query), reply] {
      answer(req, reply, [&] { return submit(req, query); });
    };
    if (!checks_->post(std::move(work), [reply] { reply(stopping()); }))
      reply(running_ ? unavailable("the server has " + std::to_string(limit) + " scenes waiting to be checked; retry in a moment", 5)
                     : stopping());
    return;
  }
  // The rest reads (or writes) the store, whose lock a large scene's write holds for a while: on the
  // lookup pool.
  auto on_lookups = [&](std::function<void()> work) {
    if (!lookups_->post(std::move(work), [reply] { reply(stopping()); }))
      reply(running_ ? unavailable("the server has too many requests waiting; retry in a moment", 1) : stopping());
  };
  // A preview: taken in there, answered by the job's worker.
  const std::string prefix = "/v1/jobs/", suffix = "/preview";
  if (req.method == "GET" && path.rfind(prefix, 0) == 0 && path.size() > prefix.size() + suffix.size() &&
      path.compare(path.size() - suffix.size(), suffix.size(), suffix) == 0 &&
      path.find('/', prefix.size()) == path.size() - suffix.size()) {
    const std::string id = path.substr(prefix.size(), path.size() - prefix.size() - suffix.size());
    return on_lookups([this, req = std::move(req), id, reply] {
      try {
        preview(id, reply);
      } catch (const std::exception& e) {
        std::fprintf(stderr, "hemibake-server: %s %s failed: %s\n", req.method.c_str(), req.target.c_str(), e.what());
        reply(Response{500, {}, R"({"error":"internal error"})"});
      }
    });
  }
  on_lookups([this, req = std::move(req), path, query = std::move(query), reply] {
    answer(req, reply, [&] { return route(req, path, query); });
  });
}

Response Service::handle(const Request& request) {
  auto done = std::make_shared<std::promise<Response>>();
  auto answered = done->get_future();
  handle_async(request, [done](Response r) { done->set_value(std::move(r)); });
  Response r = answered.get();
  if (r.parts) {
    for (uint64_t at = 0; at < r.parts_size;) {
      const auto part = r.parts(at, 1 << 20);
      if (!part || part->empty()) break;
      r.body += *part;
      at += part->size();
    }
    r.parts = nullptr;
  }
  return r;
}

void Service::events_async(const std::string& id, uint64_t after, std::chrono::milliseconds wait,
                           std::function<void(EventBatch)> reply) {
  const auto until = std::chrono::steady_clock::now() + wait;
  auto work = [this, id, after, until, reply] { read_events(id, after, until, reply); };
  if (!lookups_->post(std::move(work), [reply] { reply(EventBatch{503, {}, false, {}}); })) reply(EventBatch{503, {}, false, {}});
}

// Reads the events after `after`; with none, and the job still going, waits for the next (the
// stream's end is an event too). No stream polls the store: each read follows an event.
// Whether the last event of finished job `r` says how it ended. The worker of a running job writes
// that event after the state changed (a DELETE changes it first), on another node with a shared
// store; a stream that ended in between would miss it. Jobs that end with no such event (failed at
// a restart after their last attempt) end their streams after a grace period, unless this node's
// worker still runs the job: a DELETE that lands during a long step (seconds, under load) is
// answered by the worker only at the step's end, and a stream that ended at the grace period
// missed its "cancelled" progress and state.
bool Service::final_event_written(const JobRecord& r) {
  {
    std::lock_guard lock(mutex_);
    if (active_.count(r.id) != 0) return false;
  }
  if (unix_now() - r.finished > 3.0 || r.last_event == 0) return true;
  const auto last = store_->events_after(r.id, r.last_event - 1, 1);
  if (last.empty() || last[0].type != "state") return false;
  const json j = json::parse(last[0].data, nullptr, false);
  if (!j.is_object() || !j.contains("state") || !j["state"].is_string()) return false;
  const auto state = job_state_from(j["state"].get<std::string>());
  return state && finished(*state);
}

void Service::read_events(const std::string& id, uint64_t after, std::chrono::steady_clock::time_point until,
                          std::function<void(EventBatch)> reply) {
  for (;;) {
    uint64_t written = 0;
    {
      std::lock_guard lock(mutex_);
      written = events_written_;
    }
    EventBatch b;
    try {
      ReadError why;
      b.events = store_->events_after(id, after, 100, &why);
      const auto rec = why.error.empty() ? store_->get(id, &why) : std::nullopt;
      // Finished, and no event came between the read above and the record's: the stream ends.
      // A store that cannot answer ends nothing: the stream asks again (503 before it began).
      if (!why.error.empty()) b = EventBatch{503, {}, false, why.error};
      else if (!rec) b.status = 404;
      else b.end = finished(rec->state) && b.events.empty() && store_->events_after(id, after, 1).empty() &&
                   final_event_written(*rec);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "hemibake-server: reading the events of %s failed: %s\n", id.c_str(), e.what());
      b = EventBatch{503, {}, false, {}};
    }
    if (b.status != 200 || !b.events.empty() || b.end || std::chrono::steady_clock::now() >= until) return reply(std::move(b));
    std::unique_lock lock(mutex_);
    if (!running_) {
      lock.unlock();
      return reply(EventBatch{503, {}, false, {}});
    }
    // An event stored after the read above and before this lock would wake no one: read again.
    if (events_written_ != written) continue;
    event_waits_[id].push_back({until, after, std::move(reply)});
    lock.unlock();
    clock_wake_.notify_one();
    return;
  }
}

void Service::emit(const std::string& id, const std::string& type, const std::string& data) {
  store_->add_event(id, type, data);
  wake_streams(id);
}

void Service::wake_streams(const std::string& id) {
  std::vector<std::pair<std::string, EventWait>> waits;
  {
    std::lock_guard lock(mutex_);
    if (!running_) return;
    ++events_written_;
    for (auto it = event_waits_.begin(); it != event_waits_.end();) {
      if (!id.empty() && it->first != id) {
        ++it;
        continue;
      }
      for (auto& w : it->second) waits.emplace_back(it->first, std::move(w));
      it = event_waits_.erase(it);
    }
  }
  // Named copies, not structured bindings: clang 14 (the sanitizer build's) cannot capture those.
  for (auto& entry : waits) {
    const auto& job = entry.first;
    const auto& w = entry.second;
    auto work = [this, job, w] { read_events(job, w.after, w.until, w.reply); };
    if (!lookups_->post(std::move(work), [reply = w.reply] { reply(EventBatch{503, {}, false, {}}); })) w.reply(EventBatch{503, {}, false, {}});
  }
}

// The requests that read or write the store (not submissions, not previews), on the lookup pool.
Response Service::route(const Request& req, const std::string& path, const std::string& query) {
  if (path == "/metrics") return metrics();
  if (path == "/v1/jobs") {
    if (req.method != "GET") return not_allowed("GET, HEAD, POST");
    const auto args = parse_query(query);
    std::optional<JobState> state;
    if (auto it = args.find("state"); it != args.end()) {
      state = job_state_from(it->second);
      if (!state) return error(400, "state must be queued, running, succeeded, failed or cancelled");
    }
    size_t limit = 50;
    if (auto it = args.find("limit"); it != args.end()) {
      char* end = nullptr;
      const long v = std::strtol(it->second.c_str(), &end, 10);
      if (*end != '\0' || v < 1 || v > 1000) return error(400, "limit must be 1 to 1000");
      limit = static_cast<size_t>(v);
    }
    const std::string after = args.count("after") ? args.at("after") : "";
    ReadError why;
    // An unknown cursor would read as an empty last page.
    if (!after.empty() && !store_->get(after, &why)) {
      if (!why.error.empty()) return store_failed(why);
      return error(400, "no job " + after + " to page after (it may have expired); list again without 'after'");
    }
    const auto jobs = store_->list(state, limit, after, &why);
    if (!why.error.empty()) return store_failed(why);
    json list = json::array();
    for (const auto& r : jobs) list.push_back(json::parse(job_json(r, 200).body));
    json body = {{"jobs", list}};
    if (jobs.size() == limit) body["next"] = "/v1/jobs?limit=" + std::to_string(limit) + "&after=" + jobs.back().id +
                                             (state ? std::string("&state=") + to_string(*state) : "");
    Response r;
    r.body = body.dump(-1, ' ', false, kReplaceInvalid);
    return r;
  }
  const std::string prefix = "/v1/jobs/";
  if (path.rfind(prefix, 0) == 0) {
    std::string rest = path.substr(prefix.size());
    const size_t slash = rest.find('/');
    const std::string id = rest.substr(0, slash);
    const std::string sub = slash == std::string::npos ? "" : rest.substr(slash + 1);
    ReadError why;
    auto rec = store_->get(id, &why);
    if (!why.error.empty()) return store_failed(why);
    if (!rec) return error(404, "no job " + id);
    if (sub.empty()) {
      if (req.method == "GET") return job_json(*rec, 200);
      if (req.method == "DELETE") {
        auto over = [](JobState s) {
          return error(409, std::string("the job ") + (s == JobState::kCancelled ? "is already cancelled" : std::string("has already ") + to_string(s)));
        };
        if (finished(rec->state)) return over(rec->state);
        // One step in the store decides between this and the worker's end of the job.
        const Change c = store_->cancel(id);
        if (!c.error.empty()) return unavailable("the cancellation could not be stored: " + c.error + "; retry in a moment", 5);
        if (!c.made) {
          rec = store_->get(id, &why);
          if (!why.error.empty()) return store_failed(why);
          return rec ? over(rec->state) : error(404, "no job " + id);
        }
        {
          std::lock_guard lock(mutex_);
          if (auto it = active_.find(id); it != active_.end()) it->second.token->cancel();
        }
        // A running job's worker tells its stream, once the bake has stopped.
        if (c.from == JobState::kQueued) emit(id, "state", json{{"state", "cancelled"}}.dump(-1, ' ', false, kReplaceInvalid));
        // The cancel is stored; if the job cannot be read back, the record read before it says so.
        if (auto now = store_->get(id)) rec = std::move(now);
        else rec->state = JobState::kCancelled;
        return job_json(*rec, 200);
      }
      return not_allowed("GET, HEAD, DELETE");
    }
    if (sub == "result" && req.method == "GET") {
      if (rec->state != JobState::kSucceeded) {
        Response r = error(409, std::string("the job is ") + to_string(rec->state) + (rec->error.empty() ? "" : ": " + rec->error));
        if (!finished(rec->state)) r.headers.emplace_back("Retry-After", "5");
        return r;
      }
      const auto inm = req.headers.find("if-none-match");
      if (inm != req.headers.end() && inm->second == rec->etag) {
        Response r;
        r.status = 304;
        r.headers.emplace_back("ETag", rec->etag);
        r.content_type.clear();
        return r;
      }
      // Sent in parts read from the store as the connection takes them: a request holds one part,
      // never the whole result (64 event streams and downloads of a 36 MB job held it each).
      if (!store_->result_part(id, 0, 0, &why)) {
        if (!why.error.empty()) return store_failed(why);
        return error(404, "the result has expired");
      }
      Response r;
      r.parts_size = rec->result_bytes;
      r.parts = [store = store_.get(), id](uint64_t offset, size_t size) { return store->result_part(id, offset, size); };
      r.content_type = "model/gltf-binary";
      r.headers.emplace_back("ETag", rec->etag);
      r.headers.emplace_back("Content-Disposition", "attachment; filename=\"" + id + ".glb\"");
      return r;
    }
    // GET of an event stream is the session's; what comes here is a HEAD (or a test's GET): the
    // stream's status and type, without the stream.
    if (sub == "events" && req.method == "GET") {
      Response r;
      r.content_type = "text/event-stream";
      r.headers.emplace_back("Cache-Control", "no-cache");
      return r;
    }
    if (sub == "result" || sub == "preview" || sub == "events") return not_allowed("GET");
    return error(404, "no such resource: " + path);
  }
  return error(404, "no such resource: " + path);
}

}  // namespace hemibake::server
