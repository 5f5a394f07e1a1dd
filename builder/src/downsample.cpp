#include "vts/builder/downsample.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

namespace vts {
inline namespace builder {

const char* downsample_filter_name(DownsampleFilter f) {
  switch (f) {
    case DownsampleFilter::box:
      return "box";
    case DownsampleFilter::lanczos3:
      return "lanczos3";
  }
  return "unknown";
}

std::optional<DownsampleFilter> parse_downsample_filter(std::string_view name) {
  if (name == "box") return DownsampleFilter::box;
  if (name == "lanczos3") return DownsampleFilter::lanczos3;
  return std::nullopt;
}

std::string downsample_method(DownsampleFilter f) {
  return std::string(downsample_filter_name(f)) + "-linear";
}

void downsample_row_rgba8(const std::uint8_t* a, const std::uint8_t* b, std::uint64_t in_width,
                          std::uint8_t* out, std::uint64_t out_width) {
  const Srgb8Tables& t = srgb8_tables();
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
      out[4 * i + c] = t.encode(sum * 0.25f);
    }
    const unsigned alpha = unsigned{p00[3]} + p01[3] + p10[3] + p11[3];
    out[4 * i + 3] = static_cast<std::uint8_t>((alpha + 2) / 4);
  }
}

namespace {

// One linear RGBA texel, premultiplied colour; GCC/Clang vector extension (one SSE register).
typedef float V4 __attribute__((vector_size(16)));

double sinc(double x) {
  if (x == 0) return 1;
  const double px = std::numbers::pi * x;
  return std::sin(px) / px;
}

struct LanczosWeights {
  std::array<float, kLanczosHalfTaps> w{};
  LanczosWeights() {
    std::array<double, kLanczosHalfTaps> d{};
    double sum = 0;
    for (int k = 0; k < kLanczosHalfTaps; ++k) {
      const double x = (k + 0.5) / 2;  // coarse texels
      d[k] = sinc(x) * sinc(x / 3);
      sum += 2 * d[k];
    }
    for (int k = 0; k < kLanczosHalfTaps; ++k) w[k] = static_cast<float>(d[k] / sum);
  }
};

const LanczosWeights& lanczos_weights() {
  static const LanczosWeights w;
  return w;
}

constexpr int kTaps = 2 * kLanczosHalfTaps;
// Left padding of the decoded row: fine texel 2i - 5 for i = 0.
constexpr std::uint64_t kPadLeft = kLanczosHalfTaps - 1;

}  // namespace

double lanczos3_weight(int k) {
  return lanczos_weights().w[static_cast<std::size_t>(k)];
}

struct LanczosReducer::Impl {
  std::uint64_t in_w = 0, in_h = 0, out_w = 0, out_h = 0;
  std::uint64_t end_row = 0;   // fine rows pushed
  std::uint64_t next_out = 0;  // next coarse row to make
  std::vector<V4> decoded;     // one fine row, linear premultiplied, clamp-padded both sides
  std::vector<V4> ring;        // kTaps horizontally filtered rows of out_w; fine row y in y % kTaps

  V4* ring_row(std::uint64_t y) { return ring.data() + (y % kTaps) * out_w; }
};

LanczosReducer::LanczosReducer(std::uint64_t in_width, std::uint64_t in_height)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.in_w = in_width;
  m.in_h = in_height;
  m.out_w = (in_width + 1) / 2;
  m.out_h = (in_height + 1) / 2;
  // Coarse texel i reads fine texels 2i - 5 ... 2i + 6; the last one (i = out_w - 1) reaches
  // 2 * out_w + 4 <= in_w + 5.
  m.decoded.resize(kPadLeft + in_width + kLanczosHalfTaps);
  m.ring.resize(kTaps * m.out_w);
}

LanczosReducer::~LanczosReducer() = default;

std::uint64_t LanczosReducer::out_width() const {
  return impl_->out_w;
}
std::uint64_t LanczosReducer::out_height() const {
  return impl_->out_h;
}
std::uint64_t LanczosReducer::end_rows() const {
  return impl_->end_row;
}
std::uint64_t LanczosReducer::next_out_row() const {
  return impl_->next_out;
}

bool LanczosReducer::ready() const {
  const Impl& m = *impl_;
  if (m.next_out >= m.out_h) return false;
  const std::uint64_t last_needed = std::min(2 * m.next_out + kLanczosHalfTaps, m.in_h - 1);
  return last_needed < m.end_row;
}

