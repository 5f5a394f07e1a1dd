// The PNG writer over libdeflate (imaging/src/png_writer.cpp), seen from outside: every filter,
// level and channel count decodes back through libpng (which checks every CRC and inflates with
// zlib) to the same texels, the chunks are the ones promised, the filter asked for is the one
// written, and the levels trade bytes for time in the public order.
#include <gtest/gtest.h>
#include <libdeflate.h>

#include <cstdint>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "vts/imaging/web_image.hpp"
#include "vts/test/temp_dir.hpp"

namespace {

using vts::PixelFormat;
using vts::TileImage;
using vts::imaging::PngFilter;
using vts::imaging::WebEncodeOptions;
using vts::imaging::WebFormat;

constexpr PngFilter kFilters[] = {PngFilter::none,    PngFilter::sub,   PngFilter::up,
                                  PngFilter::average, PngFilter::paeth, PngFilter::adaptive};

// Noise over a gradient (every Paeth branch and every byte wrap-around is taken), opaque unless
// `alpha`, then with alpha varying too.
TileImage noisy(std::uint32_t w, std::uint32_t h, bool alpha) {
  TileImage img{w, h, PixelFormat::rgba8, std::vector<std::uint8_t>(std::size_t(w) * h * 4)};
  std::uint32_t state = 12345;
  for (std::size_t i = 0; i < img.pixels.size(); ++i) {
    state = state * 1664525u + 1013904223u;
    const std::size_t texel = i / 4;
    const auto ramp = std::uint8_t((texel % w) * 3 + (texel / w) * 5);
    const auto noise = std::uint8_t(state >> 29);  // 0..7
    img.pixels[i] = i % 4 == 3 ? (alpha ? std::uint8_t(state >> 24) : 255)
                               : std::uint8_t(ramp + noise + (i % 4) * 40);
  }
  return img;
}

std::uint32_t be32(const std::uint8_t* p) {
  return std::uint32_t(p[0]) << 24 | std::uint32_t(p[1]) << 16 | std::uint32_t(p[2]) << 8 | p[3];
}

struct Chunk {
  std::string type;
  std::vector<std::uint8_t> data;
};

// The chunks after the signature (lengths trusted: the bytes were decoded by libpng first).
std::vector<Chunk> chunks(const std::vector<std::uint8_t>& png) {
  std::vector<Chunk> out;
  for (std::size_t at = 8; at + 12 <= png.size();) {
    const std::uint32_t n = be32(&png[at]);
    out.push_back(
        {std::string(png.begin() + long(at) + 4, png.begin() + long(at) + 8),
         std::vector<std::uint8_t>(png.begin() + long(at) + 8, png.begin() + long(at) + 8 + n)});
    at += 12 + n;
  }
  return out;
}

std::vector<std::uint8_t> encode(const TileImage& img, int level, PngFilter filter) {
  WebEncodeOptions o;
  o.png_level = level;
  o.png_filter = filter;
  auto bytes = vts::imaging::encode_web_image(img, WebFormat::png, o);
  EXPECT_TRUE(bytes.ok()) << bytes.error().to_string();
  return bytes ? *bytes : std::vector<std::uint8_t>{};
}

}  // namespace

TEST(PngWriter, EveryFilterLevelAndSizeDecodesBackExactlyThroughLibpng) {
  for (const auto& [w, h] : {std::pair{1u, 1u}, {3u, 7u}, {257u, 5u}, {256u, 256u}}) {
    for (bool alpha : {false, true}) {
      const TileImage img = noisy(w, h, alpha);
      for (PngFilter f : kFilters) {
        for (int level : {0, 1, 4, 6, 9}) {
          auto back = vts::imaging::decode_web_image(encode(img, level, f));
          ASSERT_TRUE(back.ok()) << back.error().to_string();
          EXPECT_EQ(back->width, w);
          EXPECT_EQ(back->height, h);
          EXPECT_EQ(back->pixels, img.pixels)
              << w << "x" << h << " alpha " << alpha << " filter " << int(f) << " level " << level;
        }
      }
    }
  }
}

