// Parts and their merge (pmtiles_part.hpp): the merged archive is the Writer's archive of the same
// tiles byte for byte, whatever the partition; damaged, missing and overlapping parts are named.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "mixed_payloads.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/archive/pmtiles_part.hpp"
#include "vts/test/files.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts::archive {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

using vts::test::read_bytes;

void flip_byte(const fs::path& p, std::uint64_t offset) {
  std::fstream f(p, std::ios::binary | std::ios::in | std::ios::out);
  f.seekg(static_cast<std::streamoff>(offset));
  char c = 0;
  f.read(&c, 1);
  c = static_cast<char>(c ^ 0x5a);
  f.seekp(static_cast<std::streamoff>(offset));
  f.write(&c, 1);
}

class PartTempDir : public vts::test::TempDir {
 public:
  PartTempDir() : vts::test::TempDir("vts-part-test") {}
};

// A pyramid of levels 0..max_z with every kind of payload the layout rule treats differently:
// unique large ones, small ones repeated far apart (uniform tiles), large ones repeated in runs
// (consecutive ids) and far apart, and a run crossing sub-pyramid boundaries.
std::map<std::uint64_t, Bytes> make_tiles(int max_z, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::map<std::uint64_t, Bytes> tiles;
  const Bytes big_repeat(3000, 7);
  for (int z = 0; z <= max_z; ++z) {
    const std::uint32_t n = 1u << z;
    for (std::uint32_t y = 0; y < n; ++y)
      for (std::uint32_t x = 0; x < n; ++x) {
        const std::uint64_t id = zxy_to_tile_id(static_cast<std::uint8_t>(z), x, y);
        if (auto b = vts::archive::test::mixed_payload(rng, tiles, id)) tiles[id] = std::move(*b);
      }
  }
  // A long run of one large payload across the middle of the finest level.
  const std::uint64_t mid = zxy_to_tile_id(static_cast<std::uint8_t>(max_z), 0, 0) +
                            (std::uint64_t{1} << (2 * max_z)) / 2 - 20;
  for (std::uint64_t id = mid; id < mid + 40; ++id) tiles[id] = big_repeat;
  return tiles;
}

WriterOptions archive_options(const fs::path& path, int max_z) {
  WriterOptions o;
  o.path = path;
  o.max_zoom = static_cast<std::uint8_t>(max_z);
  return o;
}

fs::path write_single(const fs::path& dir, const std::map<std::uint64_t, Bytes>& tiles, int max_z) {
  const fs::path out = dir / "single.pmtiles";
  auto w = Writer::create(archive_options(out, max_z)).value();
  // In reverse order: the writer sorts.
  for (auto it = tiles.rbegin(); it != tiles.rend(); ++it)
    EXPECT_TRUE(w->add_tile(tile_id_to_zxy(it->first).value(), it->second));
  EXPECT_TRUE(w->finish("{\"name\":\"t\"}"));
  return out;
}

// Cuts the tiles into the sub-pyramids under every tile of `split` plus the apex (levels above).
std::vector<fs::path> write_parts(const fs::path& dir, const std::map<std::uint64_t, Bytes>& tiles,
                                  int max_z, int split) {
  std::vector<fs::path> parts;
  const auto write = [&](const std::string& name, const std::vector<std::uint64_t>& ids) {
    const fs::path p = dir / name;
    auto w = PartWriter::create(p).value();
    for (std::uint64_t id : ids) EXPECT_TRUE(w->add_tile(tile_id_to_zxy(id).value(), tiles.at(id)));
    const Bytes attachment{1, 2, 3};
    EXPECT_TRUE(w->finish(attachment, "{\"part\":\"" + name + "\"}"));
    parts.push_back(p);
  };
  std::vector<std::uint64_t> apex;
  for (const auto& [id, b] : tiles)
    if (tile_id_to_zxy(id)->z < split) apex.push_back(id);
  if (!apex.empty()) write("apex.part", apex);
  const std::uint32_t n = 1u << split;
  for (std::uint32_t y = 0; y < n; ++y)
    for (std::uint32_t x = 0; x < n; ++x) {
      std::vector<std::uint64_t> ids;
      for (int z = split; z <= max_z; ++z) {
        const TileIdRange r = subtree_tile_ids(TileId{static_cast<std::uint8_t>(split), x, y},
                                               static_cast<std::uint8_t>(z));
        for (auto it = tiles.lower_bound(r.first); it != tiles.end() && it->first <= r.last; ++it)
          ids.push_back(it->first);
      }
      write("shard-" + std::to_string(x) + "-" + std::to_string(y) + ".part", ids);
    }
  return parts;
}

