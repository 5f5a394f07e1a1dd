// Residency of the physical texture: which tile occupies which of its N fixed slots, and which
// tile to evict when a new one needs a slot (least recently used, with guards).
//
// Rules acquire() follows, in this order:
//   - a tile already resident keeps its slot;
//   - a free slot is used before anything is evicted;
//   - otherwise the least recently used unpinned tile is evicted, but only if it was last used at
//     least max(1, keep_frames) frames ago: a tile used in the current frame is never evicted (the
//     frame being drawn may sample it), and keep_frames > 1 keeps tiles that just left the view
//     for a few frames so that small camera jitter does not thrash the upload queue;
//   - pinned tiles (the root, which every fallback chain ends at) are never evicted;
//   - when nothing may be evicted the request is refused (counted) and the caller retries later.
// The caller unmaps the evicted tile from the page table before mapping the new one.
//
// Frames are caller-supplied, non-decreasing numbers. Every operation is O(1) (a hash map plus an
// intrusive LRU list of the unpinned slots). Thread safety: none; the render thread owns it.
#pragma once

#include <cstdint>
#include <list>
#include <optional>
#include <unordered_map>
#include <vector>

#include "vts/renderer/pyramid.hpp"

namespace vts::renderer {

struct SlotCacheStats {
  std::uint32_t capacity = 0;
  std::uint32_t resident = 0;   // slots holding a tile
  std::uint32_t pinned = 0;     // part of resident that may never be evicted
  std::uint64_t evictions = 0;  // tiles dropped by acquire() to make room
  std::uint64_t refusals = 0;   // acquire() calls that found no slot it was allowed to take
};

class SlotCache {
 public:
  struct Options {
    std::uint32_t capacity = 1024;  // slots in the physical texture (>= 1)
    std::uint32_t keep_frames = 2;  // a tile unseen for fewer frames than this is not evicted
  };

  struct Acquired {
    std::uint32_t slot = 0;
    std::optional<TileId> evicted;  // the tile that held the slot before, to unmap
  };

  explicit SlotCache(Options options);

  // Starts frame `frame` (>= the previous one; an older number is ignored).
  void begin_frame(std::uint64_t frame);
  std::uint64_t frame() const { return frame_; }

  // Marks a resident tile as used in the current frame; returns false if it is not resident.
  bool touch(TileId tile);

  // A slot for `tile`, which counts as used in the current frame (see the rules above), or
  // nullopt when every slot is pinned or too recently used.
  std::optional<Acquired> acquire(TileId tile);

  // Pins / unpins a resident tile; false if it is not resident.
  bool pin(TileId tile);
  bool unpin(TileId tile);
  // Frees the tile's slot (e.g. its upload failed); false if it was not resident.
  bool erase(TileId tile);

  std::optional<std::uint32_t> slot_of(TileId tile) const;
  // The tile in a slot, nullopt if free or out of range.
  std::optional<TileId> tile_in(std::uint32_t slot) const;
  SlotCacheStats stats() const;

 private:
  struct Slot {
    TileId tile;
    std::uint64_t last_used = 0;
    bool used = false;
    bool pinned = false;
    std::list<std::uint32_t>::iterator lru;  // into lru_ when used && !pinned
  };

  Options options_;
  std::uint64_t frame_ = 0;
  std::vector<Slot> slots_;
  std::vector<std::uint32_t> free_;  // stack of free slot indices
  std::list<std::uint32_t> lru_;     // unpinned resident slots, most recent first
  std::unordered_map<std::uint64_t, std::uint32_t> index_;  // tile_key -> slot
  std::uint32_t pinned_ = 0;
  std::uint64_t evictions_ = 0, refusals_ = 0;
};

}  // namespace vts::renderer
