// Boost.Beast implementation of HttpServer; the contract is in http_server.hpp.
#include "vts/server/http_server.hpp"

#include <sys/sendfile.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <algorithm>
#include <array>
#include <atomic>
#include <boost/asio/bind_executor.hpp>
#include <boost/asio/dispatch.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/http.hpp>
#include <cassert>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <deque>
#include <memory_resource>
#include <mutex>
#include <optional>
#include <span>
#include <thread>
#include <unordered_map>
#include <vector>

namespace vts {

namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;
using Clock = std::chrono::steady_clock;  // latencies

// Deadlines (seconds long, enforced by a sweep every 10-250 ms) need no nanoseconds: the coarse
// monotonic clock is read from the vDSO without touching the TSC, and a request reads it ~4 times.
struct DeadlineClock {
  using duration = std::chrono::nanoseconds;
  using rep = duration::rep;
  using period = duration::period;
  using time_point = std::chrono::time_point<DeadlineClock>;
  static constexpr bool is_steady = true;
  static time_point now() noexcept {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC_COARSE, &ts);
    return time_point(std::chrono::seconds(ts.tv_sec) + std::chrono::nanoseconds(ts.tv_nsec));
  }
};

// ---- metrics ---------------------------------------------------------------------------------

constexpr std::array<int, 17> kStatuses = {200, 204, 206, 304, 400, 401, 403, 404, 405,
                                           413, 414, 416, 431, 500, 502, 503, 0};
constexpr int kRouteCount = 7;  // Route values + admin
constexpr std::array<double, 16> kBuckets = {0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005,
                                             0.01,   0.025,   0.05,   0.1,   0.25,   0.5,
                                             1.0,    2.5,     5.0,    10.0};

int status_index(int status) {
  for (std::size_t i = 0; i + 1 < kStatuses.size(); ++i)
    if (kStatuses[i] == status) return int(i);
  return int(kStatuses.size()) - 1;  // "other"
}

const char* route_label(int r) {
  return r < 6 ? route_name(Route(r)) : "admin";
}

struct Metrics {
  std::array<std::array<std::atomic<std::uint64_t>, kStatuses.size()>, kRouteCount> requests{};
  std::array<std::atomic<std::uint64_t>, kBuckets.size() + 1> buckets{};  // last = +Inf
  std::atomic<std::uint64_t> duration_us_sum{0};
  std::atomic<std::uint64_t> response_bytes{0};
  std::atomic<std::int64_t> open_connections{0};
  std::atomic<std::uint64_t> reloads_swapped{0}, reloads_refused{0};
  std::atomic<std::uint64_t> refused_connections{0};

  void record(int route, int status, std::uint64_t bytes, Clock::duration d) {
    requests[std::size_t(route)][std::size_t(status_index(status))].fetch_add(
        1, std::memory_order_relaxed);
    response_bytes.fetch_add(bytes, std::memory_order_relaxed);
    const double s = std::chrono::duration<double>(d).count();
    std::size_t b = 0;
    while (b < kBuckets.size() && s > kBuckets[b]) ++b;
    buckets[b].fetch_add(1, std::memory_order_relaxed);
    duration_us_sum.fetch_add(
        std::uint64_t(std::chrono::duration_cast<std::chrono::microseconds>(d).count()),
        std::memory_order_relaxed);
  }
};

// ---- small helpers -------------------------------------------------------------------------

// One pass with no calls (find_first_of calls memchr once per character of its set).
bool has_line_break(std::string_view s) {
  bool found = false;
  for (const char c : s) found |= (c == '\r') | (c == '\n');
  return found;
}

// RFC 9110 IMF-fixdate, cached per second per thread.
std::string_view http_date() {
  thread_local std::time_t cached = 0;
  thread_local char buf[40];
  const std::time_t now = std::time(nullptr);
  if (now != cached) {
    std::tm tm{};
    gmtime_r(&now, &tm);
    std::strftime(buf, sizeof buf, "%a, %d %b %Y %H:%M:%S GMT", &tm);
    cached = now;
  }
  return buf;
}

std::string json_escape(std::string_view s) {
  std::string out;
  out.reserve(s.size() + 2);
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20 || u >= 0x7f) {
      char b[8];
      std::snprintf(b, sizeof b, "\\u%04x", u);
      out += b;
    } else {
      out += c;
    }
  }
  return out;
}

HttpMethod to_method(http::verb v) {
  switch (v) {
    case http::verb::get:
      return HttpMethod::get;
    case http::verb::head:
      return HttpMethod::head;
    case http::verb::options:
      return HttpMethod::options;
    default:
      return HttpMethod::other;
  }
}

// Request header fields live in a per-connection arena, reset after each request: Beast allocates
// every field separately, which would be a malloc and a free per field per request.
using FieldAllocator = std::pmr::polymorphic_allocator<char>;
using RequestParser = http::request_parser<http::empty_body, FieldAllocator>;

// The header fields the router reads, in one pass (the first of repeated fields wins).
void read_fields(const RequestParser::value_type& req, HttpRequest& hr) {
  for (const auto& f : req) {
    std::string_view* slot = nullptr;
    switch (f.name()) {
      case http::field::host:
        slot = &hr.host;
        break;
      case http::field::if_none_match:
        slot = &hr.if_none_match;
        break;
      case http::field::range:
        slot = &hr.range;
        break;
      case http::field::if_range:
        slot = &hr.if_range;
        break;
      case http::field::origin:
        slot = &hr.origin;
        break;
      case http::field::authorization:
        slot = &hr.authorization;
        break;
      case http::field::access_control_request_method:
        slot = &hr.access_control_request_method;
        break;
      default:
        continue;
    }
    if (slot->data() != nullptr) continue;
    const auto v = f.value();
    *slot = v.empty() ? std::string_view("", 0) : std::string_view(v.data(), v.size());
  }
}

HttpResponse plain_response(int status, std::string body) {
  HttpResponse r;
  r.status = status;
  r.route = Route::error;
  r.headers.emplace_back("Content-Type", "text/plain; charset=utf-8");
  r.owned = std::move(body);
  r.content_length = r.owned.size();
  return r;
}

