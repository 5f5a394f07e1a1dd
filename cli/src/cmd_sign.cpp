// vts sign: make an expiring HMAC-signed URL path for a tileset protected with "hmac_keys".
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "commands.hpp"
#include "vts/base/file_io.hpp"
#include "vts/server/router.hpp"

namespace vts::cli {

namespace {

constexpr std::int64_t kMaxTtl = 10ll * 366 * 24 * 3600;  // ten years
constexpr std::uintmax_t kMaxKeyFileBytes = 64 * 1024;

struct SignArgs {
  std::string path, key, key_file;
  std::int64_t ttl = 3600;
  std::int64_t expires = 0;
};

// A key file: a regular file of at most kMaxKeyFileBytes, trailing line breaks dropped.
Result<std::string> read_key_file(const std::filesystem::path& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::is_regular_file(status))
    return make_error(ErrorCode::invalid_argument,
                      "key file '" + path.string() + "' is not a readable regular file");
  if (std::filesystem::file_size(path, ec) > kMaxKeyFileBytes || ec)
    return make_error(ErrorCode::invalid_argument,
                      "key file '" + path.string() + "' is larger than " +
                          std::to_string(kMaxKeyFileBytes) + " bytes: not a key");
  auto key = read_file(path);
  if (!key) return key.error();
  while (!key->empty() && (key->back() == '\n' || key->back() == '\r')) key->pop_back();
  return key;
}

int run_sign(const SignArgs& a) {
  const auto bad = [](const std::string& m) {
    return report_error(make_error(ErrorCode::invalid_argument, m));
  };
  if (a.path.empty() || a.path[0] != '/' || a.path.find_first_of("?#") != std::string::npos)
    return bad("path '" + a.path + "' must be a URL path starting with '/' and without a query");
  for (const char c : a.path) {
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f)
      return bad("path '" + a.path + "' holds a space or a control character (percent-encode it)");
  }
  std::string key = a.key;
  if (!a.key_file.empty()) {
    auto k = read_key_file(a.key_file);
    if (!k) return report_error(k.error());
    key = std::move(*k);
  }
  if (key.empty()) return bad("give the signing key with --key or --key-file");
  const std::int64_t now = std::chrono::duration_cast<std::chrono::seconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
  std::int64_t expires = a.expires;
  if (expires == 0) expires = now + a.ttl;  // --ttl is range-checked: no overflow
  if (expires <= now)
    return bad("--expires " + std::to_string(expires) +
               " has already passed: the URL would be refused at once");
  std::printf("%s%s\n", a.path.c_str(), sign_path(a.path, expires, key).c_str());
  return 0;
}

}  // namespace

Runner add_sign(CLI::App& app) {
  auto a = std::make_shared<SignArgs>();
  CLI::App* c = app.add_subcommand(
      "sign", "Print an expiring HMAC-signed URL path for a tileset protected by hmac_keys");
  c->add_option("path", a->path, "URL path, e.g. /earth/3/5/2 or /earth.json")->required();
  auto* key = c->add_option("--key", a->key, "Signing key (one of the tileset's hmac_keys)");
  c->add_option("--key-file", a->key_file, "Read the signing key from a file")->excludes(key);
  c->add_option("--ttl", a->ttl, "Seconds until the signature expires (1 s to 10 years)")
      ->check(CLI::Range(std::int64_t{1}, kMaxTtl))
      ->capture_default_str();
  c->add_option("--expires", a->expires, "Absolute expiry, Unix seconds (overrides --ttl)")
      ->check(CLI::Range(std::int64_t{1}, std::int64_t{253402300799}));  // up to year 9999
  return [a] { return run_sign(*a); };
}

}  // namespace vts::cli
