// One connection of the real server (session.cpp) on 127.0.0.1, spoken to with raw bytes: what the
// network layer answers before (or instead of) routing — requests that do not parse, are too
// large, framed or addressed wrongly — and that those answers carry what every response carries.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>

#include "busy_worker.hpp"
#include "vts/test/archive.hpp"
#include "vts/test/clock.hpp"
#include "vts/test/server.hpp"
#include "vts/test/temp_dir.hpp"

using namespace std::chrono_literals;

namespace {

class Session : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new vts::test::TempDir("vts-session-test");
    vts::test::build_archive(vts::test::synthetic_options(dir_->path() / "syn.pmtiles", 600, 300));
  }
  static void TearDownTestSuite() { delete dir_; }

  // The server over syn.pmtiles with `options` (admin listener on port 0 when enabled).
  static std::unique_ptr<vts::test::RunningServer> start(vts::HttpServerOptions o) {
    o.admin_port = 0;
    return std::make_unique<vts::test::RunningServer>(
        std::vector<std::filesystem::path>{dir_->path() / "syn.pmtiles"}, std::move(o));
  }

  static inline vts::test::TempDir* dir_ = nullptr;
};

// What came back on one connection for `request`: every byte until the server closed it, or
// until `wait` passed without it closing.
struct Reply {
  std::string bytes;
  bool closed = false;
  std::string status_line() const { return bytes.substr(0, bytes.find("\r\n")); }
  // The value of header `name` (matched without regard to case) in the first response.
  std::optional<std::string> header(std::string name) const {
    const std::string head = bytes.substr(0, bytes.find("\r\n\r\n") + 2);
    for (auto& c : name) c = char(std::tolower(static_cast<unsigned char>(c)));
    std::size_t pos = head.find("\r\n");
    while (pos != std::string::npos && pos + 2 < head.size()) {
      const std::size_t end = head.find("\r\n", pos + 2);
      std::string line = head.substr(pos + 2, end - pos - 2);
      const std::size_t colon = line.find(':');
      std::string key = line.substr(0, colon);
      for (auto& c : key) c = char(std::tolower(static_cast<unsigned char>(c)));
      if (colon != std::string::npos && key == name) {
        std::size_t v = colon + 1;
        while (v < line.size() && line[v] == ' ') ++v;
        return line.substr(v);
      }
      pos = end;
    }
    return std::nullopt;
  }
};

Reply exchange(std::uint16_t port, const std::string& request,
               std::chrono::milliseconds wait = 3000ms) {
  Reply r;
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  EXPECT_GE(fd, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ADD_FAILURE() << "cannot connect to port " << port;
    ::close(fd);
    return r;
  }
  for (std::size_t done = 0; done < request.size();) {
    const auto n = ::send(fd, request.data() + done, request.size() - done, MSG_NOSIGNAL);
    if (n <= 0) break;  // the server may refuse before reading everything
    done += std::size_t(n);
  }
  const auto deadline = std::chrono::steady_clock::now() + wait;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    pollfd p{fd, POLLIN, 0};
    if (left.count() <= 0 || ::poll(&p, 1, int(left.count())) <= 0) break;
    char buf[4096];
    const auto n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) {
      r.closed = true;
      break;
    }
    r.bytes.append(buf, std::size_t(n));
  }
  ::close(fd);
  return r;
}

void expect_error_headers(const Reply& r, bool cors) {
  EXPECT_EQ(r.header("Cache-Control"), "no-store");
  EXPECT_EQ(r.header("Content-Type"), "text/plain; charset=utf-8");
  EXPECT_EQ(r.header("Connection"), "close");
  EXPECT_TRUE(r.closed);
  if (cors) {
    EXPECT_EQ(r.header("Access-Control-Allow-Origin"), "*");
    EXPECT_EQ(r.header("Access-Control-Expose-Headers"), "ETag, Content-Range, Content-Length");
  } else {
    EXPECT_FALSE(r.header("Access-Control-Allow-Origin").has_value());
  }
}

const std::string kBigHeader = "X-Big: " + std::string(10000, 'a') + "\r\n";
// Longer than the whole header limit (8 KiB): refused by the network layer, not the router.
const std::string kLongTarget = "/syn/" + std::string(9000, 'a');

}  // namespace

