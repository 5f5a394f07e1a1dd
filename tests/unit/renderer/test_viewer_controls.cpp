// The viewer's CPU side: default cameras, --scene specs, HUD text, the mouse and key controls fed
// synthetic events, and the camera recorder.
#include "vts/renderer/viewer_controls.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

namespace vts::renderer {
namespace {

namespace fs = std::filesystem;

Geometry geometry(std::uint64_t w, std::uint64_t h) {
  auto g = Geometry::create(w, h, 256, 4);
  EXPECT_TRUE(g.ok());
  return *g;
}

TEST(ViewerDefaults, ThePlaneShowsTheWholeImageAndTheGlobeTheEarthFromOrbit) {
  const CameraKey k = default_camera(geometry(4000, 1000), 800, 400);
  EXPECT_DOUBLE_EQ(k.plane.center_u, 2000);
  EXPECT_DOUBLE_EQ(k.plane.center_v, 500);
  EXPECT_DOUBLE_EQ(k.plane.texels_per_pixel, 5 * 1.05);  // the width limits: 4000 / 800
  EXPECT_DOUBLE_EQ(k.globe.altitude_m, 2e7);
  EXPECT_DOUBLE_EQ(k.globe.lat_deg, 20);
}

class SceneSpec : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("vts-scene-spec-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string file(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  fs::path dir_;
};

TEST_F(SceneSpec, NamesAndFilesSetTheSceneAndTheFilesCamera) {
  bool globe = true;
  CameraKey cam;
  ASSERT_TRUE(parse_scene("plane", globe, cam).ok());
  EXPECT_FALSE(globe);
  ASSERT_TRUE(parse_scene("globe", globe, cam).ok());
  EXPECT_TRUE(globe);

  cam.plane.texels_per_pixel = 3;
  const std::string spec =
      file("s.json", R"({"scene": "plane", "camera": {"center": [10, 20], "heading": 0.5}})");
  ASSERT_TRUE(parse_scene(spec, globe, cam).ok());
  EXPECT_FALSE(globe);
  EXPECT_DOUBLE_EQ(cam.plane.center_u, 10);
  EXPECT_DOUBLE_EQ(cam.plane.center_v, 20);
  EXPECT_DOUBLE_EQ(cam.plane.heading, 0.5);
  EXPECT_DOUBLE_EQ(cam.plane.texels_per_pixel, 3);  // not in the file: kept
}

TEST_F(SceneSpec, ErrorsNameTheSpecAndTheProblem) {
  bool globe = false;
  CameraKey cam;
  auto missing = parse_scene((dir_ / "none.json").string(), globe, cam);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(missing.error().message.find("neither plane, globe nor a readable JSON file"),
            std::string::npos);
  auto bad_scene = parse_scene(file("b.json", R"({"scene": "cube"})"), globe, cam);
  ASSERT_FALSE(bad_scene.ok());
  EXPECT_NE(bad_scene.error().message.find("\"scene\" must be"), std::string::npos);
  auto bad_camera = parse_scene(
      file("c.json", R"({"scene": "globe", "camera": {"altitude_m": -1}})"), globe, cam);
  ASSERT_FALSE(bad_camera.ok());
  EXPECT_NE(bad_camera.error().message.find("\"camera\": "), std::string::npos)
      << bad_camera.error().message;
  EXPECT_EQ(bad_camera.error().message.find("key 0"), std::string::npos);
}

TEST_F(SceneSpec, ADeeplyNestedFileIsRefusedAndUnknownCameraKeysAreIgnored) {
  // The camera object was copied whole, recursively: 100,000 levels overflowed the stack.
  bool globe = false;
  CameraKey cam;
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  auto r =
      parse_scene(file("deep.json",
                       R"({"scene": "plane", "camera": {"center": [1, 2], "note": )" + deep + "}}"),
                  globe, cam);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(r.error().message.find("nests objects or arrays deeper than 64 levels"),
            std::string::npos)
      << r.error().message;
  EXPECT_NE(r.error().message.find("deep.json"), std::string::npos) << r.error().message;
  r = parse_scene(file("n.json", R"({"scene": "plane", "camera": {"center": [1, 2],
                                     "note": [[["a"]]], "frame": 9}})"),
                  globe, cam);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_DOUBLE_EQ(cam.plane.center_u, 1);
}

