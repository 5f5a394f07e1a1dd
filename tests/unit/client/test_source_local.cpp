// The local-archive source and open_source()'s dispatch: the same bytes and ETags as
// archive::Reader and `vts serve`, absent tiles, and errors that name the path.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <optional>
#include <regex>
#include <string>

#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"
#include "vts/client/source.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/server/tileset_registry.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;
using vts::client::SourceTile;

namespace {

class SourceLocal : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new vts::test::TempDir("vts-source-local-test");
    build("dense", std::nullopt);
    // Sparse: at z = 2 (the finest level) only tile (0,0) exists.
    build("sparse", vts::TexelRect{0, 0, 256, 256});
  }
  static void TearDownTestSuite() { delete dir_; }
  static void build(const std::string& name, std::optional<vts::TexelRect> region) {
    vts::BuildOptions o;
    o.synthetic = vts::SyntheticSpec{600, 300, region, 2};
    o.output = *dir_ / (name + ".pmtiles");
    o.threads = 1;
    o.description = "test " + name;
    auto r = vts::build_synthetic_pyramid(o);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
  }
  static fs::path path(const std::string& name) { return *dir_ / (name + ".pmtiles"); }

  static std::unique_ptr<vts::client::TileSource> open(const std::string& name) {
    auto s = vts::client::open_source(path(name).string());
    EXPECT_TRUE(s.ok()) << s.error().to_string();
    return s.ok() ? std::move(*s) : nullptr;
  }

  static inline vts::test::TempDir* dir_ = nullptr;
};

// Fetches synchronously (a local source answers inside fetch()).
SourceTile fetch(vts::client::TileSource& source, vts::TileId id, std::string inm = {}) {
  std::optional<SourceTile> got;
  int calls = 0;
  vts::client::SourceRequest r;
  r.id = id;
  r.if_none_match = std::move(inm);
  source.fetch(r, [&](SourceTile&& t) {
    ++calls;
    got = std::move(t);
  });
  EXPECT_EQ(calls, 1) << "the local source answers exactly once, before fetch() returns";
  return got ? std::move(*got) : SourceTile{};
}

std::string expected_etag(std::span<const std::uint8_t> payload) {
  auto h = vts::parse_tile_header(payload);
  EXPECT_TRUE(h.ok());
  char buf[24];
  std::snprintf(buf, sizeof buf, "\"%016llx\"", static_cast<unsigned long long>(h->checksum));
  return buf;
}

std::shared_ptr<vts::archive::Reader> reader(const fs::path& p) {
  auto r = vts::archive::Reader::open(p);
  EXPECT_TRUE(r.ok()) << r.error().to_string();
  return r.ok() ? *r : nullptr;
}

}  // namespace

TEST_F(SourceLocal, ReturnsEveryTileByteExactWithTheServersEtag) {
  auto source = open("dense");
  ASSERT_TRUE(source);
  EXPECT_TRUE(source->local());
  auto archive = reader(path("dense"));
  const vts::Geometry& g = source->info().info.geometry;
  const std::regex etag_form("\"[0-9a-f]{16}\"");
  int tiles = 0;
  for (int z = 0; z <= g.max_zoom(); ++z) {
    for (std::uint32_t y = 0; y < g.tiles_y(z); ++y) {
      for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) {
        const vts::TileId id{static_cast<std::uint8_t>(z), x, y};
        SourceTile t = fetch(*source, id);
        auto want = archive->get(id);
        ASSERT_TRUE(want.ok()) << id.to_string();
        ASSERT_EQ(t.kind, SourceTile::Kind::ok) << id.to_string();
        EXPECT_FALSE(t.error.has_value());
        ASSERT_TRUE(std::equal(t.payload.begin(), t.payload.end(), want->begin(), want->end()))
            << id.to_string();
        EXPECT_TRUE(std::regex_match(t.etag, etag_form)) << t.etag;
        EXPECT_EQ(t.etag, expected_etag(*want));
        EXPECT_EQ(vts::client::tile_etag(t.payload).value(), t.etag);
        ++tiles;
      }
    }
  }
  EXPECT_EQ(tiles, static_cast<int>(g.total_tile_count()));
}

TEST_F(SourceLocal, PayloadOutlivesTheSource) {
  auto archive = reader(path("dense"));
  auto want = archive->get({0, 0, 0});
  ASSERT_TRUE(want.ok());
  SourceTile t;
  {
    auto source = open("dense");
    ASSERT_TRUE(source);
    t = fetch(*source, {0, 0, 0});
  }
  ASSERT_EQ(t.kind, SourceTile::Kind::ok);
  EXPECT_TRUE(std::equal(t.payload.begin(), t.payload.end(), want->begin(), want->end()));
}

