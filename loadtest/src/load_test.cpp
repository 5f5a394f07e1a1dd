#include "vts/loadtest/load_test.hpp"

#include <time.h>

#include <algorithm>
#include <cstdio>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <utility>

#include "vts/base/worker_pool.hpp"
#include "vts/client/tile_cache.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/renderer/tile_stream.hpp"

namespace vts::loadtest {

namespace {

using Clock = std::chrono::steady_clock;
using Ns = std::chrono::nanoseconds;

std::uint64_t ns(Ns d) {
  return d.count() > 0 ? std::uint64_t(d.count()) : 0;
}

// CPU time of the calling thread, in ms (the demand's own cost, whatever else the machine runs).
double thread_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return double(t.tv_sec) * 1e3 + double(t.tv_nsec) / 1e6;
}

// The kind an error is counted under: the HTTP status when one came, else what the fetcher said.
std::string error_kind(const client::PayloadResult& r) {
  if (r.transfer && r.transfer->status >= 400) return "http_" + std::to_string(r.transfer->status);
  if (!r.error) return "unknown";
  const std::string& m = r.error->message;
  const auto has = [&m](const char* s) { return m.find(s) != std::string::npos; };
  if (r.error->code == ErrorCode::truncated || has("partial body")) return "truncated";
  if (has("timed out")) return "timeout";
  if (has("connection refused") || has("could not connect") || has("resolve")) return "connect";
  if (has("connection reset")) return "reset";
  if (has("empty reply")) return "empty_reply";
  if (has(": TLS: ")) return "tls";
  return error_code_name(r.error->code);
}

Clock::time_point now_of(const LoadTestOptions& o) {
  return o.now ? o.now() : Clock::now();
}

// How often the calling thread looks whether the loops are done, or the drain is.
constexpr auto kPoll = std::chrono::milliseconds(5);

// Everything measured, shared by all viewers (one short lock per completed request).
class Metrics {
 public:
  explicit Metrics(Clock::time_point start) : start_(start) {}

  // `kind`: the error's kind when the engine judged it (undecodable), else from r.
  void request_done(const client::PayloadResult& r, Clock::time_point intended,
                    Clock::time_point sent, Clock::time_point done, const char* kind = nullptr) {
    const Ns lag = sent - intended;
    const std::uint64_t total = ns(done - intended);
    std::uint64_t bytes = 0;
    if (r.kind == client::PayloadResult::Kind::ok && r.tile) bytes = r.tile->payload.size();
    const bool error = r.kind == client::PayloadResult::Kind::error || kind != nullptr;
    std::lock_guard lock(mutex_);
    ++requests_;
    report_.total.record(total);
    if (r.transfer) {
      report_.queue_time.record(ns(lag + r.transfer->queued));
      if (r.transfer->first_byte.count() > 0) report_.ttfb.record(ns(lag + r.transfer->first_byte));
      if (r.transfer->status > 0) ++report_.by_status[r.transfer->status];
    } else {
      report_.queue_time.record(ns(lag));
    }
    if (!error && r.kind == client::PayloadResult::Kind::ok) {  // an undecodable tile is an error
      switch (r.from) {
        case client::PayloadResult::From::ram:
          ++report_.tiers.ram;
          break;
        case client::PayloadResult::From::disk:
          ++report_.tiers.disk;
          break;
        case client::PayloadResult::From::network:
          ++report_.tiers.network;
          break;
      }
    }
    if (error) {
      ++errors_;
      ++report_.errors_by_kind[kind ? std::string(kind) : error_kind(r)];
    }
    bytes_ += bytes;
    const auto second = std::size_t(std::max<std::int64_t>(
        0, std::chrono::duration_cast<std::chrono::seconds>(done - start_).count()));
    if (second < 24 * 3600) {
      if (seconds_.size() <= second) {
        seconds_.resize(second + 1);
        second_latency_.resize(second + 1);
      }
      ++seconds_[second].requests;
      seconds_[second].bytes += bytes;
      seconds_[second].errors += error ? 1 : 0;
      second_latency_[second].record(total);
    }
  }

