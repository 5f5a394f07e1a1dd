// Tile payload framing and the lossless codec: exact round trips, the documented byte layout,
// and hostile payloads (flipped bytes, every truncation, lying header fields) that must come back
// as distinct errors, never as a crash.
#include <gtest/gtest.h>
#include <xxhash.h>
#include <zstd.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <random>
#include <thread>
#include <vector>

#include "codec_internal.hpp"  // the codec's private entry points (protocol/src)
#include "vts/protocol/codec.hpp"

namespace vts {
namespace {

using Bytes = std::vector<std::uint8_t>;

TileImage make_image(std::uint32_t w, std::uint32_t h) {
  TileImage img;
  img.width = w;
  img.height = h;
  img.pixels.resize(std::size_t(w) * h * 4);
  return img;
}

TileImage random_image(std::uint32_t w, std::uint32_t h, std::uint32_t seed = 1) {
  TileImage img = make_image(w, h);
  std::mt19937 rng(seed);
  for (auto& b : img.pixels) b = static_cast<std::uint8_t>(rng());
  return img;
}

// Smooth, continuous-tone content with a little noise: what photographs look like to a filter.
TileImage smooth_image(std::uint32_t w, std::uint32_t h, std::uint32_t seed = 2) {
  TileImage img = make_image(w, h);
  std::mt19937 rng(seed);
  for (std::uint32_t y = 0; y < h; ++y)
    for (std::uint32_t x = 0; x < w; ++x) {
      std::uint8_t* p = &img.pixels[(std::size_t(y) * w + x) * 4];
      p[0] = static_cast<std::uint8_t>((x * 3 + y) / 2 + rng() % 3);
      p[1] = static_cast<std::uint8_t>((x + y * 2) / 3 + rng() % 3);
      p[2] = static_cast<std::uint8_t>(200 - (x + y) / 4 + rng() % 2);
      p[3] = static_cast<std::uint8_t>(255 - (y & 7));
    }
  return img;
}

TileImage flat_image(std::uint32_t w, std::uint32_t h) {
  TileImage img = make_image(w, h);
  for (std::size_t i = 0; i < img.pixels.size(); i += 4) {
    img.pixels[i] = 10;
    img.pixels[i + 1] = 200;
    img.pixels[i + 2] = 255;
    img.pixels[i + 3] = 255;
  }
  return img;
}

// Random dither of four colours: few colours, no smoothness — raw texels compress better.
TileImage dithered_image(std::uint32_t w, std::uint32_t h) {
  static const std::uint8_t kColours[4][4] = {
      {255, 0, 0, 255}, {0, 255, 0, 255}, {0, 0, 255, 255}, {255, 255, 255, 0}};
  TileImage img = make_image(w, h);
  std::mt19937 rng(3);
  for (std::size_t i = 0; i < img.pixels.size(); i += 4)
    std::memcpy(&img.pixels[i], kColours[rng() % 4], 4);
  return img;
}

Bytes encode(const TileImage& img, FilterChoice filter, int level = 3) {
  auto r = encode_lossless(img, LosslessOptions{level, filter});
  EXPECT_TRUE(r.ok()) << r.error().to_string();
  return r.ok() ? std::move(r).value() : Bytes{};
}

std::uint32_t load_u32(const std::uint8_t* p) {
  return std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 |
         std::uint32_t(p[3]) << 24;
}
void store_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
std::uint64_t load_u64(const std::uint8_t* p) {
  return std::uint64_t(load_u32(p)) | std::uint64_t(load_u32(p + 4)) << 32;
}
void store_u64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// Rewrites the header checksum to match the body, so a test reaches the checks behind it.
void resign(Bytes& payload) {
  store_u64(payload.data() + 24, XXH3_64bits(payload.data() + TileHeader::kFrameBytes,
                                             payload.size() - TileHeader::kFrameBytes));
}

std::span<const std::uint8_t> body_of(const Bytes& payload) {
  return std::span<const std::uint8_t>(payload).subspan(TileHeader::kFrameBytes);
}

// The documented predictor, written as plainly as possible.
Bytes reference_gradient(const TileImage& img) {
  const std::uint32_t w = img.width, h = img.height;
  Bytes planes(img.pixels.size());
  auto at = [&](std::int64_t x, std::int64_t y, int c) -> int {
    if (x < 0 || y < 0) return 0;
    return img.pixels[(std::size_t(y) * w + std::size_t(x)) * 4 + c];
  };
  for (int c = 0; c < 4; ++c)
    for (std::int64_t y = 0; y < h; ++y)
      for (std::int64_t x = 0; x < w; ++x) {
        const int pred =
            std::clamp(at(x - 1, y, c) + at(x, y - 1, c) - at(x - 1, y - 1, c), 0, 255);
        planes[std::size_t(c) * w * h + std::size_t(y) * w + std::size_t(x)] =
            static_cast<std::uint8_t>(at(x, y, c) - pred);
      }
  return planes;
}

struct Size {
  std::uint32_t w, h;
};
const Size kSizes[] = {{1, 1},  {1, 9},   {9, 1},   {3, 5},     {16, 16},   {17, 3},
                       {18, 2}, {33, 33}, {47, 31}, {264, 264}, {255, 257}, {1000, 1}};

TEST(GradientFilter, MatchesTheDocumentedPredictorAtEveryWidth) {
  // Widths around the 16-texel vector step exercise the SIMD body, the scalar tail and both.
  for (std::uint32_t w = 1; w <= 70; ++w) {
    for (std::uint32_t h : {1u, 2u, 5u}) {
      const TileImage img = random_image(w, h, w * 7 + h);
      Bytes planes(img.pixels.size());
      detail::gradient_filter(img.pixels.data(), w, h, planes.data());
      ASSERT_EQ(planes, reference_gradient(img)) << w << "x" << h;
      Bytes back(img.pixels.size());
      detail::gradient_unfilter(planes.data(), w, h, back.data());
      ASSERT_EQ(back, img.pixels) << w << "x" << h;
    }
  }
}

TEST(GradientFilter, HandlesClampingAtBothEnds) {
  // Alternating 0/255 drives left + up - upleft to -255 and 510.
  TileImage img = make_image(40, 40);
  for (std::uint32_t y = 0; y < 40; ++y)
    for (std::uint32_t x = 0; x < 40; ++x)
      for (int c = 0; c < 4; ++c) img.pixels[(y * 40 + x) * 4 + c] = ((x + y + c) % 2) ? 255 : 0;
  Bytes planes(img.pixels.size()), back(img.pixels.size());
  detail::gradient_filter(img.pixels.data(), 40, 40, planes.data());
  EXPECT_EQ(planes, reference_gradient(img));
  detail::gradient_unfilter(planes.data(), 40, 40, back.data());
  EXPECT_EQ(back, img.pixels);
}

// The documented inverse, written as plainly as possible: texel = residual + pred (mod 256).
Bytes reference_unfilter(const Bytes& planes, std::uint32_t w, std::uint32_t h) {
  Bytes rgba(planes.size());
  auto at = [&](std::int64_t x, std::int64_t y, int c) -> int {
    if (x < 0 || y < 0) return 0;
    return rgba[(std::size_t(y) * w + std::size_t(x)) * 4 + c];
  };
  for (std::int64_t y = 0; y < h; ++y)
    for (std::int64_t x = 0; x < w; ++x)
      for (int c = 0; c < 4; ++c) {
        const int pred =
            std::clamp(at(x - 1, y, c) + at(x, y - 1, c) - at(x - 1, y - 1, c), 0, 255);
        rgba[(std::size_t(y) * w + std::size_t(x)) * 4 + c] = static_cast<std::uint8_t>(
            planes[std::size_t(c) * w * h + std::size_t(y) * w + std::size_t(x)] + pred);
      }
  return rgba;
}

TEST(GradientFilter, UnfiltersArbitraryResidualsLikeTheDocumentedInverse) {
  // Random residuals (no filtered image makes them) put every left/up/upleft combination and
  // both clamps on the unfilter's paths: the row pairs, a last odd row, the scalar tails.
  std::mt19937 rng(11);
  std::vector<Size> sizes;
  for (std::uint32_t w = 1; w <= 70; ++w)
    for (std::uint32_t h : {1u, 2u, 3u, 4u, 7u}) sizes.push_back({w, h});
  for (Size s : {Size{264, 264}, Size{255, 257}, Size{1000, 3}}) sizes.push_back(s);
  for (const Size s : sizes) {
    Bytes planes(std::size_t(s.w) * s.h * 4);
    for (auto& b : planes) b = static_cast<std::uint8_t>(rng() % 4 == 0 ? 0 : rng());
    Bytes back(planes.size());
    detail::gradient_unfilter(planes.data(), s.w, s.h, back.data());
    ASSERT_EQ(back, reference_unfilter(planes, s.w, s.h)) << s.w << "x" << s.h;
  }
}

TEST(LosslessCodec, RoundTripsEveryFilterExactly) {
  for (const Size s : kSizes) {
    const TileImage images[] = {random_image(s.w, s.h), smooth_image(s.w, s.h),
                                flat_image(s.w, s.h), dithered_image(s.w, s.h)};
    for (const TileImage& img : images)
      for (FilterChoice f : {FilterChoice::none, FilterChoice::gradient, FilterChoice::automatic}) {
        const Bytes payload = encode(img, f);
        auto decoded = decode_tile(payload);
        ASSERT_TRUE(decoded.ok()) << decoded.error().to_string();
        EXPECT_EQ(decoded->width, s.w);
        EXPECT_EQ(decoded->height, s.h);
        EXPECT_EQ(decoded->format, PixelFormat::rgba8);
        ASSERT_EQ(decoded->pixels, img.pixels) << s.w << "x" << s.h << " filter " << int(f);
      }
  }
}

TEST(LosslessCodec, RoundTripsAtEveryZstdLevelItAccepts) {
  const TileImage img = smooth_image(40, 24);
  for (int level : {ZSTD_minCLevel(), -5, 0, 1, 3, 9, 19, ZSTD_maxCLevel()}) {
    const Bytes payload = encode(img, FilterChoice::automatic, level);
    auto decoded = decode_tile(payload);
    ASSERT_TRUE(decoded.ok()) << "level " << level;
    EXPECT_EQ(decoded->pixels, img.pixels);
  }
}

TEST(LosslessCodec, HeaderRecordsTheFilterItUsed) {
  const TileImage img = smooth_image(32, 32);
  EXPECT_EQ(parse_tile_header(encode(img, FilterChoice::none))->filter, Filter::none);
  EXPECT_EQ(parse_tile_header(encode(img, FilterChoice::gradient))->filter, Filter::gradient);
}

TEST(LosslessCodec, AutomaticKeepsTheSmallerPayload) {
  for (const TileImage& img : {smooth_image(264, 264), dithered_image(264, 264),
                               flat_image(264, 264), random_image(64, 64)}) {
    const std::size_t none = encode(img, FilterChoice::none).size();
    const std::size_t gradient = encode(img, FilterChoice::gradient).size();
    EXPECT_EQ(encode(img, FilterChoice::automatic).size(), std::min(none, gradient));
  }
}

TEST(LosslessCodec, AutomaticUsesGradientForContinuousToneAndRawForDither) {
  // The two cases the heuristic is built on; if either flips, the heuristic needs re-measuring.
  EXPECT_EQ(parse_tile_header(encode(smooth_image(264, 264), FilterChoice::automatic))->filter,
            Filter::gradient);
  EXPECT_EQ(parse_tile_header(encode(dithered_image(264, 264), FilterChoice::automatic))->filter,
            Filter::none);
}

TEST(LosslessCodec, HeaderFrameHasTheDocumentedLayout) {
  const TileImage img = smooth_image(37, 21);
  const Bytes p = encode(img, FilterChoice::gradient);
  ASSERT_GT(p.size(), 40u);
  EXPECT_EQ(load_u32(&p[0]), 0x184D2A5Au);
  EXPECT_EQ(load_u32(&p[4]), 32u);
  EXPECT_EQ(p[8], 1);   // version
  EXPECT_EQ(p[9], 0);   // codec lossless
  EXPECT_EQ(p[10], 1);  // filter gradient
  EXPECT_EQ(p[11], 0);  // rgba8
  EXPECT_EQ(load_u32(&p[12]), 37u);
  EXPECT_EQ(load_u32(&p[16]), 21u);
  EXPECT_EQ(load_u32(&p[20]), 37u * 21u * 4u);
  EXPECT_EQ(load_u64(&p[24]), XXH3_64bits(p.data() + 40, p.size() - 40));
  EXPECT_EQ(load_u64(&p[32]), 0u);

  auto h = parse_tile_header(p);
  ASSERT_TRUE(h.ok());
  EXPECT_EQ(h->version, 1);
  EXPECT_EQ(h->codec, CodecId::lossless);
  EXPECT_EQ(h->format, PixelFormat::rgba8);
  EXPECT_EQ(h->width, 37u);
  EXPECT_EQ(h->height, 21u);
  EXPECT_EQ(h->body_size, 37u * 21u * 4u);
  EXPECT_EQ(h->checksum, load_u64(&p[24]));
  EXPECT_TRUE(verify_tile(p).ok());
}

TEST(LosslessCodec, PayloadIsAPlainZstdStreamOfTheBody) {
  // Generic zstd tools skip the header frame and decompress the body: the archive may declare
  // tile_compression = zstd truthfully.
  const TileImage img = smooth_image(50, 30);
  for (FilterChoice f : {FilterChoice::none, FilterChoice::gradient}) {
    const Bytes p = encode(img, f);
    EXPECT_EQ(ZSTD_getFrameContentSize(p.data() + 40, p.size() - 40), img.pixels.size());
    Bytes body(img.pixels.size() + 16);
    const std::size_t n = ZSTD_decompress(body.data(), body.size(), p.data(), p.size());
    ASSERT_FALSE(ZSTD_isError(n)) << ZSTD_getErrorName(n);
    body.resize(n);
    EXPECT_EQ(body, f == FilterChoice::none ? img.pixels : reference_gradient(img));
  }
}

TEST(LosslessCodec, EncodeRejectsMalformedImages) {
  TileImage wrong_size = smooth_image(8, 8);
  wrong_size.pixels.pop_back();
  TileImage empty = make_image(0, 8);
  TileImage huge;
  huge.width = TileHeader::kMaxDimension + 1;
  huge.height = 1;
  huge.pixels.resize(std::size_t(huge.width) * 4);
  TileImage bc1 = smooth_image(8, 8);
  bc1.format = PixelFormat::bc1;
  for (const TileImage* img : {&wrong_size, &empty, &huge, &bc1}) {
    auto r = encode_lossless(*img);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::invalid_argument) << r.error().to_string();
  }
  auto bad_level = encode_lossless(smooth_image(8, 8), LosslessOptions{ZSTD_maxCLevel() + 1});
  ASSERT_FALSE(bad_level.ok());
  EXPECT_EQ(bad_level.error().code, ErrorCode::invalid_argument);
}

TEST(PackTile, FramesAnUnfilteredBodyAsTheLosslessEncoderDoes) {
  // The framing an encoder outside this library (the builder's bc1) relies on: the same header,
  // checksum and zstd frame as the lossless encoder's own, byte for byte.
  const TileImage img = smooth_image(33, 17);
  auto packed = pack_tile(CodecId::lossless, 33, 17, img.pixels, 5);
  ASSERT_TRUE(packed.ok()) << packed.error().to_string();
  EXPECT_EQ(*packed, encode(img, FilterChoice::none, 5));
  EXPECT_EQ(packed->capacity(), packed->size());
  auto d = decode_tile(*packed);
  ASSERT_TRUE(d.ok()) << d.error().to_string();
  EXPECT_EQ(d->pixels, img.pixels);
}

TEST(PackTile, RejectsWhatNoTileCouldHold) {
  const Bytes rgba(8 * 8 * 4, 7), blocks(2 * 2 * 8, 7);
  struct Case {
    CodecId codec;
    std::uint32_t w, h;
    const Bytes* body;
    int level;
    const char* says;
  };
  const Case cases[] = {
      {static_cast<CodecId>(9), 8, 8, &rgba, 3, "unknown codec 9"},
      {CodecId::lossless, 0, 8, &rgba, 3, "outside 1.."},
      {CodecId::bc1, TileHeader::kMaxDimension + 4, 8, &blocks, 3, "outside 1.."},
      {CodecId::lossless, 8, 8, &blocks, 3, "needs 256 bytes, has 32"},
      {CodecId::bc1, 8, 8, &rgba, 3, "needs 32 bytes, has 256"},
      {CodecId::bc1, 8, 8, &blocks, ZSTD_maxCLevel() + 1, "zstd level"},
  };
  for (const Case& c : cases) {
    auto r = pack_tile(c.codec, c.w, c.h, *c.body, c.level);
    ASSERT_FALSE(r.ok()) << c.says;
    EXPECT_EQ(r.error().code, ErrorCode::invalid_argument) << r.error().to_string();
    EXPECT_NE(r.error().message.find(c.says), std::string::npos) << r.error().message;
  }
}

TEST(LosslessCodec, AnyFlippedBodyByteFailsTheChecksum) {
  const Bytes good = encode(smooth_image(24, 24), FilterChoice::gradient);
  for (std::size_t i = TileHeader::kFrameBytes; i < good.size(); ++i) {
    for (std::uint8_t mask : {0x01, 0x80, 0xFF}) {
      Bytes bad = good;
      bad[i] ^= mask;
      auto v = verify_tile(bad);
      ASSERT_FALSE(v.ok()) << i;
      ASSERT_EQ(v.error().code, ErrorCode::checksum) << i << ": " << v.error().to_string();
      auto d = decode_tile(bad);
      ASSERT_FALSE(d.ok());
      ASSERT_EQ(d.error().code, ErrorCode::checksum);
    }
  }
}

TEST(LosslessCodec, ChecksumErrorNamesExpectedAndActualHashes) {
  Bytes bad = encode(smooth_image(8, 8), FilterChoice::none);
  bad.back() ^= 1;
  auto v = verify_tile(bad);
  ASSERT_FALSE(v.ok());
  char expected[32];
  std::snprintf(expected, sizeof expected, "0x%016llx",
                static_cast<unsigned long long>(load_u64(&bad[24])));
  EXPECT_NE(v.error().message.find(expected), std::string::npos) << v.error().message;
  EXPECT_NE(v.error().message.find("body hashes to 0x"), std::string::npos);
}

TEST(LosslessCodec, EveryTruncationIsAnErrorNotACrash) {
  for (FilterChoice f : {FilterChoice::none, FilterChoice::gradient}) {
    const Bytes good = encode(smooth_image(33, 17), f);
    for (std::size_t len = 0; len < good.size(); ++len) {
      const std::span<const std::uint8_t> prefix(good.data(), len);
      auto d = decode_tile(prefix);
      ASSERT_FALSE(d.ok()) << len;
      // The header must be whole; past it only the checksum can tell (see verify_tile).
      const ErrorCode want =
          len <= TileHeader::kFrameBytes ? ErrorCode::truncated : ErrorCode::checksum;
      ASSERT_EQ(d.error().code, want) << len << ": " << d.error().to_string();
      ASSERT_FALSE(verify_tile(prefix).ok());
      if (len < TileHeader::kFrameBytes) {
        auto h = parse_tile_header(prefix);
        ASSERT_FALSE(h.ok());
        ASSERT_EQ(h.error().code, ErrorCode::truncated);
      }
    }
  }
}

TEST(LosslessCodec, EveryTruncatedBodyIsReportedAsTruncatedBehindTheChecksum) {
  const Bytes good = encode(smooth_image(100, 60), FilterChoice::gradient);
  const TileHeader header = parse_tile_header(good).value();
  const auto body = body_of(good);
  for (std::size_t len = 0; len < body.size(); ++len) {
    auto d = detail::decode_lossless_body(header, body.first(len));
    ASSERT_FALSE(d.ok()) << len;
    ASSERT_EQ(d.error().code, ErrorCode::truncated) << len << ": " << d.error().to_string();
  }
  ASSERT_TRUE(detail::decode_lossless_body(header, body).ok());
}

TEST(LosslessCodec, TrailingBytesAfterTheBodyFrameAreCorrupt) {
  Bytes p = encode(smooth_image(16, 16), FilterChoice::none);
  p.push_back(0);
  auto unsigned_trailer = decode_tile(p);
  ASSERT_FALSE(unsigned_trailer.ok());
  EXPECT_EQ(unsigned_trailer.error().code, ErrorCode::checksum);
  resign(p);  // a writer that hashed its garbage too
  auto v = verify_tile(p);
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.error().code, ErrorCode::corrupt) << v.error().to_string();
  auto d = decode_tile(p);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().code, ErrorCode::corrupt);
  // A second frame appended is trailing data as well.
  Bytes twice = encode(smooth_image(16, 16), FilterChoice::none);
  const Bytes body(twice.begin() + TileHeader::kFrameBytes, twice.end());
  twice.insert(twice.end(), body.begin(), body.end());
  resign(twice);
  EXPECT_EQ(decode_tile(twice).error().code, ErrorCode::corrupt);
}

