// The cache daemon's provider and reconnecting upstream in process: a local archive built here is
// the upstream, a real TileCache (RAM + disk) holds the tiles, and the answers are what the HTTP
// front would turn into responses.
#include "vts/client/cache_provider.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <future>
#include <optional>

#include "vts/builder/builder.hpp"
#include "vts/client/source.hpp"
#include "vts/test/clock.hpp"
#include "vts/test/forge.hpp"
#include "vts/test/server.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;
using namespace vts::client;
using vts::ProvidedTile;
using vts::ProvidedTileset;
using vts::TileId;

namespace {

// A private temporary folder (vts::test::TempDir) whose path the tests name `d.path`.
struct Dir : vts::test::TempDir {
  Dir() : TempDir("vts-cache-provider-test"), path(TempDir::path()) {}
  const fs::path path;
};

// 1000 x 600 texels, levels 0-2; with a region, levels >= 1 hold only the tiles over it.
fs::path build_provider_archive(const fs::path& out,
                                std::optional<vts::TexelRect> region = std::nullopt,
                                std::uint64_t width = 1000) {
  vts::BuildOptions o;
  o.synthetic = vts::SyntheticSpec{width, 600, region, 1};
  o.output = out;
  o.threads = 1;
  auto r = vts::build_synthetic_pyramid(o);
  EXPECT_TRUE(r.ok()) << r.error().to_string();
  return out;
}

std::unique_ptr<TileSource> open_local(const fs::path& archive) {
  auto s = open_source(archive.string());
  EXPECT_TRUE(s.ok()) << s.error().to_string();
  return s.ok() ? std::move(*s) : nullptr;
}

// A provider over `upstream` (online when `online` is given) with a RAM and a disk cache.
struct Daemon {
  std::shared_ptr<ReconnectingSource> upstream;
  std::shared_ptr<CacheProvider> provider;
  std::shared_ptr<const ProvidedTileset> tileset;

  Daemon(const SourceInfo& info, std::unique_ptr<TileSource> online, const fs::path& location,
         const fs::path& cache_dir, ReconnectingSource::Hooks hooks = {}) {
    upstream =
        std::make_shared<ReconnectingSource>(info, std::move(online), location.string(),
                                             SourceOptions{}, std::chrono::milliseconds(20), hooks);
    TileCacheOptions co;
    co.ram_bytes = 16u << 20;
    co.disk = DiskCacheOptions{};
    co.disk->dir = cache_dir;
    auto cache = TileCache::create(upstream, co);
    EXPECT_TRUE(cache.ok()) << cache.error().to_string();
    auto t = std::make_shared<ProvidedTileset>();
    t->name = "earth";
    t->info = info.info;
    t->version = info.version;
    tileset = t;
    provider = std::make_shared<CacheProvider>(tileset, std::move(*cache), upstream);
  }
  ~Daemon() { EXPECT_TRUE(provider->shutdown().ok()); }

