// The pyramid builder behind `vts build`: cuts one image (or a C x R mosaic of images, or
// georeferenced rasters warped by GDAL onto a tiling scheme's grid, or the built-in synthetic
// source) into the tile pyramid of docs/ARCHITECTURE.md and writes a PMTiles archive.
//
// Streaming: the input is read in strips of scanlines by a reader thread; every level keeps only a
// ring of T + 2B + 2 rows of its own width, from which it cuts one row of tiles at a time and makes
// the next coarser level's rows (BuildOptions::downsample: a 2x2 box or a Lanczos-3 filter, in
// linear light; downsample.hpp). Peak memory is therefore about
//     8 * (T + 2B + 2) * W  bytes   (all levels' rings: their widths sum to ~2W)
//   + 224 * W  bytes with lanczos3  (each level's 12 horizontally filtered float rows)
//   + one band of input tiles for a tiled input (tile_height * W * channels)
//   + threads * 4 tiles being encoded + three input strips of <= 4 MiB,
// independent of the image height and of the number of texels; a 100k x 50k RGB tiled BigTIFF at
// T=256 peaked at 436 MiB RSS (bench/memory_bench.sh), ~130 MiB of it code and fixed buffers.
// Georeferenced builds keep rows of their footprint only, W <= max_window_width (column stripes
// through a scratch file beyond it: builder/src/build_plan.hpp), plus GDAL's block cache (64 MiB
// unless GDAL_CACHEMAX is set): bounded whatever the grid's or footprint's size.
// Tile encoding runs on a pool of worker threads.
//
// A build writes the archive under a temporary name and renames it at the end: a failed or
// cancelled build leaves nothing under the output name.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/builder/downsample.hpp"
#include "vts/builder/tile_encoder.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts {
inline namespace builder {

struct SyntheticSpec {
  std::uint64_t width = 0, height = 0;
  // When set, tiles at levels >= region_level exist only where they overlap this rectangle
  // (finest-level texels); coarser levels are complete. Makes planet-sized sparse test archives.
  std::optional<TexelRect> region;
  int region_level = 6;
};

struct BuildProgress {
  std::uint64_t tiles_done = 0;
  std::uint64_t tiles_total = 0;
  std::uint64_t rows_read = 0;  // input scanlines read so far (0 for synthetic)
  std::uint64_t rows_total = 0;
  std::uint64_t bytes_written = 0;  // tile payload bytes so far (before dedup)
  double seconds = 0;
  bool finishing = false;  // every tile is encoded; the archive file is being assembled
  // Georeferenced inputs checked so far, before any tile (extent, bands, values; 10^4 inputs take
  // a while): tiles_total is 0 until they all are.
  std::uint64_t inputs_checked = 0, inputs_total = 0;
};

// How georeferenced inputs are resampled onto the tiling scheme's grid (GDAL's warper).
enum class Resampling { nearest, bilinear, cubic, lanczos };
// "near", "bilinear", "cubic", "lanczos" (gdalwarp's -r spelling) and back; parse_resampling's
// error (invalid_argument) names the known ones.
const char* resampling_name(Resampling r) noexcept;
Result<Resampling> parse_resampling(std::string_view text);

// The widest grid a georeferenced build accepts, in texels: GDAL addresses rasters with int
// (2^30 = level 22 of WorldCRS84Quad at T = 256, 2^22 tiles around the equator, ~3.7 cm).
inline constexpr std::uint64_t kMaxGeoreferencedWidth = std::uint64_t{1} << 30;
// The widest window a georeferenced build's passes keep (BuildOptions::max_window_width's
// default): with T = 256, B = 4 about 8 * 266 * 32768 = 70 MiB of level rings.
inline constexpr std::uint64_t kDefaultWindowWidth = std::uint64_t{1} << 15;

struct BuildOptions {
  std::vector<std::filesystem::path> inputs;  // row-major order for a grid
  std::uint32_t grid_columns = 1, grid_rows = 1;
  std::optional<SyntheticSpec> synthetic;  // instead of inputs
  // A georeferenced tileset on an OGC tile matrix set: the image must be the scheme's grid
  // (check_tiling_geometry), `bounds` is the data's footprint in degrees. The metadata, PMTiles
  // header and TileJSON carry it, the center is default_center(), and only the footprint's tiles
  // are written, at every level (footprint_tiles()).
  // Synthetic builds: bounds default to the scheme's extent. Inputs that GDAL finds georeferenced
  // (a CRS and a geotransform) are read through GDAL and warped onto the scheme's grid
  // (tiling defaults to WorldCRS84Quad); bounds default to the union of their extents in degrees.
  // Inputs without a georeference keep the OpenImageIO path and refuse a tiling.
  Tiling tiling = Tiling::none;
  std::optional<LonLatBounds> bounds;
  // Georeferenced inputs only. max_level: our finest level (default: the first level whose texel
  // is no larger than the finest input's pixel in the scheme's CRS). bands: the data bands
  // (1-based) of every input, 1 (grey) or 3 (RGB), any band count (an alpha band not among them
  // is still alpha); empty: 1 grey, 2 grey + alpha, 3 RGB, 4 RGBA. value_range: maps values of
  // every band linearly to 0..255 (clamped); band_ranges: one such range per data band instead;
  // auto_range: per data band, the 2 %..98 % percentiles of all inputs' values together
  // (a sample of each: approximate), reported in BuildReport::value_ranges. Without a range, values
  // are used as they are, data beyond 0..255 is refused (invalid_argument naming the input and its
  // values), and inputs whose values span under 1/16 of 0..255 get a warning (on_warning,
  // BuildReport::warnings). Inputs are opened a few at a time (at most 32 at once), so any number
  // of them can be built.
  Resampling resampling = Resampling::cubic;
  // The warper's transformer error in source pixels (gdalwarp -et): exact at sample points and
  // linear within this much between them; 0 is exact at every texel (about 3x the warp's CPU on a
  // UTM mosaic). 0.01 stays at the 8-bit floor on docs/ACCURACY.md's table 6, where gdalwarp's
  // default 0.125 more than doubles cubic's error, for a few percent of the time.
  double warp_error = 0.01;
  std::optional<int> max_level;
  std::optional<std::pair<double, double>> value_range;
  // Georeferenced inputs: the widest window of the grid a pass keeps (0: kDefaultWindowWidth).
  // A footprint wider than this is built in column stripes through a scratch file next to the
  // output (builder/src/build_plan.hpp); the tiles are the same bytes whatever the width.
  std::uint64_t max_window_width = 0;
  std::vector<int> bands;
  std::vector<std::pair<double, double>> band_ranges;
  bool auto_range = false;
  // Called with each warning as soon as it is known (before tiles are built); may be empty.
  std::function<void(const std::string&)> on_warning;
  std::filesystem::path output;
  std::uint32_t tile_size = 256;
  std::uint32_t border = 4;
  CodecId codec = CodecId::lossless;
  EncodeOptions encode;
  // How each level is made from the next finer one (downsample.hpp); recorded in the metadata as
  // TilesetInfo::downsample. Not used by synthetic builds, whose levels are generated directly.
  DownsampleFilter downsample = DownsampleFilter::box;
  unsigned threads = 0;  // encoder threads; 0 = one per hardware thread
  std::string name;      // tileset name in the metadata (default: the output file's stem)
  std::string description;
  // Called from the building thread about ten times a second and once at the end.
  std::function<void(const BuildProgress&)> on_progress;
  // Polled; when it becomes true the build stops with ErrorCode::cancelled and leaves no output.
  const std::atomic<bool>* cancel = nullptr;
};

struct LevelReport {
  int z = 0;
  std::uint64_t width = 0, height = 0;
  std::uint64_t tiles = 0;
};

struct BuildReport {
  TilesetInfo info;
  archive::WriterStats stats;
  std::vector<LevelReport> levels;
  double seconds = 0;
  std::string input_description;  // "earth.jpg 2048x1024 3ch uint8" / "synthetic 3000x1700"
  // How the grid was read (build_plan.hpp): passes over it (1 unless the footprint was cut into
  // stripes; 0 for synthetic builds) and the widest window a pass kept, in texels.
  std::uint64_t passes = 0, window_width = 0;
  // Georeferenced inputs: what the user should know (BuildOptions::on_warning), and the value
  // mapping used, one MIN,MAX per data band (empty: values as they are).
  std::vector<std::string> warnings;
  std::vector<std::pair<double, double>> value_ranges;
};

Result<BuildReport> build_pyramid(const BuildOptions& options);

// The same build for synthetic options only (invalid_argument otherwise), in a program that links
// neither OpenImageIO nor GDAL: build_pyramid's image inputs are what links them
// (builder/src/input_drivers.hpp). The tests' archives are built with it.
Result<BuildReport> build_synthetic_pyramid(const BuildOptions& options);

}  // namespace builder
}  // namespace vts
