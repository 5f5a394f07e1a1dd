// fault_proxy: the FaultProxy of fault_proxy.hpp as a process, for shell tests and load tests.
//
//   fault_proxy --upstream URL [--port N] [--prefix P] [--error-every N [--error-status S]]
//               [--reset-every N] [--delay-every N --delay-ms D] [--threads N] [--stats FILE]
//
//   --upstream URL     where to forward: http://HOST:PORT, HOST:PORT or PORT (HOST: an IP
//                      literal or localhost; default 127.0.0.1)
//   --port N           listen on 127.0.0.1:N (default 0: any free port)
//   --prefix P         only requests whose target begins with P are numbered and faulted
//                      (e.g. /earth/ for that tileset's tiles); default: all requests
//   --error-every N    matching request n with n % N == 0 is answered with status S (400-599,
//   --error-status S   default 503) and a short text body, without contacting upstream
//   --reset-every N    ... is aborted with a TCP RST instead of an answer
//   --delay-every N    ... is forwarded after an asynchronous wait of D milliseconds
//   --delay-ms D
//   --threads N        threads serving connections (default 2)
//   --stats FILE       at exit, write the final GET /_proxy/stats JSON to FILE
//
// Precedence when one request is picked by several schedules: error > reset > delay.
// Prints "listening on PORT" on stdout once it accepts connections, then serves until SIGTERM or
// SIGINT and exits 0. Exit 2 on bad arguments, 1 when the port or the stats file is unusable.
#include <signal.h>

#include <charconv>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "fault_proxy.hpp"

namespace {

int usage(const std::string& why) {
  std::fprintf(stderr,
               "fault_proxy: %s\n"
               "usage: fault_proxy --upstream URL [--port N] [--prefix P]\n"
               "                   [--error-every N [--error-status S]] [--reset-every N]\n"
               "                   [--truncate-every N]\n"
               "                   [--delay-every N --delay-ms D] [--threads N] [--stats FILE]\n",
               why.c_str());
  return 2;
}

template <typename T>
bool parse_number(std::string_view s, T& out) {
  if (s.empty()) return false;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && p == s.data() + s.size();
}

// "http://HOST:PORT[/]", "HOST:PORT" or "PORT".
bool parse_upstream(std::string_view url, vts::test::FaultProxyOptions& o) {
  if (url.substr(0, 7) == "http://") url.remove_prefix(7);
  if (!url.empty() && url.back() == '/') url.remove_suffix(1);
  std::string_view host = "127.0.0.1", port = url;
  if (const auto colon = url.rfind(':'); colon != std::string_view::npos) {
    host = url.substr(0, colon);
    port = url.substr(colon + 1);
    if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
      host = host.substr(1, host.size() - 2);
    }
    if (host == "localhost") host = "127.0.0.1";
  }
  o.upstream_host = std::string(host);
  return parse_number(port, o.upstream_port) && o.upstream_port != 0;
}

}  // namespace

int main(int argc, char** argv) {
  vts::test::FaultProxyOptions options;
  std::optional<std::string> stats_path;
  bool have_upstream = false, have_status = false, have_delay_ms = false;
  long delay_ms = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string_view flag = argv[i];
    if (i + 1 >= argc) return usage("missing value after " + std::string(flag));
    const std::string_view value = argv[++i];
    bool ok = true;
    if (flag == "--upstream") {
      ok = have_upstream = parse_upstream(value, options);
    } else if (flag == "--port") {
      ok = parse_number(value, options.port);
    } else if (flag == "--prefix") {
      options.prefix = std::string(value);
    } else if (flag == "--error-every") {
      ok = parse_number(value, options.error_every) && options.error_every > 0;
    } else if (flag == "--error-status") {
      ok = have_status = parse_number(value, options.error_status);
    } else if (flag == "--reset-every") {
      ok = parse_number(value, options.reset_every) && options.reset_every > 0;
    } else if (flag == "--truncate-every") {
      ok = parse_number(value, options.truncate_every) && options.truncate_every > 0;
    } else if (flag == "--delay-every") {
      ok = parse_number(value, options.delay_every) && options.delay_every > 0;
    } else if (flag == "--delay-ms") {
      ok = have_delay_ms = parse_number(value, delay_ms) && delay_ms >= 0 && delay_ms <= 3'600'000;
    } else if (flag == "--threads") {
      ok = parse_number(value, options.threads) && options.threads > 0 && options.threads <= 256;
    } else if (flag == "--stats") {
      ok = !value.empty();
      stats_path = std::string(value);
    } else {
      return usage("unknown option " + std::string(flag));
    }
    if (!ok) return usage("bad value '" + std::string(value) + "' for " + std::string(flag));
  }
  if (!have_upstream) return usage("--upstream is required");
  if (have_status && options.error_every == 0) return usage("--error-status needs --error-every");
  if (have_delay_ms != (options.delay_every > 0)) {
    return usage("--delay-every and --delay-ms go together");
  }
  options.delay = std::chrono::milliseconds(delay_ms);

  // Opened now, so an unwritable path fails before any traffic; written at exit.
  FILE* stats_file = nullptr;
  if (stats_path) {
    stats_file = std::fopen(stats_path->c_str(), "w");
    if (!stats_file) {
      std::perror(("fault_proxy: " + *stats_path).c_str());
      return 1;
    }
  }

  // Block the signals before any thread starts, so every thread inherits the mask and sigwait()
  // below is the only receiver.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto proxy = vts::test::FaultProxy::start(options);
  if (!proxy) {
    std::fprintf(stderr, "fault_proxy: %s\n", proxy.error().to_string().c_str());
    return proxy.error().code == vts::ErrorCode::invalid_argument ? 2 : 1;
  }
  std::unique_ptr<vts::test::FaultProxy> running = std::move(*proxy);
  std::printf("listening on %u\n", unsigned(running->port()));
  std::fflush(stdout);

  int sig = 0;
  sigwait(&signals, &sig);
  running->stop();  // closes every connection and joins: the counts are final
  const vts::test::FaultProxyStats stats = running->stats();
  if (stats_file) {
    const std::string json = stats.to_json() + "\n";
    const bool written = std::fputs(json.c_str(), stats_file) >= 0;
    if (std::fclose(stats_file) != 0 || !written) {
      std::fprintf(stderr, "fault_proxy: cannot write %s\n", stats_path->c_str());
      return 1;
    }
  }
  return 0;
}
