// The tile sources over the network, in process: the real `vts serve` (HttpServer + registry on
// 127.0.0.1 port 0) for TileJSON and its .pmtiles route, and FaultServer as the plain static file
// server (Range requests, no tile logic) for remote archives. Archives come from the real builder;
// every tile a network source returns is compared with what the local-archive source returns for
// the same file: same kind, same bytes, same ETag.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "fault_server.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_cache.hpp"
#include "vts/server/http_server.hpp"
#include "vts/test/archive.hpp"
#include "vts/test/server.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using vts::TileId;
using vts::client::SourceRequest;
using vts::client::SourceTile;
using vts::client::TileSource;
using vts::test::FaultServer;

namespace {

// ---------------------------------------------------------------------------------------------
// Archives and servers, made on first use (each ctest is its own process; each builds only what
// its test needs).

const fs::path& dir() {
  static const vts::test::TempDir d("vts-sources-test");
  [[maybe_unused]] static const bool served = fs::create_directories(d / "served");
  return d.path();
}

struct Cleanup : ::testing::Environment {
  void TearDown() override;
};

void build(const fs::path& out, std::uint64_t w, std::uint64_t h,
           std::optional<vts::TexelRect> region = std::nullopt, int region_level = 6,
           std::uint32_t tile = 256, std::uint32_t border = 4,
           vts::FilterChoice filter = vts::FilterChoice::automatic) {
  vts::BuildOptions o = vts::test::synthetic_options(out, w, h, region, region_level);
  o.tile_size = tile;
  o.border = border;
  o.encode.filter = filter;
  vts::test::build_archive(o);
}

// Archives served by `vts serve` live in dir()/served (the registry loads the folder).
const fs::path& syn_archive() {
  static const fs::path p = [] {
    fs::path a = dir() / "served" / "syn.pmtiles";
    build(a, 3000, 1500);
    return a;
  }();
  return p;
}

const fs::path& sparse_archive() {
  static const fs::path p = [] {
    fs::path a = dir() / "served" / "sparse.pmtiles";
    build(a, 3000, 1500, vts::TexelRect{0, 0, 700, 600}, 2);
    return a;
  }();
  return p;
}

// 43,691 tiles of 4x4 texels: too many directory entries for a 16 KiB root, so the writer makes
// one level of leaf directories (11 of them).
const fs::path& leafy_archive() {
  static const fs::path p = [] {
    fs::path a = dir() / "leafy.pmtiles";
    build(a, 1024, 512, std::nullopt, 6, 4, 0);
    return a;
  }();
  return p;
}

// `vts serve` on its own thread for the life of the process (or of a test, for special configs).
class RunningServer {
 public:
  explicit RunningServer(vts::RouterConfig router = {})
      : server_(served(), options(std::move(router))) {}
  std::string base() const { return server_.base_url(); }
  vts::TilesetRegistry& registry() { return server_.registry(); }

 private:
  static std::vector<fs::path> served() {
    syn_archive();
    sparse_archive();
    return {dir() / "served"};
  }
  static vts::HttpServerOptions options(vts::RouterConfig router) {
    vts::HttpServerOptions o = vts::test::RunningServer::quiet_options();
    o.router = std::move(router);
    return o;
  }
  vts::test::RunningServer server_;
};

// The shared server, stopped by Cleanup before static destruction.
std::unique_ptr<RunningServer> g_serve;
std::mutex g_serve_mutex;

RunningServer& serve() {
  std::lock_guard lock(g_serve_mutex);
  if (!g_serve) g_serve = std::make_unique<RunningServer>();
  return *g_serve;
}

FaultServer& static_server(const fs::path& archive, const std::string& name) {
  static std::mutex m;
  static std::map<std::string, std::unique_ptr<FaultServer>> servers;
  std::lock_guard lock(m);
  auto& s = servers[name];
  if (!s) {
    auto started = FaultServer::start(archive, name);
    if (!started) throw std::runtime_error(started.error().to_string());
    s = std::move(*started);
  }
  return *s;
}

void Cleanup::TearDown() {
  g_serve.reset();
}
const auto* const kCleanup = ::testing::AddGlobalTestEnvironment(new Cleanup);

// Fast failure for unreachable hosts and injected errors.
vts::client::SourceOptions quick_options() {
  vts::client::SourceOptions o;
  o.fetcher.max_attempts = 2;
  o.fetcher.backoff_base = 10ms;
  o.fetcher.backoff_max = 50ms;
  o.fetcher.connect_timeout = 2000ms;
  o.fetcher.request_timeout = 10000ms;
  return o;
}

std::unique_ptr<TileSource> open_ok(const std::string& location,
                                    vts::client::SourceOptions o = quick_options()) {
  auto s = vts::client::open_source(location, std::move(o));
  if (!s) ADD_FAILURE() << location << ": " << s.error().to_string();
  return s ? std::move(*s) : nullptr;
}

// ---------------------------------------------------------------------------------------------
// Fetching

// Collects answers to many fetches; checks every callback runs exactly once.
class Collector {
 public:
  explicit Collector(std::size_t n) : tiles_(n), calls_(n, 0) {}
  vts::client::SourceCallback callback(std::size_t i) {
    return [this, i](SourceTile&& t) {
      std::lock_guard lock(mutex_);
      tiles_[i] = std::move(t);
      if (++calls_[i] == 1) ++done_;
      cv_.notify_all();
    };
  }
  // Waits for every answer; false on timeout.
  bool wait(std::chrono::seconds timeout = 20s) {
    std::unique_lock lock(mutex_);
    return cv_.wait_for(lock, timeout, [&] { return done_ == tiles_.size(); });
  }
  bool each_called_once() {
    std::lock_guard lock(mutex_);
    for (int c : calls_)
      if (c != 1) return false;
    return true;
  }
  std::vector<SourceTile>& tiles() { return tiles_; }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<SourceTile> tiles_;
  std::vector<int> calls_;
  std::size_t done_ = 0;
};

std::vector<SourceTile> fetch_all(TileSource& source, const std::vector<SourceRequest>& requests) {
  Collector c(requests.size());
  for (std::size_t i = 0; i < requests.size(); ++i) source.fetch(requests[i], c.callback(i));
  EXPECT_TRUE(c.wait()) << "not every fetch was answered within 20 s";
  std::this_thread::sleep_for(5ms);  // a second, wrong call would show up here
  EXPECT_TRUE(c.each_called_once());
  return std::move(c.tiles());
}

SourceTile fetch_one(TileSource& source, TileId id, std::string inm = {}) {
  SourceRequest r;
  r.id = id;
  r.if_none_match = std::move(inm);
  return std::move(fetch_all(source, {r}).at(0));
}

std::vector<SourceRequest> every_tile(const vts::Geometry& g) {
  std::vector<SourceRequest> out;
  for (int z = 0; z <= g.max_zoom(); ++z)
    for (std::uint32_t y = 0; y < g.tiles_y(z); ++y)
      for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) {
        SourceRequest r;
        r.id = {static_cast<std::uint8_t>(z), x, y};
        r.level = z;
        out.push_back(r);
      }
  return out;
}

