// TileCache: RAM → disk → source, with merging, verification and revalidation (see the header).
#include "vts/client/tile_cache.hpp"

#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <set>
#include <system_error>
#include <thread>
#include <unordered_map>
#include <vector>

#include "vts/protocol/codec.hpp"

namespace vts::client {

namespace {

std::int64_t now_unix() {
  return std::chrono::duration_cast<std::chrono::seconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Background revalidation goes after every real request.
constexpr int kRevalidateLevel = 1 << 20;

}  // namespace

class TileCache::Impl {
 public:
  // `disk_thread`: the disk stage's one-thread pool (start_disk_thread), null without a disk.
  Impl(std::shared_ptr<TileSource> source, TileCacheOptions options,
       std::unique_ptr<DiskCache> disk, std::unique_ptr<WorkerPool> disk_thread)
      : source_(std::move(source)),
        options_(std::move(options)),
        disk_(std::move(disk)),
        key_(source_->info().key),
        spec_(source_->info().info.tile_spec()),
        disk_thread_(std::move(disk_thread)) {
    if (options_.ram_bytes > 0) ram_ = std::make_unique<RamCache>(options_.ram_bytes);
  }

  // One thread, so that the DiskCache's one SQLite connection is used by one job at a time.
  static Result<std::unique_ptr<WorkerPool>> start_disk_thread() {
    return WorkerPool::start({.threads = 1, .capacity = 0, .name = "vts-disk"});
  }

  ~Impl() {
    std::vector<Waiter> orphans;
    std::vector<TileSource::Handle> to_cancel;
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
      for (auto& [id, p] : pending_) {
        for (auto& w : p.waiters) orphans.push_back(std::move(w));
        if (p.source_handle) to_cancel.push_back(p.source_handle);
      }
      pending_.clear();
      handle_tile_.clear();
      for (auto& [id, h] : revalidating_)
        if (h) to_cancel.push_back(h);
    }
    for (auto h : to_cancel) source_->cancel(h);
    // Every source callback captures `this`: wait until the last has run.
    {
      std::unique_lock lock(mutex_);
      idle_cv_.wait(lock, [this] { return outstanding_ == 0; });
    }
    // Runs every disk job still queued (the writes too), then joins.
    if (disk_thread_) disk_thread_->join();
    for (auto& w : orphans) {
      PayloadResult r;
      r.kind = PayloadResult::Kind::cancelled;
      w.callback(std::move(r));
    }
  }

  const SourceInfo& info() const { return source_->info(); }

  Handle get(TileId id, const GetOptions& options, PayloadCallback callback) {
    stats_.gets.fetch_add(1, std::memory_order_relaxed);
    if (ram_) {
      const TileKey key{key_, id};
      if (auto t = ram_->get(key)) {
        stats_.ram_hits.fetch_add(1, std::memory_order_relaxed);
        if (options.pin) ram_->set_pinned(key, true);
        maybe_revalidate(id, t, options);
        PayloadResult r;
        r.kind = PayloadResult::Kind::ok;
        r.from = PayloadResult::From::ram;
        r.tile = std::move(t);
        callback(std::move(r));
        return 0;
      }
    }
    Handle handle = 0;
    bool start_disk = false, start_network = false;
    std::uint64_t serial = 0;
    {
      std::unique_lock lock(mutex_);
      if (absent_.count(id)) {
        lock.unlock();
        stats_.absent.fetch_add(1, std::memory_order_relaxed);
        PayloadResult r;
        r.kind = PayloadResult::Kind::absent;
        callback(std::move(r));
        return 0;
      }
      handle = next_handle_++;
      handle_tile_.emplace(handle, id);
      const int level = options.level < 0 ? int(id.z) : options.level;
      auto it = pending_.find(id);
      if (it != pending_.end()) {
        Pending& p = it->second;
        p.level = std::min(p.level, level);
        p.urgency = std::max(p.urgency, options.urgency);
        p.pin = p.pin || options.pin;
        p.waiters.push_back({handle, std::move(callback)});
        return handle;
      }
      Pending p;
      p.serial = serial = next_serial_++;
      p.level = level;
      p.urgency = options.urgency;
      p.pin = options.pin;
      p.revalidate = options.revalidate;
      p.waiters.push_back({handle, std::move(callback)});
      pending_.emplace(id, std::move(p));
      if (disk_)
        start_disk = true;
      else
        start_network = true;
    }
    if (start_disk) {
      post_disk(/*read=*/true, [this, id, serial] { disk_read(id, serial); });
    } else if (start_network) {
      fetch(id, serial);
    }
    return handle;
  }

