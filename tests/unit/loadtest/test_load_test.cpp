// The load engine (run_load_test) over real archives built here, through the real client stack:
// a local archive (tiles arrive before get() returns, so counts are exact) and, where requests
// must stay in flight across frames, the same archive behind the real HTTP server in process.
// Tile demand comes from hand-written DemandFns, so no renderer is involved. Runs whose figures
// depend on time run in virtual time (VirtualRun): they take no wall time and their times are
// exact; the others keep the steady clock, which is what the CLI runs on.
#include "vts/loadtest/load_test.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"
#include "vts/server/http_server.hpp"
#include "vts/server/tileset_registry.hpp"
#include "vts/test/archive.hpp"
#include "vts/test/server.hpp"
#include "vts/test/temp_dir.hpp"
#include "vts/test/virtual_clock.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using namespace vts::client;
using namespace vts::loadtest;
using vts::TileId;

namespace {

using Clock = std::chrono::steady_clock;

// A folder for the suite's archives, removed at exit.
const fs::path& dir() {
  static const vts::test::TempDir d("vts-load-test");
  return d.path();
}

fs::path build(const fs::path& out) {
  vts::BuildOptions o = vts::test::synthetic_options(out, 2048, 2048);
  o.tile_size = 64;
  o.border = 2;
  vts::test::build_archive(o);
  return out;
}

// 2048x2048 texels in 64-texel tiles: levels 0..5, 1365 tiles, all distinct.
const fs::path& archive() {
  static const fs::path p = build(dir() / "served" / "syn.pmtiles");
  return p;
}

const vts::Geometry& geometry() {
  static const vts::Geometry g = [] {
    auto src = open_source(archive().string());
    EXPECT_TRUE(src.ok()) << src.error().to_string();
    return (*src)->info().info.geometry;
  }();
  return g;
}

// Every tile of levels [z0, z1], coarse first, all direct.
std::vector<DemandTile> tiles_of_levels(int z0, int z1) {
  std::vector<DemandTile> out;
  for (int z = z0; z <= z1; ++z)
    for (std::uint32_t y = 0; y < geometry().tiles_y(z); ++y)
      for (std::uint32_t x = 0; x < geometry().tiles_x(z); ++x)
        out.push_back(DemandTile{TileId{std::uint8_t(z), x, y}, 0, true});
  return out;
}

LoadTestOptions local_options(std::uint32_t viewers, double duration_s) {
  LoadTestOptions o;
  o.target = archive().string();
  o.viewers = viewers;
  o.fps = 30;
  o.duration_s = duration_s;
  o.threads = 2;
  o.drain_timeout = 2000ms;
  return o;
}

// The same demand for every viewer and frame; a move at frame 0 only.
DemandFn constant(std::vector<DemandTile> tiles) {
  return [tiles = std::move(tiles)](std::uint32_t, std::uint64_t f,
                                    double) -> vts::Result<ViewerDemand> {
    return ViewerDemand{tiles, f == 0};
  };
}

constexpr std::uint64_t nanos(std::chrono::nanoseconds d) {
  return std::uint64_t(d.count());
}

// A run in virtual time: the run's threads (its drivers, its dispatcher in open loop and the
// calling thread, as LoadTestOptions::sleep_until says) take turns in the order of their
// deadlines, so a local archive answers in no time and every figure is exact.
class VirtualRun {
 public:
  explicit VirtualRun(const LoadTestOptions& o)
      : clock_(std::min(unsigned(o.threads), o.viewers) + (o.rate > 0 ? 1u : 0u) + 1u),
        t0_(clock_.now()) {}

  vts::Result<LoadTestResult> run(LoadTestOptions o, const DemandFn& demand) {
    o.now = clock_.now_fn();
    o.sleep_until = clock_.sleep_fn();
    return run_load_test(o, demand);
  }
  vts::test::VirtualClock& clock() { return clock_; }
  // Virtual time since the clock was made.
  std::chrono::nanoseconds elapsed() const { return clock_.now() - t0_; }

