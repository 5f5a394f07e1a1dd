// The `vts serve --config` file: every documented key lands in HttpServerOptions, and anything
// else (an unknown or misspelt key, a wrong type, bad JSON) is refused naming the key and file.
#include "vts/server/serve_config.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace vts {
namespace {

namespace fs = std::filesystem;

Status apply(const std::string& text, HttpServerOptions& o) {
  return apply_serve_config_text(text, "serve.json", o);
}

void expect_refused(const std::string& text, const std::string& needle) {
  HttpServerOptions o;
  const Status st = apply(text, o);
  ASSERT_FALSE(st.ok()) << "accepted: " << text;
  EXPECT_EQ(st.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(st.error().message.find("config 'serve.json'"), std::string::npos)
      << st.error().message;
  EXPECT_NE(st.error().message.find(needle), std::string::npos) << st.error().message;
}

TEST(ServeConfig, EveryDocumentedKeyIsApplied) {
  HttpServerOptions o;
  const Status st = apply(R"({
    "listen": "0.0.0.0:8181", "admin": "[::1]:9191", "threads": 3, "cors_origin": "https://a.example",
    "max_age": 77, "public_url": "https://tiles.example", "access_log": "-",
    "reload_interval_ms": 250,
    "access": {"earth": {"tokens": ["t1", "t2"], "hmac_keys": ["k"]}},
    "limits": {"max_header_bytes": 4096, "max_target_bytes": 1024, "max_connections": 50,
               "max_pipeline": 4, "min_send_rate": 1000,
               "idle_timeout_ms": 1000, "header_timeout_ms": 2000, "write_timeout_ms": 3000,
               "drain_timeout_ms": 4000}})",
                          o);
  ASSERT_TRUE(st.ok()) << st.error().to_string();
  EXPECT_EQ(o.listen_host, "0.0.0.0");
  EXPECT_EQ(o.listen_port, 8181);
  EXPECT_EQ(o.admin_host, "::1");
  EXPECT_EQ(o.admin_port, 9191);
  EXPECT_TRUE(o.admin_enabled);
  EXPECT_EQ(o.threads, 3);
  EXPECT_EQ(o.router.cors_origin, "https://a.example");
  EXPECT_EQ(o.router.max_age_seconds, 77u);
  EXPECT_EQ(o.router.public_base_url, "https://tiles.example");
  EXPECT_EQ(o.access_log, "-");
  EXPECT_EQ(o.reload_interval, std::chrono::milliseconds(250));
  ASSERT_EQ(o.router.access.count("earth"), 1u);
  EXPECT_EQ(o.router.access["earth"].bearer_tokens, (std::vector<std::string>{"t1", "t2"}));
  EXPECT_EQ(o.router.access["earth"].hmac_keys, (std::vector<std::string>{"k"}));
  const auto& l = o.limits;
  EXPECT_EQ(l.max_header_bytes, 4096u);
  EXPECT_EQ(l.max_target_bytes, 1024u);
  EXPECT_EQ(l.max_connections, 50u);
  EXPECT_EQ(l.max_pipeline, 4u);
  EXPECT_EQ(l.min_send_rate, 1000u);
  EXPECT_EQ(l.idle_timeout, std::chrono::milliseconds(1000));
  EXPECT_EQ(l.header_timeout, std::chrono::milliseconds(2000));
  EXPECT_EQ(l.write_timeout, std::chrono::milliseconds(3000));
  EXPECT_EQ(l.drain_timeout, std::chrono::milliseconds(4000));
}

TEST(ServeConfig, AnEmptyObjectLeavesTheDefaults) {
  HttpServerOptions o;
  ASSERT_TRUE(apply("{}", o).ok());
  const HttpServerOptions d;
  EXPECT_EQ(o.listen_port, d.listen_port);
  EXPECT_EQ(o.admin_enabled, d.admin_enabled);
  EXPECT_EQ(o.limits.max_pipeline, d.limits.max_pipeline);
  EXPECT_EQ(o.reload_interval, d.reload_interval);
}

