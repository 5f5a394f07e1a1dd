// PMTiles v3: tile ids, header, directories, internal compression, Writer and Reader, including
// hostile archives (truncation at every byte, bit flips, cycles, bombs, out-of-range offsets).
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "vts/archive/pmtiles.hpp"
#include "vts/test/files.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts::archive {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

Bytes bytes_of(std::string_view s) {
  return Bytes(s.begin(), s.end());
}

using vts::test::read_bytes;

// A fresh directory under the system temp dir, removed with everything in it.
class TempDir : public vts::test::TempDir {
 public:
  TempDir() : vts::test::TempDir("vts-pmtiles-test") {}
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(path()))
      out.push_back(e.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
  }
};

TileId zxy(std::uint64_t tile_id) {
  return tile_id_to_zxy(tile_id).value();
}

// The Hilbert index as printed in the literature (Wikipedia's xy2d, rotating within the full n),
// plus the count of tiles on coarser levels: an independent reference for zxy_to_tile_id.
std::uint64_t reference_tile_id(int z, std::uint64_t x, std::uint64_t y) {
  std::uint64_t base = 0;
  for (int i = 0; i < z; ++i) base += (std::uint64_t{1} << i) * (std::uint64_t{1} << i);
  const std::uint64_t n = std::uint64_t{1} << z;
  std::uint64_t d = 0;
  for (std::uint64_t s = n / 2; s > 0; s /= 2) {
    const std::uint64_t rx = (x & s) > 0 ? 1 : 0;
    const std::uint64_t ry = (y & s) > 0 ? 1 : 0;
    d += s * s * ((3 * rx) ^ ry);
    if (ry == 0) {
      if (rx == 1) {
        x = n - 1 - x;
        y = n - 1 - y;
      }
      std::swap(x, y);
    }
  }
  return base + d;
}

// Writes an archive of the given tiles and returns its path.
fs::path write_archive(const TempDir& dir, const std::map<TileId, Bytes>& tiles,
                       const std::string& metadata = "{}", WriterOptions options = {}) {
  if (options.path.empty()) options.path = dir.path() / "a.pmtiles";
  auto writer = Writer::create(options);
  EXPECT_TRUE(writer.ok()) << writer.error().to_string();
  for (const auto& [id, payload] : tiles) EXPECT_TRUE((*writer)->add_tile(id, payload).ok());
  auto stats = (*writer)->finish(metadata);
  EXPECT_TRUE(stats.ok()) << stats.error().to_string();
  return options.path;
}

std::map<TileId, Bytes> small_tiles() {
  return {
      {TileId{0, 0, 0}, bytes_of("root tile")}, {TileId{1, 0, 0}, bytes_of("nw")},
      {TileId{1, 1, 0}, bytes_of("ne")},        {TileId{1, 0, 1}, bytes_of("same")},
      {TileId{1, 1, 1}, bytes_of("same")},      {TileId{3, 5, 2}, bytes_of("deeper tile payload")}};
}

// Hand-assembled archive: header + the given (already compressed) sections in spec order.
struct Parts {
  Bytes root, metadata, leaves, data;
  Compression compression = Compression::none;
};
Header header_for(const Parts& p) {
  Header h;
  h.internal_compression = p.compression;
  h.root_dir_offset = kHeaderSize;
  h.root_dir_length = p.root.size();
  h.metadata_offset = h.root_dir_offset + h.root_dir_length;
  h.metadata_length = p.metadata.size();
  h.leaf_dirs_offset = h.metadata_offset + h.metadata_length;
  h.leaf_dirs_length = p.leaves.size();
  h.tile_data_offset = h.leaf_dirs_offset + h.leaf_dirs_length;
  h.tile_data_length = p.data.size();
  return h;
}
Bytes assemble(const Parts& p, const Header& h) {
  const auto head = serialize_header(h);
  Bytes out(head.begin(), head.end());
  for (const Bytes* b : {&p.root, &p.metadata, &p.leaves, &p.data})
    out.insert(out.end(), b->begin(), b->end());
  return out;
}
Bytes assemble(const Parts& p) {
  return assemble(p, header_for(p));
}

// Two leaves of three tiles each behind a two-entry root, all uncompressed: small enough to flip
// every bit, and every byte of it is structure rather than a checksummed gzip stream.
Parts two_level_parts() {
  Parts p;
  p.data = bytes_of("aaaabbbbccccddddeeeeffff");
  const std::vector<Entry> leaf1{{1, 0, 4, 1}, {2, 4, 4, 1}, {3, 8, 4, 2}};
  const std::vector<Entry> leaf2{{10, 12, 4, 1}, {11, 16, 4, 1}, {20, 20, 4, 3}};
  const Bytes l1 = serialize_directory(leaf1), l2 = serialize_directory(leaf2);
  p.leaves = l1;
  p.leaves.insert(p.leaves.end(), l2.begin(), l2.end());
  const std::vector<Entry> root{{1, 0, static_cast<std::uint32_t>(l1.size()), 0},
                                {10, l1.size(), static_cast<std::uint32_t>(l2.size()), 0}};
  p.root = serialize_directory(root);
  p.metadata = bytes_of("{\"k\":1}");
  return p;
}

// Opens hostile bytes and touches everything a server or tool would; must never crash.
void exercise(std::span<const std::uint8_t> bytes) {
  ReaderOptions o;
  o.max_directory_bytes = 1 << 20;
  o.max_metadata_bytes = 1 << 20;
  auto r = Reader::open_bytes(bytes, o);
  if (!r) return;
  for (std::uint64_t id = 0; id < 32; ++id) {
    auto t = (*r)->get_by_tile_id(id);
    if (t) {
      // Exactly the bytes its entry points at, inside the archive.
      auto e = (*r)->find_entry(id);
      ASSERT_TRUE(e.ok());
      const std::uint64_t at = (*r)->header().tile_data_offset + e->offset;
      ASSERT_LE(at + t->size(), bytes.size());
      ASSERT_TRUE(std::equal(t->begin(), t->end(), bytes.begin() + std::ptrdiff_t(at)));
    }
  }
  std::uint64_t visits = 0;
  (void)(*r)->for_each_entry([&](const Entry&) { return ++visits < 100000; });
  (void)(*r)->leaf_directory_count();
}

// ---- tile ids -----------------------------------------------------------------------------------

TEST(TileId, MatchesSpecValuesAtLowZooms) {
  EXPECT_EQ(zxy_to_tile_id(0, 0, 0), 0u);
  EXPECT_EQ(zxy_to_tile_id(1, 0, 0), 1u);
  EXPECT_EQ(zxy_to_tile_id(1, 0, 1), 2u);
  EXPECT_EQ(zxy_to_tile_id(1, 1, 1), 3u);
  EXPECT_EQ(zxy_to_tile_id(1, 1, 0), 4u);
  EXPECT_EQ(zxy_to_tile_id(2, 0, 0), 5u);
  EXPECT_EQ(zxy_to_tile_id(3, 0, 0), 21u);
  EXPECT_EQ(zxy_to_tile_id(3, 7, 0), 84u);
}

