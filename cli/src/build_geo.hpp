// vts build's georeference options (--tiling, --bbox, --resampling, --max-level, --bands, --range),
// kept apart from cmd_build.cpp. Built only with the builder.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <utility>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/builder/builder.hpp"

namespace vts::cli {

struct GeoArgs {
  std::string tiling, bbox, range, bands;
  std::string resampling = resampling_name(BuildOptions{}.resampling);
  int max_level = -1;  // -1: from the inputs' resolution
  double warp_error = BuildOptions{}.warp_error;
};

void add_geo_options(CLI::App* c, GeoArgs& a);
// Fills BuildOptions::tiling, bounds, resampling, max_level, bands, value_range, band_ranges,
// auto_range; errors name the option.
Status apply_geo_options(const GeoArgs& a, BuildOptions& o);
// The value mapping as a --range argument ("MIN,MAX" or one pair per band), to reuse.
std::string range_argument(const std::vector<std::pair<double, double>>& ranges);

}  // namespace vts::cli
