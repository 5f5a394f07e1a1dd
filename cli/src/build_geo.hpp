// vts build's georeference options (--tiling, --bbox, --resampling, --max-level, --range), kept
// apart from cmd_build.cpp. Built only with the builder.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "vts/builder/builder.hpp"
#include "vts/protocol/result.hpp"

namespace vts::cli {

struct GeoArgs {
  std::string tiling, bbox, range;
  std::string resampling = resampling_name(BuildOptions{}.resampling);
  int max_level = -1;  // -1: from the inputs' resolution
};

void add_geo_options(CLI::App* c, GeoArgs& a);
// Fills BuildOptions::tiling, bounds, resampling, max_level, value_range; errors name the option.
Status apply_geo_options(const GeoArgs& a, BuildOptions& o);

}  // namespace vts::cli
