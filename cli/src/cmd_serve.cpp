// vts serve: host tilesets over HTTP (see server/include/vts/server/http_server.hpp).
#include <sys/resource.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "vts/server/http_server.hpp"

namespace vts::cli {

Result<std::pair<std::string, std::uint16_t>> parse_endpoint(const std::string& s) {
  const auto colon = s.rfind(':');
  if (colon == std::string::npos || colon + 1 == s.size())
    return make_error(ErrorCode::invalid_argument, "'" + s + "' is not HOST:PORT");
  std::string host = s.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']')
    host = host.substr(1, host.size() - 2);
  unsigned long port = 0;
  try {
    std::size_t used = 0;
    port = std::stoul(s.substr(colon + 1), &used);
    if (used != s.size() - colon - 1 || port > 65535) throw std::out_of_range("port");
  } catch (const std::exception&) {
    return make_error(ErrorCode::invalid_argument, "'" + s + "': bad port");
  }
  return std::pair{host.empty() ? std::string("0.0.0.0") : host, std::uint16_t(port)};
}

namespace {

struct ServeArgs {
  std::vector<std::string> paths;
  std::string listen, admin, config, access_log, cors_origin, public_url;
  int threads = -1;
  long long max_age = -1;
  bool print_ports = false;
  bool no_admin = false;
};

Status apply_config(const std::string& file, HttpServerOptions& o) {
  std::ifstream in(file);
  if (!in) return make_error(ErrorCode::io, "cannot read config '" + file + "'");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
    auto endpoint = [&](const char* key, std::string& host, std::uint16_t& port) -> Status {
      if (!j.contains(key)) return {};
      auto ep = parse_endpoint(j.at(key).get<std::string>());
      if (!ep) return ep.error();
      host = ep->first;
      port = ep->second;
      return {};
    };
    if (auto st = endpoint("listen", o.listen_host, o.listen_port); !st.ok()) return st;
    if (j.contains("admin") && j.at("admin").is_null()) {
      o.admin_enabled = false;
    } else if (auto st = endpoint("admin", o.admin_host, o.admin_port); !st.ok()) {
      return st;
    }
    if (j.contains("threads")) o.threads = j.at("threads").get<int>();
    if (j.contains("cors_origin")) o.router.cors_origin = j.at("cors_origin").get<std::string>();
    if (j.contains("max_age")) o.router.max_age_seconds = j.at("max_age").get<std::uint32_t>();
    if (j.contains("public_url")) o.router.public_base_url = j.at("public_url").get<std::string>();
    if (j.contains("access_log")) o.access_log = j.at("access_log").get<std::string>();
    if (j.contains("reload_interval_ms"))
      o.reload_interval = std::chrono::milliseconds(j.at("reload_interval_ms").get<long long>());
    if (j.contains("access")) {
      for (const auto& [name, a] : j.at("access").items()) {
        TilesetAccess acc;
        if (a.contains("tokens"))
          acc.bearer_tokens = a.at("tokens").get<std::vector<std::string>>();
        if (a.contains("hmac_keys"))
          acc.hmac_keys = a.at("hmac_keys").get<std::vector<std::string>>();
        o.router.access[name] = std::move(acc);
      }
    }
    if (j.contains("limits")) {
      const auto& l = j.at("limits");
      auto& L = o.limits;
      auto ms = [&](const char* key, std::chrono::milliseconds& v) {
        if (l.contains(key)) v = std::chrono::milliseconds(l.at(key).get<long long>());
      };
      auto size = [&](const char* key, std::size_t& v) {
        if (l.contains(key)) v = l.at(key).get<std::size_t>();
      };
      size("max_header_bytes", L.max_header_bytes);
      size("max_target_bytes", L.max_target_bytes);
      size("max_connections", L.max_connections);
      size("max_pipeline", L.max_pipeline);
      size("min_send_rate", L.min_send_rate);
      size("sendfile_min_bytes", L.sendfile_min_bytes);
      ms("idle_timeout_ms", L.idle_timeout);
      ms("header_timeout_ms", L.header_timeout);
      ms("write_timeout_ms", L.write_timeout);
      ms("drain_timeout_ms", L.drain_timeout);
      if (L.max_pipeline == 0 || L.max_header_bytes < 256 || L.max_target_bytes == 0)
        return make_error(ErrorCode::invalid_argument,
                          "config '" + file + "': limits too small to serve anything");
    }
  } catch (const nlohmann::json::exception& e) {
    return make_error(ErrorCode::invalid_argument, "config '" + file + "': " + e.what());
  }
  return {};
}