Result<WriterStats> merge(const std::vector<fs::path>& parts, const fs::path& out, int max_z) {
  MergeOptions m;
  m.parts.assign(parts.begin(), parts.end());
  std::reverse(m.parts.begin(), m.parts.end());  // any order
  m.archive = archive_options(out, max_z);
  m.metadata_json = "{\"name\":\"t\"}";
  return merge_parts(m);
}

TEST(Merge, WritesTheWritersArchiveByteForByteWhateverThePartition) {
  PartTempDir dir;
  constexpr int kMaxZ = 6;
  const auto tiles = make_tiles(kMaxZ, 11);
  const Bytes single = read_bytes(write_single(dir.path(), tiles, kMaxZ));
  for (int split : {0, 1, 2, 3}) {
    SCOPED_TRACE("split level " + std::to_string(split));
    const fs::path sub = dir.path() / ("split" + std::to_string(split));
    fs::create_directories(sub);
    const auto parts = write_parts(sub, tiles, kMaxZ, split);
    auto stats = merge(parts, sub / "merged.pmtiles", kMaxZ);
    ASSERT_TRUE(stats) << stats.error().message;
    EXPECT_EQ(stats->addressed_tiles, tiles.size());
    EXPECT_TRUE(read_bytes(sub / "merged.pmtiles") == single);
  }
}

TEST(Merge, FollowsTheLayoutRuleForRepeatedPayloads) {
  PartTempDir dir;
  std::map<std::uint64_t, Bytes> tiles;
  const Bytes small(100, 9), large(5000, 4);
  // Level 3: small far apart (stored once), large far apart (twice), large in a run (once).
  tiles[zxy_to_tile_id(3, 0, 0)] = small;
  tiles[zxy_to_tile_id(3, 7, 7)] = small;
  tiles[zxy_to_tile_id(3, 0, 1)] = large;
  tiles[zxy_to_tile_id(3, 6, 7)] = large;
  ASSERT_LT(zxy_to_tile_id(3, 0, 1) + 1, zxy_to_tile_id(3, 6, 7));
  tiles[zxy_to_tile_id(3, 0, 1) + 1] = Bytes(2000, 6);  // between the two: they are far apart
  const std::uint64_t run = zxy_to_tile_id(2, 1, 1);
  for (std::uint64_t id = run; id < run + 3; ++id) tiles[id] = Bytes(4000, 5);
  const fs::path out = write_single(dir.path(), tiles, 3);
  auto r = Reader::open(out).value();
  // small, large twice, the one between, the run's payload
  EXPECT_EQ(r->header().tile_contents, 5u);
  EXPECT_EQ(r->header().tile_data_length, 100u + 5000u * 2 + 2000u + 4000u);
  EXPECT_EQ(r->header().tile_entries, 6u);  // the run of three is one entry
  for (const auto& [id, b] : tiles) EXPECT_EQ(r->get_by_tile_id(id).value(), b);
  const auto parts = write_parts(dir.path(), tiles, 3, 1);
  ASSERT_TRUE(merge(parts, dir.path() / "m.pmtiles", 3));
  EXPECT_TRUE(read_bytes(dir.path() / "m.pmtiles") == read_bytes(out));
}

TEST(Merge, LaysOutLeavesOfAtMost4096EntriesThatReadersWalk) {
  PartTempDir dir;
  std::map<std::uint64_t, Bytes> tiles;
  // 3 x 4096 + 5 distinct tiles of level 7: more than a root-only archive may hold.
  const std::uint64_t first = zxy_to_tile_id(7, 0, 0);
  for (std::uint64_t i = 0; i < 3 * 4096 + 5; ++i) {
    Bytes b(8);
    for (int k = 0; k < 8; ++k)
      b[static_cast<std::size_t>(k)] = static_cast<std::uint8_t>(i >> (8 * k));
    tiles[first + i] = b;
  }
  const fs::path out = write_single(dir.path(), tiles, 7);
  auto r = Reader::open(out).value();
  EXPECT_EQ(r->leaf_directory_count().value(), 4u);
  std::uint64_t n = 0;
  ASSERT_TRUE(r->for_each_entry([&](const Entry&) { return ++n, true; }));
  EXPECT_EQ(n, tiles.size());
  for (std::uint64_t i = 0; i < tiles.size(); i += 997)
    EXPECT_EQ(r->get_by_tile_id(first + i).value(), tiles.at(first + i));
  const auto parts = write_parts(dir.path(), tiles, 7, 2);
  ASSERT_TRUE(merge(parts, dir.path() / "m.pmtiles", 7));
  EXPECT_TRUE(read_bytes(dir.path() / "m.pmtiles") == read_bytes(out));
}

