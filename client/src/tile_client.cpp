// TileClient: decode worker pool, bounded event queue (see the header).
#include "vts/client/tile_client.hpp"

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <set>

#include "vts/base/worker_pool.hpp"
#include "vts/client/image_tiles.hpp"

namespace vts::client {

class TileClient::Impl {
 public:
  // `decoders`: the pool the decodes run on, one job per payload (start_decoders).
  Impl(std::unique_ptr<TileCache> cache, TileClientOptions options,
       std::unique_ptr<WorkerPool> decoders)
      : cache_(std::move(cache)),
        options_(std::move(options)),
        spec_(cache_->info().info.tile_spec()),
        decoders_(std::move(decoders)) {}

  static Result<std::unique_ptr<WorkerPool>> start_decoders(const TileClientOptions& o) {
    return WorkerPool::start({.threads = unsigned(std::max(1, o.decode_threads)),
                              .capacity = 0,  // on_payload must not block: payloads wait here
                              .name = "vts-decode"});
  }

  ~Impl() {
    std::vector<TileCache::Handle> to_cancel;
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
      for (auto& [id, slot] : inflight_)
        if (slot.handle) to_cancel.push_back(slot.handle);
    }
    space_cv_.notify_all();
    for (auto h : to_cancel) cache_->cancel(h);
    // The decodes still queued see stop_ and return at once; a payload arriving later is refused
    // by the closed pool.
    decoders_->join();
    cache_.reset();  // runs the last callbacks (cancelled) while this object still lives
  }

  void request(TileId id, double urgency) {
    std::uint64_t serial = 0;
    {
      std::lock_guard lock(mutex_);
      if (stop_ || delivered_.count(id) || inflight_.count(id)) return;
      serial = next_serial_++;
      inflight_[id] = Slot{serial, 0, false};
      stats_.requested++;
    }
    GetOptions go;
    go.level = id.z;
    go.urgency = urgency;
    go.pin = id.z == 0;  // the root is every tile's last fallback
    const auto h = cache_->get(
        id, go, [this, id, serial](PayloadResult&& r) { on_payload(id, serial, std::move(r)); });
    std::lock_guard lock(mutex_);
    auto it = inflight_.find(id);
    if (it != inflight_.end() && it->second.serial == serial && !it->second.fetched)
      it->second.handle = h;
  }

  void cancel(TileId id) {
    TileCache::Handle h = 0;
    {
      std::lock_guard lock(mutex_);
      auto it = inflight_.find(id);
      if (it == inflight_.end() || it->second.fetched) return;  // decoding: let it finish
      h = it->second.handle;
      inflight_.erase(it);
      stats_.cancelled++;
    }
    if (h) cache_->cancel(h);
  }

  void release(TileId id) {
    std::lock_guard lock(mutex_);
    delivered_.erase(id);
  }

  std::size_t poll(std::vector<TileEvent>& out, std::size_t max) {
    std::size_t n = 0;
    {
      std::lock_guard lock(mutex_);
      while (n < max && !events_.empty()) {
        queued_bytes_ -= events_.front().image.pixels.size();
        out.push_back(std::move(events_.front()));
        events_.pop_front();
        ++n;
      }
    }
    if (n) space_cv_.notify_all();
    return n;
  }

  std::optional<TileEvent> wait(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    if (!events_cv_.wait_for(lock, timeout, [this] { return !events_.empty(); }))
      return std::nullopt;
    TileEvent e = std::move(events_.front());
    events_.pop_front();
    queued_bytes_ -= e.image.pixels.size();
    lock.unlock();
    space_cv_.notify_all();
    return e;
  }

  Stats stats() const {
    std::lock_guard lock(mutex_);
    Stats s = stats_;
    s.queued_decoded_bytes = queued_bytes_;
    return s;
  }

  TileCache& cache() { return *cache_; }

 private:
  struct Slot {
    std::uint64_t serial = 0;
    TileCache::Handle handle = 0;
    bool fetched = false;  // the payload is here (being decoded)
  };

  void on_payload(TileId id, std::uint64_t serial, PayloadResult&& r) {
    std::unique_lock lock(mutex_);
    auto it = inflight_.find(id);
    if (it == inflight_.end() || it->second.serial != serial) return;  // cancelled meanwhile
    switch (r.kind) {
      case PayloadResult::Kind::ok:
        it->second.fetched = true;
        it->second.handle = 0;
        // Queued under the lock, in the order the payloads came (the pool is unbounded: this
        // never blocks). The job holds the payload, compressed, until a decoder is free.
        decoders_->submit([this, id, serial, payload = std::move(r)]() mutable {
          decode_one(id, serial, std::move(payload));
        });
        return;
      case PayloadResult::Kind::cancelled:
        inflight_.erase(it);
        return;
      case PayloadResult::Kind::absent:
      case PayloadResult::Kind::error: {
        inflight_.erase(it);
        TileEvent e;
        e.id = id;
        e.kind = r.kind == PayloadResult::Kind::absent ? TileEvent::Kind::absent
                                                       : TileEvent::Kind::error;
        (e.kind == TileEvent::Kind::absent ? stats_.absent : stats_.errors)++;
        e.error = std::move(r.error);
        events_.push_back(std::move(e));
        lock.unlock();
        events_cv_.notify_all();
        return;
      }
    }
  }

