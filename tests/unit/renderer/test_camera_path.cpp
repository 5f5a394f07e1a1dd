// CameraPath: JSON keyframes for `vts view --camera-path`, parsed and interpolated.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "vts/renderer/camera_path.hpp"
#include "vts/renderer/globe.hpp"

using vts::ErrorCode;
using vts::renderer::CameraKey;
using vts::renderer::CameraPath;
using vts::renderer::GlobeScene;
using vts::renderer::GlobeView;
using vts::renderer::kEarthRadiusM;
using vts::renderer::PresetOptions;

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
  // A camera file from anywhere: nesting is limited as it is parsed.
  EXPECT_NE(parse_error(R"({"keys":[{"frame":0,"x":)" + std::string(100000, '[') +
                        std::string(100000, ']') + "}]}")
                .find("camera path: the document nests objects or arrays deeper than 64 levels"),
            std::string::npos);
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

// ---- "move" and to_json ----------------------------------------------------------------------

TEST(CameraPath, MoveIsParsedPerKeyAndTheFirstKeyIsAlwaysAMove) {
  const CameraPath p = parse_ok(R"({"keys":[
      {"frame":0,"lon":1},
      {"frame":5,"lon":2,"move":false},
      {"frame":6,"lon":30,"move":true},
      {"frame":9}]})");
  ASSERT_EQ(p.keys().size(), 4u);
  EXPECT_TRUE(p.keys()[0].move);
  EXPECT_FALSE(p.keys()[1].move);
  EXPECT_TRUE(p.keys()[2].move);
  EXPECT_FALSE(p.keys()[3].move) << "a move is not carried over to the next key";
  EXPECT_EQ(p.move_frames(), (std::vector<double>{0, 6}));
  EXPECT_TRUE(parse_ok(R"({"keys":[{"frame":3,"move":false}]})").keys()[0].move);

  const std::string m = parse_error(R"({"keys":[{"frame":0},{"frame":1,"move":1}]})");
  EXPECT_NE(m.find("key 1: \"move\" is not true or false"), std::string::npos) << m;
}

TEST(CameraPath, ToJsonWritesMovesAndReadsBackBitForBit) {
  const CameraPath p = parse_ok(R"({"keys":[
      {"frame":0,"center":[100.1,50.7],"texels_per_pixel":0.3,"heading":0.1,"tilt":0.2},
      {"frame":2.5,"center":[3e6,1e-9],"texels_per_pixel":123.456,"fov_y":1.1,"move":true},
      {"frame":7,"center":[0.1,0.2]}]})");
  const std::string text = p.to_json();
  // One key per line; moves marked; plane fields only.
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 5) << text;
  EXPECT_EQ(text.find("\"lon\""), std::string::npos) << text;
  std::size_t moves = 0;
  for (std::size_t at = 0; (at = text.find("\"move\":true", at)) != std::string::npos; ++at)
    ++moves;
  EXPECT_EQ(moves, 2u) << text;

  const CameraPath q = parse_ok(text);
  EXPECT_TRUE(q.has_plane());
  EXPECT_FALSE(q.has_globe());
  ASSERT_EQ(q.keys().size(), p.keys().size());
  for (std::size_t i = 0; i < p.keys().size(); ++i) {
    const CameraKey &a = p.keys()[i], &b = q.keys()[i];
    EXPECT_EQ(a.t, b.t);
    EXPECT_EQ(a.move, b.move);
    EXPECT_EQ(a.plane.center_u, b.plane.center_u);
    EXPECT_EQ(a.plane.center_v, b.plane.center_v);
    EXPECT_EQ(a.plane.texels_per_pixel, b.plane.texels_per_pixel);
    EXPECT_EQ(a.plane.heading, b.plane.heading);
    EXPECT_EQ(a.plane.tilt, b.plane.tilt);
    EXPECT_EQ(a.plane.fov_y, b.plane.fov_y);
  }
  EXPECT_EQ(q.to_json(), text) << "to_json is a fixed point";
}

