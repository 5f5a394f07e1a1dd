#include "vts/client/ram_cache.hpp"

#include <algorithm>
#include <atomic>
#include <cassert>
#include <mutex>
#include <unordered_map>
#include <utility>

namespace vts::client {
namespace {

// Links of the intrusive LRU list. Each shard owns a circular list with a sentinel head: head.next
// is the most recently used entry, head.prev the least recently used one.
struct Links {
  Links() = default;
  Links(const Links&) = delete;  // the list points at this very object
  Links& operator=(const Links&) = delete;

  Links* prev = this;
  Links* next = this;

  bool linked() const { return next != this; }
  void unlink() {
    prev->next = next;
    next->prev = prev;
    prev = next = this;
  }
  // Inserts `node` right after this one (at the front when this is the head).
  void push_after(Links* node) {
    node->prev = this;
    node->next = next;
    next->prev = node;
    next = node;
  }
};

struct Entry : Links {
  std::shared_ptr<const CachedTile> tile;
  const TileKey* key = nullptr;  // the map's own copy of the key (stable: node-based map)
  std::size_t cost = 0;
  bool pinned = false;  // pinned entries are kept off the LRU list, so eviction never sees them
};

// Spreads TileKeyHash's bits before picking a shard: its low bits vary mostly with y, so taking
// them as they are would put a whole row of tiles into one shard (murmur3's 64-bit finalizer).
std::size_t mix(std::size_t h) noexcept {
  std::uint64_t k = h;
  k ^= k >> 33;
  k *= 0xff51afd7ed558ccdULL;
  k ^= k >> 33;
  k *= 0xc4ceb9fe1a85ec53ULL;
  k ^= k >> 33;
  return static_cast<std::size_t>(k);
}

}  // namespace

// Cache-line aligned so that shards share no line. What a hit writes (the mutex, the list head,
// the hit counter) comes first, so that it fits one 64-byte line with glibc's 40-byte mutex: when
// threads take turns on a shard, one line moves between cores per hit rather than three.
struct alignas(64) RamCache::Shard {
  std::mutex mutex;
  Links lru;  // guarded by mutex
  std::atomic<std::uint64_t> hits{0};

  std::unordered_map<TileKey, Entry, TileKeyHash> map;  // guarded by mutex
  std::size_t budget = 0;
  // Written under the mutex, read by stats() without it.
  std::atomic<std::uint64_t> bytes{0}, entries{0}, pinned_bytes{0};
  std::atomic<std::uint64_t> misses{0}, evictions{0};

  // Removes an entry's bytes from the counters and drops it. Caller holds the mutex.
  void drop(std::unordered_map<TileKey, Entry, TileKeyHash>::iterator it) {
    Entry& e = it->second;
    if (e.linked()) e.unlink();
    bytes.fetch_sub(e.cost, std::memory_order_relaxed);
    entries.fetch_sub(1, std::memory_order_relaxed);
    if (e.pinned) pinned_bytes.fetch_sub(e.cost, std::memory_order_relaxed);
    map.erase(it);
  }

