#include "native_tile_cache.hpp"

#include <algorithm>

namespace vts {
inline namespace server {
namespace http_detail {

NativeTileCache::NativeTileCache(std::size_t capacity_bytes, std::size_t shards)
    : capacity_(capacity_bytes),
      shard_capacity_(capacity_bytes / std::max<std::size_t>(shards, 1)),
      shards_(std::max<std::size_t>(shards, 1)) {}

CachedTilePtr NativeTileCache::find(std::uint64_t generation, std::uint64_t tile_id) {
  const Key key{generation, tile_id};
  Shard& s = shard(key);
  {
    std::lock_guard lock(s.mutex);
    auto it = s.index.find(key);
    if (it != s.index.end()) {
      s.lru.splice(s.lru.begin(), s.lru, it->second);
      hits.fetch_add(1, std::memory_order_relaxed);
      return it->second->tile;
    }
  }
  misses.fetch_add(1, std::memory_order_relaxed);
  return nullptr;
}

void NativeTileCache::insert(std::uint64_t generation, std::uint64_t tile_id, CachedTilePtr tile) {
  if (tile == nullptr) return;
  const std::size_t c = cost(*tile);
  if (c > shard_capacity_) return;
  const Key key{generation, tile_id};
  Shard& s = shard(key);
  CachedTilePtr dropped;  // released after the lock
  std::vector<CachedTilePtr> evicted;
  std::lock_guard lock(s.mutex);
  if (auto it = s.index.find(key); it != s.index.end()) {
    s.bytes -= it->second->cost;
    dropped = std::move(it->second->tile);
    s.lru.erase(it->second);
    s.index.erase(it);
  }
  while (!s.lru.empty() && s.bytes + c > shard_capacity_) {
    s.bytes -= s.lru.back().cost;
    s.index.erase(s.lru.back().key);
    evicted.push_back(std::move(s.lru.back().tile));
    s.lru.pop_back();
    evictions.fetch_add(1, std::memory_order_relaxed);
  }
  s.lru.push_front(Held{key, std::move(tile), c});
  s.index.emplace(key, s.lru.begin());
  s.bytes += c;
}

template <class Pred>
std::size_t NativeTileCache::erase_if(Shard& s, Pred drop) {
  std::size_t n = 0;
  for (auto it = s.lru.begin(); it != s.lru.end();) {
    if (!drop(it->key.generation)) {
      ++it;
      continue;
    }
    s.bytes -= it->cost;
    s.index.erase(it->key);
    it = s.lru.erase(it);
    ++n;
  }
  return n;
}

std::size_t NativeTileCache::erase_generation(std::uint64_t generation) {
  std::size_t n = 0;
  for (Shard& s : shards_) {
    std::lock_guard lock(s.mutex);
    n += erase_if(s, [generation](std::uint64_t g) { return g == generation; });
  }
  invalidations.fetch_add(n, std::memory_order_relaxed);
  return n;
}

std::size_t NativeTileCache::retain(std::span<const std::uint64_t> live) {
  std::vector<std::uint64_t> keep(live.begin(), live.end());
  std::sort(keep.begin(), keep.end());
  std::size_t n = 0;
  for (Shard& s : shards_) {
    std::lock_guard lock(s.mutex);
    n += erase_if(
        s, [&keep](std::uint64_t g) { return !std::binary_search(keep.begin(), keep.end(), g); });
  }
  invalidations.fetch_add(n, std::memory_order_relaxed);
  return n;
}

std::size_t NativeTileCache::bytes() const {
  std::size_t n = 0;
  for (const Shard& s : shards_) {
    std::lock_guard lock(s.mutex);
    n += s.bytes;
  }
  return n;
}

std::size_t NativeTileCache::size() const {
  std::size_t n = 0;
  for (const Shard& s : shards_) {
    std::lock_guard lock(s.mutex);
    n += s.lru.size();
  }
  return n;
}

std::string tile_cache_metrics_text(const NativeTileCache& c) {
  std::string s;
  auto line = [&s](const char* name, const char* type, const char* help, std::uint64_t v) {
    s += std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " " + type + "\n" +
         name + " " + std::to_string(v) + "\n";
  };
  auto count = [](const std::atomic<std::uint64_t>& a) {
    return a.load(std::memory_order_relaxed);
  };
  line("vts_tile_cache_hits_total", "counter", "Native tiles answered from the RAM cache.",
       count(c.hits));
  line("vts_tile_cache_misses_total", "counter",
       "Native tile lookups the RAM cache could not answer (read from the archive).",
       count(c.misses));
  line("vts_tile_cache_evictions_total", "counter",
       "Native tiles evicted from the RAM cache to make room.", count(c.evictions));
  line("vts_tile_cache_invalidations_total", "counter",
       "Native tiles dropped from the RAM cache because their archive changed or was replaced.",
       count(c.invalidations));
  line("vts_tile_cache_bytes", "gauge", "Bytes the RAM cache of native tiles holds.", c.bytes());
  line("vts_tile_cache_entries", "gauge", "Native tiles the RAM cache holds.", c.size());
  line("vts_tile_cache_capacity_bytes", "gauge", "The RAM cache's byte cap (tile_cache_mib).",
       c.capacity());
  return s;
}

}  // namespace http_detail
}  // namespace server
}  // namespace vts
