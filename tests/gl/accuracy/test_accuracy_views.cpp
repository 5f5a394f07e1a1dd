// The feedback and filtering tables of `vts bench accuracy`
// (accuracy/include/vts/accuracy/accuracy.hpp) in quick mode on a 512x256 Earth archive, the size
// ctest runs the whole bench on: the figures must say what the measurements mean (1/1 finds every
// tile it needs, coarser feedback never finds more, anisotropic filtering is closer to the
// supersampled truth on an oblique view ...), and bad input must give an error.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <variant>

#include "gl_fixture.hpp"
#include "vts/accuracy/accuracy.hpp"
#include "vts/builder/builder.hpp"
#include "vts/builder/image_io.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/renderer/reference.hpp"

namespace fs = std::filesystem;
using vts::accuracy::AccuracyContext;
using vts::accuracy::AccuracyTable;

namespace {

class AccuracyViews : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("vts-accuracy-views-" + std::to_string(::getpid())));
    fs::create_directories(*dir_);
    // The Earth at 512x256 (a 4x4 box filter of the 2048x1024 image), tile 64, border 4: what
    // the bench's quick mode builds.
    auto earth = vts::read_rgba8("/usr/share/xplanet/images/earth.jpg");
    if (!earth.ok()) {
      setup_error_ = earth.error().to_string();
      return;
    }
    const int f = 4;
    vts::renderer::Image small = vts::renderer::Image::blank(earth->width / f, earth->height / f);
    for (int y = 0; y < small.height; ++y) {
      for (int x = 0; x < small.width; ++x) {
        for (int c = 0; c < 4; ++c) {
          int sum = 0;
          for (int dy = 0; dy < f; ++dy)
            for (int dx = 0; dx < f; ++dx)
              sum += earth->rgba[(std::size_t(y * f + dy) * earth->width + x * f + dx) * 4 + c];
          small.at(x, y)[c] = std::uint8_t((sum + f * f / 2) / (f * f));
        }
      }
    }
    const fs::path input = *dir_ / "earth512.png";
    if (auto s = vts::imaging::write_png(input, small.width, small.height, small.rgba); !s.ok()) {
      setup_error_ = s.error().to_string();
      return;
    }
    vts::BuildOptions o;
    o.inputs = {input};
    o.output = *dir_ / "earth512.pmtiles";
    o.tile_size = 64;
    o.border = 4;
    o.threads = 2;
    auto built = vts::build_pyramid(o);
    if (!built.ok()) setup_error_ = built.error().to_string();
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(*dir_, ec);
    delete dir_;
  }

  void SetUp() override {
    ASSERT_TRUE(setup_error_.empty()) << setup_error_;
    std::string error;
    ASSERT_NE(vts::test::shared_gl_context(&error), nullptr) << error;
  }

  static AccuracyContext quick_context() {
    AccuracyContext ctx;
    ctx.input = *dir_ / "earth512.png";
    ctx.work_dir = *dir_;
    ctx.archive = *dir_ / "earth512.pmtiles";
    ctx.quick = true;
    ctx.width = 160;
    ctx.height = 100;
    return ctx;
  }

  // The number in column `key` of row `row` (fails the test for a missing column or a text cell).
  static double num(const AccuracyTable& t, std::size_t row, const std::string& key) {
    for (std::size_t c = 0; c < t.columns.size(); ++c) {
      if (t.columns[c].key != key) continue;
      if (row >= t.rows.size() || c >= t.rows[row].size()) {
        ADD_FAILURE() << "row " << row << " has no column " << key;
        return std::nan("");
      }
      if (const double* d = std::get_if<double>(&t.rows[row][c])) return *d;
      ADD_FAILURE() << key << " is text in row " << row;
      return std::nan("");
    }
    ADD_FAILURE() << "no column " << key;
    return std::nan("");
  }
  static std::string text(const AccuracyTable& t, std::size_t row, const std::string& key) {
    for (std::size_t c = 0; c < t.columns.size(); ++c) {
      if (t.columns[c].key == key && row < t.rows.size() && c < t.rows[row].size()) {
        if (const std::string* s = std::get_if<std::string>(&t.rows[row][c])) return *s;
      }
    }
    ADD_FAILURE() << "no text column " << key << " in row " << row;
    return {};
  }

  static void well_formed(const AccuracyTable& t) {
    EXPECT_FALSE(t.title.empty());
    EXPECT_GE(t.notes.size(), 3u);
    for (const auto& row : t.rows) EXPECT_EQ(row.size(), t.columns.size());
    ASSERT_GE(t.plots.size(), 1u);
    for (const auto& p : t.plots) {
      EXPECT_FALSE(p.id.empty());
      EXPECT_FALSE(p.series.empty()) << p.id;
    }
    EXPECT_EQ(t.plots[0].series[0].points.size(), 5u) << t.plots[0].id;
  }

  static void print(const AccuracyTable& t) {
    std::string line;
    for (const auto& c : t.columns) line += c.key + " | ";
    std::printf("  %s\n", line.c_str());
    for (const auto& row : t.rows) {
      line.clear();
      for (const auto& cell : row) {
        if (const double* d = std::get_if<double>(&cell)) {
          char buf[32];
          std::snprintf(buf, sizeof buf, "%.4g", *d);
          line += buf;
        } else {
          line += std::get<std::string>(cell);
        }
        line += " | ";
      }
      std::printf("  %s\n", line.c_str());
    }
  }

  static double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

  static inline fs::path* dir_ = nullptr;
  static inline std::string setup_error_;
};