TEST(HudText, ShowsTheStreamingNumbersTheTextureAndThePlaneCamera) {
  HudNumbers n;
  n.resident = 42;
  n.pending = 3;
  n.uploads = 1.5;
  n.frame_ms = 16.25;
  n.hit_ratio = 0.875;
  n.mip_bias = 0.5;
  n.physical_bytes = 3 << 20;
  n.page_table_bytes = 1 << 19;
  PlaneView p;
  p.center_u = 100.25;
  p.center_v = 50;
  p.texels_per_pixel = 2;
  const auto lines = hud_lines(n, false, p, GlobeView{});
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[0], "resident 42  pending 3  uploads 1.5/frame");
  EXPECT_EQ(lines[1], "hit 87.5%  bias 0.50  16.2 ms/frame");
  EXPECT_EQ(lines[2], "rgba8 slots  physical 3.0 MiB  page table 0.50 MiB");
  EXPECT_EQ(lines[3], "center 100.2, 50.0  2 texels/pixel");
}

TEST(HudText, NamesTheDebugViewTheBc1AtlasAndTheGlobeCamera) {
  HudNumbers n;
  n.debug = "levels";
  n.bc1 = true;
  GlobeView g;
  g.lon_deg = 12.5;
  g.lat_deg = -3;
  g.altitude_m = 1234.4;
  const auto lines = hud_lines(n, true, PlaneView{}, g);
  EXPECT_NE(lines[1].find("  debug levels"), std::string::npos) << lines[1];
  EXPECT_EQ(lines[2].rfind("bc1 (S3TC) slots", 0), 0u) << lines[2];
  EXPECT_EQ(lines[3], "lon 12.5000  lat -3.0000  altitude 1234 m");
}

TEST(HudText, ScalesByWholeStepsWithTheFrameHeight) {
  EXPECT_EQ(hud_scale(100), 1.0f);
  EXPECT_EQ(hud_scale(719), 1.0f);
  EXPECT_EQ(hud_scale(720), 2.0f);
  EXPECT_EQ(hud_scale(1080), 3.0f);
}

CameraKey plane_start() {
  CameraKey k;
  k.plane.center_u = 500;
  k.plane.center_v = 500;
  k.plane.texels_per_pixel = 2;
  return k;
}

TEST(CameraControls, ALeftDragPansThePlaneKeepingTheTexelUnderTheCursor) {
  CameraControls c(false, plane_start(), 1000, 1000);
  const int w = 200, h = 100;
  const auto grabbed = PlaneCamera::from_view(c.plane, w, h).hit(60, 40);
  c.cursor(60, 40, 1.0, w, h);  // the first event only places the cursor
  EXPECT_FALSE(c.touched);
  c.button(CameraControls::Button::left, true, 0, 0);
  c.cursor(90, 30, 1.0, w, h);
  EXPECT_TRUE(c.touched);
  const auto now = PlaneCamera::from_view(c.plane, w, h).hit(90, 30);
  ASSERT_TRUE(grabbed && now);
  EXPECT_NEAR(now->first, grabbed->first, 1e-6);
  EXPECT_NEAR(now->second, grabbed->second, 1e-6);
  EXPECT_NE(c.plane.center_u, 500);
}

TEST(CameraControls, MovingWithoutAButtonOrAfterReleaseLeavesTheCameraAlone) {
  CameraControls c(false, plane_start(), 1000, 1000);
  c.cursor(10, 10, 1.0, 100, 100);
  c.cursor(50, 70, 1.0, 100, 100);
  c.button(CameraControls::Button::left, true, 0, 0);
  c.button(CameraControls::Button::left, false, 0, 0);
  c.cursor(80, 20, 1.0, 100, 100);
  EXPECT_FALSE(c.touched);
  EXPECT_EQ(c.plane.center_u, 500);
  EXPECT_EQ(c.plane.center_v, 500);
}

TEST(CameraControls, ARightDragTurnsAndTiltsWithinLimits) {
  CameraControls c(false, plane_start(), 1000, 1000);
  c.button(CameraControls::Button::right, true, 0, 0);
  c.cursor(100, 1000, 1.0, 100, 100);
  EXPECT_DOUBLE_EQ(c.plane.heading, 0.5);
  EXPECT_DOUBLE_EQ(c.plane.tilt, 1.4);  // clamped
  EXPECT_EQ(c.plane.center_u, 500);
}

