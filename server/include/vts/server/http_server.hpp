// The network layer of `vts serve`: an asynchronous HTTP/1.1 server (Boost.Beast/Asio) that parses
// requests into vts::HttpRequest, answers them with vts::route() (the admin listener, /metrics and
// /health, with vts::route_admin()) and writes the HttpResponse (response_writer.hpp: bodies from
// memory; an archive region read a checked chunk at a time). The router checks every target.
//
// Concurrency model (classic completion handlers, not coroutines — the pipelined read/write pair
// of one connection is easier to express as two independent handler chains):
// - `threads` io_contexts, each run by one thread; accepted connections are dealt out round-robin
//   and stay on their context, so all of a connection's handlers run on one thread, in order, and
//   it needs no lock (the one-thread context plays the role of a per-connection strand without
//   its cost, and no scheduler lock is shared between threads).
// - Per connection, reading and writing run concurrently: the next pipelined request is read
//   while earlier responses are queued or being written. At most `max_pipeline` responses are
//   queued; when the queue is full the connection stops reading (back-pressure) until the writer
//   catches up. Responses are written in request order.
// - Timeouts: a connection waiting for the first byte of a request gets `idle_timeout`; once a
//   byte has arrived, the whole header must arrive within `header_timeout` (slowloris). Each
//   response must be written within `write_timeout` plus its size at `min_send_rate` (slow
//   readers). Expiry closes the connection.
// - Limits: header bytes (431), target length (414), any request body (413), connections beyond
//   `max_connections` are accepted and closed at once. A parse error answers 400/413/414/431 with
//   `Connection: close` and closes after the response; so do a missing Host on HTTP/1.1, two Host
//   fields, and a Transfer-Encoding not ending with chunked (400). Those answers are built by
//   vts::unparsed_request_error(): no-store, and the router's CORS headers on the tile listener.
// - stop() (SIGTERM/SIGINT when handle_signals): close the listeners, let every queued response
//   finish (responses carry `Connection: close` from then on), close idle connections; after
//   `drain_timeout` whatever is left is cut. run() then returns.
// - Provided tiles (options.provider): a tile the router defers (router.hpp) holds its place in
//   the connection's response queue while the provider fetches it; the writer stops at it, so
//   responses still leave in request order, and later requests keep being read and routed (up to
//   `max_pipeline`). The provider's `done` may run on any thread, even inside tile(): a call
//   inside tile() finishes the response at once; a later one is posted to the connection's thread
//   (the pending call keeps the connection object alive). An answer for a connection that has
//   closed meanwhile is dropped. While responses are owed, the idle timeout does not run (the
//   client is waiting for us, not idle); it restarts when the last one is written.
// - Reload: a background thread calls registry.reload(false) every `reload_interval` (0 = never)
//   and registry.reload(true) on SIGHUP or reload(); swaps and refusals are logged to stderr.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "vts/base/result.hpp"
#include "vts/server/router.hpp"
#include "vts/server/tileset_registry.hpp"

namespace vts {
inline namespace server {

struct HttpServerLimits {
  std::size_t max_header_bytes = 8 * 1024;  // request line + headers; beyond: 431
  std::size_t max_target_bytes = 2 * 1024;  // request target; beyond: 414
  std::size_t max_connections = 10000;      // open client connections (both listeners)
  std::size_t max_pipeline = 16;            // queued responses per connection
  std::chrono::milliseconds idle_timeout{30000};
  std::chrono::milliseconds header_timeout{10000};
  std::chrono::milliseconds write_timeout{30000};
  // A response must be written within write_timeout plus its size at this rate (bytes/s; 0 =
  // no rate bound): a reader that trickles cannot keep a connection for ever.
  std::size_t min_send_rate = 16 * 1024;
  std::chrono::milliseconds drain_timeout{10000};
};

struct HttpServerOptions {
  std::string listen_host = "127.0.0.1";
  std::uint16_t listen_port = 8080;  // 0 = any free port; port() tells which
  std::string admin_host = "127.0.0.1";
  std::uint16_t admin_port = 9090;  // 0 = any free port
  bool admin_enabled = true;
  int threads = 0;  // 0 = std::thread::hardware_concurrency()
  HttpServerLimits limits;
  RouterConfig router;
  std::chrono::milliseconds reload_interval{2000};  // 0 = no periodic check
  // Remote tilesets (s3://, https://) and each archive's directory cache: what the registry is
  // made with (config keys s3_endpoint, directory_cache_mib; flags --s3-endpoint,
  // --directory-cache-mib).
  RegistryOptions registry;
  bool handle_signals = true;  // SIGTERM/SIGINT → stop(), SIGHUP → reload(true)
  std::string access_log;      // "" = off, "-" = stdout, else a file (appended)
  // Tilesets that are not archives (the cache daemon, `vts cache serve`): looked up when a name
  // is not in the registry (router.hpp). Null = archives only. Its tile() answers asynchronously;
  // see "Provided tiles" above for what the server guarantees. It must outlive the server's
  // run(), and every `done` it was handed must have run (or been destroyed) before the server is
  // destroyed: destroy the provider's pending work (e.g. the TileCache) first.
  std::shared_ptr<AsyncTileProvider> provider;
};

class HttpServer {
 public:
  // Binds both listeners (so port() is known before run()). Fails with io when an address cannot
  // be bound, invalid_argument when it does not parse. The registry must outlive the server.
  // Sets SIGPIPE to be ignored process-wide, as every server does: a write to a connection the
  // client has closed then fails with EPIPE and ends only that connection.
  static Result<std::unique_ptr<HttpServer>> create(HttpServerOptions options,
                                                    std::shared_ptr<TilesetRegistry> registry);
  virtual ~HttpServer() = default;

  virtual std::uint16_t port() const = 0;
  virtual std::uint16_t admin_port() const = 0;  // 0 when the admin listener is disabled

  // /health answers 503 "loading" until set_ready(true). Thread-safe.
  virtual void set_ready(bool ready) = 0;
  // Serves on `threads` threads (the caller's included) until stopped and drained. Error io,
  // before anything is served, when the system refuses a thread (a task or address-space limit);
  // the threads already started are stopped and joined first.
  virtual Status run() = 0;
  // Graceful stop; thread-safe and idempotent; returns at once (run() returns when drained).
  virtual void stop() = 0;
  // Asks the reload thread for registry.reload(force); returns at once. Thread-safe.
  virtual void request_reload(bool force) = 0;
  // The Prometheus exposition /metrics serves.
  virtual std::string metrics_text() const = 0;
};

// Each connection is a file descriptor: raises the process's soft descriptor limit to the hard
// one, so the server's connection limit, not the process's, is what refuses clients. Best effort.
void raise_fd_limit_for_connections() noexcept;

}  // namespace server
}  // namespace vts
