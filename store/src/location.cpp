#include "vts/store/location.hpp"

#include "vts/base/file_io.hpp"

namespace vts::store {
namespace {

bool bucket_char(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
         c == '_' || c == '-';
}

// A bucket name that can be the first label of a host name under TLS: S3's DNS-compatible rule
// without dots (a dotted bucket would not match the endpoint's wildcard certificate).
bool host_label_bucket(std::string_view b) {
  if (b.size() < 3 || b.size() > 63 || b.front() == '-' || b.back() == '-') return false;
  for (char c : b) {
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-')) return false;
  }
  return true;
}

// The endpoint without a trailing '/'; AWS's regional endpoint when none is set.
std::string endpoint_of(const StoreOptions& o) {
  std::string e =
      o.s3_endpoint.empty() ? "https://s3." + o.region + ".amazonaws.com" : o.s3_endpoint;
  while (!e.empty() && e.back() == '/') e.pop_back();
  return e;
}

}  // namespace

bool is_remote(std::string_view location) {
  return istarts_with(location, "s3://") || istarts_with(location, "https://") ||
         istarts_with(location, "http://");
}

Result<Location> parse_location(std::string_view location) {
  Location l;
  l.url = std::string(location);
  if (istarts_with(location, "s3://")) {
    const std::string_view rest = location.substr(5);
    const std::size_t slash = rest.find('/');
    const std::string_view bucket = rest.substr(0, slash);
    if (bucket.empty() || bucket.size() > 255) {
      return make_error(ErrorCode::invalid_argument,
                        l.url + ": expected s3://BUCKET/KEY (the bucket name is " +
                            (bucket.empty() ? "empty)" : "over 255 characters)"));
    }
    for (char c : bucket) {
      if (!bucket_char(c)) {
        return make_error(ErrorCode::invalid_argument,
                          l.url + ": a bucket name has only letters, digits, '.', '_' and '-'");
      }
    }
    l.scheme = Scheme::s3;
    l.bucket = std::string(bucket);
    if (slash != std::string_view::npos) l.key = std::string(rest.substr(slash + 1));
    return l;
  }
  const bool https = istarts_with(location, "https://");
  if (!https && !istarts_with(location, "http://")) {
    return make_error(ErrorCode::invalid_argument,
                      l.url + ": not a remote location (expected s3://, https:// or http://)");
  }
  const std::string_view rest = location.substr(https ? 8 : 7);
  const std::size_t end = rest.find_first_of("/?#");
  if (rest.substr(0, end).empty()) {
    return make_error(ErrorCode::invalid_argument, l.url + ": the URL has no host");
  }
  for (char c : location) {
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f) {
      return make_error(ErrorCode::invalid_argument,
                        "a URL may not hold spaces or control characters: " + l.url);
    }
  }
  l.scheme = https ? Scheme::https : Scheme::http;
  return l;
}

std::string uri_encode(std::string_view s, bool keep_slash) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string out;
  out.reserve(s.size());
  for (char ch : s) {
    const auto c = static_cast<unsigned char>(ch);
    if ((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' ||
        c == '.' || c == '_' || c == '~' || (c == '/' && keep_slash)) {
      out += ch;
    } else {
      out += '%';
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  return out;
}

std::string s3_request_url(const Location& l, const StoreOptions& o) {
  const std::string endpoint = endpoint_of(o);
  bool virtual_host = o.addressing == Addressing::virtual_host;
  if (o.addressing == Addressing::automatic) {
    virtual_host = o.s3_endpoint.empty() && host_label_bucket(l.bucket);
  }
  const std::string key = uri_encode(l.key, true);
  if (!virtual_host) {
    // A bucket (for a listing) is /bucket, without a trailing '/', which some stores would read
    // as an empty key.
    const std::string bucket = endpoint + "/" + uri_encode(l.bucket, false);
    return l.key.empty() ? bucket : bucket + "/" + key;
  }
  const std::size_t host = endpoint.find("://");
  const std::size_t at = host == std::string::npos ? 0 : host + 3;
  return endpoint.substr(0, at) + l.bucket + "." + endpoint.substr(at) + "/" + key;
}

}  // namespace vts::store
