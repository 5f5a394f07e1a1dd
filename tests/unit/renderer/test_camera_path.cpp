// CameraPath: JSON keyframes for `vts view --camera-path`, parsed and interpolated.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "vts/renderer/camera_path.hpp"

using vts::ErrorCode;
using vts::renderer::CameraKey;
using vts::renderer::CameraPath;

namespace {

CameraPath parse_ok(const std::string& text, const CameraKey& defaults = {}) {
  auto p = CameraPath::parse(text, defaults);
  EXPECT_TRUE(p.ok()) << (p.ok() ? "" : p.error().message);
  return p.ok() ? *p : CameraPath({CameraKey{}});
}

// The error message of a path that must not parse.
std::string parse_error(const std::string& text) {
  auto p = CameraPath::parse(text);
  EXPECT_FALSE(p.ok()) << text;
  if (p.ok()) return {};
  EXPECT_EQ(p.error().code, ErrorCode::invalid_argument);
  return p.error().message;
}

TEST(CameraPath, ParsesPlaneKeys) {
  const CameraPath p = parse_ok(R"({"keys":[
      {"frame":0,"center":[100,50],"texels_per_pixel":8,"heading":0.5,"tilt":0.25},
      {"frame":10,"center":[300,150],"texels_per_pixel":2}]})");
  ASSERT_EQ(p.keys().size(), 2u);
  EXPECT_TRUE(p.has_plane());
  EXPECT_FALSE(p.has_globe());
  EXPECT_EQ(p.keys()[0].t, 0);
  EXPECT_EQ(p.keys()[0].plane.center_u, 100);
  EXPECT_EQ(p.keys()[0].plane.center_v, 50);
  EXPECT_EQ(p.keys()[0].plane.texels_per_pixel, 8);
  EXPECT_EQ(p.keys()[0].plane.heading, 0.5);
  EXPECT_EQ(p.keys()[0].plane.tilt, 0.25);
  // Left-out fields carry over from the previous key.
  EXPECT_EQ(p.keys()[1].plane.heading, 0.5);
  EXPECT_EQ(p.keys()[1].plane.tilt, 0.25);
  EXPECT_EQ(p.first_frame(), 0);
  EXPECT_EQ(p.last_frame(), 10);
}

TEST(CameraPath, ParsesGlobeKeysAndUsesDefaultsForTheFirstKey) {
  CameraKey d;
  d.globe.lon_deg = 7;
  d.globe.lat_deg = 20;
  d.globe.altitude_m = 2e7;
  d.plane.center_u = 1024;
  const CameraPath p = parse_ok(R"({"keys":[
      {"frame":5,"lat":45},
      {"frame":15,"lon":90,"lat":-10,"altitude_m":1000,"heading":1,"tilt":0.5}]})",
                                d);
  EXPECT_TRUE(p.has_globe());
  EXPECT_FALSE(p.has_plane());
  EXPECT_EQ(p.keys()[0].globe.lon_deg, 7);
  EXPECT_EQ(p.keys()[0].globe.lat_deg, 45);
  EXPECT_EQ(p.keys()[0].globe.altitude_m, 2e7);
  EXPECT_EQ(p.keys()[0].plane.center_u, 1024);
  EXPECT_EQ(p.keys()[1].globe.lon_deg, 90);
  EXPECT_EQ(p.keys()[1].globe.heading, 1);
  EXPECT_EQ(p.keys()[1].globe.tilt, 0.5);
}

TEST(CameraPath, InterpolatesPlaneLinearlyAndZoomInLogSpace) {
  const CameraPath p = parse_ok(R"({"keys":[
      {"frame":0,"center":[0,0],"texels_per_pixel":16,"heading":0,"tilt":0},
      {"frame":10,"center":[100,-50],"texels_per_pixel":1,"heading":1,"tilt":1}]})");
  const auto mid = p.plane_at(5);
  EXPECT_DOUBLE_EQ(mid.center_u, 50);
  EXPECT_DOUBLE_EQ(mid.center_v, -25);
  EXPECT_NEAR(mid.texels_per_pixel, 4, 1e-12);  // geometric mean of 16 and 1
  EXPECT_DOUBLE_EQ(mid.heading, 0.5);
  EXPECT_DOUBLE_EQ(mid.tilt, 0.5);
  const auto q = p.plane_at(2.5);
  EXPECT_DOUBLE_EQ(q.center_u, 25);
  EXPECT_NEAR(q.texels_per_pixel, 8, 1e-12);
  // Exactly on keys.
  EXPECT_DOUBLE_EQ(p.plane_at(0).texels_per_pixel, 16);
  EXPECT_DOUBLE_EQ(p.plane_at(10).texels_per_pixel, 1);
}

