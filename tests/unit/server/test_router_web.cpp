// Web images of tiles (docs/PROTOCOL.md §12) through the router, without sockets: routing,
// ETag / 304, Cache-Control, transparent fillers, TileJSON ?format=, the query rules, and the
// bounded cache with single flight.
#include <gtest/gtest.h>

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include "busy_worker.hpp"
#include "vts/builder/builder.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/server/router.hpp"
#include "vts/server/serve_config.hpp"
#include "vts/test/temp_dir.hpp"
#include "web_tile_cache.hpp"

namespace {

using nlohmann::json;
using vts::http_detail::Flight;
using vts::http_detail::WebTile;
using vts::http_detail::WebTileCache;
using vts::http_detail::WebTilePtr;

class RouterWeb : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new vts::test::TempDir("vts-router-web-test");
    build("dense", std::nullopt);
    build("sparse", vts::TexelRect{0, 0, 256, 256});  // only 2/0/0 at the finest level
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
    o.synthetic = vts::SyntheticSpec{600, 300, region, 2};  // 3 x 2 tiles at z = 2
    o.output = *dir_ / (name + ".pmtiles");
    o.threads = 1;
    auto r = vts::build_synthetic_pyramid(o);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
  }
  void SetUp() override {
    config_.web.cache = std::make_shared<WebTileCache>(std::size_t(8) << 20);
    vts::TilesetAccess access;
    access.bearer_tokens = {"tok"};
    config_.access["secret"] = access;
  }
  // route()'s answer, a plan when it needs work (PendingAnswer).
  vts::HttpResponse plan(std::string_view target) {
    req_.target = target;
    return vts::route(req_, *registry_, config_);
  }
  // The final answer: route()'s, its plan carried out (and waited for) when it has one.
  vts::HttpResponse get(std::string_view target) { return vts::finish_pending_now(plan(target)); }
  static std::string version(std::string_view name) { return registry_->find(name)->version; }

  static inline vts::test::TempDir* dir_ = nullptr;
  static inline vts::TilesetRegistry* registry_ = nullptr;
  vts::RouterConfig config_;
  vts::HttpRequest req_;
};