  void move_done(Ns first_visible, Ns full) {
    std::lock_guard lock(mutex_);
    report_.first_visible.record(ns(first_visible));
    report_.full_resolution.record(ns(full));
    ++moves_complete_;
  }
  void moves_started(std::uint64_t n) {
    std::lock_guard lock(mutex_);
    report_.camera_moves += n;
  }
  void cancelled(std::uint64_t n) {
    std::lock_guard lock(mutex_);
    report_.cancelled += n;
  }

  LoadProgress progress(Clock::time_point now) {
    std::lock_guard lock(mutex_);
    LoadProgress p;
    p.elapsed_s = std::chrono::duration<double>(now - start_).count();
    p.requests = requests_;
    p.errors = errors_;
    p.moves_complete = moves_complete_;
    const auto s = std::size_t(std::max(0.0, p.elapsed_s));
    if (s >= 1 && s - 1 < seconds_.size()) {
      p.requests_per_s = double(seconds_[s - 1].requests);
      p.p99_ns = second_latency_[s - 1].percentile(99);
    }
    return p;
  }

  // The report so far: totals and the per-second series with their percentiles.
  LoadReport finish() {
    std::lock_guard lock(mutex_);
    LoadReport r = report_;
    r.requests = requests_;
    r.bytes = bytes_;
    r.errors = errors_;
    r.seconds = seconds_;
    for (std::size_t i = 0; i < r.seconds.size(); ++i) {
      r.seconds[i].p50_ns = second_latency_[i].percentile(50);
      r.seconds[i].p90_ns = second_latency_[i].percentile(90);
      r.seconds[i].p99_ns = second_latency_[i].percentile(99);
    }
    return r;
  }

 private:
  Clock::time_point start_;
  std::mutex mutex_;
  LoadReport report_;
  std::uint64_t requests_ = 0, errors_ = 0, bytes_ = 0, moves_complete_ = 0;
  std::vector<LoadSecond> seconds_;
  std::vector<LatencyHistogram> second_latency_;
};

struct Request {
  TileId id;
  std::uint64_t key = 0;
  Clock::time_point intended{}, sent{};
  client::TileCache::Handle handle = 0;
  bool issued = false;  // handed to the cache (under the viewer's lock)
  // Dropped by the view (or at the end of the run). Set under the viewer's lock, read by the
  // dispatcher under the queue's. Once set, the request is counted as cancelled or abandoned,
  // never also as a request, whatever its transfer brings.
  std::atomic<bool> cancelled{false};
};

class Engine;

// One simulated viewer: its client stack, its tile stream (the viewer's own policy: what to ask
// for, cancel, hold and retry) and the requests it has on their way.
class Viewer {
 public:
  Viewer(Engine& engine, std::uint32_t index, std::unique_ptr<client::TileCache> cache,
         renderer::TileStreamOptions stream)
      : engine_(engine), index_(index), cache_(std::move(cache)), stream_(std::move(stream)) {}

  std::uint32_t index() const { return index_; }
  client::TileCache& cache() { return *cache_; }

  // One frame (driver thread). Returns the demand function's error, if any.
  Status frame(std::uint64_t f, Clock::time_point due);
  // Open loop: sends a queued request in its slot (dispatcher thread); false when the view no
  // longer wants it.
  bool send(const std::shared_ptr<Request>& req, Clock::time_point slot);
  std::size_t in_flight() {
    std::lock_guard lock(mutex_);
    return inflight_.size();
  }
  // Open loop: drops a request that never got a slot (it was never on its way).
  void unqueue(const std::shared_ptr<Request>& req) {
    std::lock_guard lock(mutex_);
    req->cancelled = true;
    auto it = inflight_.find(req->key);
    if (it != inflight_.end() && it->second == req) {
      inflight_.erase(it);
      stream_.drop(req->id);
    }
  }
  // Cancels whatever is still on its way; returns how many.
  std::size_t cancel_all();
  // Ends a move still open at the end of the run.
  void end_moves(LoadRunStats& run) {
    if (move_open_) ++run.moves_incomplete;
    move_open_ = false;
  }
  std::uint64_t moves_incomplete() const { return moves_incomplete_; }
  std::uint64_t moves_started() const { return moves_started_; }
  double demand_ms = 0;  // CPU time of the driver thread in the demand function
  std::uint64_t frames = 0, demand_reused = 0;

