// The HTTP server under load and abuse, in process: a real HttpServer on 127.0.0.1 port 0 (stopped
// by a scope guard), real libcurl clients and raw sockets. The archive comes from the real
// builder in process; every tile body is compared with what archive::Reader returns.
#include <arpa/inet.h>
#include <curl/curl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/server/http_server.hpp"
#include "vts/test/archive.hpp"
#include "vts/test/server.hpp"
#include "vts/test/socket.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace {

using vts::test::connect_to;
using vts::test::read_until_closed;
using vts::test::send_all;

// One synthetic archive for the whole file (built once, in process).
const vts::test::TempDir& archive_dir() {
  static const vts::test::TempDir d("vts-http-test");
  return d;
}

const vts::test::OpenedArchive& archive() {
  static const vts::test::OpenedArchive a = vts::test::build_and_open(
      vts::test::synthetic_options(archive_dir() / "syn.pmtiles", 6000, 3000));
  return a;
}

// The server over archive(), admin listener on port 0, for the scope of a test.
class RunningServer {
 public:
  explicit RunningServer(vts::HttpServerOptions o)
      : server_({archive().path}, admin_on_port_0(std::move(o))) {}
  // Stops the server and waits for run() to return; returns how long that took.
  std::chrono::steady_clock::duration stop_and_join() { return server_.stop(); }
  vts::HttpServer& operator*() { return server_.server(); }
  vts::HttpServer* operator->() { return &server_.server(); }
  std::string base() const { return server_.base_url(); }

 private:
  static vts::HttpServerOptions admin_on_port_0(vts::HttpServerOptions o) {
    o.admin_port = 0;
    return o;
  }
  vts::test::RunningServer server_;
};

std::size_t append(char* p, std::size_t size, std::size_t n, void* user) {
  static_cast<std::string*>(user)->append(p, size * n);
  return size * n;
}

struct Fetched {
  long status = 0;
  std::string body;
  CURLcode code = CURLE_OK;
};

Fetched fetch(const std::string& url, long timeout_ms = 5000) {
  Fetched f;
  CURL* h = curl_easy_init();
  curl_easy_setopt(h, CURLOPT_URL, url.c_str());
  curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, append);
  curl_easy_setopt(h, CURLOPT_WRITEDATA, &f.body);
  curl_easy_setopt(h, CURLOPT_TIMEOUT_MS, timeout_ms);
  f.code = curl_easy_perform(h);
  curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &f.status);
  curl_easy_cleanup(h);
  return f;
}

std::string tile_path(const vts::TileId& t) {
  return "/syn/" + std::to_string(t.z) + "/" + std::to_string(t.x) + "/" + std::to_string(t.y);
}

bool same_as_archive(const vts::TileId& t, const std::string& body) {
  auto want = archive().reader->get(t);
  return want && want->size() == body.size() &&
         std::equal(want->begin(), want->end(), reinterpret_cast<const std::uint8_t*>(body.data()));
}

// True when the peer has closed `fd` (EOF or reset) within `wait`.
bool closed_by_peer(int fd, std::chrono::milliseconds wait) {
  const auto deadline = std::chrono::steady_clock::now() + wait;
  for (;;) {
    pollfd p{fd, POLLIN, 0};
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (::poll(&p, 1, int(std::max<long>(0, left.count()))) <= 0) return false;
    char buf[4096];
    const auto n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) return true;  // 0 = EOF, <0 = reset
  }
}

void raise_fd_limit() {
  rlimit rl{};
  if (getrlimit(RLIMIT_NOFILE, &rl) == 0) {
    rl.rlim_cur = rl.rlim_max;
    setrlimit(RLIMIT_NOFILE, &rl);
  }
}

}  // namespace