const char* kind_name(SourceTile::Kind k) {
  switch (k) {
    case SourceTile::Kind::ok:
      return "ok";
    case SourceTile::Kind::not_modified:
      return "not_modified";
    case SourceTile::Kind::absent:
      return "absent";
    case SourceTile::Kind::error:
      return "error";
    case SourceTile::Kind::cancelled:
      return "cancelled";
  }
  return "?";
}

std::string describe(const SourceTile& t) {
  std::string s = kind_name(t.kind);
  if (t.error) s += ": " + t.error->to_string();
  return s;
}

// Every request answered by `remote` exactly as the local source answers it for `archive`.
void expect_same_as_local(TileSource& remote, const fs::path& archive,
                          const std::vector<SourceRequest>& requests, int* ok_count = nullptr) {
  auto local = vts::client::open_local_archive(archive);
  ASSERT_TRUE(local.ok()) << local.error().to_string();
  const std::vector<SourceTile> want = fetch_all(**local, requests);
  const std::vector<SourceTile> got = fetch_all(remote, requests);
  int ok = 0;
  for (std::size_t i = 0; i < requests.size(); ++i) {
    const std::string id = requests[i].id.to_string();
    ASSERT_EQ(got[i].kind, want[i].kind) << id << ": " << describe(got[i]);
    EXPECT_EQ(got[i].etag, want[i].etag) << id;
    ASSERT_EQ(got[i].payload, want[i].payload) << id;
    ok += got[i].kind == SourceTile::Kind::ok;
  }
  if (ok_count) *ok_count = ok;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// TileJSON source against `vts serve`

TEST(TileJsonSource, ReturnsEveryTileByteExactWithTheLocalEtags) {
  auto source = open_ok(serve().base() + "/syn");
  ASSERT_TRUE(source);
  EXPECT_FALSE(source->local());
  auto local = vts::client::open_local_archive(syn_archive());
  ASSERT_TRUE(local.ok());
  const auto& info = source->info();
  EXPECT_EQ(info.key, serve().base() + "/syn");
  EXPECT_EQ(info.version, (*local)->info().version) << "the server's version is the archive's";
  EXPECT_EQ(info.info.geometry.width(), 3000u);
  EXPECT_EQ(info.info.geometry.height(), 1500u);
  EXPECT_NE(info.description_json.find("\"tilejson\""), std::string::npos);
  int ok = 0;
  expect_same_as_local(*source, syn_archive(), every_tile(info.info.geometry), &ok);
  EXPECT_EQ(ok, static_cast<int>(info.info.geometry.total_tile_count()));
}

TEST(TileJsonSource, OpensFromTheJsonUrlWithTheSameKey) {
  auto source = open_ok(serve().base() + "/syn.json");
  ASSERT_TRUE(source);
  EXPECT_EQ(source->info().key, serve().base() + "/syn");
  ASSERT_EQ(fetch_one(*source, {0, 0, 0}).kind, SourceTile::Kind::ok);
}

TEST(TileJsonSource, IfNoneMatchWithTheCurrentEtagIsNotModified) {
  auto source = open_ok(serve().base() + "/syn");
  ASSERT_TRUE(source);
  const SourceTile first = fetch_one(*source, {2, 1, 1});
  ASSERT_EQ(first.kind, SourceTile::Kind::ok) << describe(first);
  const SourceTile again = fetch_one(*source, {2, 1, 1}, first.etag);
  EXPECT_EQ(again.kind, SourceTile::Kind::not_modified) << describe(again);
  EXPECT_EQ(again.etag, first.etag);
  EXPECT_TRUE(again.payload.empty());
  const SourceTile stale = fetch_one(*source, {2, 1, 1}, "\"0000000000000000\"");
  EXPECT_EQ(stale.kind, SourceTile::Kind::ok);
  EXPECT_EQ(stale.payload, first.payload);
}

TEST(TileJsonSource, KnownEmptyTilesOfASparseArchiveAreAbsent) {
  auto source = open_ok(serve().base() + "/sparse");
  ASSERT_TRUE(source);
  ASSERT_TRUE(source->info().info.sparse);
  int ok = 0;
  const auto requests = every_tile(source->info().info.geometry);
  expect_same_as_local(*source, sparse_archive(), requests, &ok);
  EXPECT_GT(ok, 0);
  EXPECT_LT(ok, static_cast<int>(requests.size())) << "some tiles must be absent (204)";
  // Outside the pyramid (404 from the server) is absent too.
  EXPECT_EQ(fetch_one(*source, {20, 0, 0}).kind, SourceTile::Kind::absent);
}

TEST(TileJsonSource, FollowsARebuiltArchiveToItsNewVersion) {
  const fs::path archive = dir() / "served" / "rebuilt.pmtiles";
  build(archive, 700, 500, std::nullopt, 6, 256, 4, vts::FilterChoice::none);
  serve().registry().reload(true);
  auto source = open_ok(serve().base() + "/rebuilt");
  ASSERT_TRUE(source);
  const std::string old_version = source->info().version;
  const SourceTile before = fetch_one(*source, {1, 0, 0});
  ASSERT_EQ(before.kind, SourceTile::Kind::ok) << describe(before);

  // Same geometry, other bytes (another filter), hence another version: the old versioned URLs
  // now answer 404 "not current".
  build(archive, 700, 500, std::nullopt, 6, 256, 4, vts::FilterChoice::gradient);
  const auto reloaded = serve().registry().reload(true);
  ASSERT_TRUE(reloaded.failures.empty());
  ASSERT_NE(serve().registry().find("rebuilt")->version, old_version);

  // Concurrent requests on the old template all get there, whichever refetches the TileJSON.
  int ok = 0;
  expect_same_as_local(*source, archive, every_tile(source->info().info.geometry), &ok);
  EXPECT_GT(ok, 0);
  const SourceTile after = fetch_one(*source, {1, 0, 0});
  ASSERT_EQ(after.kind, SourceTile::Kind::ok);
  EXPECT_NE(after.payload, before.payload);
  EXPECT_EQ(source->info().version, old_version) << "SourceInfo describes the tileset as opened";
}

TEST(TileJsonSource, RebuiltWithAnotherGeometryFailsAskingToReopen) {
  const fs::path archive = dir() / "served" / "reshaped.pmtiles";
  build(archive, 700, 500);
  serve().registry().reload(true);
  auto source = open_ok(serve().base() + "/reshaped");
  ASSERT_TRUE(source);
  build(archive, 900, 500);
  serve().registry().reload(true);
  const SourceTile t = fetch_one(*source, {0, 0, 0});
  ASSERT_EQ(t.kind, SourceTile::Kind::error);
  EXPECT_NE(t.error->message.find("open it again"), std::string::npos) << t.error->message;
  EXPECT_NE(t.error->message.find("/reshaped.json"), std::string::npos) << t.error->message;
}

TEST(TileJsonSource, CancelAnswersCancelledAtOnce) {
  // Tiles under a URL that never answers: the TileJSON's base URL points at a stalling server.
  FaultServer& stall = static_server(syn_archive(), "syn");
  vts::RouterConfig router;
  router.public_base_url = stall.base_url() + "/fault/stall";
  RunningServer server(router);
  auto source = open_ok(server.base() + "/syn");
  ASSERT_TRUE(source);

  Collector c(3);
  SourceRequest r;
  r.id = {0, 0, 0};
  const auto h0 = source->fetch(r, c.callback(0));
  r.id = {1, 0, 0};
  const auto h1 = source->fetch(r, c.callback(1));
  r.id = {1, 1, 0};
  source->fetch(r, c.callback(2));
  std::this_thread::sleep_for(100ms);  // the transfers are on the wire, stalled
  const auto start = std::chrono::steady_clock::now();
  source->cancel(h0);
  source->cancel(h1);
  source->cancel(h1);      // twice: harmless
  source->cancel(999999);  // unknown: ignored
  // The third is cancelled by destroying the source.
  std::this_thread::sleep_for(20ms);
  source.reset();
  ASSERT_TRUE(c.wait(5s));
  EXPECT_LT(std::chrono::steady_clock::now() - start, 2s);
  EXPECT_TRUE(c.each_called_once());
  for (const SourceTile& t : c.tiles()) EXPECT_EQ(t.kind, SourceTile::Kind::cancelled);
}

TEST(TileJsonSource, ServerErrorsOnTilesNameTheUrl) {
  FaultServer& faults = static_server(syn_archive(), "syn");
  vts::RouterConfig router;
  router.public_base_url = faults.base_url() + "/fault/403";
  RunningServer server(router);
  auto source = open_ok(server.base() + "/syn");
  ASSERT_TRUE(source);
  const SourceTile t = fetch_one(*source, {0, 0, 0});
  ASSERT_EQ(t.kind, SourceTile::Kind::error);
  ASSERT_TRUE(t.error);
  EXPECT_NE(t.error->message.find(faults.base_url() + "/fault/403/syn@"), std::string::npos)
      << t.error->message;
  EXPECT_NE(t.error->message.find("403"), std::string::npos) << t.error->message;
}

// ---------------------------------------------------------------------------------------------
// Remote archive source: range reads from a plain static server, and from `vts serve`

TEST(RemoteArchiveSource, ReturnsEveryTileByteExactWithTheLocalEtags) {
  FaultServer& files = static_server(syn_archive(), "syn");
  const std::string url = files.base_url() + "/syn.pmtiles";
  auto source = open_ok(url);
  ASSERT_TRUE(source);
  EXPECT_FALSE(source->local());
  auto local = vts::client::open_local_archive(syn_archive());
  ASSERT_TRUE(local.ok());
  EXPECT_EQ(source->info().key, url);
  EXPECT_EQ(source->info().version, (*local)->info().version);
  EXPECT_EQ(source->info().description_json, (*local)->info().description_json);
  int ok = 0;
  expect_same_as_local(*source, syn_archive(), every_tile(source->info().info.geometry), &ok);
  EXPECT_EQ(ok, static_cast<int>(source->info().info.geometry.total_tile_count()));
}

TEST(RemoteArchiveSource, ReadsVtsServesArchiveRoute) {
  auto source = open_ok(serve().base() + "/sparse.pmtiles");
  ASSERT_TRUE(source);
  auto tilejson = open_ok(serve().base() + "/sparse");
  ASSERT_TRUE(tilejson);
  EXPECT_EQ(source->info().version, tilejson->info().version);
  int ok = 0;
  const auto requests = every_tile(source->info().info.geometry);
  expect_same_as_local(*source, sparse_archive(), requests, &ok);
  EXPECT_GT(ok, 0);
  EXPECT_LT(ok, static_cast<int>(requests.size())) << "some tiles must be absent";
}

TEST(RemoteArchiveSource, IfNoneMatchWithTheCurrentEtagIsNotModified) {
  auto source = open_ok(static_server(syn_archive(), "syn").base_url() + "/syn.pmtiles");
  ASSERT_TRUE(source);
  const SourceTile first = fetch_one(*source, {3, 2, 1});
  ASSERT_EQ(first.kind, SourceTile::Kind::ok) << describe(first);
  const SourceTile again = fetch_one(*source, {3, 2, 1}, "W/" + first.etag);
  EXPECT_EQ(again.kind, SourceTile::Kind::not_modified) << describe(again);
  EXPECT_EQ(again.etag, first.etag);
  EXPECT_TRUE(again.payload.empty());
  EXPECT_EQ(fetch_one(*source, {3, 2, 1}, "\"0123456789abcdef\"").payload, first.payload);
}

TEST(RemoteArchiveSource, ReadsThroughLeafDirectoriesByteExact) {
  auto reader = vts::archive::Reader::open(leafy_archive());
  ASSERT_TRUE(reader.ok());
  auto leaves = (*reader)->leaf_directory_count();
  ASSERT_TRUE(leaves.ok());
  ASSERT_GT(*leaves, 1u) << "the test archive must have leaf directories";

  // Every 8th entry, and the first and last tile of every run: each leaf is visited many times.
  std::vector<SourceRequest> requests;
  std::uint64_t n = 0;
  ASSERT_TRUE((*reader)
                  ->for_each_entry([&](const vts::archive::Entry& e) {
                    for (std::uint64_t id : {e.tile_id, e.tile_id + e.run_length - 1}) {
                      if (n++ % 8 != 0) continue;
                      SourceRequest r;
                      r.id = *vts::archive::tile_id_to_zxy(id);
                      requests.push_back(r);
                    }
                    return true;
                  })
                  .ok());
  // Scattered tiles of the finest level, and tiles outside the pyramid.
  for (std::uint32_t i = 0; i < 64; ++i) {
    SourceRequest r;
    r.id = {8, i * 13 % 256, i * 7 % 128};
    requests.push_back(r);
  }
  for (TileId id : {TileId{8, 0, 128}, TileId{8, 256, 0}, TileId{9, 0, 0}}) {
    SourceRequest r;
    r.id = id;
    requests.push_back(r);
  }
  FaultServer& files = static_server(leafy_archive(), "leafy");
  files.reset();
  auto source = open_ok(files.base_url() + "/leafy.pmtiles");
  ASSERT_TRUE(source);
  int ok = 0;
  expect_same_as_local(*source, leafy_archive(), requests, &ok);
  EXPECT_GT(ok, 5000);
  // One read to open, one per tile, and each leaf read about once (merged while in flight, then
  // from the LRU), not once per tile.
  const int reads = files.attempts("/leafy.pmtiles");
  EXPECT_LE(reads, 1 + static_cast<int>(requests.size()) + 2 * static_cast<int>(*leaves)) << reads;
}

TEST(RemoteArchiveSource, CancelAnswersCancelledAndEveryCallbackRunsOnce) {
  vts::client::SourceOptions o = quick_options();
  o.fetcher.max_in_flight = 1;  // the rest queue behind one transfer
  auto source = open_ok(static_server(syn_archive(), "syn").base_url() + "/syn.pmtiles", o);
  ASSERT_TRUE(source);
  const auto requests = every_tile(source->info().info.geometry);
  Collector c(requests.size());
  std::vector<TileSource::Handle> handles;
  for (std::size_t i = 0; i < requests.size(); ++i) {
    handles.push_back(source->fetch(requests[i], c.callback(i)));
  }
  for (std::size_t i = requests.size() / 2; i < requests.size(); ++i) source->cancel(handles[i]);
  ASSERT_TRUE(c.wait());
  int cancelled = 0;
  for (const SourceTile& t : c.tiles()) {
    EXPECT_TRUE(t.kind == SourceTile::Kind::ok || t.kind == SourceTile::Kind::cancelled)
        << describe(t);
    cancelled += t.kind == SourceTile::Kind::cancelled;
  }
  EXPECT_GT(cancelled, 0);
  EXPECT_EQ(c.tiles().front().kind, SourceTile::Kind::ok);
  EXPECT_TRUE(c.each_called_once());

  // Destroying the source with work queued cancels it; every callback still runs once.
  Collector d(requests.size());
  for (std::size_t i = 0; i < requests.size(); ++i) source->fetch(requests[i], d.callback(i));
  source.reset();
  ASSERT_TRUE(d.wait(5s));
  EXPECT_TRUE(d.each_called_once());
}

TEST(RemoteArchiveSource, SurvivesAServerThatCorruptsEveryResponse) {
  // Each body has one byte flipped: open fails cleanly or tiles come back ok/absent/error — with
  // whatever bytes the server sent (the client's checksum catches them) — never a crash or hang.
  FaultServer& files = static_server(syn_archive(), "syn");
  auto source =
      vts::client::open_source(files.base_url() + "/fault/corrupt/syn.pmtiles", quick_options());
  if (!source) {
    EXPECT_NE(source.error().message.find("/fault/corrupt/syn.pmtiles"), std::string::npos)
        << source.error().message;
    return;
  }
  const auto tiles = fetch_all(**source, every_tile((*source)->info().info.geometry));
  for (const SourceTile& t : tiles) EXPECT_NE(t.kind, SourceTile::Kind::cancelled);
}

// An archive whose header, root directory and metadata are sound (so a static server, or
// FaultServer's own reader, serves it) but whose directory entries lie: tile and leaf pointers past
// their sections, a leaf of garbage, a leaf that points to itself, a tile that is not a tile.
TEST(RemoteArchiveSource, LyingDirectoriesAreErrorsNotCrashes) {
  namespace pm = vts::archive;
  auto good = pm::Reader::open(syn_archive());
  ASSERT_TRUE(good.ok());
  auto root_tile = (*good)->get({0, 0, 0});
  ASSERT_TRUE(root_tile.ok());

  std::vector<std::uint8_t> tiles(root_tile->begin(), root_tile->end());
  const std::uint32_t junk_offset = static_cast<std::uint32_t>(tiles.size());
  tiles.insert(tiles.end(), 64, 0xAB);

  // Leaves (uncompressed): 20 bytes of garbage, then a leaf whose one entry points to itself.
  std::vector<std::uint8_t> leaves(20, 0xFF);
  const std::uint64_t cycle_offset = leaves.size();
  const std::uint64_t cycle_id = pm::zxy_to_tile_id(4, 0, 0);
  std::uint32_t cycle_length = 1;
  std::vector<std::uint8_t> cycle;
  for (int i = 0; i < 4; ++i) {  // its length is part of its own bytes: iterate to the fixpoint
    const pm::Entry self{cycle_id, cycle_offset, cycle_length, 0};
    cycle = pm::serialize_directory(std::span(&self, 1));
    cycle_length = static_cast<std::uint32_t>(cycle.size());
  }
  leaves.insert(leaves.end(), cycle.begin(), cycle.end());

  // Tile ids at z = 1 follow the Hilbert curve: (1,0,0) is 1 and (1,1,0) is 4. The z = 2 leaf
  // pointer starts one id after (2,0,0), which is then in no entry: absent.
  const std::uint64_t z2_pointer = pm::zxy_to_tile_id(2, 0, 0) + 1;
  ASSERT_GE(pm::zxy_to_tile_id(2, 1, 1), z2_pointer);
  const std::vector<pm::Entry> root_entries = {
      {0, 0, static_cast<std::uint32_t>(root_tile->size()), 1},  // 0/0/0: a real tile
      {pm::zxy_to_tile_id(1, 0, 0), tiles.size() + 100, 10, 1},  // past the tile data
      {pm::zxy_to_tile_id(1, 1, 0), junk_offset, 64, 1},         // not a tile
      {z2_pointer, 1000, 50, 0},                                 // leaf past the leaf section
      {pm::zxy_to_tile_id(3, 0, 0), 0, 20, 0},                   // leaf of garbage
      {cycle_id, cycle_offset, cycle_length, 0},                 // leaf pointing to itself
  };
  const std::vector<std::uint8_t> root = pm::serialize_directory(root_entries);
  const std::string& meta = (*good)->metadata_json();

  pm::Header h;
  h.internal_compression = pm::Compression::none;
  h.max_zoom = 4;
  h.root_dir_offset = pm::kHeaderSize;
  h.root_dir_length = root.size();
  h.metadata_offset = h.root_dir_offset + h.root_dir_length;
  h.metadata_length = meta.size();
  h.leaf_dirs_offset = h.metadata_offset + h.metadata_length;
  h.leaf_dirs_length = leaves.size();
  h.tile_data_offset = h.leaf_dirs_offset + h.leaf_dirs_length;
  h.tile_data_length = tiles.size();
  const auto header = pm::serialize_header(h);
  const fs::path path = dir() / "liar.pmtiles";
  {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(header.data()), header.size());
    out.write(reinterpret_cast<const char*>(root.data()), root.size());
    out.write(meta.data(), meta.size());
    out.write(reinterpret_cast<const char*>(leaves.data()), leaves.size());
    out.write(reinterpret_cast<const char*>(tiles.data()), tiles.size());
  }
  FaultServer& files = static_server(path, "liar");
  const std::string url = files.base_url() + "/liar.pmtiles";
  auto source = open_ok(url);
  ASSERT_TRUE(source);

  std::vector<SourceRequest> requests;
  for (TileId id : {TileId{0, 0, 0}, TileId{1, 0, 0}, TileId{1, 1, 0}, TileId{2, 0, 0},
                    TileId{2, 1, 1}, TileId{3, 2, 1}, TileId{4, 3, 2}}) {
    SourceRequest r;
    r.id = id;
    requests.push_back(r);
  }
  const auto got = fetch_all(*source, requests);
  EXPECT_EQ(got[0].kind, SourceTile::Kind::ok) << describe(got[0]);
  EXPECT_EQ(got[3].kind, SourceTile::Kind::absent) << describe(got[3]);
  for (std::size_t i : {1, 2, 4, 5, 6}) {
    ASSERT_EQ(got[i].kind, SourceTile::Kind::error) << i << ": " << describe(got[i]);
    EXPECT_EQ(got[i].error->code, vts::ErrorCode::corrupt) << got[i].error->to_string();
    EXPECT_NE(got[i].error->message.find(url), std::string::npos) << got[i].error->message;
  }
  EXPECT_NE(got[1].error->message.find("past the tile data"), std::string::npos);
  EXPECT_NE(got[2].error->message.find("no valid tile header"), std::string::npos);
  EXPECT_NE(got[4].error->message.find("past the leaf section"), std::string::npos);
  EXPECT_NE(got[6].error->message.find("too deep"), std::string::npos) << got[6].error->message;
}

