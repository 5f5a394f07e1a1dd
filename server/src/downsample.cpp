#include "vts/server/downsample.hpp"

#include <array>
#include <cmath>

namespace vts {

double srgb_to_linear(double v) {
  return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

double linear_to_srgb(double v) {
  return v <= 0.0031308 ? v * 12.92 : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
}

namespace {

struct Tables {
  std::array<float, 256> to_linear{};
  // thresholds[k] = linear value halfway (in sRGB space) between codes k and k+1.
  std::array<float, 256> thresholds{};
  // coarse[i] = code for linear i / kCoarse; corrected by at most one threshold step.
  static constexpr int kCoarse = 1 << 16;
  std::array<std::uint8_t, kCoarse + 1> coarse{};

  Tables() {
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
};

const Tables& tables() {
  static const Tables t;
  return t;
}

}  // namespace

float decode_srgb8(std::uint8_t code) {
  return tables().to_linear[code];
}

std::uint8_t encode_srgb8(float linear) {
  const Tables& t = tables();
  if (!(linear > 0.0f)) return 0;  // also NaN
  if (linear >= 1.0f) return 255;
  // The bucket's lower end maps to coarse[i]; sRGB code widths in linear space are all wider than
  // a bucket (the narrowest, near 0, is 1/(255*12.92) > 1/65536), so one step up suffices.
  const int i = static_cast<int>(linear * Tables::kCoarse);
  int code = t.coarse[i];
  if (linear >= t.thresholds[code]) ++code;
  return static_cast<std::uint8_t>(code);
}

void downsample_row_rgba8(const std::uint8_t* a, const std::uint8_t* b, std::uint64_t in_width,
                          std::uint8_t* out, std::uint64_t out_width) {
  const Tables& t = tables();
  const std::uint64_t last = in_width - 1;
  for (std::uint64_t i = 0; i < out_width; ++i) {
    const std::uint64_t x0 = 2 * i;
    const std::uint64_t x1 = x0 + 1 <= last ? x0 + 1 : last;
    const std::uint8_t* p00 = a + 4 * x0;
    const std::uint8_t* p01 = a + 4 * x1;
    const std::uint8_t* p10 = b + 4 * x0;
    const std::uint8_t* p11 = b + 4 * x1;
    for (int c = 0; c < 3; ++c) {
      const float sum =
          t.to_linear[p00[c]] + t.to_linear[p01[c]] + t.to_linear[p10[c]] + t.to_linear[p11[c]];
      out[4 * i + c] = encode_srgb8(sum * 0.25f);
    }
    const unsigned alpha = unsigned{p00[3]} + p01[3] + p10[3] + p11[3];
    out[4 * i + 3] = static_cast<std::uint8_t>((alpha + 2) / 4);
  }
}

}  // namespace vts
