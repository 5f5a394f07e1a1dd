// One HTTP request by libcurl, with the store's timeouts, retries, counters and (for S3) SigV4
// signing; easy handles come from a process-wide pool, so connections are kept alive. Private to
// the store.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/store/options.hpp"

namespace vts::store::detail {

struct HttpRequest {
  bool head = false;                 // HEAD instead of GET
  std::string url;                   // already in canonical form (location.hpp's s3_request_url)
  std::vector<std::string> headers;  // "Name: value", sent (and, when signed, signed) as given
  bool sign = false;                 // SigV4 with options.credentials (S3 only)
  bool follow_redirects = false;     // http(s) locations only: never resends S3 signatures
  // A 2xx body goes into `into` (exactly: more is an overflow) when use_into, else into
  // HttpResponse::body, at most max_body bytes (more is an overflow).
  bool use_into = false;
  std::span<std::uint8_t> into;
  std::size_t max_body = std::size_t{1} << 20;
};

struct HttpResponse {
  long status = 0;
  std::string etag, last_modified, content_range;
  std::optional<std::uint64_t> content_length;
  std::string body;          // the 2xx body (unless use_into), or the first 64 KiB of an error
  std::size_t received = 0;  // 2xx body bytes received
  bool overflow = false;     // the 2xx body was longer than the room for it (transfer stopped)
};

// Sends the request; a 5xx or 429 answer, a refused or dropped connection and a timeout are
// retried options.retries times (backoff doubling from options.retry_backoff). Any other answer,
// whatever its status, is the response. Errors: unavailable once the retries are spent (naming
// `what`, the URL and the last cause); io for other transport failures (TLS, protocol).
Result<HttpResponse> perform(const HttpRequest& request, const StoreOptions& options,
                             const std::string& what);

// "bytes A-B/TOTAL" -> {A, B, TOTAL}; "bytes */TOTAL" -> {nullopt...} with total set.
struct ContentRange {
  std::optional<std::uint64_t> first, last;
  std::optional<std::uint64_t> total;
};
std::optional<ContentRange> parse_content_range(std::string_view value);

}  // namespace vts::store::detail
