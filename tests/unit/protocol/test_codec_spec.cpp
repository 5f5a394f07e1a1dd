// A tile checked against its tileset (vts::check_tile_against): the decoders and verify_tile()
// given a TileSpec refuse a tile of another size, codec or pixel format, from its header alone.
#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "vts/protocol/codec.hpp"
#include "vts/protocol/tileset.hpp"
#include "vts/test/forge.hpp"

namespace vts {
namespace {

using Bytes = std::vector<std::uint8_t>;

const TileSpec kSpec{264, 264, CodecId::lossless};  // a tileset of 256 + 2 x 4 texel tiles

// A well-formed tile of `codec`, side x side texels (bc1: blocks of one byte value, framed as the
// builder's encoder frames them; this library has no bc1 encoder).
Bytes encoded(CodecId codec, std::uint32_t side) {
  const std::size_t blocks = (std::size_t(side) + 3) / 4;
  const Bytes body(codec == CodecId::bc1 ? blocks * blocks * 8 : std::size_t(side) * side * 4,
                   0x5A);
  auto p = pack_tile(codec, side, side, body, 3);
  EXPECT_TRUE(p.ok()) << p.error().to_string();
  return p.ok() ? *p : Bytes{};
}

TEST(TileSpec, IsTheTilesetsStoredSizeAndCodec) {
  TilesetInfo info;
  info.geometry = *Geometry::create(1000, 600, 256, 4);
  info.codec = CodecId::bc1;
  const TileSpec s = info.tile_spec();
  EXPECT_EQ(s.width, 264u);
  EXPECT_EQ(s.height, 264u);
  EXPECT_EQ(s.codec, CodecId::bc1);
}

TEST(CheckTileAgainst, AcceptsATileOfTheTilesetsShape) {
  const Bytes p = encoded(CodecId::lossless, 264);
  ASSERT_TRUE(verify_tile(p, kSpec).ok());
  auto img = decode_tile(p, kSpec);
  ASSERT_TRUE(img.ok()) << img.error().to_string();
  EXPECT_EQ(img->width, 264u);
  EXPECT_TRUE(decode_tile(encoded(CodecId::bc1, 264), TileSpec{264, 264, CodecId::bc1}).ok());
}

TEST(CheckTileAgainst, RefusesAnotherSizeCodecOrPixelFormatNamingWhatDiffers) {
  struct Case {
    Bytes payload;
    const char* says;
  };
  const Case cases[] = {
      {encoded(CodecId::lossless, 64),
       "tile declares 64x64 texels, the tileset's tiles are 264x264"},
      {test::flat_tile(264, 263, 1), "tile declares 264x263 texels"},
      {encoded(CodecId::bc1, 264), "tile uses codec bc1, the tileset lossless"},
  };
  for (const Case& c : cases) {
    ASSERT_TRUE(verify_tile(c.payload).ok()) << "a well-formed tile, only not this tileset's";
    for (const Error& e :
         {verify_tile(c.payload, kSpec).error(), decode_tile(c.payload, kSpec).error()}) {
      EXPECT_EQ(e.code, ErrorCode::corrupt) << e.to_string();
      EXPECT_NE(e.message.find(c.says), std::string::npos) << e.message;
    }
  }
  // The pixel format, on a header read alone (a lossless tile relabelled bc1 fails the
  // codec/format pairing before anything else, so the format is checked for itself here).
  TileHeader h;
  h.codec = CodecId::lossless;
  h.format = PixelFormat::bc1;
  h.width = h.height = 264;
  const Status s = check_tile_against(h, kSpec);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("pixel format 1"), std::string::npos) << s.error().message;
}

// The tile that made a cache daemon hand 256 MiB decodes to every viewer: 8 KiB of run-length
// blocks declaring 8192 x 8192 texels. Structurally valid and within the format's per-side limit,
// so only the tileset can refuse it; it is refused from the header, before the checksum is even
// computed (a damaged body still gets the size error) and so before any texel is allocated.
TEST(CheckTileAgainst, DecodersRefuseADeclaredSizeBeyondTheTilesetsBeforeTouchingTheBody) {
  Bytes huge = test::flat_tile(8192, 8192, 3);
  EXPECT_LT(huge.size(), 9000u);
  ASSERT_TRUE(verify_tile(huge).ok());
  auto d = decode_tile(huge, kSpec);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().code, ErrorCode::corrupt);
  EXPECT_NE(d.error().message.find("declares 8192x8192 texels, the tileset's tiles are 264x264"),
            std::string::npos)
      << d.error().message;
  huge[huge.size() - 1] ^= 0xFF;  // the body no longer matches its checksum
  ASSERT_EQ(verify_tile(huge).error().code, ErrorCode::checksum);
  auto again = decode_tile(huge, kSpec);
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().message.find("8192x8192"), std::string::npos) << again.error().message;
}

}  // namespace
}  // namespace vts
