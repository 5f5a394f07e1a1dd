#include "vts/client/tile_key.hpp"

namespace vts::client {

std::string TileKey::to_string() const { return tileset + "/" + id.to_string(); }

std::size_t TileKeyHash::operator()(const TileKey& k) const noexcept {
  // Tile coordinates pack into 64 bits (z < 64, x and y < 2^28 for any pyramid we accept).
  const std::uint64_t packed = (std::uint64_t(k.id.z) << 58) ^ (std::uint64_t(k.id.x) << 29) ^
                               std::uint64_t(k.id.y);
  const std::size_t h = std::hash<std::string>{}(k.tileset);
  return h ^ (std::hash<std::uint64_t>{}(packed) + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2));
}

std::vector<TileId> ancestors(TileId id) {
  std::vector<TileId> out;
  out.reserve(id.z);
  while (id.z > 0) {
    id = TileId{std::uint8_t(id.z - 1), id.x / 2, id.y / 2};
    out.push_back(id);
  }
  return out;
}

}  // namespace vts::client
