// A scanline source over georeferenced rasters, read through GDAL and warped onto a tiling
// scheme's grid (tiling.hpp) at one level, delivered as RGBA8 rows like ImageSource. Not
// thread-safe: one thread at a time uses it (it may be a different one from the opener's).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/builder/builder.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// Whether GDAL opens `path` as a raster with a CRS and a geotransform. False for anything else
// (a plain JPEG, a missing file, anything but a regular file, which is not even opened): those go
// to ImageSource, which reports its own errors.
bool gdal_is_georeferenced(const std::filesystem::path& path);

// The height of the blocks GDAL's warped VRTs compute (and cache) at a time (512 x 128, fixed by
// GDALWarp for VRT output): reads of different threads should not share one, or each computes it.
inline constexpr std::uint32_t kWarpBlockRows = 128;

struct GdalSourceOptions {
  Tiling tiling = Tiling::world_crs84_quad;
  std::uint32_t tile_size = 256, border = 4;
  std::optional<int> max_level;
  Resampling resampling = Resampling::cubic;
  double warp_error = 0.01;  // BuildOptions::warp_error
  // Called after each input is probed by open(): (inputs probed, inputs in all).
  std::function<void(std::size_t, std::size_t)> on_probe;
  // The data bands (1-based) read from every input: 1 (grey) or 3 (RGB); an alpha band (colour
  // interpretation alpha) that is not among them is still used as alpha, and so are nodata values
  // and masks. Empty: by the input's band count (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA).
  std::vector<int> bands;
  // Values mapped linearly to 0..255 (clamped): one MIN,MAX for every data band, or one per data
  // band (3 for RGB). Empty and no auto_range: values are used as they are (0..255), and data
  // beyond 0..255 is refused.
  std::vector<std::pair<double, double>> value_ranges;
  // One range per data band for the whole mosaic, from a sample of each input's values (read at
  // most 1024 x 1024, masked texels left out), each weighted by its pixel count: the
  // kAutoRangeLow..kAutoRangeHigh percentiles of all their values together (value_ranges unused).
  bool auto_range = false;
  // The most inputs kept open at once (each: its file and its warped VRT); at least 1.
  std::size_t max_open = 32;
  // Pinned by a plan (vts/builder/shard.hpp), so that a shard opening only the inputs that meet
  // its window builds the grid the whole build does: `bounds` is what bounds() returns (the union
  // of all the inputs' extents, or --bounds) and `ranges` the value mapping the whole build chose
  // (value_ranges() returns it; nothing is checked against it, chosen or warned about). With
  // max_level set too, any subset of the inputs, none included, gives the same grid.
  std::optional<LonLatBounds> bounds;
  std::optional<std::vector<std::pair<double, double>>> ranges;
};

// The percentiles --range auto clips at (QGIS's default cumulative count cut for imagery).
inline constexpr double kAutoRangeLow = 2, kAutoRangeHigh = 98;

class GdalSource {
 public:
  // Probes every input (each must be georeferenced: its extent, pixel size, bands, type and
  // approximate value range), picks the level, checks that each can be warped onto the grid, and
  // chooses the value mapping. Inputs are closed after probing and opened again when a window
  // needs them, at most options.max_open at once (least recently used closed first), so any
  // number of inputs can be built. Errors: invalid_argument (no georeference, an unsupported band
  // count or a band beyond it, values beyond 0..255 without a range, a bad level, a footprint
  // outside the scheme), too_large (a grid wider than kMaxGeoreferencedWidth), corrupt (GDAL cannot
  // open or warp it).
  // Without a range, an input whose values span under 1/16 of 0..255 gets a warning (warnings()).
  // The level (without options.max_level) follows each input's resolution where it is measured
  // (its middle, or the equator when it spans it; gdal_source.cpp input_pixel_size), and an input
  // crossing the antimeridian (west > east in degrees, longitudes past 180, a 0..360 grid) is
  // placed in two pieces, one each side of it, both warped by GDAL as gdalwarp warps it.
  static Result<std::unique_ptr<GdalSource>> open(const std::vector<std::filesystem::path>& inputs,
                                                  const GdalSourceOptions& options);
  // Virtual, as the members below that the build calls: the build reaches this class through
  // input_drivers.hpp only, so a program that builds only synthetic pyramids links no GDAL.
  virtual ~GdalSource();

  std::uint64_t width() const { return width_; }
  std::uint64_t height() const { return height_; }
  int max_level() const { return max_level_; }
  // The union of the inputs' extents in degrees, clipped to the scheme's extent; west < east
  // always: an input crossing the antimeridian (placed in two pieces) makes it every longitude.
  const LonLatBounds& bounds() const { return bounds_; }
  std::string description() const { return description_; }
  // What the build should tell its user: inputs whose values use under 1/16 of 0..255, each named
  // with its observed range (at most kMaxWarnings, then how many more).
  const std::vector<std::string>& warnings() const { return warnings_; }
  static constexpr std::size_t kMaxWarnings = 10;
  // The value mapping in use, one MIN,MAX per data band (1 or 3), or empty (values as they are).
  const std::vector<std::pair<double, double>>& value_ranges() const { return ranges_; }
  // Each input's extent in degrees, clipped to the scheme's extent (the inputs' order); every
  // longitude, its latitudes, for one crossing the antimeridian (what a plan records of it).
  virtual std::vector<LonLatBounds> input_bounds() const;
  // The most inputs that were open at once so far.
  std::size_t peak_open() const { return peak_open_; }
  // `n` readers of the same grid for n threads (GDAL datasets are not shared between threads):
  // this one and n - 1 copies of what probing found, each opening its own datasets; max_open is
  // divided between them, so the process still holds at most max_open inputs open.
  virtual std::vector<GdalSource*> split(unsigned n);

  // Grid columns [x0, x1) of rows [y, y + count) as RGBA8 ((x1 - x0) * 4 bytes per row). Texels no
  // input covers (or covers with nodata, a mask or alpha 0) are transparent black; later inputs
  // are composited over earlier ones. A GDAL read error is corrupt, naming the file.
  virtual Status read_window(std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                             std::uint32_t count, std::uint8_t* out);

  struct Input;  // one input: what probing found, and its datasets while open (gdal_source.cpp)

 private:
  GdalSource() = default;
  // Opens `in` (its file and its warped VRT) unless it is open, closing the least recently used
  // input first when max_open are open.
  Status acquire(Input& in);
  Status choose_auto_ranges();
  // read_window's part of one piece of an input (its grid texels): composited over `out`.
  Status read_piece(Input& in, std::size_t piece, std::uint64_t x0, std::uint64_t x1,
                    std::uint64_t y, std::uint32_t count, std::uint8_t* out);

  GdalSourceOptions options_;
  std::vector<std::unique_ptr<Input>> inputs_;
  std::uint64_t width_ = 0, height_ = 0;
  int max_level_ = 0;
  LonLatBounds bounds_;
  std::string description_;
  std::vector<std::string> warnings_;
  std::vector<std::pair<double, double>> ranges_;
  std::vector<Input*> open_;  // the inputs open now
  std::size_t peak_open_ = 0;
  std::uint64_t tick_ = 0;
  std::vector<float> scratch_;
  std::vector<std::unique_ptr<GdalSource>> copies_;  // split()'s
};

}  // namespace detail
}  // namespace builder
}  // namespace vts