// An archive with syn_archive()'s metadata and its 0/0/0 payload as the only tile data, a gzip
// root of `root` entries and `leaves` as the leaf section; the header declares tile compression
// `tiles`.
fs::path assemble_archive(const std::string& name, const std::vector<vts::archive::Entry>& root,
                          const std::vector<std::uint8_t>& leaves,
                          vts::archive::Compression tiles = vts::archive::Compression::zstd) {
  namespace pm = vts::archive;
  auto good = pm::Reader::open(syn_archive());
  EXPECT_TRUE(good.ok());
  const std::vector<std::uint8_t> tile = (*good)->get({0, 0, 0}).value();
  const std::vector<std::uint8_t> root_bytes =
      pm::compress(pm::serialize_directory(root), pm::Compression::gzip).value();
  const std::vector<std::uint8_t> meta =
      pm::compress(std::span(reinterpret_cast<const std::uint8_t*>((*good)->metadata_json().data()),
                             (*good)->metadata_json().size()),
                   pm::Compression::gzip)
          .value();
  pm::Header h = (*good)->header();
  h.internal_compression = pm::Compression::gzip;
  h.tile_compression = tiles;
  h.root_dir_offset = pm::kHeaderSize;
  h.root_dir_length = root_bytes.size();
  h.metadata_offset = h.root_dir_offset + h.root_dir_length;
  h.metadata_length = meta.size();
  h.leaf_dirs_offset = h.metadata_offset + h.metadata_length;
  h.leaf_dirs_length = leaves.size();
  h.tile_data_offset = h.leaf_dirs_offset + h.leaf_dirs_length;
  h.tile_data_length = tile.size();
  const auto header = pm::serialize_header(h);
  const fs::path path = dir() / (name + ".pmtiles");
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(header.data()), std::streamsize(header.size()));
  out.write(reinterpret_cast<const char*>(root_bytes.data()), std::streamsize(root_bytes.size()));
  out.write(reinterpret_cast<const char*>(meta.data()), std::streamsize(meta.size()));
  out.write(reinterpret_cast<const char*>(leaves.data()), std::streamsize(leaves.size()));
  out.write(reinterpret_cast<const char*>(tile.data()), std::streamsize(tile.size()));
  return path;
}