  void cancel(Handle h) {
    Waiter cancelled;
    TileSource::Handle source_handle = 0;
    {
      std::lock_guard lock(mutex_);
      auto ht = handle_tile_.find(h);
      if (ht == handle_tile_.end()) return;
      const TileId id = ht->second;
      handle_tile_.erase(ht);
      auto it = pending_.find(id);
      if (it == pending_.end()) return;
      auto& ws = it->second.waiters;
      for (auto w = ws.begin(); w != ws.end(); ++w) {
        if (w->handle == h) {
          cancelled = std::move(*w);
          ws.erase(w);
          break;
        }
      }
      if (ws.empty()) {
        // Nobody wants the tile any more. A fetch in flight is cancelled; should its bytes
        // arrive anyway, they are still cached (see on_fetched).
        source_handle = it->second.source_handle;
        pending_.erase(it);
      }
    }
    if (source_handle) source_->cancel(source_handle);
    if (cancelled.callback) {
      stats_.cancelled.fetch_add(1, std::memory_order_relaxed);
      PayloadResult r;
      r.kind = PayloadResult::Kind::cancelled;
      cancelled.callback(std::move(r));
    }
  }

  Status flush() {
    if (!disk_) return {};
    {
      std::unique_lock lock(disk_mutex_);
      disk_idle_cv_.wait(lock, [this] { return disk_idle() && !disk_busy_; });
    }
    std::lock_guard lock(disk_use_mutex_);
    return disk_->flush();
  }

  Stats stats() const {
    Stats s;
    s.gets = stats_.gets.load();
    s.ram_hits = stats_.ram_hits.load();
    s.disk_hits = stats_.disk_hits.load();
    s.network_fetches = stats_.network_fetches.load();
    s.absent = stats_.absent.load();
    s.errors = stats_.errors.load();
    s.corrupt_rejected = stats_.corrupt_rejected.load();
    s.revalidations = stats_.revalidations.load();
    s.not_modified = stats_.not_modified.load();
    s.disk_write_errors = stats_.disk_write_errors.load();
    s.mismatch_rejected = stats_.mismatch_rejected.load();
    s.cancelled = stats_.cancelled.load();
    return s;
  }

  RamCache* ram() { return ram_.get(); }
  DiskCache* disk() { return disk_.get(); }
  std::optional<Error> last_disk_error() const {
    std::lock_guard lock(mutex_);
    return last_disk_error_;
  }
  DiskHealth disk_health() const {
    std::lock_guard lock(health_mutex_);
    return health_;
  }

 private:
  struct Waiter {
    Handle handle = 0;
    PayloadCallback callback;
  };
  struct Put {
    TileId id;
    std::shared_ptr<const CachedTile> tile;
    bool pin = false;
  };
  struct Pending {
    std::uint64_t serial = 0;  // tells this request from a later one for the same tile
    std::vector<Waiter> waiters;
    int level = 0;
    double urgency = 0;
    bool pin = false;
    bool revalidate = true;
    TileSource::Handle source_handle = 0;
    int corrupt_attempts = 0;
  };

  // ---- completion ----