TEST_F(Session, ErrorsOfTheNetworkLayerCarryTheHeadersOfEveryErrorAndCors) {
  auto server = start(vts::test::RunningServer::quiet_options());
  const struct {
    std::string request;
    const char* status;
  } cases[] = {
      {"GET /syn/0/0/0 HTTP/1.1\r\nHost: a\r\n" + kBigHeader + "\r\n", "HTTP/1.1 431"},
      {"GET " + kLongTarget + " HTTP/1.1\r\nHost: a\r\n\r\n", "HTTP/1.1 414"},
      {"GET /syn/0/0/0 HTTP/1.1\r\nHost: a\r\nContent-Length: 4\r\n\r\nxxxx", "HTTP/1.1 413"},
      {"NOT HTTP AT ALL\r\n\r\n", "HTTP/1.1 400"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.status);
    const Reply r = exchange(server->port(), c.request);
    EXPECT_EQ(r.status_line().rfind(c.status, 0), 0u) << r.status_line();
    expect_error_headers(r, true);
  }
}

TEST_F(Session, NetworkLayerErrorsFollowTheConfiguredCorsOrigin) {
  auto o = vts::test::RunningServer::quiet_options();
  o.router.cors_origin = "https://app.example";
  auto server = start(o);
  Reply r = exchange(server->port(), "NOT HTTP AT ALL\r\n\r\n");
  EXPECT_EQ(r.header("Access-Control-Allow-Origin"), "https://app.example");
  EXPECT_EQ(r.header("Vary"), "Origin");
  o.router.cors_origin.clear();
  server = start(o);
  r = exchange(server->port(), "NOT HTTP AT ALL\r\n\r\n");
  EXPECT_EQ(r.status_line().rfind("HTTP/1.1 400", 0), 0u) << r.status_line();
  EXPECT_EQ(r.header("Cache-Control"), "no-store");
  EXPECT_FALSE(r.header("Access-Control-Allow-Origin").has_value());
}

TEST_F(Session, NetworkLayerErrorsOfTheAdminListenerAreNoStoreWithoutCors) {
  auto o = vts::test::RunningServer::quiet_options();
  o.admin_enabled = true;
  auto server = start(o);
  const Reply r = exchange(server->server().admin_port(),
                           "GET /health HTTP/1.1\r\nHost: a\r\n" + kBigHeader + "\r\n");
  EXPECT_EQ(r.status_line().rfind("HTTP/1.1 431", 0), 0u) << r.status_line();
  expect_error_headers(r, false);
}

TEST_F(Session, OptionsWithTheAsteriskTargetIs204) {
  auto server = start(vts::test::RunningServer::quiet_options());
  const Reply r =
      exchange(server->port(), "OPTIONS * HTTP/1.1\r\nHost: a\r\nConnection: close\r\n\r\n");
  EXPECT_EQ(r.status_line(), "HTTP/1.1 204 No Content") << r.bytes;
  EXPECT_EQ(r.header("Allow"), "GET, HEAD, OPTIONS");
  EXPECT_EQ(r.header("Access-Control-Allow-Origin"), "*");
}

TEST_F(Session, AnHttp11RequestWithoutHostOrWithTwoIs400AndCloses) {
  auto server = start(vts::test::RunningServer::quiet_options());
  for (const std::string headers : {"", "Host: a\r\nHost: b\r\n", "Host: a\r\nhost: a\r\n"}) {
    SCOPED_TRACE(headers);
    const Reply r = exchange(server->port(), "GET /syn/0/0/0 HTTP/1.1\r\n" + headers + "\r\n");
    EXPECT_EQ(r.status_line().rfind("HTTP/1.1 400", 0), 0u) << r.status_line();
    EXPECT_NE(r.bytes.find("Host header"), std::string::npos) << r.bytes;
    expect_error_headers(r, true);
  }
  // HTTP/1.0 did not require Host; two are still two.
  Reply r = exchange(server->port(), "GET /syn/0/0/0 HTTP/1.0\r\n\r\n");
  EXPECT_EQ(r.status_line(), "HTTP/1.1 200 OK") << r.bytes;
  r = exchange(server->port(), "GET /syn/0/0/0 HTTP/1.0\r\nHost: a\r\nHost: b\r\n\r\n");
  EXPECT_EQ(r.status_line().rfind("HTTP/1.1 400", 0), 0u) << r.status_line();
}