// A gzip leaf of `count` one-tile entries from tile id `first` on, each the archive's one tile.
std::vector<std::uint8_t> uniform_leaf(std::uint64_t first, std::size_t count,
                                       std::uint32_t tile_length) {
  std::vector<vts::archive::Entry> entries(count);
  for (std::size_t i = 0; i < count; ++i) entries[i] = {first + i, 0, tile_length, 1};
  return vts::archive::compress(vts::archive::serialize_directory(entries),
                                vts::archive::Compression::gzip)
      .value();
}

std::uint32_t syn_root_tile_length() {
  return static_cast<std::uint32_t>(
      vts::archive::Reader::open(syn_archive()).value()->get({0, 0, 0}).value().size());
}

std::uint64_t resident_kib() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stoull(line.substr(6));
  return 0;
}

TEST(RemoteArchiveSource, RefusesALeafOverTheEntryCapAsTooLarge) {
  namespace pm = vts::archive;
  // A few KiB of gzip that decode to 2^20 + 1 entries (4M took 96 MiB each before the cap).
  const std::vector<std::uint8_t> leaf =
      uniform_leaf(0, pm::kMaxDirectoryEntries + 1, syn_root_tile_length());
  const fs::path path =
      assemble_archive("leaf-bomb", {{0, 0, static_cast<std::uint32_t>(leaf.size()), 0}}, leaf);
  FaultServer& files = static_server(path, "leaf-bomb");
  auto source = open_ok(files.base_url() + "/leaf-bomb.pmtiles");
  ASSERT_TRUE(source);
  const SourceTile t = fetch_one(*source, {0, 0, 0});
  ASSERT_EQ(t.kind, SourceTile::Kind::error) << describe(t);
  EXPECT_EQ(t.error->code, vts::ErrorCode::too_large) << t.error->to_string();
  EXPECT_NE(t.error->message.find("entries per directory"), std::string::npos) << t.error->message;
}