  // Hands `result` to every waiter of the request `serial` for `id` (if it is still pending).
  void complete(TileId id, std::uint64_t serial, PayloadResult result) {
    std::vector<Waiter> waiters;
    {
      std::lock_guard lock(mutex_);
      auto it = pending_.find(id);
      if (it == pending_.end() || it->second.serial != serial) return;
      waiters = std::move(it->second.waiters);
      for (const auto& w : waiters) handle_tile_.erase(w.handle);
      pending_.erase(it);
    }
    if (result.kind == PayloadResult::Kind::error)
      stats_.errors.fetch_add(1, std::memory_order_relaxed);
    for (std::size_t i = 0; i < waiters.size(); ++i) {
      if (i + 1 == waiters.size()) {
        waiters[i].callback(std::move(result));
      } else {
        PayloadResult copy = result;
        waiters[i].callback(std::move(copy));
      }
    }
  }

  // Pending options of a request, if it is still wanted.
  std::optional<Pending> snapshot(TileId id, std::uint64_t serial) {
    std::lock_guard lock(mutex_);
    auto it = pending_.find(id);
    if (it == pending_.end() || it->second.serial != serial) return std::nullopt;
    Pending p;
    p.serial = serial;
    p.level = it->second.level;
    p.urgency = it->second.urgency;
    p.pin = it->second.pin;
    p.revalidate = it->second.revalidate;
    p.corrupt_attempts = it->second.corrupt_attempts;
    return p;
  }

  void remember(TileId id, const std::shared_ptr<const CachedTile>& tile, bool pin) {
    if (ram_) ram_->put(TileKey{key_, id}, tile, pin);
  }

  // A verified payload from the source, fresh now: into RAM and onto disk, each pinned as asked.
  std::shared_ptr<const CachedTile> keep_fetched(TileId id, SourceTile&& t, bool ram_pin,
                                                 bool disk_pin) {
    auto tile = std::make_shared<CachedTile>();
    tile->payload = std::move(t.payload);
    tile->etag = std::move(t.etag);
    tile->validated_unix = now_unix();
    tile->fresh_for = t.fresh_for;
    std::shared_ptr<const CachedTile> shared = std::move(tile);
    remember(id, shared, ram_pin);
    store_on_disk(id, shared, disk_pin);
    return shared;
  }

  // Whether a payload may be stored or handed out: it verifies (header + checksum) and its
  // header agrees with the tileset (size, codec, pixel format: check_tile_against). A refusal
  // from the network is counted (corrupt_rejected, and mismatch_rejected for a tile of another
  // shape); a disk row that fails is dropped by the caller and fetched again.
  Status acceptable(std::span<const std::uint8_t> payload, std::string_view from) {
    // Standard image tiles (SourceInfo::image_format) carry no header or checksum to verify.
    if (!source_->info().image_format.empty()) return {};
    auto header = verify_tile(payload);
    Status s;
    bool mismatch = false;
    if (!header) {
      s = header.error();
    } else if (s = check_tile_against(*header, spec_); !s) {
      mismatch = true;
    }
    if (s.ok()) return s;
    if (from == "network") stats_.corrupt_rejected.fetch_add(1, std::memory_order_relaxed);
    if (mismatch) stats_.mismatch_rejected.fetch_add(1, std::memory_order_relaxed);
    return s;
  }

  // ---- disk stage (disk thread) ----
  //
  // The disk thread is a one-thread WorkerPool, which is FIFO; the priorities (reads before
  // writes before batches of puts) stay here: each piece of work queued adds one disk_step() job,
  // and a step takes the most urgent piece there is then. A step finding nothing left (a batch of
  // puts took its piece) returns; every piece is taken by the time its own step has run.

  void post_disk(bool read, std::function<void()> job) {
    {
      std::lock_guard lock(disk_mutex_);
      (read ? disk_reads_ : disk_writes_).push_back(std::move(job));
    }
    schedule_disk_step();
  }

  void schedule_disk_step() {
    // false only once the destructor has joined the thread: nothing is queued then.
    disk_thread_->submit([this] { disk_step(); });
  }

