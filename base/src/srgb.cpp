#include "vts/base/srgb.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace vts {
inline namespace base {

double srgb_to_linear(double v) {
  return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

double linear_to_srgb(double v) {
  return v <= 0.0031308 ? v * 12.92 : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
}

Srgb8Tables::Srgb8Tables() {
  for (int k = 0; k < 256; ++k) to_linear[k] = static_cast<float>(srgb_to_linear(k / 255.0));
  for (int k = 0; k < 255; ++k)
    thresholds[k] = static_cast<float>(srgb_to_linear((k + 0.5) / 255.0));
  thresholds[255] = 2.0f;  // never crossed
  int code = 0;
  for (int i = 0; i <= kCoarse; ++i) {
    const float v = static_cast<float>(i) / kCoarse;
    while (code < 255 && v >= thresholds[code]) ++code;
    coarse[i] = static_cast<std::uint8_t>(code);
  }
}

const Srgb8Tables& srgb8_tables() noexcept {
  static const Srgb8Tables t;
  return t;
}

std::uint8_t encode_srgb8_exact(double linear) {
  if (!(linear > 0)) return 0;  // also NaN
  if (linear >= 1) return 255;
  const double e = std::clamp(linear_to_srgb(linear), 0.0, 1.0);
  return static_cast<std::uint8_t>(std::lround(e * 255.0));
}

}  // namespace base
}  // namespace vts
