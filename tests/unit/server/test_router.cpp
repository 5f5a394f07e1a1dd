// The router: every route, status and header of docs/PROTOCOL.md, without sockets.
#include "vts/server/router.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "router_internal.hpp"
#include "tile_tag_memo.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/builder.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::int64_t fixed_now() {
  return 1'700'000'000;
}

class Router : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new vts::test::TempDir("vts-router-test");
    build("dense", std::nullopt);
    // Sparse: only tile (0,0) exists at z = 2 (the finest level).
    build("sparse", vts::TexelRect{0, 0, 256, 256});
    build("secret", std::nullopt);
    registry_ = new vts::TilesetRegistry;
    auto s = registry_->load({dir_->path()});
    ASSERT_TRUE(s.ok()) << s.error().to_string();
  }
  static void TearDownTestSuite() {
    delete registry_;
    delete dir_;
  }
  static void build(const std::string& name, std::optional<vts::TexelRect> region) {
    vts::BuildOptions o;
    o.synthetic = vts::SyntheticSpec{600, 300, region, 2};
    o.output = *dir_ / (name + ".pmtiles");
    o.threads = 1;
    o.description = "test " + name;
    auto r = vts::build_synthetic_pyramid(o);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
  }

  void SetUp() override {
    config_.now_unix_seconds = fixed_now;
    vts::TilesetAccess access;
    access.bearer_tokens = {"tok-1", "tok-2"};
    access.hmac_keys = {"key-a"};
    config_.access["secret"] = access;
  }

  vts::HttpResponse get(std::string_view target, vts::HttpMethod method = vts::HttpMethod::get) {
    req_.method = method;
    req_.target = target;
    return vts::route(req_, *registry_, config_);
  }
  static std::shared_ptr<const vts::Tileset> tileset(std::string_view name) {
    return registry_->find(name);
  }

  static inline vts::test::TempDir* dir_ = nullptr;
  static inline vts::TilesetRegistry* registry_ = nullptr;
  vts::RouterConfig config_;
  vts::HttpRequest req_;
};

std::optional<std::string> header(const vts::HttpResponse& r, std::string_view name) {
  std::optional<std::string> found;
  for (const auto& [k, v] : r.headers) {
    if (k == name) {
      EXPECT_FALSE(found.has_value()) << "header " << name << " appears twice";
      found = v;
    }
  }
  return found;
}

void expect_plain_error(const vts::HttpResponse& r, int status) {
  EXPECT_EQ(r.status, status) << r.owned;
  EXPECT_EQ(header(r, "Content-Type"), "text/plain; charset=utf-8");
  ASSERT_FALSE(r.owned.empty());
  EXPECT_EQ(r.owned.back(), '\n');
  EXPECT_EQ(r.content_length, r.owned.size());
  EXPECT_TRUE(r.view.empty());
}

std::string tile_etag(std::span<const std::uint8_t> payload) {
  auto h = vts::parse_tile_header(payload);
  EXPECT_TRUE(h.ok());
  char buf[24];
  std::snprintf(buf, sizeof buf, "\"%016llx\"", static_cast<unsigned long long>(h->checksum));
  return buf;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Tiles

TEST_F(Router, ServesEveryTileAsTheStoredBytes) {
  auto t = tileset("dense");
  const auto& g = t->info.geometry;
  int count = 0;
  for (int z = 0; z <= g.max_zoom(); ++z) {
    for (std::uint32_t y = 0; y < g.tiles_y(z); ++y) {
      for (std::uint32_t x = 0; x < g.tiles_x(z); ++x) {
        const std::string target =
            "/dense/" + std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y);
        auto r = get(target);
        ASSERT_EQ(r.status, 200) << target << ": " << r.owned;
        auto stored = t->reader->get(vts::TileId{static_cast<std::uint8_t>(z), x, y});
        ASSERT_TRUE(stored.ok());
        EXPECT_TRUE(std::equal(r.view.begin(), r.view.end(), stored->begin(), stored->end()));
        EXPECT_NE(r.keep, nullptr);  // holds the bytes read
        EXPECT_EQ(r.content_length, stored->size());
        EXPECT_TRUE(r.owned.empty());
        EXPECT_EQ(r.hold, t);
        EXPECT_EQ(r.route, vts::Route::tile);
        EXPECT_EQ(header(r, "Content-Type"), "application/vnd.vtstream.tile");
        EXPECT_EQ(header(r, "ETag"), tile_etag(*stored));
        EXPECT_EQ(header(r, "Cache-Control"), "public, max-age=3600");
        EXPECT_FALSE(r.head_only);
        ++count;
      }
    }
  }
  EXPECT_EQ(count, 6 + 2 + 1);
}

TEST_F(Router, HeadAnswersWithTheSameHeadersAndLengthButNoBodyToSend) {
  auto g = get("/dense/1/1/0");
  auto h = get("/dense/1/1/0", vts::HttpMethod::head);
  EXPECT_EQ(h.status, 200);
  EXPECT_TRUE(h.head_only);
  EXPECT_EQ(h.headers, g.headers);
  EXPECT_EQ(h.content_length, g.content_length);
}

TEST_F(Router, CacheMaxAgeComesFromTheConfig) {
  config_.max_age_seconds = 42;
  EXPECT_EQ(header(get("/dense/0/0/0"), "Cache-Control"), "public, max-age=42");
}

TEST_F(Router, IfNoneMatchWithTheTileEtagAnswers304WithValidators) {
  const std::string etag = *header(get("/dense/2/1/1"), "ETag");
  for (const std::string& inm : std::vector<std::string>{etag, "W/" + etag, "\"aaaa\", " + etag,
                                                         "\"x\",W/" + etag + " ", "*"}) {
    req_.if_none_match = inm;
    auto r = get("/dense/2/1/1");
    EXPECT_EQ(r.status, 304) << inm;
    EXPECT_EQ(header(r, "ETag"), etag);
    EXPECT_EQ(header(r, "Cache-Control"), "public, max-age=3600");
    EXPECT_EQ(r.content_length, 0u);
    EXPECT_TRUE(r.view.empty());
    EXPECT_TRUE(r.owned.empty());
  }
  for (const std::string& inm :
       std::vector<std::string>{"\"0000000000000000\"", etag.substr(1), "W/x"}) {
    req_.if_none_match = inm;
    EXPECT_EQ(get("/dense/2/1/1").status, 200) << inm;
  }
}

