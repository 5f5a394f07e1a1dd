// TileJSON: what the server writes, the client reads back unchanged; the reader refuses documents
// that are not ours with the URL and the reason; relative tile URLs resolve like a browser's.
#include "vts/protocol/tilejson.hpp"
#include "vts/test/nested_json.hpp"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace vts {
namespace {

using nlohmann::json;

TilesetInfo sample() {
  TilesetInfo info;
  info.geometry = Geometry::create(86400, 43200, 512, 8).value();
  info.codec = CodecId::lossless;
  info.name = "Blue \"Marble\"";
  info.description = "line one\nline two";
  info.sparse = true;
  return info;
}

std::vector<std::uint8_t> bytes(const std::string& s) {
  return {s.begin(), s.end()};
}

Result<TileJson> read(const std::string& doc, const std::string& url = "http://h:1/earth.json") {
  return read_tilejson(bytes(doc), url);
}

void expect_error(const Result<TileJson>& r, ErrorCode code, const std::string& needle) {
  ASSERT_FALSE(r.ok()) << "expected an error mentioning " << needle;
  EXPECT_EQ(r.error().code, code) << r.error().to_string();
  EXPECT_NE(r.error().message.find(needle), std::string::npos) << r.error().to_string();
  EXPECT_NE(r.error().message.find("http://h:1/earth.json"), std::string::npos)
      << "the error names the document: " << r.error().to_string();
}

TEST(TileJson, WhatTheWriterWritesTheReaderReadsBack) {
  const TilesetInfo info = sample();
  const std::string doc =
      write_tilejson({.tileset = "earth",
                      .info = &info,
                      .version = "0123456789abcdef",
                      .tiles_url = "http://h:1/earth@0123456789abcdef/{z}/{x}/{y}",
                      .archive_url = "http://h:1/earth.pmtiles"});
  auto t = read(doc);
  ASSERT_TRUE(t.ok()) << t.error().to_string();
  EXPECT_EQ(t->tiles, "http://h:1/earth@0123456789abcdef/{z}/{x}/{y}");
  EXPECT_EQ(t->version, "0123456789abcdef");
  EXPECT_EQ(t->info.to_json(), info.to_json());
}

TEST(TileJson, TheWriterEmitsTileJson3WithTheVtstreamObject) {
  const TilesetInfo info = sample();
  const std::string doc = write_tilejson({.tileset = "earth",
                                          .info = &info,
                                          .version = "v1",
                                          .tiles_url = "/earth/{z}/{x}/{y}",
                                          .archive_url = "/earth.pmtiles"});
  ASSERT_FALSE(doc.empty());
  EXPECT_EQ(doc.back(), '\n');
  const json j = json::parse(doc);
  EXPECT_EQ(j["tilejson"], "3.0.0");
  EXPECT_EQ(j["name"], "Blue \"Marble\"");
  EXPECT_EQ(j["scheme"], "xyz");
  EXPECT_EQ(j["tiles"], json::array({"/earth/{z}/{x}/{y}"}));
  EXPECT_EQ(j["minzoom"], 0);
  EXPECT_EQ(j["maxzoom"], info.geometry.max_zoom());
  EXPECT_EQ(j["vtstream"]["archive"], "/earth.pmtiles");
  EXPECT_EQ(j["vtstream"]["width"], 86400);
}

TEST(TileJson, AGeoreferencedTilesetHasItsBoundsAndCenterAndReadsBackTheGeoreference) {
  TilesetInfo info;
  info.geometry = tiling_geometry(Tiling::web_mercator_quad, 5, 256, 4).value();
  info.georeference =
      Georeference{Tiling::web_mercator_quad, {2.25, 48.75, 2.5, 49}, {2.3, 48.9, 4}};
  const std::string doc =
      write_tilejson({.tileset = "paris", .info = &info, .tiles_url = "/paris/{z}/{x}/{y}"});
  const json j = json::parse(doc);
  EXPECT_EQ(j["bounds"], json::array({2.25, 48.75, 2.5, 49.0}));
  EXPECT_EQ(j["center"], json::array({2.3, 48.9, 4}));
  EXPECT_EQ(j["minzoom"], 0);
  EXPECT_EQ(j["maxzoom"], 5);
  EXPECT_EQ(j["vtstream"]["georeference"]["tiling"], "WebMercatorQuad");
  auto back = read(doc);
  ASSERT_TRUE(back.ok()) << back.error().to_string();
  ASSERT_TRUE(back->info.georeference.has_value());
  EXPECT_EQ(*back->info.georeference, *info.georeference);
  // A plain image keeps the whole-globe placeholder and has no center.
  const TilesetInfo plain = sample();
  const json p =
      json::parse(write_tilejson({.tileset = "e", .info = &plain, .tiles_url = "/{z}/{x}/{y}"}));
  EXPECT_EQ(p["bounds"], json::array({-180, -90, 180, 90}));
  EXPECT_FALSE(p.contains("center"));
}

TEST(TileJson, AnUnnamedTilesetIsNamedAfterItsTilesetNameAndCarriesNoArchiveKeyWithoutAnArchive) {
  TilesetInfo info = sample();
  info.name.clear();
  const json j = json::parse(write_tilejson(
      {.tileset = "earth", .info = &info, .version = "", .tiles_url = "/t/{z}/{x}/{y}"}));
  EXPECT_EQ(j["name"], "earth");
  EXPECT_FALSE(j["vtstream"].contains("archive"));
}

TEST(TileJson, EveryVtstreamKeyTheWriterKnowsReadsBack) {
  // A georeferenced tileset with a content hash: every key to_json() writes travels.
  TilesetInfo info;
  info.geometry = tiling_geometry(Tiling::world_crs84_quad, 3, 256, 4).value();
  info.georeference = Georeference{Tiling::world_crs84_quad, {-10, 35, 30, 60}, {10, 47.5, 2}};
  info.content_hash = "0123456789abcdef";
  info.color_space = "linear";
  info.downsample = "box";
  info.generator = "other 1.0";
  info.name = "n";
  info.description = "d";
  auto back = read(write_tilejson({.tileset = "n", .info = &info, .tiles_url = "/n/{z}/{x}/{y}"}));
  ASSERT_TRUE(back.ok()) << back.error().to_string();
  EXPECT_EQ(back->info.to_json(), info.to_json());
}

// Archive metadata whose "vtstream" object has keys this build does not know.
std::string metadata_with(const TilesetInfo& info, const std::string& where,
                          const std::string& value_json) {
  std::string meta = info.to_json();
  const std::string key = where == "georeference" ? "\"georeference\":{" : "\"vtstream\":{";
  const std::size_t at = meta.find(key);
  EXPECT_NE(at, std::string::npos) << meta;
  return meta.insert(at + key.size(), "\"future_key\":" + value_json + ",");
}

using test::nested_arrays;

TilesetInfo georeferenced() {
  TilesetInfo info;
  info.geometry = tiling_geometry(Tiling::web_mercator_quad, 5, 256, 4).value();
  info.georeference =
      Georeference{Tiling::web_mercator_quad, {2.25, 48.75, 2.5, 49}, {2.3, 48.9, 4}};
  return info;
}

TEST(TileJson, UnknownVtstreamKeysOfTheArchiveMetadataAreNotCopied) {
  // What an archive's metadata says beyond what this build knows stays in the archive: the
  // TileJSON's "vtstream" object is made from the TilesetInfo read from it.
  for (const char* where : {"vtstream", "georeference"}) {
    SCOPED_TRACE(where);
    const TilesetInfo written = georeferenced();
    auto info = TilesetInfo::from_json(
        metadata_with(written, where, R"({"kept": [[[["somewhere"]]]], "n": 7})"));
    ASSERT_TRUE(info.ok()) << info.error().to_string();
    const std::string doc = write_tilejson({.tileset = "earth",
                                            .info = &*info,
                                            .version = "v",
                                            .tiles_url = "/t/{z}/{x}/{y}",
                                            .archive_url = "/earth.pmtiles"});
    EXPECT_EQ(doc.find("future_key"), std::string::npos) << doc;
    json v = json::parse(doc)["vtstream"];
    EXPECT_EQ(v["archive"], "/earth.pmtiles");
    v.erase("archive");
    EXPECT_EQ(v, json::parse(written.to_json())["vtstream"]);
  }
}

TEST(TileJson, ArchiveMetadataNestedAHundredThousandLevelsIsRefusedByName) {
  // 200 KB, far inside the 16 MiB metadata limit: once read, copying or dumping it recursively
  // (as the TileJSON writer did) overflows the stack. Refused when the archive is opened.
  for (const char* where : {"vtstream", "georeference"}) {
    SCOPED_TRACE(where);
    for (const std::string& deep : {nested_arrays(100000), nested_arrays(65)}) {
      auto info = TilesetInfo::from_json(metadata_with(georeferenced(), where, deep));
      ASSERT_FALSE(info.ok());
      EXPECT_EQ(info.error().code, ErrorCode::corrupt);
      EXPECT_NE(info.error().message.find(
                    "tileset metadata nests objects or arrays deeper than 64 levels"),
                std::string::npos)
          << info.error().to_string();
      EXPECT_NE(info.error().message.find("future_key[]"), std::string::npos)
          << info.error().to_string();
    }
    // As deep as the limit allows is read (and the unknown key ignored).
    const int allowed = std::string(where) == "georeference" ? 61 : 62;
    auto info =
        TilesetInfo::from_json(metadata_with(georeferenced(), where, nested_arrays(allowed)));
    EXPECT_TRUE(info.ok()) << info.error().to_string();
  }
}

TEST(TileJson, RelativeTileUrlsResolveAgainstTheDocumentUrl) {
  const TilesetInfo info = sample();
  const std::string doc =
      write_tilejson({.tileset = "e", .info = &info, .version = "", .tiles_url = "e/{z}/{x}/{y}"});
  auto t = read(doc, "https://cdn.example/a/b/e.json?k=1");
  ASSERT_TRUE(t.ok()) << t.error().to_string();
  EXPECT_EQ(t->tiles, "https://cdn.example/a/b/e/{z}/{x}/{y}");
  EXPECT_EQ(resolve_url("https://cdn.example/a/e.json", "/x/{z}"), "https://cdn.example/x/{z}");
  EXPECT_EQ(resolve_url("https://cdn.example/a/e.json", "//other/{z}"), "https://other/{z}");
  EXPECT_EQ(resolve_url("https://cdn.example/a/e.json", "HTTP://abs/{z}"), "HTTP://abs/{z}");
  EXPECT_EQ(resolve_url("https://cdn.example", "t/{z}"), "https://cdn.example/t/{z}");
}

TEST(TileJson, TheReaderRefusesWhatIsNotTileJson) {
  expect_error(read("not json"), ErrorCode::corrupt, "is not valid JSON");
  expect_error(read("[1, 2]"), ErrorCode::corrupt, "not a JSON object");
  expect_error(read("{}"), ErrorCode::corrupt, "no \"tiles\" array");
  expect_error(read(R"({"tiles": []})"), ErrorCode::corrupt, "no \"tiles\" array");
  expect_error(read(R"({"tiles": [""]})"), ErrorCode::corrupt, "no \"tiles\" array");
  expect_error(read(R"({"tiles": [7]})"), ErrorCode::corrupt, "no \"tiles\" array");
  expect_error(read(R"({"tiles": ["/t/{z}/{x}"]})"), ErrorCode::corrupt, "lacks {y}");
}

TEST(TileJson, TheReaderRefusesDeeplyNestedDocumentsWithoutCrashing) {
  // A hostile server's TileJSON: the reader once copied "vtstream" recursively (SIGSEGV in
  // `vts loadtest`, `warm`, `cache serve`, `view`).
  const TilesetInfo info = georeferenced();
  const json good =
      json::parse(write_tilejson({.tileset = "p", .info = &info, .tiles_url = "/p/{z}/{x}/{y}"}));
  const std::string deep = nested_arrays(100000);
  const std::string vt = good["vtstream"].dump();
  const std::string geo = good["vtstream"]["georeference"].dump();
  const std::string tiles = R"("tiles": ["/p/{z}/{x}/{y}"])";
  const std::string docs[] = {
      // an unknown key of "vtstream"
      "{" + tiles + R"(, "vtstream": {"future_key": )" + deep + "," + vt.substr(1) + "}",
      // inside "georeference"
      "{" + tiles + R"(, "vtstream": )" + vt.substr(0, vt.size() - 1) +
          R"(, "georeference": {"future_key": )" + deep + "," + geo.substr(1) + "}}",
      // "vtstream" itself, and a key of TileJSON's own
      "{" + tiles + R"(, "vtstream": )" + deep + "}",
      "{" + tiles + R"(, "vector_layers": )" + deep + R"(, "vtstream": )" + vt + "}",
      deep,
  };
  for (const std::string& doc : docs) {
    expect_error(read(doc), ErrorCode::corrupt, "nests objects or arrays deeper than 64 levels");
  }
  // The same documents without the deep value are read.
  auto ok = read("{" + tiles + R"(, "vtstream": {"future_key": [[1]],)" + vt.substr(1) + "}");
  ASSERT_TRUE(ok.ok()) << ok.error().to_string();
  EXPECT_EQ(*ok->info.georeference, *info.georeference);
}

TEST(TileJson, TheReaderRefusesTileJsonThatIsNotAVtstreamTileset) {
  expect_error(read(R"({"tiles": ["/t/{z}/{x}/{y}"]})"), ErrorCode::unsupported,
               "not a vtstream tileset");
  expect_error(read(R"({"tiles": ["/t/{z}/{x}/{y}"], "vtstream": 3})"), ErrorCode::unsupported,
               "no \"vtstream\" object");
  auto broken = read(R"({"tiles": ["/t/{z}/{x}/{y}"], "vtstream": {"width": -1}})");
  ASSERT_FALSE(broken.ok());
  EXPECT_NE(broken.error().message.find("http://h:1/earth.json: "), std::string::npos)
      << broken.error().to_string();
}

TEST(TileJson, TheVersionNotCurrentSignalIsAStableHeader) {
  EXPECT_STREQ(kVtsErrorHeader, "Vts-Error");
  EXPECT_EQ(kVersionNotCurrent, "version-not-current");
}

}  // namespace
}  // namespace vts
