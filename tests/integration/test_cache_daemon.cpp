// The cache daemon (`vts cache serve`) and the server hook it stands on (AsyncTileProvider).
//
// AsyncTileProvider.*: an in-process HttpServer whose provider is a fake answering from an archive
// — inline, from another thread, late, out of order, or never — checked with raw sockets and
// libcurl against the same archive served by the registry.
// CacheDaemon.*: the real `vts` executable (VTS_EXECUTABLE) in front of a real upstream (an
// in-process HttpServer over archives made by vts::build_pyramid), on 127.0.0.1 port 0; the
// upstream is stopped and restarted under it. Every process and server is stopped by a scope
// guard.
#include <arpa/inet.h>
#include <curl/curl.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"
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

// ---- archives ---------------------------------------------------------------------------------

struct Archive : vts::test::OpenedArchive {
  vts::TilesetInfo info;
};

const vts::test::TempDir& test_dir_guard() {
  static const vts::test::TempDir d("vts-daemon-test");
  return d;
}
const fs::path& test_dir() {
  return test_dir_guard().path();
}

Archive build(const std::string& name, std::optional<vts::TexelRect> region) {
  const auto o = vts::test::synthetic_options(test_dir() / "archives" / (name + ".pmtiles"), 1500,
                                              1000, region, 2);
  Archive a;
  a.info = vts::test::build_archive(o).info;
  static_cast<vts::test::OpenedArchive&>(a) = vts::test::open_archive(o.output);
  return a;
}

// "syn": dense, 1500x1000, levels 0-3. "holes": the same image, sparse (level >= 2 only near the
// top-left corner).
const Archive& dense() {
  static const Archive a = build("syn", std::nullopt);
  return a;
}
const Archive& sparse() {
  static const Archive a = build("holes", vts::TexelRect{0, 0, 300, 300});
  return a;
}

std::string payload_of(const Archive& a, vts::TileId t) {
  auto p = a.reader->get(t);
  if (!p) return {};
  return std::string(reinterpret_cast<const char*>(p->data()), p->size());
}

// ---- an in-process server ----------------------------------------------------------------------

// The server over `archives` with `provider`, on `port` (0 = any).
class RunningServer {
 public:
  RunningServer(std::vector<fs::path> archives, std::shared_ptr<vts::AsyncTileProvider> provider,
                std::uint16_t port = 0)
      : server_(std::move(archives), options(std::move(provider), port), port != 0) {}
  void stop() { server_.stop(); }
  std::uint16_t port() const { return server_.port(); }
  std::string base() const { return server_.base_url(); }

 private:
  static vts::HttpServerOptions options(std::shared_ptr<vts::AsyncTileProvider> provider,
                                        std::uint16_t port) {
    vts::HttpServerOptions o;
    o.listen_port = port;
    o.admin_enabled = false;
    o.threads = 2;
    o.provider = std::move(provider);
    return o;
  }
  vts::test::RunningServer server_;
};

// ---- HTTP clients ------------------------------------------------------------------------------

struct Fetched {
  long status = 0;
  std::string body;
  std::map<std::string, std::string> headers;  // lower-case names
  CURLcode code = CURLE_OK;
  std::string header(const std::string& name) const {
    auto it = headers.find(name);
    return it == headers.end() ? std::string() : it->second;
  }
};

std::size_t on_body(char* p, std::size_t size, std::size_t n, void* user) {
  static_cast<std::string*>(user)->append(p, size * n);
  return size * n;
}

std::size_t on_header(char* p, std::size_t size, std::size_t n, void* user) {
  std::string line(p, size * n);
  const auto colon = line.find(':');
  if (colon != std::string::npos) {
    std::string name = line.substr(0, colon);
    for (auto& c : name) c = char(std::tolower(static_cast<unsigned char>(c)));
    std::string value = line.substr(colon + 1);
    while (!value.empty() && (value.front() == ' ')) value.erase(0, 1);
    while (!value.empty() && (value.back() == '\r' || value.back() == '\n')) value.pop_back();
    (*static_cast<std::map<std::string, std::string>*>(user))[name] = value;
  }
  return size * n;
}

