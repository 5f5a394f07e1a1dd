// The entry points that take input files fill the input table in through use_image_inputs():
// referencing the drivers here is what links OpenImageIO (ImageSource) and GDAL (GdalSource) into a
// program (input_drivers.hpp).
#include "build_core.hpp"
#include "input_drivers.hpp"

namespace vts {
inline namespace builder {
namespace detail {
namespace {

const InputDrivers kImageInputs{&gdal_is_georeferenced, &GdalSource::open, &ImageSource::open};

}  // namespace

void use_image_inputs() {
  set_input_drivers(&kImageInputs);
}

}  // namespace detail
}  // namespace builder
}  // namespace vts

namespace vts {
inline namespace builder {

Result<BuildReport> build_pyramid(const BuildOptions& options) {
  detail::use_image_inputs();
  return detail::build(options);
}

}  // namespace builder
}  // namespace vts
