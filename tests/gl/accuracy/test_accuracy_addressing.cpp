// Table 4 of `vts bench accuracy` (accuracy/src/accuracy_addressing.cpp): float32 UV against the
// renderer's integer texel + float fraction, measured on the GPU against double precision.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <variant>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/accuracy/accuracy.hpp"
#include "vts/accuracy/addressing_detail.hpp"

namespace vts::test {
namespace {

// Below the 1/256 weight resolution of hardware bilinear filtering (8 fractional bits): an error
// this small cannot move a filtered sample by more than the filter's own quantisation.
constexpr double kOursBound = 1.0 / 256.0;

class AccuracyAddressing : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string error;
    ASSERT_NE(shared_gl_context(&error), nullptr) << error;
  }
};

double number(const accuracy::Cell& c) {
  const double* d = std::get_if<double>(&c);
  EXPECT_NE(d, nullptr) << "a text cell where a number belongs";
  return d ? *d : std::nan("");
}

std::string text(const accuracy::Cell& c) {
  const std::string* s = std::get_if<std::string>(&c);
  EXPECT_NE(s, nullptr) << "a number cell where text belongs";
  return s ? *s : std::string();
}

void print(const accuracy::AccuracyTable& t) {
  for (const auto& c : t.columns) std::printf("%s | ", c.title.c_str());
  std::printf("\n");
  for (const auto& row : t.rows) {
    for (std::size_t i = 0; i < row.size(); ++i) {
      if (const double* d = std::get_if<double>(&row[i])) {
        std::printf("%.*g | ", t.columns[i].digits + 3, *d);
      } else {
        std::printf("%s | ", std::get<std::string>(row[i]).c_str());
      }
    }
    std::printf("\n");
  }
  for (const auto& n : t.notes) std::printf("- %s\n", n.c_str());
}

// The properties the table exists to show, for a table of the sizes 2^n, n in `sizes`.
void check(const accuracy::AccuracyTable& t, const std::vector<double>& sizes) {
  EXPECT_EQ(t.id, "addressing");
  const std::vector<std::string> keys = {
      "virtual_size_log2",    "variant",         "max_texel_error", "mean_texel_error",
      "wrong_texel_fraction", "max_level_error", "shader_ms",       "ratio_to_float32"};
  ASSERT_EQ(t.columns.size(), keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i) EXPECT_EQ(t.columns[i].key, keys[i]);
  // Per size: float32 UV, then ours.
  ASSERT_EQ(t.rows.size(), 2 * sizes.size());
  double previous_float = 0, first_ours = 0;
  for (std::size_t i = 0; i < t.rows.size(); i += 2) {
    const auto& f = t.rows[i];
    const auto& o = t.rows[i + 1];
    ASSERT_EQ(f.size(), keys.size());
    ASSERT_EQ(o.size(), keys.size());
    const double n = number(f[0]);
    EXPECT_EQ(n, number(o[0]));
    EXPECT_EQ(n, sizes[i / 2]);
    EXPECT_EQ(text(f[1]), "float32 UV");
    EXPECT_EQ(text(o[1]), "ours (int + frac)");
    const double fmax = number(f[2]), omax = number(o[2]);
    SCOPED_TRACE("2^" + std::to_string(int(n)) + ": float32 " + std::to_string(fmax) + ", ours " +
                 std::to_string(omax));
    // Ours: bounded, the same whatever the size (it never forms a coordinate over the whole
    // texture), and not exact by accident (it is a real float computation).
    EXPECT_LT(omax, kOursBound);
    EXPECT_GT(omax, 0.0);
    if (i == 0) first_ours = omax;
    EXPECT_LT(omax, 2 * first_ours) << "ours must not grow with the size";
    EXPECT_LE(number(o[3]), omax);
    EXPECT_LT(number(o[4]), 0.001);  // wrong-texel fraction
    EXPECT_LT(number(o[5]), 0.001);  // mip-level error
    // float32 UV: worse than ours at every size, and about a bit worse per doubling of the size.
    EXPECT_GT(fmax, omax);
    if (i > 0) {
      const double doublings = n - sizes[i / 2 - 1];
      EXPECT_GT(fmax, previous_float * std::exp2(0.6 * doublings))
          << doublings << " doublings should cost about as many bits";
    }
    previous_float = fmax;
    EXPECT_LE(number(f[3]), fmax);
    // Times: measured, positive, and the ratio is the variant's over float32's.
    const double fms = number(f[6]), oms = number(o[6]);
    EXPECT_TRUE(fms > 0 && std::isfinite(fms));
    EXPECT_TRUE(oms > 0 && std::isfinite(oms));
    EXPECT_DOUBLE_EQ(number(f[7]), 1.0);
    EXPECT_NEAR(number(o[7]), oms / fms, 1e-9);
  }
  // At 2^25 a float over [0, 1] cannot address a texel: its ulp near 1 is two texels.
  const auto& f25 = t.rows[t.rows.size() - 2];
  ASSERT_EQ(number(f25[0]), 25.0);
  EXPECT_GT(number(f25[2]), 1.0);
  EXPECT_GT(number(f25[4]), 0.25) << "many pixels should land on a wrong texel";
  EXPECT_GE(number(f25[5]), 1.0) << "and the footprint should pick a wrong level";

  EXPECT_FALSE(t.notes.empty());
  ASSERT_EQ(t.plots.size(), 2u);
  ASSERT_EQ(t.plots[0].series.size(), 3u);  // float32 UV, ours, float's half-ulp near 1
  for (const auto& series : t.plots[0].series) EXPECT_EQ(series.points.size(), sizes.size());
  // float32 UV's error is its rounding: a few half-ulps of a uv near 1, never below one.
  for (std::size_t k = 0; k < sizes.size(); ++k) {
    const auto& f = t.plots[0].series[0].points[k];
    const auto& h = t.plots[0].series[2].points[k];
    EXPECT_EQ(f.first, h.first);
    EXPECT_DOUBLE_EQ(h.second, std::exp2(sizes[k] - 25));
    EXPECT_GT(f.second, 0.5 * h.second);
    EXPECT_LT(f.second, 8 * h.second);
  }
}