// Each connection is a file descriptor; raise the soft limit to the hard one so the connection
// limit, not the process's descriptor limit, is what refuses clients.
void raise_fd_limit() {
  rlimit rl{};
  if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < rl.rlim_max) {
    rl.rlim_cur = rl.rlim_max;
    setrlimit(RLIMIT_NOFILE, &rl);
  }
}

int run_serve(const ServeArgs& a) {
  HttpServerOptions o;
  if (!a.config.empty())
    if (auto st = apply_config(a.config, o); !st.ok()) return report_error(st.error());
  if (!a.listen.empty()) {
    auto ep = parse_endpoint(a.listen);
    if (!ep) return report_error(ep.error());
    o.listen_host = ep->first;
    o.listen_port = ep->second;
  }
  if (a.no_admin) o.admin_enabled = false;
  if (!a.admin.empty()) {
    auto ep = parse_endpoint(a.admin);
    if (!ep) return report_error(ep.error());
    o.admin_host = ep->first;
    o.admin_port = ep->second;
    o.admin_enabled = true;
  }
  if (a.threads >= 0) o.threads = a.threads;
  if (!a.access_log.empty()) o.access_log = a.access_log;
  if (!a.cors_origin.empty()) o.router.cors_origin = a.cors_origin == "none" ? "" : a.cors_origin;
  if (a.max_age >= 0) o.router.max_age_seconds = std::uint32_t(a.max_age);
  if (!a.public_url.empty()) o.router.public_base_url = a.public_url;

  raise_fd_limit();
  auto registry = std::make_shared<TilesetRegistry>();
  std::vector<std::filesystem::path> paths(a.paths.begin(), a.paths.end());
  if (auto st = registry->load(paths); !st.ok()) return report_error(st.error());

  const std::string host = o.listen_host, admin_host = o.admin_host;
  auto server = HttpServer::create(std::move(o), registry);
  if (!server) return report_error(server.error());
  HttpServer& s = **server;
  s.set_ready(true);
  if (s.admin_port())
    std::printf("vts serve: listening on http://%s:%u (admin http://%s:%u), %zu tilesets\n",
                host.c_str(), unsigned(s.port()), admin_host.c_str(), unsigned(s.admin_port()),
                registry->size());
  else
    std::printf("vts serve: listening on http://%s:%u, %zu tilesets\n", host.c_str(),
                unsigned(s.port()), registry->size());
  if (a.print_ports) std::printf("port %u\nadmin_port %u\n", s.port(), s.admin_port());
  std::fflush(stdout);
  s.run();
  std::fprintf(stderr, "vts serve: stopped\n");
  return 0;
}

}  // namespace

Runner add_serve(CLI::App& app) {
  auto a = std::make_shared<ServeArgs>();
  auto* cmd = app.add_subcommand("serve", "Serve tilesets over HTTP (tiles, TileJSON, archives)");
  cmd->add_option("paths", a->paths, "Archives (*.pmtiles) or folders of archives")->required();
  cmd->add_option("--listen", a->listen, "HOST:PORT to serve tiles on (default 127.0.0.1:8080)");
  cmd->add_option("--admin", a->admin,
                  "HOST:PORT for /metrics and /health (default 127.0.0.1:9090)");
  cmd->add_flag("--no-admin", a->no_admin, "Do not open the admin listener");
  cmd->add_option("--threads", a->threads, "I/O threads (default: one per core)")
      ->check(CLI::Range(0, 256));
  cmd->add_option("--config", a->config, "JSON config file (flags override it)");
  cmd->add_option("--access-log", a->access_log, "JSON-lines access log: FILE, or - for stdout");
  cmd->add_option("--cors-origin", a->cors_origin,
                  "Access-Control-Allow-Origin (default *; 'none' disables CORS)");
  cmd->add_option("--max-age", a->max_age, "Cache-Control max-age of unversioned tile URLs (s)")
      ->check(CLI::Range(0LL, 31536000LL));
  cmd->add_option("--public-url", a->public_url, "Base URL TileJSON hands out (default: Host)");
  cmd->add_flag("--print-ports", a->print_ports, "Also print 'port N' and 'admin_port N' lines");
  return [a] { return run_serve(*a); };
}

}  // namespace vts::cli