// The answers finish_pending() hands back, from whichever thread ends the work.
class Answers {
 public:
  std::function<void(vts::HttpResponse)> sink() {
    return [this](vts::HttpResponse r) {
      std::lock_guard lock(m_);
      got_.push_back(std::move(r));
      threads_.push_back(std::this_thread::get_id());
      cv_.notify_all();
    };
  }
  std::size_t count() {
    std::lock_guard lock(m_);
    return got_.size();
  }
  // Waits (30 s at most) for `n` answers; false if they did not come.
  bool wait_for(std::size_t n) {
    std::unique_lock lock(m_);
    return cv_.wait_for(lock, std::chrono::seconds(30), [&] { return got_.size() >= n; });
  }
  vts::HttpResponse at(std::size_t i) {
    std::lock_guard lock(m_);
    return got_.at(i);
  }
  std::thread::id thread(std::size_t i) {
    std::lock_guard lock(m_);
    return threads_.at(i);
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  std::vector<vts::HttpResponse> got_;
  std::vector<std::thread::id> threads_;
};

std::optional<std::string> header_of(const vts::HttpResponse& r, std::string_view name) {
  for (const auto& [k, v] : r.headers)
    if (k == name) return v;
  return std::nullopt;
}
std::string body(const vts::HttpResponse& r) {
  if (!r.owned.empty()) return r.owned;
  return {reinterpret_cast<const char*>(r.view.data()), r.view.size()};
}
vts::TileImage decoded(const vts::HttpResponse& r) {
  auto img = vts::imaging::decode_web_image(r.view);
  EXPECT_TRUE(img.ok()) << img.error().to_string();
  return img.ok() ? *img : vts::TileImage{};
}

TEST_F(RouterWeb, PngIsTheTileContentExactly) {
  for (const char* t : {"0/0/0", "2/0/0", "2/2/1"}) {
    SCOPED_TRACE(t);
    const auto r = get(std::string("/dense/") + t + ".png");
    ASSERT_EQ(r.status, 200) << body(r);
    EXPECT_EQ(header_of(r, "Content-Type"), "image/png");
    auto t0 = registry_->find("dense");
    unsigned z, x, y;
    ASSERT_EQ(std::sscanf(t, "%u/%u/%u", &z, &x, &y), 3);
    const vts::TileId id{std::uint8_t(z), x, y};
    auto payload = t0->reader->get(id);
    ASSERT_TRUE(payload.ok());
    auto stored = vts::decode_tile(*payload);
    ASSERT_TRUE(stored.ok());
    auto want = vts::imaging::tile_content(*stored, t0->info.geometry, id);
    ASSERT_TRUE(want.ok());
    const auto got = decoded(r);
    EXPECT_EQ(got.width, 256u);
    EXPECT_EQ(got.height, 256u);
    EXPECT_TRUE(got.pixels == want->pixels) << "the PNG is not the tile's content";
  }
}

TEST_F(RouterWeb, EveryFormatHasItsTypeAndItsOwnStrongEtag) {
  const auto png = get("/dense/1/0/0.png"), webp = get("/dense/1/0/0.webp"),
             jpg = get("/dense/1/0/0.jpg"), jpeg = get("/dense/1/0/0.jpeg");
  EXPECT_EQ(header_of(webp, "Content-Type"), "image/webp");
  EXPECT_EQ(header_of(jpg, "Content-Type"), "image/jpeg");
  EXPECT_EQ(header_of(jpeg, "ETag"), header_of(jpg, "ETag"));
  const auto tag = *header_of(png, "ETag");
  // "<16 hex>-png4a": the default png_level and row filter (average)
  const std::string level = std::to_string(vts::imaging::WebEncodeOptions{}.png_level) + "a";
  EXPECT_EQ(tag.size(), 1 + 16 + 1 + 3 + level.size() + 1) << tag;
  EXPECT_TRUE(tag.ends_with("-png" + level + "\"")) << tag;
  EXPECT_NE(tag, header_of(webp, "ETag"));
  EXPECT_NE(tag, header_of(jpg, "ETag"));
  EXPECT_NE(tag, header_of(get("/dense/1/1/0.png"), "ETag"));
  // Other encoder settings, another tag (a client's copy is never wrongly current).
  config_.web.encode.png_level = 9;
  config_.web.cache = std::make_shared<WebTileCache>(1 << 20);
  EXPECT_NE(header_of(get("/dense/1/0/0.png"), "ETag"), tag);
}

TEST_F(RouterWeb, IfNoneMatchAnswers304WithoutEncoding) {
  const auto first = get("/dense/2/1/1.webp");
  const auto tag = *header_of(first, "ETag");
  config_.web.cache = std::make_shared<WebTileCache>(1 << 20);  // empty: a 304 must not encode
  req_.if_none_match = tag;
  const auto again = get("/dense/2/1/1.webp");
  EXPECT_EQ(again.status, 304);
  EXPECT_EQ(again.content_length, 0u);
  EXPECT_EQ(header_of(again, "ETag"), tag);
  EXPECT_EQ(config_.web.cache->encodes.load(), 0u);
  req_.if_none_match = "\"0000000000000000-webp90m4\"";
  EXPECT_EQ(get("/dense/2/1/1.webp").status, 200);
}

TEST_F(RouterWeb, CacheControlFollowsTheNativeRules) {
  EXPECT_EQ(header_of(get("/dense/0/0/0.png"), "Cache-Control"), "public, max-age=3600");
  const auto v = get("/dense@" + version("dense") + "/0/0/0.png");
  EXPECT_EQ(v.status, 200);
  EXPECT_EQ(header_of(v, "Cache-Control"), "public, max-age=31536000, immutable");
  const auto stale = get("/dense@" + version("sparse") + "/0/0/0.png");
  EXPECT_EQ(stale.status, 404);
  EXPECT_EQ(header_of(stale, "Vts-Error"), "version-not-current");
  // Protected: credentials checked, answers private.
  EXPECT_EQ(get("/secret/0/0/0.png").status, 401);
  req_.authorization = "Bearer tok";
  EXPECT_EQ(header_of(get("/secret/0/0/0.png"), "Cache-Control"), "private, max-age=3600");
}

TEST_F(RouterWeb, NothingToShowIsATransparentTileAndBeyondTheGridIs404) {
  // 2/3/0: beyond the image's edge (3 x 2 tiles) inside the 4 x 4 XYZ grid; 2/1/0: absent from
  // the sparse archive.
  for (const char* target : {"/dense/2/3/0.png", "/dense/2/0/3.webp", "/sparse/2/1/0.png"}) {
    SCOPED_TRACE(target);
    const auto r = get(target);
    ASSERT_EQ(r.status, 200) << body(r);
    const auto img = decoded(r);
    ASSERT_EQ(img.width, 256u);
    EXPECT_EQ(img.pixels, std::vector<std::uint8_t>(256 * 256 * 4, 0));
    EXPECT_TRUE(header_of(r, "ETag")->starts_with("\"empty-256-"));
  }
  const auto jpg = get("/dense/2/3/3.jpg");
  EXPECT_EQ(jpg.status, 200);
  EXPECT_EQ(header_of(jpg, "Content-Type"), "image/png");  // JPEG has no alpha
  for (const char* target : {"/dense/2/4/0.png", "/dense/2/0/4.png", "/dense/3/0/0.png"}) {
    EXPECT_EQ(get(target).status, 404) << target;
  }
}

TEST_F(RouterWeb, ABadExtensionIs400NamingTheAllowedOnes) {
  for (const char* target : {"/dense/0/0/0.gif", "/dense/0/0/0.", "/dense/0/0/0.png.png"}) {
    const auto r = get(target);
    EXPECT_EQ(r.status, 400) << target;
    EXPECT_NE(body(r).find(".png, .webp or .jpg"), std::string::npos) << body(r);
  }
  EXPECT_EQ(get("/dense/0/0/00.png").status, 400);
}

TEST_F(RouterWeb, WebTileJsonPointsWebMapsAtTheVersionedImages) {
  req_.host = "example.org";
  const auto r = get("/dense.json?format=webp");
  ASSERT_EQ(r.status, 200) << body(r);
  const json j = json::parse(body(r));
  EXPECT_EQ(j["tiles"][0], "http://example.org/dense@" + version("dense") + "/{z}/{x}/{y}.webp");
  EXPECT_EQ(j["tileSize"], 256);
  EXPECT_EQ(j["scheme"], "xyz");
  EXPECT_EQ(j["minzoom"], 0);
  EXPECT_EQ(j["maxzoom"], 2);
  EXPECT_FALSE(j.contains("vtstream"));
  // 600 x 300 of a 1024-texel world: east at -180 + 360 * 600 / 1024.
  EXPECT_DOUBLE_EQ(j["bounds"][2].get<double>(), -180.0 + 360.0 * 600.0 / 1024.0);
  EXPECT_EQ(j["center"].size(), 3u);
  const auto native = json::parse(body(get("/dense.json")));
  EXPECT_TRUE(native.contains("vtstream"));  // the plain TileJSON is unchanged
}

TEST_F(RouterWeb, WebTileJsonRefusesWhatItCannotServe) {
  auto expect_400 = [&](std::string_view target, std::string_view needle) {
    const auto r = get(target);
    EXPECT_EQ(r.status, 400) << target;
    EXPECT_NE(body(r).find(needle), std::string::npos) << body(r);
  };
  expect_400("/dense.json?format=gif", "png, webp, jpg");
  expect_400("/dense.json?format=png&format=png", "repeated query parameter \"format\"");
  expect_400("/dense.json?format=png&tiling=WebMercatorQuad&tiling=x", "repeated");
  expect_400("/dense.json?tiling=WebMercatorQuad", "needs format=");
  expect_400("/dense.json?format=png&tiling=WebMercatorQuad", "plain image");
  expect_400("/dense.json?format=png&tiling=Mars", "WebMercatorQuad");
}

TEST_F(RouterWeb, ANativeTileAskedAsAnImageIs406NamingTheImageRoutes) {
  req_.accept = "image/avif,image/webp,image/apng,image/*,*/*;q=0.8";  // a browser's <img>
  auto r = get("/dense/1/0/0");
  EXPECT_EQ(r.status, 406);
  EXPECT_NE(body(r).find("/dense.json?format=webp"), std::string::npos) << body(r);
  EXPECT_NE(body(r).find("/dense/1/0/0.png"), std::string::npos) << body(r);
  EXPECT_EQ(header_of(r, "Cache-Control"), "no-store");  // caches keep the 200 for the rest
  EXPECT_EQ(get("/dense/1/0/0.png").status, 200);        // the image route is not affected
  for (const char* ours :
       {"*/*", "", "application/vnd.vtstream.tile", "image/png, application/vnd.vtstream.tile"}) {
    req_.accept = ours;
    EXPECT_EQ(get("/dense/1/0/0").status, 200) << ours;
  }
}

TEST_F(RouterWeb, SignedUrlsStillWorkWithOtherParameters) {
  config_.access["secret"].hmac_keys = {"key"};
  config_.now_unix_seconds = [] { return std::int64_t(1'700'000'000); };
  const std::string path = "/secret/0/0/0.png";
  const std::string q = vts::sign_path(path, 1'700'000'100, "key");
  EXPECT_EQ(get(path + q).status, 200);
  EXPECT_EQ(get(path + q + "&format=png").status, 200);
  EXPECT_EQ(get(path + q + "&sig=00").status, 400);  // a repeated key is refused
}

WebTilePtr image(std::size_t bytes) {
  return std::make_shared<const WebTile>(WebTile{std::vector<std::uint8_t>(bytes), "\"t\"", ""});
}

TEST(WebTileCache, StaysWithinItsByteCapEvictingTheLeastRecentlyUsed) {
  WebTileCache c(1000);
  for (int i = 0; i < 3; ++i) {
    auto l = c.acquire("k" + std::to_string(i));
    ASSERT_TRUE(l.lead);
    c.finish("k" + std::to_string(i), l.lead, image(400), 200, "");
  }
  EXPECT_EQ(c.bytes.load(), 800u);  // k0 evicted
  EXPECT_EQ(c.evictions.load(), 1u);
  EXPECT_FALSE(c.acquire("k0").hit);
  EXPECT_TRUE(c.acquire("k1").hit);
  // Too big to keep: answered, never stored.
  auto big = c.acquire("big");
  c.finish("big", big.lead, image(2000), 200, "");
  EXPECT_LE(c.bytes.load(), 1000u);
  EXPECT_FALSE(c.acquire("big").hit);
}

TEST(WebTileCache, ConcurrentMissesShareOneFlight) {
  WebTileCache c(0);  // nothing kept, single flight all the same
  auto lead = c.acquire("k");
  ASSERT_TRUE(lead.lead);
  auto second = c.acquire("k");
  ASSERT_TRUE(second.wait);
  EXPECT_EQ(second.wait, lead.lead);
  int woken = 0;
  second.wait->on_done([&](const WebTilePtr& t, int, const std::string&) { woken += t ? 1 : 100; });
  EXPECT_EQ(woken, 0);
  c.finish("k", lead.lead, image(10), 200, "");
  EXPECT_EQ(woken, 1);
  // After the flight: a late waiter is answered at once, a new miss leads a new flight.
  second.wait->on_done([&](const WebTilePtr& t, int, const std::string&) { woken += t ? 1 : 100; });
  EXPECT_EQ(woken, 2);
  EXPECT_TRUE(c.acquire("k").lead);
}

TEST_F(RouterWeb, AMissWhileAnotherEncodesWaitsForThatFlight) {
  const auto first = get("/dense/1/1/0.png");  // learn the key's tag
  auto c = std::make_shared<WebTileCache>(1 << 20);
  config_.web.cache = c;
  // Lead the flight of the image as the router keys it, as if another request were encoding it.
  const auto t = registry_->find("dense");
  const std::string key = "dense@" + t->version + "/" +
                          std::to_string(vts::archive::zxy_to_tile_id(1, 1, 0)) + "/png" +
                          std::to_string(vts::imaging::WebEncodeOptions{}.png_level) + "a";
  auto lead = c->acquire(key);
  ASSERT_TRUE(lead.lead);
  auto marker = plan("/dense/1/1/0.png");
  ASSERT_TRUE(marker.pending && marker.pending->image) << marker.status;
  EXPECT_EQ(marker.pending->image->key, key);
  Answers answers;
  vts::finish_pending(std::move(marker), nullptr, {}, answers.sink());
  EXPECT_EQ(answers.count(), 0u);  // waits for the flight another request leads
  EXPECT_EQ(c->encodes.load(), 0u);
  auto tile = std::make_shared<const WebTile>(
      WebTile{std::vector<std::uint8_t>(first.view.begin(), first.view.end()),
              *header_of(first, "ETag"), "image/png"});
  c->finish(key, lead.lead, tile, 200, "");
  ASSERT_EQ(answers.count(), 1u);
  const auto done = answers.at(0);
  EXPECT_EQ(done.status, 200);
  EXPECT_EQ(body(done), body(first));
  EXPECT_EQ(header_of(done, "Access-Control-Allow-Origin"), "*");  // the marker's CORS headers
  EXPECT_EQ(c->encodes.load(), 0u);
}

TEST(ServeConfigWeb, KeysApplyAndBadValuesNameTheKey) {
  vts::HttpServerOptions o;
  ASSERT_TRUE(vts::apply_serve_config_text(
                  R"({"web": {"png_level": 1, "webp_quality": 70, "webp_lossless": true,
                              "webp_method": 2, "jpeg_quality": 50, "cache_mib": 3}})",
                  "s.json", o)
                  .ok());
  EXPECT_EQ(o.router.web.encode.png_level, 1);
  EXPECT_EQ(o.router.web.encode.webp_quality, 70);
  EXPECT_TRUE(o.router.web.encode.webp_lossless);
  EXPECT_EQ(o.router.web.encode.webp_method, 2);
  EXPECT_EQ(o.router.web.encode.jpeg_quality, 50);
  EXPECT_EQ(o.router.web.cache_bytes, std::size_t(3) << 20);
  EXPECT_EQ(vts::HttpServerOptions{}.router.web.cache_bytes, std::size_t(64) << 20);
  for (const char* bad :
       {R"({"web": {"png_level": 10}})", R"({"web": {"webp_quality": 101}})",
        R"({"web": {"jpeg_quality": 0}})", R"({"web": {"cache_mib": -1}})",
        R"({"web": {"cache_mib": 1.5}})", R"({"web": {"webp_method": 7}})",
        R"({"web": {"webp_lossless": 1}})", R"({"web": {"png": 1}})", R"({"web": 3})"}) {
    vts::HttpServerOptions p;
    const auto st = vts::apply_serve_config_text(bad, "s.json", p);
    ASSERT_FALSE(st.ok()) << bad;
    EXPECT_NE(st.error().message.find("web"), std::string::npos) << st.error().message;
  }
}

}  // namespace