TEST(HttpServer, FiveHundredParallelClientsGetEveryByteRight) {
  vts::HttpServerOptions o;
  o.threads = 2;
  RunningServer server(o);
  raise_fd_limit();
  const auto& tiles = archive().tiles;
  ASSERT_GT(tiles.size(), 100u);

  constexpr int kClients = 500, kRequests = 5000;
  struct Slot {
    CURL* h = nullptr;
    std::string body;
    vts::TileId tile;
  };
  std::vector<Slot> slots(kClients);
  CURLM* multi = curl_multi_init();
  curl_multi_setopt(multi, CURLMOPT_MAX_TOTAL_CONNECTIONS, long(kClients));
  curl_multi_setopt(multi, CURLMOPT_MAXCONNECTS, long(kClients));
  std::mt19937 rng(42);
  int started = 0, done = 0, bad = 0;
  auto launch = [&](Slot& s) {
    s.tile = tiles[rng() % tiles.size()];
    s.body.clear();
    const std::string url = server.base() + tile_path(s.tile);
    curl_easy_setopt(s.h, CURLOPT_URL, url.c_str());
    curl_multi_add_handle(multi, s.h);
    ++started;
  };
  for (auto& s : slots) {
    s.h = curl_easy_init();
    curl_easy_setopt(s.h, CURLOPT_WRITEFUNCTION, append);
    curl_easy_setopt(s.h, CURLOPT_WRITEDATA, &s.body);
    curl_easy_setopt(s.h, CURLOPT_PRIVATE, &s);
    curl_easy_setopt(s.h, CURLOPT_TIMEOUT_MS, 20000L);
    launch(s);
  }
  int running = 1;
  while (done < kRequests && running >= 0) {
    curl_multi_perform(multi, &running);
    int queued = 0;
    while (CURLMsg* m = curl_multi_info_read(multi, &queued)) {
      if (m->msg != CURLMSG_DONE) continue;
      Slot* s = nullptr;
      curl_easy_getinfo(m->easy_handle, CURLINFO_PRIVATE, reinterpret_cast<char**>(&s));
      long status = 0;
      curl_easy_getinfo(m->easy_handle, CURLINFO_RESPONSE_CODE, &status);
      const CURLcode code = m->data.result;
      curl_multi_remove_handle(multi, m->easy_handle);
      ++done;
      if (code != CURLE_OK || status != 200 || !same_as_archive(s->tile, s->body)) {
        if (bad++ < 5)
          ADD_FAILURE() << tile_path(s->tile) << ": " << curl_easy_strerror(code) << " status "
                        << status << ", " << s->body.size() << " bytes";
      }
      if (started < kRequests) launch(*s);
    }
    if (done < kRequests) curl_multi_poll(multi, nullptr, 0, 100, nullptr);
  }
  for (auto& s : slots) {
    curl_multi_remove_handle(multi, s.h);
    curl_easy_cleanup(s.h);
  }
  curl_multi_cleanup(multi);
  EXPECT_EQ(done, kRequests);
  EXPECT_EQ(bad, 0);
  const std::string metrics = server->metrics_text();
  EXPECT_NE(metrics.find("vts_http_requests_total{route=\"tile\",status=\"200\"} 5000"),
            std::string::npos)
      << metrics;
}

TEST(HttpServer, SlowlorisConnectionsAreClosedWhileOthersAreServed) {
  vts::HttpServerOptions o;
  o.threads = 2;
  o.limits.header_timeout = 1000ms;
  o.limits.idle_timeout = 3000ms;
  RunningServer server(o);
  raise_fd_limit();

  std::vector<int> partial, idle;
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 1000; ++i) {
    const int fd = connect_to(server->port());
    ASSERT_GE(fd, 0) << "connection " << i;
    ASSERT_TRUE(send_all(fd, "GET /syn/0/0/0 HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: "));
    partial.push_back(fd);
  }
  for (int i = 0; i < 200; ++i) {
    const int fd = connect_to(server->port());
    ASSERT_GE(fd, 0);
    idle.push_back(fd);
  }
  // Normal clients are served promptly while 1200 connections hang.
  const auto& tiles = archive().tiles;
  for (int i = 0; i < 20; ++i) {
    const auto& t = tiles[std::size_t(i * 7) % tiles.size()];
    const auto start = std::chrono::steady_clock::now();
    const Fetched f = fetch(server.base() + tile_path(t), 1000);
    const auto took = std::chrono::steady_clock::now() - start;
    ASSERT_EQ(f.code, CURLE_OK) << curl_easy_strerror(f.code);
    EXPECT_EQ(f.status, 200);
    EXPECT_TRUE(same_as_archive(t, f.body));
    // Within the client's own 1 s timeout (checked above); the wide bound only catches a stall.
    EXPECT_LT(took, 1000ms);
  }
  // The partial headers are cut after the header timeout; idle ones after the idle timeout.
  int partial_closed = 0, idle_closed = 0;
  for (int fd : partial) partial_closed += closed_by_peer(fd, 2000ms);
  // All cut by the header deadline, well before the idle timeout would have.
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 2500ms);
  for (int fd : idle) idle_closed += closed_by_peer(fd, 4000ms);
  EXPECT_GE(std::chrono::steady_clock::now() - t0, 2900ms);
  EXPECT_EQ(partial_closed, 1000);
  EXPECT_EQ(idle_closed, 200);
  for (int fd : partial) ::close(fd);
  for (int fd : idle) ::close(fd);
  EXPECT_EQ(fetch(server.base() + "/").status, 200);
}