TEST(RemoteArchiveSource, KeepsDecodedLeavesWithinAByteBudget) {
  namespace pm = vts::archive;
  // 24 leaves of 2^20 entries, each 24 MiB decoded: 576 MiB if the source kept them all.
  const vts::Geometry g =
      vts::TilesetInfo::from_json(pm::Reader::open(syn_archive()).value()->metadata_json())
          .value()
          .geometry;
  const std::uint32_t length = syn_root_tile_length();
  std::vector<pm::Entry> root;
  std::vector<TileId> wanted;
  std::vector<std::uint8_t> leaves;
  for (std::uint64_t id = 0; wanted.size() < 24; ++id) {
    const TileId t = pm::tile_id_to_zxy(id).value();
    if (!g.exists(t)) continue;
    const std::vector<std::uint8_t> leaf = uniform_leaf(id, pm::kMaxDirectoryEntries, length);
    root.push_back({id, leaves.size(), static_cast<std::uint32_t>(leaf.size()), 0});
    leaves.insert(leaves.end(), leaf.begin(), leaf.end());
    wanted.push_back(t);
  }
  const fs::path path = assemble_archive("big-leaves", root, leaves);
  FaultServer& files = static_server(path, "big-leaves");
  auto source = open_ok(files.base_url() + "/big-leaves.pmtiles");
  ASSERT_TRUE(source);
  const std::uint64_t before = resident_kib();
  for (TileId t : wanted) {
    const SourceTile got = fetch_one(*source, t);
    ASSERT_EQ(got.kind, SourceTile::Kind::ok) << t.to_string() << ": " << describe(got);
  }
  const std::uint64_t grown = resident_kib() - std::min(before, resident_kib());
  EXPECT_LT(grown, 200u << 10) << "the source holds " << grown << " KiB more after 24 leaves";
}

