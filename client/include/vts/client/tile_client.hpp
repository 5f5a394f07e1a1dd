// The viewer's end of the client stack: TileCache plus a decode worker pool.
//
// request(id) fetches one tile through the cache, at its level's priority (coarser levels
// first, then urgency); the root is pinned in RAM. Which tiles to ask for, ancestors included,
// is the caller's policy (the renderer's TileStream). Payloads are decoded (header, checksum,
// zstd, filter) by `decode_threads` workers ("vts-decode"); decoded tiles wait in a queue bounded
// by `decoded_bytes` (the renderer's upload queue drains it with poll()). When the queue is full
// the workers stop (back-pressure) and payloads wait undecoded, compressed, so memory stays bounded
// by what was requested.
//
// Every request ends in exactly one Event: the decoded tile, or why there is none (absent,
// error), unless it was cancelled first. A delivered tile is not asked for again until the
// consumer calls release(id) — when it has dropped the tile.
#pragma once

#include <chrono>
#include <cstddef>
#include <memory>
#include <optional>
#include <vector>

#include "vts/client/tile_cache.hpp"
#include "vts/protocol/codec.hpp"

namespace vts::client {

struct TileClientOptions {
  TileCacheOptions cache;
  int decode_threads = 2;
  std::size_t decoded_bytes = 64u << 20;  // decoded tiles waiting for the consumer
};

struct TileEvent {
  enum class Kind { decoded, absent, error };
  Kind kind = Kind::error;
  TileId id;
  TileImage image;  // Kind::decoded
  PayloadResult::From from = PayloadResult::From::network;
  std::optional<Error> error;  // Kind::error
};

class TileClient {
 public:
  static Result<std::unique_ptr<TileClient>> create(std::shared_ptr<TileSource> source,
                                                    TileClientOptions options = {});
  ~TileClient();  // cancels what is pending, stops the workers
  TileClient(const TileClient&) = delete;
  TileClient& operator=(const TileClient&) = delete;

  const SourceInfo& info() const;
  // Asks for a tile. Repeating a request for a tile on its way or delivered does nothing.
  // Thread-safe, never blocks on I/O.
  void request(TileId id, double urgency = 0);
  // Nobody wants the tile any more (it left the view): its fetch is cancelled if still pending.
  void cancel(TileId id);
  // The consumer dropped a delivered tile; a later request() fetches it again (from the caches).
  void release(TileId id);
  // Moves up to `max` events into `out` without blocking; returns how many.
  std::size_t poll(std::vector<TileEvent>& out, std::size_t max);
  // Waits up to `timeout` for one event.
  std::optional<TileEvent> wait(std::chrono::milliseconds timeout);

  struct Stats {
    std::uint64_t requested = 0, decoded = 0, decode_errors = 0, absent = 0, errors = 0,
                  cancelled = 0, queued_decoded_bytes = 0;
  };
  Stats stats() const;
  TileCache& cache();

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
  explicit TileClient(std::unique_ptr<Impl> impl);
};

}  // namespace vts::client