TEST(Part, SameTilesGiveTheSameBytesAndItsInfoReadsBack) {
  PartTempDir dir;
  const auto tiles = make_tiles(4, 3);
  const auto a = write_parts(dir.path() / "", tiles, 4, 0);
  const Bytes first = read_bytes(a.back());
  fs::remove(a.back());
  const auto b = write_parts(dir.path() / "", tiles, 4, 0);
  EXPECT_TRUE(read_bytes(b.back()) == first);
  auto info = read_part_info(b.back());
  ASSERT_TRUE(info) << info.error().message;
  EXPECT_EQ(info->tiles, tiles.size());
  EXPECT_EQ(info->first_tile_id, tiles.begin()->first);
  EXPECT_EQ(info->last_tile_id, tiles.rbegin()->first);
  EXPECT_EQ(info->segments.size(), 5u);  // levels 0..4
  EXPECT_EQ(info->manifest_json, "{\"part\":\"shard-0-0.part\"}");
  EXPECT_EQ(info->attachment, (Bytes{1, 2, 3}));
  auto reader = PartReader::open(b.back()).value();
  const TileIdRange level2 = subtree_tile_ids(TileId{0, 0, 0}, 2);
  std::vector<std::uint64_t> seen;
  ASSERT_TRUE(reader->for_each_record(level2.first, level2.last, [&](const PartRecord& r) {
    Bytes payload;
    EXPECT_TRUE(reader->read_payload(r, payload));
    EXPECT_EQ(payload, tiles.at(r.tile_id));
    seen.push_back(r.tile_id);
    return true;
  }));
  EXPECT_EQ(seen.size(),
            static_cast<std::size_t>(std::count_if(tiles.begin(), tiles.end(), [&](auto& t) {
              return t.first >= level2.first && t.first <= level2.last;
            })));
}

// The caller checks each part's manifest and attachment as the merge reads it, and sets the
// metadata once all are checked; its refusal stops the merge before anything is written.
TEST(Merge, LetsTheCallerCheckEachPartAndSetTheMetadata) {
  PartTempDir dir;
  const auto tiles = make_tiles(4, 9);
  const auto parts = write_parts(dir.path(), tiles, 4, 1);
  const fs::path out = dir.path() / "out.pmtiles";
  MergeOptions m;
  m.parts.assign(parts.begin(), parts.end());
  m.archive = archive_options(out, 4);
  m.metadata_json = "{\"name\":\"not this\"}";
  std::vector<std::string> seen;
  m.check_part = [&](const PartInfo& info) -> Status {
    EXPECT_EQ(info.attachment, (Bytes{1, 2, 3}));
    seen.push_back(info.manifest_json);
    return {};
  };
  m.check_parts = [&](std::string& metadata) -> Status {
    EXPECT_EQ(seen.size(), parts.size());  // every part checked first
    metadata = "{\"name\":\"t\"}";
    return {};
  };
  ASSERT_TRUE(merge_parts(m));
  EXPECT_EQ(seen.front(), "{\"part\":\"apex.part\"}");
  EXPECT_EQ(read_bytes(out), read_bytes(write_single(dir.path(), tiles, 4)));

  fs::remove(out);
  m.check_part = [&](const PartInfo& info) -> Status {
    if (info.path == parts[2]) return make_error(ErrorCode::invalid_argument, "stale part");
    return {};
  };
  auto r = merge_parts(m);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().message, "stale part");
  EXPECT_FALSE(fs::exists(out));
  m.check_part = nullptr;
  m.check_parts = [](std::string&) -> Status {
    return make_error(ErrorCode::invalid_argument, "apex stale");
  };
  r = merge_parts(m);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().message, "apex stale");
  EXPECT_FALSE(fs::exists(out));
}

