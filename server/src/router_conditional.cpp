// Conditional requests (If-None-Match) and byte ranges (RFC 9110 §13, §14).
#include <limits>

#include "router_internal.hpp"
#include "vts/base/file_io.hpp"

namespace vts {
inline namespace server {
namespace router_detail {

bool none_match(std::string_view header, std::string_view etag) {
  if (header.empty()) return false;
  if (trim(header) == "*") return true;
  while (!header.empty()) {
    const std::size_t comma = header.find(',');
    std::string_view tag = trim(header.substr(0, comma));
    header = comma == std::string_view::npos ? std::string_view{} : header.substr(comma + 1);
    if (tag.size() >= 2 && tag.substr(0, 2) == "W/") tag.remove_prefix(2);
    if (tag == etag) return true;
  }
  return false;
}

bool parse_pos(std::string_view s, std::uint64_t& v) {
  if (s.empty()) return false;
  v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    const auto d = static_cast<std::uint64_t>(c - '0');
    if (v > (std::numeric_limits<std::uint64_t>::max() - d) / 10) {
      v = std::numeric_limits<std::uint64_t>::max();
    } else {
      v = v * 10 + d;
    }
  }
  return true;
}

namespace {

// "a-b" or "a-" (a <= b) within `size`; an invalid spec leaves the decision `full`.
RangeDecision first_last(std::string_view a, std::string_view b, std::uint64_t size) {
  RangeDecision d;
  std::uint64_t first = 0, last = 0;
  if (!parse_pos(a, first)) return d;
  if (b.empty()) {
    last = std::numeric_limits<std::uint64_t>::max();
  } else if (!parse_pos(b, last) || last < first) {
    return d;  // last < first is an invalid range-spec (§14.1.1): ignore the header
  }
  if (first >= size) {
    d.kind = RangeDecision::unsatisfiable;
    return d;
  }
  d.kind = RangeDecision::partial;
  d.first = first;
  d.last = last >= size ? size - 1 : last;
  return d;
}

// "-n": the last n bytes.
RangeDecision suffix(std::string_view b, std::uint64_t size) {
  RangeDecision d;
  std::uint64_t n = 0;
  if (!parse_pos(b, n)) return d;
  if (n == 0) {
    d.kind = RangeDecision::unsatisfiable;
    return d;
  }
  d.kind = RangeDecision::partial;
  d.first = n >= size ? 0 : size - n;
  d.last = size - 1;
  return d;
}

}  // namespace

RangeDecision decide_range(std::string_view header, std::uint64_t size) {
  header = trim(header);
  if (header.size() < 6 || !istarts_with(header, "bytes")) return {};
  std::string_view set = trim(header.substr(5));
  if (set.empty() || set.front() != '=') return {};
  set = trim(set.substr(1));
  if (set.find(',') != std::string_view::npos) return {};  // multiple ranges: 200 full
  const std::size_t dash = set.find('-');
  if (dash == std::string_view::npos) return {};
  const std::string_view a = trim(set.substr(0, dash));
  const std::string_view b = trim(set.substr(dash + 1));
  return a.empty() ? suffix(b, size) : first_last(a, b, size);
}

}  // namespace router_detail
}  // namespace server
}  // namespace vts
