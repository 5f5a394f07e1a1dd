// The tile encoders: lossless through protocol, bc1 here. Each 4x4 block of texels becomes 8
// bytes of BC1 (S3TC DXT1) — two 5:6:5 endpoint colours and sixteen 2-bit indices — and
// vts::pack_tile() frames the blocks, row by row, as the usual payload (docs/FORMAT.md).
//
// Encoders: stb_dxt (Bc1Quality::fast) and libsquish (high: cluster fit, best: iterative cluster
// fit), both from Debian; this is the one file that uses either. stb_dxt has no punch-through
// alpha, so a block holding a texel with alpha < 128 goes to libsquish's range fit in fast mode;
// libsquish makes such texels transparent (the 3-colour mode's fourth code) and keeps alpha >= 128
// opaque. The colour error is measured with equal weights for R, G and B (what PSNR over RGB
// measures), on the sRGB-encoded values the texture stores.
//
// No OpenImageIO or GDAL header here: this file shares unity batches with the build's core, which
// the synthetic-only programs link (builder/CMakeLists.txt).
#include "vts/builder/tile_encoder.hpp"

#include <squish.h>

#include <cstring>  // stb_dxt.h uses memcpy without including it

#define STB_DXT_IMPLEMENTATION
#define STB_DXT_STATIC
#include <stb/stb_dxt.h>

#include <algorithm>
#include <string>

namespace vts {
inline namespace builder {
namespace {

// The 4x4 texels of block (bx, by) as 64 bytes of RGBA, and the mask of those inside the image
// (bit 4 * row + column). Texels past the right or bottom edge repeat the edge, so an encoder
// without masks sees no stray colours.
int gather_bc1_block(const TileImage& image, std::size_t bx, std::size_t by, std::uint8_t out[64]) {
  int mask = 0;
  for (int j = 0; j < 4; ++j) {
    const std::size_t y = by * 4 + std::size_t(j);
    const std::size_t sy = std::min<std::size_t>(y, image.height - 1);
    for (int i = 0; i < 4; ++i) {
      const std::size_t x = bx * 4 + std::size_t(i);
      const std::size_t sx = std::min<std::size_t>(x, image.width - 1);
      std::memcpy(out + 4 * (4 * j + i), image.pixels.data() + 4 * (sy * image.width + sx), 4);
      if (x < image.width && y < image.height) mask |= 1 << (4 * j + i);
    }
  }
  return mask;
}

bool has_transparent_texel(const std::uint8_t rgba[64], int mask) {
  for (int k = 0; k < 16; ++k)
    if ((mask >> k & 1) && rgba[4 * k + 3] < 128) return true;
  return false;
}

void encode_bc1_block(const std::uint8_t rgba[64], int mask, Bc1Quality quality,
                      std::uint8_t* out) {
  if (quality == Bc1Quality::fast && !has_transparent_texel(rgba, mask)) {
    stb_compress_dxt_block(out, rgba, /*alpha=*/0, STB_DXT_HIGHQUAL);
    return;
  }
  int flags = squish::kDxt1;
  switch (quality) {
    case Bc1Quality::fast:
      flags |= squish::kColourRangeFit;
      break;
    case Bc1Quality::high:
      flags |= squish::kColourClusterFit;
      break;
    case Bc1Quality::best:
      flags |= squish::kColourIterativeClusterFit;
      break;
  }
  squish::CompressMasked(rgba, mask, out, flags);
}

Result<std::vector<std::uint8_t>> encode_bc1(const TileImage& image, const EncodeOptions& options) {
  if (Status s = check_encode_input(image, CodecId::bc1); !s) return s.error();
  const std::size_t bw = bc1_blocks(image.width), bh = bc1_blocks(image.height);
  // Per thread, so that encoding millions of tiles does not allocate per tile; dropped after a
  // rare huge tile so its size is not pinned per thread for ever.
  thread_local std::vector<std::uint8_t> blocks;
  blocks.resize(bw * bh * kBc1BlockBytes);
  std::uint8_t texels[64];
  for (std::size_t by = 0; by < bh; ++by) {
    for (std::size_t bx = 0; bx < bw; ++bx) {
      const int mask = gather_bc1_block(image, bx, by, texels);
      encode_bc1_block(texels, mask, options.bc1, blocks.data() + (by * bw + bx) * kBc1BlockBytes);
    }
  }
  auto payload = pack_tile(CodecId::bc1, image.width, image.height, blocks, options.zstd_level);
  if (blocks.capacity() > (std::size_t(8) << 20)) std::vector<std::uint8_t>().swap(blocks);
  return payload;
}

}  // namespace

const char* bc1_quality_name(Bc1Quality q) noexcept {
  switch (q) {
    case Bc1Quality::fast:
      return "fast";
    case Bc1Quality::high:
      return "high";
    case Bc1Quality::best:
      return "best";
  }
  return "unknown";
}

Result<Bc1Quality> parse_bc1_quality(std::string_view name) {
  for (Bc1Quality q : {Bc1Quality::fast, Bc1Quality::high, Bc1Quality::best})
    if (name == bc1_quality_name(q)) return q;
  return make_error(ErrorCode::invalid_argument,
                    "unknown bc1 quality \"" + std::string(name) + "\" (known: fast, high, best)");
}

Result<std::vector<std::uint8_t>> encode_tile(const TileImage& image, CodecId codec,
                                              const EncodeOptions& options) {
  switch (codec) {
    case CodecId::lossless:
      return encode_lossless(image, LosslessOptions{options.zstd_level, options.filter});
    case CodecId::bc1:
      return encode_bc1(image, options);
  }
  return make_error(ErrorCode::invalid_argument,
                    "no encoder for codec " + std::to_string(static_cast<int>(codec)));
}

}  // namespace builder
}  // namespace vts