TEST(LosslessCodec, HostileHeaderFieldsAreRejectedWithDistinctCodes) {
  const Bytes good = encode(smooth_image(16, 8), FilterChoice::gradient);
  struct Case {
    const char* what;
    void (*mutate)(Bytes&);
    ErrorCode code;
  };
  const Case cases[] = {
      {"bad magic", [](Bytes& p) { p[0] ^= 1; }, ErrorCode::corrupt},
      {"frame size 31", [](Bytes& p) { store_u32(&p[4], 31); }, ErrorCode::corrupt},
      {"frame size huge", [](Bytes& p) { store_u32(&p[4], 0xFFFFFFFF); }, ErrorCode::corrupt},
      {"version 0", [](Bytes& p) { p[8] = 0; }, ErrorCode::unsupported},
      {"version 2", [](Bytes& p) { p[8] = 2; }, ErrorCode::unsupported},
      {"unknown codec", [](Bytes& p) { p[9] = 7; }, ErrorCode::unsupported},
      {"unknown filter", [](Bytes& p) { p[10] = 2; }, ErrorCode::unsupported},
      {"unknown pixel format", [](Bytes& p) { p[11] = 9; }, ErrorCode::unsupported},
      {"lossless with bc1 texels", [](Bytes& p) { p[11] = 1; }, ErrorCode::corrupt},
      {"zero width", [](Bytes& p) { store_u32(&p[12], 0); }, ErrorCode::corrupt},
      {"zero height", [](Bytes& p) { store_u32(&p[16], 0); }, ErrorCode::corrupt},
      {"huge width", [](Bytes& p) { store_u32(&p[12], 0xFFFFFFFF); }, ErrorCode::too_large},
      {"height past the limit", [](Bytes& p) { store_u32(&p[16], TileHeader::kMaxDimension + 1); },
       ErrorCode::too_large},
      {"width disagrees with body_size", [](Bytes& p) { store_u32(&p[12], 17); },
       ErrorCode::corrupt},
      {"body_size off by one", [](Bytes& p) { store_u32(&p[20], 16 * 8 * 4 + 1); },
       ErrorCode::corrupt},
      {"body_size huge", [](Bytes& p) { store_u32(&p[20], 0xFFFFFFFF); }, ErrorCode::corrupt},
  };
  for (const Case& c : cases) {
    Bytes bad = good;
    c.mutate(bad);
    auto h = parse_tile_header(bad);
    ASSERT_FALSE(h.ok()) << c.what;
    EXPECT_EQ(h.error().code, c.code) << c.what << ": " << h.error().to_string();
    auto d = decode_tile(bad);
    ASSERT_FALSE(d.ok()) << c.what;
    EXPECT_EQ(d.error().code, c.code) << c.what;
  }
  for (int i = 32; i < 40; ++i) {
    Bytes bad = good;
    bad[i] = 1;
    auto h = parse_tile_header(bad);
    ASSERT_FALSE(h.ok());
    EXPECT_EQ(h.error().code, ErrorCode::corrupt) << "reserved byte " << i;
  }
}

