// The renderer's view of a tile pyramid: how many levels, and how many tiles exist per axis at
// each level. It is the small part of vts::Geometry that the page table, the slot
// cache and the feedback reduction need, in a form that can be built without texel sizes (tests,
// synthetic pyramids) and that enforces the renderer's own level limit, kMaxLevels.
//
// Level z has tiles_x(z) x tiles_y(z) existing tiles, each axis ceil(finest / 2^(max_level - z)),
// so the root level has exactly one tile. Values are immutable and cheap to copy; all functions
// are pure and thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "vts/base/result.hpp"
#include "vts/protocol/geometry.hpp"

namespace vts::renderer {

// Levels the renderer can address: z in [0, kMaxLevels). 2^25-texel-wide textures with 256-texel
// tiles need 18 levels; 24 leaves room for smaller tiles or larger images. The page table keeps
// one layer per possible level, so this also fixes its GPU layer count.
inline constexpr int kMaxLevels = 24;

class Pyramid {
 public:
  // max_level in [0, kMaxLevels); finest_tiles_x/y in [1, 2^max_level].
  static Result<Pyramid> create(int max_level, std::uint32_t finest_tiles_x,
                                std::uint32_t finest_tiles_y);
  // The same pyramid as an archive's geometry; fails when it has more than kMaxLevels levels.
  static Result<Pyramid> from_geometry(const Geometry& geometry);

  int max_level() const { return max_level_; }
  int level_count() const { return max_level_ + 1; }
  // Existing tiles per axis at level z; 0 for levels outside [0, max_level].
  std::uint32_t tiles_x(int z) const { return valid_level(z) ? tiles_x_[z] : 0; }
  std::uint32_t tiles_y(int z) const { return valid_level(z) ? tiles_y_[z] : 0; }

  bool valid_level(int z) const { return z >= 0 && z <= max_level_; }
  bool exists(TileId t) const {
    return valid_level(t.z) && t.x < tiles_x_[t.z] && t.y < tiles_y_[t.z];
  }

 private:
  Pyramid() = default;

  int max_level_ = 0;
  std::array<std::uint32_t, kMaxLevels> tiles_x_{};
  std::array<std::uint32_t, kMaxLevels> tiles_y_{};
};

}  // namespace vts::renderer