// Every tile's id lies in the range of each of its ancestors' sub-pyramids, and the range holds
// exactly the ancestor's 4^(z - L) descendants: exhaustively to level 7, sampled to level 31.
TEST(TileId, EverySubPyramidIsOneContiguousIdRangePerLevel) {
  for (std::uint8_t z = 0; z <= 7; ++z) {
    for (std::uint32_t x = 0; x < (1u << z); ++x) {
      for (std::uint32_t y = 0; y < (1u << z); ++y) {
        const std::uint64_t id = zxy_to_tile_id(z, x, y);
        for (std::uint8_t l = 0; l <= z; ++l) {
          const TileId root{l, x >> (z - l), y >> (z - l)};
          const TileIdRange r = subtree_tile_ids(root, z);
          ASSERT_LE(r.first, id) << root.to_string() << " at " << int(z);
          ASSERT_GE(r.last, id) << root.to_string() << " at " << int(z);
          ASSERT_EQ(r.last - r.first + 1, std::uint64_t{1} << (2 * (z - l)));
        }
      }
    }
  }
  std::mt19937_64 rng(20261126);
  for (int i = 0; i < 20000; ++i) {
    const auto z = static_cast<std::uint8_t>(rng() % 32);
    const auto x = static_cast<std::uint32_t>(rng() & ((std::uint64_t{1} << z) - 1));
    const auto y = static_cast<std::uint32_t>(rng() & ((std::uint64_t{1} << z) - 1));
    const auto l = static_cast<std::uint8_t>(rng() % (z + 1u));
    const TileIdRange r = subtree_tile_ids(TileId{l, x >> (z - l), y >> (z - l)}, z);
    const std::uint64_t id = zxy_to_tile_id(z, x, y);
    ASSERT_TRUE(r.first <= id && id <= r.last)
        << z << "/" << x << "/" << y << " under level " << int(l);
    // The range's ends are the root's descendants too.
    for (std::uint64_t end : {r.first, r.last}) {
      auto t = tile_id_to_zxy(end);
      ASSERT_TRUE(t.ok());
      EXPECT_EQ(t->z, z);
      EXPECT_EQ(t->x >> (z - l), x >> (z - l));
      EXPECT_EQ(t->y >> (z - l), y >> (z - l));
    }
  }
  // Sub-pyramids sorted by their root's id are in id order at every deeper level.
  const TileIdRange a = subtree_tile_ids(TileId{2, 1, 3}, 9),
                    b = subtree_tile_ids(TileId{2, 2, 3}, 9);
  EXPECT_EQ(zxy_to_tile_id(2, 1, 3) < zxy_to_tile_id(2, 2, 3), a.last < b.first);
}

TEST(TileId, MatchesReferenceImplementationValuesAtHighZooms) {
  // Values asserted by the protomaps reference implementations' own tests.
  EXPECT_EQ(zxy_to_tile_id(20, 0, 0), 366503875925u);
  EXPECT_EQ(zxy_to_tile_id(12, 3423, 1763), 19078479u);
  EXPECT_EQ(zxy(19078479), (TileId{12, 3423, 1763}));
}

TEST(TileId, AgreesWithTextbookHilbertCurveForRandomTilesUpToZoom31) {
  std::mt19937_64 rng(7);
  for (int i = 0; i < 20000; ++i) {
    const int z = static_cast<int>(rng() % 32);
    const std::uint64_t mask = (std::uint64_t{1} << z) - 1;
    const auto x = static_cast<std::uint32_t>(rng() & mask);
    const auto y = static_cast<std::uint32_t>(rng() & mask);
    const std::uint64_t id = zxy_to_tile_id(static_cast<std::uint8_t>(z), x, y);
    ASSERT_EQ(id, reference_tile_id(z, x, y)) << z << "/" << x << "/" << y;
    ASSERT_EQ(zxy(id), (TileId{static_cast<std::uint8_t>(z), x, y}));
  }
}

TEST(TileId, RoundTripsEveryTileUpToZoom7AndRandomIdsUpToZoom31) {
  for (int z = 0; z <= 7; ++z)
    for (std::uint32_t x = 0; x < (1u << z); ++x)
      for (std::uint32_t y = 0; y < (1u << z); ++y) {
        const TileId t{static_cast<std::uint8_t>(z), x, y};
        ASSERT_EQ(zxy(zxy_to_tile_id(t.z, t.x, t.y)), t);
      }
  std::mt19937_64 rng(11);
  const std::uint64_t last_id = zxy_to_tile_id(31, 0x7fffffff, 0);  // any id below the z=32 base
  for (int i = 0; i < 100000; ++i) {
    const std::uint64_t id = rng() % last_id;
    const TileId t = zxy(id);
    ASSERT_EQ(zxy_to_tile_id(t.z, t.x, t.y), id);
  }
}

TEST(TileId, RoundTripsTheCornersOfEveryZoom) {
  for (int z = 0; z <= 31; ++z) {
    const std::uint32_t m = static_cast<std::uint32_t>((std::uint64_t{1} << z) - 1);
    for (const TileId t : {TileId{std::uint8_t(z), 0, 0}, TileId{std::uint8_t(z), m, 0},
                           TileId{std::uint8_t(z), 0, m}, TileId{std::uint8_t(z), m, m}}) {
      EXPECT_EQ(zxy(zxy_to_tile_id(t.z, t.x, t.y)), t);
    }
  }
}

TEST(TileId, ConsecutiveIdsWithinALevelAreEdgeNeighbours) {
  const std::uint64_t first = zxy_to_tile_id(6, 0, 0), end = zxy_to_tile_id(7, 0, 0);
  for (std::uint64_t id = first + 1; id < end; ++id) {
    const TileId a = zxy(id - 1), b = zxy(id);
    const auto dx = std::abs(std::int64_t{a.x} - std::int64_t{b.x});
    const auto dy = std::abs(std::int64_t{a.y} - std::int64_t{b.y});
    ASSERT_EQ(dx + dy, 1) << id;
  }
}

TEST(TileId, RejectsIdsBeyondZoom31) {
  const std::uint64_t first_z32 = 6148914691236517205ULL;  // (4^32 - 1) / 3
  EXPECT_EQ(zxy(first_z32 - 1).z, 31);
  EXPECT_EQ(tile_id_to_zxy(first_z32).error().code, ErrorCode::invalid_argument);
  EXPECT_FALSE(tile_id_to_zxy(~std::uint64_t{0}).ok());
}

// ---- header -------------------------------------------------------------------------------------

Header full_header() {
  Header h;
  h.root_dir_offset = 127;
  h.root_dir_length = 0x1122;
  h.metadata_offset = 0x1122 + 127;
  h.metadata_length = 3;
  h.leaf_dirs_offset = 0x0102030405060708ULL;
  h.leaf_dirs_length = 9;
  h.tile_data_offset = 10;
  h.tile_data_length = 0xfffffffffULL;
  h.addressed_tiles = 12;
  h.tile_entries = 13;
  h.tile_contents = 14;
  h.clustered = false;
  h.internal_compression = Compression::zstd;
  h.tile_compression = Compression::gzip;
  h.tile_type = TileType::webp;
  h.min_zoom = 2;
  h.max_zoom = 17;
  h.min_lon_e7 = -1234567890;
  h.min_lat_e7 = -876543210;
  h.max_lon_e7 = 1234567890;
  h.max_lat_e7 = 876543210;
  h.center_zoom = 9;
  h.center_lon_e7 = -5;
  h.center_lat_e7 = 7;
  return h;
}

TEST(Header, RoundTripsEveryField) {
  const Header h = full_header();
  const auto bytes = serialize_header(h);
  const Header back = parse_header(bytes).value();
  EXPECT_EQ(serialize_header(back), bytes);
  EXPECT_EQ(back.leaf_dirs_offset, h.leaf_dirs_offset);
  EXPECT_EQ(back.tile_data_length, h.tile_data_length);
  EXPECT_FALSE(back.clustered);
  EXPECT_EQ(back.internal_compression, Compression::zstd);
  EXPECT_EQ(back.tile_type, TileType::webp);
  EXPECT_EQ(back.min_lon_e7, -1234567890);
  EXPECT_EQ(back.center_lon_e7, -5);
  EXPECT_EQ(back.center_lat_e7, 7);
}

