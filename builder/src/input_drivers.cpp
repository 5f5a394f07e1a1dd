// The table of input_drivers.hpp. It names no driver: image_inputs.cpp fills it in, and that file
// is what links OpenImageIO and GDAL into a program.
#include "input_drivers.hpp"

#include <atomic>

namespace vts {
inline namespace builder {
namespace detail {
namespace {

std::atomic<const InputDrivers*> g_drivers{nullptr};

}  // namespace

void set_input_drivers(const InputDrivers* drivers) {
  g_drivers.store(drivers, std::memory_order_release);
}

Result<const InputDrivers*> input_drivers() {
  if (const InputDrivers* d = g_drivers.load(std::memory_order_acquire)) return d;
  return make_error(ErrorCode::unsupported,
                    "this program builds synthetic pyramids only: it reads no image files "
                    "(vts-build does)");
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
