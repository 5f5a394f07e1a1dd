// The bc1 codec: the payload framing it shares with the lossless codec, the BC1 block layout a GPU
// samples, and its error on a real image (the Earth) at every quality, against stated bounds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <thread>
#include <vector>

#include "vts/imaging/web_image.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/test/files.hpp"

namespace vts {
namespace {

using Bytes = std::vector<std::uint8_t>;

TileImage solid(std::uint32_t w, std::uint32_t h, std::uint8_t r, std::uint8_t g, std::uint8_t b,
                std::uint8_t a = 255) {
  TileImage img;
  img.width = w;
  img.height = h;
  img.pixels.resize(std::size_t(w) * h * 4);
  for (std::size_t i = 0; i < img.pixels.size(); i += 4) {
    img.pixels[i] = r;
    img.pixels[i + 1] = g;
    img.pixels[i + 2] = b;
    img.pixels[i + 3] = a;
  }
  return img;
}

Bytes encode(const TileImage& img, Bc1Quality q, int level = 3) {
  EncodeOptions o;
  o.bc1 = q;
  o.zstd_level = level;
  auto p = find_codec(CodecId::bc1)->encode(img, o);
  EXPECT_TRUE(p.ok()) << p.error().to_string();
  return p.ok() ? *p : Bytes{};
}

TileImage round_trip(const TileImage& img, Bc1Quality q) {
  auto d = decode_tile(encode(img, q));
  EXPECT_TRUE(d.ok()) << d.error().to_string();
  auto rgba = bc1_to_rgba8(*d);
  EXPECT_TRUE(rgba.ok()) << rgba.error().to_string();
  return *rgba;
}

struct Error2 {
  double psnr = 0;
  int max_abs = 0;
};

// PSNR and largest difference over R, G, B of two rgba8 images of one size.
Error2 rgb_error(const TileImage& a, const TileImage& b) {
  double se = 0;
  int mx = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) {
    if (i % 4 == 3) continue;
    const int d = int(a.pixels[i]) - int(b.pixels[i]);
    se += double(d) * d;
    mx = std::max(mx, std::abs(d));
    ++n;
  }
  return {se == 0 ? INFINITY : 10 * std::log10(255.0 * 255.0 * double(n) / se), mx};
}

// The Earth (xplanet's 2048x1024 blue marble) cut into 256x256 tiles, as a builder would.
std::vector<TileImage> earth_tiles() {
  auto earth = imaging::decode_web_image(test::read_bytes(VTS_EARTH_JPG));  // libjpeg-turbo
  EXPECT_TRUE(earth.ok()) << earth.error().to_string();
  if (!earth.ok()) return {};
  const int w = int(earth->width), h = int(earth->height), ch = 4;
  const std::vector<std::uint8_t>& px = earth->pixels;
  std::vector<TileImage> tiles;
  for (int ty = 0; ty + 256 <= h; ty += 256)
    for (int tx = 0; tx + 256 <= w; tx += 256) {
      TileImage t = solid(256, 256, 0, 0, 0);
      for (int y = 0; y < 256; ++y)
        for (int x = 0; x < 256; ++x)
          for (int c = 0; c < 3; ++c)
            t.pixels[(std::size_t(y) * 256 + x) * 4 + c] =
                px[(std::size_t(ty + y) * w + tx + x) * ch + std::size_t(std::min(c, ch - 1))];
      tiles.push_back(std::move(t));
    }
  return tiles;
}

TEST(Bc1Codec, IsRegisteredAndDecodesToBlocks) {
  const Codec* c = find_codec(CodecId::bc1);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->id(), CodecId::bc1);
  EXPECT_EQ(c->decoded_format(), PixelFormat::bc1);
  const Bytes p = encode(solid(264, 264, 10, 20, 30), Bc1Quality::high);
  auto h = parse_tile_header(p);
  ASSERT_TRUE(h.ok()) << h.error().to_string();
  EXPECT_EQ(h->codec, CodecId::bc1);
  EXPECT_EQ(h->format, PixelFormat::bc1);
  EXPECT_EQ(h->filter, Filter::none);
  // 66 x 66 blocks of 8 bytes: 4 bits per texel, 1/8 of rgba8.
  EXPECT_EQ(h->body_size, 66u * 66u * 8u);
  auto d = decode_tile(p);
  ASSERT_TRUE(d.ok()) << d.error().to_string();
  EXPECT_EQ(d->format, PixelFormat::bc1);
  EXPECT_EQ(d->width, 264u);
  EXPECT_EQ(d->pixels.size(), 66u * 66u * 8u);
}

