// vts sign: make an expiring HMAC-signed URL path for a tileset protected with "hmac_keys".
#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "commands.hpp"
#include "vts/server/router.hpp"

namespace vts::cli {

namespace {

struct SignArgs {
  std::string path, key, key_file;
  std::int64_t ttl = 3600;
  std::int64_t expires = 0;
};

int run_sign(const SignArgs& a) {
  if (a.path.empty() || a.path[0] != '/' || a.path.find('?') != std::string::npos)
    return report_error(make_error(
        ErrorCode::invalid_argument,
        "path '" + a.path + "' must be a URL path starting with '/' and without a query"));
  std::string key = a.key;
  if (!a.key_file.empty()) {
    std::ifstream in(a.key_file, std::ios::binary);
    if (!in)
      return report_error(make_error(ErrorCode::io, "cannot read key file '" + a.key_file + "'"));
    std::ostringstream ss;
    ss << in.rdbuf();
    key = ss.str();
    while (!key.empty() && (key.back() == '\n' || key.back() == '\r')) key.pop_back();
  }
  if (key.empty())
    return report_error(
        make_error(ErrorCode::invalid_argument, "give the signing key with --key or --key-file"));
  std::int64_t expires = a.expires;
  if (expires == 0) {
    const auto now = std::chrono::duration_cast<std::chrono::seconds>(
                         std::chrono::system_clock::now().time_since_epoch())
                         .count();
    expires = now + a.ttl;
  }
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
  c->add_option("--ttl", a->ttl, "Seconds until the signature expires")->capture_default_str();
  c->add_option("--expires", a->expires, "Absolute expiry, Unix seconds (overrides --ttl)");
  return [a] { return run_sign(*a); };
}

}  // namespace vts::cli