  // One job on the decoders: decodes the payload, then waits for room in the event queue.
  void decode_one(TileId id, std::uint64_t serial, PayloadResult payload) {
    {
      std::lock_guard lock(mutex_);
      if (stop_) return;  // closing: what is still queued is dropped undecoded
    }
    TileEvent e;
    e.id = id;
    e.from = payload.from;
    auto image = decode(payload.tile->payload);
    if (image) {
      e.kind = TileEvent::Kind::decoded;
      e.image = std::move(*image);
    } else {
      e.kind = TileEvent::Kind::error;
      e.error = image.error();
    }
    payload.tile.reset();
    std::unique_lock lock(mutex_);
    // Back-pressure: wait for room unless the queue is empty (a tile larger than the whole
    // budget still gets through, alone). A decoder waiting here takes no further job, so the
    // payloads behind it wait compressed in the pool's queue.
    space_cv_.wait(lock, [&] {
      return stop_ || events_.empty() ||
             queued_bytes_ + e.image.pixels.size() <= options_.decoded_bytes;
    });
    if (stop_) return;
    auto it = inflight_.find(id);
    if (it != inflight_.end() && it->second.serial == serial) inflight_.erase(it);
    if (e.kind == TileEvent::Kind::decoded) {
      delivered_.insert(id);
      stats_.decoded++;
    } else {
      stats_.decode_errors++;
    }
    queued_bytes_ += e.image.pixels.size();
    events_.push_back(std::move(e));
    events_cv_.notify_all();
  }

  // The tileset's size and codec bound the decode (the cache refused other tiles already). An
  // image tileset's PNG/JPEG/WebP tiles must decode to its stored size (T x T, no border); any of
  // the three is taken whatever the tileset declares, as web maps do (`vts verify` is strict).
  Result<TileImage> decode(std::span<const std::uint8_t> payload) const {
    if (!image_) return decode_tile(payload, spec_);
    return decode_image_tile(payload, "image", spec_.width);
  }

  std::unique_ptr<TileCache> cache_;
  TileClientOptions options_;
  const TileSpec spec_;                                      // what the tileset's tiles are
  const bool image_ = !cache_->info().image_format.empty();  // standard image tiles
  mutable std::mutex mutex_;
  std::condition_variable space_cv_, events_cv_;
  std::map<TileId, Slot> inflight_;
  std::set<TileId> delivered_;
  std::deque<TileEvent> events_;
  std::size_t queued_bytes_ = 0;
  std::uint64_t next_serial_ = 1;
  bool stop_ = false;
  Stats stats_;
  // "vts-decode": joined by the destructor before the members its jobs use go away.
  std::unique_ptr<WorkerPool> decoders_;
};

Result<std::unique_ptr<TileClient>> TileClient::create(std::shared_ptr<TileSource> source,
                                                       TileClientOptions options) {
  auto cache = TileCache::create(std::move(source), options.cache);
  if (!cache) return cache.error();
  auto decoders = Impl::start_decoders(options);
  if (!decoders) return std::move(decoders).error();
  auto impl = std::make_unique<Impl>(std::move(*cache), std::move(options), std::move(*decoders));
  return std::unique_ptr<TileClient>(new TileClient(std::move(impl)));
}

TileClient::TileClient(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TileClient::~TileClient() = default;
const SourceInfo& TileClient::info() const {
  return impl_->cache().info();
}
void TileClient::request(TileId id, double urgency) {
  impl_->request(id, urgency);
}
void TileClient::cancel(TileId id) {
  impl_->cancel(id);
}
void TileClient::release(TileId id) {
  impl_->release(id);
}
std::size_t TileClient::poll(std::vector<TileEvent>& out, std::size_t max) {
  return impl_->poll(out, max);
}
std::optional<TileEvent> TileClient::wait(std::chrono::milliseconds timeout) {
  return impl_->wait(timeout);
}
TileClient::Stats TileClient::stats() const {
  return impl_->stats();
}
TileCache& TileClient::cache() {
  return impl_->cache();
}

}  // namespace vts::client