TEST_F(SourceLocal, IfNoneMatchWithTheCurrentEtagIsNotModified) {
  auto source = open("dense");
  ASSERT_TRUE(source);
  const vts::TileId id{1, 1, 0};
  const SourceTile first = fetch(*source, id);
  ASSERT_EQ(first.kind, SourceTile::Kind::ok);
  for (const std::string& inm :
       {first.etag, "W/" + first.etag, "\"0000000000000000\", " + first.etag, std::string("*")}) {
    const SourceTile again = fetch(*source, id, inm);
    EXPECT_EQ(again.kind, SourceTile::Kind::not_modified) << inm;
    EXPECT_EQ(again.etag, first.etag);
    EXPECT_TRUE(again.payload.empty());
  }
  const SourceTile stale = fetch(*source, id, "\"0000000000000000\"");
  EXPECT_EQ(stale.kind, SourceTile::Kind::ok);
  EXPECT_EQ(stale.payload, first.payload);
}

TEST_F(SourceLocal, SparseArchiveAnswersAbsentForMissingTiles) {
  auto source = open("sparse");
  ASSERT_TRUE(source);
  ASSERT_TRUE(source->info().info.sparse);
  auto archive = reader(path("sparse"));
  EXPECT_EQ(fetch(*source, {2, 0, 0}).kind, SourceTile::Kind::ok);
  const vts::Geometry& g = source->info().info.geometry;
  int absent = 0;
  for (std::uint32_t y = 0; y < g.tiles_y(2); ++y) {
    for (std::uint32_t x = 0; x < g.tiles_x(2); ++x) {
      const vts::TileId id{2, x, y};
      const SourceTile t = fetch(*source, id);
      if (archive->get(id).ok()) {
        EXPECT_EQ(t.kind, SourceTile::Kind::ok) << id.to_string();
      } else {
        EXPECT_EQ(t.kind, SourceTile::Kind::absent) << id.to_string();
        EXPECT_TRUE(t.payload.empty());
        EXPECT_FALSE(t.error.has_value());
        ++absent;
      }
    }
  }
  EXPECT_GT(absent, 0);
}

TEST_F(SourceLocal, TilesOutsideThePyramidAreAbsent) {
  auto source = open("dense");
  ASSERT_TRUE(source);
  const vts::Geometry& g = source->info().info.geometry;
  const auto mz = static_cast<std::uint8_t>(g.max_zoom());
  for (vts::TileId id :
       {vts::TileId{static_cast<std::uint8_t>(mz + 1), 0, 0}, vts::TileId{mz, g.tiles_x(mz), 0},
        vts::TileId{mz, 0, g.tiles_y(mz)}, vts::TileId{0, 1, 0},
        vts::TileId{31, 0xFFFFFFFFu, 0xFFFFFFFFu}, vts::TileId{255, 0, 0}}) {
    const SourceTile t = fetch(*source, id);
    EXPECT_EQ(t.kind, SourceTile::Kind::absent) << id.to_string();
  }
}

TEST_F(SourceLocal, InfoDescribesTheArchiveLikeTheServer) {
  auto source = open("dense");
  ASSERT_TRUE(source);
  const auto& info = source->info();
  EXPECT_EQ(info.key, "file:" + path("dense").string());
  EXPECT_EQ(info.info.geometry.width(), 600u);
  EXPECT_EQ(info.info.geometry.height(), 300u);
  EXPECT_EQ(info.info.description, "test dense");
  EXPECT_EQ(info.description_json, reader(path("dense"))->metadata_json());
  // The same version `vts serve` puts in TileJSON and versioned URLs.
  auto served = vts::open_tileset(path("dense"));
  ASSERT_TRUE(served.ok()) << served.error().to_string();
  EXPECT_EQ(info.version, (*served)->version);
  EXPECT_TRUE(std::regex_match(info.version, std::regex("[0-9a-f]{16}")));
}