// A tag read once from an archive answers later conditional requests without reading the file
// again: with the file truncated in place behind the server's back, a 304 for a tile whose tag is
// known still comes (a whole old tile confirmed), while anything that must read fails as changed.
TEST_F(Router, AKnownTagAnswers304WithoutReadingTheArchiveAgain) {
  vts::test::TempDir dir("vts-router-memo");
  vts::BuildOptions o;
  o.synthetic = vts::SyntheticSpec{600, 300, std::nullopt, 2};
  o.output = dir.path() / "memo.pmtiles";
  o.threads = 1;
  ASSERT_TRUE(vts::build_synthetic_pyramid(o).ok());
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  auto route = [&](std::string_view target, std::string inm) {
    req_.method = vts::HttpMethod::get;
    req_.target = target;
    req_.if_none_match = inm;
    return vts::route(req_, registry, config_);
  };
  auto first = route("/memo/2/1/1", "\"0000000000000000\"");
  ASSERT_EQ(first.status, 200);
  const std::string etag = *header(first, "ETag");
  const std::string other = *header(route("/memo/2/0/0", ""), "ETag");

  std::filesystem::resize_file(o.output, std::filesystem::file_size(o.output) / 2);
  auto known = route("/memo/2/1/1", etag);
  EXPECT_EQ(known.status, 304) << known.owned;
  EXPECT_EQ(header(known, "ETag"), etag);
  EXPECT_EQ(header(known, "Cache-Control"), "public, max-age=3600");
  EXPECT_EQ(route("/memo/2/0/0", other).status, 304) << "a 200 teaches the tag too";
  EXPECT_EQ(route("/memo/2/1/1", "\"0000000000000000\"").status, 503)
      << "a known tag that does not match still reads the tile, which is now refused";
  EXPECT_EQ(route("/memo/2/1/0", "*").status, 503) << "an unknown tag reads the file";
}

TEST(TileTagMemo, KeepsWhatItLearntAndStaysBounded) {
  vts::http_detail::TileTagMemo memo(/*shard_entries=*/64);
  memo.remember(7, 0xabc);
  EXPECT_EQ(memo.find(7), 0xabcu);
  EXPECT_FALSE(memo.find(8).has_value());
  memo.remember(7, 0xdef);
  EXPECT_EQ(memo.find(7), 0xdefu) << "a later read replaces the tag";
  const std::size_t cap =
      vts::http_detail::TileTagMemo::kShards * vts::http_detail::TileTagMemo::kShardEntries;
  for (std::uint64_t id = 100; id < 100 + 2 * cap; ++id) memo.remember(id, id);
  EXPECT_LE(memo.size(), cap);
  EXPECT_EQ(memo.find(100 + 2 * cap - 1), 100 + 2 * cap - 1) << "the newest tag is kept";
}

TEST_F(Router, VersionedUrlOfTheCurrentArchiveIsImmutable) {
  const std::string v = tileset("dense")->version;
  auto r = get("/dense@" + v + "/2/0/1");
  EXPECT_EQ(r.status, 200);
  EXPECT_EQ(header(r, "Cache-Control"), "public, max-age=31536000, immutable");
  EXPECT_EQ(header(r, "ETag"), header(get("/dense/2/0/1"), "ETag"));
}

TEST_F(Router, VersionedUrlOfAnotherArchiveIs404AndNotCached) {
  auto r = get("/dense@0123456789abcdef/2/0/1");
  expect_plain_error(r, 404);
  EXPECT_EQ(header(r, "Cache-Control"), "no-store");
  EXPECT_NE(r.owned.find("not current"), std::string::npos) << r.owned;
  EXPECT_EQ(header(r, "Vts-Error"), "version-not-current");
  auto other = get("/dense@" + tileset("sparse")->version + "/0/0/0");
  EXPECT_EQ(other.status, 404);
  EXPECT_EQ(header(other, "Vts-Error"), "version-not-current");
}

TEST_F(Router, OnlyAStaleVersionCarriesTheVersionNotCurrentSignal) {
  for (const char* target : {"/dense/3/0/0", "/nosuch/0/0/0", "/dense/0/0/0"}) {
    EXPECT_EQ(header(get(target), "Vts-Error"), std::nullopt) << target;
  }
}

TEST_F(Router, TilesOutsideThePyramidAre404) {
  for (const char* target :
       {"/dense/3/0/0", "/dense/255/0/0", "/dense/4294967295/0/0", "/dense/2/3/0", "/dense/2/0/2",
        "/dense/0/1/0", "/dense/1/0/1", "/dense/1/2/0"}) {
    auto r = get(target);
    expect_plain_error(r, 404);
    EXPECT_EQ(r.route, vts::Route::tile) << target;
  }
}

TEST_F(Router, AbsentTileOfASparseArchiveIs204AndCacheable) {
  ASSERT_TRUE(tileset("sparse")->info.sparse);
  EXPECT_EQ(get("/sparse/2/0/0").status, 200);
  for (const char* target : {"/sparse/2/1/0", "/sparse/2/2/1"}) {
    auto r = get(target);
    EXPECT_EQ(r.status, 204) << target;
    EXPECT_EQ(r.content_length, 0u);
    EXPECT_TRUE(r.owned.empty() && r.view.empty());
    EXPECT_EQ(header(r, "Cache-Control"), "public, max-age=3600");
  }
  EXPECT_EQ(get("/sparse@" + tileset("sparse")->version + "/2/1/1").status, 204);
  EXPECT_EQ(get("/sparse/3/0/0").status, 404);
}