TEST(HttpServer, DeepPipelineIsAnsweredInOrderUnderBackPressure) {
  vts::HttpServerOptions o;
  o.limits.max_pipeline = 2;
  RunningServer server(o);
  const auto& tiles = archive().tiles;
  std::string requests;
  constexpr int kN = 40;
  for (int i = 0; i < kN; ++i)
    requests += "GET " + tile_path(tiles[std::size_t(i)]) + " HTTP/1.1\r\nHost: a\r\n" +
                (i == kN - 1 ? "Connection: close\r\n" : "") + "\r\n";
  const int fd = connect_to(server->port());
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(send_all(fd, requests));
  const std::string all = read_until_closed(fd);
  ::close(fd);
  // Walk the responses: header, Content-Length, body — in request order.
  std::size_t pos = 0;
  for (int i = 0; i < kN; ++i) {
    const auto end = all.find("\r\n\r\n", pos);
    ASSERT_NE(end, std::string::npos) << "response " << i << " missing";
    const std::string head = all.substr(pos, end - pos);
    ASSERT_EQ(head.rfind("HTTP/1.1 200", 0), 0u) << head;
    const auto cl = head.find("Content-Length: ");
    ASSERT_NE(cl, std::string::npos);
    const std::size_t len = std::stoul(head.substr(cl + 16));
    EXPECT_TRUE(same_as_archive(tiles[std::size_t(i)], all.substr(end + 4, len)))
        << "response " << i;
    pos = end + 4 + len;
  }
  EXPECT_EQ(pos, all.size());
}

TEST(HttpServer, ConnectionsBeyondTheLimitAreClosed) {
  vts::HttpServerOptions o;
  o.limits.max_connections = 20;
  RunningServer server(o);
  std::vector<int> fds;
  for (int i = 0; i < 30; ++i) fds.push_back(connect_to(server->port()));
  int closed = 0;
  std::this_thread::sleep_for(300ms);
  for (int fd : fds) closed += closed_by_peer(fd, 0ms);
  EXPECT_EQ(closed, 10);
  for (int fd : fds) ::close(fd);
  // Once they are gone, new clients get in again.
  std::this_thread::sleep_for(100ms);
  EXPECT_EQ(fetch(server.base() + "/").status, 200);
  EXPECT_NE(server->metrics_text().find("vts_http_refused_connections_total 10"),
            std::string::npos);
}