TEST(Header, FollowsTheSpecByteLayout) {
  const auto b = serialize_header(full_header());
  EXPECT_EQ(std::string(b.begin(), b.begin() + 7), "PMTiles");
  EXPECT_EQ(b[7], 3);
  EXPECT_EQ(b[8], 127);    // root offset, little-endian
  EXPECT_EQ(b[16], 0x22);  // root length low byte
  EXPECT_EQ(b[17], 0x11);
  EXPECT_EQ(b[40], 0x08);  // leaf dirs offset
  EXPECT_EQ(b[47], 0x01);
  EXPECT_EQ(b[72], 12);     // addressed tiles
  EXPECT_EQ(b[96], 0);      // clustered
  EXPECT_EQ(b[97], 4);      // internal compression zstd
  EXPECT_EQ(b[98], 2);      // tile compression gzip
  EXPECT_EQ(b[99], 4);      // webp
  EXPECT_EQ(b[100], 2);     // min zoom
  EXPECT_EQ(b[101], 17);    // max zoom
  EXPECT_EQ(b[118], 9);     // center zoom
  EXPECT_EQ(b[119], 0xfb);  // center lon -5
  EXPECT_EQ(b[122], 0xff);
  EXPECT_EQ(b[123], 7);  // center lat
}

TEST(Header, GeoreferencedBoundsContainTheFootprintWithin1e7Degrees) {
  const LonLatBounds b{-10.12345678, 35.00000001, 30.99999999, 60.5};
  const Header h = georeferenced_bounds(b, {10.00000006, 47.5, 3});
  EXPECT_EQ(h.min_lon_e7, -101234568);  // outwards
  EXPECT_EQ(h.min_lat_e7, 350000000);
  EXPECT_EQ(h.max_lon_e7, 310000000);
  EXPECT_EQ(h.max_lat_e7, 605000000);
  EXPECT_EQ(h.center_lon_e7, 100000001);  // nearest
  EXPECT_EQ(h.center_lat_e7, 475000000);
  EXPECT_EQ(h.center_zoom, 3);
  EXPECT_EQ(h.min_zoom, 0);  // the rest is the writer's
}

TEST(Header, RejectsShortInputBadMagicAndOtherVersions) {
  auto b = serialize_header(full_header());
  EXPECT_EQ(parse_header(std::span(b).first(126)).error().code, ErrorCode::truncated);
  auto bad = b;
  bad[0] = 'X';
  EXPECT_EQ(parse_header(bad).error().code, ErrorCode::corrupt);
  bad = b;
  bad[7] = 2;
  EXPECT_EQ(parse_header(bad).error().code, ErrorCode::unsupported);
}

// ---- directories --------------------------------------------------------------------------------

TEST(Directory, RoundTripsEntriesWithRunsGapsAndLeafPointers) {
  const std::vector<Entry> entries{{0, 0, 10, 1},
                                   {1, 10, 5, 3},    // contiguous
                                   {7, 0, 10, 1},    // dedup: points back
                                   {9, 1000, 1, 0},  // leaf pointer
                                   {1ull << 40, 4000000000ull, 0xffffffffu, 0xffffffffu}};
  const Bytes raw = serialize_directory(entries);
  EXPECT_EQ(parse_directory(raw).value(), entries);
}

TEST(Directory, DecodesColumnsWithZeroMeaningContiguousOffset) {
  // 3 entries: ids 1,2,5 (deltas 1,1,3), runs 1,1,1, lengths 10,20,30, offsets 0+1, then 0, 0.
  const Bytes raw{3, 1, 1, 3, 1, 1, 1, 10, 20, 30, 1, 0, 0};
  const std::vector<Entry> expected{{1, 0, 10, 1}, {2, 10, 20, 1}, {5, 30, 30, 1}};
  EXPECT_EQ(parse_directory(raw).value(), expected);
  EXPECT_EQ(serialize_directory(expected), raw);
}

TEST(Directory, ReadsZeroOffsetOfTheFirstEntryAsOffsetZero) {
  const Bytes raw{1, 4, 1, 9, 0};
  EXPECT_EQ(parse_directory(raw).value(), (std::vector<Entry>{{4, 0, 9, 1}}));
}

TEST(Directory, RejectsTruncationAtEveryByte) {
  const std::vector<Entry> entries{{3, 0, 300, 1}, {70000, 5000000, 7, 2}, {70005, 0, 1, 0}};
  const Bytes raw = serialize_directory(entries);
  for (std::size_t n = 0; n < raw.size(); ++n) {
    auto r = parse_directory(std::span(raw).first(n));
    ASSERT_FALSE(r.ok()) << n;
    EXPECT_EQ(r.error().code, ErrorCode::truncated) << n << ": " << r.error().message;
  }
}

TEST(Directory, RejectsVarintsLongerThanTenBytesOrBeyond64Bits) {
  Bytes eleven{0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x00};
  EXPECT_EQ(parse_directory(eleven).error().code, ErrorCode::corrupt);
  Bytes overflow{0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x02};
  EXPECT_EQ(parse_directory(overflow).error().code, ErrorCode::corrupt);
  // The largest valid 10-byte varint is fine as a tile id delta.
  Bytes max_delta{1, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01, 1, 1, 1};
  EXPECT_EQ(parse_directory(max_delta).value()[0].tile_id, ~std::uint64_t{0});
}

TEST(Directory, RejectsTrailingBytes) {
  Bytes raw = serialize_directory(std::vector<Entry>{{1, 0, 1, 1}});
  raw.push_back(0);
  auto r = parse_directory(raw);
  EXPECT_EQ(r.error().code, ErrorCode::corrupt);
  EXPECT_NE(r.error().message.find("trailing"), std::string::npos);
}

TEST(Directory, RejectsRepeatedTileIdsButAllowsZeroDeltaFirst) {
  EXPECT_TRUE(parse_directory(Bytes{2, 0, 1, 1, 1, 1, 1, 1, 0}).ok());
  auto r = parse_directory(Bytes{2, 5, 0, 1, 1, 1, 1, 1, 0});
  EXPECT_EQ(r.error().code, ErrorCode::corrupt);
}

TEST(Directory, RejectsZeroLengthEntries) {
  EXPECT_EQ(parse_directory(Bytes{1, 0, 1, 0, 1}).error().code, ErrorCode::corrupt);
  EXPECT_EQ(parse_directory(Bytes{1, 0, 0, 0, 1}).error().code, ErrorCode::corrupt);  // leaf too
}

TEST(Directory, RejectsLengthsAndRunLengthsBeyond32Bits) {
  // run length 2^32 (varint 80 80 80 80 10)
  EXPECT_EQ(parse_directory(Bytes{1, 0, 0x80, 0x80, 0x80, 0x80, 0x10, 1, 1}).error().code,
            ErrorCode::corrupt);
  EXPECT_EQ(parse_directory(Bytes{1, 0, 1, 0x80, 0x80, 0x80, 0x80, 0x10, 1}).error().code,
            ErrorCode::corrupt);
}

TEST(Directory, RejectsHugeEntryCountsBeforeAllocating) {
  // 2^60 entries declared in 9 bytes: refused by the limit, not by a failed allocation.
  Bytes huge{0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x10};
  EXPECT_EQ(parse_directory(huge).error().code, ErrorCode::too_large);
  EXPECT_EQ(parse_directory(huge, ~std::size_t{0}).error().code, ErrorCode::truncated);
  // Within the limit but more than the remaining bytes could hold.
  EXPECT_EQ(parse_directory(Bytes{100, 1, 1, 1, 1}).error().code, ErrorCode::truncated);
  EXPECT_EQ(parse_directory(serialize_directory(std::vector<Entry>(3, Entry{})), 2).error().code,
            ErrorCode::too_large);
}

TEST(Directory, RejectsRunsOverlappingTheNextEntryAndIdOverflow) {
  // ids 0 and 2, first run length 3 covers id 2.
  EXPECT_EQ(parse_directory(Bytes{2, 0, 2, 3, 1, 1, 1, 1, 0}).error().code, ErrorCode::corrupt);
  Bytes overflow{2,    0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
                 0xff, 0x01, 1,    1,    1,    1,    1,    1,    0};
  EXPECT_EQ(parse_directory(overflow).error().code, ErrorCode::corrupt);
}