TEST(Bc1Codec, ColoursOnThe565GridRoundTripExactlyAtEveryQuality) {
  // 5:6:5 widened by bit replication: 255/0/255 and (8 << 3 | 8 >> 2) = 66 etc. are exact.
  for (Bc1Quality q : {Bc1Quality::fast, Bc1Quality::high, Bc1Quality::best}) {
    const TileImage a = solid(16, 8, 255, 0, 255);
    EXPECT_EQ(round_trip(a, q).pixels, a.pixels) << bc1_quality_name(q);
    const TileImage b = solid(8, 8, 66, 130, 8);  // r 8/31, g 32/63, b 1/31
    EXPECT_EQ(round_trip(b, q).pixels, b.pixels) << bc1_quality_name(q);
  }
}

TEST(Bc1Codec, TheBlockLayoutIsS3tc) {
  // Two colours in one block: red left half, blue right half. Whatever the encoder, the block must
  // read as S3TC says: endpoints little-endian 5:6:5, index 2 bits per texel, row-major from the
  // top-left, texel (i, j) at bits 2 (4 j + i).
  TileImage img = solid(4, 4, 255, 0, 0);
  for (int j = 0; j < 4; ++j)
    for (int i = 2; i < 4; ++i) {
      std::uint8_t* p = &img.pixels[std::size_t(4 * j + i) * 4];
      p[0] = 0;
      p[2] = 255;
    }
  for (Bc1Quality q : {Bc1Quality::fast, Bc1Quality::high, Bc1Quality::best}) {
    auto d = decode_tile(encode(img, q));
    ASSERT_TRUE(d.ok());
    const std::uint8_t* b = d->pixels.data();
    const std::uint16_t c0 = std::uint16_t(b[0] | b[1] << 8), c1 = std::uint16_t(b[2] | b[3] << 8);
    const std::uint32_t idx = std::uint32_t(b[4]) | std::uint32_t(b[5]) << 8 |
                              std::uint32_t(b[6]) << 16 | std::uint32_t(b[7]) << 24;
    const std::uint16_t red = 0xf800, blue = 0x001f;
    ASSERT_TRUE((c0 == red && c1 == blue) || (c0 == blue && c1 == red))
        << bc1_quality_name(q) << " " << c0 << " " << c1;
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 4; ++i) {
        const std::uint32_t code = idx >> (2 * (4 * j + i)) & 3;
        const bool want_red = i < 2;
        EXPECT_EQ(code, (c0 == red) == want_red ? 0u : 1u) << bc1_quality_name(q) << i << j;
      }
  }
}

TEST(Bc1Codec, PartialBlocksAreCroppedAndOnlyRealTexelsCount) {
  // 6 x 5 texels: 2 x 2 blocks, the right and bottom ones partial.
  TileImage img = solid(6, 5, 255, 0, 255);
  auto d = decode_tile(encode(img, Bc1Quality::high));
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->pixels.size(), 2u * 2u * 8u);
  auto rgba = bc1_to_rgba8(*d);
  ASSERT_TRUE(rgba.ok());
  EXPECT_EQ(rgba->width, 6u);
  EXPECT_EQ(rgba->height, 5u);
  EXPECT_EQ(rgba->pixels, img.pixels);
}

TEST(Bc1Codec, TransparentTexelsStayTransparentAtEveryQuality) {
  // Left half alpha 0, right half opaque: BC1's punch-through mode keeps the split.
  TileImage img = solid(8, 8, 40, 160, 80);
  for (std::uint32_t y = 0; y < 8; ++y)
    for (std::uint32_t x = 0; x < 4; ++x) img.pixels[(y * 8 + x) * 4 + 3] = 0;
  for (Bc1Quality q : {Bc1Quality::fast, Bc1Quality::high, Bc1Quality::best}) {
    const TileImage out = round_trip(img, q);
    for (std::uint32_t y = 0; y < 8; ++y)
      for (std::uint32_t x = 0; x < 8; ++x)
        EXPECT_EQ(out.pixels[(y * 8 + x) * 4 + 3], x < 4 ? 0 : 255)
            << bc1_quality_name(q) << " " << x << "," << y;
  }
}