TEST(RemoteArchiveSource, RefusesOurArchiveWhoseHeaderDeclaresAnotherTileCompression) {
  const fs::path path = dir() / "gzip-tiles.pmtiles";
  fs::copy_file(syn_archive(), path, fs::copy_options::overwrite_existing);
  {
    std::fstream f(path, std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(98);  // tile_compression
    f.put(2);     // gzip
  }
  FaultServer& files = static_server(path, "gzip-tiles");
  auto source = vts::client::open_source(files.base_url() + "/gzip-tiles.pmtiles", quick_options());
  ASSERT_FALSE(source.ok());
  EXPECT_EQ(source.error().code, vts::ErrorCode::corrupt) << source.error().to_string();
  EXPECT_NE(source.error().message.find("tile_compression is 2"), std::string::npos)
      << source.error().message;
}

TEST(RemoteArchiveSource, TruncatedAnswersAreErrors) {
  FaultServer& files = static_server(syn_archive(), "syn");
  const std::string url = files.base_url() + "/fault/truncate/syn.pmtiles";
  auto source = vts::client::open_source(url, quick_options());
  ASSERT_FALSE(source.ok());
  EXPECT_NE(source.error().message.find(url), std::string::npos) << source.error().message;
}

// ---------------------------------------------------------------------------------------------
// Opening: errors say what and where

TEST(OpenSource, UnknownTilesetIsNotFoundNamingTheUrl) {
  for (const std::string& location : {serve().base() + "/nope", serve().base() + "/nope.json"}) {
    auto s = vts::client::open_source(location, quick_options());
    ASSERT_FALSE(s.ok()) << location;
    EXPECT_EQ(s.error().code, vts::ErrorCode::not_found) << s.error().to_string();
    EXPECT_NE(s.error().message.find(serve().base() + "/nope.json"), std::string::npos)
        << s.error().message;
    EXPECT_NE(s.error().message.find("no tileset named"), std::string::npos)
        << "the server's own message is kept: " << s.error().message;
  }
  const std::string archive = serve().base() + "/nope.pmtiles";
  auto s = vts::client::open_source(archive, quick_options());
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, vts::ErrorCode::not_found) << s.error().to_string();
  EXPECT_NE(s.error().message.find(archive), std::string::npos) << s.error().message;
}