TEST_F(AccuracyAddressing, QuickTableShowsFloatUvFailingAndOursHolding) {
  accuracy::AccuracyContext ctx;
  ctx.quick = true;
  ctx.width = 160;
  ctx.height = 100;
  int said = 0;
  ctx.progress = [&](const std::string&) { ++said; };
  const auto t0 = std::chrono::steady_clock::now();
  auto r = accuracy::addressing_table(ctx);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  print(*r);
  EXPECT_LT(seconds, 30.0) << "quick mode is meant to take seconds";
  EXPECT_GT(said, 0);
  check(*r, {15, 20, 25});
}

// The full table at the default viewport (minutes on llvmpipe; run by hand with
// --gtest_also_run_disabled_tests): the figures docs/ACCURACY.md quotes, under the same checks.
TEST_F(AccuracyAddressing, DISABLED_FullTable) {
  accuracy::AccuracyContext ctx;
  ctx.quick = false;
  ctx.width = 640;
  ctx.height = 400;
  ctx.progress = [](const std::string& line) { std::printf("%s\n", line.c_str()); };
  auto r = accuracy::addressing_table(ctx);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  print(*r);
  check(*r, {15, 17, 19, 21, 23, 25});
}

TEST_F(AccuracyAddressing, MeasuresTheShippedShaderCode) {
  using namespace accuracy::detail_addressing;
  EXPECT_TRUE(production_has(kOursHit));
  EXPECT_TRUE(production_has(kOursDerivatives));
  EXPECT_TRUE(production_has(kOursSplit));
  // The check is not vacuous: reformatting passes, a changed split does not.
  std::string reflowed = std::string(kOursSplit) + "\n\n";
  for (auto& c : reflowed) {
    if (c == ' ') c = '\t';
  }
  EXPECT_TRUE(production_has(reflowed));
  std::string changed = kOursSplit;
  changed.replace(changed.find("ivec2(floor(rel))"), 17, "ivec2(round(rel))");
  EXPECT_FALSE(production_has(changed));
}

TEST_F(AccuracyAddressing, RefusesAViewportItCannotRender) {
  accuracy::AccuracyContext ctx;
  ctx.quick = true;
  ctx.width = 0;
  ctx.height = 100;
  auto r = accuracy::addressing_table(ctx);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(r.error().message.find("viewport"), std::string::npos);
}

}  // namespace
}  // namespace vts::test

namespace vts::test {
namespace {

// Run with no display (the gl.without_display ctest entry): no context can be current.
TEST(GlNoDisplay, AddressingTableWithoutAContextIsAClearError) {
  accuracy::AccuracyContext ctx;
  ctx.quick = true;
  auto r = accuracy::addressing_table(ctx);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::unsupported);
  EXPECT_NE(r.error().message.find("OpenGL 4.5"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace vts::test
