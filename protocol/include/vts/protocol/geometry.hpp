// Pyramid geometry shared by every part of vtstream (docs/ARCHITECTURE.md, docs/FORMAT.md).
//
// The virtual texture is a square power-of-two quadtree: level z (0 = the single root tile) has
// 2^z x 2^z tile slots of T x T content texels. The image occupies the top-left W x H texels of the
// finest level maxz; level z holds the image downsampled by 2^(maxz - z), i.e.
// ceil(W / 2^(maxz-z)) x ceil(H / 2^(maxz-z)) texels. Tiles wholly outside a level's image do not
// exist. A stored tile is (T + 2B)^2 texels: its content plus a border of B texels copied from its
// neighbours, clamped to the level's image edge.
//
// All functions are pure and thread-safe.
#pragma once

#include <compare>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "vts/base/result.hpp"

namespace vts {
inline namespace protocol {

struct TileId {
  std::uint8_t z = 0;
  std::uint32_t x = 0;
  std::uint32_t y = 0;

  auto operator<=>(const TileId&) const = default;
  std::string to_string() const;  // "z/x/y"
};

// A 64-bit key unique per tile (z < 64, x and y < 2^28: every pyramid a Geometry accepts), for
// hash maps and sets; tile_from_key() inverts it.
constexpr std::uint64_t tile_key(TileId t) noexcept {
  return (std::uint64_t{t.z} << 56) | (std::uint64_t{t.x} << 28) | std::uint64_t{t.y};
}
constexpr TileId tile_from_key(std::uint64_t key) noexcept {
  constexpr std::uint64_t kMask = (std::uint64_t{1} << 28) - 1;
  return TileId{static_cast<std::uint8_t>(key >> 56),
                static_cast<std::uint32_t>((key >> 28) & kMask),
                static_cast<std::uint32_t>(key & kMask)};
}

// The ancestor of t at level z (0 <= z <= t.z); t itself when z == t.z.
constexpr TileId ancestor_at(TileId t, int z) noexcept {
  const int d = t.z - z;
  return TileId{static_cast<std::uint8_t>(z), t.x >> d, t.y >> d};
}

// t's ancestors from its parent up to the root (z-1, z-2, ..., 0), nearest first.
std::vector<TileId> ancestors(TileId t);

// Parses "z/x/y" (decimal, no signs, no spaces). Range is not checked against any geometry.
Result<TileId> parse_tile_id(std::string_view text);

// A half-open rectangle of texels [x0, x1) x [y0, y1) at one level.
struct TexelRect {
  std::uint64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  std::uint64_t width() const { return x1 - x0; }
  std::uint64_t height() const { return y1 - y0; }
  bool empty() const { return x1 <= x0 || y1 <= y0; }
  bool operator==(const TexelRect&) const = default;
};

class Geometry {
 public:
  static constexpr std::uint32_t kMinTileSize = 4;
  static constexpr std::uint32_t kMaxTileSize = 4096;
  static constexpr int kMaxZoom = 26;  // 2^26 tiles per side; tile ids stay far inside 64 bits

  // Validates: width, height >= 1; tile_size a power of two in [kMinTileSize, kMaxTileSize];
  // border <= tile_size / 2; the resulting max zoom <= kMaxZoom.
  static Result<Geometry> create(std::uint64_t width, std::uint64_t height,
                                 std::uint32_t tile_size = 256, std::uint32_t border = 4);

  std::uint64_t width() const { return width_; }
  std::uint64_t height() const { return height_; }
  std::uint32_t tile_size() const { return tile_; }
  std::uint32_t border() const { return border_; }
  std::uint32_t stored_size() const { return tile_ + 2 * border_; }  // T + 2B
  // Smallest z with 2^z * T >= max(W, H).
  int max_zoom() const { return max_zoom_; }
  int level_count() const { return max_zoom_ + 1; }

  // Image extent at level z, in texels (>= 1 on each axis). z must be in [0, max_zoom].
  std::uint64_t level_width(int z) const;
  std::uint64_t level_height(int z) const;
  // Number of existing tiles per axis at level z: ceil(level_width / T).
  std::uint32_t tiles_x(int z) const;
  std::uint32_t tiles_y(int z) const;
  std::uint64_t tile_count(int z) const { return std::uint64_t(tiles_x(z)) * tiles_y(z); }
  std::uint64_t total_tile_count() const;

  bool valid_level(int z) const { return z >= 0 && z <= max_zoom_; }
  // True when the tile lies (at least partly) over the image at its level.
  bool exists(TileId t) const;

  // Parent (z-1, x/2, y/2); nullopt for the root.
  std::optional<TileId> parent(TileId t) const;
  // Existing children, in the order (2x,2y), (2x+1,2y), (2x,2y+1), (2x+1,2y+1); empty at max_zoom.
  std::vector<TileId> children(TileId t) const;

  // Texels of the level's image that tile t's content covers (clipped to the image; the part of
  // the T x T content area beyond the image edge is filled by clamping).
  TexelRect content_rect(TileId t) const;
  // The T x T content rectangle, unclipped: [x*T, (x+1)*T) x [y*T, (y+1)*T).
  TexelRect content_slot(TileId t) const;
  // The tile holding level-z texel (px, py); the texel must be inside the level's image.
  TileId tile_of_texel(int z, std::uint64_t px, std::uint64_t py) const;
  // Level-z texel coordinate that stored-tile texel (sx, sy) (0 <= sx, sy < T + 2B) shows, after
  // clamping to the level's image: x*T - B + sx clamped to [0, level_width - 1].
  std::uint64_t stored_to_level_x(TileId t, std::uint32_t sx) const;
  std::uint64_t stored_to_level_y(TileId t, std::uint32_t sy) const;
  // Rectangle at level `to_z` (coarser or finer) covered by rect at level `from_z`, clipped to the
  // image at `to_z`. Coarser levels round outwards.
  TexelRect map_rect(int from_z, const TexelRect& rect, int to_z) const;

 private:
  Geometry(std::uint64_t w, std::uint64_t h, std::uint32_t t, std::uint32_t b, int mz)
      : width_(w), height_(h), tile_(t), border_(b), max_zoom_(mz) {}

  std::uint64_t width_ = 1, height_ = 1;
  std::uint32_t tile_ = 256, border_ = 4;
  int max_zoom_ = 0;
};

}  // namespace protocol
}  // namespace vts

// Tiles as keys of unordered containers.
template <>
struct std::hash<vts::TileId> {
  std::size_t operator()(vts::TileId t) const noexcept {
    return std::hash<std::uint64_t>{}(vts::tile_key(t));
  }
};
