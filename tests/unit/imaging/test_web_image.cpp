// Standard web images: PNG, WebP and JPEG round trips through the real libraries, their errors,
// and the content of a tile (border cropped, transparent beyond the image's edge).
#include "vts/imaging/web_image.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

namespace {

using vts::PixelFormat;
using vts::TileImage;
using vts::imaging::WebFormat;

// A smooth gradient with a few sharp lines and, optionally, a transparent band: what photos and
// maps look like to a codec.
TileImage sample(std::uint32_t w, std::uint32_t h, bool transparent_band) {
  TileImage img{w, h, PixelFormat::rgba8, std::vector<std::uint8_t>(std::size_t(w) * h * 4)};
  for (std::uint32_t y = 0; y < h; ++y) {
    for (std::uint32_t x = 0; x < w; ++x) {
      std::uint8_t* p = &img.pixels[(std::size_t(y) * w + x) * 4];
      p[0] = std::uint8_t(x * 255 / (w - 1));
      p[1] = std::uint8_t(y * 255 / (h - 1));
      p[2] = (x % 64 == 0 || y % 64 == 0) ? 255 : std::uint8_t(128 + 60 * std::sin(x * 0.05));
      p[3] = transparent_band && y >= h / 2 ? 0 : 255;
    }
  }
  return img;
}

// PSNR of the colour of opaque texels.
double psnr_rgb(const TileImage& a, const TileImage& b) {
  double se = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.pixels.size(); i += 4) {
    if (a.pixels[i + 3] == 0) continue;
    for (int c = 0; c < 3; ++c) {
      const double d = double(a.pixels[i + c]) - double(b.pixels[i + c]);
      se += d * d;
      ++n;
    }
  }
  return n == 0 || se == 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 / (se / double(n)));
}

TileImage round_trip(const TileImage& img, vts::imaging::WebFormat f,
                     const vts::imaging::WebEncodeOptions& o = {}) {
  auto bytes = vts::imaging::encode_web_image(img, f, o);
  EXPECT_TRUE(bytes.ok()) << bytes.error().to_string();
  if (!bytes) return {};
  auto back = vts::imaging::decode_web_image(*bytes);
  EXPECT_TRUE(back.ok()) << back.error().to_string();
  return back ? *back : TileImage{};
}

}  // namespace

TEST(WebImage, PngIsExactWithAndWithoutAlpha) {
  for (bool band : {false, true}) {
    const TileImage img = sample(256, 256, band);
    const TileImage back = round_trip(img, vts::imaging::WebFormat::png);
    EXPECT_EQ(back.width, 256u);
    EXPECT_EQ(back.height, 256u);
    EXPECT_EQ(back.pixels, img.pixels) << "transparent band: " << band;
  }
}

TEST(WebImage, WebpLosslessIsExactAndLossyKeepsAlphaAndColour) {
  vts::imaging::WebEncodeOptions lossless;
  lossless.webp_lossless = true;
  const TileImage opaque = sample(256, 256, false);
  EXPECT_EQ(round_trip(opaque, vts::imaging::WebFormat::webp, lossless).pixels, opaque.pixels);

  const TileImage band = sample(256, 256, true);
  const TileImage back = round_trip(band, vts::imaging::WebFormat::webp);
  ASSERT_EQ(back.pixels.size(), band.pixels.size());
  EXPECT_GT(psnr_rgb(band, back), 27.0);                 // 29 dB measured: 1-texel blue lines
  EXPECT_EQ(back.pixels[3], 255);                        // opaque stays opaque
  EXPECT_EQ(back.pixels[(255 * 256 + 255) * 4 + 3], 0);  // transparent stays transparent
}

TEST(WebImage, JpegKeepsColourAndCompositesTransparencyOverBlack) {
  const TileImage band = sample(256, 256, true);
  const TileImage back = round_trip(band, vts::imaging::WebFormat::jpeg);
  ASSERT_EQ(back.pixels.size(), band.pixels.size());
  EXPECT_GT(psnr_rgb(band, back), 27.0);                          // 29 dB measured (4:2:0 chroma)
  const std::uint8_t* far = &back.pixels[(250 * 256 + 100) * 4];  // inside the transparent band
  EXPECT_LE(far[0] + far[1] + far[2], 12);
  EXPECT_EQ(far[3], 255);
}

TEST(WebImage, QualityTradesBytes) {
  const TileImage img = sample(256, 256, false);
  vts::imaging::WebEncodeOptions low, high;
  low.jpeg_quality = low.webp_quality = 30;
  high.jpeg_quality = high.webp_quality = 95;
  for (vts::imaging::WebFormat f : {vts::imaging::WebFormat::jpeg, vts::imaging::WebFormat::webp}) {
    EXPECT_LT(vts::imaging::encode_web_image(img, f, low)->size(),
              vts::imaging::encode_web_image(img, f, high)->size())
        << vts::imaging::web_format_extension(f);
  }
}