TEST(CameraControls, ScrollZoomsAboutTheCursorWithinLimits) {
  CameraControls c(false, plane_start(), 1000, 1000);
  const int w = 200, h = 100;
  c.cursor(30, 20, 1.0, w, h);
  const auto before = PlaneCamera::from_view(c.plane, w, h).hit(30, 20);
  c.scroll(1, 0, 0, 1.0, w, h);  // up: closer
  EXPECT_DOUBLE_EQ(c.plane.texels_per_pixel, 2 / 1.25);
  const auto after = PlaneCamera::from_view(c.plane, w, h).hit(30, 20);
  ASSERT_TRUE(before && after);
  EXPECT_NEAR(after->first, before->first, 1e-6);
  EXPECT_NEAR(after->second, before->second, 1e-6);
  for (int i = 0; i < 200; ++i) c.scroll(-1, 0, 0, 1.0, w, h);
  EXPECT_DOUBLE_EQ(c.plane.texels_per_pixel, 4000);  // 4 x the image's larger side
}

TEST(CameraControls, AGlobeDragOrbitsAndScrollChangesTheAltitude) {
  CameraKey k;
  k.globe.lon_deg = 10;
  k.globe.lat_deg = 0;
  k.globe.altitude_m = 1e6;
  CameraControls c(true, k, 1000, 500);
  c.button(CameraControls::Button::left, true, 50, 50);
  c.cursor(40, 60, 1.0, 100, 100);  // left and down: the ground moves east and north of view
  EXPECT_GT(c.globe_view.lon_deg, 10);
  EXPECT_GT(c.globe_view.lat_deg, 0);
  c.scroll(-1, 0, 0, 1.0, 100, 100);
  EXPECT_DOUBLE_EQ(c.globe_view.altitude_m, 1.25e6);
  EXPECT_EQ(c.plane.center_u, k.plane.center_u);
}

TEST(CameraControls, KeysTurnTiltAskForDebugViewsAndToggleTheHud) {
  CameraControls c(false, plane_start(), 1000, 1000);
  c.key(CameraControls::Key::e, false);
  c.key(CameraControls::Key::e, true);
  EXPECT_DOUBLE_EQ(c.plane.heading, 0.1);
  c.key(CameraControls::Key::q, false);
  EXPECT_DOUBLE_EQ(c.plane.heading, 0.05);
  c.key(CameraControls::Key::f, false);
  EXPECT_DOUBLE_EQ(c.plane.tilt, 0);  // clamped at 0
  c.key(CameraControls::Key::r, false);
  EXPECT_DOUBLE_EQ(c.plane.tilt, 0.05);
  EXPECT_TRUE(c.touched);

  CameraControls d(false, plane_start(), 1000, 1000);
  d.key(CameraControls::Key::three, false);
  ASSERT_TRUE(d.debug_request);
  EXPECT_EQ(*d.debug_request, 2);
  d.key(CameraControls::Key::h, false);
  EXPECT_FALSE(d.show_hud);
  d.key(CameraControls::Key::h, true);  // a held key does not toggle again
  EXPECT_FALSE(d.show_hud);
  d.key(CameraControls::Key::other, false);
  EXPECT_FALSE(d.touched);
}

TEST(CameraRecorder, KeepsKeysWhereTheCameraChangesAndTheEndsOfStillStretches) {
  CameraRecorder r(false);
  EXPECT_TRUE(r.empty());
  PlaneView v;
  for (int f = 0; f <= 4; ++f) r.add(f, v, GlobeView{}, false);  // still for 0..4
  v.center_u = 7;
  r.add(5, v, GlobeView{}, false);
  r.add(6, v, GlobeView{}, true);  // a move, though the camera did not change
  r.add(7, v, GlobeView{}, false);
  const CameraPath p = r.path();
  std::vector<double> frames;
  for (const auto& k : p.keys()) frames.push_back(k.t);
  EXPECT_EQ(frames, (std::vector<double>{0, 4, 5, 6, 7}));
  EXPECT_TRUE(p.keys()[0].move);
  EXPECT_TRUE(p.keys()[3].move);
  EXPECT_TRUE(p.has_plane());
  EXPECT_FALSE(p.has_globe());
  EXPECT_DOUBLE_EQ(p.plane_at(4.5).center_u, 3.5);
}

}  // namespace
}  // namespace vts::renderer
