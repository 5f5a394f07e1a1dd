// One camera path through the GL viewer (VirtualTexture, GPU feedback under Xvfb) and through the
// load tester (run_load_test, one simulated viewer: CPU demand, the real client stack): both run
// the same streaming engine (renderer::TileStream), so they must ask for the same tiles in the same
// order and evict the same tiles. Each view is held until everything it asked for is in and one
// more frame has passed, on both sides, so the comparison does not depend on arrival timing; the
// physical texture is smaller than the path's tiles, so residency (evictions, and tiles asked for
// again after their eviction) is part of what is compared.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/loadtest/load_test.hpp"
#include "vts/renderer/demand.hpp"
#include "vts/renderer/scene.hpp"
#include "vts/renderer/tile_stream.hpp"

namespace fs = std::filesystem;
using namespace vts::renderer;

namespace {

constexpr int kWidth = 256, kHeight = 192, kDivisor = 8;
// Each view wants fewer tiles than the mip bias's high watermark (0.9 x the slots), so the bias
// stays 0; the path as a whole wants many more.
constexpr std::uint32_t kSlots = 56, kKeepFrames = 1;

// The path: pans and zooms over the Earth image, and back to the start (its tiles were evicted
// meanwhile, so they are asked for again).
const std::vector<PlaneView>& path() {
  static const std::vector<PlaneView> views = {
      {.center_u = 611.3, .center_v = 407.9, .texels_per_pixel = 1.07},
      {.center_u = 903.6, .center_v = 452.2, .texels_per_pixel = 1.13},
      {.center_u = 1403.1, .center_v = 601.7, .texels_per_pixel = 2.3},
      {.center_u = 1000.4, .center_v = 500.6, .texels_per_pixel = 4.3},
      {.center_u = 302.8, .center_v = 305.3, .texels_per_pixel = 0.77},
      {.center_u = 611.3, .center_v = 407.9, .texels_per_pixel = 1.07},
  };
  return views;
}

// What a stream decided, by kind (arrival order interleaves them differently on each side; each
// kind's own order does not depend on it).
struct Trace {
  std::vector<vts::TileId> requests, cancels, evictions;
  std::uint64_t placed = 0, answered = 0;  // answered: placed, refused, absent or failed
  void add(const StreamEvent& e) {
    switch (e.kind) {
      case StreamEvent::Kind::request:
        requests.push_back(e.tile);
        break;
      case StreamEvent::Kind::cancel:
        cancels.push_back(e.tile);
        break;
      case StreamEvent::Kind::evicted:
        evictions.push_back(e.tile);
        break;
      case StreamEvent::Kind::placed:
        ++placed;
        ++answered;
        break;
      case StreamEvent::Kind::refused:
      case StreamEvent::Kind::absent:
      case StreamEvent::Kind::failed:
        ++answered;
        break;
    }
  }
  std::uint64_t outstanding() const { return requests.size() - cancels.size() - answered; }
};

std::string list(const std::vector<vts::TileId>& tiles) {
  std::string s;
  for (const auto& t : tiles) s += t.to_string() + " ";
  return s;
}

class StreamParityTest : public vts::test::VirtualTextureFixture {};

TEST_F(StreamParityTest, TheViewerAndTheLoadTesterMakeTheSameRequestsOnOneCameraPath) {
  const fs::path archive_path = archive("earth64", 64, 4);

  // The GL viewer.
  Trace gl;
  {
    VirtualTextureOptions o;
    o.slots = kSlots;
    o.keep_frames = kKeepFrames;
    o.feedback_divisor = kDivisor;
    o.trace = [&gl](const StreamEvent& e) { gl.add(e); };
    auto vt = open(archive_path, o);
    ASSERT_TRUE(vt);
    for (std::size_t k = 0; k < path().size(); ++k) {
      const PlaneScene scene(path()[k]);
      bool complete = false;
      for (int i = 0; i < 2000 && !complete; ++i) {
        const FrameStats st = vt->render(scene, kWidth, kHeight);
        complete = st.complete;
        EXPECT_EQ(st.mip_bias, 0.0) << "view " << k;
        if (st.pending > 0) ::usleep(2000);  // the decode threads' turn
      }
      ASSERT_TRUE(complete) << "view " << k;
      vt->render(scene, kWidth, kHeight);  // one frame after the last placement, as below
    }
  }

  // The load tester, on the same path: view k until nothing is outstanding at two frames in a
  // row (the second frame marks the view's tiles used after the last one came), then view k + 1.
  Trace lt;
  std::mutex mutex;
  std::atomic<bool> stop{false};
  auto sim = DemandSimulator::create(
      [&] {
        auto src = vts::client::open_local_archive(archive_path);
        EXPECT_TRUE(src.ok());
        return (*src)->info().info.geometry;
      }(),
      DemandOptions{.feedback_divisor = kDivisor});
  ASSERT_TRUE(sim.ok()) << sim.error().to_string();
  std::size_t view = 0;
  int settled = 0;
  const vts::loadtest::DemandFn demand =
      [&](std::uint32_t, std::uint64_t f, double bias) -> vts::Result<vts::loadtest::ViewerDemand> {
    bool move = f == 0;
    {
      std::lock_guard lock(mutex);
      settled = lt.outstanding() == 0 && f > 0 ? settled + 1 : 0;
      if (settled >= 2) {
        settled = 0;
        if (view + 1 < path().size()) {
          ++view;
          move = true;
        } else {
          stop = true;
        }
      }
    }
    auto tiles = sim->demand(PlaneScene(path()[view]), kWidth, kHeight, bias);
    if (!tiles) return tiles.error();
    return vts::loadtest::ViewerDemand{std::move(*tiles), move};
  };
  vts::loadtest::LoadTestOptions o;
  o.target = archive_path.string();
  o.viewers = 1;
  o.threads = 1;
  o.fps = 100;
  o.duration_s = 120;  // ended by `stop` once the path is done
  o.resident_tiles = kSlots;
  o.keep_frames = kKeepFrames;
  o.stop = &stop;
  o.trace = [&](std::uint32_t, const StreamEvent& e) {
    std::lock_guard lock(mutex);
    lt.add(e);
  };
  auto run = vts::loadtest::run_load_test(o, demand);
  ASSERT_TRUE(run.ok()) << run.error().to_string();
  ASSERT_TRUE(stop.load()) << "the load tester did not finish the path in " << o.duration_s
                           << " s (view " << view << ")";

  std::printf("  %zu requests, %zu evictions on %zu views (GL viewer); %zu, %zu (load tester)\n",
              gl.requests.size(), gl.evictions.size(), path().size(), lt.requests.size(),
              lt.evictions.size());
  EXPECT_EQ(gl.requests, lt.requests)
      << "GL: " << list(gl.requests) << "\nload tester: " << list(lt.requests);
  EXPECT_EQ(gl.evictions, lt.evictions)
      << "GL: " << list(gl.evictions) << "\nload tester: " << list(lt.evictions);
  EXPECT_TRUE(gl.cancels.empty()) << list(gl.cancels);
  EXPECT_TRUE(lt.cancels.empty()) << list(lt.cancels);
  // The path is long enough to be a test of residency: tiles were evicted, and some of them were
  // asked for again when the path came back.
  EXPECT_GT(gl.evictions.size(), 0u);
  const std::set<vts::TileId> distinct(gl.requests.begin(), gl.requests.end());
  EXPECT_LT(distinct.size(), gl.requests.size());
}

}  // namespace