class Server;

// ---- one connection -------------------------------------------------------------------------

// A response is written as its serialised header plus its body, without copying the body: a body
// from an archive goes out with sendfile(2) from the archive's file (the kernel hands page-cache
// pages to the socket), the header just before it with MSG_MORE so both leave in one segment;
// any other body (`response.owned`) goes out with the header in one gathered write.

struct Outgoing {
  HttpResponse response;
  std::uint64_t seq = 0;  // position in the connection's request order
  bool ready = true;      // false while a provided tile is awaited (head and body not built yet)
  std::string head;       // status line and header fields, CRLF CRLF
  std::span<const char> body;  // empty for HEAD, 204 and 304
  int file_fd = -1;            // >= 0: send `body` with sendfile from this file ...
  off_t file_offset = 0;       // ... at this offset (where `body` lies in the mapping)
  std::size_t sent = 0;        // bytes of head + body written so far
  Clock::time_point start;
  DeadlineClock::time_point
      deadline{};  // set when writing starts: the whole response must be out by then
  int route = 0;
  bool close = false;
  bool keep_alive_header = false;  // HTTP/1.0 client that asked for keep-alive
  // For the access log (only filled when it is on).
  std::string method, target, tileset;

  std::size_t total() const { return head.size() + body.size(); }
};

class Session;

// The deadlines of one thread's connections, checked by one periodic timer on that thread. A
// timer per connection would be armed and cancelled several times per request, each time a
// scheduler round trip and often a timerfd update; a sweep costs a compare per connection.
class Sweeper {
 public:
  // Sweepers outlive their io_context (sessions destroyed with it still remove themselves);
  // their timer does not: the server drops it with release() before the io_context goes.
  Sweeper(asio::io_context& ioc, std::chrono::milliseconds period)
      : ioc_(ioc), timer_(std::in_place, ioc), period_(period) {}
  asio::io_context& context() { return ioc_; }
  void start() {
    asio::post(ioc_, [this] { schedule(); });
  }
  // Stops sweeping (from any thread); the timer then no longer keeps the io_context busy.
  void stop() {
    asio::post(ioc_, [this] {
      stopped_ = true;
      timer_->cancel();
    });
  }
  void release() {
    stopped_ = true;
    timer_.reset();
  }
  // add() on the connection's thread; remove() from its destructor, wherever that runs. O(1).
  void add(Session* s);
  void remove(Session* s);

 private:
  void schedule() {
    if (stopped_) return;
    timer_->expires_after(period_);
    timer_->async_wait([this](beast::error_code ec) {
      if (ec || stopped_) return;
      sweep();
      schedule();
    });
  }
  void sweep();

  asio::io_context& ioc_;
  std::optional<asio::steady_timer> timer_;
  std::chrono::milliseconds period_;
  bool stopped_ = false;
  std::mutex mutex_;
  std::vector<Session*> sessions_;
};

class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(Server& server, Sweeper& sweeper, tcp::socket socket, bool admin);
  ~Session();
  // On the connection's thread: closes the connection when a deadline has passed. The idle
  // deadline does not count while responses are owed (the client waits for us, not idle).
  void check_deadlines(DeadlineClock::time_point now) {
    if (!socket_.is_open()) return;
    const bool owed = idle_wait_ && !queue_.empty();
    if ((now >= read_deadline_ && !owed) || now >= write_deadline_) close();
  }
  std::size_t sweep_slot = 0;  // position in the Sweeper's list
  void start();
  // Called (on the strand) when the server stops: close now if nothing is queued.
  void on_server_stop();

 private:
  void wait_for_request();
  void read_request();
  void on_read(beast::error_code ec);
  void enqueue(std::unique_ptr<Outgoing> out);
  void prepare(Outgoing& o);
  void start_deferred(const Outgoing& o);
  void finish_deferred(std::uint64_t seq, ProvidedTile tile);
  void write_next();
  std::size_t write_some(Outgoing& o, beast::error_code& ec);
  bool complete_front();
  void fail_parse(int status, const char* message);
  // Deadlines, enforced by the connection's thread's Sweeper (expiry closes the connection).
  void set_read_deadline(std::chrono::milliseconds d) { read_deadline_ = DeadlineClock::now() + d; }
  void clear_read_deadline() { read_deadline_ = DeadlineClock::time_point::max(); }
  void close();
  void linger_close();
  void drain_input();
  // Outgoing objects are reused (with their header buffer): a keep-alive connection allocates
  // neither for each request.
  std::unique_ptr<Outgoing> new_outgoing() {
    return spare_ ? std::move(spare_) : std::make_unique<Outgoing>();
  }
  void recycle(std::unique_ptr<Outgoing> o) {
    std::string head = std::move(o->head);
    head.clear();
    *o = Outgoing{};  // releases what the response held (mapping, provided tile)
    o->head = std::move(head);
    spare_ = std::move(o);
  }

  Server& server_;
  tcp::socket socket_;
  bool admin_;
  Sweeper& sweeper_;
  DeadlineClock::time_point read_deadline_ = DeadlineClock::time_point::max();
  DeadlineClock::time_point write_deadline_ = DeadlineClock::time_point::max();
  beast::flat_buffer buffer_;
  std::array<std::byte, 2048> field_buffer_;
  std::pmr::monotonic_buffer_resource fields_{field_buffer_.data(), field_buffer_.size()};
  std::optional<RequestParser> parser_;
  std::deque<std::unique_ptr<Outgoing>> queue_;
  std::unique_ptr<Outgoing> spare_;
  bool reading_ = false;      // a read (wait or header) is outstanding
  bool read_paused_ = false;  // stopped reading because the pipeline is full
  bool read_done_ = false;    // no more requests will be read (close requested / error / EOF)
  bool writing_ = false;      // waiting for the socket to accept more
  bool in_write_ = false;     // inside write_next()
  bool closed_ = false;
  bool idle_wait_ = false;      // the outstanding read waits for the first byte of a request
  std::uint64_t next_seq_ = 0;  // of the next response queued
  std::string remote_;
};

// ---- the server -----------------------------------------------------------------------------