TEST(PngWriter, WritesTheChunksPromisedAndTheFilterAskedFor) {
  const TileImage img = noisy(64, 32, false);
  for (PngFilter f :
       {PngFilter::none, PngFilter::sub, PngFilter::up, PngFilter::average, PngFilter::paeth}) {
    const std::vector<std::uint8_t> png = encode(img, 4, f);
    ASSERT_TRUE(vts::imaging::decode_web_image(png).ok());
    const std::vector<Chunk> c = chunks(png);
    ASSERT_EQ(c.size(), 3u);  // a web tile carries no sRGB chunk, as before
    EXPECT_EQ(c[0].type, "IHDR");
    ASSERT_EQ(c[0].data.size(), 13u);
    EXPECT_EQ(be32(&c[0].data[0]), 64u);
    EXPECT_EQ(be32(&c[0].data[4]), 32u);
    EXPECT_EQ(c[0].data[8], 8);  // bit depth
    EXPECT_EQ(c[0].data[9], 2);  // RGB: the image is opaque
    EXPECT_EQ(c[1].type, "IDAT");
    EXPECT_EQ(c[2].type, "IEND");
    // Inflated, every row starts with the filter asked for.
    std::vector<std::uint8_t> rows((64 * 3 + 1) * 32);
    libdeflate_decompressor* d = libdeflate_alloc_decompressor();
    ASSERT_NE(d, nullptr);
    const auto r = libdeflate_zlib_decompress(d, c[1].data.data(), c[1].data.size(), rows.data(),
                                              rows.size(), nullptr);
    libdeflate_free_decompressor(d);
    ASSERT_EQ(r, LIBDEFLATE_SUCCESS);
    for (std::size_t y = 0; y < 32; ++y) EXPECT_EQ(rows[y * (64 * 3 + 1)], int(f)) << "row " << y;
  }
}

TEST(PngWriter, HigherLevelsAreNeverLargerAndFiltersHelpNaturalImages) {
  const TileImage img = noisy(256, 256, false);
  const std::size_t stored = encode(img, 0, PngFilter::average).size();
  const std::size_t fast = encode(img, 1, PngFilter::average).size();
  const std::size_t dflt = encode(img, 4, PngFilter::average).size();
  const std::size_t small = encode(img, 9, PngFilter::average).size();
  EXPECT_GT(stored, 256u * 256 * 3);  // stored blocks: the rows and their headers
  EXPECT_LT(fast, stored);
  EXPECT_LE(dflt, fast);
  EXPECT_LE(small, dflt);
  EXPECT_LT(encode(img, 4, PngFilter::average).size(), encode(img, 4, PngFilter::none).size());
}

TEST(PngWriter, WritePngFilesAreTaggedSrgbAndKeepOrDropAlpha) {
  vts::test::TempDir dir("vts-png-writer");
  const TileImage img = noisy(40, 30, true);
  for (int channels : {3, 4}) {
    const auto path = dir / ("out" + std::to_string(channels) + ".png");
    ASSERT_TRUE(vts::imaging::write_png(path, 40, 30, img.pixels, 6, channels).ok());
    std::ifstream in(path, std::ios::binary);
    const std::vector<std::uint8_t> png{std::istreambuf_iterator<char>(in), {}};
    auto back = vts::imaging::decode_web_image(png);
    ASSERT_TRUE(back.ok()) << back.error().to_string();
    const std::vector<Chunk> c = chunks(png);
    ASSERT_EQ(c.size(), 4u);
    EXPECT_EQ(c[0].data[9], channels == 4 ? 6 : 2);  // colour type RGBA or RGB
    EXPECT_EQ(c[1].type, "sRGB");
    EXPECT_EQ(c[1].data, std::vector<std::uint8_t>{0});  // perceptual, as libpng wrote it
    for (std::size_t i = 0; i < img.pixels.size(); ++i) {
      const std::uint8_t want = channels == 3 && i % 4 == 3 ? 255 : img.pixels[i];
      ASSERT_EQ(back->pixels[i], want) << "byte " << i << ", " << channels << " channels";
    }
  }
}
