// Boost.Beast/Asio implementation of FaultProxy; the contract is in fault_proxy.hpp.
//
// Every connection is one C++20 coroutine on its own strand of a small thread pool: it reads a
// request, decides its fault, and either answers it, aborts the connection, or forwards it over
// the connection's own upstream stream (after a timer wait, for a delay), then writes the answer.
// stop() marks the proxy stopping and closes the acceptor and every connection on their strands;
// each coroutine checks the mark after every wait, so the pool runs out of work and its threads
// return.
#include "fault_proxy.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <boost/asio/as_tuple.hpp>
#include <boost/asio/co_spawn.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/asio/use_awaitable.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http.hpp>
#include <cstdio>
#include <exception>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <vector>

namespace vts::test {

namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;

constexpr auto kUse = asio::as_tuple(asio::use_awaitable);
constexpr std::uint32_t kHeaderLimit = 64 * 1024;
constexpr std::uint64_t kRequestBodyLimit = 16ull << 20;
constexpr std::uint64_t kResponseBodyLimit = 1ull << 30;
constexpr std::string_view kStatsPath = "/_proxy/stats";

using Request = http::request<http::string_body>;
using Response = http::response<http::string_body>;

enum class Fault { none, error, reset, truncate, delay };

// Removes the hop-by-hop fields (RFC 9110 section 7.6.1), those the Connection field names
// included. A chunked body was decoded by the parser, so it is re-framed with a Content-Length
// (except for the answer to a HEAD, which keeps the length upstream declared, if any).
template <bool isRequest>
void strip_hop_by_hop(http::message<isRequest, http::string_body>& m, bool head_response) {
  if (m.chunked()) {
    m.chunked(false);
    if (!head_response) m.content_length(m.body().size());
  }
  std::vector<std::string> named;
  const auto [first, last] = m.equal_range(http::field::connection);
  for (auto f = first; f != last; ++f) {
    for (const auto token : http::token_list(f->value())) {
      named.emplace_back(token.data(), token.size());
    }
  }
  for (const std::string& name : named) m.erase(name);
  for (const http::field f :
       {http::field::connection, http::field::keep_alive, http::field::proxy_connection,
        http::field::te, http::field::trailer, http::field::upgrade,
        http::field::proxy_authenticate, http::field::proxy_authorization}) {
    m.erase(f);
  }
}

Response text_response(unsigned status, std::string body, unsigned version) {
  Response res;
  res.result(status);
  res.version(version);
  res.set(http::field::content_type, "text/plain");
  res.set(http::field::cache_control, "no-store");
  res.body() = std::move(body);
  res.prepare_payload();
  return res;
}

struct Connection {
  explicit Connection(tcp::socket socket)
      : client(std::move(socket)), upstream(client.get_executor()), timer(client.get_executor()) {}

  // On the connection's strand. With rst, the client connection is aborted with an RST.
  void close(bool rst = false) {
    beast::error_code ignored;
    if (rst) client.socket().set_option(asio::socket_base::linger(true, 0), ignored);
    client.close();
    close_upstream();
    timer.cancel();
  }
  void close_upstream() {
    beast::error_code ignored;
    upstream.socket().shutdown(tcp::socket::shutdown_both, ignored);
    upstream.close();
    upstream_buffer.clear();
    upstream_open = false;
  }

  beast::tcp_stream client;
  beast::tcp_stream upstream;
  beast::flat_buffer upstream_buffer;
  asio::steady_timer timer;  // delays
  bool upstream_open = false;
};

}  // namespace

std::string FaultProxyStats::to_json() const {
  nlohmann::ordered_json j;
  j["requests"] = requests;
  j["matched"] = matched;
  j["forwarded"] = forwarded;
  j["errors"] = errors;
  j["delays"] = delays;
  j["resets"] = resets;
  j["truncations"] = truncations;
  j["upstream_errors"] = upstream_errors;
  j["delay_ms"] = delay_ms;
  return j.dump();
}

class FaultProxy::Impl {
 public:
  explicit Impl(FaultProxyOptions options)
      : options_(std::move(options)), acceptor_(asio::make_strand(ioc_)) {}

  ~Impl() { stop(); }

