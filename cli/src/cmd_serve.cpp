// vts serve: host tilesets over HTTP (server/include/vts/server/http_server.hpp). Glue only: the
// config file is parsed by the server library (serve_config.hpp); flags override it.

#include <algorithm>
#include <cstdio>

#include "commands.hpp"
#include "vts/base/file_io.hpp"
#include "vts/server/http_server.hpp"
#include "vts/server/serve_config.hpp"
#include "vts/store/location.hpp"
#include "vts/store/options.hpp"

namespace vts::cli {

Result<std::pair<std::string, std::uint16_t>> parse_endpoint(const std::string& s) {
  return vts::parse_endpoint(s);
}

namespace {

struct ServeArgs {
  std::vector<std::string> paths;
  std::string listen, admin, config, access_log, cors_origin, public_url, s3_endpoint;
  int threads = -1;
  long long directory_cache_mib = -1;
  long long max_age = -1;
  bool print_ports = false;
  bool no_admin = false;
};

// The config file (if any), then the flags over it; remote stores from the AWS environment
// first (AWS_* variables, ~/.aws files), the config and the flags over it. Only when a location
// is remote: a damaged ~/.aws must not stop a server of local files.
Status make_options(const ServeArgs& a, HttpServerOptions& o) {
  if (std::any_of(a.paths.begin(), a.paths.end(),
                  [](const std::string& p) { return store::is_remote(p); })) {
    auto store = store::StoreOptions::from_environment();
    if (!store) return store.error();
    o.registry.store = std::move(*store);
  }
  if (!a.config.empty())
    if (auto st = apply_serve_config(a.config, o); !st.ok()) return st;
  if (!a.listen.empty()) {
    auto ep = parse_endpoint(a.listen);
    if (!ep) return ep.error();
    o.listen_host = ep->first;
    o.listen_port = ep->second;
  }
  if (a.no_admin) o.admin_enabled = false;
  if (!a.admin.empty()) {
    auto ep = parse_endpoint(a.admin);
    if (!ep) return ep.error();
    o.admin_host = ep->first;
    o.admin_port = ep->second;
    o.admin_enabled = true;
  }
  if (a.threads >= 0) o.threads = a.threads;
  if (!a.access_log.empty()) o.access_log = a.access_log;
  if (!a.cors_origin.empty()) o.router.cors_origin = a.cors_origin == "none" ? "" : a.cors_origin;
  if (auto st = check_cors_origin(o.router.cors_origin); !st.ok()) return st;
  if (a.max_age >= 0) o.router.max_age_seconds = std::uint32_t(a.max_age);
  if (!a.public_url.empty()) o.router.public_base_url = a.public_url;
  if (!a.s3_endpoint.empty()) o.registry.store.s3_endpoint = a.s3_endpoint;
  if (a.directory_cache_mib >= 0)
    o.registry.directory_cache_bytes = std::size_t(a.directory_cache_mib) << 20;
  return {};
}

void print_listening(const HttpServer& s, const std::string& host, const std::string& admin_host,
                     std::size_t tilesets, bool print_ports) {
  if (s.admin_port())
    std::printf("vts serve: listening on http://%s:%u (admin http://%s:%u), %zu tilesets\n",
                host.c_str(), unsigned(s.port()), admin_host.c_str(), unsigned(s.admin_port()),
                tilesets);
  else
    std::printf("vts serve: listening on http://%s:%u, %zu tilesets\n", host.c_str(),
                unsigned(s.port()), tilesets);
  if (print_ports) std::printf("port %u\nadmin_port %u\n", s.port(), s.admin_port());
  std::fflush(stdout);
}

int run_serve(const ServeArgs& a) {
  HttpServerOptions o;
  if (auto st = make_options(a, o); !st.ok()) return report_error(st.error());
  raise_fd_limit_for_connections();
  auto registry = std::make_shared<TilesetRegistry>(o.registry);
  std::vector<std::filesystem::path> paths(a.paths.begin(), a.paths.end());
  if (auto st = registry->load(paths); !st.ok()) return report_error(st.error());
  // Served without them, as a reload would; /health and /metrics list them too.
  for (const auto& skipped : registry->skipped())
    std::fprintf(stderr, "vts serve: skipped %s: %s\n",
                 escape_controls(skipped.file.string()).c_str(),
                 escape_controls(skipped.error.message).c_str());
  if (auto st = check_access_names(o, *registry); !st.ok()) return report_error(st.error());

  const std::string host = o.listen_host, admin_host = o.admin_host;
  auto server = HttpServer::create(std::move(o), registry);
  if (!server) return report_error(server.error());
  HttpServer& s = **server;
  s.set_ready(true);
  print_listening(s, host, admin_host, registry->size(), a.print_ports);
  if (const Status ran = s.run(); !ran.ok()) return report_error(ran.error());
  std::fprintf(stderr, "vts serve: stopped\n");
  return 0;
}

}  // namespace

Runner add_serve(CLI::App& app) {
  auto a = std::make_shared<ServeArgs>();
  auto* cmd = app.add_subcommand("serve", "Serve tilesets over HTTP (tiles, TileJSON, archives)");
  cmd->add_option("paths", a->paths,
                  "Archives (*.pmtiles), sets (a folder or its tileset.json), folders of them; "
                  "or the same in an object store (s3://bucket/prefix/, s3://bucket/a.pmtiles, "
                  "https://host/set/tileset.json)")
      ->required();
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
  cmd->add_option("--s3-endpoint", a->s3_endpoint,
                  "S3-compatible store's endpoint, scheme://host[:port] (default: "
                  "AWS_ENDPOINT_URL, else AWS's)");
  cmd->add_option("--directory-cache-mib", a->directory_cache_mib,
                  "Each archive's cache of decoded leaf directories, MiB (default 64): for an "
                  "archive in an object store, what makes a warm tile one ranged GET")
      ->check(CLI::Range(0LL, 1LL << 20));
  cmd->add_flag("--print-ports", a->print_ports, "Also print 'port N' and 'admin_port N' lines");
  return [a] { return run_serve(*a); };
}

}  // namespace vts::cli
