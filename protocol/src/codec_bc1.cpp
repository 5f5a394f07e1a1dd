// The bc1 codec: each 4x4 block of texels becomes 8 bytes of BC1 (S3TC DXT1) — two 5:6:5 endpoint
// colours and sixteen 2-bit indices — and the blocks, row by row, are the body of the usual
// payload (header frame + one zstd frame, docs/FORMAT.md). GPUs sample BC1 directly, so a tile
// costs 4 bits per texel in the physical texture instead of 32, and the client does no pixel work
// beyond zstd.
//
// Encoders: stb_dxt (Bc1Quality::fast) and libsquish (high: cluster fit, best: iterative cluster
// fit), both from Debian. stb_dxt has no punch-through alpha, so a block holding a texel with
// alpha < 128 goes to libsquish's range fit in fast mode; libsquish makes such texels transparent
// (the 3-colour mode's fourth code) and keeps alpha >= 128 opaque. The colour error is measured
// with equal weights for R, G and B (what PSNR over RGB measures), on the sRGB-encoded values
// the texture stores.
#include <squish.h>

#include <cstring>  // stb_dxt.h uses memcpy without including it

#define STB_DXT_IMPLEMENTATION
#define STB_DXT_STATIC
#include <stb/stb_dxt.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "codec_internal.hpp"
#include "vts/protocol/codec.hpp"

namespace vts {
inline namespace protocol {
namespace {

constexpr std::size_t kBlockBytes = 8;

std::size_t blocks_across(std::uint32_t texels) {
  return (std::size_t(texels) + 3) / 4;
}

// The 4x4 texels of block (bx, by) as 64 bytes of RGBA, and the mask of those inside the image
// (bit 4 * row + column). Texels past the right or bottom edge repeat the edge, so an encoder
// without masks sees no stray colours.
int gather_block(const TileImage& image, std::size_t bx, std::size_t by, std::uint8_t out[64]) {
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

void encode_block(const std::uint8_t rgba[64], int mask, Bc1Quality quality, std::uint8_t* out) {
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

class Bc1Codec final : public Codec {
 public:
  CodecId id() const override { return CodecId::bc1; }
  PixelFormat decoded_format() const override { return PixelFormat::bc1; }

  Result<std::vector<std::uint8_t>> encode(const TileImage& image,
                                           const EncodeOptions& options) const override {
    if (Status s = detail::check_encode_input(image, "bc1"); !s) return s.error();
    if (Status s = detail::check_zstd_level(options.zstd_level); !s) return s.error();

    const std::size_t bw = blocks_across(image.width), bh = blocks_across(image.height);
    thread_local std::vector<std::uint8_t> blocks;
    blocks.resize(bw * bh * kBlockBytes);
    std::uint8_t texels[64];
    for (std::size_t by = 0; by < bh; ++by) {
      for (std::size_t bx = 0; bx < bw; ++bx) {
        const int mask = gather_block(image, bx, by, texels);
        encode_block(texels, mask, options.bc1, blocks.data() + (by * bw + bx) * kBlockBytes);
      }
    }
    TileHeader header;
    header.codec = CodecId::bc1;
    header.format = PixelFormat::bc1;
    header.filter = Filter::none;
    header.width = image.width;
    header.height = image.height;
    std::vector<std::uint8_t> payload;
    if (Status s = detail::compress_payload(blocks.data(), blocks.size(), options.zstd_level,
                                            header, payload);
        !s)
      return s.error();
    if (blocks.capacity() > (std::size_t(8) << 20)) std::vector<std::uint8_t>().swap(blocks);
    return payload;
  }

  Result<TileImage> decode(std::span<const std::uint8_t> payload) const override {
    auto header = detail::verify_payload(payload);
    if (!header) return std::move(header).error();
    if (header->codec != CodecId::bc1)
      return make_error(ErrorCode::invalid_argument, std::string("bc1 codec asked to decode a ") +
                                                         codec_name(header->codec) + " tile");
    TileImage image;
    image.width = header->width;
    image.height = header->height;
    image.format = PixelFormat::bc1;
    if (Status s = detail::decompress_body(*header, payload.subspan(TileHeader::kFrameBytes),
                                           image.pixels);
        !s)
      return s.error();
    return image;
  }
};

const Bc1Codec kBc1;

}  // namespace

const Codec& detail::bc1_codec() {
  return kBc1;
}

Result<TileImage> bc1_to_rgba8(const TileImage& image) {
  if (image.format != PixelFormat::bc1)
    return make_error(ErrorCode::invalid_argument, "bc1_to_rgba8 needs a bc1 image");
  if (image.width == 0 || image.height == 0 || image.width > TileHeader::kMaxDimension ||
      image.height > TileHeader::kMaxDimension)
    return make_error(ErrorCode::invalid_argument, "bc1 image size " + std::to_string(image.width) +
                                                       "x" + std::to_string(image.height) +
                                                       " outside 1.." +
                                                       std::to_string(TileHeader::kMaxDimension));
  const std::size_t bw = blocks_across(image.width), bh = blocks_across(image.height);
  if (image.pixels.size() != bw * bh * kBlockBytes)
    return make_error(ErrorCode::invalid_argument,
                      "bc1 image of " + std::to_string(image.width) + "x" +
                          std::to_string(image.height) + " needs " +
                          std::to_string(bw * bh * kBlockBytes) + " bytes, has " +
                          std::to_string(image.pixels.size()));
  TileImage out;
  out.width = image.width;
  out.height = image.height;
  out.format = PixelFormat::rgba8;
  out.pixels.resize(std::size_t(image.width) * image.height * 4);
  std::uint8_t texels[64];
  for (std::size_t by = 0; by < bh; ++by) {
    for (std::size_t bx = 0; bx < bw; ++bx) {
      squish::Decompress(texels, image.pixels.data() + (by * bw + bx) * kBlockBytes, squish::kDxt1);
      const std::size_t rows = std::min<std::size_t>(4, image.height - by * 4);
      const std::size_t cols = std::min<std::size_t>(4, image.width - bx * 4);
      for (std::size_t j = 0; j < rows; ++j)
        std::memcpy(out.pixels.data() + 4 * ((by * 4 + j) * image.width + bx * 4), texels + 16 * j,
                    4 * cols);
    }
  }
  return out;
}

}  // namespace protocol
}  // namespace vts