TEST(Directory, AcceptsAnEmptyDirectory) {
  EXPECT_TRUE(parse_directory(Bytes{0}).value().empty());
  EXPECT_EQ(parse_directory(Bytes{}).error().code, ErrorCode::truncated);
}

// ---- compression --------------------------------------------------------------------------------

TEST(Compression, RoundTripsNoneGzipAndZstd) {
  Bytes data;
  for (int i = 0; i < 100000; ++i) data.push_back(static_cast<std::uint8_t>(i * 7 % 251));
  for (Compression c : {Compression::none, Compression::gzip, Compression::zstd}) {
    const Bytes packed = compress(data, c).value();
    EXPECT_EQ(decompress(packed, c, data.size()).value(), data);
    EXPECT_EQ(decompress(packed, c, data.size() - 1).error().code, ErrorCode::too_large);
    EXPECT_EQ(decompress(packed, c, ~std::size_t{0}).value(), data);  // "no limit" works too
  }
  EXPECT_TRUE(decompress(compress(Bytes{}, Compression::gzip).value(), Compression::gzip, 0)
                  .value()
                  .empty());
}

TEST(Compression, WritesRealGzipStreams) {
  const Bytes g = compress(bytes_of("hello"), Compression::gzip).value();
  ASSERT_GE(g.size(), 18u);
  EXPECT_EQ(g[0], 0x1f);
  EXPECT_EQ(g[1], 0x8b);
  EXPECT_EQ(g[2], 8);  // deflate
}

TEST(Compression, StopsDecompressionBombsAtTheLimit) {
  const Bytes zeros(16u << 20, 0);
  for (Compression c : {Compression::gzip, Compression::zstd}) {
    const Bytes bomb = compress(zeros, c).value();
    ASSERT_LT(bomb.size(), 200000u);
    auto r = decompress(bomb, c, 1u << 20);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::too_large) << r.error().message;
  }
}

TEST(Compression, ReportsEveryCutStreamAsTruncated) {
  Bytes data;
  std::mt19937 rng(3);
  for (int i = 0; i < 3000; ++i) data.push_back(static_cast<std::uint8_t>(rng() % 16));
  for (Compression c : {Compression::gzip, Compression::zstd}) {
    const Bytes packed = compress(data, c).value();
    for (std::size_t n = 0; n < packed.size(); ++n) {
      auto r = decompress(std::span(packed).first(n), c, 1 << 20);
      ASSERT_FALSE(r.ok()) << n;
      EXPECT_EQ(r.error().code, ErrorCode::truncated)
          << static_cast<int>(c) << " at " << n << ": " << r.error().message;
    }
  }
}

TEST(Compression, RejectsGarbageTrailingBytesAndUnsupportedMethods) {
  for (Compression c : {Compression::gzip, Compression::zstd}) {
    Bytes packed = compress(bytes_of("some bytes"), c).value();
    packed.push_back(0x42);
    EXPECT_FALSE(decompress(packed, c, 1000).ok());
    EXPECT_EQ(decompress(bytes_of("definitely not compressed"), c, 1000).error().code,
              ErrorCode::corrupt);
  }
  EXPECT_EQ(compress(bytes_of("x"), Compression::brotli).error().code, ErrorCode::unsupported);
  EXPECT_EQ(decompress(bytes_of("x"), Compression::unknown, 10).error().code,
            ErrorCode::unsupported);
  EXPECT_EQ(decompress(bytes_of("xyz"), Compression::none, 2).error().code, ErrorCode::too_large);
}

// ---- writer -> reader ---------------------------------------------------------------------------

TEST(Archive, RoundTripsASmallArchiveThroughWriterAndReader) {
  TempDir dir;
  WriterOptions o;
  o.path = dir.path() / "small.pmtiles";
  o.tile_type = TileType::png;
  o.min_zoom = 0;
  o.max_zoom = 3;
  o.bounds.min_lon_e7 = -100;
  o.bounds.center_zoom = 2;
  o.bounds.center_lat_e7 = 55;
  const auto tiles = small_tiles();
  write_archive(dir, tiles, R"({"name":"test"})", o);
  EXPECT_EQ(dir.names(), std::vector<std::string>{"small.pmtiles"});

  auto reader = Reader::open(o.path);
  ASSERT_TRUE(reader.ok()) << reader.error().to_string();
  const Reader& r = **reader;
  EXPECT_EQ(r.metadata_json(), R"({"name":"test"})");
  const Header& h = r.header();
  EXPECT_EQ(h.root_dir_offset, kHeaderSize);
  EXPECT_LE(h.root_dir_offset + h.root_dir_length, 16384u);
  EXPECT_EQ(h.internal_compression, Compression::gzip);
  EXPECT_EQ(h.tile_compression, Compression::zstd);
  EXPECT_EQ(h.tile_type, TileType::png);
  EXPECT_TRUE(h.clustered);
  EXPECT_EQ(h.max_zoom, 3);
  EXPECT_EQ(h.min_lon_e7, -100);
  EXPECT_EQ(h.center_zoom, 2);
  EXPECT_EQ(h.center_lat_e7, 55);
  EXPECT_EQ(h.addressed_tiles, 6u);
  EXPECT_EQ(h.tile_contents, 5u);  // "same" twice
  EXPECT_EQ(h.tile_entries, 5u);   // 1/0/1 and 1/1/1 are ids 2 and 3: one run
  EXPECT_EQ(h.tile_data_offset + h.tile_data_length, r.size());
  EXPECT_EQ(r.size(), fs::file_size(o.path));

  for (const auto& [id, payload] : tiles) {
    auto got = r.get(id);
    ASSERT_TRUE(got.ok()) << id.z << "/" << id.x << "/" << id.y << " " << got.error().to_string();
    EXPECT_EQ(Bytes(got->begin(), got->end()), payload);
  }
  EXPECT_EQ(r.get(TileId{2, 1, 1}).error().code, ErrorCode::not_found);
  EXPECT_EQ(r.get(TileId{9, 0, 0}).error().code, ErrorCode::not_found);
  EXPECT_EQ(r.leaf_directory_count().value(), 0u);
}

