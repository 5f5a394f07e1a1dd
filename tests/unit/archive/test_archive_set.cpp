// A set of archives read as one (archive_set.hpp): the manifest's rules, the routing of every tile
// to the archive that holds it, byte offsets across the archives, and a set whose archives or
// manifest do not belong together.
#include <filesystem>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "vts/archive/archive_set.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/base/file_io.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts::archive::archive_set_test {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

constexpr std::uint8_t kMaxZ = 4, kLevel = 2;
const std::string kMetadata = R"({"name":"t"})";

// Every tile of levels 0..kMaxZ but those under level-2 tile (2, 3, 1) and a few others, with
// random payloads (some repeated, so archives dedupe within themselves).
std::map<std::uint64_t, Bytes> pyramid() {
  std::mt19937 rng(7);
  std::map<std::uint64_t, Bytes> tiles;
  for (std::uint64_t id = 0; id <= levels_above(kMaxZ + 1).last; ++id) {
    const TileId t = tile_id_to_zxy(id).value();
    if (t.z >= kLevel && (t.x >> (t.z - kLevel)) == 3 && (t.y >> (t.z - kLevel)) == 1) continue;
    if (rng() % 7 == 0) continue;
    Bytes b(rng() % 5 == 0 ? 40 : 200 + rng() % 900, static_cast<std::uint8_t>(rng() % 3));
    if (b.size() > 40)
      for (auto& v : b) v = static_cast<std::uint8_t>(rng());
    tiles[id] = b;
  }
  return tiles;
}

// Writes the tiles `keep` selects as one archive at `path`; returns its SetArchive entry.
SetArchive write(const fs::path& path, const std::map<std::uint64_t, Bytes>& tiles,
                 const std::function<bool(TileId)>& keep, std::optional<TileId> root) {
  WriterOptions o;
  o.path = path;
  o.min_zoom = root ? kLevel : 0;
  o.max_zoom = root ? kMaxZ : kLevel - 1;
  o.leaf_entries = 8;  // leaves too
  auto w = Writer::create(o).value();
  for (const auto& [id, b] : tiles) {
    const TileId t = tile_id_to_zxy(id).value();
    if (keep(t)) {
      EXPECT_TRUE(w->add_tile(t, b));
    }
  }
  EXPECT_TRUE(w->finish(kMetadata));
  auto r = Reader::open(path).value();
  return {path.filename().string(), root, r->size(), r->version()};
}

class ArchiveSetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    tiles_ = pyramid();
    write(
        dir_.path() / "one.pmtiles", tiles_, [](TileId) { return true; }, std::nullopt);
    fs::create_directories(set_dir());
    manifest_.archive_level = kLevel;
    manifest_.max_zoom = kMaxZ;
    manifest_.metadata_json = kMetadata;
    manifest_.archives.push_back(write(
        set_dir() / std::string(kTopArchiveName), tiles_, [](TileId t) { return t.z < kLevel; },
        std::nullopt));
    std::vector<TileId> roots;
    for (std::uint32_t y = 0; y < 4; ++y)
      for (std::uint32_t x = 0; x < 4; ++x)
        if (!(x == 3 && y == 1)) roots.push_back({kLevel, x, y});
    std::sort(roots.begin(), roots.end(), [](TileId a, TileId b) {
      return zxy_to_tile_id(a.z, a.x, a.y) < zxy_to_tile_id(b.z, b.x, b.y);
    });
    for (const TileId& root : roots)
      manifest_.archives.push_back(write(
          set_dir() / set_archive_name(root), tiles_,
          [root](TileId t) {
            return t.z >= kLevel && (t.x >> (t.z - kLevel)) == root.x &&
                   (t.y >> (t.z - kLevel)) == root.y;
          },
          root));
    ASSERT_TRUE(
        write_file_atomically(set_dir() / std::string(kSetManifestName), manifest_.to_json()));
  }
  fs::path set_dir() const { return dir_.path() / "set"; }
  Result<SetManifest> reparse(const std::string& text) {
    return SetManifest::from_json(text, "m.json");
  }

  vts::test::TempDir dir_;
  std::map<std::uint64_t, Bytes> tiles_;
  SetManifest manifest_;
};

TEST_F(ArchiveSetTest, EveryTileReadsAsFromTheOneFileArchive) {
  auto one = Reader::open(dir_.path() / "one.pmtiles").value();
  for (const fs::path& p : {set_dir(), set_dir() / std::string(kSetManifestName)}) {
    SCOPED_TRACE(p.string());
    auto set = Reader::open(p);
    ASSERT_TRUE(set) << set.error().to_string();
    const Reader& r = **set;
    EXPECT_EQ(r.version(), manifest_.version());
    EXPECT_EQ(r.metadata_json(), kMetadata);
    EXPECT_EQ(r.header().min_zoom, 0);
    EXPECT_EQ(r.header().max_zoom, kMaxZ);
    EXPECT_EQ(r.header().addressed_tiles, tiles_.size());
    for (std::uint64_t id = 0; id <= levels_above(kMaxZ + 1).last; ++id) {
      const TileId t = tile_id_to_zxy(id).value();
      auto want = one->get(t);
      auto got = r.get(t);
      ASSERT_EQ(bool(want), bool(got)) << t.to_string();
      if (!want) {
        EXPECT_EQ(got.error().code, ErrorCode::not_found) << t.to_string();
        continue;
      }
      EXPECT_EQ(*got, *want) << t.to_string();
      // find_entry() then read() at tile_data_offset + offset: the same bytes.
      auto e = r.find_entry(id).value();
      Bytes bytes(e.length);
      ASSERT_TRUE(r.read(r.header().tile_data_offset + e.offset, bytes));
      EXPECT_EQ(bytes, *want) << t.to_string();
    }
    // Every entry once, each addressing its tile's bytes.
    std::uint64_t seen = 0;
    ASSERT_TRUE(r.for_each_entry([&](const Entry& e) {
      Bytes bytes(e.length);
      EXPECT_TRUE(r.read(e.offset, bytes));
      for (std::uint32_t i = 0; i < e.run_length; ++i) EXPECT_EQ(bytes, tiles_.at(e.tile_id + i));
      seen += e.run_length;
      return true;
    }));
    EXPECT_EQ(seen, tiles_.size());
  }
}