 private:
  // Hands the request to the cache unless the view dropped it first (then false).
  bool issue(const std::shared_ptr<Request>& req);
  void done(const std::shared_ptr<Request>& req, client::PayloadResult&& r);
  // Drops requests the stream cancelled; returns how many were on their way (wasted).
  std::size_t cancel(const std::vector<TileId>& tiles,
                     std::vector<client::TileCache::Handle>& handles);

  Engine& engine_;
  std::uint32_t index_;
  std::unique_ptr<client::TileCache> cache_;

  std::mutex mutex_;  // guards the rest (callbacks run on the cache's threads)
  renderer::TileStream stream_;
  // When each resident (or absent) tile came: the moves' times. Evicted tiles leave it.
  std::unordered_map<std::uint64_t, Clock::time_point> arrived_;
  std::unordered_map<std::uint64_t, std::shared_ptr<Request>> inflight_;

  // Driver thread only.
  bool move_open_ = false, first_visible_known_ = false;
  Clock::time_point move_start_{};
  Ns first_visible_{0};
  std::uint64_t moves_incomplete_ = 0, moves_started_ = 0;
};

class Engine {
 public:
  Engine(const LoadTestOptions& o, const DemandFn& d, Clock::time_point t0)
      : options(o), demand(d), metrics(t0), start(t0) {}

  const LoadTestOptions& options;
  const DemandFn& demand;
  Metrics metrics;
  Clock::time_point start;
  std::vector<std::unique_ptr<Viewer>> viewers;

  // The run's clock (LoadTestOptions::now / sleep_until, else the steady clock).
  Clock::time_point now() const { return now_of(options); }
  void sleep_until(Clock::time_point t) const {
    if (options.sleep_until)
      options.sleep_until(t);
    else
      std::this_thread::sleep_until(t);
  }

  // Open loop: requests waiting for their slot, which the dispatcher takes one a slot (a rate, not
  // a job queue: nothing runs them as they come).
  std::mutex queue_mutex;
  std::deque<std::pair<Viewer*, std::shared_ptr<Request>>> queue;
  std::atomic<bool> issuing{true};