TEST(LosslessCodec, HeaderThatDisagreesWithTheBodyFrameIsCorrupt) {
  // A validly signed payload whose header says 8x8 but whose body is the 8x9 frame.
  const Bytes small = encode(smooth_image(8, 8), FilterChoice::none);
  const Bytes tall = encode(smooth_image(8, 9), FilterChoice::none);
  Bytes spliced(small.begin(), small.begin() + TileHeader::kFrameBytes);
  spliced.insert(spliced.end(), tall.begin() + TileHeader::kFrameBytes, tall.end());
  resign(spliced);
  auto d = decode_tile(spliced);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().code, ErrorCode::corrupt) << d.error().to_string();
}

TEST(LosslessCodec, BodyFrameWithoutContentSizeIsCorrupt) {
  const TileImage img = smooth_image(8, 8);
  Bytes p = encode(img, FilterChoice::none);
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 0);
  // Streaming compression without a pledged size cannot write the content size.
  Bytes frame(ZSTD_compressBound(img.pixels.size()));
  ZSTD_inBuffer in{img.pixels.data(), img.pixels.size(), 0};
  ZSTD_outBuffer out{frame.data(), frame.size(), 0};
  ASSERT_EQ(ZSTD_compressStream2(cctx, &out, &in, ZSTD_e_end), 0u);
  ZSTD_freeCCtx(cctx);
  frame.resize(out.pos);
  ASSERT_EQ(ZSTD_getFrameContentSize(frame.data(), frame.size()), ZSTD_CONTENTSIZE_UNKNOWN);
  p.resize(TileHeader::kFrameBytes);
  p.insert(p.end(), frame.begin(), frame.end());
  resign(p);
  auto d = decode_tile(p);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().code, ErrorCode::corrupt) << d.error().to_string();
}