  ProvidedTile get(TileId id) {
    std::promise<ProvidedTile> p;
    auto f = p.get_future();
    provider->tile(tileset, id, [&p](ProvidedTile t) { p.set_value(std::move(t)); });
    EXPECT_EQ(f.wait_for(std::chrono::seconds(10)), std::future_status::ready);
    return f.get();
  }
};

std::vector<std::uint8_t> payload_of(TileSource& source, TileId id) {
  std::vector<std::uint8_t> out;
  SourceRequest r;
  r.id = id;
  source.fetch(r, [&](SourceTile&& t) { out = std::move(t.payload); });
  return out;
}

TEST(CacheProvider, FindsItsOneTilesetByName) {
  Dir d;
  const fs::path archive = build_provider_archive(d.path / "a.pmtiles");
  auto local = open_local(archive);
  const SourceInfo info = local->info();
  Daemon daemon(info, std::move(local), archive, d.path / "cache");
  EXPECT_EQ(daemon.provider->find("earth"), daemon.tileset);
  EXPECT_EQ(daemon.provider->find("mars"), nullptr);
  ASSERT_EQ(daemon.provider->all().size(), 1u);
  EXPECT_EQ(daemon.provider->all()[0], daemon.tileset);
}

TEST(CacheProvider, ServesTheUpstreamsTileBytesThenFromTheCache) {
  Dir d;
  const fs::path archive = build_provider_archive(d.path / "a.pmtiles");
  auto local = open_local(archive);
  const std::vector<std::uint8_t> want = payload_of(*local, TileId{2, 1, 1});
  ASSERT_FALSE(want.empty());
  const SourceInfo info = local->info();
  Daemon daemon(info, std::move(local), archive, d.path / "cache");

  for (int i = 0; i < 2; ++i) {
    const ProvidedTile t = daemon.get(TileId{2, 1, 1});
    ASSERT_EQ(t.kind, ProvidedTile::Kind::ok) << t.message;
    EXPECT_TRUE(t.keep) << "the payload's owner travels with it";
    EXPECT_EQ(std::vector<std::uint8_t>(t.payload.begin(), t.payload.end()), want);
  }
  const std::string metrics = daemon.provider->metrics_text();
  EXPECT_NE(metrics.find("vts_cache_gets_total 2\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("vts_cache_upstream_fetches_total 1\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("vts_cache_hits_total{level=\"ram\"} 1\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("vts_cache_upstream_online 1\n"), std::string::npos) << metrics;
}

// A tile whose header contradicts the tileset (the upstream's archive holds a 64 x 64 tile, and
// one declaring 8192 x 8192 texels in 8 KiB, in a tileset of 264 x 264 tiles) is refused like a
// corrupt answer: a 502 for the requester, nothing cached, counted in /metrics; the daemon stays
// healthy (it is the upstream that is broken).
TEST(CacheProvider, ATileThatContradictsTheTilesetIsBadOriginAndNeverCached) {
  Dir d;
  const fs::path good = build_provider_archive(d.path / "good.pmtiles");
  const fs::path forged = d.path / "forged.pmtiles";
  vts::test::copy_archive_replacing(good, forged,
                                    {{TileId{2, 1, 1}, vts::test::flat_tile(64, 64, 9)},
                                     {TileId{2, 2, 1}, vts::test::flat_tile(8192, 8192, 9)}});
  auto local = open_local(forged);
  const SourceInfo info = local->info();
  ASSERT_EQ(info.info.geometry.stored_size(), 264u);
  Daemon daemon(info, std::move(local), forged, d.path / "cache");
  for (const TileId id : {TileId{2, 1, 1}, TileId{2, 2, 1}, TileId{2, 1, 1}}) {
    const ProvidedTile t = daemon.get(id);
    EXPECT_EQ(t.kind, ProvidedTile::Kind::bad_origin) << id.to_string() << ": " << t.message;
    EXPECT_NE(t.message.find("the tileset's tiles are 264x264"), std::string::npos) << t.message;
  }
  EXPECT_EQ(daemon.get(TileId{2, 0, 0}).kind, ProvidedTile::Kind::ok);
  const std::string metrics = daemon.provider->metrics_text();
  EXPECT_NE(metrics.find("vts_cache_tileset_mismatch_rejected_total 9\n"), std::string::npos)
      << metrics;  // 3 gets x (1 + 2 re-fetches)
  EXPECT_EQ(daemon.provider->health_problem(), "");
}

// Revalidation against a real upstream (`vts serve` on loopback): the daemon sends back, as
// If-None-Match, the tag the upstream gave with the tile, and the upstream answers 304 (its own
// metrics count it); the tile stays served, with the tag derived from its header frame (what the
// router puts in ETag), which for this upstream is the same tag.
TEST(CacheProvider, AStaleTileIsRevalidatedWithTheUpstreamsTagAndTheUpstreamAnswers304) {
  Dir d;
  const fs::path archive = build_provider_archive(d.path / "earth.pmtiles");
  vts::test::RunningServer server({archive});
  const std::string location = server.base_url() + "/earth";
  auto opened = open_source(location);
  ASSERT_TRUE(opened.ok()) << opened.error().to_string();
  const SourceInfo info = (*opened)->info();
  auto upstream = std::make_shared<ReconnectingSource>(
      info, std::move(*opened), location, SourceOptions{}, std::chrono::milliseconds(20));
  TileCacheOptions co;
  co.disk = DiskCacheOptions{};
  co.disk->dir = d.path / "cache";
  co.revalidate_after = std::chrono::seconds(0);  // every hit is stale, whatever the server says
  co.fixed_revalidate_after = true;
  auto cache = TileCache::create(upstream, co);
  ASSERT_TRUE(cache.ok()) << cache.error().to_string();
  TileCache* c = cache->get();
  auto tileset = std::make_shared<ProvidedTileset>();
  tileset->name = "earth";
  tileset->info = info.info;
  CacheProvider provider(tileset, std::move(*cache), upstream);
  auto get = [&] {
    std::promise<ProvidedTile> p;
    auto f = p.get_future();
    provider.tile(tileset, TileId{2, 1, 1}, [&p](ProvidedTile t) { p.set_value(std::move(t)); });
    EXPECT_EQ(f.wait_for(std::chrono::seconds(10)), std::future_status::ready);
    return f.get();
  };
  const ProvidedTile first = get();
  ASSERT_EQ(first.kind, ProvidedTile::Kind::ok) << first.message;
  const std::string derived = tile_etag(first.payload).value();
  auto held = c->ram()->get(TileKey{info.key, TileId{2, 1, 1}});
  ASSERT_TRUE(held);
  EXPECT_EQ(held->etag, derived) << "vts serve's ETag is the derived tag";

  const ProvidedTile second = get();  // a RAM hit, stale: revalidated in the background
  ASSERT_EQ(second.kind, ProvidedTile::Kind::ok);
  EXPECT_EQ(tile_etag(second.payload).value(), derived);
  ASSERT_TRUE(vts::test::wait_until([&] { return c->stats().not_modified == 1; }))
      << "revalidations " << c->stats().revalidations;
  // The server counts an answer once its last byte is written, which may be after the client has
  // read it: wait for the count rather than read it once.
  const std::string line = "vts_http_requests_total{route=\"tile\",status=\"304\"} 1\n";
  EXPECT_TRUE(vts::test::wait_until([&] {
    return server.server().metrics_text().find(line) != std::string::npos;
  })) << server.server().metrics_text();
  EXPECT_TRUE(provider.shutdown().ok());
}

TEST(CacheProvider, ATileTheUpstreamLacksIsAbsent) {
  Dir d;
  const fs::path archive =
      build_provider_archive(d.path / "sparse.pmtiles", vts::TexelRect{0, 0, 256, 256});
  auto local = open_local(archive);
  const SourceInfo info = local->info();
  Daemon daemon(info, std::move(local), archive, d.path / "cache");
  EXPECT_EQ(daemon.get(TileId{2, 3, 2}).kind, ProvidedTile::Kind::absent);
  EXPECT_EQ(daemon.get(TileId{2, 0, 0}).kind, ProvidedTile::Kind::ok);
  EXPECT_NE(daemon.provider->metrics_text().find("vts_cache_absent_total 1\n"), std::string::npos);
}

TEST(CacheProvider, OfflineItServesWhatTheCacheHoldsAndTheRestIsUnavailable) {
  Dir d;
  const fs::path archive = build_provider_archive(d.path / "a.pmtiles");
  auto local = open_local(archive);
  const SourceInfo info = local->info();
  {
    Daemon online(info, std::move(local), archive, d.path / "cache");
    ASSERT_EQ(online.get(TileId{0, 0, 0}).kind, ProvidedTile::Kind::ok);
  }
  // The upstream is gone: the daemon starts offline, from the same cache folder.
  fs::rename(archive, d.path / "moved.pmtiles");
  Daemon offline(info, nullptr, archive, d.path / "cache");
  EXPECT_FALSE(offline.upstream->online());
  EXPECT_EQ(offline.get(TileId{0, 0, 0}).kind, ProvidedTile::Kind::ok);
  const ProvidedTile missing = offline.get(TileId{2, 1, 1});
  EXPECT_EQ(missing.kind, ProvidedTile::Kind::unavailable);
  EXPECT_FALSE(missing.message.empty());
  const std::string metrics = offline.provider->metrics_text();
  EXPECT_NE(metrics.find("vts_cache_upstream_online 0\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("vts_cache_errors_total 1\n"), std::string::npos) << metrics;
}

TEST(CacheProvider, AnOfflineUpstreamGoesOnlineWhenTheSameTilesetOpensAgain) {
  Dir d;
  const fs::path archive = build_provider_archive(d.path / "a.pmtiles");
  SourceInfo info = open_local(archive)->info();
  fs::rename(archive, d.path / "moved.pmtiles");
  std::promise<SourceInfo> back;
  ReconnectingSource::Hooks hooks;
  hooks.back_online = [&back](const SourceInfo& now) { back.set_value(now); };
  Daemon daemon(info, nullptr, archive, d.path / "cache", hooks);
  EXPECT_EQ(daemon.get(TileId{2, 1, 1}).kind, ProvidedTile::Kind::unavailable);

  fs::rename(d.path / "moved.pmtiles", archive);
  auto f = back.get_future();
  ASSERT_EQ(f.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_EQ(f.get().key, info.key);
  EXPECT_TRUE(daemon.upstream->online());
  EXPECT_EQ(daemon.get(TileId{2, 1, 1}).kind, ProvidedTile::Kind::ok);
}

TEST(CacheProvider, AnArchiveOverwrittenInPlaceIsReopenedAndItsNewTilesServed) {
  Dir d;
  const fs::path archive = build_provider_archive(d.path / "a.pmtiles");
  // The same tileset (name, geometry, codec) with other bytes: built with another zstd level.
  vts::BuildOptions o;
  o.synthetic = vts::SyntheticSpec{1000, 600, std::nullopt, 1};
  o.output = d.path / "b" / "a.pmtiles";
  o.threads = 1;
  o.encode.zstd_level = 19;
  fs::create_directories(d.path / "b");
  ASSERT_TRUE(vts::build_synthetic_pyramid(o).ok());
  auto first = open_local(archive);
  const SourceInfo info = first->info();
  std::promise<SourceInfo> back;
  ReconnectingSource::Hooks hooks;
  hooks.back_online = [&back](const SourceInfo& now) { back.set_value(now); };
  Daemon daemon(info, std::move(first), archive, d.path / "cache", hooks);
  ASSERT_EQ(daemon.get(TileId{0, 0, 0}).kind, ProvidedTile::Kind::ok);

  fs::copy_file(o.output, archive, fs::copy_options::overwrite_existing);  // in place
  // The first request after the change meets it: never the old archive's offsets in the new file.
  const ProvidedTile during = daemon.get(TileId{2, 1, 1});
  EXPECT_NE(during.kind, ProvidedTile::Kind::ok);
  auto f = back.get_future();
  ASSERT_EQ(f.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_TRUE(daemon.upstream->online());
  const ProvidedTile after = daemon.get(TileId{2, 1, 1});
  ASSERT_EQ(after.kind, ProvidedTile::Kind::ok);
  auto b = open_local(o.output);
  EXPECT_EQ(std::vector<std::uint8_t>(after.payload.begin(), after.payload.end()),
            payload_of(*b, TileId{2, 1, 1}));
}

TEST(CacheProvider, AnUpstreamThatReopensWithAnotherTilesetStaysOffline) {
  Dir d;
  const fs::path archive = build_provider_archive(d.path / "a.pmtiles");
  SourceInfo info = open_local(archive)->info();
  fs::remove(archive);
  build_provider_archive(archive, std::nullopt, 1200);  // same location (key), other geometry
  std::promise<SourceInfo> changed;
  std::atomic<bool> once{false};
  ReconnectingSource::Hooks hooks;
  hooks.changed = [&](const SourceInfo& now) {
    if (!once.exchange(true)) changed.set_value(now);
  };
  Daemon daemon(info, nullptr, archive, d.path / "cache", hooks);
  auto f = changed.get_future();
  ASSERT_EQ(f.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_EQ(f.get().info.geometry.width(), 1200u);
  EXPECT_FALSE(daemon.upstream->online());
  EXPECT_EQ(daemon.upstream->info().info.geometry.width(), 1000u) << "info() never changes";
}

TEST(CacheProvider, AfterShutdownTheMetricsAreEmptyAndShutdownIsIdempotent) {
  Dir d;
  const fs::path archive = build_provider_archive(d.path / "a.pmtiles");
  auto local = open_local(archive);
  const SourceInfo info = local->info();
  Daemon daemon(info, std::move(local), archive, d.path / "cache");
  EXPECT_FALSE(daemon.provider->metrics_text().empty());
  EXPECT_TRUE(daemon.provider->shutdown().ok());
  EXPECT_TRUE(daemon.provider->metrics_text().empty());
}

TEST(CacheProvider, SameTilesetComparesKeyGeometryAndCodec) {
  Dir d;
  const SourceInfo a = open_local(build_provider_archive(d.path / "a.pmtiles"))->info();
  SourceInfo other_key = a;
  other_key.key += "x";
  const SourceInfo wider =
      open_local(build_provider_archive(d.path / "b.pmtiles", std::nullopt, 1200))->info();
  SourceInfo wider_same_key = wider;
  wider_same_key.key = a.key;
  EXPECT_TRUE(same_tileset(a, a));
  EXPECT_FALSE(same_tileset(a, other_key));
  EXPECT_FALSE(same_tileset(a, wider_same_key));
}

TEST(CacheProvider, TheDefaultNameIsTheLocationsLastSegmentWithoutItsExtension) {
  EXPECT_EQ(default_tileset_name("http://host:8080/earth"), "earth");
  EXPECT_EQ(default_tileset_name("http://host:8080/earth.json"), "earth");
  EXPECT_EQ(default_tileset_name("https://h/tiles/earth.v2.pmtiles?sig=1#x"), "earth.v2");
  EXPECT_EQ(default_tileset_name("/data/earth.pmtiles"), "earth");
  EXPECT_EQ(default_tileset_name("http://host:8080/earth/"), "earth");
  EXPECT_EQ(default_tileset_name("http://host:8080"), "");
  EXPECT_EQ(default_tileset_name("http://host:8080/"), "");
}

}  // namespace