void LanczosReducer::push_row(const std::uint8_t* row) {
  Impl& m = *impl_;
  const Srgb8Tables& t = srgb8_tables();
  const auto& w = lanczos_weights().w;
  V4* d = m.decoded.data() + kPadLeft;
  constexpr float kInv255 = 1.0f / 255.0f;
  for (std::uint64_t x = 0; x < m.in_w; ++x) {
    const std::uint8_t* p = row + 4 * x;
    const float a = p[3] * kInv255;
    d[x] = V4{t.to_linear[p[0]] * a, t.to_linear[p[1]] * a, t.to_linear[p[2]] * a, a};
  }
  for (std::uint64_t x = 0; x < kPadLeft; ++x) m.decoded[x] = d[0];
  for (std::uint64_t x = m.in_w; x < m.in_w + kLanczosHalfTaps; ++x) d[x] = d[m.in_w - 1];
  V4* out = m.ring_row(m.end_row);
  for (std::uint64_t i = 0; i < m.out_w; ++i) {
    // Fine texels 2i - k and 2i + 1 + k share weight w[k].
    const V4* c = d + 2 * i;
    V4 acc = w[0] * (c[0] + c[1]);
    for (int k = 1; k < kLanczosHalfTaps; ++k) acc += w[k] * (c[-k] + c[1 + k]);
    out[i] = acc;
  }
  ++m.end_row;
}

void LanczosReducer::pop_row(std::uint8_t* out) {
  Impl& m = *impl_;
  const auto& w = lanczos_weights().w;
  const std::int64_t r2 = static_cast<std::int64_t>(2 * m.next_out);
  const std::int64_t last = static_cast<std::int64_t>(m.in_h - 1);
  const V4* above[kLanczosHalfTaps];  // fine rows 2r - k
  const V4* below[kLanczosHalfTaps];  // fine rows 2r + 1 + k
  for (int k = 0; k < kLanczosHalfTaps; ++k) {
    above[k] = m.ring_row(static_cast<std::uint64_t>(std::clamp<std::int64_t>(r2 - k, 0, last)));
    below[k] = m.ring_row(static_cast<std::uint64_t>(std::min<std::int64_t>(r2 + 1 + k, last)));
  }
  for (std::uint64_t i = 0; i < m.out_w; ++i) {
    V4 acc = w[0] * (above[0][i] + below[0][i]);
    for (int k = 1; k < kLanczosHalfTaps; ++k) acc += w[k] * (above[k][i] + below[k][i]);
    const float a = acc[3];
    std::uint8_t* o = out + 4 * i;
    if (a > 1e-6f) {
      const float inv = 1.0f / a;
      o[0] = encode_srgb8(acc[0] * inv);
      o[1] = encode_srgb8(acc[1] * inv);
      o[2] = encode_srgb8(acc[2] * inv);
      o[3] = a >= 1.0f ? 255 : static_cast<std::uint8_t>(a * 255.0f + 0.5f);
    } else {
      o[0] = o[1] = o[2] = o[3] = 0;  // nothing visible under the kernel
    }
  }
  ++m.next_out;
}

std::vector<std::uint8_t> downsample_image_rgba8(const std::uint8_t* pixels, std::uint64_t width,
                                                 std::uint64_t height, DownsampleFilter filter) {
  const std::uint64_t ow = (width + 1) / 2, oh = (height + 1) / 2;
  std::vector<std::uint8_t> out(ow * oh * 4);
  if (width == 0 || height == 0) return out;
  if (filter == DownsampleFilter::box) {
    for (std::uint64_t r = 0; r < oh; ++r) {
      const std::uint64_t r1 = std::min(2 * r + 1, height - 1);
      downsample_row_rgba8(pixels + 2 * r * width * 4, pixels + r1 * width * 4, width,
                           out.data() + r * ow * 4, ow);
    }
    return out;
  }
  LanczosReducer reducer(width, height);
  for (std::uint64_t y = 0; y < height; ++y) {
    reducer.push_row(pixels + y * width * 4);
    while (reducer.ready()) {
      const std::uint64_t r = reducer.next_out_row();
      reducer.pop_row(out.data() + r * ow * 4);
    }
  }
  return out;
}

}  // namespace builder
}  // namespace vts
