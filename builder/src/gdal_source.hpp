// A scanline source over georeferenced rasters, read through GDAL and warped onto a tiling
// scheme's grid (tiling.hpp) at one level, delivered as RGBA8 rows like ImageSource. Not
// thread-safe: one thread at a time uses it (it may be a different one from the opener's).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "vts/builder/builder.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/result.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts::detail {

// Whether GDAL opens `path` as a raster with a CRS and a geotransform. False for anything else
// (a plain JPEG, a missing file, anything but a regular file, which is not even opened): those go
// to ImageSource, which reports its own errors.
bool gdal_is_georeferenced(const std::filesystem::path& path);

struct GdalSourceOptions {
  Tiling tiling = Tiling::world_crs84_quad;
  std::uint32_t tile_size = 256, border = 4;
  std::optional<int> max_level;
  Resampling resampling = Resampling::cubic;
  std::optional<std::pair<double, double>> value_range;
};

class GdalSource {
 public:
  // Opens every input (each must be georeferenced), picks the level, and prepares one warped VRT
  // per input onto the grid. Errors: invalid_argument (no georeference, an unsupported band
  // count, non-8-bit data without a range, a bad level, a footprint outside the scheme),
  // too_large (a grid wider than kMaxGeoreferencedWidth), corrupt (GDAL cannot open or warp it).
  static Result<std::unique_ptr<GdalSource>> open(const std::vector<std::filesystem::path>& inputs,
                                                  const GdalSourceOptions& options);
  ~GdalSource();

  std::uint64_t width() const { return width_; }
  std::uint64_t height() const { return height_; }
  int max_level() const { return max_level_; }
  // The union of the inputs' extents in degrees, clipped to the scheme's extent.
  const LonLatBounds& bounds() const { return bounds_; }
  std::string description() const { return description_; }

  // Grid columns [x0, x1) of rows [y, y + count) as RGBA8 ((x1 - x0) * 4 bytes per row). Texels no
  // input covers (or covers with nodata, a mask or alpha 0) are transparent black; later inputs
  // are composited over earlier ones. A GDAL read error is corrupt, naming the file.
  Status read_window(std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint32_t count,
                     std::uint8_t* out);

  struct Input;  // one opened input and its warped VRT (gdal_source.cpp)

 private:
  GdalSource() = default;

  GdalSourceOptions options_;
  std::vector<std::unique_ptr<Input>> inputs_;
  std::uint64_t width_ = 0, height_ = 0;
  int max_level_ = 0;
  LonLatBounds bounds_;
  std::string description_;
  std::vector<float> scratch_;
};

}  // namespace vts::detail