Fetched fetch(const std::string& url, const std::string& if_none_match = {}, bool head = false) {
  Fetched f;
  CURL* h = curl_easy_init();
  curl_easy_setopt(h, CURLOPT_URL, url.c_str());
  curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, on_body);
  curl_easy_setopt(h, CURLOPT_WRITEDATA, &f.body);
  curl_easy_setopt(h, CURLOPT_HEADERFUNCTION, on_header);
  curl_easy_setopt(h, CURLOPT_HEADERDATA, &f.headers);
  curl_easy_setopt(h, CURLOPT_TIMEOUT_MS, 10000L);
  if (head) curl_easy_setopt(h, CURLOPT_NOBODY, 1L);
  curl_slist* extra = nullptr;
  if (!if_none_match.empty()) {
    extra = curl_slist_append(extra, ("If-None-Match: " + if_none_match).c_str());
    curl_easy_setopt(h, CURLOPT_HTTPHEADER, extra);
  }
  f.code = curl_easy_perform(h);
  curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &f.status);
  curl_easy_cleanup(h);
  curl_slist_free_all(extra);
  return f;
}

std::string tile_path(const std::string& name, vts::TileId t) {
  return "/" + name + "/" + std::to_string(t.z) + "/" + std::to_string(t.x) + "/" +
         std::to_string(t.y);
}

struct RawResponse {
  int status = 0;
  std::string head, body;
};