// The stated bounds (docs/ACCURACY.md, table 1): over the 32 full 256 x 256 tiles of the Earth,
// RGB PSNR >= 37.5 dB at high and best and >= 37 dB at fast; best >= high - 0.05 dB. Measured:
// fast 37.81, high 38.12, best 38.12 dB (max error 104 at every quality: a block holding ocean,
// coast and cloud has more colours than BC1's four on one line).
TEST(Bc1Codec, EarthErrorIsWithinTheStatedBounds) {
  const std::vector<TileImage> tiles = earth_tiles();
  ASSERT_EQ(tiles.size(), 32u);
  double psnr[3] = {};
  for (Bc1Quality q : {Bc1Quality::fast, Bc1Quality::high, Bc1Quality::best}) {
    double se_sum = 0;
    int mx = 0;
    for (const TileImage& t : tiles) {
      const Error2 e = rgb_error(t, round_trip(t, q));
      se_sum += 255.0 * 255.0 / std::pow(10.0, e.psnr / 10);  // the tile's MSE
      mx = std::max(mx, e.max_abs);
    }
    psnr[int(q)] = 10 * std::log10(255.0 * 255.0 / (se_sum / double(tiles.size())));
    std::printf("bc1 %s: PSNR %.2f dB, max error %d\n", bc1_quality_name(q), psnr[int(q)], mx);
    EXPECT_GT(mx, 0) << "BC1 is lossy: an exact round trip means the codec did not run";
  }
  EXPECT_GE(psnr[int(Bc1Quality::fast)], 37.0);
  EXPECT_GE(psnr[int(Bc1Quality::high)], 37.5);
  EXPECT_GE(psnr[int(Bc1Quality::best)], 37.5);
  EXPECT_GE(psnr[int(Bc1Quality::best)], psnr[int(Bc1Quality::high)] - 0.05);
}

TEST(Bc1Codec, CorruptPayloadsAreErrorsNotCrashes) {
  Bytes p = encode(solid(64, 64, 1, 2, 3), Bc1Quality::fast);
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
  auto lossless = find_codec(CodecId::lossless)->encode(solid(4, 4, 1, 2, 3), {});
  ASSERT_TRUE(lossless.ok());
  EXPECT_EQ(find_codec(CodecId::bc1)->decode(*lossless).error().code, ErrorCode::invalid_argument);
}

TEST(Bc1Codec, EncodeAndConvertRejectMalformedImages) {
  const Codec* c = find_codec(CodecId::bc1);
  TileImage bad = solid(8, 8, 0, 0, 0);
  bad.pixels.pop_back();
  EXPECT_EQ(c->encode(bad, {}).error().code, ErrorCode::invalid_argument);
  TileImage empty;
  EXPECT_EQ(c->encode(empty, {}).error().code, ErrorCode::invalid_argument);
  EncodeOptions o;
  o.zstd_level = 99;
  EXPECT_EQ(c->encode(solid(4, 4, 0, 0, 0), o).error().code, ErrorCode::invalid_argument);
  // bc1_to_rgba8 wants a bc1 image of the right byte count.
  EXPECT_FALSE(bc1_to_rgba8(solid(4, 4, 0, 0, 0)).ok());
  TileImage blocks;
  blocks.width = 8;
  blocks.height = 8;
  blocks.format = PixelFormat::bc1;
  blocks.pixels.resize(31);
  EXPECT_EQ(bc1_to_rgba8(blocks).error().code, ErrorCode::invalid_argument);
}

TEST(Bc1Codec, QualityNamesRoundTrip) {
  for (Bc1Quality q : {Bc1Quality::fast, Bc1Quality::high, Bc1Quality::best})
    EXPECT_EQ(parse_bc1_quality(bc1_quality_name(q)).value(), q);
  EXPECT_FALSE(parse_bc1_quality("HIGH").ok());
  EXPECT_FALSE(parse_bc1_quality("").ok());
}

TEST(Bc1Codec, EncodesConcurrentlyFromManyThreads) {
  std::vector<std::thread> threads;
  std::vector<int> failures(4, 0);
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([t, &failures] {
      std::mt19937 rng{std::uint32_t(t)};
      for (int i = 0; i < 10; ++i) {
        TileImage img = solid(36, 20, 0, 0, 0);
        for (auto& b : img.pixels) b = std::uint8_t(rng() | 0x80);
        EncodeOptions o;
        o.bc1 = static_cast<Bc1Quality>(i % 3);
        auto p = find_codec(CodecId::bc1)->encode(img, o);
        auto again = find_codec(CodecId::bc1)->encode(img, o);
        if (!p.ok() || !again.ok() || *p != *again || !decode_tile(*p).ok()) ++failures[t];
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(failures, std::vector<int>(4, 0));
}

}  // namespace
}  // namespace vts