namespace {

TEST_F(RouterWeb, WithWorkersEveryMissWaitsForTheEncodingOffTheIoThread) {
  auto c = std::make_shared<WebTileCache>(1 << 20, 1);
  config_.web.cache = c;
  auto marker = plan("/dense/2/1/0.jpg");  // a miss: planned, encoded by the worker, never here
  ASSERT_TRUE(marker.pending && marker.pending->image) << marker.status;
  EXPECT_EQ(c->encodes.load(), 0u);  // route() starts nothing
  Answers answers;
  vts::finish_pending(std::move(marker), nullptr, {}, answers.sink());
  ASSERT_TRUE(answers.wait_for(1));
  const auto done = answers.at(0);
  EXPECT_EQ(done.status, 200);
  EXPECT_EQ(header_of(done, "Content-Type"), "image/jpeg");
  EXPECT_NE(answers.thread(0), std::this_thread::get_id());  // answered from the encoder
  EXPECT_EQ(c->encodes.load(), 1u);
  const auto again = plan("/dense/2/1/0.jpg");  // now a hit, answered at once
  EXPECT_FALSE(again.pending);
  EXPECT_EQ(again.status, 200);
}

}  // namespace

namespace {

TEST_F(RouterWeb, ASecondRequestIsACacheHitAndIsNotEncodedAgain) {
  auto& c = *config_.web.cache;
  const auto first = get("/dense/2/2/0.webp");
  ASSERT_EQ(first.status, 200);
  const auto second = get("/dense/2/2/0.webp");
  EXPECT_EQ(second.status, 200);
  EXPECT_EQ(body(first), body(second));
  EXPECT_EQ(c.misses.load(), 1u);
  EXPECT_EQ(c.hits.load(), 1u);
  EXPECT_EQ(c.encodes.load(), 1u);
  const std::string tag = *header_of(first, "ETag");
  req_.if_none_match = tag;
  EXPECT_EQ(get("/dense/2/2/0.webp").status, 304);  // from the cached image's tag
  EXPECT_EQ(c.encodes.load(), 1u);
}

}  // namespace