class Server final : public HttpServer {
 public:
  Server(HttpServerOptions options, std::shared_ptr<TilesetRegistry> registry)
      : options_(std::move(options)),
        registry_(std::move(registry)),
        ioc_(1),
        acceptor_(ioc_),
        admin_acceptor_(ioc_),
        signals_(ioc_),
        strand_(asio::make_strand(ioc_)),
        drain_timer_(strand_) {
    const int n = options_.threads > 0 ? options_.threads
                                       : std::max(1, int(std::thread::hardware_concurrency()));
    for (int i = 1; i < n; ++i) workers_.push_back(std::make_unique<asio::io_context>(1));
    // Deadline sweeps at an eighth of the shortest timeout (so a deadline is enforced within
    // 12.5% of its length), between 10 ms and 250 ms.
    const auto& l = options_.limits;
    const auto shortest = std::min({l.idle_timeout, l.header_timeout, l.write_timeout});
    const auto period =
        std::clamp(shortest / 8, std::chrono::milliseconds(10), std::chrono::milliseconds(250));
    sweepers_.push_back(std::make_unique<Sweeper>(ioc_, period));
    for (auto& w : workers_) sweepers_.push_back(std::make_unique<Sweeper>(*w, period));
    if (!options_.access_log.empty()) {
      if (options_.access_log == "-") {
        log_ = stdout;
      } else {
        log_ = std::fopen(options_.access_log.c_str(), "a");
        owns_log_ = log_ != nullptr;
      }
    }
  }
  ~Server() override {
    destroying_ = true;
    beast::error_code ec;
    acceptor_.close(ec);
    admin_acceptor_.close(ec);
    // Sessions still pending (after a drain timeout) die with the io_contexts, while what they
    // use lives (declared earlier); the sweep timers go first, while their io_contexts live.
    for (auto& sw : sweepers_) sw->release();
    if (owns_log_) std::fclose(log_);
  }

  Status bind() {
    if (options_.access_log.size() && !log_)
      return make_error(ErrorCode::io, "cannot open access log '" + options_.access_log + "'");
    if (auto st = bind_one(acceptor_, options_.listen_host, options_.listen_port); !st.ok())
      return st;
    if (options_.admin_enabled)
      if (auto st = bind_one(admin_acceptor_, options_.admin_host, options_.admin_port); !st.ok())
        return st;
    return {};
  }

  std::uint16_t port() const override { return acceptor_.local_endpoint().port(); }
  std::uint16_t admin_port() const override {
    return options_.admin_enabled ? admin_acceptor_.local_endpoint().port() : 0;
  }
  void set_ready(bool ready) override { ready_.store(ready); }

  void run() override {
    for (auto& sw : sweepers_) sw->start();
    accept(acceptor_, false);
    if (options_.admin_enabled) accept(admin_acceptor_, true);
    if (options_.handle_signals) {
      signals_.add(SIGTERM);
      signals_.add(SIGINT);
      signals_.add(SIGHUP);
      wait_signal();
    }
    std::thread reloader([this] { reload_loop(); });
    std::vector<std::thread> threads;
    for (auto& w : workers_) {
      guards_.push_back(asio::make_work_guard(*w));
      threads.emplace_back([&w] { w->run(); });
    }
    ioc_.run();
    for (auto& t : threads) t.join();
    {
      std::lock_guard lock(reload_mutex_);
      reload_quit_ = true;
    }
    reload_cv_.notify_all();
    reloader.join();
  }

  void stop() override {
    // On the server strand, so the drain timer is never touched by two threads at once.
    asio::post(strand_, [this] {
      if (stopping_.exchange(true)) return;
      std::fprintf(stderr, "vts serve: stopping; draining open connections\n");
      beast::error_code ec;
      acceptor_.close(ec);
      admin_acceptor_.close(ec);
      signals_.cancel(ec);
      {
        std::lock_guard lock(reload_mutex_);
        reload_quit_ = true;
      }
      reload_cv_.notify_all();
      std::vector<std::weak_ptr<Session>> sessions;
      {
        std::lock_guard lock(sessions_mutex_);
        for (auto& [p, w] : sessions_) sessions.push_back(w);
      }
      for (auto& w : sessions)
        if (auto s = w.lock()) s->on_server_stop();
      drain_timer_.expires_after(options_.limits.drain_timeout);
      drain_timer_.async_wait([this](beast::error_code e) {
        if (e) return;
        std::fprintf(stderr, "vts serve: drain timeout; closing remaining connections\n");
        ioc_.stop();
        for (auto& w : workers_) w->stop();
      });
      std::lock_guard lock(sessions_mutex_);
      if (sessions_.empty()) drained();
    });
  }

  void request_reload(bool force) override {
    {
      std::lock_guard lock(reload_mutex_);
      reload_pending_ = true;
      reload_force_ = reload_force_ || force;
    }
    reload_cv_.notify_all();
  }

  std::string metrics_text() const override;

  // -- used by sessions --
  const HttpServerOptions& options() const { return options_; }
  const TilesetRegistry& registry() const { return *registry_; }
  AsyncTileProvider* provider() const { return options_.provider.get(); }
  Metrics& metrics() { return metrics_; }
  bool stopping() const { return stopping_.load(std::memory_order_relaxed); }
  FILE* access_log() const { return log_; }
  std::mutex& log_mutex() { return log_mutex_; }

  void add_session(const std::shared_ptr<Session>& s) {
    std::lock_guard lock(sessions_mutex_);
    sessions_.emplace(s.get(), s);
  }
  void remove_session(Session* s) {
    bool last = false;
    {
      std::lock_guard lock(sessions_mutex_);
      sessions_.erase(s);
      last = sessions_.empty();
    }
    // When drained, nothing keeps the io_context busy but the drain timer.
    if (last && stopping() && !destroying_) asio::post(strand_, [this] { drained(); });
  }