  void stop() {
    std::vector<std::shared_ptr<Connection>> open;
    {
      std::lock_guard lock(conns_mutex_);
      if (stopping_.exchange(true)) return;
      for (auto& [raw, weak] : conns_) {
        if (auto c = weak.lock()) open.push_back(std::move(c));
      }
    }
    asio::post(acceptor_.get_executor(), [this] {
      beast::error_code ignored;
      acceptor_.close(ignored);
    });
    for (auto& c : open) asio::post(c->client.get_executor(), [c] { c->close(); });
    for (auto& t : threads_) t.join();
    threads_.clear();
  }

  Status listen(const tcp::endpoint& upstream) {
    upstream_ = upstream;
    beast::error_code ec;
    const tcp::endpoint endpoint(asio::ip::address_v4::loopback(), options_.port);
    acceptor_.open(endpoint.protocol(), ec);
    if (!ec) acceptor_.set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acceptor_.bind(endpoint, ec);
    if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
    if (ec) {
      return make_error(ErrorCode::io, "listen on 127.0.0.1:" + std::to_string(options_.port) +
                                           ": " + ec.message());
    }
    port_ = acceptor_.local_endpoint().port();
    // The pending accept is work, so the threads do not return before stop().
    asio::co_spawn(acceptor_.get_executor(), accept_loop(), report_exception);
    for (int i = 0; i < options_.threads; ++i) threads_.emplace_back([this] { ioc_.run(); });
    return {};
  }

  std::uint16_t port() const { return port_; }

  FaultProxyStats stats() const {
    FaultProxyStats s;
    s.requests = requests_.load();
    s.matched = matched_.load();
    s.forwarded = forwarded_.load();
    s.errors = errors_.load();
    s.resets = resets_.load();
    s.truncations = truncations_.load();
    s.delays = delays_.load();
    s.upstream_errors = upstream_errors_.load();
    s.delay_ms = options_.delay.count();
    return s;
  }

 private:
  static void report_exception(std::exception_ptr e) {
    if (!e) return;
    try {
      std::rethrow_exception(e);
    } catch (const std::exception& x) {
      std::fprintf(stderr, "fault_proxy: connection failed: %s\n", x.what());
    }
  }

  // False when stopping: the connection must end at once.
  bool add(const std::shared_ptr<Connection>& c) {
    std::lock_guard lock(conns_mutex_);
    if (stopping_) return false;
    conns_.emplace(c.get(), c);
    return true;
  }
  void remove(Connection* c) {
    std::lock_guard lock(conns_mutex_);
    conns_.erase(c);
  }

  Fault pick(std::uint64_t n) const {
    const auto every = [n](int k) { return k > 0 && n % std::uint64_t(k) == 0; };
    if (every(options_.error_every)) return Fault::error;
    if (every(options_.reset_every)) return Fault::reset;
    if (every(options_.truncate_every)) return Fault::truncate;
    if (every(options_.delay_every)) return Fault::delay;
    return Fault::none;
  }

  asio::awaitable<void> accept_loop() {
    for (;;) {
      const asio::any_io_executor strand = asio::make_strand(ioc_);
      auto [ec, socket] = co_await acceptor_.async_accept(strand, kUse);
      if (stopping_ || ec == asio::error::operation_aborted) co_return;
      if (ec) {  // out of descriptors or similar: wait a little rather than spin
        asio::steady_timer pause(co_await asio::this_coro::executor);
        pause.expires_after(std::chrono::milliseconds(10));
        co_await pause.async_wait(kUse);
        continue;
      }
      beast::error_code ignored;
      socket.set_option(tcp::no_delay(true), ignored);
      auto c = std::make_shared<Connection>(std::move(socket));
      asio::co_spawn(strand, session(c), report_exception);
    }
  }

  // Writes res to the client; false when the connection is to end (write failed, stopping).
  asio::awaitable<bool> reply(Connection& c, Response& res, bool head) {
    if (head) res.body().clear();  // the fields still describe the body a GET would get
    c.client.expires_after(options_.idle_timeout);
    auto [ec, n] = co_await http::async_write(c.client, res, kUse);
    co_return !ec && !stopping_;
  }