TEST_F(Router, MalformedTargetsAre400WithAPlainMessage) {
  const std::string_view nul_target("/dense/0/0/0\0", 13);
  for (std::string_view target : {std::string_view("/dense/00/0/0"),
                                  std::string_view("/dense/01/0/0"),
                                  std::string_view("/dense/+1/0/0"),
                                  std::string_view("/dense/-1/0/0"),
                                  std::string_view("/dense/1/0/4294967296"),
                                  std::string_view("/dense/1/0/99999999999"),
                                  std::string_view("/dense/a/0/0"),
                                  std::string_view("/dense/0x1/0/0"),
                                  std::string_view("/dense/1e1/0/0"),
                                  std::string_view("/dense/ 1/0/0"),
                                  std::string_view("/dense//0/0"),
                                  std::string_view("/dense/0/0/0/"),
                                  std::string_view("/dense/0/0"),
                                  std::string_view("/dense/0/0/0/0"),
                                  std::string_view("/dense/0"),
                                  std::string_view("//dense/0/0/0"),
                                  std::string_view("/dense/../dense/0/0"),
                                  std::string_view("/./dense/0/0"),
                                  std::string_view("/dense/%2e%2e/0/0"),
                                  std::string_view("/dense/0%2F0/0"),
                                  std::string_view("/dense/%zz/0/0"),
                                  std::string_view("/dense/0/0/%"),
                                  std::string_view("/dense/0/0/%4"),
                                  std::string_view("/dense/%00/0/0"),
                                  std::string_view("/dense\\0\\0\\0"),
                                  nul_target,
                                  std::string_view("/dense/0/0/0\r\nX: y"),
                                  std::string_view("/dense/0/0/\x7f"),
                                  std::string_view("/dense/0/0/0#frag"),
                                  std::string_view("/d\xc3\xa9nse/0/0/0"),
                                  std::string_view("dense/0/0/0"),
                                  std::string_view(""),
                                  std::string_view("http://example.com/dense/0/0/0"),
                                  std::string_view("/dense@/0/0/0"),
                                  std::string_view("/dense/0/0/0?sig=a&sig=b")}) {
    auto r = get(target);
    SCOPED_TRACE(std::string(target));
    expect_plain_error(r, 400);
  }
}

TEST_F(Router, TargetLongerThanTheConfiguredBoundIs414) {
  config_.max_target_bytes = 100;
  expect_plain_error(get("/dense/0/0/0?" + std::string(100, 'a')), 414);
  EXPECT_EQ(get("/dense/0/0/0?" + std::string(80, 'a')).status, 200);
}

TEST_F(Router, OverlongTargetIs414) {
  expect_plain_error(get("/dense/0/0/0?" + std::string(9000, 'a')), 414);
}

TEST_F(Router, PercentEncodedUnreservedCharactersAreDecoded) {
  EXPECT_EQ(get("/d%65nse/0/%30/0").status, 200);
  EXPECT_EQ(get("/d%65nse.json").status, 200);
}

TEST_F(Router, QueryParametersOtherThanSignatureAreIgnored) {
  EXPECT_EQ(get("/dense/0/0/0?foo=bar&x").status, 200);
  EXPECT_EQ(get("/dense/0/0/0?").status, 200);
  EXPECT_EQ(get("/dense.json?callback=x").status, 200);
}

TEST_F(Router, UnknownTilesetAndResourceAre404) {
  expect_plain_error(get("/nope/0/0/0"), 404);
  expect_plain_error(get("/nope.json"), 404);
  expect_plain_error(get("/nope.pmtiles"), 404);
  expect_plain_error(get("/dense"), 404);
  expect_plain_error(get("/favicon.ico"), 404);
  expect_plain_error(get("/.json"), 404);
}

TEST_F(Router, OtherMethodsAre405WithAllow) {
  req_.method_text = "POST";
  auto r = get("/dense/0/0/0", vts::HttpMethod::other);
  expect_plain_error(r, 405);
  EXPECT_EQ(header(r, "Allow"), "GET, HEAD, OPTIONS");
  expect_plain_error(get("/", vts::HttpMethod::other), 405);
}

// ---------------------------------------------------------------------------------------------
// The archive

TEST_F(Router, ServesTheWholeArchiveWithRangeSupport) {
  auto t = tileset("dense");
  auto r = get("/dense.pmtiles");
  EXPECT_EQ(r.status, 200);
  EXPECT_EQ(r.route, vts::Route::archive);
  // The body is the whole archive file, read as it is sent.
  EXPECT_TRUE(r.file_body);
  EXPECT_TRUE(r.view.empty() && r.owned.empty());
  EXPECT_EQ(r.file_offset, 0u);
  EXPECT_EQ(r.content_length, t->reader->size());
  EXPECT_EQ(r.hold, t);
  EXPECT_EQ(header(r, "Accept-Ranges"), "bytes");
  EXPECT_EQ(header(r, "Content-Type"), "application/vnd.pmtiles");
  EXPECT_EQ(header(r, "ETag"), "\"" + t->version + "\"");
  EXPECT_FALSE(header(r, "Content-Range").has_value());

  auto h = get("/dense.pmtiles", vts::HttpMethod::head);
  EXPECT_TRUE(h.head_only);
  EXPECT_EQ(h.content_length, r.content_length);
}

struct RangeCase {
  std::string range;
  int status;
  std::uint64_t first, last;  // for 206
};

TEST_F(Router, RangeRequestsFollowRfc9110) {
  auto t = tileset("dense");
  const std::uint64_t n = t->reader->size();
  const std::string s = std::to_string(n);
  const std::vector<RangeCase> cases = {
      {"bytes=0-0", 206, 0, 0},
      {"bytes=0-126", 206, 0, 126},
      {"bytes=" + std::to_string(n - 1) + "-" + std::to_string(n - 1), 206, n - 1, n - 1},
      {"bytes=" + std::to_string(n - 1) + "-", 206, n - 1, n - 1},
      {"bytes=10-", 206, 10, n - 1},
      {"bytes=-1", 206, n - 1, n - 1},
      {"bytes=-100", 206, n - 100, n - 1},
      {"bytes=-" + std::to_string(n + 1000), 206, 0, n - 1},
      {"bytes=5-99999999999999999999", 206, 5, n - 1},
      {"Bytes = 3 - 4", 206, 3, 4},
      {"bytes=" + s + "-", 416, 0, 0},
      {"bytes=" + s + "-" + std::to_string(n + 5), 416, 0, 0},
      {"bytes=99999999999999999999999-", 416, 0, 0},
      {"bytes=-0", 416, 0, 0},
      {"bytes=5-2", 200, 0, 0},  // last < first: invalid, ignored
      {"bytes=0-1,4-5", 200, 0, 0},
      {"bytes=0-0,-1", 200, 0, 0},
      {"items=0-1", 200, 0, 0},
      {"bytes=abc", 200, 0, 0},
      {"bytes=1", 200, 0, 0},
      {"bytes=-", 200, 0, 0},
      {"bytes=--1", 200, 0, 0},
      {"bytes=+1-2", 200, 0, 0},
      {"bytes", 200, 0, 0},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.range);
    req_.range = c.range;
    auto r = get("/dense.pmtiles");
    ASSERT_EQ(r.status, c.status) << r.owned;
    if (c.status == 206) {
      EXPECT_EQ(header(r, "Content-Range"),
                "bytes " + std::to_string(c.first) + "-" + std::to_string(c.last) + "/" + s);
      EXPECT_TRUE(r.file_body);
      EXPECT_EQ(r.file_offset, c.first);
      EXPECT_EQ(r.content_length, c.last - c.first + 1);
      EXPECT_EQ(header(r, "ETag"), "\"" + t->version + "\"");
    } else if (c.status == 416) {
      expect_plain_error(r, 416);
      EXPECT_EQ(header(r, "Content-Range"), "bytes */" + s);
    } else {
      EXPECT_EQ(r.content_length, n);
      EXPECT_FALSE(header(r, "Content-Range").has_value());
    }
  }
}