  HttpResponse admin_route(const HttpRequest& req) {
    const std::string_view path = req.target.substr(0, req.target.find('?'));
    if (req.method != HttpMethod::get && req.method != HttpMethod::head) {
      HttpResponse r = plain_response(405, "method not allowed\n");
      r.headers.emplace_back("Allow", "GET, HEAD");
      r.head_only = req.method == HttpMethod::head;
      return r;
    }
    HttpResponse r;
    if (path == "/metrics") {
      r = plain_response(200, metrics_text());
      r.headers[0].second = "text/plain; version=0.0.4; charset=utf-8";
    } else if (path == "/health") {
      r = ready_.load() ? plain_response(200, "ok\n") : plain_response(503, "loading\n");
    } else {
      r = plain_response(404, "not found\n");
    }
    r.headers.emplace_back("Cache-Control", "no-store");
    r.head_only = req.method == HttpMethod::head;
    return r;
  }

 private:
  Status bind_one(tcp::acceptor& acc, const std::string& host, std::uint16_t port) {
    beast::error_code ec;
    const auto addr = asio::ip::make_address(host == "localhost" ? "127.0.0.1" : host, ec);
    if (ec) return make_error(ErrorCode::invalid_argument, "bad listen address '" + host + "'");
    const tcp::endpoint ep(addr, port);
    acc.open(ep.protocol(), ec);
    if (!ec) acc.set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acc.bind(ep, ec);
    if (!ec) acc.listen(asio::socket_base::max_listen_connections, ec);
    if (ec)
      return make_error(ErrorCode::io, "cannot listen on " + host + ":" + std::to_string(port) +
                                           ": " + ec.message());
    return {};
  }

  // On strand_, once every session is gone: nothing keeps any io_context busy any more.
  void drained() {
    drain_timer_.cancel();
    for (auto& sw : sweepers_) sw->stop();
    guards_.clear();
  }

  // One io_context per thread (each run by exactly one thread, so a connection's handlers are
  // serialised without a strand and the scheduler never contends); connections are dealt out
  // round-robin.
  Sweeper& next_context() { return *sweepers_[next_context_++ % sweepers_.size()]; }

  void accept(tcp::acceptor& acc, bool admin) {
    Sweeper& slot = next_context();
    acc.async_accept(
        slot.context(), [this, &acc, &slot, admin](beast::error_code ec, tcp::socket socket) {
          if (ec == asio::error::operation_aborted || !acc.is_open()) return;
          if (ec) {
            // EMFILE and friends: back off briefly rather than spin.
            std::fprintf(stderr, "vts serve: accept: %s\n", ec.message().c_str());
            auto t = std::make_shared<asio::steady_timer>(ioc_, std::chrono::milliseconds(50));
            t->async_wait([this, &acc, admin, t](beast::error_code) { accept(acc, admin); });
            return;
          }
          if (std::size_t(metrics_.open_connections.load()) >= options_.limits.max_connections) {
            metrics_.refused_connections.fetch_add(1, std::memory_order_relaxed);
            beast::error_code ignored;
            socket.close(ignored);
          } else {
            auto s = std::make_shared<Session>(*this, slot, std::move(socket), admin);
            add_session(s);
            s->start();
          }
          accept(acc, admin);
        });
  }

  void wait_signal() {
    signals_.async_wait([this](beast::error_code ec, int sig) {
      if (ec) return;
      if (sig == SIGHUP) {
        std::fprintf(stderr, "vts serve: SIGHUP: reloading every tileset\n");
        request_reload(true);
        wait_signal();
      } else {
        stop();
      }
    });
  }

  void reload_loop() {
    std::unique_lock lock(reload_mutex_);
    while (!reload_quit_) {
      if (options_.reload_interval.count() > 0)
        reload_cv_.wait_for(lock, options_.reload_interval,
                            [this] { return reload_quit_ || reload_pending_; });
      else
        reload_cv_.wait(lock, [this] { return reload_quit_ || reload_pending_; });
      if (reload_quit_) break;
      const bool force = reload_force_;
      reload_pending_ = reload_force_ = false;
      lock.unlock();
      auto result = registry_->reload(force);
      if (result.swapped > 0) {
        metrics_.reloads_swapped.fetch_add(std::uint64_t(result.swapped));
        std::fprintf(stderr, "vts serve: reloaded %d tileset(s)\n", result.swapped);
      }
      if (result.added > 0)
        std::fprintf(stderr, "vts serve: added %d new tileset(s)\n", result.added);
      if (result.removed > 0)
        std::fprintf(stderr, "vts serve: removed %d tileset(s) whose archive left its folder\n",
                     result.removed);
      for (const auto& e : result.failures) {
        metrics_.reloads_refused.fetch_add(1);
        std::fprintf(stderr, "vts serve: reload refused, keeping the old archive: %s\n",
                     e.to_string().c_str());
      }
      lock.lock();
    }
  }

  // Declared before the io_context so that they outlive it: destroying the io_context destroys
  // pending handlers, and with them sessions, which touch the metrics and the session table.
  HttpServerOptions options_;
  std::shared_ptr<TilesetRegistry> registry_;
  std::atomic<bool> stopping_{false}, ready_{false}, destroying_{false};
  Metrics metrics_;
  std::mutex sessions_mutex_;
  std::unordered_map<Session*, std::weak_ptr<Session>> sessions_;
  std::mutex reload_mutex_;
  std::condition_variable reload_cv_;
  bool reload_quit_ = false, reload_pending_ = false, reload_force_ = false;
  FILE* log_ = nullptr;
  bool owns_log_ = false;
  std::mutex log_mutex_;

  std::vector<std::unique_ptr<Sweeper>> sweepers_;  // [0] for ioc_, then one per worker
  asio::io_context ioc_;
  std::vector<std::unique_ptr<asio::io_context>> workers_;
  std::vector<asio::executor_work_guard<asio::io_context::executor_type>> guards_;
  std::size_t next_context_ = 0;  // only touched by accept handlers, which run on ioc_'s thread
  tcp::acceptor acceptor_, admin_acceptor_;
  asio::signal_set signals_;
  asio::strand<asio::io_context::executor_type> strand_;
  asio::steady_timer drain_timer_;
};

