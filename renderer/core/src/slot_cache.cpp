#include "vts/renderer/slot_cache.hpp"

#include <algorithm>
#include <cassert>

namespace vts::renderer {

SlotCache::SlotCache(Options options) : options_(options) {
  options_.capacity = std::max<std::uint32_t>(options_.capacity, 1);
  slots_.resize(options_.capacity);
  free_.reserve(options_.capacity);
  // Hand out slot 0 first, so that the first tile mapped (normally the root) is in slot 0.
  for (std::uint32_t i = options_.capacity; i-- > 0;) free_.push_back(i);
}

void SlotCache::begin_frame(std::uint64_t frame) {
  frame_ = std::max(frame_, frame);
}

bool SlotCache::touch(TileId tile) {
  auto it = index_.find(tile_key(tile));
  if (it == index_.end()) return false;
  Slot& s = slots_[it->second];
  s.last_used = frame_;
  if (!s.pinned) lru_.splice(lru_.begin(), lru_, s.lru);
  return true;
}

std::optional<SlotCache::Acquired> SlotCache::acquire(TileId tile) {
  if (auto it = index_.find(tile_key(tile)); it != index_.end()) {
    touch(tile);
    return Acquired{it->second, std::nullopt};
  }
  Acquired out;
  if (!free_.empty()) {
    out.slot = free_.back();
    free_.pop_back();
  } else {
    // The list is ordered by last use, so if its tail may not be evicted nothing may.
    const std::uint64_t min_age = std::max<std::uint32_t>(options_.keep_frames, 1);
    if (lru_.empty() || frame_ - slots_[lru_.back()].last_used < min_age) {
      ++refusals_;
      return std::nullopt;
    }
    out.slot = lru_.back();
    lru_.pop_back();
    out.evicted = slots_[out.slot].tile;
    index_.erase(tile_key(*out.evicted));
    ++evictions_;
  }
  Slot& s = slots_[out.slot];
  s.tile = tile;
  s.last_used = frame_;
  s.used = true;
  s.pinned = false;
  lru_.push_front(out.slot);
  s.lru = lru_.begin();
  index_[tile_key(tile)] = out.slot;
  return out;
}

bool SlotCache::pin(TileId tile) {
  auto it = index_.find(tile_key(tile));
  if (it == index_.end()) return false;
  Slot& s = slots_[it->second];
  if (!s.pinned) {
    lru_.erase(s.lru);
    s.pinned = true;
    ++pinned_;
  }
  return true;
}

bool SlotCache::unpin(TileId tile) {
  auto it = index_.find(tile_key(tile));
  if (it == index_.end()) return false;
  Slot& s = slots_[it->second];
  if (s.pinned) {
    s.pinned = false;
    --pinned_;
    // Unpinning does not make it the least recent: it counts as used now, like a touch.
    s.last_used = frame_;
    lru_.push_front(it->second);
    s.lru = lru_.begin();
  }
  return true;
}

bool SlotCache::erase(TileId tile) {
  auto it = index_.find(tile_key(tile));
  if (it == index_.end()) return false;
  Slot& s = slots_[it->second];
  if (s.pinned)
    --pinned_;
  else
    lru_.erase(s.lru);
  s = Slot{};
  free_.push_back(it->second);
  index_.erase(it);
  return true;
}

std::optional<std::uint32_t> SlotCache::slot_of(TileId tile) const {
  auto it = index_.find(tile_key(tile));
  if (it == index_.end()) return std::nullopt;
  return it->second;
}

std::optional<TileId> SlotCache::tile_in(std::uint32_t slot) const {
  if (slot >= slots_.size() || !slots_[slot].used) return std::nullopt;
  return slots_[slot].tile;
}

SlotCacheStats SlotCache::stats() const {
  SlotCacheStats st;
  st.capacity = options_.capacity;
  st.resident = static_cast<std::uint32_t>(index_.size());
  st.pinned = pinned_;
  st.evictions = evictions_;
  st.refusals = refusals_;
  assert(st.resident + free_.size() == options_.capacity);
  return st;
}

}  // namespace vts::renderer