TEST(ServeConfig, AdminNullTurnsTheAdminListenerOff) {
  HttpServerOptions o;
  ASSERT_TRUE(apply(R"({"admin": null})", o).ok());
  EXPECT_FALSE(o.admin_enabled);
}

TEST(ServeConfig, UnknownKeysAreRefusedNamingTheKeyAndTheFile) {
  expect_refused(R"({"reload_interval": 200})", "unknown key \"reload_interval\"");
  expect_refused(R"({"limits": {"idle_timeout": 5}})", "unknown key \"limits.idle_timeout\"");
  expect_refused(R"({"access": {"earth": {"token": ["x"]}}})",
                 "unknown key \"access.earth.token\"");
}

TEST(ServeConfig, TheUnknownKeyErrorListsTheKnownKeys) {
  expect_refused(R"({"listen": "127.0.0.1:1", "thread": 2})", "known: listen, admin, threads");
}

TEST(ServeConfig, WrongTypesBadJsonAndBadEndpointsAreRefused) {
  expect_refused(R"({"threads": "two"})", "type");
  expect_refused("{not json", "parse");
  expect_refused(R"({"limits": []})", "\"limits.\" must be an object");
  HttpServerOptions o;
  const Status st = apply(R"({"listen": "localhost"})", o);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("is not HOST:PORT"), std::string::npos);
}

TEST(ServeConfig, LimitsTooSmallToServeAnythingAreRefused) {
  expect_refused(R"({"limits": {"max_pipeline": 0}})", "limits.max_pipeline is 0");
  expect_refused(R"({"limits": {"max_header_bytes": 100}})", "at least 256");
}

TEST(ServeConfig, ZeroNegativeAndFractionalLimitsAreRefusedNamingTheLimit) {
  for (const char* key : {"max_target_bytes", "max_connections", "max_pipeline", "idle_timeout_ms",
                          "header_timeout_ms", "write_timeout_ms", "drain_timeout_ms"}) {
    SCOPED_TRACE(key);
    for (const char* value : {"0", "-5", "1.5", "\"10\""}) {
      expect_refused(std::string(R"({"limits": {")") + key + "\": " + value + "}}",
                     std::string("limits.") + key);
    }
  }
  expect_refused(R"({"limits": {"min_send_rate": -1}})", "limits.min_send_rate");
  HttpServerOptions o;
  ASSERT_TRUE(apply(R"({"limits": {"min_send_rate": 0}})", o).ok());  // 0: no rate bound
  EXPECT_EQ(o.limits.min_send_rate, 0u);
}