// Sends `paths` as pipelined GETs on one connection (the last with Connection: close) and
// splits what comes back into responses, in the order received.
std::vector<RawResponse> pipelined(std::uint16_t port, const std::vector<std::string>& paths) {
  std::string requests;
  for (std::size_t i = 0; i < paths.size(); ++i)
    requests += "GET " + paths[i] + " HTTP/1.1\r\nHost: a\r\n" +
                (i + 1 == paths.size() ? "Connection: close\r\n" : "") + "\r\n";
  std::vector<RawResponse> out;
  const int fd = connect_to(port);
  if (fd < 0 || !send_all(fd, requests)) return out;
  timeval tv{10, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  const std::string all = read_until_closed(fd);
  ::close(fd);
  std::size_t pos = 0;
  while (pos < all.size()) {
    const auto end = all.find("\r\n\r\n", pos);
    if (end == std::string::npos) break;
    RawResponse r;
    r.head = all.substr(pos, end - pos);
    r.status = std::atoi(r.head.c_str() + 9);
    std::size_t len = 0;
    if (const auto cl = r.head.find("Content-Length: "); cl != std::string::npos)
      len = std::stoul(r.head.substr(cl + 16));
    r.body = all.substr(end + 4, len);
    pos = end + 4 + len;
    out.push_back(std::move(r));
  }
  return out;
}

// ---- a fake provider ---------------------------------------------------------------------------

// Serves `archive` under `name`. Each tile's answer is chosen by `plan` (by tile): inline inside
// tile(), from a thread after a delay, or held until release_held().
class FakeProvider final : public vts::AsyncTileProvider {
 public:
  enum class Mode { inline_answer, delayed, held };
  struct Plan {
    Mode mode = Mode::inline_answer;
    std::chrono::milliseconds delay{0};
    std::optional<vts::ProvidedTile::Kind> kind;  // default: ok if stored, else absent
    bool damage = false;                          // send a payload without a valid header frame
  };

  FakeProvider(const Archive& archive, std::string name) : archive_(archive) {
    auto t = std::make_shared<vts::ProvidedTileset>();
    t->name = std::move(name);
    t->info = archive.info;
    t->version = "fakeversion";
    tileset_ = std::move(t);
  }
  ~FakeProvider() override {
    for (auto& t : threads_) t.join();
  }

  void set_plan(vts::TileId id, Plan p) {
    std::lock_guard lock(mutex_);
    plans_[id] = p;
  }

  std::shared_ptr<const vts::ProvidedTileset> find(std::string_view name) const override {
    return name == tileset_->name ? tileset_ : nullptr;
  }
  std::vector<std::shared_ptr<const vts::ProvidedTileset>> all() const override {
    return {tileset_};
  }
  void tile(const std::shared_ptr<const vts::ProvidedTileset>&, vts::TileId id,
            std::function<void(vts::ProvidedTile)> done, std::stop_token abandon) override {
    Plan plan;
    {
      std::lock_guard lock(mutex_);
      if (auto it = plans_.find(id); it != plans_.end()) plan = it->second;
      ++calls_;
      tokens_.push_back(std::move(abandon));
    }
    vts::ProvidedTile answer = make_answer(id, plan);
    switch (plan.mode) {
      case Mode::inline_answer:
        done(std::move(answer));
        break;
      case Mode::delayed: {
        std::lock_guard lock(mutex_);
        threads_.emplace_back([d = plan.delay, done = std::move(done), a = std::move(answer)] {
          std::this_thread::sleep_for(d);
          done(a);
        });
        break;
      }
      case Mode::held: {
        std::lock_guard lock(mutex_);
        held_.emplace_back(std::move(done), std::move(answer));
        cv_.notify_all();
        break;
      }
    }
  }

  bool wait_held(std::size_t n, std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    return cv_.wait_for(lock, timeout, [&] { return held_.size() >= n; });
  }
  void release_held() {
    std::vector<std::pair<std::function<void(vts::ProvidedTile)>, vts::ProvidedTile>> held;
    {
      std::lock_guard lock(mutex_);
      held.swap(held_);
    }
    for (auto& [done, answer] : held) done(std::move(answer));
  }
  int calls() const {
    std::lock_guard lock(mutex_);
    return calls_;
  }
  // The requests whose abandon token the server has requested, by order of tile() call.
  std::vector<bool> abandoned() const {
    std::lock_guard lock(mutex_);
    std::vector<bool> out;
    for (const auto& t : tokens_) out.push_back(t.stop_requested());
    return out;
  }

 private:
  vts::ProvidedTile make_answer(vts::TileId id, const Plan& plan) const {
    vts::ProvidedTile a;
    auto payload = archive_.reader->get(id);
    a.kind =
        plan.kind.value_or(payload ? vts::ProvidedTile::Kind::ok : vts::ProvidedTile::Kind::absent);
    if (a.kind == vts::ProvidedTile::Kind::ok) {
      if (plan.damage) {
        auto junk = std::make_shared<const std::vector<std::uint8_t>>(100, std::uint8_t{7});
        a.payload = *junk;
        a.keep = junk;
      } else {
        auto bytes = std::make_shared<const std::vector<std::uint8_t>>(std::move(*payload));
        a.payload = *bytes;
        a.keep = bytes;  // the copy the reader made outlives the response
      }
    }
    if (a.kind == vts::ProvidedTile::Kind::unavailable) a.message = "origin down";
    if (a.kind == vts::ProvidedTile::Kind::bad_origin) a.message = "checksum mismatch";
    return a;
  }

  const Archive& archive_;
  std::shared_ptr<const vts::ProvidedTileset> tileset_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::map<vts::TileId, Plan> plans_;
  std::vector<std::thread> threads_;
  std::vector<std::pair<std::function<void(vts::ProvidedTile)>, vts::ProvidedTile>> held_;
  int calls_ = 0;
  std::vector<std::stop_token> tokens_;
};

// ---- the daemon process ------------------------------------------------------------------------

// `vts cache serve ARGS...` with stdout on a pipe; ready once it printed its "listening on" line.
class Daemon {
 public:
  explicit Daemon(std::vector<std::string> args) {
    int out[2];
    if (::pipe(out) != 0) throw std::runtime_error("pipe");
    log_ = test_dir() / ("daemon." + std::to_string(++count_) + ".stderr");
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(out[1], 1);
      const int err = ::open(log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (err >= 0) ::dup2(err, 2);
      ::close(out[0]);
      ::close(out[1]);
      // Nothing else of ours: an inherited listening socket (the in-process upstream's) would
      // keep the upstream's port accepting connections in the daemon after the upstream stops.
      ::close_range(3, ~0u, 0);
      std::vector<std::string> all = {VTS_EXECUTABLE, "cache", "serve"};
      all.insert(all.end(), args.begin(), args.end());
      std::vector<char*> argv;
      for (auto& a : all) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    ::close(out[1]);
    out_ = out[0];
    // Wait (up to 15 s) for "listening on http://127.0.0.1:PORT".
    std::string text;
    const auto deadline = std::chrono::steady_clock::now() + 15s;
    while (std::chrono::steady_clock::now() < deadline) {
      pollfd p{out_, POLLIN, 0};
      if (::poll(&p, 1, 100) <= 0) continue;
      char buf[512];
      const auto n = ::read(out_, buf, sizeof buf);
      if (n <= 0) break;
      text.append(buf, std::size_t(n));
      const auto at = text.find("listening on http://127.0.0.1:");
      if (at != std::string::npos && text.find('\n', at) != std::string::npos) {
        port_ = std::uint16_t(std::stoul(text.substr(at + 30)));
        line_ = text.substr(at, text.find('\n', at) - at);
        return;
      }
    }
    stop();
    throw std::runtime_error("vts cache serve did not start: " + text + stderr_text());
  }
  ~Daemon() { stop(); }
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // SIGTERM, then wait; returns the exit status (or -1).
  int stop() {
    if (pid_ <= 0) return exit_status_;
    ::kill(pid_, SIGTERM);
    int status = 0;
    for (int i = 0; i < 150; ++i) {
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        pid_ = -1;
        break;
      }
      std::this_thread::sleep_for(100ms);
    }
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, &status, 0);
      pid_ = -1;
    }
    if (out_ >= 0) ::close(out_);
    out_ = -1;
    return exit_status_;
  }
  std::uint16_t port() const { return port_; }
  std::string base() const { return "http://127.0.0.1:" + std::to_string(port_); }
  const std::string& line() const { return line_; }
  std::string stderr_text() const {
    std::ifstream in(log_);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }

 private:
  static inline int count_ = 0;
  pid_t pid_ = -1;
  int out_ = -1;
  std::uint16_t port_ = 0;
  int exit_status_ = -1;
  std::string line_;
  fs::path log_;
};

