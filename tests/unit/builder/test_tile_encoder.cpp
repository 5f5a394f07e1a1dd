// The tile encoders (vts::encode_tile): bc1's BC1 block layout a GPU samples, its error on a real
// image (the Earth) at every quality against stated bounds, and the dispatch to protocol's
// lossless encoder. Also that protocol's bc1 decoder (bc1_to_rgba8) reads every block as
// libsquish's decoder does, bit for bit: the references and tolerances elsewhere assume it.
#include "vts/builder/tile_encoder.hpp"

#include <gtest/gtest.h>
#include <squish.h>

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

constexpr Bc1Quality kQualities[] = {Bc1Quality::fast, Bc1Quality::high, Bc1Quality::best};

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

EncodeOptions bc1_options(Bc1Quality q, int level = 3) {
  EncodeOptions o;
  o.bc1 = q;
  o.zstd_level = level;
  return o;
}

Bytes encode(const TileImage& img, Bc1Quality q) {
  auto p = encode_tile(img, CodecId::bc1, bc1_options(q));
  EXPECT_TRUE(p.ok()) << p.error().to_string();
  return p.ok() ? *p : Bytes{};
}

TileImage round_trip(const TileImage& img, Bc1Quality q) {
  auto d = decode_tile(encode(img, q));
  EXPECT_TRUE(d.ok()) << d.error().to_string();
  if (!d.ok()) return {};
  auto rgba = bc1_to_rgba8(*d);
  EXPECT_TRUE(rgba.ok()) << rgba.error().to_string();
  return rgba.ok() ? *rgba : TileImage{};
}

struct RgbError {
  double psnr = 0;
  int max_abs = 0;
};