  asio::awaitable<void> session(std::shared_ptr<Connection> c) {
    if (!add(c)) co_return;
    struct Unregister {
      Impl* impl;
      Connection* c;
      ~Unregister() { impl->remove(c); }
    } unregister{this, c.get()};

    beast::flat_buffer buffer;
    for (;;) {
      http::request_parser<http::string_body> parser;
      parser.header_limit(kHeaderLimit);
      parser.body_limit(kRequestBodyLimit);
      c->client.expires_after(options_.idle_timeout);
      auto [ec, n] = co_await http::async_read(c->client, buffer, parser, kUse);
      if (stopping_) co_return;
      if (ec) {
        if (ec.category() == beast::error_code(http::error::end_of_stream).category() &&
            ec != http::error::end_of_stream && ec != http::error::partial_message) {
          // A malformed request: say so and close, as a server would.
          const unsigned status = ec == http::error::body_limit     ? 413
                                  : ec == http::error::header_limit ? 431
                                                                    : 400;
          Response res = text_response(status, "bad request: " + ec.message() + "\n", 11);
          res.keep_alive(false);
          co_await reply(*c, res, false);
        }
        c->close();
        co_return;
      }

      Request req = parser.release();
      const unsigned version = req.version();
      const bool keep_alive = req.keep_alive();
      const bool head = req.method() == http::verb::head;
      const std::string_view target(req.target().data(), req.target().size());

      Response res;
      if (target.substr(0, target.find('?')) == kStatsPath) {
        res = text_response(200, stats().to_json() + "\n", version);
        res.set(http::field::content_type, "application/json");
      } else {
        requests_.fetch_add(1);
        Fault fault = Fault::none;
        if (target.substr(0, options_.prefix.size()) == options_.prefix) {
          fault = pick(matched_.fetch_add(1) + 1);
        }
        if (fault == Fault::error) {
          errors_.fetch_add(1);
          res = text_response(unsigned(options_.error_status),
                              "injected " + std::to_string(options_.error_status) + "\n", version);
        } else if (fault == Fault::reset) {
          resets_.fetch_add(1);
          c->close(/*rst=*/true);
          co_return;
        } else {
          if (fault == Fault::delay) {
            delays_.fetch_add(1);
            c->timer.expires_after(options_.delay);
            auto [wait_ec] = co_await c->timer.async_wait(kUse);
            if (stopping_ || wait_ec) co_return;
          }
          res = co_await forward(*c, req, head);
          if (stopping_) co_return;
          if (fault == Fault::truncate) {
            truncations_.fetch_add(1);
            res.version(version);
            co_await cut_short(*c, res, head);
            co_return;
          }
        }
      }
      res.version(version);
      res.keep_alive(keep_alive);
      if (!co_await reply(*c, res, head)) {
        c->close();
        co_return;
      }
      if (!keep_alive) {
        beast::error_code ignored;
        c->client.socket().shutdown(tcp::socket::shutdown_send, ignored);
        c->close();
        co_return;
      }
    }
  }

  // Writes res's header, with the Content-Length of its whole body, and the first half of the
  // body, then closes the connection: a transfer that breaks off part way.
  asio::awaitable<void> cut_short(Connection& c, Response& res, bool head) {
    if (!head) res.content_length(res.body().size());
    std::ostringstream header;
    header << res.base();
    const std::string head_bytes = header.str();
    const std::size_t half = head ? 0 : res.body().size() / 2;
    const std::array<asio::const_buffer, 2> bytes{asio::buffer(head_bytes),
                                                  asio::buffer(res.body().data(), half)};
    c.client.expires_after(options_.idle_timeout);
    co_await asio::async_write(c.client, bytes, kUse);
    beast::error_code ignored;
    c.client.socket().shutdown(tcp::socket::shutdown_send, ignored);
    c.close();
  }