TEST(LosslessCodec, RejectsABodyTooSmallForTheDeclaredSizeBeforeAllocating) {
  // 8192 x 8192 declared (256 MiB), body: a frame that claims that content size but holds a
  // single 128 KiB RLE block. The block walk rejects it without allocating the image.
  const std::uint32_t side = TileHeader::kMaxDimension;
  const std::uint32_t body_size = side * side * 4;
  Bytes body = {0x28, 0xB5, 0x2F, 0xFD,  // zstd magic
                0xA0};                   // descriptor: 4-byte content size, single segment
  body.resize(body.size() + 4);
  store_u32(&body[5], body_size);
  const std::uint32_t block = (128u * 1024u) << 3 | 1u << 1 | 1u;  // RLE, last
  body.push_back(block & 0xFF);
  body.push_back((block >> 8) & 0xFF);
  body.push_back((block >> 16) & 0xFF);
  body.push_back(0x42);
  ASSERT_EQ(ZSTD_getFrameContentSize(body.data(), body.size()), body_size);

  Bytes p(TileHeader::kFrameBytes, 0);
  store_u32(&p[0], TileHeader::kSkippableMagic);
  store_u32(&p[4], TileHeader::kHeaderBytes);
  p[8] = 1;
  store_u32(&p[12], side);
  store_u32(&p[16], side);
  store_u32(&p[20], body_size);
  p.insert(p.end(), body.begin(), body.end());
  resign(p);
  ASSERT_TRUE(verify_tile(p).ok());  // structurally a complete frame with the right size
  auto d = decode_tile(p);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().code, ErrorCode::corrupt) << d.error().to_string();
}