  // Reads first: a viewer waits for them; writes only make the next run faster.
  void disk_step() {
    constexpr std::size_t kMaxBatch = 128;
    constexpr std::size_t kMaxBatchBytes = 8u << 20;
    std::function<void()> job;
    std::vector<Put> batch;
    {
      std::lock_guard lock(disk_mutex_);
      if (disk_idle()) return;
      if (!disk_reads_.empty() || !disk_writes_.empty()) {
        auto& q = disk_reads_.empty() ? disk_writes_ : disk_reads_;
        job = std::move(q.front());
        q.pop_front();
      } else {
        std::size_t bytes = 0;
        while (!disk_puts_.empty() && batch.size() < kMaxBatch && bytes < kMaxBatchBytes) {
          bytes += disk_puts_.front().tile->payload.size();
          batch.push_back(std::move(disk_puts_.front()));
          disk_puts_.pop_front();
        }
      }
      disk_busy_ = true;
    }
    {
      std::lock_guard use(disk_use_mutex_);
      if (job)
        job();
      else
        write_puts(batch);
    }
    std::lock_guard lock(disk_mutex_);
    disk_busy_ = false;
    if (disk_idle()) disk_idle_cv_.notify_all();
  }

  void disk_read(TileId id, std::uint64_t serial) {
    auto p = snapshot(id, serial);
    if (!p) return;  // cancelled meanwhile
    // A pin is taken with the read, in one transaction: read then pinned in two, another process
    // sharing the folder could evict the tile in between.
    auto row = disk_->get(key_, id, p->pin);
    if (!row && p->pin) {
      note_disk(row.error());  // the pin could not be written (a full disk): serve it unpinned
      row = disk_->get(key_, id);
    }
    if (row && row->has_value()) {
      CachedTile& t = **row;
      // The disk cache checked its row checksum; the payload's own is checked too, so that not
      // even a tile stored by an older or buggy writer is handed out unverified.
      if (acceptable(t.payload, "disk")) {
        auto tile = std::make_shared<const CachedTile>(std::move(t));
        stats_.disk_hits.fetch_add(1, std::memory_order_relaxed);
        remember(id, tile, p->pin);
        GetOptions o;
        o.level = p->level;
        o.revalidate = p->revalidate;
        maybe_revalidate(id, tile, o);
        PayloadResult r;
        r.kind = PayloadResult::Kind::ok;
        r.from = PayloadResult::From::disk;
        r.tile = std::move(tile);
        complete(id, serial, std::move(r));
        return;
      }
      note_disk(disk_->remove(key_, id));
    }
    fetch(id, serial);
  }

  // A failed disk write (disk full, I/O error) never fails a get: the tile was delivered from
  // RAM or the network; the error is counted, kept for reporting and marks the disk failing.
  // `stored`: a tile was written, which proves the disk takes writes again.
  void note_disk(const Status& s, bool stored = false) {
    if (s.ok()) {
      if (stored) disk_recovered();
      return;
    }
    stats_.disk_write_errors.fetch_add(1, std::memory_order_relaxed);
    {
      std::lock_guard lock(mutex_);
      last_disk_error_ = s.error();
    }
    // Not the disk's fault: a tile too large for the cap, a row evicted before its update.
    const ErrorCode c = s.error().code;
    if (c != ErrorCode::too_large && c != ErrorCode::not_found) disk_failed(s.error());
  }

  // Rate-limited reporting (TileCacheOptions::disk_report): the first failure at once; after
  // that at most one line per interval, counting the failures it stands for. A spell of failures
  // that was reported gets a line when it ends; so a disk that keeps flipping between failing and
  // working costs at most about two lines per interval.
  void disk_failed(const Error& e) {
    std::string line;
    {
      std::lock_guard lock(health_mutex_);
      const auto now = options_.clock ? options_.clock() : std::chrono::steady_clock::now();
      ++health_.failed_writes;
      ++unreported_failures_;
      health_.last_error = e;
      if (!health_.failing) {
        health_.failing = true;
        health_.failing_since_unix = now_unix();
      }
      if (last_report_ && now - *last_report_ < options_.disk_report_interval) return;
      line = unreported_failures_ == health_.failed_writes && health_.failed_writes == 1
                 ? "disk cache write failed; tiles are served but not kept on disk until writes "
                   "succeed again: " +
                       e.to_string()
                 : "disk cache writes failing: " + std::to_string(unreported_failures_) +
                       " failed writes since the last report, " +
                       std::to_string(health_.failed_writes) +
                       " in a row; the last: " + e.to_string();
      unreported_failures_ = 0;
      last_report_ = now;
      spell_reported_ = true;
    }
    if (options_.disk_report) options_.disk_report(line);
  }

