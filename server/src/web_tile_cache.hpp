// The RAM cache of web images (PNG / WebP / JPEG) that `vts serve` encodes from its tiles on
// request (docs/PROTOCOL.md §12), with single flight: concurrent requests for one image encode
// it once. Thread-safe; every method is short (a lock around a map), encoding happens outside.
//
// acquire() answers a key with the cached image (hit), or makes the caller the leader of a new
// flight (miss: the caller encodes, then calls finish()), or hands it the flight already under
// way (the caller registers a callback with Flight::on_done and waits without blocking).
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <vector>

#include "vts/protocol/web_image.hpp"

namespace vts::http_detail {

// One encoded image and its strong ETag (with quotes).
struct WebTile {
  std::vector<std::uint8_t> bytes;
  std::string etag;
  const char* content_type = "";
};
using WebTilePtr = std::shared_ptr<const WebTile>;

// An encoding under way. Its result is set once (finish); callbacks registered before run on the
// thread that finishes it, those registered after run at once in on_done().
class Flight {
 public:
  // `tile` null = the encode failed, `error` says why.
  using Callback = std::function<void(const WebTilePtr& tile, const std::string& error)>;
  void on_done(Callback cb);
  void complete(WebTilePtr tile, std::string error);

 private:
  std::mutex m_;
  bool done_ = false;
  WebTilePtr tile_;
  std::string error_;
  std::vector<Callback> waiters_;
};

class WebTileCache {
 public:
  // At most `capacity_bytes` of image bytes are kept (0: none; single flight still applies).
  // With `encode_threads` > 0, encodings run on that many worker threads (run()); with 0, on
  // the caller's thread.
  explicit WebTileCache(std::size_t capacity_bytes, int encode_threads = 0);
  // stop().
  ~WebTileCache();
  // Finishes the encodings queued, then joins the workers; later encodings run on the caller's
  // thread. Call it before the threads the flights' callbacks post to go away.
  void stop();
  WebTileCache(const WebTileCache&) = delete;
  WebTileCache& operator=(const WebTileCache&) = delete;

  bool has_workers() const noexcept { return !workers_.empty(); }
  // Queues `job` for a worker (has_workers() must be true).
  void run(std::function<void()> job);

  struct Lookup {
    WebTilePtr hit;                // a cached image
    std::shared_ptr<Flight> lead;  // a miss: encode, then finish(key, lead, ...)
    std::shared_ptr<Flight> wait;  // a miss under way: wait->on_done(...)
  };
  Lookup acquire(const std::string& key);
  // The cached image, or null (counting nothing then: the acquire() that follows counts the miss).
  WebTilePtr peek(const std::string& key);
  // Stores `tile` (when it fits, evicting the least recently used), ends the flight, then wakes
  // its waiters on this thread.
  void finish(const std::string& key, const std::shared_ptr<Flight>& flight, WebTilePtr tile,
              std::string error);

  std::size_t capacity() const noexcept { return capacity_; }

  // Counters for /metrics (relaxed).
  std::array<std::atomic<std::uint64_t>, 3> requests_by_format{};  // WebFormat order
  std::atomic<std::uint64_t> hits{0}, misses{0}, waits{0}, evictions{0};
  std::atomic<std::uint64_t> encodes{0}, encode_failures{0}, encode_us_sum{0};
  std::atomic<std::uint64_t> bytes{0}, entries{0};

 private:
  struct Entry {
    WebTilePtr tile;
    std::list<std::string>::iterator lru;
  };
  std::size_t capacity_;
  std::mutex m_;
  std::unordered_map<std::string, Entry> map_;
  std::list<std::string> lru_;  // front = most recently used
  std::unordered_map<std::string, std::shared_ptr<Flight>> flights_;
  std::size_t used_ = 0;
  // The encode workers.
  std::mutex jobs_m_;
  std::condition_variable jobs_cv_;
  std::deque<std::function<void()>> jobs_;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

// Prometheus lines of the cache's counters (vts_web_*).
std::string web_metrics_text(const WebTileCache& c);

}  // namespace vts::http_detail
