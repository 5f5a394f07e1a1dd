// PNG writing with libdeflate (png_writer.hpp). The filters are the PNG spec's (ISO/IEC 15948
// §9); the per-row choice ("adaptive") is libpng's heuristic: the filter whose output has the
// smallest sum of absolute values, read as signed bytes.
#include "png_writer.hpp"

#include <libdeflate.h>

#include <array>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>

namespace vts::imaging::detail {
namespace {

using Bytes = std::vector<std::uint8_t>;

struct CompressorFree {
  void operator()(libdeflate_compressor* c) const noexcept { libdeflate_free_compressor(c); }
};
using Compressor = std::unique_ptr<libdeflate_compressor, CompressorFree>;

// This thread's compressor of `level` (0..12), made on first use; null when out of memory.
libdeflate_compressor* compressor(int level) {
  thread_local std::array<Compressor, 13> kept;
  Compressor& c = kept[std::size_t(level)];
  if (!c) c.reset(libdeflate_alloc_compressor(level));
  return c.get();
}

std::uint8_t paeth(int a, int b, int c) {
  const int pa = std::abs(b - c), pb = std::abs(a - c), pc = std::abs(a + b - 2 * c);
  if (pa <= pb && pa <= pc) return std::uint8_t(a);
  return std::uint8_t(pb <= pc ? b : c);
}

// Writes filter type `f` (1..4; 0 copies) of `row` into out[0..n), `prior` the row above (zeros
// for the first), `bpp` bytes per pixel.
void filter_row(PngFilter f, const std::uint8_t* row, const std::uint8_t* prior, std::size_t n,
                std::size_t bpp, std::uint8_t* out) {
  switch (f) {
    case PngFilter::sub:
      std::memcpy(out, row, bpp);
      for (std::size_t i = bpp; i < n; ++i) out[i] = std::uint8_t(row[i] - row[i - bpp]);
      return;
    case PngFilter::up:
      for (std::size_t i = 0; i < n; ++i) out[i] = std::uint8_t(row[i] - prior[i]);
      return;
    case PngFilter::average:
      for (std::size_t i = 0; i < bpp; ++i) out[i] = std::uint8_t(row[i] - (prior[i] >> 1));
      for (std::size_t i = bpp; i < n; ++i)
        out[i] = std::uint8_t(row[i] - ((row[i - bpp] + prior[i]) >> 1));
      return;
    case PngFilter::paeth:
      for (std::size_t i = 0; i < bpp; ++i) out[i] = std::uint8_t(row[i] - prior[i]);
      for (std::size_t i = bpp; i < n; ++i)
        out[i] = std::uint8_t(row[i] - paeth(row[i - bpp], prior[i], prior[i - bpp]));
      return;
    case PngFilter::none:
    case PngFilter::adaptive:
      std::memcpy(out, row, n);
      return;
  }
}

// libpng's measure of how well a filtered row will compress: the sum of |byte as signed|.
std::uint32_t row_cost(const std::uint8_t* filtered, std::size_t n) {
  std::uint32_t sum = 0;
  for (std::size_t i = 0; i < n; ++i) sum += std::uint32_t(std::abs(int(std::int8_t(filtered[i]))));
  return sum;
}

// The filtered rows (each a filter-type byte, then the row) of the image.
Bytes filtered_rows(const std::uint8_t* pixels, std::uint32_t width, std::uint32_t height,
                    std::size_t bpp, PngFilter filter) {
  const std::size_t n = std::size_t(width) * bpp;
  Bytes out((n + 1) * height);
  const Bytes zeros(n, 0);
  Bytes trial(filter == PngFilter::adaptive ? n : 0);
  for (std::uint32_t y = 0; y < height; ++y) {
    const std::uint8_t* row = pixels + y * n;
    const std::uint8_t* prior = y == 0 ? zeros.data() : row - n;
    std::uint8_t* dst = &out[y * (n + 1)];
    PngFilter chosen = filter;
    if (filter == PngFilter::adaptive) {
      chosen = PngFilter::none;
      std::uint32_t best = row_cost(row, n);
      for (PngFilter f : {PngFilter::sub, PngFilter::up, PngFilter::average, PngFilter::paeth}) {
        filter_row(f, row, prior, n, bpp, trial.data());
        if (const std::uint32_t cost = row_cost(trial.data(), n); cost < best) {
          best = cost;
          chosen = f;
        }
      }
    }
    dst[0] = std::uint8_t(chosen);
    filter_row(chosen, row, prior, n, bpp, dst + 1);
  }
  return out;
}

void put32(Bytes& out, std::uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(std::uint8_t(v >> s));
}

// Appends a chunk: length, type, data, CRC-32 of type and data.
void put_chunk(Bytes& out, const char (&type)[5], const std::uint8_t* data, std::size_t n) {
  put32(out, std::uint32_t(n));
  const std::size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  out.insert(out.end(), data, data + n);
  put32(out, libdeflate_crc32(0, &out[start], n + 4));
}

}  // namespace

int deflate_level(int png_level) noexcept {
  return png_level >= 9 ? 12 : png_level;
}

Result<Bytes> png_bytes(const std::uint8_t* pixels, std::uint32_t width, std::uint32_t height,
                        int channels, int png_level, PngFilter filter, bool srgb) {
  libdeflate_compressor* c = compressor(deflate_level(png_level));
  if (c == nullptr) return make_error(ErrorCode::io, "PNG encoding failed: out of memory");
  const Bytes rows = filtered_rows(pixels, width, height, std::size_t(channels), filter);
  Bytes z(libdeflate_zlib_compress_bound(c, rows.size()));
  const std::size_t zn = libdeflate_zlib_compress(c, rows.data(), rows.size(), z.data(), z.size());
  if (zn == 0 || zn > 0x7fffffffu)
    return make_error(ErrorCode::io, "PNG encoding failed: the image is too large for one chunk");
  static constexpr std::uint8_t kSignature[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  Bytes out(std::begin(kSignature), std::end(kSignature));
  out.reserve(zn + 80);
  Bytes ihdr;
  put32(ihdr, width);
  put32(ihdr, height);
  // Bit depth 8; colour type 6 (RGBA) or 2 (RGB); deflate, adaptive filtering, no interlace.
  ihdr.insert(ihdr.end(), {8, std::uint8_t(channels == 4 ? 6 : 2), 0, 0, 0});
  put_chunk(out, "IHDR", ihdr.data(), ihdr.size());
  if (srgb) {
    const std::uint8_t perceptual = 0;
    put_chunk(out, "sRGB", &perceptual, 1);
  }
  put_chunk(out, "IDAT", z.data(), zn);
  put_chunk(out, "IEND", nullptr, 0);
  return out;
}

}  // namespace vts::imaging::detail
