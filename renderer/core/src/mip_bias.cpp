#include "vts/renderer/mip_bias.hpp"

#include <algorithm>
#include <cmath>

namespace vts::renderer {

double MipBiasController::update(std::uint64_t demanded_tiles) {
  const double cap = options_.capacity;
  const double demand = static_cast<double>(demanded_tiles);
  if (since_raise_ != ~0u) ++since_raise_;
  if (demand > cap * options_.high_watermark) {
    calm_ = 0;
    if (since_raise_ >= std::max<std::uint32_t>(options_.raise_interval, 1)) {
      const double raised = std::min(bias_ + options_.step, options_.max_bias);
      if (raised != bias_) {
        bias_ = raised;
        since_raise_ = 0;
      }
    }
    return bias_;
  }
  const double lower_step = std::min(options_.step, bias_);
  const bool calm = bias_ > 0.0 && demand < cap * options_.low_watermark &&
                    demand * std::pow(options_.growth, lower_step) <= cap * options_.high_watermark;
  if (!calm) {
    calm_ = 0;
    return bias_;
  }
  if (++calm_ >= options_.calm_frames) {
    bias_ = std::max(0.0, bias_ - options_.step);
    calm_ = 0;
  }
  return bias_;
}

}  // namespace vts::renderer