TEST_F(SourceLocal, KeyIsTheAbsolutePathHoweverTheArchiveWasNamed) {
  const fs::path cwd = fs::current_path();
  fs::current_path(dir_->path());
  auto relative = vts::client::open_source("./sub/../dense.pmtiles");
  fs::current_path(cwd);
  ASSERT_TRUE(relative.ok()) << relative.error().to_string();
  EXPECT_EQ((*relative)->info().key, "file:" + path("dense").string());

  auto url = vts::client::open_source("file://" + path("dense").string());
  ASSERT_TRUE(url.ok()) << url.error().to_string();
  EXPECT_TRUE((*url)->local());
  EXPECT_EQ((*url)->info().key, "file:" + path("dense").string());
  auto localhost = vts::client::open_source("file://localhost" + path("dense").string());
  ASSERT_TRUE(localhost.ok()) << localhost.error().to_string();
  EXPECT_EQ((*localhost)->info().key, (*url)->info().key);
}

TEST_F(SourceLocal, FileUrlsArePercentDecoded) {
  const fs::path spaced = *dir_ / "with space.pmtiles";
  fs::copy_file(path("dense"), spaced, fs::copy_options::overwrite_existing);
  std::string url = "file://" + dir_->path().string() + "/with%20space.pmtiles";
  auto s = vts::client::open_source(url);
  ASSERT_TRUE(s.ok()) << s.error().to_string();
  EXPECT_EQ((*s)->info().key, "file:" + spaced.string());
}

TEST_F(SourceLocal, MissingArchiveErrorNamesThePath) {
  const std::string missing = (*dir_ / "no-such.pmtiles").string();
  auto s = vts::client::open_source(missing);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, vts::ErrorCode::not_found);
  EXPECT_NE(s.error().message.find(missing), std::string::npos) << s.error().message;
}

TEST_F(SourceLocal, FileThatIsNotAnArchiveErrorNamesThePath) {
  const fs::path text = *dir_ / "notes.pmtiles";
  std::ofstream(text) << "this is not a PMTiles archive, just some text that is long enough to "
                         "fill a header of one hundred and twenty-seven bytes, and then some more "
                         "so that the reader gets to look at the magic number first.\n";
  for (const std::string& location : {text.string(), "file://" + text.string()}) {
    auto s = vts::client::open_source(location);
    ASSERT_FALSE(s.ok()) << location;
    EXPECT_EQ(s.error().code, vts::ErrorCode::corrupt) << s.error().to_string();
    EXPECT_NE(s.error().message.find(text.string()), std::string::npos) << s.error().message;
  }
  auto dir = vts::client::open_source(dir_->path().string());
  ASSERT_FALSE(dir.ok());
  EXPECT_NE(dir.error().message.find(dir_->path().string()), std::string::npos)
      << dir.error().message;
}

TEST_F(SourceLocal, ArchiveOfAnotherToolIsRefusedNamingThePath) {
  const fs::path foreign = *dir_ / "foreign.pmtiles";
  vts::archive::WriterOptions o;
  o.path = foreign;
  auto w = vts::archive::Writer::create(o);
  ASSERT_TRUE(w.ok()) << w.error().to_string();
  const std::vector<std::uint8_t> tile(100, 7);
  ASSERT_TRUE((*w)->add_tile({0, 0, 0}, tile).ok());
  ASSERT_TRUE((*w)->finish(R"({"name":"roads","format":"pbf"})").ok());
  auto s = vts::client::open_source(foreign.string());
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, vts::ErrorCode::unsupported) << s.error().to_string();
  EXPECT_NE(s.error().message.find(foreign.string()), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("vtstream"), std::string::npos) << s.error().message;
}

TEST_F(SourceLocal, TileWithoutAValidHeaderIsAnErrorNotACrash) {
  // Our metadata, but a payload that is not a tile: what `vts serve` answers 500 for.
  auto good = vts::open_tileset(path("dense"));
  ASSERT_TRUE(good.ok());
  const fs::path damaged = *dir_ / "damaged.pmtiles";
  vts::archive::WriterOptions o;
  o.path = damaged;
  o.max_zoom = static_cast<std::uint8_t>((*good)->info.geometry.max_zoom());
  auto w = vts::archive::Writer::create(o);
  ASSERT_TRUE(w.ok()) << w.error().to_string();
  const std::vector<std::uint8_t> junk(64, 0xAB);
  ASSERT_TRUE((*w)->add_tile({0, 0, 0}, junk).ok());
  ASSERT_TRUE((*w)->finish((*good)->reader->metadata_json()).ok());

  auto s = vts::client::open_source(damaged.string());
  ASSERT_TRUE(s.ok()) << s.error().to_string();
  const SourceTile t = fetch(**s, {0, 0, 0});
  ASSERT_EQ(t.kind, SourceTile::Kind::error);
  ASSERT_TRUE(t.error.has_value());
  EXPECT_EQ(t.error->code, vts::ErrorCode::corrupt) << t.error->to_string();
  EXPECT_NE(t.error->message.find(damaged.string()), std::string::npos) << t.error->message;
  EXPECT_NE(t.error->message.find("0/0/0"), std::string::npos) << t.error->message;
  // A tile the archive lacks is still just absent.
  EXPECT_EQ(fetch(**s, {1, 0, 0}).kind, SourceTile::Kind::absent);
}