TEST_F(Session, TwoAuthorizationFieldsAre400AndClose) {
  auto server = start(vts::test::RunningServer::quiet_options());
  const Reply r = exchange(server->port(),
                           "GET /syn/0/0/0 HTTP/1.1\r\nHost: a\r\nAuthorization: Bearer a\r\n"
                           "authorization: Bearer b\r\n\r\n");
  EXPECT_EQ(r.status_line().rfind("HTTP/1.1 400", 0), 0u) << r.status_line();
  EXPECT_NE(r.bytes.find("more than one Authorization"), std::string::npos) << r.bytes;
  expect_error_headers(r, true);
}

TEST_F(Session, ATransferCodingOtherThanChunkedLastIs400AndClosesTheConnection) {
  auto server = start(vts::test::RunningServer::quiet_options());
  for (const char* coding : {"gzip", "chunked, gzip", "identity"}) {
    SCOPED_TRACE(coding);
    // The body's length is unknown: what follows must not be read as the next request.
    const Reply r =
        exchange(server->port(), std::string("GET /syn/0/0/0 HTTP/1.1\r\nHost: a\r\n") +
                                     "Transfer-Encoding: " + coding +
                                     "\r\n\r\nGET /syn/0/0/0 HTTP/1.1\r\nHost: a\r\n\r\n");
    EXPECT_EQ(r.status_line().rfind("HTTP/1.1 400", 0), 0u) << r.status_line();
    EXPECT_NE(r.bytes.find("Transfer-Encoding"), std::string::npos) << r.bytes;
    EXPECT_EQ(r.bytes.find("HTTP/1.1 200"), std::string::npos) << r.bytes;
    expect_error_headers(r, true);
  }
  // Chunked last is framed: an empty chunked body is a request like any other.
  const Reply ok = exchange(server->port(),
                            "GET /syn/0/0/0 HTTP/1.1\r\nHost: a\r\nTransfer-Encoding: gzip, "
                            "chunked\r\nConnection: close\r\n\r\n0\r\n\r\n");
  EXPECT_EQ(ok.status_line(), "HTTP/1.1 200 OK") << ok.bytes;
}

namespace {

// The value of the unlabelled counter `name` in a Prometheus exposition (-1 if absent).
double counter(const std::string& text, const std::string& name) {
  const auto at = text.find("\n" + name + " ");
  return at == std::string::npos ? -1 : std::stod(text.substr(at + name.size() + 2));
}

}  // namespace

TEST_F(Session, AClientThatPipelinesColdWebImagesAndClosesGetsNoneEncoded) {
  vts::test::build_archive(
      vts::test::synthetic_options(dir_->path() / "big" / "big.pmtiles", 2048, 1024));
  auto o = vts::test::RunningServer::quiet_options();
  o.threads = 1;
  auto cache = std::make_shared<vts::http_detail::WebTileCache>(1 << 20, 1);
  o.router.web.cache = cache;
  vts::test::RunningServer server({dir_->path() / "big" / "big.pmtiles"}, o);
  std::string requests;  // 16 distinct cold images: a full pipeline
  for (int i = 0; i < 16; ++i)
    requests += "GET /big/3/" + std::to_string(i % 8) + "/" + std::to_string(i / 8) +
                ".png HTTP/1.1\r\nHost: a\r\n\r\n";
  {
    vts::test::BusyWorker busy(*cache);      // the encodes queue behind it
    exchange(server.port(), requests, 0ms);  // sends, then closes at once
    // The server notices the close although its pipeline is full, and abandons the work.
    EXPECT_TRUE(vts::test::wait_until([&] {
      return counter(server.server().metrics_text(), "vts_http_abandoned_connections_total") == 1;
    })) << server.server().metrics_text();
  }
  // Eight queued (the per-connection cap; eight more were refused 503), all dropped unrun.
  EXPECT_TRUE(vts::test::wait_until([&] { return cache->dropped.load() == 8; }))
      << cache->dropped.load();
  EXPECT_EQ(cache->shed.load(), 8u);
  EXPECT_EQ(cache->encodes.load(), 0u);
  EXPECT_EQ(cache->queued(), 0u);
}