std::vector<std::string> daemon_args(const std::string& upstream, const fs::path& cache,
                                     std::vector<std::string> more = {}) {
  std::vector<std::string> a = {"--upstream", upstream,       "--cache-dir", cache.string(),
                                "--listen",   "127.0.0.1:0",  "--no-admin",  "--threads",
                                "2",          "--cache-size", "64M",         "--ram-size",
                                "16M"};
  a.insert(a.end(), more.begin(), more.end());
  return a;
}

fs::path fresh_cache_dir(const std::string& name) {
  const fs::path d = test_dir() / ("cache-" + name);
  std::error_code ec;
  fs::remove_all(d, ec);
  return d;
}

// A tile inside the pyramid of `a` that is not stored (for sparse archives).
std::optional<vts::TileId> missing_tile(const Archive& a) {
  const auto& g = a.info.geometry;
  for (int z = 0; z <= g.max_zoom(); ++z)
    for (std::uint32_t y = 0; y < g.tiles_y(std::uint8_t(z)); ++y)
      for (std::uint32_t x = 0; x < g.tiles_x(std::uint8_t(z)); ++x)
        if (!a.reader->get(vts::TileId{std::uint8_t(z), x, y}))
          return vts::TileId{std::uint8_t(z), x, y};
  return std::nullopt;
}

}  // namespace

// ================================================================================================
// The server hook, with a fake provider