TEST_F(Router, IfRangeWithAStaleValidatorServesTheWholeArchive) {
  const std::string etag = "\"" + tileset("dense")->version + "\"";
  req_.range = "bytes=0-9";
  req_.if_range = etag;
  EXPECT_EQ(get("/dense.pmtiles").status, 206);
  req_.if_range = "\"0000000000000000\"";
  EXPECT_EQ(get("/dense.pmtiles").status, 200);
  req_.if_range = "Wed, 21 Oct 2015 07:28:00 GMT";
  EXPECT_EQ(get("/dense.pmtiles").status, 200);
}

TEST_F(Router, HeadOfARangeReportsThePartLength) {
  req_.range = "bytes=0-99";
  auto r = get("/dense.pmtiles", vts::HttpMethod::head);
  EXPECT_EQ(r.status, 206);
  EXPECT_TRUE(r.head_only);
  EXPECT_EQ(r.content_length, 100u);
}

TEST_F(Router, IfNoneMatchOnTheArchiveAnswers304) {
  const std::string weak = "W/\"" + tileset("dense")->version + "\"";
  req_.if_none_match = weak;
  req_.range = "bytes=0-10";
  auto r = get("/dense.pmtiles");
  EXPECT_EQ(r.status, 304);
  EXPECT_EQ(r.content_length, 0u);
  EXPECT_EQ(header(r, "ETag"), "\"" + tileset("dense")->version + "\"");
}

// ---------------------------------------------------------------------------------------------
// TileJSON and the index

TEST_F(Router, TileJsonDescribesTheTilesetWithVersionedUrlsFromTheHost) {
  auto t = tileset("dense");
  req_.host = "tiles.example:8080";
  auto r = get("/dense.json");
  ASSERT_EQ(r.status, 200) << r.owned;
  EXPECT_EQ(r.route, vts::Route::tilejson);
  EXPECT_EQ(header(r, "Content-Type"), "application/json");
  EXPECT_EQ(header(r, "Cache-Control"), "public, max-age=60");
  EXPECT_EQ(r.content_length, r.owned.size());
  const json j = json::parse(r.owned);
  EXPECT_EQ(j["tilejson"], "3.0.0");
  EXPECT_EQ(j["name"], "dense");
  EXPECT_EQ(j["description"], "test dense");
  EXPECT_EQ(j["version"], t->version);
  EXPECT_EQ(j["scheme"], "xyz");
  ASSERT_EQ(j["tiles"].size(), 1u);
  EXPECT_EQ(j["tiles"][0], "http://tiles.example:8080/dense@" + t->version + "/{z}/{x}/{y}");
  EXPECT_EQ(j["minzoom"], 0);
  EXPECT_EQ(j["maxzoom"], 2);
  EXPECT_EQ(j["bounds"], json::parse("[-180,-90,180,90]"));
  const json meta = json::parse(t->reader->metadata_json())["vtstream"];
  json v = j["vtstream"];
  EXPECT_EQ(v["archive"], "http://tiles.example:8080/dense.pmtiles");
  v.erase("archive");
  EXPECT_EQ(v, meta);

  // The advertised URL works.
  EXPECT_EQ(get("/dense@" + t->version + "/2/0/0").status, 200);
}

TEST_F(Router, TileJsonUsesThePublicBaseUrlWhenConfigured) {
  config_.public_base_url = "https://cdn.example/vts/";
  req_.host = "internal:9000";
  const json j = json::parse(get("/dense.json").owned);
  EXPECT_EQ(j["tiles"][0],
            "https://cdn.example/vts/dense@" + tileset("dense")->version + "/{z}/{x}/{y}");
  EXPECT_EQ(j["vtstream"]["archive"], "https://cdn.example/vts/dense.pmtiles");
}

TEST_F(Router, TileJsonWithoutHostUsesRelativeUrls) {
  const json j = json::parse(get("/dense.json").owned);
  EXPECT_EQ(j["tiles"][0], "/dense@" + tileset("dense")->version + "/{z}/{x}/{y}");
  EXPECT_EQ(j["vtstream"]["archive"], "/dense.pmtiles");
}

TEST_F(Router, MalformedHostHeaderIs400) {
  for (const char* host : {"evil.example/x", "a b", "a\r\nX-Injected: 1", "user@host", "h\\x"}) {
    req_.host = host;
    SCOPED_TRACE(host);
    expect_plain_error(get("/dense.json"), 400);
  }
}

TEST_F(Router, IndexListsEveryTilesetSortedAndMarksProtectedOnes) {
  req_.host = "h:1";
  auto r = get("/");
  ASSERT_EQ(r.status, 200);
  EXPECT_EQ(r.route, vts::Route::index);
  EXPECT_EQ(header(r, "Content-Type"), "application/json");
  const json j = json::parse(r.owned);
  ASSERT_TRUE(j.is_array());
  ASSERT_EQ(j.size(), 3u);
  EXPECT_EQ(j[0]["name"], "dense");
  EXPECT_EQ(j[1]["name"], "secret");
  EXPECT_EQ(j[2]["name"], "sparse");
  EXPECT_EQ(j[0]["version"], tileset("dense")->version);
  EXPECT_EQ(j[0]["tilejson"], "http://h:1/dense.json");
  EXPECT_EQ(j[0]["archive"], "http://h:1/dense.pmtiles");
  EXPECT_EQ(j[0]["width"], 600);
  EXPECT_EQ(j[0]["height"], 300);
  EXPECT_EQ(j[0]["max_zoom"], 2);
  EXPECT_EQ(j[0]["codec"], "lossless");
  EXPECT_EQ(j[0]["protected"], false);
  EXPECT_EQ(j[1]["protected"], true);
  EXPECT_TRUE(get("/", vts::HttpMethod::head).head_only);
}