TEST(LosslessCodec, GarbageAndEmptyInputsAreErrors) {
  EXPECT_EQ(decode_tile({}).error().code, ErrorCode::truncated);
  const Bytes text = {'<', 'h', 't', 'm', 'l', '>', ' ', '4', '0', '4'};
  EXPECT_EQ(decode_tile(text).error().code, ErrorCode::corrupt);
  // A plain zstd frame without our header (e.g. a tile from another tool).
  Bytes plain(ZSTD_compressBound(64));
  const Bytes src(64, 7);
  plain.resize(ZSTD_compress(plain.data(), plain.size(), src.data(), src.size(), 3));
  EXPECT_EQ(decode_tile(plain).error().code, ErrorCode::corrupt);
  // Header only.
  Bytes header_only = encode(smooth_image(4, 4), FilterChoice::none);
  header_only.resize(TileHeader::kFrameBytes);
  EXPECT_EQ(decode_tile(header_only).error().code, ErrorCode::truncated);
}

TEST(CodecRegistry, UnknownCodecIdsHaveNoCodec) {
  EXPECT_EQ(find_codec(static_cast<CodecId>(200)), nullptr);
  // A header naming codec 7 is refused before any codec is looked up.
  Bytes p = encode(smooth_image(8, 8), FilterChoice::none);
  p[9] = 7;
  auto d = decode_tile(p);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().code, ErrorCode::unsupported);
}

