#include "vts/protocol/json_input.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <string>
#include <vector>

namespace vts {
inline namespace protocol {
namespace {

// A limit passed: thrown out of the parser's callback, which stops the parse there (nlohmann
// neither catches nor wraps what a callback throws). The document built so far is destroyed
// without recursion.
struct Refused {
  std::string message;
};

// An object's key as an error message quotes it: at most 40 bytes (cut at a character boundary),
// without control characters.
std::string key_text(const std::string& key) {
  constexpr std::size_t kMax = 40;
  std::size_t n = key.size();
  if (n > kMax) {
    n = kMax;
    while (n > 0 && (static_cast<unsigned char>(key[n]) & 0xC0) == 0x80) --n;
  }
  std::string out = key.substr(0, n);
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7F) c = '?';
  }
  if (n < key.size()) out += "...";
  return out;
}

// The containers open around the parser's position, outermost first.
struct Level {
  bool array = false;
  std::size_t entries = 0;
  std::string key;  // an object's latest key (key_text)
};

// Where the first `n` of `levels` (the containers around a position) put it: "seconds",
// "keys[].center", "[][]"; more than three arrays in a row are written "[]x61".
std::string path_of(const std::vector<Level>& levels, std::size_t n) {
  std::string path;
  for (std::size_t i = 0; i < n;) {
    if (levels[i].array) {
      std::size_t run = 1;
      while (i + run < n && levels[i + run].array) ++run;
      if (run > 3) {
        path += "[]x" + std::to_string(run);
      } else {
        for (std::size_t k = 0; k < run; ++k) path += "[]";
      }
      i += run;
    } else {
      if (!path.empty()) path += '.';
      path += levels[i].key;
      ++i;
    }
  }
  return path.empty() ? std::string("the top level") : path;
}

template <typename Json>
Result<Json> parse_limited(std::string_view text, std::string_view what, int max_depth,
                           std::size_t max_entries) {
  using Event = typename Json::parse_event_t;
  std::vector<Level> open;
  auto count_entry = [&] {
    Level& l = open.back();
    if (++l.entries > max_entries) {
      throw Refused{std::string(what) + ": " + path_of(open, open.size() - 1) +
                    " holds more than " + std::to_string(max_entries) + " entries"};
    }
  };
  // Called for every event with the container stack as nlohmann sees it; since no value is ever
  // discarded (the callback returns true or throws), `open` mirrors the parser's own stack.
  auto limit = [&](int /*depth*/, Event event, Json& parsed) {
    switch (event) {
      case Event::object_start:
      case Event::array_start:
        if (!open.empty() && open.back().array) count_entry();
        if (open.size() >= static_cast<std::size_t>(std::max(max_depth, 0))) {
          throw Refused{std::string(what) + " nests objects or arrays deeper than " +
                        std::to_string(max_depth) + " levels (at " + path_of(open, open.size()) +
                        ")"};
        }
        open.push_back({event == Event::array_start, 0, {}});
        break;
      case Event::key:
        count_entry();
        open.back().key = key_text(parsed.template get_ref<const std::string&>());
        break;
      case Event::value:
        if (!open.empty() && open.back().array) count_entry();
        break;
      case Event::object_end:
      case Event::array_end:
        open.pop_back();
        break;
    }
    return true;
  };
  try {
    return Json::parse(text.begin(), text.end(), limit, /*allow_exceptions=*/true);
  } catch (const Refused& r) {
    return make_error(ErrorCode::corrupt, r.message);
  } catch (const typename Json::exception& e) {
    return make_error(ErrorCode::corrupt,
                      std::string(what) + " is not valid JSON: " + std::string(e.what()));
  }
}

}  // namespace

Result<nlohmann::json> parse_json(std::string_view text, std::string_view what, int max_depth,
                                  std::size_t max_entries) {
  return parse_limited<nlohmann::json>(text, what, max_depth, max_entries);
}

Result<nlohmann::ordered_json> parse_ordered_json(std::string_view text, std::string_view what,
                                                  int max_depth, std::size_t max_entries) {
  return parse_limited<nlohmann::ordered_json>(text, what, max_depth, max_entries);
}

}  // namespace protocol
}  // namespace vts
