// The checksums (ETags) of tiles already read from one opened archive, so that a conditional
// request for a tile whose tag is known is answered 304 without touching the file: no pread of
// the header frame, no fstat. Bounded: each of the 16 shards holds at most kShardEntries tags
// and is emptied when full (tags are re-learnt from the next reads), about 16 MiB in all.
//
// A memo belongs to one Tileset, i.e. to one opened file: a replaced archive is a new Tileset
// with an empty memo. An archive modified in place keeps confirming the tags it read before
// until the change is noticed (Tileset::modified: a read answered ErrorCode::changed, a reload
// saw the file change) — which is answering 304 for a whole old tile, as a request made a moment
// earlier would have been; from then on the router no longer consults the memo.
//
// Thread-safe: every member may be called from any thread.
#pragma once

#include <array>
#include <cstdint>
#include <mutex>
#include <optional>
#include <unordered_map>

namespace vts {
inline namespace server {
namespace http_detail {

class TileTagMemo {
 public:
  static constexpr std::size_t kShards = 16;
  static constexpr std::size_t kShardEntries = 1u << 16;

  explicit TileTagMemo(std::size_t shard_entries = kShardEntries) : shard_entries_(shard_entries) {}

  std::optional<std::uint64_t> find(std::uint64_t tile_id) const {
    const Shard& s = shard(tile_id);
    std::lock_guard lock(s.mutex);
    auto it = s.tags.find(tile_id);
    if (it == s.tags.end()) return std::nullopt;
    return it->second;
  }

  void remember(std::uint64_t tile_id, std::uint64_t checksum) {
    Shard& s = shard(tile_id);
    std::lock_guard lock(s.mutex);
    if (s.tags.size() >= shard_entries_ && !s.tags.count(tile_id)) s.tags.clear();
    s.tags[tile_id] = checksum;
  }

  std::size_t size() const {
    std::size_t n = 0;
    for (const Shard& s : shards_) {
      std::lock_guard lock(s.mutex);
      n += s.tags.size();
    }
    return n;
  }

 private:
  struct Shard {
    mutable std::mutex mutex;
    std::unordered_map<std::uint64_t, std::uint64_t> tags;
  };
  // Tile ids of neighbouring tiles differ in their low bits: mix before picking a shard.
  const Shard& shard(std::uint64_t id) const { return shards_[(id * 0x9E3779B97F4A7C15ull) >> 60]; }
  Shard& shard(std::uint64_t id) { return shards_[(id * 0x9E3779B97F4A7C15ull) >> 60]; }

  std::size_t shard_entries_;
  std::array<Shard, kShards> shards_;
};

}  // namespace http_detail
}  // namespace server
}  // namespace vts
