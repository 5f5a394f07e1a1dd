// What `vts loadtest` runs, from its arguments (scenario.hpp): the target and cache choice, the
// viewers' camera demand (the renderer's real presets and demand simulator), and the simulation
// figures as JSON and as a terminal line.
#include "vts/loadtest/scenario.hpp"

#include <algorithm>

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;
using namespace vts::client;
using namespace vts::loadtest;

namespace {

TEST(Scenario, DaemonModeSendsRequestsThroughTheDaemon) {
  LoadTestOptions o;
  ASSERT_TRUE(apply_target({"http://origin/earth", "daemon", "", "http://daemon/earth"}, o).ok());
  EXPECT_EQ(o.target, "http://daemon/earth");
  EXPECT_EQ(o.cache, CacheMode::none);

  LoadTestOptions direct;
  ASSERT_TRUE(apply_target({"http://origin/earth", "ram", "", ""}, direct).ok());
  EXPECT_EQ(direct.target, "http://origin/earth");
  EXPECT_EQ(direct.cache, CacheMode::ram);
}

TEST(Scenario, DaemonModeWithoutADaemonAndDiskModeWithoutAFolderAreRefused) {
  LoadTestOptions o;
  const vts::Status daemon = apply_target({"http://origin/earth", "daemon", "", ""}, o);
  ASSERT_FALSE(daemon.ok());
  EXPECT_EQ(daemon.error().code, vts::ErrorCode::invalid_argument);
  EXPECT_NE(daemon.error().message.find("--daemon"), std::string::npos);

  const vts::Status disk = apply_target({"http://origin/earth", "disk", "", ""}, o);
  ASSERT_FALSE(disk.ok());
  EXPECT_EQ(disk.error().code, vts::ErrorCode::invalid_argument);
  EXPECT_NE(disk.error().message.find("--cache-dir"), std::string::npos);

  ASSERT_TRUE(apply_target({"http://origin/earth", "disk", "/tmp/x", ""}, o).ok());
  EXPECT_EQ(o.cache, CacheMode::disk);
  EXPECT_EQ(o.cache_dir, fs::path("/tmp/x"));
}

TEST(Scenario, APathThatIsNeitherAPresetNorAFileIsNotFoundAndTheErrorListsThePresets) {
  auto g = vts::Geometry::create(4096, 2048);
  ASSERT_TRUE(g.ok());
  CameraDemandOptions c;
  c.path = "flyovr";
  auto d = camera_demand(*g, c);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().code, vts::ErrorCode::not_found);
  EXPECT_NE(d.error().message.find("flyover"), std::string::npos) << d.error().message;
}

TEST(Scenario, AnUnparsableCameraPathFileIsNamedInTheError) {
  const fs::path file =
      fs::temp_directory_path() / ("vts-scenario-test-" + std::to_string(::getpid()) + ".json");
  std::ofstream(file) << "{ not json";
  auto g = vts::Geometry::create(4096, 2048);
  ASSERT_TRUE(g.ok());
  CameraDemandOptions c;
  c.path = file.string();
  auto d = camera_demand(*g, c);
  fs::remove(file);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().message.rfind("camera path '" + file.string() + "': ", 0), 0u)
      << d.error().message;
}

TEST(Scenario, APresetGivesEveryViewerCoarseFirstDemandStartingWithAMove) {
  auto g = vts::Geometry::create(4096, 2048);
  ASSERT_TRUE(g.ok());
  CameraDemandOptions c;
  c.path = "flyover";
  c.viewers = 3;
  c.duration_s = 2;
  c.width = 320;
  c.height = 200;
  auto d = camera_demand(*g, c);
  ASSERT_TRUE(d.ok()) << d.error().to_string();
  EXPECT_EQ(d->path_name, "flyover");
  for (std::uint32_t v = 0; v < c.viewers; ++v) {
    auto first = d->demand(v, 0, 0);
    ASSERT_TRUE(first.ok()) << first.error().to_string();
    EXPECT_TRUE(first->move) << "frame 0 starts a view";
    ASSERT_FALSE(first->tiles.empty());
    for (std::size_t i = 1; i < first->tiles.size(); ++i)
      EXPECT_LE(first->tiles[i - 1].tile.z, first->tiles[i].tile.z) << "coarse first";
  }
}