std::string Server::metrics_text() const {
  std::string out;
  out.reserve(8192);
  char line[256];
  out +=
      "# HELP vts_http_requests_total HTTP requests answered, by route and status.\n"
      "# TYPE vts_http_requests_total counter\n";
  for (int r = 0; r < kRouteCount; ++r)
    for (std::size_t s = 0; s < kStatuses.size(); ++s) {
      const auto n = metrics_.requests[std::size_t(r)][s].load(std::memory_order_relaxed);
      if (n == 0) continue;
      const std::string status = kStatuses[s] ? std::to_string(kStatuses[s]) : "other";
      std::snprintf(line, sizeof line, "vts_http_requests_total{route=\"%s\",status=\"%s\"} %llu\n",
                    route_label(r), status.c_str(), (unsigned long long)n);
      out += line;
    }
  out +=
      "# HELP vts_http_request_duration_seconds Time from a parsed request to its last byte "
      "written.\n"
      "# TYPE vts_http_request_duration_seconds histogram\n";
  std::uint64_t cumulative = 0;
  for (std::size_t b = 0; b <= kBuckets.size(); ++b) {
    cumulative += metrics_.buckets[b].load(std::memory_order_relaxed);
    if (b < kBuckets.size())
      std::snprintf(line, sizeof line, "vts_http_request_duration_seconds_bucket{le=\"%g\"} %llu\n",
                    kBuckets[b], (unsigned long long)cumulative);
    else
      std::snprintf(line, sizeof line,
                    "vts_http_request_duration_seconds_bucket{le=\"+Inf\"} %llu\n",
                    (unsigned long long)cumulative);
    out += line;
  }
  std::snprintf(line, sizeof line,
                "vts_http_request_duration_seconds_sum %.6f\n"
                "vts_http_request_duration_seconds_count %llu\n",
                double(metrics_.duration_us_sum.load()) * 1e-6, (unsigned long long)cumulative);
  out += line;
  // One unlabelled sample with its HELP and TYPE lines.
  auto single = [&out](const char* name, const char* type, const char* help, double value) {
    char buf[320];
    std::snprintf(buf, sizeof buf, "# HELP %s %s\n# TYPE %s %s\n%s %.17g\n", name, help, name, type,
                  name, value);
    out += buf;
  };
  single("vts_http_response_bytes_total", "counter", "Response bytes written (headers and bodies).",
         double(metrics_.response_bytes.load()));
  single("vts_http_open_connections", "gauge", "Open client connections.",
         double(metrics_.open_connections.load()));
  single("vts_http_refused_connections_total", "counter",
         "Connections closed at once because max_connections were open.",
         double(metrics_.refused_connections.load()));
  const std::size_t provided = options_.provider ? options_.provider->all().size() : 0;
  single("vts_tilesets_loaded", "gauge", "Tilesets being served.",
         double(registry_->size() + provided));
  std::snprintf(line, sizeof line,
                "# HELP vts_reloads_total Archive reloads, by result.\n"
                "# TYPE vts_reloads_total counter\n"
                "vts_reloads_total{result=\"swapped\"} %llu\n"
                "vts_reloads_total{result=\"refused\"} %llu\n",
                (unsigned long long)metrics_.reloads_swapped.load(),
                (unsigned long long)metrics_.reloads_refused.load());
  out += line;
  if (options_.provider) out += options_.provider->metrics_text();
  return out;
}

// ---- Sweeper implementation -------------------------------------------------------------------

void Sweeper::add(Session* s) {
  std::lock_guard lock(mutex_);
  s->sweep_slot = sessions_.size();
  sessions_.push_back(s);
}

void Sweeper::remove(Session* s) {
  std::lock_guard lock(mutex_);
  const std::size_t i = s->sweep_slot;
  if (i >= sessions_.size() || sessions_[i] != s) return;
  sessions_[i] = sessions_.back();
  sessions_[i]->sweep_slot = i;
  sessions_.pop_back();
}

void Sweeper::sweep() {
  const auto now = DeadlineClock::now();
  std::lock_guard lock(mutex_);
  // close() only closes the socket; no session is destroyed (or removed) during the loop.
  for (Session* s : sessions_) s->check_deadlines(now);
}

// ---- Session implementation ------------------------------------------------------------------

Session::Session(Server& server, Sweeper& sweeper, tcp::socket socket, bool admin)
    : server_(server), socket_(std::move(socket)), admin_(admin), sweeper_(sweeper) {
  sweeper_.add(this);
  server_.metrics().open_connections.fetch_add(1, std::memory_order_relaxed);
  beast::error_code ec;
  socket_.set_option(tcp::no_delay(true), ec);
  socket_.native_non_blocking(true, ec);  // write_some() sends with plain syscalls
  if (server_.access_log()) {
    const auto ep = socket_.remote_endpoint(ec);
    if (!ec) remote_ = ep.address().to_string() + ":" + std::to_string(ep.port());
  }
}

Session::~Session() {
  sweeper_.remove(this);
  server_.metrics().open_connections.fetch_sub(1, std::memory_order_relaxed);
  server_.remove_session(this);
}

void Session::start() {
  asio::dispatch(socket_.get_executor(), [self = shared_from_this()] {
    if (self->server_.stopping()) return self->close();
    self->wait_for_request();
  });
}

void Session::on_server_stop() {
  asio::post(socket_.get_executor(), [self = shared_from_this()] {
    self->read_done_ = true;
    if (!self->queue_.empty()) return;  // the writer closes after the last queued response
    // Idle: close at once — unless input is waiting (pipelined requests we will not answer),
    // where a plain close would reset the connection and could destroy the last response still
    // in the socket buffer.
    beast::error_code ec;
    if (self->buffer_.size() == 0 && self->socket_.available(ec) == 0 && !ec)
      self->close();
    else
      self->linger_close();
  });
}

// Hard close (timeouts, errors, idle connections): pending operations complete with an error.
void Session::close() {
  closed_ = true;
  read_done_ = true;
  beast::error_code ec;
  socket_.close(ec);
  clear_read_deadline();
  write_deadline_ = DeadlineClock::time_point::max();
}