TEST(AsyncTileProvider, ProvidedTilesGetTheSameHeadersAsArchiveTiles) {
  auto provider = std::make_shared<FakeProvider>(dense(), "prov");
  RunningServer server({dense().path}, provider);
  for (std::size_t i = 0; i < dense().tiles.size(); ++i) {
    const auto t = dense().tiles[i];
    // Alternate inline and late answers: both paths must give the same response.
    if (i % 2) provider->set_plan(t, {FakeProvider::Mode::delayed, 5ms});
    const Fetched a = fetch(server.base() + tile_path("syn", t));
    const Fetched p = fetch(server.base() + tile_path("prov", t));
    ASSERT_EQ(p.status, 200) << p.body;
    EXPECT_EQ(p.body, a.body);
    EXPECT_EQ(p.body, payload_of(dense(), t));
    for (const char* h : {"etag", "cache-control", "content-type", "content-length",
                          "access-control-allow-origin", "access-control-expose-headers"})
      EXPECT_EQ(p.header(h), a.header(h)) << h;
    const Fetched nm = fetch(server.base() + tile_path("prov", t), "W/" + a.header("etag"));
    EXPECT_EQ(nm.status, 304);
    EXPECT_EQ(nm.header("etag"), a.header("etag"));
    EXPECT_TRUE(nm.body.empty());
    const Fetched head = fetch(server.base() + tile_path("prov", t), {}, /*head=*/true);
    EXPECT_EQ(head.status, 200);
    EXPECT_EQ(head.header("content-length"), std::to_string(a.body.size()));
  }
  // Outside the pyramid: the router answers without asking the provider.
  const int calls = provider->calls();
  EXPECT_EQ(fetch(server.base() + "/prov/9/0/0").status, 404);
  EXPECT_EQ(fetch(server.base() + "/prov/0/5/0").status, 404);
  EXPECT_EQ(provider->calls(), calls);
  // TileJSON points at unversioned URLs of this server; the index lists both tilesets.
  const Fetched tj = fetch(server.base() + "/prov.json");
  EXPECT_EQ(tj.status, 200);
  EXPECT_NE(tj.body.find("\"" + server.base() + "/prov/{z}/{x}/{y}\""), std::string::npos)
      << tj.body;
  const Fetched index = fetch(server.base() + "/");
  EXPECT_NE(index.body.find("\"prov\""), std::string::npos);
  EXPECT_NE(index.body.find("\"syn\""), std::string::npos);
  EXPECT_EQ(fetch(server.base() + "/prov.pmtiles").status, 404);
  // Versioned URLs: the provider's version is accepted (not immutable), another is not current.
  const auto t0 = dense().tiles[0];
  const Fetched v = fetch(server.base() + tile_path("prov@fakeversion", t0));
  EXPECT_EQ(v.status, 200);
  EXPECT_EQ(v.header("cache-control").find("immutable"), std::string::npos);
  EXPECT_EQ(fetch(server.base() + tile_path("prov@other", t0)).status, 404);
}

TEST(AsyncTileProvider, StatusesForAbsentUnavailableAndBrokenTiles) {
  auto dense_p = std::make_shared<FakeProvider>(dense(), "prov");
  RunningServer server({}, dense_p);
  const auto t = dense().tiles.back();
  auto status_with = [&](FakeProvider::Plan plan) {
    dense_p->set_plan(t, plan);
    return fetch(server.base() + tile_path("prov", t));
  };
  using Kind = vts::ProvidedTile::Kind;
  using Mode = FakeProvider::Mode;
  EXPECT_EQ(status_with({Mode::inline_answer, 0ms, Kind::absent}).status, 404);
  const Fetched u = status_with({Mode::delayed, 2ms, Kind::unavailable});
  EXPECT_EQ(u.status, 503);
  EXPECT_NE(u.body.find("origin down"), std::string::npos);
  EXPECT_EQ(u.header("cache-control"), "no-store");
  EXPECT_EQ(u.header("access-control-allow-origin"), "*");
  EXPECT_EQ(status_with({Mode::inline_answer, 0ms, Kind::bad_origin}).status, 502);
  EXPECT_EQ(status_with({Mode::inline_answer, 0ms, std::nullopt, /*damage=*/true}).status, 502);

  // A sparse tileset's absent tile is known-empty: 204 with the tile Cache-Control.
  auto sparse_p = std::make_shared<FakeProvider>(sparse(), "holes");
  RunningServer server2({}, sparse_p);
  const auto hole = missing_tile(sparse());
  ASSERT_TRUE(hole);
  const Fetched e = fetch(server2.base() + tile_path("holes", *hole));
  EXPECT_EQ(e.status, 204);
  EXPECT_EQ(e.header("cache-control"), "public, max-age=3600");
  EXPECT_TRUE(e.body.empty());
}

TEST(AsyncTileProvider, PipelinedResponsesKeepRequestOrderWhenTilesCompleteOutOfOrder) {
  auto provider = std::make_shared<FakeProvider>(dense(), "prov");
  RunningServer server({dense().path}, provider);
  const auto& tiles = dense().tiles;
  ASSERT_GE(tiles.size(), 12u);
  std::vector<std::string> paths;
  for (std::size_t i = 0; i < 12; ++i) {
    // Earlier requests answer later: request i waits (12 - i) * 15 ms; every third answers at
    // once; archive tiles ("syn") are interleaved.
    if (i % 3 == 0)
      provider->set_plan(tiles[i], {FakeProvider::Mode::inline_answer});
    else
      provider->set_plan(tiles[i], {FakeProvider::Mode::delayed, (12 - i) * 15ms});
    paths.push_back(tile_path(i % 4 == 1 ? "syn" : "prov", tiles[i]));
  }
  const auto responses = pipelined(server.port(), paths);
  ASSERT_EQ(responses.size(), paths.size());
  for (std::size_t i = 0; i < paths.size(); ++i) {
    EXPECT_EQ(responses[i].status, 200) << i;
    EXPECT_EQ(responses[i].body, payload_of(dense(), tiles[i])) << "response " << i;
  }
}

