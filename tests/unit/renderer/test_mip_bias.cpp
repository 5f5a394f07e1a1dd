#include "vts/renderer/mip_bias.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>

namespace vts::renderer {
namespace {

MipBiasController::Options options() {
  MipBiasController::Options o;
  o.capacity = 1000;
  o.high_watermark = 0.9;
  o.low_watermark = 0.6;
  o.calm_frames = 10;
  o.step = 1.0;
  o.max_bias = 3.0;
  return o;
}

TEST(MipBias, RisesUnderPressureUpToTheMaximum) {
  MipBiasController c(options());
  EXPECT_EQ(c.update(500), 0.0);
  EXPECT_EQ(c.update(900), 0.0);  // at the watermark is not above it
  EXPECT_EQ(c.update(901), 1.0);
  EXPECT_EQ(c.update(5000), 2.0);
  EXPECT_EQ(c.update(5000), 3.0);
  EXPECT_EQ(c.update(5000), 3.0);
}

TEST(MipBias, RaisesAtMostOncePerRaiseInterval) {
  auto o = options();
  o.raise_interval = 3;
  MipBiasController c(o);
  EXPECT_EQ(c.update(5000), 1.0);
  EXPECT_EQ(c.update(5000), 1.0);
  EXPECT_EQ(c.update(5000), 1.0);
  EXPECT_EQ(c.update(5000), 2.0);
}

TEST(MipBias, LowersOnlyAfterCalmFramesBelowTheLowWatermark) {
  MipBiasController c(options());
  c.update(5000);
  c.update(5000);
  ASSERT_EQ(c.bias(), 2.0);
  // Between the watermarks: hold, however long.
  for (int i = 0; i < 100; ++i) EXPECT_EQ(c.update(700), 2.0);
  // Calm (below 600, and 4x after lowering stays <= 900) for 9 frames, then one busy frame:
  // the count restarts.
  for (int i = 0; i < 9; ++i) EXPECT_EQ(c.update(200), 2.0);
  EXPECT_EQ(c.update(700), 2.0);
  for (int i = 0; i < 9; ++i) EXPECT_EQ(c.update(200), 2.0);
  EXPECT_EQ(c.update(200), 1.0);  // the 10th consecutive calm frame
  // The next step down needs another 10 calm frames.
  for (int i = 0; i < 9; ++i) EXPECT_EQ(c.update(100), 1.0);
  EXPECT_EQ(c.update(100), 0.0);
  for (int i = 0; i < 50; ++i) EXPECT_EQ(c.update(0), 0.0);
}

// Demand of a screen-filling view: four times the tiles per level of detail added.
std::uint64_t screen_demand(double full_detail_demand, double bias) {
  return static_cast<std::uint64_t>(full_detail_demand / std::pow(4.0, bias));
}

int bias_changes(MipBiasController& c, double full_detail_demand, int frames) {
  int changes = 0;
  double last = c.bias();
  for (int f = 0; f < frames; ++f) {
    c.update(screen_demand(full_detail_demand, c.bias()));
    if (c.bias() != last) ++changes;
    last = c.bias();
  }
  return changes;
}

TEST(MipBias, SettlesWithoutOscillatingWhenLoweringWouldOverflowAgain) {
  // 2000 tiles at full detail, 500 at bias 1: below the low watermark (600), but lowering would
  // bring back 2000 > 900. The controller must settle at 1 and stay.
  MipBiasController c(options());
  EXPECT_EQ(bias_changes(c, 2000, 1000), 1);
  EXPECT_EQ(c.bias(), 1.0);
  // Without the prediction (growth 1) the same view bounces every calm_frames frames: the
  // prediction is what the previous expectation depends on.
  auto o = options();
  o.growth = 1.0;
  MipBiasController naive(o);
  EXPECT_GT(bias_changes(naive, 2000, 1000), 100);
}

TEST(MipBias, RecoversFullDetailWhenTheViewGetsCheap) {
  MipBiasController c(options());
  // 20000 tiles at full detail: 1250 > 900 still at bias 2, so it rises to 3 (312 tiles), where
  // lowering would predict 1250 again and it stays.
  bias_changes(c, 20000, 100);
  EXPECT_EQ(c.bias(), 3.0);
  bias_changes(c, 150, 100);  // a cheap view: every level fits
  EXPECT_EQ(c.bias(), 0.0);
}

TEST(MipBias, HalfLevelStepsUseTheHalfLevelGrowth) {
  auto o = options();
  o.step = 0.5;
  MipBiasController c(o);
  // 1500 at full detail: 750 at bias 0.5, which fits; lowering would predict 1500 > 900.
  EXPECT_EQ(bias_changes(c, 1500, 500), 1);
  EXPECT_EQ(c.bias(), 0.5);
}

}  // namespace
}  // namespace vts::renderer
