// The client's HTTP fetcher: one libcurl multi handle driven by one thread, with our own priority
// queue in front of it, request merging, cancellation, retries with backoff and hard limits.
//
// Thread-safety contract:
//   - submit(), cancel(), reprioritize() and stats() may be called from any thread, including from
//     inside a FetchCallback (they only post to an inbox; nothing runs inline).
//   - Every callback runs on the fetcher's own thread, exactly once per submitted handle, and must
//     not block (it delays every other transfer) nor throw (the thread would std::terminate).
//   - The destructor must not be called from a callback. It cancels all work (each pending
//     callback runs with cancelled = true) and joins the thread. A callback that keeps submitting
//     from its cancellation keeps the destructor draining: don't.
//
// Retry policy: an attempt is retried (up to max_attempts, after a backoff during which it holds no
// in-flight slot) on a timeout (request_timeout, connect_timeout or the low-speed guard), a refused
// or reset connection, an empty reply, a partial body (fewer bytes than Content-Length), a receive
// or send error, an HTTP/2 stream error, a 206 that does not match its range, HTTP 5xx and 429.
// Anything else is final: other statuses (404, 403, 401, 416, 304, ...) are results, not errors;
// bad URLs, unresolvable hosts, TLS failures and too many redirects (> 5) are errors at once.
//
// Only this file's implementation (fetcher.cpp) sees libcurl.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "vts/base/result.hpp"

namespace vts::client {

struct FetcherOptions {
  std::size_t max_in_flight = 32;         // our cap on concurrent transfers (>= 1); the rest queue
  std::size_t max_host_connections = 16;  // CURLMOPT_MAX_HOST_CONNECTIONS (0: no limit)
  std::chrono::milliseconds connect_timeout{5000};
  std::chrono::milliseconds request_timeout{30000};  // per attempt (CURLOPT_TIMEOUT_MS)
  // Stall guard: abort an attempt whose transfer rate stays below low_speed_bytes/s for
  // low_speed_time (a timeout, so it is retried). 0 bytes disables the guard.
  long low_speed_bytes = 1024;
  std::chrono::seconds low_speed_time{10};
  int max_attempts = 5;  // first try + retries (>= 1)
  // Deadline of a transfer, from the submission of its first request: queueing, every attempt and
  // every backoff included. When it passes, the attempt in flight is aborted (removed from
  // libcurl), no retry follows, and every handle gets an io error "... deadline of N ms passed".
  // 0: none (each attempt still has request_timeout).
  std::chrono::milliseconds deadline{0};
  // Cap on the transfers of one FetchRequest::group in flight at once (0: no cap). Queued
  // transfers of a group at its cap wait while those of other groups start, so a slow group (one
  // region of a tileset whose origin answers it slowly) can hold at most this many of the
  // max_in_flight slots (and of the host's connections), never all of them.
  std::size_t max_in_flight_per_group = 0;
  // Delay before retry n (n = 1, 2, ...): uniform in [0, min(backoff_max, backoff_base * 2^(n-1))]
  // ("full jitter"); a Retry-After on 429/503 raises it to at least that many seconds.
  std::chrono::milliseconds backoff_base{100}, backoff_max{10000};
  std::chrono::seconds max_retry_after{60};  // a longer Retry-After fails the request at once
  std::size_t max_body_bytes = 64u << 20;    // bigger bodies fail with too_large (bomb guard)
  std::string user_agent = "vtstream/0.1";
  std::vector<std::string> headers;  // sent with every request, e.g. "Authorization: Bearer x"
  // CA certificates (PEM) to verify https:// servers with instead of the system's (CURLOPT_CAINFO):
  // a staging server's private CA. create() fails with not_found when it cannot be read.
  std::string ca_file;
};

struct FetchRequest {
  std::string url;  // http:// or https:// only; anything else is an invalid_argument result
  // Inclusive byte range [first, last]; sends "Range: bytes=first-last".
  std::optional<std::pair<std::uint64_t, std::uint64_t>> range;
  std::string if_none_match;  // sends If-None-Match when non-empty (a 304 is a normal result)
  // Order of starting: lower level first (coarser tiles before finer), then higher urgency, then
  // submission order.
  int level = 0;
  double urgency = 0;
  // Requests of one non-empty group share FetcherOptions::max_in_flight_per_group (the tile
  // sources use the tile's region: its level and its 8x8-tile block). A merged transfer keeps the
  // group of its first request.
  std::string group;
  // Requests with equal keys are merged into one transfer. Empty: url + range + if_none_match
  // (the validator is part of the default key so that a 304 never reaches a caller who sent none).
  std::string merge_key;
  // Ranged requests only: when the server ignores Range and answers 200 with the whole resource,
  // deliver the whole body (FetchResult::range_ignored says so) instead of the slice. Part of the
  // default merge key.
  bool whole_if_range_ignored = false;
  // This request's body limit (too_large above it, as FetcherOptions::max_body_bytes); 0: that
  // option's.
  std::uint64_t max_body_bytes = 0;
};

struct FetchResult {
  // Final HTTP status; 0 when no response was received (then error is set). Any status the
  // server sent last is reported, 4xx included; a 4xx other than 429 is not an error.
  //
  // Ranged requests: body is exactly bytes [first, last] of the resource, or [first, end] when
  // the resource ends before `last`, whether the server answered 206 or ignored Range and sent
  // the whole resource with 200 (then the slice is taken here and status stays 200; a 200 body
  // that ends before `first` is an invalid_argument error, where a server honouring Range would
  // have said 416). A 206 that does not match the request (wrong start, wrong length) is an error
  // and is retried.
  int status = 0;
  std::vector<std::uint8_t> body;
  std::string etag;           // the ETag header as sent (quotes included); empty when absent
  std::string vts_error;      // the Vts-Error header (docs/PROTOCOL.md); empty when absent
  std::string cache_control;  // the Cache-Control header(s) as sent, joined by ", "; may be empty
  // A ranged request the server answered with 200 and the whole resource (it ignores Range).
  bool range_ignored = false;
  // The final response's Content-Length; -1 when absent or unknown. Set on success and on a
  // too_large error (then it is the size the server announced, when it announced one).
  std::int64_t content_length = -1;
  // Set on transport failure (io / invalid_argument), retries exhausted on 5xx/429 (io, with
  // the last status kept), a too-long Retry-After (io), a body over max_body_bytes (too_large),
  // a ranged answer that never matched (truncated), a passed FetcherOptions::deadline (io), or
  // cancellation (cancelled). The message names the method, the URL and the reason, e.g.
  // "GET http://127.0.0.1:1/x: connection refused after 5 attempts".
  std::optional<Error> error;
  // Attempts started for the transfer this handle was served by. (libcurl itself may resend a
  // request once, unseen, when a reused keep-alive connection turns out dead before any response
  // byte; a server can therefore count one more request than this.)
  int attempts = 0;
  bool cancelled = false;
  // Where the time went, each from this handle's submit() (a merged handle counts from its own):
  // queued — until the transfer's first attempt went on the wire (our priority queue and the
  // in-flight cap; the whole wait when it never started); first_byte — until the first response
  // byte of the final attempt (0 when none came: retries and backoff are inside it otherwise);
  // total — until this result was made.
  struct Timing {
    std::chrono::nanoseconds queued{0}, first_byte{0}, total{0};
  };
  Timing timing;
};

// Runs on the fetcher thread; must not block.
using FetchCallback = std::function<void(FetchResult&&)>;

class Fetcher {
 public:
  // invalid_argument when max_in_flight or max_attempts is 0; internal when libcurl fails to
  // initialise or the thread cannot start.
  static Result<std::unique_ptr<Fetcher>> create(FetcherOptions options = {});
  ~Fetcher();  // cancels everything (callbacks get cancelled = true), joins the thread

