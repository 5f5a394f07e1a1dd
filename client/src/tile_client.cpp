// TileClient: decode worker pool, bounded event queue (see the header).
#include "vts/client/tile_client.hpp"

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <set>
#include <system_error>
#include <thread>

#include "vts/imaging/web_image.hpp"

namespace vts::client {

class TileClient::Impl {
 public:
  Impl(std::unique_ptr<TileCache> cache, TileClientOptions options)
      : cache_(std::move(cache)),
        options_(std::move(options)),
        spec_(cache_->info().info.tile_spec()) {
    const int n = std::max(1, options_.decode_threads);
    try {
      for (int i = 0; i < n; ++i) workers_.emplace_back([this] { decode_loop(); });
    } catch (const std::system_error&) {
      // A thread the system refused: the started ones are stopped and joined (a joinable
      // std::thread destroyed would abort), then create() reports it.
      {
        std::lock_guard lock(mutex_);
        stop_ = true;
      }
      decode_cv_.notify_all();
      for (auto& w : workers_) w.join();
      throw;
    }
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
    decode_cv_.notify_all();
    for (auto h : to_cancel) cache_->cancel(h);
    for (auto& w : workers_) w.join();
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
  struct Job {
    TileId id;
    std::uint64_t serial = 0;
    PayloadResult payload;
  };

  void on_payload(TileId id, std::uint64_t serial, PayloadResult&& r) {
    std::unique_lock lock(mutex_);
    auto it = inflight_.find(id);
    if (it == inflight_.end() || it->second.serial != serial) return;  // cancelled meanwhile
    switch (r.kind) {
      case PayloadResult::Kind::ok:
        it->second.fetched = true;
        it->second.handle = 0;
        decode_queue_.push_back(Job{id, serial, std::move(r)});
        lock.unlock();
        decode_cv_.notify_one();
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

  void decode_loop() {
    std::unique_lock lock(mutex_);
    for (;;) {
      decode_cv_.wait(lock, [this] { return stop_ || !decode_queue_.empty(); });
      if (stop_) return;
      Job job = std::move(decode_queue_.front());
      decode_queue_.pop_front();
      lock.unlock();
      TileEvent e;
      e.id = job.id;
      e.from = job.payload.from;
      auto image = decode(job.payload.tile->payload);
      if (image) {
        e.kind = TileEvent::Kind::decoded;
        e.image = std::move(*image);
      } else {
        e.kind = TileEvent::Kind::error;
        e.error = image.error();
      }
      job.payload.tile.reset();
      lock.lock();
      // Back-pressure: wait for room unless the queue is empty (a tile larger than the whole
      // budget still gets through, alone).
      space_cv_.wait(lock, [&] {
        return stop_ || events_.empty() ||
               queued_bytes_ + e.image.pixels.size() <= options_.decoded_bytes;
      });
      if (stop_) return;
      auto it = inflight_.find(job.id);
      if (it != inflight_.end() && it->second.serial == job.serial) inflight_.erase(it);
      if (e.kind == TileEvent::Kind::decoded) {
        delivered_.insert(job.id);
        stats_.decoded++;
      } else {
        stats_.decode_errors++;
      }
      queued_bytes_ += e.image.pixels.size();
      events_.push_back(std::move(e));
      events_cv_.notify_all();
    }
  }

  // The tileset's size and codec bound the decode (the cache refused other tiles already). An
  // image tileset's PNG/JPEG/WebP tiles must decode to its stored size (T x T, no border).
  Result<TileImage> decode(std::span<const std::uint8_t> payload) const {
    if (!image_) return decode_tile(payload, spec_);
    auto image = imaging::decode_web_image(payload);
    if (image && (image->width != spec_.width || image->height != spec_.height))
      return make_error(ErrorCode::corrupt, "image tile of " + std::to_string(image->width) + "x" +
                                                std::to_string(image->height) +
                                                " pixels in a tileset of " +
                                                std::to_string(spec_.width) + " px tiles");
    return image;
  }

  std::unique_ptr<TileCache> cache_;
  TileClientOptions options_;
  const TileSpec spec_;                                      // what the tileset's tiles are
  const bool image_ = !cache_->info().image_format.empty();  // standard image tiles
  mutable std::mutex mutex_;
  std::condition_variable decode_cv_, space_cv_, events_cv_;
  std::map<TileId, Slot> inflight_;
  std::set<TileId> delivered_;
  std::deque<Job> decode_queue_;
  std::deque<TileEvent> events_;
  std::size_t queued_bytes_ = 0;
  std::uint64_t next_serial_ = 1;
  bool stop_ = false;
  Stats stats_;
  std::vector<std::thread> workers_;
};

Result<std::unique_ptr<TileClient>> TileClient::create(std::shared_ptr<TileSource> source,
                                                       TileClientOptions options) {
  auto cache = TileCache::create(std::move(source), options.cache);
  if (!cache) return cache.error();
  std::unique_ptr<Impl> impl;
  try {
    impl = std::make_unique<Impl>(std::move(*cache), std::move(options));
  } catch (const std::system_error& e) {
    return make_error(ErrorCode::io, std::string("cannot start a tile decode thread: ") + e.what());
  }
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