namespace {

TEST_F(RouterWeb, AMissBeyondTheQueuesCapsIs503WithRetryAfterAndQueuesNothing) {
  auto c = std::make_shared<WebTileCache>(1 << 20, 1, vts::http_detail::EncodeLimits{2, 1});
  config_.web.cache = c;
  vts::test::BusyWorker busy(*c);
  Answers answers;
  req_.connection = 1;
  vts::finish_pending(plan("/dense/2/0/0.png"), nullptr, {}, answers.sink());
  EXPECT_EQ(answers.count(), 0u);  // queued
  // The same connection's second cold image: refused at once.
  vts::finish_pending(plan("/dense/2/1/0.png"), nullptr, {}, answers.sink());
  ASSERT_EQ(answers.count(), 1u);
  const auto over = answers.at(0);
  EXPECT_EQ(over.status, 503);
  EXPECT_EQ(header_of(over, "Retry-After"), "1");
  EXPECT_NE(body(over).find("this connection"), std::string::npos) << body(over);
  req_.connection = 2;
  // The image refused to connection 1 left no flight behind: connection 2 queues it anew.
  vts::finish_pending(plan("/dense/2/1/0.png"), nullptr, {}, answers.sink());
  EXPECT_EQ(answers.count(), 1u);
  req_.connection = 3;
  vts::finish_pending(plan("/dense/2/2/0.png"), nullptr, {}, answers.sink());
  ASSERT_EQ(answers.count(), 2u);
  const auto full = answers.at(1);
  EXPECT_EQ(full.status, 503);
  EXPECT_EQ(header_of(full, "Retry-After"), "1");
  EXPECT_NE(body(full).find("the server has 2"), std::string::npos) << body(full);
  EXPECT_EQ(c->shed.load(), 2u);
  EXPECT_EQ(c->queued(), 2u);
  busy.release();
  c->stop();  // runs the two queued encodes
  EXPECT_EQ(c->encodes.load(), 2u);
  ASSERT_EQ(answers.count(), 4u);
  EXPECT_EQ(answers.at(2).status, 200);
  EXPECT_EQ(answers.at(3).status, 200);
}

TEST_F(RouterWeb, AnEncodeEveryWaiterOfWhichHasGoneIsDroppedNotRun) {
  auto c = std::make_shared<WebTileCache>(1 << 20, 1);
  config_.web.cache = c;
  Answers answers;
  std::stop_source gone, still_here;
  {
    vts::test::BusyWorker busy(*c);
    req_.connection = 1;
    for (const char* t : {"/dense/2/0/0.png", "/dense/2/1/0.png", "/dense/2/2/0.png"})
      vts::finish_pending(plan(t), nullptr, gone.get_token(), answers.sink());
    req_.connection = 2;
    // Joins the third image's flight.
    vts::finish_pending(plan("/dense/2/2/0.png"), nullptr, still_here.get_token(), answers.sink());
    EXPECT_EQ(answers.count(), 0u);
    gone.request_stop();  // connection 1 closed; connection 2 still waits for the third image
  }
  ASSERT_TRUE(answers.wait_for(4));
  std::vector<int> statuses;
  for (std::size_t i = 0; i < 4; ++i) statuses.push_back(answers.at(i).status);
  std::sort(statuses.begin(), statuses.end());
  EXPECT_EQ(statuses, (std::vector<int>{200, 200, 503, 503}));
  EXPECT_EQ(c->encodes.load(), 1u);
  EXPECT_EQ(c->dropped.load(), 2u);
}

}  // namespace
