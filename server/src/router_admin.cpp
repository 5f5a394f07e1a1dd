// The admin listener's routes: /metrics and /health (docs/PROTOCOL.md §10).
#include "router_internal.hpp"
#include "vts/base/file_io.hpp"

namespace vts {
inline namespace server {

using namespace router_detail;

namespace {

std::string health_text(const AdminState& state) {
  std::string body = !state.ready ? std::string("loading\n")
                     : state.degraded.empty()
                         ? std::string("ok\n")
                         : "degraded: " + escape_controls(state.degraded) + "\n";
  if (!state.skipped) return body;
  for (const auto& s : state.skipped()) {
    body += "skipped ";
    // One line per archive, whatever its file is named.
    body += escape_controls(s.file.string()) + ": " + escape_controls(s.error.message) + '\n';
  }
  return body;
}

}  // namespace

HttpResponse route_admin(const HttpRequest& request, const AdminState& state) {
  std::optional<HttpResponse> rejection;
  const auto target = parse_target(request.target, state.max_target_bytes, rejection);
  // `OPTIONS *` (asterisk-form) is as valid a request here as on the tile listener; only its
  // method is not served.
  const bool asterisk = request.method == HttpMethod::options && request.target == "*";
  HttpResponse r;
  if (!target && !asterisk) {
    r = std::move(*rejection);
  } else if (request.method != HttpMethod::get && request.method != HttpMethod::head) {
    set_owned(r, "method not allowed\n", kTextType);
    r.status = 405;
    add(r, "Allow", "GET, HEAD");
    add(r, "Cache-Control", "no-store");
  } else {
    if (target->raw_path == "/metrics") {
      set_owned(r, state.metrics_text ? state.metrics_text() : std::string(),
                "text/plain; version=0.0.4; charset=utf-8");
    } else if (target->raw_path == "/health") {
      r.status = state.ready && state.degraded.empty() ? 200 : 503;
      set_owned(r, health_text(state), kTextType);
    } else {
      r.status = 404;
      set_owned(r, "not found\n", kTextType);
    }
    add(r, "Cache-Control", "no-store");
  }
  r.route = Route::admin;
  r.head_only = request.method == HttpMethod::head;
  return r;
}

}  // namespace server
}  // namespace vts
