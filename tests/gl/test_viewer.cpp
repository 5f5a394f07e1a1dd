// The viewer in-process: its headless frame loop on a small archive, the HUD text and the
// screenshot with and without it, the camera report and the recording of the flight.
#include "vts/renderer/viewer.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/builder/synthetic.hpp"

namespace fs = std::filesystem;
using namespace vts::renderer;

namespace {

class ViewerTest : public vts::test::VirtualTextureFixture {
 protected:
  std::unique_ptr<Viewer> make(ViewerOptions o, bool default_view = true) {
    const fs::path path = archive("viewer", 64, 4, vts::SyntheticSpec{600, 400, std::nullopt, 6});
    auto src = vts::client::open_local_archive(path);
    EXPECT_TRUE(src.ok());
    if (!src.ok()) return nullptr;
    auto tiles = vts::client::TileClient::create(std::shared_ptr(std::move(*src)));
    EXPECT_TRUE(tiles.ok());
    if (!tiles.ok()) return nullptr;
    geometry_ = (*tiles)->info().info.geometry;
    o.window.width = 160;
    o.window.height = 100;
    o.window.visible = false;
    o.window.vsync = false;
    if (default_view) o.camera = default_camera(*geometry_, 160, 100);
    auto v = Viewer::create(std::shared_ptr(std::move(*tiles)), *geometry_, std::move(o),
                            [this](const std::string& line) { log_.push_back(line); });
    EXPECT_TRUE(v.ok()) << v.error().to_string();
    return v.ok() ? std::move(*v) : nullptr;
  }
  std::optional<vts::Geometry> geometry_;
  std::vector<std::string> log_;
};

TEST_F(ViewerTest, AHeadlessRunConvergesOnASmallArchiveAndStopsAtTheFirstCompleteFrame) {
  auto v = make(ViewerOptions{});
  ASSERT_TRUE(v);
  auto run = v->run_headless(400, true);
  ASSERT_TRUE(run.ok()) << run.error().to_string();
  ASSERT_TRUE(run->complete_at);
  EXPECT_EQ(run->frames.back().frame, *run->complete_at);
  EXPECT_TRUE(run->frames.back().complete);
  EXPECT_LT(run->frames.size(), 400u);
  EXPECT_TRUE(log_.empty());  // a hidden window without --hud needs no HUD, so no warning
  EXPECT_EQ(magenta(v->texture().read_image()), 0);

  // The HUD text of the run: per-frame averages and the plane camera.
  const auto& lines = v->hud_text();
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(
      lines[0].rfind("resident " + std::to_string(run->frames.back().resident) + "  pending 0", 0),
      0u)
      << lines[0];
  EXPECT_EQ(lines[3].rfind("center 300.0, 200.0", 0), 0u) << lines[3];

  const auto report = nlohmann::json::parse(v->report_json(*run, "src", ""));
  EXPECT_EQ(report["scene"], "plane");
  EXPECT_EQ(report["frames"].size(), run->frames.size());
  EXPECT_EQ(report["complete_at"], *run->complete_at);
  EXPECT_TRUE(report["screenshot"].is_null());
  EXPECT_EQ(report["camera"]["keys"][0]["center"][0], 300.0);
}

TEST_F(ViewerTest, AScreenshotGainsTheHudOnlyWhenAsked) {
  auto plain = make(ViewerOptions{});
  ASSERT_TRUE(plain);
  ASSERT_TRUE(plain->run_headless(400, true).ok());
  auto a = plain->screenshot();
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->rgba, plain->texture().read_image().rgba);
  plain.reset();

  ViewerOptions o;
  o.hud = true;
  auto with_hud = make(o);
  ASSERT_TRUE(with_hud);
  ASSERT_TRUE(with_hud->run_headless(400, true).ok());
  auto b = with_hud->screenshot();
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->width, 160);
  EXPECT_NE(b->rgba, with_hud->texture().read_image().rgba);
  // The HUD's box is in the top-left corner; the bottom-right pixel is the frame's.
  const HudBox box = Hud::measure(with_hud->hud_text(), hud_scale(100));
  ASSERT_GT(box.width, 0);
  const auto frame = with_hud->texture().read_image();
  EXPECT_EQ(std::vector<std::uint8_t>(b->at(159, 99), b->at(159, 99) + 4),
            std::vector<std::uint8_t>(frame.at(159, 99), frame.at(159, 99) + 4));
}