TEST(AsyncTileProvider, AnswerArrivingAfterTheClientLeftIsDropped) {
  auto provider = std::make_shared<FakeProvider>(dense(), "prov");
  RunningServer server({}, provider);
  const auto t = dense().tiles[0];
  provider->set_plan(t, {FakeProvider::Mode::held});
  for (int i = 0; i < 3; ++i) {
    const int fd = connect_to(server.port());
    ASSERT_GE(fd, 0);
    ASSERT_TRUE(send_all(fd, "GET " + tile_path("prov", t) + " HTTP/1.1\r\nHost: a\r\n\r\n" +
                                 "GET " + tile_path("prov", t) + " HTTP/1.1\r\nHost: a\r\n\r\n"));
    ASSERT_TRUE(provider->wait_held(std::size_t(2 * (i + 1)), 5s));
    ::close(fd);
  }
  std::this_thread::sleep_for(50ms);  // the server notices the closes
  provider->release_held();           // six answers for connections that are gone
  provider->set_plan(t, {FakeProvider::Mode::delayed, 1ms});
  const Fetched f = fetch(server.base() + tile_path("prov", t));
  EXPECT_EQ(f.status, 200);
  EXPECT_EQ(f.body, payload_of(dense(), t));
  server.stop();  // drains without waiting for anything
}