// Close after the last response: send FIN, then read and discard whatever the client still sends
// (pipelined requests we will not answer, a refused body) until it closes or kLinger passes.
// Closing a socket with unread input makes the kernel send RST, which can destroy the response
// bytes the client has not read yet (the "lingering close" of RFC 9112 §9.6).
void Session::linger_close() {
  constexpr std::chrono::milliseconds kLinger{2000};
  if (closed_) return;
  closed_ = true;
  read_done_ = true;
  write_deadline_ = DeadlineClock::time_point::max();
  beast::error_code ec;
  socket_.shutdown(tcp::socket::shutdown_send, ec);
  if (ec) return close();
  socket_.cancel(ec);  // a read still waiting for a request we will not serve
  set_read_deadline(kLinger);
  drain_input();
}

void Session::drain_input() {
  static thread_local char scratch[4096];
  socket_.async_read_some(asio::buffer(scratch),
                          [self = shared_from_this()](beast::error_code ec, std::size_t) {
                            if (ec == asio::error::operation_aborted && self->socket_.is_open())
                              return;  // the cancelled earlier read; this chain continues
                            if (ec) return self->close();
                            self->drain_input();
                          });
}

// Waits (idle timeout) for the first byte of the next request; the header then has its own
// deadline, so a client that trickles a header cannot hold the connection for idle_timeout.
void Session::wait_for_request() {
  if (closed_ || read_done_) return;
  if (queue_.size() >= server_.options().limits.max_pipeline) {
    read_paused_ = true;
    return;
  }
  if (buffer_.size() > 0) return read_request();
  reading_ = true;
  idle_wait_ = true;
  set_read_deadline(server_.options().limits.idle_timeout);
  socket_.async_read_some(buffer_.prepare(4096),
                          [self = shared_from_this()](beast::error_code ec, std::size_t n) {
                            self->reading_ = false;
                            self->idle_wait_ = false;
                            if (self->closed_) return;
                            self->clear_read_deadline();
                            if (ec || n == 0) {
                              self->read_done_ = true;
                              if (self->queue_.empty()) self->close();
                              return;
                            }
                            self->buffer_.commit(n);
                            if (self->server_.stopping()) {
                              // Unread input may follow: a plain close would reset the connection
                              // and could destroy responses still in the socket buffer.
                              self->read_done_ = true;
                              if (self->queue_.empty()) self->linger_close();
                              return;
                            }
                            self->read_request();
                          });
}

// Parses the next request from what is buffered, synchronously; reads more only when the header is
// incomplete. (http::async_read would post its completion even when the whole request is already
// buffered, sending every request once around the scheduler queue: a pipelined or busy connection
// would wait behind every other ready connection for each request.)
void Session::read_request() {
  const auto& limits = server_.options().limits;
  if (!parser_) {
    parser_.emplace(std::piecewise_construct, std::make_tuple(),
                    std::make_tuple(FieldAllocator(&fields_)));
    parser_->header_limit(std::uint32_t(limits.max_header_bytes));
    parser_->body_limit(0);
    parser_->eager(true);
    set_read_deadline(limits.header_timeout);
  }
  beast::error_code ec;
  while (buffer_.size() > 0 && !parser_->is_done()) {
    const std::size_t n = parser_->put(buffer_.data(), ec);
    buffer_.consume(n);
    if (ec || n == 0) break;
  }
  if (ec == http::error::need_more) ec = {};
  if (ec || parser_->is_done()) {
    clear_read_deadline();
    return on_read(ec);
  }
  if (buffer_.size() >= limits.max_header_bytes + 4096) {  // never: the parser stops first
    clear_read_deadline();
    return on_read(http::error::header_limit);
  }
  reading_ = true;
  socket_.async_read_some(buffer_.prepare(4096),
                          [self = shared_from_this()](beast::error_code e, std::size_t n) {
                            self->reading_ = false;
                            if (self->closed_) return;
                            if (e || n == 0) {
                              self->clear_read_deadline();
                              return self->on_read(e ? e : http::error::end_of_stream);
                            }
                            self->buffer_.commit(n);
                            self->read_request();
                          });
}

void Session::fail_parse(int status, const char* message) {
  auto out = new_outgoing();
  out->response = plain_response(status, message);
  out->start = Clock::now();
  out->route = int(Route::error);
  out->close = true;
  read_done_ = true;
  enqueue(std::move(out));
}

void Session::on_read(beast::error_code ec) {
  if (closed_) return;
  const auto& limits = server_.options().limits;
  if (ec == http::error::header_limit) {
    // A request line longer than the target limit is a long URI (414), not big headers (431).
    const auto data = buffer_.cdata();
    const std::string_view head(static_cast<const char*>(data.data()), data.size());
    const auto eol = head.find('\n');
    const std::size_t line = eol == std::string_view::npos ? head.size() : eol;
    // Beast consumes the request line once parsed; then the target is in the message.
    const auto parsed_target = parser_->get().target();
    if (parsed_target.size() > limits.max_target_bytes ||
        (parsed_target.empty() && line > limits.max_target_bytes + 16))
      return fail_parse(414, "request target too long\n");
    return fail_parse(431, "request header fields too large\n");
  }
  if (ec == http::error::body_limit) return fail_parse(413, "request body not allowed\n");
  if (ec) {
    read_done_ = true;
    // end_of_stream / reset / timeout (socket closed): nothing to answer.
    if (ec == http::error::end_of_stream || ec == asio::error::operation_aborted ||
        ec == asio::error::connection_reset || ec == asio::error::eof || !socket_.is_open()) {
      if (queue_.empty()) close();
      return;
    }
    return fail_parse(400, "bad request\n");
  }

  auto& req = parser_->get();
  auto out = new_outgoing();
  out->start = Clock::now();
  const auto target = req.target();
  HttpRequest hr;
  hr.method = to_method(req.method());
  const auto mt = req.method_string();
  hr.method_text = {mt.data(), mt.size()};
  hr.target = {target.data(), target.size()};
  read_fields(req, hr);

  if (target.size() > limits.max_target_bytes) {
    out->response = plain_response(414, "request target too long\n");
  } else if (target.empty() || target.front() != '/') {
    out->response = plain_response(400, "bad request target\n");
  } else if (admin_) {
    out->response = server_.admin_route(hr);
  } else {
    out->response = route(hr, server_.registry(), server_.options().router, server_.provider());
  }
  if (!req.keep_alive() || server_.stopping()) out->close = true;
  // HTTP/1.0 keeps a connection open only when both sides say so.
  out->keep_alive_header = req.version() < 11 && !out->close;
  out->route = admin_ ? 6 : int(out->response.route);
  if (server_.access_log()) {
    out->method = std::string(hr.method_text);
    out->target = std::string(hr.target);
    if (out->response.hold) out->tileset = out->response.hold->name;
    if (out->response.deferred) out->tileset = out->response.deferred->tileset->name;
  }
  if (out->close) read_done_ = true;
  // Done with the request (its views end here): writing may parse the next one (see write_next).
  parser_.reset();
  fields_.release();
  enqueue(std::move(out));
  wait_for_request();
}

