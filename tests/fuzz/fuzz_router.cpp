// Fuzz target for the request routers (route() and route_admin()): any method, target and header
// values must yield a well-formed response — a status in 100..599, a body that is either owned or a
// view inside the held archive mapping, a Content-Length that matches it, no body on 204/304, and
// no CR/LF/NUL in any header (no response splitting). The input is split on '\n' into
//   method, target, Host, If-None-Match, Range, If-Range, Origin, Authorization,
//   Access-Control-Request-Method, Accept
// (missing lines are absent headers). In the target, "X@cur" becomes "X@<current version of X>" so
// the fuzzer reaches the immutable versioned-tile path. Three tiny archives are built once into a
// temp folder: "t" (dense, z 0..3), "s" (sparse) and "p" (protected: token "secret", HMAC key "k").
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "vts/builder/builder.hpp"
#include "vts/server/router.hpp"
#include "vts/server/tileset_registry.hpp"

namespace {

namespace fs = std::filesystem;

void check(bool ok) {
  if (!ok) std::abort();  // an invariant broke: let the fuzzer record the input
}

struct Fixture {
  fs::path dir;
  vts::TilesetRegistry registry;
  vts::RouterConfig open_config;    // CORS "*", Host-based URLs
  vts::RouterConfig strict_config;  // one CORS origin, public base URL

  Fixture() {
    dir = fs::temp_directory_path() / ("vts-fuzz-router-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    build("t", std::nullopt);
    build("s", vts::TexelRect{0, 0, 20, 20});
    build("p", std::nullopt);
    if (!registry.load({dir})) std::abort();
    vts::TilesetAccess access;
    access.bearer_tokens = {"secret"};
    access.hmac_keys = {"k"};
    for (auto* c : {&open_config, &strict_config}) {
      c->access["p"] = access;
      c->now_unix_seconds = [] { return std::int64_t{1000}; };
    }
    strict_config.cors_origin = "https://app.example";
    strict_config.public_base_url = "https://tiles.example/base/";
  }
  ~Fixture() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }

  void build(const std::string& name, std::optional<vts::TexelRect> region) {
    vts::BuildOptions o;
    o.synthetic = vts::SyntheticSpec{100, 50, region, 2};
    o.output = dir / (name + ".pmtiles");
    o.tile_size = 16;
    o.border = 2;
    o.threads = 1;
    if (!vts::build_pyramid(o)) std::abort();
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

bool clean_header_text(std::string_view s) {
  for (char c : s) {
    if (c == '\r' || c == '\n' || c == '\0') return false;
  }
  return true;
}

void check_response(const vts::HttpRequest& req, const vts::HttpResponse& r) {
  check(r.status >= 100 && r.status <= 599);
  check(r.owned.empty() || r.view.empty());
  for (const auto& [name, value] : r.headers) {
    check(!name.empty() && clean_header_text(name) && clean_header_text(value));
  }
  if (r.file_body) {
    check(r.hold != nullptr && r.owned.empty() && r.view.empty());
    check(r.file_offset <= r.hold->reader->size() &&
          r.content_length <= r.hold->reader->size() - r.file_offset);
  } else if (!r.view.empty()) {
    check(r.keep != nullptr || r.route == vts::Route::viewer);  // viewer assets: static storage
    check(r.content_length == r.view.size());
  } else {
    check(r.content_length == r.owned.size());
  }
  if (r.status == 204 || r.status == 304) check(r.content_length == 0);
  check(r.head_only == (req.method == vts::HttpMethod::head));
  if (r.status >= 400) check(!r.owned.empty() && r.owned.back() == '\n');
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Fixture& f = fixture();
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  std::vector<std::string_view> lines;
  for (std::size_t start = 0; start <= input.size() && lines.size() < 10;) {
    const std::size_t nl = input.find('\n', start);
    if (nl == std::string_view::npos) {
      lines.push_back(input.substr(start));
      break;
    }
    lines.push_back(input.substr(start, nl - start));
    start = nl + 1;
  }
  lines.resize(10);

  vts::HttpRequest req;
  req.method_text = lines[0];
  req.method = lines[0] == "GET"       ? vts::HttpMethod::get
               : lines[0] == "HEAD"    ? vts::HttpMethod::head
               : lines[0] == "OPTIONS" ? vts::HttpMethod::options
                                       : vts::HttpMethod::other;
  // Substitute the current version for "@cur" after a one-letter tileset name.
  std::string target(lines[1]);
  if (const auto at = target.find("@cur"); at != std::string::npos && at > 0) {
    if (auto t = f.registry.find(target.substr(at - 1, 1))) {
      target.replace(at + 1, 3, t->version);
    }
  }
  req.target = target;
  req.host = lines[2];
  req.if_none_match = lines[3];
  req.range = lines[4];
  req.if_range = lines[5];
  req.origin = lines[6];
  req.authorization = lines[7];
  req.access_control_request_method = lines[8];
  req.accept = lines[9];

  for (const auto* config : {&f.open_config, &f.strict_config}) {
    // With its plan carried out (a web image is encoded on this thread: no encode pool here).
    const vts::HttpResponse r = vts::finish_pending_now(vts::route(req, f.registry, *config));
    check_response(req, r);
  }
  for (const bool ready : {false, true}) {
    vts::AdminState admin;
    admin.ready = ready;
    admin.metrics_text = [] { return std::string("vts_up 1\n"); };
    admin.max_target_bytes = 2048;
    const vts::HttpResponse r = vts::route_admin(req, admin);
    check_response(req, r);
    check(r.route == vts::Route::admin);
  }
  return 0;
}
