// The client's in-memory tile cache: the first level in front of the disk cache and the network.
//
// RamCache holds compressed tiles (payloads exactly as the server sent them) under a budget in
// bytes, split into shards by TileKeyHash so that threads looking up different tiles rarely meet
// on the same lock. Each shard has its own mutex, an unordered_map from key to entry and an
// intrusive doubly linked LRU list through the entries; a hit is one hash, one map lookup, a
// splice to the front of the list and a shared_ptr copy, all under the shard's mutex.
//
// Thread safety: every member function may be called from any thread at the same time.
// Tiles are handed out as shared_ptr<const CachedTile>: an evicted or replaced tile stays alive
// (and unchanged) for as long as a caller holds it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "vts/client/tile_key.hpp"

namespace vts::client {

// A tile as the caches hold it: the stored payload bytes exactly as the archive/server sent them
// (see protocol/codec.hpp: a zstd skippable header frame with an XXH3-64 checksum of the body, then
// the body), the server's ETag, and when it was last fetched or revalidated.
struct CachedTile {
  std::vector<std::uint8_t> payload;
  std::string etag;
  std::int64_t validated_unix = 0;  // seconds since the epoch
  // How long after validated_unix the tile stays fresh, as the server's Cache-Control said
  // (cache_control_lifetime()); -1 when it said nothing (TileCacheOptions::revalidate_after
  // applies).
  std::int64_t fresh_for = -1;
  bool pinned = false;  // as read from the disk cache (its row is pinned); not used by RamCache
};

// A snapshot of the cache's counters. The fields are read one by one without a common lock, so
// under concurrent use they may disagree with each other by the operations in flight.
struct RamCacheStats {
  std::uint64_t bytes = 0;         // cost (see RamCache::entry_cost) of everything held
  std::uint64_t entries = 0;       // tiles held
  std::uint64_t pinned_bytes = 0;  // part of `bytes` that is pinned
  std::uint64_t max_bytes = 0;     // the budget given to the constructor
  std::uint64_t hits = 0;          // get() calls that found the tile
  std::uint64_t misses = 0;        // get() calls that did not
  std::uint64_t evictions = 0;     // entries dropped to make room (not erase() or replacement)
};

class RamCache {
 public:
  // Fixed bookkeeping charged per entry on top of its bytes, as laid out by libstdc++ on 64-bit:
  // the map node (next pointer, TileKey, LRU links, tile pointer, cost, pin flag, cached hash:
  // ~130 bytes) and its bucket slot, plus the make_shared block holding the CachedTile (control
  // block and vector/string/int64 members: ~80 bytes), rounded up. It keeps the budget honest
  // for small tiles; allocator headers and the tileset string's heap buffer (when longer than
  // 15 bytes; its size is charged separately) are not in it.
  static constexpr std::size_t kEntryOverhead = 224;

  // max_bytes: budget for the whole cache; each of the `shards` shards (at least 1) gets
  // max_bytes / shards and evicts on its own, so the cache as a whole never exceeds max_bytes
  // except through pinned entries.
  explicit RamCache(std::size_t max_bytes, std::size_t shards = 16);
  ~RamCache();
  RamCache(const RamCache&) = delete;
  RamCache& operator=(const RamCache&) = delete;

  // The cached tile, or nullptr on a miss. A hit makes the entry the most recently used of its
  // shard.
  std::shared_ptr<const CachedTile> get(const TileKey& key);

  // Stores (or replaces) the tile under `key` as the most recently used entry, then evicts the
  // shard's least recently used unpinned entries until the shard is within its budget (which may
  // evict the new entry itself when pinned entries fill the shard).
  // pinned = true pins the entry; pinned = false keeps an existing entry's pin (so that refreshing
  // a pinned tile does not unpin it; use set_pinned(key, false) to unpin).
  // An entry whose cost exceeds a shard's budget (max_bytes / shards) is not stored, and any older
  // entry under the same key is dropped so that get() never returns stale bytes; returns false
  // then. A null `tile` is the same as erase(key).
  bool put(const TileKey& key, std::shared_ptr<const CachedTile> tile, bool pinned = false);

  // Drops the entry if present (pinned or not).
  void erase(const TileKey& key);

  // Pins (never evicted, still counted in bytes) or unpins an entry. Returns false when the key is
  // not cached. Unpinning makes the entry the most recently used.
  bool set_pinned(const TileKey& key, bool pinned);

  RamCacheStats stats() const;

  // What an entry is charged: payload + etag + tileset key bytes + kEntryOverhead.
  static std::size_t entry_cost(const TileKey& key, const CachedTile& tile) noexcept;

 private:
  struct Shard;
  Shard& shard_for(const TileKey& key) const noexcept;

  std::size_t max_bytes_;
  std::size_t shard_count_;
  std::unique_ptr<Shard[]> shards_;
};

}  // namespace vts::client