  void disk_recovered() {
    std::string line;
    {
      std::lock_guard lock(health_mutex_);
      if (!health_.failing) return;
      if (spell_reported_)
        line = "disk cache writes succeed again, after " + std::to_string(health_.failed_writes) +
               " failed writes";
      health_ = DiskHealth{};
      spell_reported_ = false;
    }
    if (options_.disk_report && !line.empty()) options_.disk_report(line);
  }

  // Queued, then written in batches of many tiles per transaction by the disk thread.
  void store_on_disk(TileId id, std::shared_ptr<const CachedTile> tile, bool pin) {
    if (!disk_) return;
    {
      std::lock_guard lock(disk_mutex_);
      disk_puts_.push_back(Put{id, std::move(tile), pin});
    }
    schedule_disk_step();
  }

  // On the disk thread: many tiles in one transaction (one commit, not one per tile).
  void write_puts(std::vector<Put>& batch) {
    std::vector<DiskCache::BatchItem> items;
    items.reserve(batch.size());
    for (const auto& p : batch) items.push_back({p.id, p.tile.get(), p.pin});
    Status s = disk_->put_batch(key_, items);
    if (!s && batch.size() > 1) {
      // One bad tile (too large, no room for a pin) must not cost the others: one by one.
      for (const auto& p : batch) note_disk(disk_->put(key_, p.id, *p.tile, p.pin), true);
    } else {
      note_disk(s, true);
    }
    batch.clear();
  }

  bool disk_idle() const {
    return disk_reads_.empty() && disk_writes_.empty() && disk_puts_.empty();
  }

  // ---- network stage (source thread) ----

  void fetch(TileId id, std::uint64_t serial) {
    auto p = snapshot(id, serial);
    if (!p) return;
    stats_.network_fetches.fetch_add(1, std::memory_order_relaxed);
    SourceRequest req;
    req.id = id;
    req.level = p->level;
    req.urgency = p->urgency;
    {
      std::lock_guard lock(mutex_);
      if (stopping_) return;
      ++outstanding_;
    }
    const auto h = source_->fetch(req, [this, id, serial](SourceTile&& t) {
      on_fetched(id, serial, std::move(t));
      std::lock_guard lock(mutex_);
      if (--outstanding_ == 0) idle_cv_.notify_all();
    });
    bool cancel_now = false;
    {
      std::lock_guard lock(mutex_);
      auto it = pending_.find(id);
      if (it != pending_.end() && it->second.serial == serial)
        it->second.source_handle = h;
      else
        cancel_now = stopping_;  // the destructor could not see this handle
    }
    if (cancel_now) source_->cancel(h);
  }

