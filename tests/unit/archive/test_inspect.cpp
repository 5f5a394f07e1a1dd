#include "vts/archive/inspect.hpp"

#include <gtest/gtest.h>

#include <sys/resource.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace vts {
namespace {

namespace fs = std::filesystem;

std::vector<std::uint8_t> encode_tile(std::uint32_t size, std::uint8_t fill) {
  TileImage img;
  img.width = img.height = size;
  img.pixels.assign(std::size_t{size} * size * 4, fill);
  auto p = encode_lossless(img);
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
    archive::WriterOptions o;
    o.path = path;
    o.max_zoom = static_cast<std::uint8_t>(info.geometry.max_zoom());
    auto w = archive::Writer::create(o);
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
  archive::VerifyReport verify() {
    auto r = archive::Reader::open(path);
    EXPECT_TRUE(r.ok());
    auto report = archive::verify_archive(**r, 2);
    EXPECT_TRUE(report.ok());
    return *report;
  }
};

TEST(VerifyArchive, AcceptsAnIntactArchive) {
  SmallArchive a("intact");
  a.write();
  const archive::VerifyReport r = a.verify();
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.tiles_checked, a.info.geometry.total_tile_count());
  EXPECT_EQ(r.payloads_checked, a.info.geometry.total_tile_count());
  auto reader = archive::Reader::open(a.path);
  auto s = archive::summarize_archive(**reader);
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
  const archive::VerifyReport r = a.verify();
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
  const archive::VerifyReport r = a.verify();
  EXPECT_EQ(r.bad_tiles, 6u);
  EXPECT_EQ(r.payloads_checked, 4u);  // 3 coarse tiles + the one shared payload
}

TEST(VerifyArchive, RejectsArchiveWithoutOurMetadata) {
  SmallArchive a("foreign");
  archive::WriterOptions o;
  o.path = a.path;
  auto w = archive::Writer::create(o);
  ASSERT_TRUE((*w)->add_tile({0, 0, 0}, encode_tile(20, 1)).ok());
  ASSERT_TRUE((*w)->finish("{\"name\":\"someone else's\"}").ok());
  auto reader = archive::Reader::open(a.path);
  auto report = archive::verify_archive(**reader);
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.error().code, ErrorCode::unsupported);
}