TEST(Archive, LargeArchiveSpillsIntoLeafDirectoriesAndReadsBackEveryTile) {
  TempDir dir;
  constexpr std::uint64_t kTiles = 200000;
  std::mt19937 rng(5);
  WriterOptions o;
  o.path = dir.path() / "large.pmtiles";
  auto writer = Writer::create(o).value();
  // Distinct payloads of random length, so the entries do not compress into a 16 KiB root.
  auto payload_of = [](std::uint64_t id, std::size_t extra) {
    Bytes p(8 + extra);
    for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(id >> (8 * i));
    for (std::size_t i = 8; i < p.size(); ++i) p[i] = static_cast<std::uint8_t>(id + i);
    return p;
  };
  std::vector<std::size_t> extra(kTiles);
  for (auto& e : extra) e = rng() % 24;
  std::vector<std::uint64_t> order(kTiles);
  for (std::uint64_t i = 0; i < kTiles; ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  for (std::uint64_t id : order)
    ASSERT_TRUE(writer->add_tile(zxy(id), payload_of(id, extra[id])).ok());
  const WriterStats stats = writer->finish("{}").value();
  EXPECT_EQ(stats.addressed_tiles, kTiles);
  EXPECT_EQ(stats.tile_contents, kTiles);
  EXPECT_EQ(stats.tile_entries, kTiles);
  EXPECT_EQ(stats.file_bytes, fs::file_size(o.path));

  auto reader = Reader::open(o.path).value();
  const Header& h = reader->header();
  EXPECT_LE(h.root_dir_offset + h.root_dir_length, 16384u);
  EXPECT_GT(h.leaf_dirs_length, 0u);
  EXPECT_GT(reader->leaf_directory_count().value(), 1u);

  std::uint64_t count = 0, previous_end = 0;
  ASSERT_TRUE(reader
                  ->for_each_entry([&](const Entry& e) {
                    EXPECT_EQ(e.tile_id, count);
                    EXPECT_EQ(e.offset, previous_end);  // clustered: data in tile-id order
                    previous_end = e.offset + e.length;
                    ++count;
                    return true;
                  })
                  .ok());
  EXPECT_EQ(count, kTiles);
  EXPECT_EQ(previous_end, h.tile_data_length);
  for (std::uint64_t id = 0; id < kTiles; id += 7) {
    auto got = reader->get(zxy(id));
    ASSERT_TRUE(got.ok()) << id;
    ASSERT_EQ(Bytes(got->begin(), got->end()), payload_of(id, extra[id]));
  }
  EXPECT_EQ(reader->get_by_tile_id(kTiles).error().code, ErrorCode::not_found);
}

TEST(Archive, WritesZstdAndUncompressedDirectoriesToo) {
  for (Compression c : {Compression::zstd, Compression::none}) {
    TempDir dir;
    WriterOptions o;
    o.internal_compression = c;
    const auto tiles = small_tiles();
    const fs::path p = write_archive(dir, tiles, "{\"a\":2}", o);
    auto reader = Reader::open(p).value();
    EXPECT_EQ(reader->header().internal_compression, c);
    EXPECT_EQ(reader->metadata_json(), "{\"a\":2}");
    for (const auto& [id, payload] : tiles) {
      auto got = reader->get(id).value();
      EXPECT_EQ(Bytes(got.begin(), got.end()), payload);
    }
  }
}

TEST(Writer, StoresIdenticalPayloadsOnce) {
  TempDir dir;
  WriterOptions o;
  o.path = dir.path() / "dedup.pmtiles";
  auto w = Writer::create(o).value();
  const Bytes ocean(1000, 0x42);
  // Non-consecutive ids (0/0/0, 2/0/0, 2/3/3) share one blob; no run can merge them.
  ASSERT_TRUE(w->add_tile(TileId{2, 3, 3}, ocean).ok());
  ASSERT_TRUE(w->add_tile(TileId{0, 0, 0}, ocean).ok());
  ASSERT_TRUE(w->add_tile(TileId{1, 1, 0}, bytes_of("land")).ok());
  ASSERT_TRUE(w->add_tile(TileId{2, 0, 0}, ocean).ok());
  const WriterStats s = w->finish("{}").value();
  EXPECT_EQ(s.addressed_tiles, 4u);
  EXPECT_EQ(s.tile_contents, 2u);
  EXPECT_EQ(s.tile_entries, 4u);
  EXPECT_EQ(s.tile_bytes, 1004u);

  auto r = Reader::open(o.path).value();
  EXPECT_EQ(r->header().tile_data_length, 1004u);
  auto a = r->find_entry(zxy_to_tile_id(0, 0, 0)).value();
  auto b = r->find_entry(zxy_to_tile_id(2, 3, 3)).value();
  EXPECT_EQ(a.offset, b.offset);  // the very same bytes in the file
  EXPECT_EQ(a.length, b.length);
  EXPECT_EQ(r->get(TileId{2, 3, 3}).value(), ocean);
  // The blob is placed where its first tile along the curve (id 0) is: first in the data.
  EXPECT_EQ(a.offset, 0u);
}

TEST(Writer, KeepsPayloadsThatDifferOnlyAfterTheirFirstBytesApart) {
  TempDir dir;
  std::map<TileId, Bytes> tiles;
  Bytes a(200000, 1), b(200000, 1);
  b.back() = 2;
  tiles[TileId{1, 0, 0}] = a;
  tiles[TileId{1, 1, 1}] = b;
  auto r = Reader::open(write_archive(dir, tiles)).value();
  EXPECT_EQ(r->header().tile_contents, 2u);
  auto got = r->get(TileId{1, 1, 1}).value();
  EXPECT_EQ(Bytes(got.begin(), got.end()), b);
}

TEST(Writer, MergesConsecutiveIdenticalTilesIntoOneRun) {
  TempDir dir;
  std::map<TileId, Bytes> tiles;
  // ids 5..20 (all of zoom 2) plus id 21 (3/0/0) carry the same bytes; id 22 differs.
  for (std::uint64_t id = 5; id <= 21; ++id) tiles[zxy(id)] = bytes_of("blank");
  tiles[zxy(22)] = bytes_of("other");
  auto r = Reader::open(write_archive(dir, tiles)).value();
  EXPECT_EQ(r->header().addressed_tiles, 18u);
  EXPECT_EQ(r->header().tile_entries, 2u);
  EXPECT_EQ(r->header().tile_contents, 2u);
  std::vector<Entry> entries;
  ASSERT_TRUE(r->for_each_entry([&](const Entry& e) {
                 entries.push_back(e);
                 return true;
               }).ok());
  EXPECT_EQ(entries, (std::vector<Entry>{{5, 0, 5, 17}, {22, 5, 5, 1}}));
  for (std::uint64_t id = 5; id <= 21; ++id) EXPECT_TRUE(r->get_by_tile_id(id).ok()) << id;
  EXPECT_EQ(r->get_by_tile_id(4).error().code, ErrorCode::not_found);
}

TEST(Writer, AcceptsTilesFromManyThreadsInAnyOrder) {
  TempDir dir;
  WriterOptions o;
  o.path = dir.path() / "mt.pmtiles";
  auto w = Writer::create(o).value();
  constexpr int kThreads = 4, kPerThread = 3000;
  std::vector<std::thread> threads;
  std::atomic<int> failures{0};
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < kPerThread; ++i) {
        const std::uint64_t id = static_cast<std::uint64_t>(i) * kThreads + t;
        // Every tenth tile is a shared "empty" payload, the rest unique.
        const Bytes p = id % 10 == 0 ? bytes_of("empty") : bytes_of("tile " + std::to_string(id));
        if (!w->add_tile(zxy(id), p).ok()) ++failures;
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(failures.load(), 0);
  const WriterStats s = w->finish("{}").value();
  EXPECT_EQ(s.addressed_tiles, std::uint64_t{kThreads * kPerThread});
  EXPECT_EQ(s.tile_contents, std::uint64_t{kThreads * kPerThread - kThreads * kPerThread / 10 + 1});
  auto r = Reader::open(o.path).value();
  for (std::uint64_t id = 0; id < kThreads * kPerThread; ++id) {
    auto got = r->get_by_tile_id(id).value();
    const std::string want = id % 10 == 0 ? "empty" : "tile " + std::to_string(id);
    ASSERT_EQ(std::string(got.begin(), got.end()), want);
  }
}

TEST(Writer, RejectsDuplicateTilesInvalidCoordinatesAndEmptyPayloads) {
  TempDir dir;
  WriterOptions o;
  o.path = dir.path() / "x.pmtiles";
  auto w = Writer::create(o).value();
  ASSERT_TRUE(w->add_tile(TileId{1, 1, 1}, bytes_of("a")).ok());
  EXPECT_EQ(w->add_tile(TileId{1, 1, 1}, bytes_of("b")).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(w->add_tile(TileId{1, 2, 0}, bytes_of("b")).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(w->add_tile(TileId{32, 0, 0}, bytes_of("b")).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(w->add_tile(TileId{2, 0, 0}, Bytes{}).error().code, ErrorCode::invalid_argument);
  ASSERT_TRUE(w->finish("{}").ok());
  EXPECT_EQ(w->add_tile(TileId{2, 0, 0}, bytes_of("late")).error().code,
            ErrorCode::invalid_argument);
  EXPECT_FALSE(w->finish("{}").ok());
  auto r = Reader::open(o.path).value();
  EXPECT_EQ(r->header().addressed_tiles, 1u);
}

TEST(Writer, RejectsBadOptions) {
  TempDir dir;
  WriterOptions o;
  EXPECT_EQ(Writer::create(o).error().code, ErrorCode::invalid_argument);  // no path
  o.path = dir.path();
  EXPECT_EQ(Writer::create(o).error().code, ErrorCode::invalid_argument);  // a directory
  o.path = dir.path() / "a.pmtiles";
  o.internal_compression = Compression::brotli;
  EXPECT_EQ(Writer::create(o).error().code, ErrorCode::invalid_argument);
  o.internal_compression = Compression::gzip;
  o.min_zoom = 5;
  o.max_zoom = 4;
  EXPECT_EQ(Writer::create(o).error().code, ErrorCode::invalid_argument);
  EXPECT_TRUE(dir.names().empty());
}

TEST(Writer, DroppedOrAbortedWriterLeavesNoFiles) {
  TempDir dir;
  {
    WriterOptions o;
    o.path = dir.path() / "dropped.pmtiles";
    auto w = Writer::create(o).value();
    ASSERT_TRUE(w->add_tile(TileId{0, 0, 0}, Bytes(100000, 7)).ok());
  }
  EXPECT_TRUE(dir.names().empty());
  {
    WriterOptions o;
    o.path = dir.path() / "aborted.pmtiles";
    auto w = Writer::create(o).value();
    ASSERT_TRUE(w->add_tile(TileId{0, 0, 0}, Bytes(10, 7)).ok());
    w->abort();
    EXPECT_FALSE(w->finish("{}").ok());
    EXPECT_TRUE(dir.names().empty());
  }
}

TEST(Writer, LeavesTheDestinationUntouchedUntilFinishSucceeds) {
  TempDir dir;
  const fs::path dest = dir.path() / "a.pmtiles";
  std::ofstream(dest) << "previous archive";
  WriterOptions o;
  o.path = dest;
  {
    auto w = Writer::create(o).value();
    ASSERT_TRUE(w->add_tile(TileId{0, 0, 0}, bytes_of("new")).ok());
    EXPECT_EQ(read_bytes(dest), bytes_of("previous archive"));
  }
  EXPECT_EQ(read_bytes(dest), bytes_of("previous archive"));
  write_archive(dir, {{TileId{0, 0, 0}, bytes_of("new")}}, "{}", o);
  auto reader = Reader::open(dest).value();  // the tile is a view into the reader's mapping
  auto got = reader->get(TileId{0, 0, 0}).value();
  EXPECT_EQ(Bytes(got.begin(), got.end()), bytes_of("new"));
  EXPECT_EQ(dir.names(), std::vector<std::string>{"a.pmtiles"});
}

TEST(Writer, RefusesToFinishAnArchiveWithoutTiles) {
  TempDir dir;
  WriterOptions o;
  o.path = dir.path() / "empty.pmtiles";
  auto w = Writer::create(o).value();
  EXPECT_EQ(w->finish("{}").error().code, ErrorCode::invalid_argument);
  EXPECT_TRUE(dir.names().empty());
}

TEST(Writer, ReportsAnIoErrorNamingTheUnwritablePath) {
  WriterOptions o;
  o.path = "/nonexistent-vts-dir/sub/a.pmtiles";
  auto r = Writer::create(o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::io);
  EXPECT_NE(r.error().message.find("/nonexistent-vts-dir/sub/"), std::string::npos);
  EXPECT_NE(r.error().message.find("No such file or directory"), std::string::npos)
      << r.error().message;
  o.path = "/proc/a.pmtiles";  // not writable even by root
  EXPECT_EQ(Writer::create(o).error().code, ErrorCode::io);
}

TEST(Writer, FailingWriteDuringFinishReturnsIoErrorAndLeavesNoFiles) {
  // RLIMIT_FSIZE makes writes past the limit fail with EFBIG, as a full disk fails with ENOSPC.
  TempDir dir;
  WriterOptions o;
  o.path = dir.path() / "full.pmtiles";
  auto w = Writer::create(o).value();
  std::mt19937 rng(1);
  for (std::uint64_t id = 0; id < 64; ++id) {
    Bytes p(8192);
    for (auto& b : p) b = static_cast<std::uint8_t>(rng());
    ASSERT_TRUE(w->add_tile(zxy(id), p).ok());
  }
  struct sigaction ignore {
  }, previous{};
  ignore.sa_handler = SIG_IGN;
  ASSERT_EQ(::sigaction(SIGXFSZ, &ignore, &previous), 0);
  rlimit old_limit{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  rlimit low = old_limit;
  low.rlim_cur = 100000;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &low), 0);
  auto result = w->finish("{}");
  ::setrlimit(RLIMIT_FSIZE, &old_limit);
  ::sigaction(SIGXFSZ, &previous, nullptr);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, ErrorCode::io);
  EXPECT_NE(result.error().message.find(dir.path().string()), std::string::npos)
      << result.error().message;
  EXPECT_TRUE(dir.names().empty());
}

// ---- reader: files and hostile archives ---------------------------------------------------------

TEST(Reader, ReportsMissingEmptyAndNonArchiveFiles) {
  TempDir dir;
  EXPECT_EQ(Reader::open(dir.path() / "missing.pmtiles").error().code, ErrorCode::not_found);
  std::ofstream(dir.path() / "empty.pmtiles").close();
  EXPECT_EQ(Reader::open(dir.path() / "empty.pmtiles").error().code, ErrorCode::truncated);
  std::ofstream(dir.path() / "text.pmtiles") << std::string(200, 'x');
  auto r = Reader::open(dir.path() / "text.pmtiles");
  EXPECT_EQ(r.error().code, ErrorCode::corrupt);
  EXPECT_NE(r.error().message.find("text.pmtiles"), std::string::npos);
  EXPECT_EQ(Reader::open(dir.path()).error().code, ErrorCode::invalid_argument);
}

TEST(Reader, ReadsAHandAssembledTwoLevelArchive) {
  const Bytes file = assemble(two_level_parts());
  auto r = Reader::open_bytes(file).value();
  auto tile = [&](std::uint64_t id) {
    auto got = r->get_by_tile_id(id);
    return got ? std::string(got->begin(), got->end()) : std::string("-");
  };
  EXPECT_EQ(tile(1), "aaaa");
  EXPECT_EQ(tile(3), "cccc");
  EXPECT_EQ(tile(4), "cccc");
  EXPECT_EQ(tile(5), "-");
  EXPECT_EQ(tile(0), "-");
  EXPECT_EQ(tile(11), "eeee");
  EXPECT_EQ(tile(22), "ffff");
  EXPECT_EQ(tile(23), "-");
  EXPECT_EQ(r->leaf_directory_count().value(), 2u);
  EXPECT_EQ(r->metadata_json(), "{\"k\":1}");
  int n = 0;
  ASSERT_TRUE(r->for_each_entry([&](const Entry&) { return ++n < 4; }).ok());
  EXPECT_EQ(n, 4);  // stopped by the visitor, which is not an error
}

TEST(Reader, RejectsArchiveTruncatedAtAnyByte) {
  TempDir dir;
  const Bytes written = read_bytes(write_archive(dir, small_tiles()));
  for (const Bytes& file : {written, assemble(two_level_parts())}) {
    for (std::size_t n = 0; n < file.size(); ++n) {
      auto r = Reader::open_bytes(std::span(file).first(n));
      ASSERT_FALSE(r.ok()) << n;
      EXPECT_TRUE(r.error().code == ErrorCode::truncated || r.error().code == ErrorCode::corrupt)
          << n << ": " << r.error().to_string();
    }
    EXPECT_TRUE(Reader::open_bytes(file).ok());
  }
}

TEST(Reader, SurvivesEveryBitFlip) {
  TempDir dir;
  const Bytes written = read_bytes(write_archive(dir, small_tiles()));
  for (const Bytes& file : {written, assemble(two_level_parts())}) {
    for (std::size_t bit = 0; bit < file.size() * 8; ++bit) {
      Bytes flipped = file;
      flipped[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
      exercise(flipped);
    }
  }
}

TEST(Reader, RejectsSectionsExtendingPastTheEndOfTheFile) {
  const Parts p = two_level_parts();
  const Header good = header_for(p);
  for (int section = 0; section < 4; ++section) {
    for (std::uint64_t bad_offset : {std::uint64_t{1000}, ~std::uint64_t{0} - 3}) {
      Header h = good;
      std::uint64_t* offsets[] = {&h.root_dir_offset, &h.metadata_offset, &h.leaf_dirs_offset,
                                  &h.tile_data_offset};
      *offsets[section] = bad_offset;
      const Bytes file = assemble(p, h);  // must outlive the reader
      auto r = Reader::open_bytes(file);
      ASSERT_FALSE(r.ok());
      EXPECT_EQ(r.error().code, ErrorCode::truncated) << r.error().message;
      EXPECT_NE(r.error().message.find("extends past the end"), std::string::npos);
    }
    Header h = good;
    std::uint64_t* lengths[] = {&h.root_dir_length, &h.metadata_length, &h.leaf_dirs_length,
                                &h.tile_data_length};
    *lengths[section] = ~std::uint64_t{0};
    EXPECT_EQ(Reader::open_bytes(assemble(p, h)).error().code, ErrorCode::truncated);
  }
  Header h = good;
  h.root_dir_offset = 0;  // a "directory" inside the header
  EXPECT_EQ(Reader::open_bytes(assemble(p, h)).error().code, ErrorCode::corrupt);
}

TEST(Reader, RejectsALeafDirectoryThatPointsToItself) {
  Parts p;
  p.data = bytes_of("tile");
  // The leaf holds one leaf pointer to offset 0, its own offset; the root points at it too.
  Bytes leaf = serialize_directory(std::vector<Entry>{{0, 0, 5, 0}});
  ASSERT_EQ(leaf.size(), 5u);
  p.leaves = leaf;
  p.root = serialize_directory(std::vector<Entry>{{0, 0, 5, 0}});
  const Bytes file = assemble(p);  // must outlive the reader
  auto r = Reader::open_bytes(file).value();
  auto got = r->get_by_tile_id(0);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, ErrorCode::corrupt);
  EXPECT_NE(got.error().message.find("directory cycle or too deep"), std::string::npos)
      << got.error().message;
  EXPECT_EQ(r->for_each_entry([](const Entry&) { return true; }).error().code, ErrorCode::corrupt);
  EXPECT_EQ(r->leaf_directory_count().error().code, ErrorCode::corrupt);
}

// A chain of `leaf_levels` leaf directories above one tile entry for tile id 5.
Bytes leaf_chain(int leaf_levels) {
  Parts p;
  p.data = bytes_of("tile");
  Entry next{5, 0, 4, 1};
  for (int i = 0; i < leaf_levels; ++i) {
    const Bytes dir = serialize_directory(std::vector<Entry>{next});
    next = Entry{5, p.leaves.size(), static_cast<std::uint32_t>(dir.size()), 0};
    p.leaves.insert(p.leaves.end(), dir.begin(), dir.end());
  }
  p.root = serialize_directory(std::vector<Entry>{next});
  return assemble(p);
}

TEST(Reader, FollowsLeavesUpToTheDepthLimitAndNoFurther) {
  for (int leaf_levels = 0; leaf_levels < kMaxDirectoryDepth; ++leaf_levels) {
    const Bytes file = leaf_chain(leaf_levels);
    auto r = Reader::open_bytes(file).value();
    EXPECT_TRUE(r->get_by_tile_id(5).ok()) << leaf_levels;
    EXPECT_EQ(r->leaf_directory_count().value(), std::uint64_t(leaf_levels));
  }
  const Bytes file = leaf_chain(kMaxDirectoryDepth);
  auto r = Reader::open_bytes(file).value();
  auto got = r->get_by_tile_id(5);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, ErrorCode::corrupt);
  EXPECT_NE(got.error().message.find("too deep"), std::string::npos);
  EXPECT_EQ(r->for_each_entry([](const Entry&) { return true; }).error().code, ErrorCode::corrupt);
}

TEST(Reader, RejectsALeafReferencedTwiceWhenWalking) {
  Parts p = two_level_parts();
  const std::vector<Entry> leaves = parse_directory(p.root).value();
  // Both root pointers lead to the first leaf: lookups of ids 1..4 still work, a walk refuses.
  p.root = serialize_directory(std::vector<Entry>{leaves[0], {10, 0, leaves[0].length, 0}});
  const Bytes file = assemble(p);  // must outlive the reader
  auto r = Reader::open_bytes(file).value();
  EXPECT_TRUE(r->get_by_tile_id(2).ok());
  EXPECT_EQ(r->for_each_entry([](const Entry&) { return true; }).error().code, ErrorCode::corrupt);
}

TEST(Reader, NamesALeafPointerBeyondTheLeafSection) {
  Parts p = two_level_parts();
  p.root = serialize_directory(std::vector<Entry>{{1, 123, 456, 0}});
  p.leaves.resize(400);
  const Bytes file = assemble(p);  // must outlive the reader
  auto r = Reader::open_bytes(file).value();
  auto got = r->get_by_tile_id(1);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, ErrorCode::corrupt);
  EXPECT_EQ(got.error().message,
            "leaf directory at offset 123 length 456 extends past the leaf section (size 400)");
}

