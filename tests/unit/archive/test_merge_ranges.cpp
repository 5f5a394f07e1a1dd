// Ranged merges (MergeOptions::ranges): every archive of a set split at a level (one per tile of
// the level with data, one for the levels above) is the Writer's archive of exactly its tiles,
// made from the parts of the one-file merge however they were cut, and reads about its share of
// the parts' indexes.
#include <algorithm>
#include <bit>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "mixed_payloads.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/archive/pmtiles_part.hpp"
#include "vts/test/files.hpp"
#include "vts/test/temp_dir.hpp"

// Its own namespace: this file shares a unity-build target with test_pmtiles_part.cpp.
namespace vts::archive::merge_ranges_test {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;
using Tiles = std::map<std::uint64_t, Bytes>;
using vts::test::read_bytes;

constexpr std::size_t kLeaf = 64;  // small leaves, so that the set's archives have leaves too

// Levels 0..max_z with each kind of payload the layout rule treats differently: unique large
// ones, small ones repeated far apart, large ones repeated far apart and in runs (some crossing
// sub-pyramid boundaries), missing tiles; and no tile at all under `empty_root`.
Tiles pyramid(int max_z, std::uint32_t seed, TileId empty_root) {
  std::mt19937 rng(seed);
  Tiles tiles;
  for (int z = 0; z <= max_z; ++z) {
    const auto level = static_cast<std::uint8_t>(z);
    for (std::uint64_t id = subtree_tile_ids(TileId{}, level).first;
         id <= subtree_tile_ids(TileId{}, level).last; ++id) {
      if (auto b = vts::archive::test::mixed_payload(rng, tiles, id)) tiles[id] = std::move(*b);
    }
  }
  for (std::uint8_t z = empty_root.z; z <= max_z; ++z) {
    const TileIdRange r = subtree_tile_ids(empty_root, z);
    tiles.erase(tiles.lower_bound(r.first), tiles.upper_bound(r.last));
  }
  return tiles;
}

// Level 0..max_z, one distinct 8-byte payload per tile: many records, few payload bytes.
Tiles dense_pyramid(int max_z) {
  Tiles tiles;
  const std::uint64_t end = subtree_tile_ids(TileId{}, static_cast<std::uint8_t>(max_z)).last;
  for (std::uint64_t id = 0; id <= end; ++id) {
    Bytes b(8);
    for (int k = 0; k < 8; ++k)
      b[static_cast<std::size_t>(k)] = static_cast<std::uint8_t>(id >> (8 * k));
    tiles[id] = b;
  }
  return tiles;
}

WriterOptions options_for(const fs::path& path, int max_z) {
  WriterOptions o;
  o.path = path;
  o.max_zoom = static_cast<std::uint8_t>(max_z);
  o.leaf_entries = kLeaf;
  return o;
}

const std::string kMetadata = "{\"name\":\"set\"}";

fs::path write_with_writer(const fs::path& out, const Tiles& tiles, int max_z) {
  auto w = Writer::create(options_for(out, max_z)).value();
  for (const auto& [id, b] : tiles) EXPECT_TRUE(w->add_tile(tile_id_to_zxy(id).value(), b));
  EXPECT_TRUE(w->finish(kMetadata));
  return out;
}

// Cuts the tiles into one part per sub-pyramid of a tile of level `split` (some empty) and an
// apex part of the levels above it.
std::vector<fs::path> cut_into_parts(const fs::path& dir, const Tiles& tiles, int max_z,
                                     int split) {
  fs::create_directories(dir);
  std::vector<fs::path> parts;
  const auto write = [&](const std::string& name, const std::vector<std::uint64_t>& ids) {
    const fs::path p = dir / name;
    auto w = PartWriter::create(p).value();
    for (std::uint64_t id : ids) EXPECT_TRUE(w->add_tile(tile_id_to_zxy(id).value(), tiles.at(id)));
    EXPECT_TRUE(w->finish({}, "{}"));
    parts.push_back(p);
  };
  if (split > 0) {
    std::vector<std::uint64_t> apex;
    const TileIdRange above = levels_above(static_cast<std::uint8_t>(split));
    for (auto it = tiles.begin(); it != tiles.end() && it->first <= above.last; ++it)
      apex.push_back(it->first);
    write("apex.part", apex);
  }
  const std::uint32_t n = 1u << split;
  for (std::uint32_t y = 0; y < n; ++y)
    for (std::uint32_t x = 0; x < n; ++x) {
      std::vector<std::uint64_t> ids;
      for (const TileIdRange& r : subtree_ranges(TileId{static_cast<std::uint8_t>(split), x, y},
                                                 static_cast<std::uint8_t>(max_z)))
        for (auto it = tiles.lower_bound(r.first); it != tiles.end() && it->first <= r.last; ++it)
          ids.push_back(it->first);
      write("shard-" + std::to_string(x) + "-" + std::to_string(y) + ".part", ids);
    }
  return parts;
}

// The archives of a set split at level k: the top one, then one per tile of level k (with data
// or not) in tile-id order.
std::vector<std::vector<TileIdRange>> set_at(int k, int max_z) {
  std::vector<std::vector<TileIdRange>> set{{levels_above(static_cast<std::uint8_t>(k))}};
  const TileIdRange level = subtree_tile_ids(TileId{}, static_cast<std::uint8_t>(k));
  for (std::uint64_t id = level.first; id <= level.last; ++id)
    set.push_back(subtree_ranges(tile_id_to_zxy(id).value(), static_cast<std::uint8_t>(max_z)));
  return set;
}

Tiles select(const Tiles& tiles, const std::vector<TileIdRange>& ranges) {
  Tiles out;
  for (const TileIdRange& r : ranges)
    out.insert(tiles.lower_bound(r.first), tiles.upper_bound(r.last));
  return out;
}

struct Ranged {
  Result<WriterStats> stats;
  MergeProgress last;  // the final progress report
};

Ranged merge_ranged(const std::vector<fs::path>& parts, const fs::path& out, int max_z,
                    std::vector<TileIdRange> ranges, bool verify = true) {
  MergeOptions m;
  m.parts.assign(parts.rbegin(), parts.rend());  // any order
  m.archive = options_for(out, max_z);
  m.metadata_json = kMetadata;
  m.ranges = std::move(ranges);
  m.verify = verify;
  MergeProgress last;
  m.on_progress = [&](const MergeProgress& p) { last = p; };
  Result<WriterStats> stats = merge_parts(m);
  return {std::move(stats), last};
}

class RangesTempDir : public vts::test::TempDir {
 public:
  RangesTempDir() : vts::test::TempDir("vts-merge-ranges-test") {}
};

TEST(MergeRanges, WritesEachArchiveOfASetAsTheWriterWouldFromItsTilesWhateverThePartition) {
  RangesTempDir dir;
  constexpr int kMaxZ = 6, kSplit = 2;
  const TileId empty_root{kSplit, 1, 2};
  const Tiles tiles = pyramid(kMaxZ, 23, empty_root);
  const auto set = set_at(kSplit, kMaxZ);

  // The one-file merge, whose tiles the set's archives must hold.
  const fs::path one_file = dir.path() / "one.pmtiles";
  ASSERT_TRUE(
      merge_ranged(cut_into_parts(dir.path() / "one", tiles, kMaxZ, 1), one_file, kMaxZ, {}).stats);
  auto whole = Reader::open(one_file).value();

  // What Writer writes from each archive's tiles (none for the empty sub-pyramid).
  std::vector<std::optional<Bytes>> expected;
  for (std::size_t a = 0; a < set.size(); ++a) {
    const Tiles subset = select(tiles, set[a]);
    if (subset.empty()) {
      expected.emplace_back();
      continue;
    }
    expected.emplace_back(read_bytes(write_with_writer(
        dir.path() / ("writer-" + std::to_string(a) + ".pmtiles"), subset, kMaxZ)));
  }
  ASSERT_EQ(std::count(expected.begin(), expected.end(), std::nullopt), 1);

  // Shards below, at and above the set's level, with an apex part (or none: one part).
  for (int split : {0, 1, 2, 3}) {
    const fs::path sub = dir.path() / ("split" + std::to_string(split));
    const auto parts = cut_into_parts(sub, tiles, kMaxZ, split);
    for (bool verify : {true, false}) {
      SCOPED_TRACE("parts split at level " + std::to_string(split) +
                   (verify ? ", verified" : ", copied in the kernel"));
      std::map<std::uint64_t, int> seen;  // tile id -> archives holding it
      for (std::size_t a = 0; a < set.size(); ++a) {
        SCOPED_TRACE("archive " + std::to_string(a));
        const fs::path out = sub / ("set-" + std::to_string(a) + ".pmtiles");
        fs::remove(out);
        const Ranged r = merge_ranged(parts, out, kMaxZ, set[a], verify);
        if (!expected[a]) {
          ASSERT_FALSE(r.stats);
          EXPECT_EQ(r.stats.error().code, ErrorCode::not_found);
          EXPECT_FALSE(fs::exists(out));
          continue;
        }
        ASSERT_TRUE(r.stats) << r.stats.error().message;
        const std::uint64_t n = select(tiles, set[a]).size();
        EXPECT_EQ(r.stats->addressed_tiles, n);
        EXPECT_EQ(r.last.tiles_total, n);
        EXPECT_EQ(r.last.tiles_done, n);
        EXPECT_EQ(r.stats->file_bytes, fs::file_size(out));
        ASSERT_TRUE(read_bytes(out) == *expected[a]);

        // Its tiles, read back from the archive itself, are the one-file archive's.
        auto reader = Reader::open(out).value();
        ASSERT_TRUE(reader->for_each_entry([&](const Entry& e) {
          for (std::uint64_t id = e.tile_id; id < e.tile_id + e.run_length; ++id) {
            ++seen[id];
            EXPECT_EQ(reader->get_by_tile_id(id).value(), whole->get_by_tile_id(id).value()) << id;
          }
          return true;
        }));
      }
      // Together the archives hold every tile, each once.
      ASSERT_EQ(seen.size(), tiles.size());
      for (const auto& [id, count] : seen) {
        EXPECT_TRUE(tiles.count(id)) << id;
        EXPECT_EQ(count, 1) << id;
      }
    }
  }
}

TEST(MergeRanges, RefusesRangesThatAreUnsortedOverlappingOrEmpty) {
  RangesTempDir dir;
  const Tiles tiles = pyramid(4, 5, TileId{2, 0, 0});
  const auto parts = cut_into_parts(dir.path(), tiles, 4, 1);
  const fs::path out = dir.path() / "out.pmtiles";
  for (const std::vector<TileIdRange>& bad : {std::vector<TileIdRange>{{100, 200}, {10, 20}},
                                              {{10, 20}, {20, 30}},
                                              {{30, 20}},
                                              {{0, 4}, {5, 9}, {9, 9}}}) {
    const Ranged r = merge_ranged(parts, out, 4, bad);
    ASSERT_FALSE(r.stats);
    EXPECT_EQ(r.stats.error().code, ErrorCode::invalid_argument) << r.stats.error().message;
    EXPECT_FALSE(fs::exists(out));
  }
  // Adjacent ranges are disjoint: the same tiles as one range.
  const TileIdRange top = levels_above(2);
  ASSERT_TRUE(merge_ranged(parts, out, 4, {{0, 2}, {3, top.last}}).stats);
  EXPECT_TRUE(read_bytes(out) ==
              read_bytes(write_with_writer(dir.path() / "w.pmtiles", select(tiles, {top}), 4)));
}

TEST(MergeRanges, SaysNotFoundAndWritesNothingWhenNoTileLiesInTheRanges) {
  RangesTempDir dir;
  const TileId empty_root{2, 3, 1};
  const Tiles tiles = pyramid(4, 7, empty_root);
  const auto parts = cut_into_parts(dir.path(), tiles, 4, 1);
  const fs::path out = dir.path() / "out.pmtiles";
  const TileIdRange beyond = subtree_tile_ids(TileId{}, 7);
  for (const std::vector<TileIdRange>& nothing :
       {subtree_ranges(empty_root, 4), std::vector<TileIdRange>{beyond}}) {
    const Ranged r = merge_ranged(parts, out, 4, nothing);
    ASSERT_FALSE(r.stats);
    EXPECT_EQ(r.stats.error().code, ErrorCode::not_found);
    EXPECT_EQ(r.stats.error().message, "no tile of the parts lies in the ranges asked");
  }
  EXPECT_FALSE(fs::exists(out));
  for (const auto& e : fs::directory_iterator(dir.path()))
    EXPECT_EQ(e.path().extension(), ".part") << e.path();
}

// The bar: the merges of a set together read about what the one-file merge reads, so each
// reads its share of the index, not every part's whole index (beyond the checksum of each part,
// counted apart).
TEST(MergeRanges, ReadsAboutItsShareOfTheIndexWhateverTheNumberOfParts) {
  RangesTempDir dir;
  constexpr int kMaxZ = 8, kSplit = 3;
  const Tiles tiles = dense_pyramid(kMaxZ);
  const auto set = set_at(kSplit, kMaxZ);
  for (int split : {1, 4}) {
    SCOPED_TRACE("parts split at level " + std::to_string(split));
    const fs::path sub = dir.path() / ("split" + std::to_string(split));
    const auto parts = cut_into_parts(sub, tiles, kMaxZ, split);
    std::uint64_t biggest_part = 0;
    for (const fs::path& p : parts) biggest_part = std::max(biggest_part, read_part_info(p)->tiles);
    // A binary search reads at most bit_width(records) records; each range clips one segment
    // with two searches and reads the two records at the cut.
    const std::uint64_t per_range = 2 * (std::bit_width(biggest_part) + 1);

    const Ranged one = merge_ranged(parts, sub / "one.pmtiles", kMaxZ, {});
    ASSERT_TRUE(one.stats);
    EXPECT_EQ(one.last.records_read, 2 * tiles.size());  // each record once per pass
    EXPECT_EQ(one.last.records_checked, tiles.size());

    std::uint64_t total = 0;
    for (std::size_t a = 0; a < set.size(); ++a) {
      SCOPED_TRACE("archive " + std::to_string(a));
      const fs::path out = sub / "set.pmtiles";
      fs::remove(out);
      const Ranged r = merge_ranged(parts, out, kMaxZ, set[a]);
      ASSERT_TRUE(r.stats) << r.stats.error().message;
      const std::uint64_t n = select(tiles, set[a]).size();
      EXPECT_GE(r.last.records_read, 2 * n);
      EXPECT_LE(r.last.records_read, 2 * n + set[a].size() * per_range);
      // The checksums still read every part's whole index.
      EXPECT_EQ(r.last.records_checked, tiles.size());
      total += r.last.records_read;
    }
    EXPECT_LE(static_cast<double>(total), 1.10 * static_cast<double>(one.last.records_read));
  }
}

// A ranged merge told which parts can hold its tiles (MergeOptions::index_needed) checks only
// those parts' indexes; every part's manifest is still seen by check_part, and the archive is the
// same bytes.
TEST(MergeRanges, PartsNotNeededAreReadForTheirManifestsOnly) {
  RangesTempDir dir;
  constexpr int kMaxZ = 7, kSplit = 3, kLevel = 2;
  const Tiles tiles = dense_pyramid(kMaxZ);
  const auto parts = cut_into_parts(dir.path() / "parts", tiles, kMaxZ, kSplit);
  const TileId root{kLevel, 1, 0};
  std::vector<bool> needed;
  std::uint64_t needed_tiles = 0;
  for (const fs::path& p : parts) {
    // "apex.part" holds the levels above the split (here also levels 2..), "shard-X-Y.part" the
    // sub-pyramid of (kSplit, X, Y).
    bool in = p.filename() == "apex.part";
    std::uint32_t x = 0, y = 0;
    if (std::sscanf(p.filename().c_str(), "shard-%u-%u.part", &x, &y) == 2)
      in = (x >> (kSplit - kLevel)) == root.x && (y >> (kSplit - kLevel)) == root.y;
    needed.push_back(in);
    if (in) needed_tiles += read_part_info(p)->tiles;
  }
  const auto ranges = subtree_ranges(root, kMaxZ);
  auto merge = [&](const fs::path& out, bool hint, MergeProgress& last, std::size_t& seen) {
    MergeOptions m;
    m.parts.assign(parts.begin(), parts.end());
    m.archive = options_for(out, kMaxZ);
    m.metadata_json = kMetadata;
    m.ranges = ranges;
    if (hint) m.index_needed = needed;
    m.on_progress = [&](const MergeProgress& p) { last = p; };
    m.check_part = [&](const PartInfo& info) {
      EXPECT_FALSE(info.manifest_json.empty()) << info.path;
      ++seen;
      return Status{};
    };
    return merge_parts(m);
  };
  MergeProgress all_last, hinted_last;
  std::size_t all_seen = 0, hinted_seen = 0;
  ASSERT_TRUE(merge(dir.path() / "all.pmtiles", false, all_last, all_seen));
  ASSERT_TRUE(merge(dir.path() / "hinted.pmtiles", true, hinted_last, hinted_seen));
  EXPECT_EQ(read_bytes(dir.path() / "hinted.pmtiles"), read_bytes(dir.path() / "all.pmtiles"));
  EXPECT_EQ(all_seen, parts.size());
  EXPECT_EQ(hinted_seen, parts.size());
  EXPECT_EQ(all_last.records_checked, tiles.size());
  EXPECT_EQ(hinted_last.records_checked, needed_tiles);
  EXPECT_LT(needed_tiles * 3, tiles.size());  // about a quarter of the parts' records
  // A hint of the wrong size is a caller's bug, refused.
  needed.pop_back();
  MergeProgress ignored;
  std::size_t n = 0;
  EXPECT_EQ(merge(dir.path() / "bad.pmtiles", true, ignored, n).error().code,
            ErrorCode::invalid_argument);
}

TEST(MergeRanges, HelpersNameEachLevelOfASubPyramidAndTheLevelsAbove) {
  const std::vector<TileIdRange> r = subtree_ranges(TileId{2, 1, 3}, 5);
  ASSERT_EQ(r.size(), 4u);
  for (std::uint8_t z = 2; z <= 5; ++z) EXPECT_EQ(r[z - 2u], subtree_tile_ids(TileId{2, 1, 3}, z));
  EXPECT_EQ(subtree_ranges(TileId{3, 5, 6}, 3),
            (std::vector<TileIdRange>{{zxy_to_tile_id(3, 5, 6), zxy_to_tile_id(3, 5, 6)}}));
  EXPECT_EQ(levels_above(1), (TileIdRange{0, 0}));
  EXPECT_EQ(levels_above(3), (TileIdRange{0, 1 + 4 + 16 - 1}));
  EXPECT_EQ(levels_above(3).last + 1, zxy_to_tile_id(3, 0, 0));
}

}  // namespace
}  // namespace vts::archive::merge_ranges_test
