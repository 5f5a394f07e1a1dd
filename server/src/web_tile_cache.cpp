#include "web_tile_cache.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

void Flight::on_done(Callback cb, std::stop_token interest) {
  std::unique_lock lock(m_);
  if (expected_ > 0) --expected_;
  if (!done_) {
    waiters_.push_back({std::move(cb), std::move(interest)});
    return;
  }
  lock.unlock();
  cb(tile_, status_, error_);
}

void Flight::expect() {
  std::lock_guard lock(m_);
  ++expected_;
}

bool Flight::wanted() const {
  std::lock_guard lock(m_);
  if (expected_ > 0) return true;
  for (const Waiter& w : waiters_)
    if (!w.interest.stop_requested()) return true;
  return false;
}

void Flight::complete(WebTilePtr tile, int status, std::string error) {
  std::vector<Waiter> waiters;
  {
    std::lock_guard lock(m_);
    tile_ = std::move(tile);
    status_ = status;
    error_ = std::move(error);
    done_ = true;
    waiters.swap(waiters_);
  }
  for (auto& w : waiters) w.cb(tile_, status_, error_);  // the result no longer changes
}

WebTileCache::WebTileCache(std::size_t capacity_bytes, int encode_threads, EncodeLimits limits)
    : capacity_(capacity_bytes) {
  if (encode_threads > 0) queue_ = std::make_unique<EncodeQueue>(encode_threads, limits);
}

WebTileCache::~WebTileCache() {
  stop();
}

void WebTileCache::stop() {
  if (queue_) queue_->stop();
}

EncodeQueue::Admit WebTileCache::queue(const std::string& key, const std::shared_ptr<Flight>& lead,
                                       std::uint64_t owner, std::function<void()> encode) {
  // The cache outlives its jobs (its destructor runs or drops the queued ones before it returns).
  EncodeQueue::Job job;
  job.owner = owner;
  job.wanted = [this, key, lead] { return !drop_if_unwanted(key, lead); };
  job.run = std::move(encode);
  job.dropped = [this, lead] {
    dropped.fetch_add(1, std::memory_order_relaxed);
    lead->complete(nullptr, 503, "nobody waits for this image any more");
  };
  const auto admit = queue_->push(std::move(job));
  if (admit != EncodeQueue::Admit::queued) shed.fetch_add(1, std::memory_order_relaxed);
  return admit;
}

bool WebTileCache::drop_if_unwanted(const std::string& key, const std::shared_ptr<Flight>& flight) {
  // Under the map's lock, so that a request arriving now either joins this flight before the
  // check (and keeps it wanted) or finds no flight and leads a new one.
  std::lock_guard lock(m_);
  if (flight->wanted()) return false;
  if (auto it = flights_.find(key); it != flights_.end() && it->second == flight)
    flights_.erase(it);
  return true;
}

WebTilePtr WebTileCache::peek(const std::string& key) {
  std::lock_guard lock(m_);
  auto it = map_.find(key);
  if (it == map_.end()) return nullptr;
  lru_.splice(lru_.begin(), lru_, it->second.lru);
  hits.fetch_add(1, std::memory_order_relaxed);
  return it->second.tile;
}

WebTileCache::Lookup WebTileCache::acquire(const std::string& key) {
  std::lock_guard lock(m_);
  if (auto it = map_.find(key); it != map_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second.lru);
    hits.fetch_add(1, std::memory_order_relaxed);
    return {.hit = it->second.tile};
  }
  misses.fetch_add(1, std::memory_order_relaxed);
  if (auto it = flights_.find(key); it != flights_.end()) {
    waits.fetch_add(1, std::memory_order_relaxed);
    it->second->expect();
    return {.wait = it->second};
  }
  auto flight = std::make_shared<Flight>();
  flight->expect();
  flights_.emplace(key, flight);
  return {.lead = std::move(flight)};
}

