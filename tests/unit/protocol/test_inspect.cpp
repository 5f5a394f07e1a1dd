#include "vts/protocol/inspect.hpp"

#include <gtest/gtest.h>

#include <filesystem>

namespace vts {
namespace {

namespace fs = std::filesystem;

std::vector<std::uint8_t> encode_tile(std::uint32_t size, std::uint8_t fill) {
  TileImage img;
  img.width = img.height = size;
  img.pixels.assign(std::size_t{size} * size * 4, fill);
  auto p = find_codec(CodecId::lossless)->encode(img, {});
  EXPECT_TRUE(p.ok());
  return *p;
}

// A 40x20 image with T=16, B=2: levels 0..2 with 1 + 2 + 6 tiles, written tile by tile so the
// test can plant bad ones.
struct SmallArchive {
  fs::path path;
  TilesetInfo info;
  explicit SmallArchive(const std::string& name) {
    path = fs::temp_directory_path() / ("vts-inspect-" + std::to_string(::getpid()) + name);
    info.geometry = *Geometry::create(40, 20, 16, 2);
    info.name = name;
  }
  ~SmallArchive() { fs::remove(path); }

  // Writes every existing tile; `tamper` may replace a payload (return empty to skip the tile).
  void write(const std::function<std::vector<std::uint8_t>(TileId, std::vector<std::uint8_t>)>&
                 tamper = {},
             std::vector<TileId> extra = {}) {
    pmtiles::WriterOptions o;
    o.path = path;
    o.max_zoom = static_cast<std::uint8_t>(info.geometry.max_zoom());
    auto w = pmtiles::Writer::create(o);
    ASSERT_TRUE(w.ok());
    const Geometry& g = info.geometry;
    std::uint8_t fill = 1;
    auto add = [&](TileId id) {
      auto payload = encode_tile(g.stored_size(), fill++);
      if (tamper) payload = tamper(id, std::move(payload));
      if (!payload.empty()) {
        ASSERT_TRUE((*w)->add_tile(id, payload).ok());
      }
    };
    for (int z = 0; z <= g.max_zoom(); ++z)
      for (std::uint32_t y = 0; y < g.tiles_y(z); ++y)
        for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) add({static_cast<std::uint8_t>(z), x, y});
    for (TileId id : extra) add(id);
    ASSERT_TRUE((*w)->finish(info.to_json()).ok());
  }
  VerifyReport verify() {
    auto r = pmtiles::Reader::open(path);
    EXPECT_TRUE(r.ok());
    auto report = verify_archive(**r, 2);
    EXPECT_TRUE(report.ok());
    return *report;
  }
};

TEST(VerifyArchive, AcceptsAnIntactArchive) {
  SmallArchive a("intact");
  a.write();
  const VerifyReport r = a.verify();
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.tiles_checked, a.info.geometry.total_tile_count());
  EXPECT_EQ(r.payloads_checked, a.info.geometry.total_tile_count());
  auto reader = pmtiles::Reader::open(a.path);
  auto s = summarize_archive(**reader);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->addressed_tiles, a.info.geometry.total_tile_count());
  EXPECT_EQ(s->levels.back().tiles_present, 6u);
  EXPECT_DOUBLE_EQ(s->dedup_ratio, 1.0);
}

TEST(VerifyArchive, NamesTheFirstBadTileAndCountsEveryBadOne) {
  SmallArchive a("bad");
  a.write(
      [&](TileId id, std::vector<std::uint8_t> p) {
        if (id == TileId{2, 1, 1}) p.back() ^= 0x40;          // checksum mismatch
        if (id == TileId{2, 2, 0}) return encode_tile(8, 7);  // wrong tile size
        if (id == TileId{1, 1, 0}) p[20] = 0xEE;              // header: wrong body size
        return p;
      },
      {TileId{2, 3, 3}});  // a tile outside the 40x20 image (level 2 has 3x2 tiles)
  const VerifyReport r = a.verify();
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(r.bad_tiles, 4u);
  ASSERT_TRUE(r.first_bad.has_value());
  EXPECT_EQ(*r.first_bad, (TileId{1, 1, 0}));  // lowest tile id among the bad
  EXPECT_FALSE(r.first_error.empty());
}

TEST(VerifyArchive, SharedPayloadCountsEveryTileThatUsesIt) {
  SmallArchive a("shared");
  const auto bad = [] {
    auto p = encode_tile(20, 9);
    p.back() ^= 1;
    return p;
  }();
  a.write([&](TileId id, std::vector<std::uint8_t> p) { return id.z == 2 ? bad : p; });
  const VerifyReport r = a.verify();
  EXPECT_EQ(r.bad_tiles, 6u);
  EXPECT_EQ(r.payloads_checked, 4u);  // 3 coarse tiles + the one shared payload
}

TEST(VerifyArchive, RejectsArchiveWithoutOurMetadata) {
  SmallArchive a("foreign");
  pmtiles::WriterOptions o;
  o.path = a.path;
  auto w = pmtiles::Writer::create(o);
  ASSERT_TRUE((*w)->add_tile({0, 0, 0}, encode_tile(20, 1)).ok());
  ASSERT_TRUE((*w)->finish("{\"name\":\"someone else's\"}").ok());
  auto reader = pmtiles::Reader::open(a.path);
  auto report = verify_archive(**reader);
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.error().code, ErrorCode::unsupported);
}

}  // namespace
}  // namespace vts