TEST(OpenSource, UnreachableServerIsAnIoErrorNamingTheUrl) {
  for (const std::string location : {"http://127.0.0.1:1/syn", "http://127.0.0.1:1/syn.pmtiles"}) {
    const auto start = std::chrono::steady_clock::now();
    auto s = vts::client::open_source(location, quick_options());
    ASSERT_FALSE(s.ok()) << location;
    EXPECT_EQ(s.error().code, vts::ErrorCode::io) << s.error().to_string();
    EXPECT_NE(s.error().message.find(location), std::string::npos) << s.error().message;
    EXPECT_LT(std::chrono::steady_clock::now() - start, 5s);
  }
}

TEST(OpenSource, UrlThatIsNotAnArchiveOrTileJsonIsRefused) {
  FaultServer& files = static_server(syn_archive(), "syn");
  // 200 with a short text body.
  const std::string archive = files.base_url() + "/fault/200/syn.pmtiles";
  auto a = vts::client::open_source(archive, quick_options());
  ASSERT_FALSE(a.ok());
  EXPECT_EQ(a.error().code, vts::ErrorCode::corrupt) << a.error().to_string();
  EXPECT_NE(a.error().message.find(archive), std::string::npos) << a.error().message;
  EXPECT_NE(a.error().message.find("not a PMTiles"), std::string::npos) << a.error().message;

  const std::string tilejson = files.base_url() + "/fault/200/syn.json";
  auto t = vts::client::open_source(tilejson, quick_options());
  ASSERT_FALSE(t.ok());
  EXPECT_EQ(t.error().code, vts::ErrorCode::corrupt) << t.error().to_string();
  EXPECT_NE(t.error().message.find(tilejson), std::string::npos) << t.error().message;
  EXPECT_NE(t.error().message.find("not TileJSON"), std::string::npos) << t.error().message;

  // A tile payload is neither.
  const std::string tile = serve().base() + "/syn/0/0/0";
  auto p = vts::client::open_source(tile, quick_options());
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error().message.find(tile), std::string::npos) << p.error().message;
}

