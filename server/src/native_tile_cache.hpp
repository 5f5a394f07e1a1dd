// The RAM cache of native tiles `vts serve` has read from its archives (docs/PROTOCOL.md §6,
// "Native tile cache"): a hot tile is answered with no pread(2) and no stat, its bytes sent from
// the shared buffer held here (a gathered write of header + body, as for every body in memory).
//
// Keys: (generation, tile id). A generation names one opening of an archive (Tileset::generation),
// unique in the process and never reused: a tileset re-opened by a reload is a new generation,
// whose tiles are never answered from its predecessor's entries. What may be kept: the whole
// stored payload of a tile as one read returned it, i.e. read completely from the file and
// verified unchanged after the read (archive::Reader: pread, then fstat), with the checksum of its
// header frame (its ETag). When an entry may be answered is the router's business (Tileset's
// `modified` flag and its periodic re-check, router.cpp); here: storage, bounds and eviction.
//
// Bounded in bytes: the entries cost at most capacity() in all (cost(): the payload's buffer plus
// a fixed overhead each), split evenly between `shards` shards, each its own least-recently-used
// list under its own mutex. A tile costing more than one shard's share is never kept. Tiles handed
// out stay valid (shared) after eviction. Capacity 0 keeps nothing.
//
// Thread-safe: every member may be called from any thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

namespace vts {
inline namespace server {
namespace http_detail {

// One stored tile as its archive holds it, and the checksum of its header frame.
struct CachedTile {
  std::vector<std::uint8_t> bytes;
  std::uint64_t checksum = 0;
};
using CachedTilePtr = std::shared_ptr<const CachedTile>;

class NativeTileCache {
 public:
  static constexpr std::size_t kShards = 8;
  // Per entry beyond the payload: the CachedTile and its control block, list node, index slot.
  static constexpr std::size_t kEntryOverhead = 160;

  explicit NativeTileCache(std::size_t capacity_bytes, std::size_t shards = kShards);
  NativeTileCache(const NativeTileCache&) = delete;
  NativeTileCache& operator=(const NativeTileCache&) = delete;

  // The tile kept for (generation, tile_id), now the most recently used of its shard; null when
  // none (counted as a hit or a miss).
  CachedTilePtr find(std::uint64_t generation, std::uint64_t tile_id);
  // Keeps `tile` (replacing what was kept for the key), evicting the least recently used of its
  // shard until it fits; not kept when it alone costs more than a shard's share.
  void insert(std::uint64_t generation, std::uint64_t tile_id, CachedTilePtr tile);
  // Drops every entry of `generation` (its archive changed or was replaced); returns how many.
  std::size_t erase_generation(std::uint64_t generation);
  // Drops every entry whose generation is not in `live` (any order); returns how many.
  std::size_t retain(std::span<const std::uint64_t> live);

  static std::size_t cost(const CachedTile& t) { return t.bytes.capacity() + kEntryOverhead; }
  std::size_t capacity() const noexcept { return capacity_; }
  std::size_t bytes() const;  // <= capacity()
  std::size_t size() const;

  // Counters for /metrics (relaxed).
  std::atomic<std::uint64_t> hits{0}, misses{0}, evictions{0}, invalidations{0};

 private:
  struct Key {
    std::uint64_t generation, tile_id;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const noexcept {
      return std::size_t((k.tile_id ^ (k.generation << 40)) * 0x9E3779B97F4A7C15ull >> 7);
    }
  };
  struct Held {
    Key key;
    CachedTilePtr tile;
    std::size_t cost;
  };
  struct Shard {
    mutable std::mutex mutex;
    std::list<Held> lru;  // most recently used first
    std::unordered_map<Key, std::list<Held>::iterator, KeyHash> index;
    std::size_t bytes = 0;
  };
  Shard& shard(const Key& k) { return shards_[(KeyHash{}(k) >> 3) % shards_.size()]; }
  // Under s.mutex: drops the entries `drop` selects; returns how many.
  template <class Pred>
  std::size_t erase_if(Shard& s, Pred drop);

  const std::size_t capacity_;
  const std::size_t shard_capacity_;
  std::vector<Shard> shards_;
};

// Prometheus lines of the cache's counters and gauges (vts_tile_cache_*).
std::string tile_cache_metrics_text(const NativeTileCache& c);

}  // namespace http_detail
}  // namespace server
}  // namespace vts