  std::mutex error_mutex;
  std::optional<Error> error;
  void fail(Error e) {
    std::lock_guard lock(error_mutex);
    if (!error) error = std::move(e);
    issuing = false;
  }
  bool stopped() const { return !issuing.load() || (options.stop && options.stop->load()); }
};

Status Viewer::frame(std::uint64_t f, Clock::time_point due) {
  ++frames;
  const double t0 = thread_cpu_ms();
  double bias = 0;
  {
    std::lock_guard lock(mutex_);
    bias = stream_.bias();
  }
  auto d = engine_.demand(index_, f, bias);
  demand_ms += thread_cpu_ms() - t0;
  if (!d) return d.error();
  if (d->reused) ++demand_reused;

  // Moves.
  if (d->move || f == 0) {
    if (move_open_) ++moves_incomplete_;
    move_open_ = true;
    first_visible_known_ = false;
    move_start_ = due;
    ++moves_started_;
  }

  std::vector<std::shared_ptr<Request>> to_issue;
  std::vector<client::TileCache::Handle> to_cancel;
  std::size_t cancelled = 0;  // issued requests dropped (wasted)
  std::size_t direct = 0, resolved = 0, fresh = 0;
  Clock::time_point first{Clock::time_point::max()}, last{Clock::time_point::min()};
  {
    std::lock_guard lock(mutex_);
    const renderer::StreamStep step = stream_.frame(f, due, &d->tiles);
    cancelled = cancel(step.cancels, to_cancel);
    for (const DemandTile& t : step.requests) {
      auto req = std::make_shared<Request>();
      req->id = t.tile;
      req->key = tile_key(t.tile);
      req->intended = due;
      inflight_[req->key] = req;
      to_issue.push_back(std::move(req));
    }
    for (const DemandTile& t : d->tiles) {
      if (!t.direct) continue;
      ++direct;
      auto a = arrived_.find(tile_key(t.tile));
      if (a == arrived_.end()) continue;
      ++resolved;
      // Only tiles that came after the move make it "visible": a coarse tile held from before
      // (the globe's limb, a shared ancestor) shows nothing new.
      if (a->second >= move_start_) {
        ++fresh;
        first = std::min(first, a->second);
      }
      last = std::max(last, a->second);
    }
  }
  for (client::TileCache::Handle h : to_cancel) cache_->cancel(h);
  if (cancelled) engine_.metrics.cancelled(cancelled);

  if (move_open_) {
    if (!first_visible_known_ && fresh > 0) {
      first_visible_ = std::max(Ns(0), Ns(first - move_start_));
      first_visible_known_ = true;
    }
    if (resolved == direct) {
      if (!first_visible_known_) first_visible_ = Ns(0);  // the whole view was already held
      first_visible_known_ = true;
      const Ns full = direct == 0 ? Ns(0) : std::max(Ns(0), Ns(last - move_start_));
      engine_.metrics.move_done(first_visible_, full);
      move_open_ = false;
    } else if (engine_.now() - move_start_ > engine_.options.view_timeout) {
      ++moves_incomplete_;
      move_open_ = false;
    }
  }

  if (engine_.options.rate > 0) {
    std::lock_guard lock(engine_.queue_mutex);
    for (auto& r : to_issue) engine_.queue.emplace_back(this, std::move(r));
  } else {
    for (auto& r : to_issue) issue(r);
  }
  return {};
}

std::size_t Viewer::cancel(const std::vector<TileId>& tiles,
                           std::vector<client::TileCache::Handle>& handles) {
  std::size_t n = 0;
  for (const TileId t : tiles) {
    auto it = inflight_.find(tile_key(t));
    if (it == inflight_.end()) continue;
    it->second->cancelled = true;
    if (it->second->issued) ++n;
    if (it->second->handle != 0) handles.push_back(it->second->handle);
    inflight_.erase(it);
  }
  return n;
}

bool Viewer::issue(const std::shared_ptr<Request>& req) {
  {
    std::lock_guard lock(mutex_);
    if (req->cancelled) return false;
    req->issued = true;
    req->sent = engine_.now();
  }
  client::GetOptions o;
  o.level = req->id.z;
  const client::TileCache::Handle h =
      cache_->get(req->id, o, [this, req](client::PayloadResult&& r) { done(req, std::move(r)); });
  std::lock_guard lock(mutex_);
  req->handle = h;
  return true;
}

bool Viewer::send(const std::shared_ptr<Request>& req, Clock::time_point slot) {
  req->intended = slot;  // the dispatcher's alone until issued
  return issue(req);
}

void Viewer::done(const std::shared_ptr<Request>& req, client::PayloadResult&& r) {
  if (r.kind == client::PayloadResult::Kind::cancelled) {
    // Cancelled by the cache itself (ours left inflight_ first): the stream may ask again.
    std::lock_guard lock(mutex_);
    auto it = inflight_.find(req->key);
    if (it != inflight_.end() && it->second == req) {
      inflight_.erase(it);
      stream_.drop(req->id);
    }
    return;
  }
  const auto now = engine_.now();  // the answer's arrival: --decode's time is not the server's
  // --decode: an image tile that does not decode shows nothing; it is an error, not resident.
  const char* kind = nullptr;
  if (engine_.options.decode && r.kind == client::PayloadResult::Kind::ok && r.tile &&
      r.from == client::PayloadResult::From::network && !cache_->info().image_format.empty() &&
      !imaging::decode_web_image(r.tile->payload))
    kind = "undecodable";
  bool counted = false;
  {
    std::lock_guard lock(mutex_);
    auto it = inflight_.find(req->key);
    if (it != inflight_.end() && it->second == req) inflight_.erase(it);
    // Dropped while its answer was on its way: already counted as cancelled or abandoned.
    counted = !req->cancelled;
    if (!kind && r.kind == client::PayloadResult::Kind::ok) {
      // A slot, as the viewer's physical texture gives (or refuses, or takes from another tile).
      if (const auto got = stream_.place(req->id)) {
        arrived_[req->key] = now;
        if (got->evicted) arrived_.erase(tile_key(*got->evicted));
      }
    } else if (!kind && r.kind == client::PayloadResult::Kind::absent) {
      stream_.absent(req->id);
      arrived_[req->key] = now;
    } else {
      stream_.failed(req->id, now);
    }
  }
  if (counted) engine_.metrics.request_done(r, req->intended, req->sent, now, kind);
}

std::size_t Viewer::cancel_all() {
  std::vector<client::TileCache::Handle> handles;
  std::size_t n = 0;  // issued: on their way
  {
    std::lock_guard lock(mutex_);
    for (auto& [k, r] : inflight_) {
      r->cancelled = true;
      if (r->issued) ++n;
      if (r->handle) handles.push_back(r->handle);
    }
    inflight_.clear();
  }
  for (auto h : handles) cache_->cancel(h);
  return n;
}

// A viewer's stream: its physical texture's slots, and the run's trace.
renderer::TileStreamOptions stream_options(const LoadTestOptions& o, std::uint32_t viewer) {
  renderer::TileStreamOptions s;
  s.slots.capacity = std::uint32_t(std::clamp<std::size_t>(o.resident_tiles, 1, 1u << 20));
  s.slots.keep_frames = o.keep_frames;
  if (o.trace)
    s.trace = [&trace = o.trace, viewer](const renderer::StreamEvent& e) { trace(viewer, e); };
  return s;
}

Status check(const LoadTestOptions& o) {
  const auto bad = [](const std::string& m) { return make_error(ErrorCode::invalid_argument, m); };
  if (o.viewers < 1 || o.viewers > 10000) return bad("viewers must be 1 to 10000");
  if (!(o.fps > 0) || o.fps > 1000) return bad("fps must be above 0 and at most 1000");
  if (!(o.duration_s > 0) || o.duration_s > 7 * 24 * 3600.0)
    return bad("duration must be above 0 s and at most a week");
  if (!(o.rate >= 0) || o.rate > 1e7) return bad("rate must be 0 (closed loop) to 1e7 req/s");
  if (o.cache == CacheMode::disk && o.cache_dir.empty())
    return bad("the disk cache mode needs a cache folder");
  if (o.target.empty()) return bad("no target to load-test");
  return {};
}

// The run in time, and what its loops count: shared by the loops and the calling thread.
struct Run {
  Clock::time_point start, end;
  Clock::duration frame_period{};
  double fps = 30;
  int threads = 1;