TEST(CameraPath, ToJsonOfKeysWithoutAKindWritesBoth) {
  CameraKey k;
  k.plane.center_u = 5;
  k.globe.lon_deg = 6;
  const std::string text = CameraPath({k}).to_json();
  EXPECT_NE(text.find("\"center\""), std::string::npos) << text;
  EXPECT_NE(text.find("\"lon\""), std::string::npos) << text;
  EXPECT_NE(text.find("\"move\":true"), std::string::npos) << text;
  const CameraPath q = parse_ok(text);
  EXPECT_TRUE(q.has_plane() && q.has_globe());
  EXPECT_EQ(q.keys()[0].globe.lon_deg, 6);
  EXPECT_EQ(CameraPath({k}, false, true).to_json().find("\"center\""), std::string::npos);
}

// ---- Presets ---------------------------------------------------------------------------------

constexpr double kPi = std::numbers::pi;

PresetOptions options(std::uint64_t w, std::uint64_t h, std::uint64_t seed = 1) {
  PresetOptions o;
  o.image_width = w;
  o.image_height = h;
  o.fps = 30;
  o.duration_s = 20;
  o.seed = seed;
  o.viewport_width = 1280;
  o.viewport_height = 720;
  return o;
}

CameraPath preset_ok(std::string_view name, const PresetOptions& o) {
  auto p = CameraPath::preset(name, o);
  EXPECT_TRUE(p.ok()) << name << ": " << (p.ok() ? "" : p.error().message);
  return p.ok() ? *p : CameraPath({CameraKey{}});
}

std::string preset_error(std::string_view name, const PresetOptions& o) {
  auto p = CameraPath::preset(name, o);
  EXPECT_FALSE(p.ok()) << name;
  if (p.ok()) return {};
  EXPECT_EQ(p.error().code, ErrorCode::invalid_argument);
  return p.error().message;
}

// Ground distance between two (u, v) of a W x H equirectangular image, in finest texels
// (2 pi R / W metres).
double texel_distance(std::pair<double, double> a, std::pair<double, double> b, double w,
                      double h) {
  const double lon1 = a.first / w * 2 * kPi, lon2 = b.first / w * 2 * kPi;
  const double lat1 = (0.5 - a.second / h) * kPi, lat2 = (0.5 - b.second / h) * kPi;
  const double s = std::sin((lat2 - lat1) / 2), t = std::sin((lon2 - lon1) / 2);
  const double angle = 2 * std::asin(std::sqrt(s * s + std::cos(lat1) * std::cos(lat2) * t * t));
  return angle / (2 * kPi) * w;
}

// Texels per pixel at the screen centre of a globe view, across (one pixel right) and along (one
// pixel down) the view direction, from the scene's own hit math.
std::pair<double, double> centre_texels_per_pixel(const GlobeView& v, const PresetOptions& o) {
  const GlobeScene scene(v, o.image_width, o.image_height);
  const double cx = o.viewport_width / 2.0, cy = o.viewport_height / 2.0;
  const auto c = scene.hit(cx, cy, o.viewport_width, o.viewport_height);
  const auto r = scene.hit(cx + 1, cy, o.viewport_width, o.viewport_height);
  const auto d = scene.hit(cx, cy + 1, o.viewport_width, o.viewport_height);
  EXPECT_TRUE(c && r && d) << "the centre ray misses the globe";
  if (!c || !r || !d) return {0, 0};
  const double w = double(o.image_width), h = double(o.image_height);
  return {texel_distance(*c, *r, w, h), texel_distance(*c, *d, w, h)};
}

// Images from a tiny one to a 2^25-wide planet, square and not, powers of two and not.
const std::vector<std::pair<std::uint64_t, std::uint64_t>> kImages = {
    {2048, 1024}, {86400, 43200}, {10752, 9216}, {std::uint64_t{1} << 25, std::uint64_t{1} << 24}};

TEST(CameraPath, PresetNamesAreTheFourBuiltIns) {
  EXPECT_EQ(CameraPath::preset_names(),
            (std::vector<std::string_view>{"flyover", "zoom", "jumps", "pan"}));
}