TEST(WebImage, DamagedOrForeignBytesAreCorruptNeverAnImage) {
  const TileImage img = sample(128, 128, false);
  for (vts::imaging::WebFormat f : {vts::imaging::WebFormat::png, vts::imaging::WebFormat::webp,
                                    vts::imaging::WebFormat::jpeg}) {
    auto bytes = vts::imaging::encode_web_image(img, f);
    ASSERT_TRUE(bytes.ok());
    const std::vector<std::uint8_t> half(bytes->begin(), bytes->begin() + bytes->size() / 2);
    auto r = vts::imaging::decode_web_image(half);
    ASSERT_FALSE(r.ok()) << vts::imaging::web_format_extension(f) << " cut in half decoded";
    EXPECT_EQ(r.error().code, vts::ErrorCode::corrupt);
  }
  const std::vector<std::uint8_t> text = {'h', 'e', 'l', 'l', 'o'};
  auto r = vts::imaging::decode_web_image(text);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("not a PNG, WebP or JPEG"), std::string::npos);
  EXPECT_FALSE(vts::imaging::decode_web_image({}).ok());
}

TEST(WebImage, OptionsAndFormatsAreCheckedByName) {
  vts::imaging::WebEncodeOptions o;
  o.jpeg_quality = 0;
  auto s = vts::imaging::validate(o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("jpeg_quality"), std::string::npos);
  o = {};
  o.png_level = 10;
  EXPECT_FALSE(
      vts::imaging::encode_web_image(sample(8, 8, false), vts::imaging::WebFormat::png, o).ok());
  EXPECT_FALSE(vts::imaging::encode_web_image(TileImage{}, vts::imaging::WebFormat::png).ok());

  EXPECT_EQ(*vts::imaging::parse_web_format("JPEG"), vts::imaging::WebFormat::jpeg);
  EXPECT_EQ(*vts::imaging::parse_web_format("jpg"), vts::imaging::WebFormat::jpeg);
  EXPECT_EQ(*vts::imaging::parse_web_format("webp"), vts::imaging::WebFormat::webp);
  auto bad = vts::imaging::parse_web_format("gif");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("png, webp, jpg"), std::string::npos);
  EXPECT_EQ(vts::imaging::web_format_content_type(vts::imaging::WebFormat::webp), "image/webp");
  EXPECT_EQ(vts::imaging::web_format_extension(vts::imaging::WebFormat::jpeg), "jpg");
}

TEST(WebImage, TileContentCropsTheBorderAndIsTransparentBeyondTheEdge) {
  // 600 x 300 texels, T = 256, B = 4: level 2 is 600 x 300, tiles 3 x 2; tile (2, 2, 1) holds
  // 88 x 44 texels of image.
  auto g = vts::Geometry::create(600, 300, 256, 4);
  ASSERT_TRUE(g.ok()) << g.error().to_string();
  const std::uint32_t s = g->stored_size();
  TileImage stored{s, s, PixelFormat::rgba8, std::vector<std::uint8_t>(std::size_t(s) * s * 4)};
  for (std::uint32_t y = 0; y < s; ++y)
    for (std::uint32_t x = 0; x < s; ++x) {
      std::uint8_t* p = &stored.pixels[(std::size_t(y) * s + x) * 4];
      p[0] = std::uint8_t(x), p[1] = std::uint8_t(y), p[2] = 7, p[3] = 255;
    }
  auto interior = vts::imaging::tile_content(stored, *g, vts::TileId{2, 0, 0});
  ASSERT_TRUE(interior.ok()) << interior.error().to_string();
  EXPECT_EQ(interior->width, 256u);
  EXPECT_EQ(interior->pixels[0], 4);  // stored texel (4, 4): the border is cropped
  EXPECT_EQ(interior->pixels[1], 4);
  EXPECT_EQ(interior->pixels[(255 * 256 + 255) * 4 + 3], 255);

  auto edge = vts::imaging::tile_content(stored, *g, vts::TileId{2, 2, 1});
  ASSERT_TRUE(edge.ok());
  const auto at = [&](std::uint32_t x, std::uint32_t y) {
    return &edge->pixels[(y * 256 + x) * 4];
  };
  EXPECT_EQ(at(87, 43)[3], 255);
  EXPECT_EQ(at(87, 43)[0], 87 + 4);
  EXPECT_EQ(at(88, 43)[3], 0);  // beyond the image's right edge
  EXPECT_EQ(at(87, 44)[3], 0);  // below its bottom edge
  EXPECT_EQ(at(255, 255)[0] + at(255, 255)[3], 0);

  EXPECT_FALSE(vts::imaging::tile_content(stored, *g, vts::TileId{2, 3, 0}).ok());  // no such tile
  TileImage small{8, 8, PixelFormat::rgba8, std::vector<std::uint8_t>(8 * 8 * 4)};
  EXPECT_FALSE(vts::imaging::tile_content(small, *g, vts::TileId{0, 0, 0}).ok());
}
