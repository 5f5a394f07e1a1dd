#include "vts/client/tile_key.hpp"

namespace vts::client {

std::string TileKey::to_string() const {
  return tileset + "/" + id.to_string();
}

std::size_t TileKeyHash::operator()(const TileKey& k) const noexcept {
  const std::size_t h = std::hash<std::string>{}(k.tileset);
  return h ^ (std::hash<TileId>{}(k.id) + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2));
}

}  // namespace vts::client