TEST(SourceLocalOpen, MeaninglessLocationsAreInvalidArguments) {
  for (const char* location :
       {"", "   ", "s3://", "s3:///no-bucket.pmtiles", "ftp://host/earth.pmtiles",
        "file://otherhost/x", "file:relative/x.pmtiles", "file:///bad%zzescape.pmtiles"}) {
    auto s = vts::client::open_source(location);
    ASSERT_FALSE(s.ok()) << location;
    EXPECT_EQ(s.error().code, vts::ErrorCode::invalid_argument) << s.error().to_string();
    if (*location != '\0' && *location != ' ') {
      EXPECT_NE(s.error().message.find(location), std::string::npos) << s.error().message;
    }
  }
}

TEST(SourceLocalOpen, OfflineSourceAnswersEveryFetchWithAnErrorAtOnce) {
  vts::client::SourceInfo info;
  info.key = "http://example.invalid/earth";
  info.version = "0123456789abcdef";
  auto source = vts::client::offline_source(info);
  EXPECT_EQ(source->info().key, info.key);
  EXPECT_EQ(source->info().version, info.version);
  int calls = 0;
  vts::client::SourceRequest r;
  r.id = {3, 1, 2};
  source->fetch(r, [&](SourceTile&& t) {
    ++calls;
    EXPECT_EQ(t.kind, SourceTile::Kind::error);
    ASSERT_TRUE(t.error.has_value());
    EXPECT_EQ(t.error->code, vts::ErrorCode::io);
    EXPECT_NE(t.error->message.find("offline"), std::string::npos);
    EXPECT_NE(t.error->message.find("3/1/2"), std::string::npos);
  });
  EXPECT_EQ(calls, 1);
}

TEST(SourceLocalOpen, EtagMatchingIsTheServersWeakComparison) {
  using vts::client::etag_matches;
  EXPECT_TRUE(etag_matches("\"abc\"", "\"abc\""));
  EXPECT_TRUE(etag_matches("W/\"abc\"", "\"abc\""));
  EXPECT_TRUE(etag_matches(" \"x\" , \"abc\" ", "\"abc\""));
  EXPECT_TRUE(etag_matches("*", "\"abc\""));
  EXPECT_FALSE(etag_matches("", "\"abc\""));
  EXPECT_FALSE(etag_matches("\"abd\"", "\"abc\""));
  EXPECT_FALSE(etag_matches("abc", "\"abc\""));
  EXPECT_FALSE(etag_matches(",,", "\"abc\""));
}

TEST(SourceLocalOpen, TileEtagRejectsPayloadsWithoutATileHeader) {
  const std::vector<std::uint8_t> junk(64, 0x11);
  auto e = vts::client::tile_etag(junk);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(vts::client::tile_etag({}).ok(), false);
}

TEST(SourceLocalOpen, CacheControlGivesTheFreshnessLifetime) {
  using vts::client::cache_control_lifetime;
  using vts::client::kFreshForever;
  EXPECT_EQ(cache_control_lifetime(""), -1);
  EXPECT_EQ(cache_control_lifetime("public"), -1);
  EXPECT_EQ(cache_control_lifetime("public, max-age=3600"), 3600);
  EXPECT_EQ(cache_control_lifetime("Max-Age=1"), 1);
  EXPECT_EQ(cache_control_lifetime("max-age=\"60\""), 60);
  EXPECT_EQ(cache_control_lifetime("public, max-age=31536000, immutable"), kFreshForever);
  EXPECT_EQ(cache_control_lifetime("no-cache"), 0);
  EXPECT_EQ(cache_control_lifetime("no-store, max-age=600"), 0);
  EXPECT_EQ(cache_control_lifetime("s-maxage=60"), -1);
  EXPECT_EQ(cache_control_lifetime("max-age=-5"), -1);
  EXPECT_EQ(cache_control_lifetime("max-age=abc"), -1);
  EXPECT_EQ(cache_control_lifetime("max-age=99999999999999999999999"), kFreshForever);
}