TEST(HttpServer, ClientsThatVanishMidResponseDoNotKillTheProcess) {
  // Tiles go out with sendfile(2), which has no MSG_NOSIGNAL: writing to a connection the client
  // has reset raises SIGPIPE, whose default action ends the process (seen under `vts loadtest`
  // with 64 viewers). The server must ignore it, whatever the disposition it started with.
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  sigemptyset(&dfl.sa_mask);
  ASSERT_EQ(::sigaction(SIGPIPE, &dfl, nullptr), 0);
  RunningServer server(vts::HttpServerOptions{});
  struct sigaction now {};
  ASSERT_EQ(::sigaction(SIGPIPE, nullptr, &now), 0);
  EXPECT_EQ(now.sa_handler, SIG_IGN);

  // Clients with a tiny receive window ask for the whole archive, read a byte and reset.
  const std::string request =
      "GET /" + archive().path.stem().string() + ".pmtiles HTTP/1.1\r\nHost: t\r\n\r\n";
  for (int i = 0; i < 50; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    ASSERT_GE(fd, 0);
    const int small = 4096;
    ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(server->port());
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    ASSERT_EQ(::send(fd, request.data(), request.size(), MSG_NOSIGNAL), ssize_t(request.size()));
    char byte = 0;
    (void)::recv(fd, &byte, 1, 0);
    const linger rst{1, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &rst, sizeof rst);
    ::close(fd);
  }
  std::this_thread::sleep_for(100ms);
  EXPECT_EQ(fetch(server.base() + "/").status, 200);
}

TEST(HttpServer, HealthSaysLoadingUntilReady) {
  vts::HttpServerOptions o;
  RunningServer server(o);
  const std::string admin = "http://127.0.0.1:" + std::to_string(server->admin_port());
  Fetched f = fetch(admin + "/health");
  EXPECT_EQ(f.status, 503);
  EXPECT_EQ(f.body, "loading\n");
  server->set_ready(true);
  f = fetch(admin + "/health");
  EXPECT_EQ(f.status, 200);
  EXPECT_EQ(f.body, "ok\n");
  f = fetch(admin + "/metrics");
  EXPECT_EQ(f.status, 200);
  EXPECT_NE(f.body.find("vts_tilesets_loaded 1"), std::string::npos);
  EXPECT_NE(f.body.find("# TYPE vts_http_request_duration_seconds histogram"), std::string::npos);
}

TEST(HttpServer, StopFinishesQueuedResponsesThenClosesAndReturns) {
  vts::HttpServerOptions o;
  o.threads = 2;
  RunningServer server(o);
  const auto archive_size = fs::file_size(archive().path);
  // Enough pipelined archive downloads that the socket buffers fill and writes are in flight.
  // (more than the loopback socket buffers, ~4 MiB each way, can hold, plus the pipeline cap)
  const int kN = int(std::max<std::uintmax_t>(64, (48u << 20) / archive_size));
  std::string requests;
  for (int i = 0; i < kN; ++i) requests += "GET /syn.pmtiles HTTP/1.1\r\nHost: a\r\n\r\n";
  const int fd = connect_to(server->port());
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(send_all(fd, requests));
  std::this_thread::sleep_for(200ms);
  std::thread stopper([&] { server.stop_and_join(); });
  const std::string all = read_until_closed(fd);
  ::close(fd);
  stopper.join();
  // Whole responses only, each the whole archive, then EOF.
  std::size_t pos = 0;
  int complete = 0;
  while (pos < all.size()) {
    const auto end = all.find("\r\n\r\n", pos);
    ASSERT_NE(end, std::string::npos);
    ASSERT_EQ(all.compare(pos, 15, "HTTP/1.1 200 OK"), 0);
    ASSERT_LE(end + 4 + archive_size, all.size()) << "response " << complete << " cut short";
    pos = end + 4 + archive_size;
    ++complete;
  }
  EXPECT_GE(complete, 1);
  EXPECT_LT(complete, kN) << "requests not yet read when stopping should not be answered";
}

TEST(HttpServer, StopClosesIdleKeepAliveConnectionsAtOnce) {
  vts::HttpServerOptions o;
  RunningServer server(o);
  std::vector<int> fds;
  for (int i = 0; i < 50; ++i) {
    const int fd = connect_to(server->port());
    ASSERT_GE(fd, 0);
    ASSERT_TRUE(send_all(fd, "GET /syn/0/0/0 HTTP/1.1\r\nHost: a\r\n\r\n"));
    fds.push_back(fd);
  }
  std::this_thread::sleep_for(100ms);
  EXPECT_LT(server.stop_and_join(), 1s);  // the idle timeout is 30 s
  for (int fd : fds) {
    EXPECT_TRUE(closed_by_peer(fd, 100ms));
    ::close(fd);
  }
}