TEST(ServeConfig, EmptyCredentialsOutOfRangeSettingsAndAFolderAreRefused) {
  expect_refused(R"({"access": {"earth": {"hmac_keys": [""]}}})", "empty key");
  expect_refused(R"({"access": {"earth": {"tokens": ["ok", ""]}}})", "empty token");
  expect_refused(R"({"access": {"earth": {}}})", "no tokens and no hmac_keys");
  expect_refused(R"({"threads": -1})", "threads is -1");
  expect_refused(R"({"threads": 100000})", "threads is 100000");
  expect_refused(R"({"max_age": -5})", "max_age is -5");
  expect_refused(R"({"reload_interval_ms": -100})", "reload_interval_ms is -100");
  // Found by fuzz_serve_config: converted before the check, these were accepted as 1, 2 and 0.
  expect_refused(R"({"threads": 4294967297})", "threads is 4294967297");
  expect_refused(R"({"threads": 2.5})", "threads is 2.5");
  expect_refused(R"({"reload_interval_ms": 0.5})", "reload_interval_ms is 0.5");
  expect_refused(R"({"reload_interval_ms": 1e300})", "reload_interval_ms is 1e+300");
  const fs::path dir =
      fs::temp_directory_path() / ("vts-serve-config-dir-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  HttpServerOptions o;
  const Status st = apply_serve_config(dir, o);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(st.error().message.find("not a regular file"), std::string::npos);
  fs::remove_all(dir);
}

TEST(ServeConfig, DeepNestingAndAControlCharacterInCorsOriginAreRefused) {
  // 100,000 nested arrays (200 KB): refused at the parser, never copied or dumped (a stack
  // overflow before).
  const std::string deep =
      R"({"access": )" + std::string(100000, '[') + std::string(100000, ']') + "}";
  expect_refused(deep, "deeper than 64");
  // CR/LF would end the Access-Control-Allow-Origin header and forge the rest.
  expect_refused(R"({"cors_origin": "https://a.example\r\nSet-Cookie: x=1"})",
                 "cors_origin holds a control character");
  EXPECT_FALSE(check_cors_origin("https://a.example\n").ok());
  EXPECT_TRUE(check_cors_origin("https://a.example").ok());
  EXPECT_TRUE(check_cors_origin("").ok());  // no CORS headers
}

TEST(ServeConfig, TheEncodeQueueCapsAreAppliedAndZeroIsRefused) {
  HttpServerOptions o;
  ASSERT_TRUE(
      apply(R"({"web": {"max_queued_encodes": 50, "max_queued_encodes_per_connection": 2}})", o)
          .ok());
  EXPECT_EQ(o.router.web.max_queued_encodes, 50u);
  EXPECT_EQ(o.router.web.max_queued_encodes_per_connection, 2u);
  EXPECT_EQ(HttpServerOptions{}.router.web.max_queued_encodes, 1024u);
  EXPECT_EQ(HttpServerOptions{}.router.web.max_queued_encodes_per_connection, 8u);
  expect_refused(R"({"web": {"max_queued_encodes": 0}})", "web.max_queued_encodes");
  expect_refused(R"({"web": {"max_queued_encodes_per_connection": -1}})",
                 "web.max_queued_encodes_per_connection");
}

TEST(ServeConfig, TheTileCacheSizeIsAppliedInMibAndZeroTurnsItOff) {
  EXPECT_EQ(HttpServerOptions{}.router.tile_cache_bytes, std::size_t(256) << 20);
  HttpServerOptions o;
  ASSERT_TRUE(apply(R"({"tile_cache_mib": 200})", o).ok());
  EXPECT_EQ(o.router.tile_cache_bytes, std::size_t(200) << 20);
  ASSERT_TRUE(apply(R"({"tile_cache_mib": 0})", o).ok());
  EXPECT_EQ(o.router.tile_cache_bytes, 0u);
  expect_refused(R"({"tile_cache_mib": -1})", "tile_cache_mib");
  expect_refused(R"({"tile_cache_mib": 1.5})", "tile_cache_mib");
  expect_refused(R"({"tile_cache_mib": 1048577})", "tile_cache_mib");
}

TEST(ServeConfig, AFileIsReadAndAMissingOneIsAnIoErrorNamingIt) {
  const fs::path dir =
      fs::temp_directory_path() / ("vts-serve-config-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path file = dir / "serve.json";
  std::ofstream(file) << R"({"threads": 5, "bogus": 1})";
  HttpServerOptions o;
  Status st = apply_serve_config(file, o);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("config '" + file.string() + "'"), std::string::npos)
      << st.error().message;
  EXPECT_NE(st.error().message.find("\"bogus\""), std::string::npos) << st.error().message;
  st = apply_serve_config(dir / "missing.json", o);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, ErrorCode::io);
  EXPECT_NE(st.error().message.find("missing.json"), std::string::npos);
  fs::remove_all(dir);
}

TEST(ServeEndpoint, HostPortFormsParse) {
  EXPECT_EQ(parse_endpoint("127.0.0.1:80").value(),
            std::pair(std::string("127.0.0.1"), std::uint16_t(80)));
  EXPECT_EQ(parse_endpoint("[::1]:9").value(), std::pair(std::string("::1"), std::uint16_t(9)));
  EXPECT_EQ(parse_endpoint(":8080").value(),
            std::pair(std::string("0.0.0.0"), std::uint16_t(8080)));
  for (const char* bad : {"nohost", "h:", "h:65536", "h:12x", "h:-1"}) {
    EXPECT_FALSE(parse_endpoint(bad).ok()) << bad;
  }
}

}  // namespace
}  // namespace vts
