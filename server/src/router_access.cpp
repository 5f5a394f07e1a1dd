// Access control: bearer tokens and HMAC-signed URLs (docs/PROTOCOL.md §6).
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>

#include <array>
#include <chrono>
#include <span>

#include "router_internal.hpp"
#include "vts/base/file_io.hpp"

namespace vts {
inline namespace server {
namespace {

using namespace router_detail;

std::int64_t now_seconds(const RouterConfig& config) {
  if (config.now_unix_seconds != nullptr) return config.now_unix_seconds();
  return std::chrono::duration_cast<std::chrono::seconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::array<unsigned char, 32> sha256(std::string_view s) {
  std::array<unsigned char, 32> out{};
  unsigned int len = 0;
  EVP_Digest(s.data(), s.size(), out.data(), &len, EVP_sha256(), nullptr);
  return out;
}

std::array<unsigned char, 32> hmac_sha256(std::string_view key, std::string_view message) {
  std::array<unsigned char, 32> out{};
  unsigned int len = 0;
  HMAC(EVP_sha256(), key.data(), static_cast<int>(key.size()),
       reinterpret_cast<const unsigned char*>(message.data()), message.size(), out.data(), &len);
  return out;
}

std::string hex(std::span<const unsigned char> bytes) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string s;
  s.reserve(bytes.size() * 2);
  for (unsigned char b : bytes) {
    s.push_back(kDigits[b >> 4]);
    s.push_back(kDigits[b & 15]);
  }
  return s;
}

// The token of "Authorization: Bearer <token>"; empty when there is none.
std::string_view bearer_token(std::string_view authorization) {
  const std::string_view auth = trim(authorization);
  const std::size_t sp = auth.find(' ');
  if (sp == std::string_view::npos || !iequals(auth.substr(0, sp), "bearer")) return {};
  return trim(auth.substr(sp + 1));
}

// Compares digests so the comparison is constant-time whatever the lengths.
bool token_accepted(const TilesetAccess& access, std::string_view token) {
  const auto given = sha256(token);
  bool ok = false;
  for (const auto& t : access.bearer_tokens) {
    const auto want = sha256(t);
    ok |= CRYPTO_memcmp(given.data(), want.data(), want.size()) == 0;
  }
  return ok;
}

// nullopt = accepted; else the 403.
std::optional<HttpResponse> check_signature(const TilesetAccess& access, std::string_view raw_path,
                                            const Query& query, const RouterConfig& config) {
  const HttpResponse refused = error(403, "credentials not accepted for this tileset");
  if (!query.expires || !query.sig) return refused;
  std::uint64_t expires = 0;
  const std::string_view sig = *query.sig;
  std::array<unsigned char, 32> given{};
  bool well_formed =
      parse_pos(*query.expires, expires) && query.expires->size() <= 18 && sig.size() == 64;
  for (std::size_t i = 0; well_formed && i < 32; ++i) {
    const int hi = hex_value(sig[2 * i]), lo = hex_value(sig[2 * i + 1]);
    if (hi < 0 || lo < 0) well_formed = false;
    given[i] = static_cast<unsigned char>(hi * 16 + lo);
  }
  if (!well_formed) return refused;
  if (static_cast<std::int64_t>(expires) < now_seconds(config)) {
    return error(403, "signed URL has expired");
  }
  const std::string message = std::string(raw_path) + "?expires=" + std::string(*query.expires);
  bool ok = false;
  for (const auto& key : access.hmac_keys) {
    const auto want = hmac_sha256(key, message);
    ok |= CRYPTO_memcmp(given.data(), want.data(), want.size()) == 0;
  }
  if (ok) return std::nullopt;
  return refused;
}

}  // namespace

namespace router_detail {

std::optional<HttpResponse> check_access(const TilesetAccess& access, const HttpRequest& request,
                                         std::string_view raw_path, const Query& query,
                                         const RouterConfig& config) {
  const std::string_view token = bearer_token(request.authorization);
  const bool has_signature = query.expires.has_value() || query.sig.has_value();
  if (token.empty() && !has_signature) {
    HttpResponse r = error(401, "this tileset needs credentials: a bearer token or a signed URL");
    add(r, "WWW-Authenticate", "Bearer realm=\"vtstream\"");
    return r;
  }
  if (!token.empty() && token_accepted(access, token)) return std::nullopt;
  if (!has_signature) return error(403, "credentials not accepted for this tileset");
  return check_signature(access, raw_path, query, config);
}

bool is_protected(const RouterConfig& config, std::string_view name) {
  auto it = config.access.find(name);
  return it != config.access.end() &&
         (!it->second.bearer_tokens.empty() || !it->second.hmac_keys.empty());
}

}  // namespace router_detail

std::string sign_path(std::string_view path, std::int64_t expires_unix, std::string_view key) {
  const std::string expires = std::to_string(expires_unix);
  const auto mac = hmac_sha256(key, std::string(path) + "?expires=" + expires);
  return "?expires=" + expires + "&sig=" + hex(mac);
}

}  // namespace server
}  // namespace vts
