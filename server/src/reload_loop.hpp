// The background thread that keeps the registry current: registry.reload(false) every `interval`
// (0 = never), and on request (force: registry.reload(true)). Requests that arrive while a reload
// runs are merged into the next one, and unforced ones wait until kMinGap after the previous
// reload: requests for tiles of an archive being copied in place ask for one each. A file
// modified in place (or new in a folder) is opened once it has been left unmodified for a whole
// interval (kMaxSettle at most; kIdleSettle when there is no interval). Swaps,
// additions, removals and refusals are logged to stderr (file names with escape_controls: one
// line each, whatever a file is named) and counted in the metrics. A refusal that every reload
// repeats (a folder that cannot be listed while the process is out of file descriptors) is
// logged again only after kRepeatInterval, with the number of times it was not.
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "metrics.hpp"
#include "native_tile_cache.hpp"
#include "vts/base/result.hpp"
#include "vts/server/tileset_registry.hpp"

namespace vts {
inline namespace server {
namespace http_detail {

class ReloadLoop {
 public:
  // `registry` and `metrics` must outlive the loop.
  ReloadLoop(TilesetRegistry& registry, Metrics& metrics, std::chrono::milliseconds interval)
      : registry_(registry),
        metrics_(metrics),
        interval_(interval),
        settle_(interval.count() > 0 ? std::min(interval, kMaxSettle) : kIdleSettle) {}
  ReloadLoop(const ReloadLoop&) = delete;
  ReloadLoop& operator=(const ReloadLoop&) = delete;
  ~ReloadLoop() { stop(); }

  // After each reload that replaced, removed or found modified a tileset, drops from `cache` the
  // tiles of every archive no longer served as it was opened. Before start().
  void drop_stale_tiles_from(std::shared_ptr<NativeTileCache> cache) { tiles_ = std::move(cache); }
  // Starts the thread. Error io when the system refuses a thread (the loop then does nothing;
  // stop() is still safe).
  Status start();
  // Asks for a reload (force: every tileset) and returns at once. Thread-safe.
  void request(bool force);
  // Ends the loop after the reload in progress, if any; returns at once. Thread-safe.
  void quit();
  // quit(), then waits for the thread. From the thread that called start().
  void stop();

 private:
  void run();
  void reload(bool force);
  void drop_stale_tiles();

  static constexpr std::chrono::milliseconds kMinGap{100};
  static constexpr std::chrono::milliseconds kMaxSettle{2000}, kIdleSettle{1000};
  static constexpr std::chrono::seconds kRepeatInterval{60};

  // Refusals the previous reload logged or held back (only the reload thread touches it).
  struct Logged {
    std::chrono::steady_clock::time_point at;  // when its last line was written
    std::uint64_t held_back = 0;               // repeats since that line
  };
  std::map<std::string, Logged> refusals_;

  TilesetRegistry& registry_;
  Metrics& metrics_;
  std::shared_ptr<NativeTileCache> tiles_;  // may be null
  const std::chrono::milliseconds interval_;
  const std::chrono::milliseconds settle_;  // see TilesetRegistry::reload
  std::mutex mutex_;
  std::condition_variable cv_;
  bool quit_ = false, pending_ = false, force_ = false;
  std::chrono::steady_clock::time_point last_{};  // when the previous reload ended
  std::thread thread_;
};

}  // namespace http_detail
}  // namespace server
}  // namespace vts