  // Evicts from the LRU end until within budget or nothing unpinned is left. Caller holds the
  // mutex.
  void evict_to_budget() {
    while (bytes.load(std::memory_order_relaxed) > budget && lru.prev != &lru) {
      auto* victim = static_cast<Entry*>(lru.prev);
      auto it = map.find(*victim->key);
      assert(it != map.end() && &it->second == victim);
      drop(it);
      evictions.fetch_add(1, std::memory_order_relaxed);
    }
  }
};

RamCache::RamCache(std::size_t max_bytes, std::size_t shards)
    : max_bytes_(max_bytes),
      shard_count_(std::max<std::size_t>(shards, 1)),
      shards_(new Shard[shard_count_]) {
  for (std::size_t i = 0; i < shard_count_; ++i) shards_[i].budget = max_bytes_ / shard_count_;
}

RamCache::~RamCache() = default;

std::size_t RamCache::entry_cost(const TileKey& key, const CachedTile& tile) noexcept {
  return tile.payload.size() + tile.etag.size() + key.tileset.size() + kEntryOverhead;
}

RamCache::Shard& RamCache::shard_for(const TileKey& key) const noexcept {
  return shards_[mix(TileKeyHash{}(key)) % shard_count_];
}

std::shared_ptr<const CachedTile> RamCache::get(const TileKey& key) {
  Shard& s = shard_for(key);
  std::unique_lock lock(s.mutex);
  auto it = s.map.find(key);
  if (it == s.map.end()) {
    lock.unlock();
    s.misses.fetch_add(1, std::memory_order_relaxed);
    return nullptr;
  }
  Entry& e = it->second;
  if (!e.pinned && s.lru.next != &e) {
    e.unlink();
    s.lru.push_after(&e);
  }
  std::shared_ptr<const CachedTile> tile = e.tile;
  lock.unlock();
  s.hits.fetch_add(1, std::memory_order_relaxed);
  return tile;
}

bool RamCache::put(const TileKey& key, std::shared_ptr<const CachedTile> tile, bool pinned) {
  if (!tile) {
    erase(key);
    return false;
  }
  const std::size_t cost = entry_cost(key, *tile);
  Shard& s = shard_for(key);
  std::shared_ptr<const CachedTile> old;  // released after the lock, not under it
  std::lock_guard lock(s.mutex);
  auto it = s.map.find(key);
  if (cost > s.budget) {
    if (it != s.map.end()) {
      old = std::move(it->second.tile);
      s.drop(it);
    }
    return false;
  }
  if (it == s.map.end()) {
    it = s.map.try_emplace(key).first;
    it->second.key = &it->first;
    s.entries.fetch_add(1, std::memory_order_relaxed);
  } else {
    Entry& e = it->second;
    s.bytes.fetch_sub(e.cost, std::memory_order_relaxed);
    if (e.pinned) s.pinned_bytes.fetch_sub(e.cost, std::memory_order_relaxed);
    if (e.linked()) e.unlink();
    old = std::move(e.tile);
  }
  Entry& e = it->second;
  e.tile = std::move(tile);
  e.cost = cost;
  e.pinned = e.pinned || pinned;
  s.bytes.fetch_add(cost, std::memory_order_relaxed);
  if (e.pinned) {
    s.pinned_bytes.fetch_add(cost, std::memory_order_relaxed);
  } else {
    s.lru.push_after(&e);
  }
  s.evict_to_budget();
  return s.map.find(key) != s.map.end();
}

void RamCache::erase(const TileKey& key) {
  Shard& s = shard_for(key);
  std::shared_ptr<const CachedTile> old;
  std::lock_guard lock(s.mutex);
  auto it = s.map.find(key);
  if (it == s.map.end()) return;
  old = std::move(it->second.tile);
  s.drop(it);
}

bool RamCache::set_pinned(const TileKey& key, bool pinned) {
  Shard& s = shard_for(key);
  std::lock_guard lock(s.mutex);
  auto it = s.map.find(key);
  if (it == s.map.end()) return false;
  Entry& e = it->second;
  if (e.pinned == pinned) return true;
  e.pinned = pinned;
  if (pinned) {
    e.unlink();
    s.pinned_bytes.fetch_add(e.cost, std::memory_order_relaxed);
  } else {
    s.pinned_bytes.fetch_sub(e.cost, std::memory_order_relaxed);
    s.lru.push_after(&e);
    // Pinned entries may have pushed the shard over budget; now that one is evictable, restore
    // the bound (this may evict the entry itself if it is the only unpinned one).
    s.evict_to_budget();
  }
  return true;
}

RamCacheStats RamCache::stats() const {
  RamCacheStats out;
  out.max_bytes = max_bytes_;
  for (std::size_t i = 0; i < shard_count_; ++i) {
    const Shard& s = shards_[i];
    out.bytes += s.bytes.load(std::memory_order_relaxed);
    out.entries += s.entries.load(std::memory_order_relaxed);
    out.pinned_bytes += s.pinned_bytes.load(std::memory_order_relaxed);
    out.hits += s.hits.load(std::memory_order_relaxed);
    out.misses += s.misses.load(std::memory_order_relaxed);
    out.evictions += s.evictions.load(std::memory_order_relaxed);
  }
  return out;
}

}  // namespace vts::client