TEST_F(ViewerTest, FollowsACameraPathAndRecordsItFrameForFrame) {
  CameraKey start;
  start.plane.center_u = 300;
  start.plane.center_v = 200;
  start.plane.texels_per_pixel = 2;
  auto path = CameraPath::parse(
      R"({"keys": [{"frame": 0, "center": [100, 100]}, {"frame": 4, "center": [500, 300]}]})",
      start);
  ASSERT_TRUE(path.ok()) << path.error().to_string();
  ViewerOptions o;
  o.camera = start;
  o.path = *path;
  o.record = true;
  auto v = make(o, false);
  ASSERT_TRUE(v);
  EXPECT_FALSE(v->recorded());
  ASSERT_TRUE(v->run_headless(7, false).ok());
  EXPECT_DOUBLE_EQ(v->controls().plane.center_u, 500);
  auto recorded = v->recorded();
  ASSERT_TRUE(recorded);
  for (double f = 0; f <= 6; ++f) {
    EXPECT_DOUBLE_EQ(recorded->plane_at(f).center_u, path->plane_at(f).center_u) << f;
    EXPECT_DOUBLE_EQ(recorded->plane_at(f).center_v, path->plane_at(f).center_v) << f;
  }
  const auto cam = nlohmann::json::parse(v->camera_json());
  EXPECT_EQ(cam["scene"], "plane");
  EXPECT_EQ(cam["debug"], "none");
  EXPECT_EQ(cam["keys"][0]["center"][1], 300.0);
}

TEST_F(ViewerTest, DebugViewNamesRoundTrip) {
  for (DebugView d :
       {DebugView::none, DebugView::levels, DebugView::physical, DebugView::page_table})
    EXPECT_EQ(debug_view_from_name(debug_view_name(d)), d);
  EXPECT_EQ(debug_view_from_name("nonsense"), DebugView::none);
}

}  // namespace

// A georeferenced plane (the scheme set as vts view sets it from the georeference): the HUD's
// camera line ends with the place at the screen centre, then, once the cursor is seen, at the
// cursor. 600 x 400 in 64-texel tiles: levels 0-4, 1024 finest texels per 360 degrees.
TEST_F(ViewerTest, AGeoreferencedPlaneHudShowsThePlaceAtTheCentreThenAtTheCursor) {
  ViewerOptions o;
  o.tiling = vts::Tiling::world_crs84_quad;
  auto v = make(o);
  ASSERT_TRUE(v);
  ASSERT_TRUE(v->run_headless(400, true).ok());
  // The centre, texel (300, 200): lon 300 / 1024 * 360 - 180, lat 90 - 200 / 1024 * 360.
  EXPECT_NE(v->hud_text()[3].find("lon -74.53125  lat 19.68750 (centre)"), std::string::npos)
      << v->hud_text()[3];
  // 32 pixels right of the centre at 4.2 texels per pixel: u = 300 + 134.4.
  v->controls().cursor(112, 50, 1, 160, 100);
  ASSERT_TRUE(v->run_headless(1, false).ok());
  EXPECT_NE(v->hud_text()[3].find("lon -27.28125  lat 19.68750 (cursor)"), std::string::npos)
      << v->hud_text()[3];
}

TEST_F(ViewerTest, TheGlobeRefusesAWebMercatorTilesetBeforeOpeningAWindow) {
  const fs::path path = archive("viewer", 64, 4, vts::SyntheticSpec{600, 400, std::nullopt, 6});
  auto src = vts::client::open_local_archive(path);
  ASSERT_TRUE(src.ok());
  auto tiles = vts::client::TileClient::create(std::shared_ptr(std::move(*src)));
  ASSERT_TRUE(tiles.ok());
  const vts::Geometry geometry = (*tiles)->info().info.geometry;
  ViewerOptions o;
  o.globe = true;
  o.tiling = vts::Tiling::web_mercator_quad;
  o.window.visible = false;
  auto v = Viewer::create(std::shared_ptr(std::move(*tiles)), geometry, std::move(o),
                          [](const std::string&) {});
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.error().code, vts::ErrorCode::unsupported);
  EXPECT_NE(v.error().message.find("WebMercatorQuad"), std::string::npos);
}
