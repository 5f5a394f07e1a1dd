// The load test's CPU demand simulator against the renderer's GPU feedback on the same cameras:
// the tiles a view asks for must be the same set (Jaccard similarity), plane and globe, with and
// without anisotropy, at 1/1 feedback and at 1/8.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <set>
#include <string>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/renderer/demand.hpp"
#include "vts/renderer/globe.hpp"
#include "vts/renderer/scene.hpp"
#include "vts/renderer/virtual_texture.hpp"

namespace fs = std::filesystem;
using namespace vts::renderer;

namespace {

class DemandTest : public vts::test::VirtualTextureFixture {
 protected:
  using Keys = std::set<std::uint64_t>;

  static Keys keys(const std::vector<TileRequest>& requests, bool direct_only) {
    Keys k;
    for (const TileRequest& r : requests)
      if (r.direct || !direct_only) k.insert(tile_key(r.tile));
    return k;
  }

  static double jaccard(const Keys& a, const Keys& b) {
    if (a.empty() && b.empty()) return 1;
    std::size_t both = 0;
    for (auto k : a) both += b.count(k);
    return double(both) / double(a.size() + b.size() - both);
  }

  // GPU feedback of `scene` once the view is complete (so the wanted list is this view's), and
  // the simulator's demand for the same view and bias; prints and returns the direct-tile
  // Jaccard similarity (and checks the one with ancestors too).
  double compare(const fs::path& path, const Scene& scene, int w, int h, int k, int aniso,
                 const std::string& name) {
    VirtualTextureOptions o;
    o.slots = 1024;
    o.window = 128;
    o.feedback_divisor = k;
    o.anisotropy = aniso;
    auto vt = open(path, o);
    EXPECT_TRUE(vt);
    if (!vt) return 0;
    bool complete = false;
    for (int i = 0; i < 400 && !complete; ++i) {
      const FrameStats st = vt->render(scene, w, h);
      complete = st.complete;
      if (st.pending > 0) ::usleep(2000);
    }
    EXPECT_TRUE(complete) << name;
    auto sim = DemandSimulator::create(vt->geometry(), DemandOptions{k, aniso});
    EXPECT_TRUE(sim.ok()) << sim.error().to_string();
    if (!sim.ok()) return 0;
    auto cpu = sim->demand(scene, w, h, vt->mip_bias());
    EXPECT_TRUE(cpu.ok()) << cpu.error().to_string();
    if (!cpu.ok()) return 0;
    const auto& gpu = vt->last_wanted();
    const double direct = jaccard(keys(gpu, true), keys(*cpu, true));
    const double all = jaccard(keys(gpu, false), keys(*cpu, false));
    std::printf("  %s: GPU %zu tiles, CPU %zu tiles, Jaccard direct %.4f, with ancestors %.4f\n",
                name.c_str(), gpu.size(), cpu->size(), direct, all);
    EXPECT_GE(all, direct - 0.02) << name;  // ancestors only add shared tiles
    if (direct < 1) {
      const Keys g = keys(gpu, true), c = keys(*cpu, true);
      for (const auto& r : gpu)
        if (r.direct && !c.count(tile_key(r.tile)))
          std::printf("    GPU only: %s (%u px)\n", r.tile.to_string().c_str(), r.coverage);
      for (const auto& r : *cpu)
        if (r.direct && !g.count(tile_key(r.tile)))
          std::printf("    CPU only: %s (%u px)\n", r.tile.to_string().c_str(), r.coverage);
    }
    return direct;
  }
};

TEST_F(DemandTest, PlaneViewsMatchTheGpuFeedback) {
  const fs::path path = archive("earth64", 64, 4);
  const PlaneView views[] = {
      {.center_u = 700.3, .center_v = 400.7, .texels_per_pixel = 1.7},
      {.center_u = 1200, .center_v = 500, .texels_per_pixel = 0.8, .heading = 0.6, .tilt = 1.0},
      {.center_u = 1000, .center_v = 600, .texels_per_pixel = 1.2, .heading = -0.4, .tilt = 1.25},
      {.center_u = 300, .center_v = 900, .texels_per_pixel = 6.5, .heading = 2.0, .tilt = 0.5},
  };
  int i = 0;
  for (const PlaneView& v : views) {
    for (int aniso : {1, 8}) {
      const std::string name = "plane" + std::to_string(i) + "-aniso" + std::to_string(aniso);
      EXPECT_GE(compare(path, PlaneScene(v), 256, 192, 1, aniso, name), 0.95) << name;
    }
    ++i;
  }
}

TEST_F(DemandTest, GlobeViewsMatchTheGpuFeedback) {
  const fs::path path = archive("earth64", 64, 4);
  auto probe = open(path);
  ASSERT_TRUE(probe);
  const auto W = probe->geometry().width(), H = probe->geometry().height();
  const GlobeView views[] = {
      {.lon_deg = 15, .lat_deg = 25, .altitude_m = 2e7, .heading = 0.3},
      {.lon_deg = 179.9, .lat_deg = 66, .altitude_m = 3e5, .heading = 1.4, .tilt = 1.2},
      {.lon_deg = -40, .lat_deg = 88, .altitude_m = 1e6, .heading = 0.2, .tilt = 0.4},
  };
  int i = 0;
  for (const GlobeView& v : views) {
    for (int aniso : {1, 8}) {
      const std::string name = "globe" + std::to_string(i) + "-aniso" + std::to_string(aniso);
      EXPECT_GE(compare(path, GlobeScene(v, W, H), 256, 192, 1, aniso, name), 0.95) << name;
    }
    ++i;
  }
}

TEST_F(DemandTest, ReducedFeedbackResolutionMatchesToo) {
  const fs::path path = archive("earth64", 64, 4);
  const PlaneView v{
      .center_u = 1200, .center_v = 500, .texels_per_pixel = 0.8, .heading = 0.6, .tilt = 1.0};
  EXPECT_GE(compare(path, PlaneScene(v), 256, 192, 8, 1, "plane-k8"), 0.95);
}

}  // namespace