  Fetcher(const Fetcher&) = delete;
  Fetcher& operator=(const Fetcher&) = delete;

  using Handle = std::uint64_t;  // never 0

  // Queues a request. Thread-safe; never blocks on the network. The callback runs exactly once.
  Handle submit(FetchRequest request, FetchCallback callback);
  // The handle's callback runs once with cancelled = true (unless it has already run or is
  // running; then nothing happens). When every handle of a transfer is cancelled, a queued transfer
  // is dropped and an in-flight one is aborted. Thread-safe; unknown handles are ignored.
  void cancel(Handle h);
  // New priority for a request still queued or waiting to retry (no effect once its transfer has
  // started). A merged transfer takes the most urgent priority among its handles.
  void reprioritize(Handle h, int level, double urgency);

  // Counters since creation. submitted / merged / succeeded / failed / cancelled count handles
  // (succeeded: callback without error; failed: with an error other than cancellation); started
  // counts attempts put on the wire, retried the attempts after the first; in_flight and queued
  // are transfers now on the wire / waiting (in the queue or for a retry); bytes is response-body
  // bytes received over all attempts; expired counts transfers failed by their deadline (their
  // handles are in failed). Once idle: submitted == succeeded + failed + cancelled.
  struct Stats {
    std::uint64_t submitted = 0, merged = 0, started = 0, retried = 0, succeeded = 0, failed = 0,
                  cancelled = 0, expired = 0, in_flight = 0, queued = 0, bytes = 0;
  };
  Stats stats() const;  // thread-safe; each counter is read atomically (not all at one instant)

 private:
  class Impl;
  explicit Fetcher(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace vts::client