void Session::enqueue(std::unique_ptr<Outgoing> out) {
  out->seq = next_seq_++;
  Outgoing& o = *out;
  const bool deferred = o.response.deferred != nullptr;
  if (deferred)
    o.ready = false;
  else
    prepare(o);
  queue_.push_back(std::move(out));
  if (deferred)
    start_deferred(o);  // may finish it at once (a cache hit)
  else if (!writing_ && !in_write_)
    write_next();
}

// Asks the provider for a deferred tile. Its answer comes back through finish_deferred(): at once
// when `done` runs inside tile() (a RAM hit: no scheduler round trip), else posted to this
// connection's thread. `state` tells the two apart without a lock: whoever moves it from
// kCalling first decides.
void Session::start_deferred(const Outgoing& o) {
  struct Call {
    enum : int { kCalling, kReturned, kAnsweredInside };
    std::atomic<int> state{kCalling};
    ProvidedTile answer;  // written by `done` before it sets kAnsweredInside
  };
  auto call = std::make_shared<Call>();
  const std::uint64_t seq = o.seq;
  const DeferredTile& d = *o.response.deferred;
  server_.provider()->tile(
      d.tileset, d.id,
      [self = shared_from_this(), call, seq,
       executor = socket_.get_executor()](ProvidedTile tile) mutable {
        auto keep_alive = std::move(self);  // released here or on the connection's thread
        call->answer = std::move(tile);
        int expected = Call::kCalling;
        if (call->state.compare_exchange_strong(expected, Call::kAnsweredInside,
                                                std::memory_order_acq_rel))
          return;  // start_deferred() picks the answer up when tile() returns
        asio::post(executor, [session = std::move(keep_alive), call = std::move(call), seq] {
          session->finish_deferred(seq, std::move(call->answer));
        });
      });
  int expected = Call::kCalling;
  if (!call->state.compare_exchange_strong(expected, Call::kReturned, std::memory_order_acq_rel))
    finish_deferred(seq, std::move(call->answer));
}

// On the connection's thread: the provider answered response `seq`. Dropped when the
// connection has closed meanwhile (its queue is gone or going).
void Session::finish_deferred(std::uint64_t seq, ProvidedTile tile) {
  if (closed_) return;
  auto it = std::find_if(queue_.begin(), queue_.end(),
                         [seq](const std::unique_ptr<Outgoing>& o) { return o->seq == seq; });
  if (it == queue_.end() || (*it)->ready) return;
  Outgoing& o = **it;
  o.response = complete_deferred(std::move(o.response), std::move(tile));
  o.ready = true;
  prepare(o);
  // Inside write_next() (the answer came at once, while completing a response resumed reading),
  // that loop writes it.
  if (!writing_ && !in_write_) write_next();
}

// Serialises the status line and header fields of `o`, and points its body at the bytes to send
// (an archive's file for sendfile, or memory).
void Session::prepare(Outgoing& o) {
  Outgoing* out = &o;
  HttpResponse& r = out->response;
  std::string& h = out->head;
  h.reserve(512);
  h += "HTTP/1.1 ";
  h += std::to_string(r.status);
  h += ' ';
  const auto reason = http::obsolete_reason(static_cast<http::status>(r.status));
  h.append(reason.data(), reason.size());
  h += "\r\nServer: vtstream\r\nDate: ";
  h += http_date();
  h += "\r\n";
  for (const auto& [k, v] : r.headers) {
    // Header injection guard: a value with CR or LF (from a bad config) is dropped, not sent.
    if (has_line_break(v)) continue;
    h += k;
    h += ": ";
    h += v;
    h += "\r\n";
  }
  if (out->close)
    h += "Connection: close\r\n";
  else if (out->keep_alive_header)
    h += "Connection: keep-alive\r\n";
  const bool no_body = r.status == 304 || r.status == 204 || (r.status >= 100 && r.status < 200);
  if (!no_body) {
    h += "Content-Length: ";
    h += std::to_string(r.content_length);
    h += "\r\n";
  }
  h += "\r\n";
  if (!r.head_only && !no_body) {
    if (!r.view.empty()) {
      out->body = {reinterpret_cast<const char*>(r.view.data()), r.view.size()};
      const pmtiles::Reader* reader = r.hold ? r.hold->reader.get() : nullptr;
      const auto whole = reader ? reader->bytes() : std::span<const std::uint8_t>{};
      if (reader && reader->file_descriptor() >= 0 && r.view.data() >= whole.data() &&
          r.view.data() + r.view.size() <= whole.data() + whole.size() &&
          r.view.size() >= server_.options().limits.sendfile_min_bytes) {
        out->file_fd = reader->file_descriptor();
        out->file_offset = off_t(r.view.data() - whole.data());
      }
    } else {
      out->body = {r.owned.data(), r.owned.size()};
    }
    assert(out->body.size() == r.content_length);
  }
}

