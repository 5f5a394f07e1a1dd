// The RAM cache of web images (PNG / WebP / JPEG) that `vts serve` encodes from its tiles on
// request (docs/PROTOCOL.md §12), with single flight: concurrent requests for one image encode
// it once. Thread-safe; every method is short (a lock around a map), encoding happens outside.
//
// acquire() answers a key with the cached image (hit), or makes the caller the leader of a new
// flight (miss: the caller encodes, then calls finish()), or hands it the flight already under
// way (the caller registers a callback with Flight::on_done and waits without blocking).
//
// With workers, encodes go through an EncodeQueue (encode_queue.hpp): bounded, fair between
// connections, and cancellable. A flight knows who still waits for it (each waiter registers with
// its connection's stop token); an encode nobody waits for any more is dropped before it runs.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <stop_token>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "encode_queue.hpp"
#include "vts/imaging/web_image.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

// One encoded image and its strong ETag (with quotes).
struct WebTile {
  std::vector<std::uint8_t> bytes;
  std::string etag;
  const char* content_type = "";
};
using WebTilePtr = std::shared_ptr<const WebTile>;

// An encoding under way. Its result is set once (complete); callbacks registered before run on
// the thread that completes it, those registered after run at once in on_done().
class Flight {
 public:
  // `tile` null = no image: `status` (500: the encode failed; 503: the server shed or dropped it,
  // try again) and `error` say why.
  using Callback =
      std::function<void(const WebTilePtr& tile, int status, const std::string& error)>;
  // Registers a waiter. A waiter whose `interest` is stopped (its connection closed) no longer
  // counts as wanting the image; its callback still runs when the flight completes.
  void on_done(Callback cb, std::stop_token interest = {});
  // True while the result may still be wanted: a request counted by expect() that has not called
  // on_done() yet, or a waiter whose interest has not been stopped.
  bool wanted() const;
  // One more request will call on_done() (WebTileCache::acquire counts its caller).
  void expect();
  void complete(WebTilePtr tile, int status, std::string error);

 private:
  struct Waiter {
    Callback cb;
    std::stop_token interest;
  };
  mutable std::mutex m_;
  bool done_ = false;
  int expected_ = 0;  // requests handed the flight that have not called on_done() yet
  WebTilePtr tile_;
  int status_ = 200;
  std::string error_;
  std::vector<Waiter> waiters_;
};

class WebTileCache {
 public:
  // At most `capacity_bytes` of image bytes are kept (0: none; single flight still applies).
  // With `encode_threads` > 0, encodings run on that many worker threads (queue()); with 0, on
  // the caller's thread. A worker thread the system refuses: std::system_error, after the ones
  // started are joined.
  explicit WebTileCache(std::size_t capacity_bytes, int encode_threads = 0,
                        EncodeLimits limits = {});
  // stop().
  ~WebTileCache();
  // Finishes the encodings queued, then joins the workers; later encodings run on the caller's
  // thread. Call it before the threads the flights' callbacks post to go away.
  void stop();
  WebTileCache(const WebTileCache&) = delete;
  WebTileCache& operator=(const WebTileCache&) = delete;

  bool has_workers() const noexcept { return queue_ && queue_->threads() > 0; }

  struct Lookup {
    WebTilePtr hit;                // a cached image
    std::shared_ptr<Flight> lead;  // a miss: encode, then finish(key, lead, ...)
    std::shared_ptr<Flight> wait;  // a miss under way: wait->on_done(...)
  };
  // Every lead and wait counts its caller as expected to call on_done() (Flight::expect).
  Lookup acquire(const std::string& key);
  // The cached image, or null (counting nothing then: the acquire() that follows counts the miss).
  WebTilePtr peek(const std::string& key);
  // Stores `tile` (when it fits, evicting the least recently used), ends the flight, then wakes
  // its waiters on this thread. `status` as in Flight::Callback.
  void finish(const std::string& key, const std::shared_ptr<Flight>& flight, WebTilePtr tile,
              int status, std::string error);

  // Queues `encode` of the flight `lead` of `key` for the workers (has_workers() must be true),
  // on behalf of connection `owner`. Before it runs, a flight nobody wants any more is ended
  // (503, not cached) and `encode` never runs. Over a cap (EncodeQueue::Admit), nothing is
  // queued: the caller ends the flight (finish with 503).
  EncodeQueue::Admit queue(const std::string& key, const std::shared_ptr<Flight>& lead,
                           std::uint64_t owner, std::function<void()> encode);

  std::size_t capacity() const noexcept { return capacity_; }
  EncodeLimits limits() const noexcept { return queue_ ? queue_->limits() : EncodeLimits{}; }
  std::size_t queued() const { return queue_ ? queue_->queued() : 0; }

  // Counters for /metrics (relaxed).
  std::array<std::atomic<std::uint64_t>, 3> requests_by_format{};  // WebFormat order
  std::atomic<std::uint64_t> hits{0}, misses{0}, waits{0}, evictions{0};
  std::atomic<std::uint64_t> encodes{0}, encode_failures{0}, encode_us_sum{0};
  std::atomic<std::uint64_t> bytes{0}, entries{0};
  // Encodes dropped before they ran (nobody waited any more), and misses refused 503 because
  // the queue was full (in all, or for their connection).
  std::atomic<std::uint64_t> dropped{0}, shed{0};

 private:
  // Under m_: ends `flight` when it is still the one of `key` and nobody wants it; true then.
  bool drop_if_unwanted(const std::string& key, const std::shared_ptr<Flight>& flight);

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
  std::unique_ptr<EncodeQueue> queue_;  // null without workers
};

// Prometheus lines of the cache's counters (vts_web_*).
std::string web_metrics_text(const WebTileCache& c);

}  // namespace http_detail
}  // namespace server
}  // namespace vts
