// The options of a build, shared by `vts build` and `vts plan` (which fixes them in a plan).
// Built only with the builder.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "build_geo.hpp"
#include "vts/base/result.hpp"
#include "vts/builder/builder.hpp"

namespace vts::cli {

struct BuildArgs {
  std::vector<std::string> inputs;
  std::string input_list;
  std::string output;
  std::uint32_t tile = 256, border = 4;
  std::string codec = "lossless";
  int zstd_level = 3;
  std::string filter = "auto";
  std::string bc1_quality = "fast";
  std::string downsample = downsample_filter_name(BuildOptions{}.downsample);
  unsigned threads = 0;
  std::string grid, synthetic, region;
  GeoArgs geo;
  int region_level = 6;
  std::string name;
  bool json = false, quiet = false;
};

// Declares the inputs and every build option but -o, --json and --quiet.
void add_build_options(CLI::App* c, BuildArgs& a);
// The BuildOptions the arguments ask for; errors name the option.
Result<BuildOptions> build_options(const BuildArgs& a);

}  // namespace vts::cli
