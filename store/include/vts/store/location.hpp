// Where a remote object lives: s3://bucket/key or an http(s):// URL, and the request URLs the
// store sends for it.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "vts/base/result.hpp"
#include "vts/store/options.hpp"

namespace vts::store {

// True for locations the store reads: s3://, https:// and http:// (scheme case-insensitive).
// Anything else (a path, file://) is the local file system's.
bool is_remote(std::string_view location);

enum class Scheme : std::uint8_t { s3, http, https };

struct Location {
  Scheme scheme = Scheme::s3;
  std::string bucket;  // s3 only
  std::string key;     // s3 only: the object key or prefix, literal (no percent-decoding)
  std::string url;     // as given (what messages name)
};

// Parses a remote location. s3://BUCKET[/KEY]: BUCKET of 1 to 255 characters among A-Z a-z 0-9
// . _ - (S3's own rule is stricter; S3-compatible stores accept more), KEY anything, possibly
// empty (a whole bucket as a prefix). http(s)://HOST...: a host is required; kept as given.
// invalid_argument, naming the location, otherwise.
Result<Location> parse_location(std::string_view location);

// S3's URI encoding (SigV4 canonical form): every byte but A-Z a-z 0-9 - . _ ~ as %XX (upper
// case hex), '/' too unless keep_slash.
std::string uri_encode(std::string_view s, bool keep_slash);

// The https/http URL of an S3 object, or (key empty) of its bucket for listings, under `options`
// (endpoint, region, addressing). Keys are uri_encode()d with '/' kept, so the URL is already
// in SigV4's canonical form. Not for http(s) locations (their url is the request URL).
std::string s3_request_url(const Location& location, const StoreOptions& options);

}  // namespace vts::store