// One non-blocking send of what is left of `o` (one syscall). Sets would_block when the socket
// buffer is full.
std::size_t Session::write_some(Outgoing& o, beast::error_code& ec) {
  const int sock = socket_.native_handle();
  ssize_t n = 0;
  if (o.sent < o.head.size()) {
    const char* p = o.head.data() + o.sent;
    const std::size_t len = o.head.size() - o.sent;
    if (o.file_fd >= 0) {
      // The body follows from the file: MSG_MORE holds this partial segment for it.
      n = ::send(sock, p, len, MSG_NOSIGNAL | MSG_MORE);
    } else {
      iovec iov[2] = {{const_cast<char*>(p), len},
                      {const_cast<char*>(o.body.data()), o.body.size()}};
      msghdr msg{};
      msg.msg_iov = iov;
      msg.msg_iovlen = o.body.empty() ? 1 : 2;
      n = ::sendmsg(sock, &msg, MSG_NOSIGNAL);
    }
  } else {
    const std::size_t done = o.sent - o.head.size();
    const std::size_t len = o.body.size() - done;
    if (o.file_fd >= 0) {
      off_t off = o.file_offset + off_t(done);
      n = ::sendfile(sock, o.file_fd, &off, std::min<std::size_t>(len, std::size_t(1) << 30));
    } else {
      n = ::send(sock, o.body.data() + done, len, MSG_NOSIGNAL);
    }
  }
  if (n < 0) {
    const int err = errno;
    ec = (err == EAGAIN || err == EWOULDBLOCK)
             ? beast::error_code(asio::error::would_block)
             : beast::error_code(err, boost::system::system_category());
    return 0;
  }
  if (n == 0) ec = asio::error::eof;  // a file shorter than its mapping: never for a valid reader
  return std::size_t(n);
}

// Writes queued responses in order until the queue is empty or the socket is full; then waits for
// it to drain. Each response must be completely written by its deadline: `write_timeout` plus its
// size at `min_send_rate`, so a client reading a trickle cannot hold a connection for ever.
void Session::write_next() {
  // Completing a response can resume reading, which can parse and enqueue the next response:
  // that one is written by this loop, never by a nested call.
  if (in_write_) return;
  in_write_ = true;
  struct Reset {
    bool& flag;
    ~Reset() { flag = false; }
  } reset{in_write_};
  const auto& limits = server_.options().limits;
  while (!closed_ && !queue_.empty()) {
    Outgoing& o = *queue_.front();
    if (!o.ready) return;  // a provided tile not answered yet: finish_deferred() resumes
    if (o.deadline == DeadlineClock::time_point{}) {
      o.deadline = DeadlineClock::now() + limits.write_timeout;
      if (limits.min_send_rate > 0)
        o.deadline += std::chrono::milliseconds(o.total() * 1000 / limits.min_send_rate);
    }
    beast::error_code ec;
    const std::size_t n = o.total() > o.sent ? write_some(o, ec) : 0;
    if (ec == asio::error::would_block) {
      writing_ = true;
      write_deadline_ = o.deadline;
      socket_.async_wait(tcp::socket::wait_write, [self = shared_from_this()](beast::error_code e) {
        self->writing_ = false;
        self->write_deadline_ = DeadlineClock::time_point::max();
        if (e || self->closed_) {
          self->close();
          self->queue_.clear();
          return;
        }
        self->write_next();
      });
      return;
    }
    if (ec == asio::error::interrupted) continue;
    if (ec) {
      close();
      queue_.clear();
      return;
    }
    server_.metrics().response_bytes.fetch_add(n, std::memory_order_relaxed);
    o.sent += n;
    if (o.sent < o.total()) continue;
    if (!complete_front()) return;
  }
  // Nothing more will be answered (stop, EOF, Connection: close): a read still pending is only
  // waiting for a request we will not serve.
  if (!closed_ && read_done_ && queue_.empty()) linger_close();
}

// The front response is completely written: account for it, then either close (it asked to) or
// resume reading if the pipeline had filled. Returns false when the connection is closing.
bool Session::complete_front() {
  Outgoing& out = *queue_.front();
  const auto elapsed = Clock::now() - out.start;
  server_.metrics().record(out.route, out.response.status, 0, elapsed);
  if (FILE* log = server_.access_log()) {
    char tbuf[32];
    const std::time_t now = std::time(nullptr);
    std::tm tm{};
    gmtime_r(&now, &tm);
    std::strftime(tbuf, sizeof tbuf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    const std::string line =
        std::string("{\"time\":\"") + tbuf + "\",\"remote\":\"" + remote_ + "\",\"method\":\"" +
        json_escape(out.method) + "\",\"target\":\"" + json_escape(out.target) +
        "\",\"status\":" + std::to_string(out.response.status) +
        ",\"bytes\":" + std::to_string(out.response.head_only ? 0 : out.response.content_length) +
        ",\"duration_us\":" +
        std::to_string(std::chrono::duration_cast<std::chrono::microseconds>(elapsed).count()) +
        ",\"route\":\"" + route_label(out.route) + "\",\"tileset\":\"" + json_escape(out.tileset) +
        "\"}\n";
    std::lock_guard lock(server_.log_mutex());
    std::fwrite(line.data(), 1, line.size(), log);
    std::fflush(log);
  }
  const bool close_after = out.close;
  recycle(std::move(queue_.front()));
  queue_.pop_front();
  if (close_after) {
    queue_.clear();
    linger_close();
    return false;
  }
  // Idle time counts from the last response owed (check_deadlines).
  if (idle_wait_ && queue_.empty()) set_read_deadline(server_.options().limits.idle_timeout);
  if (read_paused_ && queue_.size() < server_.options().limits.max_pipeline) {
    read_paused_ = false;
    wait_for_request();
  }
  return true;
}

}  // namespace

Result<std::unique_ptr<HttpServer>> HttpServer::create(HttpServerOptions options,
                                                       std::shared_ptr<TilesetRegistry> registry) {
  if (!registry) return make_error(ErrorCode::invalid_argument, "no tileset registry");
  // sendfile(2) has no MSG_NOSIGNAL: a client that closes while its tile is on the way would kill
  // the whole process with SIGPIPE. Like every server, ignore it (the write then fails with EPIPE
  // and only that connection ends).
  ::signal(SIGPIPE, SIG_IGN);
  auto s = std::make_unique<Server>(std::move(options), std::move(registry));
  if (auto st = s->bind(); !st.ok()) return st.error();
  return std::unique_ptr<HttpServer>(std::move(s));
}

}  // namespace vts