  // start + s, to the clock's tick (each time from the start, so no rounding adds up).
  Clock::time_point at(double s) const {
    return start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
  }
  std::atomic<std::uint64_t> late_frames{0};
  std::uint64_t idle_slots = 0, startup_slots = 0;  // the dispatcher's; read once it has ended
  std::atomic<unsigned> drivers{0}, loops{0};       // still running
  std::atomic<bool> loops_done{false};
  Clock::time_point loops_end{};  // when the last loop ended; written before loops_done

  void loop_ended(const Engine& engine) {
    if (loops.fetch_sub(1) != 1) return;
    loops_end = engine.now();
    loops_done = true;
  }
};

// Driver `t`: the frames of viewers t, t + threads, ..., each at its due time.
void drive(Engine& engine, Run& run, int t) {
  for (std::uint64_t f = 0;;) {
    const auto due = run.at(double(f) / run.fps);
    if (engine.stopped()) break;
    if (due >= run.end) {
      engine.sleep_until(run.end);  // the run lasts its duration, whatever the frame rate
      break;
    }
    engine.sleep_until(due);
    const auto now = engine.now();
    if (now >= run.end) break;
    if (now - due > run.frame_period) {
      // Behind by more than a frame (the load generator is the bottleneck): like a renderer
      // whose frame rate drops, skip to the frame due now instead of replaying a backlog.
      const auto behind =
          std::uint64_t(std::chrono::duration<double>(now - run.start).count() * run.fps);
      run.late_frames.fetch_add(behind - f);
      f = behind;
      continue;
    }
    const std::uint64_t frame = f++;
    for (std::size_t v = std::size_t(t); v < engine.viewers.size(); v += std::size_t(run.threads)) {
      if (engine.stopped()) break;
      if (auto st = engine.viewers[v]->frame(frame, due); !st) {
        engine.fail(st.error());
        break;
      }
    }
  }
}

// Open loop: one request per slot, slot k at start + k / rate.
void dispatch(Engine& engine, Run& run) {
  bool sent_any = false;
  for (std::uint64_t k = 0;; ++k) {
    const auto slot = run.at(double(k) / engine.options.rate);
    if (slot >= run.end || engine.stopped()) break;
    engine.sleep_until(slot);
    // The next request still wanted; one the view drops between the pop and the send is not
    // spent: the slot goes to the one after it.
    bool sent = false;
    for (;;) {
      std::pair<Viewer*, std::shared_ptr<Request>> item{nullptr, nullptr};
      {
        std::lock_guard lock(engine.queue_mutex);
        while (!engine.queue.empty() && !item.first) {
          item = std::move(engine.queue.front());
          engine.queue.pop_front();
          if (item.second->cancelled) item = {nullptr, nullptr};
        }
      }
      if (!item.first) break;
      if ((sent = item.first->send(item.second, slot))) break;
    }
    if (!sent) {
      // Before the first request the viewers are still working out their first frame: the
      // generator starting up, not a demand that fails to fill the rate.
      ++(sent_any ? run.idle_slots : run.startup_slots);
      continue;
    }
    sent_any = true;
  }
}

// Progress about once a second, from the calling thread, between its polls.
class Reporter {
 public:
  Reporter(Engine& engine, Run& run)
      : engine_(engine), run_(run), next_(run.start + std::chrono::seconds(1)) {}