TEST(CameraPath, InterpolatesGlobeAltitudeInLogSpace) {
  const CameraPath p = parse_ok(R"({"keys":[
      {"frame":0,"lon":-20,"lat":0,"altitude_m":1e7},
      {"frame":4,"lon":20,"lat":40,"altitude_m":1e3}]})");
  const auto mid = p.globe_at(2);
  EXPECT_DOUBLE_EQ(mid.lon_deg, 0);
  EXPECT_DOUBLE_EQ(mid.lat_deg, 20);
  EXPECT_NEAR(mid.altitude_m, 1e5, 1e-6);
  EXPECT_NEAR(p.globe_at(1).altitude_m, 1e6, 1e-6);
}

TEST(CameraPath, ClampsOutsideTheKeys) {
  const CameraPath p = parse_ok(R"({"keys":[
      {"frame":10,"center":[1,2],"texels_per_pixel":3},
      {"frame":20,"center":[5,6],"texels_per_pixel":7},
      {"frame":30,"center":[9,9],"texels_per_pixel":9}]})");
  EXPECT_EQ(p.plane_at(-100).center_u, 1);
  EXPECT_EQ(p.plane_at(0).texels_per_pixel, 3);
  EXPECT_EQ(p.plane_at(30).center_u, 9);
  EXPECT_EQ(p.plane_at(1e9).texels_per_pixel, 9);
  // Between the second and third keys.
  EXPECT_DOUBLE_EQ(p.plane_at(25).center_u, 7);
  EXPECT_DOUBLE_EQ(p.plane_at(25).center_v, 7.5);
}

TEST(CameraPath, OneKeyIsAStillCamera) {
  const CameraPath p = parse_ok(R"({"keys":[{"frame":3,"lon":12,"altitude_m":5e5}]})");
  EXPECT_EQ(p.globe_at(0).lon_deg, 12);
  EXPECT_EQ(p.globe_at(3).altitude_m, 5e5);
  EXPECT_EQ(p.globe_at(100).lon_deg, 12);
}

TEST(CameraPath, ErrorsNameWhatIsWrong) {
  EXPECT_NE(parse_error("{not json").find("not valid JSON"), std::string::npos);
  EXPECT_NE(parse_error("[1,2]").find("not a JSON object"), std::string::npos);
  EXPECT_NE(parse_error("{}").find("no \"keys\""), std::string::npos);
  EXPECT_NE(parse_error(R"({"keys":3})").find("not an array"), std::string::npos);
  EXPECT_NE(parse_error(R"({"keys":[]})").find("empty"), std::string::npos);
  EXPECT_NE(parse_error(R"({"keys":[7]})").find("key 0 is not a JSON object"), std::string::npos);
  EXPECT_NE(parse_error(R"({"keys":[{"center":[1,2]}]})").find("key 0: no \"frame\""),
            std::string::npos);
  std::string m = parse_error(R"({"keys":[{"frame":0},{"frame":"x"}]})");
  EXPECT_NE(m.find("key 1"), std::string::npos) << m;
  EXPECT_NE(m.find("\"frame\" is not a number"), std::string::npos) << m;
  m = parse_error(R"({"keys":[{"frame":0},{"frame":5},{"frame":5}]})");
  EXPECT_NE(m.find("key 2"), std::string::npos) << m;
  EXPECT_NE(m.find("frames must increase"), std::string::npos) << m;
  m = parse_error(R"({"keys":[{"frame":0,"center":[1]}]})");
  EXPECT_NE(m.find("\"center\""), std::string::npos) << m;
  m = parse_error(R"({"keys":[{"frame":0},{"frame":1,"texels_per_pixel":0}]})");
  EXPECT_NE(m.find("key 1: \"texels_per_pixel\" must be > 0"), std::string::npos) << m;
  m = parse_error(R"({"keys":[{"frame":0,"altitude_m":-3}]})");
  EXPECT_NE(m.find("\"altitude_m\""), std::string::npos) << m;
  m = parse_error(R"({"keys":[{"frame":0,"lat":91}]})");
  EXPECT_NE(m.find("\"lat\""), std::string::npos) << m;
  m = parse_error(R"({"keys":[{"frame":0,"tilt":2}]})");
  EXPECT_NE(m.find("\"tilt\""), std::string::npos) << m;
  m = parse_error(R"({"keys":[{"frame":0,"heading":"north"}]})");
  EXPECT_NE(m.find("\"heading\" is not a number"), std::string::npos) << m;
}

}  // namespace