// The provider learns that nobody waits any more: a connection closed, or half-closed, while its
// tiles are owed requests their abandon tokens; a connection still open does not.
TEST(AsyncTileProvider, TilesOwedToAClientThatLeftAreAbandoned) {
  auto provider = std::make_shared<FakeProvider>(dense(), "prov");
  RunningServer server({}, provider);
  const auto t = dense().tiles[0];
  provider->set_plan(t, {FakeProvider::Mode::held});
  const std::string get = "GET " + tile_path("prov", t) + " HTTP/1.1\r\nHost: a\r\n\r\n";
  const int stays = connect_to(server.port()), closes = connect_to(server.port()),
            half = connect_to(server.port());
  ASSERT_TRUE(stays >= 0 && closes >= 0 && half >= 0);
  ASSERT_TRUE(send_all(stays, get));
  ASSERT_TRUE(provider->wait_held(1, 5s));
  ASSERT_TRUE(send_all(closes, get + get));
  ASSERT_TRUE(provider->wait_held(3, 5s));
  ASSERT_TRUE(send_all(half, get));
  ASSERT_TRUE(provider->wait_held(4, 5s));
  ::close(closes);
  ::shutdown(half, SHUT_WR);
  const std::vector<bool> want = {false, true, true, true};
  const auto until = std::chrono::steady_clock::now() + 5s;
  while (provider->abandoned() != want && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(2ms);
  EXPECT_EQ(provider->abandoned(), want);
  provider->release_held();  // the connection still open gets its tile
  timeval tv{5, 0};
  ::setsockopt(stays, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  char buf[64] = {};
  ASSERT_GT(::recv(stays, buf, sizeof buf - 1, 0), 12);
  EXPECT_EQ(std::string(buf, 12), "HTTP/1.1 200");
  ::close(stays);
  ::close(half);
  server.stop();
}

TEST(AsyncTileProvider, StopWaitsForAnAnswerStillOwed) {
  auto provider = std::make_shared<FakeProvider>(dense(), "prov");
  auto server = std::make_unique<RunningServer>(std::vector<fs::path>{}, provider);
  const auto t = dense().tiles[1];
  provider->set_plan(t, {FakeProvider::Mode::delayed, 300ms});
  Fetched f;
  std::thread client([&] { f = fetch(server->base() + tile_path("prov", t)); });
  std::this_thread::sleep_for(100ms);
  server->stop();  // drains: the response still owed is written first
  client.join();
  EXPECT_EQ(f.status, 200);
  EXPECT_EQ(f.body, payload_of(dense(), t));
}

// ================================================================================================
// The daemon

TEST(CacheDaemon, ServesEveryTileByteExactWithTheOriginsETags) {
  RunningServer upstream({dense().path}, nullptr);
  Daemon d(daemon_args(upstream.base() + "/syn", fresh_cache_dir("exact")));
  EXPECT_NE(d.line().find("tileset syn from"), std::string::npos) << d.line();
  for (const auto& t : dense().tiles) {
    const Fetched origin = fetch(upstream.base() + tile_path("syn", t));
    const Fetched got = fetch(d.base() + tile_path("syn", t));
    ASSERT_EQ(got.status, 200) << got.body;
    EXPECT_EQ(got.body, payload_of(dense(), t)) << t.to_string();
    EXPECT_EQ(got.header("etag"), origin.header("etag"));
    EXPECT_EQ(got.header("cache-control"), origin.header("cache-control"));
    EXPECT_EQ(got.header("content-type"), origin.header("content-type"));
    EXPECT_EQ(fetch(d.base() + tile_path("syn", t), origin.header("etag")).status, 304);
  }
  // Second round: from the cache, still identical.
  for (const auto& t : dense().tiles)
    EXPECT_EQ(fetch(d.base() + tile_path("syn", t)).body, payload_of(dense(), t));
  const Fetched tj = fetch(d.base() + "/syn.json");
  EXPECT_EQ(tj.status, 200);
  EXPECT_NE(tj.body.find("\"" + d.base() + "/syn/{z}/{x}/{y}\""), std::string::npos) << tj.body;
  EXPECT_EQ(fetch(d.base() + "/syn/9/9/9").status, 404);
  EXPECT_EQ(fetch(d.base() + "/other/0/0/0").status, 404);
  EXPECT_EQ(d.stop(), 0);
}

TEST(CacheDaemon, SparseOriginsAbsentTileIs204) {
  RunningServer upstream({sparse().path}, nullptr);
  Daemon d(daemon_args(upstream.base() + "/holes.json", fresh_cache_dir("sparse")));
  const auto hole = missing_tile(sparse());
  ASSERT_TRUE(hole);
  EXPECT_EQ(fetch(d.base() + tile_path("holes", *hole)).status, 204);
  EXPECT_EQ(fetch(d.base() + tile_path("holes", *hole)).status, 204);  // remembered
  const auto t = sparse().tiles.back();
  EXPECT_EQ(fetch(d.base() + tile_path("holes", t)).body, payload_of(sparse(), t));
}

TEST(CacheDaemon, AnswersPipelinedRequestsInOrder) {
  RunningServer upstream({dense().path}, nullptr);
  Daemon d(daemon_args(upstream.base() + "/syn", fresh_cache_dir("pipeline")));
  const auto& tiles = dense().tiles;
  // Every other tile is cached first, so answers from RAM and from the origin interleave.
  for (std::size_t i = 0; i < tiles.size(); i += 2)
    ASSERT_EQ(fetch(d.base() + tile_path("syn", tiles[i])).status, 200);
  std::vector<std::string> paths;
  std::vector<vts::TileId> want;
  for (std::size_t i = tiles.size(); i-- > 0;) {  // finest (uncached, slower) first
    paths.push_back(tile_path("syn", tiles[i]));
    want.push_back(tiles[i]);
  }
  const auto responses = pipelined(d.port(), paths);
  ASSERT_EQ(responses.size(), paths.size());
  for (std::size_t i = 0; i < paths.size(); ++i) {
    EXPECT_EQ(responses[i].status, 200) << responses[i].head;
    EXPECT_EQ(responses[i].body, payload_of(dense(), want[i])) << "response " << i;
  }
}

TEST(CacheDaemon, ServesCachedTilesOfflineAndStartsOfflineFromTheSavedSource) {
  auto upstream = std::make_unique<RunningServer>(std::vector<fs::path>{dense().path}, nullptr);
  const std::uint16_t port = upstream->port();
  const std::string origin = upstream->base() + "/syn";
  const fs::path cache = fresh_cache_dir("offline");
  const auto& tiles = dense().tiles;
  const std::size_t half = tiles.size() / 2;
  auto d = std::make_unique<Daemon>(daemon_args(origin, cache));
  for (std::size_t i = 0; i < half; ++i)
    ASSERT_EQ(fetch(d->base() + tile_path("syn", tiles[i])).status, 200);

  // The origin goes away: cached tiles still come, byte-exact; the others are 503.
  upstream->stop();
  for (std::size_t i = 0; i < half; ++i)
    EXPECT_EQ(fetch(d->base() + tile_path("syn", tiles[i])).body, payload_of(dense(), tiles[i]));
  const Fetched miss = fetch(d->base() + tile_path("syn", tiles.back()));
  EXPECT_EQ(miss.status, 503);
  EXPECT_EQ(miss.header("cache-control"), "no-store");
  EXPECT_EQ(d->stop(), 0);

  // A new daemon with the origin down starts from the saved SourceInfo and serves the cache.
  d = std::make_unique<Daemon>(daemon_args(origin, cache, {"--reconnect-interval", "1"}));
  EXPECT_NE(d->line().find("offline"), std::string::npos) << d->line();
  EXPECT_NE(d->stderr_text().find("unavailable"), std::string::npos);
  for (std::size_t i = 0; i < half; ++i) {
    const Fetched f = fetch(d->base() + tile_path("syn", tiles[i]));
    EXPECT_EQ(f.status, 200);
    EXPECT_EQ(f.body, payload_of(dense(), tiles[i]));
  }
  const Fetched tj = fetch(d->base() + "/syn.json");
  EXPECT_EQ(tj.status, 200);
  EXPECT_NE(tj.body.find("\"max_zoom\": " + std::to_string(dense().info.geometry.max_zoom())),
            std::string::npos);
  EXPECT_EQ(fetch(d->base() + tile_path("syn", tiles.back())).status, 503);

  // The origin comes back on its port: the daemon reconnects and fetches again.
  upstream = std::make_unique<RunningServer>(std::vector<fs::path>{dense().path}, nullptr, port);
  Fetched back;
  for (int i = 0; i < 60; ++i) {
    back = fetch(d->base() + tile_path("syn", tiles.back()));
    if (back.status == 200) break;
    std::this_thread::sleep_for(100ms);
  }
  EXPECT_EQ(back.status, 200);
  EXPECT_EQ(back.body, payload_of(dense(), tiles.back()));
  EXPECT_EQ(d->stop(), 0);
}

TEST(CacheDaemon, WithoutOriginOrSavedSourceItExitsWithAnError) {
  RunningServer upstream({dense().path}, nullptr);
  const std::string gone = upstream.base() + "/syn";
  upstream.stop();
  EXPECT_THROW([&] { Daemon d(daemon_args(gone, fresh_cache_dir("never"))); }(),
               std::runtime_error);
}

TEST(CacheDaemon, TwoDaemonsShareOneCacheDir) {
  auto upstream = std::make_unique<RunningServer>(std::vector<fs::path>{dense().path}, nullptr);
  const std::string origin = upstream->base() + "/syn";
  const fs::path cache = fresh_cache_dir("shared");
  Daemon a(daemon_args(origin, cache));
  Daemon b(daemon_args(origin, cache));
  const auto& tiles = dense().tiles;
  // Each fetches half; then, with the origin gone, each serves the other's half from disk.
  for (std::size_t i = 0; i < tiles.size(); ++i) {
    Daemon& d = i % 2 ? a : b;
    ASSERT_EQ(fetch(d.base() + tile_path("syn", tiles[i])).status, 200);
  }
  upstream->stop();
  for (std::size_t i = 0; i < tiles.size(); ++i) {
    Daemon& d = i % 2 ? b : a;
    Fetched f;
    // The other daemon's disk write trails its response by a little.
    for (int k = 0; k < 50; ++k) {
      f = fetch(d.base() + tile_path("syn", tiles[i]));
      if (f.status == 200) break;
      std::this_thread::sleep_for(50ms);
    }
    EXPECT_EQ(f.status, 200) << tiles[i].to_string() << ": " << f.body;
    EXPECT_EQ(f.body, payload_of(dense(), tiles[i]));
  }
  EXPECT_EQ(a.stop(), 0);
  EXPECT_EQ(b.stop(), 0);
}
