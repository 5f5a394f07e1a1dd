// The pieces of the resampling table (accuracy_resampling.cpp), exposed for its tests: an
// analytic pattern on a projected grid written as a GeoTIFF, and the score of a georeferenced
// build of it against the pattern itself.
#pragma once

#include <cstdint>
#include <filesystem>

#include "vts/base/result.hpp"
#include "vts/protocol/tiling.hpp"

namespace vts::accuracy::detail {

// smooth: two plane waves of 20 and 13 source pixels (well below the source's Nyquist frequency);
// fine: two plane waves of 3.2 and 2.6 source pixels (near Nyquist, 2 pixels), where near aliases
// and short kernels blur. Both are band-limited: their samples determine them exactly.
enum class WarpPattern { smooth, fine };
const char* warp_pattern_name(WarpPattern p) noexcept;

// A north-up raster in a projected CRS (EPSG code `epsg`, metres): pixel (i, j) covers
// [x0 + i p, x0 + (i + 1) p] x [y0 - (j + 1) p, y0 - j p] and holds value() at its centre.
struct PatternRaster {
  int epsg = 32632;  // WGS 84 / UTM zone 32N
  double x0 = 0, y0 = 0, pixel = 1;
  int width = 0, height = 0;
  WarpPattern pattern = WarpPattern::smooth;
  // The pattern at projected (x, y), on the 0..255 scale (it stays within 37.5 .. 217.5).
  double value(double x, double y) const noexcept;
};

// Writes the raster as a one-band Float32 GeoTIFF (values exact to float, no 8-bit rounding) with
// its CRS and geotransform. Errors: io (GDAL cannot create or write it, with GDAL's message).
Status write_pattern_geotiff(const PatternRaster& r, const std::filesystem::path& path);

struct WarpError {
  double sum_sq = 0, max_abs = 0, sum = 0;  // of (texel code - pattern value)
  std::uint64_t texels = 0;
  double rms() const noexcept;
  double bias() const noexcept;
  double psnr() const noexcept;  // 20 log10(255 / rms)
};

// Reads the finest level of `archive` (a georeferenced build of `r`) and compares the grey code of
// every opaque texel whose centre lies at least `margin` source pixels inside `r` with r.value()
// at that centre: the texel centre's longitude and latitude from the tiling scheme, transformed to
// r's CRS by PROJ (OGRCoordinateTransformation, double precision). `offset` (in texels) moves the
// point where the pattern is evaluated: 0 for the true reference; tests give a wrong one to show
// the score catches it. Errors: the archive's (not found, corrupt), invalid_argument (not
// georeferenced, no texel to compare), internal (PROJ fails).
Result<WarpError> score_warp(const std::filesystem::path& archive, const PatternRaster& r,
                             double margin, TexelPoint offset = {});

}  // namespace vts::accuracy::detail