// ---------------------------------------------------------------------------------------------
// CORS

TEST_F(Router, EveryResponseCarriesCorsHeadersIncludingErrors) {
  for (const char* target : {"/dense/0/0/0", "/nope/0/0/0", "/dense/x/0/0", "/", "/dense.json"}) {
    auto r = get(target);
    SCOPED_TRACE(target);
    EXPECT_EQ(header(r, "Access-Control-Allow-Origin"), "*");
    EXPECT_EQ(header(r, "Access-Control-Expose-Headers"), "ETag, Content-Range, Content-Length");
    if (std::string_view(target) == "/") {
      EXPECT_EQ(header(r, "Vary"), "Accept");  // a browser gets the HTML index
    } else {
      EXPECT_FALSE(header(r, "Vary").has_value());
    }
  }
  EXPECT_EQ(header(get("/dense/0/0/0", vts::HttpMethod::other), "Access-Control-Allow-Origin"),
            "*");
}

// ---------------------------------------------------------------------------------------------
// The browser viewer (router_web_page.cpp)

std::string body_text(const vts::HttpResponse& r) {
  if (!r.view.empty())
    return std::string(reinterpret_cast<const char*>(r.view.data()), r.view.size());
  return r.owned;
}

TEST_F(Router, IndexIsHtmlForABrowserAndTheSameJsonOtherwise) {
  const std::string index_json = get("/").owned;
  ASSERT_EQ(nlohmann::json::parse(index_json).size(), 3u);
  req_.accept = "text/html,application/xhtml+xml,application/xml;q=0.9,*/*;q=0.8";
  auto html = get("/");
  EXPECT_EQ(html.status, 200);
  EXPECT_EQ(html.route, vts::Route::viewer);
  EXPECT_EQ(header(html, "Content-Type"), "text/html; charset=utf-8");
  EXPECT_EQ(header(html, "Vary"), "Accept");
  for (const char* name : {"dense", "secret", "sparse"}) {
    EXPECT_NE(html.owned.find("<a href=\"" + std::string(name) + "/\">" + name + "</a>"),
              std::string::npos)
        << html.owned;
  }
  req_.accept = "*/*";
  EXPECT_EQ(get("/").owned, index_json);
  req_.accept = "";
  EXPECT_EQ(get("/").owned, index_json);
}

TEST_F(Router, ViewerPageOfATilesetLinksItsTileJsonAndTheEmbeddedAssets) {
  auto r = get("/dense/");
  EXPECT_EQ(r.status, 200);
  EXPECT_EQ(r.route, vts::Route::viewer);
  EXPECT_EQ(header(r, "Content-Type"), "text/html; charset=utf-8");
  EXPECT_NE(r.owned.find("data-tileset=\"dense\" data-tilejson=\"../dense.json\""),
            std::string::npos);
  EXPECT_EQ(get("/nope/").status, 404);
  EXPECT_EQ(get("/secret/").status, 401);  // a protected tileset's page needs its credentials
  req_.authorization = "Bearer tok-1";
  EXPECT_EQ(get("/secret/").status, 200);
  // Every asset the page names is served with its type, an immutable lifetime and its ETag.
  int assets = 0;
  for (std::size_t at = r.owned.find("../_viewer/"); at != std::string::npos;
       at = r.owned.find("../_viewer/", at + 1)) {
    const std::string url = r.owned.substr(at + 2, r.owned.find('"', at) - at - 2);
    SCOPED_TRACE(url);
    auto a = get(url);
    ++assets;
    EXPECT_EQ(a.status, 200);
    EXPECT_EQ(a.route, vts::Route::viewer);
    EXPECT_GT(body_text(a).size(), 100u);
    EXPECT_EQ(header(a, "Content-Type"),
              url.ends_with(".js") ? "text/javascript; charset=utf-8" : "text/css; charset=utf-8");
    EXPECT_EQ(header(a, "Cache-Control"), "public, max-age=31536000, immutable");
    const auto etag = header(a, "ETag");
    ASSERT_TRUE(etag.has_value());
    EXPECT_NE(url.find("." + etag->substr(1, 16) + "."), std::string::npos);
    req_.if_none_match = *etag;
    auto not_modified = get(url);
    EXPECT_EQ(not_modified.status, 304);
    EXPECT_EQ(not_modified.content_length, 0u);
    req_.if_none_match = "";
  }
  EXPECT_EQ(assets, 4);
  EXPECT_EQ(get("/_viewer/ol.js").status, 404);  // only the hashed names
  EXPECT_EQ(get("/_viewer/").status, 404);
}

// Tileset names are [A-Za-z0-9._-] today; the pages escape them all the same.
TEST(ViewerPage, NamesAreEscapedForHtmlAndUrls) {
  EXPECT_EQ(vts::html_escape("a<b>&\"c'd"), "a&lt;b&gt;&amp;&quot;c&#39;d");
  EXPECT_EQ(vts::router_detail::url_segment("a b/c%d.e-f_g~h\xff"), "a%20b%2Fc%25d.e-f_g~h%FF");
}

TEST_F(Router, ASpecificCorsOriginVariesOnOrigin) {
  config_.cors_origin = "https://app.example";
  auto r = get("/dense/0/0/0");
  EXPECT_EQ(header(r, "Access-Control-Allow-Origin"), "https://app.example");
  EXPECT_EQ(header(r, "Vary"), "Origin");
}

TEST_F(Router, EmptyCorsOriginSendsNoCorsHeaders) {
  config_.cors_origin.clear();
  auto r = get("/dense/0/0/0");
  for (const auto& [k, v] : r.headers) EXPECT_EQ(k.rfind("Access-Control-", 0), std::string::npos);
}