TEST(OpenSource, AllThreeSourcesAgreeOnTheTilesetVersion) {
  auto local = vts::client::open_source(syn_archive().string());
  ASSERT_TRUE(local.ok());
  auto tilejson = open_ok(serve().base() + "/syn");
  auto remote = open_ok(serve().base() + "/syn.pmtiles");
  ASSERT_TRUE(tilejson && remote);
  EXPECT_EQ((*local)->info().version, tilejson->info().version);
  EXPECT_EQ((*local)->info().version, remote->info().version);
  EXPECT_EQ((*local)->info().key, "file:" + syn_archive().string());
}

// ---------------------------------------------------------------------------------------------
// The whole client stack (TileCache over a TileJSON source) against a faulty origin: vts serve
// hands out tile URLs on the fault server, which corrupts, truncates or refuses them.

TEST(ClientStackOverFaults, TransientFaultsAreRetriedAndBadTilesAreNeverCachedOrDelivered) {
  FaultServer& faults = static_server(syn_archive(), "syn");
  auto reader = vts::archive::Reader::open(syn_archive());
  ASSERT_TRUE(reader.ok());
  struct Case {
    std::string spec;
    bool ok;
  };
  const std::vector<Case> cases = {{"corrupt*1", true}, {"truncate*2", true}, {"503ra1*1", true},
                                   {"500*2", true},     {"corrupt", false},   {"500", false},
                                   {"drop", false}};
  int n = 0;
  for (const auto& c : cases) {
    SCOPED_TRACE(c.spec);
    vts::RouterConfig router;
    router.public_base_url = faults.base_url() + "/fault/" + c.spec;
    RunningServer server(router);
    auto o = quick_options();
    o.fetcher.max_attempts = 4;
    auto opened = open_ok(server.base() + "/syn", o);
    ASSERT_TRUE(opened);
    std::shared_ptr<TileSource> source = std::move(opened);
    vts::client::TileCacheOptions co;
    co.disk = vts::client::DiskCacheOptions{};
    co.disk->dir = dir() / ("client-cache-" + std::to_string(n++));
    auto cache = vts::client::TileCache::create(source, co);
    ASSERT_TRUE(cache.ok()) << cache.error().to_string();

    const TileId id{1, 1, 0};
    std::mutex m;
    std::condition_variable cv;
    std::optional<vts::client::PayloadResult> got;
    (*cache)->get(id, {}, [&](vts::client::PayloadResult&& r) {
      std::lock_guard lock(m);
      got = std::move(r);
      cv.notify_all();
    });
    {
      std::unique_lock lock(m);
      ASSERT_TRUE(cv.wait_for(lock, 20s, [&] { return got.has_value(); }));
    }
    ASSERT_TRUE((*cache)->flush().ok());
    const auto stored = (*reader)->get(id);
    ASSERT_TRUE(stored.ok());
    auto row = (*cache)->disk()->get(source->info().key, id);
    ASSERT_TRUE(row.ok());
    if (c.ok) {
      ASSERT_EQ(got->kind, vts::client::PayloadResult::Kind::ok)
          << (got->error ? got->error->to_string() : "");
      EXPECT_TRUE(std::equal(got->tile->payload.begin(), got->tile->payload.end(), stored->begin(),
                             stored->end()));
      ASSERT_TRUE(row->has_value());
      EXPECT_TRUE(std::equal((*row)->payload.begin(), (*row)->payload.end(), stored->begin(),
                             stored->end()));
    } else {
      ASSERT_EQ(got->kind, vts::client::PayloadResult::Kind::error);
      EXPECT_FALSE(got->error->message.empty());
      EXPECT_FALSE(row->has_value()) << "a bad tile reached the disk cache";
      EXPECT_EQ((*cache)->ram()->get({source->info().key, id}), nullptr);
    }
  }
}