// PSNR and largest difference over R, G, B of two rgba8 images of one size.
RgbError rgb_error(const TileImage& a, const TileImage& b) {
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

TEST(EncodeTile, Bc1WritesBlocksOfFourBitsPerTexel) {
  const Bytes p = encode(solid(264, 264, 10, 20, 30), Bc1Quality::high);
  auto h = parse_tile_header(p);
  ASSERT_TRUE(h.ok()) << h.error().to_string();
  EXPECT_EQ(h->codec, CodecId::bc1);
  EXPECT_EQ(h->format, PixelFormat::bc1);
  EXPECT_EQ(h->filter, Filter::none);
  // 66 x 66 blocks of 8 bytes: 4 bits per texel, 1/8 of rgba8.
  EXPECT_EQ(h->body_size, 66u * 66u * 8u);
  EXPECT_EQ(p.capacity(), p.size());
  auto d = decode_tile(p);
  ASSERT_TRUE(d.ok()) << d.error().to_string();
  EXPECT_EQ(d->format, PixelFormat::bc1);
  EXPECT_EQ(d->pixels.size(), 66u * 66u * 8u);
}

TEST(EncodeTile, Bc1ColoursOnThe565GridRoundTripExactlyAtEveryQuality) {
  // 5:6:5 widened by bit replication: 255/0/255 and (8 << 3 | 8 >> 2) = 66 etc. are exact.
  for (Bc1Quality q : kQualities) {
    const TileImage a = solid(16, 8, 255, 0, 255);
    EXPECT_EQ(round_trip(a, q).pixels, a.pixels) << bc1_quality_name(q);
    const TileImage b = solid(8, 8, 66, 130, 8);  // r 8/31, g 32/63, b 1/31
    EXPECT_EQ(round_trip(b, q).pixels, b.pixels) << bc1_quality_name(q);
  }
}

TEST(EncodeTile, Bc1BlockLayoutIsS3tc) {
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
  for (Bc1Quality q : kQualities) {
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

TEST(EncodeTile, Bc1PartialBlocksAreCroppedAndOnlyRealTexelsCount) {
  // 6 x 5 texels: 2 x 2 blocks, the right and bottom ones partial.
  const TileImage img = solid(6, 5, 255, 0, 255);
  auto d = decode_tile(encode(img, Bc1Quality::high));
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->pixels.size(), 2u * 2u * 8u);
  auto rgba = bc1_to_rgba8(*d);
  ASSERT_TRUE(rgba.ok());
  EXPECT_EQ(rgba->width, 6u);
  EXPECT_EQ(rgba->height, 5u);
  EXPECT_EQ(rgba->pixels, img.pixels);
}

TEST(EncodeTile, Bc1TransparentTexelsStayTransparentAtEveryQuality) {
  // Left half alpha 0, right half opaque: BC1's punch-through mode keeps the split.
  TileImage img = solid(8, 8, 40, 160, 80);
  for (std::uint32_t y = 0; y < 8; ++y)
    for (std::uint32_t x = 0; x < 4; ++x) img.pixels[(y * 8 + x) * 4 + 3] = 0;
  for (Bc1Quality q : kQualities) {
    const TileImage out = round_trip(img, q);
    ASSERT_EQ(out.pixels.size(), img.pixels.size());
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
TEST(EncodeTile, Bc1EarthErrorIsWithinTheStatedBounds) {
  const std::vector<TileImage> tiles = earth_tiles();
  ASSERT_EQ(tiles.size(), 32u);
  double psnr[3] = {};
  for (Bc1Quality q : kQualities) {
    double se_sum = 0;
    int mx = 0;
    for (const TileImage& t : tiles) {
      const RgbError e = rgb_error(t, round_trip(t, q));
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

TEST(EncodeTile, RejectsMalformedImagesLevelsAndCodecs) {
  TileImage short_image = solid(8, 8, 0, 0, 0);
  short_image.pixels.pop_back();
  TileImage bc1_input = solid(8, 8, 0, 0, 0);
  bc1_input.format = PixelFormat::bc1;
  for (CodecId codec : {CodecId::lossless, CodecId::bc1}) {
    for (const TileImage& img : {short_image, TileImage{}, bc1_input})
      EXPECT_EQ(encode_tile(img, codec).error().code, ErrorCode::invalid_argument)
          << codec_name(codec);
    EncodeOptions o;
    o.zstd_level = 99;
    EXPECT_EQ(encode_tile(solid(4, 4, 0, 0, 0), codec, o).error().code, ErrorCode::invalid_argument)
        << codec_name(codec);
  }
  auto unknown = encode_tile(solid(4, 4, 0, 0, 0), static_cast<CodecId>(7));
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().code, ErrorCode::invalid_argument);
}

TEST(EncodeTile, LosslessIsProtocolsEncoderWithTheSameOptions) {
  TileImage img = solid(40, 24, 0, 0, 0);
  std::mt19937 rng{3};
  for (std::size_t i = 0; i < img.pixels.size(); ++i)
    img.pixels[i] = std::uint8_t(i / 4 % 40 * 5 + (rng() & 3));
  for (FilterChoice f : {FilterChoice::none, FilterChoice::gradient, FilterChoice::automatic}) {
    EncodeOptions o;
    o.zstd_level = 7;
    o.filter = f;
    o.bc1 = Bc1Quality::best;  // ignored by lossless
    auto p = encode_tile(img, CodecId::lossless, o);
    ASSERT_TRUE(p.ok()) << p.error().to_string();
    EXPECT_EQ(*p, encode_lossless(img, LosslessOptions{7, f}).value());
    EXPECT_EQ(decode_tile(*p).value().pixels, img.pixels);
  }
}

TEST(Bc1Quality, NamesRoundTrip) {
  for (Bc1Quality q : kQualities) EXPECT_EQ(parse_bc1_quality(bc1_quality_name(q)).value(), q);
  for (const char* bad : {"HIGH", "", "fast "}) {
    auto r = parse_bc1_quality(bad);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
  }
}

TEST(EncodeTile, Bc1EncodesConcurrentlyFromManyThreads) {
  std::vector<std::thread> threads;
  std::vector<int> failures(4, 0);
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([t, &failures] {
      std::mt19937 rng{std::uint32_t(t)};
      for (int i = 0; i < 10; ++i) {
        TileImage img = solid(36, 20, 0, 0, 0);
        for (auto& b : img.pixels) b = std::uint8_t(rng() | 0x80);
        const EncodeOptions o = bc1_options(kQualities[i % 3]);
        auto p = encode_tile(img, CodecId::bc1, o);
        auto again = encode_tile(img, CodecId::bc1, o);
        if (!p.ok() || !again.ok() || *p != *again || !decode_tile(*p).ok()) ++failures[t];
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(failures, std::vector<int>(4, 0));
}

// Protocol decodes bc1 without libsquish; its reading of a block must still be libsquish's, to
// the bit: random blocks cover both colour modes and every code, the endpoints chosen so that
// every channel's thirds and halves are reached.
TEST(Bc1Decoder, ReadsEveryBlockAsLibsquishDoes) {
  std::mt19937 rng{11};
  constexpr std::uint32_t kSide = 256;  // 4096 blocks
  TileImage blocks;
  blocks.width = blocks.height = kSide;
  blocks.format = PixelFormat::bc1;
  blocks.pixels.resize(std::size_t(kSide / 4) * (kSide / 4) * 8);
  for (auto& b : blocks.pixels) b = std::uint8_t(rng());
  // A few blocks with equal endpoints (three-colour mode at its edge).
  for (std::size_t k = 0; k < blocks.pixels.size(); k += 8 * 97) {
    blocks.pixels[k + 2] = blocks.pixels[k];
    blocks.pixels[k + 3] = blocks.pixels[k + 1];
  }
  auto ours = bc1_to_rgba8(blocks);
  ASSERT_TRUE(ours.ok()) << ours.error().to_string();
  std::size_t differing = 0;
  for (std::uint32_t by = 0; by < kSide / 4; ++by)
    for (std::uint32_t bx = 0; bx < kSide / 4; ++bx) {
      std::uint8_t want[64];
      squish::Decompress(want, &blocks.pixels[(std::size_t(by) * (kSide / 4) + bx) * 8],
                         squish::kDxt1);
      for (std::uint32_t j = 0; j < 4; ++j)
        differing +=
            std::memcmp(&ours->pixels[((by * 4 + j) * kSide + bx * 4) * 4], want + 16 * j, 16) != 0;
    }
  EXPECT_EQ(differing, 0u);
}

}  // namespace
}  // namespace vts