TEST_F(Router, PreflightIsAnswered204WithTheAllowedMethodsAndHeaders) {
  req_.origin = "https://app.example";
  req_.access_control_request_method = "GET";
  auto r = get("/dense/0/0/0", vts::HttpMethod::options);
  EXPECT_EQ(r.status, 204);
  EXPECT_EQ(r.route, vts::Route::preflight);
  EXPECT_EQ(r.content_length, 0u);
  EXPECT_EQ(header(r, "Access-Control-Allow-Origin"), "*");
  EXPECT_EQ(header(r, "Access-Control-Allow-Methods"), "GET, HEAD, OPTIONS");
  EXPECT_EQ(header(r, "Access-Control-Allow-Headers"), "Authorization, If-None-Match, Range");
  EXPECT_EQ(header(r, "Access-Control-Max-Age"), "86400");
}

TEST_F(Router, PlainOptionsListsTheAllowedMethods) {
  for (const char* target : {"*", "/dense/0/0/0", "/"}) {
    auto r = get(target, vts::HttpMethod::options);
    EXPECT_EQ(r.status, 204) << target;
    EXPECT_EQ(header(r, "Allow"), "GET, HEAD, OPTIONS");
  }
}

TEST(UnparsedRequestError, IsAnErrorAsTheRouterGivesOneWithItsCorsHeaders) {
  vts::RouterConfig config;
  config.cors_origin = "https://app.example";
  auto r = vts::unparsed_request_error(431, "request header fields too large", &config);
  EXPECT_EQ(r.status, 431);
  EXPECT_EQ(r.route, vts::Route::error);
  EXPECT_EQ(r.owned, "request header fields too large\n");
  EXPECT_EQ(r.content_length, r.owned.size());
  EXPECT_EQ(header(r, "Content-Type"), "text/plain; charset=utf-8");
  EXPECT_EQ(header(r, "Cache-Control"), "no-store");
  EXPECT_EQ(header(r, "Access-Control-Allow-Origin"), "https://app.example");
  EXPECT_EQ(header(r, "Vary"), "Origin");
  EXPECT_EQ(header(r, "Access-Control-Expose-Headers"), "ETag, Content-Range, Content-Length");
  auto admin = vts::unparsed_request_error(400, "bad request", nullptr);
  EXPECT_EQ(header(admin, "Cache-Control"), "no-store");
  EXPECT_FALSE(header(admin, "Access-Control-Allow-Origin").has_value());
}

// ---------------------------------------------------------------------------------------------
// Access control

TEST_F(Router, ProtectedTilesetWithoutCredentialsIs401) {
  for (const char* target : {"/secret/0/0/0", "/secret.json", "/secret.pmtiles"}) {
    auto r = get(target);
    SCOPED_TRACE(target);
    expect_plain_error(r, 401);
    EXPECT_EQ(header(r, "WWW-Authenticate"), "Bearer realm=\"vtstream\"");
    EXPECT_EQ(header(r, "Cache-Control"), "no-store");
  }
  req_.authorization = "Basic dXNlcjpwYXNz";
  expect_plain_error(get("/secret/0/0/0"), 401);
}

TEST_F(Router, ProtectedTilesetWithAWrongTokenIs403) {
  for (const char* auth : {"Bearer tok-3", "Bearer tok-", "Bearer tok-1x", "Bearer  "}) {
    req_.authorization = auth;
    SCOPED_TRACE(auth);
    auto r = get("/secret/0/0/0");
    EXPECT_EQ(r.status, std::string_view(auth) == "Bearer  " ? 401 : 403);
    EXPECT_TRUE(r.view.empty());
  }
}

TEST_F(Router, ProtectedTilesetWithAValidTokenIsServedPrivately) {
  for (const char* auth : {"Bearer tok-1", "bearer tok-2"}) {
    req_.authorization = auth;
    auto r = get("/secret/1/0/0");
    EXPECT_EQ(r.status, 200) << auth;
    EXPECT_EQ(header(r, "Cache-Control"), "private, max-age=3600");
  }
  auto v = get("/secret@" + tileset("secret")->version + "/1/0/0");
  EXPECT_EQ(header(v, "Cache-Control"), "private, max-age=31536000, immutable");
  EXPECT_EQ(get("/secret.pmtiles").status, 200);
  auto tj = get("/secret.json");
  EXPECT_EQ(tj.status, 200);
  EXPECT_EQ(header(tj, "Cache-Control"), "private, max-age=60");
}

TEST_F(Router, ValidSignedUrlIsServed) {
  const std::int64_t expires = fixed_now() + 60;
  for (const std::string path : {"/secret/2/1/1", "/secret.json", "/secret.pmtiles"}) {  // NOLINT
    const std::string target = path + vts::sign_path(path, expires, "key-a");
    auto r = get(target);
    EXPECT_EQ(r.status, 200) << target << " " << r.owned;
    EXPECT_EQ(header(r, "Cache-Control").value_or("").rfind("private", 0), 0u);
    // Extra parameters do not matter.
    EXPECT_EQ(get(target + "&utm=1").status, 200);
  }
  // Expiring exactly now is still valid.
  EXPECT_EQ(get("/secret/0/0/0" + vts::sign_path("/secret/0/0/0", fixed_now(), "key-a")).status,
            200);
}

TEST_F(Router, SignatureIsLowercaseHexHmacSha256OfPathAndExpires) {
  // Against an independently computed value (Python: hmac.new(key, msg, sha256).hexdigest()).
  EXPECT_EQ(vts::sign_path("/secret/0/0/0", 1700000060, "key-a"),
            "?expires=1700000060&sig="
            "7953600767388df81c97e42831e6caede81277a4dd5cdde2ab24a0514401fa54");
}

