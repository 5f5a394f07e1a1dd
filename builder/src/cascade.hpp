// The streaming level cascade over a window of the grid: rows of the finest level's window are
// pushed in order; every level keeps a ring of T + 2B + 2 rows of its window's width, cuts its tile
// rows as soon as their last (border) row has arrived, and makes the next coarser level's rows.
//
// Windows. Level z holds only the texels of its window (TexelRect, level coordinates); every texel
// outside the window but inside the level's image reads as transparent black (0, 0, 0, 0), and
// beyond the image's edges the edge texel repeats (Geometry's clamp-to-edge). coarser_window()
// gives the next level's window from a level's: every texel of the coarser level that the filter
// can make non-zero from the window's texels. So when everything outside the finest window really
// is transparent (a sparse footprint), every level comes out exactly as a build of the whole grid
// would make it, at the cost of the footprint's width instead of the grid's. When it is not (a
// column stripe of a wider build), the texels near the window's sides are wrong and the caller
// keeps a halo wide enough that no tile it writes reads them (stripe_halo()).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "vts/builder/downsample.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// The window of level z - 1 that level z's `window` can make non-transparent with `filter`
// (box: the parents of its texels; lanczos3: three more texels on each side), clipped to the image.
TexelRect coarser_window(const Geometry& g, int z, const TexelRect& window,
                         DownsampleFilter filter);

// How many texels of the finest level a column stripe must read beyond its own columns on each
// side so that `levels` coarser levels of it are exact out to B texels around its columns (so its
// tiles, borders included, and its texels at the coarsest level equal a whole-grid build's).
std::uint64_t stripe_halo(const Geometry& g, int levels, DownsampleFilter filter);

class Cascade {
 public:
  using TileSink = std::function<void(TileId, TileImage&&)>;
  // A row `y` (level coordinates) of the coarsest level's window, window-width RGBA8 texels.
  using RowSink = std::function<void(std::uint64_t y, const std::uint8_t* row)>;

  // Levels finest down to coarsest (inclusive). windows[z] is level z's window for z in that range
  // (windows[z - 1] must be coarser_window() of windows[z]); emit[z] the tiles of level z to cut
  // and hand to `tiles` (an empty rect: none). `rows`, if set, receives the coarsest level's rows.
  Cascade(const Geometry& g, int finest, int coarsest, std::vector<TexelRect> windows,
          DownsampleFilter filter, std::vector<TileRect> emit, TileSink tiles, RowSink rows);
  ~Cascade();
  Cascade(const Cascade&) = delete;
  Cascade& operator=(const Cascade&) = delete;

  // Pushes the next row of the finest level's window (its width in RGBA8 texels). After the
  // window's last row every level has made all its rows and cut all its tiles.
  void push_row(const std::uint8_t* row);

 private:
  struct Level;
  void push_row(int z, const std::uint8_t* row);
  void make_parent_rows(int z);
  void emit_tile_rows(int z);
  void cut_tile(int z, std::uint32_t tx, std::uint32_t ty);
  const std::uint8_t* row_at(int z, std::uint64_t y) const;  // nullptr: transparent
  std::uint64_t oldest_needed(int z) const;

  const Geometry& g_;
  int finest_, coarsest_;
  TileSink tiles_;
  RowSink rows_;
  std::vector<std::unique_ptr<Level>> levels_;
};

}  // namespace detail
}  // namespace builder
}  // namespace vts
