// JSON from places we do not control: archive metadata, TileJSON, plans and parts' manifests,
// load-test reports, saved cache sources, serve configs, camera paths. Parsed without recursion
// and with a nesting limit, so that what comes back is safe to copy, compare and dump (nlohmann's
// copy, comparison and dump recurse once per level: a 200 KB document of 100,000 nested arrays
// would overflow the stack of whoever touches it). Callers then copy out only the fields they
// know; an untrusted value is never forwarded whole.
#pragma once

#include <cstddef>
#include <limits>
#include <nlohmann/json_fwd.hpp>
#include <string_view>

#include "vts/base/result.hpp"

namespace vts {
inline namespace protocol {

// Far deeper than anything we write or read (our metadata nests 3 levels, reports 5), far
// shallower than any stack.
inline constexpr int kMaxJsonDepth = 64;
// No limit on the entries of one array or object (the default: the document's size bounds them).
inline constexpr std::size_t kUnlimitedJsonEntries = std::numeric_limits<std::size_t>::max();

// Parses `text` as one JSON document (no exceptions escape; the parser itself is iterative).
// Objects and arrays may nest at most `max_depth` levels (a top-level object or array is level 1;
// scalars inside the deepest one are fine), and no one array or object may hold more than
// `max_entries` elements or members. The parse stops at the first container past a limit, so a
// refused document never costs more memory than the limits allow. Errors are corrupt and begin
// with `what` ("tileset metadata", "TileJSON from URL", a file name, ...):
//   "WHAT is not valid JSON: <the parser's message>"
//   "WHAT nests objects or arrays deeper than N levels (at PATH)"
//   "WHAT: PATH holds more than N entries"
// where PATH names the place with dots and [] ("seconds", "latency_ns.total.buckets",
// "keys[].center", "the top level").
Result<nlohmann::json> parse_json(std::string_view text, std::string_view what,
                                  int max_depth = kMaxJsonDepth,
                                  std::size_t max_entries = kUnlimitedJsonEntries);
Result<nlohmann::ordered_json> parse_ordered_json(std::string_view text, std::string_view what,
                                                  int max_depth = kMaxJsonDepth,
                                                  std::size_t max_entries = kUnlimitedJsonEntries);

}  // namespace protocol
}  // namespace vts
