// The bc1 codec as a reader sees it: the payload framing it shares with the lossless codec, the
// blocks it hands back untouched, and bc1_to_rgba8() reading S3TC blocks made by hand (the
// encoder is the builder's: tests/unit/builder/test_tile_encoder.cpp).
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "vts/protocol/codec.hpp"

namespace vts {
namespace {

using Bytes = std::vector<std::uint8_t>;

// One BC1 block: endpoints c0 and c1 (5:6:5) and the 2-bit codes of rows 0..3 (texel i of a row
// at bits 2i).
Bytes block(std::uint16_t c0, std::uint16_t c1, std::uint8_t row0, std::uint8_t row1,
            std::uint8_t row2, std::uint8_t row3) {
  return {std::uint8_t(c0),
          std::uint8_t(c0 >> 8),
          std::uint8_t(c1),
          std::uint8_t(c1 >> 8),
          row0,
          row1,
          row2,
          row3};
}

TileImage bc1_image(std::uint32_t w, std::uint32_t h, Bytes blocks) {
  TileImage img;
  img.width = w;
  img.height = h;
  img.format = PixelFormat::bc1;
  img.pixels = std::move(blocks);
  return img;
}

using Rgba = std::array<int, 4>;
Rgba texel(const TileImage& img, std::uint32_t x, std::uint32_t y) {
  const std::uint8_t* p = &img.pixels[(std::size_t(y) * img.width + x) * 4];
  return {p[0], p[1], p[2], p[3]};
}

TEST(Bc1Codec, IsRegisteredAndHandsBackTheBlocksItWasGiven) {
  const Codec* c = find_codec(CodecId::bc1);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->id(), CodecId::bc1);
  EXPECT_EQ(c->decoded_format(), PixelFormat::bc1);
  // 66 x 66 blocks of 8 bytes: 4 bits per texel, 1/8 of rgba8.
  Bytes blocks(66u * 66u * 8u);
  std::mt19937 rng{7};
  for (auto& b : blocks) b = std::uint8_t(rng());
  auto p = pack_tile(CodecId::bc1, 264, 264, blocks, 3);
  ASSERT_TRUE(p.ok()) << p.error().to_string();
  auto h = parse_tile_header(*p);
  ASSERT_TRUE(h.ok()) << h.error().to_string();
  EXPECT_EQ(h->codec, CodecId::bc1);
  EXPECT_EQ(h->format, PixelFormat::bc1);
  EXPECT_EQ(h->filter, Filter::none);
  EXPECT_EQ(h->body_size, 66u * 66u * 8u);
  auto d = decode_tile(*p);
  ASSERT_TRUE(d.ok()) << d.error().to_string();
  EXPECT_EQ(d->format, PixelFormat::bc1);
  EXPECT_EQ(d->width, 264u);
  EXPECT_EQ(d->pixels, blocks);
}

TEST(Bc1ToRgba8, AFourColourBlockInterpolatesWithTruncatingDivisionInS3tcTexelOrder) {
  // c0 = white > c1 = (1, 1, 0) in 5:6:5 = (8, 4, 0): four opaque colours. Thirds truncate, as in
  // libsquish's decoder: (2 * 255 + 8) / 3 = 172.67 -> 172, (255 + 2 * 4) / 3 = 87.67 -> 87.
  const Rgba colours[4] = {
      {255, 255, 255, 255}, {8, 4, 0, 255}, {172, 171, 170, 255}, {90, 87, 85, 255}};
  // Rows: codes 0 1 2 3, 3 2 1 0, all 0, all 3 (texel i of a row at bits 2i).
  auto rgba = bc1_to_rgba8(bc1_image(4, 4, block(0xFFFF, 0x0820, 0xE4, 0x1B, 0x00, 0xFF)));
  ASSERT_TRUE(rgba.ok()) << rgba.error().to_string();
  const int codes[4][4] = {{0, 1, 2, 3}, {3, 2, 1, 0}, {0, 0, 0, 0}, {3, 3, 3, 3}};
  for (std::uint32_t y = 0; y < 4; ++y)
    for (std::uint32_t x = 0; x < 4; ++x)
      EXPECT_EQ(texel(*rgba, x, y), colours[codes[y][x]]) << x << "," << y;
}

TEST(Bc1ToRgba8, AThreeColourBlockHasAMidpointAndTransparentBlack) {
  // c0 = (1, 1, 1) = (8, 4, 8) <= c1 = white: the midpoint truncates ((8 + 255) / 2 = 131), the
  // fourth code is transparent black. Equal endpoints select this mode too.
  auto rgba = bc1_to_rgba8(bc1_image(4, 4, block(0x0821, 0xFFFF, 0xE4, 0xE4, 0xE4, 0xE4)));
  ASSERT_TRUE(rgba.ok()) << rgba.error().to_string();
  EXPECT_EQ(texel(*rgba, 0, 0), (Rgba{8, 4, 8, 255}));
  EXPECT_EQ(texel(*rgba, 1, 0), (Rgba{255, 255, 255, 255}));
  EXPECT_EQ(texel(*rgba, 2, 0), (Rgba{131, 129, 131, 255}));
  EXPECT_EQ(texel(*rgba, 3, 3), (Rgba{0, 0, 0, 0}));
  auto equal = bc1_to_rgba8(bc1_image(4, 4, block(0x0821, 0x0821, 0xFF, 0xFF, 0xFF, 0xFF)));
  ASSERT_TRUE(equal.ok());
  EXPECT_EQ(texel(*equal, 2, 1), (Rgba{0, 0, 0, 0}));
}

TEST(Bc1ToRgba8, PartialBlocksAreCropped) {
  // 6 x 5 texels: 2 x 2 blocks, the right and bottom ones partial; each block one colour (code 0).
  const std::uint16_t c[4] = {0xF800, 0x07E0, 0x001F, 0xFFFF};  // red, green, blue, white
  Bytes blocks;
  for (std::uint16_t c0 : c) {
    const Bytes b = block(c0, 0x0000, 0, 0, 0, 0);
    blocks.insert(blocks.end(), b.begin(), b.end());
  }
  auto rgba = bc1_to_rgba8(bc1_image(6, 5, blocks));
  ASSERT_TRUE(rgba.ok()) << rgba.error().to_string();
  EXPECT_EQ(rgba->width, 6u);
  EXPECT_EQ(rgba->height, 5u);
  ASSERT_EQ(rgba->pixels.size(), 6u * 5u * 4u);
  const Rgba want[4] = {{255, 0, 0, 255}, {0, 255, 0, 255}, {0, 0, 255, 255}, {255, 255, 255, 255}};
  for (std::uint32_t y = 0; y < 5; ++y)
    for (std::uint32_t x = 0; x < 6; ++x)
      EXPECT_EQ(texel(*rgba, x, y), want[(y / 4) * 2 + x / 4]) << x << "," << y;
}

TEST(Bc1Codec, CorruptPayloadsAreErrorsNotCrashes) {
  const Bytes blocks(16u * 16u * 8u, 0x3C);
  const Bytes p = pack_tile(CodecId::bc1, 64, 64, blocks, 3).value();
  // Any flipped body byte fails the checksum.
  for (std::size_t i = TileHeader::kFrameBytes; i < p.size(); ++i) {
    Bytes q = p;
    q[i] ^= 0x10;
    auto d = decode_tile(q);
    ASSERT_FALSE(d.ok()) << i;
    EXPECT_EQ(d.error().code, ErrorCode::checksum);
  }
  // Every truncation is an error.
  for (std::size_t n = 0; n < p.size(); ++n) {
    auto d = decode_tile(std::span(p.data(), n));
    EXPECT_FALSE(d.ok()) << n;
  }
  // The lossless codec refuses a bc1 payload and vice versa.
  EXPECT_EQ(find_codec(CodecId::lossless)->decode(p).error().code, ErrorCode::invalid_argument);
  TileImage rgba;
  rgba.width = rgba.height = 4;
  rgba.pixels.assign(4 * 4 * 4, 9);
  auto lossless = encode_lossless(rgba);
  ASSERT_TRUE(lossless.ok());
  EXPECT_EQ(find_codec(CodecId::bc1)->decode(*lossless).error().code, ErrorCode::invalid_argument);
}

TEST(Bc1ToRgba8, RejectsAnImageThatIsNotBc1OfItsSize) {
  TileImage rgba;
  rgba.width = rgba.height = 4;
  rgba.pixels.assign(4 * 4 * 4, 0);
  EXPECT_EQ(bc1_to_rgba8(rgba).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(bc1_to_rgba8(bc1_image(8, 8, Bytes(31))).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(bc1_to_rgba8(bc1_image(0, 8, Bytes{})).error().code, ErrorCode::invalid_argument);
}

}  // namespace
}  // namespace vts
