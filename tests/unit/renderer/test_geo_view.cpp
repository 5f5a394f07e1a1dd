// The viewer on georeferenced tilesets: the start camera in degrees, the HUD's place, and the
// globe's mapping checked against tiling.hpp's.
#include "vts/renderer/geo_view.hpp"

#include <gtest/gtest.h>

#include "vts/renderer/globe.hpp"
#include "vts/renderer/viewer_controls.hpp"

using namespace vts::renderer;

namespace {

const vts::Geometry kGeo = *vts::Geometry::create(16384, 8192, 256, 4);  // WorldCRS84Quad z 0-6

vts::Georeference crs84() {
  return vts::Georeference{
      vts::Tiling::world_crs84_quad, {-10.5, 35.25, 30.125, 60.1}, {9.8125, 47.675, 4}};
}

}  // namespace

TEST(GeoView, CameraAtPutsThePlaneCentreOnTheTexelOfThePlaceAndTheZoomAtTheLevel) {
  const CameraKey base = default_camera(kGeo, 1280, 720);
  auto k = camera_at(base, vts::Tiling::world_crs84_quad, kGeo, {5, 45}, 4);
  ASSERT_TRUE(k) << k.error().message;
  // 16384 texels per 360 degrees from (-180, 90): u = 185 / 360 * 16384, v = 45 / 360 * 16384.
  EXPECT_NEAR(k->plane.center_u, 185.0 / 360 * 16384, 1e-9);
  EXPECT_NEAR(k->plane.center_v, 2048.0, 1e-9);
  EXPECT_EQ(k->plane.texels_per_pixel, 4.0);  // level 4 of 6: 4 finest texels per pixel
  EXPECT_EQ(k->globe.lon_deg, 5);
  EXPECT_EQ(k->globe.lat_deg, 45);
  EXPECT_EQ(k->globe.tilt, 0);
  const GlobeScene globe(k->globe, kGeo.width(), kGeo.height());
  EXPECT_NEAR(globe.texels_per_pixel(), 4.0, 1e-6);
  // The globe's texel under the screen centre is the plane's: the globe maps the image as the
  // scheme does (x = lon, y = lat over the top half of the square grid).
  auto hit = globe.hit(640, 360, 1280, 720);
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->first, k->plane.center_u, 1e-3);
  EXPECT_NEAR(hit->second, k->plane.center_v, 1e-3);
}

TEST(GeoView, TheGlobeMapsEveryPlaceToTheTexelTilingHppGives) {
  for (const vts::LonLat p : {vts::LonLat{-10.5, 60.1}, vts::LonLat{30.125, 35.25},
                              vts::LonLat{-179, -80}, vts::LonLat{120.3, 12.7}}) {
    const GlobeScene globe(GlobeView{.lon_deg = p.lon, .lat_deg = p.lat, .altitude_m = 1e5},
                           kGeo.width(), kGeo.height());
    const auto t = vts::lonlat_to_texel(vts::Tiling::world_crs84_quad, 256, 6, p);
    auto hit = globe.hit(64, 64, 128, 128);
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->first, t.x, 1e-3) << p.lon << "," << p.lat;
    EXPECT_NEAR(hit->second, t.y, 1e-3) << p.lon << "," << p.lat;
  }
}

TEST(GeoView, StartAtPlaceTakesTheFlagsOrTheGeoreferencesCenterAndNamesWhatIsWrong) {
  const CameraKey base = default_camera(kGeo, 1280, 720);
  CameraKey k = base;
  ASSERT_TRUE(start_at_place(std::nullopt, kGeo, "", -1, k));  // nothing asked: nothing changes
  EXPECT_EQ(k.plane.center_u, base.plane.center_u);
  ASSERT_TRUE(start_at_place(crs84(), kGeo, "", -1, k));  // --level alone or nothing: its center
  ASSERT_TRUE(start_at_place(crs84(), kGeo, "", 4, k));
  EXPECT_NEAR(k.globe.lon_deg, 9.8125, 1e-12);
  EXPECT_EQ(k.plane.texels_per_pixel, 4.0);
  ASSERT_TRUE(start_at_place(crs84(), kGeo, "-3.5,40.25", 6, k));
  EXPECT_EQ(k.globe.lon_deg, -3.5);
  EXPECT_EQ(k.globe.lat_deg, 40.25);
  EXPECT_EQ(k.plane.texels_per_pixel, 1.0);
  for (const char* bad : {"5", "5,", ",5", "a,b", "5,45,1", "nan,3"}) {
    auto s = start_at_place(crs84(), kGeo, bad, -1, k);
    ASSERT_FALSE(s) << bad;
    EXPECT_NE(s.error().message.find("LON,LAT"), std::string::npos) << s.error().message;
  }
  auto outside = start_at_place(crs84(), kGeo, "200,0", -1, k);
  ASSERT_FALSE(outside);
  EXPECT_NE(outside.error().message.find("extent"), std::string::npos);
  auto level = start_at_place(crs84(), kGeo, "0,0", 7, k);
  ASSERT_FALSE(level);
  EXPECT_NE(level.error().message.find("levels 0-6"), std::string::npos);
  auto plain = start_at_place(std::nullopt, kGeo, "0,0", -1, k);
  ASSERT_FALSE(plain);
  EXPECT_NE(plain.error().message.find("not georeferenced"), std::string::npos);
  auto mercator = camera_at(base, vts::Tiling::web_mercator_quad, kGeo, {0, 89}, 0);
  ASSERT_FALSE(mercator);  // beyond 85.0511
}

