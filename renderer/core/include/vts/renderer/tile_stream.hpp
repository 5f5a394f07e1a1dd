// The streaming policy of one viewer: which tiles to ask for, which to cancel, which to hold and
// for how long a failed tile waits. The GL viewer (VirtualTexture) and the load tester's simulated
// viewers both run it, so a load test measures the requests the real viewer makes.
//
// In: the wanted list of each frame (FeedbackProcessor's order: every ancestor up to the root
// already added, coarse first), and what became of each request (placed, absent, failed,
// dropped). Out: the requests and cancellations of the frame, and residency (which tile holds
// which slot of the physical texture, by the SlotCache's rules).
//
// Per frame, frame() asks for every wanted tile that is neither resident, nor on its way, nor
// absent, nor backing off, in the wanted list's order; it cancels every tile on its way that the
// new list no longer wants (never the root: every fallback ends at it); then it marks the wanted
// resident tiles used. A tile's life:
//   - place(): its data is here; it takes a slot (evicting the least recently used tile the slot
//     cache allows) or is refused when every slot is too recently used (then it is asked for
//     again at a later frame). The root is pinned once placed.
//   - absent(): the source has no such tile: never asked for again (it counts as resolved).
//   - failed(): asked for again after a back-off: `backoff`, doubling per failure up to
//     `max_backoff` (a viewer does not hammer a failing server every frame).
//   - drop(): the request ended with nothing (the client cancelled it): asked for again when
//     wanted.
// Ancestors are added once, by the wanted list; the stream adds none. The stream also holds the
// mip bias (MipBiasController, over the slots): each new wanted list updates it, and the owner
// reduces the next feedback with bias() (coarser levels when a view wants more than the slots).
//
// Every decision can be traced (TileStreamOptions::trace), in the order it was made.
//
// Thread safety: none; the owner serialises every call (the render thread, or a load-test
// viewer's lock). The clock is the caller's: every call that depends on time takes `now`.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "vts/renderer/feedback.hpp"
#include "vts/renderer/mip_bias.hpp"
#include "vts/renderer/slot_cache.hpp"

namespace vts::renderer {

struct StreamEvent {
  enum class Kind : std::uint8_t { request, cancel, placed, refused, evicted, absent, failed };
  Kind kind = Kind::request;
  TileId tile;
};
const char* stream_event_name(StreamEvent::Kind kind);

struct TileStreamOptions {
  SlotCache::Options slots{.capacity = 256, .keep_frames = 8};
  std::chrono::milliseconds backoff{250};       // after the first failure
  std::chrono::milliseconds max_backoff{8000};  // the doubling stops here
  double max_bias = 4.0;                        // upper bound of the automatic mip bias
  std::function<void(const StreamEvent&)> trace;
};

// What the owner does this frame: ask the tile client for `requests` (in this order) and cancel
// `cancels`.
struct StreamStep {
  std::vector<TileRequest> requests;
  std::vector<TileId> cancels;
};

class TileStream {
 public:
  using Clock = std::chrono::steady_clock;
  enum class State : std::uint8_t { none, pending, resident, absent, backing_off };

  explicit TileStream(TileStreamOptions options = {});

  // Before any view is known: the root, which every fallback ends at.
  StreamStep start();
  // Frame `frame` (non-decreasing) at `now`, with a new wanted list or (nullptr) the last one.
  StreamStep frame(std::uint64_t frame, Clock::time_point now,
                   const std::vector<TileRequest>* wanted);

  // A tile's data is here: the slot it takes (and the tile evicted for it, forgotten here), or
  // nullopt when no slot may be taken this frame or the tile is resident already.
  std::optional<SlotCache::Acquired> place(TileId tile);
  void absent(TileId tile);
  void failed(TileId tile, Clock::time_point now);
  void drop(TileId tile);

  State state(TileId tile) const;
  const std::vector<TileRequest>& wanted() const { return wanted_; }
  std::size_t pending() const { return pending_.size(); }
  // Wanted tiles neither resident nor absent.
  std::uint32_t missing() const;
  const SlotCache& slots() const { return slots_; }
  // The mip bias to reduce the next feedback with, in levels.
  double bias() const { return bias_.bias(); }
  std::uint64_t absent_count() const { return absent_count_; }
  std::uint64_t failure_count() const { return failure_count_; }

 private:
  struct Entry {
    State state = State::none;  // pending, absent or backing_off (residency is the slot cache's)
    int failures = 0;
    Clock::time_point retry_at{};
  };
  void note(StreamEvent::Kind kind, TileId tile) const;

  TileStreamOptions options_;
  SlotCache slots_;
  MipBiasController bias_;
  std::vector<TileRequest> wanted_;
  std::unordered_set<std::uint64_t> wanted_keys_;
  std::unordered_map<std::uint64_t, Entry> entries_;  // tile_key -> what is known of the tile
  // The tiles on its way: a new wanted list looks for cancellations among these only, not among
  // every tile it knows (absent ones are kept forever).
  std::unordered_set<std::uint64_t> pending_;
  std::uint64_t absent_count_ = 0, failure_count_ = 0;
};

}  // namespace vts::renderer
