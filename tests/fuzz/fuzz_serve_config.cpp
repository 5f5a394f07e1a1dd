// Fuzz target for the serve config parser (apply_serve_config_text): any text is either refused as
// invalid_argument naming the file, or accepted with every value within the bounds
// docs/DEPLOY.md promises — threads an integer 0..256 equal to the one written, no access entry
// without a credential or with an empty one, limits whole numbers at their minimums, a
// reload interval that is a non-negative integer equal to the one written. Never an exception or
// a crash.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "vts/server/serve_config.hpp"

namespace {

void check(bool ok) {
  if (!ok) std::abort();  // an invariant broke: let the fuzzer record the input
}

// True when the text gave `key` no value, or gave it exactly `value` as a JSON integer.
bool integer_equals(const nlohmann::json& j, const char* key, long long value) {
  if (!j.is_object() || !j.contains(key)) return true;
  const nlohmann::json& v = j.at(key);
  if (v.is_number_unsigned()) return v.get<std::uint64_t>() == static_cast<std::uint64_t>(value);
  return v.is_number_integer() && v.get<std::int64_t>() == value;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  vts::HttpServerOptions o;
  vts::Status s = vts::apply_serve_config_text(text, "fuzz.json", o);
  if (!s) {
    check(s.error().code == vts::ErrorCode::invalid_argument);
    check(s.error().message.find("fuzz.json") != std::string::npos ||
          s.error().message.find("HOST:PORT") != std::string::npos ||
          s.error().message.find("port") != std::string::npos);
    return 0;
  }
  const nlohmann::json j = nlohmann::json::parse(text);  // it parsed once: it parses again
  check(o.threads >= 0 && o.threads <= 256 && integer_equals(j, "threads", o.threads));
  check(o.reload_interval.count() >= 0 &&
        integer_equals(j, "reload_interval_ms", o.reload_interval.count()));
  check(o.router.max_age_seconds <= 31536000);
  for (const auto& [name, access] : o.router.access) {
    check(!access.bearer_tokens.empty() || !access.hmac_keys.empty());
    for (const auto& t : access.bearer_tokens) check(!t.empty());
    for (const auto& k : access.hmac_keys) check(!k.empty());
  }
  const vts::HttpServerLimits& L = o.limits;
  check(L.max_header_bytes >= 256 && L.max_target_bytes >= 1 && L.max_connections >= 1 &&
        L.max_pipeline >= 1);
  check(L.idle_timeout.count() >= 1 && L.header_timeout.count() >= 1 &&
        L.write_timeout.count() >= 1 && L.drain_timeout.count() >= 1);
  return 0;
}
