// The image inputs a build opens: plain images through OpenImageIO (ImageSource) and georeferenced
// rasters through GDAL (GdalSource). The build reaches them only through this table, which the
// entry points that take input files (build_pyramid, the shard plan and builds) fill in first
// (use_image_inputs(), image_inputs.cpp). A program that builds only synthetic pyramids
// (build_synthetic_pyramid: the tests' archives) therefore links neither library, and with the
// linker's --as-needed does not load their ~260 shared libraries at start.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include "gdal_source.hpp"
#include "image_source.hpp"
#include "vts/base/result.hpp"

namespace vts {
inline namespace builder {
namespace detail {

struct InputDrivers {
  bool (*is_georeferenced)(const std::filesystem::path& path) = nullptr;
  Result<std::unique_ptr<GdalSource>> (*open_georeferenced)(
      const std::vector<std::filesystem::path>& inputs, const GdalSourceOptions& options) = nullptr;
  Result<std::unique_ptr<ImageSource>> (*open_image)(
      const std::vector<std::filesystem::path>& inputs, std::uint32_t columns,
      std::uint32_t rows) = nullptr;
};

// Fills the table in with the image inputs (image_inputs.cpp; idempotent, thread-safe).
void use_image_inputs();
void set_input_drivers(const InputDrivers* drivers);
// The table, or unsupported naming what this program lacks (it was linked for synthetic builds).
Result<const InputDrivers*> input_drivers();

}  // namespace detail
}  // namespace builder
}  // namespace vts