TEST_F(AccuracyViews, FeedbackTableMeasuresWhatCoarserFeedbackMisses) {
  AccuracyContext ctx = quick_context();
  int said = 0;
  ctx.progress = [&](const std::string&) { ++said; };
  const auto t0 = std::chrono::steady_clock::now();
  auto table = vts::accuracy::feedback_table(ctx);
  const double took = seconds_since(t0);
  ASSERT_TRUE(table.ok()) << table.error().to_string();
  const AccuracyTable& t = *table;
  print(t);
  std::printf("  feedback table: %.1f s\n", took);
  EXPECT_EQ(t.id, "feedback");
  ASSERT_EQ(t.rows.size(), 5u);
  well_formed(t);
  EXPECT_GT(said, 3);
  EXPECT_LT(took, 30.0) << "quick mode must stay quick";

  const int divisors[] = {1, 2, 4, 8, 16};
  for (std::size_t r = 0; r < 5; ++r) {
    const int k = divisors[r];
    EXPECT_EQ(num(t, r, "divisor"), k);
    const int fw = (160 + k - 1) / k, fh = (100 + k - 1) / k;
    EXPECT_EQ(text(t, r, "feedback_px"), std::to_string(fw) + "x" + std::to_string(fh));
    EXPECT_EQ(num(t, r, "readback_bytes"), double(fw) * fh * 8);
    const double found = num(t, r, "tiles_found");
    EXPECT_GE(found, 0.0);
    EXPECT_LE(found, 1.0);
    EXPECT_LE(num(t, r, "tiles_found_min"), found);
    EXPECT_LE(num(t, r, "pixels_full_res"), 1.0);
    // The feedback of a jump is read back frames after it was drawn: never complete at once.
    const double frames = num(t, r, "frames_to_complete");
    EXPECT_TRUE(std::isfinite(frames)) << "1/" << k;
    EXPECT_GE(frames, 2.0) << "1/" << k;
    EXPECT_GT(num(t, r, "vt_cpu_ms"), 0.0);
    EXPECT_GT(num(t, r, "frame_ms"), 0.0);
    EXPECT_GT(num(t, r, "tiles_requested"), 0.0);
    EXPECT_GT(num(t, r, "upload_mb"), 0.0);
  }
  // 1/1 is the yardstick: it finds all it needs, and has its final image by the time it is
  // complete (the image may be final a frame or two before its feedback says so).
  EXPECT_EQ(num(t, 0, "tiles_found"), 1.0);
  EXPECT_EQ(num(t, 0, "pixels_full_res"), 1.0);
  EXPECT_GE(num(t, 0, "frames_to_full_image"), 1.0);
  EXPECT_LE(num(t, 0, "frames_to_full_image"), num(t, 0, "frames_to_complete"));
  EXPECT_EQ(num(t, 0, "psnr_at_complete_db"), INFINITY);
  EXPECT_EQ(text(t, 0, "jumps_full_image"), "5 of 5");
  // Coarser feedback never finds more than a finer one (allowing for a tile a coarse pixel
  // happens to hit on one view), and 1/16 of a 160x100 view misses some of what 1/1 needs.
  for (std::size_t r = 1; r < 5; ++r) {
    EXPECT_LE(num(t, r, "tiles_found"), num(t, r - 1, "tiles_found") + 0.02) << r;
    EXPECT_LE(num(t, r, "pixels_full_res"), num(t, r - 1, "pixels_full_res") + 0.005) << r;
  }
  EXPECT_LT(num(t, 4, "tiles_found"), 1.0);
  EXPECT_LT(num(t, 4, "pixels_full_res"), 1.0);
  // What the fidelity buys: 256 times fewer feedback pixels to reduce.
  EXPECT_GT(num(t, 0, "reduce_ms"), num(t, 4, "reduce_ms"));
  EXPECT_GT(num(t, 0, "tiles_requested"), num(t, 4, "tiles_requested"));
}