TEST_F(Router, ExpiredOrTamperedSignaturesAre403) {
  const std::string path = "/secret/2/1/1";
  const std::string good = vts::sign_path(path, fixed_now() + 60, "key-a");
  const std::string sig = good.substr(good.find("&sig=") + 5);
  const std::vector<std::string> bad = {
      path + vts::sign_path(path, fixed_now() - 1, "key-a"),                  // expired
      path + vts::sign_path(path, fixed_now() + 60, "key-b"),                 // wrong key
      "/secret/2/1/0" + good,                                                 // other path
      path + "?expires=" + std::to_string(fixed_now() + 61) + "&sig=" + sig,  // other expiry
      path + "?expires=" + std::to_string(fixed_now() + 60) + "&sig=" + sig.substr(2),
      path + "?expires=" + std::to_string(fixed_now() + 60) + "&sig=zz" + sig.substr(2),
      path + "?expires=" + std::to_string(fixed_now() + 60),  // no sig
      path + "?sig=" + sig,                                   // no expires
      path + "?expires=-5&sig=" + sig,
  };
  for (const auto& target : bad) {
    auto r = get(target);
    SCOPED_TRACE(target);
    expect_plain_error(r, 403);
  }
  auto expired = get(path + vts::sign_path(path, fixed_now() - 1, "key-a"));
  EXPECT_NE(expired.owned.find("expired"), std::string::npos);
}

TEST_F(Router, SignaturesDoNotOpenPublicTilesetsToAnythingNew) {
  EXPECT_EQ(get("/dense/0/0/0?expires=1&sig=00").status, 200);
}

TEST(RouterDamage, ADamagedTileHeaderAnswers500NamingTheTileAndOtherTilesStillServe) {
  const vts::test::TempDir dir("vts-router-damage");
  vts::BuildOptions o;
  o.synthetic = vts::SyntheticSpec{600, 300};
  o.output = dir / "d.pmtiles";
  o.threads = 1;
  ASSERT_TRUE(vts::build_synthetic_pyramid(o).ok());
  // Overwrite the magic of tile 2/1/0's header frame in the file itself.
  std::uint64_t offset = 0;
  {
    auto reader = vts::archive::Reader::open(o.output);
    ASSERT_TRUE(reader.ok());
    auto entry = (*reader)->find_entry(vts::archive::zxy_to_tile_id(2, 1, 0));
    ASSERT_TRUE(entry.ok());
    offset = (*reader)->header().tile_data_offset + entry->offset;
  }
  {
    std::fstream f(o.output, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(offset));
    f.write("XXXX", 4);
  }
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  vts::RouterConfig config;
  vts::HttpRequest req;
  req.method = vts::HttpMethod::get;
  req.target = "/d/2/1/0";
  auto r = vts::route(req, registry, config);
  expect_plain_error(r, 500);
  EXPECT_NE(r.owned.find("2/1/0"), std::string::npos) << r.owned;
  EXPECT_NE(r.owned.find("damaged"), std::string::npos) << r.owned;
  EXPECT_TRUE(r.view.empty());
  req.target = "/d/2/0/0";
  EXPECT_EQ(vts::route(req, registry, config).status, 200);
}

// ---------------------------------------------------------------------------------------------
// The admin listener

class AdminRouter : public ::testing::Test {
 protected:
  vts::HttpResponse get(std::string_view target, vts::HttpMethod method = vts::HttpMethod::get) {
    req_.method = method;
    req_.target = target;
    return vts::route_admin(req_, state_);
  }
  int metrics_calls_ = 0;
  vts::AdminState state_{.ready = true,
                         .metrics_text =
                             [this] {
                               ++metrics_calls_;
                               return std::string("vts_up 1\n");
                             },
                         .max_target_bytes = 8192};
  vts::HttpRequest req_;
};

TEST_F(AdminRouter, MetricsAreServedAsPrometheusTextAndNeverCached) {
  auto r = get("/metrics");
  EXPECT_EQ(r.status, 200);
  EXPECT_EQ(r.route, vts::Route::admin);
  EXPECT_EQ(r.owned, "vts_up 1\n");
  EXPECT_EQ(r.content_length, r.owned.size());
  EXPECT_EQ(header(r, "Content-Type"), "text/plain; version=0.0.4; charset=utf-8");
  EXPECT_EQ(header(r, "Cache-Control"), "no-store");
  EXPECT_EQ(metrics_calls_, 1);
}

TEST_F(AdminRouter, HealthSaysLoadingWith503UntilReady) {
  state_.ready = false;
  auto loading = get("/health");
  EXPECT_EQ(loading.status, 503);
  EXPECT_EQ(loading.owned, "loading\n");
  EXPECT_EQ(header(loading, "Cache-Control"), "no-store");
  state_.ready = true;
  auto ok = get("/health?probe=1");
  EXPECT_EQ(ok.status, 200);
  EXPECT_EQ(ok.owned, "ok\n");
  EXPECT_EQ(ok.route, vts::Route::admin);
  EXPECT_EQ(metrics_calls_, 0) << "/health must not build the metrics text";
}

TEST_F(AdminRouter, HealthListsTheSkippedArchivesOneLineEach) {
  state_.skipped = [] {
    return std::vector<vts::SkippedArchive>{
        {"/srv/half.pmtiles", vts::make_error(vts::ErrorCode::truncated, "archive is truncated")},
        {"/srv/a\nb.pmtiles", vts::make_error(vts::ErrorCode::invalid_argument, "bad\rname")}};
  };
  auto r = get("/health");
  EXPECT_EQ(r.status, 200) << "skipped archives do not make the server unhealthy";
  EXPECT_EQ(r.owned,
            "ok\n"
            "skipped /srv/half.pmtiles: archive is truncated\n"
            "skipped /srv/a\\x0ab.pmtiles: bad\\x0dname\n");
  EXPECT_EQ(header(r, "Content-Type"), "text/plain; charset=utf-8");
  state_.skipped = [] { return std::vector<vts::SkippedArchive>{}; };
  EXPECT_EQ(get("/health").owned, "ok\n");
}

TEST_F(AdminRouter, HealthSaysDegradedWith503AndTheReasonWhileAProblemIsReported) {
  state_.degraded = "disk cache writes failing";
  auto degraded = get("/health");
  EXPECT_EQ(degraded.status, 503);
  EXPECT_EQ(degraded.owned, "degraded: disk cache writes failing\n");
  EXPECT_EQ(header(degraded, "Cache-Control"), "no-store");
  state_.ready = false;
  EXPECT_EQ(get("/health").owned, "loading\n") << "not serving yet says so first";
  state_.ready = true;
  state_.degraded.clear();
  auto ok = get("/health");
  EXPECT_EQ(ok.status, 200);
  EXPECT_EQ(ok.owned, "ok\n");
}

