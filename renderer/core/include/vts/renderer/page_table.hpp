// The sparse-virtual-texture page table (indirection), CPU side: what the shader reads to find the
// physical slot holding a virtual tile. See docs/RENDERER.md for the scheme and a worked size.
//
// A dense table (one entry per tile of every level) grows with the virtual size: ~46 GB of 4-byte
// entries for a 2^25 x 2^24-texel planet. This one is a clipmap: each of kMaxLevels levels has a
// toroidal window of W x W entries (W a power of two), so its memory is kMaxLevels * W^2 * 4 bytes
// whatever the archive (gpu_bytes()). Level z's window covers the tiles [ox, ox+W) x [oy, oy+W) of
// that level, clipped to the level's existing tiles; tile (x, y) lives in cell (x mod W, y mod W)
// of layer z, so moving a window rewrites only the cells of tiles that entered it. Levels whose
// whole extent fits in W x W are covered entirely and never move.
//
// Invariant (checked by the tests against a brute force): every cell of every window holds the
// nearest *resident* ancestor-or-self of its tile, so the shader needs a single lookup. Keeping it
// is the CPU's job: map/unmap rewrite the affected descendants inside the windows, recenter fills
// the cells of entering tiles. The root must be mapped before any other tile and unmapped last,
// so that once it is resident every cell in every window is valid.
//
// Thread safety: none; one thread (the render thread) owns a table.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/renderer/pyramid.hpp"

namespace vts::renderer {

// One page-table entry, packed into a uint32 (one texel of an R32UI texture array):
//   bit  31     valid: 1 when the entry points at a resident tile
//   bits 26-30  level actually mapped (0..31): the level of the resident ancestor-or-self, from
//               which the shader derives where inside that tile's slot the fragment falls
//   bits  0-25  physical slot index (up to 2^26 slots)
// An all-zero entry is invalid, so a freshly cleared texture is a valid empty table.
struct PageEntry {
  static constexpr std::uint32_t kValidBit = 1u << 31;
  static constexpr int kLevelShift = 26;
  static constexpr std::uint32_t kLevelMask = 0x1fu;
  static constexpr std::uint32_t kMaxSlot = (1u << 26) - 1;

  std::uint32_t slot = 0;
  std::uint8_t level = 0;

  static std::uint32_t pack(std::uint32_t slot, int level) {
    return kValidBit | (std::uint32_t(level) << kLevelShift) | slot;
  }
  // nullopt for an invalid entry.
  static std::optional<PageEntry> unpack(std::uint32_t packed) {
    if (!(packed & kValidBit)) return std::nullopt;
    return PageEntry{packed & kMaxSlot,
                     static_cast<std::uint8_t>((packed >> kLevelShift) & kLevelMask)};
  }
  bool operator==(const PageEntry&) const = default;
};

// A run of changed cells in one row of one layer, in storage (cell) coordinates: cells
// [x0, x1) of row `row` of layer `layer`. Ready for one glTexSubImage3D each (or to be merged).
struct DirtySpan {
  int layer = 0;
  std::uint32_t row = 0;
  std::uint32_t x0 = 0, x1 = 0;
  bool operator==(const DirtySpan&) const = default;
};

class ClipmapPageTable {
 public:
  struct Options {
    std::uint32_t window = 64;  // W: cells per side of each level's window; power of two <= 4096
  };

  // GPU memory of a table with windows of `window` cells: independent of the pyramid.
  static constexpr std::uint64_t gpu_bytes(std::uint32_t window) {
    return std::uint64_t{kMaxLevels} * window * window * sizeof(std::uint32_t);
  }

  // Fails (invalid_argument) when the window is not a power of two in [1, 4096]. All windows start
  // at origin (0, 0); every entry starts invalid.
  static Result<ClipmapPageTable> create(const Pyramid& pyramid, Options options);