  // Sends req upstream over the connection's upstream stream (opened when needed) and returns the
  // answer with its hop-by-hop fields removed, or a 502 / 504 of the proxy's own.
  asio::awaitable<Response> forward(Connection& c, Request& req, bool head) {
    strip_hop_by_hop(req, false);
    req.version(11);
    req.keep_alive(true);
    for (int attempt = 0;; ++attempt) {
      const bool reused = c.upstream_open;
      beast::error_code ec;
      bool answered_some = false;
      if (!reused) {
        c.upstream.expires_after(options_.upstream_timeout);
        std::tie(ec) = co_await c.upstream.async_connect(upstream_, kUse);
        if (stopping_) co_return Response{};
        if (!ec) {
          c.upstream_open = true;
          c.upstream.socket().set_option(tcp::no_delay(true), ec);
        }
      }
      if (!ec) {
        c.upstream.expires_after(options_.upstream_timeout);
        std::size_t n = 0;
        std::tie(ec, n) = co_await http::async_write(c.upstream, req, kUse);
        if (stopping_) co_return Response{};
      }
      if (!ec) {
        http::response_parser<http::string_body> parser;
        parser.header_limit(kHeaderLimit);
        parser.body_limit(kResponseBodyLimit);
        parser.skip(head);
        std::size_t n = 0;
        std::tie(ec, n) = co_await http::async_read(c.upstream, c.upstream_buffer, parser, kUse);
        if (stopping_) co_return Response{};
        answered_some = parser.got_some();
        if (!ec) {
          Response res = parser.release();
          if (!res.keep_alive()) c.close_upstream();
          strip_hop_by_hop(res, head);
          forwarded_.fetch_add(1);
          co_return res;
        }
      }
      c.close_upstream();
      // A kept-alive upstream connection may have been closed by the server just before we
      // reused it: one fresh attempt, as HTTP clients do, when nothing of an answer arrived.
      if (reused && attempt == 0 && !answered_some && ec != beast::error::timeout) continue;
      upstream_errors_.fetch_add(1);
      const bool timeout = ec == beast::error::timeout;
      co_return text_response(timeout ? 504 : 502,
                              std::string(timeout ? "upstream timed out" : "upstream failed") +
                                  ": " + ec.message() + "\n",
                              11);
    }
  }

  const FaultProxyOptions options_;
  tcp::endpoint upstream_;
  std::uint16_t port_ = 0;

  std::atomic<std::uint64_t> requests_{0}, matched_{0}, forwarded_{0};
  std::atomic<std::uint64_t> errors_{0}, resets_{0}, truncations_{0}, delays_{0},
      upstream_errors_{0};

  // Declared before the io_context: coroutine frames it may still destroy unregister from here.
  std::mutex conns_mutex_;
  std::atomic<bool> stopping_{false};
  std::unordered_map<Connection*, std::weak_ptr<Connection>> conns_;

  asio::io_context ioc_;
  tcp::acceptor acceptor_;
  std::vector<std::thread> threads_;
};

Result<std::unique_ptr<FaultProxy>> FaultProxy::start(FaultProxyOptions options) {
  const auto bad = [](std::string message) {
    return make_error(ErrorCode::invalid_argument, std::move(message));
  };
  if (options.upstream_port == 0) return bad("no upstream port");
  if (options.error_every < 0 || options.reset_every < 0 || options.truncate_every < 0 ||
      options.delay_every < 0) {
    return bad("a fault schedule's period must be >= 0 (0: off)");
  }
  if (options.error_status < 400 || options.error_status > 599) {
    return bad("the injected error status must be 400-599, not " +
               std::to_string(options.error_status));
  }
  if (options.delay.count() < 0) return bad("negative delay");
  if (options.threads < 1) return bad("threads must be >= 1");
  beast::error_code ec;
  const auto address = asio::ip::make_address(options.upstream_host, ec);
  if (ec) return bad("upstream host '" + options.upstream_host + "' is not an IP address");
  const tcp::endpoint upstream(address, options.upstream_port);

  auto impl = std::make_unique<Impl>(std::move(options));
  if (Status st = impl->listen(upstream); !st.ok()) return st.error();
  return std::unique_ptr<FaultProxy>(new FaultProxy(std::move(impl)));
}

FaultProxy::FaultProxy(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
FaultProxy::~FaultProxy() = default;

std::uint16_t FaultProxy::port() const {
  return impl_->port();
}
std::string FaultProxy::base_url() const {
  return "http://127.0.0.1:" + std::to_string(port());
}
void FaultProxy::stop() {
  impl_->stop();
}
FaultProxyStats FaultProxy::stats() const {
  return impl_->stats();
}

}  // namespace vts::test
