// The bc1 codec, as a reader sees it: each 4x4 block of texels is 8 bytes of BC1 (S3TC DXT1) —
// two 5:6:5 endpoint colours and sixteen 2-bit indices — and the blocks, row by row, are the body
// of the usual payload (header frame + one zstd frame, docs/FORMAT.md). GPUs sample BC1 directly,
// so a tile costs 4 bits per texel in the physical texture instead of 32, and the client does no
// pixel work beyond zstd. Decoding stops at the blocks; bc1_to_rgba8() widens them to texels for
// the CPU references. The encoder (stb_dxt, libsquish) is the builder's
// (builder/src/tile_encoder.cpp): readers of tiles never link it.
#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "codec_internal.hpp"
#include "vts/protocol/codec.hpp"

namespace vts {
inline namespace protocol {
namespace {

// A 5:6:5 endpoint (little-endian) widened to 8 bits a channel by bit replication, opaque.
std::uint16_t unpack_565(const std::uint8_t* p, std::uint8_t rgba[4]) {
  const std::uint16_t v = static_cast<std::uint16_t>(p[0] | p[1] << 8);
  const int r = v >> 11 & 0x1f, g = v >> 5 & 0x3f, b = v & 0x1f;
  rgba[0] = static_cast<std::uint8_t>(r << 3 | r >> 2);
  rgba[1] = static_cast<std::uint8_t>(g << 2 | g >> 4);
  rgba[2] = static_cast<std::uint8_t>(b << 3 | b >> 2);
  rgba[3] = 255;
  return v;
}

// One block into 16 RGBA texels, row-major. The two derived colours are computed as libsquish's
// decoder computes them (DecompressColour: truncating integer division), so the CPU references
// match the images the accuracy tables and GL tests were calibrated against.
void decode_bc1_block(const std::uint8_t block[8], std::uint8_t out[64]) {
  std::uint8_t palette[4][4];
  const std::uint16_t c0 = unpack_565(block, palette[0]);
  const std::uint16_t c1 = unpack_565(block + 2, palette[1]);
  const bool four_colours = c0 > c1;
  for (int i = 0; i < 3; ++i) {
    const int a = palette[0][i], b = palette[1][i];
    palette[2][i] = static_cast<std::uint8_t>(four_colours ? (2 * a + b) / 3 : (a + b) / 2);
    palette[3][i] = static_cast<std::uint8_t>(four_colours ? (a + 2 * b) / 3 : 0);
  }
  palette[2][3] = 255;
  palette[3][3] = four_colours ? 255 : 0;
  for (int k = 0; k < 16; ++k) {
    const int code = block[4 + k / 4] >> (2 * (k % 4)) & 3;
    std::memcpy(out + 4 * k, palette[code], 4);
  }
}

class Bc1Codec final : public Codec {
 public:
  CodecId id() const override { return CodecId::bc1; }
  PixelFormat decoded_format() const override { return PixelFormat::bc1; }

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
  const std::size_t bw = bc1_blocks(image.width), bh = bc1_blocks(image.height);
  if (image.pixels.size() != bw * bh * kBc1BlockBytes)
    return make_error(ErrorCode::invalid_argument,
                      "bc1 image of " + std::to_string(image.width) + "x" +
                          std::to_string(image.height) + " needs " +
                          std::to_string(bw * bh * kBc1BlockBytes) + " bytes, has " +
                          std::to_string(image.pixels.size()));
  TileImage out;
  out.width = image.width;
  out.height = image.height;
  out.format = PixelFormat::rgba8;
  out.pixels.resize(std::size_t(image.width) * image.height * 4);
  std::uint8_t texels[64];
  for (std::size_t by = 0; by < bh; ++by) {
    for (std::size_t bx = 0; bx < bw; ++bx) {
      decode_bc1_block(image.pixels.data() + (by * bw + bx) * kBc1BlockBytes, texels);
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
