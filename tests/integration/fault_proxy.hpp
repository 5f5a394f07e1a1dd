// A fault-injecting HTTP/1.1 reverse proxy for load tests: it sits between a client and the real
// `vts serve` on loopback, forwards every request, and injects errors, delays and connection resets
// on a deterministic schedule, counting exactly what it injected so a test can hold a client's
// report against it.
//
// Schedule. Requests whose target (path and query, as received) begins with `prefix` are
// "matching" (an empty prefix matches everything); they are numbered 1, 2, 3, ... in the order
// they have been read in full (across all connections: arrival order). Matching request n is
//   an error  when error_every > 0 and n % error_every == 0: answered with error_status and a short
//             text body, upstream is not contacted;
//   a reset   when reset_every > 0 and n % reset_every == 0: the client connection is aborted
//             with a TCP RST (SO_LINGER 0) instead of an answer, upstream is not contacted;
//   a truncation when truncate_every > 0 and n % truncate_every == 0: forwarded, and upstream's
//             answer sent with the Content-Length of its whole body but only the first half of
//             the body (rounded down), then the connection is closed (a transfer broken off part
//             way; an answer without a body arrives whole, and still counts);
//   a delay   when delay_every > 0 and n % delay_every == 0: forwarded after waiting `delay`
//             (an asynchronous timer: other connections keep being served meanwhile).
// The schedules count independently (each looks at n alone); a request picked by more than one
// gets only one fault, by precedence error > reset > truncation > delay, and only that one is
// counted. So with N matching requests, errors = floor(N / error_every) exactly, whatever the
// concurrency. Requests that do not match are forwarded untouched and are not numbered.
//
// A reset is only seen by a client as a failure on a fresh connection: libcurl (like most HTTP
// clients) silently retries a request once when a connection it reused dies before any byte of
// the answer, and the retry is one more matching request to the schedule (which may be faulted
// in turn). A load test on keep-alive connections therefore counts a reset as a retried request
// (stats().requests exceeds its own count by the retries), not as a failure; errors and delays
// it sees one for one.
//
// Stats. GET /_proxy/stats (never forwarded, never counted) answers with stats().to_json():
//   {"requests": all requests proxied, "matched": those numbered by the schedule,
//    "forwarded": answered by upstream and relayed (delayed ones included),
//    "errors", "resets", "truncations", "delays": faults injected (truncations are among the
//    forwarded),
//    "upstream_errors": answered 502 (upstream unreachable or broken) or 504 (upstream timeout),
//    "delay_ms": the configured delay}
// and requests = forwarded + errors + resets + upstream_errors once no request is in flight.
// A fault is counted when it is decided (a delayed request whose client leaves during the wait
// still counts as a delay).
//
// Forwarding. Each client connection gets its own upstream connection, opened on its first
// forwarded request and reused (keep-alive on both sides); a reused upstream connection that
// turns out to be closed is replaced once, transparently. Hop-by-hop fields (Connection,
// Keep-Alive, TE, Upgrade, ...) are not forwarded; everything else, Host included, passes
// unchanged in both directions. Request and response bodies are buffered whole (responses up to
// 1 GiB). Requests are answered one at a time per connection, in order (pipelining works, without
// overlap). A request that does not parse is answered 400 (413, 431 for a body or header over
// the limits) and ends its connection; it is not counted. A client connection idle longer than
// idle_timeout is closed; upstream gets upstream_timeout for each exchange.
//
// Threads: start() returns with the proxy running on `threads` threads (one strand per
// connection). stats() is thread-safe.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "vts/base/result.hpp"

namespace vts::test {

struct FaultProxyOptions {
  std::string upstream_host = "127.0.0.1";  // an IPv4 or IPv6 literal
  std::uint16_t upstream_port = 0;
  std::uint16_t port = 0;  // listens on 127.0.0.1:port; 0: any free port
  std::string prefix;      // requests whose target begins with it are numbered; "" = all

  int error_every = 0;  // 0: off
  int error_status = 503;
  int reset_every = 0;     // 0: off
  int truncate_every = 0;  // 0: off
  int delay_every = 0;     // 0: off
  std::chrono::milliseconds delay{0};

  int threads = 2;
  std::chrono::milliseconds idle_timeout{60'000};
  std::chrono::milliseconds upstream_timeout{30'000};
};

struct FaultProxyStats {
  std::uint64_t requests = 0, matched = 0, forwarded = 0;
  std::uint64_t errors = 0, resets = 0, truncations = 0, delays = 0, upstream_errors = 0;
  std::int64_t delay_ms = 0;

  std::string to_json() const;  // one line, no trailing newline
};

class FaultProxy {
 public:
  // Fails with invalid_argument for a meaningless option (no upstream port, every < 0, status
  // outside 400-599, negative delay, threads < 1) and io when 127.0.0.1:port cannot be bound.
  static Result<std::unique_ptr<FaultProxy>> start(FaultProxyOptions options);
  ~FaultProxy();  // stop()

  // Closes the listener and every connection (delays in progress included) and joins all
  // threads; stats() then stays readable and final. Idempotent; not concurrent with itself.
  void stop();

  FaultProxy(const FaultProxy&) = delete;
  FaultProxy& operator=(const FaultProxy&) = delete;

  std::uint16_t port() const;
  std::string base_url() const;  // "http://127.0.0.1:PORT"
  FaultProxyStats stats() const;

 private:
  class Impl;
  explicit FaultProxy(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace vts::test
