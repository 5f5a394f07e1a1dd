#include "vts/store/options.hpp"

#include <cstdlib>
#include <filesystem>
#include <map>
#include <system_error>

#include "vts/base/file_io.hpp"

namespace vts::store {
namespace {

// One AWS shared file: section name -> key -> value. Nested keys (an indented `key = value`
// under a top-level `key =` with no value, as in `s3 =` / `  addressing_style = path`) are
// stored as "parent.key".
using IniFile = std::map<std::string, std::map<std::string, std::string>>;

constexpr std::uintmax_t kMaxSharedFileBytes = std::uintmax_t{1} << 20;

IniFile parse_ini(std::string_view text) {
  IniFile ini;
  std::string section, parent;
  bool in_section = false;
  while (!text.empty()) {
    const std::size_t nl = text.find('\n');
    std::string_view raw = text.substr(0, nl);
    text = nl == std::string_view::npos ? std::string_view{} : text.substr(nl + 1);
    const bool indented = !raw.empty() && (raw.front() == ' ' || raw.front() == '\t');
    const std::string_view line = trim(raw);
    if (line.empty() || line.front() == '#' || line.front() == ';') continue;
    if (line.front() == '[' && line.back() == ']') {
      section = std::string(trim(line.substr(1, line.size() - 2)));
      in_section = true;
      parent.clear();
      ini[section];  // an empty section still names a profile
      continue;
    }
    const std::size_t eq = line.find('=');
    if (!in_section || eq == std::string_view::npos) continue;  // not ours to judge: skipped
    const std::string key(trim(line.substr(0, eq)));
    const std::string value(trim(line.substr(eq + 1)));
    if (indented && !parent.empty()) {
      ini[section][parent + "." + key] = value;
      continue;
    }
    parent = value.empty() ? key : std::string{};
    ini[section][key] = value;
  }
  return ini;
}

// The file at `path` parsed; empty when it does not exist.
Result<IniFile> load_ini(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return IniFile{};
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) return make_error(ErrorCode::io, "cannot read " + path.string() + ": " + ec.message());
  if (size > kMaxSharedFileBytes) {
    return make_error(ErrorCode::too_large,
                      path.string() + " has " + std::to_string(size) + " bytes (at most 1 MiB)");
  }
  Result<std::string> text = read_file(path);
  if (!text) return make_error(ErrorCode::io, text.error().message);
  return parse_ini(*text);
}

const std::map<std::string, std::string>* find_section(const IniFile& ini,
                                                       const std::string& name) {
  const auto it = ini.find(name);
  return it == ini.end() ? nullptr : &it->second;
}

std::string value_of(const std::map<std::string, std::string>* section, const std::string& key) {
  if (section == nullptr) return {};
  const auto it = section->find(key);
  return it == section->end() ? std::string{} : it->second;
}

// Credentials of one section: none when it has neither key; invalid_argument when it has one.
Result<std::optional<Credentials>> credentials_in(const std::map<std::string, std::string>* s,
                                                  const std::string& where) {
  Credentials c{value_of(s, "aws_access_key_id"), value_of(s, "aws_secret_access_key"),
                value_of(s, "aws_session_token")};
  if (c.access_key_id.empty() && c.secret_access_key.empty()) {
    return std::optional<Credentials>{};
  }
  if (c.access_key_id.empty() || c.secret_access_key.empty()) {
    return make_error(ErrorCode::invalid_argument,
                      where + " has " +
                          (c.access_key_id.empty() ? "aws_secret_access_key without "
                                                     "aws_access_key_id"
                                                   : "aws_access_key_id without "
                                                     "aws_secret_access_key"));
  }
  return std::optional<Credentials>{std::move(c)};
}

Result<Addressing> parse_addressing(const std::string& style, const std::string& where) {
  if (style.empty() || style == "auto") return Addressing::automatic;
  if (style == "path") return Addressing::path;
  if (style == "virtual") return Addressing::virtual_host;
  return make_error(ErrorCode::invalid_argument, where + ": s3 addressing_style \"" + style +
                                                     "\" (expected auto, path or virtual)");
}

}  // namespace

Counters::Snapshot Counters::snapshot() const noexcept {
  return {requests.load(), bytes.load(), retries.load(), coalesced.load(), first_block_hits.load()};
}