TEST(Reader, RejectsATileEntryBeyondTheTileData) {
  Parts p;
  p.data = bytes_of("0123456789");
  p.root = serialize_directory(std::vector<Entry>{{0, 0, 10, 1}, {1, 5, 6, 1}});
  const Bytes file = assemble(p);  // must outlive the reader
  auto r = Reader::open_bytes(file).value();
  EXPECT_TRUE(r->get_by_tile_id(0).ok());
  auto got = r->get_by_tile_id(1);
  EXPECT_EQ(got.error().code, ErrorCode::corrupt);
  EXPECT_NE(got.error().message.find("extends past the tile data section (size 10)"),
            std::string::npos);
  EXPECT_EQ(r->for_each_entry([](const Entry&) { return true; }).error().code, ErrorCode::corrupt);
}

TEST(Reader, StopsAGzipBombInTheRootOrALeafDirectory) {
  // 16 MiB of zeros: a directory of zero entries followed by garbage, after decompression.
  const Bytes bomb = compress(Bytes(16u << 20, 0), Compression::gzip).value();
  ReaderOptions small;
  small.max_directory_bytes = 1u << 20;
  {
    Parts p;
    p.compression = Compression::gzip;
    p.root = bomb;
    p.data = bytes_of("x");
    const Bytes file = assemble(p);  // must outlive the reader
    auto r = Reader::open_bytes(file, small);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::too_large);
    EXPECT_NE(r.error().message.find("root directory"), std::string::npos);
  }
  {
    Parts p;
    p.compression = Compression::gzip;
    p.leaves = bomb;
    p.root = compress(serialize_directory(
                          std::vector<Entry>{{0, 0, static_cast<std::uint32_t>(bomb.size()), 0}}),
                      Compression::gzip)
                 .value();
    p.data = bytes_of("x");
    const Bytes file = assemble(p);  // must outlive the reader
    auto r = Reader::open_bytes(file, small).value();
    EXPECT_EQ(r->get_by_tile_id(0).error().code, ErrorCode::too_large)
        << r->get_by_tile_id(0).error().message;
    EXPECT_EQ(r->for_each_entry([](const Entry&) { return true; }).error().code,
              ErrorCode::too_large);
  }
  {
    Parts p;
    p.compression = Compression::gzip;
    p.root =
        compress(serialize_directory(std::vector<Entry>{{0, 0, 1, 1}}), Compression::gzip).value();
    p.metadata = bomb;
    p.data = bytes_of("x");
    ReaderOptions o;
    o.max_metadata_bytes = 1000;
    EXPECT_EQ(Reader::open_bytes(assemble(p), o).error().code, ErrorCode::too_large);
  }
}