 private:
  vts::test::VirtualClock clock_;
  Clock::time_point t0_;
};

// `vts serve` over the suite's "served" folder, in process on 127.0.0.1 port 0.
class Server {
 public:
  Server() : server_(served(), options()) {}
  std::string url(const std::string& name) const { return server_.base_url() + "/" + name; }

 private:
  static std::vector<fs::path> served() {
    archive();
    return {dir() / "served"};
  }
  static vts::HttpServerOptions options() {
    vts::HttpServerOptions o = vts::test::RunningServer::quiet_options();
    o.threads = 1;
    return o;
  }
  vts::test::RunningServer server_;
};

TEST(LoadTest, EveryViewerStreamsItsDemandOnceAndReachesFullResolution) {
  const auto tiles = tiles_of_levels(0, 2);
  ASSERT_EQ(tiles.size(), 21u);
  LoadTestOptions o = local_options(3, 0.5);
  o.title = "levels 0-2";
  o.path_name = "still";
  VirtualRun v(o);
  auto r = v.run(o, constant(tiles));
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const LoadReport& rep = r->report;
  EXPECT_EQ(rep.camera_moves, 3u);
  EXPECT_EQ(rep.full_resolution.count(), 3u);
  EXPECT_EQ(rep.first_visible.count(), 3u);
  EXPECT_EQ(r->run.moves_incomplete, 0u);
  // Resident tiles are not asked for again: one request per tile and viewer.
  EXPECT_EQ(rep.requests, 21u * 3);
  EXPECT_EQ(rep.errors, 0u);
  EXPECT_TRUE(rep.errors_by_kind.empty());
  EXPECT_EQ(rep.tiers.network, 21u * 3);  // CacheMode::none: every tile from the source
  EXPECT_EQ(rep.tiers.ram + rep.tiers.disk, 0u);
  EXPECT_EQ(rep.total.count(), rep.requests);
  EXPECT_EQ(rep.queue_time.count(), rep.requests);
  EXPECT_EQ(rep.ttfb.count(), 0u);  // a local archive has no first byte
  EXPECT_GT(rep.bytes, 0u);
  EXPECT_EQ(rep.cancelled, 0u);
  // Frame 0 asks for everything and a local read answers in no (virtual) time: the view is
  // complete at its due time (its tiles' arrival, not the frame that noticed it, 33 ms later).
  EXPECT_EQ(rep.full_resolution.max(), 0u);
  EXPECT_EQ(rep.first_visible.max(), 0u);
  EXPECT_EQ(rep.total.max(), 0u);
  EXPECT_EQ(r->run.abandoned, 0u);
  EXPECT_EQ(r->run.frames, 3u * 15);  // frames 0..14 are due in 0.5 s at 30 fps
  EXPECT_EQ(r->run.late_frames, 0u);
  // Passed through.
  EXPECT_EQ(rep.title, "levels 0-2");
  EXPECT_EQ(rep.path, "still");
  EXPECT_EQ(rep.target, archive().string());
  EXPECT_EQ(rep.viewers, 3u);
  EXPECT_EQ(rep.fps, 30);
  EXPECT_EQ(rep.mode, LoopMode::closed);
  EXPECT_DOUBLE_EQ(rep.duration_s, 0.5);
  ASSERT_EQ(rep.seconds.size(), 1u);  // every request in the run's first second
  EXPECT_EQ(rep.seconds[0].requests, rep.requests);
}

TEST(LoadTest, EveryMoveTheDemandAnnouncesIsCountedAndTimed) {
  // Moves at frames 0, 5 and 10, each to a level of its own.
  const DemandFn demand = [](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    const int z = f < 5 ? 1 : f < 10 ? 2 : 3;
    return ViewerDemand{tiles_of_levels(z, z), f == 0 || f == 5 || f == 10};
  };
  auto r = run_load_test(local_options(2, 0.5), demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  EXPECT_EQ(r->report.camera_moves, 2u * 3);
  EXPECT_EQ(r->report.full_resolution.count(), 2u * 3);
  EXPECT_EQ(r->run.moves_incomplete, 0u);
  EXPECT_EQ(r->report.requests, 2u * (4 + 16 + 64));
}

TEST(LoadTest, AMoveToAViewAlreadyResidentIsAtFullResolutionAtOnce) {
  // The same tiles before and after the move at frame 10.
  const auto tiles = tiles_of_levels(0, 2);
  const DemandFn demand = [&](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    return ViewerDemand{tiles, f == 0 || f == 10};
  };
  auto r = run_load_test(local_options(1, 0.5), demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const LoadReport& rep = r->report;
  EXPECT_EQ(rep.camera_moves, 2u);
  ASSERT_EQ(rep.full_resolution.count(), 2u);
  EXPECT_EQ(rep.full_resolution.min(), 0u);
  EXPECT_EQ(rep.first_visible.min(), 0u);
  EXPECT_EQ(rep.requests, 21u);
}

TEST(LoadTest, AbsentTilesResolveWithoutErrors) {
  // One tile beyond the pyramid's finest level and one beyond the image's edge, next to a real one.
  const std::vector<DemandTile> tiles = {
      {TileId{0, 0, 0}, 0, true},
      {TileId{std::uint8_t(geometry().max_zoom() + 1), 0, 0}, 0, true},
      {TileId{1, 7, 0}, 0, true},
  };
  auto r = run_load_test(local_options(2, 0.4), constant(tiles));
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const LoadReport& rep = r->report;
  EXPECT_EQ(rep.errors, 0u);
  EXPECT_EQ(rep.requests, 3u * 2);  // absent is an answer: not asked for again
  EXPECT_EQ(rep.tiers.network, 1u * 2);
  EXPECT_EQ(rep.camera_moves, 2u);
  EXPECT_EQ(rep.full_resolution.count(), 2u);
  EXPECT_EQ(r->run.moves_incomplete, 0u);
}

TEST(LoadTest, ViewsAlternatingFasterThanTilesArriveCancelWhatTheyNoLongerNeed) {
  Server server;
  // The two halves of level 5 (512 tiles each), swapped every frame at 200 fps: far more than
  // the fetcher's 32 transfers at a time can bring in 5 ms, so each frame cancels most of the
  // other half.
  const auto level5 = tiles_of_levels(5, 5);
  ASSERT_EQ(level5.size(), 1024u);
  const std::vector<DemandTile> a(level5.begin(), level5.begin() + 512),
      b(level5.begin() + 512, level5.end());
  const DemandFn demand = [&](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    return ViewerDemand{f % 2 ? b : a, f == 0};
  };
  LoadTestOptions o = local_options(1, 0.5);
  o.target = server.url("syn");
  o.fps = 200;
  auto r = run_load_test(o, demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const LoadReport& rep = r->report;
  EXPECT_GT(rep.cancelled, 0u) << rep.requests << " requests in " << r->run.frames << " frames";
  EXPECT_GT(rep.requests, 0u);
  EXPECT_EQ(rep.errors, 0u) << "a cancelled request is not an error";
  EXPECT_EQ(rep.tiers.network, rep.requests);
  EXPECT_EQ(rep.by_status.at(200), rep.requests);
  // Over HTTP every request has a first byte.
  EXPECT_EQ(rep.ttfb.count(), rep.requests);
  EXPECT_LE(rep.ttfb.percentile(50), rep.total.percentile(50));
}

TEST(LoadTest, ResidentSetKeepsItsCapAndEvictedTilesComeBackFromRam) {
  // Sets A and B of 6 tiles each, alternated every frame, 8 slots that a tile unseen for one
  // frame may lose: each frame evicts 4 tiles of the other set, which the next frame asks for
  // again and the RAM cache answers.
  const auto level3 = tiles_of_levels(3, 3);
  const std::vector<DemandTile> a(level3.begin(), level3.begin() + 6),
      b(level3.begin() + 6, level3.begin() + 12);
  const DemandFn demand = [&](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    return ViewerDemand{f % 2 ? b : a, f == 0};
  };
  LoadTestOptions o = local_options(1, 0.5);
  o.cache = CacheMode::ram;
  o.resident_tiles = 8;
  o.keep_frames = 1;
  VirtualRun v(o);
  auto r = v.run(o, demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const LoadReport& rep = r->report;
  ASSERT_EQ(r->run.frames, 15u);
  ASSERT_EQ(r->run.late_frames, 0u);
  EXPECT_EQ(rep.tiers.network, 12u);  // each tile from the source once
  EXPECT_EQ(rep.tiers.ram, rep.requests - 12);
  EXPECT_EQ(rep.errors, 0u);
  // Frames 0 and 1 fetch 12 tiles, each of the 13 later frames re-requests the 4 evicted ones.
  EXPECT_EQ(rep.requests, 12u + 4 * 13);
}

TEST(LoadTest, DiskModeKeepsOneCachePerViewerAcrossRuns) {
  const fs::path cache = dir() / "disk-cache";
  LoadTestOptions o = local_options(2, 0.3);
  o.cache = CacheMode::disk;
  o.cache_dir = cache;
  auto first = run_load_test(o, constant(tiles_of_levels(0, 2)));
  ASSERT_TRUE(first.ok()) << first.error().to_string();
  EXPECT_EQ(first->report.tiers.network, 21u * 2);
  EXPECT_TRUE(fs::is_directory(cache / "viewer-0"));
  EXPECT_TRUE(fs::is_directory(cache / "viewer-1"));
  auto second = run_load_test(o, constant(tiles_of_levels(0, 2)));
  ASSERT_TRUE(second.ok()) << second.error().to_string();
  EXPECT_EQ(second->report.tiers.disk, 21u * 2);
  EXPECT_EQ(second->report.tiers.network, 0u);
  EXPECT_EQ(second->report.errors, 0u);
}

TEST(LoadTest, LatencyCountsFromTheFrameDueTimeNotFromWhenTheDriverGotRoundToIt) {
  // The demand of frame 0 takes 40 ms: its requests go out 40 ms after they were due, and that
  // lag is part of their queue time and total latency (no coordinated omission).
  const auto tiles = tiles_of_levels(0, 1);
  LoadTestOptions o = local_options(1, 0.3);
  VirtualRun v(o);
  const DemandFn demand = [&](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    if (f == 0) v.clock().spend(40ms);
    return ViewerDemand{tiles, f == 0};
  };
  auto r = v.run(o, demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const LoadReport& rep = r->report;
  ASSERT_EQ(rep.requests, 5u);
  // The lag, and nothing else: a local read takes no virtual time.
  EXPECT_EQ(rep.queue_time.min(), nanos(40ms));
  EXPECT_EQ(rep.queue_time.max(), nanos(40ms));
  EXPECT_EQ(rep.total.min(), nanos(40ms));
  EXPECT_EQ(rep.total.max(), nanos(40ms));
  EXPECT_EQ(rep.full_resolution.min(), nanos(40ms));
  // Frame 1 (due at 33 ms) ran 7 ms late, less than a frame: not skipped.
  EXPECT_EQ(r->run.late_frames, 0u);
  EXPECT_EQ(r->run.frames, 9u);
}

TEST(LoadTest, OpenLoopSendsAtExactlyTheRateAndMeasuresFromEachSlot) {
  // Far more demand than 200 req/s can serve in 1 s: the dispatcher is never idle.
  LoadTestOptions o = local_options(2, 1.0);
  o.rate = 200;
  VirtualRun v(o);
  auto r = v.run(o, constant(tiles_of_levels(0, 5)));
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const LoadReport& rep = r->report;
  EXPECT_EQ(rep.mode, LoopMode::open);
  EXPECT_EQ(rep.rate, 200);
  // Slot 0 is due with frame 0: it passes at start-up when the dispatcher gets there first. From
  // the first request on no slot is idle, and every one of the 200 slots sent a request (a local
  // read: none is still on its way at the end).
  EXPECT_EQ(r->run.idle_slots, 0u);
  EXPECT_LE(r->run.startup_slots, 1u);
  EXPECT_EQ(r->run.abandoned, 0u);
  EXPECT_EQ(rep.requests + r->run.startup_slots, 200u);
  EXPECT_EQ(rep.errors, 0u);
  // Requests waited up to a second in the queue for their slot, but latency counts from the
  // slot: a local read takes no time.
  EXPECT_EQ(rep.total.max(), 0u);
  EXPECT_EQ(rep.queue_time.max(), 0u);
  ASSERT_EQ(rep.seconds.size(), 1u);
  EXPECT_EQ(rep.seconds[0].requests, rep.requests);
  // Requests still queued when the run ends were never sent: nothing to wait for (the run ends
  // within a poll of its 20 ms start-up and 1 s; a drain would wait its 2 s).
  EXPECT_LE(v.elapsed(), 20ms + 1s + 5ms);
}

TEST(LoadTest, OpenLoopCountsSlotsItHadNothingToSendIn) {
  LoadTestOptions o = local_options(1, 0.5);
  o.rate = 100;
  VirtualRun v(o);
  auto r = v.run(o, constant(tiles_of_levels(0, 1)));  // 5 tiles, then nothing to do
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  EXPECT_EQ(r->report.requests, 5u);
  // 50 slots: the 5 requests, slot 0 when it passed before frame 0 (start-up), the rest idle.
  EXPECT_LE(r->run.startup_slots, 1u);
  EXPECT_EQ(r->run.idle_slots + r->run.startup_slots, 45u);
}

TEST(LoadTest, OpenLoopSpendsNoSlotOnARequestTheViewNoLongerWants) {
  // Two sets of 16 tiles swapped every frame (33 ms) while slots come every 10 ms: most of a
  // set is still queued when the next frame drops it, and the dispatcher skips what was dropped.
  const auto level4 = tiles_of_levels(4, 4);
  const std::vector<DemandTile> a(level4.begin(), level4.begin() + 16),
      b(level4.begin() + 16, level4.begin() + 32);
  const DemandFn demand = [&](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    return ViewerDemand{f % 2 ? b : a, f == 0};
  };
  LoadTestOptions o = local_options(1, 0.5);
  o.rate = 100;
  VirtualRun v(o);
  auto r = v.run(o, demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  // Every one of the 50 slots sent one wanted request or was idle (or passed at start-up): a
  // slot spent on a dropped request would leave the sum short.
  EXPECT_EQ(r->report.requests + r->report.cancelled + r->run.abandoned + r->run.idle_slots +
                r->run.startup_slots,
            50u);
  EXPECT_EQ(r->report.cancelled + r->run.abandoned, 0u);  // a local read is never on its way
  // The 32 tiles stay resident, so each is asked for once; the slots left over are idle.
  EXPECT_EQ(r->report.requests, 32u);
  EXPECT_EQ(r->report.errors, 0u);
}

TEST(LoadTest, AFailingTileIsRetriedAfterABackoffNotEveryFrame) {
  // A copy of the archive with one byte of tile 1/0/0 flipped: it fails verification.
  const fs::path bad = dir() / "bitflip.pmtiles";
  std::uint64_t offset = 0, length = 0;
  {
    auto reader = vts::archive::Reader::open(archive());
    ASSERT_TRUE(reader.ok()) << reader.error().to_string();
    auto entry = (*reader)->find_entry(vts::archive::zxy_to_tile_id(1, 0, 0));
    ASSERT_TRUE(entry.ok()) << entry.error().to_string();
    offset = (*reader)->header().tile_data_offset + entry->offset;
    length = entry->length;
  }
  fs::copy_file(archive(), bad, fs::copy_options::overwrite_existing);
  {
    std::fstream f(bad, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(std::streamoff(offset + length / 2));
    const char c = char(f.get() ^ 0x40);
    f.seekp(std::streamoff(offset + length / 2));
    f.put(c);
  }
  LoadTestOptions o = local_options(2, 1.0);
  o.target = bad.string();
  // Moves at frames 0 and 15: the first is superseded, the second still open at the end.
  const DemandFn demand = [](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    return ViewerDemand{{{TileId{0, 0, 0}, 0, true}, {TileId{1, 0, 0}, 0, true}},
                        f == 0 || f == 15};
  };
  VirtualRun v(o);
  auto r = v.run(o, demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const LoadReport& rep = r->report;
  // 30 frames wanted the tile; each viewer asked for it at frame 0, at the first frame 250 ms
  // later (8, at 267 ms) and at the first 500 ms after that (23 at 767 ms, or 24 at 800 ms: the
  // frame times are rounded to the clock's nanosecond); the next back-off (1 s) ends after the
  // run.
  EXPECT_EQ(rep.errors, 2u * 3);
  EXPECT_EQ(rep.requests, rep.errors + 2);
  ASSERT_EQ(rep.errors_by_kind.size(), 1u);
  EXPECT_EQ(rep.errors_by_kind.begin()->second, rep.errors);
  // Neither view reached full resolution, so neither is in the histograms.
  EXPECT_EQ(rep.camera_moves, 2u * 2);
  EXPECT_EQ(rep.full_resolution.count(), 0u);
  EXPECT_EQ(rep.first_visible.count(), 0u);
  EXPECT_EQ(r->run.moves_incomplete, 2u * 2);
}

TEST(LoadTest, TheDemandFunctionsErrorEndsTheRunAndIsReturned) {
  const auto tiles = tiles_of_levels(0, 1);
  const DemandFn demand = [&](std::uint32_t v, std::uint64_t f,
                              double) -> vts::Result<ViewerDemand> {
    if (v == 1 && f == 3) return vts::make_error(vts::ErrorCode::corrupt, "camera path broke");
    return ViewerDemand{tiles, f == 0};
  };
  LoadTestOptions o = local_options(2, 10);
  VirtualRun v(o);
  auto r = v.run(o, demand);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, vts::ErrorCode::corrupt);
  EXPECT_EQ(r.error().message, "camera path broke");
  // The run ended at frame 3 (100 ms after its 20 ms start-up; the other driver, asleep by then,
  // at its frame 4; then one poll of the calling thread), not after its 10 s.
  EXPECT_LE(v.elapsed(), 20ms + 134ms + 5ms);
}

TEST(LoadTest, OptionsOutOfRangeAreInvalidArguments) {
  const auto demand = constant(tiles_of_levels(0, 0));
  const auto expect_invalid = [&](const LoadTestOptions& o, const std::string& what) {
    auto r = run_load_test(o, demand);
    ASSERT_FALSE(r.ok()) << what;
    EXPECT_EQ(r.error().code, vts::ErrorCode::invalid_argument) << what;
    EXPECT_FALSE(r.error().message.empty()) << what;
  };
  LoadTestOptions o = local_options(1, 0.2);
  o.viewers = 0;
  expect_invalid(o, "no viewers");
  o = local_options(1, 0.2);
  o.fps = 0;
  expect_invalid(o, "fps 0");
  o.fps = std::numeric_limits<double>::quiet_NaN();
  expect_invalid(o, "fps NaN");
  o = local_options(1, 0.2);
  o.duration_s = 0;
  expect_invalid(o, "duration 0");
  o = local_options(1, 0.2);
  o.rate = -1;
  expect_invalid(o, "negative rate");
  o = local_options(1, 0.2);
  o.cache = CacheMode::disk;
  expect_invalid(o, "disk mode without a cache folder");
  o = local_options(1, 0.2);
  o.target.clear();
  expect_invalid(o, "no target");
}

TEST(LoadTest, ATargetThatCannotBeOpenedIsTheOpenError) {
  LoadTestOptions o = local_options(2, 0.2);
  o.target = (dir() / "no-such.pmtiles").string();
  auto r = run_load_test(o, constant(tiles_of_levels(0, 0)));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, vts::ErrorCode::not_found);
  EXPECT_NE(r.error().message.find("no-such.pmtiles"), std::string::npos) << r.error().message;
}

TEST(LoadTest, TheStopFlagEndsTheRunPromptlyWithWhatItHas) {
  std::atomic<bool> stop{false};
  LoadTestOptions o = local_options(2, 30);
  o.stop = &stop;
  std::atomic<int> progress_calls{0};
  o.progress = [&](const LoadProgress&) { ++progress_calls; };
  // Stopped (as SIGINT would) while frame 9 is worked out, 300 ms into the run.
  const DemandFn demand = [&](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    if (f == 9) stop = true;
    return ViewerDemand{tiles_of_levels(0, 2), f == 0};
  };
  VirtualRun v(o);
  auto r = v.run(o, demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  EXPECT_EQ(r->report.requests, 21u * 2);
  EXPECT_EQ(r->report.camera_moves, 2u);
  // The run ends at frame 9, not after its 30 s: the report's time is the 300 ms it ran, and the
  // calling thread returns within a poll.
  EXPECT_NEAR(r->report.duration_s, 0.3, 1e-6);
  EXPECT_LE(r->run.frames, 2u * 10);
  EXPECT_LE(v.elapsed(), 20ms + 300ms + 5ms);
  EXPECT_EQ(progress_calls.load(), 0);  // stopped before its first second
}

TEST(LoadTest, ProgressIsReportedOnceASecond) {
  std::vector<LoadProgress> seen;
  LoadTestOptions o = local_options(1, 2.5);
  o.progress = [&](const LoadProgress& p) { seen.push_back(p); };  // the calling thread
  // Level 1 in the first second, level 2 in the second, all tiles in the run's first frame of it.
  const DemandFn demand = [](std::uint32_t, std::uint64_t f, double) -> vts::Result<ViewerDemand> {
    return ViewerDemand{tiles_of_levels(f < 30 ? 1 : 2, f < 30 ? 1 : 2), f == 0 || f == 30};
  };
  VirtualRun v(o);
  auto r = v.run(o, demand);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_DOUBLE_EQ(seen[0].elapsed_s, 1.0);
  EXPECT_DOUBLE_EQ(seen[1].elapsed_s, 2.0);
  // At 1 s: frame 30 (due at 1 s) may have run already; either way second 0 had level 1's 4.
  EXPECT_EQ(seen[0].requests_per_s, 4);
  EXPECT_EQ(seen[1].requests, 4u + 16);
  EXPECT_EQ(seen[1].requests_per_s, 16);  // second 1: level 2's tiles
  EXPECT_EQ(seen[1].moves_complete, 2u);
  EXPECT_EQ(seen[1].errors, 0u);
  EXPECT_EQ(seen[1].late_frames, 0u);
}

}  // namespace

TEST(LoadTestProgress, ASecondWithoutResponsesShowsNoLatency) {
  vts::loadtest::LoadProgress p;
  p.elapsed_s = 3;
  p.requests = 120;
  p.in_flight = 7;
  p.p99_ns = 0;  // nothing completed in the last second
  const std::string idle = vts::loadtest::progress_text(p, 30);
  EXPECT_NE(idle.find("no responses this second"), std::string::npos) << idle;
  EXPECT_EQ(idle.find("p99"), std::string::npos) << idle;
  p.requests_per_s = 40;
  p.p99_ns = 8'210'000;
  p.late_frames = 2;
  EXPECT_EQ(vts::loadtest::progress_text(p, 30),
            "[    3s/30s] 120 requests (40/s), 0 errors, 7 in flight, p99 8.21 ms, 0 moves at "
            "full resolution, 2 late frames");
}