void WebTileCache::finish(const std::string& key, const std::shared_ptr<Flight>& flight,
                          WebTilePtr tile, int status, std::string error) {
  {
    std::lock_guard lock(m_);
    if (auto it = flights_.find(key); it != flights_.end() && it->second == flight)
      flights_.erase(it);
    const std::size_t size = tile ? tile->bytes.size() : 0;
    if (tile && size <= capacity_ && !map_.contains(key)) {
      while (used_ + size > capacity_ && !lru_.empty()) {
        auto victim = map_.find(lru_.back());
        used_ -= victim->second.tile->bytes.size();
        map_.erase(victim);
        lru_.pop_back();
        evictions.fetch_add(1, std::memory_order_relaxed);
      }
      lru_.push_front(key);
      map_.emplace(key, Entry{tile, lru_.begin()});
      used_ += size;
    }
    bytes.store(used_, std::memory_order_relaxed);
    entries.store(map_.size(), std::memory_order_relaxed);
  }
  flight->complete(std::move(tile), status, std::move(error));
}

std::string web_metrics_text(const WebTileCache& c) {
  auto v = [](const std::atomic<std::uint64_t>& a) {
    return std::to_string(a.load(std::memory_order_relaxed));
  };
  std::string s;
  s += "# HELP vts_web_tile_requests_total Web image tile requests (PNG/WebP/JPEG) by format.\n";
  s += "# TYPE vts_web_tile_requests_total counter\n";
  constexpr imaging::WebFormat kFormats[] = {imaging::WebFormat::png, imaging::WebFormat::webp,
                                             imaging::WebFormat::jpeg};
  for (imaging::WebFormat f : kFormats) {
    s += "vts_web_tile_requests_total{format=\"" + std::string(imaging::web_format_extension(f)) +
         "\"} " + v(c.requests_by_format[static_cast<std::size_t>(f)]) + "\n";
  }
  auto counter = [&](const char* name, const char* help, const std::atomic<std::uint64_t>& a,
                     const char* type = "counter") {
    s += std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " " + type + "\n" +
         name + " " + v(a) + "\n";
  };
  counter("vts_web_cache_hits_total", "Web images answered from the RAM cache.", c.hits);
  counter("vts_web_cache_misses_total", "Web images not in the RAM cache.", c.misses);
  counter("vts_web_cache_waits_total",
          "Misses that waited for the encoding of the same image under way (single flight).",
          c.waits);
  counter("vts_web_cache_evictions_total", "Web images evicted from the RAM cache.", c.evictions);
  counter("vts_web_cache_bytes", "Bytes of web images held in the RAM cache.", c.bytes, "gauge");
  counter("vts_web_cache_entries", "Web images held in the RAM cache.", c.entries, "gauge");
  s += "# HELP vts_web_cache_capacity_bytes The RAM cache's byte cap (web.cache_mib).\n";
  s += "# TYPE vts_web_cache_capacity_bytes gauge\n";
  s += "vts_web_cache_capacity_bytes " + std::to_string(c.capacity()) + "\n";
  counter("vts_web_encodes_dropped_total",
          "Web image encodes dropped before they ran: every request waiting for them had gone.",
          c.dropped);
  counter("vts_web_encodes_shed_total",
          "Web image misses answered 503 (Retry-After) because the encode queue was full, in all "
          "or for their connection.",
          c.shed);
  s += "# HELP vts_web_encode_queue_length Web image encodes waiting for a worker.\n";
  s += "# TYPE vts_web_encode_queue_length gauge\n";
  s += "vts_web_encode_queue_length " + std::to_string(c.queued()) + "\n";
  counter("vts_web_encodes_total", "Web images encoded (tile decoded, cropped, encoded).",
          c.encodes);
  counter("vts_web_encode_failures_total", "Web image encodings that failed.", c.encode_failures);
  s += "# HELP vts_web_encode_seconds_sum Time spent decoding tiles and encoding web images.\n";
  s += "# TYPE vts_web_encode_seconds_sum counter\n";
  s += "vts_web_encode_seconds_sum " +
       std::to_string(double(c.encode_us_sum.load(std::memory_order_relaxed)) / 1e6) + "\n";
  return s;
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