  void on_fetched(TileId id, std::uint64_t serial, SourceTile&& t) {
    {
      std::lock_guard lock(mutex_);
      auto it = pending_.find(id);
      if (it != pending_.end() && it->second.serial == serial) it->second.source_handle = 0;
    }
    PayloadResult r;
    r.transfer = t.transfer;
    switch (t.kind) {
      case SourceTile::Kind::ok: {
        if (Status v = acceptable(t.payload, "network"); !v) {
          int attempts = 0;
          {
            std::lock_guard lock(mutex_);
            auto it = pending_.find(id);
            if (it == pending_.end() || it->second.serial != serial) return;
            attempts = ++it->second.corrupt_attempts;
          }
          if (attempts <= options_.corrupt_retries) return fetch(id, serial);
          r.kind = PayloadResult::Kind::error;
          // Either way the upstream sent bytes that cannot be used (to_provided: 502).
          r.error = make_error(
              v.error().code == ErrorCode::corrupt ? ErrorCode::corrupt : ErrorCode::checksum,
              "tile " + id.to_string() + " from " + key_ + " failed verification " +
                  std::to_string(attempts) + " times: " + v.error().message);
          break;
        }
        auto p = snapshot(id, serial);
        const bool pin = p && p->pin;
        r.kind = PayloadResult::Kind::ok;
        r.from = PayloadResult::From::network;
        r.tile = keep_fetched(id, std::move(t), pin, pin);
        break;
      }
      case SourceTile::Kind::absent: {
        std::lock_guard lock(mutex_);
        absent_.insert(id);
      }
        stats_.absent.fetch_add(1, std::memory_order_relaxed);
        r.kind = PayloadResult::Kind::absent;
        break;
      case SourceTile::Kind::cancelled:
        r.kind = PayloadResult::Kind::cancelled;
        break;
      case SourceTile::Kind::not_modified:
        r.kind = PayloadResult::Kind::error;
        r.error = make_error(ErrorCode::internal, "tile " + id.to_string() + " from " + key_ +
                                                      ": 304 to a request without a validator");
        break;
      case SourceTile::Kind::error:
        r.kind = PayloadResult::Kind::error;
        r.error = t.error ? *t.error
                          : make_error(ErrorCode::io, "tile " + id.to_string() + " from " + key_ +
                                                          ": fetch failed");
        break;
    }
    complete(id, serial, std::move(r));
  }

  // ---- revalidation ----

  void maybe_revalidate(TileId id, const std::shared_ptr<const CachedTile>& tile,
                        const GetOptions& options) {
    if (!options.revalidate || source_->local()) return;
    const std::int64_t fresh_for = tile->fresh_for >= 0 && !options_.fixed_revalidate_after
                                       ? tile->fresh_for
                                       : std::int64_t(options_.revalidate_after.count());
    // A tile with no lifetime (0: no-cache) is revalidated at every hit, including in the
    // second it was fetched.
    if (fresh_for > 0 && now_unix() - tile->validated_unix < fresh_for) return;
    {
      std::lock_guard lock(mutex_);
      if (stopping_ || !revalidating_.emplace(id, 0).second) return;
      ++outstanding_;
    }
    stats_.revalidations.fetch_add(1, std::memory_order_relaxed);
    SourceRequest req;
    req.id = id;
    req.if_none_match = tile->etag;
    req.level = kRevalidateLevel;
    req.urgency = -1;
    const bool pin = options.pin;
    auto h = source_->fetch(req, [this, id, tile, pin](SourceTile&& t) {
      on_revalidated(id, tile, pin, std::move(t));
      std::lock_guard lock(mutex_);
      revalidating_.erase(id);
      if (--outstanding_ == 0) idle_cv_.notify_all();
    });
    bool cancel_now = false;
    {
      std::lock_guard lock(mutex_);
      auto it = revalidating_.find(id);
      if (it != revalidating_.end()) it->second = h;
      cancel_now = stopping_;
    }
    if (cancel_now) source_->cancel(h);
  }

  void on_revalidated(TileId id, const std::shared_ptr<const CachedTile>& old, bool pin,
                      SourceTile&& t) {
    const TileKey key{key_, id};
    switch (t.kind) {
      case SourceTile::Kind::not_modified: {
        stats_.not_modified.fetch_add(1, std::memory_order_relaxed);
        auto fresh = std::make_shared<CachedTile>(*old);
        fresh->validated_unix = now_unix();
        if (t.fresh_for >= 0) fresh->fresh_for = t.fresh_for;  // the 304's Cache-Control
        remember(id, fresh, false);
        if (disk_) {
          const auto when = fresh->validated_unix;
          const auto fresh_for = fresh->fresh_for;
          post_disk(false, [this, id, when, fresh_for] {
            note_disk(disk_->set_validated(key_, id, when, fresh_for));
          });
        }
        break;
      }
      case SourceTile::Kind::ok: {
        if (!acceptable(t.payload, "network")) break;  // keep the old one
        keep_fetched(id, std::move(t), false, pin);
        break;
      }
      case SourceTile::Kind::absent: {
        if (ram_) ram_->erase(key);
        if (disk_) post_disk(false, [this, id] { note_disk(disk_->remove(key_, id)); });
        std::lock_guard lock(mutex_);
        absent_.insert(id);
        break;
      }
      case SourceTile::Kind::error:
      case SourceTile::Kind::cancelled:
        break;  // offline or gone: keep serving what we have
    }
  }