TEST(Reader, RejectsAHugeEntryCountWithoutAllocatingIt) {
  Parts p;
  p.root = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x7f, 1, 1, 1, 1};
  p.data = bytes_of("x");
  const Bytes file = assemble(p);  // must outlive the reader
  auto r = Reader::open_bytes(file);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::too_large);
}

TEST(Reader, RejectsUnsupportedInternalCompression) {
  Parts p = two_level_parts();
  p.compression = Compression::brotli;
  EXPECT_EQ(Reader::open_bytes(assemble(p)).error().code, ErrorCode::unsupported);
}

TEST(Reader, ValidatesTileCoordinatesBeforeLookingUp) {
  TempDir dir;
  auto r = Reader::open(write_archive(dir, small_tiles())).value();
  EXPECT_EQ(r->get(TileId{32, 0, 0}).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(r->get(TileId{2, 4, 0}).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(r->get(TileId{2, 0, 4}).error().code, ErrorCode::invalid_argument);
  EXPECT_EQ(r->get(TileId{31, 0x7fffffff, 0x7fffffff}).error().code, ErrorCode::not_found);
}

TEST(Reader, ServesConcurrentLookupsThroughATinyLeafCache) {
  TempDir dir;
  WriterOptions o;
  o.path = dir.path() / "leafy.pmtiles";
  o.internal_compression = Compression::none;  // a 16 KiB uncompressed root holds ~3000 entries
  std::map<TileId, Bytes> tiles;
  for (std::uint64_t id = 0; id < 20000; ++id)
    tiles[zxy(id)] = bytes_of(std::to_string(id) + std::string(id % 13, '.'));
  write_archive(dir, tiles, "{}", o);
  ReaderOptions ro;
  ro.leaf_cache_entries = 2;
  auto r = Reader::open(o.path, ro).value();
  ASSERT_GT(r->leaf_directory_count().value(), 2u);
  std::atomic<int> bad{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937 rng(t);
      for (int i = 0; i < 1000; ++i) {
        const std::uint64_t id = rng() % 20000;
        auto got = r->get_by_tile_id(id);
        if (!got || std::string(got->begin(), got->end()) !=
                        std::to_string(id) + std::string(id % 13, '.')) {
          ++bad;
        }
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(bad.load(), 0);
}

// A directory of n one-tile entries (ids first.., all at offset 0, length 1), gzip-compressed:
// a few KiB however large n is.
Bytes uniform_directory(std::uint64_t first, std::size_t n) {
  std::vector<Entry> entries(n);
  for (std::size_t i = 0; i < n; ++i) entries[i] = Entry{first + i, 0, 1, 1};
  return compress(serialize_directory(entries), Compression::gzip).value();
}

TEST(Directory, CapsEntriesPerDirectoryFarAboveWhatWritersMake) {
  // A writer makes 4096 per leaf (ours) or some 10^5 (go-pmtiles' planet leaves).
  static_assert(kMaxDirectoryEntries >= 1000 * 1024);
  std::vector<Entry> entries(kMaxDirectoryEntries + 1);
  for (std::size_t i = 0; i < entries.size(); ++i) entries[i] = Entry{i, 0, 1, 1};
  const Bytes over = serialize_directory(entries);
  Result<std::vector<Entry>> got = parse_directory(over);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, ErrorCode::too_large);
  EXPECT_NE(got.error().message.find("entries per directory"), std::string::npos)
      << got.error().message;
  entries.pop_back();
  EXPECT_EQ(parse_directory(serialize_directory(entries)).value().size(), kMaxDirectoryEntries);
}

TEST(DirectoryCache, EvictsTheLeastRecentlyUsedToStayWithinItsBytes) {
  auto dir = [](std::size_t n) {
    return std::make_shared<const std::vector<Entry>>(n, Entry{0, 0, 1, 1});
  };
  const std::size_t each = DirectoryCache::cost(*dir(1000));
  DirectoryCache cache(3 * each);
  for (std::uint64_t i = 0; i < 3; ++i) cache.insert(i, 10, dir(1000));
  EXPECT_EQ(cache.size(), 3u);
  EXPECT_EQ(cache.bytes(), 3 * each);
  ASSERT_NE(cache.find(0, 10), nullptr);  // 0 is now the most recently used; 1 the least
  EXPECT_EQ(cache.find(0, 11), nullptr);  // the length is part of the key
  cache.insert(3, 10, dir(1000));
  EXPECT_EQ(cache.find(1, 10), nullptr);
  EXPECT_NE(cache.find(0, 10), nullptr);
  EXPECT_NE(cache.find(3, 10), nullptr);
  EXPECT_LE(cache.bytes(), 3 * each);
  // One directory costing more than the whole budget is handed back but never kept.
  const Directory big = dir(4000);
  EXPECT_EQ(cache.insert(9, 10, big), big);
  EXPECT_EQ(cache.find(9, 10), nullptr);
  EXPECT_EQ(cache.size(), 3u);
}

TEST(DirectoryCache, KeepsTheFirstCopyOfADirectoryDecodedTwice) {
  DirectoryCache cache(1u << 20, 2);
  const Directory first = std::make_shared<const std::vector<Entry>>(1, Entry{1, 0, 1, 1});
  const Directory second = std::make_shared<const std::vector<Entry>>(1, Entry{1, 0, 1, 1});
  EXPECT_EQ(cache.insert(5, 7, first), first);
  EXPECT_EQ(cache.insert(5, 7, second), first);
  cache.insert(6, 7, second);
  cache.insert(8, 7, second);  // over the count limit of 2: 5 goes
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_EQ(cache.find(5, 7), nullptr);
}

TEST(Reader, RefusesALeafOverTheEntryCapAsTooLarge) {
  // Old readers took 4M entries per leaf: 96 MiB each from a few KiB of gzip.
  Parts p;
  p.compression = Compression::gzip;
  p.leaves = uniform_directory(0, kMaxDirectoryEntries + 1);
  p.root = compress(serialize_directory(
                        std::vector<Entry>{{0, 0, static_cast<std::uint32_t>(p.leaves.size()), 0}}),
                    Compression::gzip)
               .value();
  p.data = bytes_of("x");
  const Bytes file = assemble(p);  // must outlive the reader
  auto r = Reader::open_bytes(file).value();
  Result<std::vector<std::uint8_t>> got = r->get_by_tile_id(7);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, ErrorCode::too_large);
  EXPECT_NE(got.error().message.find("entries per directory"), std::string::npos)
      << got.error().message;
  EXPECT_NE(got.error().message.find("leaf directory at offset 0"), std::string::npos)
      << got.error().message;
}

TEST(Reader, RefusesARootOverTheEntryCapAsTooLarge) {
  Parts p;
  p.compression = Compression::gzip;
  p.root = uniform_directory(0, kMaxDirectoryEntries + 1);
  p.data = bytes_of("x");
  const Bytes file = assemble(p);  // must outlive the reader
  auto r = Reader::open_bytes(file);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::too_large);
  EXPECT_NE(r.error().message.find("root directory"), std::string::npos) << r.error().message;
}

TEST(Reader, ReadsAnArchiveWithoutMetadata) {
  Parts p = two_level_parts();
  p.metadata.clear();
  const Bytes file = assemble(p);  // must outlive the reader
  auto r = Reader::open_bytes(file).value();
  EXPECT_EQ(r->metadata_json(), "");
  EXPECT_TRUE(r->get_by_tile_id(20).ok());
}

}  // namespace
}  // namespace vts::archive
