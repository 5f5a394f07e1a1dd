// Tile identity on the client side: which tileset (a stable source key, such as a TileJSON URL or
// an archive path) and which tile. Shared by the caches, the fetcher's merging and the prefetcher.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "vts/protocol/geometry.hpp"

namespace vts::client {

struct TileKey {
  std::string tileset;
  TileId id;

  bool operator==(const TileKey&) const = default;
  std::string to_string() const;  // "tileset/z/x/y"
};

struct TileKeyHash {
  std::size_t operator()(const TileKey& k) const noexcept;
};

}  // namespace vts::client