TEST(HttpServer, Http10KeepAliveIsHonouredAndAnnouncedOtherwiseTheConnectionCloses) {
  vts::HttpServerOptions o;
  RunningServer server(o);
  const int fd = connect_to(server->port());
  ASSERT_GE(fd, 0);
  const std::string req = "GET /syn/0/0/0 HTTP/1.0\r\nConnection: keep-alive\r\n\r\n";
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(send_all(fd, req)) << "request " << i << ": connection closed too early";
    std::string got;
    char buf[65536];
    while (got.find("\r\n\r\n") == std::string::npos) {
      const auto n = ::recv(fd, buf, sizeof buf, 0);
      ASSERT_GT(n, 0) << "request " << i;
      got.append(buf, std::size_t(n));
    }
    const std::string head = got.substr(0, got.find("\r\n\r\n"));
    EXPECT_NE(head.find(" 200 "), std::string::npos) << head;
    EXPECT_NE(head.find("Connection: keep-alive"), std::string::npos) << head;
    const auto cl = head.find("Content-Length: ");
    ASSERT_NE(cl, std::string::npos);
    const std::size_t want = head.size() + 4 + std::stoul(head.substr(cl + 16));
    while (got.size() < want) {
      const auto n = ::recv(fd, buf, sizeof buf, 0);
      ASSERT_GT(n, 0);
      got.append(buf, std::size_t(n));
    }
  }
  ::close(fd);
  // Without keep-alive, HTTP/1.0 gets one response and the connection ends.
  const int fd2 = connect_to(server->port());
  ASSERT_TRUE(send_all(fd2, "GET /syn/0/0/0 HTTP/1.0\r\n\r\n"));
  std::string all;
  char buf[65536];
  for (;;) {
    const auto n = ::recv(fd2, buf, sizeof buf, 0);
    if (n <= 0) break;
    all.append(buf, std::size_t(n));
  }
  ::close(fd2);
  EXPECT_NE(all.find("Connection: close"), std::string::npos);
}

TEST(HttpServer, AReaderThatTricklesIsCutAtItsResponseDeadline) {
  vts::HttpServerOptions o;
  o.limits.write_timeout = 500ms;
  o.limits.min_send_rate = 1u << 20;  // 1 MiB/s
  RunningServer server(o);
  const auto archive_size = fs::file_size(archive().path);
  // More than the socket buffers hold, so writes must wait for the reader.
  const int kN = int(std::max<std::uintmax_t>(8, (32u << 20) / archive_size));
  std::string requests;
  for (int i = 0; i < kN; ++i) requests += "GET /syn.pmtiles HTTP/1.1\r\nHost: a\r\n\r\n";
  const int fd = connect_to(server->port());
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(send_all(fd, requests));
  // Read 1 KiB every 50 ms (20 KiB/s): far below the rate bound. What the client has buffered
  // (megabytes) hides the close from it for minutes, so watch the server's connection gauge.
  const auto start = std::chrono::steady_clock::now();
  const auto limit = 500ms + std::chrono::milliseconds(archive_size * 1000 / (1u << 20));
  bool cut = false;
  char buf[1024];
  while (!cut && std::chrono::steady_clock::now() - start < limit + 5s) {
    ASSERT_GT(::recv(fd, buf, sizeof buf, 0), 0);
    cut = server->metrics_text().find("vts_http_open_connections 0\n") != std::string::npos;
    std::this_thread::sleep_for(50ms);
  }
  const auto took = std::chrono::steady_clock::now() - start;
  ::close(fd);
  EXPECT_TRUE(cut) << "still connected after " << std::chrono::duration<double>(took).count()
                   << " s";
  // The first response to stall had write_timeout + its size at min_send_rate, counted from
  // when its writing began (at most `took` after the start).
  EXPECT_LT(took, limit + 2s);
  // A normal client is unaffected.
  EXPECT_EQ(fetch(server.base() + "/syn.pmtiles").status, 200);
}