TEST(CameraPath, EveryPresetIsAValidPathCoveringTheDurationInsideItsSurface) {
  for (auto name : CameraPath::preset_names()) {
    for (auto [w, h] : kImages) {
      for (double duration : {0.5, 20.0, 61.3}) {
        PresetOptions o = options(w, h, 7);
        o.duration_s = duration;
        const CameraPath p = preset_ok(name, o);
        SCOPED_TRACE(std::string(name) + " " + std::to_string(w) + "x" + std::to_string(h) +
                     " for " + std::to_string(duration) + " s");
        const auto& keys = p.keys();
        ASSERT_GE(keys.size(), 2u);
        EXPECT_EQ(p.first_frame(), 0);
        EXPECT_EQ(p.last_frame(), std::ceil(duration * o.fps - 1e-9));
        EXPECT_GE(p.last_frame(), duration * o.fps - 1e-6);
        EXPECT_TRUE(keys[0].move);
        EXPECT_EQ(p.has_plane(), name == "pan");
        EXPECT_EQ(p.has_globe(), name != "pan");
        for (std::size_t i = 1; i < keys.size(); ++i)
          ASSERT_GT(keys[i].t, keys[i - 1].t) << "key " << i;
        // What parse() checks, by a round trip through the JSON form.
        const CameraPath q = parse_ok(p.to_json());
        ASSERT_EQ(q.keys().size(), keys.size());
        for (double f = 0; f <= p.last_frame(); f += 0.37) {
          if (name == "pan") {
            const auto v = p.plane_at(f);
            ASSERT_GE(v.center_u, 0) << f;
            ASSERT_LE(v.center_u, double(w)) << f;
            ASSERT_GE(v.center_v, 0) << f;
            ASSERT_LE(v.center_v, double(h)) << f;
          } else {
            const auto v = p.globe_at(f);
            ASSERT_TRUE(std::isfinite(v.lon_deg)) << f;
            ASSERT_GE(v.lat_deg, -85) << f;
            ASSERT_LE(v.lat_deg, 85) << f;
            ASSERT_GT(v.altitude_m, 0) << f;
            if (name != "flyover") {  // a flyover's longitudes are unwrapped (header)
              ASSERT_GE(v.lon_deg, -180) << f;
              ASSERT_LE(v.lon_deg, 180) << f;
            }
          }
        }
      }
    }
  }
}

TEST(CameraPath, PresetsAreDeterministicForASeedAndDifferAcrossSeeds) {
  for (auto name : CameraPath::preset_names()) {
    const auto o = options(86400, 43200, 11);
    const std::string a = preset_ok(name, o).to_json();
    EXPECT_EQ(preset_ok(name, o).to_json(), a) << name;
    auto o2 = o;
    o2.seed = 12;
    EXPECT_NE(preset_ok(name, o2).to_json(), a) << name;
  }
  // 64 viewers on jumps: 64 different first places.
  std::vector<std::pair<double, double>> firsts;
  for (std::uint64_t seed = 0; seed < 64; ++seed) {
    const auto g = preset_ok("jumps", options(86400, 43200, seed)).keys()[0].globe;
    firsts.emplace_back(g.lon_deg, g.lat_deg);
  }
  std::sort(firsts.begin(), firsts.end());
  EXPECT_EQ(std::unique(firsts.begin(), firsts.end()), firsts.end());
}

TEST(CameraPath, FlyoverHoldsItsAltitudeNearTheFinestLevelAndHeadsAlongItsMotion) {
  for (auto [w, h] : kImages) {
    for (int rows : {480, 720, 1080}) {
      PresetOptions o = options(w, h, 3);
      o.viewport_height = rows;
      o.viewport_width = rows * 16 / 9;
      const CameraPath p = preset_ok("flyover", o);
      SCOPED_TRACE(std::to_string(w) + " wide, " + std::to_string(rows) + " rows");
      const double altitude = p.keys()[0].globe.altitude_m;
      for (const auto& k : p.keys()) {
        ASSERT_EQ(k.globe.altitude_m, altitude);
        ASSERT_GT(k.globe.tilt, 0);
        ASSERT_LE(k.globe.tilt, 0.3);
      }
      for (double f = 0; f <= p.last_frame(); f += 97) {
        const GlobeView v = p.globe_at(f);
        const auto [across, along] = centre_texels_per_pixel(v, o);
        EXPECT_GE(across, 0.5) << f;
        EXPECT_LE(across, 4) << f;
        EXPECT_GE(along, 0.5) << f;
        EXPECT_LE(along, 4) << f;
        // The scene's own zoom figure (given for 1024 rows) agrees.
        const double tpp = GlobeScene(v, w, h).texels_per_pixel() * 1024 / rows;
        EXPECT_NEAR(tpp, 1.5, 0.01) << f;
      }
      // On a coarse image a second of flight spans tens of degrees: the chord checks below need
      // a finer one.
      if (w < 10000) continue;
      // Heading along the motion: the bearing from one key to the next.
      const auto& keys = p.keys();
      for (std::size_t i = 0; i + 1 < keys.size(); i += 7) {
        const auto &a = keys[i].globe, &b = keys[i + 1].globe;
        const double east =
            (b.lon_deg - a.lon_deg) * std::cos((a.lat_deg + b.lat_deg) / 2 * kPi / 180);
        const double north = b.lat_deg - a.lat_deg;
        const double bearing = std::atan2(east, north);
        EXPECT_NEAR(bearing, (a.heading + b.heading) / 2, 0.02) << "key " << i;
      }
      // Steady: the same ground distance every second (half a screen height of 1.5-texel pixels).
      const double per_s = 0.5 * rows * 1.5;
      for (double f = 0; f + o.fps <= p.last_frame(); f += 5 * o.fps) {
        const GlobeView a = p.globe_at(f), b = p.globe_at(f + o.fps);
        const auto uv = [&](const GlobeView& v) {
          return std::pair<double, double>{(v.lon_deg + 180) / 360 * double(w),
                                           (90 - v.lat_deg) / 180 * double(h)};
        };
        EXPECT_NEAR(texel_distance(uv(a), uv(b), double(w), double(h)), per_s, 0.01 * per_s);
      }
    }
  }
}