  const Pyramid& pyramid() const { return pyramid_; }
  std::uint32_t window() const { return w_; }
  std::uint64_t gpu_bytes() const { return gpu_bytes(w_); }

  // Makes `tile` resident in `slot` (or moves it to `slot` when already mapped) and points every
  // in-window descendant whose nearest resident ancestor was coarser than `tile` at it.
  // Errors (invalid_argument, table unchanged): the tile does not exist in the pyramid, the slot is
  // above PageEntry::kMaxSlot, or the tile is not the root and the root is not mapped.
  Status map(TileId tile, std::uint32_t slot);
  // Makes `tile` non-resident; in-window cells that pointed at it fall back to its nearest
  // resident ancestor. Unmapping a tile that is not mapped is a no-op. Error (invalid_argument,
  // table unchanged): unmapping the root while other tiles are mapped.
  Status unmap(TileId tile);
  bool is_mapped(TileId tile) const;
  std::size_t mapped_count() const { return resident_.size(); }

  // Moves level z's window so that tile (cx, cy) of that level is as close to its centre as the
  // level's extent allows (origin clamped to [0, tiles - W] per axis). Cells of tiles that left
  // the window are rewritten for the tiles that entered it. No-op for invalid levels.
  void recenter(int z, std::uint32_t cx, std::uint32_t cy);
  // Tile coordinates of the top-left of level z's window (0 for levels out of range).
  std::uint32_t origin_x(int z) const { return z >= 0 && z < kMaxLevels ? ox_[z] : 0; }
  std::uint32_t origin_y(int z) const { return z >= 0 && z < kMaxLevels ? oy_[z] : 0; }

  // True when the tile exists and lies inside its level's window (so entry() can answer).
  bool contains(TileId tile) const;
  // The entry the shader would read for the tile: nullopt when outside the window or invalid.
  std::optional<PageEntry> entry(TileId tile) const;
  // The nearest resident ancestor-or-self of any existing tile, from the residency set (not the
  // windows), so it answers outside the windows too; nullopt when none is resident.
  std::optional<PageEntry> resolve(TileId tile) const;

  // Raw cells of layer z (W * W packed entries, row-major, row = y mod W), for uploads. Layers for
  // levels above the pyramid's max level stay all zero.
  std::span<const std::uint32_t> layer(int z) const;

  // The cells whose value differs from what the previous take_dirty() (or the all-zero initial
  // table) reported, as maximal runs per row, ordered by layer, row, x0; then forgets them.
  // A cell changed and changed back in between is not reported.
  std::vector<DirtySpan> take_dirty();

 private:
  ClipmapPageTable(const Pyramid& pyramid, std::uint32_t w);

  std::uint32_t& cell(int z, std::uint32_t x, std::uint32_t y) {
    return cells_[(std::size_t(z) * w_ + (y & mask_)) * w_ + (x & mask_)];
  }
  void write(int z, std::uint32_t x, std::uint32_t y, std::uint32_t value);
  // Packed nearest resident ancestor-or-self of tile, walking the residency set; 0 if none.
  std::uint32_t resolve_packed(TileId tile) const;
  // Calls fn(z, x, y) for every in-window tile at levels >= t.z that descends from t (or is t).
  template <typename Fn>
  void for_each_window_descendant(TileId t, Fn&& fn);

  Pyramid pyramid_;
  std::uint32_t w_ = 0, mask_ = 0;
  std::vector<std::uint32_t> cells_;  // kMaxLevels layers of W x W
  std::vector<std::uint32_t> shown_;  // what the last take_dirty() reported (the GPU's copy)
  std::vector<std::uint8_t> dirty_;   // per cell: written since the last take_dirty()
  std::vector<std::uint8_t> layer_dirty_;
  std::uint32_t ox_[kMaxLevels] = {}, oy_[kMaxLevels] = {};
  std::unordered_map<std::uint64_t, std::uint32_t> resident_;  // tile_key -> slot
};

}  // namespace vts::renderer