  std::shared_ptr<TileSource> source_;
  TileCacheOptions options_;
  std::unique_ptr<RamCache> ram_;
  std::unique_ptr<DiskCache> disk_;
  const std::string key_;
  const TileSpec spec_;  // what every tile of the source's tileset is

  mutable std::mutex mutex_;
  std::condition_variable idle_cv_;
  std::map<TileId, Pending> pending_;
  std::unordered_map<Handle, TileId> handle_tile_;
  std::set<TileId> absent_;
  std::map<TileId, TileSource::Handle> revalidating_;  // 0 until the fetch has a handle
  Handle next_handle_ = 1;
  std::uint64_t next_serial_ = 1;
  std::size_t outstanding_ = 0;  // source callbacks not yet run
  bool stopping_ = false;
  std::optional<Error> last_disk_error_;
  mutable std::mutex health_mutex_;
  DiskHealth health_;
  std::uint64_t unreported_failures_ = 0;  // failed writes no report line has counted yet
  std::optional<std::chrono::steady_clock::time_point> last_report_;
  bool spell_reported_ = false;  // the current failing spell has had a line

  // Disk stage: one thread (SQLite has one connection per DiskCache), reads before writes.
  std::unique_ptr<WorkerPool> disk_thread_;  // "vts-disk"; joined by the destructor
  std::mutex disk_mutex_, disk_use_mutex_;
  std::condition_variable disk_idle_cv_;
  std::deque<std::function<void()>> disk_reads_, disk_writes_;
  std::deque<Put> disk_puts_;
  bool disk_busy_ = false;

  struct {
    std::atomic<std::uint64_t> gets{0}, ram_hits{0}, disk_hits{0}, network_fetches{0}, absent{0},
        errors{0}, corrupt_rejected{0}, revalidations{0}, not_modified{0}, disk_write_errors{0},
        cancelled{0}, mismatch_rejected{0};
  } stats_;
};

Result<std::unique_ptr<TileCache>> TileCache::create(std::shared_ptr<TileSource> source,
                                                     TileCacheOptions options) {
  if (!source) return make_error(ErrorCode::invalid_argument, "tile cache without a source");
  std::unique_ptr<DiskCache> disk;
  if (options.disk) {
    auto d = DiskCache::open(*options.disk);
    if (!d) return d.error();
    disk = std::move(*d);
  }
  std::unique_ptr<WorkerPool> disk_thread;
  if (disk) {
    auto started = Impl::start_disk_thread();
    if (!started) return std::move(started).error();
    disk_thread = std::move(*started);
  }
  auto impl = std::make_unique<Impl>(std::move(source), std::move(options), std::move(disk),
                                     std::move(disk_thread));
  return std::unique_ptr<TileCache>(new TileCache(std::move(impl)));
}

TileCache::TileCache(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TileCache::~TileCache() = default;
const SourceInfo& TileCache::info() const {
  return impl_->info();
}
TileCache::Handle TileCache::get(TileId id, const GetOptions& options, PayloadCallback callback) {
  return impl_->get(id, options, std::move(callback));
}
void TileCache::cancel(Handle h) {
  impl_->cancel(h);
}
Status TileCache::flush() {
  return impl_->flush();
}
TileCache::Stats TileCache::stats() const {
  return impl_->stats();
}
RamCache* TileCache::ram() {
  return impl_->ram();
}
DiskCache* TileCache::disk() {
  return impl_->disk();
}
std::optional<Error> TileCache::last_disk_error() const {
  return impl_->last_disk_error();
}
DiskHealth TileCache::disk_health() const {
  return impl_->disk_health();
}

}  // namespace vts::client