TEST(CodecNames, RoundTripAndRejectUnknownNames) {
  EXPECT_STREQ(codec_name(CodecId::lossless), "lossless");
  EXPECT_STREQ(codec_name(CodecId::bc1), "bc1");
  EXPECT_EQ(parse_codec_name("lossless").value(), CodecId::lossless);
  EXPECT_EQ(parse_codec_name("bc1").value(), CodecId::bc1);
  for (const char* bad : {"", "LOSSLESS", "png", "bc1 "}) {
    auto r = parse_codec_name(bad);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.error().code, ErrorCode::unsupported);
  }
  EXPECT_STREQ(filter_name(Filter::none), "none");
  EXPECT_STREQ(filter_name(Filter::gradient), "gradient");
  EXPECT_STREQ(filter_name(static_cast<Filter>(9)), "unknown");
}

TEST(LosslessCodec, EncodesAndDecodesConcurrentlyFromManyThreads) {
  // Each thread owns its zstd contexts and scratch buffers; results must not interfere.
  std::vector<std::thread> threads;
  std::vector<int> failures(4, 0);
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([t, &failures] {
      for (int i = 0; i < 20; ++i) {
        const TileImage img =
            (i % 2) ? smooth_image(64 + t, 48, t * 100 + i) : random_image(40, 40 + t, t * 100 + i);
        auto p = encode_lossless(img);
        if (!p.ok()) {
          ++failures[t];
          continue;
        }
        auto d = decode_tile(*p);
        if (!d.ok() || d->pixels != img.pixels) ++failures[t];
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(failures, std::vector<int>(4, 0));
}

}  // namespace
}  // namespace vts
