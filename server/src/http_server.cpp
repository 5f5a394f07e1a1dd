// Boost.Beast implementation of HttpServer (the contract is in http_server.hpp): listeners,
// threads, signals and the graceful stop. Connections are session.cpp; the wire format of a
// response response_writer.cpp; deadlines deadline_sweeper.cpp; /metrics metrics.cpp; the access
// log access_log.cpp; hot reload reload_loop.cpp.
#include "vts/server/http_server.hpp"

#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <csignal>
#include <cstdio>
#include <mutex>
#include <system_error>
#include <thread>
#include <unordered_map>
#include <vector>

#include "access_log.hpp"
#include "deadline_sweeper.hpp"
#include "metrics.hpp"
#include "native_tile_cache.hpp"
#include "reload_loop.hpp"
#include "session.hpp"
#include "web_tile_cache.hpp"

namespace vts {
inline namespace server {
namespace {

using namespace http_detail;
namespace asio = boost::asio;
using tcp = asio::ip::tcp;
using error_code = boost::system::error_code;

class Server final : public HttpServer, public SessionHost {
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
    // The router checks the target (414 beyond the smaller of its bound and the listener's).
    options_.router.max_target_bytes =
        std::min(options_.router.max_target_bytes, options_.limits.max_target_bytes);
    if (!options_.router.web.cache) {
      options_.router.web.cache = std::make_shared<http_detail::WebTileCache>(
          options_.router.web.cache_bytes, n,
          http_detail::EncodeLimits{options_.router.web.max_queued_encodes,
                                    options_.router.web.max_queued_encodes_per_connection});
    }
    if (!options_.router.tile_cache && options_.router.tile_cache_bytes > 0) {
      options_.router.tile_cache =
          std::make_shared<http_detail::NativeTileCache>(options_.router.tile_cache_bytes);
    }
    reload_.drop_stale_tiles_from(options_.router.tile_cache);
    for (int i = 1; i < n; ++i) workers_.push_back(std::make_unique<asio::io_context>(1));
    // Deadline sweeps at an eighth of the shortest timeout (so a deadline is enforced within
    // 12.5% of its length), between 10 ms and 250 ms.
    const auto& l = options_.limits;
    const auto shortest = std::min({l.idle_timeout, l.header_timeout, l.write_timeout});
    const auto period =
        std::clamp(shortest / 8, std::chrono::milliseconds(10), std::chrono::milliseconds(250));
    sweepers_.push_back(std::make_unique<Sweeper>(ioc_, period));
    for (auto& w : workers_) sweepers_.push_back(std::make_unique<Sweeper>(*w, period));
  }
  ~Server() override {
    // Web images still being encoded post their answers to the connections' threads: done
    // before those go.
    options_.router.web.cache->stop();
    destroying_ = true;
    error_code ec;
    acceptor_.close(ec);
    admin_acceptor_.close(ec);
    // Sessions still pending (after a drain timeout) die with the io_contexts, while what they
    // use lives (declared earlier); the sweep timers go first, while their io_contexts live.
    for (auto& sw : sweepers_) sw->release();
  }

  Status bind() {
    if (auto st = log_.open(options_.access_log); !st.ok()) return st;
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

  Status run() override {
    // The threads first: a thread the system refuses (a task or address-space limit) ends the
    // run before anything is accepted, with the threads already started stopped and joined.
    std::vector<std::thread> threads;
    Status started = reload_.start();
    for (std::size_t i = 0; started.ok() && i < workers_.size(); ++i) {
      auto& w = *workers_[i];
      guards_.push_back(asio::make_work_guard(w));
      try {
        threads.emplace_back([&w] { w.run(); });
      } catch (const std::system_error& e) {
        started = make_error(ErrorCode::io, "cannot start serving thread " + std::to_string(i + 2) +
                                                " of " + std::to_string(workers_.size() + 1) +
                                                ": " + e.what());
      }
    }
    if (!started.ok()) {
      guards_.clear();
      for (auto& w : workers_) w->stop();
      for (auto& t : threads) t.join();
      reload_.stop();
      return started;
    }
    for (auto& sw : sweepers_) sw->start();
    accept(acceptor_, false);
    if (options_.admin_enabled) accept(admin_acceptor_, true);
    if (options_.handle_signals) {
      signals_.add(SIGTERM);
      signals_.add(SIGINT);
      signals_.add(SIGHUP);
      wait_signal();
    }
    ioc_.run();
    for (auto& t : threads) t.join();
    reload_.stop();
    return {};
  }

  void stop() override {
    // On the server strand, so the drain timer is never touched by two threads at once.
    asio::post(strand_, [this] {
      if (stopping_.exchange(true)) return;
      std::fprintf(stderr, "vts serve: stopping; draining open connections\n");
      error_code ec;
      acceptor_.close(ec);
      admin_acceptor_.close(ec);
      signals_.cancel(ec);
      reload_.quit();
      std::vector<std::weak_ptr<Session>> sessions;
      {
        std::lock_guard lock(sessions_mutex_);
        for (auto& [p, w] : sessions_) sessions.push_back(w);
      }
      for (auto& w : sessions)
        if (auto s = w.lock()) s->on_server_stop();
      drain_timer_.expires_after(options_.limits.drain_timeout);
      drain_timer_.async_wait([this](error_code e) {
        if (e) return;
        std::fprintf(stderr, "vts serve: drain timeout; closing remaining connections\n");
        ioc_.stop();
        for (auto& w : workers_) w->stop();
      });
      std::lock_guard lock(sessions_mutex_);
      if (sessions_.empty()) drained();
    });
  }

  void request_reload(bool force) override { reload_.request(force); }

  std::string metrics_text() const override {
    return prometheus_text(metrics_, registry_->size(), registry_->skipped().size(),
                           options_.provider.get()) +
           web_metrics_text(*options_.router.web.cache) +
           (options_.router.tile_cache ? tile_cache_metrics_text(*options_.router.tile_cache)
                                       : std::string()) +
           (options_.registry.store.counters ? store_metrics_text(*options_.registry.store.counters)
                                             : std::string());
  }

  // -- SessionHost --
  const HttpServerOptions& options() const override { return options_; }
  const TilesetRegistry& registry() const override { return *registry_; }
  AsyncTileProvider* provider() const override { return options_.provider.get(); }
  Metrics& metrics() override { return metrics_; }
  AccessLog& access_log() override { return log_; }
  bool stopping() const override { return stopping_.load(std::memory_order_relaxed); }

  void add_session(const std::shared_ptr<Session>& s) {
    std::lock_guard lock(sessions_mutex_);
    sessions_.emplace(s.get(), s);
  }
  void remove_session(Session* s) override {
    bool last = false;
    {
      std::lock_guard lock(sessions_mutex_);
      sessions_.erase(s);
      last = sessions_.empty();
    }
    // When drained, nothing keeps the io_context busy but the drain timer.
    if (last && stopping() && !destroying_) asio::post(strand_, [this] { drained(); });
  }

  HttpResponse admin_route(const HttpRequest& req) override {
    AdminState state;
    state.ready = ready_.load();
    if (state.ready && options_.provider) state.degraded = options_.provider->health_problem();
    state.metrics_text = [this] { return metrics_text(); };
    state.skipped = [this] { return registry_->skipped(); };
    state.max_target_bytes = options_.router.max_target_bytes;
    return route_admin(req, state);
  }

 private:
  Status bind_one(tcp::acceptor& acc, const std::string& host, std::uint16_t port) {
    error_code ec;
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
    acc.async_accept(slot.context(), [this, &acc, &slot, admin](error_code ec, tcp::socket socket) {
      if (ec == asio::error::operation_aborted || !acc.is_open()) return;
      if (ec == asio::error::connection_aborted) {
        accept(acc, admin);  // that client gave up before we took it; nothing is wrong here
        return;
      }
      if (ec) {
        // EMFILE and friends: back off rather than spin; the connections wait in the backlog.
        auto t = std::make_shared<asio::steady_timer>(ioc_, accept_failed(ec));
        t->async_wait([this, &acc, admin, t](error_code) { accept(acc, admin); });
        return;
      }
      if (accept_failures_ > 0) accept_recovered();
      if (std::size_t(metrics_.open_connections.load()) >= options_.limits.max_connections) {
        metrics_.refused_connections.fetch_add(1, std::memory_order_relaxed);
        error_code ignored;
        socket.close(ignored);
      } else {
        auto s = std::make_shared<Session>(*this, slot, std::move(socket), admin);
        add_session(s);
        s->start();
      }
      accept(acc, admin);
    });
  }

  // A failed accept (on ioc_'s thread, like every accept handler): counted, and logged at once
  // for the first of a spell, then at most every kAcceptReportInterval with the count since the
  // last line. Returns how long to wait before accepting again: kAcceptBackoffMin, doubling with
  // each failure in a row up to kAcceptBackoffMax.
  std::chrono::milliseconds accept_failed(const error_code& ec) {
    const auto now = std::chrono::steady_clock::now();
    ++accept_failures_;
    ++accept_unreported_;
    if (accept_failures_ == 1) {
      std::fprintf(stderr,
                   "vts serve: cannot accept connections: %s; backing off (further failures are "
                   "counted, one line every %lld s)\n",
                   ec.message().c_str(), static_cast<long long>(kAcceptReportInterval.count()));
      accept_unreported_ = 0;
      accept_reported_at_ = now;
    } else if (now - accept_reported_at_ >= kAcceptReportInterval) {
      std::fprintf(stderr,
                   "vts serve: still cannot accept connections: %s; %llu failed accepts since the "
                   "last report\n",
                   ec.message().c_str(), static_cast<unsigned long long>(accept_unreported_));
      accept_unreported_ = 0;
      accept_reported_at_ = now;
    }
    accept_backoff_ = accept_failures_ == 1 ? kAcceptBackoffMin
                                            : std::min(accept_backoff_ * 2, kAcceptBackoffMax);
    return accept_backoff_;
  }

  void accept_recovered() {
    std::fprintf(stderr, "vts serve: accepting connections again, after %llu failed accepts\n",
                 static_cast<unsigned long long>(accept_failures_));
    accept_failures_ = 0;
    accept_unreported_ = 0;
  }

  void wait_signal() {
    signals_.async_wait([this](error_code ec, int sig) {
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

  // Declared before the io_context so that they outlive it: destroying the io_context destroys
  // pending handlers, and with them sessions, which touch the metrics and the session table.
  HttpServerOptions options_;
  std::shared_ptr<TilesetRegistry> registry_;
  std::atomic<bool> stopping_{false}, ready_{false}, destroying_{false};
  Metrics metrics_;
  std::mutex sessions_mutex_;
  std::unordered_map<Session*, std::weak_ptr<Session>> sessions_;
  ReloadLoop reload_{*registry_, metrics_, options_.reload_interval};
  AccessLog log_;

  std::vector<std::unique_ptr<Sweeper>> sweepers_;  // [0] for ioc_, then one per worker
  asio::io_context ioc_;
  std::vector<std::unique_ptr<asio::io_context>> workers_;
  std::vector<asio::executor_work_guard<asio::io_context::executor_type>> guards_;
  std::size_t next_context_ = 0;  // only touched by accept handlers, which run on ioc_'s thread
  // Failed accepts (accept_failed()), also only on ioc_'s thread.
  static constexpr std::chrono::milliseconds kAcceptBackoffMin{50}, kAcceptBackoffMax{1000};
  static constexpr std::chrono::seconds kAcceptReportInterval{5};
  std::uint64_t accept_failures_ = 0;    // in a row, since the last accept that worked
  std::uint64_t accept_unreported_ = 0;  // since the last line
  std::chrono::steady_clock::time_point accept_reported_at_{};
  std::chrono::milliseconds accept_backoff_{0};
  tcp::acceptor acceptor_, admin_acceptor_;
  asio::signal_set signals_;
  asio::strand<asio::io_context::executor_type> strand_;
  asio::steady_timer drain_timer_;
};

}  // namespace

Result<std::unique_ptr<HttpServer>> HttpServer::create(HttpServerOptions options,
                                                       std::shared_ptr<TilesetRegistry> registry) {
  if (!registry) return make_error(ErrorCode::invalid_argument, "no tileset registry");
  // Every write passes MSG_NOSIGNAL, but a library's may not: like every server, ignore SIGPIPE
  // (a write to a closed connection then fails with EPIPE and only that connection ends).
  ::signal(SIGPIPE, SIG_IGN);
  std::unique_ptr<Server> s;
  try {
    s = std::make_unique<Server>(std::move(options), std::move(registry));
  } catch (const std::system_error& e) {  // a worker thread (web encodes) the system refused
    return make_error(ErrorCode::io,
                      std::string("cannot start the web image encoding threads: ") + e.what());
  }
  if (auto st = s->bind(); !st.ok()) return st.error();
  return std::unique_ptr<HttpServer>(std::move(s));
}

void raise_fd_limit_for_connections() noexcept {
  rlimit rl{};
  if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < rl.rlim_max) {
    rl.rlim_cur = rl.rlim_max;
    setrlimit(RLIMIT_NOFILE, &rl);
  }
}

}  // namespace server
}  // namespace vts