Result<StoreOptions> StoreOptions::from_environment(const std::string& profile) {
  return from_lookup(
      [](const std::string& name) -> std::optional<std::string> {
        const char* v = std::getenv(name.c_str());  // NOLINT(concurrency-mt-unsafe): read only
        if (v == nullptr) return std::nullopt;
        return std::string(v);
      },
      profile);
}

Result<StoreOptions> StoreOptions::from_lookup(const Environment& env, const std::string& profile) {
  // An empty variable counts as unset, as the AWS CLI treats it.
  const auto var = [&env](const std::string& name) {
    std::optional<std::string> v = env(name);
    return v ? *v : std::string{};
  };
  StoreOptions o;
  bool named = !profile.empty();
  o.profile = profile;
  for (const char* name : {"AWS_PROFILE", "AWS_DEFAULT_PROFILE"}) {
    if (o.profile.empty() && !var(name).empty()) {
      o.profile = var(name);
      named = true;
    }
  }
  if (o.profile.empty()) o.profile = "default";

  const std::string home = var("HOME");
  std::filesystem::path credentials_file = var("AWS_SHARED_CREDENTIALS_FILE");
  std::filesystem::path config_file = var("AWS_CONFIG_FILE");
  if (credentials_file.empty() && !home.empty()) credentials_file = home + "/.aws/credentials";
  if (config_file.empty() && !home.empty()) config_file = home + "/.aws/config";
  Result<IniFile> creds_ini = credentials_file.empty() ? IniFile{} : load_ini(credentials_file);
  if (!creds_ini) return std::move(creds_ini).error();
  Result<IniFile> config_ini = config_file.empty() ? IniFile{} : load_ini(config_file);
  if (!config_ini) return std::move(config_ini).error();

  const auto* creds_section = find_section(*creds_ini, o.profile);
  const auto* config_section = find_section(
      *config_ini, o.profile == "default" ? std::string("default") : "profile " + o.profile);
  if (o.profile == "default" && config_section == nullptr) {
    config_section = find_section(*config_ini, "profile default");
  }
  if (named && creds_section == nullptr && config_section == nullptr) {
    return make_error(ErrorCode::invalid_argument,
                      "AWS profile \"" + o.profile + "\" is in neither " +
                          credentials_file.string() + " nor " + config_file.string());
  }

  const std::string key_id = var("AWS_ACCESS_KEY_ID"), secret = var("AWS_SECRET_ACCESS_KEY");
  if (!key_id.empty() || !secret.empty()) {
    if (key_id.empty() || secret.empty()) {
      return make_error(ErrorCode::invalid_argument,
                        key_id.empty() ? "AWS_SECRET_ACCESS_KEY is set without AWS_ACCESS_KEY_ID"
                                       : "AWS_ACCESS_KEY_ID is set without AWS_SECRET_ACCESS_KEY");
    }
    o.credentials = Credentials{key_id, secret, var("AWS_SESSION_TOKEN")};
  } else {
    Result<std::optional<Credentials>> c =
        credentials_in(creds_section, credentials_file.string() + " [" + o.profile + "]");
    if (!c) return std::move(c).error();
    if (!*c) {
      c = credentials_in(config_section, config_file.string() + " (profile " + o.profile + ")");
      if (!c) return std::move(c).error();
    }
    o.credentials = std::move(*c);
  }

  o.region = var("AWS_REGION");
  if (o.region.empty()) o.region = var("AWS_DEFAULT_REGION");
  if (o.region.empty()) o.region = value_of(config_section, "region");
  if (o.region.empty()) o.region = "us-east-1";

  o.s3_endpoint = var("AWS_ENDPOINT_URL_S3");
  if (o.s3_endpoint.empty()) o.s3_endpoint = var("AWS_ENDPOINT_URL");
  if (o.s3_endpoint.empty()) o.s3_endpoint = value_of(config_section, "s3.endpoint_url");
  if (o.s3_endpoint.empty()) o.s3_endpoint = value_of(config_section, "endpoint_url");

  Result<Addressing> addressing =
      parse_addressing(value_of(config_section, "s3.addressing_style"),
                       config_file.string() + " (profile " + o.profile + ")");
  if (!addressing) return std::move(addressing).error();
  o.addressing = *addressing;
  return o;
}

}  // namespace vts::store