TEST_F(AccuracyViews, FilteringTableJudgesEachFilterAgainstTheSupersampledTruth) {
  AccuracyContext ctx = quick_context();
  int said = 0;
  ctx.progress = [&](const std::string&) { ++said; };
  const auto t0 = std::chrono::steady_clock::now();
  auto table = vts::accuracy::filtering_table(ctx);
  const double took = seconds_since(t0);
  ASSERT_TRUE(table.ok()) << table.error().to_string();
  const AccuracyTable& t = *table;
  print(t);
  std::printf("  filtering table: %.1f s\n", took);
  EXPECT_EQ(t.id, "filtering");
  ASSERT_EQ(t.rows.size(), 5u);
  well_formed(t);
  EXPECT_GT(said, 3);
  EXPECT_LT(took, 30.0) << "quick mode must stay quick";

  const char* modes[] = {"bilinear", "trilinear", "anisotropic 2", "anisotropic 4",
                         "anisotropic 8"};
  const int taps[] = {1, 1, 2, 4, 8};
  for (std::size_t r = 0; r < 5; ++r) {
    EXPECT_EQ(text(t, r, "mode"), modes[r]);
    EXPECT_EQ(num(t, r, "max_taps"), taps[r]);
    // A real image against its supersampled truth: close, never identical.
    const double psnr = num(t, r, "psnr_db");
    EXPECT_GT(psnr, 20.0) << modes[r];
    EXPECT_LT(psnr, 60.0) << modes[r];
    EXPECT_GT(num(t, r, "mean_abs"), 0.0) << modes[r];
    EXPECT_GE(num(t, r, "max_abs"), num(t, r, "mean_abs")) << modes[r];
    EXPECT_LE(num(t, r, "max_abs"), 255.0) << modes[r];
    EXPECT_GT(num(t, r, "frame_ms"), 0.0) << modes[r];
    EXPECT_GT(num(t, r, "upload_mb"), 0.0) << modes[r];
  }
  EXPECT_EQ(num(t, 1, "time_vs_trilinear"), 1.0);
  // On the oblique views trilinear blurs along the footprint's short axis; taps along the long
  // one get closer to the truth. Against the 64-sample truth of the oblique view (8 samples along
  // each axis) every doubling of the taps gets closer still; the 16-sample one cannot tell 8 taps
  // from 4.
  for (std::size_t r = 2; r < 5; ++r) {
    EXPECT_GT(num(t, r, "psnr_oblique_db"), num(t, 1, "psnr_oblique_db") + 1.0) << modes[r];
    EXPECT_GT(num(t, r, "psnr_db"), num(t, 1, "psnr_db")) << modes[r];
    EXPECT_GT(num(t, r, "psnr_oblique_64_db"), num(t, r - 1, "psnr_oblique_64_db")) << modes[r];
  }
  EXPECT_GT(num(t, 3, "psnr_oblique_db"), num(t, 2, "psnr_oblique_db"));
  EXPECT_GT(num(t, 4, "psnr_oblique_64_db"), num(t, 1, "psnr_oblique_64_db") + 3.0);
  // Anisotropy samples finer levels: it wants at least the tiles trilinear wants.
  EXPECT_GE(num(t, 4, "tiles_wanted"), num(t, 1, "tiles_wanted"));
  // The plot has a point per mode at (frame ms, PSNR).
  for (std::size_t r = 0; r < 5; ++r) {
    EXPECT_EQ(t.plots[0].series[0].points[r].first, num(t, r, "frame_ms"));
    EXPECT_EQ(t.plots[0].series[0].points[r].second, num(t, r, "psnr_db"));
  }
}

TEST_F(AccuracyViews, MissingArchiveAndBadViewportAreErrors) {
  AccuracyContext ctx = quick_context();
  ctx.archive = *dir_ / "no-such-archive.pmtiles";
  for (auto* table : {&vts::accuracy::feedback_table, &vts::accuracy::filtering_table}) {
    auto r = table(ctx);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("no-such-archive"), std::string::npos) << r.error().message;
  }
  ctx = quick_context();
  ctx.width = 0;
  for (auto* table : {&vts::accuracy::feedback_table, &vts::accuracy::filtering_table}) {
    auto r = table(ctx);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, vts::ErrorCode::invalid_argument) << r.error().message;
  }
}

TEST_F(AccuracyViews, WithoutACurrentGlContextTheTablesRefuseToRun) {
  vts::renderer::GlContext* gl = vts::test::shared_gl_context();
  ASSERT_NE(gl, nullptr);
  vts::renderer::GlContext::release_current();
  ASSERT_FALSE(vts::renderer::GlContext::any_current());
  const AccuracyContext ctx = quick_context();
  auto feedback = vts::accuracy::feedback_table(ctx);
  auto filtering = vts::accuracy::filtering_table(ctx);
  gl->make_current();
  for (auto* r : {&feedback, &filtering}) {
    ASSERT_FALSE(r->ok());
    EXPECT_EQ(r->error().code, vts::ErrorCode::unsupported);
    EXPECT_NE(r->error().message.find("OpenGL"), std::string::npos) << r->error().message;
  }
}

}  // namespace