TEST_F(AdminRouter, HeadAnswersWithTheLengthButNoBodyToSend) {
  auto r = get("/metrics", vts::HttpMethod::head);
  EXPECT_EQ(r.status, 200);
  EXPECT_TRUE(r.head_only);
  EXPECT_EQ(r.content_length, std::string("vts_up 1\n").size());
}

TEST_F(AdminRouter, OtherPathsAre404AndOtherMethods405) {
  for (const char* target : {"/", "/metrics/", "/healthz", "/dense/0/0/0"}) {
    auto r = get(target);
    expect_plain_error(r, 404);
    EXPECT_EQ(r.route, vts::Route::admin) << target;
  }
  for (auto m : {vts::HttpMethod::options, vts::HttpMethod::other}) {
    auto r = get("/metrics", m);
    expect_plain_error(r, 405);
    EXPECT_EQ(header(r, "Allow"), "GET, HEAD");
    EXPECT_EQ(r.route, vts::Route::admin);
  }
  EXPECT_EQ(metrics_calls_, 0);
}

TEST_F(AdminRouter, OptionsWithTheAsteriskTargetIsAMethodNotServedNotABadTarget) {
  auto r = get("*", vts::HttpMethod::options);
  expect_plain_error(r, 405);
  EXPECT_EQ(header(r, "Allow"), "GET, HEAD");
  EXPECT_EQ(header(r, "Cache-Control"), "no-store") << "every admin answer";
  expect_plain_error(get("*"), 400);
}

TEST_F(AdminRouter, TargetsAreCheckedAsOnTheTileListener) {
  state_.max_target_bytes = 64;
  auto long_target = get("/metrics?" + std::string(64, 'a'));
  expect_plain_error(long_target, 414);
  EXPECT_EQ(long_target.route, vts::Route::admin);
  for (const char* target : {"metrics", "http://x/metrics", "/a%2fb", "/a b", ""}) {
    auto r = get(target);
    expect_plain_error(r, 400);
    EXPECT_EQ(r.route, vts::Route::admin) << target;
  }
}

TEST(RouteNames, EveryRouteHasAStableMetricsLabel) {
  EXPECT_STREQ(vts::route_name(vts::Route::admin), "admin");
  EXPECT_STREQ(vts::route_name(vts::Route::tile), "tile");
  EXPECT_STREQ(vts::route_name(vts::Route::error), "error");
  EXPECT_STREQ(vts::route_name(vts::Route::viewer), "viewer");
  EXPECT_EQ(vts::kRouteCount, int(vts::Route::viewer) + 1);
}

// ---------------------------------------------------------------------------------------------
// Georeferenced tilesets: the tile matrix set route and TileJSON's bounds and center

TEST(RouterGeoreference, ServesTheTileMatrixSetOfAGeoreferencedTilesetAnd404ForAPlainOne) {
  const vts::test::TempDir dir("vts-router-geo");
  vts::BuildOptions o;
  o.synthetic = vts::SyntheticSpec{1024, 512};  // WorldCRS84Quad TMS levels 0..1
  o.tiling = vts::Tiling::world_crs84_quad;
  o.bounds = vts::LonLatBounds{-10, 35, 30, 60};
  o.output = dir / "geo.pmtiles";
  o.threads = 1;
  auto built = vts::build_synthetic_pyramid(o);
  ASSERT_TRUE(built.ok()) << built.error().to_string();
  vts::BuildOptions p;
  p.synthetic = vts::SyntheticSpec{600, 300};
  p.output = dir / "plain.pmtiles";
  p.threads = 1;
  ASSERT_TRUE(vts::build_synthetic_pyramid(p).ok());
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  vts::RouterConfig config;
  vts::HttpRequest req;
  req.method = vts::HttpMethod::get;
  req.target = "/geo/tilematrixset.json";
  const vts::HttpResponse r = vts::route(req, registry, config);
  ASSERT_EQ(r.status, 200) << r.owned;
  EXPECT_EQ(r.route, vts::Route::tilejson);
  EXPECT_EQ(header(r, "Content-Type"), "application/json");
  EXPECT_EQ(header(r, "Cache-Control"), "public, max-age=60");
  EXPECT_EQ(header(r, "Access-Control-Allow-Origin"), "*");
  EXPECT_FALSE(header(r, "ETag").has_value());  // as TileJSON
  const json tms = json::parse(r.owned);
  EXPECT_EQ(tms["id"], "WorldCRS84Quad");
  ASSERT_EQ(tms["tileMatrices"].size(), 2u);
  EXPECT_EQ(tms["tileMatrices"][1]["matrixWidth"], 4);
  EXPECT_EQ(tms["tileMatrixSetLimits"][1]["minTileCol"], 1);
  EXPECT_EQ(tms["tileMatrixSetLimits"][1]["maxTileCol"], 2);

  req.target = "/geo.json";
  const json tj = json::parse(vts::route(req, registry, config).owned);
  EXPECT_EQ(tj["bounds"], json::parse("[-10, 35, 30, 60]"));
  EXPECT_EQ(tj["center"], json::parse("[10, 47.5, 2]"));
  EXPECT_EQ(tj["maxzoom"], 2);

  req.target = "/plain/tilematrixset.json";
  const vts::HttpResponse none = vts::route(req, registry, config);
  expect_plain_error(none, 404);
  EXPECT_NE(none.owned.find("not georeferenced"), std::string::npos) << none.owned;
  req.target = "/nosuch/tilematrixset.json";
  expect_plain_error(vts::route(req, registry, config), 404);
  req.method = vts::HttpMethod::head;
  req.target = "/geo/tilematrixset.json";
  const vts::HttpResponse head = vts::route(req, registry, config);
  EXPECT_EQ(head.status, 200);
  EXPECT_TRUE(head.head_only);
  EXPECT_EQ(head.content_length, r.content_length);

  // A protected tileset's tile matrix set needs credentials and is private, as its TileJSON.
  vts::TilesetAccess access;
  access.bearer_tokens = {"tok"};
  config.access["geo"] = access;
  req.method = vts::HttpMethod::get;
  EXPECT_EQ(vts::route(req, registry, config).status, 401);
  req.authorization = "Bearer tok";
  const vts::HttpResponse priv = vts::route(req, registry, config);
  EXPECT_EQ(priv.status, 200);
  EXPECT_EQ(header(priv, "Cache-Control"), "private, max-age=60");
}