TEST(Merge, NamesAMissingADamagedOrAnOverlappingPartAndWritesNothing) {
  PartTempDir dir;
  const auto tiles = make_tiles(4, 5);
  auto parts = write_parts(dir.path(), tiles, 4, 1);
  const fs::path out = dir.path() / "out.pmtiles";

  auto missing = parts;
  missing.push_back(dir.path() / "shard-9.part");
  auto r = merge(missing, out, 4);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("shard-9.part"), std::string::npos) << r.error().message;

  // A byte of the index, then a byte of a payload (found only when copied).
  const fs::path victim = parts[2];
  const Bytes good = read_bytes(victim);
  const auto info = read_part_info(victim).value();
  flip_byte(victim, info.data_bytes + 3);
  EXPECT_FALSE(read_part_info(victim));
  r = merge(parts, out, 4);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find(victim.string()), std::string::npos) << r.error().message;
  std::ofstream(victim, std::ios::binary)
      .write(reinterpret_cast<const char*>(good.data()), static_cast<std::streamsize>(good.size()));
  flip_byte(victim, 10);
  r = merge(parts, out, 4);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find(victim.string()), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("checksum"), std::string::npos) << r.error().message;

  // Truncated: its footer is gone.
  fs::resize_file(victim, good.size() - 1);
  r = merge(parts, out, 4);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find(victim.string()), std::string::npos) << r.error().message;
  std::ofstream(victim, std::ios::binary)
      .write(reinterpret_cast<const char*>(good.data()), static_cast<std::streamsize>(good.size()));

  auto twice = parts;
  twice.push_back(parts[1]);
  r = merge(twice, out, 4);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("overlapping"), std::string::npos) << r.error().message;

  EXPECT_FALSE(fs::exists(out));
  for (const auto& e : fs::directory_iterator(dir.path()))
    EXPECT_EQ(e.path().filename().string().find(".out.pmtiles"), std::string::npos) << e.path();
  ASSERT_TRUE(merge(parts, out, 4));
}

}  // namespace
}  // namespace vts::archive

namespace vts::archive {
namespace {

TEST(Merge, NestsLeavesOfLeavesWhenTheRootCannotHoldEveryLeafAndReadersWalkThem) {
  PartTempDir dir;
  std::map<std::uint64_t, Bytes> tiles;
  const std::uint64_t first = zxy_to_tile_id(6, 0, 0);
  for (std::uint64_t i = 0; i < 3000; ++i)
    tiles[first + i] = Bytes(1 + i % 7, static_cast<std::uint8_t>(i));
  WriterOptions o = archive_options(dir.path() / "nested.pmtiles", 6);
  o.leaf_entries = 16;  // 3000 entries: 188 leaves, 12 leaves of pointers, a root of 12
  auto w = Writer::create(o).value();
  for (const auto& [id, b] : tiles) ASSERT_TRUE(w->add_tile(tile_id_to_zxy(id).value(), b));
  ASSERT_TRUE(w->finish("{}"));
  auto r = Reader::open(o.path).value();
  EXPECT_EQ(r->leaf_directory_count().value(), 188u + 12u);
  for (const auto& [id, b] : tiles) ASSERT_EQ(r->get_by_tile_id(id).value(), b) << id;
  const auto parts = write_parts(dir.path(), tiles, 6, 1);
  MergeOptions m;
  m.parts.assign(parts.begin(), parts.end());
  m.archive = o;
  m.archive.path = dir.path() / "merged.pmtiles";
  m.metadata_json = "{}";
  ASSERT_TRUE(merge_parts(m));
  EXPECT_TRUE(read_bytes(m.archive.path) == read_bytes(o.path));
}

}  // namespace
}  // namespace vts::archive

namespace vts::archive {
namespace {

TEST(Merge, CopiesInTheKernelWithoutVerifyingToTheSameBytes) {
  PartTempDir dir;
  const auto tiles = make_tiles(5, 17);
  const Bytes single = read_bytes(write_single(dir.path(), tiles, 5));
  const auto parts = write_parts(dir.path(), tiles, 5, 2);
  MergeOptions m;
  m.parts.assign(parts.begin(), parts.end());
  m.archive = archive_options(dir.path() / "cloned.pmtiles", 5);
  m.metadata_json = "{\"name\":\"t\"}";
  m.verify = false;
  ASSERT_TRUE(merge_parts(m));
  EXPECT_TRUE(read_bytes(m.archive.path) == single);
  // A damaged payload gets through without verification (the index is still checked), and is
  // caught with it.
  flip_byte(parts[3], 5);
  fs::remove(m.archive.path);
  EXPECT_TRUE(merge_parts(m));
  m.verify = true;
  auto r = merge_parts(m);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("checksum"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace vts::archive