  // Waits `poll` (less when a report falls due first), then reports if one is due.
  void wait(Clock::duration poll) {
    const auto& progress = engine_.options.progress;
    const auto until = engine_.now() + poll;
    engine_.sleep_until(progress ? std::min(next_, until) : until);
    const auto now = engine_.now();
    if (!progress || now < next_) return;
    next_ += std::chrono::seconds(1);
    LoadProgress p = engine_.metrics.progress(now);
    for (auto& v : engine_.viewers) p.in_flight += v->in_flight();
    p.late_frames = run_.late_frames.load();
    progress(p);
  }

 private:
  Engine& engine_;
  Run& run_;
  Clock::time_point next_;
};

}  // namespace

Result<LoadTestResult> run_load_test(const LoadTestOptions& options, const DemandFn& demand) {
  if (auto st = check(options); !st) return st.error();

  // Every viewer's client stack first: opening is not part of the measured run.
  std::vector<std::unique_ptr<client::TileCache>> caches;
  for (std::uint32_t v = 0; v < options.viewers; ++v) {
    if (options.stop && options.stop->load())
      return make_error(ErrorCode::cancelled, "load test interrupted while opening viewers");
    auto src = client::open_source(options.target, options.source);
    if (!src) return src.error();
    client::TileCacheOptions co;
    co.ram_bytes = options.cache == CacheMode::none ? 0 : options.ram_bytes;
    if (options.cache == CacheMode::disk)
      co.disk =
          client::DiskCacheOptions{.dir = options.cache_dir / ("viewer-" + std::to_string(v))};
    auto cache =
        client::TileCache::create(std::shared_ptr<client::TileSource>(std::move(*src)), co);
    if (!cache) return cache.error();
    caches.push_back(std::move(*cache));
  }

  const auto start = now_of(options) + std::chrono::milliseconds(20);
  Engine engine(options, demand, start);
  for (std::uint32_t v = 0; v < options.viewers; ++v)
    engine.viewers.push_back(
        std::make_unique<Viewer>(engine, v, std::move(caches[v]), stream_options(options, v)));

  Run run;
  run.start = start;
  run.end = run.at(options.duration_s);
  run.fps = options.fps;
  run.frame_period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / options.fps));
  run.threads = std::max(
      1, std::min<int>(options.threads > 0 ? options.threads
                                           : int(std::max(1u, std::thread::hardware_concurrency())),
                       int(options.viewers)));

  // The loops, one thread each: the drivers and, in open loop, the dispatcher. Each thread ends
  // with its loop (the pool is closed once they are queued).
  const unsigned loops = unsigned(run.threads) + (options.rate > 0 ? 1u : 0u);
  auto pool = WorkerPool::start({.threads = loops, .capacity = 0, .name = "vts-loadtest"});
  if (!pool) return pool.error();
  run.drivers = unsigned(run.threads);
  run.loops = loops;
  for (int t = 0; t < run.threads; ++t)
    (*pool)->submit([&engine, &run, t] {
      drive(engine, run, t);
      // The last driver ends the issuing: the dispatcher sends no slot after it.
      if (run.drivers.fetch_sub(1) == 1) engine.issuing = false;
      run.loop_ended(engine);
    });
  if (options.rate > 0)
    (*pool)->submit([&engine, &run] {
      dispatch(engine, run);
      run.loop_ended(engine);
    });
  (*pool)->close();

  // This thread reports progress, about once a second, until the loops are done and the drain
  // is over.
  Reporter reporter(engine, run);
  while (!run.loops_done.load()) reporter.wait(kPoll);
  (*pool)->join();
  {
    // Requests still waiting for a slot were never sent: the drain does not wait for them.
    std::lock_guard lock(engine.queue_mutex);
    for (auto& [viewer, req] : engine.queue) viewer->unqueue(req);
    engine.queue.clear();
  }
  const auto measured_end = std::min(run.loops_end, run.end);

  // Drain: what is on its way may still arrive (and count); then the rest is abandoned.
  const auto drain_until = engine.now() + options.drain_timeout;
  for (;;) {
    std::size_t n = 0;
    for (auto& v : engine.viewers) n += v->in_flight();
    if (n == 0 || engine.now() >= drain_until || (options.stop && options.stop->load())) break;
    reporter.wait(kPoll);
  }

  LoadTestResult result;
  for (auto& v : engine.viewers) {
    result.run.abandoned += v->cancel_all();
    v->end_moves(result.run);
    result.run.moves_incomplete += v->moves_incomplete();
    engine.metrics.moves_started(v->moves_started());
    result.run.demand_cpu_ms_per_frame += v->demand_ms;
    result.run.demand_reused += v->demand_reused;
  }
  std::uint64_t revalidated = 0;
  for (auto& v : engine.viewers) revalidated += v->cache().stats().not_modified;
  for (auto& v : engine.viewers) result.run.frames += v->frames;  // viewer-frames
  if (result.run.frames) result.run.demand_cpu_ms_per_frame /= double(result.run.frames);
  result.run.late_frames = run.late_frames.load();
  result.run.idle_slots = run.idle_slots;
  result.run.startup_slots = run.startup_slots;
  engine.viewers.clear();  // closes every client stack (flushes disk caches)

  if (engine.error) return *engine.error;

  LoadReport& r = result.report = engine.metrics.finish();
  r.tiers.revalidated = revalidated;
  r.title = options.title;
  r.target = options.target;
  r.command_line = options.command_line;
  r.start = std::chrono::system_clock::now() -
            std::chrono::duration_cast<std::chrono::system_clock::duration>(engine.now() - start);
  r.duration_s = std::max(0.0, std::chrono::duration<double>(measured_end - start).count());
  r.viewers = options.viewers;
  r.path = options.path_name;
  r.fps = options.fps;
  r.mode = options.rate > 0 ? LoopMode::open : LoopMode::closed;
  r.rate = options.rate;
  return result;
}

std::string progress_text(const LoadProgress& p, double duration_s) {
  char line[256];
  std::snprintf(
      line, sizeof line,
      "[%5.0fs/%.0fs] %llu requests (%.0f/s), %llu errors, %llu in flight, %s, "
      "%llu moves at full resolution%s",
      p.elapsed_s, duration_s, static_cast<unsigned long long>(p.requests), p.requests_per_s,
      static_cast<unsigned long long>(p.errors), static_cast<unsigned long long>(p.in_flight),
      p.requests_per_s > 0 ? ("p99 " + duration_text(double(p.p99_ns))).c_str()
                           : "no responses this second",
      static_cast<unsigned long long>(p.moves_complete),
      p.late_frames ? (", " + std::to_string(p.late_frames) + " late frames").c_str() : "");
  return line;
}

}  // namespace vts::loadtest
