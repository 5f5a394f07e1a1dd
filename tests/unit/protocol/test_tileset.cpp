// TilesetInfo <-> PMTiles JSON metadata: the documented keys, an exact round trip, and clear
// errors (never exceptions) for metadata that is not ours, newer than us, or broken.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "vts/protocol/tileset.hpp"

namespace vts {
namespace {

using nlohmann::json;

TilesetInfo sample_tileset() {
  TilesetInfo info;
  info.geometry = Geometry::create(86400, 43200, 512, 8).value();
  info.name = "Blue \"Marble\" — 2004";
  info.description = "line one\nline two";
  info.color_space = "linear";
  info.downsample = "box-linear";
  info.sparse = true;
  info.generator = "vtstream 0.1.0";
  return info;
}

json metadata() {
  return json::parse(sample_tileset().to_json());
}

Result<TilesetInfo> read(const json& j) {
  return TilesetInfo::from_json(j.dump());
}

void expect_error(const Result<TilesetInfo>& r, ErrorCode code, const std::string& needle) {
  ASSERT_FALSE(r.ok()) << "expected an error mentioning " << needle;
  EXPECT_EQ(r.error().code, code) << r.error().to_string();
  EXPECT_NE(r.error().message.find(needle), std::string::npos) << r.error().to_string();
}

TEST(TilesetInfo, WritesTheDocumentedKeys) {
  const json j = metadata();
  EXPECT_EQ(j["name"], sample_tileset().name);
  EXPECT_EQ(j["description"], sample_tileset().description);
  EXPECT_EQ(j["type"], "baselayer");
  EXPECT_EQ(j["format"], "vts-lossless");
  EXPECT_EQ(j["version"], "1");
  const json& v = j["vtstream"];
  EXPECT_EQ(v["format_version"], 1);
  EXPECT_EQ(v["width"], 86400);
  EXPECT_EQ(v["height"], 43200);
  EXPECT_EQ(v["tile_size"], 512);
  EXPECT_EQ(v["border"], 8);
  EXPECT_EQ(v["max_zoom"], 8);  // 512 * 2^8 = 131072 >= 86400 > 65536
  EXPECT_EQ(v["stored_size"], 528);
  EXPECT_EQ(v["codec"], "lossless");
  EXPECT_EQ(v["pixel_format"], "rgba8");
  EXPECT_EQ(v["color_space"], "linear");
  EXPECT_EQ(v["downsample"], "box-linear");
  EXPECT_EQ(v["sparse"], true);
  EXPECT_EQ(v["checksum"], "xxh3-64");
  EXPECT_EQ(v["payload"], "zstd-skippable-header-v1");
  EXPECT_EQ(v["generator"], "vtstream 0.1.0");
  EXPECT_EQ(v.size(), 15u);
}

TEST(TilesetInfo, RoundTripsThroughJson) {
  const TilesetInfo in = sample_tileset();
  auto out = TilesetInfo::from_json(in.to_json());
  ASSERT_TRUE(out.ok()) << out.error().to_string();
  EXPECT_EQ(out->format_version, 1);
  EXPECT_EQ(out->geometry.width(), 86400u);
  EXPECT_EQ(out->geometry.height(), 43200u);
  EXPECT_EQ(out->geometry.tile_size(), 512u);
  EXPECT_EQ(out->geometry.border(), 8u);
  EXPECT_EQ(out->codec, CodecId::lossless);
  EXPECT_EQ(out->name, in.name);
  EXPECT_EQ(out->description, in.description);
  EXPECT_EQ(out->color_space, in.color_space);
  EXPECT_EQ(out->downsample, in.downsample);
  EXPECT_EQ(out->sparse, in.sparse);
  EXPECT_EQ(out->generator, in.generator);
  // And the defaults survive too, including the bc1 codec's names.
  TilesetInfo bc1;
  bc1.codec = CodecId::bc1;
  const json j = json::parse(bc1.to_json());
  EXPECT_EQ(j["format"], "vts-bc1");
  EXPECT_EQ(j["vtstream"]["pixel_format"], "bc1");
  auto back = TilesetInfo::from_json(bc1.to_json());
  ASSERT_TRUE(back.ok()) << back.error().to_string();
  EXPECT_EQ(back->codec, CodecId::bc1);
  EXPECT_EQ(back->geometry.width(), 1u);
  EXPECT_EQ(back->color_space, "srgb");
  EXPECT_FALSE(back->sparse);
}

// A WorldCRS84Quad tileset of TMS levels 0..3 (our 0..4, 4096 x 2048 texels) over Europe.
TilesetInfo georeferenced_tileset() {
  TilesetInfo info;
  info.geometry = tiling_geometry(Tiling::world_crs84_quad, 3, 256, 4).value();
  info.sparse = true;
  info.georeference = Georeference{Tiling::world_crs84_quad, {-10.5, 35.25, 30, 60}, {10, 47, 2}};
  return info;
}

TEST(TilesetInfo, GeoreferenceRoundTripsUnderItsDocumentedKeys) {
  const TilesetInfo in = georeferenced_tileset();
  const json j = json::parse(in.to_json());
  const json& g = j["vtstream"]["georeference"];
  EXPECT_EQ(g["tiling"], "WorldCRS84Quad");
  EXPECT_EQ(g["crs"], "OGC:CRS84");
  EXPECT_EQ(g["bounds"], json::array({-10.5, 35.25, 30.0, 60.0}));
  EXPECT_EQ(g["center"], json::array({10.0, 47.0, 2}));
  EXPECT_EQ(g.size(), 4u);
  auto out = TilesetInfo::from_json(in.to_json());
  ASSERT_TRUE(out.ok()) << out.error().to_string();
  ASSERT_TRUE(out->georeference.has_value());
  EXPECT_EQ(*out->georeference, *in.georeference);
  // Metadata without the key (every archive written before it existed) is a plain image.
  EXPECT_FALSE(metadata()["vtstream"].contains("georeference"));
  auto plain = TilesetInfo::from_json(sample_tileset().to_json());
  ASSERT_TRUE(plain.ok());
  EXPECT_FALSE(plain->georeference.has_value());
}

TEST(TilesetInfo, RejectsAGeoreferenceThatContradictsItselfOrTheGeometry) {
  auto with = [](auto edit) {
    json j = json::parse(georeferenced_tileset().to_json());
    edit(j["vtstream"]["georeference"]);
    return read(j);
  };
  expect_error(with([](json& g) { g["tiling"] = "GoogleCRS84Quad"; }), ErrorCode::corrupt,
               "vtstream.georeference.tiling");
  expect_error(with([](json& g) { g["tiling"] = "none"; }), ErrorCode::corrupt,
               "vtstream.georeference.tiling");
  expect_error(with([](json& g) { g["crs"] = "EPSG:3857"; }), ErrorCode::corrupt,
               "vtstream.georeference.crs");
  expect_error(with([](json& g) {
                 g["bounds"] = json::array({1, 2, 3});
               }),
               ErrorCode::corrupt, "vtstream.georeference.bounds");
  expect_error(with([](json& g) {
                 g["bounds"] = json::array({170, 0, -170, 10});
               }),
               ErrorCode::corrupt, "antimeridian");
  expect_error(with([](json& g) {
                 g["bounds"] = json::array({0, 10, 20, 10});
               }),
               ErrorCode::corrupt, "empty");
  expect_error(with([](json& g) {
                 g["bounds"] = json::array({-190, 0, 20, 10});
               }),
               ErrorCode::corrupt, "extent");
  expect_error(with([](json& g) {
                 g["center"] = json::array({100, 47, 2});
               }),
               ErrorCode::corrupt, "outside the bounds");
  expect_error(with([](json& g) {
                 g["center"] = json::array({10, 47, 5});
               }),
               ErrorCode::corrupt, "level 5 is not within 0..4");
  expect_error(with([](json& g) {
                 g["center"] = json::array({10, 47, 1.5});
               }),
               ErrorCode::corrupt, "integer");
  expect_error(with([](json& g) { g = "WorldCRS84Quad"; }), ErrorCode::corrupt,
               "vtstream.georeference");
  // A WebMercatorQuad tileset must be square, and stop at 85.05 degrees.
  expect_error(with([](json& g) {
                 g["tiling"] = "WebMercatorQuad";
                 g["crs"] = "EPSG:3857";
               }),
               ErrorCode::corrupt, "square");
  TilesetInfo merc;
  merc.geometry = tiling_geometry(Tiling::web_mercator_quad, 2, 256, 4).value();
  merc.georeference = Georeference{Tiling::web_mercator_quad, {-10, 80, 10, 89}, {0, 82, 0}};
  expect_error(TilesetInfo::from_json(merc.to_json()), ErrorCode::corrupt, "extent");
  // And a plain image cannot claim a scheme.
  TilesetInfo odd = sample_tileset();
  odd.georeference = georeferenced_tileset().georeference;
  expect_error(TilesetInfo::from_json(odd.to_json()), ErrorCode::corrupt, "WorldCRS84Quad");
}

TEST(TilesetInfo, ToJsonNeverThrowsOnInvalidUtf8) {
  TilesetInfo info;
  info.name = std::string("bad \xff\xfe name");
  std::string text;
  ASSERT_NO_THROW(text = info.to_json());
  auto back = TilesetInfo::from_json(text);
  ASSERT_TRUE(back.ok()) << back.error().to_string();
}

TEST(TilesetInfo, RejectsMetadataWithoutAVtstreamObject) {
  auto r = TilesetInfo::from_json(R"({"name":"osm","format":"pbf","type":"baselayer"})");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::unsupported);
  EXPECT_EQ(r.error().message, "not a vtstream archive (metadata has no \"vtstream\" object)");
}

TEST(TilesetInfo, RejectsNewerFormatVersionAsUnsupported) {
  json j = metadata();
  j["vtstream"]["format_version"] = 2;
  expect_error(read(j), ErrorCode::unsupported, "format_version 2");
  j["vtstream"]["format_version"] = 0;
  expect_error(read(j), ErrorCode::corrupt, "format_version");
}

TEST(TilesetInfo, RejectsTextThatIsNotAJsonObject) {
  for (const char* text : {"", "{", "not json", "[1,2,3]", "42", "\"vtstream\"", "null",
                           "{\"vtstream\": 1}", "{\"vtstream\": []}"}) {
    Result<TilesetInfo> r = TilesetInfo::from_json(text);
    ASSERT_FALSE(r.ok()) << text;
    EXPECT_EQ(r.error().code, ErrorCode::corrupt) << text << ": " << r.error().to_string();
  }
}

TEST(TilesetInfo, RejectsGeometryThatGeometryCreateRejects) {
  struct Case {
    const char* key;
    json value;
  };
  for (const Case& c :
       {Case{"tile_size", 300}, Case{"tile_size", 2}, Case{"border", 300}, Case{"width", 0},
        Case{"height", 0}, Case{"width", std::uint64_t(1) << 40}}) {
    json j = metadata();
    j["vtstream"][c.key] = c.value;
    auto r = read(j);
    ASSERT_FALSE(r.ok()) << c.key << "=" << c.value;
    EXPECT_EQ(r.error().code, ErrorCode::corrupt) << r.error().to_string();
    EXPECT_NE(r.error().message.find("geometry"), std::string::npos) << r.error().to_string();
  }
}

TEST(TilesetInfo, RejectsDerivedValuesThatDisagreeWithTheGeometry) {
  json j = metadata();
  j["vtstream"]["max_zoom"] = 7;
  expect_error(read(j), ErrorCode::corrupt, "max_zoom");
  j = metadata();
  j["vtstream"]["stored_size"] = 512;
  expect_error(read(j), ErrorCode::corrupt, "stored_size");
  j = metadata();
  j["vtstream"]["pixel_format"] = "bc1";
  expect_error(read(j), ErrorCode::corrupt, "pixel_format");
  j = metadata();
  j["format"] = "vts-bc1";
  expect_error(read(j), ErrorCode::corrupt, "format");
}

TEST(TilesetInfo, RejectsUnknownCodecChecksumPayloadAndColourSpaceAsUnsupported) {
  const std::pair<const char*, const char*> cases[] = {{"codec", "webp"},
                                                       {"checksum", "crc32"},
                                                       {"payload", "zstd-skippable-header-v2"},
                                                       {"color_space", "display-p3"}};
  for (const auto& [key, value] : cases) {
    json j = metadata();
    j["vtstream"][key] = value;
    expect_error(read(j), ErrorCode::unsupported, value);
  }
}

TEST(TilesetInfo, RejectsWrongTypesNamingTheKey) {
  const json wrong_for_numbers[] = {"256", 256.5, true, nullptr, json::array(), -1};
  for (const char* key :
       {"format_version", "width", "height", "tile_size", "border", "max_zoom", "stored_size"})
    for (const json& bad : wrong_for_numbers) {
      json j = metadata();
      j["vtstream"][key] = bad;
      auto r = read(j);
      ASSERT_FALSE(r.ok()) << key << "=" << bad;
      EXPECT_EQ(r.error().code, ErrorCode::corrupt) << r.error().to_string();
      EXPECT_NE(r.error().message.find(std::string("\"vtstream.") + key + "\""), std::string::npos)
          << r.error().to_string();
    }
  for (const char* key : {"codec", "pixel_format", "color_space", "downsample", "checksum",
                          "payload", "generator", "sparse"}) {
    json j = metadata();
    j["vtstream"][key] = 5;
    expect_error(read(j), ErrorCode::corrupt, std::string("\"vtstream.") + key + "\"");
  }
  for (const char* key : {"name", "description", "format"}) {
    json j = metadata();
    j[key] = json::object();
    expect_error(read(j), ErrorCode::corrupt, std::string("\"") + key + "\"");
  }
}

TEST(TilesetInfo, RejectsMissingKeysNamingTheKey) {
  const json all = metadata();
  for (const auto& [key, value] : all["vtstream"].items()) {
    json j = metadata();
    j["vtstream"].erase(key);
    expect_error(read(j), ErrorCode::corrupt, "\"vtstream." + key + "\" is missing");
  }
}

TEST(TilesetInfo, ToleratesUnknownKeysAndMissingGenericKeys) {
  json j = metadata();
  j["vtstream"]["future_field"] = {{"x", 1}};
  j["attribution"] = "someone";
  j.erase("name");
  j.erase("description");
  j.erase("format");
  j.erase("type");
  auto r = read(j);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  EXPECT_EQ(r->name, "");
  EXPECT_EQ(r->geometry.width(), 86400u);
}

TEST(TilesetInfo, HugeNumbersAreErrorsNotOverflows) {
  json j = metadata();
  j["vtstream"]["tile_size"] = std::uint64_t(1) << 33;  // would truncate to 0 as uint32
  expect_error(read(j), ErrorCode::corrupt, "vtstream.tile_size");
  // Beyond uint64 nlohmann parses as a float: still a clean error.
  auto r = TilesetInfo::from_json(
      R"({"vtstream":{"format_version":1,"width":1e400,"height":1,"tile_size":256,"border":4}})");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::corrupt);
}

}  // namespace
}  // namespace vts