// `a`'s archive (written) with its root replaced by `root` (uncompressed), its tile data by
// `data`, and the header field tile_compression set to `tile_compression`; metadata kept.
void rewrite(const SmallArchive& a, const std::vector<archive::Entry>& root,
             const std::vector<std::uint8_t>& data,
             archive::Compression tile_compression = archive::Compression::zstd) {
  auto old = archive::Reader::open(a.path);
  ASSERT_TRUE(old.ok());
  const std::string meta = (*old)->metadata_json();
  const std::vector<std::uint8_t> dir = archive::serialize_directory(root);
  archive::Header h = (*old)->header();
  h.internal_compression = archive::Compression::none;
  h.tile_compression = tile_compression;
  h.root_dir_offset = archive::kHeaderSize;
  h.root_dir_length = dir.size();
  h.metadata_offset = h.root_dir_offset + h.root_dir_length;
  h.metadata_length = meta.size();
  h.leaf_dirs_offset = h.metadata_offset + h.metadata_length;
  h.leaf_dirs_length = 0;
  h.tile_data_offset = h.leaf_dirs_offset;
  h.tile_data_length = data.size();
  const auto head = archive::serialize_header(h);
  old->reset();
  std::ofstream out(a.path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(head.data()), std::streamsize(head.size()));
  out.write(reinterpret_cast<const char*>(dir.data()), std::streamsize(dir.size()));
  out.write(meta.data(), std::streamsize(meta.size()));
  out.write(reinterpret_cast<const char*>(data.data()), std::streamsize(data.size()));
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

TEST(VerifyArchive, CountsARunOfFourBillionTilesByLevelWithoutVisitingEach) {
  SmallArchive a("run");
  a.write();
  const auto payload = encode_tile(a.info.geometry.stored_size(), 5);
  const auto length = static_cast<std::uint32_t>(payload.size());
  constexpr std::uint32_t kRun = 0xFFFFFFFF;  // ids 0 .. 2^32 - 2: levels 0..15 and part of 16
  rewrite(a, {{0, 0, length, kRun}}, payload);
  auto reader = archive::Reader::open(a.path);
  ASSERT_TRUE(reader.ok());

  const auto t0 = std::chrono::steady_clock::now();
  auto s = archive::summarize_archive(**reader);
  ASSERT_TRUE(s.ok()) << s.error().to_string();
  EXPECT_EQ(s->addressed_tiles, kRun);
  EXPECT_EQ(s->addressed_bytes, std::uint64_t{kRun} * length);
  EXPECT_EQ(s->entries, 1u);
  EXPECT_EQ(s->unique_tiles, 1u);
  ASSERT_EQ(s->levels.size(), 3u);  // levels of the tileset only: each wholly addressed
  EXPECT_EQ(s->levels[0].tiles_present, 1u);
  EXPECT_EQ(s->levels[1].tiles_present, 4u);
  EXPECT_EQ(s->levels[2].tiles_present, 16u);
  EXPECT_EQ(s->levels[2].bytes, 16u * length);

  const archive::VerifyReport r = *archive::verify_archive(**reader, 2);
  EXPECT_LT(seconds_since(t0), 5.0) << "a run must cost what one tile costs";
  EXPECT_EQ(r.tiles_checked, kRun);
  EXPECT_EQ(r.payloads_checked, 1u);
  // The 9 tiles of the 40x20 pyramid are fine; every other id of the run lies outside it.
  EXPECT_EQ(r.bad_tiles, kRun - a.info.geometry.total_tile_count());
  ASSERT_TRUE(r.first_bad.has_value());
  // Level 1 is 2x1 tiles; in Hilbert order its ids are (0,0), (0,1), (1,1), (1,0).
  EXPECT_EQ(*r.first_bad, (TileId{1, 0, 1}));
  EXPECT_NE(r.first_error.find("outside the pyramid"), std::string::npos) << r.first_error;
}

TEST(VerifyArchive, CountsATileOutsideThePyramidWithABadPayloadOnce) {
  SmallArchive a("once");
  a.write();
  auto payload = encode_tile(a.info.geometry.stored_size(), 5);
  payload.back() ^= 1;  // every tile of the run is bad twice over: outside, and a bad checksum
  const auto length = static_cast<std::uint32_t>(payload.size());
  // Ids 1..20: level 1 (2 of 4 inside) and level 2 (6 of 16 inside).
  rewrite(a, {{1, 0, length, 20}}, payload);
  auto reader = archive::Reader::open(a.path);
  const archive::VerifyReport r = *archive::verify_archive(**reader, 2);
  EXPECT_EQ(r.tiles_checked, 20u);
  EXPECT_EQ(r.bad_tiles, 20u);  // each tile counted once (40 before)
  EXPECT_EQ(*r.first_bad, (TileId{1, 0, 0}));
  EXPECT_NE(r.first_error.find("checksum"), std::string::npos) << r.first_error;
}

TEST(VerifyArchive, RefusesAnArchiveWhoseHeaderDeclaresAnotherTileCompression) {
  SmallArchive a("gzip-tiles");
  a.write();
  const auto payload = encode_tile(a.info.geometry.stored_size(), 5);
  rewrite(a, {{0, 0, static_cast<std::uint32_t>(payload.size()), 1}}, payload,
          archive::Compression::gzip);
  auto reader = archive::Reader::open(a.path);
  ASSERT_TRUE(reader.ok());
  for (const Error& e :
       {archive::verify_archive(**reader).error(), archive::summarize_archive(**reader).error()}) {
    EXPECT_EQ(e.code, ErrorCode::corrupt);
    EXPECT_NE(e.message.find("tile_compression is 2"), std::string::npos) << e.message;
  }
  EXPECT_EQ(archive::archive_tileset((*reader)->header(), (*reader)->metadata_json()).error().code,
            ErrorCode::corrupt);
}

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define VTS_ADDRESS_SPACE_LIMITS_WORK 0
#else
#define VTS_ADDRESS_SPACE_LIMITS_WORK 1
#endif

// Verifies with 2000 decoder threads in an address space with room for the process as it is
// plus 64 MiB: a few 8 MiB stacks, not 2000 of them. Exits 0 when verify returned the error.
[[noreturn]] void verify_with_too_little_address_space(const archive::Reader& reader) {
  std::ifstream status("/proc/self/status");
  std::string line;
  std::uint64_t vm_kib = 0;
  while (std::getline(status, line))
    if (line.rfind("VmSize:", 0) == 0) vm_kib = std::stoull(line.substr(7));
  const rlim_t bytes = (vm_kib << 10) + (64u << 20);
  const rlimit limit{bytes, bytes};
  setrlimit(RLIMIT_AS, &limit);
  auto r = archive::verify_archive(reader, 2000);
  const bool named = !r && r.error().code == ErrorCode::io &&
                     r.error().message.find("cannot start decoder thread") != std::string::npos;
  std::_Exit(named ? 0 : 1);
}

// Under an address-space limit thread stacks cannot be mapped: the pool joins the threads it
// started and returns an error (the process used to abort: "terminate called without an active
// exception").
TEST(VerifyArchiveDeathTest, ReportsADecoderThreadThatCannotStartAsAnError) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "sanitizers reserve the address space";
#endif
  SmallArchive a("threads");
  a.write();
  auto reader = archive::Reader::open(a.path);
  ASSERT_TRUE(reader.ok());
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(verify_with_too_little_address_space(**reader), ::testing::ExitedWithCode(0), "");
}

}  // namespace
}  // namespace vts