TEST(CameraPath, ZoomGoesFromOrbitToTheFinestLevelAboveOnePlace) {
  for (auto [w, h] : kImages) {
    const auto o = options(w, h, 5);
    const CameraPath p = preset_ok("zoom", o);
    SCOPED_TRACE(std::to_string(w) + " wide");
    const auto& keys = p.keys();
    ASSERT_EQ(keys.size(), 2u);
    EXPECT_GE(keys[0].globe.altitude_m, 2e7);
    EXPECT_EQ(keys[0].globe.lon_deg, keys[1].globe.lon_deg);
    EXPECT_EQ(keys[0].globe.lat_deg, keys[1].globe.lat_deg);
    // Orbit shows the whole planet: the limb is inside the field of view.
    const double limb = std::asin(kEarthRadiusM / (kEarthRadiusM + keys[0].globe.altitude_m));
    EXPECT_LT(limb, keys[0].globe.fov_y / 2);
    double prev = 1e300;
    for (double f = 0; f <= p.last_frame(); f += 10) {
      const double a = p.globe_at(f).altitude_m;
      EXPECT_LT(a, prev) << f;
      prev = a;
    }
    const auto [across, along] = centre_texels_per_pixel(p.globe_at(p.last_frame()), o);
    EXPECT_NEAR(across, 1.5, 0.05);
    EXPECT_NEAR(along, 1.5, 0.05);
  }
}

TEST(CameraPath, JumpsHoldEachPlaceForTheDwellThenJumpInOneFrame) {
  PresetOptions o = options(86400, 43200, 9);
  o.fps = 30;
  o.dwell_s = 2;
  o.duration_s = 21;
  const CameraPath p = preset_ok("jumps", o);
  const auto& keys = p.keys();
  const auto moves = p.move_frames();
  // 630 frames: places at 0, 60, ..., 600 (the last held to 630).
  ASSERT_EQ(moves.size(), 11u);
  for (std::size_t i = 0; i < moves.size(); ++i) EXPECT_EQ(moves[i], 60.0 * double(i));
  for (std::size_t i = 0; i < keys.size(); ++i) {
    const auto& k = keys[i];
    if (i % 2 == 0) {
      EXPECT_TRUE(k.move) << i;
    } else {
      // The hold: the same place as the landing key before it.
      EXPECT_FALSE(k.move) << i;
      EXPECT_EQ(k.globe.lon_deg, keys[i - 1].globe.lon_deg);
      EXPECT_EQ(k.globe.lat_deg, keys[i - 1].globe.lat_deg);
      if (i + 1 < keys.size()) {
        // The jump: one frame, to another place.
        EXPECT_EQ(keys[i + 1].t, k.t + 1) << i;
        EXPECT_NE(keys[i + 1].globe.lon_deg, k.globe.lon_deg) << i;
      }
    }
  }
  EXPECT_EQ(keys.back().t, 630);
  // Still while held; at the finest level.
  EXPECT_EQ(p.globe_at(10).lon_deg, keys[0].globe.lon_deg);
  EXPECT_EQ(p.globe_at(59).lat_deg, keys[0].globe.lat_deg);
  EXPECT_EQ(p.globe_at(60).lon_deg, keys[2].globe.lon_deg);
  const auto [across, along] = centre_texels_per_pixel(p.globe_at(75), o);
  EXPECT_NEAR(across, 1.5, 0.05);
  EXPECT_NEAR(along, 1.5, 0.05);
}

