// How a build covers its grid in passes of bounded width (cascade.hpp): a window no wider than the
// limit is one pass from the finest level to level 0. A wider one is cut into column stripes of
// 2^s tiles (plus a halo on each side, stripe_halo()) that each build levels finest .. finest - s
// and leave their level finest - s columns in a scratch raster (a temporary file); that raster,
// 2^s times narrower, is then built the same way, down to level 0. Every pass keeps rings of its
// own width only, so memory is bounded by the limit whatever the grid's size, and the tiles are
// the bytes a single pass over the whole grid would make.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/builder/downsample.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts {
inline namespace builder {
namespace detail {

struct Pass {
  int finest = 0, coarsest = 0;
  TexelRect window;                        // at `finest`
  int source = -1;                         // what it reads: -1 the input, else that scratch raster
  int scratch = -1;                        // a stripe: the scratch raster its coarsest rows go to
  std::uint64_t core_x0 = 0, core_x1 = 0;  // a stripe: its columns of that raster (coarsest)
  std::vector<TileRect> emit;              // tiles to write per level (index z; finest + 1 entries)
};

struct ScratchPlan {
  int level = 0;
  TexelRect window;  // at `level`
};

struct BuildPlan {
  std::vector<Pass> passes;  // in order: a scratch raster is complete before a pass reads it
  std::vector<ScratchPlan> scratch;
  std::uint64_t rows = 0;    // rows all passes read, for progress
  std::uint64_t tiles = 0;   // tiles all passes write
  std::uint64_t widest = 0;  // the widest pass window, in texels
};

// `window`: the finest level's texels that may be non-transparent (all of the image, or a
// footprint); `emit[z]`: the tiles of level z to write. `max_width`: the widest pass allowed.
// `coarsest`: the last level the passes make (0 for a whole build; a shard of a sharded build
// stops at its split level, whose rows the apex's build reads instead).
Result<BuildPlan> make_build_plan(const Geometry& g, DownsampleFilter filter,
                                  const TexelRect& window, const std::vector<TileRect>& emit,
                                  std::uint64_t max_width, int coarsest = 0);

// The windows of levels pass.finest down to pass.coarsest (index z).
std::vector<TexelRect> pass_windows(const Geometry& g, DownsampleFilter filter, const Pass& pass);

// A raster of RGBA8 texels over `window` in an unnamed temporary file in `dir` (gone when closed
// or when the process dies), transparent until written.
class ScratchRaster {
 public:
  static Result<ScratchRaster> create(const std::filesystem::path& dir, const TexelRect& window);
  ScratchRaster(ScratchRaster&& other) noexcept;
  ScratchRaster& operator=(ScratchRaster&&) = delete;
  ~ScratchRaster();

  // Texels [x0, x1) of row y (level coordinates, inside the window).
  Status write(std::uint64_t y, std::uint64_t x0, std::uint64_t x1, const std::uint8_t* texels);
  // Columns [x0, x1) of rows [y, y + count); texels outside the window are transparent.
  Status read(std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint32_t count,
              std::uint8_t* out) const;

 private:
  ScratchRaster(int fd, const TexelRect& window) : fd_(fd), window_(window) {}
  int fd_ = -1;
  TexelRect window_;
};

}  // namespace detail
}  // namespace builder
}  // namespace vts