TEST_F(ArchiveSetTest, ReadsAcrossArchiveBoundaries) {
  auto set = Reader::open(set_dir()).value();
  Bytes all;
  for (const SetArchive& a : manifest_.archives) {
    const std::string bytes = read_file(set_dir() / a.name).value();
    all.insert(all.end(), bytes.begin(), bytes.end());
  }
  ASSERT_EQ(set->size(), all.size());
  const std::uint64_t edge = manifest_.archives[0].bytes;
  Bytes span(300);
  ASSERT_TRUE(set->read(edge - 100, span));
  EXPECT_TRUE(std::equal(span.begin(), span.end(), all.begin() + (edge - 100)));
  Bytes past(2);
  EXPECT_EQ(set->read(all.size() - 1, past).error().code, ErrorCode::invalid_argument);
}

TEST_F(ArchiveSetTest, AnArchiveThatIsNotTheManifestsIsChanged) {
  // Another archive under a listed name: its size or version differ from the manifest's.
  fs::copy_file(set_dir() / std::string(kTopArchiveName), set_dir() / manifest_.archives[3].name,
                fs::copy_options::overwrite_existing);
  auto set = Reader::open(set_dir());
  ASSERT_FALSE(set);
  EXPECT_EQ(set.error().code, ErrorCode::changed);
  EXPECT_NE(set.error().message.find(manifest_.archives[3].name), std::string::npos);
  fs::remove(set_dir() / manifest_.archives[3].name);
  EXPECT_EQ(Reader::open(set_dir()).error().code, ErrorCode::not_found);
}

TEST_F(ArchiveSetTest, ManifestRoundTripsAndRefusesWhatWeDoNotWrite) {
  auto again = reparse(manifest_.to_json());
  ASSERT_TRUE(again) << again.error().to_string();
  EXPECT_EQ(again->archives, manifest_.archives);
  EXPECT_EQ(again->version(), manifest_.version());

  auto with = [&](const std::function<void(SetManifest&)>& change) {
    SetManifest m = manifest_;
    change(m);
    return reparse(m.to_json());
  };
  struct Case {
    const char* what;
    std::function<void(SetManifest&)> change;
    const char* says;
  };
  const Case cases[] = {
      {"a name climbing out", [](SetManifest& m) { m.archives[1].name = "../x.pmtiles"; },
       "plain file name"},
      {"a name with a folder", [](SetManifest& m) { m.archives[1].name = "a/b.pmtiles"; },
       "plain file name"},
      {"a name twice", [](SetManifest& m) { m.archives[2].name = m.archives[1].name; },
       "listed twice"},
      {"no top first", [](SetManifest& m) { std::swap(m.archives[0], m.archives[1]); }, "top"},
      {"roots out of order", [](SetManifest& m) { std::swap(m.archives[1], m.archives[2]); },
       "tile-id order"},
      {"a root at another level", [](SetManifest& m) { m.archives[1].root->z = 3; },
       "archive_level"},
      {"level 0", [](SetManifest& m) { m.archive_level = 0; }, "archive_level"},
      {"level past the pyramid", [](SetManifest& m) { m.archive_level = kMaxZ + 1; },
       "archive_level"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    auto r = with(c.change);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::corrupt);
    EXPECT_NE(r.error().message.find(c.says), std::string::npos) << r.error().message;
  }
  // Hand-edited bytes, another format, hostile JSON.
  std::string text = manifest_.to_json();
  text.replace(text.find(manifest_.archives[1].version), 16, "0123456789abcdef");
  EXPECT_EQ(reparse(text).error().code, ErrorCode::corrupt);
  EXPECT_EQ(reparse(R"({"vtstream_set": 2})").error().code, ErrorCode::unsupported);
  EXPECT_EQ(reparse("[]").error().code, ErrorCode::corrupt);
  EXPECT_EQ(reparse(std::string(1000, '[')).error().code, ErrorCode::corrupt);
  EXPECT_EQ(reparse(R"({"vtstream_set": 1, "max_zoom": 3, "archive_level": 1, "tileset": {},
                        "archives": [{"name": "top.pmtiles", "tile": null, "bytes": 0,
                                      "version": "0123456789abcdef"}]})")
                .error()
                .code,
            ErrorCode::corrupt);
}

TEST(ArchiveSetNames, NamesAndPaths) {
  EXPECT_EQ(set_archive_name(std::nullopt), "top.pmtiles");
  EXPECT_EQ(set_archive_name(TileId{5, 17, 3}), "5-17-3.pmtiles");
  vts::test::TempDir dir;
  EXPECT_FALSE(is_set_path(dir.path()));
  EXPECT_TRUE(is_set_path(dir.path() / "tileset.json"));
  ASSERT_TRUE(write_file_atomically(dir.path() / "tileset.json", "{}"));
  EXPECT_TRUE(is_set_path(dir.path()));
  EXPECT_EQ(set_manifest_path(dir.path()), dir.path() / "tileset.json");
}

}  // namespace
}  // namespace vts::archive::archive_set_test
