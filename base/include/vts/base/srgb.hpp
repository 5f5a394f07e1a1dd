// The sRGB transfer functions (IEC 61966-2-1), the one home of every conversion between 8-bit
// sRGB codes and linear light: the builder's downsampling, the reference renderer, the accuracy
// tables. All functions are pure and thread-safe.
#pragma once

#include <array>
#include <cstdint>

namespace vts {
inline namespace base {

// Exact transfer functions on [0, 1], in double precision (references).
double srgb_to_linear(double encoded);
double linear_to_srgb(double linear);

// The tables behind the fast 8-bit conversions. Hot loops fetch them once (srgb8_tables()) and
// call the inline members; everything else calls encode_srgb8 / decode_srgb8.
struct Srgb8Tables {
  Srgb8Tables();
  std::array<float, 256> to_linear{};  // linear value of each code
  // thresholds[k] = linear value halfway (in sRGB space) between codes k and k+1.
  std::array<float, 256> thresholds{};
  // coarse[i] = code for linear i / kCoarse; corrected by at most one threshold step.
  static constexpr int kCoarse = 1 << 16;
  std::array<std::uint8_t, kCoarse + 1> coarse{};

  float decode(std::uint8_t code) const noexcept { return to_linear[code]; }
  std::uint8_t encode(float linear) const noexcept {
    if (!(linear > 0.0f)) return 0;  // also NaN
    if (linear >= 1.0f) return 255;
    // The bucket's lower end maps to coarse[i]; sRGB code widths in linear space are all wider
    // than a bucket (the narrowest, near 0, is 1/(255*12.92) > 1/65536): one step up suffices.
    const int i = static_cast<int>(linear * kCoarse);
    int code = coarse[i];
    if (linear >= thresholds[code]) ++code;
    return static_cast<std::uint8_t>(code);
  }
};
const Srgb8Tables& srgb8_tables() noexcept;

// Nearest 8-bit sRGB code of a linear value, rounded in sRGB space: 0 for NaN and values <= 0,
// 255 for values >= 1. encode_srgb8 is the fast path (tables, exact for every float);
// encode_srgb8_exact evaluates the formula in double, for references.
inline std::uint8_t encode_srgb8(float linear) {
  return srgb8_tables().encode(linear);
}
std::uint8_t encode_srgb8_exact(double linear);

// Linear value of an 8-bit sRGB code (table lookup).
inline float decode_srgb8(std::uint8_t code) {
  return srgb8_tables().decode(code);
}

}  // namespace base
}  // namespace vts
