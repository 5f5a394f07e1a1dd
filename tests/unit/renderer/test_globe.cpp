// GlobeScene on the CPU: the double-precision hit() that the reference renderer and the GPU follow.
#include "vts/renderer/globe.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>

namespace vts::renderer {
namespace {

constexpr std::uint64_t kW = 2048, kH = 1024;

double u_of(double lon) {
  return (lon + 180) / 360 * kW;
}
double v_of(double lat) {
  return (90 - lat) / 180 * kH;
}

TEST(GlobeScene, CentreStraightDownIsTheNadir) {
  for (double alt : {1.0, 1e3, 2e7}) {
    for (auto [lon, lat] : {std::pair{10.0, 20.0}, {-120.5, -45.25}, {179.0, 0.0}}) {
      GlobeScene scene(GlobeView{.lon_deg = lon, .lat_deg = lat, .altitude_m = alt, .heading = 0.7},
                       kW, kH);
      const auto h = scene.hit(128, 96, 256, 192);
      ASSERT_TRUE(h) << alt;
      EXPECT_NEAR(h->first, u_of(lon), 1e-6) << alt;
      EXPECT_NEAR(h->second, v_of(lat), 1e-6) << alt;
      const auto f = scene.focus();
      EXPECT_NEAR(f.first, u_of(lon), 1e-6);
      EXPECT_NEAR(f.second, v_of(lat), 1e-6);
      EXPECT_EQ(scene.anchor()[0], std::int64_t(std::floor(u_of(lon))));
      EXPECT_EQ(scene.anchor()[1], std::int64_t(std::floor(v_of(lat))));
    }
  }
}

TEST(GlobeScene, HeadingZeroPutsNorthAtTheTopAndEastOnTheRight) {
  GlobeScene scene(GlobeView{.lon_deg = 30, .lat_deg = 10, .altitude_m = 1e6}, kW, kH);
  const auto top = scene.hit(128, 10, 256, 256);
  const auto bottom = scene.hit(128, 246, 256, 256);
  const auto left = scene.hit(10, 128, 256, 256);
  const auto right = scene.hit(246, 128, 256, 256);
  ASSERT_TRUE(top && bottom && left && right);
  EXPECT_LT(top->second, bottom->second);  // north (smaller v) at the top
  EXPECT_NEAR(top->first, u_of(30), 1e-6);
  EXPECT_LT(left->first, right->first);  // east (larger u) on the right
  EXPECT_NEAR(left->second, right->second, 1e-6);
  // Heading pi/2: screen-up points east.
  GlobeScene east(GlobeView{.lon_deg = 30, .lat_deg = 10, .altitude_m = 1e6, .heading = M_PI / 2},
                  kW, kH);
  const auto up = east.hit(128, 10, 256, 256);
  ASSERT_TRUE(up);
  EXPECT_GT(up->first, u_of(30) + 1);
  EXPECT_NEAR(up->second, v_of(10), 0.5);  // a great circle east bends a little south
}

TEST(GlobeScene, RaysAboveTheHorizonMiss) {
  GlobeScene scene(GlobeView{.lat_deg = 45, .altitude_m = 1000, .tilt = 1.5, .fov_y = 0.8}, kW, kH);
  EXPECT_FALSE(scene.hit(128, 1, 256, 256));   // top row: above the horizon
  EXPECT_TRUE(scene.hit(128, 255, 256, 256));  // bottom row: the ground
  // The whole globe from far away: the corners are space.
  GlobeScene far(GlobeView{.altitude_m = 2e7}, kW, kH);
  EXPECT_TRUE(far.hit(128, 128, 256, 256));
  EXPECT_FALSE(far.hit(0.5, 0.5, 256, 256));
  // Looking past the limb: focus falls back on the nadir.
  GlobeScene sky(GlobeView{.lon_deg = 5, .lat_deg = 5, .altitude_m = 1000, .tilt = 1.6}, kW, kH);
  EXPECT_FALSE(sky.hit(128, 128, 256, 256));
  EXPECT_NEAR(sky.focus().first, u_of(5), 1e-6);
  EXPECT_NEAR(sky.focus().second, v_of(5), 1e-6);
}

TEST(GlobeScene, UWrapsIntoTheImageAcrossTheDateLine) {
  GlobeScene scene(GlobeView{.lon_deg = 180, .altitude_m = 1e6}, kW, kH);
  EXPECT_EQ(scene.u_period(), double(kW));
  bool saw_low = false, saw_high = false;
  for (int x = 0; x < 256; x += 5) {
    const auto h = scene.hit(x + 0.5, 128, 256, 256);
    ASSERT_TRUE(h);
    EXPECT_GE(h->first, 0.0);
    EXPECT_LT(h->first, double(kW));
    saw_low |= h->first < 100;
    saw_high |= h->first > kW - 100;
  }
  EXPECT_TRUE(saw_low && saw_high);
  EXPECT_GE(scene.anchor()[0], 0);
  EXPECT_LT(scene.anchor()[0], std::int64_t(kW));
}

TEST(GlobeScene, PolesStayFiniteAndInRange) {
  for (double lat : {90.0, 89.9, -90.0, -89.9}) {
    GlobeScene scene(GlobeView{.lon_deg = 33, .lat_deg = lat, .altitude_m = 5e5}, kW, kH);
    for (int y = 0; y < 64; y += 3) {
      for (int x = 0; x < 64; x += 3) {
        const auto h = scene.hit(x + 0.5, y + 0.5, 64, 64);
        ASSERT_TRUE(h);
        EXPECT_TRUE(std::isfinite(h->first) && std::isfinite(h->second));
        EXPECT_GE(h->second, 0.0);
        EXPECT_LT(h->second, double(kH));
        EXPECT_GE(h->first, 0.0);
        EXPECT_LT(h->first, double(kW));
      }
    }
    EXPECT_GT(scene.texels_per_pixel(), 0.0);
  }
}

TEST(GlobeScene, ZoomFollowsTheAltitude) {
  // 2^25 texels around the equator: 1.19 m per texel. Straight down from h, a pixel of a
  // 1024-row viewport spans h * 2 tan(fov/2) / 1024 metres.
  const std::uint64_t w = 1ull << 25;
  GlobeScene scene(GlobeView{.altitude_m = 1000}, w, w / 2);
  const double expect = 1000 * 2 * std::tan(0.4) / 1024 / (2 * M_PI * kEarthRadiusM / double(w));
  EXPECT_NEAR(scene.texels_per_pixel(), expect, 1e-9 * expect);
}

}  // namespace
}  // namespace vts::renderer