TEST(GeoView, TheGlobeRefusesWebMercatorByName) {
  EXPECT_TRUE(check_globe_tiling(vts::Tiling::none));
  EXPECT_TRUE(check_globe_tiling(vts::Tiling::world_crs84_quad));
  auto s = check_globe_tiling(vts::Tiling::web_mercator_quad);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("WebMercatorQuad"), std::string::npos);
}

TEST(GeoView, ThePlaneHudShowsTheLongitudeAndLatitudeAtTheScreenCentre) {
  HudNumbers n;
  PlaneView p;
  p.center_u = 185.0 / 360 * 16384;
  p.center_v = 2048;
  EXPECT_EQ(lonlat_text(vts::Tiling::world_crs84_quad, kGeo, p.center_u, p.center_v),
            "lon 5.00000  lat 45.00000");
  n.place = lonlat_text(vts::Tiling::world_crs84_quad, kGeo, p.center_u, p.center_v);
  const auto lines = hud_lines(n, false, p, GlobeView{});
  EXPECT_NE(lines.back().find("lon 5.00000  lat 45.00000"), std::string::npos) << lines.back();
  const auto plain = hud_lines(HudNumbers{}, false, p, GlobeView{});
  EXPECT_EQ(plain.back().find("lon"), std::string::npos) << plain.back();
}

TEST(GeoView, ThePlacesTextIsAtTheCursorWhenThereIsOneElseAtTheCentre) {
  PlaneView p;
  p.center_u = 185.0 / 360 * 16384;
  p.center_v = 2048;
  p.texels_per_pixel = 2;
  const auto t = vts::Tiling::world_crs84_quad;
  EXPECT_EQ(plane_place_text(t, kGeo, p, 200, 100, std::nullopt),
            "lon 5.00000  lat 45.00000 (centre)");
  // 45.5111 texels per degree: 91.0222 pixels at 2 texels per pixel is 4 degrees.
  const double px = 16384.0 / 360 * 4 / 2;
  EXPECT_EQ(plane_place_text(t, kGeo, p, 200, 100, std::pair{100 + px, 50 - px}),
            "lon 9.00000  lat 49.00000 (cursor)");
  p.tilt = 1.4;  // the cursor at the top row looks above the horizon: the centre instead
  EXPECT_EQ(plane_place_text(t, kGeo, p, 200, 100, std::pair{100.0, 0.0}),
            "lon 5.00000  lat 45.00000 (centre)");
}

TEST(GeoView, APathOfPlacesFliesThePlaneOverTheSamePlacesAtTheSameZoom) {
  const CameraKey base = default_camera(kGeo, 1280, 720);
  auto a = camera_at(base, vts::Tiling::world_crs84_quad, kGeo, {5, 45}, 4);
  auto b = camera_at(base, vts::Tiling::world_crs84_quad, kGeo, {-10, 50}, 6);
  ASSERT_TRUE(a && b);
  auto path = CameraPath::parse(R"({"keys": [
      {"frame": 0, "lon": 5, "lat": 45, "altitude_m": )" +
                                    std::to_string(a->globe.altitude_m) +
                                    R"(, "heading": 0.5, "tilt": 0.25},
      {"frame": 10, "lon": -10, "lat": 50, "altitude_m": )" +
                                    std::to_string(b->globe.altitude_m) + "}]}",
                                base);
  ASSERT_TRUE(path) << path.error().message;
  ASSERT_FALSE(path->has_plane());
  const CameraPath plane = plane_path_from_places(*path, vts::Tiling::world_crs84_quad, kGeo);
  ASSERT_TRUE(plane.has_plane());
  const PlaneView v0 = plane.plane_at(0), v1 = plane.plane_at(10);
  EXPECT_NEAR(v0.center_u, a->plane.center_u, 1e-9);
  EXPECT_NEAR(v0.center_v, a->plane.center_v, 1e-9);
  EXPECT_NEAR(v0.texels_per_pixel, 4.0, 1e-5);  // level 4 of 6
  EXPECT_EQ(v0.heading, 0.5);
  EXPECT_EQ(v0.tilt, 0.25);
  EXPECT_NEAR(v1.center_u, b->plane.center_u, 1e-9);
  EXPECT_NEAR(v1.center_v, b->plane.center_v, 1e-9);
  EXPECT_NEAR(v1.texels_per_pixel, 1.0, 1e-5);  // the finest level
  // The globe half of the path is kept.
  EXPECT_EQ(plane.globe_at(10).lon_deg, -10);
}

TEST(GeoView, APathFitsTheSceneOrSaysWhyNot) {
  const CameraKey base = default_camera(kGeo, 1280, 720);
  auto places = CameraPath::parse(R"({"keys": [{"frame": 0, "lon": 5, "lat": 45}]})", base);
  auto plane = CameraPath::parse(R"({"keys": [{"frame": 0, "center": [10, 20]}]})", base);
  ASSERT_TRUE(places && plane);
  CameraPath p = *places;
  EXPECT_EQ(fit_path_to_scene(p, false, vts::Tiling::world_crs84_quad, kGeo), std::nullopt);
  EXPECT_TRUE(p.has_plane());  // flies the plane over the places
  EXPECT_NEAR(p.plane_at(0).center_u, 185.0 / 360 * 16384, 1e-9);
  p = *places;
  auto w = fit_path_to_scene(p, false, vts::Tiling::none, kGeo);  // a plain image: no places
  ASSERT_TRUE(w);
  EXPECT_NE(w->find("only globe fields"), std::string::npos) << *w;
  p = *plane;
  w = fit_path_to_scene(p, true, vts::Tiling::world_crs84_quad, kGeo);
  ASSERT_TRUE(w);
  EXPECT_NE(w->find("only plane fields"), std::string::npos) << *w;
  EXPECT_EQ(fit_path_to_scene(p, false, vts::Tiling::world_crs84_quad, kGeo), std::nullopt);
}
