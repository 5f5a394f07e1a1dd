// The builder's 2x reductions (BuildOptions::downsample, `vts build --downsample`), both computed
// in linear light — sRGB-decoded to linear, filtered, re-encoded to the nearest 8-bit sRGB code —
// and both clamp-to-edge at the image's edges (Geometry's convention: at an odd edge the last
// row/column stands for the missing one):
//   box       each coarser texel is the mean of its (up to) four children, alpha averaged directly
//             (rounded half up). The cheapest filter; it aliases (everything between the coarse
//             Nyquist frequency and the fine one folds back) and blurs a little.
//   lanczos3  separable Lanczos-3 windowed sinc scaled for 2x reduction: 12 taps per axis (six fine
//             texels each side of the coarse texel's centre), weights sinc(d) sinc(d/3) at the
//             coarse-texel distances d = 0.25, 0.75, ... 2.75, normalised to sum 1. It passes
//             detail almost untouched up to the coarse Nyquist frequency and stops what lies above
//             it, so coarse levels are sharper and free of moire. Colour is filtered premultiplied
//             by alpha (so transparent texels lend no colour to their neighbours) and divided by
//             the filtered alpha afterwards; its small negative lobes can ring past [0, 1], so
//             colour and alpha are clamped. A constant image stays exactly constant.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "vts/base/srgb.hpp"

namespace vts {
inline namespace builder {

enum class DownsampleFilter : std::uint8_t { box, lanczos3 };

// "box" / "lanczos3" (the names `vts build --downsample` takes), and back.
const char* downsample_filter_name(DownsampleFilter f);
std::optional<DownsampleFilter> parse_downsample_filter(std::string_view name);
// What TilesetInfo::downsample records for a build with f: "box-linear" / "lanczos3-linear".
std::string downsample_method(DownsampleFilter f);

// The box filter on one row pair: makes one row of `out_width` RGBA8 texels from rows a and b (b
// may equal a at an odd bottom edge) of `in_width` texels: out[i] = mean of a[2i], a[2i+1], b[2i],
// b[2i+1] with 2i+1 clamped to in_width - 1. out_width must be ceil(in_width / 2).
void downsample_row_rgba8(const std::uint8_t* a, const std::uint8_t* b, std::uint64_t in_width,
                          std::uint8_t* out, std::uint64_t out_width);

// The Lanczos-3 weight of the fine texels at distance (k + 0.5) fine texels from a coarse texel's
// centre, k in [0, kLanczosHalfTaps): both sides together sum to 1.
inline constexpr int kLanczosHalfTaps = 6;
double lanczos3_weight(int k);

// Streaming Lanczos-3 reduction of one level (in_width x in_height RGBA8) to the next coarser one
// (ceil(in_width / 2) x ceil(in_height / 2)): rows of the finer level go in in order, coarser rows
// come out as soon as the rows under their kernel have arrived (coarse row r needs fine rows up to
// 2r + 6). Every pushed row is filtered horizontally at once into a ring of 12 half-width rows of
// linear, premultiplied float RGBA, so the reducer holds about 16 * (12 * in_width / 2 + in_width)
// = 112 * in_width bytes whatever the height, and the caller need not keep the fine rows.
class LanczosReducer {
 public:
  LanczosReducer(std::uint64_t in_width, std::uint64_t in_height);
  ~LanczosReducer();
  LanczosReducer(const LanczosReducer&) = delete;
  LanczosReducer& operator=(const LanczosReducer&) = delete;

  std::uint64_t out_width() const;
  std::uint64_t out_height() const;
  // Row number end_rows() of the finer level (in_width texels); at most in_height rows in all.
  void push_row(const std::uint8_t* row);
  std::uint64_t end_rows() const;
  // True when coarse row next_out_row() can be made from the rows pushed so far.
  bool ready() const;
  std::uint64_t next_out_row() const;
  // Writes coarse row next_out_row() (out_width() RGBA8 texels) and advances. Needs ready().
  void pop_row(std::uint8_t* out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The whole-image form of `filter` (every row through the same code as the builder's cascade):
// returns the ceil(width / 2) x ceil(height / 2) RGBA8 reduction of a width x height RGBA8 image.
std::vector<std::uint8_t> downsample_image_rgba8(const std::uint8_t* pixels, std::uint64_t width,
                                                 std::uint64_t height, DownsampleFilter filter);

}  // namespace builder
}  // namespace vts
