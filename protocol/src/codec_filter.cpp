// Gradient prediction filter of the lossless codec (Filter::gradient). These loops run for every
// texel of every tile, so they are branch-free row loops over raw pointers: the first row reads a
// static zero row as "up", and the first texel of each row is peeled off, so the inner loops have
// no boundary tests. On x86-64 (SSE2 is baseline) 16 texels are processed per step; the scalar
// loops handle the rest of each row and every other architecture, and produce identical bytes.
#include <algorithm>
#include <cassert>
#include <cstdint>
#include <cstring>

#include "codec_internal.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#define VTS_FILTER_SSE2 1
#endif

namespace vts {
inline namespace protocol {
namespace detail {
namespace {

// Neighbours outside the image are 0: the row above the first row is this zero row.
constexpr std::uint32_t kMaxRowBytes = TileHeader::kMaxDimension * 4;
alignas(64) constexpr std::uint8_t kZeroRow[kMaxRowBytes] = {};

// clamp(left + up - upleft, 0, 255).
inline int predict(int a, int b, int c) {
  return std::clamp(a + b - c, 0, 255);
}

// Scalar kernels for texels [x0, width) of one row; x0 >= 1.
void filter_row_scalar(const std::uint8_t* cur, const std::uint8_t* up, std::uint32_t x0,
                       std::uint32_t width, std::uint8_t* r, std::uint8_t* g, std::uint8_t* b,
                       std::uint8_t* a) {
  for (std::uint32_t x = x0; x < width; ++x) {
    const std::uint8_t* c = cur + 4 * x;
    const std::uint8_t* u = up + 4 * x;
    r[x] = static_cast<std::uint8_t>(c[0] - predict(c[-4], u[0], u[-4]));
    g[x] = static_cast<std::uint8_t>(c[1] - predict(c[-3], u[1], u[-3]));
    b[x] = static_cast<std::uint8_t>(c[2] - predict(c[-2], u[2], u[-2]));
    a[x] = static_cast<std::uint8_t>(c[3] - predict(c[-1], u[3], u[-1]));
  }
}

void unfilter_row_scalar(std::uint8_t* cur, const std::uint8_t* up, std::uint32_t x0,
                         std::uint32_t width, const std::uint8_t* r, const std::uint8_t* g,
                         const std::uint8_t* b, const std::uint8_t* a) {
  // Serial along the row: each texel depends on its left neighbour. The four channels are four
  // independent dependency chains that the CPU overlaps.
  for (std::uint32_t x = x0; x < width; ++x) {
    std::uint8_t* c = cur + 4 * x;
    const std::uint8_t* u = up + 4 * x;
    c[0] = static_cast<std::uint8_t>(r[x] + predict(c[-4], u[0], u[-4]));
    c[1] = static_cast<std::uint8_t>(g[x] + predict(c[-3], u[1], u[-3]));
    c[2] = static_cast<std::uint8_t>(b[x] + predict(c[-2], u[2], u[-2]));
    c[3] = static_cast<std::uint8_t>(a[x] + predict(c[-1], u[3], u[-1]));
  }
}

#if VTS_FILTER_SSE2
inline __m128i load16(const std::uint8_t* p) {
  return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
}
inline void store16(std::uint8_t* p, __m128i v) {
  _mm_storeu_si128(reinterpret_cast<__m128i*>(p), v);
}

// Residuals of 4 interleaved texels (16 bytes) starting at cur/up (cur[-4], up[-4] readable).
inline __m128i filter4(const std::uint8_t* cur, const std::uint8_t* up) {
  const __m128i zero = _mm_setzero_si128();
  const __m128i x = load16(cur), a = load16(cur - 4), b = load16(up), c = load16(up - 4);
  const __m128i lo =
      _mm_sub_epi16(_mm_add_epi16(_mm_unpacklo_epi8(a, zero), _mm_unpacklo_epi8(b, zero)),
                    _mm_unpacklo_epi8(c, zero));
  const __m128i hi =
      _mm_sub_epi16(_mm_add_epi16(_mm_unpackhi_epi8(a, zero), _mm_unpackhi_epi8(b, zero)),
                    _mm_unpackhi_epi8(c, zero));
  // packus saturates each int16 to 0..255: exactly the predictor's clamp.
  return _mm_sub_epi8(x, _mm_packus_epi16(lo, hi));
}

// 16 interleaved RGBA texels (v0..v3, 4 texels each) -> 16 bytes of each channel.
inline void deinterleave(__m128i v0, __m128i v1, __m128i v2, __m128i v3, __m128i& r, __m128i& g,
                         __m128i& b, __m128i& a) {
  const __m128i t0 = _mm_unpacklo_epi8(v0, v1), t1 = _mm_unpackhi_epi8(v0, v1);
  const __m128i t2 = _mm_unpacklo_epi8(v2, v3), t3 = _mm_unpackhi_epi8(v2, v3);
  const __m128i u0 = _mm_unpacklo_epi8(t0, t1), u1 = _mm_unpackhi_epi8(t0, t1);
  const __m128i u2 = _mm_unpacklo_epi8(t2, t3), u3 = _mm_unpackhi_epi8(t2, t3);
  const __m128i w0 = _mm_unpacklo_epi8(u0, u1), w1 = _mm_unpackhi_epi8(u0, u1);
  const __m128i w2 = _mm_unpacklo_epi8(u2, u3), w3 = _mm_unpackhi_epi8(u2, u3);
  r = _mm_unpacklo_epi64(w0, w2);
  g = _mm_unpackhi_epi64(w0, w2);
  b = _mm_unpacklo_epi64(w1, w3);
  a = _mm_unpackhi_epi64(w1, w3);
}

// Inverse of deinterleave(): px[k] receives texels 4k..4k+3 as RGBA.
inline void interleave(__m128i r, __m128i g, __m128i b, __m128i a, __m128i px[4]) {
  const __m128i rg_lo = _mm_unpacklo_epi8(r, g), rg_hi = _mm_unpackhi_epi8(r, g);
  const __m128i ba_lo = _mm_unpacklo_epi8(b, a), ba_hi = _mm_unpackhi_epi8(b, a);
  px[0] = _mm_unpacklo_epi16(rg_lo, ba_lo);
  px[1] = _mm_unpackhi_epi16(rg_lo, ba_lo);
  px[2] = _mm_unpacklo_epi16(rg_hi, ba_hi);
  px[3] = _mm_unpackhi_epi16(rg_hi, ba_hi);
}

// The unfilter works in bytes: with dp = max(up - upleft, 0) and dn = max(upleft - up, 0) (one
// of them is 0), clamp(left + up - upleft, 0, 255) == subs_epu8(adds_epu8(left, dp), dn). dp and
// dn come from the row above, off the dependency chain, which is then three single-cycle byte ops
// per texel (saturating add, saturating subtract, add of the residual).
//
// One row being unfiltered: its output, the row above, its four residual planes, and the texel
// left of the next one (low 32 bits), kept in a register across the row: reading it back from
// `cur` would put a store-to-load forwarding delay on the chain.
struct UnfilterRow {
  std::uint8_t* cur;
  const std::uint8_t* up;
  const std::uint8_t *r, *g, *b, *a;
  __m128i left;
};

// Decodes one texel in the low 32 bits (the higher lanes are don't-care) and makes it `left`.
inline __m128i unfilter1(__m128i& left, __m128i dp, __m128i dn, __m128i res) {
  left = _mm_add_epi8(_mm_subs_epu8(_mm_adds_epu8(left, dp), dn), res);
  return left;
}

// Texels x .. x+3 of a row, `res` their residuals interleaved.
inline void unfilter4(UnfilterRow& row, std::uint32_t x, __m128i res) {
  const std::uint8_t* u = row.up + 4 * x;
  const __m128i uv = load16(u), ul = load16(u - 4);
  const __m128i dp = _mm_subs_epu8(uv, ul), dn = _mm_subs_epu8(ul, uv);
  const __m128i v0 = unfilter1(row.left, dp, dn, res);
  const __m128i v1 =
      unfilter1(row.left, _mm_srli_si128(dp, 4), _mm_srli_si128(dn, 4), _mm_srli_si128(res, 4));
  const __m128i v2 =
      unfilter1(row.left, _mm_srli_si128(dp, 8), _mm_srli_si128(dn, 8), _mm_srli_si128(res, 8));
  const __m128i v3 =
      unfilter1(row.left, _mm_srli_si128(dp, 12), _mm_srli_si128(dn, 12), _mm_srli_si128(res, 12));
  // Gather the four texels (each in the low 32 bits) into one 16-byte store.
  store16(row.cur + 4 * x,
          _mm_unpacklo_epi64(_mm_unpacklo_epi32(v0, v1), _mm_unpacklo_epi32(v2, v3)));
}

inline void residuals16(const UnfilterRow& row, std::uint32_t x, __m128i res[4]) {
  interleave(load16(row.r + x), load16(row.g + x), load16(row.b + x), load16(row.a + x), res);
}

// Texels x .. x+15 of one row.
inline void unfilter16(UnfilterRow& row, std::uint32_t x) {
  __m128i res[4];
  residuals16(row, x, res);
  for (std::uint32_t k = 0; k < 4; ++k) unfilter4(row, x + 4 * k, res[k]);
}

// Texels x0 .. x0+15 of row p and x1 .. x1+15 of row q, interleaved: the two dependency chains
// are independent, so the CPU runs them side by side.
inline void unfilter16x2(UnfilterRow& p, std::uint32_t x0, UnfilterRow& q, std::uint32_t x1) {
  __m128i rp[4], rq[4];
  residuals16(p, x0, rp);
  residuals16(q, x1, rq);
  for (std::uint32_t k = 0; k < 4; ++k) {
    unfilter4(p, x0 + 4 * k, rp[k]);
    unfilter4(q, x1 + 4 * k, rq[k]);
  }
}
#endif

}  // namespace

void gradient_filter(const std::uint8_t* rgba, std::uint32_t width, std::uint32_t height,
                     std::uint8_t* planes) {
  assert(width >= 1 && width <= TileHeader::kMaxDimension && height >= 1);
  const std::size_t plane = std::size_t(width) * height;
  const std::size_t row_bytes = std::size_t(width) * 4;
  for (std::uint32_t y = 0; y < height; ++y) {
    const std::uint8_t* cur = rgba + y * row_bytes;
    const std::uint8_t* up = y == 0 ? kZeroRow : cur - row_bytes;
    std::uint8_t* r = planes + std::size_t(y) * width;
    std::uint8_t* g = r + plane;
    std::uint8_t* b = g + plane;
    std::uint8_t* a = b + plane;
    // x = 0: left = upleft = 0, so the prediction is `up`.
    r[0] = static_cast<std::uint8_t>(cur[0] - up[0]);
    g[0] = static_cast<std::uint8_t>(cur[1] - up[1]);
    b[0] = static_cast<std::uint8_t>(cur[2] - up[2]);
    a[0] = static_cast<std::uint8_t>(cur[3] - up[3]);
    std::uint32_t x = 1;
#if VTS_FILTER_SSE2
    for (; x + 16 <= width; x += 16) {
      const std::uint8_t* c = cur + 4 * x;
      const std::uint8_t* u = up + 4 * x;
      __m128i vr, vg, vb, va;
      deinterleave(filter4(c, u), filter4(c + 16, u + 16), filter4(c + 32, u + 32),
                   filter4(c + 48, u + 48), vr, vg, vb, va);
      store16(r + x, vr);
      store16(g + x, vg);
      store16(b + x, vb);
      store16(a + x, va);
    }
#endif
    filter_row_scalar(cur, up, x, width, r, g, b, a);
  }
}

namespace {

// Row y of the image, its first texel decoded (left = 0 and upleft = 0: the prediction is `up`).
#if VTS_FILTER_SSE2
UnfilterRow start_row(const std::uint8_t* planes, std::uint32_t width, std::uint32_t height,
                      std::uint32_t y, std::uint8_t* rgba) {
  const std::size_t plane = std::size_t(width) * height;
  UnfilterRow row;
  row.cur = rgba + std::size_t(y) * width * 4;
  row.up = y == 0 ? kZeroRow : row.cur - std::size_t(width) * 4;
  row.r = planes + std::size_t(y) * width;
  row.g = row.r + plane;
  row.b = row.g + plane;
  row.a = row.b + plane;
  row.cur[0] = static_cast<std::uint8_t>(row.r[0] + row.up[0]);
  row.cur[1] = static_cast<std::uint8_t>(row.g[0] + row.up[1]);
  row.cur[2] = static_cast<std::uint8_t>(row.b[0] + row.up[2]);
  row.cur[3] = static_cast<std::uint8_t>(row.a[0] + row.up[3]);
  std::uint32_t first;
  std::memcpy(&first, row.cur, 4);
  row.left = _mm_cvtsi32_si128(static_cast<int>(first));
  return row;
}

void finish_row(const UnfilterRow& row, std::uint32_t x, std::uint32_t width) {
  unfilter_row_scalar(row.cur, row.up, x, width, row.r, row.g, row.b, row.a);
}

// Rows y and y+1 together, the second one 16-texel block behind the first (a block needs the
// row above up to its own last texel): two independent chains instead of one.
void unfilter_row_pair(const std::uint8_t* planes, std::uint32_t width, std::uint32_t height,
                       std::uint32_t y, std::uint8_t* rgba) {
  const std::uint32_t blocks = (width - 1) / 16;  // >= 1: width >= 17
  const std::uint32_t tail = 1 + 16 * blocks;
  UnfilterRow p = start_row(planes, width, height, y, rgba);
  unfilter16(p, 1);
  UnfilterRow q = start_row(planes, width, height, y + 1, rgba);
  for (std::uint32_t i = 1; i < blocks; ++i) unfilter16x2(p, 1 + 16 * i, q, 1 + 16 * (i - 1));
  finish_row(p, tail, width);
  unfilter16(q, tail - 16);
  finish_row(q, tail, width);
}
#endif

}  // namespace

void gradient_unfilter(const std::uint8_t* planes, std::uint32_t width, std::uint32_t height,
                       std::uint8_t* rgba) {
  assert(width >= 1 && width <= TileHeader::kMaxDimension && height >= 1);
  std::uint32_t y = 0;
#if VTS_FILTER_SSE2
  if (width >= 17) {
    for (; y + 2 <= height; y += 2) unfilter_row_pair(planes, width, height, y, rgba);
    if (y < height) {
      UnfilterRow row = start_row(planes, width, height, y, rgba);
      std::uint32_t x = 1;
      for (; x + 16 <= width; x += 16) unfilter16(row, x);
      finish_row(row, x, width);
      ++y;
    }
  }
#endif
  const std::size_t plane = std::size_t(width) * height;
  const std::size_t row_bytes = std::size_t(width) * 4;
  for (; y < height; ++y) {
    std::uint8_t* cur = rgba + y * row_bytes;
    const std::uint8_t* up = y == 0 ? kZeroRow : cur - row_bytes;
    const std::uint8_t* r = planes + std::size_t(y) * width;
    const std::uint8_t* g = r + plane;
    const std::uint8_t* b = g + plane;
    const std::uint8_t* a = b + plane;
    cur[0] = static_cast<std::uint8_t>(r[0] + up[0]);
    cur[1] = static_cast<std::uint8_t>(g[0] + up[1]);
    cur[2] = static_cast<std::uint8_t>(b[0] + up[2]);
    cur[3] = static_cast<std::uint8_t>(a[0] + up[3]);
    unfilter_row_scalar(cur, up, 1, width, r, g, b, a);
  }
}

}  // namespace detail
}  // namespace protocol
}  // namespace vts