// A camera that stays put wants the same tiles: the jumps preset holds each place for its dwell,
// and every frame after the first of a place reuses the demand instead of simulating it again,
// with the tiles a fresh simulation of that frame gives.
TEST(Scenario, AnUnmovedCameraReusesItsDemandAndAMovedOneIsSimulatedAgain) {
  auto g = vts::Geometry::create(1 << 16, 1 << 15);
  ASSERT_TRUE(g.ok());
  CameraDemandOptions c;
  c.path = "jumps";
  c.viewers = 1;
  c.duration_s = 10;
  c.fps = 10;
  c.width = 320;
  c.height = 200;
  auto d = camera_demand(*g, c);
  ASSERT_TRUE(d.ok()) << d.error().to_string();
  int reused = 0, moves = 0;
  for (std::uint64_t f = 0; f < 100; ++f) {
    auto r = d->demand(0, f, 0);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
    if (r->move || f == 0) {
      ++moves;
      EXPECT_FALSE(r->reused) << "frame " << f << " starts a view";
    }
    reused += r->reused;
    if (f % 7 == 3) {
      auto fresh = camera_demand(*g, c);  // the same viewer, asked only for this frame
      ASSERT_TRUE(fresh.ok());
      auto one = fresh->demand(0, f, 0);
      ASSERT_TRUE(one.ok());
      EXPECT_FALSE(one->reused) << "frame " << f;
      ASSERT_EQ(one->tiles.size(), r->tiles.size()) << "frame " << f;
      for (std::size_t i = 0; i < r->tiles.size(); ++i) {
        EXPECT_EQ(one->tiles[i].tile, r->tiles[i].tile) << "frame " << f;
        EXPECT_EQ(one->tiles[i].coverage, r->tiles[i].coverage) << "frame " << f;
        EXPECT_EQ(one->tiles[i].direct, r->tiles[i].direct) << "frame " << f;
      }
    }
  }
  EXPECT_GT(moves, 1);
  EXPECT_EQ(reused, 100 - moves) << "every frame but a place's first reuses its demand";
}

// Viewers replaying a camera file start spread along it over all the generators: generator 1 of 2
// (viewers 2 and 3 of 4) flies what viewers 2 and 3 of one generator of 4 fly, not viewers 0, 1.
TEST(Scenario, GeneratorsSpreadTheirViewersAlongACameraFileTogether) {
  auto g = vts::Geometry::create(1 << 14, 1 << 13);
  ASSERT_TRUE(g.ok());
  // A flight round the globe at 2,000 km: each viewer's start is a different place.
  const fs::path file =
      fs::temp_directory_path() / ("vts-scenario-spread-" + std::to_string(::getpid()) + ".json");
  std::ofstream(file) << R"({"keys": [
    {"frame": 0, "lon": -180, "lat": 0, "altitude_m": 2e6},
    {"frame": 100, "lon": 0, "lat": 30, "altitude_m": 2e6},
    {"frame": 200, "lon": 180, "lat": 0, "altitude_m": 2e6}]})";
  CameraDemandOptions all;
  all.path = file.string();
  all.viewers = 4;
  all.width = 320;
  all.height = 200;
  CameraDemandOptions second = all;
  second.viewers = 2;
  second.first_viewer = 2;
  second.total_viewers = 4;
  auto a = camera_demand(*g, all);
  auto b = camera_demand(*g, second);
  fs::remove(file);
  ASSERT_TRUE(a.ok() && b.ok());
  for (std::uint32_t v = 0; v < 2; ++v) {
    auto want = a->demand(2 + v, 0, 0), got = b->demand(v, 0, 0), first = a->demand(v, 0, 0);
    ASSERT_TRUE(want.ok() && got.ok() && first.ok());
    ASSERT_EQ(got->tiles.size(), want->tiles.size()) << "viewer " << v;
    for (std::size_t i = 0; i < got->tiles.size(); ++i)
      EXPECT_EQ(got->tiles[i].tile, want->tiles[i].tile) << "viewer " << v;
    EXPECT_FALSE(
        first->tiles.size() == got->tiles.size() &&
        std::equal(got->tiles.begin(), got->tiles.end(), first->tiles.begin(),
                   [](const DemandTile& x, const DemandTile& y) { return x.tile == y.tile; }))
        << "viewer " << v << " flies what generator 0's viewer " << v << " flies";
  }
}

TEST(Scenario, TheSimulationFiguresAppearInTheJsonAndTheLine) {
  LoadRunStats run;
  run.frames = 120;
  run.late_frames = 3;
  run.moves_incomplete = 2;
  run.idle_slots = 7;
  run.startup_slots = 2;
  run.abandoned = 1;
  run.demand_cpu_ms_per_frame = 0.25;
  run.demand_reused = 90;
  CameraDemandOptions c;
  c.width = 640;
  c.height = 480;
  const nlohmann::json j = simulation_json(run, c, "ram", 2);
  EXPECT_EQ(j["viewer_frames"], 120);
  EXPECT_EQ(j["late_frames"], 3);
  EXPECT_EQ(j["idle_slots"], 7);
  EXPECT_EQ(j["startup_slots"], 2);
  EXPECT_EQ(j["viewport"], nlohmann::json({640, 480}));
  EXPECT_EQ(j["feedback_divisor"], 8);
  EXPECT_EQ(j["cache"], "ram");
  EXPECT_EQ(j["retries"], 2);
  EXPECT_EQ(j["demand_reused_frames"], 90);

  EXPECT_EQ(simulation_line(run, false),
            "simulation: 120 viewer-frames (3 late, 90 unmoved), demand 0.25 ms CPU/frame, 2 moves "
            "not at full resolution in time, 1 abandoned at the end\n");
  EXPECT_NE(simulation_line(run, true).find(", 7 idle slots (2 more at start-up)\n"),
            std::string::npos);
}

}  // namespace