TEST(CameraPath, PanMovesAtMapScaleAtASteadySpeedAndStaysHalfAScreenInside) {
  for (auto [w, h] : kImages) {
    if (w < 4 * 1280 || h < 4 * 720) continue;  // room for the full speed
    const auto o = options(w, h, 21);
    const CameraPath p = preset_ok("pan", o);
    SCOPED_TRACE(std::to_string(w) + "x" + std::to_string(h));
    const double speed = 0.5 * o.viewport_width / o.fps;  // texels per frame
    const auto& keys = p.keys();
    for (std::size_t i = 0; i < keys.size(); ++i) {
      const auto& v = keys[i].plane;
      EXPECT_EQ(v.texels_per_pixel, 1);
      EXPECT_EQ(v.heading, 0);
      EXPECT_EQ(v.tilt, 0);
      EXPECT_GE(v.center_u, 640 - 1e-6);
      EXPECT_LE(v.center_u, double(w) - 640 + 1e-6);
      EXPECT_GE(v.center_v, 360 - 1e-6);
      EXPECT_LE(v.center_v, double(h) - 360 + 1e-6);
      if (i > 0) {
        const auto& u = keys[i - 1];
        const double dist =
            std::hypot(v.center_u - u.plane.center_u, v.center_v - u.plane.center_v);
        EXPECT_NEAR(dist / (keys[i].t - u.t), speed, 1e-6 * speed) << "key " << i;
      }
    }
  }
  // A small image: the centre stays inside, the speed drops to at most its inner width a second.
  const CameraPath small = preset_ok("pan", options(300, 200, 4));
  for (double f = 0; f <= small.last_frame(); f += 0.5) {
    const auto v = small.plane_at(f);
    ASSERT_GE(v.center_u, 75 - 1e-9);
    ASSERT_LE(v.center_u, 225 + 1e-9);
    ASSERT_GE(v.center_v, 50 - 1e-9);
    ASSERT_LE(v.center_v, 150 + 1e-9);
  }
}

TEST(CameraPath, PresetErrorsNameWhatIsWrong) {
  const auto good = options(2048, 1024);
  std::string m = preset_error("orbit", good);
  EXPECT_NE(m.find("unknown preset \"orbit\""), std::string::npos) << m;
  EXPECT_NE(m.find("flyover, zoom, jumps, pan"), std::string::npos) << m;
  EXPECT_NE(preset_error("", good).find("unknown preset"), std::string::npos);

  auto o = good;
  o.image_width = 0;
  m = preset_error("pan", o);
  EXPECT_NE(m.find("preset \"pan\": the image size 0x1024 is empty"), std::string::npos) << m;
  for (double fps : {0.0, -1.0, std::nan(""), 1e9}) {
    o = good;
    o.fps = fps;
    m = preset_error("flyover", o);
    EXPECT_NE(m.find("fps"), std::string::npos) << m;
  }
  for (double d : {0.0, -5.0, std::numeric_limits<double>::infinity(), 1e7}) {
    o = good;
    o.duration_s = d;
    m = preset_error("zoom", o);
    EXPECT_NE(m.find("duration_s"), std::string::npos) << m;
  }
  o = good;
  o.viewport_height = 0;
  m = preset_error("flyover", o);
  EXPECT_NE(m.find("viewport"), std::string::npos) << m;
  o = good;
  o.dwell_s = 1.0 / 60;
  m = preset_error("jumps", o);
  EXPECT_NE(m.find("dwell_s"), std::string::npos) << m;
  EXPECT_NE(m.find("less than 2 frames"), std::string::npos) << m;
  EXPECT_TRUE(CameraPath::preset("pan", o).ok()) << "only jumps dwell";
}

}  // namespace
