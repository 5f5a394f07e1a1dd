// The admin listener's routes: /metrics and /health (docs/PROTOCOL.md §10).
#include "router_internal.hpp"

namespace vts {

using namespace router_detail;

HttpResponse route_admin(const HttpRequest& request, const AdminState& state) {
  std::optional<HttpResponse> rejection;
  const auto target = parse_target(request.target, state.max_target_bytes, rejection);
  HttpResponse r;
  if (!target) {
    r = std::move(*rejection);
  } else if (request.method != HttpMethod::get && request.method != HttpMethod::head) {
    set_owned(r, "method not allowed\n", kTextType);
    r.status = 405;
    add(r, "Allow", "GET, HEAD");
  } else {
    if (target->raw_path == "/metrics") {
      set_owned(r, state.metrics_text ? state.metrics_text() : std::string(),
                "text/plain; version=0.0.4; charset=utf-8");
    } else if (target->raw_path == "/health") {
      r.status = state.ready && state.degraded.empty() ? 200 : 503;
      set_owned(r,
                !state.ready             ? std::string("loading\n")
                : state.degraded.empty() ? std::string("ok\n")
                                         : "degraded: " + state.degraded + "\n",
                kTextType);
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

}  // namespace vts
